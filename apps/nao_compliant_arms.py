"""Compliant arms on the simulated Nao-like robot (Hawley, Rahem, Suleiman 2019, Sec. 6.4,
eqs. 25-29, Figs. 12-14).

Both hands are pushed backwards (-x) by the same force, put on with a 2 s quintic ramp,
held, and released; the arms yield as x_h = x_h^0 + F_x / k (eq. 29, k = 50 N/m), with F_x
the blend (eq. 28) of the Kalman observer (read as a force on the hands) and the joint-level
estimate from the arm's position errors (eqs. 25-27, K_m identified in simulation first:
``diagrams.observer.calibration``, an explicit run before the cases).

* case a: standing (wide stance), all 8 FSRs loaded: K1 = 1, the observer drives eq. 29;
* case b: the robot first leans sideways (t = 0.5-2.5 s, both hip rolls -0.1 rad, ankle
  rolls +0.1 rad; ``--lean``): the soft ankles let both feet roll onto their -y edges and
  FSRs lose contact, so K1 = K_a / K_t < 1 and the joint-level estimate takes part of the
  weight. A larger lean saturates an FSR and degrades the observer's estimate (the paper's
  "unreliable data from the FSR"); ``--saturation-guard`` (an extension of eq. 28) then
  sets K1 = 0. The app prints each case's steady K1; ``metrics.json`` also holds the FSR
  forces and saturated samples.

Floor (issue 7): hand displacement (true, torso frame) within 10 % of F / k in steady state,
against the true force and against the estimate
(``diagrams.observer.nao_compliant_arms.scenario_metrics``).

The scenario is ``NaoCompliantArmsScenario`` (``diagrams.observer.nao_compliant_arms``;
every field in ``apps/scenarios/nao_compliant_arms_default.yaml``); the options ``--case``,
``--force``, ``--lean``, ``--seed``, ``--saturation-guard`` and
``--no-deflection-compensation`` override its fields. (The paper's "scenarios" a and b are
``--case a|b``: ``--scenario`` is the scenario file, as in every app.)

Run: ``python -m apps.nao_compliant_arms [--out DIR] [--headless] [--no-replay]
[--scenario FILE] [--scenario-text YAML] [--seed N] [--case a|b|all] [--force N]
[--lean RAD] [--saturation-guard] [--no-deflection-compensation]``.
Writes to ``DIR/nao_compliant_arms/`` (DIR default ``out``): ``scenario_<s>.png`` (Fig. 14
style), ``scenario_<s>.html`` (Meshcat replay: red = applied forces, blue = blended
estimate), ``metrics.json``, and prints a table.
"""

import functools
import time
from pathlib import Path

import matplotlib.pyplot as plt

from apps.runner import (
    experiment_parser,
    logged_signals,
    output_folder,
    print_written,
    replay_meshcat,
    run_app,
    save_replay,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.observer.calibration import identified_motor_constants, settle_standing_state
from diagrams.observer.nao_compliant_arms import (
    CASE_NAMES,
    DISPLACEMENT_FLOOR,
    DURATION,
    SIDES,
    STEADY_WINDOW,
    HandPushCase,
    NaoCompliantArmsScenario,
    arms_summary,
    build_case_diagram,
    scenario_cases,
    scenario_metrics,
)
from diagrams.observer.nao_force_observer import wide_stance

EXPERIMENT = "nao_compliant_arms"


def plot_scenario(path: Path, case: HandPushCase, metrics: dict) -> None:
    """Fig. 14 style: hand displacement with F/k, the estimated forces, and K1."""
    d = metrics["_series"]
    t, k = d["t"], metrics["stiffness_N_per_m"]
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.3]})
    colors = {"left": "tab:blue", "right": "tab:orange"}
    for j, side in enumerate(SIDES):
        x = 3 * j
        axes[0].plot(
            t,
            100 * d["dx"][:, x],
            color=colors[side],
            lw=2.6 if side == "left" else 1.2,
            alpha=0.6 if side == "left" else 1.0,
            label=f"{side} hand displacement (true)",
        )
    axes[0].plot(t, 100 * d["F_true"][:, 0] / k, "--", color="tab:green", lw=1.5, label="F_true / k")
    axes[0].plot(t, 100 * d["blended_force"][:, 0] / k, ":", color="k", lw=1.3, label="F_est / k (left)")
    axes[0].set_ylabel("x_h - x_h^0 [cm]")
    axes[0].legend(fontsize=8, loc="lower left")
    axes[0].set_title(case.title, fontsize=10)
    axes[1].plot(t, d["F_true"][:, 0], "--", color="tab:green", lw=1.5, label="true (per hand)")
    axes[1].plot(
        t, d["observer_force"][:, 0], color="tab:purple", lw=2.4, alpha=0.6, label="observer (eq. 11 inverted)"
    )
    axes[1].plot(t, d["joint_force"][:, 0], color="tab:red", lw=1.0, label="joint level (eqs. 25-27)")
    axes[1].plot(t, d["blended_force"][:, 0], color="k", lw=1.3, label="blended (eq. 28)")
    axes[1].set_ylabel("F_x, left hand [N]")
    axes[1].legend(fontsize=8, loc="lower left")
    axes[2].plot(t, d["k1"], color="tab:gray")
    axes[2].set_ylim(-0.05, 1.05)
    axes[2].set_ylabel("K1")
    axes[2].set_xlabel("time [s] (grey: steady-state window)")
    for ax in axes:
        ax.axvspan(*STEADY_WINDOW, color="0.92", zorder=0)
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _parse(argv):
    parser = experiment_parser(f"apps.{EXPERIMENT}", __doc__)
    parser.add_argument("--seed", type=int, default=None, help="sensor noise seed (overrides the scenario's)")
    parser.add_argument(
        "--case",
        choices=(*CASE_NAMES, "all"),
        default=None,
        help="which of the paper's scenarios a, b (overrides the scenario's cases; all = a b)",
    )
    parser.add_argument("--force", type=float, default=None, help="push per hand, N (overrides the scenario's)")
    parser.add_argument(
        "--lean",
        type=float,
        default=None,
        help="case b's hip-roll lean, rad (overrides the scenario's; -0.2 saturates an FSR)",
    )
    parser.add_argument(
        "--saturation-guard",
        action="store_const",
        const=True,
        default=None,
        help="extension of eq. 28: K1 = 0 while an FSR saturates (25 N)",
    )
    parser.add_argument(
        "--no-deflection-compensation",
        dest="compensate_deflection",
        action="store_const",
        const=False,
        default=None,
        help="ablation: command eq. 29's IK solution without the K_m^-1 J^T F offset",
    )
    return parser.parse_args(argv)


def _print_table(metrics: dict) -> None:
    print(
        f"{'scenario':<12}{'hand':<7}{'dx [cm]':>9}{'Ftrue/k':>9}{'Fest/k':>9}{'err true':>10}{'err est':>9}"
        f"{'K1':>6}{'floor':>8}{'RTF':>6}"
    )
    for key, m in metrics.items():
        for side, h in m["hands"].items():
            print(
                f"{key:<12}{side:<7}{100 * h['displacement_m']:>9.3f}{100 * h['F_true_over_k_m']:>9.3f}"
                f"{100 * h['F_est_over_k_m']:>9.3f}{100 * h['relative_error_vs_true']:>9.1f}%"
                f"{100 * h['relative_error_vs_estimate']:>8.1f}%{m['k1_steady_mean']:>6.2f}"
                f"{'met' if m['meets_floor'] else 'MISSED':>8}{m['real_time_factor']:>6.2f}"
            )
    print(
        f"floor: steady-state hand displacement within {100 * DISPLACEMENT_FLOOR:g} % of F/k "
        "(against the true force and against the estimate)"
    )


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        cases = None
        if args.case is not None:
            cases = list(CASE_NAMES) if args.case == "all" else [args.case]
        scenario = scenario_from_args(
            NaoCompliantArmsScenario,
            args,
            seed=args.seed,
            cases=cases,
            force=args.force,
            lean=args.lean,
            saturation_guard=args.saturation_guard,
            compensate_deflection=args.compensate_deflection,
        )
        runs = scenario_cases(scenario)  # every case checked before the calibration
        out_dir = output_folder(args, EXPERIMENT)
        start = time.perf_counter()
        km = dict(identified_motor_constants())  # the calibration run, explicit
        print(
            f"K_m identified (static loads on the hands, {time.perf_counter() - start:.1f} s): "
            + ", ".join(f"{n} {v:.3f}" for n, v in km.items())
            + " N m/rad"
        )
        initial_state = settle_standing_state(wide_stance(), plant_config=scenario.station.plant_config)
        meshcat = replay_meshcat(not args.no_replay, args.headless)
        metrics = {}
        for case in runs:
            print(f"scenario {case.title}: {DURATION:g} s simulated ...", flush=True)
            diagram, handles = build_case_diagram(scenario, case, km, meshcat)
            run = simulate(
                diagram,
                DURATION,
                set_initial_state=functools.partial(handles.set_initial_state, state=initial_state),
                simulator_config=scenario.simulator_config,
                meshcat=meshcat,
                live=not args.headless,
                camera=([0.8, -0.8, 0.5], [0.0, 0.0, 0.25]),
            )
            key = f"scenario_{case.name}"
            save_replay(meshcat, out_dir / f"{key}.html")
            signals = logged_signals(handles.loggers, run.context, "state")
            m = scenario_metrics(
                case, {"signals": signals, "handles": handles, "wall": run.wall_time_s}, scenario.stiffness
            )
            plot_scenario(out_dir / f"{key}.png", case, m)
            m.pop("_series")
            metrics[key] = m
        write_metrics(out_dir, {**metrics, "summary": arms_summary(scenario, metrics, km)}, scenario, args)
        _print_table(metrics)
        print_written(out_dir)
        return 0

    return run_app(EXPERIMENT, body)


if __name__ == "__main__":
    raise SystemExit(main())
