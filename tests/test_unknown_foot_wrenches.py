"""Contact estimation on a humanoid without foot F/T sensors: the ground's wrenches on the
soles are unknowns of the estimators (``unknown_wrench_frames``), not measurements.

The residuals fed to the estimators are built here independently of their code: a wrench
on a sole enters through Drake's own force machinery (``CalcGeneralizedForces`` of an
applied spatial force), a point push through Drake's Jacobians and mass matrix
(``tests/test_multi_contact.py``'s ``_exact_residuals``), both with the floating-base
elimination tau_int = tau_j - (M_bb^-1 M_bj)^T tau_b of eq. (12).
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.tree import BodyIndex, MultibodyForces
from scipy.stats import chi2

from systems.observer.fsr_sensing import FsrSoleWrenches
from systems.residuals.contact_estimation import (
    AMBIGUOUS,
    NO_INTERSECTION,
    SOLE_SHEAR_AND_YAW,
    VALID,
    ContactDetector,
    ContactForceEstimator,
    ContactLocalizer,
    UnknownWrenches,
    _SensedConfiguration,
    unexplained_residuals,
    unknown_wrench_columns,
)
from systems.residuals.multi_contact import MultiContactLocalizer
from tests.test_multi_contact import _exact_residuals, _limb, _sample_contact

SOLE_FRAMES = ("l_sole_frame", "r_sole_frame")
SOLES = ("l_sole", "r_sole")
#: A standing robot's ground wrenches, [moment about the sole frame; force], world: about
#: half of hrp4_like's 39 kg on each foot, with moments and shear of a robot shifting its
#: weight.
STANDING_WRENCHES = np.array([3.0, -6.0, 0.5, 8.0, -5.0, 200.0, -4.0, -5.0, -0.3, -6.0, 4.0, 180.0])


@pytest.fixture(scope="module")
def hrp4(hrp4_moved):
    plant, scene_graph, _, context = hrp4_moved
    return plant, scene_graph, context


def _ground_residuals(plant, context, wrenches: np.ndarray) -> np.ndarray:
    """[r_ext; r_int] of wrenches [m_F; f] (world, moment about each sole frame's origin)
    on the soles, from Drake's generalized forces of applied spatial forces."""
    external = np.zeros(6)
    forces = MultibodyForces(plant)
    forces.SetZero()
    for name, w in zip(SOLE_FRAMES, wrenches.reshape(-1, 6)):
        frame = plant.GetFrameByName(name)
        body = frame.body()
        p_WF = frame.CalcPoseInWorld(context).translation()
        p_WB = plant.EvalBodyPoseInWorld(context, body).translation()
        # Applied at the sole frame's origin (offset from the body's origin, world).
        body.AddInForce(context, p_WF - p_WB, SpatialForce(w[:3], w[3:]), plant.world_frame(), forces)
        external += np.concatenate((w[:3] + np.cross(p_WF, w[3:]), w[3:]))
    tau = plant.CalcGeneralizedForces(context, forces)
    M = plant.CalcMassMatrix(context)
    E = np.linalg.solve(M[:6, :6], M[:6, 6:])
    return np.concatenate((external, tau[6:] - E.T @ tau[:6]))


def _columns(plant, context) -> np.ndarray:
    kin = _SensedConfiguration(plant, "test")
    kin.set_positions(plant.GetPositions(context))
    return unknown_wrench_columns(kin, [plant.GetFrameByName(n) for n in SOLE_FRAMES])


def test_unknown_wrench_columns_match_drakes_generalized_forces(hrp4):
    plant, _, context = hrp4
    T = _columns(plant, context)
    assert T.shape == (plant.num_velocities(), 12)
    rng = np.random.default_rng(11)
    for w in (STANDING_WRENCHES, rng.normal(size=12) * 30.0):
        expected = _ground_residuals(plant, context, w)
        np.testing.assert_allclose(T @ w, expected, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("components", [None, [SOLE_SHEAR_AND_YAW] * 2])
def test_columns_of_many_samples_at_once_are_the_columns_sample_by_sample(hrp4, components):
    """``UnknownWrenches.columns_of_samples`` (Pinocchio's kinematics and mass matrix per
    sample, the rest stacked: what the offline replays use) gives ``columns`` and
    ``world_map`` (Drake, one sample at a time) at random poses, whole wrenches and FSR soles'
    shear and yaw alike."""
    plant, _, context = hrp4
    unknown = UnknownWrenches(plant, SOLE_FRAMES, components, "test")
    kin = _SensedConfiguration(plant, "test")
    rng = np.random.default_rng(12)
    q = np.tile(plant.GetPositions(context), (6, 1))
    q[:, 7:] += 0.2 * rng.standard_normal((6, q.shape[1] - 7))
    quaternions = rng.standard_normal((6, 4))
    q[:, :4] = quaternions / np.linalg.norm(quaternions, axis=1, keepdims=True)
    q[:, 4:7] += rng.standard_normal((6, 3))
    columns, world = unknown.columns_of_samples(kin.pinocchio, q)
    for k in range(6):
        kin.set_positions(q[k])
        expected = unknown.columns(kin)
        np.testing.assert_allclose(columns[k], expected, rtol=0, atol=1e-12 * np.abs(expected).max())
        np.testing.assert_allclose(world[k], unknown.world_map(kin), rtol=0, atol=1e-12)


def _arm_push(plant, context, localizer, seed: int):
    rng = np.random.default_rng(seed)
    return _sample_contact(plant, context, localizer, rng, "R_WRIST_Y_LINK")


@pytest.fixture(scope="module")
def localizer(hrp4):
    plant, scene_graph, _ = hrp4
    return MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES, unknown_wrench_frames=SOLE_FRAMES)


@pytest.fixture(scope="module")
def line_localizer(hrp4):
    plant, scene_graph, _ = hrp4
    return ContactLocalizer(plant, scene_graph, exclude_bodies=SOLES, unknown_wrench_frames=SOLE_FRAMES)


def test_force_estimator_recovers_push_and_ground_wrenches(hrp4, localizer):
    plant, _, context = hrp4
    body, p_B, p_W, f_W = _arm_push(plant, context, localizer, 1)
    wrench, tau = _exact_residuals(plant, context, [(body, p_B, p_W, f_W)])
    b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, STANDING_WRENCHES)
    dut = ContactForceEstimator(plant, "stacked", [(body, p_B)], unknown_wrench_frames=SOLE_FRAMES)
    assert [f.name() for f in dut.unknown_wrench_frames] == list(SOLE_FRAMES)
    ctx = dut.CreateDefaultContext()
    state = np.concatenate((plant.GetPositions(context), np.zeros(plant.num_velocities())))
    dut.GetInputPort("state").FixValue(ctx, state)
    dut.GetInputPort("external_wrench_world").FixValue(ctx, b[:6])
    dut.GetInputPort("residual").FixValue(ctx, b[6:])
    np.testing.assert_allclose(dut.GetOutputPort("contact_forces_world").Eval(ctx), f_W, atol=1e-8)
    np.testing.assert_allclose(dut.GetOutputPort("unknown_wrenches_world").Eval(ctx), STANDING_WRENCHES, atol=1e-7)
    assert dut.GetOutputPort("fit_error").Eval(ctx)[0] < 1e-8
    # Without the ground's wrenches among the unknowns the same residuals are no push on
    # the wrist: the fit misses by tens of N and N m, its force by more than the push.
    blind = ContactForceEstimator(plant, "stacked", [(body, p_B)])
    ctx = blind.CreateDefaultContext()
    blind.GetInputPort("state").FixValue(ctx, state)
    blind.GetInputPort("external_wrench_world").FixValue(ctx, b[:6])
    blind.GetInputPort("residual").FixValue(ctx, b[6:])
    assert blind.GetOutputPort("fit_error").Eval(ctx)[0] > 10.0
    assert np.linalg.norm(blind.GetOutputPort("contact_forces_world").Eval(ctx) - f_W) > np.linalg.norm(f_W)


def test_force_estimator_refuses_unknown_wrenches_it_cannot_use(hrp4):
    plant, _, _ = hrp4
    with pytest.raises(ValueError, match="need mode 'stacked'"):
        ContactForceEstimator(plant, "external", unknown_wrench_frames=SOLE_FRAMES)
    with pytest.raises(ValueError, match="'l_heel' is not a frame of the plant"):
        ContactForceEstimator(plant, "stacked", unknown_wrench_frames=["l_heel"])
    with pytest.raises(ValueError, match="twice"):
        ContactForceEstimator(plant, "stacked", unknown_wrench_frames=["l_sole_frame", "l_sole_frame"])


def _detector(plant, context, **kwargs) -> ContactDetector:
    return ContactDetector(
        plant,
        nominal_positions=plant.GetPositions(context),
        unknown_wrench_frames=SOLE_FRAMES,
        **kwargs,
    )


def test_detector_ignores_any_ground_wrench_and_sees_a_small_push(hrp4, localizer):
    plant, _, context = hrp4
    dut = _detector(plant, context)
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    on = dut.thresholds["on"][1]
    assert on == pytest.approx(chi2.isf(1e-9, 3 + n - 12))
    rng = np.random.default_rng(2)
    columns = dut.unknown_columns(q)  # a robot at rest: the filtered columns are these
    for w in (STANDING_WRENCHES, 3.0 * STANDING_WRENCHES + 50.0 * rng.normal(size=12)):
        b = _ground_residuals(plant, context, w)
        s_ext, s_int = dut.statistics(b[:6], b[6:], columns)
        assert s_ext == 0.0 and s_int < 1e-12 * on
    # A 5 N push on the wrist, on top of the standing wrenches, is far above the threshold.
    body, p_B, p_W, f_W = _arm_push(plant, context, localizer, 3)
    push = 5.0 * f_W / np.linalg.norm(f_W)
    wrench, tau = _exact_residuals(plant, context, [(body, p_B, p_W, push)])
    b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, STANDING_WRENCHES)
    assert dut.statistics(b[:6], b[6:], columns)[1] > 10.0 * on
    # The system reads q from its state port and switches on (its filtered columns those
    # of a robot standing there for long).
    ctx = dut.CreateDefaultContext()
    ctx.SetDiscreteState(np.concatenate(([0.0, -1.0, 0.0, 0.0, 0.0, 0.0], columns.ravel())))
    dut.GetInputPort("state").FixValue(ctx, np.concatenate((q, np.zeros(plant.num_velocities()))))
    dut.GetInputPort("external_wrench_world").FixValue(ctx, b[:6])
    dut.GetInputPort("residual").FixValue(ctx, b[6:])
    ctx.SetTime(0.0)
    update = dut.EvalUniquePeriodicDiscreteUpdate(ctx)
    ctx.SetDiscreteState(update)
    assert dut.GetOutputPort("contact_detected").Eval(ctx)[0] == 1.0


def test_detector_statistic_is_chi_square_under_noise(hrp4):
    """Sensor-like noise of the detector's own covariances on top of changing ground
    wrenches: the statistic has the chi-square's mean and variance with 3 + n - 12 dof."""
    plant, _, context = hrp4
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(4)
    A = rng.normal(size=(n, n)) * 0.002
    cov_int = A @ A.T + 0.003**2 * np.eye(n)
    cov_f = np.diag([0.2, 0.3, 0.25]) ** 2
    dut = _detector(plant, context, covariance_internal=cov_int, covariance_external_force=cov_f)
    q = plant.GetPositions(context)
    count = 2000
    wrenches = np.zeros((count, 6))
    residuals = np.zeros((count, n))
    for k in range(count):
        b = _ground_residuals(plant, context, STANDING_WRENCHES + 20.0 * rng.normal(size=12))
        wrenches[k] = b[:6]
        wrenches[k, 3:] += rng.multivariate_normal(np.zeros(3), cov_f)
        residuals[k] = b[6:] + rng.multivariate_normal(np.zeros(n), cov_int)
    columns = np.tile(dut.unknown_columns(q), (count, 1, 1))
    s = dut.statistics_of_samples(wrenches, residuals, columns)[:, 1]
    dof = 3 + n - 12
    assert abs(s.mean() - dof) < 5.0 * np.sqrt(2.0 * dof / count)
    assert abs(s.var() / (2.0 * dof) - 1.0) < 0.15
    np.testing.assert_allclose(s[:5], [dut.statistics(wrenches[k], residuals[k], columns[k])[1] for k in range(5)])
    with pytest.raises(ValueError, match="filtered columns"):
        dut.statistics_of_samples(wrenches, residuals)


def _moving_robot_residuals(plant, q0, rng, amplitude, times, wrenches, K=35.0, T=1e-3):
    """A standing robot moving its torso, head and arms (each joint a 0.5 Hz sine of
    ``amplitude`` rad and a random phase; v[6:] order: the legs first) while the ground
    puts ``wrenches`` (per sample, 12) on its soles: (positions, [r_ext; r_int] per sample),
    the residuals the first-order filter of J(q(t))^T w (eqs. 11, 16; r_k = (1 - K T) r_k-1
    + K T J_k^T w_k)."""
    moving = np.zeros(q0.size)
    moving[7 + 12 :] = amplitude
    phase = rng.uniform(0.0, 2.0 * np.pi, q0.size)
    positions = q0 + moving * np.sin(2.0 * np.pi * 0.5 * times[:, None] + phase)
    kin = _SensedConfiguration(plant, "test")
    frames = [plant.GetFrameByName(f) for f in SOLE_FRAMES]
    residual = np.zeros(plant.num_velocities())
    residuals = np.zeros((len(times), plant.num_velocities()))
    for k, q in enumerate(positions):
        kin.set_positions(q)
        residual = (1.0 - K * T) * residual + K * T * (unknown_wrench_columns(kin, frames) @ wrenches[k])
        residuals[k] = residual
    return positions, residuals


def test_detector_filters_the_columns_as_the_residuals_filter_the_ground_wrench(hrp4):
    """A robot moving its arms and torso while standing: the residuals are the first-order
    filter of J(q(t))^T w (eqs. 11, 16; r_k = (1 - K T) r_k-1 + K T J_k^T w), not J(q)^T w.
    Projecting out the columns at the current q leaves their lag, J-dot^T w / K with w the
    robot's weight, far above the threshold; the detector's filtered columns leave none,
    and its system update reproduces ``filtered_columns``."""
    plant, _, context = hrp4
    dut = _detector(plant, context)
    T = 1e-3  # the residuals' period (their gain K = 35/s, the detector's default)
    q0 = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(5)
    times = np.arange(600) * T
    positions, residuals = _moving_robot_residuals(plant, q0, rng, 0.3, times, np.tile(STANDING_WRENCHES, (600, 1)))
    late = np.vstack((np.zeros((1, 6 + n)), residuals[:-1]))  # update k reads residual k - 1
    used, end = dut.filtered_columns(np.zeros(dut.unknown_columns(q0).size), positions)
    filtered = dut.statistics_of_samples(late[:, :6], late[:, 6:], used)[100:, 1]
    instantaneous = np.array(
        [dut.statistics(late[k, :6], late[k, 6:], dut.unknown_columns(positions[k - 1]))[1] for k in range(100, 600)]
    )
    on = dut.thresholds["on"][1]
    assert filtered.max() < 1e-6 * on
    assert instantaneous.max() > 10.0 * on
    # The system: the same filter in its state, update by update.
    ctx = dut.CreateDefaultContext()
    velocity = np.zeros(plant.num_velocities())
    for k in range(50):
        dut.GetInputPort("state").FixValue(ctx, np.concatenate((positions[k], velocity)))
        dut.GetInputPort("external_wrench_world").FixValue(ctx, late[k, :6])
        dut.GetInputPort("residual").FixValue(ctx, late[k, 6:])
        ctx.SetTime(times[k])
        ctx.SetDiscreteState(dut.EvalUniquePeriodicDiscreteUpdate(ctx))
    np.testing.assert_allclose(
        ctx.get_discrete_state_vector().CopyToVector()[6:],
        dut.filtered_columns(np.zeros(end.size), positions[:50])[1].ravel(),
    )
    assert dut.GetOutputPort("contact_detected").Eval(ctx)[0] == 0.0


def test_detector_refuses_known_and_unknown_wrenches_together(hrp4):
    plant, _, context = hrp4
    with pytest.raises(ValueError, match="'l_sole_frame' is both known and wholly unknown"):
        _detector(plant, context, known_wrench_frames=[plant.GetFrameByName("l_sole_frame")])
    with pytest.raises(ValueError, match="use_internal"):
        _detector(plant, context, use_internal=False)


def test_localizer_finds_arm_and_torso_pushes_exactly_with_unknown_ground_wrenches(hrp4, localizer):
    """Noise-free: every push on an arm or the torso is found on its link at its point,
    with its force and both feet's wrenches, whatever the ground carries."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    rng = np.random.default_rng(21)
    found = 0
    while found < 12:
        contact = _sample_contact(plant, context, localizer, rng)
        if "leg" in _limb(contact[0].name()):
            continue
        wrench, tau = _exact_residuals(plant, context, [contact])
        ground = STANDING_WRENCHES + 30.0 * rng.normal(size=12)
        b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, ground)
        fit = localizer.fit_one(q, b[:6], b[6:])
        assert fit.body_indices == (int(contact[0].index()),), contact[0].name()
        np.testing.assert_allclose(fit.points_W[0], contact[2], atol=1e-6)
        np.testing.assert_allclose(fit.forces_W[0], contact[3], atol=1e-6)
        np.testing.assert_allclose(fit.unknown_wrenches.reshape(-1), ground, atol=1e-5)
        assert fit.dof == plant.num_velocities() - 5 - 12 - np.count_nonzero(fit.stop_torques)
        result = localizer.localize(q, b[:6], b[6:], max_contacts=1)
        assert result.num_contacts == 1 and result.valid
        found += 1


def test_localizers_never_claim_a_push_on_a_stance_leg(hrp4, localizer, line_localizer):
    """A push on a stance leg's shank reaches the residuals that no ground wrench explains
    only through the joints between it and the sole (the two ankle joints): fewer equations
    than a contact's 5 unknowns. The fit is exact on more than one link, and neither
    localizer's result is valid: they never claim a link."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    rng = np.random.default_rng(8)
    for name in ("L_KNEE_P_LINK", "R_KNEE_P_LINK", "R_HIP_P_LINK"):
        contact = _sample_contact(plant, context, localizer, rng, name)
        wrench, tau = _exact_residuals(plant, context, [contact])
        b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, STANDING_WRENCHES)
        result = localizer.localize(q, b[:6], b[6:], max_contacts=1)
        assert result.num_contacts == 1
        assert not result.valid
        assert result.one.statistic < 1e-9 and result.one.runner_up_statistic < 1e-6
        assert line_localizer.localize(q, b[:6], b[6:]).status in (AMBIGUOUS, NO_INTERSECTION), name
        # The same push seen with the ground's wrenches measured (F/T) is placed exactly.
        with_ft = MultiContactLocalizer(plant, hrp4[1], exclude_bodies=SOLES)
        fit = with_ft.fit_one(q, wrench, tau)
        assert fit.body_indices == (int(contact[0].index()),)
        np.testing.assert_allclose(fit.points_W[0], contact[2], atol=1e-6)


def test_localizer_refuses_too_many_unknown_wrenches(hrp4):
    plant, scene_graph, _ = hrp4
    with pytest.raises(ValueError, match="not a frame of the plant"):
        MultiContactLocalizer(plant, scene_graph, unknown_wrench_frames=["nowhere"])
    # 7 wrenches (42 unknowns) leave 40 - 42 < 11 of hrp4_like's 40 rows.
    body_frames = [plant.get_body(BodyIndex(i)).body_frame() for i in range(1, plant.num_bodies())]
    with pytest.raises(ValueError, match="fewer than two contacts need"):
        MultiContactLocalizer(plant, scene_graph, unknown_wrench_frames=body_frames[:7])


def test_line_localizer_finds_arm_and_torso_pushes_exactly_with_unknown_ground_wrenches(
    hrp4, localizer, line_localizer
):
    """Eq. (22) on each link's own wrench, the ground's projected out: noise-free pushes on
    the arms and the torso come out VALID on their link, at their point, with their force."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    rng = np.random.default_rng(22)
    found = ambiguous = 0
    while found < 12:
        contact = _sample_contact(plant, context, localizer, rng)
        if "leg" in _limb(contact[0].name()):
            continue
        wrench, tau = _exact_residuals(plant, context, [contact])
        b = np.concatenate((wrench, tau)) + _ground_residuals(
            plant, context, STANDING_WRENCHES + 30.0 * rng.normal(size=12)
        )
        result = line_localizer.localize(q, b[:6], b[6:])
        # AMBIGUOUS when another link could explain the residuals about as well: a hand on
        # its stop moves with its wrist (as with F/T sensors), and a free wrench on the
        # next link may miss by less than the 0.01 N m margin (its extra joint's torque).
        assert result.status in (VALID, AMBIGUOUS), (contact[0].name(), result.reason)
        ambiguous += result.status == AMBIGUOUS
        assert line_localizer.same_link(result.body_index, int(contact[0].index()))
        np.testing.assert_allclose(result.point_W, contact[2], atol=1e-6)
        np.testing.assert_allclose(result.force_W, contact[3], atol=1e-6)
        assert result.score < 1e-6
        found += 1
    assert ambiguous <= 4  # seed 22: three wrist/hand pairs on a stop, one shoulder
    # Without the unknown wrenches the same residuals put the body weight on the line.
    blind = ContactLocalizer(plant, hrp4[1], exclude_bodies=SOLES)
    assert np.linalg.norm(blind.localize(q, b[:6], b[6:]).force_W) > 300.0


def test_line_localizer_system_with_unknown_wrenches(hrp4, localizer, line_localizer):
    """The LeafSystem: one update with a detected contact gives localize's answer."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    contact = _arm_push(plant, context, localizer, 5)
    wrench, tau = _exact_residuals(plant, context, [contact])
    b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, STANDING_WRENCHES)
    ctx = line_localizer.CreateDefaultContext()
    line_localizer.GetInputPort("state").FixValue(ctx, np.concatenate((q, np.zeros(plant.num_velocities()))))
    line_localizer.GetInputPort("external_wrench_world").FixValue(ctx, b[:6])
    line_localizer.GetInputPort("residual").FixValue(ctx, b[6:])
    line_localizer.GetInputPort("contact_detected").FixValue(ctx, [1.0])
    ctx.SetDiscreteState(line_localizer.EvalUniquePeriodicDiscreteUpdate(ctx))
    assert line_localizer.GetOutputPort("valid").Eval(ctx)[0] == 1.0
    assert line_localizer.same_link(
        int(line_localizer.GetOutputPort("contact_body").Eval(ctx)[0]), int(contact[0].index())
    )
    np.testing.assert_allclose(line_localizer.GetOutputPort("contact_force_world").Eval(ctx), contact[3], atol=1e-6)


# ---------------------------------------------------------------------------------------
# Soles with FSRs: their normal force and centre of pressure are measured (known wrenches),
# their shear and yaw moment unknowns (SOLE_SHEAR_AND_YAW).
# ---------------------------------------------------------------------------------------

FSR_COMPONENTS = (SOLE_SHEAR_AND_YAW, SOLE_SHEAR_AND_YAW)


def _sole_rotation(plant, context, name: str) -> np.ndarray:
    return plant.GetFrameByName(name).CalcPoseInWorld(context).rotation().matrix()


def _fsr_part(plant, context, wrenches: np.ndarray) -> np.ndarray:
    """What the soles' FSRs measure of ground wrenches [m_F; f] (world): in each sole's axes
    the normal force f_z and the moments m_x, m_y (the others 0), back in world."""
    out = np.zeros_like(wrenches)
    for i, name in enumerate(SOLE_FRAMES):
        R = _sole_rotation(plant, context, name)
        local = np.concatenate((R.T @ wrenches[6 * i : 6 * i + 3], R.T @ wrenches[6 * i + 3 : 6 * i + 6]))
        local[list(SOLE_SHEAR_AND_YAW)] = 0.0
        out[6 * i : 6 * i + 6] = np.concatenate((R @ local[:3], R @ local[3:]))
    return out


def test_fsr_sole_wrenches_are_the_fsrs_normal_forces_at_their_points(hrp4_moved):
    """The wrench ``FsrSoleWrenches`` gives each sole, mapped into the residuals, equals
    Drake's generalized forces of the readings applied as forces along the sole's normal
    at the FSRs' points (the sole's posture tilted by the moved legs)."""
    plant, _, handles, context = hrp4_moved
    dut = FsrSoleWrenches(plant, handles)
    readings = np.array([31.0, 12.5, 44.0, 20.0, 5.0, 61.0, 17.5, 28.0])
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("fsr_forces").FixValue(ctx, readings)
    dut.GetInputPort("state").FixValue(
        ctx, np.concatenate((plant.GetPositions(context), np.zeros(plant.num_velocities())))
    )
    wrenches = dut.GetOutputPort("wrenches").Eval(ctx)
    forces = MultibodyForces(plant)
    forces.SetZero()
    external = np.zeros(6)
    for side, frame_name, values in zip(("left", "right"), SOLE_FRAMES, readings.reshape(2, 4)):
        frame = plant.GetFrameByName(frame_name)
        X_WS = frame.CalcPoseInWorld(context)
        body = frame.body()
        p_WB = plant.EvalBodyPoseInWorld(context, body).translation()
        normal = X_WS.rotation().matrix()[:, 2]
        for (x, y), value in zip(handles.fsr_positions[side], values):
            p_WP = X_WS @ np.array([x, y, 0.0])
            body.AddInForce(
                context, p_WP - p_WB, SpatialForce(np.zeros(3), value * normal), plant.world_frame(), forces
            )
            external += np.concatenate((np.cross(p_WP, value * normal), value * normal))
    tau = plant.CalcGeneralizedForces(context, forces)
    M = plant.CalcMassMatrix(context)
    expected = np.concatenate((external, tau[6:] - np.linalg.solve(M[:6, :6], M[:6, 6:]).T @ tau[:6]))
    np.testing.assert_allclose(_columns(plant, context) @ wrenches, expected, atol=1e-9 * np.abs(expected).max())
    # Only f_z, m_x and m_y in each sole's axes: the FSRs see no shear and no yaw moment.
    for i, name in enumerate(SOLE_FRAMES):
        R = _sole_rotation(plant, context, name)
        local = np.concatenate((R.T @ wrenches[6 * i : 6 * i + 3], R.T @ wrenches[6 * i + 3 : 6 * i + 6]))
        np.testing.assert_allclose(local[list(SOLE_SHEAR_AND_YAW)], 0.0, atol=1e-9)
        assert local[5] == pytest.approx(readings[4 * i : 4 * i + 4].sum())
    with pytest.raises(ValueError, match="sides must be distinct"):
        FsrSoleWrenches(plant, handles, sides=("left", "left"))


def test_force_estimator_recovers_push_and_sole_shear_with_fsr_soles(hrp4, localizer):
    """The residuals after eq. (10) subtracted the FSRs' wrenches: the push on the wrist
    and each sole's unmeasured shear and yaw moment come out exactly."""
    plant, _, context = hrp4
    body, p_B, p_W, f_W = _arm_push(plant, context, localizer, 1)
    wrench, tau = _exact_residuals(plant, context, [(body, p_B, p_W, f_W)])
    unmeasured = STANDING_WRENCHES - _fsr_part(plant, context, STANDING_WRENCHES)
    b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, unmeasured)
    dut = ContactForceEstimator(
        plant, "stacked", [(body, p_B)], unknown_wrench_frames=SOLE_FRAMES, unknown_wrench_components=FSR_COMPONENTS
    )
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("state").FixValue(
        ctx, np.concatenate((plant.GetPositions(context), np.zeros(plant.num_velocities())))
    )
    dut.GetInputPort("external_wrench_world").FixValue(ctx, b[:6])
    dut.GetInputPort("residual").FixValue(ctx, b[6:])
    np.testing.assert_allclose(dut.GetOutputPort("contact_forces_world").Eval(ctx), f_W, atol=1e-8)
    np.testing.assert_allclose(dut.GetOutputPort("unknown_wrenches_world").Eval(ctx), unmeasured, atol=1e-7)
    assert dut.GetOutputPort("fit_error").Eval(ctx)[0] < 1e-8
    with pytest.raises(ValueError, match="distinct indices 0-5"):
        ContactForceEstimator(
            plant, "stacked", unknown_wrench_frames=SOLE_FRAMES, unknown_wrench_components=[(2, 3, 9)] * 2
        )
    with pytest.raises(ValueError, match="1 entries for 2 unknown wrench frames"):
        ContactForceEstimator(
            plant, "stacked", unknown_wrench_frames=SOLE_FRAMES, unknown_wrench_components=[(2, 3, 4)]
        )


def test_detector_with_fsr_soles_tests_what_shear_and_yaw_cannot_explain(hrp4, localizer):
    """3 + n - 6 degrees of freedom; any shear and yaw moment at the soles leaves the
    statistic at 0, an unmeasured normal force (an FSR that reads nothing) and a 5 N push do
    not. The soles may be known frames too (the FSRs' wrench)."""
    plant, _, context = hrp4
    dut = _detector(plant, context, unknown_wrench_components=FSR_COMPONENTS, known_wrench_frames=SOLE_FRAMES)
    n = plant.num_velocities() - 6
    on = dut.thresholds["on"][1]
    assert on == pytest.approx(chi2.isf(1e-9, 3 + n - 6))
    columns = dut.unknown_columns(plant.GetPositions(context))
    assert columns.shape == (3 + n, 6)
    unmeasured = STANDING_WRENCHES - _fsr_part(plant, context, STANDING_WRENCHES)
    b = _ground_residuals(plant, context, unmeasured)
    assert dut.statistics(b[:6], b[6:], columns)[1] < 1e-12 * on
    b = _ground_residuals(plant, context, STANDING_WRENCHES)  # the normal forces not subtracted
    assert dut.statistics(b[:6], b[6:], columns)[1] > 10.0 * on
    body, p_B, p_W, f_W = _arm_push(plant, context, localizer, 3)
    wrench, tau = _exact_residuals(plant, context, [(body, p_B, p_W, 5.0 * f_W / np.linalg.norm(f_W))])
    b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, unmeasured)
    assert dut.statistics(b[:6], b[6:], columns)[1] > 10.0 * on


def test_localizers_place_stance_leg_pushes_with_fsr_soles(hrp4, localizer):
    """The pushes of ``test_localizers_never_claim_a_push_on_a_stance_leg``, with the soles'
    normal forces and centres of pressure measured: only shear and yaw (3 unknowns per
    sole) stay free, every leg joint sees the push again, and the stacked fit places each
    on its link, at its point, with its force, and calls it valid (a leg link's line entry
    is polished along its surface: with the soles' columns projected out its zero-pitch
    wrench is not unique, and on Drake 1.58 the entry alone lay 8 mm from the R_KNEE_P push)."""
    plant, scene_graph, context = hrp4
    q = plant.GetPositions(context)
    fsr = MultiContactLocalizer(
        plant,
        scene_graph,
        exclude_bodies=SOLES,
        unknown_wrench_frames=SOLE_FRAMES,
        unknown_wrench_components=FSR_COMPONENTS,
    )
    assert fsr.partly_known_wrenches and not localizer.partly_known_wrenches
    rng = np.random.default_rng(8)
    for name in ("L_KNEE_P_LINK", "R_KNEE_P_LINK", "R_HIP_P_LINK"):
        contact = _sample_contact(plant, context, localizer, rng, name)
        wrench, tau = _exact_residuals(plant, context, [contact])
        unmeasured = STANDING_WRENCHES - _fsr_part(plant, context, STANDING_WRENCHES)
        b = np.concatenate((wrench, tau)) + _ground_residuals(plant, context, unmeasured)
        result = fsr.localize(q, b[:6], b[6:], max_contacts=1)
        assert result.num_contacts == 1 and result.valid, name
        assert result.body_indices == (int(contact[0].index()),), name
        np.testing.assert_allclose(result.one.points_W[0], contact[2], atol=1e-6)
        np.testing.assert_allclose(result.one.forces_W[0], contact[3], atol=1e-6)
        np.testing.assert_allclose(result.one.unknown_wrenches.reshape(-1), unmeasured, atol=1e-5)


def test_a_standing_robot_with_fsr_feet_measures_its_weight_at_the_soles():
    """hrp4_like with FSR feet (``models/robots/hrp4_like_fsr.yaml``) in the study's
    diagram: the station's known wrenches are the soles' FSR wrenches (the description's
    500 N range), which carry the robot's weight while it stands, and the detector, testing
    what the soles' shear and yaw cannot explain, stays off."""
    from pydrake.systems.analysis import Simulator

    from diagrams.residuals.contact_study import ContactLocalizationScenario, build_contact_localization_diagram
    from diagrams.station.config import StationConfig

    scenario = ContactLocalizationScenario(station=StationConfig(model="models/robots/hrp4_like_fsr.yaml"))
    diagram, handles = build_contact_localization_diagram(scenario, online=True)
    station = handles.station
    np.testing.assert_array_equal(station.sensors.fsr_array.saturation, np.full(8, 500.0))
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.AdvanceTo(0.5)
    port = station.known_wrenches
    wrenches = port.Eval(port.get_system().GetMyContextFromRoot(context)).reshape(2, 6)
    plant_context = station.plant.GetMyContextFromRoot(context)
    weight = station.plant.CalcTotalMass(plant_context) * 9.81
    assert wrenches[:, 5].sum() == pytest.approx(weight, rel=0.01)
    assert np.all(wrenches[:, 5] > 0.3 * weight)
    assert (
        handles.detector.GetOutputPort("contact_detected").Eval(handles.detector.GetMyContextFromRoot(context))[0]
        == 0.0
    )


def test_unexplained_residuals_leave_the_noise_of_a_moving_robot_on_shifting_feet(hrp4):
    """The noise model's input on a robot without F/T sensors: residuals of a robot moving
    its arms and torso while its weight shifts between its feet (the ground's wrenches
    change), plus white noise: what the soles' filtered columns cannot explain is the noise
    (its projection), not the ground's hundreds of newtons."""
    plant, _, context = hrp4
    K, T = 35.0, 1e-3
    q0 = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(12)
    times = np.arange(800) * T
    shift = np.outer(np.sin(2.0 * np.pi * 0.3 * times), np.array([0, 0, 0, 0, 0, 60.0, 0, 0, 0, 0, 0, -60.0]))
    positions, residuals = _moving_robot_residuals(plant, q0, rng, 0.2, times, STANDING_WRENCHES + shift)
    noise = rng.normal(size=residuals.shape) * 0.05
    force, internal = unexplained_residuals(
        plant,
        SOLE_FRAMES,
        None,
        positions,
        residuals[:, :6] + noise[:, :6],
        residuals[:, 6:] + noise[:, 6:],
        external_gain=K,
        internal_gain=K,
        period=T,
    )
    rest = np.concatenate((force, internal), axis=1)[100:]
    raw = np.concatenate((residuals[:, 3:6], residuals[:, 6:]), axis=1)[100:]
    white = np.concatenate((noise[:, 3:6], noise[:, 6:]), axis=1)[100:]
    assert np.sqrt(np.mean(raw**2)) > 1000.0 * np.sqrt(np.mean(white**2))
    # The noise's projection: its 3 + n - 12 free dimensions of 3 + n, within 10 %.
    expected = np.sqrt(np.mean(white**2) * (3 + n - 12) / (3 + n))
    assert np.sqrt(np.mean(rest**2)) == pytest.approx(expected, rel=0.1)
