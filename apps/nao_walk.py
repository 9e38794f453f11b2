"""The Nao-like robot walks straight on flat ground: ZMP preview control (Kajita 2003) on the
cart-table model, swing-foot trajectories and analytic leg IK give joint targets that the
station's joint PD tracks (position control, as on Nao). Issue 7, item 1.

Floors (issue 7): >= 20 steps and >= 1 m forward at a mean speed >= 0.08 m/s without falling.
Definitions (``diagrams.locomotion.nao_walk.walking_metrics``): distance = CoM x displacement over the
run; mean speed = CoM x displacement from the first step's start to one step after the last
touch-down, divided by that time; steps = touch-downs after lift-offs in the contact forces;
fall = base tilt > 30 deg or base height < 70 % of its initial value; ZMP in support = the
ZMP from the contact forces inside the convex hull of the contact spheres of the feet that
the plan has on the ground (at their actual poses).

Run: ``python -m apps.nao_walk [--steps N] [--step-length L] [--step-duration T]
[--double-support-ratio R] [--swing-height H] [--com-height Z] [--zmp-correction-passes K]
[--noise] [--seed S]
[--out DIR] [--headless] [--no-replay]``. Writes to DIR (default ``out/nao_walk``):
``metrics.json``, ``walk_top.png`` (top view: footprints, ZMP, CoM), ``walk_time.png``
(x / y of ZMP and CoM vs their references, foot normal forces, base tilt) and
``walk.html`` (self-contained Meshcat replay).
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
from diagrams.locomotion.nao_walk import build_nao_walk_diagram, walking_floors, walking_metrics  # noqa: E402
from systems.locomotion.walking_pattern import WalkingParameters  # noqa: E402


def simulate(params: WalkingParameters, *, noise: bool = False, seed: int = 0, meshcat: Meshcat | None = None,
             zmp_correction_passes: int = 1) -> dict:
    """Builds the walking diagram, runs the whole pattern, returns handles, context, metrics
    and wall time."""
    diagram, handles = build_nao_walk_diagram(params, noise=noise, seed=seed, meshcat=meshcat,
                                                 zmp_correction_passes=zmp_correction_passes)
    simulator = Simulator(diagram)
    handles.set_initial_state(simulator.get_mutable_context())
    if meshcat is not None:
        meshcat.SetCameraPose(camera_in_world=[0.6, -1.2, 0.6], target_in_world=[0.4, 0.0, 0.2])
        meshcat.StartRecording(frames_per_second=32.0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(handles.controller.duration)
    wall = time.perf_counter() - start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    metrics = walking_metrics(handles, simulator.get_context())
    return {"handles": handles, "context": simulator.get_context(), "metrics": metrics, "wall": wall}


def plot_top(path: Path, run: dict) -> None:
    """Top view: planned footprints (grey), the support polygons, ZMP (measured, reference),
    CoM (reference, actual)."""
    s = run["metrics"]["signals"]
    controller = run["handles"].controller
    humanoid = run["handles"].station.humanoid
    fig, ax = plt.subplots(figsize=(12, 4.2))
    fsr = {side: humanoid.fsr_positions[side] for side in ("left", "right")}
    order = [0, 1, 3, 2, 0]  # front_left, front_right, rear_right, rear_left
    prints = [(side, p) for side, p in (("left", controller.pattern.soles["left"][0]),
                                       ("right", controller.pattern.soles["right"][0]))]
    prints += [(step.side, step.end) for step in controller.pattern.steps]
    for side, p in prints:
        corners = fsr[side][order] + p[:2]
        ax.plot(corners[:, 0], corners[:, 1], color="0.6", lw=0.8)
    ax.plot(s["zmp"][:, 0], s["zmp"][:, 1], color="tab:red", lw=0.6, alpha=0.8, label="ZMP (contact forces)")
    ax.plot(s["zmp_reference"][:, 0], s["zmp_reference"][:, 1], "--", color="k", lw=0.8, label="ZMP reference")
    ax.plot(s["com_reference"][:, 0], s["com_reference"][:, 1], color="tab:green", lw=1.2, label="CoM reference")
    ax.plot(s["com"][:, 0], s["com"][:, 1], ":", color="tab:blue", lw=1.5, label="CoM (simulated)")
    ax.set_aspect("equal")
    ax.set_ylim(-0.16, 0.12)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7, loc="lower left", ncol=4)
    ax.set_title("nao_like walking: footprints (FSR polygons), ZMP and CoM", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _parse(argv):
    d = WalkingParameters()
    parser = argparse.ArgumentParser(prog="python -m apps.nao_walk", description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=d.num_steps, help=f"number of steps (default {d.num_steps})")
    parser.add_argument("--step-length", type=float, default=d.step_length, help=f"m (default {d.step_length})")
    parser.add_argument("--step-duration", type=float, default=d.step_duration, help=f"s (default {d.step_duration})")
    parser.add_argument("--double-support-ratio", type=float, default=d.double_support_ratio,
                        help=f"(default {d.double_support_ratio})")
    parser.add_argument("--swing-height", type=float, default=d.swing_height, help=f"m (default {d.swing_height})")
    parser.add_argument("--com-height", type=float, default=d.com_height, help=f"m (default {d.com_height})")
    parser.add_argument("--zmp-correction-passes", type=int, default=1,
                        help="passes of the multibody ZMP correction (Kajita 2003; 0 = cart-table only; default 1)")
    parser.add_argument("--noise", action="store_true", help="sensor noise on (the PD reads the noisy sensed state)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    parser.add_argument("--out", type=Path, default=Path("out") / "nao_walk", help="output folder (default out/nao_walk)")
    parser.add_argument("--headless", action="store_true", help="no live Meshcat URL (the replay is still written)")
    parser.add_argument("--no-replay", action="store_true", help="skip the Meshcat replay (faster)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    try:
        if args.seed < 0:
            raise ValueError(f"--seed must be non-negative, got {args.seed}")
        if args.zmp_correction_passes < 0:
            raise ValueError(f"--zmp-correction-passes must be >= 0, got {args.zmp_correction_passes}")
        params = WalkingParameters(num_steps=args.steps, step_length=args.step_length,
                                   step_duration=args.step_duration, double_support_ratio=args.double_support_ratio,
                                   swing_height=args.swing_height, com_height=args.com_height)
    except ValueError as error:
        print(f"nao_walk: error: {error}", file=sys.stderr)
        return 2
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    meshcat = replay_meshcat(not args.no_replay, args.headless)
    print(f"walking {params.num_steps} steps of {params.step_length} m, {params.step_duration} s each "
          f"({params.duration:.1f} s simulated) ...", flush=True)
    try:
        run = simulate(params, noise=args.noise, seed=args.seed, meshcat=meshcat,
                       zmp_correction_passes=args.zmp_correction_passes)
    except ValueError as error:  # unreachable steps, joint limits
        print(f"nao_walk: error: {error}", file=sys.stderr)
        return 2
    m = run["metrics"]
    if meshcat is not None:
        (out / "walk.html").write_text(meshcat.StaticHtml())
    plot_top(out / "walk_top.png", run)
    plot_walking_time(out / "walk_time.png", run)
    checks = walking_floors(m)
    summary = {k: v for k, v in m.items() if k != "signals"}
    summary.update({
        "floors": checks,
        "meets_floors": all(checks.values()),
        "wall_time_s": run["wall"],
        "real_time_factor": m["duration_s"] / run["wall"],
        "parameters": {k: getattr(params, k) for k in params.__dataclass_fields__},
        "zmp_correction_passes": args.zmp_correction_passes,
        "noise": args.noise,
        "seed": args.seed,
    })
    (out / "metrics.json").write_text(json.dumps(summary, indent=2))
    print(f"  distance {m['distance_m']:.3f} m, mean speed {m['mean_speed_mps']:.3f} m/s, steps "
          f"{m['steps_detected']}/{m['steps_planned']}, {'upright' if m['upright'] else 'FELL'} (max tilt "
          f"{m['max_base_tilt_deg']:.1f} deg), ZMP in support {100 * m['zmp_in_support_fraction']:.1f} % "
          f"(5th-percentile margin {1000 * m['zmp_margin_p05_m']:.1f} mm; in the loaded feet's polygon "
          f"{1000 * m['zmp_loaded_margin_p05_m']:.1f} mm)")
    print(f"  {run['wall']:.1f} s wall (real-time factor {summary['real_time_factor']:.2f}); floors "
          f"{'met' if summary['meets_floors'] else 'MISSED: ' + ', '.join(k for k, v in checks.items() if not v)}")
    print(f"wrote {out}: " + ", ".join(sorted(p.name for p in out.iterdir())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
