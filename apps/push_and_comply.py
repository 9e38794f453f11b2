"""Push and comply: Flacco et al. (2016), Sec. IV, Figs. 5-6. The main job (`make demo`).

HRP-4-like stands still; from t = 5 s two downward forces push both shoulders (polynomial
profile peaking at 8.5 s, gone at 12 s). A joint admittance controller (eq. 14) driven by a
residual moves the joints in the direction of the effort the residual sees. The scenario
runs twice: with the classical residual (eq. 7: it only feels the chest) and with the
internal residual (eq. 11: it feels the legs too, and the robot bends as if sitting down).

Run: ``python -m apps.push_and_comply [--headless] [--out DIR] [--scenario FILE] [--seed N]``.
Writes to ``DIR/push_and_comply/``: ``internal.html`` and ``classical.html`` (self-contained
Meshcat replays: red spheres at the joints grow with the residual's effort, red arrows are
the pushes), ``joint_trajectories.png``, ``residual_vs_true_effort.png`` and
``metrics.json``, and prints a table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from pydrake.geometry import Meshcat  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402

from apps.common import logged_signals, memory_allocator  # noqa: E402
from diagrams.residuals.push_and_comply import (  # noqa: E402
    RESIDUAL_KINDS,
    PushAndComplyScenario,
    build_push_and_comply_diagram,
    load_scenario,
)

#: Joints plotted (the paper's Figs. 5-6 discuss knees, hips, ankles and chest pitch).
PLOTTED_JOINTS = ("R_KNEE_P", "L_KNEE_P", "R_HIP_P", "L_HIP_P", "R_ANKLE_P", "L_ANKLE_P", "CHEST_P")
#: A run counts as upright while the pelvis keeps this fraction of its height and tilts less.
UPRIGHT_HEIGHT_FRACTION = 0.7
UPRIGHT_MAX_TILT_DEG = 30.0


def _parse(argv):
    parser = argparse.ArgumentParser(prog="python -m apps.push_and_comply", description=__doc__.split("\n\n")[0])
    parser.add_argument("--headless", action="store_true", help="no live Meshcat URL (the replays are still written)")
    parser.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out)")
    parser.add_argument("--scenario", type=Path, default=None, help="YAML scenario (default: the built-in one)")
    parser.add_argument("--seed", type=int, default=None, help="sensor noise seed (overrides the scenario's)")
    parser.add_argument("--runs", nargs="+", choices=RESIDUAL_KINDS, default=list(RESIDUAL_KINDS), help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def simulate(
    scenario: PushAndComplyScenario, kind: str, meshcat: Meshcat | None, *, progress: bool = True, live: bool = True
) -> dict:
    """Runs one closed loop; returns the logged signals and the wall time. With ``meshcat``
    the run is recorded for the replay, and shown live too when ``live`` (a headless run
    records without sending each frame to the live view)."""
    if meshcat is not None:
        meshcat.Delete()
        meshcat.DeleteRecording()
    diagram, handles = build_push_and_comply_diagram(scenario, kind, meshcat)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.station.set_initial_state(context)
    if meshcat is not None:
        meshcat.SetCameraPose(camera_in_world=[1.6, -1.6, 1.2], target_in_world=[0.0, 0.0, 0.7])
        meshcat.StartRecording(frames_per_second=32.0, set_visualizations_while_recording=live)
    simulator.Initialize()
    start = time.perf_counter()
    t, step = 0.0, 0.5
    while t < scenario.duration - 1e-9:
        t = min(t + step, scenario.duration)
        simulator.AdvanceTo(t)
        if progress:
            print(f"\r  {kind:9s} {t:5.1f} / {scenario.duration:.1f} s simulated", end="", flush=True)
    wall = time.perf_counter() - start
    if progress:
        print(f"  ({wall:.1f} s wall, real-time factor {scenario.duration / wall:.2f})")
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    signals = logged_signals(handles.loggers, context, "state")
    return {"signals": signals, "handles": handles, "wall": wall}


def run_metrics(scenario: PushAndComplyScenario, run: dict) -> dict:
    """The metrics of one run (see the module docstring of the README)."""
    handles, s = run["handles"], run["signals"]
    station = handles.station
    plant, humanoid = station.plant, station.humanoid
    t, x = s["t"], s["state"]
    names = station.joint_names
    q = np.array([x[j.position_start()] for j in station.topology.joints])
    reference = int(np.searchsorted(t, scenario.push_start))  # posture when the push begins
    displacement = q - q[:, [reference]]
    max_displacement_deg = {n: float(np.degrees(np.abs(displacement[k, reference:]).max())) for k, n in enumerate(names)}
    knees = [n for n in names if "KNEE" in n.upper()]
    flexion = {n: float(np.degrees(displacement[names.index(n), reference:].max())) for n in knees}

    context = plant.CreateDefaultContext()
    com_z, pelvis_z, tilt_deg, soles = [], [], [], {side: [] for side in humanoid.sole_frames}
    for k in range(reference, x.shape[1]):
        plant.SetPositionsAndVelocities(context, x[:, k])
        com_z.append(plant.CalcCenterOfMassPositionInWorld(context)[2])
        X_WB = humanoid.base_body.EvalPoseInWorld(context)
        pelvis_z.append(X_WB.translation()[2])
        tilt_deg.append(np.degrees(np.arccos(np.clip(X_WB.rotation().matrix()[2, 2], -1.0, 1.0))))
        for side, frame in humanoid.sole_frames.items():
            soles[side].append(frame.CalcPoseInWorld(context).translation())
    com_z, pelvis_z = np.array(com_z), np.array(pelvis_z)
    slip = {side: float(np.linalg.norm(np.array(p)[:, :2] - np.array(p)[0, :2], axis=1).max()) for side, p in soles.items()}
    upright = bool(pelvis_z.min() > UPRIGHT_HEIGHT_FRACTION * pelvis_z[0] and max(tilt_deg) < UPRIGHT_MAX_TILT_DEG)
    return {
        "residual": handles.residual_kind,
        "knee_pitch_flexion_deg": min(flexion.values()) if flexion else None,
        "knee_pitch_flexion_per_knee_deg": flexion,
        "joints_moved_over_1deg": int(sum(v > 1.0 for v in max_displacement_deg.values())),
        "com_height_drop_m": float(com_z[0] - com_z.min()),
        "pelvis_height_drop_m": float(pelvis_z[0] - pelvis_z.min()),
        "max_foot_slip_m": max(slip.values()),
        "foot_slip_m": slip,
        "max_base_tilt_deg": float(max(tilt_deg)),
        "upright": upright,
        "real_time_factor": scenario.duration / run["wall"],
        "wall_time_s": run["wall"],
        "max_joint_displacement_deg": max_displacement_deg,
    }


def _plot(out_dir: Path, scenario: PushAndComplyScenario, runs: dict) -> None:
    kinds = list(runs)
    fig, axes = plt.subplots(1, len(kinds), figsize=(6 * len(kinds), 4), sharey=True, squeeze=False)
    for ax, kind in zip(axes[0], kinds):
        station, s = runs[kind]["handles"].station, runs[kind]["signals"]
        names = station.joint_names
        for name in PLOTTED_JOINTS:
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
        for row, group in enumerate((("R_KNEE_P", "L_KNEE_P"), ("CHEST_P", "R_HIP_P"))):
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
    print("largest joint displacements [deg]:")
    for kind in kinds:
        top = sorted(metrics[kind]["max_joint_displacement_deg"].items(), key=lambda item: -item[1])[:8]
        print(f"  {kind:9s} " + ", ".join(f"{name} {value:.1f}" for name, value in top))


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    try:
        scenario = load_scenario(args.scenario)
    except ValueError as error:
        print(f"push_and_comply: error: {error}", file=sys.stderr)
        return 2
    if args.seed is not None:
        scenario.seed = args.seed
    out_dir = args.out / "push_and_comply"
    out_dir.mkdir(parents=True, exist_ok=True)
    meshcat = Meshcat()
    if not args.headless:
        print(f"Meshcat (live view): {meshcat.web_url()}")
    print(
        f"push and comply: {scenario.model}, {scenario.push_peak_force:g} N down on each shoulder from "
        f"{scenario.push_start:g} s (peak {scenario.push_peak_time:g} s, off {scenario.push_end:g} s), {scenario.duration:g} s"
    )
    runs, metrics = {}, {}
    try:
        for kind in args.runs:
            runs[kind] = simulate(scenario, kind, meshcat, live=not args.headless)
            (out_dir / f"{kind}.html").write_text(meshcat.StaticHtml())
            metrics[kind] = run_metrics(scenario, runs[kind])
    except ValueError as error:
        print(f"\npush_and_comply: error: {error}", file=sys.stderr)
        return 2
    _plot(out_dir, scenario, runs)
    metrics["scenario"] = {k: v for k, v in vars(scenario).items()}
    metrics["memory_allocator"] = memory_allocator()
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2))
    _print_table({k: v for k, v in metrics.items() if k in RESIDUAL_KINDS})
    print(f"memory allocator: {metrics['memory_allocator']} (make preloads tcmalloc when installed; see BENCHMARKS.md)")
    print(f"wrote {out_dir}: " + ", ".join(sorted(p.name for p in out_dir.iterdir())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
