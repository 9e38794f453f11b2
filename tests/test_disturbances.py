"""Tests of systems.simulation.disturbances: force profiles, Push, and the PushSource LeafSystem.

Every expected number is derived independently from Drake (poses, Jacobians, mass matrix,
spatial momentum) or from closed-form profiles, not from the code under test.
"""

import dataclasses
import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    JacobianWrtVariable,
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    SpatialInertia,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from models import add_humanoid
from systems.dynamics.floating_base import FloatingBaseDynamics
from systems.simulation.disturbances import PolynomialRampUpDown, Push, PushSource, Sinusoid, Step, profile_support

# ---------------------------------------------------------------------------------------
# Profiles.
# ---------------------------------------------------------------------------------------


def test_ramp_key_values():
    ramp = PolynomialRampUpDown(peak=5.0, t_start=5.0, t_peak=8.5, t_end=12.0)
    assert ramp.value(5.0) == 0.0
    assert ramp.value(8.5) == pytest.approx(5.0, abs=1e-12)
    assert ramp.value(12.0) == 0.0
    for t in (-1.0, 0.0, 4.999, 12.001, 100.0):
        assert ramp.value(t) == 0.0
    # Quintic smoothstep is symmetric about x = 1/2: half the peak half-way up and down.
    assert ramp.value(5.0 + 1.75) == pytest.approx(2.5, abs=1e-12)
    assert ramp.value(8.5 + 1.75) == pytest.approx(2.5, abs=1e-12)
    # s(x) = 10x^3 - 15x^4 + 6x^5 at x = 0.2 on the way up.
    x = 0.2
    assert ramp.value(5.0 + x * 3.5) == pytest.approx(5.0 * (10 * x**3 - 15 * x**4 + 6 * x**5), rel=1e-12)
    # Strictly positive inside, monotone up then down.
    t = np.linspace(5.001, 11.999, 2001)
    v = ramp.value(t)
    assert np.all(v > 0.0)
    up = t <= 8.5
    assert np.all(np.diff(v[up]) >= 0.0) and np.all(np.diff(v[~up]) <= 0.0)


def test_ramp_vectorised_matches_scalar_and_negative_peak():
    ramp = PolynomialRampUpDown(peak=-3.0, t_start=1.0, t_peak=1.5, t_end=3.0)
    t = np.linspace(0.0, 4.0, 401)
    vec = ramp.value(t)
    assert vec.shape == t.shape
    np.testing.assert_allclose(vec, [ramp.value(float(s)) for s in t], atol=1e-15)
    assert ramp.value(1.5) == pytest.approx(-3.0)
    assert isinstance(ramp.value(2.0), float)


def test_ramp_is_continuous_and_c1():
    """Finite differences: no jumps in the value nor in the slope, slope 0 at the knots."""
    ramp = PolynomialRampUpDown(peak=5.0, t_start=5.0, t_peak=8.5, t_end=12.0)
    h = 1e-4
    t = np.arange(4.0, 13.0, h)
    v = ramp.value(t)
    # Continuity: neighbouring samples differ by at most max|slope| h (max slope 15/8 peak/T).
    max_slope = 15.0 / 8.0 * 5.0 / 3.5
    assert np.max(np.abs(np.diff(v))) <= max_slope * h * 1.001
    # C1: the finite-difference slope changes by O(h) between neighbours (max |s''| ~ 5.77).
    slope = np.diff(v) / h
    assert np.max(np.abs(np.diff(slope))) < 10.0 * 5.0 / 3.5**2 * h * 1.01
    # One-sided slopes vanish at t_start, t_peak and t_end.
    for knot in (5.0, 8.5, 12.0):
        left = (ramp.value(knot) - ramp.value(knot - 1e-5)) / 1e-5
        right = (ramp.value(knot + 1e-5) - ramp.value(knot)) / 1e-5
        assert abs(left) < 1e-6 and abs(right) < 1e-6, knot


def test_sinusoid_matches_formula():
    s = Sinusoid(amplitude=20.0, frequency_hz=0.5, phase=0.3, offset=1.0, t_start=2.0, t_end=7.0)
    t = np.linspace(2.0, 7.0, 501)
    expected = 1.0 + 20.0 * np.sin(2 * np.pi * 0.5 * (t - 2.0) + 0.3)
    np.testing.assert_allclose(s.value(t), expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose([s.value(float(x)) for x in t], expected, rtol=0, atol=1e-12)
    for outside in (0.0, 1.999, 7.001, 50.0):
        assert s.value(outside) == 0.0
    np.testing.assert_array_equal(s.value(np.array([1.0, 8.0])), [0.0, 0.0])
    # Defaults: active from t = 0 forever, plain A sin(2 pi f t).
    d = Sinusoid(amplitude=2.0, frequency_hz=1.0)
    assert d.value(0.25) == pytest.approx(2.0)
    assert d.value(1e6 + 0.25) == pytest.approx(2.0, abs=1e-6)
    assert d.value(-0.1) == 0.0


def test_step_on_off():
    step = Step(magnitude=7.0, t_on=1.0, t_off=2.0)
    assert step.value(0.999) == 0.0
    assert step.value(1.0) == 7.0
    assert step.value(1.5) == 7.0
    assert step.value(2.0) == 0.0
    assert step.value(3.0) == 0.0
    np.testing.assert_array_equal(step.value(np.array([0.0, 1.0, 1.9, 2.0])), [0.0, 7.0, 7.0, 0.0])
    forever = Step(magnitude=-1.0, t_on=0.0)
    assert forever.value(1e9) == -1.0


@pytest.mark.parametrize(
    "make",
    [
        lambda: PolynomialRampUpDown(5.0, 5.0, 5.0, 12.0),
        lambda: PolynomialRampUpDown(5.0, 5.0, 12.0, 8.5),
        lambda: PolynomialRampUpDown(5.0, 6.0, 5.0, 12.0),
        lambda: PolynomialRampUpDown(math.nan, 5.0, 8.5, 12.0),
        lambda: PolynomialRampUpDown(5.0, 5.0, 8.5, math.inf),
        lambda: PolynomialRampUpDown("five", 5.0, 8.5, 12.0),
        lambda: Sinusoid(1.0, -1.0),
        lambda: Sinusoid(math.inf, 1.0),
        lambda: Sinusoid(1.0, 1.0, t_start=2.0, t_end=1.0),
        lambda: Sinusoid(1.0, 1.0, t_start=2.0, t_end=2.0),
        lambda: Sinusoid(1.0, 1.0, t_end=math.nan),
        lambda: Sinusoid(1.0, 1.0, phase=math.nan),
        lambda: Step(1.0, t_on=2.0, t_off=1.0),
        lambda: Step(1.0, t_on=math.inf),
        lambda: Step(math.nan, t_on=0.0),
    ],
)
def test_bad_profile_parameters_raise(make):
    with pytest.raises(ValueError):
        make()


def test_profiles_are_frozen():
    ramp = PolynomialRampUpDown(5.0, 5.0, 8.5, 12.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        ramp.peak = 3.0


# ---------------------------------------------------------------------------------------
# Push.
# ---------------------------------------------------------------------------------------


def test_push_normalises_direction_and_validates():
    push = Push("link", [0.1, 0.0, 0.0], [0.0, 3.0, 4.0], Step(10.0, 0.0))
    np.testing.assert_allclose(push.direction_W, [0.0, 0.6, 0.8])
    np.testing.assert_allclose(push.force_W(1.0), [0.0, 6.0, 8.0])
    np.testing.assert_allclose(push.force_W(np.array([-1.0, 1.0])), [[0, 0, 0], [0.0, 6.0, 8.0]])
    with pytest.raises(ValueError):
        push.direction_W[0] = 1.0  # read-only
    assert push == Push("link", (0.1, 0, 0), (0, 0.6, 0.8), Step(10.0, 0.0))
    with pytest.raises(ValueError, match="non-zero"):
        Push("link", [0, 0, 0], [0, 0, 0], Step(1.0, 0.0))
    with pytest.raises(ValueError):
        Push("link", [0, 0], [0, 0, 1], Step(1.0, 0.0))
    with pytest.raises(ValueError):
        Push("link", [0, 0, math.nan], [0, 0, 1], Step(1.0, 0.0))
    with pytest.raises(ValueError):
        Push("", [0, 0, 0], [0, 0, 1], Step(1.0, 0.0))
    with pytest.raises(ValueError):
        Push("link", [0, 0, 0], [0, 0, 1], 5.0)


# ---------------------------------------------------------------------------------------
# PushSource against Drake.
# ---------------------------------------------------------------------------------------


def _small_floating_plant(time_step=0.0, gravity=True, builder=None):
    """A 4-body floating tree whose free joint's child frame F0 is offset from the base
    body frame (so base-frame quantities are not the body frame's), plus a wall welded to
    the world (not part of the robot)."""
    if builder is None:
        plant = MultibodyPlant(time_step)
    else:
        plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=time_step), builder)
    base = plant.AddRigidBody("base", SpatialInertia.SolidBoxWithMass(5.0, 0.3, 0.2, 0.4))
    F0 = plant.AddFrame(
        FixedOffsetFrame("F0", base.body_frame(), RigidTransform(RollPitchYaw(0.2, -0.3, 0.5), [0.05, -0.03, 0.1]))
    )
    plant.AddJoint(QuaternionFloatingJoint("free", plant.world_frame(), F0))
    inertia = SpatialInertia.SolidBoxWithMass(1.0, 0.05, 0.05, 0.3).Shift([0.0, 0.0, -0.15])
    arm = plant.AddRigidBody("arm", inertia)
    plant.AddJoint(RevoluteJoint("shoulder", base.body_frame(), arm.body_frame(), [0.0, 1.0, 0.0]))
    hand = plant.AddRigidBody("hand", SpatialInertia.SolidBoxWithMass(0.5, 0.05, 0.05, 0.1))
    elbow = plant.AddFrame(FixedOffsetFrame("elbow_frame", arm.body_frame(), RigidTransform([0.0, 0.0, -0.3])))
    plant.AddJoint(RevoluteJoint("elbow", elbow, hand.body_frame(), [1.0, 0.0, 0.0]))
    head = plant.AddRigidBody("head", SpatialInertia.SolidSphereWithMass(0.8, 0.08))
    neck = plant.AddFrame(FixedOffsetFrame("neck_frame", base.body_frame(), RigidTransform([0.0, 0.0, 0.3])))
    plant.AddJoint(PrismaticJoint("neck", neck, head.body_frame(), [0.0, 0.0, 1.0]))
    wall = plant.AddRigidBody("wall", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1))
    plant.WeldFrames(plant.world_frame(), wall.body_frame(), RigidTransform([1.0, 0.0, 0.5]))
    if not gravity:
        plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    plant.Finalize()
    return plant


def _random_state(plant, rng, speed=1.0):
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    q = np.concatenate((quat, rng.normal(scale=0.5, size=3), rng.uniform(-1, 1, plant.num_positions() - 7)))
    v = rng.normal(scale=speed, size=plant.num_velocities())
    return np.concatenate((q, v))


def _small_pushes():
    return [
        Push("arm", [0.02, 0.03, -0.25], [1.0, -0.5, 0.2], Sinusoid(8.0, 1.3, phase=0.4)),
        Push(
            "head",
            [0.0, 0.05, 0.02],
            [0.0, 0.0, -1.0],
            PolynomialRampUpDown(peak=5.0, t_start=0.1, t_peak=0.6, t_end=1.2),
        ),
        Push("hand", [0.0, 0.0, -0.05], [0.0, 1.0, 0.0], Step(3.0, t_on=2.0)),  # off before t=2
        Push("base", [0.1, -0.1, 0.2], [0.3, 0.3, 1.0], Step(-4.0, t_on=0.0)),
    ]


def _hrp4_plant():
    plant = MultibodyPlant(0.0)
    add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    return plant


def _hrp4_pushes():
    return [
        Push("R_SHOULDER_P_LINK", [0.0, -0.05, 0.02], [0.2, 1.0, -0.1], Sinusoid(20.0, 0.5)),
        Push(
            "L_SHOULDER_P_LINK",
            [0.0, 0.05, 0.0],
            [0.0, 0.0, -1.0],
            PolynomialRampUpDown(peak=5.0, t_start=0.0, t_peak=0.5, t_end=1.0),
        ),
        Push("R_ANKLE_R_LINK", [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], Step(5.0, t_on=3.0)),  # off
    ]


def _expected_ground_truth(plant, base_frame, pushes, x, t):
    """Forces, points, wrenches and tau_c_real from Drake's own kinematics and dynamics."""
    ctx = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(ctx, x)
    world = plant.world_frame()
    forces, points = [], []
    wrench_W = np.zeros(6)
    wrench_F0 = np.zeros(6)
    X_F0W = plant.CalcRelativeTransform(ctx, base_frame, world)
    M = plant.CalcMassMatrix(ctx)
    tau = np.zeros(plant.num_velocities() - 6)
    for push in pushes:
        body = plant.GetBodyByName(push.body_name)
        d = np.asarray(push.direction_W)
        f = float(push.profile.value(t)) * d
        p_WP = plant.EvalBodyPoseInWorld(ctx, body) @ np.asarray(push.p_BoP_B)
        forces.append(f)
        points.append(p_WP)
        wrench_W += np.concatenate((np.cross(p_WP, f), f))
        p_F0P = X_F0W @ p_WP
        f_F0 = X_F0W.rotation() @ f
        wrench_F0 += np.concatenate((np.cross(p_F0P, f_F0), f_F0))
        J = plant.CalcJacobianTranslationalVelocity(
            ctx, JacobianWrtVariable.kV, body.body_frame(), np.asarray(push.p_BoP_B), world, world
        )
        J_fb = J[:, 6:] - J[:, :6] @ np.linalg.solve(M[:6, :6], M[:6, 6:])
        tau += J_fb.T @ f
    return np.array(forces), np.array(points), wrench_W, wrench_F0, tau


def _check_against_drake(plant, pushes, x, t, dynamics=None):
    dut = PushSource(plant, pushes, dynamics=dynamics)
    ctx = dut.CreateDefaultContext()
    ctx.SetTime(t)
    dut.GetInputPort("state").FixValue(ctx, x)
    base_frame = (dynamics or FloatingBaseDynamics(plant)).topology.base_frame
    forces, points, wrench_W, wrench_F0, tau = _expected_ground_truth(plant, base_frame, pushes, x, t)

    applied = dut.GetOutputPort("applied_spatial_forces").Eval(ctx)
    on = [i for i, f in enumerate(forces) if f.any()]  # the pushes at zero are left out
    assert len(applied) == len(on)
    for push, a, f in zip([pushes[i] for i in on], applied, forces[on]):
        assert a.body_index == plant.GetBodyByName(push.body_name).index()
        np.testing.assert_array_equal(a.p_BoBq_B, push.p_BoP_B)
        np.testing.assert_array_equal(a.F_Bq_W.rotational(), np.zeros(3))
        np.testing.assert_allclose(a.F_Bq_W.translational(), f, rtol=0, atol=1e-14)

    np.testing.assert_allclose(dut.GetOutputPort("force_world").Eval(ctx), forces.reshape(-1), atol=1e-14)
    np.testing.assert_allclose(dut.GetOutputPort("point_world").Eval(ctx), points.reshape(-1), atol=1e-13)
    np.testing.assert_allclose(dut.GetOutputPort("total_wrench_world").Eval(ctx), wrench_W, atol=1e-12)
    np.testing.assert_allclose(dut.GetOutputPort("total_wrench_base").Eval(ctx), wrench_F0, atol=1e-12)
    tau_dut = dut.GetOutputPort("tau_c_real").Eval(ctx)
    assert tau_dut.shape == (plant.num_velocities() - 6,)
    np.testing.assert_allclose(tau_dut, tau, rtol=1e-10, atol=1e-10 * max(1.0, np.abs(tau).max()))
    return dut, ctx, tau


def test_push_source_small_plant_matches_drake():
    plant = _small_floating_plant()
    rng = np.random.default_rng(0)
    pushes = _small_pushes()
    for t in (0.35, 0.9):
        x = _random_state(plant, rng)
        dut, ctx, tau = _check_against_drake(plant, pushes, x, t)
        # The base frame F0 is the offset frame, not the base body frame: the two base
        # wrenches must differ (guards against using the body frame by mistake).
        assert dut.dynamics.topology.base_frame.name() == "F0"
        assert np.linalg.norm(tau) > 0.1
    # Also equal to the sum of FloatingBaseDynamics' own floating Jacobians (both
    # implementations), paper eq. (12).
    t = 0.35
    for impl in ("fast", "reference"):
        dyn = FloatingBaseDynamics(plant, implementation=impl)
        dut, ctx, tau = _check_against_drake(plant, pushes, x, t, dynamics=dyn)
        expected = sum(
            dyn.floating_jacobian(
                x[: plant.num_positions()], plant.GetBodyByName(p.body_name).body_frame(), p.p_BoP_B
            ).T
            @ p.force_W(t)
            for p in pushes
        )
        np.testing.assert_allclose(dut.GetOutputPort("tau_c_real").Eval(ctx), expected, atol=1e-9)


def test_push_source_hrp4_matches_drake():
    plant = _hrp4_plant()
    rng = np.random.default_rng(1)
    x = _random_state(plant, rng)
    x[7 : plant.num_positions()] *= 0.5
    dut, ctx, tau = _check_against_drake(plant, _hrp4_pushes(), x, 0.3)
    # The push on the right shoulder moves leg joints too (the point of eq. 12, Sec. III).
    legs = [plant.GetJointByName(n).velocity_start() - 6 for n in ("R_KNEE_P", "L_KNEE_P")]
    assert np.all(np.abs(tau[legs]) > 1e-3)


def test_zero_forces_give_zero_ground_truth():
    plant = _small_floating_plant()
    pushes = [Push("arm", [0, 0, -0.2], [1, 0, 0], Step(5.0, t_on=1.0, t_off=2.0))]
    dut = PushSource(plant, pushes)
    ctx = dut.CreateDefaultContext()
    x = _random_state(plant, np.random.default_rng(2))
    dut.GetInputPort("state").FixValue(ctx, x)
    for t in (0.5, 2.5):
        ctx.SetTime(t)
        for name in ("force_world", "total_wrench_world", "total_wrench_base", "tau_c_real"):
            np.testing.assert_array_equal(dut.GetOutputPort(name).Eval(ctx), 0.0)
        assert np.linalg.norm(dut.GetOutputPort("point_world").Eval(ctx)) > 0.0
        assert dut.GetOutputPort("applied_spatial_forces").Eval(ctx) == []  # off: nothing applied
    ctx.SetTime(1.5)  # on: the cached values must be recomputed
    applied = dut.GetOutputPort("applied_spatial_forces").Eval(ctx)
    assert len(applied) == 1
    np.testing.assert_array_equal(applied[0].F_Bq_W.translational(), [5.0, 0.0, 0.0])
    assert np.linalg.norm(dut.GetOutputPort("tau_c_real").Eval(ctx)) > 0.0
    np.testing.assert_allclose(dut.GetOutputPort("force_world").Eval(ctx), [5.0, 0.0, 0.0])


def test_state_change_updates_cached_ground_truth():
    plant = _small_floating_plant()
    pushes = _small_pushes()
    dut = PushSource(plant, pushes)
    ctx = dut.CreateDefaultContext()
    ctx.SetTime(0.4)
    rng = np.random.default_rng(3)
    for _ in range(2):
        x = _random_state(plant, rng)
        dut.GetInputPort("state").FixValue(ctx, x)
        _, points, wrench_W, wrench_F0, tau = _expected_ground_truth(
            plant, dut.dynamics.topology.base_frame, pushes, x, 0.4
        )
        np.testing.assert_allclose(dut.GetOutputPort("point_world").Eval(ctx), points.reshape(-1), atol=1e-13)
        np.testing.assert_allclose(dut.GetOutputPort("total_wrench_base").Eval(ctx), wrench_F0, atol=1e-12)
        np.testing.assert_allclose(dut.GetOutputPort("tau_c_real").Eval(ctx), tau, atol=1e-10)


def test_push_on_body_outside_robot_is_applied_but_not_ground_truth():
    plant = _small_floating_plant()
    pushes = [Push("wall", [0, 0, 0], [0, 0, 1], Step(2.0, 0.0)), Push("arm", [0, 0, -0.2], [1, 0, 0], Step(5.0, 0.0))]
    dut = PushSource(plant, pushes)
    np.testing.assert_array_equal(dut.on_robot, [False, True])
    ctx = dut.CreateDefaultContext()
    x = _random_state(plant, np.random.default_rng(4))
    dut.GetInputPort("state").FixValue(ctx, x)
    ctx.SetTime(1.0)
    applied = dut.GetOutputPort("applied_spatial_forces").Eval(ctx)
    assert applied[0].body_index == plant.GetBodyByName("wall").index()
    np.testing.assert_allclose(applied[0].F_Bq_W.translational(), [0, 0, 2.0])
    np.testing.assert_allclose(dut.GetOutputPort("force_world").Eval(ctx), [0, 0, 2, 5, 0, 0])
    np.testing.assert_allclose(dut.GetOutputPort("point_world").Eval(ctx)[:3], [1.0, 0.0, 0.5])
    _, _, wrench_W, _, tau = _expected_ground_truth(plant, dut.dynamics.topology.base_frame, pushes[1:], x, 1.0)
    np.testing.assert_allclose(dut.GetOutputPort("total_wrench_world").Eval(ctx), wrench_W, atol=1e-12)
    np.testing.assert_allclose(dut.GetOutputPort("tau_c_real").Eval(ctx), tau, atol=1e-10)


def test_unknown_body_raises_naming_it():
    plant = _small_floating_plant()
    with pytest.raises(ValueError, match="no_such_link"):
        PushSource(plant, [Push("no_such_link", [0, 0, 0], [0, 0, 1], Step(1.0, 0.0))])
    with pytest.raises(ValueError, match="nowhere"):
        PushSource(plant, [Push("arm", [0, 0, 0], [0, 0, 1], Step(1.0, 0.0), model_instance_name="nowhere")])
    with pytest.raises(ValueError, match="not a Push"):
        PushSource(plant, ["arm"])
    unfinalized = MultibodyPlant(0.0)
    with pytest.raises(ValueError, match="finalized"):
        PushSource(unfinalized, [])


def test_model_instance_name_resolves_body():
    plant = _hrp4_plant()
    push = Push("R_SHOULDER_P_LINK", [0, 0, 0], [0, 0, 1], Step(1.0, 0.0), model_instance_name="hrp4_like")
    dut = PushSource(plant, [push])
    assert dut.bodies[0].name() == "R_SHOULDER_P_LINK"


def test_applied_forces_do_not_depend_on_state():
    plant = _small_floating_plant()
    dut = PushSource(plant, _small_pushes())
    state = dut.GetInputPort("state").get_index()
    assert not dut.HasDirectFeedthrough(state, dut.GetOutputPort("applied_spatial_forces").get_index())
    assert not dut.HasDirectFeedthrough(state, dut.GetOutputPort("force_world").get_index())
    assert dut.HasDirectFeedthrough(state, dut.GetOutputPort("tau_c_real").get_index())
    # Evaluates without the state input connected.
    ctx = dut.CreateDefaultContext()
    ctx.SetTime(0.3)
    assert len(dut.GetOutputPort("applied_spatial_forces").Eval(ctx)) == 3  # the hand's push starts at 2 s


class _CustomProfile:
    """A user profile with no known support: on in [0.5, 0.6) only."""

    def value(self, t):
        return 2.0 if 0.5 <= t < 0.6 else 0.0


def test_applied_forces_are_the_pushes_on_at_t_in_order():
    """A run's schedule of many pushes (the contact study's) hands the plant only those on at
    t, with each force; support windows and user profiles without one give the same list."""
    plant = _small_floating_plant()
    pushes = [
        Push("arm", [0.0, 0.0, -0.2], [1.0, 0.0, 0.0], Step(1.0 + k, t_on=0.1 * k, t_off=0.1 * k + 0.1))
        for k in range(10)
    ]
    pushes.append(Push("head", [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], _CustomProfile()))
    pushes.append(Push("hand", [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], Sinusoid(3.0, 2.0, t_start=0.55, t_end=0.7)))
    dut = PushSource(plant, pushes)
    ctx = dut.CreateDefaultContext()
    for t in (0.0, 0.25, 0.52, 0.57, 0.65, 0.95, 1.5):
        ctx.SetTime(t)
        applied = dut.GetOutputPort("applied_spatial_forces").Eval(ctx)
        expected = [(i, p) for i, p in enumerate(pushes) if p.force_W(t).any()]
        assert [a.body_index for a in applied] == [dut.bodies[i].index() for i, _ in expected]
        for a, (_, push) in zip(applied, expected):
            np.testing.assert_array_equal(a.F_Bq_W.translational(), push.force_W(t))
            np.testing.assert_array_equal(a.p_BoBq_B, push.p_BoP_B)
    ctx.SetTime(1.5)
    assert dut.GetOutputPort("applied_spatial_forces").Eval(ctx) == []


def test_profile_support_bounds_each_profile_of_this_module():
    assert profile_support(Step(2.0, t_on=0.5, t_off=0.7)) == (0.5, 0.7)
    assert profile_support(Sinusoid(1.0, 2.0, t_start=0.3)) == (0.3, math.inf)
    assert profile_support(PolynomialRampUpDown(peak=5.0, t_start=0.1, t_peak=0.6, t_end=1.2)) == (0.1, 1.2)
    assert profile_support(_CustomProfile()) == (-math.inf, math.inf)
    for profile in (Step(2.0, 0.5, 0.7), Sinusoid(1.0, 2.0, t_start=0.3, t_end=0.9, offset=0.5)):
        start, end = profile_support(profile)
        outside = np.array([start - 0.2, start - 1e-9, end + 1e-9, end + 0.3])
        np.testing.assert_array_equal(profile.value(outside), 0.0)


def test_empty_push_list_connects_and_outputs_zeros():
    diagram, plant, source, _ = _pushed_diagram([], 1e-3, True)
    context = diagram.CreateDefaultContext()
    sc = source.GetMyContextFromRoot(context)
    assert source.GetOutputPort("applied_spatial_forces").Eval(sc) == []
    assert source.GetOutputPort("force_world").size() == 0
    np.testing.assert_array_equal(source.GetOutputPort("total_wrench_base").Eval(sc), np.zeros(6))
    np.testing.assert_array_equal(source.GetOutputPort("tau_c_real").Eval(sc), np.zeros(plant.num_velocities() - 6))


# ---------------------------------------------------------------------------------------
# Physics: the pushes really act on the plant.
# ---------------------------------------------------------------------------------------


def _pushed_diagram(pushes, time_step, gravity, log_period=None):
    builder = DiagramBuilder()
    plant = _small_floating_plant(time_step=time_step, gravity=gravity, builder=builder)
    source = builder.AddSystem(PushSource(plant, pushes))
    builder.Connect(source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), source.GetInputPort("state"))
    logger = None
    if log_period is not None:
        logger = LogVectorOutput(source.GetOutputPort("total_wrench_world"), builder, log_period)
    diagram = builder.Build()
    return diagram, plant, source, logger


def _robot_mass(plant, plant_context):
    """Mass of the moving bodies (the welded wall's weight goes to the world)."""
    return plant.CalcTotalMass(plant_context) - plant.GetBodyByName("wall").default_mass()


def _momentum(plant, plant_context):
    h = plant.CalcSpatialMomentumInWorldAboutPoint(plant_context, np.zeros(3))
    return np.concatenate((h.rotational(), h.translational()))


def test_accelerations_match_equations_of_motion_with_pushes():
    """Continuous plant: M v̇ + C v - τ_g = Σ J_c^T f_c at a moving state."""
    pushes = _small_pushes()
    diagram, plant, _, _ = _pushed_diagram(pushes, time_step=0.0, gravity=True)
    context = diagram.CreateDefaultContext()
    context.SetTime(0.4)
    pc = plant.GetMyMutableContextFromRoot(context)
    x = _random_state(plant, np.random.default_rng(5))
    plant.SetPositionsAndVelocities(pc, x)
    derivatives = diagram.EvalTimeDerivatives(context)
    vdot = derivatives.get_vector().CopyToVector()[plant.num_positions() :]  # plant is the only stateful system
    world = plant.world_frame()
    generalized = np.zeros(plant.num_velocities())
    for push in pushes:
        J = plant.CalcJacobianTranslationalVelocity(
            pc,
            JacobianWrtVariable.kV,
            plant.GetBodyByName(push.body_name).body_frame(),
            np.asarray(push.p_BoP_B),
            world,
            world,
        )
        generalized += J.T @ push.force_W(0.4)
    lhs = plant.CalcMassMatrix(pc) @ vdot + plant.CalcBiasTerm(pc) - plant.CalcGravityGeneralizedForces(pc)
    np.testing.assert_allclose(lhs, generalized, atol=1e-9 * max(1.0, np.abs(generalized).max()))
    assert np.abs(generalized).max() > 1.0


def test_momentum_change_equals_impulse_continuous():
    """Linear momentum: ΔP = ∫ Σ f dt + m g Δt; angular about the world origin (no gravity):
    ΔL = ∫ total_wrench_world[:3] dt (trapezoid on the 1 ms log)."""
    pushes = _small_pushes()
    t0, t1 = 0.0, 0.8
    for gravity in (True, False):
        diagram, plant, source, logger = _pushed_diagram(pushes, 0.0, gravity, log_period=1e-3)
        simulator = Simulator(diagram)
        simulator.get_mutable_integrator().set_target_accuracy(1e-9)
        context = simulator.get_mutable_context()
        pc = plant.GetMyMutableContextFromRoot(context)
        x = _random_state(plant, np.random.default_rng(6), speed=0.3)
        x[4:7] = [0.0, 0.0, 1.0]
        plant.SetPositionsAndVelocities(pc, x)
        h0 = _momentum(plant, pc)
        simulator.AdvanceTo(t1)
        h1 = _momentum(plant, pc)
        mass = _robot_mass(plant, pc)
        g = np.asarray(plant.gravity_field().gravity_vector())
        t = np.linspace(t0, t1, 80001)
        force = sum(p.force_W(t) for p in pushes)
        impulse = np.trapezoid(force, t, axis=0)
        np.testing.assert_allclose(h1[3:] - h0[3:], impulse + mass * g * (t1 - t0), rtol=0, atol=1e-6)
        assert np.linalg.norm(impulse) > 1.0
        if not gravity:
            log = logger.FindLog(context)
            angular_impulse = np.trapezoid(log.data()[:3], log.sample_times(), axis=1)
            assert log.sample_times()[-1] == pytest.approx(t1)
            np.testing.assert_allclose(
                h1[:3] - h0[:3], angular_impulse, rtol=0, atol=2e-5 * np.linalg.norm(angular_impulse)
            )
            assert np.linalg.norm(angular_impulse) > 0.1


def test_momentum_change_equals_impulse_discrete():
    """Discrete plant: ΔP over 0.3 s with a constant push equals (f + m g) Δt, up to the
    first-order time discretisation (the error shrinks with the step)."""
    pushes = [
        Push("arm", [0.02, 0.0, -0.2], [1.0, 0.5, 0.0], Step(10.0, t_on=0.0)),
        Push("head", [0.0, 0.0, 0.05], [0.0, 0.0, -1.0], Step(4.0, t_on=0.0)),
    ]
    errors = []
    for time_step in (1e-3, 2.5e-4):
        diagram, plant, _, _ = _pushed_diagram(pushes, time_step, True)
        simulator = Simulator(diagram)
        context = simulator.get_mutable_context()
        pc = plant.GetMyMutableContextFromRoot(context)
        x = _random_state(plant, np.random.default_rng(7), speed=0.0)
        x[4:7] = [0.0, 0.0, 1.0]
        plant.SetPositionsAndVelocities(pc, x)
        h0 = _momentum(plant, pc)
        simulator.AdvanceTo(0.3)
        h1 = _momentum(plant, pc)
        f = sum(p.force_W(0.0) for p in pushes)
        g = np.asarray(plant.gravity_field().gravity_vector())
        expected = (f + _robot_mass(plant, pc) * g) * 0.3
        np.testing.assert_allclose(h1[3:] - h0[3:], expected, rtol=0, atol=1e-2 * np.linalg.norm(expected))
        errors.append(np.linalg.norm(h1[3:] - h0[3:] - expected))
    assert errors[1] < 0.5 * errors[0], errors


def test_smooth_piecewise_profile_through_its_knots():
    from systems.simulation.disturbances import SmoothPiecewise

    profile = SmoothPiecewise((1.0, 2.0, 4.0, 5.0), (0.0, 3.0, 3.0, -1.0))
    t = np.linspace(0.0, 6.0, 601)
    values = profile.value(t)
    np.testing.assert_allclose(values, [profile.value(float(s)) for s in t], atol=1e-12)  # scalar == vector path
    np.testing.assert_allclose(
        profile.value(np.array([0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 5.5])), [0.0, 0.0, 3.0, 3.0, 3.0, -1.0, -1.0], atol=1e-12
    )
    assert profile.value(1.5) == pytest.approx(1.5)  # the smoothstep's midpoint
    slope = np.gradient(values, t)
    assert abs(slope[np.searchsorted(t, 2.0)]) < 0.05  # flat at the knot (the ramp peaks at 4.5 N/s)
    assert profile.plateaus(1.0) == [(2.0, 4.0)]
    with pytest.raises(ValueError, match="times must increase"):
        SmoothPiecewise((0.0, 1.0, 0.5), (1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="times must increase"):
        SmoothPiecewise((0.0, 1.0, 1.0, 1.0), (1.0, 2.0, 3.0, 4.0))  # a time thrice


def test_smooth_piecewise_steps_at_a_repeated_knot():
    """A knot time given twice is a step (Hawley et al.'s loads, issue 31): the value jumps
    there, both evaluation paths agree, and the plateaus on either side are found."""
    from systems.simulation.disturbances import SmoothPiecewise

    profile = SmoothPiecewise((0.0, 1.0, 1.0, 3.0, 3.0), (0.0, 0.0, 11.0, 11.0, 0.0))
    t = np.array([0.5, 0.999999, 1.0, 2.0, 2.999999, 3.0, 4.0])
    expected = [0.0, 0.0, 11.0, 11.0, 11.0, 0.0, 0.0]
    np.testing.assert_array_equal(profile.value(t), expected)
    assert [profile.value(float(s)) for s in t] == expected
    assert profile.plateaus(1.0) == [(0.0, 1.0), (1.0, 3.0)]
