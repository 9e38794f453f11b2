"""How the studies scale (issue 35): the same contact study on a process pool and on Ray, one
and two workers here, the driver's cost per trial, and a model of a sweep on N nodes.

1. **The same study on each engine.** ``apps.contact_localization`` with ``--trials N``
   (default 200) and otherwise its defaults (the realistic world, its calibration, the runs
   without contact, the one-or-two-contact fits), headless, without replays: on Ray with 2
   workers, on the pool with 2 workers, and in this process (one worker). The model is
   calibrated once before (``refined_model``, cached), so that each run times the same
   jobs. Per run: the wall time and its phases (``metrics.json``), and whether the per-trial
   results are the same as the pool's (they must be: the engine changes where jobs run,
   not what they compute).
2. **The driver's cost per trial.** Ray's round trip of a job that does nothing
   (``apps.engine.worker_info``, 2 actors, ``--driver-jobs`` jobs), and the time to write a
   sweep chunk's Parquet file of ``trials_per_job`` rows (``apps.sweep.write_chunk``): what
   the driver spends per trial, so how many trials per second one driver can absorb.
3. **A model of N nodes.** A sweep's wall time on N nodes of c workers each is about
   ``startup + C t_cal / W + T t_trial / W`` with W = N c workers (C calibrations of t_cal
   each, T trials of t_trial each, both measured here: t_trial from the one-worker run's
   trial phase), as long as the driver keeps up (T / wall below what it absorbs) and each
   worker has several jobs (the last wave of jobs rounds the time up: at most one chunk's
   or one calibration's time more). Written for the issue's sweep (6 robots x 5
   imperfection draws x 3 noise levels x 1000 trials: 90 cells, 90,000 trials) at 8 and
   64 nodes of this machine's size.

Run: ``python -m apps.engine_scaling [--trials N] [--results NAME] [--out DIR]``: prints the
tables and writes ``results/NAME.json`` (default ``engine_scaling``; docs/sweeps.md quotes it).
About 15 min on an idle 2-core machine; run it on an idle machine.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from apps.engine import choose_engine, open_engine, worker_info
from apps.results import app_command, write_results
from apps.runner import positive_int, results_name

ROOT = Path(__file__).resolve().parents[1]
#: The issue's sweep: robots x imperfection draws x noise levels, and trials per cell.
SWEEP_CELLS, SWEEP_TRIALS_PER_CELL = 6 * 5 * 3, 1000
#: The node counts the model is written for, and the workers per node (this machine's cores).
MODEL_NODES = (1, 8, 64)
#: Per-trial result fields that are timings (they differ between runs of the same trials).
TIMING_FIELDS = ("simulation_wall_s", "localizer_update_s")


def _run_study(engine: str, workers: int, trials: int, seed: int, out: Path, extra: list[str]) -> dict:
    """Runs the contact study in a fresh process (with the options ``extra``); its metrics.json."""
    command = [
        sys.executable,
        "-m",
        "apps.contact_localization",
        "--trials",
        str(trials),
        "--seed",
        str(seed),
        "--engine",
        engine,
        "--workers",
        str(workers),
        "--replays",
        "0",
        "--headless",
        "--out",
        str(out),
        *extra,
    ]
    start = time.perf_counter()
    run = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if run.returncode != 0:
        raise RuntimeError(f"the study on {engine} failed ({run.returncode}): {run.stderr[-3000:]}")
    metrics = json.loads((out / "contact_localization" / "metrics.json").read_text())
    metrics["process_wall_s"] = wall
    return metrics


def _comparable(metrics: dict) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_FIELDS} for r in metrics["per_trial"]]


def _driver_costs(jobs: int, trials_per_job: int) -> dict:
    """Ray's round trip of an empty job (s) with 2 actors, and the write of one chunk (s)."""
    from diagrams.residuals.contact_sweep import SweepCell, write_chunk

    with open_engine(choose_engine("ray", 2)) as engine:
        list(engine.imap_unordered(worker_info, range(2 * engine.workers)))  # warm
        start = time.perf_counter()
        count = sum(1 for _ in engine.imap_unordered(worker_info, range(jobs)))
        round_trip = (time.perf_counter() - start) / count
    cell = SweepCell("hrp4_like", 0, 1.0, 1.0, 1, 0.5)
    row = {
        **cell.as_row(),
        "chunk": 0,
        "trial": 0,
        "seed": 0,
        "trial_of_seed": 0,
        "body": "L_ELBOW_P_LINK",
        "bodies": ["L_ELBOW_P_LINK"],
        "geometry": "g",
        "force_N": 20.0,
        "force_world": [0.0, 0.0, 20.0],
        "point_body": [0.0, 0.0, 0.0],
        "detected": True,
        "detection_delay_s": 0.01,
        "detector_on_at_push_start": False,
        "false_detections_before_push": 0,
        "status": "0",
        "estimated_body": "L_ELBOW_P_LINK",
        "correct_link": True,
        "link_among_pushed": True,
        "position_error_m": 0.01,
        "force_error_rel": 0.05,
        "angle_error_deg": 2.0,
        "sole_slip_m": 0.0,
        "sole_slipped": False,
        "simulation_wall_s": 1.0,
        "localizer_update_s": 1e-4,
        "worker": "host:1",
    }
    with tempfile.TemporaryDirectory() as folder:
        (Path(folder) / "trials").mkdir()
        repeats = 50
        start = time.perf_counter()
        for k in range(repeats):
            write_chunk(Path(folder), cell.key, k, [{**row, "trial": i} for i in range(trials_per_job)])
        write = (time.perf_counter() - start) / repeats
    return {"ray_round_trip_s": round_trip, "chunk_write_s": write, "trials_per_job": trials_per_job}


def sweep_model(
    trial_s: float,
    calibration_s: float,
    startup_s: float,
    driver_per_trial_s: float,
    nodes: int,
    workers_per_node: int,
    cells: int = SWEEP_CELLS,
    trials_per_cell: int = SWEEP_TRIALS_PER_CELL,
) -> dict:
    """The model of the module docstring: the wall time (s) of a sweep of ``cells`` cells
    (one calibration each) of ``trials_per_cell`` trials on ``nodes`` nodes, and the trial
    rate the driver must absorb against the rate it can."""
    workers = nodes * workers_per_node
    trials = cells * trials_per_cell
    calibration = math.ceil(cells / workers) * calibration_s
    trial_phase = trials * trial_s / workers
    wall = startup_s + calibration + trial_phase
    needed = trials / trial_phase
    return {
        "nodes": nodes,
        "workers": workers,
        "trials": trials,
        "calibration_phase_s": calibration,
        "trial_phase_s": trial_phase,
        "wall_s": wall,
        "trials_per_s_needed": needed,
        "trials_per_s_driver_absorbs": 1.0 / driver_per_trial_s,
        "driver_keeps_up": needed < 1.0 / driver_per_trial_s,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m apps.engine_scaling", description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=positive_int, default=200, help="trials of the study (default 200)")
    parser.add_argument("--seed", type=int, default=4200, help="the study's first seed (default 4200)")
    parser.add_argument("--driver-jobs", type=positive_int, default=2000, help="empty jobs timed (default 2000)")
    parser.add_argument("--results", type=results_name, default=None, help="write results/NAME.json")
    parser.add_argument("--out", type=Path, default=Path("out"), help="the studies' folders go in DIR/engine_scaling")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a check of the app, not a measurement: the ideal world (no calibration), no runs without contact",
    )
    args = parser.parse_args(argv)
    extra = ["--ideal", "--no-contact-duration", "0", "--slow-motion-duration", "0"] if args.quick else []
    out = args.out / "engine_scaling"
    # The calibration, once, in the shared cache (the studies' --out is DIR/engine_scaling/<run>,
    # their cache DIR/engine_scaling/<run>/calibration_cache: link them all to one).
    cache = out / "calibration_cache"
    cache.mkdir(parents=True, exist_ok=True)
    calibration_s = None if args.quick else _calibrate(args.seed, cache)
    runs = {}
    for label, engine, workers in (("ray_2", "ray", 2), ("pool_2", "pool", 2), ("local_1", "local", 1)):
        folder = out / label
        folder.mkdir(parents=True, exist_ok=True)
        link = folder / "calibration_cache"
        if not link.exists():
            link.symlink_to(cache.resolve(), target_is_directory=True)
        print(f"the {args.trials}-trial study on {engine} with {workers} worker(s) ...", flush=True)
        metrics = _run_study(engine, workers, args.trials, args.seed, folder, extra)
        runs[label] = metrics
        print(f"  {metrics['wall_time_s']:.1f} s ({metrics['phase_wall_s']})", flush=True)
    reference = _comparable(runs["pool_2"])
    same = {label: _comparable(m) == reference for label, m in runs.items()}
    print("driver costs ...", flush=True)
    driver = _driver_costs(args.driver_jobs, 10)
    driver_per_trial = (driver["ray_round_trip_s"] + driver["chunk_write_s"]) / driver["trials_per_job"]
    one = runs["local_1"]
    # Per trial: the one worker's simulation phase over the trials (with the runs without
    # contact in it: an upper bound); the start-up: Ray's start, the trials' sampling and
    # reading the cached calibration (the study's "calibration" phase on Ray).
    trial_s = one["phase_wall_s"]["simulations"] / args.trials
    startup_s = runs["ray_2"]["phase_wall_s"]["calibration"]
    workers_per_node = os.cpu_count() or 2
    model = [
        sweep_model(trial_s, calibration_s or 0.0, startup_s, driver_per_trial, n, workers_per_node)
        for n in MODEL_NODES
    ]
    ray_s, pool_s = runs["ray_2"]["wall_time_s"], runs["pool_2"]["wall_time_s"]
    data = {
        "trials": args.trials,
        "seed": args.seed,
        "runs": {
            label: {
                "engine": m["engine"],
                "workers": m["workers"],
                "wall_time_s": m["wall_time_s"],
                "process_wall_s": m["process_wall_s"],
                "phase_wall_s": m["phase_wall_s"],
                "same_results_as_pool": same[label],
                "correct_link_rate": m.get("correct_link_rate"),
            }
            for label, m in runs.items()
        },
        "ray_over_pool": ray_s / pool_s,
        "ray_within_10_percent_of_pool": ray_s <= 1.1 * pool_s,
        "speedup_2_workers": one["wall_time_s"] / pool_s,
        "trial_s_one_worker": trial_s,
        "calibration_s_one_worker": calibration_s,
        "driver": {**driver, "per_trial_s": driver_per_trial, "trials_per_s": 1.0 / driver_per_trial},
        "model_workers_per_node": workers_per_node,
        "model": model,
        "sweep": {"cells": SWEEP_CELLS, "trials_per_cell": SWEEP_TRIALS_PER_CELL},
        "cpu_count": os.cpu_count(),
    }
    _print(data)
    if args.results:
        print(f"wrote {write_results(args.results, data, command=app_command('apps.engine_scaling', argv))}")
    return 0


def _calibrate(seed: int, cache: Path) -> float:
    """Calibrates the study's model (seed ``seed``) afresh, on one worker, into ``cache``
    (where the studies find it); returns its wall time, s."""
    import shutil

    from diagrams.residuals.contact_study import ContactLocalizationScenario
    from diagrams.residuals.model_refinement import calibration_file, refined_model
    from diagrams.station.config import StationConfig

    scenario = ContactLocalizationScenario(station=StationConfig.realistic(seed=seed))
    print("calibrating the study's model once (timed; the studies reuse it)", flush=True)
    with tempfile.TemporaryDirectory() as fresh:
        path = calibration_file(scenario, Path(fresh))
        start = time.perf_counter()
        refined_model(scenario, Path(fresh))
        elapsed = time.perf_counter() - start
        shutil.copyfile(path, calibration_file(scenario, cache))
    return elapsed


def _print(data: dict) -> None:
    print(f"\nthe same {data['trials']}-trial contact study:")
    for run in data["runs"].values():
        phases = ", ".join(f"{k} {v:.0f} s" for k, v in run["phase_wall_s"].items())
        print(
            f"  {run['engine']:5s} {run['workers']} worker(s): {run['wall_time_s']:7.1f} s ({phases});"
            f" same results as the pool: {run['same_results_as_pool']}"
        )
    print(
        f"  Ray / pool: {data['ray_over_pool']:.3f} (floor <= 1.10: {data['ray_within_10_percent_of_pool']});"
        f" 2 workers vs 1: {data['speedup_2_workers']:.2f}x"
    )
    d = data["driver"]
    print(
        f"driver: Ray round trip {1e3 * d['ray_round_trip_s']:.2f} ms per job, chunk write"
        f" {1e3 * d['chunk_write_s']:.2f} ms per {d['trials_per_job']} trials: {d['trials_per_s']:.0f} trials/s"
    )
    print(
        f"model ({data['model_workers_per_node']} workers per node, trial {data['trial_s_one_worker']:.2f} s,"
        f" calibration {data['calibration_s_one_worker'] or 0:.0f} s):"
    )
    for m in data["model"]:
        print(
            f"  {m['nodes']:3d} node(s): {m['trials']} trials in {m['wall_s'] / 3600:.2f} h"
            f" (needs {m['trials_per_s_needed']:.1f} trials/s of the driver: keeps up {m['driver_keeps_up']})"
        )


if __name__ == "__main__":
    raise SystemExit(main())
