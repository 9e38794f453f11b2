"""The localizer's compiled geometric queries (``systems.residuals.geometry_intersection``:
``line_intersections``, ``outward_normals``, ``signed_distances``) against their vectorised
numpy formulation (below, the project's implementation until the queries were compiled,
itself tested analytically in test_contact_estimation.py and test_multi_contact.py) on
thousands of random primitives of every kind, with axis-parallel lines and points inside and
outside: the same hits and faces, the parameters and distances to rounding (the two sum the
dot products in different orders)."""

from __future__ import annotations

import numpy as np
import pytest

from systems.residuals.geometry_intersection import (
    BOX,
    CAPSULE,
    CONVEX,
    CYLINDER,
    SPHERE,
    line_intersections,
    outward_normals,
    signed_distances,
)

_INF = np.inf


@pytest.fixture(scope="module")
def primitives():
    """4000 random primitives (all five kinds; convex ones with 7 face planes and unused
    rows), a line per primitive (one in seven along z, one in eleven along x, some through
    the axis) and five points per primitive."""
    rng = np.random.default_rng(0)
    g = 4000
    kinds = rng.integers(0, 5, g)
    params = np.abs(rng.normal(size=(g, 3))) * 0.1 + 0.01
    params[kinds == SPHERE, 1:] = 0.0
    params[(kinds == CYLINDER) | (kinds == CAPSULE), 2] = 0.0
    params[kinds == CONVEX] = 0.0
    planes = np.zeros((g, 8, 4))
    planes[:, :, 3] = np.inf
    for i in np.flatnonzero(kinds == CONVEX):
        n = rng.normal(size=(6, 3))
        n = np.vstack((n, -n[:1])) / np.linalg.norm(np.vstack((n, -n[:1])), axis=1, keepdims=True)
        planes[i, :7, :3], planes[i, :7, 3] = n, 0.05 + 0.05 * rng.random(7)
    o = rng.normal(size=(g, 3)) * 0.15
    d = rng.normal(size=(g, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[::7], d[::11] = (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)
    o[::13, :2] = 0.0
    points = rng.normal(size=(5, g, 3)) * 0.15
    return kinds, params, planes, o, d, points


def test_line_intersections_equal_the_numpy_formulation(primitives):
    kinds, params, planes, o, d, _ = primitives
    l_in, l_out, hit = line_intersections(o, d, kinds, params, planes)
    want_in, want_out, want_hit = numpy_line_intersections(o, d, kinds, params, planes)
    np.testing.assert_array_equal(hit, want_hit)
    assert 0.2 < hit.mean() < 0.8  # both outcomes, many times
    for got, want in ((l_in, want_in), (l_out, want_out)):
        finite = np.isfinite(want)
        np.testing.assert_array_equal(got[~finite], want[~finite])
        np.testing.assert_allclose(got[finite], want[finite], rtol=1e-13, atol=1e-15)


def test_outward_normals_and_signed_distances_equal_the_numpy_formulation(primitives):
    kinds, params, planes, o, d, points = primitives
    l_in, _, hit = numpy_line_intersections(o, d, kinds, params, planes)
    on_surface = o + np.where(hit, l_in, 0.0)[:, None] * d
    np.testing.assert_allclose(
        outward_normals(on_surface, kinds, params, planes),
        numpy_outward_normals(on_surface, kinds, params, planes),
        rtol=0,
        atol=1e-15,
    )
    got = signed_distances(points, kinds, params, planes)
    np.testing.assert_allclose(got, numpy_signed_distances(points, kinds, params, planes), rtol=0, atol=1e-15)
    assert (got < 0).any() and (got > 0).any()  # points inside and outside


def test_convex_primitives_without_planes_are_refused():
    with pytest.raises(ValueError, match="CONVEX primitives need their face planes"):
        line_intersections(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.array([CONVEX]), np.zeros((1, 3)))
    # Without CONVEX ones, no planes are needed.
    _, _, hit = line_intersections(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.array([BOX]), np.ones((1, 3)))
    assert hit[0]


# The vectorised numpy formulation of the three queries.


def numpy_slab(o: np.ndarray, d: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-h - o) / d
        t2 = (h - o) / d
    lo = np.minimum(t1, t2)
    hi = np.maximum(t1, t2)
    parallel = d == 0.0
    if np.any(parallel):
        inside = np.abs(o) <= h
        lo = np.where(parallel, np.where(inside, -_INF, _INF), lo)
        hi = np.where(parallel, np.where(inside, _INF, -_INF), hi)
    return lo, hi


def numpy_sphere_interval(o: np.ndarray, d: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    b = np.einsum("ij,ij->i", o, d)
    c = np.einsum("ij,ij->i", o, o) - r * r
    disc = b * b - c
    hit = disc >= 0.0
    s = np.sqrt(np.where(hit, disc, 0.0))
    return np.where(hit, -b - s, _INF), np.where(hit, -b + s, -_INF)


def numpy_radial_interval(o: np.ndarray, d: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]
    c = o[:, 0] ** 2 + o[:, 1] ** 2 - r * r
    parallel = a < 1e-14
    safe_a = np.where(parallel, 1.0, a)
    disc = b * b - a * c
    hit = disc >= 0.0
    s = np.sqrt(np.where(hit, disc, 0.0))
    lo = np.where(hit, (-b - s) / safe_a, _INF)
    hi = np.where(hit, (-b + s) / safe_a, -_INF)
    lo = np.where(parallel, np.where(c <= 0.0, -_INF, _INF), lo)
    hi = np.where(parallel, np.where(c <= 0.0, _INF, -_INF), hi)
    return lo, hi


def numpy_outward_normals(
    points: np.ndarray, kinds: np.ndarray, params: np.ndarray, planes: np.ndarray | None = None
) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    n = np.zeros_like(p)
    r = params[:, 0]
    m = kinds == SPHERE
    n[m] = p[m]
    m = kinds == BOX
    if np.any(m):
        ratio = np.abs(p[m]) - params[m]  # signed distance to each face plane
        axis = np.argmax(ratio, axis=1)
        rows = np.arange(axis.size)
        nb = np.zeros((axis.size, 3))
        nb[rows, axis] = np.sign(p[m][rows, axis])
        n[m] = nb
    m = kinds == CYLINDER
    if np.any(m):
        pc = p[m]
        radial = np.hypot(pc[:, 0], pc[:, 1]) - r[m]
        cap = np.abs(pc[:, 2]) - params[m, 1]
        side = radial >= cap
        nc = np.where(
            side[:, None],
            pc * np.array([1.0, 1.0, 0.0]),
            np.stack([np.zeros(len(pc)), np.zeros(len(pc)), np.sign(pc[:, 2])], axis=1),
        )
        n[m] = nc
    m = kinds == CAPSULE
    if np.any(m):
        pc = p[m].copy()
        pc[:, 2] -= np.clip(pc[:, 2], -params[m, 1], params[m, 1])
        n[m] = pc
    m = kinds == CONVEX
    if np.any(m):
        pl = planes[m]
        face = np.argmax(np.einsum("gpj,gj->gp", pl[:, :, :3], p[m]) - pl[:, :, 3], axis=1)
        n[m] = pl[np.arange(face.size), face, :3]
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(norm > 0.0, norm, 1.0)


def numpy_line_intersections(
    origins: np.ndarray, directions: np.ndarray, kinds: np.ndarray, params: np.ndarray, planes: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    o = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    g = len(kinds)
    l_in = np.full(g, _INF)
    l_out = np.full(g, -_INF)
    r = params[:, 0]

    m = kinds == SPHERE
    if np.any(m):
        l_in[m], l_out[m] = numpy_sphere_interval(o[m], d[m], r[m])
    m = kinds == BOX
    if np.any(m):
        lo, hi = numpy_slab(o[m], d[m], params[m])
        l_in[m], l_out[m] = lo.max(axis=1), hi.min(axis=1)
    m = kinds == CYLINDER
    if np.any(m):
        rlo, rhi = numpy_radial_interval(o[m], d[m], r[m])
        zlo, zhi = numpy_slab(o[m, 2], d[m, 2], params[m, 1])
        l_in[m], l_out[m] = np.maximum(rlo, zlo), np.minimum(rhi, zhi)
    m = kinds == CAPSULE
    if np.any(m):
        om, dm, rm, hm = o[m], d[m], r[m], params[m, 1]
        # Convex union of the finite cylinder and the two end spheres: the interval is the
        # union of the pieces' intervals (they overlap), i.e. min of entries, max of exits.
        rlo, rhi = numpy_radial_interval(om, dm, rm)
        zlo, zhi = numpy_slab(om[:, 2], dm[:, 2], hm)
        clo, chi = np.maximum(rlo, zlo), np.minimum(rhi, zhi)
        clo, chi = np.where(clo <= chi, clo, _INF), np.where(clo <= chi, chi, -_INF)
        shift = np.zeros_like(om)
        shift[:, 2] = hm
        alo, ahi = numpy_sphere_interval(om - shift, dm, rm)
        blo, bhi = numpy_sphere_interval(om + shift, dm, rm)
        l_in[m] = np.minimum(np.minimum(clo, alo), blo)
        l_out[m] = np.maximum(np.maximum(chi, ahi), bhi)
    m = kinds == CONVEX
    if np.any(m):
        pl = planes[m]
        denom = np.einsum("gpj,gj->gp", pl[:, :, :3], d[m])  # n . d
        room = pl[:, :, 3] - np.einsum("gpj,gj->gp", pl[:, :, :3], o[m])  # c - n . o
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = room / denom
        entry = np.where(denom < 0.0, bound, -_INF)
        exit_ = np.where(denom > 0.0, bound, _INF)
        blocked = ((denom == 0.0) & (room < 0.0)).any(axis=1)  # parallel and outside a face
        l_in[m] = np.where(blocked, _INF, entry.max(axis=1))
        l_out[m] = np.where(blocked, -_INF, exit_.min(axis=1))
    hit = l_in <= l_out
    return l_in, l_out, hit


def numpy_signed_distances(
    points: np.ndarray, kinds: np.ndarray, params: np.ndarray, planes: np.ndarray | None = None
) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    out = np.empty(p.shape[:2])
    r = params[:, 0]
    m = kinds == SPHERE
    if np.any(m):
        out[:, m] = np.linalg.norm(p[:, m], axis=2) - r[m]
    m = kinds == BOX
    if np.any(m):
        q = np.abs(p[:, m]) - params[m]
        out[:, m] = np.linalg.norm(np.maximum(q, 0.0), axis=2) + np.minimum(q.max(axis=2), 0.0)
    m = kinds == CYLINDER
    if np.any(m):
        pc = p[:, m]
        q = np.stack([np.hypot(pc[..., 0], pc[..., 1]) - r[m], np.abs(pc[..., 2]) - params[m, 1]], axis=-1)
        out[:, m] = np.linalg.norm(np.maximum(q, 0.0), axis=2) + np.minimum(q.max(axis=2), 0.0)
    m = kinds == CAPSULE
    if np.any(m):
        pc = p[:, m].copy()
        pc[..., 2] -= np.clip(pc[..., 2], -params[m, 1], params[m, 1])
        out[:, m] = np.linalg.norm(pc, axis=2) - r[m]
    m = kinds == CONVEX
    if np.any(m):
        pl = planes[m]
        out[:, m] = (np.einsum("gpj,mgj->mgp", pl[:, :, :3], p[:, m]) - pl[None, :, :, 3]).max(axis=2)
    return out
