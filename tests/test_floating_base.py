"""FloatingBaseDynamics: the fast and reference implementations agree, obey the equations of
motion that Drake integrates, and refuse plants and states they cannot handle."""

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    BallRpyJoint,
    JacobianWrtVariable,
    PlanarJoint,
    RevoluteJoint,
    RpyFloatingJoint,
    SpatialInertia,
)
from random_trees import make_random_floating_tree, random_state

from models import MODEL_NAMES, add_humanoid
from systems.dynamics.floating_base import FloatingBaseDynamics

FIELDS = ("H", "F", "I0c", "C_hat", "p_hat", "H_dot", "F_dot", "I0c_dot", "H_fb", "H_fb_dot", "C_fb", "R_WB", "v0")


def relative_error(actual: np.ndarray, expected: np.ndarray) -> float:
    """Frobenius norm of the difference over the norm of the expected value (absolute if 0)."""
    scale = np.linalg.norm(expected)
    return float(np.linalg.norm(actual - expected) / (scale if scale > 0 else 1.0))


def humanoid_plant(name: str) -> MultibodyPlant:
    plant = MultibodyPlant(time_step=0.0)
    add_humanoid(plant, name)
    plant.Finalize()
    return plant


# (num_joints, seed) pairs: chains, wide trees, mixed; 1 to 60 joints.
RANDOM_TREES = [(1, 0), (2, 1), (5, 2), (9, 3), (17, 4), (34, 5), (45, 6), (60, 7), (60, 8), (23, 9)]


@pytest.mark.parametrize("num_joints,seed", RANDOM_TREES)
def test_fast_equals_reference_on_random_trees(num_joints, seed):
    plant, _ = make_random_floating_tree(num_joints, seed)
    fast = FloatingBaseDynamics(plant, "fast")
    reference = FloatingBaseDynamics(plant, "reference")
    rng = np.random.default_rng(100 + seed)
    for _ in range(3):
        q, v = random_state(plant, rng)
        a, b = fast.compute(q, v), reference.compute(q, v)
        errors = {f: relative_error(getattr(a, f), getattr(b, f)) for f in FIELDS}
        worst = max(errors, key=errors.get)
        assert errors[worst] < 1e-8, f"{worst}: relative error {errors[worst]:.2e} ({errors})"


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_fast_equals_reference_on_humanoids(name):
    plant = humanoid_plant(name)
    fast = FloatingBaseDynamics(plant, "fast")
    reference = FloatingBaseDynamics(plant, "reference")
    rng = np.random.default_rng(7)
    for _ in range(3):
        q, v = random_state(plant, rng)
        a, b = fast.compute(q, v), reference.compute(q, v)
        for f in FIELDS:
            assert relative_error(getattr(a, f), getattr(b, f)) < 1e-8, f
        frame = fast.topology.joints[-1].child_body().body_frame()
        p = rng.normal(size=3) * 0.1
        for spatial in (False, True):
            assert (
                relative_error(
                    fast.floating_jacobian(q, frame, p, spatial=spatial),
                    reference.floating_jacobian(q, frame, p, spatial=spatial),
                )
                < 1e-8
            )


def _forward_dynamics(plant, context, q, v, tau_joints, body, p_BP, f_W):
    """Drake's v_dot for joint torques tau and a force f_W at point P of body (free base)."""
    plant.SetPositions(context, q)
    plant.SetVelocities(context, v)
    M = plant.CalcMassMatrix(context)
    J = plant.CalcJacobianTranslationalVelocity(
        context, JacobianWrtVariable.kV, body.body_frame(), p_BP, plant.world_frame(), plant.world_frame()
    )
    generalized = plant.CalcGravityGeneralizedForces(context) - plant.CalcBiasTerm(context) + J.T @ f_W
    generalized[6:] += tau_joints
    return np.linalg.solve(M, generalized)


@pytest.mark.parametrize("implementation", ["fast", "reference"])
@pytest.mark.parametrize("num_joints,seed", [(3, 11), (12, 12), (30, 13), (60, 14)])
def test_equations_of_motion_with_an_external_force(implementation, num_joints, seed):
    """Paper eq. (9) with one external force: the joint rows H_fb q_dd + C_fb = tau + J_fb^T f
    (eq. 12) and the base rows I0c a0 + F q_dd + p_hat = 0X*_ref f hold for Drake's dynamics."""
    plant, context = make_random_floating_tree(num_joints, seed)
    dynamics = FloatingBaseDynamics(plant, implementation)
    rng = np.random.default_rng(seed)
    q, v = random_state(plant, rng)
    n = dynamics.num_joints
    tau = rng.normal(size=n)
    body = plant.get_joint(dynamics.topology.joints[rng.integers(n)].index()).child_body()
    p_BP = rng.normal(size=3) * 0.2
    f_W = rng.normal(size=3) * 5.0
    v_dot = _forward_dynamics(plant, context, q, v, tau, body, p_BP, f_W)
    terms = dynamics.compute(q, v)

    J_fb = dynamics.floating_jacobian(q, body.body_frame(), p_BP)
    assert J_fb.shape == (3, n)
    joint_rows = terms.H_fb @ v_dot[6:] + terms.C_fb
    assert relative_error(joint_rows, tau + J_fb.T @ f_W) < 1e-9

    # Base rows in F0: a0 is the derivative of v0 = [R^T w; R^T v_Bo] (Featherstone).
    plant.SetPositions(context, q)
    X_WB = dynamics.topology.base_frame.CalcPoseInWorld(context)
    R = terms.R_WB
    assert relative_error(R, X_WB.rotation().matrix()) < 1e-12
    P = dynamics.topology.free_joint.frame_on_parent().CalcPoseInWorld(context).rotation().matrix()
    w_B, v_B = terms.v0[:3], terms.v0[3:]
    a0 = np.concatenate((R.T @ P @ v_dot[:3], R.T @ P @ v_dot[3:6] - np.cross(w_B, v_B)))
    p_P_W = plant.CalcPointsPositions(context, body.body_frame(), p_BP, plant.world_frame()).ravel()
    r_B = R.T @ (p_P_W - X_WB.translation())
    f_B = R.T @ f_W
    wrench_F0 = np.concatenate((np.cross(r_B, f_B), f_B))
    base_rows = terms.I0c @ a0 + terms.F @ v_dot[6:] + terms.p_hat
    assert relative_error(base_rows, wrench_F0) < 1e-9


@pytest.mark.parametrize("num_joints,seed", [(6, 21), (40, 22)])
def test_fast_derivatives_equal_finite_differences(num_joints, seed):
    """H_dot, F_dot, I0c_dot, H_fb_dot of the fast implementation vs. a central difference of
    its own H, F, I0c, H_fb along the joint motion (in F0 they depend on joints only)."""
    plant, _ = make_random_floating_tree(num_joints, seed)
    dynamics = FloatingBaseDynamics(plant, "fast")
    q, v = random_state(plant, np.random.default_rng(seed))
    h = 1e-6
    plus, minus = q.copy(), q.copy()
    plus[7:] += h * v[6:]
    minus[7:] -= h * v[6:]
    a, b, terms = dynamics.compute(plus, v), dynamics.compute(minus, v), dynamics.compute(q, v)
    for name in ("H", "F", "I0c", "H_fb"):
        fd = (getattr(a, name) - getattr(b, name)) / (2 * h)
        assert relative_error(getattr(terms, name + "_dot"), fd) < 1e-6, name


def test_zero_joint_velocity_gives_zero_derivatives():
    plant, _ = make_random_floating_tree(8, 31)
    dynamics = FloatingBaseDynamics(plant, "fast")
    q, v = random_state(plant, np.random.default_rng(1))
    v[6:] = 0.0
    terms = dynamics.compute(q, v)
    assert not terms.H_dot.any() and not terms.F_dot.any() and not terms.I0c_dot.any()


# --- Plants the floating-base dynamics must refuse ---------------------------------------


def _plant_with(joint_factory=None, *, weld_root=False, second_free_body=False, finalize=True):
    plant = MultibodyPlant(time_step=0.0)
    inertia = SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.2, 0.3)
    base = plant.AddRigidBody("base", inertia)
    link = plant.AddRigidBody("link", inertia)
    if joint_factory is None:
        plant.AddJoint(RevoluteJoint("hinge", base.body_frame(), link.body_frame(), [0, 0, 1]))
    else:
        plant.AddJoint(joint_factory(base, link))
    if weld_root:
        plant.WeldFrames(plant.world_frame(), base.body_frame(), RigidTransform())
    if second_free_body:
        plant.AddRigidBody("box", inertia)
    if finalize:
        plant.Finalize()
    return plant


@pytest.mark.parametrize(
    "plant_factory,message",
    [
        (lambda: _plant_with(weld_root=True), "no floating base"),
        (lambda: _plant_with(second_free_body=True), "2 floating bases"),
        (
            lambda: _plant_with(lambda b, l: BallRpyJoint("shoulder", b.body_frame(), l.body_frame())),
            "'shoulder' is a 'ball_rpy' joint",
        ),
        (
            lambda: _plant_with(lambda b, l: PlanarJoint("slide", b.body_frame(), l.body_frame(), [0, 0, 0])),
            "'slide' is a 'planar' joint",
        ),
        (lambda: _plant_with(finalize=False), "finalized"),
    ],
)
@pytest.mark.parametrize("implementation", ["fast", "reference"])
def test_refuses_unsupported_plants(plant_factory, message, implementation):
    with pytest.raises(ValueError, match=message):
        FloatingBaseDynamics(plant_factory(), implementation)


def test_refuses_rpy_floating_base():
    plant = MultibodyPlant(time_step=0.0)
    base = plant.AddRigidBody("base", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.2, 0.3))
    plant.AddJoint(RpyFloatingJoint("rpy_free", plant.world_frame(), base.body_frame()))
    plant.Finalize()
    with pytest.raises(ValueError, match="rpy_free"):
        FloatingBaseDynamics(plant)


def test_refuses_unknown_implementation():
    plant, _ = make_random_floating_tree(2, 0)
    with pytest.raises(ValueError, match="unknown implementation"):
        FloatingBaseDynamics(plant, "magic")


@pytest.mark.parametrize("implementation", ["fast", "reference"])
def test_refuses_bad_states(implementation):
    plant, _ = make_random_floating_tree(4, 3)
    dynamics = FloatingBaseDynamics(plant, implementation)
    q, v = random_state(plant, np.random.default_rng(0))
    bad_q = q.copy()
    bad_q[8] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        dynamics.compute(bad_q, v)
    bad_v = v.copy()
    bad_v[2] = np.inf
    with pytest.raises(ValueError, match="NaN|inf"):
        dynamics.compute(q, bad_v)
    with pytest.raises(ValueError, match="positions|entries"):
        dynamics.compute(q[:-1], v)
    with pytest.raises(ValueError, match="velocities|entries"):
        dynamics.compute(q, v[:-1])
    for factor in (0.0, 1.2):
        bad_quaternion = q.copy()
        bad_quaternion[:4] *= factor
        with pytest.raises(ValueError, match="quaternion"):
            dynamics.compute(bad_quaternion, v)
    # A slightly denormalised quaternion (as from an integrator) is normalised, not refused.
    close = q.copy()
    close[:4] *= 1.0 + 1e-6
    np.testing.assert_allclose(dynamics.compute(close, v).H_fb, dynamics.compute(q, v).H_fb, rtol=1e-12, atol=1e-14)
    frame = dynamics.topology.base_frame
    with pytest.raises(ValueError, match="NaN"):
        dynamics.floating_jacobian(bad_q, frame, np.zeros(3))
