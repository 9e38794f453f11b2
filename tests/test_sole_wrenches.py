"""``SoleWrenchCompensation``: eq. (10) with the soles' wrenches estimated, on a robot
without foot F/T sensors (and with FSRs). The residuals it reads are built here from Drake:
the soles' wrenches through ``CalcGeneralizedForces`` (``test_unknown_foot_wrenches``), the
pushes through Drake's Jacobians and mass matrix (``test_multi_contact``)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable

from systems.residuals.contact_estimation import SOLE_SHEAR_AND_YAW, UnknownWrenches, _SensedConfiguration
from systems.residuals.momentum_residuals import ResidualModel
from systems.residuals.sole_wrenches import SoleWrenchCompensation
from tests.test_multi_contact import _exact_residuals
from tests.test_unknown_foot_wrenches import SOLE_FRAMES, STANDING_WRENCHES, _fsr_part, _ground_residuals

LEG_PREFIXES = ("L_HIP", "R_HIP", "L_KNEE", "R_KNEE", "L_ANKLE", "R_ANKLE")


@pytest.fixture(scope="module")
def hrp4(hrp4_moved):
    plant, _, handles, context = hrp4_moved
    return plant, handles, context


def _shoulder_pushes(plant, handles, context, force=(0.0, 0.0, -20.0)):
    """Flacco et al.'s push: a force down on each shoulder body's origin."""
    pushes = []
    for side in ("left", "right"):
        body = handles.shoulder_bodies[side]
        p_W = plant.EvalBodyPoseInWorld(context, body).translation()
        pushes.append((body, np.zeros(3), p_W, np.asarray(force, dtype=float)))
    return pushes


def _classical_of_pushes(plant, context, pushes) -> np.ndarray:
    """The classical residual of point forces (model 8): [moment about the base origin,
    force, both in the base's axes; J_j^T f]."""
    world = plant.world_frame()
    base = next(b for b in (plant.get_body(i) for i in plant.GetFloatingBaseBodies()))
    X_WB = plant.EvalBodyPoseInWorld(context, base)
    R, p_B = X_WB.rotation().matrix(), X_WB.translation()
    out = np.zeros(plant.num_velocities())
    for body, p_BoP, p_W, f_W in pushes:
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, body.body_frame(), p_BoP, world, world
        )
        out[:3] += R.T @ np.cross(p_W - p_B, f_W)
        out[3:6] += R.T @ f_W
        out[6:] += J[:, 6:].T @ f_W
    return out


def _at_rest(dut: SoleWrenchCompensation, plant, context, components, inputs: dict):
    """A context of ``dut`` for a robot standing at the context's posture long enough that
    the filtered columns are the columns, its link chosen on ``inputs``."""
    kin = _SensedConfiguration(plant, "test")
    q = plant.GetPositions(context)
    kin.set_positions(q)
    stacked = UnknownWrenches(plant, SOLE_FRAMES, components, "test").columns(kin)
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("state").FixValue(ctx, np.concatenate((q, np.zeros(plant.num_velocities()))))
    for name, value in inputs.items():
        dut.GetInputPort(name).FixValue(ctx, value)
    rows = np.concatenate((inputs["external_wrench_world"], inputs["internal_residual"]))
    slot = dut.choose_link(q, rows, stacked)
    parts = [[float(slot)], stacked.ravel()]
    if dut.HasInputPort("classical_residual"):
        parts.append(dut.classical_columns(q).ravel())
    ctx.SetDiscreteState(np.concatenate(parts))
    return ctx, slot


@pytest.mark.parametrize("components", [None, [SOLE_SHEAR_AND_YAW] * 2], ids=["no foot sensing", "FSRs"])
def test_the_pushes_joint_effort_comes_out_net_of_the_soles(hrp4, components):
    """Noise-free: the shoulders' push on a robot standing on unknown ground wrenches (with
    FSRs: only their shear and yaw unknown, the rest subtracted as eq. 10 does): the
    internal and the classical residuals net of the soles' estimated wrenches are the
    push's own, to 1e-9, and the soles' wrenches are the ground's."""
    plant, handles, context = hrp4
    pushes = _shoulder_pushes(plant, handles, context)
    wrench, tau = _exact_residuals(plant, context, pushes)
    ground = (
        STANDING_WRENCHES if components is None else STANDING_WRENCHES - _fsr_part(plant, context, STANDING_WRENCHES)
    )
    soles = _ground_residuals(plant, context, ground)
    inputs = {"external_wrench_world": wrench + soles[:6], "internal_residual": tau + soles[6:]}
    dut = SoleWrenchCompensation(plant, SOLE_FRAMES, components, gain=5.0)
    ctx, slot = _at_rest(dut, plant, context, components, inputs)
    assert slot >= 0 and not dut.candidate_bodies[slot].name().startswith(LEG_PREFIXES)
    np.testing.assert_allclose(dut.GetOutputPort("residual").Eval(ctx), tau, atol=1e-9)
    np.testing.assert_allclose(dut.GetOutputPort("sole_wrenches_world").Eval(ctx), ground, atol=1e-7)
    assert dut.GetOutputPort("contact_body_index").Eval(ctx)[0] == int(dut.candidate_bodies[slot].index())

    # The classical residual: the soles' share in its coordinates, and the push's own left.
    soles_classical = np.zeros(plant.num_velocities())
    model = ResidualModel(plant)
    x = np.concatenate((plant.GetPositions(context), np.zeros(plant.num_velocities())))
    terms = model.evaluate(x)
    frames = [plant.GetFrameByName(name) for name in SOLE_FRAMES]
    w_F0, joints = model.known_wrench_forces(terms, frames, ground)
    soles_classical[:6], soles_classical[6:] = w_F0, joints
    classical = _classical_of_pushes(plant, context, pushes)
    dut = SoleWrenchCompensation(plant, SOLE_FRAMES, components, gain=5.0, residual="classical")
    ctx, _ = _at_rest(dut, plant, context, components, {**inputs, "classical_residual": classical + soles_classical})
    np.testing.assert_allclose(dut.GetOutputPort("residual").Eval(ctx), classical, atol=1e-9)


def test_stance_leg_links_are_never_chosen_without_foot_sensing(hrp4):
    """A free wrench on a link of a stance leg is what the soles' wrenches can produce (its
    columns lose a direction once theirs are projected out): with only leg links to choose
    from there is none, and the output is the residual net of the soles' best fit."""
    plant, handles, context = hrp4
    legs = [plant.GetBodyByName(name) for name in ("L_KNEE_P_LINK", "R_HIP_P_LINK", "L_ANKLE_P_LINK")]
    dut = SoleWrenchCompensation(plant, SOLE_FRAMES, gain=5.0, candidate_bodies=legs)
    wrench, tau = _exact_residuals(plant, context, _shoulder_pushes(plant, handles, context))
    soles = _ground_residuals(plant, context, STANDING_WRENCHES)
    inputs = {"external_wrench_world": wrench + soles[:6], "internal_residual": tau + soles[6:]}
    ctx, slot = _at_rest(dut, plant, context, None, inputs)
    assert slot == -1
    assert dut.GetOutputPort("contact_body_index").Eval(ctx)[0] == -1.0
    rows = np.concatenate((wrench, tau)) + soles
    kin = _SensedConfiguration(plant, "test")
    kin.set_positions(plant.GetPositions(context))
    U = UnknownWrenches(plant, SOLE_FRAMES, None, "test").columns(kin)
    fitted = U @ np.linalg.lstsq(U, rows, rcond=None)[0]
    np.testing.assert_allclose(dut.GetOutputPort("residual").Eval(ctx), (rows - fitted)[6:], atol=1e-9)


def test_bad_settings_are_refused(hrp4):
    plant, _, _ = hrp4
    with pytest.raises(ValueError, match="needs the soles as unknown_wrench_frames"):
        SoleWrenchCompensation(plant, (), gain=5.0)
    with pytest.raises(ValueError, match="unknown residual 'external'"):
        SoleWrenchCompensation(plant, SOLE_FRAMES, gain=5.0, residual="external")
    with pytest.raises(ValueError, match="gain times period must be in"):
        SoleWrenchCompensation(plant, SOLE_FRAMES, gain=2000.0)
    with pytest.raises(ValueError, match="no_such_body"):
        SoleWrenchCompensation(plant, SOLE_FRAMES, gain=5.0, candidate_bodies=["no_such_body"])


@pytest.mark.parametrize("components", [None, [SOLE_SHEAR_AND_YAW] * 2], ids=["no foot sensing", "FSRs"])
def test_replay_is_the_system_update_by_update(hrp4, components):
    """``replay`` (the offline twin a log's estimation runs) gives what the system's own
    update and outputs give, stepped through a moving robot with residuals that change:
    the chosen link, the internal and external residuals net of the soles and the soles'
    wrenches, from the start and when continued from a replay's end."""
    plant, handles, context = hrp4
    q0 = plant.GetPositions(context)
    pushes = _shoulder_pushes(plant, handles, context)
    wrench, tau = _exact_residuals(plant, context, pushes)
    soles = _ground_residuals(plant, context, STANDING_WRENCHES)
    rng = np.random.default_rng(3)
    N, nq = 130, plant.num_positions()
    positions = np.tile(q0, (N, 1))
    positions[:, 7:] += 0.02 * np.sin(np.linspace(0.0, 3.0, N))[:, None] * rng.uniform(-1, 1, nq - 7)
    scale = np.linspace(0.0, 1.0, N)[:, None]
    external = scale * (wrench + soles[:6]) + 0.1 * rng.standard_normal((N, 6))
    internal = scale * (tau + soles[6:]) + 0.05 * rng.standard_normal((N, len(tau)))
    dut = SoleWrenchCompensation(plant, SOLE_FRAMES, components, gain=20.0, selection_period=0.01)
    replayed = dut.replay(positions, external, internal)
    ctx = dut.CreateDefaultContext()
    v = np.zeros(plant.num_velocities())
    for k in range(N):
        ctx.SetTime(k * 1e-3)
        dut.GetInputPort("state").FixValue(ctx, np.concatenate((positions[k], v)))
        # The update reads the residuals of their previous update, the outputs their latest.
        dut.GetInputPort("external_wrench_world").FixValue(ctx, external[k - 1] if k else np.zeros(6))
        dut.GetInputPort("internal_residual").FixValue(ctx, internal[k - 1] if k else np.zeros(internal.shape[1]))
        ctx.SetDiscreteState(dut.EvalUniquePeriodicDiscreteUpdate(ctx).get_vector().CopyToVector())
        dut.GetInputPort("external_wrench_world").FixValue(ctx, external[k])
        dut.GetInputPort("internal_residual").FixValue(ctx, internal[k])
        assert dut.GetOutputPort("contact_body_index").Eval(ctx)[0] == replayed.body_index[k]
        np.testing.assert_allclose(dut.GetOutputPort("residual").Eval(ctx), replayed.internal[k], atol=1e-9)
        np.testing.assert_allclose(
            dut.GetOutputPort("external_wrench_world").Eval(ctx), replayed.external_wrench_world[k], atol=1e-9
        )
        np.testing.assert_allclose(
            dut.GetOutputPort("sole_wrenches_world").Eval(ctx), replayed.sole_wrenches_world[k], atol=1e-7
        )
    assert (replayed.body_index >= 0).any()
    np.testing.assert_allclose(ctx.get_discrete_state_vector().CopyToVector(), replayed.end, atol=1e-12)
    # In two parts: the second goes on from the first's end.
    first = dut.replay(positions[:57], external[:57], internal[:57])
    second = dut.replay(
        positions[57:],
        external[57:],
        internal[57:],
        start=first.end,
        first_update=57,
        before=(external[56], internal[56]),
    )
    np.testing.assert_allclose(second.internal, replayed.internal[57:], atol=1e-9)
    np.testing.assert_array_equal(second.body_index, replayed.body_index[57:])
    with pytest.raises(ValueError, match="internal_residual must be"):
        dut.replay(positions, external, internal[:, :3])
    with pytest.raises(ValueError, match="positions holds NaN"):
        dut.replay(np.full_like(positions, np.nan), external, internal)


def test_replay_takes_a_given_link_unless_the_soles_can_mimic_it(hrp4):
    """``replay(links=)``, as a log's estimation passes the localizer's answer: a given link
    that the soles' wrenches cannot mimic (an elbow) is the one fitted at every selection
    update, whatever the misfit would choose; a stance leg's link (a knee), which they can
    mimic, and -1 leave the choice by misfit as without links."""
    plant, handles, context = hrp4
    q0 = plant.GetPositions(context)
    wrench, tau = _exact_residuals(plant, context, _shoulder_pushes(plant, handles, context))
    soles = _ground_residuals(plant, context, STANDING_WRENCHES)
    N = 30
    positions = np.tile(q0, (N, 1))
    external = np.tile(wrench + soles[:6], (N, 1))
    internal = np.tile(tau + soles[6:], (N, 1))
    dut = SoleWrenchCompensation(plant, SOLE_FRAMES, gain=20.0, selection_period=0.01)
    chosen = dut.replay(positions, external, internal)
    elbow, knee = (int(plant.GetBodyByName(name).index()) for name in ("L_ELBOW_P_LINK", "L_KNEE_P_LINK"))
    assert elbow not in chosen.body_index
    given = dut.replay(positions, external, internal, links=np.full(N, elbow))
    np.testing.assert_array_equal(given.body_index, np.full(N, elbow))
    for links in (np.full(N, knee), np.full(N, -1)):
        np.testing.assert_array_equal(
            dut.replay(positions, external, internal, links=links).body_index, chosen.body_index
        )
    with pytest.raises(ValueError, match="links must be"):
        dut.replay(positions, external, internal, links=np.zeros(N - 1))


def test_batched_least_squares_is_lstsq_sample_by_sample():
    """``replay``'s batched fit: QR where a sample's matrix has full column rank, the
    minimum-norm solution where it has not (two equal columns), as ``lstsq`` per sample."""
    from systems.residuals.sole_wrenches import _least_squares_of_samples

    rng = np.random.default_rng(8)
    A, b = rng.normal(size=(5, 20, 7)), rng.normal(size=(5, 20))
    A[2, :, 6] = A[2, :, 5]
    x = _least_squares_of_samples(A, b)
    for k in range(5):
        np.testing.assert_allclose(x[k], np.linalg.lstsq(A[k], b[k], rcond=None)[0], rtol=1e-9, atol=1e-12)
