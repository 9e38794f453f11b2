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

Measured (2 cores, ~9 s wall for 12.7 s simulated; episode = forwards / backwards):

    settings                                    start latency   steps begun after drop   false starts
    default (joint, 3 N, 1.5 N), seeds 0-4      0.18 / 0.18 s   1 / 1 (stop decided      0
      and --no-noise                                            +0.13 s after the drop)
    --force 0, seeds 0-4 and --no-noise         -               -                        0
    --trigger-source observer, 3 N, seed 1      0.32 / 0.32 s   forwards stopped 0.7 s   0
                                                                before the drop / 2
    observer, 4 N (the former default)          0.28 / 0.28 s   1 / 3 (seed 1, no noise) 0
                                                                1 / 1 (seeds 0, 2)
    joint, 4 N, seed 0                          0.17 / 0.17 s   1 / 6: the backward gait 0
                                                                breaks up (yaw 40 deg)
    blend (eq. 28), 3 N, seed 1                 0.27 / 0.26 s   2 / 1                    0
    blend (eq. 28), 4 N, seed 1                 0.25 / 0.23 s   1 / 3                    0

Walking backwards while pushed backwards with 4 N is beyond the walking controller: once
the trigger keeps it walking for the whole 3 s push (6 steps), the steps degrade into
short hops with both feet off the ground (seed 0: 17 lift-offs, yaw 40 deg); the observer
trigger hid this by stopping early. Hence the 3 N default (ZMP shift ~1.3 cm).

Run: ``python -m apps.nao_force_guided_walk [--force N] [--threshold N] [--trigger-source
joint|observer|blend] [--preset walking|standing] [--force-rate-variance V] [--start-debounce S]
[--stop-debounce S] [--seed S] [--no-noise] [--out DIR] [--headless] [--no-replay]``. Writes to
DIR (default ``out/nao_force_guided_walk``): ``metrics.json``, ``guided.png`` (applied and
estimated F_x (both estimates) with the threshold, walking state, CoM x, foot forces) and
``guided.html`` (Meshcat replay).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from pydrake.geometry import Meshcat  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402

from apps.common import replay_meshcat  # noqa: E402
from diagrams.observer.nao_force_guided_walk import (DEFAULT_TRIGGER_SOURCE, TRIGGER_SOURCES,  # noqa: E402
                                                     build_force_guided_diagram, guided_metrics)
from systems.observer.force_guided_walking import GUIDED_WALKING, TriggerParameters  # noqa: E402
from systems.observer.hand_guidance import GuidanceProfile  # noqa: E402

#: App defaults (measured, see the module docstring's table). 3 N on the hands moves the ZMP
#: ~1.3 cm; 4 N pushing backwards for 3 s while the robot walks backwards breaks its gait up.
#: The observer's settings (only with ``--trigger-source observer``): the paper does not give
#: them for Sec. 6.5; its walking preset (eq. 22) lags ~0.5 s behind a force step, too slow
#: for the start floor; eq. 21 with a 10x larger force-rate variance follows within ~0.2 s.
DEFAULT_FORCE = 3.0
DEFAULT_THRESHOLD = 1.5
DEFAULT_PRESET = "standing"
DEFAULT_FORCE_RATE_VARIANCE = 1e4
#: The guidance episodes (t_on, t_off, sign of the force) and the simulated time, s.
EPISODES = ((1.5, 5.5, 1.0), (7.5, 10.5, -1.0))
DURATION = 12.7


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


def run(profile: GuidanceProfile, trigger: TriggerParameters, *, preset: str = "walking",
        force_rate_variance: float | None = None, noise: bool = True,
        seed: int = 0, duration: float | None = None, meshcat: Meshcat | None = None,
        trigger_source: str = DEFAULT_TRIGGER_SOURCE) -> dict:
    diagram, handles = build_force_guided_diagram(profile, trigger, preset=preset,
                                                  force_rate_variance=force_rate_variance, noise=noise, seed=seed,
                                                  meshcat=meshcat, trigger_source=trigger_source)
    simulator = Simulator(diagram)
    handles["station"].set_initial_state(simulator.get_mutable_context())
    if meshcat is not None:
        meshcat.SetCameraPose(camera_in_world=[0.3, -1.4, 0.6], target_in_world=[0.2, 0.0, 0.2])
        meshcat.StartRecording(frames_per_second=32.0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(duration if duration is not None else profile.end + 2.0)
    wall = time.perf_counter() - start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    m = guided_metrics(handles, simulator.get_context(), profile, trigger)
    m["wall_time_s"] = wall
    m["simulated_s"] = simulator.get_context().get_time()
    return m


def _parse(argv):
    parser = argparse.ArgumentParser(prog="python -m apps.nao_force_guided_walk", description=__doc__.split("\n\n")[0])
    parser.add_argument("--force", type=float, default=DEFAULT_FORCE,
                        help=f"total guidance force on the hands, N (default {DEFAULT_FORCE}; 0: no force, the "
                             "false-start check)")
    parser.add_argument("--trigger-source", choices=TRIGGER_SOURCES, default=DEFAULT_TRIGGER_SOURCE,
                        help="the trigger's input: the arm joints' hand force estimate (eqs. 25-27), the "
                             "observer's, or eq. 28's blend of the two with K1 = K_a / 8 "
                             f"(default {DEFAULT_TRIGGER_SOURCE})")
    parser.add_argument("--threshold", type=float, default=DEFAULT_THRESHOLD,
                        help=f"threshold on the estimated F_x, N (default {DEFAULT_THRESHOLD})")
    parser.add_argument("--preset", choices=("walking", "standing"), default=DEFAULT_PRESET,
                        help=f"observer covariances: eq. 22 (walking) or eq. 21 (standing; default {DEFAULT_PRESET})")
    parser.add_argument("--force-rate-variance", type=float, default=DEFAULT_FORCE_RATE_VARIANCE,
                        help="sigma^2 of the force's second derivative (eq. 17), (N/s^2)^2 "
                             f"(default {DEFAULT_FORCE_RATE_VARIANCE:g}; the paper's presets: 1e3)")
    parser.add_argument("--start-debounce", type=float, default=TriggerParameters().start_debounce, help="s")
    parser.add_argument("--stop-debounce", type=float, default=TriggerParameters().stop_debounce, help="s")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-noise", action="store_true")
    parser.add_argument("--out", type=Path, default=Path("out") / "nao_force_guided_walk")
    parser.add_argument("--headless", action="store_true")
    parser.add_argument("--no-replay", action="store_true")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    try:
        if args.seed < 0:
            raise ValueError(f"--seed must be non-negative, got {args.seed}")
        if not (args.force > args.threshold or args.force == 0.0):
            raise ValueError(f"--force ({args.force} N) must exceed --threshold ({args.threshold} N), or be 0")
        trigger = TriggerParameters(threshold=args.threshold, start_debounce=args.start_debounce,
                                    stop_debounce=args.stop_debounce)
        profile = GuidanceProfile(plateaus=tuple((t_on, t_off, sign * args.force) for t_on, t_off, sign in EPISODES)
                                  if args.force > 0 else ())
    except ValueError as error:
        print(f"nao_force_guided_walk: error: {error}", file=sys.stderr)
        return 2
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    meshcat = replay_meshcat(not args.no_replay, args.headless)
    source = {"joint": "the arm joints' hand force estimate",
              "observer": f"the observer's estimate ({args.preset} preset)",
              "blend": f"eq. 28's blend of the observer ({args.preset} preset) and the arm joints"}[args.trigger_source]
    print(f"guiding nao_like by the hands: {args.force} N forwards 1.5-5.5 s, backwards 7.5-10.5 s; threshold "
          f"{args.threshold} N on {source} ...", flush=True)
    m = run(profile, trigger, preset=args.preset, force_rate_variance=args.force_rate_variance, noise=not args.no_noise,
            seed=args.seed, meshcat=meshcat, trigger_source=args.trigger_source, duration=DURATION)
    if meshcat is not None:
        (out / "guided.html").write_text(meshcat.StaticHtml())
    plot(out / "guided.png", m, args.threshold)
    checks = {}
    for i, e in enumerate(m["episodes"]):
        checks[f"episode{i}_start_within_0.5s"] = e["start_ok"]
        checks[f"episode{i}_stop_within_one_step"] = e["stop_ok"]
        checks[f"episode{i}_moved_in_force_direction"] = e["moved_in_force_direction"]
    checks["no_false_start"] = not m["false_starts_s"]
    checks["no_fall"] = not m["fell"]
    summary = {k: v for k, v in m.items() if k != "signals"}
    summary.update(floors=checks, meets_floors=all(checks.values()), threshold_N=args.threshold, force_N=args.force,
                   trigger_source=args.trigger_source, preset=args.preset, noise=not args.no_noise, seed=args.seed,
                   walking_parameters=dataclasses.asdict(GUIDED_WALKING))
    (out / "metrics.json").write_text(json.dumps(summary, indent=2, default=float))
    def seconds(value) -> str:
        return "never" if value is None else f"{value:.3f} s"

    for i, e in enumerate(m["episodes"]):
        print(f"  episode {i} ({'forwards' if e['direction'] > 0 else 'backwards'}): start latency "
              f"{seconds(e['start_latency_s'])} (first lift-off {seconds(e['first_lift_off_latency_s'])}), "
              f"{e['steps_during']} steps, CoM x {e['com_x_displacement_m']:+.3f} m; after the drop: stop decided "
              f"+{seconds(e['stop_decision_latency_s'])}, "
              f"steps begun {e['steps_begun_after_drop']} (lift-offs {e['lift_offs_after_drop']}), last touch-down "
              f"+{e['last_touch_down_after_drop_s']:.2f} s")
    print(f"  false starts (no force on): {len(m['false_starts_s'])}")
    for name, err in m["estimate_errors_while_walking"].items():
        if err["samples"]:
            print(f"  F_x error while walking, {name}: mean {err['mean_N']:+.3f} N, std {err['std_N']:.3f} N, max "
                  f"|e| {err['max_abs_N']:.2f} N ({err['samples']} samples)")
    print(f"  {'upright' if not m['fell'] else 'FELL'} (max tilt {m['max_base_tilt_deg']:.1f} deg, max |yaw| "
          f"{m['max_abs_yaw_deg']:.1f} deg); {m['wall_time_s']:.1f} s wall for {m['simulated_s']:.1f} s; floors "
          f"{'met' if summary['meets_floors'] else 'MISSED: ' + ', '.join(k for k, v in checks.items() if not v)}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
