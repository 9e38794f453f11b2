"""Offline estimation from a log (issue 14): a simulated known push on hrp4_like, logged,
written in every format, read back and estimated offline; the offline replay equals what the
same estimators reported in the simulation; the app end to end."""

from __future__ import annotations

import json
import os
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from apps import estimate_from_log as estimate_from_log_app
from diagrams.residuals.log_estimation import (
    LogEstimationSettings,
    build_estimator_plant,
    estimate_from_log,
    log_inputs,
    simulate_push_log,
)
from systems.io.robot_log import LOG_FORMATS, RobotLog, read_log, write_log
from systems.residuals.contact_estimation import VALID
from systems.simulation.visualization import read_static_html

FORMATS = {"csv": "push.csv", "parquet": "push.parquet", "mcap": "push.mcap", "ros1": "push.bag", "ros2": "push_ros2"}


@pytest.fixture(scope="module")
def simulated():
    """hrp4_like standing 1.5 s, pushed with 28 N on the right upper arm from 0.5 s: the log
    and what the estimators reported online."""
    return simulate_push_log("hrp4_like", duration=1.5)


@pytest.fixture(scope="module")
def robot():
    return build_estimator_plant("hrp4_like")


def recovered_push(estimates, online) -> tuple[np.ndarray, str, np.ndarray]:
    """(mean force of eq. 19 over the push's second half, N; the last valid localization's
    link and force) of the one detected contact."""
    contacts = estimates.contacts()
    assert len(contacts) == 1, contacts
    contact = contacts[0]
    assert online.push_start <= contact["start_s"] < online.push_start + 0.02  # detected within 20 ms
    return np.asarray(contact["mean_force_world_N"]), contact["link"], np.asarray(contact["localized_force_world_N"])


def test_offline_replay_equals_the_online_estimators(simulated, robot):
    log, online = simulated
    estimates = estimate_from_log(robot, log)
    scale_int = np.abs(online.internal_residual).max()
    scale_ext = np.abs(online.external_wrench_world).max()
    np.testing.assert_allclose(estimates.internal_residual, online.internal_residual, rtol=0, atol=1e-10 * scale_int)
    np.testing.assert_allclose(
        estimates.external_wrench_world, online.external_wrench_world, rtol=0, atol=1e-10 * scale_ext
    )
    np.testing.assert_array_equal(estimates.contact_detected, online.contact_detected)
    loc = estimates.localization
    np.testing.assert_array_equal(loc["status"], online.status)
    np.testing.assert_array_equal(loc["body_index"], online.body_index)
    np.testing.assert_allclose(loc["point_world"], online.point_world, rtol=0, atol=1e-9)
    np.testing.assert_allclose(loc["force_world"], online.force_world, rtol=0, atol=1e-9)
    # Not vacuous: a contact was found and localized online.
    assert online.contact_detected.any() and (online.status == VALID).any()
    # One sample of shift breaks the equality (the test sees the timing).
    assert np.abs(estimates.internal_residual[1:] - online.internal_residual[:-1]).max() > 1e3 * 1e-10 * scale_int


@pytest.mark.parametrize("robot_file", ["hrp4_like_no_ft.yaml", "hrp4_like_fsr.yaml"])
def test_a_log_of_a_robot_without_foot_ft_sensors(robot_file):
    """The demo push on hrp4_like without foot F/T sensors (without foot sensing, and with
    FSRs, whose readings the log holds): offline, the detector and the localizer (the soles'
    wrenches their unknowns) give what they gave online, exactly; the contact is found on
    the pushed link, its force net of the soles' estimated wrenches is the push's, and the
    soles' estimated normal forces (without sensing) hold the robot's weight less the push's
    vertical part (statics)."""
    name = f"models/robots/{robot_file}"
    log, online = simulate_push_log(name, duration=1.5)
    assert not log.wrenches and (log.fsr_forces is not None) == ("fsr" in robot_file)
    robot = build_estimator_plant(name)
    estimates = estimate_from_log(robot, log)
    assert estimates.not_estimated == {}
    np.testing.assert_array_equal(estimates.contact_detected, online.contact_detected)
    loc = estimates.localization
    np.testing.assert_array_equal(loc["status"], online.status)
    np.testing.assert_array_equal(loc["body_index"], online.body_index)
    np.testing.assert_allclose(loc["point_world"], online.point_world, rtol=0, atol=1e-9)
    # The soles' compensation: the same link as online every update; its outputs read the
    # posture of the update after online (the sensed state's sample-and-hold), hence not
    # equal to rounding (tests/test_sole_wrenches.py checks the replay update by update).
    np.testing.assert_array_equal(estimates.sole_contact_body_index, online.extra["sole_body"][:, 0])
    raw = np.abs(online.internal_residual).max()
    assert np.abs(estimates.internal_residual - online.extra["sole_internal"]).max() < 0.005 * raw

    force, link, localized = recovered_push(estimates, online)
    true_force = online.push.force_W(1.0)
    assert link == online.push.body_name
    assert np.linalg.norm(force - true_force) < 0.03 * np.linalg.norm(true_force)
    assert np.linalg.norm(localized - true_force) < 0.03 * np.linalg.norm(true_force)
    assert estimates.sole_frames == tuple(f.name() for f in robot.unknown_wrench_frames)
    if "no_ft" in robot_file:
        pushed = (estimates.time > 1.2) & (estimates.time < 1.5)
        normal = estimates.sole_wrenches_world[pushed].reshape(-1, 2, 6)[:, :, 5].sum(axis=1)
        weight = robot.plant.CalcTotalMass(robot.plant.CreateDefaultContext()) * 9.81
        np.testing.assert_allclose(normal.mean(), weight - true_force[2], rtol=0.005)


def test_stacked_residuals_equal_the_systems_own_updates(simulated, robot):
    """The whole-log residuals of ``replay_contact_estimation`` and ``replay_residuals(stacked=True)``
    (eq. 9's elimination, the momenta and rates stacked over the samples; the classical
    residual of eq. 7 alongside) equal the systems' own ``advance`` run sample by sample;
    the detector's stacked test statistics equal its per-sample ones."""
    from diagrams.residuals.log_estimation import build_offline_estimators, make_detector
    from systems.residuals.momentum_residuals import ClassicalResidual
    from systems.residuals.offline import _replay_residuals, _stacked_residuals, replay_residuals

    log, _ = simulated
    inputs = log_inputs(robot, log)
    _, internal, external = build_offline_estimators(robot, LogEstimationSettings(), inputs.period)
    classical = ClassicalResidual(robot.plant, 30.0, inputs.period, robot.ft_frames, model=internal.model)
    stacked, _ = _stacked_residuals(
        internal, external, inputs.state, inputs.joint_torque, inputs.known_wrenches, chunk=400, classical=classical
    )
    one_by_one, _ = _replay_residuals(
        internal, external, classical, inputs.state, inputs.joint_torque, inputs.known_wrenches
    )
    for a, b in (
        (stacked.internal, one_by_one.internal),
        (stacked.external_wrench_world, one_by_one.external_wrench_world),
        (stacked.classical, one_by_one.classical),
    ):
        assert np.abs(b).max() > 1.0
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * np.abs(b).max())
    # replay_residuals's stacked path (same numbers as above).
    public = replay_residuals(
        robot.plant,
        internal.model,
        robot.ft_frames,
        inputs.state,
        inputs.joint_torque,
        inputs.known_wrenches,
        internal_gain=35.0,
        external_gain=35.0,
        period=inputs.period,
        classical_gain=30.0,
        stacked=True,
    )
    for a, b in ((public.internal, one_by_one.internal), (public.classical, one_by_one.classical)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * np.abs(b).max())
    detector = make_detector(robot, LogEstimationSettings(), inputs.period)
    rows = [0, 400, 900, 1400]
    expected = [detector.statistics(one_by_one.external_wrench_world[k], one_by_one.internal[k]) for k in rows]
    got = detector.statistics_of_samples(one_by_one.external_wrench_world[rows], one_by_one.internal[rows])
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    # The stacked path checks the log's quaternions once (not per sample): a bad one is named.
    bad = inputs.state.copy()
    bad[700, :4] *= 1.2
    with pytest.raises(ValueError, match="quaternion of sample 700 is not of unit norm"):
        _stacked_residuals(internal, external, bad, inputs.joint_torque, inputs.known_wrenches)


@pytest.mark.parametrize("kind", LOG_FORMATS)
def test_push_recovered_through_each_format(simulated, robot, tmp_path: Path, kind: str):
    log, online = simulated
    back = read_log(write_log(log, tmp_path / FORMATS[kind]))
    estimates = estimate_from_log(robot, back)
    force, link, localized = recovered_push(estimates, online)
    true = online.push.force_W(1.0)
    assert np.linalg.norm(force - true) <= 0.05 * np.linalg.norm(true), (force, true)
    assert np.linalg.norm(localized - true) <= 0.05 * np.linalg.norm(true), (localized, true)
    assert link == online.push.body_name


def test_log_without_base_state_gets_the_invariant_ekf(robot):
    """A log without base pose and velocity: the invariant EKF replayed on its IMU, joint
    positions and F/T contact reproduces the station's online filter (base_state
    "invariant_ekf"), hence the same residuals; with its default settings (IMU biases
    estimated, start standing on level ground from the log's joints) it still recovers
    the push."""
    log, online = simulate_push_log("hrp4_like", duration=1.0, base_state="invariant_ekf")
    no_base = replace(log, base_pose=None, base_velocity=None)
    station_like = LogEstimationSettings(estimate_imu_bias=False)  # the ideal IMU: the bias-free filter
    inputs = log_inputs(robot, no_base, station_like, initial_base_pose=robot.standing_state[:7])
    assert inputs.base_estimated
    np.testing.assert_allclose(inputs.state[:, :7], log.base_pose, rtol=0, atol=1e-12)
    np.testing.assert_allclose(inputs.state[:, 41:47], log.base_velocity, rtol=0, atol=1e-12)
    assert np.abs(inputs.state[1:, :7] - log.base_pose[:-1]).max() > 1e-6  # the timing matters
    estimates = estimate_from_log(robot, no_base, station_like, initial_base_pose=robot.standing_state[:7])
    np.testing.assert_allclose(estimates.internal_residual, online.internal_residual, rtol=0, atol=1e-10)
    default = estimate_from_log(robot, no_base)
    assert default.base_state.startswith("invariant EKF")
    force, link, _ = recovered_push(default, online)
    true = online.push.force_W(0.75)
    assert np.linalg.norm(force - true) <= 0.05 * np.linalg.norm(true) and link == online.push.body_name
    without_imu = replace(no_base, imu_angular_velocity=None, imu_linear_acceleration=None)
    with pytest.raises(ValueError, match="no base pose and velocity .* nor the IMU and foot F/T wrenches"):
        log_inputs(robot, without_imu)


def test_log_inputs_errors(simulated, robot):
    log, _ = simulated
    short = log.select(slice(0, 20))
    renamed = replace(short, joint_names=("R_KNEE",) + short.joint_names[1:])
    with pytest.raises(ValueError, match=r"the log's joints \['R_KNEE'\] are not joints of the robot"):
        log_inputs(robot, renamed)
    fewer = replace(
        short,
        joint_names=short.joint_names[1:],
        joint_positions=short.joint_positions[:, 1:],
        joint_velocities=short.joint_velocities[:, 1:],
        joint_torques=short.joint_torques[:, 1:],
    )
    with pytest.raises(ValueError, match=rf"no data for the robot's joints \['{short.joint_names[0]}'\]"):
        log_inputs(robot, fewer)
    with pytest.raises(ValueError, match="no base pose and velocity"):
        log_inputs(robot, replace(short, base_pose=None, base_velocity=None, imu_angular_velocity=None))
    wrenches = dict(short.wrenches)
    wrenches["l_foot"] = wrenches.pop("L_FT_SENSOR_child")
    wrong_frame = replace(short, wrenches=wrenches)
    with pytest.raises(ValueError, match=r"wrenches \['l_foot'\] are not F/T frames of the robot"):
        log_inputs(robot, wrong_frame)


def test_gaps_and_implausible_values_are_refused_naming_them(simulated, robot, tmp_path, capsys):
    """A gap in the time column is refused with its time (never interpolated across: a 100 s
    gap once became a 101 s contact on the wrong link), and so is a joint velocity, gyro rate
    or acceleration beyond physical plausibility (one 1e200 rad/s once turned 800 rows into
    NaN with exit code 0); the app says so in one line, exit code 2."""
    log, _ = simulated
    short = log.select(slice(0, 300))
    gap = short.select(slice(None))
    gap.time = short.time + np.where(np.arange(300) >= 150, 100.0, 0.0)
    with pytest.raises(ValueError, match=r"a gap of 100\.001 s after t = 0\.149 s"):
        log_inputs(robot, gap)
    absurd = short.select(slice(None))
    absurd.joint_velocities = short.joint_velocities.copy()
    absurd.joint_velocities[200, 3] = 1e200
    name = short.joint_names[3]
    with pytest.raises(ValueError, match=rf"joint_velocities \(channel '{name}'\) is 1e\+200 rad/s at t = 0\.2 s"):
        log_inputs(robot, absurd)
    spinning = short.select(slice(None))
    spinning.imu_angular_velocity = short.imu_angular_velocity.copy()
    spinning.imu_angular_velocity[10, 2] = -60.0
    with pytest.raises(ValueError, match=r"imu_angular_velocity \(channel 'z'\) is -60 rad/s at t = 0\.01 s"):
        log_inputs(robot, spinning)
    path = tmp_path / "gap.csv"
    write_log(gap, path)
    code = estimate_from_log_app.main(["--robot", "hrp4_like", "--log", str(path), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and "a gap of 100.001 s" in err and "Traceback" not in err
    assert not (tmp_path / "estimate_from_log").exists()
    with pytest.raises(SystemExit):
        estimate_from_log_app.main(["--robot", "hrp4_like", "--log", str(path), "--calibrate-first", "-0.2"])
    assert "--calibrate-first: must be finite and > 0" in capsys.readouterr().err


def _corrupted(log, field, channel, value, row=200):
    """A copy of ``log`` with ``field``'s ``channel`` (a column index, or (frame, index) for a
    wrench) set to ``value`` at ``row``."""
    bad = log.select(slice(None))
    if field == "wrenches":
        frame, c = channel
        bad.wrenches = {name: w.copy() for name, w in log.wrenches.items()}
        bad.wrenches[frame][row, c] = value
    else:
        values = getattr(log, field).copy()
        values[row, channel] = value
        setattr(bad, field, values)
    return bad


@pytest.mark.parametrize(
    "field, channel, value, message",
    [
        (
            "joint_torques",
            5,
            1e200,
            r"joint_torques \(channel '{joint}'\) is 1e\+200 N m at t = 0\.2 s, beyond the "
            r"physically plausible \+-\d",
        ),
        (
            "joint_positions",
            5,
            1e5,
            r"joint_positions \(channel '{joint}'\) is 100000 rad at t = 0\.2 s, beyond the "
            r"physically plausible \[-\d",
        ),
        (
            "wrenches",
            ("L_FT_SENSOR_child", 5),
            1e200,
            r"wrenches\['L_FT_SENSOR_child'\] \(channel 'fz'\) is 1e\+200 N "
            r"at t = 0\.2 s",
        ),
        (
            "wrenches",
            ("R_FT_SENSOR_child", 0),
            -1e200,
            r"wrenches\['R_FT_SENSOR_child'\] \(channel 'tx'\) is -1e\+200 N m",
        ),
        (
            "base_velocity",
            3,
            300.0,
            r"base_velocity \(channel 'vx'\) is 300 m/s at t = 0\.2 s, beyond the physically "
            r"plausible \+-20 m/s",
        ),
    ],
)
def test_implausible_torques_positions_wrenches_and_base_velocity_are_refused(
    simulated, robot, tmp_path, capsys, field, channel, value, message
):
    """One joint torque or wrench entry of 1e200 once gave half the estimate rows NaN with
    exit code 0, a joint position of 1e5 rad was accepted: each is refused naming the
    channel, the time and the bound, by ``log_inputs`` and by the app (exit code 2)."""
    log, _ = simulated
    short = log.select(slice(0, 300))
    message = message.format(joint=short.joint_names[5])
    bad = _corrupted(short, field, channel, value)
    with pytest.raises(ValueError, match=message):
        log_inputs(robot, bad)
    path = write_log(bad, tmp_path / "bad.csv")
    code = estimate_from_log_app.main(
        ["--robot", "hrp4_like", "--log", str(path), "--out", str(tmp_path), "--no-replay"]
    )
    err = capsys.readouterr().err
    assert code == 2 and re.search(message, err) and "Traceback" not in err, err
    assert not (tmp_path / "estimate_from_log").exists()


def test_plausibility_bounds_come_from_the_model_and_pass_a_normal_log(simulated, robot):
    """The bounds are the model's limits widened (positions), times 10 (velocities,
    torques), 10 m g (forces) and 10 m g L (moments, joints without effort limit); the
    simulated push log (a normal log) is within them and passes, a value just beyond one
    is refused."""
    from diagrams.residuals.log_estimation import (
        POSITION_LIMIT_MARGIN,
        TORQUE_LIMIT_FACTOR,
        WRENCH_WEIGHT_FACTOR,
        plausibility_bounds,
    )
    from systems.common.topology import floating_base_topology

    log, _ = simulated
    joints = {j.name(): j for j in floating_base_topology(robot.plant).joints}
    order = [joints[name] for name in log.joint_names]
    bounds = plausibility_bounds(robot, order)
    j = order[5]
    assert bounds.position_upper[5] == j.position_upper_limits()[0] + POSITION_LIMIT_MARGIN
    actuator = next(
        robot.plant.get_joint_actuator(i)
        for i in robot.plant.GetJointActuatorIndices()
        if robot.plant.get_joint_actuator(i).joint().index() == j.index()
    )
    assert bounds.torque[5] == TORQUE_LIMIT_FACTOR * actuator.effort_limit()
    mass = robot.plant.CalcTotalMass(robot.plant.CreateDefaultContext())
    assert bounds.wrench[5] == pytest.approx(WRENCH_WEIGHT_FACTOR * 9.81 * mass)
    assert 1.0 < bounds.size < 2.0  # hrp4_like is about 1.5 m tall
    inputs = log_inputs(robot, log)  # the normal log passes
    assert np.isfinite(inputs.state).all()
    just_beyond = _corrupted(log.select(slice(0, 300)), "joint_torques", 5, 1.01 * bounds.torque[5])
    with pytest.raises(ValueError, match="joint_torques"):
        log_inputs(robot, just_beyond)


def test_a_non_finite_estimate_fails_the_app_naming_column_and_time(simulated, robot, tmp_path, capsys, monkeypatch):
    """The last guard: should an estimate come out NaN or inf anyway, the app fails (exit
    code 2) naming the first non-finite column and its time, and writes nothing."""
    log, _ = simulated
    short = log.select(slice(0, 300))
    path = write_log(short, tmp_path / "short.csv")
    real = estimate_from_log_app.estimate_from_log

    def poisoned(*args, **kwargs):
        estimates = real(*args, **kwargs)
        estimates.internal_residual[150:, 2] = np.nan
        estimates.force_world[170, 0] = np.inf
        return estimates

    monkeypatch.setattr(estimate_from_log_app, "estimate_from_log", poisoned)
    code = estimate_from_log_app.main(
        ["--robot", "hrp4_like", "--log", str(path), "--out", str(tmp_path), "--no-replay"]
    )
    err = capsys.readouterr().err
    column = f"residual_{robot.joint_names[2]}"
    assert code == 2 and f"the estimate '{column}' is nan at t = 0.15 s" in err, err
    assert not (tmp_path / "estimate_from_log").exists()
    monkeypatch.undo()
    assert (
        estimate_from_log_app.main(["--robot", "hrp4_like", "--log", str(path), "--out", str(tmp_path), "--no-replay"])
        == 0
    )


def test_a_log_at_99_hz_without_base_state_gets_the_ekf(simulated, robot):
    """A log at 99 Hz (10.104 ms, a period that does not divide the EKF's 0.1 s level-ground
    period) without base pose and velocity runs the invariant EKF at its own period (it was
    refused: "level_ground_period must be a multiple of period")."""
    log, _ = simulated
    slow = log.select(slice(0, None, 10))
    slow.time = slow.time * 1.0104
    inputs = log_inputs(robot, replace(slow, base_pose=None, base_velocity=None))
    assert inputs.base_estimated and inputs.period == pytest.approx(0.010104)
    assert np.isfinite(inputs.state).all()


def test_the_estimated_base_state_and_imu_biases_are_written_out(robot, tmp_path):
    """A log without base state: the invariant EKF's base pose and velocity (and its IMU
    bias estimate) are part of the estimates and of ``estimates.csv``, per sample; against
    the simulator's base (the log's own, removed before estimating) the pose is within 3 mm
    and 0.1 deg, the velocity within 1.5 cm/s (measured: 0.27 mm, 0.008 deg, 1.3 mm/s)."""
    log, _ = simulate_push_log("hrp4_like", duration=1.0, base_state="invariant_ekf")
    estimates = estimate_from_log(robot, replace(log, base_pose=None, base_velocity=None))
    assert estimates.base_pose.shape == (log.num_samples, 7) and estimates.imu_bias.shape == (log.num_samples, 6)
    truth_pose, truth_velocity = log.base_pose, log.base_velocity
    assert np.abs(estimates.base_pose[:, 4:] - truth_pose[:, 4:]).max() < 3e-3
    cos_half = np.abs(np.einsum("ij,ij->i", estimates.base_pose[:, :4], truth_pose[:, :4]))
    assert np.degrees(2.0 * np.arccos(np.minimum(cos_half, 1.0))).max() < 0.1
    assert np.abs(estimates.base_velocity[:, 3:] - truth_velocity[:, 3:]).max() < 0.015
    path = estimate_from_log_app.write_estimates_csv(tmp_path / "estimates.csv", estimates)
    header = path.read_text().splitlines()[0].split(",")
    base_columns = ("qw", "qx", "qy", "qz", "x", "y", "z", "wx", "wy", "wz", "vx", "vy", "vz")
    assert header[-19:-6] == [f"base_{a}" for a in base_columns]
    assert header[-6:] == ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x", "accel_bias_y", "accel_bias_z"]
    rows = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(len(header) - 19, len(header)))
    np.testing.assert_array_equal(rows[:, :7], estimates.base_pose)
    np.testing.assert_array_equal(rows[:, 13:], estimates.imu_bias)


def test_noisy_stamps_of_evenly_spaced_rows_are_fitted_not_interpolated(simulated, robot, tmp_path, capsys):
    """Rows every 1 ms whose stamps alternate +-0.2 ms: stamp noise. The estimators run on
    the fitted uniform stamps (period 1 ms, jitter 0.2 ms RMS) with the logged data as they
    are (no interpolation); the printout and metrics.json say so."""
    log, _ = simulated
    short = log.select(slice(0, 300))
    jittered = short.select(slice(None))
    jittered.time = short.time + 2e-4 * np.where(np.arange(300) % 2, 1.0, -1.0)
    inputs = log_inputs(robot, jittered)
    timing = inputs.timing
    assert timing.case == "stamp noise" and not inputs.resampled
    assert inputs.period == timing.fitted_period == pytest.approx(1e-3, rel=1e-4)
    assert timing.jitter_rms == pytest.approx(2e-4, rel=1e-3)
    np.testing.assert_allclose(inputs.time, short.time, rtol=0, atol=1e-5)  # 5 % of the jitter
    np.testing.assert_array_equal(inputs.state, log_inputs(robot, short).state)  # the data untouched
    assert log_inputs(robot, short).timing.case == "uniform"
    path = write_log(jittered, tmp_path / "jittered.csv")
    code = estimate_from_log_app.main(
        ["--robot", "hrp4_like", "--log", str(path), "--out", str(tmp_path), "--no-replay"]
    )
    assert code == 0
    assert "stamps: evenly spaced rows with noisy stamps (fitted period 0.001" in capsys.readouterr().out
    stamps = json.loads((tmp_path / "estimate_from_log" / "metrics.json").read_text())["stamps"]
    assert stamps["case"] == "stamp noise" and stamps["fitted_period_s"] == pytest.approx(1e-3, rel=1e-4)
    assert stamps["jitter_rms_s"] == pytest.approx(2e-4, rel=1e-3)


def test_unevenly_sampled_log_is_resampled(simulated, robot):
    """160 rows 1 ms apart, then 140 rows 1.25 ms apart: genuinely uneven sampling (its
    stamps stray far from any straight line), resampled to the median period 1 ms by
    linear interpolation."""
    log, _ = simulated
    short = log.select(slice(0, 300))
    uneven = short.select(slice(None))
    uneven.time = np.concatenate(([0.0], np.cumsum(np.where(np.arange(299) < 159, 1e-3, 1.25e-3))))
    inputs = log_inputs(robot, uneven)
    timing = inputs.timing
    assert timing.case == "uneven" and inputs.resampled and inputs.period == pytest.approx(1e-3)
    assert timing.max_deviation > 0.25 * timing.fitted_period
    count = int(np.floor(uneven.duration / 1e-3 + 1e-9)) + 1
    np.testing.assert_allclose(inputs.time, 1e-3 * np.arange(count), rtol=0, atol=1e-12)
    name = short.joint_names[7]
    column = robot.plant.GetJointByName(name).position_start()
    expected = np.interp(inputs.time, uneven.time, uneven.joint_positions[:, 7])
    np.testing.assert_allclose(inputs.state[:, column], expected, rtol=0, atol=1e-12)


def test_noise_calibrated_on_the_log_start(simulated, robot):
    log, online = simulated
    estimates = estimate_from_log(robot, log, LogEstimationSettings(noise_calibration_time=0.45))
    assert estimates.noise_model != "predicted"
    force, link, _ = recovered_push(estimates, online)
    assert link == online.push.body_name
    with pytest.raises(ValueError, match="longer than the log"):
        estimate_from_log(robot, log.select(slice(0, 200)), LogEstimationSettings(noise_calibration_time=0.45))


def test_fsr_feet_without_their_readings_in_the_log_have_whole_sole_wrenches_unknown():
    """nao_like (FSR feet, no F/T) with a log that has no FSR readings: its soles' whole
    wrenches become unknowns (as with ``sensing: none``); with the readings, only their
    shear and yaw. Either way the residuals, the detector and the localizer run."""
    from diagrams.residuals.log_estimation import fsr_sides_logged
    from systems.common.topology import floating_base_topology
    from systems.observer.fsr_sensing import FSR_NAMES
    from systems.residuals.contact_estimation import ALL_WRENCH_COMPONENTS, SOLE_SHEAR_AND_YAW

    nao = build_estimator_plant("nao_like")
    state = nao.standing_state
    samples = 200
    joints = floating_base_topology(nao.plant).joints
    q = np.tile([state[j.position_start()] for j in joints], (samples, 1))
    log = RobotLog(
        time=1e-3 * np.arange(samples),
        joint_names=tuple(j.name() for j in joints),
        joint_positions=q,
        joint_velocities=np.zeros_like(q),
        joint_torques=np.zeros_like(q),
        base_pose=np.tile(state[:7], (samples, 1)),
        base_velocity=np.zeros((samples, 6)),
    )
    assert nao.unknown_wrench_components == (SOLE_SHEAR_AND_YAW, SOLE_SHEAR_AND_YAW)
    unlogged = fsr_sides_logged(nao, log)
    assert unlogged.unknown_wrench_components == (ALL_WRENCH_COMPONENTS, ALL_WRENCH_COMPONENTS)
    assert unlogged.fsr_sides == () and unlogged.known_wrench_frames == ()
    with_fsrs = replace(log, fsr_names=FSR_NAMES, fsr_forces=np.full((samples, len(FSR_NAMES)), 6.0))
    assert fsr_sides_logged(nao, with_fsrs) is nao
    one_side = replace(log, fsr_names=FSR_NAMES[:4], fsr_forces=np.full((samples, 4), 6.0))
    assert fsr_sides_logged(nao, one_side).unknown_wrench_components == (SOLE_SHEAR_AND_YAW, ALL_WRENCH_COMPONENTS)
    for each in (log, with_fsrs):
        estimates = estimate_from_log(nao, each)
        assert estimates.not_estimated == {}
        assert estimates.sole_frames == ("l_sole_frame", "r_sole_frame")
        assert estimates.internal_residual.shape == (samples, len(joints))
        np.testing.assert_array_equal(estimates.base_pose, log.base_pose)


def _hrp4_like_without_collision_geometry(folder: Path) -> Path:
    """hrp4_like's description on a copy of its SDF whose links have no collision geometry
    but the soles' contact spheres (the feet below the F/T sensors, never localized)."""
    models = Path(__file__).resolve().parents[1] / "models"
    removed = 0

    def strip(link: re.Match) -> str:
        nonlocal removed
        if link.group(2) in ("l_sole", "r_sole"):
            return link.group(0)
        body, count = re.subn(r"<collision .*?</collision>\s*", "", link.group(3), flags=re.DOTALL)
        removed += count
        return link.group(1) + body + link.group(4)

    text = re.sub(
        r'(<link name="([^"]+)">)(.*?)(</link>)', strip, (models / "hrp4_like.sdf").read_text(), flags=re.DOTALL
    )
    assert removed > 20
    (folder / "hrp4_like.sdf").write_text(text)
    description = folder / "no_collision.yaml"
    description.write_text((models / "hrp4_like.yaml").read_text().replace("name: hrp4_like", "name: no_collision"))
    return description


def test_a_model_without_collision_geometry_runs_all_but_localization(simulated, robot, tmp_path, capsys):
    """A model whose links have no collision geometry made the localizer refuse the whole
    estimation ("no candidate link left"): the residuals, the force and the detector run
    (as on the full model, the geometry aside), the localization is not made, and the
    printout and metrics.json say so and why."""
    from diagrams.residuals.log_estimation import LOCALIZATION, localization_unavailable

    log, online = simulated
    part = log.select(slice(0, 800))
    bare = build_estimator_plant(str(_hrp4_like_without_collision_geometry(tmp_path)))
    assert "no collision geometry" in localization_unavailable(bare) and localization_unavailable(robot) is None
    estimates = estimate_from_log(bare, part)
    assert estimates.localization is None
    assert "no collision geometry" in estimates.not_estimated[LOCALIZATION]
    full = estimate_from_log(robot, part)
    assert full.not_estimated == {}
    np.testing.assert_array_equal(estimates.internal_residual, full.internal_residual)
    np.testing.assert_array_equal(estimates.contact_detected, full.contact_detected)
    assert estimates.contact_detected[-1]  # the push from 0.5 s is detected
    path = write_log(part, tmp_path / "part.csv")
    args = ["--robot", str(tmp_path / "no_collision.yaml"), "--log", str(path), "--out", str(tmp_path), "--no-replay"]
    assert estimate_from_log_app.main(args) == 0
    assert f"not estimated: {LOCALIZATION}: the model's links have no collision geometry" in capsys.readouterr().out
    metrics = json.loads((tmp_path / "estimate_from_log" / "metrics.json").read_text())
    (entry,) = metrics["not_estimated"]
    assert entry["estimate"] == LOCALIZATION and "no collision geometry" in entry["reason"]
    (contact,) = metrics["contacts"]
    assert contact["link"] is None and np.linalg.norm(contact["mean_force_world_N"]) > 10.0
    assert_estimate_files_agree(tmp_path / "estimate_from_log")  # the localization's columns empty, null


def pq_column(folder: Path, name: str) -> list:
    import pyarrow.parquet as pq

    return pq.read_table(folder / "estimates.parquet").column(name).to_pylist()


def assert_estimate_files_agree(folder: Path) -> None:
    """estimates.parquet holds estimates.csv's columns, in its order, with its values (bit
    for bit: the CSV writes repr), empty CSV cells as nulls."""
    import csv

    import pyarrow.parquet as pq

    with open(folder / "estimates.csv", newline="") as stream:
        header, *rows = list(csv.reader(stream))
    table = pq.read_table(folder / "estimates.parquet")
    assert table.column_names == header and table.num_rows == len(rows) > 0
    for i, name in enumerate(header):
        cells = [row[i] for row in rows]
        values = table.column(name).to_pylist()
        if all(v is None for v in values):
            assert cells == [""] * len(rows), name
        elif name == "contact_link":
            assert values == cells
        elif name in ("contact_detected", "localization_status"):
            assert values == [int(c) for c in cells], name
        else:
            np.testing.assert_array_equal(np.array(values), np.array([float(c) for c in cells]), err_msg=name)


def test_app_end_to_end(simulated, tmp_path: Path):
    from apps.estimate_from_log import main

    log, online = simulated
    path = write_log(log, tmp_path / "push.parquet")
    assert main(["--robot", "hrp4_like", "--log", str(path), "--out", str(tmp_path), "--headless"]) == 0
    folder = tmp_path / "estimate_from_log"
    for name in ("estimates.csv", "contact_forces.png", "metrics.json", "replay.html"):
        assert (folder / name).stat().st_size > 0, name
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["samples"] == log.num_samples and metrics["real_time_factor"] > 0
    (contact,) = metrics["contacts"]
    assert contact["link"] == online.push.body_name
    header = (folder / "estimates.csv").read_text().splitlines()[0].split(",")
    assert header[:2] == ["time", "contact_detected"] and "residual_R_KNEE_P" in header
    assert_estimate_files_agree(folder)
    assert "R_SHOULDER_Y_LINK" in pq_column(folder, "contact_link")  # not vacuous: a localized link
    assert metrics["stamps"]["case"] == "uniform" and metrics["not_estimated"] == []
    scene = read_static_html((folder / "replay.html").read_text())
    assert any(path.startswith("/drake/estimated_force") for path in scene.objects), sorted(scene.objects)[:5]
    assert any("R_SHOULDER_Y_LINK" in path for path in scene.tracks)  # the robot moves in the recording
    arrow = [v for path, tracks in scene.tracks.items() if path.startswith("/drake/estimated_force") for v in tracks]
    assert arrow, "the estimated force's arrow is animated"
    # A bad log is a clean error (exit code 2), not a traceback.
    assert main(["--log", str(tmp_path / "missing.csv"), "--out", str(tmp_path), "--no-replay"]) == 2


def test_benchmark_reports_the_real_time_factor():
    """``make benchmark``'s figure for the issue's floor (timings are not asserted)."""
    from apps.benchmark import benchmark_log_estimation

    blas_threads = os.environ.get("OPENBLAS_NUM_THREADS")
    row = benchmark_log_estimation(0.7, repeats=1)
    assert row["blas_threads"] == "1" and os.environ.get("OPENBLAS_NUM_THREADS") == blas_threads  # restored
    assert row["num_joints"] == 34 and row["log_rate_hz"] == pytest.approx(1000.0)
    assert row["log_seconds"] == pytest.approx(0.7, abs=2e-3)
    assert 0.1 < row["contact_fraction"] < 0.5  # the push from 0.5 s
    assert row["real_time_factor"] == pytest.approx(row["log_seconds"] / row["wall_s"])


@pytest.mark.parametrize("time_constant", [None, 0.05])
def test_localizer_replay_equals_stepping_its_updates(simulated, robot, time_constant):
    """``ContactLocalizer.replay`` (running means, the exponential tail by a linear filter,
    localizations only where due) equals stepping ``advance`` sample by sample, over a
    detection pattern with two contacts, the second shorter than the settle time."""
    from systems.residuals.contact_estimation import ContactLocalizer

    log, online = simulated
    inputs = log_inputs(robot, log)
    N = 1200
    x = inputs.state[:N]
    w, r = online.external_wrench_world[:N], online.internal_residual[:N]
    detected = np.zeros(N, dtype=bool)
    detected[520:1100] = True
    detected[1130:1180] = True  # 50 ms: never settled (settle time 0.1 s)
    localizer = ContactLocalizer(
        robot.plant,
        robot.scene_graph,
        exclude_bodies=robot.excluded_bodies,
        period=inputs.period,
        localization_period=0.01,
        settle_time=0.1,
        averaging_time_constant=time_constant,
    )
    times = np.arange(N) * inputs.period
    state = localizer.initial_state()
    stepped = np.empty((N, 14))
    states = {}
    for k in range(N):
        state = localizer.advance(state, times[k], x[k], w[k], r[k], bool(detected[k]))
        stepped[k] = state[3]
        states[k] = state
    replayed = localizer.replay(times, x, w, r, detected)
    # replay_from's end state is the stepped one: after the last sample (idle, the means of
    # the first contact, the raw inputs of the second's last localization) and in the
    # middle of an averaging (sample 700), from which it goes on as stepping does.
    for stop in (N, 701):
        _, end = localizer.replay_from(None, times[:stop], x[:stop], w[:stop], r[:stop], detected[:stop])
        for a, b in zip(end, states[stop - 1]):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    rest, _ = localizer.replay_from(end, times[701:], x[701:], w[701:], r[701:], detected[701:])
    np.testing.assert_allclose(rest[:, :8], stepped[701:, :8], rtol=1e-9, atol=1e-9)
    # end_only: the same state with one localization (the means are the last contact's:
    # after sample N - 1 that contact never settled, so the stepped means are the first's).
    for stop in (N, 701):
        out, end = localizer.replay_from(
            None, times[:stop], x[:stop], w[:stop], r[:stop], detected[:stop], end_only=True
        )
        assert out is None
        for i, (a, b) in enumerate(zip(end, states[stop - 1])):
            if i != 1 or stop == 701:
                np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(replayed[:, :2], stepped[:, :2])  # status, link
    finite = np.isfinite(stepped)
    np.testing.assert_array_equal(finite, np.isfinite(replayed))
    np.testing.assert_allclose(replayed[finite], stepped[finite], rtol=1e-9, atol=1e-9)
    assert (stepped[600:1100, 0] == VALID).mean() > 0.9  # not vacuous: it localized


@pytest.mark.parametrize("split", [300, 800])
def test_a_replay_continued_from_where_it_left_off_equals_the_whole(simulated, robot, split):
    """``replay_contact_estimation`` over the log's first samples and then, from their
    ``end`` state, over the rest (before the push, split 300; in the middle of the
    localizer's averaging, split 800) gives what one replay of the whole log gives: the
    residuals, the detector and the localizer's results, and the same end state."""
    from diagrams.residuals.log_estimation import build_offline_estimators, make_detector, make_localizer
    from systems.residuals.offline import replay_contact_estimation

    log, _ = simulated
    settings = LogEstimationSettings()
    inputs = log_inputs(robot, log)
    period = inputs.period
    times = np.arange(len(inputs.time)) * period

    def replay(rows, start=None):
        _, internal, external = build_offline_estimators(robot, settings, period)
        return replay_contact_estimation(
            internal,
            external,
            lambda *_: make_detector(robot, settings, period),
            make_localizer(robot, settings, period),
            inputs.state[rows],
            inputs.joint_torque[rows],
            inputs.known_wrenches[rows],
            start=start,
            times=times[rows],
        )

    whole = replay(slice(None))
    first = replay(slice(0, split))
    rest = replay(slice(split, None), start=first.end)
    assert first.end.detected == (split == 800) and whole.contact_detected[600:1400].all()
    scale = np.abs(whole.internal).max()
    np.testing.assert_allclose(rest.internal, whole.internal[split:], rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(
        rest.external_wrench_world, whole.external_wrench_world[split:], rtol=0, atol=1e-11 * scale
    )
    np.testing.assert_array_equal(rest.contact_detected, whole.contact_detected[split:])
    for key in ("status", "body_index"):
        np.testing.assert_array_equal(rest.localization[key], whole.localization[key][split:])
    for key in ("point_world", "force_world"):
        np.testing.assert_allclose(rest.localization[key], whole.localization[key][split:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(rest.end.integral, whole.end.integral, rtol=1e-11)
    np.testing.assert_array_equal(rest.end.detector[:4], whole.end.detector[:4])
    for a, b in zip(rest.end.localizer, whole.end.localizer):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)


# ---------------------------------------------------------------------------------------
# Logs without joint torques, or whose feet log only their normal forces (issue 32).
# ---------------------------------------------------------------------------------------


def _first_second_without_base(simulated) -> RobotLog:
    log, _ = simulated
    return replace(log.select(slice(0, 1000)), base_pose=None, base_velocity=None)


def test_a_log_without_torques_estimates_the_base_state_and_the_external_residual(simulated, robot, tmp_path, capsys):
    """The log of the push without its tau_ columns and without base state: the invariant
    EKF's base state and IMU biases are those of the same log with torques (bit for bit:
    the filter never reads torques), and close to the simulator's base (the log's own before
    it was removed: the truth plus the stand-in estimator's white noise; measured 4.0 mm,
    0.11 deg, 8 mm/s); the external residual (eq. 16, no torques in it) is the one of the log
    with torques; the internal residual, the detection and the localization are not
    estimated, and the app says so (printout, metrics.json, empty columns)."""
    from diagrams.residuals.log_estimation import DETECTION, EXTERNAL_RESIDUAL, INTERNAL_RESIDUAL, LOCALIZATION

    log, _ = simulated
    part = _first_second_without_base(simulated)
    with_torques = estimate_from_log(robot, part)
    assert with_torques.not_estimated == {} and with_torques.base_state.startswith("invariant EKF")
    no_torques = replace(part, joint_torques=None)
    estimates = estimate_from_log(robot, no_torques)
    np.testing.assert_array_equal(estimates.base_pose, with_torques.base_pose)
    np.testing.assert_array_equal(estimates.base_velocity, with_torques.base_velocity)
    np.testing.assert_array_equal(estimates.imu_bias, with_torques.imu_bias)
    np.testing.assert_allclose(estimates.external_wrench_world, with_torques.external_wrench_world, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(estimates.force_world, estimates.external_wrench_world[:, 3:])
    assert np.linalg.norm(estimates.force_world[-1]) > 10.0  # the push from 0.5 s, not vacuous
    truth_pose, truth_velocity = log.base_pose[:1000], log.base_velocity[:1000]
    assert np.abs(estimates.base_pose[:, 4:] - truth_pose[:, 4:]).max() < 0.01
    cos_half = np.abs(np.einsum("ij,ij->i", estimates.base_pose[:, :4], truth_pose[:, :4]))
    assert np.degrees(2.0 * np.arccos(np.minimum(cos_half, 1.0))).max() < 0.25
    assert np.abs(estimates.base_velocity[:, 3:] - truth_velocity[:, 3:]).max() < 0.02
    assert estimates.internal_residual is None and estimates.contact_detected is None
    assert estimates.test_statistics is None and estimates.localization is None and estimates.contacts() == []
    assert list(estimates.not_estimated) == [INTERNAL_RESIDUAL, DETECTION, LOCALIZATION]
    assert "no joint torques" in estimates.not_estimated[INTERNAL_RESIDUAL]
    assert EXTERNAL_RESIDUAL not in estimates.not_estimated
    # The app on the CSV without tau_ columns.
    path = write_log(no_torques, tmp_path / "no_torques.csv")
    assert not [c for c in path.read_text().splitlines()[0].split(",") if "tau_" in c]
    assert read_log(path).joint_torques is None
    assert estimate_from_log_app.main(["--log", str(path), "--out", str(tmp_path), "--headless"]) == 0
    out = capsys.readouterr().out
    assert f"not estimated: {INTERNAL_RESIDUAL}: the log has no joint torques" in out
    assert f"not estimated: {DETECTION}" in out and "no contact detected" not in out
    folder = tmp_path / "estimate_from_log"
    metrics = json.loads((folder / "metrics.json").read_text())
    assert [e["estimate"] for e in metrics["not_estimated"]] == [INTERNAL_RESIDUAL, DETECTION, LOCALIZATION]
    assert metrics["contacts"] is None and metrics["base_state"].startswith("invariant EKF")
    for name in ("contact_forces.png", "replay.html"):
        assert (folder / name).stat().st_size > 0, name
    assert_estimate_files_agree(folder)
    header = (folder / "estimates.csv").read_text().splitlines()[0].split(",")
    base = np.loadtxt(folder / "estimates.csv", delimiter=",", skiprows=1, usecols=[header.index("base_z")])
    np.testing.assert_allclose(base, estimates.base_pose[:, 6], rtol=0, atol=1e-12)
    force = np.loadtxt(folder / "estimates.csv", delimiter=",", skiprows=1, usecols=[header.index("force_x")])
    np.testing.assert_allclose(force, estimates.force_world[:, 0], rtol=0, atol=1e-12)
    assert all(v is None for v in pq_column(folder, "residual_R_KNEE_P"))
    assert all(v is None for v in pq_column(folder, "contact_detected"))


def test_a_log_with_only_the_feet_normal_forces_estimates_the_base_state(simulated, robot, tmp_path, capsys):
    """The feet log only their normal forces (wrench_<frame>_fz alone), no torques, no base
    state: the EKF's contact flags come from the normal forces, the same as from the full
    wrenches on this standing log, so the base state is that of the full log, bit for bit;
    neither residual runs (both subtract the feet's full wrenches), nor the detection and
    localization, each named with its reason; with torques, the internal residual is still
    not estimated, for want of the wrenches. The app writes the base state and no force plot."""
    from diagrams.residuals.log_estimation import DETECTION, EXTERNAL_RESIDUAL, INTERNAL_RESIDUAL, LOCALIZATION

    part = _first_second_without_base(simulated)
    reference = estimate_from_log(robot, replace(part, joint_torques=None))
    normal = replace(
        part, joint_torques=None, wrenches={}, normal_forces={frame: w[:, 5] for frame, w in part.wrenches.items()}
    )
    estimates = estimate_from_log(robot, normal)
    assert "left normal force, right normal force" in estimates.base_state
    np.testing.assert_array_equal(estimates.base_pose, reference.base_pose)
    np.testing.assert_array_equal(estimates.base_velocity, reference.base_velocity)
    assert estimates.external_wrench_world is None and estimates.force_world is None
    assert list(estimates.not_estimated) == [INTERNAL_RESIDUAL, EXTERNAL_RESIDUAL, DETECTION, LOCALIZATION]
    assert "no 6-axis F/T wrench" in estimates.not_estimated[EXTERNAL_RESIDUAL]
    with_torques = estimate_from_log(robot, replace(normal, joint_torques=part.joint_torques))
    assert "no 6-axis F/T wrench" in with_torques.not_estimated[INTERNAL_RESIDUAL]
    np.testing.assert_array_equal(with_torques.base_pose, reference.base_pose)
    path = write_log(normal, tmp_path / "normal.parquet")
    back = read_log(path)
    assert back.wrenches == {} and sorted(back.normal_forces) == sorted(part.wrenches)
    assert estimate_from_log_app.main(["--log", str(path), "--out", str(tmp_path), "--no-replay"]) == 0
    out = capsys.readouterr().out
    assert f"not estimated: {EXTERNAL_RESIDUAL}: the feet" in out and "normal-force frames" in out
    folder = tmp_path / "estimate_from_log"
    assert not (folder / "contact_forces.png").exists()
    metrics = json.loads((folder / "metrics.json").read_text())
    assert len(metrics["not_estimated"]) == 4
    assert_estimate_files_agree(folder)
    header = (folder / "estimates.csv").read_text().splitlines()[0].split(",")
    base = np.loadtxt(folder / "estimates.csv", delimiter=",", skiprows=1, usecols=[header.index("base_x")])
    np.testing.assert_allclose(base, estimates.base_pose[:, 4], rtol=0, atol=1e-12)
    wrong = replace(normal, normal_forces={"l_foot": part.wrenches["L_FT_SENSOR_child"][:, 5]})
    with pytest.raises(ValueError, match=r"normal forces \['l_foot'\] are not at F/T or sole frames"):
        log_inputs(robot, wrong)
    one_foot = replace(normal, normal_forces={"L_FT_SENSOR_child": part.wrenches["L_FT_SENSOR_child"][:, 5]})
    with pytest.raises(ValueError, match=r"no base pose and velocity .* \(no force for the feet \['right'\]\)"):
        log_inputs(robot, one_foot)


def test_a_nao_log_with_fsr_feet_and_no_torques_estimates_the_base_state(tmp_path, capsys):
    """nao_like standing still (no F/T sensors): joint positions, an IMU reading gravity and
    each foot's four FSRs (fsr_<side>_<corner> columns) carrying half the weight, no torques,
    no base state. The EKF runs on the FSR sums' contact flags and keeps the base where it
    started, standing on level ground (within 1 mm and 0.05 deg over 0.5 s); the internal
    residual, the detection and the localization are not estimated."""
    from diagrams.residuals.log_estimation import (
        EXTERNAL_RESIDUAL,
        INTERNAL_RESIDUAL,
        LOCALIZATION,
        standing_base_pose,
    )
    from systems.common.topology import floating_base_topology
    from systems.observer.fsr_sensing import FSR_NAMES

    nao = build_estimator_plant("nao_like")
    plant, samples = nao.plant, 500
    joints = floating_base_topology(plant).joints
    nq = plant.num_positions()
    q = nao.standing_state[:nq]
    start = standing_base_pose(nao, q)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, np.concatenate((start, q[7:])))
    R_WI = nao.humanoid.imu_frame.CalcPoseInWorld(context).rotation().matrix()
    weight = plant.CalcTotalMass(context) * 9.81
    positions = np.tile([q[j.position_start()] for j in joints], (samples, 1))
    log = RobotLog(
        time=1e-3 * np.arange(samples),
        joint_names=tuple(j.name() for j in joints),
        joint_positions=positions,
        joint_velocities=np.zeros_like(positions),
        fsr_names=FSR_NAMES,
        fsr_forces=np.full((samples, len(FSR_NAMES)), weight / len(FSR_NAMES)),
        imu_angular_velocity=np.zeros((samples, 3)),
        imu_linear_acceleration=np.tile(R_WI.T @ [0.0, 0.0, 9.81], (samples, 1)),
    )
    estimates = estimate_from_log(nao, log)
    assert "left FSR sum, right FSR sum" in estimates.base_state
    assert np.abs(estimates.base_pose[:, 4:] - start[4:]).max() < 1e-3
    cos_half = np.abs(estimates.base_pose[:, :4] @ start[:4])
    assert np.degrees(2.0 * np.arccos(np.minimum(cos_half, 1.0))).max() < 0.05
    assert INTERNAL_RESIDUAL in estimates.not_estimated and LOCALIZATION in estimates.not_estimated
    # No F/T frame and no torques: the ground's wrenches cannot be estimated, so neither can the external residual.
    assert estimates.external_wrench_world is None and "no joint torques" in estimates.not_estimated[EXTERNAL_RESIDUAL]
    path = write_log(log, tmp_path / "nao.csv")
    args = ["--robot", "nao_like", "--log", str(path), "--out", str(tmp_path), "--no-replay"]
    assert estimate_from_log_app.main(args) == 0
    assert "foot contact from: left FSR sum, right FSR sum" in capsys.readouterr().out
    unloaded = replace(log, fsr_forces=np.zeros_like(log.fsr_forces), fsr_names=FSR_NAMES)
    assert estimate_from_log(nao, unloaded).base_pose.shape == (samples, 7)  # runs, on the IMU alone
    left_only = replace(log, fsr_names=FSR_NAMES[:4], fsr_forces=log.fsr_forces[:, :4])
    with pytest.raises(ValueError, match=r"no force for the feet \['right'\]"):
        log_inputs(nao, left_only)


def _yaw_deg(pose: np.ndarray) -> np.ndarray:
    """Yaw (deg, about world z) of Drake free-joint poses (N, 7) [w, x, y, z, ...]."""
    w, x, y, z = pose[:, :4].T
    return np.degrees(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


@pytest.mark.slow
def test_the_ekf_starts_from_the_gyro_bias_measured_at_rest(robot, tmp_path, capsys):
    """hrp4_like standing still 3 s (its first 0.1 s of settling dropped: the log starts
    still), a constant 0.35 deg/s added to every gyro axis of the log: the detected still
    window is the whole log, the at-rest gyro bias is within 4 standard errors of the
    truth on each axis, and the EKF's yaw drift against the simulator's yaw (the logged base
    pose, removed before estimating) is under 0.1 deg at the end, less than a fifth of the
    drift without the initialisation (which cannot learn the vertical bias while standing:
    measured 1.03 deg vs 0.001 deg). The bias is still tracked after (the EKF's last vertical
    gyro bias within 1e-4 rad/s), --calibrate-first gives the window, and the app reports it."""
    log, _ = simulate_push_log("hrp4_like", duration=3.1, push_start=10.0, push_end=11.0)  # no push in the log
    log = log.select(slice(100, None))
    log.time = log.time - log.time[0]
    truth_yaw = _yaw_deg(log.base_pose)
    bias = np.radians(0.35)
    biased = replace(log, base_pose=None, base_velocity=None, imu_angular_velocity=log.imu_angular_velocity + bias)
    with_rest = log_inputs(robot, biased)
    at_rest = with_rest.at_rest
    assert at_rest.source == "detected" and at_rest.start_s == 0.0
    assert at_rest.end_s == pytest.approx(3.0, abs=2e-3) and at_rest.samples == log.num_samples
    assert np.all(np.abs(at_rest.gyro_bias - bias) <= 4.0 * at_rest.gyro_bias_std), (at_rest.gyro_bias, bias)
    assert np.all(at_rest.gyro_bias_std >= 1e-4) and abs(at_rest.accel_magnitude_error) < 0.05
    without = log_inputs(robot, biased, LogEstimationSettings(at_rest_bias=False))
    assert without.at_rest is None
    drift_with = abs(np.mean(_yaw_deg(with_rest.state[-100:, :7]) - truth_yaw[-100:]))
    drift_without = abs(np.mean(_yaw_deg(without.state[-100:, :7]) - truth_yaw[-100:]))
    assert drift_with < 0.1 and drift_with < 0.2 * drift_without, (drift_with, drift_without)
    assert abs(with_rest.imu_bias[-1, 2] - bias) < 1e-4
    given = log_inputs(robot, biased, LogEstimationSettings(noise_calibration_time=1.0))
    assert given.at_rest.source == "given" and given.at_rest.samples == 1000
    assert np.all(np.abs(given.at_rest.gyro_bias - bias) <= 4.0 * given.at_rest.gyro_bias_std)
    with pytest.raises(ValueError, match="still window of 5.0 s"):
        log_inputs(robot, biased, LogEstimationSettings(noise_calibration_time=5.0))
    path = write_log(biased.select(slice(0, 1000)), tmp_path / "still.parquet")
    assert estimate_from_log_app.main(["--log", str(path), "--out", str(tmp_path), "--headless", "--no-replay"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"at-rest IMU bias: still window 0\.000-1\.000 s \(detected\), initial gyro bias \[0\.3", out), out
    metrics = json.loads((tmp_path / "estimate_from_log" / "metrics.json").read_text())
    assert metrics["at_rest_imu_bias"]["source"] == "detected"
    assert metrics["at_rest_imu_bias"]["still_window_s"] == pytest.approx([0.0, 1.0])
    np.testing.assert_allclose(metrics["at_rest_imu_bias"]["gyro_bias_rad_s"], bias, atol=1e-3)


def test_the_still_window_is_the_first_still_span_long_enough(simulated, robot, tmp_path, capsys):
    """The simulated log starts as the robot settles on its knees (joint speeds up to 0.26
    rad/s in its first 20 ms), then stands still until the push (0.5 s) moves it: a still
    span of about 0.45 s. With the default minimum of 0.5 s no still window is found, the
    EKF starts from a zero bias and the printout says so; with a minimum of 0.3 s the
    window is that span, after the settling (not from the first sample); a gyro turning at
    5 deg/s is never still."""
    from diagrams.residuals.log_estimation import STILL_MIN_DURATION, first_still_window, still_mask, still_samples
    from systems.estimation.ekf_settings import EkfSettings

    log = _first_second_without_base(simulated)
    inputs = log_inputs(robot, log)
    assert inputs.at_rest.source == "none" and not inputs.at_rest.used
    assert inputs.at_rest.end_s < STILL_MIN_DURATION and "never still for 0.5 s" in inputs.at_rest.reason
    shorter = log_inputs(robot, log, LogEstimationSettings(ekf=EkfSettings(still_min_duration=0.3)))
    window = shorter.at_rest
    assert window.source == "detected" and 0.0 < window.start_s <= 0.1 and 0.4 <= window.end_s < 0.55, window
    assert window.samples == round((window.end_s - window.start_s) / 1e-3)
    later = log.select(slice(100, None))  # settled at 0.1 s, pushed from 0.5 s: still up to shortly after
    assert 400 <= still_samples(later.imu_angular_velocity, later.joint_velocities, 1e-3) < 450
    turning = later.imu_angular_velocity + [0.0, 0.0, np.radians(5.0)]
    assert still_samples(turning, later.joint_velocities, 1e-3) < 10  # the averaged gyro tells it within 10 ms
    assert not still_mask(turning, later.joint_velocities, 1e-3)[10:].any()
    assert first_still_window(np.array([1, 0, 1, 1, 1, 0, 1, 1, 1, 1], bool), 3) == (2, 5)
    assert first_still_window(np.array([1, 1, 0, 1, 1], bool), 3) is None
    path = write_log(log, tmp_path / "moving.parquet")
    assert estimate_from_log_app.main(["--log", str(path), "--out", str(tmp_path), "--headless", "--no-replay"]) == 0
    out = capsys.readouterr().out
    assert "at-rest IMU bias: none (the log is never still for 0.5 s" in out, out
    metrics = json.loads((tmp_path / "estimate_from_log" / "metrics.json").read_text())
    assert metrics["at_rest_imu_bias"]["source"] == "none" and metrics["at_rest_imu_bias"]["gyro_bias_rad_s"] is None


def test_ekf_settings_load_from_yaml_override_and_refuse_bad_values(tmp_path):
    """``load_ekf_settings``: the defaults are the estimator's documented constants; a YAML
    sets some keys (the others keep their defaults); a command-line override wins over the
    file; an unknown key, a negative, zero, NaN or non-numeric value, and an off threshold
    above the on threshold are refused naming the key."""
    from systems.estimation import base_state_estimator as bse
    from systems.estimation.ekf_settings import EkfSettings, load_ekf_settings

    default = load_ekf_settings()
    assert default == EkfSettings()
    assert (
        default.gyro_noise_density == bse.GYRO_NOISE_DENSITY and default.accel_noise_density == bse.ACCEL_NOISE_DENSITY
    )
    assert default.gyro_bias_random_walk == bse.GYRO_BIAS_RANDOM_WALK
    assert default.contact_on_weight_fraction == 0.10 and default.contact_off_weight_fraction == 0.05
    assert default.still_min_duration == 0.5
    path = tmp_path / "imu.yaml"
    path.write_text("gyro_noise_density: 3.5e-4\ncontact_on_weight_fraction: 0.15\n")
    loaded = load_ekf_settings(path)
    assert loaded.gyro_noise_density == 3.5e-4 and loaded.contact_on_weight_fraction == 0.15
    assert loaded.accel_noise_density == default.accel_noise_density
    overridden = load_ekf_settings(path, gyro_noise_density=1e-3, accel_noise_density=None)
    assert overridden.gyro_noise_density == 1e-3 and overridden.contact_on_weight_fraction == 0.15
    bad = {
        "gyro_nosie_density: 1e-4\n": r"unknown keys \['gyro_nosie_density'\]",
        "accel_noise_density: -1e-3\n": "accel_noise_density must be a finite number > 0, got -0.001",
        "gyro_bias_random_walk: .nan\n": "gyro_bias_random_walk must be a finite number > 0, got nan",
        "still_joint_speed: 0\n": "still_joint_speed must be a finite number > 0",
        "still_min_duration: fast\n": "still_min_duration must be a number, got 'fast'",
        "contact_off_weight_fraction: 0.2\n": "contact_off_weight_fraction 0.2 is above contact_on_weight_fraction 0.1",
        "- 1\n": "must hold a mapping",
    }
    for text, message in bad.items():
        path.write_text(text)
        with pytest.raises(ValueError, match=message):
            load_ekf_settings(path)
    with pytest.raises(ValueError, match="gyro_noise_density must be a finite number > 0, got inf"):
        load_ekf_settings(None, gyro_noise_density=float("inf"))
    with pytest.raises(ValueError, match="unknown EKF setting 'gyro'"):
        load_ekf_settings(None, gyro=1.0)


def test_ekf_settings_reach_the_estimator_and_the_app(simulated, robot, tmp_path, capsys):
    """The settings are the EKF's: a minimum still duration shorter than the log's still
    start (0.4 s) gives an at-rest bias, the default 0.5 s none; a larger gyro noise density changes the base estimate;
    contact thresholds above what a standing foot carries leave the filter without contact
    (its base drifts away from the logged one); the app reads --estimator-settings and the
    overrides (recorded in metrics.json) and refuses a bad file naming the key."""
    from systems.estimation.ekf_settings import EkfSettings

    log, _ = simulated
    still = replace(log.select(slice(100, 500)), base_pose=None, base_velocity=None)
    still.time = still.time - still.time[0]
    default = log_inputs(robot, still)  # still 0.4 s (pushed from 0.5 s), under the default 0.5 s
    assert default.at_rest.source == "none" and "never still for 0.5 s" in default.at_rest.reason
    shorter = log_inputs(robot, still, LogEstimationSettings(ekf=EkfSettings(still_min_duration=0.3)))
    assert shorter.at_rest.source == "detected" and shorter.at_rest.end_s == pytest.approx(0.4, abs=2e-3)
    noisier = log_inputs(robot, still, LogEstimationSettings(ekf=EkfSettings(gyro_noise_density=1e-2)))
    assert np.abs(noisier.state[:, :7] - default.state[:, :7]).max() > 1e-6
    unanchored = log_inputs(
        robot,
        still,
        LogEstimationSettings(ekf=EkfSettings(contact_on_weight_fraction=0.95, contact_off_weight_fraction=0.9)),
    )
    truth = log.base_pose[100:500, 4:7]  # the simulator's, plus its 1 mm-level noise: compare means

    def offset(inputs) -> float:
        return float(np.linalg.norm(np.mean(inputs.state[-100:, 4:7] - truth[-100:], axis=0)))

    print("base position offset over the last 0.1 s, m:", offset(default), offset(unanchored))
    assert offset(default) < 3e-3 and offset(unanchored) > 2.0 * offset(default)
    path = write_log(still, tmp_path / "still.parquet")
    settings = tmp_path / "imu.yaml"
    settings.write_text("gyro_noise_density: 3.5e-4\nstill_min_duration: 0.2\n")
    args = ["--log", str(path), "--out", str(tmp_path), "--headless", "--no-replay", "--estimator-settings"]
    assert estimate_from_log_app.main([*args, str(settings), "--accel-noise-density", "2e-3"]) == 0
    metrics = json.loads((tmp_path / "estimate_from_log" / "metrics.json").read_text())
    ekf = metrics["settings"]["ekf"]
    assert ekf["gyro_noise_density"] == 3.5e-4 and ekf["accel_noise_density"] == 2e-3
    assert ekf["still_min_duration"] == 0.2 and ekf["contact_on_weight_fraction"] == 0.1
    assert metrics["at_rest_imu_bias"]["source"] == "detected"
    capsys.readouterr()
    settings.write_text("gyro_noise_density: -1\n")
    assert estimate_from_log_app.main([*args, str(settings)]) == 2
    assert "gyro_noise_density must be a finite number > 0" in capsys.readouterr().err
