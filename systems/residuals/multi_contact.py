"""Two simultaneous unknown contacts from the momentum residuals: where, how hard, and how
many (one or two), with a calibrated test (Flacco, Paolillo, Kheddar 2016, eqs. 20, 22).

``MultiContactLocalizer`` (plain Python; the LeafSystem wrapper is separate) fits k = 1 or 2
point forces (p_c on link B_c, f_c) to one sample of the residuals by the stacked, weighted
least squares of eq. (20):

    b = [r_ext; r_int] ~ sum_c A_c f_c,   A_c = [skew(p_c); I; J^fb_c^T]   ((6 + n) x 3)

whitened by the Cholesky factors of the residuals' covariances (W = blockdiag(L_ext^-1,
L_int^-1), cov = L L^T), so that the misfit s = ||W (b - sum A_c f_c)||^2 is a chi-square
variable when the model is right. Forces must push into the surface (f_c . n_c <= 0, n_c
the outward normal): a candidate whose least-squares force pulls is rejected, not clamped.

Lines of action (eq. 22, generalised): the residuals of a force do not depend on where
along its line it acts, so on a link B they depend only on the link's wrench w_B = [m_B; f]
(moment about B's origin, force; world): b = T_B w_B, T_B = [[I, skew(p_B)]; [0, I];
J^fb_B^T] (J^fb_B: the 6 x n floating-base Jacobian of B's origin). The best zero-pitch
wrench (m_B . f = 0: a pure force) on B is a least squares with one quadratic constraint,
solved exactly (a secular equation); its line p_B + (f x m_B) / |f|^2 + s f / |f| (eq. 22
with the wrench fitted to ALL the rows instead of r_ext alone) enters B's primitives at the
contact point: the first entry along f (f . n < 0 there), not buried in another link. With
exact residuals this is the true point, not a grid point.

Candidate points: grids on every collision primitive (``surface_grid``; dense ``spacing``
1.5 cm, ``medium_spacing`` 4 cm, ``coarse_spacing`` 6 cm; links with few points get a few
spread-out dense points instead), kept at each query pose only on the robot's OUTER
surface (outside every other link's primitives).

* One contact (``fit_one``): every link's line entry and every dense grid point (3 x 3
  solves for all at once), the best per link; where one of the two best links has only a
  grid point (its line misses it), that point is polished along the surface
  (Levenberg-Marquardt, tangent steps projected back onto the surface); the best
  ``refit_links`` links are refitted with the joint stops below.
* Two contacts (``fit_two``), a deterministic alternative to the contact particle filter of
  Manuelli & Tedrake ("Localizing external contact using proprioceptive sensors: The
  contact particle filter", IROS 2016), which samples surface points scored by the same
  quadratic-program misfit: (a) ALL pairs of coarse points on different links at once by
  the projection trick (A_i = U_i R_i; b and every A_j projected on the complement of A_i,
  then one 3 x 3 solve per pair, component-wise numpy over the pairs; the parts that depend
  on the pose only are computed once per pose), both forces pushing in, the best pair of
  every link pair; (a') a lower bound of every link pair's misfit: the misfit of two FREE
  wrenches on the two links (12 unknowns, one 12 x 12 solve per pair, all at once; a point
  force is a zero-pitch wrench); (b) the 5 K best link pairs of (a) (K = ``link_pairs``),
  each started from its lines (the entry into each link of the line of its best zero-pitch
  wrench with a free wrench on the other: eq. 22 for two contacts) and from its best pair
  on the medium grids, (c) that one refined on all pairs of dense points within
  ``medium_spacing`` of it; (b') then branch and bound: the other link pairs in increasing
  order of their bounds, the same way, while a bound is below the best misfit found plus
  a margin (at most ``max_link_pairs`` link pairs: the coarse grid alone ranks link pairs
  badly, since the misfit changes by hundreds within a grid spacing); (d) line polish of
  all of them at once: each contact in turn moves to the entry of its link's best
  zero-pitch wrench given the other contact (9 unknowns: that wrench and the other force;
  eq. 22 on what the other contact leaves), a block-coordinate descent that never raises
  the misfit (``polish_iterations`` rounds); the K best link pairs kept and the best four
  polished along their surfaces (Levenberg-Marquardt); (e) the final refits, and the
  choice among them by the evidence below, with the runner-up.

Choosing the link pair by its evidence, not its least misfit: under model errors (the
realistic world), neighbouring links often explain the residuals about equally well (the
misfits of the true pair and of a neighbour pair differ by less than the chi-square's
spread). The Bayesian choice weighs each pair by p(residuals | pair) = integral over its
forces and surface points of the likelihood exp(-s/2) times their prior, which the
particle filter above approximates by sampling; here by Laplace's method (MacKay,
"Bayesian interpolation", Neural Computation 4(3), 1992; Bishop, "Pattern Recognition and
Machine Learning", 2006, Secs. 3.5 and 4.4): log evidence = -s/2 - 1/2 log det(I + S0^1/2
J^T J S0^1/2) + const, J the derivative of the whitened model with respect to the three
force components and two surface coordinates of each contact at the fit, S0 the prior
covariance: each force component broad (``_FORCE_PRIOR_STD``), each surface coordinate
a / (2 pi) with a the link's outer surface area (``contact_prior`` "link": every link
equally likely and the point uniform over it, the study's own sampling of contacts; the
Gaussian of the same peak density). A pair whose fit is sharp (a small region of its links
explains the data) or whose links are large pays an Occam factor.

Joint stops (as ``ContactLocalizer``): a joint within ``limit_margin`` of a position limit
may carry a stop reaction mu_j of the stop's sign (+1 at a lower limit), which the internal
residual sees as external effort. The search leaves these reactions free (their whitened
columns are projected out of every row); the final refits constrain their sign (non-negative
least squares) and ties go to the fit that needs the least stop torque.

Test statistics and model selection (``localize``): s_k, the whitened misfit of the best k
contacts, is chi-square with dof_k = 6 + n - 5 k - E degrees of freedom (3 force and 2
surface coordinates per contact, E stop reactions engaged in the fit) when the model and
the covariances are right. With alpha = ``false_alarm`` and L joints on a stop:

* 0 contacts when s_0 = ||P W b||^2 <= chi2.isf(alpha, 6 + n - L) (the residuals are noise;
  P removes the stop columns);
* else 2 contacts when s_1 > chi2.isf(alpha, dof_1) (one contact does not explain the
  residuals: the calibrated false-alarm test) AND the F-test of the nested models rejects
  one contact: F = ((s_1 - s_2) / 5) / (s_2 / dof_2) > F.isf(alpha, 5, dof_2) (5 more
  parameters; the ratio does not depend on a common error in the covariances' scale, so
  a second contact must also explain much more when both fits are poor, e.g. under model
  errors);
* else 1 contact. ``p_value_one`` = chi2.sf(s_1, dof_1) is the calibrated confidence of a
  single-contact result.

Robots without foot F/T sensors (``unknown_wrench_frames``: the soles): eq. (10) has no
measured wrench to subtract, and the residuals carry the ground's wrenches w_F at known
places. They are nuisance unknowns, handled as the stops' reactions: their whitened
columns T_F (``systems.residuals.contact_estimation.UnknownWrenches``) are projected
out of every row (P removes them with the stops' columns), so every search and test above
runs unchanged on what no ground wrench can explain, with 6 fewer degrees of freedom per
frame (3 for a sole whose FSRs measure its normal force and centre of pressure, the
known wrench; its shear and yaw moment stay unknown); the final refits estimate them
(``ContactFit.unknown_wrenches``). A contact force
whose effect a ground wrench can also produce (on a leg, part of its effect) is seen only
through the rest of it: legs are harder than arms here.

Conventions (as ``systems.residuals.contact_estimation``): ``wrench_W`` = the external
residual = [moment about the WORLD origin, N m; force, N], world frame; ``residual`` = the
internal residual, n = nv - 6 joint efforts in the plant's v[6:] order, N m; a point force
f_W at P on B contributes [p_P x f_W; f_W] and J^fb_P^T f_W, J^fb = J_j - J_b M_bb^-1 M_bj.
Points in world, m; forces in world, N.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import SceneGraph, SceneGraphInspector
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, RigidBody
from scipy.optimize import linprog, nnls
from scipy.stats import chi2
from scipy.stats import f as f_distribution

from systems.common.checks import check_plant, positive_number
from systems.common.topology import rigid_link_of_bodies, same_rigid_link
from systems.residuals.contact_estimation import (
    UnknownWrenches,
    _JointStops,
    _SensedConfiguration,
    _skews,
    candidate_geometry,
    wrench_maps,
)
from systems.residuals.geometry_intersection import (
    BOX,
    CAPSULE,
    CONVEX,
    CYLINDER,
    SPHERE,
    RobotGeometry,
    line_intersections,
    outward_normals,
    signed_distances,
)

__all__ = [
    "DEFAULT_EXTERNAL_FORCE_STD",
    "DEFAULT_EXTERNAL_MOMENT_STD",
    "DEFAULT_INTERNAL_STD",
    "VALID_GAP",
    "ContactFit",
    "MultiContactLocalizer",
    "MultiContactResult",
    "surface_grid",
]

#: Default noise of the AVERAGED residuals (the localizer's inputs): standard deviations
#: of the external moment (N m) and force (N) per axis and of each internal residual entry
#: (N m). Round values of the order of the residual noise after ~1 s of averaging in the
#: contact study (hrp4_like, K = 35/s: the detector's ~0.28 N per-axis external force noise
#: over ~15 independent samples; moments about the world origin with ~0.5 m lever arms).
#: Pass the covariances of your own residuals for a calibrated test.
DEFAULT_EXTERNAL_MOMENT_STD = 0.05
DEFAULT_EXTERNAL_FORCE_STD = 0.1
DEFAULT_INTERNAL_STD = 0.005
#: A single-contact result is ``valid`` when every other link's best fit is worse by more
#: than this in the whitened misfit: chi2.isf(0.01, 1), a likelihood-ratio criterion at
#: 1 % (the two links' fits differ in where they place one point force): issue 12 asks that
#: fewer than 0.5 % of the valid results be wrong, which a 5 % criterion (3.84) does not
#: promise (194 of 195 right on 200 noisy draws, tests/test_multi_contact.py).
VALID_GAP = float(chi2.isf(0.01, 1))

_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
_POLISH_TOLERANCE = 1e-4  # m: the line polish stops early when no point moves more than this
_LM_ITERATIONS = 15  # at most, of the surface Levenberg-Marquardt polish
_MAX_STEP = 0.02  # m, its largest tangent step per contact
_LM_GAIN = 1e-6  # it stops when an iteration gains less than this times the misfit (or moves < 0.1 um)
_LM_CANDIDATES = 4  # fit_two polishes the best this many link pairs with it (fit_one: 2 links)
_MEDIUM_PAIRS = 5  # times link_pairs: the link pairs searched on the medium grids
_PAIR_BLOCK = 8192  # point pairs per block of the vectorised pair search (cache-sized arrays)
#: The pair searches skip a pair of points whose 3 x 3 Schur complement S (the second
#: force's columns projected off the first's) has a trace below ``_WELL_POSED`` times its
#: Gram matrix's or a determinant below ``_WELL_POSED`` times (trace / 3)^3 (the second
#: force nearly in the span of the first's columns: the solve is rounding noise), and a
#: misfit below -``_ROUNDING`` relative to |b|^2.
_WELL_POSED = 1e-10
_ROUNDING = 1e-9
#: fit_two's bound step goes on while a link pair's lower bound is below the best misfit
#: found plus this (whitened chi-square units): the answer is chosen by the evidence, which
#: may prefer a pair of slightly larger misfit (its Occam factor, a few units of log).
_BOUND_MARGIN = 10.0
_BOUND_BATCH = 10  # link pairs refined per round of the bound step
#: The evidence's force prior: each force component N(0, this^2), N. Nearly the same for
#: every link pair (the forces are well determined); it only needs to be broad.
_FORCE_PRIOR_STD = 20.0
CONTACT_PRIORS = ("link", "surface")


# ---------------------------------------------------------------------------------------
# Results.
# ---------------------------------------------------------------------------------------


@dataclass
class ContactFit:
    """The best k point contacts (``fit_one``: k = 1, ``fit_two``: k = 2). Units: m, N, N m.

    Attributes:
        body_indices: the k links (plant BodyIndex); () when no candidate was feasible.
        points_W: (k, 3) contact points, world.
        forces_W: (k, 3) forces, world.
        statistic: the whitened squared misfit s_k (inf when no candidate was feasible).
        dof: its chi-square degrees of freedom, 6 + n - 5 k - (stop reactions engaged) - 6
            per unknown wrench frame.
        runner_up_statistic: s_k of the runner-up: the best fit with another link (k = 1),
            the link pair of the next largest evidence (k = 2).
        runner_up_body_indices: those links (() if none).
        limited_joints: joints (v[6:] order) taken as resting on a position limit.
        stop_torques: their stop reactions in the fit (N m, signed as joint efforts).
        point_std: (k,) 1-sigma position uncertainty of each contact along its surface, m:
            the Cramer-Rao bound from the whitened rows at the fit (inf where the residuals
            cannot place the contact, e.g. two contacts on one leg, whose parallel pitch
            axes leave a family of exact fits).
        force_std: (k,) the same for the forces (root of the trace of their covariance), N.
        log_evidence: ``fit_two`` (k = 2): the Laplace approximation of the log evidence of
            this link pair (module docstring), up to a constant shared by all pairs; the
            pair is the one of the largest evidence, not always of the least misfit. nan for
            k = 1.
        runner_up_log_evidence: the runner-up pair's (``runner_up_body_indices``) for k = 2.
        unknown_wrenches: (m, 6) the wrenches at the localizer's ``unknown_wrench_frames``
            in this fit, [moment about the frame's origin, N m; force, N], world ((0, 6)
            without such frames; a sole with FSRs: only its unknown shear and yaw).
    """

    body_indices: tuple[int, ...]
    points_W: np.ndarray
    forces_W: np.ndarray
    statistic: float
    dof: int
    runner_up_statistic: float = math.inf
    runner_up_body_indices: tuple[int, ...] = ()
    limited_joints: tuple[int, ...] = ()
    stop_torques: np.ndarray = field(default_factory=lambda: np.zeros(0))
    point_std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    force_std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    log_evidence: float = math.nan
    runner_up_log_evidence: float = math.nan
    unknown_wrenches: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))

    @property
    def p_value(self) -> float:
        """chi2.sf(statistic, dof): the probability of a misfit this large if the fit is right."""
        return float(chi2.sf(self.statistic, self.dof)) if math.isfinite(self.statistic) else 0.0


@dataclass
class MultiContactResult:
    """``MultiContactLocalizer.localize``'s answer. Units: m, N.

    Attributes:
        num_contacts: 0, 1 or 2 (module docstring's model selection).
        body_indices: the links of the chosen model's contacts (plant BodyIndex).
        points_W: (num_contacts, 3), world. forces_W: (num_contacts, 3), world.
        statistic_zero: s_0 = ||P W b||^2 (no contact; P removes the stop columns and the
            unknown wrenches' columns).
        statistic_one, statistic_two: s_1, s_2 (nan when not computed: s_1 with 0 contacts,
            s_2 when one contact explains the residuals or ``max_contacts`` is 1).
        dof_one, dof_two: their degrees of freedom (without a fit: 6 + n - 5 k - L - 6 m, L
            joints on a stop, m unknown wrench frames).
        p_value_one: chi2.sf(s_1, dof_1), the single-contact fit's calibrated confidence
            (nan when not computed).
        one, two: the fits themselves (None when not computed).
    """

    num_contacts: int
    body_indices: tuple[int, ...]
    points_W: np.ndarray
    forces_W: np.ndarray
    statistic_zero: float
    statistic_one: float
    statistic_two: float
    dof_one: int
    dof_two: int
    p_value_one: float
    one: ContactFit | None = None
    two: ContactFit | None = None

    @property
    def valid(self) -> bool:
        """One contact, and every other link's best single fit worse by more than
        ``VALID_GAP`` (the answer's link is not ambiguous)."""
        one = self.one
        return self.num_contacts == 1 and one is not None and one.runner_up_statistic - one.statistic > VALID_GAP

    @property
    def contacts(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """[(body index, point_W, force_W)] of the chosen model."""
        return [(b, p, f) for b, p, f in zip(self.body_indices, self.points_W, self.forces_W)]


# ---------------------------------------------------------------------------------------
# Surface grids.
# ---------------------------------------------------------------------------------------


def _fibonacci_sphere(count: int) -> np.ndarray:
    """(count, 3) nearly uniform unit vectors (Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    rho = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = _GOLDEN_ANGLE * np.arange(count)
    return np.stack((rho * np.cos(phi), rho * np.sin(phi), z), axis=1)


def _cells(half: float, spacing: float) -> np.ndarray:
    """Centres of ceil(2 half / spacing) equal cells of [-half, half]."""
    count = max(1, math.ceil(2.0 * half / spacing - 1e-9))
    return -half + (np.arange(count) + 0.5) * (2.0 * half / count)


def _disc(radius: float, spacing: float) -> np.ndarray:
    """(m, 2) points covering a disc: rings at (k + 1/2) radius / rings."""
    rings = max(1, math.ceil(radius / spacing - 1e-9))
    out = []
    for k in range(rings):
        rho = (k + 0.5) * radius / rings
        count = max(3, math.ceil(2.0 * math.pi * rho / spacing - 1e-9))
        phi = (np.arange(count) + 0.5 * (k % 2)) * 2.0 * math.pi / count
        out.append(np.stack((rho * np.cos(phi), rho * np.sin(phi)), axis=1))
    return np.concatenate(out)


def _convex_grid(planes: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points of a convex polytope's surface (half-spaces n . x <= c) by rays from its
    Chebyshev centre (denser where the surface is nearer the centre)."""
    rows = planes[np.isfinite(planes[:, 3])]
    # Chebyshev centre: max t s.t. n . x + t <= c (|n| = 1).
    res = linprog(
        c=[0.0, 0.0, 0.0, -1.0],
        A_ub=np.hstack((rows[:, :3], np.ones((len(rows), 1)))),
        b_ub=rows[:, 3],
        bounds=[(None, None)] * 3 + [(0.0, None)],
    )
    if not res.success:
        raise ValueError("a convex collision shape has no interior")
    centre = res.x[:3]
    kinds = np.full(1, CONVEX)
    params = np.zeros((1, 3))

    def cast(directions: np.ndarray) -> np.ndarray:
        m = len(directions)
        _, l_out, _ = line_intersections(
            np.tile(centre, (m, 1)), directions, np.full(m, CONVEX), np.zeros((m, 3)), np.repeat(planes[None], m, 0)
        )
        return centre + l_out[:, None] * directions

    first = cast(_fibonacci_sphere(200))
    radius = float(np.sqrt(np.mean(np.sum((first - centre) ** 2, axis=1))))
    points = cast(_fibonacci_sphere(max(20, math.ceil(4.0 * math.pi * radius**2 / spacing**2))))
    normals = np.array([outward_normals(p[None], kinds, params, planes[None])[0] for p in points])
    return points, normals


def surface_grid(
    kind: int, params: np.ndarray, spacing: float, planes: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic points about ``spacing`` apart on a primitive's surface, and the outward
    unit normals there, in the primitive's frame G (``geometry_intersection`` conventions).

    Boxes: cell centres of every face; cylinders: rings on the side and on the caps;
    spheres and the capsules' end caps: Fibonacci lattices; convex hulls (``planes``): rays
    from the Chebyshev centre. Every face gets at least one point.

    Args:
        kind, params: SPHERE/BOX/CYLINDER/CAPSULE/CONVEX and its parameters, m.
        spacing: m, > 0.
        planes: (P, 4) face planes [n, c] of a CONVEX primitive.

    Returns:
        (p_G (m, 3), n_G (m, 3)).
    """
    h = positive_number(spacing, "surface_grid: spacing")
    params = np.asarray(params, dtype=float)
    r, half = float(params[0]), float(params[1])
    if kind == SPHERE:
        n = _fibonacci_sphere(max(4, math.ceil(4.0 * math.pi * r * r / (h * h))))
        return r * n, n
    if kind == BOX:
        pts, nrm = [], []
        for axis in range(3):
            u, v = [a for a in range(3) if a != axis]
            gu, gv = np.meshgrid(_cells(params[u], h), _cells(params[v], h), indexing="ij")
            for sign in (1.0, -1.0):
                p = np.zeros((gu.size, 3))
                p[:, u], p[:, v], p[:, axis] = gu.ravel(), gv.ravel(), sign * params[axis]
                n = np.zeros_like(p)
                n[:, axis] = sign
                pts.append(p)
                nrm.append(n)
        return np.concatenate(pts), np.concatenate(nrm)
    if kind in (CYLINDER, CAPSULE):
        count = max(4, math.ceil(2.0 * math.pi * r / h - 1e-9))
        phi = np.arange(count) * 2.0 * math.pi / count
        z = _cells(half, h)
        gphi, gz = np.meshgrid(phi, z, indexing="ij")
        n_side = np.stack((np.cos(gphi.ravel()), np.sin(gphi.ravel()), np.zeros(gphi.size)), axis=1)
        p_side = r * n_side + np.outer(gz.ravel(), [0.0, 0.0, 1.0])
        if kind == CYLINDER:
            disc = _disc(r, h)
            caps_p, caps_n = [], []
            for sign in (1.0, -1.0):
                caps_p.append(np.column_stack((disc, np.full(len(disc), sign * half))))
                caps_n.append(np.tile([0.0, 0.0, sign], (len(disc), 1)))
            return np.concatenate([p_side, *caps_p]), np.concatenate([n_side, *caps_n])
        n_ends = _fibonacci_sphere(max(8, math.ceil(4.0 * math.pi * r * r / (h * h))))
        p_ends = r * n_ends + np.outer(np.where(n_ends[:, 2] >= 0.0, half, -half), [0.0, 0.0, 1.0])
        return np.concatenate((p_side, p_ends)), np.concatenate((n_side, n_ends))
    if kind == CONVEX:
        if planes is None:
            raise ValueError("surface_grid: a CONVEX primitive needs its planes")
        return _convex_grid(np.asarray(planes, dtype=float), h)
    raise ValueError(f"surface_grid: unknown primitive kind {kind}")


# ---------------------------------------------------------------------------------------
# Small batched linear algebra.
# ---------------------------------------------------------------------------------------


def _solve3(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with A x = b for stacks of 3 x 3 systems (Cramer's rule, vectorised); nan where A
    is singular to working precision."""
    c0 = _cross(A[..., 1, :], A[..., 2, :])
    c1 = _cross(A[..., 2, :], A[..., 0, :])
    c2 = _cross(A[..., 0, :], A[..., 1, :])
    det = np.einsum("...i,...i->...", A[..., 0, :], c0)
    scale = np.abs(A).max(axis=(-2, -1)) ** 3
    ok = np.abs(det) > 1e-13 * scale
    adj_b = np.stack((c0, c1, c2), axis=-1) @ b[..., None]  # (A^-1 = [c0 c1 c2] / det)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = adj_b[..., 0] / det[..., None]
    return np.where(ok[..., None], x, np.nan)


def _bounding_radius(kind: int, params: np.ndarray, planes: np.ndarray) -> float:
    """Radius of a ball about the primitive frame's origin that contains the primitive, m."""
    r, h = float(params[0]), float(params[1])
    if kind == SPHERE:
        return r
    if kind == BOX:
        return float(np.linalg.norm(params))
    if kind == CYLINDER:
        return math.hypot(r, h)
    if kind == CAPSULE:
        return r + h
    # CONVEX: the farthest hull point along many directions from the origin.
    directions = _fibonacci_sphere(400)
    count = len(directions)
    _, l_out, hit = line_intersections(
        np.zeros((count, 3)),
        directions,
        np.full(count, CONVEX),
        np.zeros((count, 3)),
        np.repeat(planes[None], count, 0),
    )
    _, l_back, _ = line_intersections(
        np.zeros((count, 3)),
        -directions,
        np.full(count, CONVEX),
        np.zeros((count, 3)),
        np.repeat(planes[None], count, 0),
    )
    reach = np.concatenate((np.abs(l_out[hit]), np.abs(l_back[hit])))
    return 1.05 * float(reach.max()) + 1e-3 if reach.size else math.inf


def _zero_pitch_solve(H: np.ndarray, g: np.ndarray) -> np.ndarray:
    """argmin x^T H x - 2 g^T x subject to x[:3] . x[3:6] = 0, for stacks (B, d, d), (B, d).

    Stationarity: (H + lam Q) x = g with x^T Q x = m . f (Q symmetric, indefinite). With
    H = L L^T and L^-1 Q L^-T = V diag(mu) V^T, y = L^T x, h = V^T L^-1 g, the constraint is
    phi(lam) = sum mu_i h_i^2 / (1 + lam mu_i)^2 = 0: decreasing on the interval where
    H + lam Q is positive definite, (-1 / max mu, -1 / min mu), whose root is the global
    minimum (one quadratic constraint). Found by Newton's method safeguarded by bisection;
    where there is no sign change (degenerate data) the unconstrained minimum is returned.
    """
    d = H.shape[-1]
    Q = np.zeros((d, d))
    Q[0:3, 3:6] = Q[3:6, 0:3] = 0.5 * np.eye(3)
    # A relative jitter keeps degenerate stacks (e.g. two links that only a joint on its stop
    # tells apart) solvable; their answers are then arbitrary and lose in the final refits.
    jitter = 1e-12 * np.trace(H, axis1=-2, axis2=-1)[:, None, None] / d
    L = np.linalg.cholesky(H + jitter * np.eye(d))
    Linv = np.linalg.inv(L)
    mu, V = np.linalg.eigh(Linv @ Q @ np.swapaxes(Linv, -1, -2))
    h = np.einsum("bji,bj->bi", V, np.einsum("bij,bj->bi", Linv, g))
    lam = np.array([_secular_root(mu[k].tolist(), h[k].tolist()) for k in range(len(H))])
    y = V @ (h / (1.0 + lam[:, None] * mu))[..., None]
    return np.einsum("bji,bj->bi", Linv, y[..., 0])  # x = L^-T y


def _secular_root(mu: list, h: list, iterations: int = 100) -> float:
    """The root of phi(lam) = sum mu_i h_i^2 / (1 + lam mu_i)^2 in (-1 / max mu, -1 / min mu)
    (``_zero_pitch_solve``; mu ascending), or 0.0 when phi does not change sign there."""
    w = [m * x * x for m, x in zip(mu, h)]
    total = sum(abs(v) for v in w)
    if not (mu[-1] > 0.0 > mu[0]) or total == 0.0:
        return 0.0
    lo, hi = -1.0 / mu[-1], -1.0 / mu[0]
    width = hi - lo

    def phi(lam: float) -> tuple[float, float]:
        value = slope = 0.0
        for m, v in zip(mu, w):
            inv = 1.0 / (1.0 + lam * m)
            value += v * inv * inv
            slope -= 2.0 * m * v * inv * inv * inv
        return value, slope

    a, b = lo + 1e-12 * width, hi - 1e-12 * width
    if not (phi(a)[0] > 0.0 > phi(b)[0]):
        return 0.0
    lam = 0.0
    for _ in range(iterations):
        value, slope = phi(lam)
        if value > 0.0:
            a = lam
        else:
            b = lam
        step = lam - value / slope if slope != 0.0 else math.nan
        new = step if a < step < b else 0.5 * (a + b)  # Newton, else bisection
        if abs(new - lam) <= 1e-13 * width or abs(value) <= 1e-14 * total:
            return new
        lam = new
    return lam


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (broadcasting; cheaper than np.cross for small arrays)."""
    a, b = np.asarray(a), np.asarray(b)
    return np.stack(
        (
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ),
        axis=-1,
    )


def _tangents(n: np.ndarray) -> np.ndarray:
    """(3, 2) an orthonormal basis of the plane normal to the unit vector n."""
    a = _cross(n, np.array([1.0, 0.0, 0.0]))
    if a @ a < 0.01:
        a = _cross(n, np.array([0.0, 1.0, 0.0]))
    a = a / math.sqrt(a @ a)
    return np.stack((a, _cross(n, a)), axis=1)


def _closest_surface_point(p: np.ndarray, kind: int, params: np.ndarray, planes: np.ndarray) -> tuple:
    """(q, n): the point of a primitive's SURFACE nearest to p (inside or out) and the
    outward unit normal there, in the primitive's frame."""
    r, h = float(params[0]), float(params[1])
    if kind in (SPHERE, CAPSULE):
        c = np.array([0.0, 0.0, float(np.clip(p[2], -h, h)) if kind == CAPSULE else 0.0])
        d = p - c
        norm = np.linalg.norm(d)
        n = d / norm if norm > 1e-12 else np.array([1.0, 0.0, 0.0])
        return c + r * n, n
    if kind == CYLINDER:
        rho = math.hypot(p[0], p[1])
        radial = p[:2] / rho if rho > 1e-12 else np.array([1.0, 0.0])
        side = np.array([r * radial[0], r * radial[1], float(np.clip(p[2], -h, h))])
        sign = 1.0 if p[2] >= 0.0 else -1.0
        cap = np.array([*(p[:2] * min(1.0, r / rho) if rho > 1e-12 else p[:2]), sign * h])
        if np.linalg.norm(side - p) <= np.linalg.norm(cap - p):
            return side, np.array([radial[0], radial[1], 0.0])
        return cap, np.array([0.0, 0.0, sign])
    if kind == BOX:
        q = np.clip(p, -params, params)
        if np.array_equal(q, p):  # inside: the nearest face
            axis = int(np.argmax(np.abs(p) - params))
            q[axis] = params[axis] if p[axis] >= 0.0 else -params[axis]
        n = outward_normals(q[None], np.array([BOX]), params[None])[0]
        return q, n
    # CONVEX: a few projections onto the most violated face plane.
    q = p.copy()
    rows = planes[np.isfinite(planes[:, 3])]
    for _ in range(4):
        dist = rows[:, :3] @ q - rows[:, 3]
        face = int(np.argmax(dist))
        q = q - dist[face] * rows[face, :3]
    n = outward_normals(q[None], np.array([CONVEX]), np.zeros((1, 3)), planes[None])[0]
    return q, n


def _signed_distance(p: np.ndarray, kind: int, params: np.ndarray, planes: np.ndarray) -> float:
    """Signed distance of one point (primitive frame) to a primitive, m (as
    ``geometry_intersection.signed_distances``, for a single point)."""
    x, y, z = float(p[0]), float(p[1]), float(p[2])
    r, h = float(params[0]), float(params[1])
    if kind == SPHERE:
        return math.sqrt(x * x + y * y + z * z) - r
    if kind == CAPSULE:
        z -= min(max(z, -h), h)
        return math.sqrt(x * x + y * y + z * z) - r
    if kind == BOX:
        q = (abs(x) - params[0], abs(y) - params[1], abs(z) - params[2])
    elif kind == CYLINDER:
        q = (math.hypot(x, y) - r, abs(z) - h)
    else:
        rows = planes[np.isfinite(planes[:, 3])]
        return float(np.max(rows[:, :3] @ p - rows[:, 3]))
    outside = math.sqrt(sum(max(v, 0.0) ** 2 for v in q))
    return outside + min(max(q), 0.0)


# ---------------------------------------------------------------------------------------
# Per-configuration data.
# ---------------------------------------------------------------------------------------


@dataclass
class _Points:
    """Candidate points on the outer surface at one pose."""

    slot: np.ndarray  # (m,) the link's position in the candidate list
    p_W: np.ndarray  # (m, 3)
    n_W: np.ndarray  # (m, 3) outward normals
    cols: np.ndarray  # (m, rows, 3) whitened, stop-projected columns
    gram: np.ndarray  # (m, 3, 3) cols^T cols
    by_slot: list  # per link: indices into these arrays

    def subset(self, index: np.ndarray) -> _Points:
        return _Points(self.slot[index], self.p_W[index], self.n_W[index], self.cols[index], self.gram[index], [])


def _concatenate(parts: list[_Points]) -> _Points:
    """One _Points of several (by_slot rebuilt)."""
    cat = {name: np.concatenate([getattr(p, name) for p in parts]) for name in ("slot", "p_W", "n_W", "cols", "gram")}
    slots = int(max((p.slot.max() for p in parts if len(p.slot)), default=-1)) + 1
    by_slot = [np.flatnonzero(cat["slot"] == b) for b in range(max(slots, len(parts)))]
    return _Points(cat["slot"], cat["p_W"], cat["n_W"], cat["cols"], cat["gram"], by_slot)


def _spread(points: np.ndarray, count: int) -> np.ndarray:
    """Indices of up to ``count`` well-spread points (deterministic farthest-point sampling
    from the first point)."""
    if len(points) <= count:
        return np.arange(len(points))
    chosen = [0]
    distance = np.linalg.norm(points - points[0], axis=1)
    for _ in range(count - 1):
        k = int(np.argmax(distance))
        chosen.append(k)
        distance = np.minimum(distance, np.linalg.norm(points - points[k], axis=1))
    return np.array(sorted(chosen))


@dataclass
class _Pose:
    key: bytes
    X_WB: np.ndarray  # (B, 3, 4)
    R_WG: np.ndarray  # (g, 3, 3)
    p_WG: np.ndarray  # (g, 3)
    Tw: np.ndarray  # (B, rows, 6) whitened link maps
    Tp: np.ndarray  # (B, rows, 6) whitened, stop-projected
    P: np.ndarray  # (rows, rows) projector onto the complement of the stop columns
    limited: np.ndarray  # (L,) joint indices
    signs: np.ndarray  # (L,) their stops' signs
    stops: np.ndarray  # (rows, L) whitened stop columns times the stops' signs
    unknown: np.ndarray  # (rows, size) whitened columns of the unknown wrenches' components
    unknown_to_world: np.ndarray  # (6 m, size) their values -> the wrenches in world
    dense: _Points | None = None
    search: _Points | None = None  # the pair search's points, by link
    pairs: dict | None = None  # ``_pair_precomputation`` of the search points, once needed
    medium: list = field(default_factory=list)  # per link: the medium grid's _Points


@dataclass
class _Candidate:
    """k contacts during the search (points on the outer surface)."""

    slots: np.ndarray  # (k,)
    points: np.ndarray  # (k, 3)
    normals: np.ndarray  # (k, 3)
    misfit: float
    on_line: bool = False  # a line entry of fit_one (already its link's best point)


# ---------------------------------------------------------------------------------------
# MultiContactLocalizer.
# ---------------------------------------------------------------------------------------


class MultiContactLocalizer:
    """One or two simultaneous unknown point contacts from the external and internal
    residuals (module docstring: method, statistics, model selection).

    Args:
        plant: finalized floating-base plant (free joint coordinates first).
        scene_graph: its SceneGraph or a SceneGraphInspector (the collision shapes).
        bodies: candidate links (RigidBody, names or indices); default every body with a
            collision geometry, minus ``exclude_bodies``.
        exclude_bodies: links never considered (e.g. the soles below F/T sensors).
        covariance_external: 6 x 6 covariance of the (averaged) external residual,
            [moment (N m); force (N)] (or 6 standard deviations). Default: diagonal, from
            ``DEFAULT_EXTERNAL_MOMENT_STD`` (0.05 N m) and ``DEFAULT_EXTERNAL_FORCE_STD``
            (0.1 N).
        covariance_internal: n x n covariance of the (averaged) internal residual, N^2 m^2
            (or n standard deviations). Default: (``DEFAULT_INTERNAL_STD`` = 0.005 N m)^2 I.
        false_alarm: alpha of the tests in ``localize``, in (0, 1) (default 1e-3).
        spacing: dense grid spacing, m (default 0.015).
        medium_spacing, coarse_spacing: the pair search's grids, m (defaults 0.04, 0.06;
            coarse 0.08 m left the true pair of links out of the search in 5 of 60 realistic
            two-contact trials, 0.06 m in 1, at 1.6 times the cost).
            A link with fewer than ``min_search_points`` coarse points (twice as many
            medium ones) on the outer surface gets that many spread-out dense points.
        min_search_points: see above (default 6).
        link_pairs: K, the link pairs refitted in ``fit_two`` (default 6; 5 K are searched
            on the medium grids).
        polish_iterations: rounds of line steps per polish (default 2).
        refit_links: best links refitted with sign-constrained stops in ``fit_one`` (and
            the runner-up taken among), default 6.
        surface_tolerance: m, a point deeper than this inside another link's primitive is
            not on the robot's surface (default 0.01).
        limit_margin: rad (m): joints this close to a position limit rest on it (default
            0.01); None: no joint does.
        skip_unsupported_shapes: ignore shapes other than spheres, boxes, cylinders,
            capsules and convex meshes instead of raising.
        relative_error: eps >= 0, a model error proportional to the load (e.g. a motor-torque
            scale error, or a model's inertial error, times the contact's effort): each call
            whitens with the covariances plus diag((eps b)^2), b its own inputs (default 0:
            the covariances alone, right for sensor noise on an exact model).
        max_link_pairs: at most this many link pairs refined in ``fit_two`` (the K best
            coarse ones and the bound step's, default 100).
        contact_prior: where an unknown contact is a priori, for ``fit_two``'s choice of
            link pair by the evidence: "link" (default: every candidate link equally likely,
            the point uniform over that link's outer surface) or "surface" (the point
            uniform over the robot's whole outer surface: large links likelier).
        load_covariance_external, load_covariance_internal: a model error that grows with
            the load, as covariances per N^2 of the total external force (6 x 6 and n x n):
            each call whitens with the covariances plus |f|^2 times these, f the external
            residual's force (its inputs' ``wrench_W[3:]``). Measured on pushes of known
            force (``diagrams.residuals.contact_study.offline.load_model_error``); default
            None: no such term.
        unknown_wrench_frames: frames (or names) whose wrenches are unknowns (module
            docstring): the soles of a robot without foot F/T sensors, whose residuals were
            computed without ``known_wrench_frames``. Default () (F/T sensors measure them).
        unknown_wrench_components: per unknown wrench frame, its unknown components
            (``systems.residuals.contact_estimation.UnknownWrenches``; the shear and yaw of a
            sole with FSRs); None: all six.

    Raises:
        ValueError: a bad plant, scene graph, body, frame, covariance (shape, NaN,
            asymmetric, not positive definite) or setting.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        scene_graph: SceneGraph | SceneGraphInspector,
        *,
        bodies: Sequence | None = None,
        exclude_bodies: Sequence = (),
        covariance_external=None,
        covariance_internal=None,
        false_alarm: float = 1e-3,
        spacing: float = 0.015,
        coarse_spacing: float = 0.06,
        medium_spacing: float = 0.04,
        min_search_points: int = 6,
        link_pairs: int = 6,
        polish_iterations: int = 2,
        refit_links: int = 6,
        surface_tolerance: float = 0.01,
        limit_margin: float | None = 0.01,
        skip_unsupported_shapes: bool = False,
        relative_error: float = 0.0,
        load_covariance_external=None,
        load_covariance_internal=None,
        max_link_pairs: int = 100,
        contact_prior: str = "link",
        unknown_wrench_frames: Sequence = (),
        unknown_wrench_components: Sequence | None = None,
    ):
        who = self._who = "MultiContactLocalizer"
        check_plant(plant, who)
        self._kin = kin = _SensedConfiguration(plant, who)
        self._plant = plant
        self._unknown = UnknownWrenches(plant, unknown_wrench_frames, unknown_wrench_components, who)
        self._geometry, self._bodies = candidate_geometry(
            plant, scene_graph, bodies, exclude_bodies, who, skip_unsupported_shapes
        )
        geo = self._geometry
        self._rigid_link = rigid_link_of_bodies(plant)  # welded bodies are one link
        self._n = n = kin.n
        self._rows = 6 + n
        # Degrees of freedom of the rows after the unknown wrenches are projected out.
        self._free_rows = self._rows - self._unknown.size
        if self._free_rows < 11:
            raise ValueError(
                f"{who}: {len(self._unknown)} unknown wrenches leave {self._free_rows} of the {self._rows} "
                f"residual rows, fewer than two contacts need"
            )
        default_ext = np.array([DEFAULT_EXTERNAL_MOMENT_STD] * 3 + [DEFAULT_EXTERNAL_FORCE_STD] * 3)
        self._L_ext_inv = self._whitener(covariance_external, 6, "covariance_external", default_ext)
        self._L_int_inv = self._whitener(
            covariance_internal, n, "covariance_internal", np.full(n, DEFAULT_INTERNAL_STD)
        )
        # The covariances themselves (L L^T), for the load-proportional term.
        self._cov_ext = np.linalg.inv(self._L_ext_inv.T @ self._L_ext_inv)
        self._cov_int = np.linalg.inv(self._L_int_inv.T @ self._L_int_inv)
        self._relative_error = float(relative_error)
        if not (math.isfinite(self._relative_error) and self._relative_error >= 0.0):
            raise ValueError(f"{who}: relative_error must be finite and non-negative, got {relative_error!r}")
        self._load_cov_ext = self._load_covariance(load_covariance_external, 6, "load_covariance_external")
        self._load_cov_int = self._load_covariance(load_covariance_internal, n, "load_covariance_internal")
        self._whitened_for: bytes | None = None
        try:
            self._alpha = float(false_alarm)
        except (TypeError, ValueError):
            raise ValueError(f"{who}: false_alarm must be a number in (0, 1), got {false_alarm!r}") from None
        if not 0.0 < self._alpha < 1.0:
            raise ValueError(f"{who}: false_alarm must be in (0, 1), got {false_alarm!r}")
        self._spacing = positive_number(spacing, f"{who}: spacing")
        self._coarse_spacing = positive_number(coarse_spacing, f"{who}: coarse_spacing")
        self._medium_spacing = positive_number(medium_spacing, f"{who}: medium_spacing")
        for name, value in (
            ("min_search_points", min_search_points),
            ("link_pairs", link_pairs),
            ("polish_iterations", polish_iterations),
            ("refit_links", refit_links),
            ("max_link_pairs", max_link_pairs),
        ):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{who}: {name} must be a positive integer, got {value!r}")
        self._min_search_points = int(min_search_points)
        self._link_pairs = int(link_pairs)
        self._polish_iterations = int(polish_iterations)
        self._refit_links = int(refit_links)
        self._max_link_pairs = int(max_link_pairs)
        if contact_prior not in CONTACT_PRIORS:
            raise ValueError(f"{who}: contact_prior must be one of {CONTACT_PRIORS}, got {contact_prior!r}")
        self._contact_prior = contact_prior
        self._tolerance = positive_number(surface_tolerance, f"{who}: surface_tolerance", allow_zero=True)
        if limit_margin is None:
            self._limit_margin = -math.inf
        else:
            self._limit_margin = positive_number(limit_margin, f"{who}: limit_margin", allow_zero=True)
        self._stops = _JointStops(kin.topology.joints, self._limit_margin)
        self._dense_grid = self._make_grid(self._spacing)
        self._coarse_grid = self._make_grid(self._coarse_spacing)
        self._medium_grid = self._make_grid(self._medium_spacing)
        # Bounding radii of the primitives about their frames' origins (for the cheap
        # "near another primitive?" prefilter of the surface tests).
        self._radius = np.array(
            [_bounding_radius(int(geo.kinds[g]), geo.params[g], geo.planes[g]) for g in range(len(geo))]
        )
        self._pose_cache: _Pose | None = None

    # -- construction helpers ----------------------------------------------------------------
    def _whitener(self, cov, size: int, name: str, default_std: np.ndarray) -> np.ndarray:
        """L^-1 with cov = L L^T (from a covariance, or standard deviations)."""
        if cov is None:
            return np.diag(1.0 / default_std)
        try:
            c = np.array(cov, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{self._who}: {name} must be numbers, got {cov!r}") from None
        if not np.all(np.isfinite(c)):
            raise ValueError(f"{self._who}: {name} has NaN or inf entries")
        if c.shape == (size,):
            if np.any(c <= 0.0):
                raise ValueError(f"{self._who}: {name} as standard deviations must be positive")
            c = np.diag(c**2)
        if c.shape != (size, size):
            raise ValueError(
                f"{self._who}: {name} must be {size} standard deviations or a {size}x{size} covariance, "
                f"got shape {c.shape}"
            )
        if not np.allclose(c, c.T, rtol=1e-9, atol=1e-12 * np.abs(c).max()):
            raise ValueError(f"{self._who}: {name} must be symmetric")
        try:
            L = np.linalg.cholesky(0.5 * (c + c.T))
        except np.linalg.LinAlgError:
            raise ValueError(f"{self._who}: {name} must be positive definite") from None
        return np.linalg.inv(L)

    def _load_covariance(self, cov, size: int, name: str) -> np.ndarray | None:
        """A load covariance (per N^2): None, or a finite symmetric positive semi-definite
        size x size matrix."""
        if cov is None:
            return None
        try:
            c = np.array(cov, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{self._who}: {name} must be numbers, got {cov!r}") from None
        if c.shape != (size, size):
            raise ValueError(f"{self._who}: {name} must be a {size}x{size} covariance, got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError(f"{self._who}: {name} has NaN or inf entries")
        if not np.allclose(c, c.T, rtol=1e-9, atol=1e-12 * max(np.abs(c).max(), 1e-300)):
            raise ValueError(f"{self._who}: {name} must be symmetric")
        c = 0.5 * (c + c.T)
        if np.linalg.eigvalsh(c)[0] < -1e-9 * max(np.abs(c).max(), 1e-300):
            raise ValueError(f"{self._who}: {name} must be positive semi-definite")
        return c

    def _make_grid(self, spacing: float) -> dict:
        """Body-frame grid points of every candidate primitive."""
        geo = self._geometry
        p_B, n_B, prim = [], [], []
        for g in range(len(geo)):
            p_G, n_G = surface_grid(int(geo.kinds[g]), geo.params[g], spacing, geo.planes[g])
            R, p = geo.X_BG[g, :, :3], geo.X_BG[g, :, 3]
            p_B.append(p_G @ R.T + p)
            n_B.append(n_G @ R.T)
            prim.append(np.full(len(p_G), g))
        prim = np.concatenate(prim)
        return {"p_B": np.concatenate(p_B), "n_B": np.concatenate(n_B), "prim": prim, "slot": geo.slot[prim]}

    # -- public ---------------------------------------------------------------------------
    @property
    def geometry(self) -> RobotGeometry:
        """The candidate links' collision primitives."""
        return self._geometry

    @property
    def candidate_bodies(self) -> list[RigidBody]:
        return list(self._bodies)

    @property
    def false_alarm(self) -> float:
        return self._alpha

    @property
    def unknown_wrench_frames(self) -> tuple:
        """The frames whose wrenches are unknowns (() with foot F/T sensors)."""
        return self._unknown.frames

    @property
    def partly_known_wrenches(self) -> bool:
        """Whether some unknown wrench frame has measured components (a sole with FSRs)."""
        return any(len(chosen) < 6 for chosen in self._unknown.components)

    def grid_size(self, dense: bool = True) -> int:
        """Number of grid points (all primitives, before the outer-surface test)."""
        return len((self._dense_grid if dense else self._coarse_grid)["prim"])

    def limited_joints(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(indices (v[6:] order), signs) of the joints within ``limit_margin`` of a limit:
        +1 at a lower limit (the stop pushes the joint up), -1 at an upper one."""
        return self._stops.limited(self._check_q(q))

    def body_name(self, body_index: int) -> str:
        """The plant's name of the body of this BodyIndex value."""
        return self._plant.get_body(BodyIndex(int(body_index))).name()

    def same_link(self, body_a: int, body_b: int) -> bool:
        """Whether two BodyIndex values are one rigid link (the same body, or welded)."""
        return same_rigid_link(self._rigid_link, body_a, body_b)

    def fit_one(self, q: np.ndarray, wrench_W: np.ndarray, residual: np.ndarray) -> ContactFit:
        """The best single contact (module docstring).

        Args:
            q: the plant's positions (nq), free joint first (unit quaternion).
            wrench_W: the external residual, [moment about the world origin (N m); force (N)].
            residual: the internal residual (n), N m.

        Returns:
            The fit; with no feasible candidate (e.g. every force would pull) its statistic
            is inf and it names no body.

        Raises:
            ValueError: wrong sizes, NaN or inf, a q whose quaternion is not of unit norm.
        """
        pose, bt, bp = self._prepare(q, wrench_W, residual)
        return self._fit_one(pose, bt, bp)

    def fit_two(self, q: np.ndarray, wrench_W: np.ndarray, residual: np.ndarray) -> ContactFit:
        """The best pair of contacts on two different links (module docstring; arguments,
        return and errors as ``fit_one``; ValueError with fewer than two candidate links)."""
        if len(self._bodies) < 2:
            raise ValueError(f"{self._who}: two contacts need at least two candidate links")
        pose, bt, bp = self._prepare(q, wrench_W, residual)
        return self._fit_two(pose, bt, bp)

    def localize(
        self, q: np.ndarray, wrench_W: np.ndarray, residual: np.ndarray, max_contacts: int = 2
    ) -> MultiContactResult:
        """0, 1 or 2 contacts by the module docstring's tests (arguments and errors as
        ``fit_one``; ``max_contacts`` 1 or 2). ``fit_two`` runs only when one contact does
        not explain the residuals."""
        if max_contacts not in (1, 2) or isinstance(max_contacts, bool):
            raise ValueError(f"{self._who}: max_contacts must be 1 or 2, got {max_contacts!r}")
        if max_contacts == 2 and len(self._bodies) < 2:
            raise ValueError(f"{self._who}: two contacts need at least two candidate links")
        pose, bt, bp = self._prepare(q, wrench_W, residual)
        L = len(pose.limited)
        dof1, dof2 = self._free_rows - 5 - L, self._free_rows - 10 - L
        s0 = float(bp @ bp)
        nan = math.nan
        if s0 <= chi2.isf(self._alpha, self._free_rows - L):
            return MultiContactResult(0, (), np.zeros((0, 3)), np.zeros((0, 3)), s0, nan, nan, dof1, dof2, nan)
        one = self._fit_one(pose, bt, bp)
        s1, dof1, two, s2, chosen = one.statistic, one.dof, None, nan, one
        if max_contacts == 2 and not s1 <= chi2.isf(self._alpha, dof1):
            two = self._fit_two(pose, bt, bp)
            s2, dof2 = two.statistic, two.dof
            if two.body_indices and s2 < s1:
                F = ((s1 - s2) / 5.0) / max(s2 / dof2, 1e-300)
                if F > f_distribution.isf(self._alpha, 5, dof2):
                    chosen = two
        return MultiContactResult(
            len(chosen.body_indices),
            chosen.body_indices,
            chosen.points_W.copy(),
            chosen.forces_W.copy(),
            s0,
            s1,
            s2,
            dof1,
            dof2,
            one.p_value,
            one,
            two,
        )

    # -- inputs, pose -----------------------------------------------------------------------
    def _check_q(self, q) -> np.ndarray:
        q = self._vector(q, self._kin.nq, "q")
        norm = float(np.linalg.norm(q[:4]))
        if not abs(norm - 1.0) < 1e-3:
            raise ValueError(f"{self._who}: q[:4] must be a unit quaternion, its norm is {norm}")
        return q

    def _vector(self, value, size: int, name: str) -> np.ndarray:
        try:
            x = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{self._who}: {name} must be {size} numbers, got {value!r}") from None
        if x.shape != (size,):
            raise ValueError(f"{self._who}: {name} must have shape ({size},), got shape {x.shape}")
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise ValueError(f"{self._who}: {name} has NaN or inf at indices {bad.tolist()}")
        return x

    def _prepare(self, q, wrench_W, residual) -> tuple[_Pose, np.ndarray, np.ndarray]:
        """(pose, whitened data b~, stop-projected whitened data P b~)."""
        q = self._check_q(q)
        w = self._vector(wrench_W, 6, "wrench_W")
        r = self._vector(residual, self._n, "residual")
        if self._relative_error > 0.0 or self._load_cov_ext is not None or self._load_cov_int is not None:
            # Whiten with the load-dependent terms of these inputs (the pose's whitened
            # columns are recomputed when they change).
            key = np.concatenate((w, r)).tobytes()
            if key != self._whitened_for:
                eps2 = self._relative_error**2
                load2 = float(w[3:] @ w[3:])
                cov_ext = self._cov_ext + np.diag(eps2 * w**2)
                cov_int = self._cov_int + np.diag(eps2 * r**2)
                if self._load_cov_ext is not None:
                    cov_ext = cov_ext + load2 * self._load_cov_ext
                if self._load_cov_int is not None:
                    cov_int = cov_int + load2 * self._load_cov_int
                self._L_ext_inv = np.linalg.inv(np.linalg.cholesky(cov_ext))
                self._L_int_inv = np.linalg.inv(np.linalg.cholesky(cov_int))
                self._whitened_for = key
                self._pose_cache = None
        pose = self._pose(q)
        bt = np.concatenate((self._L_ext_inv @ w, self._L_int_inv @ r))
        return pose, bt, pose.P @ bt

    def _pose(self, q: np.ndarray) -> _Pose:
        """Everything that depends on q only (cached for the last q)."""
        key = q.tobytes()
        if self._pose_cache is not None and self._pose_cache.key == key:
            return self._pose_cache
        kin, geo = self._kin, self._geometry
        kin.set_positions(q)
        rows = self._rows
        X_WB = np.array([kin.body_pose(b) for b in self._bodies])
        # T_B: link wrench [m_B (about its origin); f] -> [r_ext; r_int] (module docstring).
        T = wrench_maps(kin, [body.body_frame() for body in self._bodies])
        Tw = np.concatenate((self._L_ext_inv @ T[:, :6], self._L_int_inv @ T[:, 6:]), axis=1)
        limited, signs = self.limited_joints(q)
        stops = np.zeros((rows, len(limited)))
        stops[6:] = self._L_int_inv[:, limited] * signs
        U = self._unknown.columns(kin)
        unknown = np.concatenate((self._L_ext_inv @ U[:6], self._L_int_inv @ U[6:]))
        P = np.eye(rows)
        if len(limited) or unknown.shape[1]:
            Qs, _ = np.linalg.qr(np.concatenate((unknown, stops), axis=1))
            P -= Qs @ Qs.T
        Tp = P @ Tw
        R_WG, p_WG = geo.world_poses(X_WB)
        pose = _Pose(key, X_WB, R_WG, p_WG, Tw, Tp, P, limited, signs, stops, unknown, self._unknown.world_map(kin))
        pose.dense = self._outer_points(pose, self._dense_grid)
        self._pose_cache = pose
        return pose

    def _search_points(self, pose: _Pose) -> None:
        """The pair search's points (coarse and medium) of ``pose``, once: each link's grid
        points, or (with fewer than min_search_points, twice that for the medium grid) that
        many spread-out dense points."""
        if pose.search is not None:
            return
        dense, search, medium = pose.dense, [], []
        for grid, count, out in (
            (self._coarse_grid, self._min_search_points, search),
            (self._medium_grid, 2 * self._min_search_points, medium),
        ):
            points = self._outer_points(pose, grid)
            for b in range(len(self._bodies)):
                rows = points.by_slot[b]
                if len(rows) >= count:
                    out.append(points.subset(rows))
                else:
                    rows = dense.by_slot[b]
                    out.append(dense.subset(rows[_spread(dense.p_W[rows], count)]))
        pose.medium = medium
        pose.search = _concatenate(search)

    def _outer_points(self, pose: _Pose, grid: dict) -> _Points:
        """The grid points outside every other primitive at this pose (the outer surface)."""
        X = pose.X_WB[grid["slot"]]
        p_W = np.einsum("mij,mj->mi", X[:, :, :3], grid["p_B"]) + X[:, :, 3]
        sd = self._other_distances(pose, p_W, grid["prim"])
        keep = np.flatnonzero(sd > 0.0)
        slot = grid["slot"][keep]
        n_W = np.einsum("mij,mj->mi", X[keep, :, :3], grid["n_B"][keep])
        cols = self._columns(pose.Tp, slot, p_W[keep] - X[keep, :, 3])
        gram = np.swapaxes(cols, 1, 2) @ cols
        by_slot = [np.flatnonzero(slot == s) for s in range(len(self._bodies))]
        return _Points(slot, p_W[keep], n_W, cols, gram, by_slot)

    def _other_distances(self, pose: _Pose, p_W: np.ndarray, prim: np.ndarray) -> np.ndarray:
        """(m,) the smallest signed distance of each point (on primitive ``prim``) to the
        other primitives whose bounding balls reach its primitive's ball (inf if none), m."""
        geo = self._geometry
        out = np.full(len(p_W), np.inf)
        gap = np.linalg.norm(pose.p_WG[:, None, :] - pose.p_WG[None], axis=2)
        reach = gap < self._radius[:, None] + self._radius[None] + self._tolerance
        np.fill_diagonal(reach, False)
        for a in np.unique(prim):
            rows = np.flatnonzero(prim == a)
            for g in np.flatnonzero(reach[a]):
                local = ((p_W[rows] - pose.p_WG[g]) @ pose.R_WG[g])[:, None, :]
                d = signed_distances(local, geo.kinds[g : g + 1], geo.params[g : g + 1], geo.planes[g : g + 1])
                out[rows] = np.minimum(out[rows], d[:, 0])
        return out

    @staticmethod
    def _columns(T: np.ndarray, slot: np.ndarray, r_W: np.ndarray) -> np.ndarray:
        """(m, rows, 3) columns of point forces at r_W from their links' origins:
        T_B [skew(r); I] (a force f at r has the link wrench [r x f; f])."""
        Ts = T[slot]
        return Ts[:, :, :3] @ _skews(r_W) + Ts[:, :, 3:]

    def _point_columns(self, pose: _Pose, slots, points: np.ndarray, projected: bool = True) -> np.ndarray:
        slots = np.asarray(slots, dtype=int)
        return self._columns(pose.Tp if projected else pose.Tw, slots, points - pose.X_WB[slots, :, 3])

    # -- lines, surfaces ------------------------------------------------------------------------
    def _entries(
        self, pose: _Pose, slots: np.ndarray, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First surface entry of each line (origin, unit direction; world) into its link's
        primitives where the direction points into the surface (f . n < 0) and the point is
        not buried deeper than ``surface_tolerance`` in another primitive.

        Returns (points (K, 3), outward normals (K, 3), valid (K,))."""
        geo = self._geometry
        K = len(slots)
        points, normals, valid = np.zeros((K, 3)), np.zeros((K, 3)), np.zeros(K, dtype=bool)
        kk, gg = np.nonzero(geo.slot[None, :] == np.asarray(slots)[:, None])
        if kk.size == 0:
            return points, normals, valid
        R = pose.R_WG[gg]
        o_G = np.einsum("mji,mj->mi", R, origins[kk] - pose.p_WG[gg])
        d_G = np.einsum("mji,mj->mi", R, directions[kk])
        l_in, _, hit = line_intersections(o_G, d_G, geo.kinds[gg], geo.params[gg], geo.planes[gg])
        ok = hit & np.isfinite(l_in)
        l_safe = np.where(ok, l_in, 0.0)
        n_G = outward_normals(o_G + l_safe[:, None] * d_G, geo.kinds[gg], geo.params[gg], geo.planes[gg])
        ok &= np.einsum("mi,mi->m", n_G, d_G) < -1e-9
        pts = origins[kk] + l_safe[:, None] * directions[kk]
        ok &= self._other_distances(pose, pts, gg) >= -self._tolerance
        for m in np.argsort(np.where(ok, l_in, np.inf), kind="stable")[::-1]:
            if ok[m]:  # written last: the smallest valid l_in of its line
                k = kk[m]
                points[k], normals[k], valid[k] = pts[m], R[m] @ n_G[m], True
        return points, normals, valid

    def _line_points(
        self, pose: _Pose, slots: np.ndarray, wrenches: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Entries (``_entries``) of the central axes of link wrenches [m_B; f] (moment about
        the link's origin): the lines o_B + (f x m_B) / |f|^2 + s f / |f| (eq. 22)."""
        m, f = wrenches[:, :3], wrenches[:, 3:6]
        f2 = np.einsum("ij,ij->i", f, f)
        good = f2 > 1e-300
        safe = np.where(good, f2, 1.0)
        origins = pose.X_WB[slots, :, 3] + _cross(f, m) / safe[:, None]
        points, normals, valid = self._entries(pose, slots, origins, f / np.sqrt(safe)[:, None])
        return points, normals, valid & good

    def _project(self, pose: _Pose, slot: int, p_W: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """The point of link ``slot``'s surface nearest to p_W, its outward normal (world),
        and whether it is on the outer surface (within ``surface_tolerance``)."""
        geo = self._geometry
        best = (math.inf, p_W, np.zeros(3), -1)
        for g in np.flatnonzero(geo.slot == slot):
            R, o = pose.R_WG[g], pose.p_WG[g]
            p_G = R.T @ (p_W - o)
            q_G, n_G = _closest_surface_point(p_G, int(geo.kinds[g]), geo.params[g], geo.planes[g])
            d = float(np.linalg.norm(q_G - p_G))
            if d < best[0]:
                best = (d, R @ q_G + o, R @ n_G, g)
        _, point, normal, g = best
        diff = point - pose.p_WG
        near = np.flatnonzero(np.einsum("gi,gi->g", diff, diff) < (self._radius + self._tolerance) ** 2)
        for h in near:
            if h != g:
                p_G = diff[h] @ pose.R_WG[h]
                if _signed_distance(p_G, int(geo.kinds[h]), geo.params[h], geo.planes[h]) < -self._tolerance:
                    return point, normal, False
        return point, normal, True

    # -- fits ------------------------------------------------------------------------------
    def _fit_at(self, pose: _Pose, bp: np.ndarray, cand: _Candidate) -> tuple[float, np.ndarray]:
        """(misfit, forces (k, 3)) of k contacts at given points (stops free); misfit inf
        when a force pulls."""
        A = np.concatenate(list(self._point_columns(pose, cand.slots, cand.points)), axis=1)
        x = _normal_solve(A, bp)
        forces = x.reshape(-1, 3)
        if np.any(np.einsum("ij,ij->i", forces, cand.normals) > 0.0):
            return math.inf, forces
        e = A @ x - bp
        return float(e @ e), forces

    def _final_fit(
        self, pose: _Pose, bt: np.ndarray, cand: _Candidate
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        """(forces (k, 3), stop torques (L,), misfit, unknown wrenches (m, 6)) at given
        points with sign-constrained stop reactions (non-negative least squares after
        eliminating the forces and the free unknown wrenches); misfit inf when a force
        pulls."""
        A = np.concatenate(list(self._point_columns(pose, cand.slots, cand.points, projected=False)), axis=1)
        S, U = pose.stops, pose.unknown
        k3 = A.shape[1]
        AU = np.concatenate((A, U), axis=1)  # the free unknowns: forces, then the wrenches
        mu = np.zeros(S.shape[1])
        if S.shape[1]:
            Qa, _ = np.linalg.qr(AU)
            mu, _ = nnls(S - Qa @ (Qa.T @ S), bt - Qa @ (Qa.T @ bt))
        rhs = bt - S @ mu
        x, *_ = np.linalg.lstsq(AU, rhs, rcond=None)
        e = AU @ x - rhs
        forces = x[:k3].reshape(-1, 3)
        misfit = float(e @ e)
        if np.any(np.einsum("ij,ij->i", forces, cand.normals) > 0.0):
            misfit = math.inf
        return forces, pose.signs * mu, misfit, (pose.unknown_to_world @ x[k3:]).reshape(-1, 6)

    def _uncertainty(self, pose: _Pose, bp: np.ndarray, cand: _Candidate) -> tuple[np.ndarray, np.ndarray]:
        """1-sigma (Cramer-Rao) position (m, along the surface) and force (N) uncertainty of
        each contact: the diagonal blocks of the inverse Fisher information of the whitened
        rows at the fit (stops free); inf where the residuals cannot place the contact."""
        J = self._jacobian(pose, bp, cand)[0]
        k = len(cand.slots)
        JTJ = J.T @ J
        scale = np.sqrt(np.diag(JTJ))
        scale[scale <= 0.0] = 1.0
        Jn = JTJ / np.outer(scale, scale)
        if np.linalg.cond(Jn) > 1e12:
            w, V = np.linalg.eigh(Jn)
            w = np.where(w > 1e-12 * w.max(), w, 0.0)
            with np.errstate(divide="ignore"):
                cov_n = (V / np.where(w > 0.0, w, np.nan)) @ V.T  # nan along the unidentifiable directions
        else:
            cov_n = np.linalg.inv(Jn)
        cov = cov_n / np.outer(scale, scale)
        d = np.diag(cov)
        force_std = np.sqrt(np.array([d[3 * c : 3 * c + 3].sum() for c in range(k)]))
        point_std = np.sqrt(np.array([d[3 * k + 2 * c : 3 * k + 2 * c + 2].sum() for c in range(k)]))
        return np.nan_to_num(point_std, nan=np.inf), np.nan_to_num(force_std, nan=np.inf)

    def _jacobian(self, pose: _Pose, bp: np.ndarray, cand: _Candidate) -> tuple:
        """(J (rows, 5 k), e, tangent bases): the model's derivative with respect to the
        forces and the points' tangent displacements, at the least-squares forces."""
        k = len(cand.slots)
        A = np.concatenate(list(self._point_columns(pose, cand.slots, cand.points)), axis=1)
        f = _normal_solve(A, bp)
        bases, D = [], []
        for c in range(k):
            t = _tangents(cand.normals[c])
            bases.append(t)
            # d(r x f)/dr = -skew(f)
            D.append(-pose.Tp[cand.slots[c]][:, :3] @ _skews(f[3 * c : 3 * c + 3][None])[0] @ t)
        return np.concatenate([A, *D], axis=1), bp - A @ f, bases

    def _lm_polish(self, pose: _Pose, bp: np.ndarray, cand: _Candidate) -> _Candidate:
        """Levenberg-Marquardt on the k points along their links' surfaces (tangent steps of
        at most ``_MAX_STEP`` projected back onto the surface; forces re-solved at every
        trial). Steps that raise the misfit, leave the outer surface or make a force pull
        are refused."""
        k = len(cand.slots)
        damping = 1e-3
        for _ in range(_LM_ITERATIONS):
            J, e, bases = self._jacobian(pose, bp, cand)
            JTJ, g = J.T @ J, J.T @ e
            scale = np.diag(JTJ).copy()
            scale[scale <= 0.0] = 1.0
            if g @ _jittered_solve(JTJ, g) < _LM_GAIN * cand.misfit:
                break  # converged: the Gauss-Newton step would gain (almost) nothing
            accepted = None
            for _ in range(6):
                try:
                    step = np.linalg.solve(JTJ + damping * np.diag(scale), g)[3 * k :].reshape(k, 2)
                except np.linalg.LinAlgError:
                    damping *= 10.0
                    continue
                norms = np.linalg.norm(step, axis=1)
                step *= np.minimum(1.0, _MAX_STEP / np.maximum(norms, 1e-300))[:, None]
                points, normals, ok = cand.points.copy(), cand.normals.copy(), True
                for c in range(k):
                    points[c], normals[c], outer = self._project(
                        pose, cand.slots[c], cand.points[c] + bases[c] @ step[c]
                    )
                    ok &= outer
                trial = _Candidate(cand.slots, points, normals, math.inf)
                if ok:
                    trial.misfit = self._fit_at(pose, bp, trial)[0]
                if trial.misfit < cand.misfit:
                    accepted = trial
                    damping = max(damping / 10.0, 1e-9)
                    break
                damping *= 10.0
            if accepted is None:
                break
            moved = float(np.max(np.linalg.norm(accepted.points - cand.points, axis=1)))
            gain = cand.misfit - accepted.misfit
            cand = accepted
            if moved < 1e-7 or gain < _LM_GAIN * cand.misfit:
                break
        return cand

    def _line_polish(self, pose: _Pose, bp: np.ndarray, cands: list[_Candidate]) -> list[_Candidate]:
        """Line steps (module docstring, step d) on a batch of candidates of k contacts
        each: each contact in turn moves to the entry of the line of its link's best
        zero-pitch wrench given the other contacts, where that lowers the misfit (all
        candidates at once)."""
        if not cands:
            return cands
        slots = np.stack([c.slots for c in cands])
        points = np.stack([c.points for c in cands])
        normals = np.stack([c.normals for c in cands])
        misfit = np.array([c.misfit for c in cands])
        k = slots.shape[1]
        for _ in range(self._polish_iterations):
            moved = 0.0
            for c in range(k):
                others = [self._point_columns(pose, slots[:, o], points[:, o]) for o in range(k) if o != c]
                A = np.concatenate([pose.Tp[slots[:, c]], *others], axis=2)  # (P, rows, 6 + 3 (k - 1))
                x = _zero_pitch_solve(np.swapaxes(A, 1, 2) @ A, np.matmul(bp, A))
                p_new, n_new, ok = self._line_points(pose, slots[:, c], x[:, :6])
                trial_p, trial_n = points.copy(), normals.copy()
                trial_p[:, c], trial_n[:, c] = p_new, n_new
                s_new = self._misfits_at(pose, bp, slots, trial_p, trial_n)
                better = np.flatnonzero(ok & (s_new <= misfit))
                if better.size:
                    moved = max(moved, float(np.max(np.linalg.norm(p_new[better] - points[better, c], axis=1))))
                    points[better], normals[better], misfit[better] = trial_p[better], trial_n[better], s_new[better]
            if moved < _POLISH_TOLERANCE:
                break
        return [_Candidate(slots[m], points[m], normals[m], float(misfit[m])) for m in range(len(cands))]

    def _misfits_at(
        self, pose: _Pose, bp: np.ndarray, slots: np.ndarray, points: np.ndarray, normals: np.ndarray
    ) -> np.ndarray:
        """(P,) misfits of P candidates of k contacts (slots (P, k), points and normals
        (P, k, 3); stops free), inf where a force pulls."""
        P, k = slots.shape
        A = np.concatenate([self._point_columns(pose, slots[:, c], points[:, c]) for c in range(k)], axis=2)
        H = np.swapaxes(A, 1, 2) @ A
        g = np.matmul(bp, A)
        jitter = 1e-12 * np.trace(H, axis1=1, axis2=2)[:, None, None] * np.eye(3 * k)
        x = np.linalg.solve(H + jitter, g[..., None])[..., 0]
        e = np.einsum("pri,pi->pr", A, x) - bp
        s = np.einsum("pr,pr->p", e, e)
        pulls = np.any(np.einsum("pci,pci->pc", x.reshape(P, k, 3), normals) > 0.0, axis=1)
        return np.where(pulls | ~np.isfinite(s), np.inf, s)

    def _result(
        self, pose: _Pose, bt: np.ndarray, bp: np.ndarray, cands: list[_Candidate], k: int, by_evidence: bool = False
    ) -> ContactFit:
        """Final refits (sign-constrained stops) of candidates on different links or link
        pairs; the best (the least misfit, ties to the least stop torque; ``by_evidence``:
        the largest evidence, ``_log_evidence``) and the runner-up."""
        finals = []
        for cand in cands:
            forces, stop, s, unknown = self._final_fit(pose, bt, cand)
            evidence = self._log_evidence(pose, bp, cand, s) if by_evidence and math.isfinite(s) else math.nan
            finals.append((s, float(np.linalg.norm(stop)), cand, forces, stop, evidence, unknown))
        scale = max(float(bp @ bp), 1.0)
        finals.sort(key=lambda t: (round(t[0] / scale, 12), round(t[1], 9)))
        if by_evidence:
            finals.sort(key=lambda t: -t[5] if math.isfinite(t[5]) else math.inf)  # stable: ties keep that order
        limited = tuple(int(j) for j in pose.limited)
        if not finals or not math.isfinite(finals[0][0]):
            dof = self._free_rows - 5 * k - len(limited)
            return ContactFit((), np.zeros((0, 3)), np.zeros((0, 3)), math.inf, dof, limited_joints=limited)
        s, _, cand, forces, stop, evidence, unknown = finals[0]
        dof = self._free_rows - 5 * k - int(np.count_nonzero(stop))  # the stops engaged are fitted too
        point_std, force_std = self._uncertainty(pose, bp, cand)
        bodies = self._geometry.bodies
        runner = finals[1] if len(finals) > 1 else None
        return ContactFit(
            tuple(int(bodies[b]) for b in cand.slots),
            cand.points.copy(),
            forces.copy(),
            float(s),
            dof,
            runner[0] if runner else math.inf,
            tuple(int(bodies[b]) for b in runner[2].slots) if runner else (),
            limited,
            stop,
            point_std,
            force_std,
            evidence,
            runner[5] if runner else math.nan,
            unknown,
        )

    def _log_evidence(self, pose: _Pose, bp: np.ndarray, cand: _Candidate, misfit: float) -> float:
        """Laplace approximation of log p(residuals | these k links), up to a constant
        shared by every candidate of k contacts (module docstring): -s/2 - 1/2 log det(I +
        S0^1/2 J^T J S0^1/2), J the whitened model's derivative with respect to the forces
        and the points' tangent coordinates at the fit, S0 the prior covariance (forces:
        ``_FORCE_PRIOR_STD``^2; each tangent coordinate: a_c / (2 pi), a_c the link's outer
        surface area with ``contact_prior`` "link", the same for every link with "surface":
        the Gaussian of the uniform density's peak)."""
        k = len(cand.slots)
        J = self._jacobian(pose, bp, cand)[0]
        if self._contact_prior == "link":
            areas = np.array([max(len(pose.dense.by_slot[b]), 1) for b in cand.slots]) * self._spacing**2
        else:  # the whole outer surface's area, the same for every candidate
            areas = np.full(k, max(len(pose.dense.slot), 1) * self._spacing**2)
        variances = np.concatenate((np.full(3 * k, _FORCE_PRIOR_STD**2), np.repeat(areas / (2.0 * math.pi), 2)))
        prior_std = np.sqrt(variances)
        Js = J * prior_std
        _, logdet = np.linalg.slogdet(np.eye(5 * k) + Js.T @ Js)
        return -0.5 * misfit - 0.5 * float(logdet)

    # -- one contact --------------------------------------------------------------------------
    def _fit_one(self, pose: _Pose, bt: np.ndarray, bp: np.ndarray) -> ContactFit:
        B = len(self._bodies)
        c0 = float(bp @ bp)
        best = [None] * B
        # Every link's best zero-pitch wrench and its line's entry.
        slots = np.arange(B)
        x = _zero_pitch_solve(np.einsum("bri,brj->bij", pose.Tp, pose.Tp), np.einsum("bri,r->bi", pose.Tp, bp))
        line_p, line_n, line_ok = self._line_points(pose, slots, x)
        idx = np.flatnonzero(line_ok)
        if idx.size:
            cols = self._point_columns(pose, idx, line_p[idx])
            s, f = _single_misfits(cols, np.einsum("mri,mrj->mij", cols, cols), bp, c0)
            s = np.where(np.einsum("ij,ij->i", f, line_n[idx]) <= 0.0, s, np.inf)
            for m, b in enumerate(idx):
                best[b] = _Candidate(np.array([b]), line_p[b][None], line_n[b][None], float(s[m]), on_line=True)
        # Every grid point.
        pts = pose.dense
        if len(pts.slot):
            s, f = _single_misfits(pts.cols, pts.gram, bp, c0)
            s = np.where(np.einsum("ij,ij->i", f, pts.n_W) <= 0.0, s, np.inf)
            for b in range(B):
                rows = pts.by_slot[b]
                if rows.size:
                    k = rows[np.argmin(s[rows])]
                    if best[b] is None or s[k] < best[b].misfit:
                        best[b] = _Candidate(np.array([b]), pts.p_W[k][None], pts.n_W[k][None], float(s[k]))
        # Bodies joined by welds are one rigid link: keep each link's best body.
        link_best = {}
        for c in best:
            if c is not None and math.isfinite(c.misfit):
                link = int(self._rigid_link[int(self._bodies[int(c.slots[0])].index())])
                if link not in link_best or c.misfit < link_best[link].misfit:
                    link_best[link] = c
        cands = sorted(link_best.values(), key=lambda c: c.misfit)
        cands = cands[: self._refit_links]
        # The two best are polished along their surfaces: a grid point, and a line entry too
        # (the best point of its link only where the link's zero-pitch wrench is unique; with
        # the soles' columns projected out a stance leg link's is not). At a line entry that
        # is already the best point the polish stops at its first step.
        for m in range(min(len(cands), 2)):
            cands[m] = self._lm_polish(pose, bp, cands[m])
        return self._result(pose, bt, bp, cands, 1)

    # -- two contacts -------------------------------------------------------------------------
    def _pair_table(self, pose: _Pose, bp: np.ndarray, c0: float) -> tuple[np.ndarray, np.ndarray]:
        """(a) Every pair of search points on two different links, all at once: the best
        misfit of each link pair (B, B) (upper triangle, inf where no pair pushes in) and its
        two points (B, B, 2) (indices into ``pose.search``). The parts that depend on the
        pose only (``_pair_precomputation``) are computed once per pose."""
        if pose.pairs is None:
            pose.pairs = _pair_precomputation(pose.search)
        pc = pose.pairs
        I, J = pc["I"], pc["J"]
        beta = pc["beta_map"] @ bp  # (3 N,): U_i^T b
        beta = beta.reshape(-1, 3).T  # (3, N)
        c = np.matmul(bp, pose.search.cols).T  # (3, N): A_j^T b
        bI, cJ, v, Si = beta[:, I], c[:, J], pc["V"], pc["Sinv"]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rhs = [cJ[m] - (v[0, m] * bI[0] + v[1, m] * bI[1] + v[2, m] * bI[2]) for m in range(3)]
            f = [Si[k, 0] * rhs[0] + Si[k, 1] * rhs[1] + Si[k, 2] * rhs[2] for k in range(3)]
            s = c0 - (bI[0] * bI[0] + bI[1] * bI[1] + bI[2] * bI[2]) - (rhs[0] * f[0] + rhs[1] * f[1] + rhs[2] * f[2])
            t = [bI[k] - (v[k, 0] * f[0] + v[k, 1] * f[1] + v[k, 2] * f[2]) for k in range(3)]
            R = pc["R"]  # (3, 3, P): R_i's entries
            a2 = t[2] / R[2, 2]
            a1 = (t[1] - R[1, 2] * a2) / R[1, 1]
            a0 = (t[0] - R[0, 1] * a1 - R[0, 2] * a2) / R[0, 0]
            nI, nJ = pc["nI"], pc["nJ"]
            ok = (a0 * nI[0] + a1 * nI[1] + a2 * nI[2] <= 0.0) & (f[0] * nJ[0] + f[1] * nJ[1] + f[2] * nJ[2] <= 0.0)
        ok &= pc["well_posed"] & (s >= -_ROUNDING * c0)
        s = np.where(ok & np.isfinite(s), np.maximum(s, 0.0), np.inf)
        # The best pair of each link pair: pairs are sorted by link pair (segments).
        B = len(self._bodies)
        table = np.full((B, B), np.inf)
        where = np.full((B, B, 2), -1, dtype=int)
        seg_start, seg_a, seg_b = pc["seg_start"], pc["seg_a"], pc["seg_b"]
        best = np.minimum.reduceat(s, seg_start)
        hit = np.flatnonzero(s == np.repeat(best, np.diff(np.append(seg_start, len(s)))))
        segment = np.searchsorted(seg_start, hit, side="right") - 1
        first = hit[np.unique(segment, return_index=True)[1]]
        table[seg_a, seg_b] = best
        where[seg_a, seg_b, 0], where[seg_a, seg_b, 1] = I[first], J[first]
        return table, where

    def _fit_two(self, pose: _Pose, bt: np.ndarray, bp: np.ndarray) -> ContactFit:
        c0 = float(bp @ bp)
        self._search_points(pose)
        table, where = self._pair_table(pose, bp, c0)  # (a)
        a_all, b_all = np.triu_indices(len(self._bodies), 1)
        bounds, H, g = self._pair_bounds(pose, bp, c0, a_all, b_all)  # (a')
        done: set[int] = set()

        def refine(pairs) -> list[_Candidate]:
            """(b)-(d) on the link pairs ``pairs`` (indices into a_all, b_all) not yet done."""
            pairs = np.array([m for m in pairs if m not in done], dtype=int)
            done.update(pairs.tolist())
            if not pairs.size:
                return []
            starts = self._line_starts(pose, bp, a_all[pairs], b_all[pairs], H[pairs], g[pairs])
            for m in pairs:
                start = self._medium_start(pose, bp, c0, table, where, int(a_all[m]), int(b_all[m]))
                if start is not None:
                    starts.append(self._dense_refine(pose, bp, c0, start))
            return self._line_polish(pose, bp, starts)

        # (b) The 5 K best link pairs of the coarse table; (b') then, in increasing order of
        # their lower bounds, every link pair that could still beat the best so far.
        table_order = np.argsort(table[a_all, b_all], kind="stable")[: _MEDIUM_PAIRS * self._link_pairs]
        cands = refine(m for m in table_order if math.isfinite(table[a_all[m], b_all[m]]))
        best = min((c.misfit for c in cands), default=math.inf)
        order = [int(m) for m in np.argsort(bounds, kind="stable") if m not in done]
        while order and len(done) < self._max_link_pairs:
            room = min(_BOUND_BATCH, self._max_link_pairs - len(done))
            batch = [m for m in order[:room] if bounds[m] < best + _BOUND_MARGIN]
            if not batch:
                break
            order = order[len(batch) :]
            cands += refine(batch)
            best = min([best, *(c.misfit for c in cands)])
        # One candidate per link pair; of those within the margin of the best misfit, the K
        # of the largest evidence; the best few polished along their surfaces.
        per_pair: dict[tuple, _Candidate] = {}
        for cand in cands:
            key = tuple(int(x) for x in cand.slots)
            if key not in per_pair or cand.misfit < per_pair[key].misfit:
                per_pair[key] = cand
        cands = sorted(per_pair.values(), key=lambda c: c.misfit)
        close = [c for c in cands if c.misfit < best + _BOUND_MARGIN]
        if len(close) > self._link_pairs:
            evidence = [self._log_evidence(pose, bp, c, c.misfit) for c in close]
            cands = [close[m] for m in np.argsort(evidence, kind="stable")[::-1][: self._link_pairs]]
        else:
            cands = cands[: self._link_pairs]
        for m in range(min(len(cands), _LM_CANDIDATES)):
            cands[m] = self._lm_polish(pose, bp, cands[m])
        return self._result(pose, bt, bp, cands, 2, by_evidence=True)  # (e)

    def _pair_bounds(
        self, pose: _Pose, bp: np.ndarray, c0: float, a: np.ndarray, b: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(a') Lower bounds of the misfit of two point forces on links a and b (arrays of
        slots): the misfit of two FREE wrenches on them (12 unknowns; a point force is a
        zero-pitch wrench, 5 of them), all link pairs at once. Returns (bounds (P,), the
        normal matrices H (P, 12, 12) and right-hand sides g (P, 12))."""
        A = np.concatenate((pose.Tp[a], pose.Tp[b]), axis=2)  # (P, rows, 12)
        H = np.swapaxes(A, 1, 2) @ A
        g = np.matmul(bp, A)
        jitter = 1e-12 * np.trace(H, axis1=1, axis2=2)[:, None, None] / 12.0 * np.eye(12)
        x = np.linalg.solve(H + jitter, g[..., None])[..., 0]
        return np.maximum(c0 - np.einsum("pi,pi->p", g, x), 0.0), H, g

    def _line_starts(
        self, pose: _Pose, bp: np.ndarray, a: np.ndarray, b: np.ndarray, H: np.ndarray, g: np.ndarray
    ) -> list[_Candidate]:
        """Starts of the link pairs (a, b) from their lines (eq. 22 for two contacts): the
        entry into a of the line of a's best zero-pitch wrench with a free wrench on b, and
        the same for b; only where both lines enter their links and both forces push in."""
        swap = np.r_[6:12, 0:6]
        points, normals, ok = [], [], np.ones(len(a), dtype=bool)
        for slots, Hs, gs in ((a, H, g), (b, H[:, swap][:, :, swap], g[:, swap])):
            x = _zero_pitch_solve(Hs, gs)
            p, n, valid = self._line_points(pose, slots, x[:, :6])
            points.append(p)
            normals.append(n)
            ok &= valid
        slots = np.stack((a, b), axis=1)
        points, normals = np.stack(points, axis=1), np.stack(normals, axis=1)
        misfits = self._misfits_at(pose, bp, slots, points, normals)
        return [
            _Candidate(slots[m].copy(), points[m], normals[m], float(misfits[m]))
            for m in np.flatnonzero(ok & np.isfinite(misfits))
        ]

    def _medium_start(
        self, pose: _Pose, bp: np.ndarray, c0: float, table: np.ndarray, where: np.ndarray, a: int, b: int
    ) -> _Candidate | None:
        """(b) The better of the link pair's coarse-table pair and its best pair on the
        medium grids (None when neither pushes in)."""
        P = pose.search
        start = None
        if math.isfinite(table[a, b]):
            i, j = where[a, b]
            start = _Candidate(np.array([a, b]), P.p_W[[i, j]], P.n_W[[i, j]], float(table[a, b]))
        Ma, Mb = pose.medium[a], pose.medium[b]
        s, i, j = _best_pair(Ma, Mb, bp, c0)
        if math.isfinite(s) and (start is None or s < start.misfit):
            start = _Candidate(np.array([a, b]), np.stack((Ma.p_W[i], Mb.p_W[j])), np.stack((Ma.n_W[i], Mb.n_W[j])), s)
        return start

    def _dense_refine(self, pose: _Pose, bp: np.ndarray, c0: float, cand: _Candidate) -> _Candidate:
        """(c) The best of the start and all pairs of dense points within ``medium_spacing``
        of its points."""
        dense, sets = pose.dense, []
        for c in range(2):
            rows = dense.by_slot[cand.slots[c]]
            rows = rows[np.linalg.norm(dense.p_W[rows] - cand.points[c], axis=1) <= self._medium_spacing]
            sets.append(dense.subset(rows))
        s, i, j = _best_pair(sets[0], sets[1], bp, c0)
        if s < cand.misfit:
            return _Candidate(
                cand.slots,
                np.stack((sets[0].p_W[i], sets[1].p_W[j])),
                np.stack((sets[0].n_W[i], sets[1].n_W[j])),
                s,
            )
        return cand


def _pair_precomputation(P: _Points) -> dict:
    """The pose-only parts of the all-pairs search (``_pair_table``) over the pairs i < j of
    points on different links, sorted by link pair: with A_i = U_i R_i, V_ij = U_i^T A_j
    (3, 3, P), the inverse Schur complements (K_jj - V_ij^T V_ij)^-1 (3, 3, P), R_i
    (3, 3, P), the normals, and the map b -> U_i^T b (3 N, rows)."""
    N = len(P.slot)
    U, R = np.linalg.qr(P.cols)
    rows = U.shape[1]
    Ut = np.ascontiguousarray(U.transpose(0, 2, 1)).reshape(3 * N, rows)
    I, J = np.triu_indices(N, 1)
    keep = P.slot[I] != P.slot[J]
    I, J = I[keep], J[keep]
    order = np.lexsort((J, I, P.slot[J], P.slot[I]))  # by (link of i, link of j), then i, j
    I, J = I[order], J[order]
    V_all = (Ut @ P.cols.transpose(1, 0, 2).reshape(rows, 3 * N)).reshape(N, 3, N, 3)
    V = np.ascontiguousarray(V_all[I, :, J, :].transpose(1, 2, 0))  # (3, 3, P)
    G = P.gram[J].transpose(1, 2, 0)  # (3, 3, P)
    S = G - np.einsum("klp,kmp->lmp", V, V)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        C = np.empty_like(S)
        C[0, 0] = S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1]
        C[0, 1] = S[0, 2] * S[2, 1] - S[0, 1] * S[2, 2]
        C[0, 2] = S[0, 1] * S[1, 2] - S[0, 2] * S[1, 1]
        C[1, 1] = S[0, 0] * S[2, 2] - S[0, 2] * S[2, 0]
        C[1, 2] = S[0, 2] * S[1, 0] - S[0, 0] * S[1, 2]
        C[2, 2] = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
        C[1, 0], C[2, 0], C[2, 1] = C[0, 1], C[0, 2], C[1, 2]
        det = S[0, 0] * C[0, 0] + S[0, 1] * C[1, 0] + S[0, 2] * C[2, 0]
        Sinv = C / det
        # Pairs whose second force is (nearly) in the span of the first's columns: their
        # 3 x 3 solve is rounding noise (misfits far below zero); _pair_table skips them.
        well_posed = _well_posed(S[0, 0] + S[1, 1] + S[2, 2], G[0, 0] + G[1, 1] + G[2, 2], det)
    link_pair = P.slot[I] * (P.slot.max() + 1) + P.slot[J]
    seg_start = np.flatnonzero(np.r_[True, link_pair[1:] != link_pair[:-1]])
    return {
        "I": I,
        "J": J,
        "V": V,
        "Sinv": Sinv,
        "well_posed": well_posed,
        "R": np.ascontiguousarray(R[I].transpose(1, 2, 0)),
        "nI": np.ascontiguousarray(P.n_W[I].T),
        "nJ": np.ascontiguousarray(P.n_W[J].T),
        "beta_map": Ut,
        "seg_start": seg_start,
        "seg_a": P.slot[I[seg_start]],
        "seg_b": P.slot[J[seg_start]],
    }


def _well_posed(trace_S, trace_G, det_S):
    """Whether a pair search's 3 x 3 Schur complement S (the second force's columns
    projected off the first's; G: their Gram matrix) gives a solve worth its name
    (``_WELL_POSED``), from the traces of S and G and the determinant of S (arrays)."""
    trace = trace_S / 3.0
    return (trace > _WELL_POSED * trace_G / 3.0) & (det_S > _WELL_POSED * trace**3)


def _jittered_solve(H: np.ndarray, g: np.ndarray) -> np.ndarray:
    """H^-1 g for a symmetric positive semi-definite H, with a relative jitter of 1e-12."""
    return np.linalg.solve(H + 1e-12 * np.trace(H) / len(H) * np.eye(len(H)), g)


def _normal_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least-squares x of A x = b by the (jittered) normal equations."""
    return _jittered_solve(A.T @ A, A.T @ b)


def _single_misfits(cols: np.ndarray, gram: np.ndarray, b: np.ndarray, c0: float) -> tuple[np.ndarray, np.ndarray]:
    """(misfits (m,), forces (m, 3)) of one point force per column block (m, rows, 3)."""
    g = np.matmul(b, cols)  # (m, 3)
    f = _solve3(gram, g)
    s = c0 - np.einsum("mi,mi->m", g, f)
    return np.where(np.isfinite(s), np.maximum(s, 0.0), np.inf), f


def _best_pair(Pa: _Points, Pb: _Points, b: np.ndarray, c0: float) -> tuple[float, int, int]:
    """The best pair (misfit, i, j) of point forces i in Pa, j in Pb (``_pair_misfits``)."""
    if len(Pa.slot) == 0 or len(Pb.slot) == 0:
        return math.inf, -1, -1
    s = _pair_misfits(Pa, Pb, b, c0)
    k = int(np.argmin(s))
    i, j = divmod(k, s.shape[1])
    return float(s[i, j]), i, j


def _pair_misfits(
    Pa: _Points, Pb: _Points, b: np.ndarray, c0: float, qr: tuple | None = None, V: np.ndarray | None = None
) -> np.ndarray:
    """(Na, Nb) misfits of all pairs of point forces i in Pa, j in Pb (inf unless both
    push into their surfaces), by the projection trick: with A_i = U_i R_i (QR), b and
    every A_j are projected on the complement of A_i (V_ij = U_i^T A_j, beta_i = U_i^T b),
    leaving one 3 x 3 system per pair, (K_jj - V_ij^T V_ij) f_j = c_j - V_ij^T beta_i, and
    f_i = R_i^-1 (beta_i - V_ij f_j); misfit = |b|^2 - |beta_i|^2 - f_j . (c_j - V_ij^T beta_i).
    Computed component by component on (Na, Nb) arrays, in blocks of columns that stay in
    the cache (no loop over pairs). ``qr`` = (U, R) of Pa's columns and ``V`` (Na, 3, Nb, 3)
    may be given precomputed (they depend on the pose only)."""
    Na, Nb = len(Pa.slot), len(Pb.slot)
    U, R = np.linalg.qr(Pa.cols) if qr is None else qr  # (Na, rows, 3), (Na, 3, 3)
    rows = U.shape[1]
    Ut = np.ascontiguousarray(U.transpose(0, 2, 1)).reshape(3 * Na, rows)
    beta = (Ut @ b).reshape(Na, 3, 1)
    b0, b1, b2 = beta[:, 0], beta[:, 1], beta[:, 2]  # (Na, 1)
    base = c0 - (b0 * b0 + b1 * b1 + b2 * b2)
    r00, r01, r02, r11, r12, r22 = (R[:, i, j][:, None] for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
    na = Pa.n_W[:, :, None]
    out = np.empty((Na, Nb))
    block = max(1, _PAIR_BLOCK // max(Na, 1))
    for start in range(0, Nb, block):
        sl = slice(start, min(Nb, start + block))
        Bc = Pb.cols[sl]
        m = Bc.shape[0]
        Vb = (Ut @ Bc.transpose(1, 0, 2).reshape(rows, 3 * m)).reshape(Na, 3, m, 3) if V is None else V[:, :, sl]
        v = [[np.ascontiguousarray(Vb[:, k, :, l]) for l in range(3)] for k in range(3)]  # v[k][l] (Na, m)
        G = Pb.gram[sl]
        cb = np.matmul(b, Bc)  # (m, 3)
        nb = Pb.n_W[sl]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            S = {}
            for l, n in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
                S[l, n] = G[:, l, n] - (v[0][l] * v[0][n] + v[1][l] * v[1][n] + v[2][l] * v[2][n])
            rhs = [cb[:, l] - (v[0][l] * b0 + v[1][l] * b1 + v[2][l] * b2) for l in range(3)]
            s00, s01, s02, s11, s12, s22 = S[0, 0], S[0, 1], S[0, 2], S[1, 1], S[1, 2], S[2, 2]
            C00 = s11 * s22 - s12 * s12
            C01 = s02 * s12 - s01 * s22
            C02 = s01 * s12 - s02 * s11
            C11 = s00 * s22 - s02 * s02
            C12 = s01 * s02 - s00 * s12
            C22 = s00 * s11 - s01 * s01
            det = s00 * C00 + s01 * C01 + s02 * C02
            inv_det = 1.0 / det
            f0 = (C00 * rhs[0] + C01 * rhs[1] + C02 * rhs[2]) * inv_det
            f1 = (C01 * rhs[0] + C11 * rhs[1] + C12 * rhs[2]) * inv_det
            f2 = (C02 * rhs[0] + C12 * rhs[1] + C22 * rhs[2]) * inv_det
            s = base - (rhs[0] * f0 + rhs[1] * f1 + rhs[2] * f2)
            t = [beta[:, k] - (v[k][0] * f0 + v[k][1] * f1 + v[k][2] * f2) for k in range(3)]
            a2 = t[2] / r22
            a1 = (t[1] - r12 * a2) / r11
            a0 = (t[0] - r01 * a1 - r02 * a2) / r00
            ok = (a0 * na[:, 0] + a1 * na[:, 1] + a2 * na[:, 2] <= 0.0) & (
                f0 * nb[:, 0] + f1 * nb[:, 1] + f2 * nb[:, 2] <= 0.0
            )
            # As in _pair_precomputation: ill-posed pairs and rounding noise are skipped.
            ok &= _well_posed(s00 + s11 + s22, G[:, 0, 0] + G[:, 1, 1] + G[:, 2, 2], det) & (s >= -_ROUNDING * c0)
            out[:, sl] = np.where(ok & np.isfinite(s), np.maximum(s, 0.0), np.inf)
    return out
