"""Contact localization Monte Carlo study: Flacco et al. (2016), Secs. V-VI, Fig. 9.

The humanoid (``hrp4_like``) stands holding its posture with noisy sensors; in each trial a
constant force of 5-40 N, within 60 deg of the inward surface normal, pushes a random point
of the outer collision surface of a random link (upper body and legs; the soles, below the
F/T sensors, are excluded) for 1 s. The internal and external residuals, the
ContactDetector and the ContactLocalizer see only the sensors. Per trial the app records
detection and its delay, the localized link and point and the force at the end of the push
(t = start + 1 s; the localizer averages its inputs from 0.1 s after detection), and the
computation time of one localizer update. A separate run without contact (10 s) counts
false detections.

Run: ``python -m apps.contact_localization [--trials N] [--seed S] [--model M] [--out DIR]
[--headless] [--workers W] [--replays R]``. Trials run in parallel processes ('spawn').
Writes to ``DIR/contact_localization/``: ``metrics.json`` (totals, floors, per-trial
results), ``position_errors.png`` (histogram), and ``replay_trial_<i>.html`` (Meshcat
replays of the first R trials: green arrow = true force ending at the true contact
point, red arrow = the localizer's estimate, shown while valid).

Metric definitions: ``detection_rate`` = trials whose contact was detected during the push
(a detection before the push counts as a false detection, not as this trial's);
``correct_link_rate`` and the position errors are over ALL trials (a trial without a
localization counts as a wrong link and an infinite position error); force errors are over
the detected trials: |f_hat - f| / |f| and the angle between f_hat and f.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from diagrams.residuals.contact_localization import MAX_ANGLE_DEG, MAX_FORCE, MIN_FORCE, sample_trials  # noqa: E402

FLOORS = {
    "detection_rate": (">=", 0.99),
    "median_detection_delay_s": ("<=", 0.020),
    "false_detections": ("<=", 0),
    "correct_link_rate": (">=", 0.95),
    "median_position_error_m": ("<=", 0.02),
    "p95_position_error_m": ("<=", 0.05),
    "median_force_error_rel": ("<=", 0.05),
    "median_angle_error_deg": ("<=", 5.0),
    "median_localizer_update_ms": ("<=", 2.0),
}

# ---------------------------------------------------------------------------------------
# One trial (worker process).
# ---------------------------------------------------------------------------------------


def _time_localizer_update(handles, context, repeats: int = 20) -> float:
    """Median wall time [s] of one ContactLocalizer update with the trial's final inputs,
    each call at a slightly different q (so that no pose or mass matrix is reused)."""
    localizer = handles.localizer
    lc = localizer.GetMyContextFromRoot(context)
    x = np.array(localizer.GetInputPort("state").Eval(lc))
    probe = localizer.CreateDefaultContext()
    state_value = localizer.GetInputPort("state").FixValue(probe, x)
    for name in ("external_wrench_world", "residual", "contact_detected"):
        localizer.GetInputPort(name).FixValue(probe, np.array(localizer.GetInputPort(name).Eval(lc)))
    localizer.GetInputPort("contact_detected").FixValue(probe, [1.0])
    rng = np.random.default_rng(0)
    nq = handles.plant.num_positions()
    samples = []
    for _ in range(repeats):
        x2 = x.copy()
        x2[7:nq] += 1e-6 * rng.normal(size=nq - 7)
        state_value.GetMutableData().set_value(x2)
        start = time.perf_counter()
        localizer.EvalUniquePeriodicDiscreteUpdate(probe)
        samples.append(time.perf_counter() - start)
    return float(np.median(samples))


def run_trial(spec: dict, model: str = "hrp4_like", push_start: float = 0.5, duration: float = 1.0,
              noise: bool = True, meshcat=None) -> dict:
    """Simulates one trial; returns its results (see the module docstring)."""
    from pydrake.multibody.tree import BodyIndex
    from pydrake.systems.analysis import Simulator

    from diagrams.residuals.contact_localization import ContactLocalizationConfig, build_contact_localization_diagram

    config = ContactLocalizationConfig(
        model=model, push_body=spec["body"], push_point=tuple(spec["point_body"]), push_force=tuple(spec["force_world"]),
        push_start=push_start, push_duration=duration, noise=noise, seed=spec["noise_seed"])
    diagram, handles = build_contact_localization_diagram(config, meshcat)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.station.set_initial_state(context)
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=32.0)
    simulator.Initialize()
    wall = time.perf_counter()
    t_end = push_start + duration
    simulator.AdvanceTo(t_end)
    wall = time.perf_counter() - wall
    estimate = handles.localizer.estimate(handles.localizer.GetMyContextFromRoot(context))
    pc = handles.push_source.GetMyContextFromRoot(context)
    true_point = np.array(handles.push_source.GetOutputPort("point_world").Eval(pc))
    f_true = np.asarray(spec["force_world"])
    if meshcat is not None:
        simulator.AdvanceTo(t_end + 0.3)  # the replay shows the release too
        meshcat.StopRecording()
        meshcat.PublishRecording()

    log = handles.loggers["contact_detected"].FindLog(context)
    t, detected = log.sample_times(), log.data()[0]
    times = handles.loggers["detection_time"].FindLog(context).data()[0]
    during = (t >= push_start) & (t <= t_end) & (detected > 0.5)
    rising = np.flatnonzero(np.diff(np.concatenate(([0.0], detected))) > 0.5)
    false_before = int(np.sum(t[rising] < push_start))
    result = {
        **spec,
        "detected": bool(during.any()),
        "false_detections_before_push": false_before,
        "detection_delay_s": None,
        "status": estimate.status,
        "status_reason": estimate.reason,
        "estimated_body_index": estimate.body_index,
        "estimated_body": handles.plant.get_body(BodyIndex(estimate.body_index)).name()
        if estimate.body_index >= 0 else None,
        "correct_link": estimate.body_index == spec["body_index"],
        "position_error_m": None,
        "force_error_rel": None,
        "angle_error_deg": None,
        "score": estimate.score if math.isfinite(estimate.score) else None,
        "runner_up_score": estimate.runner_up_score if math.isfinite(estimate.runner_up_score) else None,
        "true_point_world": true_point.tolist(),
        "estimated_point_world": estimate.point_W.tolist(),
        "estimated_force_world": estimate.force_W.tolist(),
        "simulation_wall_s": wall,
    }
    if result["detected"]:
        first = np.flatnonzero(during)[0]
        result["detection_delay_s"] = float(times[first] - push_start)
        f_hat = estimate.force_W
        result["force_error_rel"] = float(np.linalg.norm(f_hat - f_true) / np.linalg.norm(f_true))
        cos = float(f_hat @ f_true / max(np.linalg.norm(f_hat) * np.linalg.norm(f_true), 1e-300))
        result["angle_error_deg"] = math.degrees(math.acos(min(1.0, max(-1.0, cos))))
    if estimate.body_index >= 0:
        result["position_error_m"] = float(np.linalg.norm(estimate.point_W - true_point))
    result["localizer_update_s"] = _time_localizer_update(handles, context)
    return result


def run_no_contact(model: str, duration: float, seed: int, noise: bool = True) -> dict:
    """A run without contact: the number of OFF->ON switches of the detector."""
    from pydrake.systems.analysis import Simulator

    from diagrams.residuals.contact_localization import ContactLocalizationConfig, build_contact_localization_diagram

    config = ContactLocalizationConfig(model=model, push_body=None, noise=noise, seed=seed, log_period=1e-3)
    diagram, handles = build_contact_localization_diagram(config)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.station.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    log = handles.loggers["contact_detected"].FindLog(context)
    detected = log.data()[0]
    stats = handles.loggers["test_statistics"].FindLog(context).data()
    on = handles.detector.thresholds["on"]
    return {
        "duration_s": duration,
        "noise_seed": seed,
        "false_detections": int(np.sum(np.diff(np.concatenate(([0.0], detected))) > 0.5)),
        "max_statistic_over_threshold": [float(stats[0].max() / on[0]), float(stats[1].max() / on[1])],
    }


def _job(job: tuple) -> tuple[str, dict]:
    kind, payload, options = job
    if kind == "trial":
        return kind, run_trial(payload, **options)
    return kind, run_no_contact(**payload)


# ---------------------------------------------------------------------------------------
# Metrics and outputs.
# ---------------------------------------------------------------------------------------


def summarize(results: list[dict], no_contact: dict | None) -> dict:
    """The totals of the module docstring."""
    n = len(results)
    detected = [r for r in results if r["detected"]]
    delays = [r["detection_delay_s"] for r in detected]
    positions = np.array([r["position_error_m"] if r["position_error_m"] is not None else np.inf for r in results])
    forces = [r["force_error_rel"] for r in detected]
    angles = [r["angle_error_deg"] for r in detected]
    updates = np.array([r["localizer_update_s"] for r in results]) * 1e3

    def median(values):
        return float(np.median(values)) if len(values) else None

    metrics = {
        "trials": n,
        "detection_rate": len(detected) / n if n else None,
        "median_detection_delay_s": median(delays),
        "p95_detection_delay_s": float(np.percentile(delays, 95)) if delays else None,
        "false_detections": (no_contact["false_detections"] if no_contact else 0)
        + sum(r["false_detections_before_push"] for r in results),
        "false_detections_no_contact_run": no_contact["false_detections"] if no_contact else None,
        "no_contact_run_s": no_contact["duration_s"] if no_contact else None,
        "false_detections_before_push_in_trials": sum(r["false_detections_before_push"] for r in results),
        "correct_link_rate": float(np.mean([r["correct_link"] for r in results])) if n else None,
        "valid_rate": float(np.mean([r["status"] == 0 for r in results])) if n else None,
        "ambiguous_rate": float(np.mean([r["status"] == 4 for r in results])) if n else None,
        "median_position_error_m": float(np.median(positions)) if n else None,
        "p95_position_error_m": float(np.percentile(positions, 95)) if n else None,
        "median_position_error_correct_link_m": median([r["position_error_m"] for r in results if r["correct_link"]]),
        "median_force_error_rel": median(forces),
        "p95_force_error_rel": float(np.percentile(forces, 95)) if forces else None,
        "median_angle_error_deg": median(angles),
        "p95_angle_error_deg": float(np.percentile(angles, 95)) if angles else None,
        "median_localizer_update_ms": float(np.median(updates)) if n else None,
        "max_localizer_update_ms": float(np.max(updates)) if n else None,
        "status_counts": {reason: sum(r["status_reason"] == reason for r in results)
                          for reason in sorted({r["status_reason"] for r in results})},
        "wrong_links": [{"trial": r["trial"], "true": r["body"], "estimated": r["estimated_body"],
                         "status": r["status_reason"]} for r in results if not r["correct_link"]],
    }
    checks = {}
    for key, (op, floor) in FLOORS.items():
        value = metrics.get(key)
        checks[key] = None if value is None else bool(value >= floor if op == ">=" else value <= floor)
    metrics["floors"] = {k: f"{op} {v}" for k, (op, v) in FLOORS.items()}
    metrics["meets_floors"] = checks
    return metrics


def plot_position_errors(path: Path, results: list[dict]) -> None:
    errors = np.array([r["position_error_m"] for r in results if r["position_error_m"] is not None]) * 100.0
    fig, ax = plt.subplots(figsize=(7, 4))
    if errors.size:
        ax.hist(np.minimum(errors, 20.0), bins=np.linspace(0.0, 20.0, 41), color="tab:blue", edgecolor="k")
        ax.axvline(np.median(errors), color="tab:green", label=f"median {np.median(errors):.2f} cm")
        ax.axvline(np.percentile(errors, 95), color="tab:orange", label=f"95th percentile {np.percentile(errors, 95):.2f} cm")
    ax.axvline(2.0, color="tab:green", ls="--", label="floor: median 2 cm")
    ax.axvline(5.0, color="tab:orange", ls="--", label="floor: p95 5 cm")
    missing = sum(r["position_error_m"] is None for r in results)
    ax.set_xlabel("position error [cm] (clipped at 20)")
    ax.set_ylabel("trials")
    ax.set_title(f"Contact localization, {len(results)} trials ({missing} without a localization)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _parse(argv):
    parser = argparse.ArgumentParser(prog="python -m apps.contact_localization", description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200, help="number of random contacts (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the trials and of the sensor noise")
    parser.add_argument("--model", default="hrp4_like", help="humanoid with foot F/T sensors (hrp4_like)")
    parser.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out)")
    parser.add_argument("--headless", action="store_true", help="no live Meshcat URL (replays are still written)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="parallel processes (default: all cores)")
    parser.add_argument("--replays", type=int, default=3, help="Meshcat replays of the first N trials (default 3)")
    parser.add_argument("--push-start", type=float, default=0.5, help="contact onset, s (default 0.5)")
    parser.add_argument("--contact-duration", type=float, default=1.0, help="contact duration, s (default 1)")
    parser.add_argument("--no-contact-duration", type=float, default=10.0,
                        help="length of the run without contact for false detections, s (default 10; 0 skips)")
    parser.add_argument("--no-noise", action="store_true", help="ideal sensors")
    args = parser.parse_args(argv)
    if args.trials < 1 or args.workers < 1 or args.replays < 0 or args.contact_duration <= 0 or args.push_start < 0:
        parser.error("--trials and --workers must be >= 1, --replays >= 0, --contact-duration > 0, --push-start >= 0")
    return args


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    out_dir = args.out / "contact_localization"
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    try:
        specs = sample_trials(args.model, args.trials, args.seed)
    except ValueError as error:
        print(f"contact_localization: error: {error}", file=sys.stderr)
        return 2
    options = {"model": args.model, "push_start": args.push_start, "duration": args.contact_duration,
               "noise": not args.no_noise}
    jobs = []
    if args.no_contact_duration > 0:  # the longest job first
        jobs.append(("no_contact", {"model": args.model, "duration": args.no_contact_duration,
                                    "seed": (args.seed * 100003 + 99991) % (2**31 - 1), "noise": not args.no_noise}, None))
    jobs += [("trial", spec, options) for spec in specs]
    results, no_contact = [], None
    if args.workers == 1:
        outputs = map(_job, jobs)
        pool = None
    else:
        pool = multiprocessing.get_context("spawn").Pool(min(args.workers, len(jobs)))
        outputs = pool.imap_unordered(_job, jobs)
    try:
        for done, (kind, value) in enumerate(outputs, 1):
            if kind == "trial":
                results.append(value)
            else:
                no_contact = value
            print(f"\r{done}/{len(jobs)} jobs done", end="", flush=True)
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    print()
    results.sort(key=lambda r: r["trial"])
    metrics = summarize(results, no_contact)
    metrics.update({"model": args.model, "seed": args.seed, "noise": not args.no_noise, "workers": args.workers,
                    "push_start_s": args.push_start, "contact_duration_s": args.contact_duration,
                    "force_range_N": [MIN_FORCE, MAX_FORCE], "max_angle_from_normal_deg": MAX_ANGLE_DEG,
                    "wall_time_s": None, "no_contact_run": no_contact})

    if args.replays:
        from pydrake.geometry import Meshcat

        meshcat = Meshcat()
        if not args.headless:
            print(f"Meshcat (live view): {meshcat.web_url()}")
        for spec in specs[: args.replays]:
            meshcat.Delete()
            meshcat.DeleteRecording()
            meshcat.SetCameraPose(camera_in_world=[1.6, -1.6, 1.2], target_in_world=[0.0, 0.0, 0.7])
            run_trial(spec, meshcat=meshcat, **options)
            (out_dir / f"replay_trial_{spec['trial']}.html").write_text(meshcat.StaticHtml())
    metrics["wall_time_s"] = time.perf_counter() - start
    metrics["per_trial"] = results
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=True))
    plot_position_errors(out_dir / "position_errors.png", results)
    _print_summary(metrics, out_dir)
    return 0


def _print_summary(metrics: dict, out_dir: Path) -> None:
    print(f"contact localization on {metrics['model']}, {metrics['trials']} trials, noise {'on' if metrics['noise'] else 'off'}:")
    for key, (op, floor) in FLOORS.items():
        value = metrics.get(key)
        ok = metrics["meets_floors"].get(key)
        text = "n/a" if value is None else f"{value:.4g}"
        print(f"  {key:32s} {text:>10s}   floor {op} {floor:<6}  {'ok' if ok else 'MISSED' if ok is not None else ''}")
    print(f"  status counts: {metrics['status_counts']}")
    print(f"wall time {metrics['wall_time_s']:.1f} s; wrote {out_dir}")


if __name__ == "__main__":
    raise SystemExit(main())
