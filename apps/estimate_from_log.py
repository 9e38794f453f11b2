"""Offline contact estimation from a recorded log (issue 14): the residuals of Flacco et al.
(2016), the contact force (eq. 19), the contact detector and, on a robot with foot F/T
sensors, the localizer (Sec. VI) run on a CSV, Parquet, MCAP, ROS 1 bag or ROS 2 bag log.

The log's layout (columns, ROS topics and message types, frames and units) is in
``systems/io/robot_log.py``; ROS topic names can be mapped with ``--topics FILE.yaml``
(keys ``joint_states``, ``odometry``, ``imu``, ``wrenches: {FRAME: TOPIC}``). A log without
the base's pose and velocity gets them from the contact-aided invariant EKF replayed on its
IMU, joint positions and each foot's F/T wrench, normal force or FSRs
(``diagrams.residuals.log_estimation``).

Run: ``python -m apps.estimate_from_log --robot hrp4_like --log LOG [--topics FILE.yaml]
[--out DIR] [--headless] [--no-replay] [--calibrate-first S] [--localization-period S]
[--estimator-settings FILE.yaml] [--gyro-noise-density X] [--accel-noise-density X]
[--gyro-bias-random-walk X] [--accel-bias-random-walk X]`` (the EKF's settings,
``systems.estimation.ekf_settings``), or try it end to end on a
simulated push: ``python -m apps.estimate_from_log [--robot R] --write-demo-log out/demo_push.mcap``
(simulates the robot under a known push, on hrp4_like 28 N, writes the log, then estimates from it).
Writes to ``DIR/estimate_from_log/``: ``estimates.csv`` (per sample: detection, test
statistics, force, external wrench, localized link and point, internal residual, the base
state used, logged or estimated, and the estimated IMU biases) and ``estimates.parquet``
(the same columns; with pyarrow, a dependency),
``contact_forces.png`` (not written when neither residual ran), ``metrics.json`` (the
contacts found, None without a detector, the real-time factor, how the stamps were spaced:
uniform, stamp noise or uneven, with the fitted period and jitter, for a log without base
state ``at_rest_imu_bias``: the still start the EKF's IMU bias was measured on, given by
``--calibrate-first`` or detected, and the initial gyro bias, and ``slip_updates``: per foot
the contact updates the EKF's slip test dropped, and ``not_estimated``:
the estimates not made and why, e.g. no localization on a model without collision
geometry, no internal residual, detection or localization on a log without joint torques,
no residual at all on a log whose feet log only their normal forces; their columns are
then empty) and
``replay.html`` (a self-contained Meshcat replay of the robot with the estimated contact
force), and prints the contacts and the real-time factor of the estimation.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
from pathlib import Path

import numpy as np

from apps.runner import (
    add_out_argument,
    output_folder,
    positive_float,
    print_written,
    replay_meshcat,
    run_app,
    write_metrics,
)
from diagrams.residuals.log_estimation import (
    LogEstimates,
    LogEstimationSettings,
    build_estimator_plant,
    demo_push,
    estimate_from_log,
    record_replay,
    simulate_push_log,
    status_reason,
)
from systems.estimation.ekf_settings import load_ekf_settings
from systems.io.robot_log import read_log, write_log

EXPERIMENT = "estimate_from_log"
#: The EKF settings with a command-line option of their own, and their units.
EKF_OPTIONS = {
    "gyro_noise_density": "RAD/S/SQRT(HZ)",
    "accel_noise_density": "M/S^2/SQRT(HZ)",
    "gyro_bias_random_walk": "RAD/S^2/SQRT(HZ)",
    "accel_bias_random_walk": "M/S^3/SQRT(HZ)",
}


def _parse(argv):
    parser = argparse.ArgumentParser(prog=f"python -m apps.{EXPERIMENT}", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--robot",
        default="hrp4_like",
        metavar="FILE.yaml",
        help="the robot: a robot description YAML (docs/robots.md, 'Bring your own robot') or a built-in name "
        "(hrp4_like, nao_like; default hrp4_like)",
    )
    parser.add_argument(
        "--log", type=Path, default=None, help="the log: .csv, .parquet, .mcap, .bag or a ROS 2 bag folder"
    )
    parser.add_argument("--topics", type=Path, default=None, metavar="FILE.yaml", help="ROS topic names by role")
    add_out_argument(parser, EXPERIMENT)
    parser.add_argument("--headless", action="store_true", help="no live Meshcat URL (the replay is still written)")
    parser.add_argument("--no-replay", action="store_true", help="skip the Meshcat replay")
    parser.add_argument(
        "--calibrate-first",
        type=positive_float,
        default=None,
        metavar="S",
        help="the log's first S seconds are still and free of contact: measure the detector's noise model on "
        "them instead of predicting it from the default sensor noise and, for a log without base state, the IMU "
        "bias the EKF starts from (default: the still start is detected)",
    )
    parser.add_argument(
        "--localization-period",
        type=positive_float,
        default=LogEstimationSettings.localization_period,
        metavar="S",
        help=f"s between two localizations in contact (default {LogEstimationSettings.localization_period}; the "
        "online contact study uses 0.01)",
    )
    parser.add_argument(
        "--estimator-settings",
        type=Path,
        default=None,
        metavar="FILE.yaml",
        help="the base-state EKF's settings for a log without base state (keys of systems.estimation."
        "ekf_settings.EkfSettings: noise densities, bias random walks, contact thresholds, stillness thresholds; "
        "keys left out keep their documented defaults)",
    )
    for option, unit in EKF_OPTIONS.items():
        parser.add_argument(
            f"--{option.replace('_', '-')}",
            type=positive_float,
            default=None,
            metavar=unit,
            help=f"the EKF's {option.replace('_', ' ')} (overrides --estimator-settings)",
        )
    parser.add_argument(
        "--write-demo-log",
        type=Path,
        default=None,
        metavar="PATH",
        help="simulate --robot under a known push (on hrp4_like a fixed 28 N push, elsewhere a random contact "
        "of the contact study, on a robot lighter than hrp4_like capped at the study's largest force scaled by "
        "its mass), write its log to PATH (format by extension) and, without --log, estimate from it",
    )
    args = parser.parse_args(argv)
    if args.log is None and args.write_demo_log is None:
        parser.error("give --log LOG (or --write-demo-log PATH to make one)")
    return args


def estimate_columns(estimates: LogEstimates) -> dict[str, np.ndarray | None]:
    """The columns of ``estimates.csv`` in order, one value per sample: ``time`` (s),
    ``contact_detected`` (0/1), ``statistic_external``, ``statistic_internal``, ``force_*``
    (eq. 19, N), ``external_wrench_*`` (world, N m and N), ``localization_status``,
    ``contact_link`` (str), ``contact_point_*`` (m), ``localized_force_*`` (N) (these four
    None without a localizer), ``residual_<joint>`` (N m); each of them None (empty) when
    its estimate was not made (``LogEstimates.not_estimated``), the base state the estimators
    used (``base_qw`` .. ``base_vz``: logged, or the invariant EKF's; m, rad/s, m/s) and,
    when the EKF estimated IMU biases, ``gyro_bias_*`` (rad/s) and ``accel_bias_*``
    (m/s^2); on a robot without foot F/T sensors the soles' estimated ground wrenches
    ``sole_<frame>_mx`` .. ``sole_<frame>_fz`` (world, about the sole frame's origin; N m,
    N), which the residual and force columns are net of (``LogEstimates.sole_frames``)."""
    detected, statistics = estimates.contact_detected, estimates.test_statistics
    force, wrench, residual = estimates.force_world, estimates.external_wrench_world, estimates.internal_residual
    columns: dict[str, np.ndarray | None] = {
        "time": np.asarray(estimates.time, dtype=float),
        "contact_detected": None if detected is None else np.asarray(detected, dtype=np.int64),
        "statistic_external": None if statistics is None else statistics[:, 0],
        "statistic_internal": None if statistics is None else statistics[:, 1],
    }
    columns |= {f"force_{a}": None if force is None else force[:, i] for i, a in enumerate("xyz")}
    axes = ("mx", "my", "mz", "fx", "fy", "fz")
    columns |= {f"external_wrench_{a}": None if wrench is None else wrench[:, i] for i, a in enumerate(axes)}
    loc = estimates.localization
    columns["localization_status"] = None if loc is None else np.asarray(loc["status"], dtype=np.int64)
    columns["contact_link"] = (
        None
        if loc is None
        else np.array([estimates.body_names.get(int(b), "") for b in loc["body_index"]], dtype=object)
    )
    columns |= {f"contact_point_{a}": None if loc is None else loc["point_world"][:, i] for i, a in enumerate("xyz")}
    columns |= {f"localized_force_{a}": None if loc is None else loc["force_world"][:, i] for i, a in enumerate("xyz")}
    for i, joint in enumerate(estimates.joint_names):
        columns[f"residual_{joint}"] = None if residual is None else residual[:, i]
    if estimates.base_pose is not None:
        names = ("qw", "qx", "qy", "qz", "x", "y", "z", "wx", "wy", "wz", "vx", "vy", "vz")
        base = np.hstack((estimates.base_pose, estimates.base_velocity))
        columns |= {f"base_{a}": base[:, i] for i, a in enumerate(names)}
    if estimates.imu_bias is not None:
        names = [f"gyro_bias_{a}" for a in "xyz"] + [f"accel_bias_{a}" for a in "xyz"]
        columns |= {name: estimates.imu_bias[:, i] for i, name in enumerate(names)}
    for j, frame in enumerate(estimates.sole_frames):
        columns |= {f"sole_{frame}_{a}": estimates.sole_wrenches_world[:, 6 * j + i] for i, a in enumerate(axes)}
    return columns


def check_finite(estimates: LogEstimates) -> None:
    """Raises ValueError naming the first (in time, then in column order) estimate column
    that is NaN or inf and its time: a non-finite estimate is never written as a result."""
    columns = estimate_columns(estimates)
    first = None
    for name, values in columns.items():
        if values is None or values.dtype == object:
            continue
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size and (first is None or bad[0] < first[1]):
            first = (name, int(bad[0]))
    if first is not None:
        name, k = first
        raise ValueError(
            f"the estimate {name!r} is {columns[name][k]} at t = {estimates.time[k]:.6g} s (from the log's start): "
            "the log holds values the estimators cannot digest there; nothing was written"
        )


def write_estimates_csv(path: Path, estimates: LogEstimates) -> Path:
    """One row per sample, the columns of ``estimate_columns`` (empty cells for a column
    that is None: no localizer)."""
    columns = estimate_columns(estimates)
    N = len(estimates.time)
    cells = []
    for values in columns.values():
        if values is None:
            cells.append([""] * N)
        elif values.dtype == object:
            cells.append(list(values))
        elif values.dtype.kind in "iub":
            cells.append([int(x) for x in values])
        else:
            cells.append([repr(float(x)) for x in values])
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(list(columns))
        writer.writerows(zip(*cells))
    return path


def write_estimates_parquet(path: Path, estimates: LogEstimates) -> Path | None:
    """The columns of ``estimates.csv`` (``estimate_columns``, same names, order and values)
    as a Parquet table: float64, ``contact_detected`` and ``localization_status`` int64,
    ``contact_link`` string; a column that is None (no localizer) all null. None (nothing
    written) when pyarrow is not installed."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    kinds = {"contact_detected": pa.int64(), "localization_status": pa.int64(), "contact_link": pa.string()}
    N = len(estimates.time)
    arrays, names = [], []
    for name, values in estimate_columns(estimates).items():
        kind = kinds.get(name, pa.float64())
        arrays.append(
            pa.nulls(N, kind) if values is None else pa.array(list(values) if kind == pa.string() else values, kind)
        )
        names.append(name)
    pq.write_table(pa.table(arrays, names=names), path)
    return path


def timing_metrics(estimates: LogEstimates) -> dict:
    """metrics.json's ``stamps``: ``case`` ("uniform", "stamp noise": the fitted uniform
    stamps used, the data not interpolated, or "uneven": resampled), ``period_s`` (the
    estimators' period), ``fitted_period_s`` (the line fitted to stamp vs row) and
    ``jitter_rms_s`` (the stamps' RMS deviation from it), s."""
    timing = estimates.timing
    return {
        "case": timing.case,
        "period_s": timing.period,
        "fitted_period_s": timing.fitted_period,
        "jitter_rms_s": timing.jitter_rms,
    }


def describe_timing(estimates: LogEstimates) -> str:
    """The printout's line on the stamps (``timing_metrics``)."""
    timing = estimates.timing
    fit = f"fitted period {timing.fitted_period:.6g} s, jitter {timing.jitter_rms:.3g} s RMS"
    if timing.case == "stamp noise":
        return f"evenly spaced rows with noisy stamps ({fit}): run on the fitted uniform stamps, data not interpolated"
    if timing.case == "uneven":
        return f"unevenly sampled ({fit}): resampled to its median period {timing.period:.6g} s"
    return f"uniform ({fit})"


def at_rest_metrics(estimates: LogEstimates) -> dict | None:
    """metrics.json's ``at_rest_imu_bias`` (None unless the EKF estimated the base with bias
    states): ``source`` ("given" by --calibrate-first, "detected" or "none"),
    ``still_window_s`` ([start, end], s; with "none" the still start found, too short),
    ``samples``, ``gyro_bias_rad_s`` and ``gyro_bias_std_rad_s`` (3 each, IMU frame, the
    EKF's initial bias and prior std), ``accel_magnitude_error_m_s2`` (|mean specific
    force| - |g|) and ``reason`` (why none was used)."""
    at_rest = estimates.at_rest
    if at_rest is None:
        return None
    return {
        "source": at_rest.source,
        "still_window_s": [at_rest.start_s, at_rest.end_s],
        "samples": at_rest.samples,
        "gyro_bias_rad_s": None if at_rest.gyro_bias is None else at_rest.gyro_bias.tolist(),
        "gyro_bias_std_rad_s": None if at_rest.gyro_bias_std is None else at_rest.gyro_bias_std.tolist(),
        "accel_magnitude_error_m_s2": at_rest.accel_magnitude_error,
        "reason": at_rest.reason,
    }


def describe_at_rest(estimates: LogEstimates) -> str | None:
    """The printout's line on the at-rest IMU bias initialisation (``at_rest_metrics``)."""
    at_rest = estimates.at_rest
    if at_rest is None:
        return None
    if not at_rest.used:
        return f"at-rest IMU bias: none ({at_rest.reason})"
    how = "given by --calibrate-first" if at_rest.source == "given" else "detected"
    bias = np.round(np.degrees(at_rest.gyro_bias), 4).tolist()
    std = np.round(np.degrees(at_rest.gyro_bias_std), 4).tolist()
    return (
        f"at-rest IMU bias: still window {at_rest.start_s:.3f}-{at_rest.end_s:.3f} s ({how}), initial gyro bias "
        f"{bias} deg/s +- {std} deg/s, accelerometer magnitude error {at_rest.accel_magnitude_error:.4f} m/s^2"
    )


def plot_contact_forces(path: Path, estimates: LogEstimates) -> Path | None:
    """The estimated contact force (eq. 19) per axis and its norm, the detected contact
    shaded; below, the detector's test statistics (empty without a detector). None
    (nothing written) when the force was not estimated (``LogEstimates.not_estimated``)."""
    import matplotlib.pyplot as plt

    if estimates.force_world is None:
        return None
    t, f = estimates.time, estimates.force_world
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    ax = axes[0]
    for i, (axis, color) in enumerate(zip("xyz", ("tab:red", "tab:green", "tab:blue"))):
        ax.plot(t, f[:, i], color=color, lw=0.8, label=f"f_{axis}")
    ax.plot(t, np.linalg.norm(f, axis=1), color="k", lw=1.0, label="|f|")
    top = max(1.0, float(np.linalg.norm(f, axis=1).max()))
    if estimates.contact_detected is not None:
        ax.fill_between(t, -top, top, where=estimates.contact_detected, color="tab:orange", alpha=0.12, step="mid")
    ax.set_ylabel("estimated force, eq. (19) [N]")
    ax.set_title("contact force estimated from the log (shaded: contact detected)")
    ax.legend(fontsize=8, ncol=4)
    ax.grid(True, alpha=0.3)
    ax = axes[1]
    if estimates.test_statistics is not None:
        statistics = estimates.test_statistics
        ax.semilogy(t, np.maximum(statistics[:, 0], 1e-3), lw=0.8, label="s_ext (3 dof)")
        ax.semilogy(t, np.maximum(statistics[:, 1], 1e-3), lw=0.8, label=f"s_int ({len(estimates.joint_names)} dof)")
        ax.legend(fontsize=8)
    else:
        ax.set_title("no contact detection (see not_estimated)")
    ax.set_ylabel("test statistic")
    ax.set_xlabel("time [s]")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _run(args: argparse.Namespace) -> int:
    folder = output_folder(args, EXPERIMENT)
    if not args.localization_period > 0:
        raise ValueError(f"--localization-period must be positive, got {args.localization_period}")
    ekf = load_ekf_settings(args.estimator_settings, **{option: getattr(args, option) for option in EKF_OPTIONS})
    settings = LogEstimationSettings(
        noise_calibration_time=args.calibrate_first, localization_period=args.localization_period, ekf=ekf
    )
    log_path = args.log
    if args.write_demo_log is not None:
        print(f"simulating {args.robot} under a known push for the demo log ...")
        body, point, force = demo_push(args.robot)
        demo, online = simulate_push_log(
            args.robot, push_body=body, push_point=point, push_force=force, settings=settings
        )
        write_log(demo, args.write_demo_log)
        force = online.push.force_W(0.5 * (online.push_start + online.push_end))
        print(
            f"wrote {args.write_demo_log}: {demo.num_samples} samples, a push of {np.linalg.norm(force):.1f} N "
            f"{np.round(force, 2).tolist()} on {online.push.body_name} from {online.push_start} s to "
            f"{online.push_end} s"
        )
        if log_path is None:
            log_path = args.write_demo_log
    log = read_log(log_path, args.topics)
    robot = build_estimator_plant(args.robot)
    estimates = estimate_from_log(robot, log, settings)
    check_finite(estimates)
    contacts = estimates.contacts()
    duration = estimates.period * len(estimates.time)
    print(
        f"{log_path}: {log.num_samples} samples over {duration:.3f} s at {1.0 / estimates.period:.0f} Hz, "
        f"{len(estimates.joint_names)} joints, F/T frames {sorted(log.wrenches)}"
        + (f", normal-force frames {sorted(log.normal_forces)}" if log.normal_forces else "")
        + ("" if log.joint_torques is not None else ", no joint torques")
        + f"; base state: {estimates.base_state}"
    )
    print(f"stamps: {describe_timing(estimates)}")
    at_rest_line = describe_at_rest(estimates)
    if at_rest_line is not None:
        print(at_rest_line)
    if estimates.slip_updates:
        slips = ", ".join(f"{side} {count}" for side, count in estimates.slip_updates.items())
        print(f"slip test: contact updates dropped as slips, per foot: {slips}")
    for estimate, reason in estimates.not_estimated.items():
        print(f"not estimated: {estimate}: {reason}")
    if estimates.sole_frames:
        normal = estimates.sole_wrenches_world.reshape(len(estimates.time), -1, 6)[:, :, 5]
        print(
            "no foot F/T sensors: the soles' ground wrenches are estimated with the contacts (residual and force "
            "net of them); mean normal force "
            + ", ".join(f"{frame} {f:.1f} N" for frame, f in zip(estimates.sole_frames, normal.mean(axis=0)))
        )
    print(
        f"estimation: {estimates.wall_time_s:.2f} s wall for {duration:.2f} s of log: real-time factor "
        f"{estimates.real_time_factor:.2f} (one thread)"
    )
    if not contacts and estimates.contact_detected is not None:
        print("no contact detected")
    for i, contact in enumerate(contacts):
        force = np.asarray(contact["mean_force_world_N"])
        where = f"on {contact['link']} at {np.round(contact['point_world_m'], 3).tolist()} m" if contact["link"] else ""
        if estimates.localization is not None and not contact["link"]:
            where = "not localized"
        print(
            f"contact {i + 1}: {contact['start_s']:.3f}-{contact['end_s']:.3f} s, force {np.linalg.norm(force):.2f} N "
            f"{np.round(force, 2).tolist()} {where}".rstrip()
        )
    write_estimates_csv(folder / "estimates.csv", estimates)
    write_estimates_parquet(folder / "estimates.parquet", estimates)
    plot_contact_forces(folder / "contact_forces.png", estimates)
    last_status = None if estimates.localization is None else int(estimates.localization["status"][-1])
    metrics = {
        "robot": args.robot,
        "log": str(log_path),
        "samples": int(log.num_samples),
        "duration_s": duration,
        "period_s": estimates.period,
        "resampled": estimates.resampled,
        "stamps": timing_metrics(estimates),
        "at_rest_imu_bias": at_rest_metrics(estimates),
        "slip_updates": estimates.slip_updates or None,
        "noise_model": estimates.noise_model,
        "base_state": estimates.base_state,
        "estimated_sole_wrenches": list(estimates.sole_frames) or None,
        "wall_time_s": estimates.wall_time_s,
        "real_time_factor": estimates.real_time_factor,
        "contacts": None if estimates.contact_detected is None else contacts,
        "localization": "none (see not_estimated)" if last_status is None else status_reason(last_status),
        "not_estimated": [{"estimate": e, "reason": r} for e, r in estimates.not_estimated.items()],
        "settings": dataclasses.asdict(settings),
    }
    write_metrics(folder, metrics)
    meshcat = replay_meshcat(not args.no_replay, args.headless)
    if meshcat is not None:
        record_replay(meshcat, robot, log, estimates)
        (folder / "replay.html").write_text(meshcat.StaticHtml())
    print_written(folder)
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    return run_app(f"apps.{EXPERIMENT}", lambda: _run(args))


if __name__ == "__main__":
    raise SystemExit(main())
