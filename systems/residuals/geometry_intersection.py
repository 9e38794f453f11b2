"""Analytic line / primitive geometry for contact localization (Flacco et al. 2016, Sec. VI).

The contact of a single unknown force lies on its line of action (eq. 22). This module
intersects such lines with a robot's collision primitives, all at once (one compiled loop
over the primitives, numba; a localization's queries cost microseconds), and gives the
signed distance of points to the same primitives (to discard intersections buried inside
another link's geometry) and uniform random points on their surfaces (for Monte Carlo
studies).

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
from numba import njit
from pydrake.geometry import Box, Capsule, Convex, Cylinder, Mesh, SceneGraphInspector, Sphere
from pydrake.multibody.plant import MultibodyPlant

SPHERE, BOX, CYLINDER, CAPSULE, CONVEX = 0, 1, 2, 3, 4
KIND_NAMES = ("sphere", "box", "cylinder", "capsule", "convex")

_INF = np.inf


# ---------------------------------------------------------------------------------------
# The queries' per-primitive arithmetic, compiled (numba): a localization queries a few to a
# few dozen primitives, where numpy's per-call overhead (about 60 array operations per query)
# cost ten times the arithmetic. One loop over the primitives, the formulas in the order of
# the module docstring's definitions.
# ---------------------------------------------------------------------------------------


@njit(cache=True)
def _slab_1d(o: float, d: float, h: float) -> tuple[float, float]:
    """(lo, hi) of the line o + l d through the slab |x| <= h; d = 0: (-inf, inf) when
    |o| <= h, else the empty (inf, -inf)."""
    if d == 0.0:
        if abs(o) <= h:
            return -_INF, _INF
        return _INF, -_INF
    t1 = (-h - o) / d
    t2 = (h - o) / d
    return min(t1, t2), max(t1, t2)


@njit(cache=True)
def _sphere_1(ox: float, oy: float, oz: float, dx: float, dy: float, dz: float, r: float) -> tuple[float, float]:
    """(l_in, l_out) of a unit-direction line through a sphere of radius r at the origin."""
    b = ox * dx + oy * dy + oz * dz
    c = (ox * ox + oy * oy + oz * oz) - r * r
    disc = b * b - c
    if disc >= 0.0:
        s = math.sqrt(disc)
        return -b - s, -b + s
    return _INF, -_INF


@njit(cache=True)
def _radial_1(ox: float, oy: float, dx: float, dy: float, r: float) -> tuple[float, float]:
    """(l_in, l_out) of a line through the infinite cylinder x^2 + y^2 <= r^2."""
    a = dx * dx + dy * dy
    b = ox * dx + oy * dy
    c = ox * ox + oy * oy - r * r
    if a < 1e-14:  # parallel to the axis
        if c <= 0.0:
            return -_INF, _INF
        return _INF, -_INF
    disc = b * b - a * c
    if disc >= 0.0:
        s = math.sqrt(disc)
        return (-b - s) / a, (-b + s) / a
    return _INF, -_INF


@njit(cache=True)
def _line_intervals(o, d, kinds, params, planes, l_in, l_out) -> None:
    for g in range(kinds.shape[0]):
        ox, oy, oz = o[g, 0], o[g, 1], o[g, 2]
        dx, dy, dz = d[g, 0], d[g, 1], d[g, 2]
        kind, r, h = kinds[g], params[g, 0], params[g, 1]
        lo, hi = _INF, -_INF
        if kind == SPHERE:
            lo, hi = _sphere_1(ox, oy, oz, dx, dy, dz, r)
        elif kind == BOX:
            lx, hx = _slab_1d(ox, dx, params[g, 0])
            ly, hy = _slab_1d(oy, dy, params[g, 1])
            lz, hz = _slab_1d(oz, dz, params[g, 2])
            lo, hi = max(lx, ly, lz), min(hx, hy, hz)
        elif kind == CYLINDER:
            rlo, rhi = _radial_1(ox, oy, dx, dy, r)
            zlo, zhi = _slab_1d(oz, dz, h)
            lo, hi = max(rlo, zlo), min(rhi, zhi)
        elif kind == CAPSULE:
            # Convex union of the finite cylinder and the two end spheres: the interval is
            # the union of the pieces' intervals (they overlap): min of entries, max of exits.
            rlo, rhi = _radial_1(ox, oy, dx, dy, r)
            zlo, zhi = _slab_1d(oz, dz, h)
            clo, chi = max(rlo, zlo), min(rhi, zhi)
            if not clo <= chi:
                clo, chi = _INF, -_INF
            alo, ahi = _sphere_1(ox, oy, oz - h, dx, dy, dz, r)
            blo, bhi = _sphere_1(ox, oy, oz + h, dx, dy, dz, r)
            lo, hi = min(min(clo, alo), blo), max(max(chi, ahi), bhi)
        elif kind == CONVEX:
            # Cyrus-Beck: clip the line against every face plane n . x <= c.
            lo, hi = -_INF, _INF
            blocked = False
            for p in range(planes.shape[1]):
                nx, ny, nz, c = planes[g, p, 0], planes[g, p, 1], planes[g, p, 2], planes[g, p, 3]
                denom = nx * dx + ny * dy + nz * dz  # n . d
                room = c - (nx * ox + ny * oy + nz * oz)  # c - n . o
                if denom < 0.0:
                    lo = max(lo, room / denom)
                elif denom > 0.0:
                    hi = min(hi, room / denom)
                elif room < 0.0:  # parallel and outside the face
                    blocked = True
            if blocked:
                lo, hi = _INF, -_INF
        l_in[g], l_out[g] = lo, hi


@njit(cache=True)
def _normals(p, kinds, params, planes, out) -> None:
    for g in range(kinds.shape[0]):
        x, y, z = p[g, 0], p[g, 1], p[g, 2]
        kind = kinds[g]
        nx, ny, nz = 0.0, 0.0, 0.0
        if kind == SPHERE:
            nx, ny, nz = x, y, z
        elif kind == BOX:
            # The face of the largest normalised coordinate (the first on a tie).
            rx, ry, rz = abs(x) - params[g, 0], abs(y) - params[g, 1], abs(z) - params[g, 2]
            if rx >= ry and rx >= rz:
                nx = np.sign(x)
            elif ry >= rz:
                ny = np.sign(y)
            else:
                nz = np.sign(z)
        elif kind == CYLINDER:
            if math.hypot(x, y) - params[g, 0] >= abs(z) - params[g, 1]:
                nx, ny = x, y
            else:
                nz = np.sign(z)
        elif kind == CAPSULE:
            h = params[g, 1]
            nx, ny, nz = x, y, z - min(max(z, -h), h)
        elif kind == CONVEX:
            best, face = -_INF, 0
            for f in range(planes.shape[1]):
                s = (planes[g, f, 0] * x + planes[g, f, 1] * y + planes[g, f, 2] * z) - planes[g, f, 3]
                if s > best:
                    best, face = s, f
            nx, ny, nz = planes[g, face, 0], planes[g, face, 1], planes[g, face, 2]
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        if not norm > 0.0:
            norm = 1.0
        out[g, 0], out[g, 1], out[g, 2] = nx / norm, ny / norm, nz / norm


@njit(cache=True)
def _distances(p, kinds, params, planes, out) -> None:
    for g in range(kinds.shape[0]):
        kind, r, h = kinds[g], params[g, 0], params[g, 1]
        for i in range(p.shape[0]):
            x, y, z = p[i, g, 0], p[i, g, 1], p[i, g, 2]
            if kind == SPHERE:
                out[i, g] = math.sqrt(x * x + y * y + z * z) - r
            elif kind == BOX:
                qx, qy, qz = abs(x) - params[g, 0], abs(y) - params[g, 1], abs(z) - params[g, 2]
                ux, uy, uz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
                out[i, g] = math.sqrt(ux * ux + uy * uy + uz * uz) + min(max(qx, qy, qz), 0.0)
            elif kind == CYLINDER:
                qr, qz = math.hypot(x, y) - r, abs(z) - h
                ur, uz = max(qr, 0.0), max(qz, 0.0)
                out[i, g] = math.sqrt(ur * ur + uz * uz) + min(max(qr, qz), 0.0)
            elif kind == CAPSULE:
                zc = z - min(max(z, -h), h)
                out[i, g] = math.sqrt(x * x + y * y + zc * zc) - r
            elif kind == CONVEX:
                best = -_INF
                for f in range(planes.shape[1]):
                    s = (planes[g, f, 0] * x + planes[g, f, 1] * y + planes[g, f, 2] * z) - planes[g, f, 3]
                    best = max(best, s)
                out[i, g] = best
            else:
                out[i, g] = _INF


def load_compiled_queries() -> None:
    """Compiles the queries' kernels (a machine's first run, a few seconds; ``make`` does it
    at install) or loads them from numba's cache beside this file: one query of each kind."""
    kinds = np.arange(5)
    params, planes = np.full((5, 3), 0.1), np.zeros((5, 1, 4))
    planes[4, 0] = (0.0, 0.0, 1.0, 0.1)
    o, d = np.zeros((5, 3)), np.tile([0.0, 0.0, 1.0], (5, 1))
    line_intersections(o, d, kinds, params, planes)
    outward_normals(o, kinds, params, planes)
    signed_distances(o[None], kinds, params, planes)


def _query_arrays(kinds: np.ndarray, params: np.ndarray, planes: np.ndarray | None, who: str):
    """(kinds int64, params float64 (g, 3), planes float64 (g, P, 4)) contiguous, as the
    kernels take them; planes may be None only without CONVEX primitives."""
    kinds = np.ascontiguousarray(kinds, dtype=np.int64)
    params = np.ascontiguousarray(params, dtype=float)
    if planes is None:
        if np.any(kinds == CONVEX):
            raise ValueError(f"{who}: CONVEX primitives need their face planes")
        planes = np.zeros((kinds.shape[0], 0, 4))
    return kinds, params, np.ascontiguousarray(planes, dtype=float)


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
    kinds, params, planes = _query_arrays(kinds, params, planes, "outward_normals")
    out = np.empty((kinds.shape[0], 3))
    _normals(np.ascontiguousarray(points, dtype=float), kinds, params, planes, out)
    return out


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
    kinds, params, planes = _query_arrays(kinds, params, planes, "line_intersections")
    g = kinds.shape[0]
    l_in, l_out = np.empty(g), np.empty(g)
    o = np.ascontiguousarray(origins, dtype=float)
    _line_intervals(o, np.ascontiguousarray(directions, dtype=float), kinds, params, planes, l_in, l_out)
    return l_in, l_out, l_in <= l_out


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
    kinds, params, planes = _query_arrays(kinds, params, planes, "signed_distances")
    p = np.ascontiguousarray(points, dtype=float)
    out = np.empty(p.shape[:2])
    _distances(p, kinds, params, planes, out)
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
