"""Tests of systems.simulation.noise and systems.simulation.sensors (simulated sensors)."""

import re

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialForce, SpatialVelocity
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    ExternallyAppliedSpatialForce,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PrismaticJoint,
    RevoluteJoint,
    SpatialInertia,
    WeldJoint,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from diagrams.station.standing import default_gains
from models import add_ground, add_humanoid, set_standing_state
from systems.simulation import sensors as sensor_defaults
from systems.simulation.noise import BLOCK_SIZE, NoisyVector, SampledNoise
from systems.simulation.pd_gravity import PdGravityController, joint_vector_from_names
from systems.simulation.sensors import (
    BaseStateEstimator,
    FootForceTorqueSensors,
    JointEncoders,
    MotorTorqueSensor,
    SensedStateAssembler,
    add_imu,
    add_sensors,
)

G = 9.81
PERIOD = 1e-3


# ---------------------------------------------------------------------------------------
# Plants.
# ---------------------------------------------------------------------------------------


def _box(mass):
    return SpatialInertia.SolidBoxWithMass(mass, 0.1, 0.2, 0.3)


def _branched_plant(time_step=0.0):
    """Free base with a branched tree whose joint indices differ from velocity order.

    Joints are added jb (a->b, prismatic), ja (base->a), jc (base->c), so JointIndex order
    is jb, ja, jc while Drake orders the velocities ja, jb, jc. Actuators are added for jc
    then ja (actuation order: jc, ja; jb unactuated). A sole body is welded below c
    through weld "ft" whose child frame is offset and rotated from the sole body frame.
    """
    plant = MultibodyPlant(time_step)
    base = plant.AddRigidBody("base", _box(5.0))
    a = plant.AddRigidBody("a", _box(1.0))
    b = plant.AddRigidBody("b", _box(2.0))
    c = plant.AddRigidBody("c", _box(3.0))
    sole = plant.AddRigidBody("sole", SpatialInertia.SolidSphereWithMass(0.7, 0.02).Shift([-0.01, 0.02, -0.03]))
    plant.AddJoint(PrismaticJoint("jb", a.body_frame(), b.body_frame(), [1.0, 0.0, 0.0]))
    ja = plant.AddJoint(RevoluteJoint("ja", base.body_frame(), a.body_frame(), [0.0, 1.0, 0.0]))
    jc = plant.AddJoint(RevoluteJoint("jc", base.body_frame(), c.body_frame(), [1.0, 0.0, 0.0]))
    S = plant.AddFrame(
        FixedOffsetFrame("S", sole.body_frame(), RigidTransform(RollPitchYaw(0.3, -0.2, 0.5), [0.05, -0.02, 0.04]))
    )
    plant.AddJoint(WeldJoint("ft", c.body_frame(), S, RigidTransform(RollPitchYaw(0.1, 0.0, 0.0), [0.0, 0.0, -0.2])))
    plant.AddJointActuator("ac", jc)
    plant.AddJointActuator("aa", ja)
    plant.Finalize()
    return plant


def _random_branched_state(plant, seed=0):
    rng = np.random.default_rng(seed)
    ctx = plant.CreateDefaultContext()
    base = plant.GetBodyByName("base")
    plant.SetFreeBodyPose(ctx, base, RigidTransform(RollPitchYaw(rng.normal(size=3)), rng.normal(size=3)))
    plant.SetFreeBodySpatialVelocity(ctx, base, SpatialVelocity(rng.normal(size=3), rng.normal(size=3)))
    for name, (q, v) in zip(("ja", "jb", "jc"), rng.normal(size=(3, 2))):
        joint = plant.GetJointByName(name)
        if name == "jb":
            joint.set_translation(ctx, q)
            joint.set_translation_rate(ctx, v)
        else:
            joint.set_angle(ctx, q)
            joint.set_angular_rate(ctx, v)
    return ctx


def _joint_truth(plant, ctx, names=("ja", "jb", "jc")):
    """(positions, velocities) of the named joints read through the joints' own API."""
    q, v = [], []
    for name in names:
        joint = plant.GetJointByName(name)
        if joint.type_name() == "prismatic":
            q.append(joint.get_translation(ctx))
            v.append(joint.get_translation_rate(ctx))
        else:
            q.append(joint.get_angle(ctx))
            v.append(joint.get_angular_rate(ctx))
    return np.array(q), np.array(v)


def test_branched_plant_premise():
    """The fixture really has joint-index order != velocity order != actuation order."""
    plant = _branched_plant()
    assert [plant.get_joint(i).name() for i in plant.GetJointIndices()][:3] == ["jb", "ja", "jc"]
    starts = {n: plant.GetJointByName(n).velocity_start() for n in ("ja", "jb", "jc")}
    assert starts == {"ja": 6, "jb": 7, "jc": 8}
    assert plant.GetJointActuatorByName("ac").input_start() == 0
    assert plant.GetJointActuatorByName("aa").input_start() == 1


@pytest.fixture(scope="module")
def hrp4_plant():
    plant = MultibodyPlant(1e-3)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    return plant, handles


def _stats_times(count):
    return (np.arange(count) + 0.5) * PERIOD


# ---------------------------------------------------------------------------------------
# Noise.
# ---------------------------------------------------------------------------------------


def test_noise_is_deterministic_per_seed_and_index():
    a = SampledNoise(3, [1.0, 2.0, 0.5], PERIOD, 7)
    b = SampledNoise(3, [1.0, 2.0, 0.5], PERIOD, 7)
    times = [0.0, 0.0123, 1.0237, 5.0, 0.0123]
    first = [a.value(t) for t in times]
    # Visit many other blocks (evicting the cache), then come back; other instance too.
    for t in np.arange(0.0, 20 * BLOCK_SIZE * PERIOD, BLOCK_SIZE * PERIOD * 0.7):
        a.value(t)
    for t, v in zip(times, first):
        np.testing.assert_array_equal(a.value(t), v)
        np.testing.assert_array_equal(b.value(t), v)
    # Block boundaries: consecutive samples all distinct and reproducible.
    ks = [BLOCK_SIZE - 1, BLOCK_SIZE, BLOCK_SIZE + 1]
    s1 = [a.sample(k) for k in ks]
    assert len({tuple(s) for s in s1}) == 3
    np.testing.assert_array_equal(np.array(s1), np.array([b.sample(k) for k in ks]))
    # The returned array is a copy: modifying it does not change later values.
    v = a.value(0.0123)
    v[:] = 99.0
    np.testing.assert_array_equal(a.value(0.0123), first[1])


def test_noise_is_held_within_a_period_and_changes_across():
    noise = SampledNoise(2, 1.0, PERIOD, 3)
    for k in (0, 1, 3, 17, 999, 1000, 123456):
        held = [noise.value(k * PERIOD + f * PERIOD) for f in (0.0, 0.25, 0.5, 0.999)]
        for v in held[1:]:
            np.testing.assert_array_equal(v, held[0])
        assert not np.array_equal(noise.value((k + 1) * PERIOD), held[0])
    # t = k * period in floating point falls in sample k even when t / period < k in
    # doubles: 2001 * 1e-3 / 1e-3 and a time accumulated by 1 ms steps.
    assert 2001 * 1e-3 / 1e-3 < 2001
    assert noise.sample_index(2001 * 1e-3) == 2001
    t = 0.0
    for _ in range(1007):
        t += 1e-3
    assert t / 1e-3 < 1007
    assert noise.sample_index(t) == 1007
    np.testing.assert_array_equal(noise.value(t), noise.sample(1007))
    assert SampledNoise(1, 1.0, 0.1, 0).sample_index(0.3) == 3  # 0.3 / 0.1 = 2.9999999999999996


def test_noise_statistics_and_independence():
    std = np.array([0.5, 2.0, 1e-3])
    n = 20000
    a = SampledNoise(3, std, PERIOD, 11)
    b = SampledNoise(3, std, PERIOD, 12)
    xa = np.array([a.value(t) for t in _stats_times(n)])
    xb = np.array([b.value(t) for t in _stats_times(n)])
    for x in (xa, xb):
        np.testing.assert_allclose(x.std(axis=0), std, rtol=0.05)
        assert np.all(np.abs(x.mean(axis=0)) < 4.0 * std / np.sqrt(n))
    # Gaussian: 68.27 % within one std, 95.45 % within two, kurtosis 3.
    z = xa / std
    assert np.mean(np.abs(z) < 1.0) == pytest.approx(0.6827, abs=0.01)
    assert np.mean(np.abs(z) < 2.0) == pytest.approx(0.9545, abs=0.005)
    assert np.mean(z**4) == pytest.approx(3.0, abs=0.15)
    # Consecutive samples are uncorrelated (white).
    assert abs(np.corrcoef(xa[1:, 0], xa[:-1, 0])[0, 1]) < 4.0 / np.sqrt(n)
    # Entries of one noise and the two seeds are uncorrelated (|rho| < 4 / sqrt(n)).
    for i in range(3):
        assert abs(np.corrcoef(xa[:, i], xb[:, i])[0, 1]) < 4.0 / np.sqrt(n)
    assert abs(np.corrcoef(xa[:, 0], xa[:, 1])[0, 1]) < 4.0 / np.sqrt(n)
    # Changing one entry's std only scales that entry.
    c = SampledNoise(3, [0.5, 7.0, 1e-3], PERIOD, 11)
    v, w = a.value(0.5), c.value(0.5)
    np.testing.assert_array_equal(v[[0, 2]], w[[0, 2]])
    assert w[1] == pytest.approx(v[1] * 3.5, rel=1e-14)


def test_noise_zero_std_and_bad_arguments():
    zero = SampledNoise(4, 0.0, PERIOD, 0)
    assert zero.is_zero
    np.testing.assert_array_equal(zero.value(12.345), np.zeros(4))
    partial = SampledNoise(2, [0.0, 1.0], PERIOD, 0)
    assert np.all(np.array([partial.value(t)[0] for t in _stats_times(50)]) == 0.0)
    with pytest.raises(ValueError, match="std must be non-negative"):
        SampledNoise(2, [-1.0, 1.0], PERIOD, 0)
    with pytest.raises(ValueError, match=r"std must be a scalar or have shape \(2,\)"):
        SampledNoise(2, [1.0, 1.0, 1.0], PERIOD, 0)
    with pytest.raises(ValueError, match="std must be finite"):
        SampledNoise(2, np.nan, PERIOD, 0)
    with pytest.raises(ValueError, match="period"):
        SampledNoise(2, 1.0, 0.0, 0)
    with pytest.raises(ValueError, match="seed"):
        SampledNoise(2, 1.0, PERIOD, -1)
    with pytest.raises(ValueError, match="seed"):
        SampledNoise(2, 1.0, PERIOD, 1.5)
    with pytest.raises(ValueError, match="dimension"):
        SampledNoise(-1, 1.0, PERIOD, 0)
    with pytest.raises(ValueError, match="time must be >= 0"):
        SampledNoise(2, 1.0, PERIOD, 0).value(-0.1)


def test_noisy_vector():
    dut = NoisyVector(3, [0.0, 0.1, 0.2], PERIOD, 5)
    assert dut.get_input_port().get_name() == "clean"
    assert dut.get_output_port().get_name() == "noisy"
    ctx = dut.CreateDefaultContext()
    clean = np.array([1.0, -2.0, 3.0])
    dut.get_input_port().FixValue(ctx, clean)
    ctx.SetTime(0.0421)
    expected = clean + SampledNoise(3, [0.0, 0.1, 0.2], PERIOD, 5).value(0.0421)
    np.testing.assert_array_equal(dut.get_output_port().Eval(ctx), expected)
    assert dut.get_output_port().Eval(ctx)[0] == 1.0
    quiet = NoisyVector(3, 0.0)
    qctx = quiet.CreateDefaultContext()
    quiet.get_input_port().FixValue(qctx, clean)
    qctx.SetTime(3.3)
    np.testing.assert_array_equal(quiet.get_output_port().Eval(qctx), clean)
    dut.get_input_port().FixValue(ctx, [1.0, np.nan, 3.0])
    with pytest.raises(ValueError, match=re.escape("NoisyVector: input 'clean' has NaN or inf at indices [1]")):
        dut.get_output_port().Eval(ctx)


# ---------------------------------------------------------------------------------------
# Joint encoders.
# ---------------------------------------------------------------------------------------


def test_joint_encoders_noise_free_equal_truth_in_velocity_order():
    plant = _branched_plant()
    pctx = _random_branched_state(plant, seed=1)
    dut = JointEncoders(plant, position_noise_std=0.0, velocity_noise_std=0.0)
    assert [dut.get_input_port(i).get_name() for i in range(dut.num_input_ports())] == ["state"]
    assert [dut.get_output_port(i).get_name() for i in range(dut.num_output_ports())] == ["position", "velocity"]
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("state").FixValue(ctx, plant.GetPositionsAndVelocities(pctx))
    ctx.SetTime(0.777)
    q, v = _joint_truth(plant, pctx)
    np.testing.assert_array_equal(dut.GetOutputPort("position").Eval(ctx), q)
    np.testing.assert_array_equal(dut.GetOutputPort("velocity").Eval(ctx), v)


def test_joint_encoders_noise_statistics(hrp4_plant):
    plant, _ = hrp4_plant
    dut = JointEncoders(plant)  # the module's default noise levels
    ctx = dut.CreateDefaultContext()
    pctx = plant.CreateDefaultContext()
    x = plant.GetPositionsAndVelocities(pctx)
    x[plant.num_positions() :] = np.linspace(-1.0, 1.0, plant.num_velocities())
    dut.GetInputPort("state").FixValue(ctx, x)
    nq = plant.num_positions()
    q_true, v_true = x[7:nq], x[nq + 6 :]
    eq, ev = [], []
    for t in _stats_times(700):  # 700 x 34 joints = 23800 samples each
        ctx.SetTime(t)
        eq.append(dut.GetOutputPort("position").Eval(ctx) - q_true)
        ev.append(dut.GetOutputPort("velocity").Eval(ctx) - v_true)
    eq, ev = np.array(eq), np.array(ev)
    assert eq.std() == pytest.approx(sensor_defaults.ENCODER_POSITION_NOISE_STD, rel=0.05)
    assert ev.std() == pytest.approx(sensor_defaults.ENCODER_VELOCITY_NOISE_STD, rel=0.05)
    assert abs(eq.mean()) < 4 * sensor_defaults.ENCODER_POSITION_NOISE_STD / np.sqrt(eq.size)
    # Position and velocity noises are independent.
    assert abs(np.corrcoef(eq.ravel(), ev.ravel())[0, 1]) < 4.0 / np.sqrt(eq.size)


# ---------------------------------------------------------------------------------------
# Motor torque.
# ---------------------------------------------------------------------------------------


def test_motor_torque_maps_actuation_order_to_velocity_order():
    plant = _branched_plant()
    dut = MotorTorqueSensor(plant, noise_std=0.0)
    assert dut.GetInputPort("actuation").size() == 2
    assert dut.GetOutputPort("measured_torque").size() == 3
    ctx = dut.CreateDefaultContext()
    u = np.array([3.5, -1.25])  # actuation order: ac (jc), aa (ja)
    dut.GetInputPort("actuation").FixValue(ctx, u)
    tau = dut.GetOutputPort("measured_torque").Eval(ctx)
    np.testing.assert_array_equal(tau, [-1.25, 0.0, 3.5])  # ja, jb (unactuated), jc
    # Independently through Drake's actuation matrix.
    np.testing.assert_array_equal(tau, (plant.MakeActuationMatrix() @ u)[6:])
    np.testing.assert_array_equal(dut.actuated_joints, [2, 0])


def test_motor_torque_noise_statistics():
    plant = _branched_plant()
    dut = MotorTorqueSensor(plant, noise_std=[0.1, 0.2, 0.3])
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("actuation").FixValue(ctx, [3.5, -1.25])
    err = []
    for t in _stats_times(20000):
        ctx.SetTime(t)
        err.append(dut.GetOutputPort("measured_torque").Eval(ctx) - [-1.25, 0.0, 3.5])
    err = np.array(err)
    np.testing.assert_allclose(err[:, [0, 2]].std(axis=0), [0.1, 0.3], rtol=0.05)
    assert np.all(err[:, 1] == 0.0)  # unactuated joint: exactly 0, no noise
    with pytest.raises(ValueError, match=r"MotorTorqueSensor: noise_std must be a scalar or have shape \(3,\)"):
        MotorTorqueSensor(plant, noise_std=[0.1, 0.2])
    with pytest.raises(ValueError, match="MotorTorqueSensor: noise_std must be non-negative"):
        MotorTorqueSensor(plant, noise_std=-0.1)


# ---------------------------------------------------------------------------------------
# Force/torque sensors: the reaction-force convention on a hand-made static case.
# ---------------------------------------------------------------------------------------


def _weld_test_plant():
    """World -weld(rotated)- ankle -weld "ft" (offset, rotated; child frame S offset and
    rotated in the sole body)- sole (mass 2 kg, CoM off the body origin) -weld- toe (0.5 kg).
    Continuous plant, no degrees of freedom: everything is static."""
    plant = MultibodyPlant(0.0)
    ankle = plant.AddRigidBody("ankle", _box(1.0))
    sole = plant.AddRigidBody("sole", SpatialInertia.SolidBoxWithMass(2.0, 0.2, 0.1, 0.02).Shift([-0.03, 0.01, 0.02]))
    toe = plant.AddRigidBody("toe", SpatialInertia.SolidSphereWithMass(0.5, 0.01))
    plant.WeldFrames(
        plant.world_frame(), ankle.body_frame(), RigidTransform(RollPitchYaw(0.2, -0.4, 0.9), [0.3, -0.1, 0.8])
    )
    S = plant.AddFrame(
        FixedOffsetFrame("S", sole.body_frame(), RigidTransform(RollPitchYaw(-0.5, 0.3, 1.1), [0.04, 0.06, -0.05]))
    )
    F = plant.AddFrame(
        FixedOffsetFrame("F", ankle.body_frame(), RigidTransform(RollPitchYaw(0.0, 0.7, 0.0), [0.0, 0.02, -0.1]))
    )
    ft = plant.AddJoint(WeldJoint("ft", F, S, RigidTransform(RollPitchYaw(0.3, 0.0, -0.2), [0.01, 0, 0])))
    plant.AddJoint(WeldJoint("toe_weld", sole.body_frame(), toe.body_frame(), RigidTransform([0.12, 0.0, 0.0])))
    plant.Finalize()
    return plant, ft, sole, toe


def test_reaction_force_convention_and_ft_wrench_static():
    plant, ft, sole, toe = _weld_test_plant()
    pctx = plant.CreateDefaultContext()
    # A known wrench on the sole: force f at point p_SoleQ (sole frame), plus a torque.
    p_BQ = np.array([0.07, -0.03, -0.01])
    tau_W, f_W = np.array([0.4, -0.2, 1.1]), np.array([12.0, -7.0, 150.0])
    applied = ExternallyAppliedSpatialForce()
    applied.body_index = sole.index()
    applied.p_BoBq_B = p_BQ
    applied.F_Bq_W = SpatialForce(tau_W, f_W)
    plant.get_applied_spatial_force_input_port().FixValue(pctx, [applied])
    reactions = plant.get_reaction_forces_output_port().Eval(pctx)

    # Independent statics, all in world about So (origin of S = ft.frame_on_child()).
    X_WS = ft.frame_on_child().CalcPoseInWorld(pctx)
    p_WSo, R_WS = X_WS.translation(), X_WS.rotation().matrix()
    p_WQ = plant.EvalBodyPoseInWorld(pctx, sole) @ p_BQ
    M_applied = tau_W + np.cross(p_WQ - p_WSo, f_W)
    g = np.array([0.0, 0.0, -G])
    M_gravity, F_gravity = np.zeros(3), np.zeros(3)
    for body in (sole, toe):
        m = body.default_mass()
        p_Wcm = plant.EvalBodyPoseInWorld(pctx, body) @ body.default_com()
        M_gravity += np.cross(p_Wcm - p_WSo, m * g)
        F_gravity += m * g
    # Equilibrium of the sole + toe: weld + applied + gravity = 0. The port's entry is the
    # force on the CHILD body, at the child frame's origin So, expressed in the child frame S.
    F_weld = reactions[int(ft.index())]
    np.testing.assert_allclose(R_WS @ F_weld.translational(), -(f_W + F_gravity), atol=1e-10)
    np.testing.assert_allclose(R_WS @ F_weld.rotational(), -(M_applied + M_gravity), atol=1e-10)

    # The sensor reports the wrench of "the ground" (here the applied wrench) about So,
    # in world, once the sole+toe weight is compensated.
    dut = FootForceTorqueSensors(plant, [ft], force_noise_std=0.0, moment_noise_std=0.0)
    assert dut.sole_masses == pytest.approx([2.5])
    assert dut.sensor_frames[0].name() == "S"
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("reaction_forces").FixValue(ctx, reactions)
    dut.GetInputPort("state").FixValue(ctx, plant.GetPositionsAndVelocities(pctx))
    np.testing.assert_allclose(dut.GetOutputPort("wrenches").Eval(ctx), np.concatenate([M_applied, f_W]), atol=1e-10)
    raw = FootForceTorqueSensors(plant, [ft], force_noise_std=0.0, moment_noise_std=0.0, compensate_sole_weight=False)
    rctx = raw.CreateDefaultContext()
    raw.GetInputPort("reaction_forces").FixValue(rctx, reactions)
    raw.GetInputPort("state").FixValue(rctx, plant.GetPositionsAndVelocities(pctx))
    np.testing.assert_allclose(
        raw.GetOutputPort("wrenches").Eval(rctx), np.concatenate([M_applied + M_gravity, f_W + F_gravity]), atol=1e-10
    )


def test_ft_wrench_dynamic_equals_applied_minus_sole_inertia():
    """A free-floating ankle+sole pushed on the sole, at rest (zero velocity): the sensor
    reads the applied wrench minus the sole's rate of momentum change (about So)."""
    plant = MultibodyPlant(0.0)
    ankle = plant.AddRigidBody("ankle", _box(3.0))
    sole = plant.AddRigidBody("sole", SpatialInertia.SolidBoxWithMass(1.5, 0.2, 0.1, 0.03).Shift([0.02, -0.01, 0.015]))
    S = plant.AddFrame(
        FixedOffsetFrame("S", sole.body_frame(), RigidTransform(RollPitchYaw(0.2, 0.1, -0.3), [0.0, 0.01, 0.03]))
    )
    ft = plant.AddJoint(WeldJoint("ft", ankle.body_frame(), S, RigidTransform([0.0, 0.0, -0.15])))
    plant.Finalize()
    pctx = plant.CreateDefaultContext()
    plant.SetFreeBodyPose(pctx, ankle, RigidTransform(RollPitchYaw(0.3, -0.2, 0.4), [0.0, 0.0, 1.0]))
    applied = ExternallyAppliedSpatialForce()
    applied.body_index = sole.index()
    applied.p_BoBq_B = np.array([0.05, 0.02, -0.02])
    applied.F_Bq_W = SpatialForce([0.3, 0.5, -0.2], [20.0, -10.0, 40.0])
    plant.get_applied_spatial_force_input_port().FixValue(pctx, [applied])
    reactions = plant.get_reaction_forces_output_port().Eval(pctx)
    A_WSole = plant.get_body_spatial_accelerations_output_port().Eval(pctx)[int(sole.index())]

    X_WB = plant.EvalBodyPoseInWorld(pctx, sole)
    p_WSo = S.CalcPoseInWorld(pctx).translation()
    p_WQ = X_WB @ applied.p_BoBq_B
    M_applied = applied.F_Bq_W.rotational() + np.cross(p_WQ - p_WSo, applied.F_Bq_W.translational())
    # Rate of the sole's momentum about So at zero velocity: M_So_W * A_WSo.
    M_Bo_W = sole.default_spatial_inertia().ReExpress(X_WB.rotation())
    M_So_W = M_Bo_W.Shift(p_WSo - X_WB.translation())
    alpha = A_WSole.rotational()
    a_So = A_WSole.translational() + np.cross(alpha, p_WSo - X_WB.translation())
    h_dot = M_So_W.CopyToFullMatrix6() @ np.concatenate([alpha, a_So])
    dut = FootForceTorqueSensors(plant, [ft], force_noise_std=0.0, moment_noise_std=0.0)
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("reaction_forces").FixValue(ctx, reactions)
    dut.GetInputPort("state").FixValue(ctx, plant.GetPositionsAndVelocities(pctx))
    expected = np.concatenate([M_applied, applied.F_Bq_W.translational()]) - h_dot
    np.testing.assert_allclose(dut.GetOutputPort("wrenches").Eval(ctx), expected, atol=1e-9)
    assert np.linalg.norm(h_dot) > 1.0  # the inertial term is not negligible here


def test_ft_noise_statistics_and_validation():
    plant, ft, _, _ = _weld_test_plant()
    pctx = plant.CreateDefaultContext()
    dut = FootForceTorqueSensors(plant, [ft])  # defaults 0.5 N, 0.05 N m
    ctx = dut.CreateDefaultContext()
    reactions = plant.get_reaction_forces_output_port().Eval(pctx)
    dut.GetInputPort("reaction_forces").FixValue(ctx, reactions)
    dut.GetInputPort("state").FixValue(ctx, plant.GetPositionsAndVelocities(pctx))
    clean = dut.CalcGroundWrenches(reactions, plant.GetPositionsAndVelocities(pctx))
    np.testing.assert_allclose(clean, 0.0, atol=1e-10)  # only gravity: compensated away
    err = []
    for t in _stats_times(7000):  # x 3 axes = 21000 samples
        ctx.SetTime(t)
        err.append(dut.GetOutputPort("wrenches").Eval(ctx) - clean)
    err = np.array(err)
    assert err[:, :3].std() == pytest.approx(sensor_defaults.FT_MOMENT_NOISE_STD, rel=0.05)
    assert err[:, 3:].std() == pytest.approx(sensor_defaults.FT_FORCE_NOISE_STD, rel=0.05)

    hrp = _branched_plant()
    with pytest.raises(ValueError, match=r"sensor_joints\[0\] \('ja'\) is a 'revolute' joint, not a weld"):
        FootForceTorqueSensors(hrp, [hrp.GetJointByName("ja")])
    with pytest.raises(ValueError, match="not a joint of this plant"):
        FootForceTorqueSensors(hrp, [ft])
    with pytest.raises(ValueError, match="sensor_joints is empty"):
        FootForceTorqueSensors(plant, [])
    with pytest.raises(ValueError, match="sequence of weld joints"):
        FootForceTorqueSensors(plant, ft)
    with pytest.raises(ValueError, match="appears twice"):
        FootForceTorqueSensors(plant, [ft, ft])
    with pytest.raises(ValueError, match=r"sensor_joints\[1\] is a str"):
        FootForceTorqueSensors(plant, [ft, "ft"])
    with pytest.raises(ValueError, match="force_noise_std must be non-negative"):
        FootForceTorqueSensors(plant, [ft], force_noise_std=-1.0)
    with pytest.raises(ValueError, match=r"moment_noise_std must be a scalar or have shape \(3,\)"):
        FootForceTorqueSensors(plant, [ft], moment_noise_std=[1.0, 2.0])

    # NaN in a reaction force: clear error naming the port and joint.
    bad = list(reactions)
    bad[int(ft.index())] = SpatialForce([0.0, np.nan, 0.0], [0.0, 0.0, 0.0])
    dut.GetInputPort("reaction_forces").FixValue(ctx, bad)
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"FootForceTorqueSensors: input 'reaction_forces' has NaN or inf at indices [{int(ft.index())}]"
        ),
    ):
        dut.GetOutputPort("wrenches").Eval(ctx)


# ---------------------------------------------------------------------------------------
# Base state and assembler.
# ---------------------------------------------------------------------------------------


def test_base_state_estimator_noise_free_and_statistics():
    plant = _branched_plant()
    pctx = _random_branched_state(plant, seed=2)
    x = plant.GetPositionsAndVelocities(pctx)
    free = plant.GetJointByName("base")  # the automatic free joint, named after its body
    quat = free.get_quaternion(pctx).wxyz()
    truth_pose = np.concatenate([quat, free.get_translation(pctx)])
    truth_vel = np.concatenate([free.get_angular_velocity(pctx), free.get_translational_velocity(pctx)])

    quiet = BaseStateEstimator(
        plant,
        orientation_noise_std=0.0,
        position_noise_std=0.0,
        angular_velocity_noise_std=0.0,
        linear_velocity_noise_std=0.0,
    )
    ctx = quiet.CreateDefaultContext()
    quiet.GetInputPort("state").FixValue(ctx, x)
    ctx.SetTime(0.5)
    np.testing.assert_array_equal(quiet.GetOutputPort("base_pose").Eval(ctx), truth_pose)
    np.testing.assert_array_equal(quiet.GetOutputPort("base_velocity").Eval(ctx), truth_vel)

    dut = BaseStateEstimator(plant)  # 1e-3 rad, 1e-3 m, 2e-3 rad/s, 2e-3 m/s
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("state").FixValue(ctx, x)
    R_true = free.get_quaternion(pctx).rotation()
    phis, dps, dvs = [], [], []
    for t in _stats_times(7000):
        ctx.SetTime(t)
        pose = dut.GetOutputPort("base_pose").Eval(ctx)
        assert abs(np.linalg.norm(pose[:4]) - 1.0) < 1e-12
        # Rotation error in the base frame: R_true^T R_noisy = exp([phi]x), small.
        w, qx, qy, qz = pose[:4]
        R = np.array(
            [
                [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - w * qz), 2 * (qx * qz + w * qy)],
                [2 * (qx * qy + w * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - w * qx)],
                [2 * (qx * qz - w * qy), 2 * (qy * qz + w * qx), 1 - 2 * (qx * qx + qy * qy)],
            ]
        )
        E = R_true.T @ R
        phis.append(0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]]))
        dps.append(pose[4:] - truth_pose[4:])
        dvs.append(dut.GetOutputPort("base_velocity").Eval(ctx) - truth_vel)
    phis, dps, dvs = np.array(phis), np.array(dps), np.array(dvs)
    d = sensor_defaults
    assert phis.std() == pytest.approx(d.BASE_ORIENTATION_NOISE_STD, rel=0.05)
    assert dps.std() == pytest.approx(d.BASE_POSITION_NOISE_STD, rel=0.05)
    assert dvs[:, :3].std() == pytest.approx(d.BASE_ANGULAR_VELOCITY_NOISE_STD, rel=0.05)
    assert dvs[:, 3:].std() == pytest.approx(d.BASE_LINEAR_VELOCITY_NOISE_STD, rel=0.05)
    assert abs(phis.mean()) < 4 * d.BASE_ORIENTATION_NOISE_STD / np.sqrt(phis.size)


def test_assembler_round_trip_on_branched_plant():
    plant = _branched_plant()
    pctx = _random_branched_state(plant, seed=3)
    x = plant.GetPositionsAndVelocities(pctx)
    free = plant.GetJointByName("base")
    dut = SensedStateAssembler(plant)
    names = [dut.get_input_port(i).get_name() for i in range(dut.num_input_ports())]
    assert names == ["base_pose", "base_velocity", "joint_position", "joint_velocity"]
    ctx = dut.CreateDefaultContext()
    q, v = _joint_truth(plant, pctx)
    dut.GetInputPort("base_pose").FixValue(
        ctx, np.concatenate([free.get_quaternion(pctx).wxyz(), free.get_translation(pctx)])
    )
    dut.GetInputPort("base_velocity").FixValue(
        ctx, np.concatenate([free.get_angular_velocity(pctx), free.get_translational_velocity(pctx)])
    )
    dut.GetInputPort("joint_position").FixValue(ctx, q)
    dut.GetInputPort("joint_velocity").FixValue(ctx, v)
    np.testing.assert_array_equal(dut.GetOutputPort("state").Eval(ctx), x)
    # Encoders + base estimator (noise off) -> assembler also returns x exactly.
    enc = JointEncoders(plant, position_noise_std=0.0, velocity_noise_std=0.0)
    ectx = enc.CreateDefaultContext()
    enc.GetInputPort("state").FixValue(ectx, x)
    np.testing.assert_array_equal(enc.GetOutputPort("position").Eval(ectx), q)
    dut.GetInputPort("joint_velocity").FixValue(ctx, [np.inf, 0.0, 0.0])
    with pytest.raises(
        ValueError, match=re.escape("SensedStateAssembler: input 'joint_velocity' has NaN or inf at indices [0]")
    ):
        dut.GetOutputPort("state").Eval(ctx)


def test_nan_inputs_and_constructor_errors():
    plant = _branched_plant()
    x = plant.GetPositionsAndVelocities(plant.CreateDefaultContext())
    x[9] = np.nan
    for cls in (JointEncoders, BaseStateEstimator):
        dut = cls(plant)
        ctx = dut.CreateDefaultContext()
        dut.GetInputPort("state").FixValue(ctx, x)
        with pytest.raises(ValueError, match=re.escape(f"{cls.__name__}: input 'state' has NaN or inf at indices [9]")):
            dut.get_output_port(0).Eval(ctx)
    torque = MotorTorqueSensor(plant)
    ctx = torque.CreateDefaultContext()
    torque.GetInputPort("actuation").FixValue(ctx, [0.0, np.nan])
    with pytest.raises(
        ValueError, match=re.escape("MotorTorqueSensor: input 'actuation' has NaN or inf at indices [1]")
    ):
        torque.GetOutputPort("measured_torque").Eval(ctx)

    unfinalized = MultibodyPlant(0.0)
    unfinalized.AddRigidBody("base", _box(1.0))
    for cls in (JointEncoders, MotorTorqueSensor, BaseStateEstimator, SensedStateAssembler):
        with pytest.raises(ValueError, match=f"{cls.__name__}: the MultibodyPlant must be finalized"):
            cls(unfinalized)
    with pytest.raises(ValueError, match="must be finalized"):
        FootForceTorqueSensors(unfinalized, [])
    with pytest.raises(ValueError, match="plant must be a MultibodyPlant"):
        JointEncoders("plant")
    with pytest.raises(ValueError, match=r"JointEncoders: position_noise_std must be a scalar or have shape \(3,\)"):
        JointEncoders(plant, position_noise_std=[1.0, 2.0])
    with pytest.raises(ValueError, match="JointEncoders: velocity_noise_std must be non-negative"):
        JointEncoders(plant, velocity_noise_std=-1.0)
    with pytest.raises(ValueError, match="JointEncoders: seed must be a non-negative integer"):
        JointEncoders(plant, seed=-3)
    with pytest.raises(ValueError, match="BaseStateEstimator: period must be a positive number"):
        BaseStateEstimator(plant, period=0.0)
    with pytest.raises(ValueError, match="BaseStateEstimator: orientation_noise_std"):
        BaseStateEstimator(plant, orientation_noise_std=[1.0, 2.0])
    fixed = MultibodyPlant(0.0)
    fixed.WeldFrames(fixed.world_frame(), fixed.AddRigidBody("b", _box(1.0)).body_frame())
    fixed.Finalize()
    with pytest.raises(ValueError, match="SensedStateAssembler: the plant has no floating base"):
        SensedStateAssembler(fixed)


# ---------------------------------------------------------------------------------------
# The humanoid standing with all sensors.
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def hrp4_standing():
    """hrp4_like standing 1.5 s under PD + gravity, sensors without noise (add_sensors)."""
    builder = DiagramBuilder()
    config = MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap", contact_model="point")
    plant, scene_graph = AddMultibodyPlant(config, builder)
    humanoid = add_humanoid(plant, "hrp4_like", scene_graph=scene_graph)
    add_ground(plant)
    plant.Finalize()
    kp, kd = default_gains(plant, humanoid)
    controller = builder.AddSystem(PdGravityController(plant, kp, kd))
    source = builder.AddSystem(ConstantVectorSource(joint_vector_from_names(plant, humanoid.nominal_posture)))
    builder.Connect(source.get_output_port(), controller.GetInputPort("desired_position"))
    builder.Connect(plant.get_state_output_port(), controller.GetInputPort("state"))
    builder.Connect(controller.get_output_port(), plant.get_actuation_input_port())
    sensors = add_sensors(builder, plant, humanoid, noise=False)
    noisy = add_sensors(builder, plant, humanoid, noise=True, seed=5, name_prefix="noisy_")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    set_standing_state(plant, plant.GetMyMutableContextFromRoot(context), humanoid)
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(1.5)
    return dict(
        diagram=diagram,
        context=context,
        plant=plant,
        humanoid=humanoid,
        controller=controller,
        sensors=sensors,
        noisy=noisy,
    )


def _eval(port, system, context):
    return port.Eval(system.GetMyContextFromRoot(context))


def test_standing_ft_forces_sum_to_weight_and_match_contacts(hrp4_standing):
    s = hrp4_standing
    plant, humanoid, context = s["plant"], s["humanoid"], s["context"]
    sensors = s["sensors"]
    pctx = plant.GetMyContextFromRoot(context)
    assert sensors.ft_sides == ("left", "right")
    wrenches = _eval(sensors.ft_wrenches, sensors.ft_sensors, context).reshape(2, 6)
    weight = plant.CalcTotalMass(pctx) * G
    total = wrenches[:, 3:].sum(axis=0)
    assert total[2] == pytest.approx(weight, rel=0.005)
    assert np.linalg.norm(total[:2]) < 0.005 * weight

    # Contact wrench on each sole (its four spheres) about the sensor origin, in world.
    results = plant.get_contact_results_output_port().Eval(pctx)
    for side, wrench in zip(sensors.ft_sides, wrenches):
        joint = humanoid.ft_sensor_joints[side]
        sole = joint.child_body().index()
        p_WSo = joint.frame_on_child().CalcPoseInWorld(pctx).translation()
        force, moment, count = np.zeros(3), np.zeros(3), 0
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            f = info.contact_force()  # on body B, at the contact point, world
            if info.bodyB_index() == sole:
                pass
            elif info.bodyA_index() == sole:
                f = -f
            else:
                continue
            count += 1
            force += f
            moment += np.cross(info.contact_point() - p_WSo, f)
        assert count == 4
        np.testing.assert_allclose(wrench[3:], force, rtol=0, atol=0.01 * np.linalg.norm(force))
        np.testing.assert_allclose(
            wrench[:3], moment, rtol=0, atol=0.01 * max(np.linalg.norm(moment), 0.01 * np.linalg.norm(force))
        )
    assert tuple(f.name() for f in sensors.ft_frames) == tuple(
        humanoid.ft_sensor_frames[side].name() for side in ("left", "right")
    )


def test_ft_wrenches_are_expressed_with_the_robots_own_orientation(hrp4_standing):
    """A real robot rotates its F/T readings into world with its estimated orientation, so
    the estimators see the wrenches and gravity in one frame: add_sensors feeds the F/T
    sensors the sensed state, and a base orientation off by a tilt rotates the (weld)
    wrench by that tilt."""
    s = hrp4_standing
    diagram, plant, humanoid, context = s["diagram"], s["plant"], s["humanoid"], s["context"]
    for sensors in (s["sensors"], s["noisy"]):
        source = diagram.connection_map()[(sensors.ft_sensors, sensors.ft_sensors.GetInputPort("state").get_index())]
        assert source == (sensors.assembler, sensors.assembler.GetOutputPort("state").get_index())
    pctx = plant.GetMyContextFromRoot(context)
    raw = FootForceTorqueSensors(
        plant,
        [humanoid.ft_sensor_joints[side] for side in ("left", "right")],
        compensate_sole_weight=False,
        force_noise_std=0.0,
        moment_noise_std=0.0,
    )
    reactions = plant.get_reaction_forces_output_port().Eval(pctx)
    x = plant.GetPositionsAndVelocities(pctx).copy()
    tilt = RollPitchYaw(0.02, -0.03, 0.0).ToRotationMatrix()
    X_WB = plant.GetFreeBodyPose(pctx, humanoid.base_body)
    x_tilted = x.copy()
    x_tilted[:4] = (tilt @ X_WB.rotation()).ToQuaternion().wxyz()
    true_frame = raw.CalcGroundWrenches(reactions, x).reshape(-1, 3)
    tilted_frame = raw.CalcGroundWrenches(reactions, x_tilted).reshape(-1, 3)
    np.testing.assert_allclose(tilted_frame, true_frame @ tilt.matrix().T, rtol=0, atol=1e-9)


def test_standing_imu_at_rest(hrp4_standing):
    s = hrp4_standing
    plant, humanoid, context = s["plant"], s["humanoid"], s["context"]
    imu = s["sensors"].imu
    pctx = plant.GetMyContextFromRoot(context)
    R_WS = humanoid.imu_frame.CalcPoseInWorld(pctx).rotation().matrix()
    accel = _eval(imu.linear_acceleration, imu.accel_noise, context)
    gyro = _eval(imu.angular_velocity, imu.gyro_noise, context)
    np.testing.assert_allclose(R_WS @ accel, [0.0, 0.0, G], atol=0.1)  # +9.81 upward
    np.testing.assert_allclose(gyro, 0.0, atol=0.03)
    # Exactly Drake's kinematics of the IMU frame (noise off).
    w_WS_W = humanoid.imu_frame.CalcSpatialVelocityInWorld(pctx).rotational()
    np.testing.assert_allclose(gyro, R_WS.T @ w_WS_W, atol=1e-12)
    body = humanoid.imu_frame.body()
    A_WB = plant.get_body_spatial_accelerations_output_port().Eval(pctx)[int(body.index())]
    V_WB = plant.EvalBodySpatialVelocityInWorld(pctx, body)
    X_WB = plant.EvalBodyPoseInWorld(pctx, body)
    p_BoSo_W = X_WB.rotation() @ humanoid.imu_frame.GetFixedPoseInBodyFrame().translation()
    a_WS = A_WB.Shift(p_BoSo_W, V_WB.rotational()).translational()
    np.testing.assert_allclose(accel, R_WS.T @ (a_WS - [0.0, 0.0, -G]), atol=1e-9)


def test_standing_sensed_state_and_torque_are_truth_without_noise(hrp4_standing):
    s = hrp4_standing
    plant, context, sensors = s["plant"], s["context"], s["sensors"]
    pctx = plant.GetMyContextFromRoot(context)
    x = plant.GetPositionsAndVelocities(pctx)
    np.testing.assert_array_equal(_eval(sensors.state, sensors.assembler, context), x)
    # The torque sensor reports what the motors applied over the last step.
    u = plant.get_net_actuation_output_port().Eval(pctx)
    tau = _eval(sensors.measured_torque, sensors.torque_sensor, context)
    np.testing.assert_array_equal(tau, (plant.MakeActuationMatrix() @ u)[6:])
    assert sensors.seeds == {"encoders": 0, "torque": 1, "ft": 2, "imu": 3, "base": 4, "fsr": 5}


def test_standing_noisy_sensors_differ_by_noise_only(hrp4_standing):
    s = hrp4_standing
    context, quiet, noisy = s["context"], s["sensors"], s["noisy"]
    assert len(set(noisy.seeds.values())) == 6
    assert set(noisy.seeds.values()).isdisjoint(quiet.seeds.values())
    d_state = _eval(noisy.state, noisy.assembler, context) - _eval(quiet.state, quiet.assembler, context)
    assert 0 < np.abs(d_state).max() < 0.02
    d_ft = _eval(noisy.ft_wrenches, noisy.ft_sensors, context) - _eval(quiet.ft_wrenches, quiet.ft_sensors, context)
    assert 0 < np.abs(d_ft).max() < 5 * 0.5
    d_acc = _eval(noisy.imu.linear_acceleration, noisy.imu.accel_noise, context) - _eval(
        quiet.imu.linear_acceleration, quiet.imu.accel_noise, context
    )
    assert 0 < np.abs(d_acc).max() < 5 * 0.02


def test_add_imu_validation(hrp4_plant):
    plant, handles = hrp4_plant
    other = _branched_plant()
    builder = DiagramBuilder()
    with pytest.raises(ValueError, match="add_imu: frame 'imu' is not a frame of this plant"):
        add_imu(builder, other, handles.imu_frame)
    with pytest.raises(ValueError, match="add_imu: gyro_noise_std must be non-negative"):
        add_imu(builder, plant, handles.imu_frame, gyro_noise_std=-1.0)


def test_add_sensors_without_ft_sensors_nao():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    humanoid = add_humanoid(plant, "nao_like", scene_graph=scene_graph)
    plant.Finalize()
    sensors = add_sensors(builder, plant, humanoid, seed=2)
    assert sensors.ft_sensors is None and sensors.ft_wrenches is None
    assert sensors.ft_frames == () and sensors.ft_sides == ()
    assert sensors.seeds["encoders"] == 32
    assert sensors.state.size() == plant.num_positions() + plant.num_velocities()
    assert sensors.measured_torque.size() == plant.num_velocities() - 6
    assert sensors.imu.frame.name() == "imu"
    # The torque sensor reads what the motors applied: the plant's net actuation.
    assert sensors.torque_sensor.GetInputPort("actuation").size() == plant.num_actuated_dofs()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    x = plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))
    np.testing.assert_allclose(_eval(sensors.state, sensors.assembler, context), x, atol=0.02)
    with pytest.raises(ValueError, match="add_sensors: noise must be a bool"):
        add_sensors(DiagramBuilder(), plant, humanoid, noise="yes")
    with pytest.raises(ValueError, match="add_sensors: seed must be a non-negative integer"):
        add_sensors(DiagramBuilder(), plant, humanoid, seed=-1)
    with pytest.raises(ValueError, match="add_sensors: handles must be HumanoidHandles"):
        add_sensors(DiagramBuilder(), plant, None)


def test_add_sensors_noise_scale_multiplies_every_noise_std():
    """noise_scale (the sweeps' noise level) multiplies each sensor's white noise std; the
    same seeds draw the same normalised samples, so every noise sample doubles exactly."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    humanoid = add_humanoid(plant, "hrp4_like", scene_graph=scene_graph)
    plant.Finalize()
    one = add_sensors(builder, plant, humanoid, seed=3)
    two = add_sensors(builder, plant, humanoid, seed=3, noise_scale=2.0, name_prefix="twice_")
    assert (one.noise_std_factor, two.noise_std_factor) == (1.0, 2.0)
    np.testing.assert_allclose(two.encoders.noise.std, 2.0 * one.encoders.noise.std)
    assert one.encoders.noise.std.max() > 0.0
    for t in (0.0, 0.0137, 0.5):
        np.testing.assert_allclose(two.encoders.noise.value(t), 2.0 * one.encoders.noise.value(t))
    for bad in (-1.0, float("nan"), float("inf"), True, "2"):
        with pytest.raises(ValueError, match="add_sensors: noise_scale"):
            add_sensors(DiagramBuilder(), plant, humanoid, noise_scale=bad)
