"""The contact-aided invariant EKF (systems.estimation.base_state_estimator) against physics
and truth: synthetic IMU and foot kinematics for the numpy core (analytic signals of a
robot standing, moving at constant velocity, with a tilted initial guess, with IMU
noise), and the Drake wrapper on the hrp4_like station (its simulated IMU, encoders and
F/T sensors) against the plant's true base state, standing and pushed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.station.humanoid_station import add_humanoid_station
from systems.dynamics.base_state import quaternion_to_rotation
from systems.estimation.base_state_estimator import (
    ACCEL_NOISE_DENSITY,
    GYRO_NOISE_DENSITY,
    KINEMATICS_NOISE_STD,
    ContactAidedInvariantEkf,
    FootContactFromForceTorque,
    InvariantEkfBaseStateEstimator,
    base_to_imu,
    contact_flags_from_wrenches,
    imu_to_base,
    rotation_to_quaternion,
    so3_exp,
    so3_gamma,
)
from systems.simulation.disturbances import Push, PushSource, Step

G = np.array([0.0, 0.0, -9.81])
DT = 1e-3
#: Two feet fixed on the ground, m.
FEET = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])


def rot_z(angle: float) -> np.ndarray:
    return so3_exp(np.array([0.0, 0.0, angle]))


def tilt_and_yaw(R_est: np.ndarray, R_true: np.ndarray) -> tuple[float, float]:
    """(tilt, yaw) of the world-frame error E = R_est R_trueᵀ, rad: the angle between E's z
    axis and the vertical, and E's rotation about the vertical."""
    E = R_est @ R_true.T
    tilt = math.acos(min(1.0, max(-1.0, E[2, 2])))
    yaw = math.atan2(E[1, 0] - E[0, 1], E[0, 0] + E[1, 1])
    return tilt, yaw


def synthetic_step(ekf, R, v, p, omega_body, rng=None, kin_std=0.0):
    """One filter step on exact signals of a body moving with constant body-frame ω and
    constant world velocity v (so the specific force is Rᵀ(−g)), both feet fixed."""
    h = (FEET - p) @ R  # rows: Rᵀ (d_j − p)
    a = R.T @ (-G)
    omega = np.array(omega_body, dtype=float)
    if rng is not None:
        omega = omega + rng.normal(0.0, GYRO_NOISE_DENSITY / math.sqrt(DT), 3)
        a = a + rng.normal(0.0, ACCEL_NOISE_DENSITY / math.sqrt(DT), 3)
        h = h + rng.normal(0.0, kin_std, h.shape)
    ekf.correct_kinematics(h, [True, True])
    ekf.propagate(omega, a, DT)


# ---------------------------------------------------------------------------------------
# Lie helpers.
# ---------------------------------------------------------------------------------------


def test_gamma_functions_match_their_series():
    phi = np.array([0.3, -0.7, 0.5])
    K = np.array([[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]])
    for m in range(3):
        series, term = np.zeros((3, 3)), np.eye(3)
        for n in range(30):
            series += term / math.factorial(n + m)
            term = term @ K
        np.testing.assert_allclose(so3_gamma(phi, m), series, atol=1e-13)
        np.testing.assert_allclose(so3_gamma(1e-8 * phi, m), np.eye(3) / math.factorial(m), atol=1e-8)


def test_quaternion_round_trip_and_imu_base_transform():
    rng = np.random.default_rng(0)
    for _ in range(20):
        R = so3_exp(rng.normal(size=3) * 2.0)
        np.testing.assert_allclose(quaternion_to_rotation(rotation_to_quaternion(R)), R, atol=1e-12)
    R_BI, p_BI = so3_exp([0.1, 0.2, -0.3]), np.array([0.01, -0.02, 0.05])
    pose = np.concatenate([rotation_to_quaternion(so3_exp([0.2, -0.1, 1.0])), [0.3, 0.1, 0.8]])
    velocity = np.array([0.5, -0.2, 0.3, 0.1, 0.2, -0.05])
    R, p, v = base_to_imu(pose, velocity, R_BI, p_BI)
    omega_I = R.T @ velocity[:3]
    pose2, velocity2 = imu_to_base(R, p, v, omega_I, R_BI, p_BI)
    np.testing.assert_allclose(pose2, pose, atol=1e-12)
    np.testing.assert_allclose(velocity2, velocity, atol=1e-12)


# ---------------------------------------------------------------------------------------
# Numpy core against analytic trajectories.
# ---------------------------------------------------------------------------------------


def test_standing_still_stays_at_truth():
    R, v, p = rot_z(0.4), np.zeros(3), np.array([0.05, 0.0, 0.8])
    ekf = ContactAidedInvariantEkf(2, rotation=R, velocity=v, position=p, gravity=G)
    for _ in range(2000):
        synthetic_step(ekf, R, v, p, np.zeros(3))
    np.testing.assert_allclose(ekf.rotation, R, atol=1e-10)
    np.testing.assert_allclose(ekf.velocity, v, atol=1e-9)
    np.testing.assert_allclose(ekf.position, p, atol=1e-9)
    np.testing.assert_allclose(ekf.foot_positions, FEET, atol=1e-9)
    assert ekf.num_contacts == 2


def test_constant_velocity_turning_trajectory_is_tracked_from_a_velocity_error():
    """Constant world velocity and yaw rate (exact signals); the filter starts 0.2 m/s off
    and converges onto the trajectory (velocity is observable through the contacts). The
    error decays roughly as 1/t once the gain settles (measured: 4.3e-3 m/s at 0.5 s, 1.0e-3
    at 2 s, 6.5e-4 at 3 s)."""
    v = np.array([0.3, -0.1, 0.05])
    yaw_rate = 0.2
    R0, p0 = rot_z(0.1), np.array([0.0, 0.0, 0.8])
    ekf = ContactAidedInvariantEkf(2, rotation=R0, velocity=v + [0.2, 0.0, -0.1], position=p0, gravity=G)
    steps = 3000
    for k in range(steps):
        t = k * DT
        synthetic_step(ekf, rot_z(0.1 + yaw_rate * t), v, p0 + v * t, [0.0, 0.0, yaw_rate])
    t = steps * DT
    R, p = rot_z(0.1 + yaw_rate * t), p0 + v * t
    np.testing.assert_allclose(ekf.velocity, v, atol=1e-3)
    tilt, yaw = tilt_and_yaw(ekf.rotation, R)
    assert tilt < 1e-4 and abs(yaw) < 1e-3
    # The position keeps the offset gathered while the velocity was wrong (unobservable),
    # bounded by the initial error integrated over the convergence time.
    assert np.linalg.norm(ekf.position - p) < 0.05


def test_tilt_converges_yaw_stays():
    """Roll/pitch observable through gravity and contacts; yaw is not (InEKF theory)."""
    R, v, p = rot_z(0.3), np.zeros(3), np.array([0.0, 0.0, 0.8])
    yaw_error = math.radians(10.0)
    R_guess = so3_exp([math.radians(4.0), math.radians(-3.0), yaw_error]) @ R
    ekf = ContactAidedInvariantEkf(2, rotation=R_guess, velocity=v, position=p, gravity=G, initial_orientation_std=0.2)
    tilt0, yaw0 = tilt_and_yaw(ekf.rotation, R)
    assert math.degrees(tilt0) > 4.9
    for _ in range(5000):
        synthetic_step(ekf, R, v, p, np.zeros(3))
    tilt, yaw = tilt_and_yaw(ekf.rotation, R)
    assert math.degrees(tilt) < 0.05
    assert abs(yaw - yaw0) < math.radians(0.1)
    assert np.linalg.norm(ekf.velocity) < 1e-3


def test_drift_with_imu_noise_per_minute():
    """Standing 60 s with BMI088 gyro/accelerometer noise and 2 mm kinematic noise.

    Yaw and position are unobservable and random-walk. Physical scale: the gyro's yaw
    random walk is σ_g √T = 2.44e-4 · √60 = 1.9e-3 rad = 0.11° (1σ) per minute; the bounds
    below (0.5° and 1 cm per minute) are loose. Measured (seed 1): yaw -0.17°, position
    0.95 mm, tilt 0.037°, velocity 5.4 mm/s after 60 s (printed with ``pytest -s``)."""
    rng = np.random.default_rng(1)
    R, v, p = rot_z(0.0), np.zeros(3), np.array([0.0, 0.0, 0.8])
    ekf = ContactAidedInvariantEkf(2, rotation=R, velocity=v, position=p, gravity=G)
    for _ in range(60000):
        synthetic_step(ekf, R, v, p, np.zeros(3), rng=rng, kin_std=KINEMATICS_NOISE_STD)
    tilt, yaw = tilt_and_yaw(ekf.rotation, R)
    drift = np.linalg.norm(ekf.position - p)
    print(
        f"\n60 s drift: yaw {math.degrees(yaw):.4f} deg, position {1e3 * drift:.2f} mm, "
        f"tilt {math.degrees(tilt):.4f} deg, |v| {1e3 * np.linalg.norm(ekf.velocity):.2f} mm/s"
    )
    assert abs(math.degrees(yaw)) < 0.5
    assert drift < 0.01
    assert math.degrees(tilt) < 0.1


def test_contact_switching_adds_and_removes_feet_and_imu_only_propagation():
    R, v, p = np.eye(3), np.zeros(3), np.array([0.0, 0.0, 0.8])
    ekf = ContactAidedInvariantEkf(2, rotation=R, velocity=v, position=p, gravity=G)
    h = (FEET - p) @ R
    ekf.correct_kinematics(h, [True, False])
    assert ekf.in_contact.tolist() == [True, False]
    np.testing.assert_allclose(ekf.foot_positions[0], FEET[0])
    P = ekf.covariance
    np.testing.assert_allclose(P[9:12, 9:12], P[6:9, 6:9] + KINEMATICS_NOISE_STD**2 * np.eye(3))  # (E8)
    assert not P[12:15].any()
    ekf.correct_kinematics(h, [False, True])
    assert ekf.in_contact.tolist() == [False, True]
    assert not ekf.covariance[9:12].any() and not ekf.covariance[:, 9:12].any()
    # No contact: IMU-only propagation, exact for a free fall (specific force 0).
    ekf.correct_kinematics(h, [False, False])
    assert ekf.num_contacts == 0
    for _ in range(100):
        ekf.propagate(np.zeros(3), np.zeros(3), DT)
    np.testing.assert_allclose(ekf.velocity, G * 0.1, atol=1e-12)
    np.testing.assert_allclose(ekf.position, p + 0.5 * G * 0.01, atol=1e-12)


def test_contact_flags_from_wrenches():
    w = np.array([0, 0, 0, 0, 0, 150.0, 1, 2, 3, 5, 5, 10.0])
    np.testing.assert_array_equal(contact_flags_from_wrenches(w, 20.0), [1.0, 0.0])


# ---------------------------------------------------------------------------------------
# Drake wrapper.
# ---------------------------------------------------------------------------------------


def _station_with_estimator(push: Push | None = None):
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, "hrp4_like", noise=True)
    hold = builder.AddSystem(ConstantVectorSource(station.q_hold))
    builder.Connect(hold.get_output_port(), station.desired_position)
    sensors = station.sensors
    contact = builder.AddSystem(FootContactFromForceTorque(len(sensors.ft_sides)))
    builder.Connect(sensors.ft_wrenches, contact.GetInputPort("wrenches"))
    q0 = station.topology.free_joint.position_start()
    estimator = builder.AddSystem(
        InvariantEkfBaseStateEstimator(
            station.plant,
            station.humanoid.imu_frame,
            [station.humanoid.sole_frames[side] for side in sensors.ft_sides],
            initial_base_pose=station.initial_state[q0 : q0 + 7],
        )
    )
    builder.Connect(sensors.imu.angular_velocity, estimator.GetInputPort("angular_velocity"))
    builder.Connect(sensors.imu.linear_acceleration, estimator.GetInputPort("linear_acceleration"))
    builder.Connect(sensors.encoders.GetOutputPort("position"), estimator.GetInputPort("joint_positions"))
    builder.Connect(contact.GetOutputPort("foot_contact"), estimator.GetInputPort("foot_contact"))
    if push is not None:
        source = builder.AddSystem(PushSource(station.plant, [push]))
        builder.Connect(
            source.get_applied_spatial_forces_output_port(), station.plant.get_applied_spatial_force_input_port()
        )
        builder.Connect(station.plant.get_state_output_port(), source.get_state_input_port())
    logs = {
        name: LogVectorOutput(estimator.GetOutputPort(name), builder, DT)
        for name in ("base_pose", "base_velocity", "valid")
    }
    logs["state"] = LogVectorOutput(station.plant.get_state_output_port(), builder, DT)
    return builder.Build(), station, logs


def _run_against_truth(push: Push | None, duration: float) -> dict:
    diagram, station, logs = _station_with_estimator(push)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    data = {k: log.FindLog(context).data() for k, log in logs.items()}
    n = min(d.shape[1] for d in data.values())
    q0 = station.topology.free_joint.position_start()
    v0 = station.plant.num_positions() + station.topology.free_joint.velocity_start()
    x, pose, velocity = data["state"][:, :n], data["base_pose"][:, :n], data["base_velocity"][:, :n]
    tilt = np.array(
        [
            tilt_and_yaw(quaternion_to_rotation(pose[:4, k]), quaternion_to_rotation(x[q0 : q0 + 4, k]))[0]
            for k in range(n)
        ]
    )
    dv = velocity[3:6] - x[v0 + 3 : v0 + 6]
    return {
        "max_tilt_deg": math.degrees(tilt.max()),
        "velocity_rms": float(np.sqrt(np.mean(np.sum(dv**2, axis=0)))),
        "angular_velocity_rms": float(np.sqrt(np.mean(np.sum((velocity[:3] - x[v0 : v0 + 3]) ** 2, axis=0)))),
        "position_error": float(np.linalg.norm(pose[4:7, -1] - x[q0 + 4 : q0 + 7, -1])),
        "true_speed_max": float(np.linalg.norm(x[v0 + 3 : v0 + 6], axis=0).max()),
        "valid_after_first_steps": float(data["valid"][0, 10:].min()),
    }


@pytest.mark.parametrize(
    "push",
    [None, Push("waist", [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], Step(80.0, 1.0, 1.2))],
    ids=["standing", "pushed_80N_0.2s"],
)
def test_hrp4_station_estimate_meets_issue_floors(push):
    """3 s on the hrp4_like station with its noisy sensors (the issue's floors: tilt <= 0.5°,
    linear-velocity RMS <= 0.02 m/s). Measured: standing, max tilt 0.021°, velocity RMS
    0.9 mm/s; pushed (80 N on the waist for 0.2 s, true speed up to 0.24 m/s), max tilt
    0.021°, velocity RMS 1.2 mm/s (printed with ``pytest -s``)."""
    m = _run_against_truth(push, 3.0)
    print("\n", {k: round(v, 5) for k, v in m.items()})
    assert m["valid_after_first_steps"] == 1.0
    assert m["max_tilt_deg"] <= 0.5
    assert m["velocity_rms"] <= 0.02
    assert m["angular_velocity_rms"] <= 0.01
    assert m["position_error"] <= 0.01
    if push is not None:
        assert m["true_speed_max"] > 0.1  # the push really moved the base


def _standalone_estimator():
    from pydrake.multibody.plant import MultibodyPlant

    from models import add_humanoid

    plant = MultibodyPlant(0.0)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    estimator = InvariantEkfBaseStateEstimator(
        plant, handles.imu_frame, [handles.sole_frames["left"], handles.sole_frames["right"]]
    )
    context = estimator.CreateDefaultContext()
    n = estimator.GetInputPort("joint_positions").size()
    estimator.GetInputPort("angular_velocity").FixValue(context, np.zeros(3))
    estimator.GetInputPort("linear_acceleration").FixValue(context, [0.0, 0.0, 9.81])
    estimator.GetInputPort("joint_positions").FixValue(context, np.zeros(n))
    estimator.GetInputPort("foot_contact").FixValue(context, [1.0, 1.0])
    return estimator, context


@pytest.mark.parametrize("port", ["angular_velocity", "linear_acceleration", "joint_positions", "foot_contact"])
def test_nan_input_names_the_port(port):
    estimator, context = _standalone_estimator()
    value = np.array(estimator.GetInputPort(port).Eval(context), dtype=float)
    value[0] = np.nan
    estimator.GetInputPort(port).FixValue(context, value)
    with pytest.raises(ValueError, match=f"InvariantEkfBaseStateEstimator: input '{port}'"):
        estimator.EvalUniquePeriodicDiscreteUpdate(context)


def test_no_contact_is_flagged_and_propagates_on_the_imu():
    estimator, context = _standalone_estimator()
    update = estimator.EvalUniquePeriodicDiscreteUpdate(context)
    context.SetDiscreteState(update)
    assert estimator.GetOutputPort("valid").Eval(context)[0] == 1.0
    estimator.GetInputPort("foot_contact").FixValue(context, [0.0, 0.0])
    # Free fall on the IMU alone: specific force 0.
    estimator.GetInputPort("linear_acceleration").FixValue(context, np.zeros(3))
    v_before = estimator.GetOutputPort("base_velocity").Eval(context)[3:6].copy()
    for _ in range(10):
        context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
    assert estimator.GetOutputPort("valid").Eval(context)[0] == 0.0
    v_after = estimator.GetOutputPort("base_velocity").Eval(context)[3:6]
    np.testing.assert_allclose(v_after - v_before, [0.0, 0.0, -9.81 * 10 * estimator.period], atol=1e-9)
    assert np.isfinite(estimator.GetOutputPort("standard_deviation").Eval(context)).all()
