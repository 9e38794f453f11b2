"""The result type shared by every implementation of the floating-base decomposition.

Coordinates (the paper's, Flacco et al. 2016, Sec. III; Featherstone 2008, Sec. 9.4):

* ``F0`` is the floating base's frame: the child frame of the plant's free joint (the base
  body's own frame for a body that Drake made floating).
* The base velocity is ``v0 = [w_WB_B; v_WBo_B]``: angular then linear velocity of F0 in
  the world, both expressed in F0 (Featherstone's base-frame coordinates). Its time
  derivative is the base acceleration ``a0`` of eq. (9).
* Spatial forces on the base are ``[moment about the F0 origin; force]``, expressed in F0.
* Joint-space quantities are ordered as the plant's joint velocities ``v[6:]``.

Drake's own free-joint velocities are ``[w_WB_W; v_WBo_W]`` (world-aligned), so the base rows
of Drake's mass matrix differ from ``F`` and ``I0c`` by the base rotation; the quantities of
the reduced joint dynamics (``H``, ``H_fb``, ``C_fb``, ``H_fb_dot``) and the floating
Jacobian do not depend on that choice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack


@dataclass(slots=True)
class FloatingBaseTerms:
    """Floating-base decomposition of the equations of motion, paper eq. (9), at one (q, v).

    Attributes:
        H: (n, n) joint-space inertia with F0 as base [kg m^2 / kg].
        F: (6, n) columns are the spatial forces at F0 (in F0) that support a unit
            acceleration of each joint.
        I0c: (6, 6) composite spatial inertia of the whole robot about the F0 origin, in F0.
        C_hat: (n,) joint bias force with zero base and joint accelerations, gravity
            included (Algorithm 1's C^) [N m or N].
        p_hat: (6,) spatial bias force of the whole robot at F0, in F0, gravity included
            (Algorithm 1's p^0c).
        H_dot, F_dot, I0c_dot: time derivatives of H, F, I0c along the current motion
            (Algorithm 2). In F0 these depend on the joint velocities only.
        H_fb: (n, n) floating inertia H - F^T I0c^-1 F.
        H_fb_dot: (n, n) its time derivative, eq. (13).
        C_fb: (n,) floating generalized bias force C^ - F^T I0c^-1 p^0c.
        R_WB: (3, 3) rotation of F0 in the world.
        v0: (6,) base velocity [w_WB_B; v_WBo_B].
        I0c_inv_F: (6, n) I0c^-1 F, the by-product of the elimination; it maps a base-frame
            wrench w_F0 to its joint share: J^fb^T = J_0^T - F^T I0c^-1 (eq. 9, 10).
    """

    H: np.ndarray
    F: np.ndarray
    I0c: np.ndarray
    C_hat: np.ndarray
    p_hat: np.ndarray
    H_dot: np.ndarray
    F_dot: np.ndarray
    I0c_dot: np.ndarray
    H_fb: np.ndarray
    H_fb_dot: np.ndarray
    C_fb: np.ndarray
    R_WB: np.ndarray
    v0: np.ndarray
    I0c_inv_F: np.ndarray


def reduce_to_floating_terms(
    H: np.ndarray,
    F: np.ndarray,
    I0c: np.ndarray,
    C_hat: np.ndarray,
    p_hat: np.ndarray,
    H_dot: np.ndarray,
    F_dot: np.ndarray,
    I0c_dot: np.ndarray,
    R_WB: np.ndarray,
    v0: np.ndarray,
) -> FloatingBaseTerms:
    """Eliminates the base acceleration (paper eq. 9) and differentiates the result (eq. 13).

    H_fb = H - F^T I0c^-1 F, C_fb = C^ - F^T I0c^-1 p^, and
    H_fb_dot = H_dot - F_dot^T I0c^-1 F - F^T I0c^-1 F_dot + F^T I0c^-1 I0c_dot I0c^-1 F.
    """
    # One Cholesky solve (LAPACK dposv: low call overhead at this size) gives G = I0c^-1 F;
    # F^T I0c^-1 p^ = G^T p^ because I0c is symmetric.
    _, G, info = lapack.dposv(I0c, F)
    if info != 0:
        raise ValueError(f"the composite inertia I0c is not positive definite (LAPACK dposv info={info})")
    FT_Iinv_Fdot = G.T @ F_dot
    H_fb = H - F.T @ G
    C_fb = C_hat - G.T @ p_hat
    H_fb_dot = H_dot - FT_Iinv_Fdot - FT_Iinv_Fdot.T + G.T @ I0c_dot @ G
    return FloatingBaseTerms(
        H=H,
        F=F,
        I0c=I0c,
        C_hat=C_hat,
        p_hat=p_hat,
        H_dot=H_dot,
        F_dot=F_dot,
        I0c_dot=I0c_dot,
        H_fb=H_fb,
        H_fb_dot=H_fb_dot,
        C_fb=C_fb,
        R_WB=R_WB,
        v0=v0,
        I0c_inv_F=G,
    )
