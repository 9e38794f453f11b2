"""The contact-aided invariant EKF (systems.estimation.base_state_estimator) against physics
and truth: synthetic IMU and foot kinematics for the numpy core (analytic signals of a
robot standing, moving at constant velocity, with a tilted initial guess, with IMU
noise), and the Drake wrapper on the hrp4_like station (its simulated IMU, encoders and
F/T sensors) against the plant's true base state, standing and pushed; the IMU bias states
(E11) against finite differences, an injected gyro bias, and the station with the realistic
IMU (BMI088 noise, EuRoC bias walks) with and without them; FSR contact flags."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from models import add_humanoid, set_standing_state
from systems.dynamics.base_state import quaternion_to_rotation
from systems.estimation.base_state_estimator import (
    ACCEL_NOISE_DENSITY,
    CONTACT_OFF_WEIGHT_FRACTION,
    CONTACT_ON_WEIGHT_FRACTION,
    GYRO_NOISE_DENSITY,
    INITIAL_GYRO_BIAS_STD,
    KINEMATICS_NOISE_STD,
    LEVEL_GROUND_TILT_STD,
    SLIP_SPEED,
    ContactAidedInvariantEkf,
    ContactHysteresis,
    FootContactFromForceTorque,
    FootContactFromFsr,
    InvariantEkfBaseStateEstimator,
    base_to_imu,
    contact_flags_from_fsr,
    contact_flags_from_wrenches,
    contact_flags_with_hysteresis,
    imu_to_base,
    rotation_to_quaternion,
    so3_exp,
    so3_gamma,
)
from systems.simulation.disturbances import Push, PushSource, Step
from systems.simulation.imperfections import Imperfections

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


@pytest.mark.parametrize("bias", [False, True])
def test_one_call_step_equals_correction_then_propagation_bit_for_bit(bias):
    """``correct_and_propagate`` (the Drake wrapper's step) is set_state_vector,
    correct_kinematics and propagate, to the last bit, through contact changes."""
    rng = np.random.default_rng(7)
    R, p = rot_z(0.3), np.array([0.01, -0.02, 0.8])
    ekf = ContactAidedInvariantEkf(2, rotation=R, velocity=np.array([0.1, 0.0, 0.0]), position=p, gravity=G,
                                   estimate_imu_bias=bias)  # fmt: skip
    x = ekf.state_vector()
    for flags in ([True, True], [True, True], [True, False], [False, False], [False, True], [True, True]):
        h = (FEET - p) @ R + rng.normal(0.0, 1e-3, (2, 3))
        omega, a = rng.normal(0.0, 0.1, 3), R.T @ (-G) + rng.normal(0.0, 0.05, 3)
        one_call = ekf.correct_and_propagate(x, h, np.array(flags), omega, a, DT)
        ekf.set_state_vector(x)
        ekf.correct_kinematics(h, flags)
        ekf.propagate(omega, a, DT)
        x = ekf.state_vector()
        np.testing.assert_array_equal(one_call, x)
    assert ekf.in_contact.tolist() == [True, True] and x.shape == (ekf.state_size,)


def test_contact_flags_from_wrenches():
    w = np.array([0, 0, 0, 0, 0, 150.0, 1, 2, 3, 5, 5, 10.0])
    np.testing.assert_array_equal(contact_flags_from_wrenches(w, 20.0), [1.0, 0.0])


def test_contact_hysteresis_switches_on_above_the_upper_and_off_below_the_lower_threshold():
    """A known force profile through the hysteresis of a 400 N robot (on above 40 N, off
    below 20 N): a foot's force rising through 30 N stays off until it passes 40 N, falling
    back through 30 N stays on until it drops below 20 N; a second foot hovering between the
    two thresholds from the start never comes on; the flags without hysteresis (a single
    threshold of 30 N) toggle at every crossing instead."""
    hysteresis = ContactHysteresis.from_weight(2, 400.0)
    assert (hysteresis.on_threshold, hysteresis.off_threshold) == (
        CONTACT_ON_WEIGHT_FRACTION * 400.0,
        CONTACT_OFF_WEIGHT_FRACTION * 400.0,
    )
    assert CONTACT_OFF_WEIGHT_FRACTION < CONTACT_ON_WEIGHT_FRACTION
    left = np.array([0.0, 30.0, 39.0, 41.0, 30.0, 25.0, 31.0, 20.0, 19.0, 30.0, 39.9, 40.1])
    right = np.array([30.0, 35.0, 25.0, 39.0, 21.0, 30.0, 35.0, 25.0, 38.0, 22.0, 30.0, 30.0])
    forces = np.stack((left, right), axis=1)
    flags = contact_flags_with_hysteresis(forces, 40.0, 20.0)
    np.testing.assert_array_equal(flags[:, 0], [0, 0, 0, 1, 1, 1, 1, 1, 0, 0, 0, 1])
    np.testing.assert_array_equal(flags[:, 1], np.zeros(12))
    np.testing.assert_array_equal([hysteresis.update(f) for f in forces], flags)
    single = (left > 30.0).astype(float)
    assert np.count_nonzero(np.diff(single)) > np.count_nonzero(np.diff(flags[:, 0]))
    with pytest.raises(ValueError, match="off_threshold 50.0 N is above on_threshold 40.0 N"):
        ContactHysteresis(2, 40.0, 50.0)
    with pytest.raises(ValueError, match="3 normal forces for 2 feet"):
        hysteresis.update([1.0, 2.0, 3.0])


# ---------------------------------------------------------------------------------------
# Drake wrapper.
# ---------------------------------------------------------------------------------------


def _station_with_estimator(push: Push | None = None):
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model="hrp4_like", noise=True))
    hold = builder.AddSystem(ConstantVectorSource(station.q_hold))
    builder.Connect(hold.get_output_port(), station.desired_position)
    sensors = station.sensors
    contact = builder.AddSystem(FootContactFromForceTorque(len(sensors.ft_sides)))
    builder.Connect(sensors.ft_wrenches, contact.GetInputPort("wrenches"))
    q0 = station.topology.free_joint.position_start()
    estimator = builder.AddSystem(
        InvariantEkfBaseStateEstimator(
            station.estimator.plant,  # the estimators' own plant, never the simulated one
            station.estimator.humanoid.imu_frame,
            [station.estimator.humanoid.sole_frames[side] for side in sensors.ft_sides],
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
            source.GetOutputPort("applied_spatial_forces"), station.plant.get_applied_spatial_force_input_port()
        )
        builder.Connect(station.plant.get_state_output_port(), source.GetInputPort("state"))
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


def _standing_hrp4_estimator(angular_velocity, **options):
    """hrp4_like's estimator with the level-ground correction (``options`` passed on) and a
    context whose inputs hold it still on both feet, turning at ``angular_velocity``."""
    plant = MultibodyPlant(0.0)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    estimator = InvariantEkfBaseStateEstimator(
        plant,
        handles.imu_frame,
        [handles.sole_frames["left"], handles.sole_frames["right"]],
        level_ground_tilt_std=LEVEL_GROUND_TILT_STD,
        **options,
    )
    context = estimator.CreateDefaultContext()
    n = estimator.GetInputPort("joint_positions").size()
    estimator.GetInputPort("angular_velocity").FixValue(context, angular_velocity)
    estimator.GetInputPort("linear_acceleration").FixValue(context, [0.0, 0.0, 9.81])
    estimator.GetInputPort("joint_positions").FixValue(context, np.zeros(n))
    estimator.GetInputPort("foot_contact").FixValue(context, [1.0, 1.0])
    return estimator, context


def test_loading_the_compiled_steps_covers_what_the_filter_runs():
    """``load_compiled_filter_steps`` (a worker pool's start-up) loads every compiled step
    with the argument types the Drake filter passes: its updates then add no signature (a
    new one would be compiled, or loaded, in the middle of a simulation)."""

    from systems.estimation import invariant_ekf_steps as steps
    from systems.estimation.base_state_estimator import load_compiled_filter_steps

    load_compiled_filter_steps()
    kernels = (steps.correct_and_propagate_state_vector, steps.correct_kinematics_step, steps.propagate_step,
               steps.update_step, steps.foot_slip_step)  # fmt: skip
    loaded = [list(kernel.signatures) for kernel in kernels]
    assert all(loaded)
    estimator, context = _standing_hrp4_estimator([0.01, 0.0, 0.0], estimate_imu_bias=True, slip_speed=SLIP_SPEED)
    for step in range(3):  # step 0 is a level-ground step (E12), the others are not
        context.SetTime(step * estimator.period)
        context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
    assert estimator.GetOutputPort("valid").Eval(context)[0] == 1.0
    assert [list(kernel.signatures) for kernel in kernels] == loaded


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


# ---------------------------------------------------------------------------------------
# IMU bias states (E11).
# ---------------------------------------------------------------------------------------


def test_bias_states_off_by_default_and_their_layout():
    off = ContactAidedInvariantEkf(2, gravity=G)
    on = ContactAidedInvariantEkf(2, gravity=G, estimate_imu_bias=True)
    assert not off.estimates_imu_bias and on.estimates_imu_bias
    assert off.covariance.shape == (15, 15) and on.covariance.shape == (21, 21)
    assert off.state_size == 15 + 8 + 15**2 and on.state_size == 15 + 8 + 6 + 21**2
    np.testing.assert_allclose(np.sqrt(np.diag(on.covariance)[15:18]), INITIAL_GYRO_BIAS_STD)
    on.reset(imu_bias=[1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(on.imu_bias_of(on.state_vector()), [1, 2, 3, 4, 5, 6])
    with pytest.raises(ValueError, match="no bias states"):
        off.reset(imu_bias=np.zeros(6))
    with pytest.raises(ValueError, match="gyro_bias_random_walk"):
        ContactAidedInvariantEkf(2, estimate_imu_bias=True, gyro_bias_random_walk=float("nan"))


def test_bias_columns_of_the_transition_match_finite_differences():
    """The linearised error dynamics with biases (E11): two filters, the estimate and a
    "truth" X = Exp(ξ)⁻¹ X̄, θ = θ̄ − ζ (|ξ| ~ 1e-6), propagated 10 ms on the same IMU sample;
    the new right-invariant error matches Φ [ξ; ζ] to 1e-10 (the remainder is the O(dt²)
    of holding X̄ over the step), 100 times closer than Φ without its bias columns."""
    rng = np.random.default_rng(3)
    R, v, p = so3_exp([0.2, -0.1, 0.7]), np.array([0.3, -0.2, 0.1]), np.array([0.5, 0.2, 0.8])
    theta = np.array([0.01, -0.02, 0.005, 0.1, -0.05, 0.2])
    est = ContactAidedInvariantEkf(2, gravity=G, estimate_imu_bias=True)
    est.reset(R, v, p, imu_bias=theta)
    est.correct_kinematics(np.array([[0.05, 0.1, -0.75], [0.0, -0.1, -0.8]]), [True, True])  # (E8) only
    xi = rng.normal(size=21) * 1e-6
    E, J = so3_exp(xi[:3]), so3_gamma(xi[:3], 1)

    def true_point(point, k):  # Exp(ξ)⁻¹ applied to a column of X̄
        return E.T @ (point - J @ xi[k : k + 3])

    x = est.state_vector()  # [R 9; v; p; d 6; in_contact 2; θ 6; P]
    x[:9] = (E.T @ R).reshape(-1)
    x[9:12], x[12:15] = true_point(v, 3), true_point(p, 6)
    x[15:18], x[18:21] = true_point(est.foot_positions[0], 9), true_point(est.foot_positions[1], 12)
    x[23:29] = theta - xi[15:]
    truth = ContactAidedInvariantEkf(2, gravity=G, estimate_imu_bias=True)
    truth.set_state_vector(x)
    dt = 0.01
    Phi = est.transition_matrix(dt)
    omega, a = np.array([0.3, -0.5, 0.8]), np.array([0.5, 0.2, 9.5])
    est.propagate(omega, a, dt)
    truth.propagate(omega, a, dt)
    eta = est.rotation @ truth.rotation.T
    xi_new = np.concatenate(
        [
            0.5 * np.array([eta[2, 1] - eta[1, 2], eta[0, 2] - eta[2, 0], eta[1, 0] - eta[0, 1]]),
            est.velocity - eta @ truth.velocity,
            est.position - eta @ truth.position,
            (est.foot_positions - truth.foot_positions @ eta.T).reshape(-1),
            est.gyro_bias - truth.gyro_bias,
            est.accel_bias - truth.accel_bias,
        ]
    )
    error = np.abs(xi_new - Phi @ xi).max()
    without_bias_columns = Phi.copy()
    without_bias_columns[:15, 15:] = 0.0
    print(f"\n|ξ⁺ − Φξ| {error:.2e}, without the bias columns {np.abs(xi_new - without_bias_columns @ xi).max():.2e}")
    assert error < 1e-10
    assert np.abs(xi_new - without_bias_columns @ xi).max() > 100.0 * error


def _standing_robot():
    """hrp4_like in its standing posture (no simulation): plant, handles, the free joint's
    pose (7), joint positions (v[6:] order) and R_WI of the IMU frame."""
    from systems.common.topology import floating_base_topology

    plant = MultibodyPlant(0.0)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    topology = floating_base_topology(plant)
    q = plant.GetPositions(context)
    q0 = topology.free_joint.position_start()
    joints = np.array([q[j.position_start()] for j in topology.joints])
    R_WI = handles.imu_frame.CalcRotationMatrixInWorld(context).matrix()
    return plant, handles, q[q0 : q0 + 7], joints, R_WI


def test_injected_gyro_bias_is_estimated_where_observable():
    """A robot standing still (exact IMU and encoder signals from test-local sources) whose
    gyro reads a constant bias b = [0.01, 0, 0.01] rad/s (IMU frame, upright: x horizontal,
    z vertical; ~0.57 °/s), 10 s, the initial bias std raised to 0.02 rad/s (a bias this
    large is an uncalibrated gyro). Three filters on the same signals:

    * two feet in contact, bias states: the horizontal part of b (a roll/pitch rate would
      tilt the estimate away from gravity) converges within seconds; the vertical part (a
      yaw rate) is observable only through the leg kinematics (the two feet, fixed in world,
      would move in the IMU frame), weakly (the contact points may slide with σ_c): it
      moves part of the way to the truth and its std shrinks slowly.
    * one foot in contact, bias states: the vertical part is unobservable (a yaw about the
      vertical through the contact point leaves the kinematics unchanged): its estimate
      stays at the prior mean 0 with the prior std and yaw drifts at b_z.
    * two feet, no bias states: the bias becomes a tilt and velocity error.

    Measured (``pytest -s``): two feet, horizontal error 1e-6 rad/s (std 1.7e-4), vertical
    estimate 0.0038 (38 %), std 0.0158, yaw drift 0.0062 rad/s; one foot, vertical estimate
    3e-6, std 0.0200, yaw drift 0.0100 rad/s; tilt 0.0003° with bias states vs 1.5° (and
    0.31 m/s) without."""
    plant, handles, pose, joints, R_WI = _standing_robot()
    gravity = np.asarray(plant.gravity_field().gravity_vector(), dtype=float)
    b_true = np.array([0.01, 0.0, 0.01])
    prior_std = 0.02
    up_I = R_WI.T @ np.array([0.0, 0.0, 1.0])  # the world vertical in the IMU frame
    assert up_I[2] > 0.999  # the IMU is upright: its z is the vertical
    builder = DiagramBuilder()
    sources = {
        "angular_velocity": b_true,  # the robot does not rotate: the gyro reads its bias
        "linear_acceleration": R_WI.T @ -gravity,
        "joint_positions": joints,
    }
    feet = [handles.sole_frames["left"], handles.sole_frames["right"]]
    estimators, contact = {}, {}
    for key, bias, flags in (
        ("two_feet", True, [1.0, 1.0]),
        ("one_foot", True, [1.0, 0.0]),
        ("no_bias", False, [1.0, 1.0]),
    ):
        estimators[key] = builder.AddSystem(
            InvariantEkfBaseStateEstimator(
                plant,
                handles.imu_frame,
                feet,
                initial_base_pose=pose,
                estimate_imu_bias=bias,
                initial_gyro_bias_std=prior_std,
            )
        )
        contact[key] = builder.AddSystem(ConstantVectorSource(np.array(flags)))
        builder.Connect(contact[key].get_output_port(), estimators[key].GetInputPort("foot_contact"))
    for name, value in sources.items():
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        for estimator in estimators.values():
            builder.Connect(source.get_output_port(), estimator.GetInputPort(name))
    simulator = Simulator(builder.Build())
    duration = 10.0
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    R_WB_true = quaternion_to_rotation(pose[:4])
    horizontal_truth = np.linalg.norm(b_true - (b_true @ up_I) * up_I)
    r = {}
    for key, e in estimators.items():
        out = {
            port: e.GetOutputPort(port).Eval(e.GetMyContextFromRoot(context)).copy()
            for port in ("base_pose", "base_velocity", "imu_bias", "imu_bias_standard_deviation")
        }
        b_est, b_std = out["imu_bias"][:3], out["imu_bias_standard_deviation"][:3]
        error = b_est - b_true
        tilt, yaw = tilt_and_yaw(quaternion_to_rotation(out["base_pose"][:4]), R_WB_true)
        r[key] = {
            "horizontal_error": float(np.linalg.norm(error - (error @ up_I) * up_I)),
            "vertical_estimate": float(b_est @ up_I),
            "vertical_std": float(b_std @ np.abs(up_I)),
            "horizontal_std": float(max(b_std[:2])),
            "yaw_rate": yaw / duration,
            "tilt_deg": math.degrees(tilt),
            "speed": float(np.linalg.norm(out["base_velocity"][3:])),
        }
        print(
            f"\ninjected gyro bias {b_true} rad/s, {duration:.0f} s, {key}: "
            + str({k: round(v, 6) for k, v in r[key].items()})
        )
    two, one, off = r["two_feet"], r["one_foot"], r["no_bias"]
    for case in (two, one):  # horizontal: observable through gravity, converged
        assert case["horizontal_error"] < 0.05 * horizontal_truth
        assert case["horizontal_std"] < 0.05 * prior_std
        assert case["tilt_deg"] < 0.05 and case["speed"] < 0.01
    # Vertical, two feet: weakly observable through the leg kinematics.
    assert 0.2 * b_true[2] < two["vertical_estimate"] < b_true[2]
    assert 0.5 * prior_std < two["vertical_std"] < 0.9 * prior_std
    # Vertical, one foot: unobservable; yaw drifts at the bias's rate.
    assert abs(one["vertical_estimate"]) < 1e-4 and one["vertical_std"] > 0.99 * prior_std
    assert abs(one["yaw_rate"] - b_true @ up_I) < 0.02 * b_true[2]
    assert off["tilt_deg"] > 10.0 * max(two["tilt_deg"], 0.01)


def test_level_ground_makes_the_horizontal_accelerometer_bias_observable():
    """The robot of the gyro-bias test standing still on level ground, its accelerometer
    reading a constant horizontal bias b_a = [0.04, -0.03, 0] m/s² (IMU frame, upright), 10 s,
    bias states on in both filters. Without the level-ground correction (E12) the bias is not
    separable from tilt: the filter reads it as a tilt of |b_a| / |g| = 0.29° and its bias
    estimate stays near 0. With it the feet's sole normals pin the tilt, and the bias is
    estimated. Measured (``pytest -s``): tilt 0.289° without, 0.0024° with; bias error
    0.049 m/s² without, 5e-4 m/s² with (the correction runs every 0.1 s)."""
    plant, handles, pose, joints, R_WI = _standing_robot()
    gravity = np.asarray(plant.gravity_field().gravity_vector(), dtype=float)
    b_true = np.array([0.04, -0.03, 0.0])
    builder = DiagramBuilder()
    sources = {
        "angular_velocity": np.zeros(3),
        "linear_acceleration": R_WI.T @ -gravity + b_true,
        "joint_positions": joints,
        "foot_contact": np.ones(2),
    }
    feet = [handles.sole_frames["left"], handles.sole_frames["right"]]
    estimators = {
        key: builder.AddSystem(
            InvariantEkfBaseStateEstimator(
                plant,
                handles.imu_frame,
                feet,
                initial_base_pose=pose,
                estimate_imu_bias=True,
                level_ground_tilt_std=tilt_std,
            )
        )
        for key, tilt_std in (("level_ground", LEVEL_GROUND_TILT_STD), ("kinematics_only", None))
    }
    for name, value in sources.items():
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        for estimator in estimators.values():
            builder.Connect(source.get_output_port(), estimator.GetInputPort(name))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(10.0)
    context = simulator.get_context()
    R_WB_true = quaternion_to_rotation(pose[:4])
    r = {}
    for key, e in estimators.items():
        c = e.GetMyContextFromRoot(context)
        tilt, _ = tilt_and_yaw(quaternion_to_rotation(e.GetOutputPort("base_pose").Eval(c)[:4]), R_WB_true)
        bias = e.GetOutputPort("imu_bias").Eval(c)[3:]
        r[key] = {"tilt_deg": math.degrees(tilt), "bias_error": float(np.linalg.norm(bias - b_true))}
        print(f"\naccelerometer bias {b_true} m/s², 10 s, {key}: {r[key]}")
    tilt_from_bias = math.degrees(np.linalg.norm(b_true) / np.linalg.norm(gravity))
    assert r["kinematics_only"]["tilt_deg"] > 0.8 * tilt_from_bias
    assert r["kinematics_only"]["bias_error"] > 0.5 * np.linalg.norm(b_true)
    assert r["level_ground"]["tilt_deg"] < 0.02 * tilt_from_bias
    assert r["level_ground"]["bias_error"] < 0.02 * np.linalg.norm(b_true)


def test_level_ground_correction_matches_its_jacobian():
    """(E12)'s H against the measurement it linearises: for a small right-invariant rotation
    error ξ_R (true R = Exp(ξ_R) R̄), the innovation (R̄ n − e_z)_xy equals H ξ_R to second
    order, with n the true sole normal (R n = e_z)."""
    rng = np.random.default_rng(3)
    R_true = so3_exp(rng.normal(0.0, 0.3, 3))
    n = R_true.T @ np.array([0.0, 0.0, 1.0])
    H = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    for scale in (1e-3, 1e-4):
        xi = rng.normal(0.0, scale, 3)
        R_est = so3_exp(-xi) @ R_true
        innovation = (R_est @ n - np.array([0.0, 0.0, 1.0]))[:2]
        assert np.allclose(innovation, H @ xi, atol=5 * scale**2)
    # The gate, on a filter sure of its tilt (0.06°): a sole tilted 5° (rolling on an edge) is
    # left out, one tilted 0.1° is used.
    for tilt_deg, used in ((5.0, 0), (0.1, 2)):
        ekf = ContactAidedInvariantEkf(2, estimate_imu_bias=True, initial_orientation_std=1e-3)
        ekf.correct_kinematics(FEET, [True, True])
        normals = np.tile(so3_exp(np.array([math.radians(tilt_deg), 0.0, 0.0]))[:, 2], (2, 1))
        assert ekf.correct_level_ground(normals, LEVEL_GROUND_TILT_STD) == used
    # A foot whose sole is turning (not still) is left out, whatever its tilt.
    ekf = ContactAidedInvariantEkf(2, estimate_imu_bias=True, initial_orientation_std=1e-3)
    ekf.correct_kinematics(FEET, [True, True])
    flat = np.tile([0.0, 0.0, 1.0], (2, 1))
    assert ekf.correct_level_ground(flat, LEVEL_GROUND_TILT_STD, still=[False, True]) == 1
    assert ekf.correct_level_ground(flat, LEVEL_GROUND_TILT_STD, still=[False, False]) == 0
    plant, handles, _, _, _ = _standing_robot()
    with pytest.raises(ValueError, match="level_ground_tilt_std"):
        InvariantEkfBaseStateEstimator(
            plant, handles.imu_frame, [handles.sole_frames["left"]], level_ground_tilt_std=0.0
        )


def test_imu_bias_outputs_are_zero_without_bias_states():
    estimator, context = _standalone_estimator()
    context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
    assert not estimator.estimates_imu_bias
    np.testing.assert_array_equal(estimator.GetOutputPort("imu_bias").Eval(context), np.zeros(6))
    np.testing.assert_array_equal(estimator.GetOutputPort("imu_bias_standard_deviation").Eval(context), np.zeros(6))
    assert estimator.GetOutputPort("standard_deviation").size() == 9


# ---------------------------------------------------------------------------------------
# The station with the realistic IMU, with and without bias states.
# ---------------------------------------------------------------------------------------


def _realistic_imu_run(push: Push | None, duration: float, log_period: float = 0.01) -> dict:
    """The hrp4_like station with ``Imperfections.realistic()``'s IMU (BMI088 white noise,
    EuRoC ADIS16448 bias random walks) and base_state "invariant_ekf" (the station's filter
    then has bias states), holding its posture; a second, bias-free filter fed by the same
    sensor signals (test-local). Returns, per filter, its errors against the plant's truth
    (velocity RMS and max tilt over the run, yaw and position errors at its end) and its
    bias estimate at the end, and the simulated IMU's true biases then."""
    builder = DiagramBuilder()
    imu = Imperfections(imu=Imperfections.realistic().imu)
    station = add_humanoid_station(builder, StationConfig(imperfections=imu, base_state="invariant_ekf"))
    builder.Connect(builder.AddSystem(ConstantVectorSource(station.q_hold)).get_output_port(), station.desired_position)
    sensors, with_bias = station.sensors, station.base_state_estimator
    assert with_bias.estimates_imu_bias
    q0 = station.topology.free_joint.position_start()
    v0 = station.plant.num_positions() + station.topology.free_joint.velocity_start()
    without = builder.AddSystem(
        InvariantEkfBaseStateEstimator(
            station.estimator.plant,  # the estimators' own plant, as the station's filter
            station.estimator.humanoid.imu_frame,
            with_bias.foot_frames,
            initial_base_pose=station.initial_state[q0 : q0 + 7],
        )
    )
    builder.Connect(sensors.imu.angular_velocity, without.GetInputPort("angular_velocity"))
    builder.Connect(sensors.imu.linear_acceleration, without.GetInputPort("linear_acceleration"))
    builder.Connect(sensors.encoders.GetOutputPort("position"), without.GetInputPort("joint_positions"))
    builder.Connect(station.foot_contact.GetOutputPort("foot_contact"), without.GetInputPort("foot_contact"))
    if push is not None:
        source = builder.AddSystem(PushSource(station.plant, [push]))
        builder.Connect(
            source.GetOutputPort("applied_spatial_forces"), station.plant.get_applied_spatial_force_input_port()
        )
        builder.Connect(station.plant.get_state_output_port(), source.GetInputPort("state"))
    estimators = {"with_bias": with_bias, "without_bias": without}
    logs = {
        (key, port): LogVectorOutput(e.GetOutputPort(port), builder, log_period)
        for key, e in estimators.items()
        for port in ("base_pose", "base_velocity")
    }
    logs["state"] = LogVectorOutput(station.plant.get_state_output_port(), builder, log_period)
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    without.SetInitialBaseState(
        without.GetMyMutableContextFromRoot(context),
        station.initial_state[q0 : q0 + 7],
        station.initial_state[v0 : v0 + 6],
    )
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    x = logs["state"].FindLog(context).data()
    metrics = {}
    for key, estimator in estimators.items():
        pose = logs[key, "base_pose"].FindLog(context).data()
        velocity = logs[key, "base_velocity"].FindLog(context).data()
        n = min(x.shape[1], pose.shape[1])
        errors = np.array(
            [
                tilt_and_yaw(quaternion_to_rotation(pose[:4, k]), quaternion_to_rotation(x[q0 : q0 + 4, k]))
                for k in range(n)
            ]
        )
        dv = velocity[3:6, :n] - x[v0 + 3 : v0 + 6, :n]
        bias = estimator.GetOutputPort("imu_bias").Eval(estimator.GetMyContextFromRoot(context))
        metrics[key] = {
            "velocity_rms": float(np.sqrt(np.mean(np.sum(dv**2, axis=0)))),
            "max_tilt_deg": math.degrees(errors[:, 0].max()),
            "yaw_error_end_deg": math.degrees(errors[-1, 1]),
            "position_error_end_m": float(np.linalg.norm(pose[4:7, n - 1] - x[q0 + 4 : q0 + 7, n - 1])),
            "gyro_bias_estimate": np.round(bias[:3], 6).tolist(),
            "accel_bias_estimate": np.round(bias[3:], 4).tolist(),
        }
    true_bias = {
        kind: system.GetMyContextFromRoot(context).get_discrete_state(0).value().copy()
        for kind, system in (("gyro", sensors.imu.gyro_bias), ("accel", sensors.imu.accel_bias))
    }
    metrics["true_bias"] = {
        "gyro": np.round(true_bias["gyro"], 6).tolist(),
        "accel": np.round(true_bias["accel"], 4).tolist(),
    }
    metrics["true_speed_max"] = float(np.linalg.norm(x[v0 + 3 : v0 + 6], axis=0).max())
    return metrics


def _print_metrics(title: str, metrics: dict) -> None:
    print(f"\n{title}")
    for key, value in metrics.items():
        if isinstance(value, dict):
            value = {k: (round(v, 5) if isinstance(v, float) else v) for k, v in value.items()}
        print(f"  {key}: {value}")


@pytest.mark.slow
def test_hrp4_realistic_imu_standing_60_s_with_and_without_bias_states():
    """60 s standing on the hrp4_like station with the realistic IMU (the gyro's turn-on
    bias, (0.12, -0.08, 0.35) deg/s, which the station's filter measures about the vertical
    over the first 0.5 s; both biases random-walk: after 60 s ~1.5e-4 rad/s and ~0.023 m/s²,
    1σ). The issue's floors (base
    linear-velocity RMS <= 0.02 m/s, tilt <= 0.5°) hold with bias states; the bias-free
    filter's velocity error is larger (the vertical accelerometer bias, observable, is
    estimated with bias states and otherwise fought by the contact corrections). Without
    bias states the tilt error is the horizontal accelerometer bias over g (not separable
    from tilt when upright); the station's filter with bias states also has the level-ground
    correction (E12), which separates them. Yaw and position drift: unobservable, their
    errors after the minute. Measured (``pytest -s``; seeds fixed): with bias states,
    velocity RMS 6.6 mm/s, max tilt 0.099°, yaw 0.59°/min (its vertical gyro bias estimate
    6.30e-3 rad/s against the true 6.09e-3, which walked from 6.11e-3: weakly observable
    through the feet), position 3.3 mm/min, accelerometer z bias -0.049 m/s² estimated
    (true -0.055); without, velocity RMS 0.150 m/s (over the floor), max tilt 0.55°, yaw
    21°/min (the turn-on bias). The true horizontal accelerometer bias at 60 s, 0.0245 m/s²,
    is 0.14° of tilt. ~100 s of wall time."""
    m = _realistic_imu_run(None, 60.0)
    _print_metrics("hrp4_like, realistic IMU, standing 60 s:", m)
    on, off = m["with_bias"], m["without_bias"]
    assert on["velocity_rms"] <= 0.02
    assert on["max_tilt_deg"] <= 0.5
    assert on["velocity_rms"] < off["velocity_rms"]
    # Unobservable, the drift over the minute: yaw (gyro white noise alone: 0.11° 1σ) and
    # position.
    assert abs(on["yaw_error_end_deg"]) < 1.0
    assert on["position_error_end_m"] < 0.02


def test_hrp4_realistic_imu_pushed_with_and_without_bias_states():
    """The 80 N, 0.2 s push on the waist (as the tests above), 3 s, realistic IMU: the floors
    hold with bias states. Measured (``pytest -s``): true speed up to 0.24 m/s; with bias
    states velocity RMS 8.0 mm/s, max tilt 0.17°, yaw 0.02°, position error 0.6 mm at 3 s;
    without, 12.8 mm/s, 0.28°, yaw 1.06° (the gyro's turn-on bias), 4.8 mm. With the level-ground
    correction fused at every 1 ms step and no rest test (tried while developing) the
    rocking soles pulled the tilt to 1.8° and the velocity error to 46 mm/s."""
    m = _realistic_imu_run(Push("waist", [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], Step(80.0, 1.0, 1.2)), 3.0)
    _print_metrics("hrp4_like, realistic IMU, pushed 80 N for 0.2 s, 3 s:", m)
    assert m["true_speed_max"] > 0.1
    assert m["with_bias"]["velocity_rms"] <= 0.02
    assert m["with_bias"]["max_tilt_deg"] <= 0.5


# ---------------------------------------------------------------------------------------
# FSR contact flags.
# ---------------------------------------------------------------------------------------


def test_contact_flags_from_fsr_and_the_system():
    forces = np.array([1.0, 1.0, 0.5, 0.2, 0.0, 0.1, 0.0, 0.1])  # left 2.7 N, right 0.2 N
    np.testing.assert_array_equal(contact_flags_from_fsr(forces, 2.5), [1.0, 0.0])
    system = FootContactFromFsr(50.9)  # a 5.19 kg Nao: 5 % of its weight is 2.5 N
    assert system.threshold == pytest.approx(0.05 * 50.9)
    context = system.CreateDefaultContext()
    system.GetInputPort("fsr_forces").FixValue(context, forces)
    np.testing.assert_array_equal(system.GetOutputPort("foot_contact").Eval(context), [1.0, 0.0])
    forces[3] = np.nan
    system.GetInputPort("fsr_forces").FixValue(context, forces)
    with pytest.raises(ValueError, match="FootContactFromFsr: input 'fsr_forces'"):
        system.GetOutputPort("foot_contact").Eval(context)
    with pytest.raises(ValueError, match="weight_fraction"):
        FootContactFromFsr(50.9, weight_fraction=1.5)
    with pytest.raises(ValueError, match="robot_weight"):
        FootContactFromFsr(0.0)


def _flags_through(system, port: str, samples: np.ndarray) -> np.ndarray:
    """The system's flags at each sample, stepped as a diagram steps it: the output at t_k
    reads sample k, then the periodic update stores the flags."""
    context = system.CreateDefaultContext()
    flags = []
    for k, sample in enumerate(samples):
        context.SetTime(k * 1e-3)
        system.GetInputPort(port).FixValue(context, sample)
        flags.append(system.GetOutputPort("foot_contact").Eval(context).copy())
        if system.num_discrete_state_groups():
            context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
    return np.array(flags)


def test_online_contact_flags_have_the_logs_hysteresis():
    """The station's contact systems with an off threshold give, sample by sample, the flags
    of the log pipeline's ContactHysteresis (on above 40 N, off below 20 N; between the two a
    foot keeps its flag; a late release is not a contact); without one, the plain threshold,
    stateless. The station builds them at 10 % and 5 % of the estimators' model's weight."""
    from diagrams.station.humanoid_station import add_humanoid_station
    from systems.estimation.base_state_estimator import contact_flags_with_hysteresis

    normal = np.array([[0.0, 50.0], [30.0, 30.0], [45.0, 19.0], [30.0, 25.0], [15.0, 45.0], [30.0, 20.0]])
    expected = contact_flags_with_hysteresis(normal, 40.0, 20.0)
    np.testing.assert_array_equal(expected[:, 0], [0, 0, 1, 1, 0, 0])  # 30 N: off before, on after 45 N
    np.testing.assert_array_equal(expected[:, 1], [1, 1, 0, 0, 1, 1])
    wrenches = np.zeros((len(normal), 12))
    wrenches[:, 5], wrenches[:, 11] = normal[:, 0], normal[:, 1]
    ft = FootContactFromForceTorque(2, 40.0, off_threshold=20.0)
    np.testing.assert_array_equal(_flags_through(ft, "wrenches", wrenches), expected)
    assert (ft.threshold, ft.off_threshold) == (40.0, 20.0)
    plain = FootContactFromForceTorque(2, 40.0)
    assert plain.num_discrete_state_groups() == 0
    np.testing.assert_array_equal(_flags_through(plain, "wrenches", wrenches), normal > 40.0)
    fsr = FootContactFromFsr(400.0, weight_fraction=0.1, off_weight_fraction=0.05)  # 40 N and 20 N
    forces = np.repeat(normal / 4.0, 4, axis=1)
    np.testing.assert_array_equal(_flags_through(fsr, "fsr_forces", forces), expected)
    with pytest.raises(ValueError, match="off_threshold 50.0 N is above the threshold 40.0 N"):
        FootContactFromForceTorque(2, 40.0, off_threshold=50.0)
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model="hrp4_like", base_state="invariant_ekf"))
    model = station.estimator.plant
    weight = model.CalcTotalMass(model.CreateDefaultContext()) * 9.81
    contact = station.foot_contact
    assert contact.threshold == pytest.approx(0.10 * weight, rel=1e-3)
    assert contact.off_threshold == pytest.approx(0.05 * weight, rel=1e-3)


@pytest.mark.parametrize(("period", "every"), [(1e-3, 100), (0.010104, 10), (0.003003, 33), (0.25, 1)])
def test_level_ground_period_is_rounded_to_the_update_period_not_refused(period, every):
    """Real logs come at 99, 333 or 4 Hz: the level-ground correction runs every
    round(0.1 s / period) updates (at least one) instead of refusing a period that does not
    divide 0.1 s; the filter then runs at that period."""
    estimator, context = _standing_hrp4_estimator([0.0, 0.0, 0.0], period=period)
    assert estimator.level_ground_period_used == pytest.approx(every * period, rel=1e-12)
    for step in range(every + 2):
        context.SetTime(step * period)
        context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
    assert estimator.GetOutputPort("valid").Eval(context)[0] == 1.0


def test_the_filter_starts_from_a_given_imu_bias():
    """``initial_imu_bias`` (e.g. measured at rest): the bias output starts at it and stays
    there after SetInitialBaseState; a standing robot whose gyro reads exactly that bias
    about the vertical keeps its yaw (the vertical bias is not learned while standing); bad
    values and a bias without bias states are refused."""
    bias = np.array([0.001, -0.002, np.radians(0.35), 0.0, 0.0, 0.01])
    estimator, context = _standing_hrp4_estimator(bias[:3], estimate_imu_bias=True, initial_imu_bias=bias)
    np.testing.assert_array_equal(estimator.GetOutputPort("imu_bias").Eval(context), bias)
    estimator.SetInitialBaseState(context, estimator.GetOutputPort("base_pose").Eval(context))
    np.testing.assert_array_equal(estimator.GetOutputPort("imu_bias").Eval(context), bias)
    q0 = estimator.GetOutputPort("base_pose").Eval(context)[:4].copy()
    for step in range(2000):
        context.SetTime(step * estimator.period)
        context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
    q = estimator.GetOutputPort("base_pose").Eval(context)[:4]
    assert np.degrees(2.0 * np.arccos(min(1.0, abs(float(q @ q0))))) < 0.01  # 0.7 deg without the bias
    with pytest.raises(ValueError, match="initial_imu_bias must be 6 finite"):
        _standing_hrp4_estimator(np.zeros(3), estimate_imu_bias=True, initial_imu_bias=[0.0, np.nan, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="initial_imu_bias given without estimate_imu_bias"):
        _standing_hrp4_estimator(np.zeros(3), initial_imu_bias=np.zeros(6))


def _yaw_change_after(estimator, context, steps: int) -> float:
    """Runs ``steps`` updates; returns the base orientation's turn about the vertical, deg."""
    q0 = estimator.GetOutputPort("base_pose").Eval(context)[:4].copy()
    for step in range(steps):
        context.SetTime(step * estimator.period)
        context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
    q = estimator.GetOutputPort("base_pose").Eval(context)[:4]
    return abs(math.degrees(tilt_and_yaw(quaternion_to_rotation(q), quaternion_to_rotation(q0))[1]))


def test_the_at_rest_window_measures_the_gyro_bias_about_the_vertical():
    """``at_rest_duration``: a standing robot whose gyro reads a constant bias (0.35 deg/s
    about the vertical, the realistic IMU's; the filter starts from a zero bias): over the
    window the filter runs and averages; then its vertical bias is the mean reading's and
    the yaw that bias turned over the window is turned back. After 2 s its yaw has not
    turned (the same robot without the window: 0.7 deg) and its vertical bias estimate
    is the reading's; the horizontal ones are the filter's own (gravity observes them).
    Bad windows are refused naming the option."""
    bias = np.array([0.001, -0.002, np.radians(0.35)])
    estimator, context = _standing_hrp4_estimator(bias, estimate_imu_bias=True, at_rest_duration=0.5)
    assert estimator.at_rest_duration == pytest.approx(0.5)
    turned = _yaw_change_after(estimator, context, 2000)
    estimate = estimator.GetOutputPort("imu_bias").Eval(context)[:3]
    print(f"at rest: turned {turned:.5f} deg, gyro bias estimate {estimate} against {bias}")
    assert turned < 0.01
    assert abs(estimate[2] - bias[2]) < 1e-5
    plain, plain_context = _standing_hrp4_estimator(bias, estimate_imu_bias=True)
    assert _yaw_change_after(plain, plain_context, 2000) > 0.5
    # SetInitialBaseState starts the window again.
    estimator.SetInitialBaseState(context, estimator.GetOutputPort("base_pose").Eval(context))
    assert _yaw_change_after(estimator, context, 2000) < 0.01
    with pytest.raises(ValueError, match="at_rest_duration needs estimate_imu_bias"):
        _standing_hrp4_estimator(np.zeros(3), at_rest_duration=0.5)
    with pytest.raises(ValueError, match="shorter than two periods"):
        _standing_hrp4_estimator(np.zeros(3), estimate_imu_bias=True, at_rest_duration=1e-3)
    with pytest.raises(ValueError, match="at_rest_duration"):
        _standing_hrp4_estimator(np.zeros(3), estimate_imu_bias=True, at_rest_duration=-1.0)


# ---------------------------------------------------------------------------------------
# Slip rejection (E13).
# ---------------------------------------------------------------------------------------


def _sliding_foot_run(slip_speed: float | None, seed: int = 0) -> dict:
    """hrp4_like stands still on both feet (true base fixed at its standing pose; IMU
    signals with the BMI088's white noise, seeded); from 0.5 s to 0.8 s its left foot,
    flagged in contact throughout, slides outward: the left hip roll turns at 0.45 rad/s,
    so the sole's kinematic position in the IMU frame moves at ~0.3 m/s (~9 cm), the base
    does not move. From 1.2 s only the left foot is flagged (the right lifted): the base
    estimate then rests on the re-anchored left foot alone. Returns the filter's largest
    base position and velocity errors from the slip's start to the lift and after it, the
    sole's kinematic speed in the slide, the slip counts, the feet's speeds at the end and
    the smallest ``valid`` while on the left foot alone."""
    from systems.common.topology import floating_base_topology

    plant, handles, pose, joints, R_WI = _standing_robot()
    gravity = np.asarray(plant.gravity_field().gravity_vector(), dtype=float)
    topology = floating_base_topology(plant)
    hip = [j.name() for j in topology.joints].index("L_HIP_R")
    sole = handles.sole_frames["left"]
    estimator = InvariantEkfBaseStateEstimator(
        plant, handles.imu_frame, [sole, handles.sole_frames["right"]], initial_base_pose=pose, slip_speed=slip_speed
    )
    context = estimator.CreateDefaultContext()
    plant_context = plant.CreateDefaultContext()
    q_index = [j.position_start() for j in topology.joints]

    def sole_in_imu(q: np.ndarray) -> np.ndarray:
        positions = plant.GetPositions(plant_context)
        positions[q_index] = q
        plant.SetPositions(plant_context, positions)
        return sole.CalcPose(plant_context, handles.imu_frame).translation().copy()

    rng = np.random.default_rng(seed)
    rate, start, stop, lift, end = 0.45, 0.5, 0.8, 1.2, 1.6
    specific_force = R_WI.T @ -gravity
    position_error, velocity_error, valid_alone = [], [], []
    for k in range(int(round(end / DT))):
        t = k * DT
        q = joints.copy()
        q[hip] += rate * (min(max(t, start), stop) - start)
        estimator.GetInputPort("angular_velocity").FixValue(
            context, rng.normal(0.0, GYRO_NOISE_DENSITY / math.sqrt(DT), 3)
        )
        estimator.GetInputPort("linear_acceleration").FixValue(
            context, specific_force + rng.normal(0.0, ACCEL_NOISE_DENSITY / math.sqrt(DT), 3)
        )
        estimator.GetInputPort("joint_positions").FixValue(context, q)
        estimator.GetInputPort("foot_contact").FixValue(context, [1.0, 0.0 if t >= lift else 1.0])
        context.SetTime(t)
        context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
        position_error.append(float(np.linalg.norm(estimator.GetOutputPort("base_pose").Eval(context)[4:] - pose[4:])))
        velocity_error.append(float(np.linalg.norm(estimator.GetOutputPort("base_velocity").Eval(context)[3:])))
        if t >= lift:
            valid_alone.append(estimator.GetOutputPort("valid").Eval(context)[0])
    slide = joints.copy()
    slide[hip] += rate * (stop - start)
    k_start, k_lift = int(round(start / DT)), int(round(lift / DT))
    return {
        "max_position_error_before": max(position_error[:k_start]),
        "max_position_error": max(position_error[k_start:k_lift]),
        "max_velocity_error": max(velocity_error[k_start:k_lift]),
        "max_position_error_alone": max(position_error[k_lift:]),
        "kinematic_speed": float(np.linalg.norm(sole_in_imu(slide) - sole_in_imu(joints)) / (stop - start)),
        "slip_count": estimator.GetOutputPort("slip_count").Eval(context).copy(),
        "foot_speed": estimator.GetOutputPort("foot_speed").Eval(context).copy(),
        "valid_alone": min(valid_alone),
    }


def test_a_sliding_stance_foot_is_rejected_and_re_anchored():
    """A stance foot slides 9 cm at ~0.3 m/s while flagged in contact, the base still
    (``_sliding_foot_run``). Without the slip test the filter trusts it and the base
    estimate is dragged by centimetres; with it (``SLIP_SPEED``, 0.1 m/s) the foot's
    correction is dropped after the few milliseconds its low-passed speed takes to cross
    the threshold (~8 ms, ~2.5 mm of slide), the base estimate stays within a few
    millimetres of the truth, the slip is counted on that foot alone, and once the foot
    stops it is re-anchored where it stands: with the other foot lifted, the filter rests
    on it (``valid``) and the base stays put. Measured (``pytest -s``, seed 0): without the
    test, base position error up to 65 mm and velocity error 0.16 m/s, still 49 mm on the
    left foot alone; with it, 3.0 mm (1.8 mm before the slide; 2.9-3.8 mm over seeds 0-4)
    and 9.3 mm/s, 309 updates dropped (the 300 ms slide less ~8 ms of detection, plus the
    ~20 ms the low-passed speed takes to fall back below the threshold), 1.6 mm on the
    re-anchored foot alone."""
    off = _sliding_foot_run(None)
    on = _sliding_foot_run(SLIP_SPEED)
    print(f"\nsliding foot, no slip test: { {k: v for k, v in off.items()} }")
    print(f"sliding foot, slip test at {SLIP_SPEED} m/s: { {k: v for k, v in on.items()} }")
    assert 0.25 < on["kinematic_speed"] < 0.35  # the slide is as stated
    # Without the test: dragged (and the slip goes unreported).
    assert off["max_position_error"] > 0.02 or off["max_velocity_error"] > 0.1
    assert off["slip_count"].tolist() == [0.0, 0.0]
    # With it: the base stays near the truth; the left foot's updates are dropped for about
    # the slide's duration (0.3 s at 1 kHz, less the detection delay, plus the low-pass's
    # decay after the stop), the right foot's never.
    assert on["max_position_error"] < 0.005
    assert on["max_velocity_error"] < 0.02
    assert 200 < on["slip_count"][0] < 400 and on["slip_count"][1] == 0.0
    # Re-anchored: the left foot alone holds the base after the lift.
    assert on["valid_alone"] == 1.0
    assert on["max_position_error_alone"] < 0.005
    assert (on["foot_speed"] < 0.01).all()


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan"), float("inf"), "fast"])
def test_a_bad_slip_speed_is_refused_naming_it(bad):
    plant, handles, pose, _, _ = _standing_robot()
    with pytest.raises(ValueError, match="InvariantEkfBaseStateEstimator: slip_speed"):
        InvariantEkfBaseStateEstimator(
            plant, handles.imu_frame, [handles.sole_frames["left"]], initial_base_pose=pose, slip_speed=bad
        )


def test_slip_speed_is_an_ekf_setting_on_by_default_for_logs(tmp_path):
    """``EkfSettings.slip_speed`` defaults to ``SLIP_SPEED``, is read from the settings YAML
    and refused there when not a finite number > 0, naming the key; the filter reports it
    (None when off, its default)."""
    from systems.estimation.ekf_settings import EkfSettings, check_ekf_settings, load_ekf_settings

    assert EkfSettings().slip_speed == SLIP_SPEED == 0.1
    path = tmp_path / "ekf.yaml"
    path.write_text("slip_speed: 0.15\n")
    assert load_ekf_settings(path).slip_speed == 0.15
    assert load_ekf_settings(None, slip_speed=0.2).slip_speed == 0.2
    for bad in ("-0.1", "0", ".inf", "fast"):
        path.write_text(f"slip_speed: {bad}\n")
        with pytest.raises(ValueError, match="slip_speed"):
            load_ekf_settings(path)
    with pytest.raises(ValueError, match="slip_speed"):
        check_ekf_settings(EkfSettings(slip_speed=float("nan")))
    plant, handles, pose, _, _ = _standing_robot()
    feet = [handles.sole_frames["left"]]
    assert InvariantEkfBaseStateEstimator(plant, handles.imu_frame, feet).slip_speed is None
    assert InvariantEkfBaseStateEstimator(plant, handles.imu_frame, feet, slip_speed=0.1).slip_speed == 0.1


@pytest.mark.slow
def test_no_false_slips_on_the_simulated_walking_log():
    """No false slip on a normal stance: the realistic world's walking log of nao_like
    (``diagrams.locomotion.walking_log``: 3 s standing then 10 s walking, BMI088-like IMU
    with a gyro bias, 14-bit encoders, FSR contact, 99 Hz jittery samples) through the log
    pipeline: with the default slip test (0.1 m/s) the base estimate is bit for bit the one
    of a test that never fires (1e9 m/s), so no stance foot's correction was dropped. The
    test can fail: at 0.02 m/s (below the stance feet's speeds, up to ~60 mm/s on this log at
    99 Hz, see ``EkfSettings.slip_speed``) feet are dropped and the estimate differs.
    ~45 s of wall time (the simulation)."""
    import dataclasses

    from diagrams.locomotion.walking_log import ROBOT, WalkingLogSettings, simulate_walking_log
    from diagrams.residuals.log_estimation import LogEstimationSettings, build_estimator_plant, estimate_from_log

    walk = simulate_walking_log(WalkingLogSettings())
    robot = build_estimator_plant(ROBOT)
    base = {}
    for slip_speed in (SLIP_SPEED, 1e9, 0.02):
        settings = LogEstimationSettings()
        settings = dataclasses.replace(settings, ekf=dataclasses.replace(settings.ekf, slip_speed=slip_speed))
        estimates = estimate_from_log(robot, walk.log, settings)
        base[slip_speed] = np.hstack((estimates.base_pose, estimates.base_velocity))
    assert np.isfinite(base[SLIP_SPEED]).all()
    np.testing.assert_array_equal(base[SLIP_SPEED], base[1e9])
    assert np.abs(base[0.02] - base[1e9]).max() > 1e-6
