"""Tests of the momentum residuals (systems/residuals/momentum_residuals.py) against physics with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable, RevoluteJoint, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, LogVectorOutput

from models import MODEL_NAMES, add_humanoid, set_standing_state
from systems.residuals.momentum_residuals import ClassicalResidual, ExternalResidual, InternalResidual, ResidualModel
from systems.simulation.pd_gravity import PdGravityController

T = 1e-3


def _push(plant, body, p_BoP_B, f_W):
    force = ExternallyAppliedSpatialForce()
    force.body_index = body.index()
    force.p_BoBq_B = np.asarray(p_BoP_B, dtype=float)
    force.F_Bq_W = SpatialForce(np.zeros(3), np.asarray(f_W, dtype=float))
    return force


def _single_body_plant():
    plant = MultibodyPlant(time_step=T)
    plant.AddRigidBody("body", SpatialInertia.SolidBoxWithMass(3.0, 0.4, 0.2, 0.1))
    plant.Finalize()
    return plant


def _chain_plant(reverse: bool = False, time_step: float = T):
    """Three boxes A - B - C linked by two revolute joints (about y, then x).

    With ``reverse`` the same physical chain is built from C (the floating base is C
    instead of A): the base frame moves to the other end of the robot."""
    plant = MultibodyPlant(time_step=time_step)
    inertia = {
        "A": SpatialInertia.SolidBoxWithMass(4.0, 0.3, 0.3, 0.3),
        "B": SpatialInertia.SolidBoxWithMass(1.5, 0.1, 0.1, 0.4),
        "C": SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.3),
    }
    bodies = {name: plant.AddRigidBody(name, m) for name, m in inertia.items()}
    # Joint 1 between A and B at A's top; joint 2 between B and C at B's top.
    joints = [("A", "B", [0, 0, 0.15], [0, 0, -0.2], [0, 1, 0]), ("B", "C", [0, 0, 0.2], [0, 0, -0.15], [1, 0, 0])]
    if reverse:
        joints = [(c, p, pc, pp, [-a for a in axis]) for (p, c, pp, pc, axis) in reversed(joints)]
    for k, (parent, child, p_parent, p_child, axis) in enumerate(joints):
        plant.AddJoint(
            RevoluteJoint(
                f"j{k}_{parent}{child}",
                plant.AddFrame(_offset(f"{parent}{child}_P", bodies[parent], p_parent)),
                plant.AddFrame(_offset(f"{parent}{child}_C", bodies[child], p_child)),
                axis,
            )
        )
    plant.Finalize()
    return plant


def _offset(name, body, p):
    from pydrake.multibody.tree import FixedOffsetFrame

    return FixedOffsetFrame(name, body.body_frame(), RigidTransform(np.asarray(p, dtype=float)))


def _run(plant, pushes, residuals, duration, *, torque=None, initial_state=None):
    """Simulates ``plant`` with constant ``pushes`` and returns {name: (times, log)}."""
    builder = DiagramBuilder()
    builder.AddSystem(plant)
    if pushes:
        builder.Connect(
            builder.AddSystem(ConstantValueSource(AbstractValue.Make(pushes))).get_output_port(),
            plant.get_applied_spatial_force_input_port(),
        )
    logs = {}
    for name, residual in residuals.items():
        builder.AddSystem(residual)
        builder.Connect(plant.get_state_output_port(), residual.GetInputPort("state"))
        if residual.HasInputPort("measured_torque"):
            n = residual.GetInputPort("measured_torque").size()
            tau = np.zeros(n) if torque is None else torque
            builder.Connect(
                builder.AddSystem(ConstantVectorSource(tau)).get_output_port(), residual.GetInputPort("measured_torque")
            )
        port = residual.GetOutputPort("residual" if residual.HasOutputPort("residual") else "external_wrench_base")
        logs[name] = LogVectorOutput(port, builder, publish_period=T)
        if residual.HasOutputPort("external_wrench_world"):
            logs[name + "_world"] = LogVectorOutput(
                residual.GetOutputPort("external_wrench_world"), builder, publish_period=T
            )
    logs["plant_state"] = LogVectorOutput(plant.get_state_output_port(), builder, publish_period=T)
    if torque is not None and plant.num_actuated_dofs() > 0:
        builder.Connect(
            builder.AddSystem(ConstantVectorSource(torque)).get_output_port(), plant.get_actuation_input_port()
        )
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    if initial_state is not None:
        plant.SetPositionsAndVelocities(plant.GetMyMutableContextFromRoot(context), initial_state)
    simulator.AdvanceTo(duration)
    out = {}
    for name, logger in logs.items():
        log = logger.FindLog(context)
        out[name] = (log.sample_times(), log.data())
    return out, plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))


def test_external_residual_of_a_free_body_converges_like_a_first_order_filter():
    """A constant force on a free body: r_ext -> the wrench about the body origin in F0, with
    the discrete first-order response r_k = (1 - (1 - K T)^k) f (time constant ~ 1/K)."""
    plant = _single_body_plant()
    body = plant.GetBodyByName("body")
    f_W = np.array([2.0, -1.0, 4.0])
    p_B = np.zeros(3)  # through the centre of mass: the body translates without turning
    K = 25.0
    logs, x_final = _run(plant, [_push(plant, body, p_B, f_W)], {"ext": ExternalResidual(plant, K)}, 0.4)
    times, r = logs["ext"]
    _, r_world = logs["ext_world"]
    # The logger's sample at t_k is published before the update at t_k: it shows r_{k-1}.
    k = int(round((1.0 / K) / T))
    expected_fraction = 1.0 - (1.0 - K * T) ** (k - 1)
    assert abs(np.linalg.norm(r[3:, k]) / np.linalg.norm(f_W) - expected_fraction) < 1e-3
    # Steady state (t >> 1/K): the world force equals f, the world moment about the world
    # origin equals p_WP x f (P moves with the body: compare with its final position).
    final_world = r_world[:, -1]
    assert np.allclose(final_world[3:], f_W, rtol=0, atol=1e-3 * np.linalg.norm(f_W))
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, x_final)
    p_WP = plant.CalcPointsPositions(context, body.body_frame(), p_B, plant.world_frame()).ravel()
    # In F0 the wrench is [0; f] (the force acts at the base origin), so the world moment
    # follows the moving point without lag (the log is one sample behind: 1 ms of motion).
    assert np.linalg.norm(final_world[:3] - np.cross(p_WP, f_W)) < 2e-3 * np.linalg.norm(np.cross(p_WP, f_W))


def test_residuals_vanish_without_external_force():
    """No push, a robot moving fast under gravity: all residuals stay ~0. The plant is
    continuous (the 1 kHz observers integrate its motion to second order: ~1e-6 here); on a
    1 kHz discrete (symplectic Euler) plant the same case gives ~4e-3 N, first order in T."""
    plant = _chain_plant(time_step=0.0)
    rng = np.random.default_rng(0)
    x0 = plant.GetPositionsAndVelocities(plant.CreateDefaultContext())
    nq = plant.num_positions()
    x0[nq:] = rng.normal(size=plant.num_velocities()) * 0.5
    model = ResidualModel(plant)
    residuals = {
        "classical": ClassicalResidual(plant, 50.0, model=model, joint_damping=0.0),
        "internal": InternalResidual(plant, 50.0, model=model, joint_damping=0.0),
        "external": ExternalResidual(plant, 50.0, model=model),
    }
    logs, _ = _run(plant, [], residuals, 0.5, initial_state=x0)
    for name in residuals:
        r = logs[name][1]
        assert np.abs(r).max() < 2e-5, (name, np.abs(r).max())


def _filtered(samples: np.ndarray, K: float) -> np.ndarray:
    """What a residual logged at t_k shows for truth samples tau(t_j) (columns): the discrete
    first-order filter f_{j+1} = (1 - K T) f_j + K T tau_j, one sample behind (the logger
    publishes before the update at t_k)."""
    out = np.zeros_like(samples)
    f = np.zeros(samples.shape[0])
    for k in range(2, samples.shape[1]):
        f = (1.0 - K * T) * f + K * T * samples[:, k - 2]
        out[:, k] = f
    return out


def _true_joint_effort(plant, x, body, p_B, f_W):
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, x)
    world = plant.world_frame()
    J = plant.CalcJacobianTranslationalVelocity(context, JacobianWrtVariable.kV, body.body_frame(), p_B, world, world)
    M = plant.CalcMassMatrix(context)
    J_fb = J[:, 6:] - J[:, :6] @ np.linalg.solve(M[:6, :6], M[:6, 6:])
    return J_fb.T @ f_W, J[:, 6:].T @ f_W


def test_internal_residual_on_a_floating_chain_and_its_base_invariance():
    """A force on the middle body of a floating 3-body chain: the internal residual equals the
    true joint effort J^fb^T f (eq. 12) whichever end is the floating base, while the
    classical residual's joint part is J_j^T f, which depends on where the base is."""
    f_W = np.array([0.0, 3.0, -2.0])
    p_B = np.array([0.02, 0.0, 0.1])
    results = {}
    K = 100.0
    for reverse in (False, True):
        plant = _chain_plant(reverse, time_step=0.0)
        body = plant.GetBodyByName("B")
        model = ResidualModel(plant)
        residuals = {
            "internal": InternalResidual(plant, K, model=model, joint_damping=0.0),
            "classical": ClassicalResidual(plant, K, model=model, joint_damping=0.0),
        }
        logs, _ = _run(plant, [_push(plant, body, p_B, f_W)], residuals, 0.15)
        states = logs["plant_state"][1]
        truths = [_true_joint_effort(plant, states[:, k], body, p_B, f_W) for k in range(states.shape[1])]
        true_fb = _filtered(np.array([t[0] for t in truths]).T, K)
        true_fixed = _filtered(np.array([t[1] for t in truths]).T, K)
        internal = logs["internal"][1]
        classical = logs["classical"][1][6:]
        # Against the first-order-filtered truth over the whole run, to 0.2 % of its peak
        # (what is left is the O(T^2) time alignment of a 1 kHz observer on a moving robot).
        assert np.abs(internal - true_fb).max() < 2e-3 * np.abs(true_fb).max(), np.abs(internal - true_fb).max()
        assert np.abs(classical - true_fixed).max() < 2e-3 * np.abs(true_fixed).max()
        results[reverse] = (np.abs(internal[:, -1]), np.abs(classical[:, -1]))
    # Joint order is reversed in the reversed chain; the joint efforts' magnitudes agree.
    internal_a, classical_a = results[False]
    internal_b, classical_b = results[True]
    assert np.allclose(internal_a, internal_b[::-1], rtol=0.03), (internal_a, internal_b)
    # The classical estimate depends on the base: from A the force on B loads only joint 1,
    # from C it loads only joint 2 (between C and B).
    assert classical_a[1] < 1e-3 and classical_b[1] < 1e-3
    assert classical_a[0] > 0.02 and classical_b[0] > 0.02


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_internal_and_external_residuals_on_a_humanoid_in_zero_gravity(name):
    """A humanoid floating in space under joint PD control is pushed on the right shoulder:
    the internal residual converges to J^fb^T f (legs included) and the external one to the
    pushing wrench; the classical one sees nothing at the legs."""
    plant = MultibodyPlant(time_step=T)
    handles = add_humanoid(plant, name)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    plant.Finalize()
    shoulder = handles.shoulder_bodies["right"]
    f_W = np.array([4.0, -3.0, -5.0]) * (1.0 if name == "hrp4_like" else 0.25)
    p_B = np.zeros(3)
    model = ResidualModel(plant)
    residuals = {
        "internal": InternalResidual(plant, 100.0, model=model),
        "external": ExternalResidual(plant, 100.0, model=model),
        "classical": ClassicalResidual(plant, 100.0, model=model),
    }
    builder = DiagramBuilder()
    builder.AddSystem(plant)
    builder.Connect(
        builder.AddSystem(
            ConstantValueSource(AbstractValue.Make([_push(plant, shoulder, p_B, f_W)]))
        ).get_output_port(),
        plant.get_applied_spatial_force_input_port(),
    )
    n = plant.num_velocities() - 6
    controller = builder.AddSystem(PdGravityController(plant, 200.0, 5.0))
    # The nominal posture keeps every joint away from its limits (a limit's constraint force
    # would be an external effort that no residual models).
    context0 = plant.CreateDefaultContext()
    set_standing_state(plant, context0, handles)
    q_joints = np.array([plant.GetPositions(context0)[j.position_start()] for j in model.dynamics.topology.joints])
    builder.Connect(builder.AddSystem(ConstantVectorSource(q_joints)).get_output_port(), controller.get_input_port(0))
    builder.Connect(plant.get_state_output_port(), controller.get_input_port(1))
    builder.Connect(controller.get_output_port(), plant.get_actuation_input_port())
    # The torque each motor applied over the last step, in v[6:] order.
    torque = builder.AddSystem(_ActuationToJointTorque(plant))
    builder.Connect(plant.get_net_actuation_output_port(), torque.get_input_port())
    loggers = {}
    for residual in residuals.values():
        builder.AddSystem(residual)
        builder.Connect(plant.get_state_output_port(), residual.GetInputPort("state"))
        if residual.HasInputPort("measured_torque"):
            builder.Connect(torque.get_output_port(), residual.GetInputPort("measured_torque"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    plant.SetPositionsAndVelocities(
        plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()), plant.GetPositionsAndVelocities(context0)
    )
    simulator.AdvanceTo(0.2)
    context = simulator.get_context()
    x = plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))
    true_fb, _ = _true_joint_effort(plant, x, shoulder, p_B, f_W)
    internal = residuals["internal"].GetOutputPort("residual").Eval(residuals["internal"].GetMyContextFromRoot(context))
    assert np.linalg.norm(internal - true_fb) < 0.03 * np.linalg.norm(true_fb)
    legs = [model.dynamics.topology.joints.index(plant.GetJointByName(j)) for j in handles.joint_groups["legs"]]
    assert np.linalg.norm(true_fb[legs]) > 0.2 * np.linalg.norm(true_fb)  # the legs feel it
    classical = (
        residuals["classical"].GetOutputPort("residual").Eval(residuals["classical"].GetMyContextFromRoot(context))
    )
    assert np.abs(classical[6:][legs]).max() < 1e-3 * np.linalg.norm(f_W)  # the classical one does not
    external = (
        residuals["external"]
        .GetOutputPort("external_wrench_world")
        .Eval(residuals["external"].GetMyContextFromRoot(context))
    )
    assert np.linalg.norm(external[3:] - f_W) < 0.02 * np.linalg.norm(f_W)
    del loggers, n


class _ActuationToJointTorque:
    """Factory for a tiny system mapping actuation (actuator order) to v[6:] joint torques."""

    def __new__(cls, plant):
        from pydrake.systems.primitives import MatrixGain

        B = plant.MakeActuationMatrix()[6:, :]  # (n, nu): tau_joints = B u
        return MatrixGain(B)


def test_bad_inputs_give_clear_errors():
    plant = _chain_plant()
    residual = InternalResidual(plant, 50.0)
    context = residual.CreateDefaultContext()
    x = plant.GetPositionsAndVelocities(plant.CreateDefaultContext())
    residual.GetInputPort("state").FixValue(context, x)
    torque = np.zeros(2)
    torque[1] = np.nan
    residual.GetInputPort("measured_torque").FixValue(context, torque)
    with pytest.raises(ValueError, match="'measured_torque' has NaN or inf at indices \\[1\\]"):
        residual.EvalUniquePeriodicDiscreteUpdate(context)
    with pytest.raises(ValueError, match="known wrench frame 'nowhere'"):
        InternalResidual(plant, 50.0, known_wrench_frames=["nowhere"])
    with pytest.raises(ValueError, match="fixed to the world"):
        ExternalResidual(plant, 50.0, known_wrench_frames=[plant.world_frame()])
    with pytest.raises(ValueError, match="K T < 1"):
        ExternalResidual(plant, 2000.0)
    with pytest.raises(ValueError, match="gain must be a scalar or have 2 entries"):
        InternalResidual(plant, [1.0, 2.0, 3.0])
    other = _chain_plant()
    with pytest.raises(ValueError, match="another plant"):
        InternalResidual(plant, 10.0, model=ResidualModel(other))
    with pytest.raises(ValueError, match="no floating base"):
        fixed = MultibodyPlant(T)
        fixed.WeldFrames(
            fixed.world_frame(), fixed.AddRigidBody("b", SpatialInertia.SolidBoxWithMass(1, 1, 1, 1)).body_frame()
        )
        fixed.Finalize()
        ExternalResidual(fixed, 10.0)


def test_known_wrenches_are_removed_from_every_residual():
    """Eqs. (6), (10), (16): a measured wrench (e.g. an F/T sensor's) on the known-wrench port
    is the robot's known external force; telling the residuals about a push removes it."""
    plant = MultibodyPlant(time_step=0.0)
    inertia = SpatialInertia.SolidBoxWithMass(2.0, 0.2, 0.2, 0.2)
    base = plant.AddRigidBody("base", inertia)
    link = plant.AddRigidBody("link", inertia)
    plant.AddJoint(RevoluteJoint("hinge", base.body_frame(), link.body_frame(), [0, 1, 0]))
    p_link = np.array([0.1, 0.0, 0.3])
    sensor = plant.AddFrame(_offset("sensor", link, p_link))
    plant.Finalize()
    f_W = np.array([1.0, 0.5, -2.0])
    known = np.concatenate((np.zeros(3), f_W))  # [moment about the sensor origin; force], world
    model = ResidualModel(plant)
    residuals = {
        "classical": ClassicalResidual(plant, 50.0, known_wrench_frames=[sensor], model=model, joint_damping=0.0),
        "internal": InternalResidual(plant, 50.0, known_wrench_frames=["sensor"], model=model, joint_damping=0.0),
        "external": ExternalResidual(plant, 50.0, known_wrench_frames=[sensor], model=model),
    }
    builder = DiagramBuilder()
    builder.AddSystem(plant)
    builder.Connect(
        builder.AddSystem(ConstantValueSource(AbstractValue.Make([_push(plant, link, p_link, f_W)]))).get_output_port(),
        plant.get_applied_spatial_force_input_port(),
    )
    wrench_source = builder.AddSystem(ConstantVectorSource(known))
    zero_torque = builder.AddSystem(ConstantVectorSource(np.zeros(1)))
    for residual in residuals.values():
        builder.AddSystem(residual)
        builder.Connect(plant.get_state_output_port(), residual.GetInputPort("state"))
        builder.Connect(wrench_source.get_output_port(), residual.GetInputPort("known_wrenches"))
        if residual.HasInputPort("measured_torque"):
            builder.Connect(zero_torque.get_output_port(), residual.GetInputPort("measured_torque"))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    for name, residual in residuals.items():
        port = residual.GetOutputPort("residual" if name != "external" else "external_wrench_world")
        value = port.Eval(residual.GetMyContextFromRoot(context))
        # Unknown part ~0: below 0.5 % of the (fully known) push. What is left is the O(T)
        # error of reading, at t_k, a wrench whose point moved during the last period
        # (about 0.2 % here; the residuals take measured forces as held over that period).
        assert np.abs(value).max() < 5e-3 * np.linalg.norm(f_W), (name, value)


def test_classical_residual_on_a_fixed_base_arm():
    """The classical special case (De Luca et al., recalled by eq. 7): on a fixed-base
    two-link arm under gravity with a constant force at the tip, r -> J^T f."""
    plant = MultibodyPlant(time_step=0.0)
    upper = plant.AddRigidBody("upper", SpatialInertia.SolidCylinderWithMass(2.0, 0.04, 0.4, [0, 0, 1]))
    lower = plant.AddRigidBody("lower", SpatialInertia.SolidCylinderWithMass(1.0, 0.03, 0.3, [0, 0, 1]))
    plant.AddJoint(
        RevoluteJoint("shoulder", plant.world_frame(), plant.AddFrame(_offset("u_top", upper, [0, 0, 0.2])), [0, 1, 0])
    )
    plant.AddJoint(
        RevoluteJoint(
            "elbow",
            plant.AddFrame(_offset("u_bottom", upper, [0, 0, -0.2])),
            plant.AddFrame(_offset("l_top", lower, [0, 0, 0.15])),
            [0, 1, 0],
        )
    )
    plant.Finalize()
    tip = np.array([0.0, 0.0, -0.15])
    f_W = np.array([3.0, 0.0, 1.0])
    K = 100.0
    residual = ClassicalResidual(plant, K, joint_damping=0.0)
    assert residual.GetOutputPort("residual").size() == 2
    x0 = np.array([0.3, -0.5, 0.0, 0.0])
    logs, _ = _run(plant, [_push(plant, lower, tip, f_W)], {"classical": residual}, 0.3, initial_state=x0)
    states = logs["plant_state"][1]
    context = plant.CreateDefaultContext()
    truth = []
    for k in range(states.shape[1]):
        plant.SetPositionsAndVelocities(context, states[:, k])
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, lower.body_frame(), tip, plant.world_frame(), plant.world_frame()
        )
        truth.append(J.T @ f_W)
    expected = _filtered(np.array(truth).T, K)
    r = logs["classical"][1]
    assert np.abs(r - expected).max() < 2e-3 * np.abs(expected).max(), np.abs(r - expected).max()
