"""Force-guided walking (Hawley et al. 2019, Sec. 6.5, Fig. 15) in simulation: a "human" pulls
both hands of nao_like forwards, lets go, then pushes them backwards; an estimate of the
force on the hands drives ``ForceGuidedWalkingController``, which walks in its direction while
|F_x| exceeds the threshold and stops when it falls below. Issue 7, item 4.

The trigger's input (``--trigger-source``):

* ``joint`` (default): the hands' total force from the arm joints (Sec. 6.4, eqs. 25-27:
  tau_m = K_m (q_d - q) against the walking controller's arm targets, minus the arm rows of
  the floating-base inverse dynamics, through (J^T)^+; ``systems.observer.arm_compliance``), i.e.
  eq. 28's blend with K1 = 0. Sec. 6.5 is the interaction of Sec. 6.4 (a human holding the
  hands); eq. 28 gives the joint-level estimate the weight of the FSRs that lose contact,
  and a walking robot unloads one foot's four FSRs in every single support. This estimate
  has no Kalman filter lag (only a 0.1 s low-pass) and does not depend on the feet's
  contact: measured (seed 1) while walking, its error against the applied force has mean
  0.000 N and std 0.03 N (pushed, steady) / 0.02 N (no force, closing steps); standing,
  std 0.002 N (simulation: the model is exact and the encoders' noise is 2e-5 rad).
* ``observer``: the Kalman observer's virtual F_x (eq. 11; ``--preset``, eq. 21 with a 10x
  force-rate variance by default). While walking it errs by ~2 N RMS and lags: walking
  backwards it stayed beyond the threshold up to 0.66 s after the push ended (3 steps begun
  after the drop, 4 N, seed 1), and at 3 N it dips below the threshold mid-walk.
* ``blend``: eq. 28 as in ``diagrams.observer.nao_compliant_arms`` (K1 = K_a / 8, FSRs above 1 N; the
  observer's estimate read as a force on the hands by ``ObserverHandForce``). With both
  feet down (double support, standing, the closing step's end) K1 = 1: the observer alone,
  with its errors; measured (seed 1) it misses the stop floor too (3 N: 2 steps begun after
  the forward drop; 4 N: the backward stop is never decided in time, 3 steps begun).

Floors (issue 7): the robot starts within 0.5 s of the (applied) force crossing the
threshold, and stops within one step after it drops. Definitions here: start latency = the
controller's start decision (the segment's t_0, when the CoM starts its first weight shift)
minus the time the applied F_x (sum over both hands) crosses the threshold; the first
lift-off's latency is reported too. Stop: "steps begun after the drop" = detected lift-offs
later than t_drop + the double-support time (a lift-off before that belongs to the step in
progress at t_drop); the floor is <= 1 (the closing step); the time from the drop to the last
touch-down is reported. Also checked: no false start (a start decision outside every
episode's window [force on, force off + 0.5 s)); ``--force 0`` runs the same 12.7 s without
any force (the false-start check alone).

The app prints each episode's start latency and stop and the false starts, and writes them
to ``metrics.json``. Why the default force is 3 N, not 4 N: ``NaoForceGuidedWalkScenario``
(measured per trigger source, force and seed when it was chosen; see the git history of
BENCHMARKS.md).

Run: ``python -m apps.nao_force_guided_walk [--scenario FILE] [--scenario-text YAML] [--force N]
[--threshold N] [--trigger-source joint|observer|blend] [--preset walking|standing]
[--force-rate-variance V] [--start-debounce S] [--stop-debounce S] [--seed S] [--no-noise]
[--out DIR] [--headless] [--no-replay]``: the scenario is
``diagrams.observer.nao_force_guided_walk.NaoForceGuidedWalkScenario``
(``apps/scenarios/nao_force_guided_walk_default.yaml`` lists every field); the shorthand
options override its fields. Writes to ``DIR/nao_force_guided_walk/`` (default
``out/nao_force_guided_walk/``): ``metrics.json``, ``guided.png`` (applied and estimated F_x
(both estimates) with the threshold, walking state, CoM x, foot forces) and ``guided.html``
(Meshcat replay).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
from pydrake.geometry import Meshcat

from apps.runner import (
    experiment_parser,
    output_folder,
    print_written,
    replace_fields,
    replay_meshcat,
    run_app,
    save_replay,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.observer.nao_force_guided_walk import (
    TRIGGER_SOURCES,
    NaoForceGuidedWalkScenario,
    build_force_guided_diagram,
    force_guided_walk_metrics,
)


def plot(path: Path, m: dict, threshold: float) -> None:
    s = m["signals"]
    t = s["t"]
    applied_x = s["applied"][:, 0] + s["applied"][:, 3]
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True)
    ax = axes[0]
    ax.plot(t, applied_x, "--", color="tab:green", label="applied $F_x$ (both hands)")
    ax.plot(t, s["estimate"][:, 0], color="tab:blue", lw=0.8, alpha=0.6, label="estimated $F_x$ (observer, eq. 11)")
    ax.plot(t, s["joint_estimate"][:, 0], color="tab:orange", lw=0.8, label="estimated $F_x$ (arm joints, eqs. 25-27)")
    for sgn in (1, -1):
        ax.axhline(sgn * threshold, color="tab:red", ls=":", lw=0.8)
    ax.set_ylabel("$F_x$ [N]")
    ax.legend(fontsize=7)
    axes[1].plot(t, s["walking_state"][:, 0], color="k", lw=0.8, label="mode (0 stand, 1 walk, 2 stop)")
    axes[1].plot(t, s["walking_state"][:, 1], color="tab:purple", lw=0.8, label="direction")
    axes[1].legend(fontsize=7)
    axes[2].plot(t, s["com"][:, 0], color="tab:blue")
    axes[2].set_ylabel("CoM x [m]")
    for i, side in enumerate(("left", "right")):
        axes[3].plot(t, s["feet"][:, i], lw=0.7, label=f"{side} foot")
    axes[3].set_ylabel("normal force [N]")
    axes[3].set_xlabel("time [s]")
    axes[3].legend(fontsize=7)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_scenario(scenario: NaoForceGuidedWalkScenario, meshcat: Meshcat | None = None, *, live: bool = True) -> dict:
    """Builds the diagram, simulates ``scenario.duration``; returns the metrics
    (``force_guided_walk_metrics``, with their signals)."""
    diagram, handles = build_force_guided_diagram(scenario, meshcat=meshcat)
    run = simulate(
        diagram,
        scenario.duration,
        set_initial_state=handles["station"].set_initial_state,
        simulator_config=scenario.simulator_config,
        meshcat=meshcat,
        live=live,
        camera=([0.3, -1.4, 0.6], [0.2, 0.0, 0.2]),
    )
    return force_guided_walk_metrics(scenario, handles, run.context, run.wall_time_s)


def _parse(argv):
    d = NaoForceGuidedWalkScenario()
    parser = experiment_parser("apps.nao_force_guided_walk", __doc__)
    parser.add_argument(
        "--force",
        type=float,
        default=None,
        help=f"total guidance force on the hands, N (default {d.force}; 0: no force, the false-start check)",
    )
    parser.add_argument(
        "--trigger-source",
        choices=TRIGGER_SOURCES,
        default=None,
        help="the trigger's input: the arm joints' hand force estimate (eqs. 25-27), the "
        "observer's, or eq. 28's blend of the two with K1 = K_a / 8 "
        f"(default {d.trigger_source})",
    )
    parser.add_argument(
        "--threshold",
        type=float,
        default=None,
        help=f"threshold on the estimated F_x, N (default {d.trigger.threshold})",
    )
    parser.add_argument(
        "--preset",
        choices=("walking", "standing"),
        default=None,
        help=f"observer covariances: eq. 22 (walking) or eq. 21 (standing; default {d.preset})",
    )
    parser.add_argument(
        "--force-rate-variance",
        type=float,
        default=None,
        help="sigma^2 of the force's second derivative (eq. 17), (N/s^2)^2 "
        f"(default {d.force_rate_variance:g}; the paper's presets: 1e3)",
    )
    parser.add_argument("--start-debounce", type=float, default=None, help=f"s (default {d.trigger.start_debounce})")
    parser.add_argument("--stop-debounce", type=float, default=None, help=f"s (default {d.trigger.stop_debounce})")
    parser.add_argument("--seed", type=int, default=None, help="noise seed (default 0)")
    parser.add_argument("--no-noise", action="store_true", help="ideal sensors")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        scenario = scenario_from_args(
            NaoForceGuidedWalkScenario,
            args,
            force=args.force,
            trigger_source=args.trigger_source,
            preset=args.preset,
            force_rate_variance=args.force_rate_variance,
            seed=args.seed,
            noise=False if args.no_noise else None,
        )
        scenario.trigger = replace_fields(
            scenario.trigger,
            threshold=args.threshold,
            start_debounce=args.start_debounce,
            stop_debounce=args.stop_debounce,
        )
        scenario.check()
        out = output_folder(args, "nao_force_guided_walk")
        meshcat = replay_meshcat(not args.no_replay, args.headless)
        source = {
            "joint": "the arm joints' hand force estimate",
            "observer": f"the observer's estimate ({scenario.preset} preset)",
            "blend": f"eq. 28's blend of the observer ({scenario.preset} preset) and the arm joints",
        }[scenario.trigger_source]
        episodes = ", ".join(
            f"{'forwards' if sign > 0 else 'backwards'} {t_on:g}-{t_off:g} s" for t_on, t_off, sign in scenario.episodes
        )
        print(
            f"guiding nao_like by the hands: {scenario.force} N {episodes}; threshold "
            f"{scenario.trigger.threshold} N on {source} ...",
            flush=True,
        )
        m = run_scenario(scenario, meshcat, live=not args.headless)
        save_replay(meshcat, out / "guided.html")
        plot(out / "guided.png", m, scenario.trigger.threshold)
        write_metrics(out, {k: v for k, v in m.items() if k != "signals"}, scenario, args)
        checks = m["floors"]

        def seconds(value) -> str:
            return "never" if value is None else f"{value:.3f} s"

        for i, e in enumerate(m["episodes"]):
            print(
                f"  episode {i} ({'forwards' if e['direction'] > 0 else 'backwards'}): start latency "
                f"{seconds(e['start_latency_s'])} (first lift-off {seconds(e['first_lift_off_latency_s'])}), "
                f"{e['steps_during']} steps, CoM x {e['com_x_displacement_m']:+.3f} m; after the drop: stop decided "
                f"+{seconds(e['stop_decision_latency_s'])}, "
                f"steps begun {e['steps_begun_after_drop']} (lift-offs {e['lift_offs_after_drop']}), last touch-down "
                f"+{e['last_touch_down_after_drop_s']:.2f} s"
            )
        print(f"  false starts (no force on): {len(m['false_starts_s'])}")
        for name, err in m["estimate_errors_while_walking"].items():
            if err["samples"]:
                print(
                    f"  F_x error while walking, {name}: mean {err['mean_N']:+.3f} N, std {err['std_N']:.3f} N, "
                    f"max |e| {err['max_abs_N']:.2f} N ({err['samples']} samples)"
                )
        print(
            f"  {'upright' if not m['fell'] else 'FELL'} (max tilt {m['max_base_tilt_deg']:.1f} deg, max |yaw| "
            f"{m['max_abs_yaw_deg']:.1f} deg); {m['wall_time_s']:.1f} s wall for {m['simulated_s']:.1f} s; floors "
            f"{'met' if m['meets_floors'] else 'MISSED: ' + ', '.join(k for k, v in checks.items() if not v)}"
        )
        print_written(out)
        return 0

    return run_app("nao_force_guided_walk", body)


if __name__ == "__main__":
    raise SystemExit(main())
