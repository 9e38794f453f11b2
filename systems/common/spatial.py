"""Featherstone's 6-D spatial vector algebra in numpy, for the reference algorithms.

Ordering is Featherstone's and the paper's: motion vectors are ``[angular; linear]`` and
force vectors are ``[moment; force]``. Equation numbers refer to Flacco et al. 2016
(Sec. II-A) and to Featherstone, *Rigid Body Dynamics Algorithms*, 2008 (RBDA, Ch. 2).

These functions favour clarity over speed; they build fresh 3x3 / 6x6 arrays on every call.
"""

from __future__ import annotations

import numpy as np


def skew(r: np.ndarray) -> np.ndarray:
    """The 3x3 skew-symmetric matrix ``r×`` with ``skew(r) @ u == np.cross(r, u)`` (RBDA eq. 2.8)."""
    x, y, z = np.asarray(r, dtype=float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` of two 3-vectors, or row by row of (..., 3) arrays (broadcast).

    The arithmetic of ``np.cross`` ((a_y b_z - a_z b_y, a_z b_x - a_x b_z, a_x b_y - a_y b_x),
    the same numbers), without its overhead on single vectors (~15 µs per call).

    Raises:
        ValueError: an argument whose last dimension is not 3.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == (3,) and b.shape == (3,):
        ax, ay, az = a.tolist()
        bx, by, bz = b.tolist()
        return np.array((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx))
    if a.shape[-1:] != (3,) or b.shape[-1:] != (3,):
        raise ValueError(f"cross needs 3-vectors (shape (..., 3)), got shapes {a.shape} and {b.shape}")
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx), axis=-1)


def crm(v: np.ndarray) -> np.ndarray:
    """Spatial cross product for motion vectors, ``v×`` (RBDA eq. 2.31).

    ``crm(v) @ m`` is ``v × m`` for a motion vector ``m``; ``v = [w; u]`` gives
    ``[[w×, 0], [u×, w×]]``.
    """
    v = np.asarray(v, dtype=float).reshape(6)
    w = skew(v[:3])
    out = np.zeros((6, 6))
    out[:3, :3] = w
    out[3:, 3:] = w
    out[3:, :3] = skew(v[3:])
    return out


def crf(v: np.ndarray) -> np.ndarray:
    """Spatial cross product for force vectors, ``v×* = -(v×)^T`` (RBDA eq. 2.32)."""
    return -crm(v).T


def plucker(E: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Motion transform ``^B X_A`` (paper eq. 2, RBDA eq. 2.24: ``rot(E) xlt(r)``).

    Args:
        E: (3, 3) rotation ``^B E_A`` taking 3-D coordinates in A to coordinates in B.
        r: (3,) position of B's origin relative to A's origin, in A's coordinates.

    Returns:
        ``[[E, 0], [-E r×, E]]``, which maps motion vectors in A to motion vectors in B.
    """
    E = np.asarray(E, dtype=float).reshape(3, 3)
    out = np.zeros((6, 6))
    out[:3, :3] = E
    out[3:, 3:] = E
    out[3:, :3] = -E @ skew(r)
    return out


def force_transform(X: np.ndarray) -> np.ndarray:
    """Force transform ``X* = X^{-T}`` of a motion transform ``X`` (paper eq. 1, RBDA eq. 2.25).

    For ``X = [[E, 0], [-E r×, E]]`` this is ``[[E, -E r×], [0, E]]`` (no inversion needed).
    """
    X = np.asarray(X, dtype=float)
    out = np.zeros((6, 6))
    out[:3, :3] = X[:3, :3]
    out[3:, 3:] = X[3:, 3:]
    out[:3, 3:] = X[3:, :3]
    return out


def inverse_motion_transform(X: np.ndarray) -> np.ndarray:
    """``(^B X_A)^{-1} = ^A X_B`` of a Plücker motion transform (RBDA eq. 2.26)."""
    X = np.asarray(X, dtype=float)
    E = X[:3, :3]
    out = np.zeros((6, 6))
    out[:3, :3] = E.T
    out[3:, 3:] = E.T
    out[3:, :3] = X[3:, :3].T
    return out


def spatial_inertia(mass: float, com: np.ndarray, I_com: np.ndarray) -> np.ndarray:
    """Spatial inertia about a frame's origin, in that frame (RBDA eq. 2.63).

    Args:
        mass: body mass [kg].
        com: (3,) centre of mass in the frame's coordinates [m].
        I_com: (3, 3) rotational inertia about the centre of mass, frame axes [kg m^2].

    Returns:
        ``[[I_com + m c× c×^T, m c×], [m c×^T, m 1]]``.
    """
    C = skew(com)
    out = np.zeros((6, 6))
    out[:3, :3] = np.asarray(I_com, dtype=float) + mass * C @ C.T
    out[:3, 3:] = mass * C
    out[3:, :3] = mass * C.T
    out[3:, 3:] = mass * np.eye(3)
    return out


def transform_inertia(X_BA: np.ndarray, I_A: np.ndarray) -> np.ndarray:
    """Re-expresses a spatial inertia from frame A in frame B (paper eq. 3, RBDA eq. 2.66).

    ``^B I = ^B X*_A  ^A I  ^A X_B = (^A X_B)^T  ^A I  ^A X_B``, with ``X_BA = ^B X_A``.
    """
    X_AB = inverse_motion_transform(X_BA)
    return X_AB.T @ I_A @ X_AB
