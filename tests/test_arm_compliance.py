"""Compliant arms (Hawley et al. 2019, Sec. 6.4, eqs. 25-29): each system against physics or an
independent computation (Drake's recursive inverse dynamics, eq. 11's forward map, forward
kinematics), K_m identification against the PD's gain, and a short closed-loop run in which
the hands yield by F / k."""

import numpy as np
import pytest
from pydrake.math import RotationMatrix
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from diagrams.observer.calibration import (
    identified_motor_constants,
    motor_constant_identification,
    settle_standing_state,
)
from diagrams.observer.nao_compliant_arms import (
    build_nao_compliant_arms_diagram,
    hand_pushes,
)
from diagrams.observer.nao_force_observer import full_posture, wide_stance
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from diagrams.station.standing import default_gains
from systems.observer.arm_compliance import (
    NAO_ARM_CHAINS,
    ArmChain,
    ArmExternalForceEstimator,
    CompliantArmBlender,
    HandComplianceController,
    JointTorqueFromPositionError,
    ObserverHandForce,
)
from systems.simulation.disturbances import SmoothPiecewise
from systems.simulation.ground_truth import VirtualForceTruth
from systems.simulation.pd_gravity import joint_vector_from_names

ARM_JOINTS = [n for c in NAO_ARM_CHAINS for n in c.joint_names]


@pytest.fixture(scope="module")
def station():
    return add_humanoid_station(DiagramBuilder(), StationConfig(model="nao_like", noise=False))


def _gains(station):
    kp, kd = default_gains(station.plant, station.humanoid)
    names = station.joint_names
    return ({n: kp[names.index(n)] for n in ARM_JOINTS}, {n: kd[names.index(n)] for n in ARM_JOINTS})


def _moving_state(station, rng):
    """The settled stance with random joint angles offsets and velocities (base included)."""
    plant = station.plant
    x = settle_standing_state(wide_stance()).copy()
    nq = plant.num_positions()
    x[nq:] = 0.3 * rng.standard_normal(plant.num_velocities())
    for n in ARM_JOINTS:
        x[plant.GetJointByName(n).position_start()] += 0.2 * rng.standard_normal()
    return x


def test_motor_constant_identification_recovers_the_pd_stiffness(station):
    """Static loads on both hands: K_m (eq. 27) = the station PD's K_p (5 N m/rad on the
    shoulders/elbows, 2 on the wrists), the PD compensating gravity itself."""
    result = motor_constant_identification()
    kp, _ = _gains(station)
    assert result.joint_names == tuple(ARM_JOINTS)
    np.testing.assert_allclose(result.motor_constants, [kp[n] for n in ARM_JOINTS], rtol=0.02)
    # Every joint was moved by the loads, and the static balance holds to < 3 % of the torques.
    assert np.all(np.abs(result.position_errors).max(axis=0) > 1e-3)
    assert result.residual_rms < 0.03 * np.sqrt(np.mean(result.load_torques**2))


def test_joint_torque_is_km_times_the_position_error(station):
    plant = station.plant
    km = {n: 1.0 + i for i, n in enumerate(ARM_JOINTS)}
    dut = JointTorqueFromPositionError(plant, km)
    context = dut.CreateDefaultContext()
    rng = np.random.default_rng(1)
    x = _moving_state(station, rng)
    q_d = rng.standard_normal(len(station.joint_names))
    dut.GetInputPort("desired_position").FixValue(context, q_d)
    dut.GetInputPort("state").FixValue(context, x)
    expected = [
        km[n] * (q_d[station.joint_names.index(n)] - x[plant.GetJointByName(n).position_start()]) for n in ARM_JOINTS
    ]
    np.testing.assert_allclose(dut.GetOutputPort("motor_torque").Eval(context), expected, rtol=1e-12)


def test_estimator_inverts_drakes_inverse_dynamics_for_a_hand_force(station):
    """Eqs. (25)-(26) against Drake's recursive Newton-Euler: with the PD torque that a known
    hand force, gravity, damping, velocities and accelerations require, the estimator
    returns the force (the chains' joints are 5 >= 3, so J^T has full column rank)."""
    plant = station.plant
    _, kd = _gains(station)
    dut = ArmExternalForceEstimator(plant, damping=kd)
    ctx = plant.CreateDefaultContext()
    rng = np.random.default_rng(7)
    x = _moving_state(station, rng)
    v_dot = rng.standard_normal(plant.num_velocities())
    plant.SetPositionsAndVelocities(ctx, x)
    forces = MultibodyForces(plant)
    plant.CalcForceElementsContribution(ctx, forces)  # gravity and joint damping
    F = np.array([[1.2, -0.7, 0.4], [-2.0, 0.3, -0.5]])
    for chain, f in zip(NAO_ARM_CHAINS, F):
        plant.GetBodyByName(chain.hand_body).AddInForce(
            ctx, np.asarray(chain.p_HP, float), SpatialForce(np.zeros(3), f), plant.world_frame(), forces
        )
    tau = plant.CalcInverseDynamics(ctx, v_dot, forces)  # the actuation the motion needs
    tau_g = plant.CalcGravityGeneralizedForces(ctx)
    rows = [plant.GetJointByName(n).velocity_start() for n in ARM_JOINTS]
    # The station's PD: u = -tau_g + K_m (q_d - q) - K_d v, so eq. 27 reads u + tau_g + K_d v.
    tau_m = tau[rows] + tau_g[rows] + np.array([kd[n] for n in ARM_JOINTS]) * x[plant.num_positions() :][rows]
    np.testing.assert_allclose(dut.hand_forces(x, tau_m, v_dot), F.reshape(-1), atol=1e-9)
    # Without the inertia term the same data gives a wrong answer: the term matters here.
    assert np.abs(dut.hand_forces(x, tau_m) - F.reshape(-1)).max() > 0.05


def test_estimator_filter_and_first_sample(station):
    """The first update takes the raw estimate (static: v_dot = 0); later updates low-pass it
    with alpha = 1 - exp(-T / tau)."""
    plant = station.plant
    dut = ArmExternalForceEstimator(plant, period=0.01, filter_time_constant=0.1)
    context = dut.CreateDefaultContext()
    x = settle_standing_state(wide_stance()).copy()
    x[plant.num_positions() :] = 0.0
    tau_m = np.linspace(-0.2, 0.3, len(ARM_JOINTS))
    dut.GetInputPort("motor_torque").FixValue(context, tau_m)
    dut.GetInputPort("state").FixValue(context, x)
    raw = dut.hand_forces(x, tau_m)
    state = dut.EvalUniquePeriodicDiscreteUpdate(context)
    context.SetDiscreteState(state)
    np.testing.assert_allclose(dut.GetOutputPort("hand_forces").Eval(context), raw, rtol=1e-12)
    dut.GetInputPort("motor_torque").FixValue(context, 2 * tau_m)
    context.SetDiscreteState(dut.EvalUniquePeriodicDiscreteUpdate(context))
    alpha = 1 - np.exp(-0.1)
    np.testing.assert_allclose(dut.GetOutputPort("hand_forces").Eval(context), raw + alpha * raw, rtol=1e-9)


def test_observer_hand_force_inverts_eq_11(station):
    """VirtualForceTruth (eq. 11, systems.simulation.ground_truth) of a force at the hands' mean
    position, mapped back: the original force, shared by the two hands."""
    plant, humanoid = station.plant, station.humanoid
    dut = ObserverHandForce(plant, humanoid.sole_frames["right"], model_instances=[humanoid.model_instance])
    context = dut.CreateDefaultContext()
    x = settle_standing_state(wide_stance())
    ctx = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(ctx, x)
    p_hand = np.mean(
        [plant.GetBodyByName(c.hand_body).EvalPoseInWorld(ctx).translation() for c in NAO_ARM_CHAINS], axis=0
    )
    p_com = plant.CalcCenterOfMassPositionInWorld(ctx, [humanoid.model_instance])
    ground = humanoid.sole_frames["right"].CalcPoseInWorld(ctx).translation()[2]
    F = np.array([-3.0, 0.8, -1.5])
    wrench = np.concatenate([np.cross(p_hand, F), F])
    virtual = VirtualForceTruth.virtual_force(wrench, p_com, ground)
    assert abs(virtual[0] / F[0] - 1.0) > 0.1  # the hands are well below the CoM
    dut.GetInputPort("virtual_force").FixValue(context, virtual)
    dut.GetInputPort("state").FixValue(context, x)
    np.testing.assert_allclose(dut.GetOutputPort("hand_forces").Eval(context), np.tile(F / 2, 2), atol=1e-12)


def test_blender_k1_is_the_fraction_of_loaded_fsrs():
    """Eq. (28): K1 = K_a / K_t with K_t = 8, K2 = 1 - K1; and the constant-gain option."""
    dut = CompliantArmBlender(6, fsr_threshold=1.0)
    context = dut.CreateDefaultContext()
    F_o, F_j = np.arange(6.0), -np.arange(6.0) - 1.0
    dut.GetInputPort("observer_force").FixValue(context, F_o)
    dut.GetInputPort("joint_force").FixValue(context, F_j)
    for readings, k_a in (([6, 6, 6, 6, 6, 6, 6, 6], 8), ([6, 0.2, 6, 0, 1.0, 1.01, 0, 25], 4), ([0.0] * 8, 0)):
        dut.GetInputPort("fsr_forces").FixValue(context, readings)
        k1 = k_a / 8
        assert dut.GetOutputPort("k1").Eval(context)[0] == k1
        np.testing.assert_allclose(dut.GetOutputPort("blended_force").Eval(context), k1 * F_o + (1 - k1) * F_j)
    constant = CompliantArmBlender(6, constant_k1=0.3)
    context = constant.CreateDefaultContext()
    constant.GetInputPort("observer_force").FixValue(context, F_o)
    constant.GetInputPort("joint_force").FixValue(context, F_j)
    constant.GetInputPort("fsr_forces").FixValue(context, np.zeros(8))
    np.testing.assert_allclose(constant.GetOutputPort("blended_force").Eval(context), 0.3 * F_o + 0.7 * F_j)
    # Extension: a saturated FSR (the observer's CoP and normal force are wrong) gives K1 = 0.
    guarded = CompliantArmBlender(6, saturation_guard=25.0)
    context = guarded.CreateDefaultContext()
    guarded.GetInputPort("fsr_forces").FixValue(context, [6, 6, 6, 25.0, 6, 6, 6, 6])
    assert guarded.GetOutputPort("k1").Eval(context)[0] == 0.0
    guarded.GetInputPort("fsr_forces").FixValue(context, [6, 6, 6, 24.9, 6, 6, 6, 0.5])
    assert guarded.GetOutputPort("k1").Eval(context)[0] == 7 / 8


def test_controller_targets_and_ik_follow_eq_29(station):
    """With the torso yawed and pitched, a constant world force: after a few updates the IK
    solution puts each hand (forward kinematics on an independent context, torso frame) at
    x_h^0 + F_x / k with F_x along the torso's x axis; q_d adds -K_m^-1 J^T F."""
    plant, humanoid = station.plant, station.humanoid
    q_nominal = joint_vector_from_names(plant, full_posture(humanoid, wide_stance()))
    km = 5.0
    dut = HandComplianceController(plant, q_nominal, stiffness=50.0, motor_constants=km, ik_iterations=3)
    context = dut.CreateDefaultContext()
    x = settle_standing_state(wide_stance()).copy()
    yaw, pitch = 0.4, 0.1
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]) @ np.array(
        [[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0], [-np.sin(pitch), 0, np.cos(pitch)]]
    )
    x[:4] = RotationMatrix(R).ToQuaternion().wxyz()
    F_W = np.array([-1.0, 0.5, 0.2, -2.0, -0.3, 0.1])
    dut.GetInputPort("hand_forces").FixValue(context, F_W)
    dut.GetInputPort("state").FixValue(context, x)
    for _ in range(5):
        context.SetDiscreteState(dut.EvalUniquePeriodicDiscreteUpdate(context))
    q_d = dut.GetOutputPort("desired_position").Eval(context)
    m = len(ARM_JOINTS)
    q_ik = context.get_discrete_state(0).get_value()[:m]
    ctx = plant.CreateDefaultContext()
    q = plant.GetPositions(ctx)
    for k, joint in enumerate(station.topology.joints):
        q[joint.position_start()] = q_nominal[k]
    for n, value in zip(ARM_JOINTS, q_ik):
        q[plant.GetJointByName(n).position_start()] = value
    plant.SetPositions(ctx, q)
    torso = humanoid.base_body.body_frame()
    p0 = dut.rest_hand_positions.reshape(2, 3)
    for i, chain in enumerate(NAO_ARM_CHAINS):
        F_B = R.T @ F_W[3 * i : 3 * i + 3]
        p = plant.CalcPointsPositions(ctx, plant.GetBodyByName(chain.hand_body).body_frame(), np.zeros(3), torso)
        np.testing.assert_allclose(p.ravel(), p0[i] + [F_B[0] / 50.0, 0, 0], atol=2e-5)
        J = plant.CalcJacobianTranslationalVelocity(
            ctx, JacobianWrtVariable.kV, plant.GetBodyByName(chain.hand_body).body_frame(), np.zeros(3), torso, torso
        )
        cols = [plant.GetJointByName(n).velocity_start() for n in chain.joint_names]
        k = [station.joint_names.index(n) for n in chain.joint_names]
        np.testing.assert_allclose(q_d[k], q_ik[5 * i : 5 * i + 5] - J[:, cols].T @ F_B / km, atol=1e-9)
    # The other joints keep the nominal targets.
    others = [k for k, n in enumerate(station.joint_names) if n not in ARM_JOINTS]
    np.testing.assert_array_equal(q_d[others], q_nominal[others])


def test_compliance_moves_the_hands_by_f_over_k():
    """Closed loop on the simulated robot (noise off, joint-level estimate only, K1 = 0 so
    that a 2.5 s run reaches steady state): 1.5 N backwards on each hand; the hands' true
    displacement along the torso's x axis is within 10 % of F / k, and the joint-level
    estimate is within 3 % of the applied force."""
    profile = SmoothPiecewise((0.0, 0.3, 1.0), (0.0, 0.0, 1.5))
    diagram, handles = build_nao_compliant_arms_diagram(
        hand_pushes(profile),
        station=StationConfig(model="nao_like", noise=False),
        constant_k1=0.0,
        motor_constants=dict(identified_motor_constants()),
    )
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.set_initial_state(context, settle_standing_state(wide_stance()))
    simulator.AdvanceTo(2.5)
    plant = handles.station.plant
    ctx = plant.GetMyContextFromRoot(context)
    torso = handles.station.humanoid.base_body.body_frame()
    R_WB = torso.CalcRotationMatrixInWorld(ctx).matrix()
    F_B = R_WB.T @ np.array([-1.5, 0.0, 0.0])
    p0 = handles.controller.rest_hand_positions.reshape(2, 3)
    estimate = (
        handles.joint_estimator.GetOutputPort("hand_forces")
        .Eval(handles.joint_estimator.GetMyContextFromRoot(context))
        .reshape(2, 3)
    )
    for i, chain in enumerate(NAO_ARM_CHAINS):
        p = plant.CalcPointsPositions(ctx, plant.GetBodyByName(chain.hand_body).body_frame(), np.zeros(3), torso)
        displacement = p.ravel()[0] - p0[i][0]
        assert abs(displacement - F_B[0] / 50.0) < 0.10 * abs(F_B[0] / 50.0), (chain.side, displacement)
        assert np.linalg.norm(estimate[i] - [-1.5, 0, 0]) < 0.03 * 1.5, estimate[i]


def test_bad_parameters_and_nan_inputs(station):
    plant = station.plant
    q_nominal = np.zeros(len(station.joint_names))
    with pytest.raises(ValueError, match="motor_constants must be positive"):
        JointTorqueFromPositionError(plant, 0.0)
    with pytest.raises(ValueError, match="no value for"):
        JointTorqueFromPositionError(plant, {"LShoulderPitch": 5.0})
    with pytest.raises(ValueError, match="unknown or no joints"):
        JointTorqueFromPositionError(plant, 5.0, [ArmChain("left", ("NoSuchJoint",), "l_gripper")])
    with pytest.raises(ValueError, match="no body named"):
        ArmExternalForceEstimator(plant, [ArmChain("left", ("LShoulderPitch",), "no_hand")])
    with pytest.raises(ValueError, match="share joints"):
        ArmExternalForceEstimator(plant, [NAO_ARM_CHAINS[0], NAO_ARM_CHAINS[0]])
    with pytest.raises(ValueError, match="period must be positive"):
        ArmExternalForceEstimator(plant, period=0.0)
    with pytest.raises(ValueError, match="filter_time_constant must be non-negative"):
        ArmExternalForceEstimator(plant, filter_time_constant=-1.0)
    with pytest.raises(ValueError, match="constant_k1 must be in"):
        CompliantArmBlender(6, constant_k1=1.5)
    with pytest.raises(ValueError, match="size must be a positive integer"):
        CompliantArmBlender(0)
    with pytest.raises(ValueError, match="fsr_threshold must be non-negative"):
        CompliantArmBlender(6, fsr_threshold=float("nan"))
    with pytest.raises(ValueError, match="stiffness must be positive"):
        HandComplianceController(plant, q_nominal, stiffness=0.0)
    with pytest.raises(ValueError, match="nominal_position must be"):
        HandComplianceController(plant, q_nominal[:-1])
    with pytest.raises(ValueError, match="ik_iterations"):
        HandComplianceController(plant, q_nominal, ik_iterations=0)
    # NaN on an input names the system and the port.
    blender = CompliantArmBlender(6)
    context = blender.CreateDefaultContext()
    blender.GetInputPort("observer_force").FixValue(context, np.full(6, np.nan))
    blender.GetInputPort("joint_force").FixValue(context, np.zeros(6))
    blender.GetInputPort("fsr_forces").FixValue(context, np.zeros(8))
    with pytest.raises(ValueError, match="CompliantArmBlender: input 'observer_force' has NaN"):
        blender.GetOutputPort("blended_force").Eval(context)
    torque = JointTorqueFromPositionError(plant, 5.0)
    context = torque.CreateDefaultContext()
    torque.GetInputPort("desired_position").FixValue(context, np.zeros(len(station.joint_names)))
    x = settle_standing_state(wide_stance()).copy()
    x[-1] = np.inf
    torque.GetInputPort("state").FixValue(context, x)
    with pytest.raises(ValueError, match="JointTorqueFromPositionError: input 'state' has NaN or inf"):
        torque.GetOutputPort("motor_torque").Eval(context)
    controller = HandComplianceController(plant, joint_vector_from_names(plant, station.humanoid.nominal_posture))
    context = controller.CreateDefaultContext()
    controller.GetInputPort("hand_forces").FixValue(context, [np.nan] + [0.0] * 5)
    controller.GetInputPort("state").FixValue(context, settle_standing_state(wide_stance()))
    with pytest.raises(ValueError, match="HandComplianceController: input 'hand_forces'"):
        controller.EvalUniquePeriodicDiscreteUpdate(context)
