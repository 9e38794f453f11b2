"""Experiment 4 of Hawley et al. (2019), Sec. 6.3 (Figs. 9-11), in simulation: nao_like walks
forward, a cable tied to its waist tightens over a pulley, lifts a 0.3 kg mass and pulls the
robot backwards by ~3 N at ~5 deg from the x axis; the Kalman force observer (WALKING
preset, eq. 22) estimates the pull from the FSRs, IMU and encoders. Issue 7, item 2.

Floors (issue 7): walking >= 20 steps and >= 1 m forward at a mean speed >= 0.08 m/s
without falling WITH the pull (definitions: ``apps.nao_walk``); while the mass hangs and the
robot walks steadily (from 1 s after the load leaves the ground to the last planned
touch-down), the mean estimated F_x within 0.5 N of the true pull (the cable force's x
component, mean over the same samples) and the RMS error (sample by sample) <= 1.5 N. The
virtual force of eq. 11 (what the LIP observer estimates by construction) is reported too.

Run: ``python -m apps.nao_walk_pulled [--steps N] [--seed S] [--no-noise]
[--no-pull] [--out DIR] [--headless] [--no-replay]``. Writes to DIR (default
``out/nao_walk_pulled``): ``metrics.json`` (walking and observer metrics, floors),
``force_xy.png`` / ``force_z.png`` (Fig. 10 a/b: estimated F_x, F_y, F_z vs the pull and the
virtual force), ``normal_force.png`` (Fig. 11: f_n^o), ``load.png`` (tension and load
height), ``walk_time.png`` (ZMP/CoM, foot forces, tilt/yaw) and ``walk_pulled.html``
(self-contained Meshcat replay: the robot, the cable force in red, the estimate in blue).
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
from pydrake.geometry import Meshcat  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402

from apps.common import plot_walking_time, replay_meshcat  # noqa: E402
from diagrams.observer.nao_walk_pulled import CableSetup, build_nao_walk_pulled_diagram, observer_metrics  # noqa: E402
from diagrams.locomotion.nao_walk import walking_floors, walking_metrics  # noqa: E402
from systems.locomotion.walking_pattern import WalkingParameters  # noqa: E402

#: Floors of issue 7, Exp. 4.
MAX_MEAN_ERROR_X = 0.5  # N
MAX_RMS_ERROR_X = 1.5  # N


def simulate(params: WalkingParameters, setup: CableSetup | None = None, *, pull: bool = True,
             noise: bool = True, seed: int = 0, meshcat: Meshcat | None = None) -> dict:
    """Builds the diagram, runs the whole pattern, returns handles, context, metrics, wall time."""
    diagram, handles = build_nao_walk_pulled_diagram(params, setup, pull=pull, noise=noise,
                                                     seed=seed, meshcat=meshcat)
    simulator = Simulator(diagram)
    handles.set_initial_state(simulator.get_mutable_context())
    if meshcat is not None:
        meshcat.SetCameraPose(camera_in_world=[0.2, -1.6, 0.7], target_in_world=[0.2, 0.0, 0.2])
        if handles.cable is not None:  # the pulley and the line's fixed run (drawn once)
            from pydrake.geometry import Rgba, Sphere
            from pydrake.math import RigidTransform
            meshcat.SetObject("pulley", Sphere(0.02), Rgba(0.2, 0.2, 0.2, 1.0))
            meshcat.SetTransform("pulley", RigidTransform(handles.cable.pulley))
        meshcat.StartRecording(frames_per_second=32.0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(handles.controller.duration)
    wall = time.perf_counter() - start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    context = simulator.get_context()
    return {"handles": handles, "context": context, "walking": walking_metrics(handles, context),
            "observer": observer_metrics(handles, context), "wall": wall}


def floors(run: dict, pull: bool = True) -> dict:
    """The issue's floors, each True/False (the Exp. 4 ones only with the pull)."""
    checks = {k + "_with_pull" if pull else k: v for k, v in walking_floors(run["walking"]).items()}
    o = run["observer"]
    if pull:
        ok = o.get("window_samples", 0) > 0
        checks["mean_Fx_error_le_0.5N"] = bool(ok and abs(o["mean_error_x_N"]) <= MAX_MEAN_ERROR_X)
        checks["rms_Fx_error_le_1.5N"] = bool(ok and o["rms_error_x_N"] <= MAX_RMS_ERROR_X)
    return checks


def _shade(ax, o: dict) -> None:
    s = o["signals"]
    window = o["window_mask"]
    if window.any():
        t = s["t"]
        ax.axvspan(t[window][0], t[window][-1], color="tab:green", alpha=0.07, lw=0)


def plot_forces(out: Path, run: dict) -> None:
    """Fig. 10 (a) F_x, F_y and (b) F_z: estimate vs the cable pull and eq. 11's virtual force."""
    o = run["observer"]
    s = o["signals"]
    t = s["t"]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for i, (ax, axis) in enumerate(zip(axes, "xy")):
        ax.plot(t, s["estimate"][:, i], color="tab:blue", lw=0.8, label=f"estimated $F_{axis}$")
        ax.plot(t, s["pull"][:, i], "--", color="tab:green", lw=1.2, label=f"cable pull $F_{axis}$ (truth)")
        ax.plot(t, s["virtual_truth"][:, i], ":", color="k", lw=0.8, label="virtual force (eq. 11)")
        ax.set_ylabel(f"$F_{axis}$ [N]")
        ax.grid(True, alpha=0.3)
        _shade(ax, o)
    axes[0].legend(fontsize=7, ncol=3)
    axes[0].set_title("Exp. 4: walking while pulled (shaded: evaluation window, load hanging)", fontsize=10)
    axes[1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(out / "force_xy.png", dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(t, s["estimate"][:, 2], color="tab:blue", lw=0.8, label="estimated $F_z$")
    ax.plot(t, s["pull"][:, 2], "--", color="tab:green", lw=1.2, label="cable pull $F_z$ (truth)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("$F_z$ [N]")
    ax.grid(True, alpha=0.3)
    _shade(ax, o)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "force_z.png", dpi=110)
    plt.close(fig)


def plot_normal_force(out: Path, run: dict) -> None:
    """Fig. 11: f_n^o = -(sum of the 8 FSR readings)."""
    o = run["observer"]
    s = o["signals"]
    mass = run["handles"].parameters.mass
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(s["t"], s["normal_force"], color="tab:purple", lw=0.8, label="$f_n^o$ (FSRs)")
    ax.axhline(-mass * 9.81, color="k", ls="--", lw=0.8, label="$-M g$")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("normal force [N]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "normal_force.png", dpi=110)
    plt.close(fig)


def plot_load(out: Path, run: dict) -> None:
    s = run["observer"]["signals"]
    if "tension" not in s:
        return
    fig, axes = plt.subplots(2, 1, figsize=(10, 4.5), sharex=True)
    axes[0].plot(s["t"], s["tension"], color="tab:red", lw=0.8)
    axes[0].set_ylabel("tension [N]")
    axes[1].plot(s["t"], s["load_height"], color="tab:brown", lw=0.8)
    axes[1].set_ylabel("load height [m]")
    axes[1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "load.png", dpi=110)
    plt.close(fig)


def _parse(argv):
    d = WalkingParameters()
    parser = argparse.ArgumentParser(prog="python -m apps.nao_walk_pulled", description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=d.num_steps, help=f"number of steps (default {d.num_steps})")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    parser.add_argument("--no-noise", action="store_true", help="ideal sensors (default: the sensors' noise on)")
    parser.add_argument("--no-pull", action="store_true", help="walk without the cable (observer bias while walking)")
    parser.add_argument("--tighten-distance", type=float, default=None,
                        help="torso travel before the line is taut, m (default: CableSetup's, scaled to --steps)")
    parser.add_argument("--out", type=Path, default=Path("out") / "nao_walk_pulled",
                        help="output folder (default out/nao_walk_pulled)")
    parser.add_argument("--headless", action="store_true", help="no live Meshcat URL (the replay is still written)")
    parser.add_argument("--no-replay", action="store_true", help="skip the Meshcat replay (faster)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    pull = not args.no_pull
    try:
        if args.seed < 0:
            raise ValueError(f"--seed must be non-negative, got {args.seed}")
        params = WalkingParameters(num_steps=args.steps)
        default = CableSetup()
        if args.tighten_distance is not None:
            tighten = args.tighten_distance
        else:  # keep the default's share of the walk before the line is taut
            tighten = default.tighten_distance * (args.steps - 1) / (WalkingParameters().num_steps - 1)
        setup = CableSetup(tighten_distance=tighten)
    except ValueError as error:
        print(f"nao_walk_pulled: error: {error}", file=sys.stderr)
        return 2
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    meshcat = replay_meshcat(not args.no_replay, args.headless)
    print(f"walking {params.num_steps} steps of {params.step_length} m ({params.duration:.1f} s simulated)"
          f"{' pulled by a 0.3 kg load over a pulley' if pull else ' without the cable'} ...", flush=True)
    try:
        run = simulate(params, setup, pull=pull, noise=not args.no_noise, seed=args.seed,
                       meshcat=meshcat)
    except ValueError as error:
        print(f"nao_walk_pulled: error: {error}", file=sys.stderr)
        return 2
    if meshcat is not None:
        (out / "walk_pulled.html").write_text(meshcat.StaticHtml())
    plot_forces(out, run)
    plot_normal_force(out, run)
    plot_load(out, run)
    plot_walking_time(out / "walk_time.png", {"metrics": run["walking"]})
    checks = floors(run, pull)
    h = run["handles"]
    w = {k: v for k, v in run["walking"].items() if k != "signals"}
    o = {k: v for k, v in run["observer"].items() if k not in ("signals", "window_mask")}
    summary = {
        "walking": w,
        "observer": o,
        "floors": checks,
        "meets_floors": all(checks.values()),
        "cable": ({"pulley_world_m": h.cable.pulley.tolist(), "natural_length_m": h.slack_length,
                   "planned_tighten_time_s": h.planned_tighten_time, "planned_lift_time_s": h.planned_lift_time,
                   **{k: getattr(h.setup, k) for k in h.setup.__dataclass_fields__}} if h.cable is not None else None),
        "observer_parameters": {"mass": h.parameters.mass, "period": h.parameters.period,
                                "jerk_variance": h.parameters.jerk_variance,
                                "force_rate_variance": h.parameters.force_rate_variance,
                                "R_z": h.parameters.R_z, "R_xy": h.parameters.R_xy, "preset": "WALKING (eq. 22)"},
        "frame": "F0: world-aligned, origin at the right sole at t = 0 (fixed for the run)",
        "noise": not args.no_noise,
        "seed": args.seed,
        "wall_time_s": run["wall"],
        "real_time_factor": w["duration_s"] / run["wall"],
        "walking_parameters": {k: getattr(params, k) for k in params.__dataclass_fields__},
    }
    (out / "metrics.json").write_text(json.dumps(summary, indent=2))
    print(f"  walk: {w['steps_detected']}/{w['steps_planned']} steps, {w['distance_m']:.3f} m, mean speed "
          f"{w['mean_speed_mps']:.3f} m/s, {'upright' if w['upright'] else 'FELL'} (max tilt "
          f"{w['max_base_tilt_deg']:.1f} deg, max |yaw| {w['max_abs_yaw_deg']:.1f} deg)")
    if pull and o.get("window_samples", 0):
        print(f"  load lifted at {o['measured_lift_time_s']:.2f} s (up to {o['max_load_height_m']:.3f} m); window "
              f"{o['window_s'][0]:.2f}-{o['window_s'][1]:.2f} s: pull F_x {o['true_pull_x_mean_N']:.3f} N "
              f"(virtual {o['true_virtual_x_mean_N']:.3f} N), estimated {o['estimated_x_mean_N']:.3f} N "
              f"(mean error {o['mean_error_x_N']:+.3f} N, RMS {o['rms_error_x_N']:.3f} N); F_y "
              f"{o['true_pull_y_mean_N']:.3f} vs {o['estimated_y_mean_N']:.3f} N; F_z {o['true_pull_z_mean_N']:.3f} "
              f"vs {o['estimated_z_mean_N']:.3f} N")
    print(f"  {run['wall']:.1f} s wall (real-time factor {summary['real_time_factor']:.2f}); floors "
          f"{'met' if summary['meets_floors'] else 'MISSED: ' + ', '.join(k for k, v in checks.items() if not v)}")
    print(f"wrote {out}: " + ", ".join(sorted(p.name for p in out.iterdir())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
