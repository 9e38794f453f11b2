"""Validation and conversion of a floating-base robot's state (q, v) in Drake's coordinates.

q = [q_w, q_x, q_y, q_z, x, y, z, joints...]: the free joint's quaternion and position of the
base frame F0 in the joint's parent frame; v = [w, v_Bo, joint rates] in that parent frame.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

#: How far the base quaternion's norm may be from 1 before the state is refused; within it
#: the quaternion is normalised (a discrete simulator or a state estimator lets the norm
#: drift by a fraction of a per cent; a zero or garbage quaternion is refused).
QUATERNION_NORM_TOLERANCE = 0.05


def quaternion_to_rotation(quaternion_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion [w, x, y, z] (Drake's order)."""
    w, x, y, z = np.asarray(quaternion_wxyz, dtype=float).tolist()
    return np.array(  # a flat tuple of floats, reshaped: the cheapest way to a 3 x 3 array
        (
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        )
    ).reshape(3, 3)  # fmt: skip


def quaternions_to_rotations(quaternions_wxyz: np.ndarray) -> np.ndarray:
    """(K, 3, 3) rotation matrices of K unit quaternions (K, 4) [w, x, y, z]: the formula of
    ``quaternion_to_rotation``, stacked (the same numbers)."""
    w, x, y, z = np.asarray(quaternions_wxyz, dtype=float).T
    R = np.empty((len(w), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return R


def checked_state(
    plant: MultibodyPlant, q: np.ndarray, v: np.ndarray, sizes: tuple[int, int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Returns (q, v) as float arrays with a unit base quaternion, or raises ValueError.

    ``sizes`` = (num_positions, num_velocities) of ``plant``, when the caller has them cached.

    Raises:
        ValueError: wrong sizes, NaN or infinite entries (named by index), or a base
            quaternion whose norm is not 1 within ``QUATERNION_NORM_TOLERANCE``.
    """
    nq, nv = sizes if sizes is not None else (plant.num_positions(), plant.num_velocities())
    q = np.asarray(q, dtype=float).reshape(-1)
    v = np.asarray(v, dtype=float).reshape(-1)
    if q.size != nq:
        raise ValueError(f"q has {q.size} entries; the plant has {nq} positions")
    if v.size != nv:
        raise ValueError(f"v has {v.size} entries; the plant has {nv} velocities")
    if not math.isfinite(float(q @ q) + float(v @ v)):
        for name, x in (("q", q), ("v", v)):
            bad = np.flatnonzero(~np.isfinite(x))
            if bad.size:
                raise ValueError(f"{name} has non-finite entries (NaN or inf) at indices {bad.tolist()}")
    qw, qx, qy, qz = q[:4].tolist()
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise ValueError(f"the base quaternion q[0:4] has norm {norm:.6g}; expected a unit quaternion")
    if norm != 1.0:
        q = q.copy()
        q[:4] /= norm
    return q, v
