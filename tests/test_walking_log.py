"""The base-state test bed (issue 32): the simulated walking log a real robot would write,
the error figures against its truth, and the app that runs the front door on it."""

import contextlib
import io
import json
import math

import numpy as np
import pytest

from apps import base_state_from_log as app
from diagrams.locomotion.walking_log import (
    FLOORS,
    WalkingLog,
    WalkingLogSettings,
    base_state_errors,
    floors_met,
    simulate_walking_log,
)
from systems.io.robot_log import read_log, stamp_timing

SHORT = WalkingLogSettings(standing_start=1.0, walking=2.5, seed=4)


@pytest.fixture(scope="module")
def app_run(tmp_path_factory):
    """The app's test bed on a short walk (one simulation for the whole module): its output
    folder and what it printed."""
    out = tmp_path_factory.mktemp("out")
    argv = ["--seeds", str(SHORT.seed), "--standing", str(SHORT.standing_start), "--walking", str(SHORT.walking)]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert app.main([*argv, "--out", str(out)]) == 0
    return out / "base_state_from_log", printed.getvalue()


@pytest.fixture(scope="module")
def walk(app_run):
    """The simulated log and its truth, as the app wrote them."""
    folder = app_run[0] / f"seed{SHORT.seed}"
    names = [f"base_{a}" for a in ("qw", "qx", "qy", "qz", "x", "y", "z", "wx", "wy", "wz", "vx", "vy", "vz")]
    truth = app.read_columns(folder / "truth.csv", ("time", *names))
    return WalkingLog(
        log=read_log(folder / "walk.csv"),
        truth_time=truth["time"],
        truth_base_pose=np.column_stack([truth[n] for n in names[:7]]),
        truth_base_velocity=np.column_stack([truth[n] for n in names[7:]]),
        gyro_bias_rad_s=np.radians(SHORT.gyro_bias_deg_s),
        settings=SHORT,
    )


@pytest.mark.slow
def test_the_log_holds_what_a_robot_logs_and_no_truth(walk):
    """Joint states, the IMU and the soles' normal forces at ~99 Hz with jittery stamps; no
    torques, no base state, no F/T wrench; standing, the two soles carry the robot's weight
    (FSR sums within 10 %) and the gyro reads its turn-on bias (within 4 standard errors)."""
    log = walk.log
    assert log.joint_torques is None and log.base_pose is None and log.base_velocity is None
    assert not log.wrenches and sorted(log.normal_forces) == ["l_sole_frame", "r_sole_frame"]
    steps = np.diff(log.time)
    assert np.median(steps) == pytest.approx(1.0 / 99.0, abs=1.1e-3)
    assert steps.min() > 0.0 and steps.max() - steps.min() > 1e-3  # jittery, unevenly stamped
    timing = stamp_timing(log.time)
    assert timing.case != "uniform" and timing.fitted_period == pytest.approx(1.0 / 99.0, rel=0.02)
    assert log.time[-1] == pytest.approx(SHORT.duration, abs=0.02)
    standing = (log.time > 0.3) & (log.time < SHORT.standing_start)
    weight = 9.81 * 5.3  # nao_like's mass is about 5.3 kg: checked against the truth's model below
    total = log.normal_forces["l_sole_frame"][standing] + log.normal_forces["r_sole_frame"][standing]
    assert np.mean(total) == pytest.approx(weight, rel=0.1)
    gyro = log.imu_angular_velocity[standing]
    standard_error = gyro.std(axis=0) / math.sqrt(gyro.shape[0])  # the BMI088's noise: ~0.05 deg/s here
    assert np.all(np.abs(gyro.mean(axis=0) - np.radians(SHORT.gyro_bias_deg_s)) < 4.0 * standard_error)
    assert np.all(np.diff(walk.truth_time) > 0) and walk.truth_time[-1] >= log.time[-1]
    walked = walk.truth_base_pose[-1, 4] - walk.truth_base_pose[0, 4]
    assert walked > 0.04  # it walked forward


def _rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _quaternion(R):
    from systems.estimation.base_state_estimator import rotation_to_quaternion

    return rotation_to_quaternion(R)


@pytest.mark.slow
def test_the_error_figures_against_known_errors(walk):
    """The truth against itself: every error 0 and every floor met; a known yaw drift, tilt,
    displacement error and velocity error come out as injected."""
    times = walk.log.time
    pose = np.column_stack([np.interp(times, walk.truth_time, walk.truth_base_pose[:, i]) for i in range(7)])
    velocity = np.column_stack([np.interp(times, walk.truth_time, walk.truth_base_velocity[:, i]) for i in range(6)])
    truth = (walk.truth_time, walk.truth_base_pose, walk.truth_base_velocity, SHORT.standing_start)
    exact = base_state_errors(times, pose, velocity, *truth)
    for name in ("tilt_rms_deg", "yaw_error_deg", "horizontal_drift_m", "velocity_rms_m_s"):
        assert abs(exact[name]) < 1e-6, (name, exact[name])
    assert all(floors_met(exact).values()) and set(floors_met(exact)) == set(FLOORS)
    assert exact["displacement_m"] > 0.02 and exact["path_length_m"] >= exact["displacement_m"]
    # Inject: yaw growing linearly to 3 deg at the end, a constant 0.5 deg tilt about x, a
    # 1 cm lateral drift at the end, a 0.05 m/s velocity error along x while walking.
    from systems.io.robot_log import quaternion_to_rotation

    fraction = (times - times[0]) / (times[-1] - times[0])
    R = quaternion_to_rotation(pose[:, :4])
    tilt = np.radians(0.5)
    R_tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(tilt), -math.sin(tilt)], [0.0, math.sin(tilt), math.cos(tilt)]])
    wrong = pose.copy()
    for k in range(times.size):
        wrong[k, :4] = _quaternion(_rotation_z(np.radians(3.0) * fraction[k]) @ R[k] @ R_tilt)
    wrong[:, 5] += 0.01 * fraction
    wrong_velocity = velocity.copy()
    wrong_velocity[times >= SHORT.standing_start, 3] += 0.05
    errors = base_state_errors(times, wrong, wrong_velocity, *truth)
    assert errors["yaw_error_deg"] == pytest.approx(3.0, abs=0.02)  # read at the end (shorter than 12 s)
    assert errors["tilt_rms_deg"] == pytest.approx(0.5, abs=0.02)
    assert errors["horizontal_drift_m"] == pytest.approx(0.01, abs=1e-6)
    assert errors["drift_percent"] == pytest.approx(100 * 0.01 / exact["displacement_m"], rel=1e-6)
    assert errors["velocity_rms_m_s"] == pytest.approx(0.05, abs=1e-9)
    assert errors["velocity_rms_standing_m_s"] < 1e-9
    assert floors_met(errors)["yaw_error_deg"] is False and floors_met(errors)["tilt_rms_deg"] is True


def test_bad_settings_are_refused_naming_them():
    for changes, message in (
        ({"rate_hz": 0.0}, "rate_hz"),
        ({"rate_hz": 1000.0}, "rate_hz"),
        ({"walking": -1.0}, "walking"),
        ({"stamp_noise_s": math.nan}, "stamp_noise_s"),
        ({"gyro_bias_deg_s": (0.1, 0.2)}, "gyro_bias_deg_s"),
    ):
        with pytest.raises(ValueError, match=message):
            simulate_walking_log(WalkingLogSettings(**changes))


@pytest.mark.slow
def test_the_app_runs_the_front_door_and_checks_a_log_against_its_truth(app_run, tmp_path, capsys):
    """The test bed on a short walk: the app writes the log and truth, runs
    apps.estimate_from_log on it, and meets every floor (the EKF with the at-rest bias; the
    bias-free ablation does worse on yaw); the same files through --log/--truth give the same
    figures; a truth without its columns is refused naming them."""
    folder, printed = app_run
    assert "$ python -m apps.estimate_from_log --robot nao_like --log" in printed
    metrics = json.loads((folder / "metrics.json").read_text())
    (row,) = metrics["rows"]
    assert row["log"]["channels"].endswith("no torques, no base state")
    assert row["front_door_metrics"]["at_rest_imu_bias"]["source"] == "detected"
    assert set(row["front_door_metrics"]["slip_updates"]) == {"left", "right"}  # the slip test ran
    assert "slip test: contact updates dropped as slips, per foot: left" in printed
    assert all(row["front_door"]["floors_met"].values()), row["front_door"]
    labels = [ablation["label"] for ablation in row["ablations"]]
    assert labels == [label for label, _ in app.ABLATIONS]
    bias_free = row["ablations"][1]["errors"]
    assert abs(bias_free["yaw_error_deg"]) > abs(row["front_door"]["yaw_error_deg"])
    log_path, truth_path = folder / "seed4" / "walk.csv", folder / "seed4" / "truth.csv"
    assert list(app.read_columns(truth_path, ("time",), ("base_vz",))) == ["time", "base_vz"]
    assert read_log(log_path).joint_torques is None
    again = tmp_path / "again"
    argv = ["--log", str(log_path), "--truth", str(truth_path), "--walking-start", "1.0", "--out", str(again)]
    assert app.main(argv) == 0
    checked = json.loads((again / "base_state_from_log" / "metrics.json").read_text())["errors"]
    for name in ("tilt_rms_deg", "yaw_error_deg", "drift_percent", "velocity_rms_m_s"):
        assert checked[name] == pytest.approx(row["front_door"][name], rel=1e-9, abs=1e-12)
    bad = tmp_path / "bad_truth.csv"
    bad.write_text("time,base_qw\n0.0,1.0\n0.1,1.0\n")
    capsys.readouterr()
    argv = ["--log", str(log_path), "--truth", str(bad), "--out", str(tmp_path / "bad")]
    assert app.main(argv) == 2
    assert "has no columns ['base_qx'" in capsys.readouterr().err
