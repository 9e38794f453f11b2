"""Tests of systems.simulation.pd_gravity.PdGravityController."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import RevoluteJoint, SpatialInertia
from pydrake.systems.framework import DiagramBuilder

from models import add_humanoid
from systems.simulation.pd_gravity import (
    PdGravityController,
    joint_vector_from_names,
    joints_in_velocity_order,
)

G = 9.81


def _small_ball(mass, p_BoBcm_B):
    """Spatial inertia about Bo of a 1 cm solid ball of `mass` centred at p_BoBcm_B."""
    return SpatialInertia.SolidSphereWithMass(mass, 0.01).Shift(-np.asarray(p_BoBcm_B))


def _chain_plant(actuator_order, effort_limits=(np.inf, np.inf, np.inf), masses=(1.0, 2.0, 3.0), lever=0.3):
    """Floating base + a chain of 3 links on revolute-y joints, CoM at `lever` along x.

    Actuators are added in `actuator_order` (indices of joints), so the actuation order
    can differ from the joint (velocity) order.
    """
    plant = MultibodyPlant(0.0)
    base = plant.AddRigidBody("base", SpatialInertia.SolidBoxWithMass(5.0, 0.2, 0.2, 0.2))
    parent = base
    joints = []
    for i, m in enumerate(masses):
        link = plant.AddRigidBody(f"link{i}", _small_ball(m, [lever, 0.0, 0.0]))
        joint = plant.AddJoint(RevoluteJoint(f"j{i}", parent.body_frame(), link.body_frame(), [0.0, 1.0, 0.0]))
        joints.append(joint)
        parent = link
    for i in actuator_order:
        plant.AddJointActuator(f"a{i}", joints[i], effort_limits[i])
    plant.Finalize()
    return plant, joints


def _fixed_context(dut, q_desired, x):
    ctx = dut.CreateDefaultContext()
    dut.get_input_port(0).FixValue(ctx, q_desired)
    dut.get_input_port(1).FixValue(ctx, x)
    return ctx


def test_ports_and_names():
    plant, _ = _chain_plant([0, 1, 2])
    dut = PdGravityController(plant, 1.0, 0.1)
    assert dut.get_input_port(0).get_name() == "desired_position"
    assert dut.get_input_port(0).size() == 3
    assert dut.get_input_port(1).get_name() == "state"
    assert dut.get_input_port(1).size() == plant.num_positions() + plant.num_velocities()
    assert dut.get_output_port(0).get_name() == "actuation"
    assert dut.get_output_port(0).size() == plant.num_actuated_dofs() == 3
    assert dut.joint_count == 3


def test_single_link_hand_computed():
    """One link with CoM at distance l along its x axis, joint axis y, base level.

    Rotating about y by θ maps x to (cos θ, 0, -sin θ), so the CoM height is
    z_base - l sin θ, V = m g z, and the gravity generalized force is
    τ_g = -dV/dθ = m g l cos θ; the controller outputs -τ_g + kp (θ_d - θ) - kd θ̇.
    """
    m, l = 2.0, 0.3
    plant = MultibodyPlant(0.0)
    base = plant.AddRigidBody("base", SpatialInertia.SolidBoxWithMass(5.0, 0.2, 0.2, 0.2))
    link = plant.AddRigidBody("link", _small_ball(m, [l, 0.0, 0.0]))
    joint = plant.AddJoint(RevoluteJoint("j", base.body_frame(), link.body_frame(), [0.0, 1.0, 0.0]))
    plant.AddJointActuator("a", joint, 100.0)
    plant.Finalize()
    kp, kd = 40.0, 3.0
    dut = PdGravityController(plant, kp, kd)
    theta, theta_dot, theta_d = 0.4, -0.7, 0.1
    ctx_p = plant.CreateDefaultContext()
    plant.SetFreeBodyPose(ctx_p, base, RigidTransform([0.1, 0.2, 1.0]))
    joint.set_angle(ctx_p, theta)
    joint.set_angular_rate(ctx_p, theta_dot)
    plant.SetFreeBodySpatialVelocity(ctx_p, base, SpatialVelocity([0.1, 0.0, 0.2], [0.3, 0.0, 0.0]))
    x = plant.GetPositionsAndVelocities(ctx_p)
    ctx = _fixed_context(dut, [theta_d], x)
    u = dut.get_output_port(0).Eval(ctx)
    expected = -m * G * l * np.cos(theta) + kp * (theta_d - theta) - kd * theta_dot
    np.testing.assert_allclose(u, [expected], rtol=1e-12)

    # Clipping to the actuator's effort limit (100 N m): a huge error saturates.
    ctx = _fixed_context(dut, [theta + 100.0], x)
    np.testing.assert_allclose(dut.get_output_port(0).Eval(ctx), [100.0])
    ctx = _fixed_context(dut, [theta - 100.0], x)
    np.testing.assert_allclose(dut.get_output_port(0).Eval(ctx), [-100.0])


def test_actuation_order_differs_from_joint_order():
    order = [2, 0, 1]  # actuator a2 first
    limits = (5.0, 6.0, 7.0)  # per joint
    plant, joints = _chain_plant(order, effort_limits=limits)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    # Joint (velocity) order is j0, j1, j2; actuation order is a2, a0, a1.
    assert [j.name() for j in joints_in_velocity_order(plant)] == ["j0", "j1", "j2"]
    kp = np.array([1.0, 10.0, 100.0])
    kd = np.array([0.5, 0.25, 0.125])
    dut = PdGravityController(plant, kp, kd)
    ctx_p = plant.CreateDefaultContext()
    q = np.array([0.01, 0.02, 0.03])
    qd = np.array([-0.1, 0.2, -0.3])
    for j, qi, vi in zip(joints, q, qd):
        j.set_angle(ctx_p, qi)
        j.set_angular_rate(ctx_p, vi)
    x = plant.GetPositionsAndVelocities(ctx_p)
    q_des = np.array([0.02, 0.0, 0.05])
    u = dut.get_output_port(0).Eval(_fixed_context(dut, q_des, x))
    tau = kp * (q_des - q) - kd * qd  # per joint, no gravity
    np.testing.assert_allclose(u, tau[order], rtol=1e-12)
    # Same thing through Drake's actuation matrix: B u = generalized force on the joints.
    B = plant.MakeActuationMatrix()
    np.testing.assert_allclose((B @ u)[6:], tau, rtol=1e-12)
    # The effort limits follow the actuators to their joints.
    u = dut.get_output_port(0).Eval(_fixed_context(dut, q_des + 1e3, x))
    np.testing.assert_allclose(u, np.array(limits)[order])


def test_gravity_compensation_on_humanoid_matches_actuation_matrix():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    h = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    dut = PdGravityController(plant, 100.0, 1.0, effort_limits=1e6)
    ctx_p = plant.CreateDefaultContext()
    rng = np.random.default_rng(0)
    q = plant.GetPositions(ctx_p)
    q[7:] = rng.uniform(-0.3, 0.3, plant.num_positions() - 7)
    plant.SetPositions(ctx_p, q)
    plant.SetFreeBodyPose(ctx_p, h.base_body, RigidTransform(RollPitchYaw(0.1, -0.2, 0.3), [0.0, 0.0, 0.8]))
    x = plant.GetPositionsAndVelocities(ctx_p)
    q_joints = np.array([j.GetOnePosition(ctx_p) for j in joints_in_velocity_order(plant)])
    u = dut.get_output_port(0).Eval(_fixed_context(dut, q_joints, x))
    B = plant.MakeActuationMatrix()
    tau_g = plant.CalcGravityGeneralizedForces(ctx_p)
    np.testing.assert_allclose(B @ u, np.concatenate([np.zeros(6), -tau_g[6:]]), atol=1e-9)
    # Nominal posture packing follows joint names.
    vec = joint_vector_from_names(plant, h.nominal_posture)
    joints = joints_in_velocity_order(plant)
    for k, j in enumerate(joints):
        assert vec[k] == h.nominal_posture[j.name()]
    with pytest.raises(ValueError, match="nope"):
        joint_vector_from_names(plant, {"nope": 1.0})


def test_bad_sizes_raise():
    plant, _ = _chain_plant([0, 1, 2])
    with pytest.raises(ValueError, match="kp"):
        PdGravityController(plant, np.ones(2), 1.0)
    with pytest.raises(ValueError, match="kd"):
        PdGravityController(plant, 1.0, np.ones((3, 1)))
    with pytest.raises(ValueError, match="effort_limits"):
        PdGravityController(plant, 1.0, 1.0, effort_limits=np.ones(4))
    with pytest.raises(ValueError, match="non-negative"):
        PdGravityController(plant, -1.0, 1.0)
    unfinalized = MultibodyPlant(0.0)
    with pytest.raises(ValueError, match="finalized"):
        PdGravityController(unfinalized, 1.0, 1.0)
    fixed = MultibodyPlant(0.0)
    body = fixed.AddRigidBody("b", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1))
    fixed.WeldFrames(fixed.world_frame(), body.body_frame())
    fixed.Finalize()
    with pytest.raises(ValueError, match="floating"):
        PdGravityController(fixed, 1.0, 1.0)


def test_internal_context_created_once():
    plant, _ = _chain_plant([0, 1, 2])
    dut = PdGravityController(plant, 1.0, 1.0)
    ctx_before = dut._context
    x = plant.GetPositionsAndVelocities(plant.CreateDefaultContext())
    dut.get_output_port(0).Eval(_fixed_context(dut, np.zeros(3), x))
    dut.get_output_port(0).Eval(_fixed_context(dut, np.ones(3), x))
    assert dut._context is ctx_before


def test_nan_inputs_raise_a_named_error():
    plant, _ = _chain_plant([0, 1, 2])
    dut = PdGravityController(plant, 10.0, 1.0)
    x = plant.GetPositionsAndVelocities(plant.CreateDefaultContext())
    x_bad = x.copy()
    x_bad[9] = np.nan
    with pytest.raises(ValueError, match=r"'state' has NaN or inf at indices \[9\]"):
        dut.get_output_port(0).Eval(_fixed_context(dut, np.zeros(3), x_bad))
    with pytest.raises(ValueError, match="'desired_position'"):
        dut.get_output_port(0).Eval(_fixed_context(dut, [0.0, np.inf, 0.0], x))


def test_gravity_from_a_shared_residual_model_equals_drakes_gravity():
    """The PD's gravity through the estimators' ResidualModel (F[3:6]^T R_WB^T g) against
    Drake's CalcGravityGeneralizedForces, at random tilted, moving states of HRP-4."""
    from systems.residuals.momentum_residuals import ResidualModel

    plant = MultibodyPlant(1e-3)
    add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    model = ResidualModel(plant)
    shared = PdGravityController(plant, 50.0, 2.0, gravity_model=model)
    own = PdGravityController(plant, 50.0, 2.0)
    rng = np.random.default_rng(7)
    context = plant.CreateDefaultContext()
    n = shared.joint_count
    for _ in range(3):
        q = plant.GetPositions(context)
        q[:4] = RollPitchYaw(rng.uniform(-0.6, 0.6, 3)).ToQuaternion().wxyz()
        q[4:7] = rng.uniform(-1.0, 1.0, 3)
        q[7:] = rng.uniform(-0.3, 0.3, q.size - 7)
        x = np.concatenate([q, rng.normal(size=plant.num_velocities())])
        plant.SetPositions(context, q)
        tau_g = plant.CalcGravityGeneralizedForces(context)[6:]
        np.testing.assert_allclose(model.gravity_joint_torques(x), tau_g, atol=1e-9 * np.abs(tau_g).max())
        q_d = rng.uniform(-0.3, 0.3, n)
        u_shared = shared.get_output_port(0).Eval(_fixed_context(shared, q_d, x))
        u_own = own.get_output_port(0).Eval(_fixed_context(own, q_d, x))
        np.testing.assert_allclose(u_shared, u_own, atol=1e-9 * np.abs(u_own).max())


def test_gravity_of_a_mismatched_model_uses_the_models_inertias():
    """With the estimators' inertias perturbed (5 % mass, 10 % CoM, the realistic world's
    mismatch), the PD's gravity is the model's: uniform gravity's generalized force is
    M[:, 3:6] g, so its joint entries are F[3:6]^T R_WB^T g of the model's own
    floating-base decomposition (an independent route through three mass matrices), and
    they differ from the plant's defaults."""
    from systems.residuals.momentum_residuals import ResidualModel
    from systems.simulation.imperfections import ModelMismatch, perturbed_spatial_inertias

    plant = MultibodyPlant(1e-3)
    add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    model = ResidualModel(plant)
    model.set_spatial_inertias(perturbed_spatial_inertias(plant, ModelMismatch(5.0, 10.0, 10.0), seed=3))
    rng = np.random.default_rng(11)
    context = plant.CreateDefaultContext()
    g_W = plant.gravity_field().gravity_vector()
    for _ in range(3):
        q = plant.GetPositions(context)
        q[:4] = RollPitchYaw(rng.uniform(-0.6, 0.6, 3)).ToQuaternion().wxyz()
        q[7:] = rng.uniform(-0.3, 0.3, q.size - 7)
        x = np.concatenate([q, rng.normal(size=plant.num_velocities())])
        terms = model.evaluate(x)
        expected = terms.F[3:6].T @ (g_W @ terms.R_WB)
        np.testing.assert_allclose(model.gravity_joint_torques(x), expected, atol=1e-9 * np.abs(expected).max())
        plant.SetPositions(context, q)
        default = plant.CalcGravityGeneralizedForces(context)[6:]
        assert np.abs(expected - default).max() > 1e-3 * np.abs(default).max()


def test_a_gravity_model_of_another_plant_is_refused():
    from systems.residuals.momentum_residuals import ResidualModel

    plant, _ = _chain_plant([0, 1, 2])
    other, _ = _chain_plant([0, 1, 2])
    with pytest.raises(ValueError, match="gravity_model"):
        PdGravityController(plant, 1.0, 1.0, gravity_model=ResidualModel(other))
