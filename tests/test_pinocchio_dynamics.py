"""PinocchioFloatingBaseDynamics (Pinocchio's kernels on a model built from the Drake plant)
gives the floating-base terms of eq. (9) and (13) that the "fast" (Drake) and "reference"
(the paper's recursive algorithms) implementations give.

Tolerances (relative, Frobenius): against the reference, every term to 1e-10 (both exact;
about 1e-14 is reached); against "fast", M and the bias to 1e-10 (about 1e-15 reached) and the
derivatives H_dot, F_dot, I0c_dot, H_fb_dot to 1e-8 ("fast" takes a central difference of the
mass matrix, relative error about 1e-10). Controls: without the reflected rotor inertia or
with a wrong coordinate permutation the same comparison fails by orders of magnitude."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from random_trees import make_random_floating_tree, random_spatial_inertia, random_state

from models import MODELS_DIR, add_humanoid
from systems.dynamics.base_state import quaternion_to_rotation
from systems.dynamics.floating_base import FloatingBaseDynamics
from systems.dynamics.pinocchio_dynamics import PinocchioFloatingBaseDynamics
from systems.dynamics.pinocchio_model import pinocchio_model_from_plant
from systems.residuals.momentum_residuals import ClassicalResidual, ExternalResidual, InternalResidual, ResidualModel

ROBOTS = {"hrp4_like": "hrp4_like", "talos": str(MODELS_DIR / "robots" / "talos.yaml")}
EXACT = ("H", "F", "I0c", "C_hat", "p_hat", "H_fb", "C_fb", "R_WB", "v0", "I0c_inv_F")
DERIVATIVES = ("H_dot", "F_dot", "I0c_dot", "H_fb_dot")
#: (num_joints, seed, explicit free joint: a world-offset parent frame) of the random trees.
RANDOM_TREES = [(1, 0, False), (9, 3, True), (23, 9, True), (45, 6, False)]

_PLANTS: dict = {}


def relative_error(actual: np.ndarray, expected: np.ndarray) -> float:
    scale = np.linalg.norm(expected)
    return float(np.linalg.norm(actual - expected) / (scale if scale > 0 else 1.0))


def robot(name: str) -> MultibodyPlant:
    if name not in _PLANTS:
        plant = MultibodyPlant(time_step=0.0)
        add_humanoid(plant, ROBOTS[name])
        plant.Finalize()
        _PLANTS[name] = plant
    return _PLANTS[name]


def errors(actual, expected, fields=EXACT + DERIVATIVES) -> dict[str, float]:
    return {f: relative_error(getattr(actual, f), getattr(expected, f)) for f in fields}


def assert_agree(pinocchio, other, derivative_tolerance: float) -> None:
    """Every exact term to 1e-10; each derivative block to ``derivative_tolerance`` relative
    to its own norm or, if larger, that of the whole M_dot (a block can be zero: H_dot of a
    single joint)."""
    exact = errors(pinocchio, other, EXACT)
    scale = sum(np.linalg.norm(getattr(other, f)) for f in ("H_dot", "F_dot", "I0c_dot"))
    derivatives = {
        f: np.linalg.norm(getattr(pinocchio, f) - getattr(other, f))
        / (max(np.linalg.norm(getattr(other, f)), scale) or 1.0)
        for f in DERIVATIVES
    }
    assert max(exact.values()) < 1e-10, exact
    assert max(derivatives.values()) < derivative_tolerance, derivatives


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_humanoids_agree_with_fast_and_reference(name):
    plant = robot(name)
    pinocchio = PinocchioFloatingBaseDynamics(plant)
    fast, reference = FloatingBaseDynamics(plant, "fast"), FloatingBaseDynamics(plant, "reference")
    rng = np.random.default_rng(11)
    for _ in range(3):  # random orientation, moving base, random joints
        q, v = random_state(plant, rng)
        terms = pinocchio.compute(q, v)
        assert_agree(terms, fast.compute(q, v), 1e-8)
        assert_agree(terms, reference.compute(q, v), 1e-10)


@pytest.mark.parametrize("num_joints,seed,explicit_free_joint", RANDOM_TREES)
def test_random_trees_agree_with_fast_and_reference(num_joints, seed, explicit_free_joint):
    plant, _ = make_random_floating_tree(num_joints, seed, explicit_free_joint=explicit_free_joint)
    pinocchio = PinocchioFloatingBaseDynamics(plant)
    fast, reference = FloatingBaseDynamics(plant, "fast"), FloatingBaseDynamics(plant, "reference")
    rng = np.random.default_rng(200 + seed)
    for _ in range(3):
        q, v = random_state(plant, rng)
        terms = pinocchio.compute(q, v)
        assert_agree(terms, fast.compute(q, v), 1e-8)
        assert_agree(terms, reference.compute(q, v), 1e-10)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_a_pinocchio_joint_order_that_differs_from_the_plants(name):
    """Sibling subtrees added in reverse: Pinocchio's joints are not in v[6:] order, so
    ``compute`` gathers whole matrices through the permutation."""
    plant = robot(name)
    pinocchio = PinocchioFloatingBaseDynamics(plant, pinocchio_model_from_plant(plant, reverse_siblings=True))
    assert pinocchio._joint_flat is not None
    assert not np.array_equal(pinocchio.permutation[6:], np.arange(6, plant.num_velocities()))
    fast, reference = FloatingBaseDynamics(plant, "fast"), FloatingBaseDynamics(plant, "reference")
    rng = np.random.default_rng(29)
    for _ in range(2):
        q, v = random_state(plant, rng)
        terms = pinocchio.compute(q, v)
        assert_agree(terms, fast.compute(q, v), 1e-8)
        assert_agree(terms, reference.compute(q, v), 1e-10)
        M, M_dot, bias, _, _ = pinocchio.mass_matrix_terms(q, v)
        assert relative_error(M[6:, 6:], terms.H) < 1e-14 and relative_error(M_dot[:6, 6:], terms.F_dot) < 1e-14
        assert relative_error(bias[6:], terms.C_hat) < 1e-14
        g = pinocchio.gravity_generalized_forces(q)
        assert relative_error(g, fast.gravity_generalized_forces(q)) < 1e-10
        frame = pinocchio.topology.joints[-1].child_body().body_frame()
        assert relative_error(pinocchio.spatial_jacobian_F0(frame), _jacobian_F0(plant, q, frame)) < 1e-12
        p = 0.1 * rng.normal(size=3)
        expected = fast.floating_jacobian(q, frame, p, spatial=True)
        assert relative_error(pinocchio.floating_jacobian(q, frame, p, spatial=True), expected) < 1e-10


def test_zero_joint_velocity_gives_exact_derivatives_of_the_reference():
    plant = robot("hrp4_like")
    pinocchio, reference = PinocchioFloatingBaseDynamics(plant), FloatingBaseDynamics(plant, "reference")
    q, v = random_state(plant, np.random.default_rng(3))
    v[6:] = 0.0
    terms = pinocchio.compute(q, v)
    for f in DERIVATIVES:
        assert np.abs(getattr(terms, f)).max() < 1e-12, f
    assert_agree(terms, reference.compute(q, v), 1e-10)


def test_controls_without_armature_or_with_a_wrong_permutation_disagree():
    """The comparison sees a dropped reflected rotor inertia (TALOS: 0.1 kg m^2 per joint), a
    base with linear and angular velocities swapped, and two joints swapped."""
    plant = robot("talos")
    q, v = random_state(plant, np.random.default_rng(5))
    expected = FloatingBaseDynamics(plant, "fast").compute(q, v)

    no_armature = PinocchioFloatingBaseDynamics(plant)
    assert np.abs(no_armature.model.armature[6:]).min() > 0.0
    no_armature.model.armature = np.zeros(no_armature.model.nv)
    e = errors(no_armature.compute(q, v), expected)
    assert e["H"] > 1e-4 and e["H_fb"] > 1e-4, e

    swapped_base = PinocchioFloatingBaseDynamics(plant)
    P = swapped_base.permutation.copy()
    P[:3], P[3:6] = swapped_base.permutation[3:6], swapped_base.permutation[:3]
    swapped_base._use_permutation(P)
    e = errors(swapped_base.compute(q, v), expected)
    assert e["I0c"] > 1e-2 and e["p_hat"] > 1e-2, e

    swapped_joints = PinocchioFloatingBaseDynamics(plant)
    P = swapped_joints.permutation.copy()
    P[[6, 7]] = P[[7, 6]]
    swapped_joints._use_permutation(P)
    e = errors(swapped_joints.compute(q, v), expected)
    assert e["H"] > 1e-4 and e["C_hat"] > 1e-4 and e["H_dot"] > 1e-4, e


def test_spatial_inertia_overrides_match_the_fast_implementation():
    plant = robot("hrp4_like")
    pinocchio, fast = PinocchioFloatingBaseDynamics(plant), FloatingBaseDynamics(plant, "fast")
    rng = np.random.default_rng(9)
    q, v = random_state(plant, rng)
    before = pinocchio.compute(q, v)
    bodies = [fast.topology.base_body] + [j.child_body() for j in fast.topology.joints[::7]]
    inertias = {int(body.index()): random_spatial_inertia(rng) for body in bodies}
    pinocchio.set_spatial_inertias(inertias)
    fast.set_spatial_inertias(inertias)
    terms = pinocchio.compute(q, v)
    assert relative_error(terms.H, before.H) > 1e-3  # the override changed the model
    assert_agree(terms, fast.compute(q, v), 1e-8)
    assert relative_error(pinocchio.gravity_generalized_forces(q), fast.gravity_generalized_forces(q)) < 1e-10
    with pytest.raises(ValueError, match="not on the floating tree"):
        pinocchio.set_spatial_inertias({int(plant.world_body().index()): random_spatial_inertia(rng)})


def test_spatial_inertia_overrides_of_welded_bodies_on_a_random_tree():
    plant, _ = make_random_floating_tree(23, 9, explicit_free_joint=True, weld_fraction=0.3)
    pinocchio, fast = PinocchioFloatingBaseDynamics(plant), FloatingBaseDynamics(plant, "fast")
    assert any(j.type_name() == "weld" for j in (plant.get_joint(i) for i in plant.GetJointIndices()))
    rng = np.random.default_rng(31)
    bodies = list(pinocchio.pinocchio.bodies)
    inertias = {b: random_spatial_inertia(rng) for b in bodies}  # every body, welded ones included
    pinocchio.set_spatial_inertias(inertias)
    fast.set_spatial_inertias(inertias)
    q, v = random_state(plant, rng)
    assert_agree(pinocchio.compute(q, v), fast.compute(q, v), 1e-8)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_gravity_and_floating_jacobian_match_drake(name):
    plant = robot(name)
    pinocchio, fast = PinocchioFloatingBaseDynamics(plant), FloatingBaseDynamics(plant, "fast")
    rng = np.random.default_rng(13)
    frame = fast.topology.joints[-1].child_body().body_frame()
    for _ in range(2):
        q, _ = random_state(plant, rng)
        assert relative_error(pinocchio.gravity_generalized_forces(q), fast.gravity_generalized_forces(q)) < 1e-10
        p = 0.1 * rng.normal(size=3)
        for spatial in (False, True):
            expected = fast.floating_jacobian(q, frame, p, spatial=spatial)
            assert relative_error(pinocchio.floating_jacobian(q, frame, p, spatial=spatial), expected) < 1e-10


def _jacobian_F0(plant, q, frame) -> np.ndarray:
    """Drake's spatial-velocity Jacobian of ``frame``'s origin at the true pose, converted to
    rows [angular; linear] in F0 and columns [v0; qdot] (v0 = [w; v] in F0)."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    world = plant.world_frame()
    J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world)
    free = FloatingBaseDynamics(plant).topology.free_joint
    R_WP = free.frame_on_parent().CalcPoseInWorld(context).rotation().matrix()
    R_PB = quaternion_to_rotation(q[:4])
    R_WB = R_WP @ R_PB
    J = np.vstack((R_WB.T @ J[:3], R_WB.T @ J[3:]))
    J[:, :3] = J[:, :3] @ R_PB  # Drake's base velocities are in the parent frame P
    J[:, 3:6] = J[:, 3:6] @ R_PB
    return J


@pytest.mark.parametrize("source", ["hrp4_like", "tree"])
def test_mass_matrix_terms_of_samples_match_one_at_a_time_and_drake(source):
    if source == "tree":
        plant, _ = make_random_floating_tree(12, 4, explicit_free_joint=True)
    else:
        plant = robot(source)
    pinocchio, fast = PinocchioFloatingBaseDynamics(plant), FloatingBaseDynamics(plant, "fast")
    frames = [fast.topology.joints[-1].child_body().body_frame(), fast.topology.joints[0].child_body().body_frame()]
    rng = np.random.default_rng(17)
    samples = [random_state(plant, rng) for _ in range(3)]
    Q, V = np.array([s[0] for s in samples]), np.array([s[1] for s in samples])
    M, M_dot, bias, R_WB, v0, J = pinocchio.mass_matrix_terms_of_samples(Q, V, frames)
    for k, (q, v) in enumerate(samples):
        one = pinocchio.mass_matrix_terms(q, v)
        for stacked, single in zip((M, M_dot, bias, R_WB, v0), one):
            assert relative_error(stacked[k], single) < 1e-14
        for f, frame in enumerate(frames):
            assert relative_error(J[k, f], _jacobian_F0(plant, q, frame)) < 1e-12
    # The "fast" implementation too, also with the tree's free joint on a rotated, offset
    # parent frame (its Jacobians' rows turned from the world to F0 axes).
    expected = fast.mass_matrix_terms_of_samples(Q, V, frames)
    for name, a, b in zip(("M", "M_dot", "bias", "R_WB", "v0", "J"), (M, M_dot, bias, R_WB, v0, J), expected):
        assert relative_error(a, b) < (1e-8 if name == "M_dot" else 1e-10), name


def _bank(plant, frames, model):
    return [
        ClassicalResidual(plant, 35.0, known_wrench_frames=frames, model=model),
        InternalResidual(plant, 20.0, known_wrench_frames=frames, model=model),
        ExternalResidual(plant, 50.0, known_wrench_frames=frames, model=model),
    ]


def pinocchio_residual_model(plant) -> ResidualModel:
    """A ResidualModel on the Pinocchio dynamics."""
    return ResidualModel(plant, "pinocchio")


def test_the_residual_bank_on_pinocchio_dynamics_matches_the_fast_bank():
    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    frames = tuple(handles.ft_sensor_frames.values())
    banks = [_bank(plant, frames, ResidualModel(plant, "fast")), _bank(plant, frames, pinocchio_residual_model(plant))]
    contexts = [[system.CreateDefaultContext() for system in bank] for bank in banks]
    rng = np.random.default_rng(23)
    outputs = [[], []]
    for _ in range(6):
        q, v = random_state(plant, rng)
        x, tau, wrenches = (
            np.concatenate((q, v)),
            20.0 * rng.normal(size=plant.num_velocities() - 6),
            rng.normal(size=12),
        )
        for b, (bank, bank_contexts) in enumerate(zip(banks, contexts)):
            for system, context in zip(bank, bank_contexts):
                system.GetInputPort("state").FixValue(context, x)
                system.GetInputPort("known_wrenches").FixValue(context, wrenches)
                if system.HasInputPort("measured_torque"):
                    system.GetInputPort("measured_torque").FixValue(context, tau)
                context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
            outputs[b].append(
                np.concatenate(
                    [bank[0].GetOutputPort("residual").Eval(bank_contexts[0])]
                    + [bank[1].GetOutputPort("residual").Eval(bank_contexts[1])]
                    + [
                        bank[2].GetOutputPort(p).Eval(bank_contexts[2])
                        for p in ("external_wrench_base", "external_wrench_world")
                    ]
                )
            )
    ours, theirs = np.array(outputs[1]), np.array(outputs[0])
    assert np.abs(ours).max() > 1.0
    assert np.abs(ours - theirs).max() < 1e-8 * np.abs(theirs).max()


def test_refuses_bad_states_and_plants():
    plant = robot("hrp4_like")
    pinocchio = PinocchioFloatingBaseDynamics(plant)
    q, v = random_state(plant, np.random.default_rng(1))
    with pytest.raises(ValueError, match="unit quaternion"):
        pinocchio.compute(np.concatenate(([2.0], q[1:])), v)
    with pytest.raises(ValueError, match="entries"):
        pinocchio.compute(q, v[:-1])
    unfinished = MultibodyPlant(time_step=0.0)
    with pytest.raises(ValueError, match="finalized"):
        PinocchioFloatingBaseDynamics(unfinished)
    with pytest.raises(ValueError, match="compute"):
        pinocchio.spatial_jacobian_F0(pinocchio.topology.base_frame)
    with pytest.raises(ValueError, match="floating tree"):
        pinocchio.floating_jacobian(q, plant.world_frame(), np.zeros(3))


@pytest.mark.parametrize("source", ["hrp4_like", "tree"])
def test_spatial_jacobian_F0_is_drakes_in_F0_coordinates(source):
    if source == "tree":
        plant, _ = make_random_floating_tree(12, 4, explicit_free_joint=True)
    else:
        plant = robot(source)
    pinocchio = PinocchioFloatingBaseDynamics(plant)
    topology = pinocchio.topology
    frames = [topology.joints[-1].child_body().body_frame(), topology.joints[3].child_body().body_frame()]
    rng = np.random.default_rng(19)
    for _ in range(2):
        q, v = random_state(plant, rng)
        pinocchio.compute(q, v)
        for frame in frames:
            assert relative_error(pinocchio.spatial_jacobian_F0(frame), _jacobian_F0(plant, q, frame)) < 1e-12
    if source == "hrp4_like":  # what ResidualModel computes with the "fast" implementation's context
        model = ResidualModel(plant, "fast")
        model.evaluate(np.concatenate((q, v)))
        for frame in frames:
            assert relative_error(pinocchio.spatial_jacobian_F0(frame), model.spatial_jacobian_F0(frame)) < 1e-12


def test_the_residual_model_jacobians_are_in_F0_with_a_rotated_free_joint_parent():
    """A free joint whose parent frame is rotated and offset from the world: the residual
    model's F0 Jacobians (the known wrenches' generalized forces, eq. 10) are Drake's
    Jacobian at the true pose turned to F0 rows and columns, for the "fast" and
    "pinocchio" dynamics alike; the known wrench's generalized force agrees between them."""
    plant, _ = make_random_floating_tree(12, 4, explicit_free_joint=True)
    topology = FloatingBaseDynamics(plant).topology
    R_WP = topology.free_joint.frame_on_parent().CalcPoseInWorld(plant.CreateDefaultContext()).rotation().matrix()
    assert np.abs(R_WP - np.eye(3)).max() > 0.1  # the case under test
    frames = [topology.joints[-1].child_body().body_frame(), topology.joints[0].child_body().body_frame()]
    rng = np.random.default_rng(23)
    wrench = rng.normal(size=6 * len(frames))
    q, v = random_state(plant, rng)
    forces = []
    for implementation in ("fast", "pinocchio"):
        model = ResidualModel(plant, implementation)
        terms = model.evaluate(np.concatenate((q, v)))
        for frame in frames:
            assert relative_error(model.spatial_jacobian_F0(frame), _jacobian_F0(plant, q, frame)) < 1e-12
        forces.append(np.concatenate(model.known_wrench_forces(terms, tuple(frames), wrench)))
    assert relative_error(forces[0], forces[1]) < 1e-12


@pytest.mark.parametrize("source", ["hrp4_like", "tree"])
def test_frame_rotations_of_samples_match_drake(source):
    """The offline log's sensor rotations R_WF from Pinocchio's forward kinematics equal
    Drake's ``CalcPoseInWorld`` at random states, a free joint on a rotated, offset parent
    included (the tree)."""
    if source == "tree":
        plant, _ = make_random_floating_tree(12, 4, explicit_free_joint=True)
    else:
        plant = robot(source)
    dynamics = PinocchioFloatingBaseDynamics(plant)
    joints = dynamics.topology.joints
    frames = [joints[-1].child_body().body_frame(), joints[len(joints) // 2].frame_on_child()]
    rng = np.random.default_rng(23)
    Q = np.array([random_state(plant, rng)[0] for _ in range(4)])
    R = dynamics.frame_rotations_of_samples(Q, frames)
    context = plant.CreateDefaultContext()
    for k, q in enumerate(Q):
        plant.SetPositions(context, q)
        for f, frame in enumerate(frames):
            expected = frame.CalcPoseInWorld(context).rotation().matrix()
            assert np.abs(R[k, f] - expected).max() < 1e-13
            assert np.abs(expected - np.eye(3)).max() > 1e-2  # not trivially the identity
