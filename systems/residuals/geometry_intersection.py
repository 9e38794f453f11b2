"""Analytic line / primitive geometry for contact localization (Flacco et al. 2016, Sec. VI).

The contact of a single unknown force lies on its line of action (eq. 22). This module
intersects such lines with a robot's collision primitives, all at once (vectorised numpy,
no Python loop over geometries), and gives the signed distance of points to the same
primitives (to discard intersections buried inside another link's geometry) and uniform
random points on their surfaces (for Monte Carlo studies).

Primitives, each in its own geometry frame G (Drake's conventions, SI units):

* ``SPHERE``: centre at the origin; params [radius, 0, 0].
* ``BOX``: centred, params [half width x, half depth y, half height z].
* ``CYLINDER``: axis z, centred; params [radius, half length, 0].
* ``CAPSULE``: axis z, centred, a cylinder of the given length closed by two hemispheres;
  params [radius, half length of the cylindrical part, 0].
* ``CONVEX``: a ``Convex`` or ``Mesh`` shape through its convex hull (Drake's
  ``GetConvexHull()``), as the half-spaces n . x <= c of its faces: ``planes`` (g, P, 4)
  rows [n, c] (unused rows [0, 0, 0, inf]); params [0, 0, 0]. Intersections by clipping the
  line against every face plane (Cyrus-Beck); the signed distance is max_f (n_f . x - c_f),
  exact inside and a lower bound outside. Surface sampling is for the four primitives only.

Lines are x(l) = o + l d with unit d (l in R, both directions). For a convex primitive the
intersection is one interval [l_in, l_out]: the line ENTERS at l_in (where d . n <= 0, n the
outward normal) and leaves at l_out. A force of direction d that pushes on the surface
(f . n < 0, Sec. VI) can therefore only act at the entry point.

Other shapes (half-spaces, ellipsoids) are not supported (``RobotGeometry`` raises
ValueError unless told to skip them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, Capsule, Convex, Cylinder, Mesh, SceneGraphInspector, Sphere
from pydrake.multibody.plant import MultibodyPlant

SPHERE, BOX, CYLINDER, CAPSULE, CONVEX = 0, 1, 2, 3, 4
KIND_NAMES = ("sphere", "box", "cylinder", "capsule", "convex")

_INF = np.inf


def _slab(o: np.ndarray, d: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry/exit parameters of lines o + l d through slabs |x| <= h (element-wise).

    Where d = 0 the interval is (-inf, inf) if |o| <= h, else empty (+inf, -inf)."""
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


def _sphere_interval(o: np.ndarray, d: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(l_in, l_out) of unit-direction lines through spheres of radius r at the origin
    (l_in = +inf, l_out = -inf on a miss)."""
    b = np.einsum("ij,ij->i", o, d)
    c = np.einsum("ij,ij->i", o, o) - r * r
    disc = b * b - c
    hit = disc >= 0.0
    s = np.sqrt(np.where(hit, disc, 0.0))
    return np.where(hit, -b - s, _INF), np.where(hit, -b + s, -_INF)


def _radial_interval(o: np.ndarray, d: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(l_in, l_out) of lines through infinite cylinders x^2 + y^2 <= r^2 (axis z)."""
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


def outward_normals(
    points: np.ndarray, kinds: np.ndarray, params: np.ndarray, planes: np.ndarray | None = None
) -> np.ndarray:
    """Outward unit normals of the primitives at (or near) surface points, geometry frames.

    Args:
        points: (g, 3) one point per primitive, in its frame G, m.
        kinds, params: (g,), (g, 3) as in the module docstring.

    Returns:
        (g, 3). For a box the face of the largest normalised coordinate; for a cylinder the
        side or the cap, whichever the point is closer to (edges: either).
    """
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


def line_intersections(
    origins: np.ndarray, directions: np.ndarray, kinds: np.ndarray, params: np.ndarray, planes: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entry and exit parameters of lines through primitives, one line per primitive.

    Args:
        origins: (g, 3) a point of each line, in the primitive's frame G, m.
        directions: (g, 3) unit directions in G.
        kinds: (g,) SPHERE, BOX, CYLINDER or CAPSULE.
        params: (g, 3) shape parameters (module docstring), m.
        planes: (g, P, 4) face planes of CONVEX primitives (may be None without them).

    Returns:
        (l_in, l_out, hit): (g,) parameters of the entry and exit points o + l d (m, since d
        is a unit vector) and whether the line meets the primitive (l_in <= l_out). For
        tangent lines l_in == l_out.
    """
    o = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    g = len(kinds)
    l_in = np.full(g, _INF)
    l_out = np.full(g, -_INF)
    r = params[:, 0]

    m = kinds == SPHERE
    if np.any(m):
        l_in[m], l_out[m] = _sphere_interval(o[m], d[m], r[m])
    m = kinds == BOX
    if np.any(m):
        lo, hi = _slab(o[m], d[m], params[m])
        l_in[m], l_out[m] = lo.max(axis=1), hi.min(axis=1)
    m = kinds == CYLINDER
    if np.any(m):
        rlo, rhi = _radial_interval(o[m], d[m], r[m])
        zlo, zhi = _slab(o[m, 2], d[m, 2], params[m, 1])
        l_in[m], l_out[m] = np.maximum(rlo, zlo), np.minimum(rhi, zhi)
    m = kinds == CAPSULE
    if np.any(m):
        om, dm, rm, hm = o[m], d[m], r[m], params[m, 1]
        # Convex union of the finite cylinder and the two end spheres: the interval is the
        # union of the pieces' intervals (they overlap), i.e. min of entries, max of exits.
        rlo, rhi = _radial_interval(om, dm, rm)
        zlo, zhi = _slab(om[:, 2], dm[:, 2], hm)
        clo, chi = np.maximum(rlo, zlo), np.minimum(rhi, zhi)
        clo, chi = np.where(clo <= chi, clo, _INF), np.where(clo <= chi, chi, -_INF)
        shift = np.zeros_like(om)
        shift[:, 2] = hm
        alo, ahi = _sphere_interval(om - shift, dm, rm)
        blo, bhi = _sphere_interval(om + shift, dm, rm)
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


def signed_distances(
    points: np.ndarray, kinds: np.ndarray, params: np.ndarray, planes: np.ndarray | None = None
) -> np.ndarray:
    """Signed distance of points to primitives (negative inside), m.

    Args:
        points: (m, g, 3) point i expressed in primitive j's frame.
        kinds, params: (g,), (g, 3).

    Returns:
        (m, g). Exact for spheres, boxes, cylinders and capsules; for CONVEX exact inside and
        a lower bound outside (the largest face-plane distance).
    """
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


def surface_areas(kinds: np.ndarray, params: np.ndarray) -> np.ndarray:
    """(g,) surface areas of the primitives, m^2."""
    r, h = params[:, 0], params[:, 1]
    area = np.zeros(len(kinds))
    area[kinds == SPHERE] = (4.0 * np.pi * r**2)[kinds == SPHERE]
    b = params
    area[kinds == BOX] = (8.0 * (b[:, 0] * b[:, 1] + b[:, 1] * b[:, 2] + b[:, 0] * b[:, 2]))[kinds == BOX]
    area[kinds == CYLINDER] = (2.0 * np.pi * r * 2.0 * h + 2.0 * np.pi * r**2)[kinds == CYLINDER]
    area[kinds == CAPSULE] = (2.0 * np.pi * r * 2.0 * h + 4.0 * np.pi * r**2)[kinds == CAPSULE]
    return area


def sample_surface(kind: int, params: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One point uniformly distributed (by area) on a primitive's surface.

    Returns:
        (p_G, n_G): the point and the outward unit normal there, in the primitive's frame.
    """
    r, h = float(params[0]), float(params[1])
    if kind == SPHERE:
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        return r * n, n
    if kind == BOX:
        hx, hy, hz = (float(v) for v in params)
        faces = np.array([hy * hz, hy * hz, hx * hz, hx * hz, hx * hy, hx * hy])
        face = rng.choice(6, p=faces / faces.sum())
        axis, sign = face // 2, 1.0 if face % 2 == 0 else -1.0
        p = rng.uniform(-1.0, 1.0, 3) * params
        p[axis] = sign * params[axis]
        n = np.zeros(3)
        n[axis] = sign
        return p, n
    if kind == CYLINDER:
        side, caps = 4.0 * np.pi * r * h, 2.0 * np.pi * r * r
        if rng.uniform() < side / (side + caps):
            phi = rng.uniform(0.0, 2.0 * np.pi)
            n = np.array([np.cos(phi), np.sin(phi), 0.0])
            return np.array([r * n[0], r * n[1], rng.uniform(-h, h)]), n
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        rho, phi = r * np.sqrt(rng.uniform()), rng.uniform(0.0, 2.0 * np.pi)
        return np.array([rho * np.cos(phi), rho * np.sin(phi), sign * h]), np.array([0.0, 0.0, sign])
    if kind == CAPSULE:
        side, ends = 4.0 * np.pi * r * h, 4.0 * np.pi * r * r
        if rng.uniform() < side / (side + ends):
            phi = rng.uniform(0.0, 2.0 * np.pi)
            n = np.array([np.cos(phi), np.sin(phi), 0.0])
            return np.array([r * n[0], r * n[1], rng.uniform(-h, h)]), n
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        return r * n + np.array([0.0, 0.0, h if n[2] >= 0.0 else -h]), n
    raise ValueError(f"surface sampling supports spheres, boxes, cylinders and capsules, not kind {kind}")


def convex_hull_planes(shape) -> np.ndarray:
    """(F, 4) face planes [n, c] (outward unit n, n . x <= c inside) of the convex hull of a
    ``Convex`` or ``Mesh`` shape, in its geometry frame (Drake's ``GetConvexHull()``)."""
    hull = shape.GetConvexHull()
    vertices = np.array([hull.vertex(i) for i in range(hull.num_vertices())]).reshape(-1, 3)
    data = hull.face_data()
    planes, i = [], 0
    for f in range(hull.num_faces()):
        count = data[i]
        first = vertices[data[i + 1]]
        n = np.asarray(hull.face_normal(f), dtype=float).reshape(3)
        planes.append([*n, float(n @ first)])
        i += count + 1
    return np.array(planes)


def shape_parameters(shape) -> tuple[int, np.ndarray] | None:
    """(kind, params) of a Drake shape, or None for an unsupported shape (CONVEX shapes need
    ``convex_hull_planes`` too)."""
    if isinstance(shape, Sphere):
        return SPHERE, np.array([shape.radius(), 0.0, 0.0])
    if isinstance(shape, Box):
        return BOX, 0.5 * np.array([shape.width(), shape.depth(), shape.height()])
    if isinstance(shape, Cylinder):
        return CYLINDER, np.array([shape.radius(), 0.5 * shape.length(), 0.0])
    if isinstance(shape, Capsule):
        return CAPSULE, np.array([shape.radius(), 0.5 * shape.length(), 0.0])
    if isinstance(shape, (Convex, Mesh)):
        return CONVEX, np.zeros(3)
    return None


@dataclass
class RobotGeometry:
    """A robot's collision primitives, each fixed in a body, ready for vectorised queries.

    Attributes:
        body_indices: (g,) int, the plant BodyIndex of each primitive's body.
        kinds: (g,) int, SPHERE/BOX/CYLINDER/CAPSULE/CONVEX.
        params: (g, 3) shape parameters, m.
        planes: (g, P, 4) face planes of the CONVEX ones (padding rows [0, 0, 0, inf]).
        X_BG: (g, 3, 4) the primitive's pose in its body frame [R | p].
        names: the geometries' names.
        bodies: the unique body indices, and ``slot`` (g,) the position of each primitive's
            body in ``bodies`` (to gather body poses once per body).
    """

    body_indices: np.ndarray
    kinds: np.ndarray
    params: np.ndarray
    planes: np.ndarray
    X_BG: np.ndarray
    names: tuple[str, ...]
    bodies: np.ndarray
    slot: np.ndarray

    @staticmethod
    def from_plant(
        plant: MultibodyPlant,
        inspector: SceneGraphInspector,
        bodies=None,
        *,
        skip_unsupported: bool = False,
    ) -> RobotGeometry:
        """Collects the collision geometries of ``bodies`` (default: every body but the world).

        Raises:
            ValueError: a shape other than sphere/box/cylinder/capsule/convex/mesh (unless
                ``skip_unsupported``), or no supported geometry at all.
        """
        if bodies is None:
            bodies = [plant.get_body(i) for i in range(1, plant.num_bodies())]
        rows = []
        for body in bodies:
            for gid in plant.GetCollisionGeometriesForBody(body):
                shape = inspector.GetShape(gid)
                parsed = shape_parameters(shape)
                name = inspector.GetName(gid)
                if parsed is None:
                    if skip_unsupported:
                        continue
                    raise ValueError(
                        f"collision geometry '{name}' of body '{body.name()}' is a {type(shape).__name__}: "
                        "only spheres, boxes, cylinders, capsules and convex hulls of meshes are supported"
                    )
                planes = convex_hull_planes(shape) if parsed[0] == CONVEX else np.zeros((0, 4))
                X = inspector.GetPoseInFrame(gid).GetAsMatrix34()
                rows.append((int(body.index()), parsed[0], parsed[1], X, name, planes))
        if not rows:
            raise ValueError("no supported collision geometry on the given bodies")
        body_indices = np.array([r[0] for r in rows], dtype=int)
        unique, slot = np.unique(body_indices, return_inverse=True)
        max_planes = max(len(r[5]) for r in rows)
        planes = np.zeros((len(rows), max(max_planes, 1), 4))
        planes[:, :, 3] = np.inf
        for i, r in enumerate(rows):
            planes[i, : len(r[5])] = r[5]
        return RobotGeometry(
            body_indices=body_indices,
            kinds=np.array([r[1] for r in rows], dtype=int),
            params=np.array([r[2] for r in rows]),
            planes=planes,
            X_BG=np.array([r[3] for r in rows]),
            names=tuple(r[4] for r in rows),
            bodies=unique,
            slot=slot,
        )

    def __len__(self) -> int:
        return len(self.kinds)

    def world_poses(self, X_WB: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R_WG (g, 3, 3), p_WG (g, 3)) from the body poses X_WB (len(bodies), 3, 4)."""
        X = X_WB[self.slot]
        R_WB, p_WB = X[:, :, :3], X[:, :, 3]
        R_WG = R_WB @ self.X_BG[:, :, :3]
        p_WG = np.einsum("gij,gj->gi", R_WB, self.X_BG[:, :, 3]) + p_WB
        return R_WG, p_WG

    def outside_other_links(self, p_W: np.ndarray, R_WG: np.ndarray, p_WG: np.ndarray, body_index: int) -> bool:
        """True when the world point p_W lies outside every primitive of the links other
        than ``body_index`` (poses from ``world_poses``): a point of the robot's outer
        surface, where a pusher can touch it."""
        local = np.einsum("gji,gj->gi", R_WG, p_W - p_WG)[None]
        distances = signed_distances(local, self.kinds, self.params, self.planes)[0]
        distances[self.body_indices == body_index] = np.inf
        return bool(distances.min() > 0.0)


def inward_direction(n_W: np.ndarray, rng: np.random.Generator, max_angle_deg: float = 60.0) -> np.ndarray:
    """A unit direction uniform on the spherical cap of half-angle ``max_angle_deg`` around
    -n_W (a push into a surface of outward normal n_W)."""
    ct = rng.uniform(math.cos(math.radians(max_angle_deg)), 1.0)
    phi = rng.uniform(0.0, 2.0 * math.pi)
    a = np.cross(n_W, [1.0, 0.0, 0.0])
    if np.linalg.norm(a) < 0.1:
        a = np.cross(n_W, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n_W, a)
    return -ct * n_W + math.sqrt(1.0 - ct * ct) * (math.cos(phi) * a + math.sin(phi) * b)
