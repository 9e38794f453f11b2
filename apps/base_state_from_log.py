"""Base-state estimation from a robot's own log, against the truth (issue 32's floors).

By default, on the test bed of ``diagrams.locomotion.walking_log``: ``nao_like`` stands 3 s,
then walks 10 s; its log holds only joint states, the IMU (with a 0.35 deg/s gyro bias about
the vertical) and each foot's normal force, at 99 Hz with jittery stamps, no joint torques.
For each seed the app writes the log and its truth (``OUT/base_state_from_log/seed<K>/``
``walk.csv``, ``truth.csv``), runs the front door on the log exactly as a user would
(``python -m apps.estimate_from_log --robot nao_like --log walk.csv``), reads the base
state it wrote (``estimates.csv``) and compares it with the truth: tilt RMS, yaw error after
12 s, horizontal drift in percent of the distance walked and the base velocity's RMS error
while walking, against the issue's floors (``diagrams.locomotion.walking_log.FLOORS``).
Two ablations run the same log through the library: the EKF without the at-rest IMU bias
(starting from a zero bias) and the bias-free filter.

On your own robot's log with a ground truth (motion capture)::

    python -m apps.base_state_from_log --robot my_robot.yaml --log run.mcap --truth truth.csv \\
        --walking-start 3.0 [--topics topics.yaml] [--calibrate-first S] [--estimator-settings F.yaml]

``truth.csv``: columns ``time`` (s, the log's clock) and ``base_qw base_qx base_qy base_qz
base_x base_y base_z`` (the base's pose in the world, Drake's free-joint order; m), optionally
``base_vx base_vy base_vz`` (the base origin's velocity in the world, m/s; without them it is
the central difference of the truth's positions). Other columns are ignored.

Run: ``python -m apps.base_state_from_log [--seeds K ...] [--standing S] [--walking S] [--out DIR]
[--results NAME]``
(``make base-state-from-log``; ``--results base_state_from_log`` writes
``results/base_state_from_log.json``, the table of docs/robots.md and the README).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from apps.results import app_command, write_results
from apps.runner import (
    add_out_argument,
    non_negative_float,
    output_folder,
    positive_float,
    print_written,
    run_app,
    write_metrics,
)
from diagrams.locomotion.walking_log import (
    FLOORS,
    ROBOT,
    WalkingLogSettings,
    base_state_errors,
    floors_met,
    simulate_walking_log,
)
from diagrams.residuals.log_estimation import LogEstimationSettings, build_estimator_plant, estimate_from_log
from systems.io.robot_log import write_log

EXPERIMENT = "base_state_from_log"
_POSE = ("base_qw", "base_qx", "base_qy", "base_qz", "base_x", "base_y", "base_z")
_VELOCITY = ("base_vx", "base_vy", "base_vz")
#: The ablations run through the library on the same log: (label, LogEstimationSettings changes).
ABLATIONS = (
    ("EKF from a zero IMU bias (no at-rest initialisation)", {"at_rest_bias": False}),
    ("bias-free EKF", {"estimate_imu_bias": False}),
)


def read_columns(path: Path, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """The float columns ``required`` (and those of ``optional`` present) of a CSV file with a
    header row.

    Raises:
        ValueError: an unreadable file, a missing required column, a value that is not a
            finite number (the file, column and row named).
    """
    try:
        with open(path, newline="") as stream:
            rows = list(csv.reader(stream))
    except OSError as error:
        raise ValueError(f"cannot read '{path}': {error}") from error
    if not rows:
        raise ValueError(f"'{path}' is empty: expected a header row with {list(required)}")
    header = rows[0]
    missing = [name for name in required if name not in header]
    if missing:
        raise ValueError(f"'{path}' has no columns {missing} (its columns: {header})")
    columns = {}
    for name in (*required, *(n for n in optional if n in header)):
        j = header.index(name)
        values = []
        for i, row in enumerate(rows[1:], start=2):
            try:
                value = float(row[j])
            except (IndexError, ValueError):
                value = float("nan")
            if not np.isfinite(value):
                raise ValueError(f"'{path}', column {name!r}, row {i}: not a finite number ({row[j : j + 1]})")
            values.append(value)
        columns[name] = np.asarray(values)
    if columns["time"].size < 2 or np.any(np.diff(columns["time"]) <= 0):
        raise ValueError(f"'{path}': the time column must have 2 or more strictly increasing values")
    return columns


def write_columns(path: Path, columns: dict[str, np.ndarray]) -> Path:
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(list(columns))
        writer.writerows(zip(*([repr(float(x)) for x in values] for values in columns.values())))
    return path


def truth_arrays(truth: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """(time, base pose (M, 7), base velocity (M, 6) [w; v], velocity given) of a truth
    table; a missing velocity is the central difference of the positions (its angular part,
    unused, zero)."""
    time = truth["time"]
    pose = np.column_stack([truth[name] for name in _POSE])
    given = all(name in truth for name in _VELOCITY)
    linear = np.column_stack([truth[name] for name in _VELOCITY]) if given else np.gradient(pose[:, 4:], time, axis=0)
    return time, pose, np.hstack((np.zeros_like(linear), linear)), given


def compare(estimates: dict[str, np.ndarray], truth: dict[str, np.ndarray], walking_start: float) -> dict:
    """``base_state_errors`` of an ``estimates.csv``'s columns against a truth table, the
    floors met, and whether the truth gave the velocity."""
    time, pose, velocity, given = truth_arrays(truth)
    estimated_velocity = np.column_stack(
        [np.zeros((estimates["time"].size, 3))] + [estimates[name] for name in _VELOCITY]
    )
    errors = base_state_errors(
        estimates["time"],
        np.column_stack([estimates[name] for name in _POSE]),
        estimated_velocity,
        time,
        pose,
        velocity,
        walking_start,
    )
    return errors | {"floors_met": floors_met(errors), "truth_velocity_given": given}


#: The repository's root (put on the front door's PYTHONPATH).
ROOT = Path(__file__).resolve().parent.parent
#: The front door: the app a user runs on a log, and its output folder's name.
FRONT_DOOR = "apps.estimate_from_log"
FRONT_DOOR_FOLDER = "estimate_from_log"


def _front_door(log_path: Path, folder: Path, robot: str, extra: list[str]) -> dict[str, np.ndarray]:
    """Runs ``python -m apps.estimate_from_log`` on ``log_path`` into ``folder``, in a process
    of its own as a user would, and returns the base state it wrote (``estimates.csv``'s
    base columns and time).

    Raises:
        ValueError: the front door refused the log (its message).
    """
    argv = ["--robot", robot, "--log", str(log_path), "--out", str(folder), "--no-replay", "--headless", *extra]
    print(f"$ python -m {FRONT_DOOR} {' '.join(argv)}", flush=True)
    path = os.environ.get("PYTHONPATH", "")
    environment = os.environ | {"PYTHONPATH": str(ROOT) + (os.pathsep + path if path else "")}
    done = subprocess.run(
        [sys.executable, "-m", FRONT_DOOR, *argv], env=environment, capture_output=True, text=True, check=False
    )
    print(done.stdout, end="", flush=True)
    if done.returncode != 0:
        raise ValueError(f"{FRONT_DOOR} exited with {done.returncode}: {done.stderr.strip()}")
    return read_columns(folder / FRONT_DOOR_FOLDER / "estimates.csv", ("time", *_POSE, *_VELOCITY))


def _describe(label: str, errors: dict) -> str:
    met = errors["floors_met"]

    def mark(name: str) -> str:
        return "" if met[name] else " (floor missed)"

    return (
        f"{label}: tilt RMS {errors['tilt_rms_deg']:.3f} deg{mark('tilt_rms_deg')}, yaw error at "
        f"{errors['yaw_error_time_s']:.1f} s {errors['yaw_error_deg']:+.3f} deg{mark('yaw_error_deg')}, drift "
        f"{100 * errors['horizontal_drift_m']:.1f} cm = {errors['drift_percent']:.2f} % of "
        f"{errors['displacement_m']:.2f} m{mark('drift_percent')}, velocity RMS walking "
        f"{errors['velocity_rms_m_s']:.4f} m/s{mark('velocity_rms_m_s')}"
    )


def run_test_bed(seeds: list[int], folder: Path, base: WalkingLogSettings | None = None) -> dict:
    """The test bed for each seed (module docstring; ``base``: the log's settings but the
    seed, default ``WalkingLogSettings()``): the front door's errors and the ablations'.
    Returns the results' ``data``."""
    base = base or WalkingLogSettings()
    robot = build_estimator_plant(ROBOT)
    rows = []
    for seed in seeds:
        settings = dataclasses.replace(base, seed=seed)
        what = f"standing {settings.standing_start} s then walking {settings.walking} s"
        print(f"seed {seed}: simulating {ROBOT} {what} ...")
        walk = simulate_walking_log(settings)
        seed_folder = folder / f"seed{seed}"
        seed_folder.mkdir()
        log_path = write_log(walk.log, seed_folder / "walk.csv")
        write_columns(seed_folder / "truth.csv", walk.truth_table())
        steps = np.diff(walk.log.time)
        estimated = _front_door(log_path, seed_folder, ROBOT, [])
        truth = walk.truth_table()
        errors = compare(estimated, truth, settings.standing_start)
        print(_describe(f"seed {seed}, apps.estimate_from_log", errors))
        ablations = []
        for label, changes in ABLATIONS:
            estimates = estimate_from_log(robot, walk.log, dataclasses.replace(LogEstimationSettings(), **changes))
            columns = {"time": estimates.time}
            state = np.hstack((estimates.base_pose, estimates.base_velocity[:, 3:]))
            columns |= {name: state[:, i] for i, name in enumerate((*_POSE, *_VELOCITY))}
            ablation = compare(columns, truth, settings.standing_start)
            print(_describe(f"seed {seed}, {label}", ablation))
            ablations.append({"label": label, "errors": ablation})
        metrics = (seed_folder / FRONT_DOOR_FOLDER / "metrics.json").read_text()
        rows.append(
            {
                "seed": seed,
                "log": {
                    "samples": walk.log.num_samples,
                    "duration_s": float(walk.log.time[-1] - walk.log.time[0]),
                    "median_period_s": float(np.median(steps)),
                    "step_range_s": [float(steps.min()), float(steps.max())],
                    "gyro_bias_deg_s": np.degrees(walk.gyro_bias_rad_s).tolist(),
                    "channels": "joint positions and velocities, IMU, foot normal forces; no torques, no base state",
                },
                "front_door": errors,
                "front_door_metrics": _json(metrics),
                "ablations": ablations,
            }
        )
    return {
        "robot": ROBOT,
        "settings": dataclasses.asdict(base),
        "floors": FLOORS,
        "rows": rows,
        "all_floors_met": all(all(row["front_door"]["floors_met"].values()) for row in rows),
    }


def _json(text: str) -> dict:
    payload = json.loads(text)
    keep = ("stamps", "at_rest_imu_bias", "slip_updates", "base_state", "real_time_factor", "not_estimated")
    return {key: payload.get(key) for key in keep}


def _parse(argv):
    parser = argparse.ArgumentParser(prog=f"python -m apps.{EXPERIMENT}", description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="test-bed seeds (default 0 1 2)")
    parser.add_argument("--robot", default=ROBOT, help="with --log: the robot (a description YAML or a built-in name)")
    parser.add_argument(
        "--log", type=Path, default=None, help="your robot's log (a format apps.estimate_from_log reads)"
    )
    parser.add_argument("--truth", type=Path, default=None, help="with --log: the truth CSV (module docstring)")
    parser.add_argument(
        "--walking-start",
        type=non_negative_float,
        default=0.0,
        metavar="S",
        help="with --log: s from the log's start after which the robot moves (the velocity RMS is over the rest)",
    )
    defaults = WalkingLogSettings()
    parser.add_argument(
        "--standing",
        type=non_negative_float,
        default=defaults.standing_start,
        metavar="S",
        help=f"test bed: s standing still before walking (default {defaults.standing_start})",
    )
    parser.add_argument(
        "--walking",
        type=positive_float,
        default=defaults.walking,
        metavar="S",
        help=f"test bed: s of walking logged (default {defaults.walking}; the yaw error is read at 12 s or the end)",
    )
    parser.add_argument("--results", default=None, metavar="NAME", help="also write results/NAME.json (test bed)")
    add_out_argument(parser, EXPERIMENT)
    args, passthrough = parser.parse_known_args(argv)
    if (args.log is None) != (args.truth is None):
        parser.error("--log and --truth go together")
    if passthrough and args.log is None:
        parser.error(f"unrecognized arguments: {' '.join(passthrough)}")
    if any(seed < 0 for seed in args.seeds):
        parser.error(f"--seeds must be >= 0, got {args.seeds}")
    return args, passthrough


def _run(args: argparse.Namespace, passthrough: list[str], argv) -> int:
    folder = output_folder(args, EXPERIMENT)
    if args.log is not None:
        truth = read_columns(args.truth, ("time", *_POSE), _VELOCITY)
        estimated = _front_door(args.log, folder, args.robot, passthrough)
        errors = compare(estimated, truth, args.walking_start)
        print(_describe(str(args.log), errors))
        if not errors["truth_velocity_given"]:
            print("(the truth has no base_vx..vz: its velocity is the central difference of its positions)")
        write_metrics(folder, {"robot": args.robot, "log": str(args.log), "truth": str(args.truth), "errors": errors})
        print_written(folder)
        return 0
    data = run_test_bed(args.seeds, folder, WalkingLogSettings(standing_start=args.standing, walking=args.walking))
    write_metrics(folder, data)
    if args.results:
        path = write_results(args.results, data, command=app_command(f"apps.{EXPERIMENT}", argv))
        print(f"wrote {path}")
    print("every floor met on every seed" if data["all_floors_met"] else "a floor was missed (see above)")
    print_written(folder)
    return 0


def main(argv: list[str] | None = None) -> int:
    args, passthrough = _parse(argv)
    return run_app(f"apps.{EXPERIMENT}", lambda: _run(args, passthrough, argv))


if __name__ == "__main__":
    raise SystemExit(main())
