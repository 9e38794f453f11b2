"""Tests of systems/residuals/multi_contact.py against exact physics.

The residuals fed to the localizer are computed here from known point forces with Drake
directly: the external residual is the world wrench sum [p x f; f] (moment about the world
origin), the internal one sum J^fb^T f with J^fb = J_j - J_b M_bb^-1 M_bj from
``CalcJacobianTranslationalVelocity`` and ``CalcMassMatrix``. True contacts are sampled as
the contact study samples them (``diagrams/residuals/contact_study/sampling.py::sample_trials``):
a uniform candidate link, a primitive by area, a uniform point of it on the robot's outer
surface, a force of 5-40 N within 60 deg of the inward normal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.multibody.tree import BodyIndex, JacobianWrtVariable
from scipy.stats import multivariate_normal

from systems.residuals.geometry_intersection import (
    BOX,
    CAPSULE,
    CONVEX,
    CYLINDER,
    SPHERE,
    inward_direction,
    outward_normals,
    sample_surface,
    signed_distances,
    surface_areas,
)
from systems.residuals.multi_contact import MultiContactLocalizer, _pair_misfits, surface_grid

#: As the contact study's ``sample_trials``: force magnitude (N) and largest angle to the
#: inward normal (deg).
MIN_FORCE, MAX_FORCE, MAX_ANGLE_DEG = 5.0, 40.0, 60.0
#: The noise added in the noisy tests (averaged residuals): external moment (N m) and force
#: (N) per axis, internal entries (N m); also the localizer's covariances there.
MOMENT_STD, FORCE_STD, INTERNAL_STD = 0.05, 0.1, 0.005
SOLES = ["l_sole", "r_sole"]
LIMBS = {
    "trunk": ("waist", "CHEST", "NECK"),
    "right arm": ("R_SHOULDER", "R_ELBOW", "R_WRIST", "R_HAND"),
    "left arm": ("L_SHOULDER", "L_ELBOW", "L_WRIST", "L_HAND"),
    "right leg": ("R_HIP", "R_KNEE", "R_ANKLE"),
    "left leg": ("L_HIP", "L_KNEE", "L_ANKLE"),
}
#: Two contacts on one limb: upper arm + forearm, elbow + forearm, upper arm + elbow,
#: chest + head.
SAME_LIMB_PAIRS = [
    ("R_SHOULDER_Y_LINK", "R_WRIST_Y_LINK"),
    ("L_SHOULDER_Y_LINK", "L_WRIST_Y_LINK"),
    ("R_ELBOW_P_LINK", "R_WRIST_Y_LINK"),
    ("L_SHOULDER_Y_LINK", "L_ELBOW_P_LINK"),
    ("R_SHOULDER_P_LINK", "R_WRIST_Y_LINK"),
    ("L_SHOULDER_R_LINK", "L_WRIST_R_LINK"),
    ("CHEST_Y_LINK", "NECK_P_LINK"),
    ("R_SHOULDER_Y_LINK", "R_WRIST_R_LINK"),
]


# ---------------------------------------------------------------------------------------
# Fixtures and exact residuals.
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def hrp4(hrp4_moved):
    """hrp4_like standing, arms and torso moved away from the nominal posture (conftest)."""
    plant, scene_graph, _, context = hrp4_moved
    return plant, scene_graph, context


@pytest.fixture(scope="module")
def localizer(hrp4):
    plant, scene_graph, _ = hrp4
    return MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES)


def _sample_contact(plant, context, dut, rng, body_name: str | None = None):
    """(body, p_B, p_W, f_W): a random outer-surface point of a link (uniform link unless
    given, primitive by area) and a push of 5-40 N within 60 deg of its inward normal."""
    geo = dut.geometry
    X_WB = np.array([plant.EvalBodyPoseInWorld(context, b).GetAsMatrix34() for b in dut.candidate_bodies])
    R_WG, p_WG = geo.world_poses(X_WB)
    areas = surface_areas(geo.kinds, geo.params)
    links = np.unique(geo.body_indices)
    for _ in range(1000):
        link = rng.choice(links) if body_name is None else int(plant.GetBodyByName(body_name).index())
        rows = np.flatnonzero(geo.body_indices == link)
        g = rng.choice(rows, p=areas[rows] / areas[rows].sum())
        p_G, n_G = sample_surface(geo.kinds[g], geo.params[g], rng)
        p_W = R_WG[g] @ p_G + p_WG[g]
        if geo.outside_other_links(p_W, R_WG, p_WG, link) and p_W[2] > 0.02:
            break
    else:
        raise AssertionError("no outer-surface point found")
    body = plant.get_body(BodyIndex(int(link)))
    p_B = plant.EvalBodyPoseInWorld(context, body).inverse().multiply(p_W)
    f_W = rng.uniform(MIN_FORCE, MAX_FORCE) * inward_direction(R_WG[g] @ n_G, rng, MAX_ANGLE_DEG)
    return body, p_B, p_W, f_W


def _exact_residuals(plant, context, contacts) -> tuple[np.ndarray, np.ndarray]:
    """(external wrench [sum p x f; sum f], internal residual sum J^fb^T f) of point forces
    [(body, p_B, p_W, f_W)], from Drake's Jacobians and mass matrix."""
    world = plant.world_frame()
    M = plant.CalcMassMatrix(context)
    A = np.linalg.solve(M[:6, :6], M[:6, 6:])
    wrench = np.zeros(6)
    tau = np.zeros(plant.num_velocities() - 6)
    for body, p_B, p_W, f_W in contacts:
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, body.body_frame(), p_B, world, world
        )
        tau += (J[:, 6:] - J[:, :6] @ A).T @ f_W
        wrench += np.concatenate((np.cross(p_W, f_W), f_W))
    return wrench, tau


def _noise(rng, n: int) -> np.ndarray:
    std = np.concatenate(([MOMENT_STD] * 3, [FORCE_STD] * 3, [INTERNAL_STD] * n))
    return std * rng.normal(size=6 + n)


def _limb(name: str) -> str:
    return next(limb for limb, prefixes in LIMBS.items() if name.startswith(prefixes))


def _pair_errors(fit, contacts) -> tuple[bool, list[float], list[float]]:
    """(both links right, position errors (m), relative force errors); errors inf on a
    wrong link (as the contact study counts them)."""
    truth = [int(c[0].index()) for c in contacts]
    if fit.body_indices == tuple(truth):
        order = [0, 1]
    elif fit.body_indices == tuple(truth[::-1]):
        order = [1, 0]
    else:
        return False, [math.inf, math.inf], [math.inf, math.inf]
    pos = [float(np.linalg.norm(fit.points_W[order[k]] - c[2])) for k, c in enumerate(contacts)]
    force = [
        float(np.linalg.norm(fit.forces_W[order[k]] - c[3]) / np.linalg.norm(c[3])) for k, c in enumerate(contacts)
    ]
    return True, pos, force


def _two_contact_cases(plant, context, dut, count: int, seed: int):
    """``count`` seeded pairs: SAME_LIMB_PAIRS first (random points on those links), then
    links on two different limbs."""
    rng = np.random.default_rng(seed)
    names = [b.name() for b in dut.candidate_bodies]
    cases = []
    for k in range(count):
        if k < len(SAME_LIMB_PAIRS):
            a, b = SAME_LIMB_PAIRS[k]
        else:
            while True:
                a, b = rng.choice(names, 2, replace=False)
                if _limb(a) != _limb(b):
                    break
        cases.append([_sample_contact(plant, context, dut, rng, a), _sample_contact(plant, context, dut, rng, b)])
    return cases


# ---------------------------------------------------------------------------------------
# Surface grids.
# ---------------------------------------------------------------------------------------

OCTAHEDRON_PLANES = np.array([[sx, sy, sz, 0.1] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
OCTAHEDRON_PLANES[:, :3] /= math.sqrt(3.0)
OCTAHEDRON_PLANES[:, 3] /= math.sqrt(3.0)


@pytest.mark.parametrize(
    "kind,params,planes",
    [
        (SPHERE, [0.05, 0, 0], None),
        (BOX, [0.1, 0.03, 0.05], None),
        (CYLINDER, [0.04, 0.07, 0], None),
        (CAPSULE, [0.035, 0.065, 0], None),
        (CONVEX, [0, 0, 0], OCTAHEDRON_PLANES),
    ],
)
def test_surface_grid_is_on_the_surface(kind, params, planes):
    """Every grid point lies on the primitive's surface with the outward unit normal
    there, the count follows the area (about area / spacing^2), and the grid is
    deterministic."""
    params = np.array(params, dtype=float)
    spacing = 0.015
    p, n = surface_grid(kind, params, spacing, planes)
    kinds = np.full(len(p), kind)
    all_params = np.tile(params, (len(p), 1))
    all_planes = None if planes is None else np.repeat(planes[None], len(p), 0)
    sd = signed_distances(p[:, None, :], np.array([kind]), params[None], None if planes is None else planes[None])
    np.testing.assert_allclose(sd[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    if kind != BOX:  # a box's outward_normals is ambiguous only on edges; cell centres are not there
        np.testing.assert_allclose(np.einsum("ij,ij->i", n, outward_normals(p, kinds, all_params, all_planes)), 1.0)
    if kind != CONVEX:
        area = surface_areas(np.array([kind]), params[None])[0]
        assert 0.6 < len(p) * spacing**2 / area < 2.0
    p2, _ = surface_grid(kind, params, spacing, planes)
    np.testing.assert_array_equal(p, p2)


# ---------------------------------------------------------------------------------------
# One contact.
# ---------------------------------------------------------------------------------------


def test_one_contact_exact_every_link(hrp4, localizer):
    """One outer-surface push on every candidate link of hrp4_like, exact residuals:
    fit_one finds the link, the point within 1 cm and the force within 1 %; localize says 1
    contact and its p-value is not small (the exact misfit is ~0)."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    rng = np.random.default_rng(11)
    worst_position, worst_force = 0.0, 0.0
    for body in localizer.candidate_bodies:
        contact = _sample_contact(plant, context, localizer, rng, body.name())
        wrench, tau = _exact_residuals(plant, context, [contact])
        fit = localizer.fit_one(q, wrench, tau)
        assert fit.body_indices == (int(body.index()),), body.name()
        worst_position = max(worst_position, float(np.linalg.norm(fit.points_W[0] - contact[2])))
        worst_force = max(worst_force, float(np.linalg.norm(fit.forces_W[0] - contact[3]) / np.linalg.norm(contact[3])))
        result = localizer.localize(q, wrench, tau)
        assert result.num_contacts == 1 and result.body_indices == (int(body.index()),)
        assert result.p_value_one > 0.99 and math.isnan(result.statistic_two)
    print(f"\none contact, every link: worst position error {worst_position:.2e} m, force {worst_force:.2e}")
    assert worst_position < 0.01 and worst_force < 0.01


def test_no_contact_and_joint_stops(hrp4, localizer):
    """Residuals of noise only: 0 contacts. A hand push pressed into a joint stop (the stop
    takes that joint's torque): fit_one still explains the residuals exactly, on the pushed
    link or on its parent (which then needs the stop torque: the two are alike to the
    residuals), and reports the stop torque."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(3)
    assert localizer.localize(q, np.zeros(6), np.zeros(n)).num_contacts == 0
    zeros = [localizer.localize(q, *np.split(_noise(rng, n), [6])).num_contacts == 0 for _ in range(20)]
    assert sum(zeros) >= 19
    limited, signs = localizer.limited_joints(q)
    assert limited.size  # HRP-4's hand J1 joints rest beyond their lower stops in this posture
    pressed = 0
    for _ in range(40):
        contact = _sample_contact(plant, context, localizer, rng, rng.choice(["R_HAND_J1_LINK", "L_HAND_J1_LINK"]))
        wrench, tau = _exact_residuals(plant, context, [contact])
        into = limited[signs * tau[limited] < 0.0]
        if into.size == 0:
            continue
        pressed += 1
        stop_torque = -tau[into]
        tau[into] = 0.0
        fit = localizer.fit_one(q, wrench, tau)
        parent = plant.GetJointByName(contact[0].name().replace("_LINK", "")).parent_body()
        assert fit.body_indices[0] in (int(contact[0].index()), int(parent.index()))
        assert fit.statistic < 1e-6
        if fit.body_indices[0] == int(contact[0].index()):
            reported = dict(zip(fit.limited_joints, fit.stop_torques))
            np.testing.assert_allclose([reported[int(j)] for j in into], stop_torque, rtol=1e-4, atol=1e-6)
    assert pressed >= 5


# ---------------------------------------------------------------------------------------
# Two contacts.
# ---------------------------------------------------------------------------------------


@pytest.mark.slow
def test_two_contacts_exact(hrp4, localizer):
    """24 seeded pairs (8 on one limb, 16 on two limbs), exact residuals.

    Floors: both links right in >= 80 % of the pairs; median position error <= 2 cm and
    median force error <= 5 % over all contacts (a wrong link counts as an infinite
    error); localize says 2 contacts in every pair (every force is >= 5 N). The right-link
    floor is not 100 %: two pushes can be unidentifiable from the residuals (the fit's
    point_std is then inf). A link and its parent are alike when the push barely loads the
    joint between (here: the elbow link taken for the upper arm, the neck pitch link for
    the neck yaw link, both with an exact fit); on one leg the three parallel pitch axes
    leave a family of exact two-contact fits; two links that only a joint on its stop tells
    apart are alike. The search itself should not fail: its misfit stays at the true
    contacts' (0) but for at most two stuck searches (measured: 1, a wrist push taken for
    the hand link next to it)."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    right, positions, forces, stuck = [], [], [], []
    for contacts in _two_contact_cases(plant, context, localizer, 24, seed=21):
        wrench, tau = _exact_residuals(plant, context, contacts)
        result = localizer.localize(q, wrench, tau)
        assert result.num_contacts == 2, [c[0].name() for c in contacts]
        ok, pos, force = _pair_errors(result.two, contacts)
        right.append(ok)
        positions += pos
        forces += force
        stuck.append(result.two.statistic > 1e-3)
    first = _exact_residuals(plant, context, _two_contact_cases(plant, context, localizer, 1, seed=21)[0])
    single = localizer.localize(q, *first, max_contacts=1)
    assert single.num_contacts == 1 and math.isnan(single.statistic_two) and single.p_value_one < 1e-6
    rate = float(np.mean(right))
    print(
        f"\ntwo contacts, exact: right links {rate:.0%} ({sum(right)}/{len(right)}), "
        f"median position error {np.median(positions):.2e} m, median force error {np.median(forces):.2e}, "
        f"searches stuck above the exact fit {sum(stuck)}"
    )
    assert rate >= 0.8
    assert np.median(positions) <= 0.02 and np.median(forces) <= 0.05
    assert sum(stuck) <= 2


def test_noise_false_alarm_and_calibration(hrp4, localizer):
    """Single contacts with Gaussian noise of the localizer's covariances, 200 seeded
    draws: localize says 2 contacts in <= 2 % of them (the tests' false-alarm rate is
    1e-3), and the single-contact statistic is calibrated: the mean of s_1 - dof_1 is
    within 2 of 0 (its standard error is ~0.6), and p < 0.05 in 1-12 % of the draws (5 %
    expected; 5.3 % measured over 600 other draws). ``valid`` (the runner-up link's fit
    worse by more than ``VALID_GAP``) holds for >= 80 % of the draws, and >= 99.5 % of the
    valid results are on the right link (issue 12's precision floor)."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(31)
    excess, p_values, two, right, valid, valid_right = [], [], 0, 0, 0, 0
    for _ in range(200):
        contact = _sample_contact(plant, context, localizer, rng)
        wrench, tau = _exact_residuals(plant, context, [contact])
        noise = _noise(rng, n)
        result = localizer.localize(q, wrench + noise[:6], tau + noise[6:])
        assert result.num_contacts >= 1
        two += result.num_contacts == 2
        right += result.one.body_indices == (int(contact[0].index()),)
        valid += result.valid
        valid_right += result.valid and result.body_indices == (int(contact[0].index()),)
        excess.append(result.statistic_one - result.dof_one)
        p_values.append(result.p_value_one)
    small_p = float(np.mean(np.array(p_values) < 0.05))
    print(
        f"\nnoisy single contacts: 2 contacts in {two}/200, right link {right}/200, "
        f"mean s_1 - dof_1 {np.mean(excess):.2f}, p < 0.05 in {small_p:.1%}, valid {valid} ({valid_right} right)"
    )
    assert valid >= 160 and valid_right >= 0.995 * valid
    assert two <= 4
    assert abs(np.mean(excess)) < 2.0
    assert 0.01 <= small_p <= 0.12


@pytest.mark.slow
def test_noise_two_contacts_detected(hrp4, localizer):
    """Two contacts with the same noise, 40 seeded pairs: localize says 2 in >= 90 %, and
    names both links right in >= 90 %."""
    plant, _, context = hrp4
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(41)
    said_two, right = 0, 0
    for contacts in _two_contact_cases(plant, context, localizer, 40, seed=43):
        wrench, tau = _exact_residuals(plant, context, contacts)
        noise = _noise(rng, n)
        result = localizer.localize(q, wrench + noise[:6], tau + noise[6:])
        said_two += result.num_contacts == 2
        right += result.num_contacts == 2 and _pair_errors(result.two, contacts)[0]
    print(f"\nnoisy two contacts: 2 contacts in {said_two}/40, both links right in {right}/40")
    assert said_two >= 36
    # Measured 38 of 40 (34 before the bound step and the choice by evidence).
    assert right >= 36


def _prepared(plant, context, localizer, seed: int):
    """(pose, whitened data b~ and its stop projection, the true contacts) of one seeded
    noisy two-contact case."""
    q = plant.GetPositions(context)
    contacts = _two_contact_cases(plant, context, localizer, 9, seed=seed)[-1]  # two limbs
    wrench, tau = _exact_residuals(plant, context, contacts)
    noise = _noise(np.random.default_rng(seed), plant.num_velocities() - 6)
    pose, bt, bp = localizer._prepare(q, wrench + noise[:6], tau + noise[6:])
    return pose, bt, bp, contacts


def test_pair_bounds_are_lower_bounds_and_the_point_pairs_exact(hrp4, localizer):
    """The bound step's free-wrench misfit of a link pair is below every pair of point
    forces on those links (here: all pairs of their medium grid points, and the true
    points), and the vectorised pair search's misfits equal a direct least squares
    (numpy's lstsq on the 6 stacked columns) where both forces push in; a pair of
    identical points (the second force in the span of the first's columns: an ill-posed
    3 x 3 solve, rounding noise) is skipped (inf), never a misfit of 0."""
    plant, _, context = hrp4
    pose, _, bp, contacts = _prepared(plant, context, localizer, seed=61)
    localizer._search_points(pose)
    c0 = float(bp @ bp)
    slot_of = {int(b.index()): s for s, b in enumerate(localizer.candidate_bodies)}
    true_slots = sorted(slot_of[int(c[0].index())] for c in contacts)
    rng = np.random.default_rng(62)
    B = len(localizer.candidate_bodies)
    pairs = [tuple(true_slots)] + [tuple(sorted(rng.choice(B, 2, replace=False))) for _ in range(5)]
    a, b = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    bounds, _, _ = localizer._pair_bounds(pose, bp, c0, a, b)
    checked = 0
    for (sa, sb), bound in zip(pairs, bounds):
        Ma, Mb = pose.medium[sa], pose.medium[sb]
        s = _pair_misfits(Ma, Mb, bp, c0)
        finite = np.isfinite(s)
        assert np.all(s[finite] >= bound - 1e-9 * c0)
        for i, j in zip(*np.nonzero(finite)):
            if checked >= 40:
                break
            A = np.concatenate((Ma.cols[i], Mb.cols[j]), axis=1)
            x = np.linalg.lstsq(A, bp, rcond=None)[0]
            assert s[i, j] == pytest.approx(float(np.sum((A @ x - bp) ** 2)), rel=1e-7, abs=1e-9 * c0)
            checked += 1
    assert checked == 40
    points = np.array([c[2] for c in sorted(contacts, key=lambda c: slot_of[int(c[0].index())])])
    A = np.concatenate(list(localizer._point_columns(pose, np.array(true_slots), points)), axis=1)
    x = np.linalg.lstsq(A, bp, rcond=None)[0]
    assert bounds[0] <= float(np.sum((A @ x - bp) ** 2)) + 1e-9 * c0
    Ma = pose.medium[true_slots[0]]
    same = _pair_misfits(Ma, Ma, bp, c0)
    assert np.all(np.isinf(np.diag(same)))


def test_log_evidence_is_the_gaussian_marginal_likelihood(hrp4, localizer):
    """``_log_evidence`` against scipy: for the model linearised at a fit (data b~ = J theta
    + unit noise, theta ~ N(theta_fit, S0), J^T (b~ - J theta_fit) = 0 at a stationary fit),
    the marginal likelihood is the normal density of b~ with mean J theta_fit and covariance
    I + J S0 J^T; the two agree up to the constant rows/2 log(2 pi) (S0 with the link areas
    as the localizer measures them). The data are made exactly stationary at the fitted
    points (the residual's part along J removed)."""
    from systems.residuals.multi_contact import _FORCE_PRIOR_STD, _Candidate

    plant, _, context = hrp4
    pose, bt, bp, _ = _prepared(plant, context, localizer, seed=71)
    fit = localizer._fit_two(pose, bt, bp)
    assert len(fit.body_indices) == 2
    slot_of = {int(b.index()): s for s, b in enumerate(localizer.candidate_bodies)}
    slots = np.array([slot_of[b] for b in fit.body_indices])
    normals = np.array([localizer._project(pose, s, p)[1] for s, p in zip(slots, fit.points_W)])
    cand = _Candidate(slots, fit.points_W, normals, 0.0)
    J, e, _ = localizer._jacobian(pose, bp, cand)
    Q, _ = np.linalg.qr(J)
    e_perp = e - Q @ (Q.T @ e)
    data = bp - e + e_perp
    misfit = localizer._fit_at(pose, data, cand)[0]
    assert misfit == pytest.approx(float(e_perp @ e_perp), rel=1e-9)
    np.testing.assert_allclose(localizer._jacobian(pose, data, cand)[0], J, rtol=1e-9, atol=1e-9 * np.abs(J).max())
    areas = np.array([len(pose.dense.by_slot[s]) for s in slots]) * 0.015**2
    S0 = np.diag(np.concatenate((np.full(6, _FORCE_PRIOR_STD**2), np.repeat(areas / (2 * math.pi), 2))))
    rows = len(bp)
    density = multivariate_normal(mean=data - e_perp, cov=np.eye(rows) + J @ S0 @ J.T).logpdf(data)
    assert localizer._log_evidence(pose, data, cand, misfit) == pytest.approx(
        density + 0.5 * rows * math.log(2 * math.pi), rel=1e-9
    )


def test_bad_input(hrp4, localizer):
    plant, scene_graph, context = hrp4
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    w, r = np.zeros(6), np.zeros(n)
    bad_w = w.copy()
    bad_w[2] = np.nan
    with pytest.raises(ValueError, match="wrench_W has NaN"):
        localizer.fit_one(q, bad_w, r)
    with pytest.raises(ValueError, match=r"residual must have shape \(34,\)"):
        localizer.fit_two(q, w, np.zeros(n + 1))
    with pytest.raises(ValueError, match=r"q must have shape"):
        localizer.localize(q[:-1], w, r)
    bad_q = q.copy()
    bad_q[0] = np.inf
    with pytest.raises(ValueError, match="q has NaN or inf"):
        localizer.localize(bad_q, w, r)
    with pytest.raises(ValueError, match="unit quaternion"):
        localizer.localize(np.concatenate(([2.0], q[1:])), w, r)
    with pytest.raises(ValueError, match="max_contacts"):
        localizer.localize(q, w, r, max_contacts=3)
    make = lambda **kw: MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES, **kw)  # noqa: E731
    with pytest.raises(ValueError, match="covariance_external must be positive definite"):
        make(covariance_external=np.diag([1.0] * 5 + [-1.0]))
    with pytest.raises(ValueError, match="covariance_external must be symmetric"):
        make(covariance_external=np.eye(6) + np.triu(np.ones((6, 6)), 1))
    with pytest.raises(ValueError, match="covariance_internal must be 34 standard deviations or a 34x34"):
        make(covariance_internal=np.eye(3))
    with pytest.raises(ValueError, match="covariance_internal has NaN"):
        make(covariance_internal=np.full(n, np.nan))
    with pytest.raises(ValueError, match="standard deviations must be positive"):
        make(covariance_internal=np.zeros(n))
    with pytest.raises(ValueError, match="false_alarm"):
        make(false_alarm=0.0)
    with pytest.raises(ValueError, match="spacing"):
        make(spacing=-0.01)
    with pytest.raises(ValueError, match="link_pairs"):
        make(link_pairs=0)
    with pytest.raises(ValueError, match="max_link_pairs must be a positive integer"):
        make(max_link_pairs=0)
    with pytest.raises(ValueError, match=r"contact_prior must be one of \('link', 'surface'\), got 'uniform'"):
        make(contact_prior="uniform")
    with pytest.raises(ValueError, match="unknown body"):
        MultiContactLocalizer(plant, scene_graph, exclude_bodies=["nope"])
    with pytest.raises(ValueError, match="SceneGraph"):
        MultiContactLocalizer(plant, "not a scene graph")
    with pytest.raises(ValueError, match="MultibodyPlant"):
        MultiContactLocalizer("not a plant", scene_graph)
    one_link = MultiContactLocalizer(plant, scene_graph, bodies=["CHEST_Y_LINK"])
    with pytest.raises(ValueError, match="at least two candidate links"):
        one_link.fit_two(q, w, r)
    # Explicit covariances (stds or matrices) give the same fit as the defaults they equal.
    stds = make(covariance_external=[0.05] * 3 + [0.1] * 3, covariance_internal=np.diag([0.005**2] * n))
    rng = np.random.default_rng(2)
    wrench, tau = _exact_residuals(plant, context, [_sample_contact(plant, context, localizer, rng)])
    a, b = localizer.fit_one(q, wrench, tau), stds.fit_one(q, wrench, tau)
    assert a.body_indices == b.body_indices
    np.testing.assert_allclose(a.points_W, b.points_W, atol=1e-9)


@pytest.mark.slow
def test_relative_error_accounts_for_a_load_proportional_model_error(hrp4):
    """A model error proportional to the load (each residual entry scaled by 1 + d, d ~
    N(0, 0.03^2): a 3 % torque-scale or inertial error times the contact's effort) on
    single contacts with sensor noise: with the covariances alone the chi-square test
    takes it for a second contact in most draws; with ``relative_error`` = 0.03 it says
    two contacts in <= 5 % of them, and still says two for two real contacts."""
    plant, scene_graph, context = hrp4
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    plain = MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES)
    relative = MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES, relative_error=0.03)
    rng = np.random.default_rng(47)
    says_two = {"plain": 0, "relative": 0}
    draws = 40
    for _ in range(draws):
        contact = _sample_contact(plant, context, relative, rng)
        wrench, tau = _exact_residuals(plant, context, [contact])
        scale = 1.0 + 0.03 * rng.normal(size=6 + n)
        noise = _noise(rng, n)
        w, r = wrench * scale[:6] + noise[:6], tau * scale[6:] + noise[6:]
        says_two["plain"] += plain.localize(q, w, r).num_contacts == 2
        says_two["relative"] += relative.localize(q, w, r).num_contacts == 2
    found_two = 0
    for _ in range(10):
        contacts = [
            _sample_contact(plant, context, relative, rng, name) for name in ("R_ELBOW_P_LINK", "L_KNEE_P_LINK")
        ]
        wrench, tau = _exact_residuals(plant, context, contacts)
        noise = _noise(rng, n)
        found_two += relative.localize(q, wrench + noise[:6], tau + noise[6:]).num_contacts == 2
    print(f"\nload-proportional error: 2 contacts in {says_two} of {draws}; two real contacts found in {found_two}/10")
    assert says_two["plain"] >= draws // 2
    assert says_two["relative"] <= 0.05 * draws
    assert found_two >= 9
    with pytest.raises(ValueError, match="relative_error"):
        MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES, relative_error=-1.0)


def _scaled_contact(plant, context, dut, rng, n: int, body_name: str | None = None):
    """A random single contact (``_sample_contact``) and its residuals with sensor noise and
    a model error proportional to the load: each entry scaled by 1 + d, d ~ N(0, 0.03^2)
    (a 3 % torque-scale or inertial error times the contact's effort)."""
    contact = _sample_contact(plant, context, dut, rng, body_name)
    wrench, tau = _exact_residuals(plant, context, [contact])
    scale = 1.0 + 0.03 * rng.normal(size=6 + n)
    noise = _noise(rng, n)
    return contact, wrench * scale[:6] + noise[:6], tau * scale[6:] + noise[6:]


@pytest.mark.slow
def test_load_covariance_measured_on_known_pushes_accounts_for_the_model_error(hrp4):
    """The study's procedure: the model error per N^2 measured on 60 pushes of known force
    (``load_model_error``; their residuals with sensor noise and a load-proportional error,
    ``_scaled_contact``) and given to the localizer (``load_covariance_*``). On 40 other
    single pushes whose model error is drawn from that covariance times |f|^2, the sensor
    covariances alone take the error for a second contact in a quarter of the draws or more
    and give p < 0.05 in nearly all; with the measured load covariance the localizer says
    two contacts in <= 5 % of the draws, its p-value is below 0.05 in <= 15 %, and two real
    contacts (with the load-proportional error) are still found."""
    from diagrams.residuals.contact_study import load_model_error

    plant, scene_graph, context = hrp4
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    plain = MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES)
    rng = np.random.default_rng(53)
    known = []
    for k in range(60):
        (body, p_B, _, f_W), w, r = _scaled_contact(plant, context, plain, rng, n)
        contact = {"body_index": int(body.index()), "point_body": p_B.tolist(), "force_world": f_W.tolist()}
        known.append(
            {"trial": k, "contacts": [contact], "localizer_inputs": {"q": q, "external_wrench_world": w, "residual": r}}
        )
    S_ext, S_int = load_model_error(plant, known)
    loaded = MultiContactLocalizer(
        plant, scene_graph, exclude_bodies=SOLES, load_covariance_external=S_ext, load_covariance_internal=S_int
    )
    chol = np.linalg.cholesky(np.block([[S_ext, np.zeros((6, n))], [np.zeros((n, 6)), S_int]]) + 1e-12 * np.eye(6 + n))
    draws, says_two, low_p = 40, {"plain": 0, "loaded": 0}, {"plain": 0, "loaded": 0}
    for _ in range(draws):
        contact = _sample_contact(plant, context, plain, rng)
        wrench, tau = _exact_residuals(plant, context, [contact])
        error = np.linalg.norm(contact[3]) * (chol @ rng.normal(size=6 + n)) + _noise(rng, n)
        w, r = wrench + error[:6], tau + error[6:]
        for name, dut in (("plain", plain), ("loaded", loaded)):
            result = dut.localize(q, w, r)
            says_two[name] += result.num_contacts == 2
            low_p[name] += result.p_value_one < 0.05
    found_two = 0
    for _ in range(10):
        contacts = [_sample_contact(plant, context, loaded, rng, name) for name in ("R_ELBOW_P_LINK", "L_KNEE_P_LINK")]
        wrench, tau = _exact_residuals(plant, context, contacts)
        scale = 1.0 + 0.03 * rng.normal(size=6 + n)
        noise = _noise(rng, n)
        found_two += loaded.localize(q, wrench * scale[:6] + noise[:6], tau * scale[6:] + noise[6:]).num_contacts == 2
    print(f"\nload error: 2 contacts in {says_two} of {draws}, p < 0.05 in {low_p}; two found in {found_two}/10")
    assert says_two["plain"] >= draws // 4 and low_p["plain"] >= 0.9 * draws
    assert says_two["loaded"] <= 0.05 * draws
    assert low_p["loaded"] <= 0.15 * draws
    assert found_two >= 9
    with pytest.raises(ValueError, match="load_covariance_internal must be a 34x34"):
        MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES, load_covariance_internal=np.eye(3))
    with pytest.raises(ValueError, match="load_covariance_external must be positive semi-definite"):
        MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES, load_covariance_external=-np.eye(6))
    with pytest.raises(ValueError, match="load_covariance_external has NaN"):
        MultiContactLocalizer(
            plant, scene_graph, exclude_bodies=SOLES, load_covariance_external=np.full((6, 6), np.nan)
        )


def test_load_model_error_measures_what_the_true_contacts_do_not_explain(hrp4):
    """``load_model_error`` (the study's calibration on pushes of known force) against
    Drake's Jacobians and mass matrix (``_exact_residuals``): exact residuals of the true
    contacts leave no model error; a known error e_k added to each trial's inputs comes
    back as sum e e^T / sum |F|^2, F the trial's total force, for one and two contacts."""
    from diagrams.residuals.contact_study import cross_fitting_folds, load_model_error

    plant, scene_graph, context = hrp4
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    dut = MultiContactLocalizer(plant, scene_graph, exclude_bodies=SOLES)
    rng = np.random.default_rng(61)
    trials, injected = [], []
    for k in range(6):
        contacts = [_sample_contact(plant, context, dut, rng) for _ in range(1 + k % 2)]
        wrench, tau = _exact_residuals(plant, context, contacts)
        e = rng.normal(size=6 + n) * 0.05
        injected.append((e, sum(c[3] for c in contacts)))
        specs = [
            {"body_index": int(c[0].index()), "point_body": c[1].tolist(), "force_world": c[3].tolist()}
            for c in contacts
        ]
        exact = {"q": q, "external_wrench_world": wrench, "residual": tau}
        loaded = {"q": q, "external_wrench_world": wrench + e[:6], "residual": tau + e[6:]}
        trials.append(
            (
                {"trial": k, "contacts": specs, "localizer_inputs": exact},
                {"trial": k, "contacts": specs, "localizer_inputs": loaded},
            )
        )
    zero_ext, zero_int = load_model_error(plant, [t[0] for t in trials])
    assert np.abs(zero_ext).max() < 1e-12 and np.abs(zero_int).max() < 1e-12
    S_ext, S_int = load_model_error(plant, [t[1] for t in trials])
    load = sum(float(F @ F) for _, F in injected)
    expected = sum(np.outer(e, e) for e, _ in injected) / load
    np.testing.assert_allclose(S_ext, expected[:6, :6], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(S_int, expected[6:, 6:], rtol=1e-9, atol=1e-14)
    with pytest.raises(ValueError, match="at least one push"):
        load_model_error(plant, [])
    with pytest.raises(ValueError, match="has no 'localizer_inputs'"):
        load_model_error(plant, [{"trial": 3, "contacts": trials[0][0]["contacts"]}])
    # Cross-fitting: one fold per seed; with one seed, the even and the odd trials.
    assert cross_fitting_folds([{"seed": 2}, {"seed": 1}, {"seed": 2}]) == [[1], [0, 2]]
    assert cross_fitting_folds([{"seed": 0}] * 5) == [[0, 2, 4], [1, 3]]
