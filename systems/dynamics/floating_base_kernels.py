"""The floating-base dynamics' per-state arithmetic, compiled (numba): the gather of
Pinocchio's mass matrix and Coriolis matrix into F0 coordinates
(``PinocchioFloatingBaseDynamics.mass_matrix_terms``) and the residuals' momenta and rates
(``systems.residuals.momentum_residuals.ResidualModel.state_rates``).

At every residual update (1 kHz in the simulations) the model turns the floating-base mass
matrix M (nv x nv, F0 coordinates: base [w_B; v_B] then the joints), its derivative M_dot and
the bias [p^; C^] into the three residuals' momenta and model rates (``ResidualModel.
state_rates``'s docstring: the elimination of eq. (9) and its derivative, eq. (13), applied
to vectors). In numpy these are a dozen small products and two 6 x 6 Cholesky solves, whose
cost is mostly call overhead; here they are one compiled call of plain loops. The numbers
are the numpy formulas' to rounding (``tests/test_momentum_residuals.py``).

Compiled once per machine (``cache=True``: numba's cache beside this file);
``load_compiled_kernels`` loads them into a process.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def gather_mass_matrix_terms(M_pin: np.ndarray, C: np.ndarray, v_pin: np.ndarray, P: np.ndarray, g_B: np.ndarray):
    """(M, M_dot, bias) in F0 coordinates from Pinocchio's: M = M_pin[P][:, P], its exact
    derivative M_dot = (C + C^T)[P][:, P], and bias = (C v_pin)[P] - M[:, 3:6] g_B, the
    Coriolis terms plus gravity (g_B: gravity in the base frame, m/s^2; M[:, 3:6] g_B is the
    generalized gravity force of a free body's linear coordinates).

    Args:
        M_pin, C: (nv, nv) Pinocchio's mass and Coriolis matrices (``crba``,
            ``computeCoriolisMatrix``). v_pin: (nv) Pinocchio's velocity. P: (nv) int64, F0
            coordinate a is Pinocchio's P[a].
    """
    nv = P.size
    Cv = np.zeros(nv)
    for i in range(nv):
        s = 0.0
        for j in range(nv):
            s += C[i, j] * v_pin[j]
        Cv[i] = s
    M = np.empty((nv, nv))
    M_dot = np.empty((nv, nv))
    for a in range(nv):
        pa = P[a]
        for b in range(nv):
            pb = P[b]
            M[a, b] = M_pin[pa, pb]
            M_dot[a, b] = C[pa, pb] + C[pb, pa]
    bias = np.empty(nv)
    for a in range(nv):
        bias[a] = Cv[P[a]] - (M[a, 3] * g_B[0] + M[a, 4] * g_B[1] + M[a, 5] * g_B[2])
    return M, M_dot, bias


@njit(cache=True)
def _cholesky_upper(A: np.ndarray) -> tuple[np.ndarray, bool]:
    """(U, ok): U upper triangular with A = U^T U (LAPACK dpotrf's upper factor; zeros below
    the diagonal), ok False when A is not positive definite."""
    m = A.shape[0]
    U = np.zeros((m, m))
    for i in range(m):
        s = A[i, i]
        for k in range(i):
            s -= U[k, i] * U[k, i]
        if not s > 0.0:
            return U, False
        d = np.sqrt(s)
        U[i, i] = d
        for j in range(i + 1, m):
            t = A[i, j]
            for k in range(i):
                t -= U[k, i] * U[k, j]
            U[i, j] = t / d
    return U, True


@njit(cache=True)
def _solve_upper(U: np.ndarray, B: np.ndarray) -> np.ndarray:
    """X with U^T U X = B (B: m x k), by forward then back substitution."""
    m, k = B.shape
    X = B.copy()
    for c in range(k):
        for i in range(m):  # U^T y = b
            s = X[i, c]
            for j in range(i):
                s -= U[j, i] * X[j, c]
            X[i, c] = s / U[i, i]
        for i in range(m - 1, -1, -1):  # U x = y
            s = X[i, c]
            for j in range(i + 1, m):
                s -= U[i, j] * X[j, c]
            X[i, c] = s / U[i, i]
    return X


@njit(cache=True)
def floating_state_rates(M: np.ndarray, M_dot: np.ndarray, bias: np.ndarray, v0: np.ndarray, qdot: np.ndarray):
    """The residuals' momenta and model rates at one state.

    Args:
        M, M_dot: (nv, nv) the F0 mass matrix [[I0c, F], [F^T, H]] and its time derivative.
        bias: (nv) [p^; C^] (gravity included). v0: (6) [w_B; v_B]. qdot: (n = nv - 6).

    Returns:
        (p_classical = M nu, a_classical = M_dot nu - bias (nv, nu = [v0; qdot]),
        p_internal = H_fb qdot, a_internal = H_fb_dot qdot - C_fb (n), U (6 x 6, I0c = U^T U),
        ok: False when I0c is not positive definite (the other outputs are then not set)).
    """
    nv = M.shape[0]
    n = nv - 6
    p_c = np.zeros(nv)
    a_c = np.zeros(nv)
    Mq = np.zeros(nv)  # M [0; qdot]
    Mdq = np.zeros(nv)  # M_dot [0; qdot]
    for i in range(nv):
        s_q = 0.0
        s_dq = 0.0
        for j in range(n):
            s_q += M[i, 6 + j] * qdot[j]
            s_dq += M_dot[i, 6 + j] * qdot[j]
        s_v = 0.0
        s_dv = 0.0
        for j in range(6):
            s_v += M[i, j] * v0[j]
            s_dv += M_dot[i, j] * v0[j]
        Mq[i], Mdq[i] = s_q, s_dq
        p_c[i] = s_v + s_q
        a_c[i] = s_dv + s_dq - bias[i]
    U, ok = _cholesky_upper(M[:6, :6])
    p_i = np.zeros(n)
    a_i = np.zeros(n)
    if not ok:
        return p_c, a_c, p_i, a_i, U, False
    G_qdot = _solve_upper(U, Mq[:6].reshape(6, 1))[:, 0]  # I0c^-1 F qdot
    rhs = np.zeros((6, 3))  # [F_dot qdot, I0c_dot G qdot, p^]
    for r in range(6):
        s = 0.0
        for c in range(6):
            s += M_dot[r, c] * G_qdot[c]
        rhs[r, 0], rhs[r, 1], rhs[r, 2] = Mdq[r], s, bias[r]
    Y = _solve_upper(U, rhs)
    for j in range(n):
        FtG = 0.0  # (F^T G qdot)_j
        GT0 = 0.0  # (G^T F_dot qdot)_j
        GT1 = 0.0  # (G^T I0c_dot G qdot)_j
        GT2 = 0.0  # (G^T p^)_j
        MdG = 0.0  # (M_dot[6:, :6] G qdot)_j
        for r in range(6):
            F_rj = M[r, 6 + j]
            FtG += F_rj * G_qdot[r]
            GT0 += F_rj * Y[r, 0]
            GT1 += F_rj * Y[r, 1]
            GT2 += F_rj * Y[r, 2]
            MdG += M_dot[6 + j, r] * G_qdot[r]
        p_i[j] = Mq[6 + j] - FtG
        a_i[j] = Mdq[6 + j] - GT0 - MdG + GT1 - (bias[6 + j] - GT2)
    return p_c, a_c, p_i, a_i, U, True


def load_compiled_kernels() -> None:
    """Loads (or, on a machine's first run, compiles) the kernels into this process with
    one call each on a small positive-definite system."""
    nv = 8
    M = np.eye(nv) + 0.1 * np.ones((nv, nv))
    gather_mass_matrix_terms(M, np.zeros((nv, nv)), np.zeros(nv), np.arange(nv), np.zeros(3))
    floating_state_rates(M, np.zeros((nv, nv)), np.zeros(nv), np.zeros(6), np.zeros(nv - 6))


__all__ = ["floating_state_rates", "gather_mass_matrix_terms", "load_compiled_kernels"]
