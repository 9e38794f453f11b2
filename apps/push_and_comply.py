"""Push and comply: Flacco et al. (2016), Sec. IV, Figs. 5-6. The main job (`make demo`).

HRP-4-like stands still; from t = 5 s two downward forces push both shoulders (polynomial
profile peaking at 8.5 s, gone at 12 s). A joint admittance controller (eq. 14) driven by a
residual moves the joints in the direction of the effort the residual sees. The scenario
runs twice: with the classical residual (eq. 7: it only feels the chest) and with the
internal residual (eq. 11: it feels the legs too, and the robot bends as if sitting down).

By default it runs in the realistic world (``diagrams.station.config``: the invariant
EKF's base state, realistic sensor, friction and model imperfections, the model refined
from a calibration motion first, cached in ``DIR/calibration_cache/``); ``--ideal`` runs it
in the ideal world. The admittance keeps both soles and the centre of mass still
(``closed_chain_projection``, ``hold_center_of_mass``).

Run: ``python -m apps.push_and_comply [--headless] [--out DIR] [--scenario FILE] [--scenario-text YAML]
[--seed N] [--ideal]``.
Writes to ``DIR/push_and_comply/``: ``internal.html`` and ``classical.html`` (self-contained
Meshcat replays: red spheres at the joints grow with the residual's effort, red arrows are
the pushes), ``joint_trajectories.png``, ``residual_vs_true_effort.png`` and
``metrics.json``, and prints a table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from apps.runner import (
    calibration_cache_folder,
    experiment_parser,
    logged_signals,
    memory_allocator,
    output_folder,
    print_written,
    replay_meshcat,
    run_app,
    save_replay,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.residuals.model_refinement import refined_model
from diagrams.residuals.push_and_comply import (
    RESIDUAL_KINDS,
    PushAndComplyScenario,
    build_push_and_comply_diagram,
    push_and_comply_metrics,
)
from systems.estimation.model_identification import ModelCorrections

#: Joints plotted (the paper's Figs. 5-6 discuss knees, hips, ankles and chest pitch).


def plotted_joints(humanoid) -> dict[str, tuple[str, ...]]:
    """The joints the plots show, by role: both knees, both hip pitches (each six-joint
    leg's third joint), both ankle pitches, the first torso joint (on hrp4_like: R/L_KNEE_P,
    R/L_HIP_P, R/L_ANKLE_P, CHEST_P)."""
    groups = humanoid.joint_groups
    legs = [groups[f"{side}_leg"] for side in ("right", "left") if len(groups[f"{side}_leg"]) == 6]
    return {
        "knees": tuple(leg[3] for leg in legs),
        "hips": tuple(leg[2] for leg in legs),
        "ankles": tuple(leg[4] for leg in legs),
        "torso": tuple(groups["torso"][:1]),
    }


def _parse(argv):
    parser = experiment_parser("apps.push_and_comply", __doc__, replay=False, conditions=True, robot=True)
    parser.add_argument("--seed", type=int, default=None, help="sensor noise seed (overrides the scenario's)")
    parser.add_argument(
        "--runs", nargs="+", choices=RESIDUAL_KINDS, default=list(RESIDUAL_KINDS), help=argparse.SUPPRESS
    )
    return parser.parse_args(argv)


def run_once(
    scenario: PushAndComplyScenario,
    kind: str,
    meshcat,
    *,
    progress: bool = True,
    live: bool = True,
    model_corrections: ModelCorrections | None = None,
) -> dict:
    """One closed loop with the ``kind`` residual: its logged signals, handles and metrics.
    With ``meshcat`` the run is recorded for the replay (and shown live when ``live``);
    ``model_corrections``: the refined model (``refined_model``)."""
    diagram, handles = build_push_and_comply_diagram(scenario, kind, meshcat, model_corrections=model_corrections)
    run = simulate(
        diagram,
        scenario.duration,
        set_initial_state=handles.station.set_initial_state,
        simulator_config=scenario.simulator_config,
        meshcat=meshcat,
        live=live,
        camera=([1.6, -1.6, 1.2], [0.0, 0.0, 0.7]),
        label=kind if progress else None,
    )
    signals = logged_signals(handles.loggers, run.context, "state")
    metrics = push_and_comply_metrics(scenario, handles, signals, run.wall_time_s)
    return {"signals": signals, "handles": handles, "wall": run.wall_time_s, "metrics": metrics}


def _plot(out_dir: Path, scenario: PushAndComplyScenario, runs: dict) -> None:
    kinds = list(runs)
    fig, axes = plt.subplots(1, len(kinds), figsize=(6 * len(kinds), 4), sharey=True, squeeze=False)
    for ax, kind in zip(axes[0], kinds):
        station, s = runs[kind]["handles"].station, runs[kind]["signals"]
        names = station.joint_names
        for name in [n for joints in plotted_joints(station.humanoid).values() for n in joints]:
            if name in names:
                joint = station.topology.joints[names.index(name)]
                q = s["state"][joint.position_start()]
                ax.plot(s["t"], np.degrees(q - q[0]), label=name)
        ax.axvspan(scenario.push_start, scenario.push_end, color="0.9")
        ax.set_title(f"{kind} residual: joint displacement")
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("displacement from start [deg]")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / "joint_trajectories.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(2, len(kinds), figsize=(6 * len(kinds), 6), sharex=True, squeeze=False)
    for col, kind in enumerate(kinds):
        station, s = runs[kind]["handles"].station, runs[kind]["signals"]
        names = list(station.joint_names)
        offset = 6 if kind == "classical" else 0
        roles = plotted_joints(station.humanoid)
        for row, group in enumerate((roles["knees"], roles["torso"] + roles["hips"][:1])):
            ax = axes[row][col]
            for name in group:
                if name in names:
                    k = names.index(name)
                    (line,) = ax.plot(s["t"], s["residual"][offset + k], label=f"{name} residual")
                    ax.plot(s["t"], s["tau_c_real"][k], "--", color=line.get_color(), label=f"{name} true")
            ax.set_ylabel("joint effort [N m]")
            ax.legend(fontsize=7)
            ax.grid(True, alpha=0.3)
        axes[0][col].set_title(f"{kind} residual (solid) vs true effort tau_c,real (dashed)")
        axes[1][col].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(out_dir / "residual_vs_true_effort.png", dpi=110)
    plt.close(fig)


def _print_table(metrics: dict) -> None:
    kinds = list(metrics)
    rows = [
        ("knee pitch flexion (smaller knee) [deg]", "knee_pitch_flexion_deg", "{:.2f}"),
        ("joints moved > 1 deg", "joints_moved_over_1deg", "{:d}"),
        ("CoM height drop [cm]", "com_height_drop_m", "{:.2f}", 100.0),
        ("pelvis height drop [cm]", "pelvis_height_drop_m", "{:.2f}", 100.0),
        ("max foot slip [mm]", "max_foot_slip_m", "{:.2f}", 1000.0),
        ("upright", "upright", "{}"),
        ("real-time factor", "real_time_factor", "{:.2f}"),
    ]
    print(f"{'':42s}" + "".join(f"{k:>12s}" for k in kinds))
    for label, key, fmt, *scale in rows:
        cells = []
        for kind in kinds:
            value = metrics[kind][key]
            if scale:
                value = value * scale[0]
            cells.append(fmt.format(value))
        print(f"{label:42s}" + "".join(f"{c:>12s}" for c in cells))
    for label, key in (
        ("knee dead band [N m]", "knee_dead_band_N_m"),
        ("push's knee effort, peak [N m]", "knee_push_effort_N_m"),
    ):
        cells = [max(metrics[kind][key].values(), default=float("nan")) for kind in kinds]
        print(f"{label:42s}" + "".join(f"{c:>12.3f}" for c in cells))
    print("largest joint displacements [deg]:")
    for kind in kinds:
        top = sorted(metrics[kind]["max_joint_displacement_deg"].items(), key=lambda item: -item[1])[:8]
        print(f"  {kind:9s} " + ", ".join(f"{name} {value:.1f}" for name, value in top))


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        scenario = scenario_from_args(PushAndComplyScenario, args, seed=args.seed)
        # A bad model, joint group or push schedule fails here, before the calibration (0.3 s).
        build_push_and_comply_diagram(scenario, args.runs[0])
        out_dir = output_folder(args, "push_and_comply")
        corrections = refined_model(scenario, calibration_cache_folder(args))
        meshcat = replay_meshcat(True, args.headless)
        print(
            f"push and comply: {scenario.station.model}, {scenario.push_peak_force:g} N"
            f"{' (on hrp4_like; scaled to the robot: see the table)' if scenario.scale_to_robot else ''} down on each "
            "shoulder from "
            f"{scenario.push_start:g} s (peak {scenario.push_peak_time:g} s, off {scenario.push_end:g} s), "
            f"{scenario.duration:g} s"
        )
        runs, metrics = {}, {}
        for kind in args.runs:
            runs[kind] = run_once(scenario, kind, meshcat, live=not args.headless, model_corrections=corrections)
            save_replay(meshcat, out_dir / f"{kind}.html")
            metrics[kind] = runs[kind]["metrics"]
        _plot(out_dir, scenario, runs)
        write_metrics(out_dir, metrics, scenario, args)
        _print_table(metrics)
        print(f"push peak force on this robot: {next(iter(metrics.values()))['push_peak_force_N']:.1f} N per shoulder")
        print(f"memory allocator: {memory_allocator()} (make preloads tcmalloc when installed; see BENCHMARKS.md)")
        print_written(out_dir)
        return 0

    return run_app("push_and_comply", body)


if __name__ == "__main__":
    raise SystemExit(main())
