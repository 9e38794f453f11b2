"""Tests of the reference floating-base algorithms (systems/dynamics/floating_base_reference.py).

The reference (paper Algorithms 1-2, eqs. 9, 12, 13) is compared with

* Drake, after the documented change of base coordinates: T = blkdiag(R^T, R^T, I) with R
  the rotation of F0 in the free joint's parent frame (the world for Drake's automatic free
  joint); M_F0 = T M T^T = [[I0c, F], [F^T, H]] and
  [p^; C^] = T (C v - tau_g) + M_F0 [0; w_B x v_B; 0];
* central finite differences (H_dot, F_dot, I0c_dot, H_fb_dot);
* Pinocchio (an independent model, tests/pinocchio_oracle.py): crba, rnea, gravity,
  ccrba/dccrba, computeCoriolisMatrix, aba.

Every comparison reports its relative error (||ours - theirs||_F / ||theirs||_F) when it fails.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FrameIndex, JacobianWrtVariable
from random_trees import make_random_floating_tree, random_state

from systems.common.spatial import skew
from systems.dynamics.floating_base import FloatingBaseDynamics
from systems.dynamics.floating_base_reference import RecursiveFloatingBaseDynamics

TOL_DRAKE = 1e-9
TOL_FD = 1e-6
TOL_PIN = 1e-9

# (num_joints, seed, explicit_free_joint, gravity[, shape])
TREES = [
    (0, 11, False, True),
    (1, 12, True, True),
    (2, 13, False, True),
    (5, 14, True, False),
    (9, 15, False, True),
    (17, 16, True, True),
    (34, 17, False, True),
    (34, 18, True, True),
    (60, 19, True, True),
    (60, 20, False, True),
    (45, 21, True, True, "chain"),
    (30, 22, False, True, "wide"),
]
TREE_IDS = [
    f"n{t[0]}-seed{t[1]}-{'explicit' if t[2] else 'auto'}{'' if t[3] else '-nograv'}{'-' + t[4] if len(t) > 4 else ''}"
    for t in TREES
]


def rel(ours, theirs, scale=None) -> float:
    """||ours - theirs|| / ||theirs|| (or / scale when theirs may vanish)."""
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    if ours.size == 0:
        return 0.0
    den = np.linalg.norm(theirs) if scale is None else scale
    diff = np.linalg.norm(ours - theirs)
    return diff / den if den > 0 else diff


def check(name: str, ours, theirs, tol: float, scale=None) -> float:
    err = rel(ours, theirs, scale)
    assert err <= tol, f"{name}: relative error {err:.3e} > {tol:.0e}"
    return err


def free_joint_of(plant):
    return next(
        plant.get_joint(i) for i in plant.GetJointIndices() if plant.get_joint(i).type_name() == "quaternion_floating"
    )


def drake_in_base_coordinates(plant, ctx, q, v):
    """(M_F0, bias_F0, gravity_F0, R_FwB, v0) from Drake at (q, v) in the F0 convention."""
    plant.SetPositions(ctx, q)
    plant.SetVelocities(ctx, v)
    free = free_joint_of(plant)
    X_FwB = plant.CalcRelativeTransform(ctx, free.frame_on_parent(), free.frame_on_child())
    R = X_FwB.rotation().matrix()
    nv = plant.num_velocities()
    T = np.eye(nv)
    T[:3, :3] = R.T
    T[3:6, 3:6] = R.T
    M_F0 = T @ plant.CalcMassMatrix(ctx) @ T.T
    tau_g = plant.CalcGravityGeneralizedForces(ctx)
    c = plant.CalcBiasTerm(ctx) - tau_g
    v_fb = T @ v
    correction = np.zeros(nv)
    correction[3:6] = np.cross(v_fb[:3], v_fb[3:6])
    return M_F0, T @ c + M_F0 @ correction, -T @ tau_g, R, v_fb[:6]


_CACHE: dict = {}


def tree(spec):
    if spec not in _CACHE:
        n, seed, explicit, gravity = spec[:4]
        shape = spec[4] if len(spec) > 4 else None
        plant, ctx = make_random_floating_tree(n, seed, explicit_free_joint=explicit, gravity=gravity, shape=shape)
        _CACHE[spec] = (plant, ctx, RecursiveFloatingBaseDynamics(plant))
    return _CACHE[spec]


def humanoid(name):
    key = ("humanoid", name)
    if key not in _CACHE:
        import models

        plant = MultibodyPlant(time_step=0.0)
        models.add_humanoid(plant, name)
        plant.Finalize()
        _CACHE[key] = (plant, plant.CreateDefaultContext(), RecursiveFloatingBaseDynamics(plant))
    return _CACHE[key]


def humanoid_names():
    from models import MODEL_NAMES

    return list(MODEL_NAMES)


def all_plants(min_joints: int = 0):
    """Random trees with at least ``min_joints`` joints, and the humanoids."""
    return [pytest.param(("tree", s), id=i) for s, i in zip(TREES, TREE_IDS) if s[0] >= min_joints] + [
        pytest.param(("humanoid", h), id=h) for h in humanoid_names()
    ]


def get(spec):
    kind, arg = spec
    return tree(arg) if kind == "tree" else humanoid(arg)


# ---------------------------------------------------------------------------- Drake
@pytest.mark.parametrize("spec", all_plants())
def test_blocks_match_drake(spec):
    plant, ctx, ref = get(spec)
    rng = np.random.default_rng(1)
    n = ref.num_joints
    for _ in range(3):
        q, v = random_state(plant, rng)
        terms = ref.compute(q, v)
        M_F0, bias, grav, R_FwB, v0 = drake_in_base_coordinates(plant, ctx, q, v)
        free = free_joint_of(plant)
        R_WFw = free.frame_on_parent().CalcPoseInWorld(ctx).rotation().matrix()
        check("R_WB vs Drake", terms.R_WB, R_WFw @ R_FwB, TOL_DRAKE)
        check("v0 vs Drake", terms.v0, v0, TOL_DRAKE, scale=max(np.linalg.norm(v0), 1.0))
        check("I0c vs Drake M", terms.I0c, M_F0[:6, :6], TOL_DRAKE)
        if n:
            check("H vs Drake M", terms.H, M_F0[6:, 6:], TOL_DRAKE)
            check("F vs Drake M", terms.F, M_F0[:6, 6:], TOL_DRAKE)
            check("C_hat vs Drake bias", terms.C_hat, bias[6:], TOL_DRAKE, scale=np.linalg.norm(bias))
        check("p_hat vs Drake bias", terms.p_hat, bias[:6], TOL_DRAKE)
        # Gravity alone: the bias at zero velocity.
        still = ref.compute(q, np.zeros_like(v))
        if np.linalg.norm(grav) > 0:
            check("gravity vs Drake", np.concatenate((still.p_hat, still.C_hat)), grav, TOL_DRAKE)
        else:
            assert np.linalg.norm(np.concatenate((still.p_hat, still.C_hat))) == 0.0
        # H_fb, C_fb from Drake's own matrices (coordinate invariant).
        if n:
            Mw = plant.CalcMassMatrix(ctx)
            H_fb = Mw[6:, 6:] - Mw[6:, :6] @ np.linalg.solve(Mw[:6, :6], Mw[:6, 6:])
            check("H_fb vs Drake", terms.H_fb, H_fb, TOL_DRAKE)
            C_fb = bias[6:] - M_F0[6:, :6] @ np.linalg.solve(M_F0[:6, :6], bias[:6])
            check("C_fb vs Drake", terms.C_fb, C_fb, TOL_DRAKE, scale=np.linalg.norm(bias))


@pytest.mark.parametrize("spec", all_plants())
def test_spatial_momentum_matches_drake(spec):
    plant, ctx, ref = get(spec)
    rng = np.random.default_rng(2)
    free = free_joint_of(plant)
    for _ in range(2):
        q, v = random_state(plant, rng)
        terms = ref.compute(q, v)
        plant.SetPositions(ctx, q)
        plant.SetVelocities(ctx, v)
        p_WB = free.frame_on_child().CalcPoseInWorld(ctx).translation()
        L = plant.CalcSpatialMomentumInWorldAboutPoint(ctx, p_WB)
        drake = np.concatenate((terms.R_WB.T @ L.rotational(), terms.R_WB.T @ L.translational()))
        ours = terms.I0c @ terms.v0 + terms.F @ v[6:]
        check("momentum vs Drake", ours, drake, TOL_DRAKE)


def test_forward_dynamics_matches_drake():
    """Eq. (9) without contacts, solved for (a0, qdd), equals Drake's acceleration converted
    to the base-frame convention a0 = T vdot - [0; w_B x v_B]."""
    plant, ctx, ref = tree(TREES[6])
    rng = np.random.default_rng(3)
    q, v = random_state(plant, rng)
    tau = rng.normal(size=ref.num_joints)
    terms = ref.compute(q, v)
    M_F0 = np.block([[terms.I0c, terms.F], [terms.F.T, terms.H]])
    ours = np.linalg.solve(M_F0, np.concatenate((-terms.p_hat, tau - terms.C_hat)))
    plant.SetPositions(ctx, q)
    plant.SetVelocities(ctx, v)
    rhs = plant.CalcGravityGeneralizedForces(ctx) - plant.CalcBiasTerm(ctx)
    rhs[6:] += tau
    vdot = np.linalg.solve(plant.CalcMassMatrix(ctx), rhs)
    R = terms.R_WB
    drake = vdot.copy()
    drake[:3] = R.T @ vdot[:3]
    drake[3:6] = R.T @ vdot[3:6] - np.cross(terms.v0[:3], terms.v0[3:])
    check("forward dynamics vs Drake", ours, drake, TOL_DRAKE)
    # And the floating joint dynamics (second row of eq. 9) alone.
    qdd = np.linalg.solve(terms.H_fb, tau - terms.C_fb)
    check("H_fb qdd = tau - C_fb vs Drake", qdd, vdot[6:], TOL_DRAKE)


# ---------------------------------------------------------------------------- derivatives
def _shift_joints(q, qdot, h):
    out = q.copy()
    out[7:] += h * qdot
    return out


@pytest.mark.parametrize("spec", all_plants(min_joints=1))
def test_time_derivatives_match_finite_differences(spec):
    plant, ctx, ref = get(spec)
    rng = np.random.default_rng(4)
    h = 1e-5
    for _ in range(2):
        q, v = random_state(plant, rng)
        qdot = v[6:]
        terms = ref.compute(q, v)
        plus = ref.compute(_shift_joints(q, qdot, h), v)
        minus = ref.compute(_shift_joints(q, qdot, -h), v)
        for name in ("H", "F", "I0c", "H_fb"):
            fd = (getattr(plus, name) - getattr(minus, name)) / (2 * h)
            check(f"{name}_dot vs finite differences", getattr(terms, f"{name}_dot"), fd, TOL_FD)


def test_full_state_finite_differences_including_base_motion():
    """Integrating the whole state (quaternion via MapVelocityToQDot) gives the same
    derivatives: F0-expressed H, F, I0c do not depend on the base pose."""
    plant, ctx, ref = tree(TREES[5])
    rng = np.random.default_rng(5)
    q, v = random_state(plant, rng)
    terms = ref.compute(q, v)
    plant.SetPositions(ctx, q)
    qd = plant.MapVelocityToQDot(ctx, v)
    h = 1e-5
    qp, qm = q + h * qd, q - h * qd
    qp[:4] /= np.linalg.norm(qp[:4])
    qm[:4] /= np.linalg.norm(qm[:4])
    plus, minus = ref.compute(qp, v), ref.compute(qm, v)
    for name in ("H", "F", "I0c", "H_fb"):
        fd = (getattr(plus, name) - getattr(minus, name)) / (2 * h)
        check(f"{name}_dot vs full-state finite differences", getattr(terms, f"{name}_dot"), fd, TOL_FD)
    # Independence of the base pose.
    q2, _ = random_state(plant, rng)
    q2[7:] = q[7:]
    other = ref.compute(q2, v)
    for name in ("H", "F", "I0c", "H_dot", "F_dot", "I0c_dot"):
        check(f"{name} independent of base pose", getattr(other, name), getattr(terms, name), 1e-12)


# ---------------------------------------------------------------------------- Pinocchio
def _oracle(spec):
    from pinocchio_oracle import build_pinocchio_oracle

    key = ("oracle", spec)
    if key not in _CACHE:
        plant, _, _ = get(spec)
        _CACHE[key] = build_pinocchio_oracle(plant)
    return _CACHE[key]


def _centroidal_from_ours(terms):
    """(Ag, dAg/dt) from I0c, F and their derivatives: momentum about the CoM in world axes,
    rows [angular; linear]. With c = p_{F0,CoM} in F0 (from I0c's m c x block) and
    X* = [[R, -R c x], [0, R]]: Ag = X* [I0c F], dAg = Xdot* [I0c F] + X* [I0c_dot F_dot],
    Rdot = R w_B x."""
    m = terms.I0c[3, 3]

    def vee(S):
        return np.array([S[2, 1], S[0, 2], S[1, 0]])

    c = vee(terms.I0c[:3, 3:]) / m
    c_dot = vee(terms.I0c_dot[:3, 3:]) / m
    R, W = terms.R_WB, skew(terms.v0[:3])
    X = np.zeros((6, 6))
    X[:3, :3] = X[3:, 3:] = R
    X[:3, 3:] = -R @ skew(c)
    Xd = np.zeros((6, 6))
    Xd[:3, :3] = Xd[3:, 3:] = R @ W
    Xd[:3, 3:] = -R @ W @ skew(c) - R @ skew(c_dot)
    IF = np.hstack((terms.I0c, terms.F))
    IF_dot = np.hstack((terms.I0c_dot, terms.F_dot))
    return X @ IF, Xd @ IF + X @ IF_dot


@pytest.mark.parametrize("spec", all_plants())
@pytest.mark.parametrize("implementation", ["reference", "fast"])
def test_matches_pinocchio(spec, implementation):
    plant, ctx, ref = get(spec)
    if implementation == "fast":
        ref = FloatingBaseDynamics(plant, "fast")
    oracle = _oracle(spec)
    rng = np.random.default_rng(6)
    for _ in range(2):
        q, v = random_state(plant, rng)
        terms = ref.compute(q, v)
        still = ref.compute(q, np.zeros_like(v))
        qp, vp = oracle.to_pinocchio(q, v)
        M_ours = np.block([[terms.I0c, terms.F], [terms.F.T, terms.H]])
        check("mass matrix vs pin.crba", M_ours, oracle.mass_matrix(qp), TOL_PIN)
        bias_ours = np.concatenate((terms.p_hat, terms.C_hat))
        check("bias vs pin.rnea(q, v, 0)", bias_ours, oracle.bias(qp, vp), TOL_PIN)
        g_pin = oracle.gravity(qp)
        g_ours = np.concatenate((still.p_hat, still.C_hat))
        if np.linalg.norm(g_pin) > 0:
            check("gravity vs pin.computeGeneralizedGravity", g_ours, g_pin, TOL_PIN)
        M_dot = np.block([[terms.I0c_dot, terms.F_dot], [terms.F_dot.T, terms.H_dot]])
        scale = np.linalg.norm(M_ours) * max(np.linalg.norm(v), 1.0)
        check("dM/dt vs pin C + C^T", M_dot, oracle.mass_matrix_derivative(qp, vp), TOL_PIN, scale=scale)
        Ag, dAg = oracle.centroidal(qp, vp)
        Ag_ours, dAg_ours = _centroidal_from_ours(terms)
        check("Ag vs pin.ccrba", Ag_ours, Ag, TOL_PIN)
        check("dAg vs pin.dccrba", dAg_ours, dAg, TOL_PIN, scale=np.linalg.norm(Ag) * max(np.linalg.norm(v), 1.0))


def test_pinocchio_free_flyer_acceleration_is_base_frame_derivative():
    """Pinocchio's free-flyer acceleration (pin.aba) equals our a0 = d/dt [w_B; v_B], i.e.
    Drake's world-aligned vdot converted as T vdot - [0; w_B x v_B; 0]; it does NOT equal
    the plain rotation T vdot (the 'classical' acceleration of the base origin)."""
    spec = ("tree", TREES[6])
    plant, ctx, ref = get(spec)
    oracle = _oracle(spec)
    rng = np.random.default_rng(7)
    q, v = random_state(plant, rng)
    tau = rng.normal(size=ref.num_joints)
    qp, vp = oracle.to_pinocchio(q, v)
    a_pin = oracle.forward_dynamics(qp, vp, np.concatenate((np.zeros(6), tau)))
    plant.SetPositions(ctx, q)
    plant.SetVelocities(ctx, v)
    rhs = plant.CalcGravityGeneralizedForces(ctx) - plant.CalcBiasTerm(ctx)
    rhs[6:] += tau
    vdot = np.linalg.solve(plant.CalcMassMatrix(ctx), rhs)
    terms = ref.compute(q, v)
    R = terms.R_WB
    rotated = vdot.copy()
    rotated[:3] = R.T @ vdot[:3]
    rotated[3:6] = R.T @ vdot[3:6]
    base_frame = rotated.copy()
    base_frame[3:6] -= np.cross(terms.v0[:3], terms.v0[3:])
    check("pin.aba vs Drake vdot (base-frame convention)", a_pin, base_frame, TOL_PIN)
    assert rel(a_pin, rotated) > 1e-6, "the w x v term should matter for a random state"


# ---------------------------------------------------------------------------- Jacobian
def _frames_on_tree(plant, ref):
    world = plant.world_body().index()
    frames = []
    for i in range(plant.num_frames()):
        frame = plant.get_frame(FrameIndex(i))
        if frame.body().index() != world:
            frames.append(frame)
    return frames


@pytest.mark.parametrize("spec", all_plants(min_joints=1))
def test_floating_jacobian_matches_drake(spec):
    plant, ctx, ref = get(spec)
    rng = np.random.default_rng(8)
    frames = _frames_on_tree(plant, ref)
    world = plant.world_frame()
    picks = list(rng.choice(len(frames), size=min(8, len(frames)), replace=False))
    # Make sure frames of welded bodies are exercised when there are any.
    child_of_weld = {
        plant.get_joint(i).child_body().index()
        for i in plant.GetJointIndices()
        if plant.get_joint(i).type_name() == "weld"
    }
    picks += [k for k, f in enumerate(frames) if f.body().index() in child_of_weld][:3]
    q, v = random_state(plant, rng)
    plant.SetPositions(ctx, q)
    M = plant.CalcMassMatrix(ctx)
    for k in picks:
        frame = frames[k]
        p = rng.uniform(-0.2, 0.2, size=3)
        Jv = plant.CalcJacobianTranslationalVelocity(ctx, JacobianWrtVariable.kV, frame, p, world, world)
        J_fb = Jv[:, 6:] - Jv[:, :6] @ np.linalg.solve(M[:6, :6], M[:6, 6:])
        ours = ref.floating_jacobian(q, frame, p)
        check("J_fb (3-D) vs Drake", ours, J_fb, TOL_DRAKE)
        Js = plant.CalcJacobianSpatialVelocity(ctx, JacobianWrtVariable.kV, frame, p, world, world)
        Js_fb = Js[:, 6:] - Js[:, :6] @ np.linalg.solve(M[:6, :6], M[:6, 6:])
        check("J_fb (6-D) vs Drake", ref.floating_jacobian(q, frame, p, spatial=True), Js_fb, TOL_DRAKE)


def test_floating_jacobian_physics():
    """A force f at P changes the joint accelerations by H_fb^-1 J_fb^T f (eq. 9, 2nd row):
    compare with Drake's full forward dynamics M^-1 J^T f."""
    plant, ctx, ref = tree(TREES[7])
    rng = np.random.default_rng(9)
    q, v = random_state(plant, rng)
    plant.SetPositions(ctx, q)
    frames = _frames_on_tree(plant, ref)
    frame = frames[int(rng.integers(len(frames)))]
    p = rng.uniform(-0.2, 0.2, size=3)
    f = rng.normal(size=3) * 10.0
    Jv = plant.CalcJacobianTranslationalVelocity(
        ctx, JacobianWrtVariable.kV, frame, p, plant.world_frame(), plant.world_frame()
    )
    dvdot = np.linalg.solve(plant.CalcMassMatrix(ctx), Jv.T @ f)
    terms = ref.compute(q, v)
    tau_c = ref.floating_jacobian(q, frame, p).T @ f
    check("H_fb dqdd = J_fb^T f vs Drake", terms.H_fb @ dvdot[6:], tau_c, TOL_DRAKE)


# ---------------------------------------------------------------------------- validation
def test_rejects_plants_without_floating_base():
    plant = MultibodyPlant(time_step=0.0)
    from pydrake.multibody.tree import SpatialInertia

    body = plant.AddRigidBody("b", SpatialInertia.SolidSphereWithMass(1.0, 0.1))
    plant.WeldFrames(plant.world_frame(), body.body_frame())
    plant.Finalize()
    with pytest.raises(ValueError, match="no floating base"):
        RecursiveFloatingBaseDynamics(plant)


def test_rejects_gravity_disabled_instance():
    from pydrake.multibody.tree import SpatialInertia

    plant = MultibodyPlant(time_step=0.0)
    instance = plant.AddModelInstance("robot")
    plant.AddRigidBody("b", instance, SpatialInertia.SolidSphereWithMass(1.0, 0.1))
    plant.set_gravity_enabled(instance, False)
    plant.Finalize()
    with pytest.raises(ValueError, match="gravity is disabled"):
        RecursiveFloatingBaseDynamics(plant)


# ---------------------------------------------------------------------------- spatial algebra
def test_spatial_algebra_matches_drake():
    """plucker / force_transform / transform_inertia against Drake's own spatial types."""
    from pydrake.multibody.math import SpatialForce, SpatialVelocity
    from random_trees import random_spatial_inertia, random_transform

    from systems.common.spatial import (
        crf,
        crm,
        force_transform,
        inverse_motion_transform,
        plucker,
        spatial_inertia,
        transform_inertia,
    )

    rng = np.random.default_rng(12)
    for _ in range(5):
        X_AB = random_transform(rng, 1.0)  # pose of B in A
        R_AB, p_AB = X_AB.rotation().matrix(), X_AB.translation()
        X = plucker(R_AB.T, p_AB)  # ^B X_A
        # A motion vector at A's origin, in A -> same motion at B's origin, in B.
        V_A = SpatialVelocity(rng.normal(size=3), rng.normal(size=3))
        V_B = V_A.Shift(p_AB)  # shift to B's origin, still in A's axes
        expected = np.concatenate((R_AB.T @ V_B.rotational(), R_AB.T @ V_B.translational()))
        check("plucker vs Drake shift", X @ V_A.get_coeffs(), expected, 1e-13)
        F_A = SpatialForce(rng.normal(size=3), rng.normal(size=3))
        F_B = F_A.Shift(p_AB)
        expected = np.concatenate((R_AB.T @ F_B.rotational(), R_AB.T @ F_B.translational()))
        check("force transform vs Drake shift", force_transform(X) @ F_A.get_coeffs(), expected, 1e-13)
        check("force transform = X^-T", force_transform(X), np.linalg.inv(X).T, 1e-13)
        check("inverse motion transform", inverse_motion_transform(X) @ X, np.eye(6), 1e-13)
        v, m = rng.normal(size=6), rng.normal(size=6)
        check("crf = -crm^T", crf(v), -crm(v).T, 0.0)
        check("crm(v) v = 0", crm(v) @ v, np.zeros(6), 1e-15, scale=1.0)
        check("crm(v) m = -crm(m) v", crm(v) @ m, -crm(m) @ v, 1e-15)
        M_BBo_B = random_spatial_inertia(rng)
        mass, com = M_BBo_B.get_mass(), np.array(M_BBo_B.get_com())
        I_com = M_BBo_B.Shift(com).CalcRotationalInertia().CopyToFullMatrix3()
        I_B = spatial_inertia(mass, com, I_com)
        check("spatial_inertia vs Drake", I_B, M_BBo_B.CopyToFullMatrix6(), 1e-13)
        # Inertia of B re-expressed about A's origin in A: ^A I = transform_inertia(^A X_B, ^B I).
        X_BA = X_AB.inverse()
        M_BAo_A = M_BBo_B.ReExpress(X_AB.rotation()).Shift(-X_AB.translation())
        ours = transform_inertia(plucker(X_BA.rotation().matrix().T, X_BA.translation()), I_B)
        check("transform_inertia vs Drake", ours, M_BAo_A.CopyToFullMatrix6(), 1e-13)
