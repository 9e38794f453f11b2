"""Standing simulation of the humanoids under PD + gravity compensation.

Usage::

    python -m apps.standing [--model hrp4_like|nao_like|all] [--duration 10]
                         [--no-meshcat] [--out DIR]

For each model: simulates ``--duration`` seconds (1 ms discrete steps, SAP, point
contact), prints a table (base drift after the first second of settling, smallest foot
sphere normal force, feet flat, real-time factor), writes ``DIR/stand/<model>.json`` and,
with Meshcat on, a self-contained replay ``DIR/stand/<model>.html``. Exits with status 1
if a robot falls.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from diagrams.station.standing import build_standing_diagram, set_initial_state, standing_metrics
from models import MODEL_NAMES

SETTLE_TIME = 1.0  # s; drift is measured after this


def _parse(argv):
    parser = argparse.ArgumentParser(
        prog="python -m apps.standing", description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", choices=(*MODEL_NAMES, "all"), default="all",
                        help="which humanoid to simulate (default: all)")
    parser.add_argument("--duration", type=float, default=10.0,
                        help="simulated time per model, s (default: 10)")
    parser.add_argument("--no-meshcat", action="store_true",
                        help="do not start Meshcat (no live view, no HTML replay)")
    parser.add_argument("--out", type=Path, default=Path("out"),
                        help="output directory (default: out); files go to OUT/stand/")
    args = parser.parse_args(argv)
    if args.duration <= 0:
        parser.error("--duration must be positive")
    return args


def run_model(name: str, duration: float, meshcat, out_dir: Path) -> dict:
    """Simulates one model standing; returns its metrics as a dict."""
    if meshcat is not None:
        meshcat.Delete()
    diagram, handles = build_standing_diagram(name, meshcat=meshcat)
    if meshcat is not None:
        # A three-quarter view framing the robot (Meshcat's default camera is far away).
        height = 1.5 if name == "hrp4_like" else 0.57
        meshcat.SetCameraPose(
            camera_in_world=np.array([1.1, -1.1, 0.8]) * height, target_in_world=np.array([0.0, 0.0, 0.5 * height])
        )
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_initial_state(diagram, context, handles)
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=32.0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(duration)
    wall = time.perf_counter() - start
    metrics = standing_metrics(handles, context, settle_time=min(SETTLE_TIME, duration))
    row = dict(
        model=name,
        duration_s=duration,
        wall_s=wall,
        real_time_factor=duration / wall,
        base_drift_cm=100.0 * metrics.base_drift_m,
        base_drift_deg=float(np.degrees(metrics.base_drift_rad)),
        min_sphere_force_N=metrics.min_sphere_force_N,
        sole_tilt_deg={k: float(np.degrees(v)) for k, v in metrics.sole_tilt_rad.items()},
        sole_height_mm={k: 1000.0 * v for k, v in metrics.sole_height_m.items()},
        sphere_forces_N={k: v.tolist() for k, v in metrics.sphere_forces_N.items()},
        feet_flat=metrics.feet_flat,
        fell=metrics.fell,
    )
    (out_dir / f"{name}.json").write_text(json.dumps(row, indent=2) + "\n")
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        html = out_dir / f"{name}.html"
        html.write_text(meshcat.StaticHtml())
        row["replay"] = str(html)
    return row


def main(argv=None) -> int:
    """Runs the app; returns the process exit status (1 if a robot fell)."""
    args = _parse(argv)
    print("standing simulation of the humanoids (PD + gravity compensation)")
    names = MODEL_NAMES if args.model == "all" else (args.model,)
    out_dir = args.out / "stand"
    out_dir.mkdir(parents=True, exist_ok=True)
    meshcat = None
    if not args.no_meshcat:
        from pydrake.geometry import StartMeshcat

        meshcat = StartMeshcat()
        print(f"Meshcat: {meshcat.web_url()}")

    rows = []
    for name in names:
        print(f"simulating {name} for {args.duration:g} s ...", flush=True)
        rows.append(run_model(name, args.duration, meshcat, out_dir))

    header = (f"{'model':<10} {'drift cm':>9} {'drift deg':>9} {'min F N':>8} "
              f"{'feet flat':>9} {'RTF':>6} {'fell':>5}")
    print(f"\nbase drift measured after the first {SETTLE_TIME:g} s; "
          "min F = smallest foot-sphere normal force at the end")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['model']:<10} {r['base_drift_cm']:9.3f} {r['base_drift_deg']:9.3f} "
              f"{r['min_sphere_force_N']:8.2f} {str(r['feet_flat']):>9} "
              f"{r['real_time_factor']:6.2f} {str(r['fell']):>5}")
    for r in rows:
        if "replay" in r:
            print(f"replay: {r['replay']}")
    fell = [r["model"] for r in rows if r["fell"]]
    if fell:
        print(f"FELL: {', '.join(fell)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
