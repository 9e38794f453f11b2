"""Simulated experiments 1-3 of Hawley, Rahem and Suleiman (2019), Sec. 6.1-6.2, Figs. 6-8:
the Kalman force observer on the Nao-like robot standing under joint position control.

* experiment 1 (Fig. 6): a 2 N force through the torso in the x-z plane, at several angles
  theta (eq. 23: F_x = |F| cos theta, F_z = |F| sin theta); the force's direction turns
  from one angle to the next at constant magnitude;
* experiment 2 (Fig. 7): a 1.13 kg load pulling the right arm along -y (m g = 11.09 N) by a
  cable at the elbow. The paper's cable acts at about the CoM height (its W_2, eq. 24); on
  the model that is the wrist, 0.15 m below the shoulder, where 11.09 N sideways needs
  1.7 N m of shoulder roll, more than the model's 1.5 N m effort limit (the hand needs
  2.3 N m): the arm would be pulled out. At the elbow it needs 1.1 N m; being 6 cm above the
  CoM, the virtual force is ~-13.8 N instead of the paper's -10.96 N;
* experiment 3 (Fig. 8): the same load hanging from the right hand (-z): its moment about
  the CoM gives horizontal virtual forces (eqs. 11 and 24).

The robot stands with a slightly wider stance than the nominal one (each hip rolled out by
0.1 rad, ``diagrams.observer.nao_force_observer.wide_stance``): the nominal stance's FSR
polygon ends 3 cm outside each foot's centre (8 cm from the mid-line) and experiment 2 moves
the CoP 7 cm sideways (eq. 10). The measured nominal-stance runs are in BENCHMARKS.md.

Expected values: the virtual force F^ of eq. (11) computed from the applied wrench and the
true CoM at every sample (``diagrams.observer.nao_force_observer.VirtualForceTruth``): a
force at a point above or below the CoM, or beside it, creates a moment that moves the ZMP;
eq. (11) maps it to the equivalent force at the CoM height. Loads are put on and taken off
with smooth (quintic) ramps, like a hand lowering the mass; ``--ramp`` sets their duration
(5 s by default; experiment 1's 2 N force ramps in 1.5 s and turns in 1 s): with the
paper's eq. (21) parameters the filters overshoot a step and the x/y filters need ~4 s to
settle, so a step load over a ~20 s run gives an RMS error above 1 N (measurements in
BENCHMARKS.md).

The scenario is ``NaoForceObserverScenario`` (``diagrams.observer.nao_force_observer``;
every field in ``apps/scenarios/nao_force_observer_default.yaml``); the options
``--experiment``, ``--time-scale``, ``--ramp`` and ``--seed`` override its fields.

Run: ``python -m apps.nao_force_observer [--out DIR] [--headless] [--no-replay]
[--scenario FILE] [--scenario-text YAML] [--seed N] [--experiment 1|2|3|all]
[--time-scale S] [--ramp SECONDS]``. Writes to ``DIR/nao_force_observer/`` (DIR default
``out``): ``experiment_<k>.png`` (estimate vs expected, Figs. 6-8 style),
``experiment_<k>.html`` (self-contained Meshcat replay: red arrows = applied forces, blue =
estimated virtual force at the CoM) and ``metrics.json`` (RMS and steady-state error per
component per experiment, with the floors, and the scenario), and prints a table.

Floors (issue 6): per experiment and component, steady-state error <= 0.5 N and RMS error
over the run <= 1 N (``diagrams.observer.nao_force_observer.experiment_metrics``).
"""

from __future__ import annotations

import functools
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

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
from diagrams.observer.calibration import settle_standing_state
from diagrams.observer.nao_force_observer import (
    COMPONENTS,
    EXPERIMENT_NUMBERS,
    RMS_FLOOR,
    STEADY_STATE_FLOOR,
    STEADY_WINDOW,
    Experiment,
    NaoForceObserverScenario,
    aligned,
    build_experiment_diagram,
    experiment_metrics,
    experiments_summary,
    scenario_experiments,
)

EXPERIMENT = "nao_force_observer"


def plot_experiment(path: Path, experiment: Experiment, run: dict) -> None:
    """Figs. 6-8 style: each component's estimate (solid) and expected value (green dashed);
    experiment 3 adds the norm (as Fig. 8b)."""
    a = aligned(run["signals"])
    rows = 4 if experiment.number == 3 else 3
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.0 * rows + 0.6), sharex=True)
    labels = [f"F_{c}" for c in COMPONENTS] + (["|F|"] if rows == 4 else [])
    estimate, expected = a["estimate"], a["expected"]
    if rows == 4:
        estimate = np.column_stack((estimate, np.linalg.norm(estimate, axis=1)))
        expected = np.column_stack((expected, np.linalg.norm(expected, axis=1)))
    for k, ax in enumerate(axes):
        ax.plot(a["t"], estimate[:, k], color="tab:blue", lw=1.2, label="estimate")
        ax.plot(a["t"], expected[:, k], "--", color="tab:green", lw=1.5, label="expected (eq. 11)")
        for _t0, t1 in experiment.windows:
            ax.axvspan(t1 - STEADY_WINDOW, t1, color="0.92", zorder=0)
        low, high = ax.get_ylim()  # at least +-1 N, so that noise is not blown up
        ax.set_ylim(min(low, -1.0), max(high, 1.0))
        ax.set_ylabel(f"{labels[k]} [N]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, loc="best")
    axes[0].set_title(experiment.title, fontsize=10)
    axes[-1].set_xlabel("time [s] (grey: steady-state windows)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _parse(argv):
    parser = experiment_parser(f"apps.{EXPERIMENT}", __doc__)
    parser.add_argument("--seed", type=int, default=None, help="sensor noise seed (overrides the scenario's)")
    parser.add_argument(
        "--experiment",
        choices=(*map(str, EXPERIMENT_NUMBERS), "all"),
        default=None,
        help="which experiment (overrides the scenario's experiments; all = 1 2 3)",
    )
    parser.add_argument(
        "--time-scale",
        type=float,
        default=None,
        help="multiply every duration of the schedules (e.g. 0.5 for a quick run; overrides the scenario's)",
    )
    parser.add_argument(
        "--ramp",
        type=float,
        default=None,
        help="load ramp duration of experiments 2-3 before scaling, s (overrides the scenario's)",
    )
    return parser.parse_args(argv)


def _print_table(metrics: dict) -> None:
    print(
        f"{'experiment':<12}{'RMS x':>8}{'RMS y':>8}{'RMS z':>8}{'SS x':>8}{'SS y':>8}{'SS z':>8}"
        f"{'floors':>9}{'RTF':>7}"
    )
    for key, m in metrics.items():
        rms, ss = m["rms_error_N"], m["steady_state_error_N"]
        print(
            f"{key:<12}"
            + "".join(f"{rms[c]:>8.3f}" for c in COMPONENTS)
            + "".join(f"{ss[c]:>8.3f}" for c in COMPONENTS)
            + f"{'met' if m['meets_floors'] else 'MISSED':>9}{m['real_time_factor']:>7.2f}"
        )
    print(f"errors in N; floors: steady state (SS) <= {STEADY_STATE_FLOOR} N, RMS <= {RMS_FLOOR} N per component")


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        experiments = None
        if args.experiment is not None:
            experiments = list(EXPERIMENT_NUMBERS) if args.experiment == "all" else [int(args.experiment)]
        scenario = scenario_from_args(
            NaoForceObserverScenario,
            args,
            seed=args.seed,
            experiments=experiments,
            time_scale=args.time_scale,
            ramp=args.ramp,
        )
        schedules = scenario_experiments(scenario)  # every schedule checked before the first run
        out_dir = output_folder(args, EXPERIMENT)
        meshcat = replay_meshcat(not args.no_replay, args.headless)
        initial_state = settle_standing_state(scenario.posture(), plant_config=scenario.plant_config)
        metrics = {}
        for experiment in schedules:
            print(f"{experiment.title}: {experiment.duration:.1f} s simulated ...", flush=True)
            diagram, handles = build_experiment_diagram(scenario, experiment, meshcat)
            run = simulate(
                diagram,
                experiment.duration,
                set_initial_state=functools.partial(handles.set_initial_state, state=initial_state),
                simulator_config=scenario.simulator_config,
                meshcat=meshcat,
                live=not args.headless,
                camera=([0.9, -0.9, 0.6], [0.0, 0.0, 0.25]),
            )
            key = f"experiment_{experiment.number}"
            save_replay(meshcat, out_dir / f"{key}.html")
            signals = logged_signals(handles.loggers, run.context, "virtual_force")
            result = {"signals": signals, "handles": handles, "wall": run.wall_time_s}
            metrics[key] = experiment_metrics(experiment, result)
            plot_experiment(out_dir / f"{key}.png", experiment, result)
            m = metrics[key]
            print(
                f"  {m['wall_time_s']:.1f} s wall (real-time factor {m['real_time_factor']:.2f}); floors "
                f"{'met' if m['meets_floors'] else 'MISSED'}"
            )
        write_metrics(out_dir, {**metrics, "summary": experiments_summary(scenario, metrics)}, scenario, args)
        _print_table(metrics)
        print_written(out_dir)
        return 0

    return run_app(EXPERIMENT, body)


if __name__ == "__main__":
    raise SystemExit(main())
