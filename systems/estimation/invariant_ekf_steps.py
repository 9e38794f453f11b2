"""The contact-aided invariant EKF's per-step arithmetic, compiled (numba).

``ContactAidedInvariantEkf`` (``base_state_estimator``) runs at the IMU rate, 1 kHz in the
simulations, with a 21 x 21 covariance (two feet and the IMU bias states). In numpy its
small-matrix operations cost mostly call overhead, which compiling them removes from each
propagation and kinematic correction (measured when this was chosen; see the git history of
BENCHMARKS.md). The equations and their labels (E1)-(E13) are those of
``base_state_estimator``'s docstring; the filter's state is passed as arrays:

    R (3 x 3), v (3), p (3): R_WI, v_WIo (m/s), p_WIo (m);
    d (K x 3): the foot points in contact, world, m; in_contact (K, bool);
    b (6): [b_g (rad/s); b_a (m/s^2)] (zeros without bias states);
    P (n x n): the covariance over [ξ_R; ξ_v; ξ_p; ξ_d1 ...; (ζ_g; ζ_a)], n = b0 (+ 6).

Each function returns the state arrays it may change; it never modifies its arguments (an
array it leaves unchanged may be returned as the argument itself).
Compiled once per machine (``cache=True``: numba's cache beside this file).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def skew3(w: np.ndarray) -> np.ndarray:
    """[w]× of a 3-vector."""
    out = np.zeros((3, 3))
    out[0, 1] = -w[2]
    out[0, 2] = w[1]
    out[1, 0] = w[2]
    out[1, 2] = -w[0]
    out[2, 0] = -w[1]
    out[2, 1] = w[0]
    return out


@njit(cache=True)
def so3_gammas3(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Γ_0(φ), Γ_1(φ), Γ_2(φ)) of ``base_state_estimator.so3_gamma``: Exp(φ), the left
    Jacobian and its integral, from one [φ]× and one [φ]×²."""
    theta2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    K = skew3(phi)
    K2 = K @ K
    if theta2 < 1e-12:
        c0, c1, c2 = 1.0, 0.5, 1.0 / 6.0
        d0, d1, d2 = 0.5, 1.0 / 6.0, 1.0 / 24.0
    else:
        theta = math.sqrt(theta2)
        sin, cos = math.sin(theta), math.cos(theta)
        c0, d0 = sin / theta, (1.0 - cos) / theta2
        c1, d1 = d0, (theta - sin) / (theta2 * theta)
        c2, d2 = d1, (theta2 + 2.0 * cos - 2.0) / (2.0 * theta2 * theta2)
    eye = np.eye(3)
    return eye + c0 * K + d0 * K2, eye + c1 * K + d1 * K2, 0.5 * eye + c2 * K + d2 * K2


@njit(cache=True)
def adjoint(R, v, p, d, in_contact, n: int, b0: int) -> np.ndarray:
    """Ad_X̄ of SE_{2+K}(3) (E5), n x n; rows of feet out of contact 0; with bias states
    (n > b0) blkdiag(Ad_X̄, I_6) (E11)."""
    Ad = np.zeros((n, n))
    Ad[0:3, 0:3] = R
    Ad[3:6, 0:3] = skew3(v) @ R
    Ad[3:6, 3:6] = R
    Ad[6:9, 0:3] = skew3(p) @ R
    Ad[6:9, 6:9] = R
    for j in range(in_contact.shape[0]):
        if in_contact[j]:
            s = 9 + 3 * j
            Ad[s : s + 3, 0:3] = skew3(d[j]) @ R
            Ad[s : s + 3, s : s + 3] = R
    for i in range(b0, n):
        Ad[i, i] = 1.0
    return Ad


@njit(cache=True)
def transition(R, Ad, g_skew, dt: float, n: int, b0: int) -> np.ndarray:
    """Φ over dt (E5): I + A dt + ½ A² dt², X̄ held over the step; with bias states (n > b0)
    its bias columns (E11), B dt + A_X B dt²/2 + A_X² B dt³/6, where B's gyro columns are
    minus Ad_X̄'s first three columns and its accelerometer columns -R in rows v."""
    Phi = np.eye(n)
    Phi[3:6, 0:3] = g_skew * dt
    Phi[6:9, 0:3] = 0.5 * g_skew * dt * dt
    for i in range(3):
        Phi[6 + i, 3 + i] = dt
    if n > b0:
        B = np.zeros((b0, 6))
        B[:, 0:3] = -Ad[:b0, 0:3]
        B[3:6, 3:6] = -R
        gB = g_skew @ B[0:3]
        columns = B * dt
        columns[3:6] += gB * (0.5 * dt * dt)
        columns[6:9] += B[3:6] * (0.5 * dt * dt) + gB * (dt * dt * dt / 6.0)
        Phi[:b0, b0:] = columns
    return Phi


@njit(cache=True)
def propagate_step(R, v, p, d, in_contact, b, P, omega, a, dt: float, g, g_skew, noise, b0: int):
    """IMU propagation over dt (E1)-(E5), measurements held; with bias states (P larger
    than b0) the measurements corrected by the bias estimate and the covariance propagated
    with the bias columns and noises (E11). ``noise``: the variances (σ_g², σ_a², σ_c²,
    σ_bg², σ_ba²). Returns (R, v, p, P)."""
    n = P.shape[0]
    bias = n > b0
    if bias:
        omega = omega - b[:3]
        a = a - b[3:]
    # Covariance first: Φ and Ad_X̄ at the state before the step.
    Ad = adjoint(R, v, p, d, in_contact, n, b0)
    Phi = transition(R, Ad, g_skew, dt, n, b0)
    q = np.zeros(n)
    q[0:3] = noise[0]
    q[3:6] = noise[1]
    for j in range(in_contact.shape[0]):
        if in_contact[j]:
            q[9 + 3 * j : 12 + 3 * j] = noise[2]
    if bias:
        q[b0 : b0 + 3] = noise[3]
        q[b0 + 3 :] = noise[4]
    G = Phi @ Ad
    P = Phi @ P @ Phi.T + (G * q) @ G.T * dt
    P = 0.5 * (P + P.T)
    # Mean (E1)-(E4).
    exp_phi, gamma1, gamma2 = so3_gammas3(omega * dt)
    Ra1 = R @ (gamma1 @ a)
    Ra2 = R @ (gamma2 @ a)
    p_next = p + v * dt + Ra2 * dt * dt + 0.5 * g * dt * dt
    v_next = v + Ra1 * dt + g * dt
    return R @ exp_phi, v_next, p_next, P


@njit(cache=True)
def update_step(R, v, p, d, in_contact, b, P, H, r, var: float, b0: int):
    """(E7) with measurement noise var I: S = H P Hᵀ + N, K = P Hᵀ S⁻¹, X⁺ = Exp(K r) X̄
    (R⁺ = Exp(δ_R) R̄, v⁺ = Exp(δ_R) v̄ + J_l(δ_R) δ_v, likewise p and the feet in contact;
    with bias states θ⁺ = θ̄ + δ_θ), Joseph-form P⁺ = (I − KH) P (I − KH)ᵀ + K N Kᵀ
    (symmetrised). Returns (R, v, p, d, b, P)."""
    n = P.shape[0]
    PHt = P @ H.T
    S = H @ PHt
    for i in range(S.shape[0]):
        S[i, i] += var
    K = np.linalg.solve(S, PHt.T).T
    delta = K @ r
    dR, J, _ = so3_gammas3(delta[0:3])
    R = dR @ R
    v = dR @ v + J @ delta[3:6]
    p = dR @ p + J @ delta[6:9]
    d = d.copy()
    for j in range(in_contact.shape[0]):
        if in_contact[j]:
            s = 9 + 3 * j
            d[j] = dR @ d[j] + J @ delta[s : s + 3]
    if n > b0:
        b = b + delta[b0:]
    IKH = np.eye(n) - K @ H
    P = IKH @ P @ IKH.T + var * (K @ K.T)
    return R, v, p, d, b, 0.5 * (P + P.T)


@njit(cache=True)
def correct_kinematics_step(R, v, p, d, in_contact, b, P, h, flags, var_k: float, b0: int):
    """Kinematic correction and contact switching (E6)-(E9): feet that left contact are
    removed (E9), feet in contact already in the state correct it in one stacked update
    (E6, E7), feet that made contact are added (E8). ``h``: the foot points in the IMU
    frame (K x 3, m), ``flags``: in contact now (K). Returns (R, v, p, d, in_contact, b, P)."""
    n = P.shape[0]
    K = in_contact.shape[0]
    P = P.copy()
    d = d.copy()
    in_contact = in_contact.copy()
    # (E9) contact lost: marginalise the slot.
    for j in range(K):
        if in_contact[j] and not flags[j]:
            s = 9 + 3 * j
            P[s : s + 3, :] = 0.0
            P[:, s : s + 3] = 0.0
            in_contact[j] = False
    # (E6), (E7) feet in contact and in the state.
    m = 0
    for j in range(K):
        if in_contact[j] and flags[j]:
            m += 1
    if m:
        H = np.zeros((3 * m, n))
        r = np.zeros(3 * m)
        i = 0
        for j in range(K):
            if in_contact[j] and flags[j]:
                r[3 * i : 3 * i + 3] = R @ h[j] - (d[j] - p)
                for k in range(3):
                    H[3 * i + k, 6 + k] = -1.0
                    H[3 * i + k, 9 + 3 * j + k] = 1.0
                i += 1
        R, v, p, d, b, P = update_step(R, v, p, d, in_contact, b, P, H, r, var_k, b0)
    # (E8) contact made: d_j = p + R h_j, ξ_dj = ξ_p + R n_j.
    for j in range(K):
        if flags[j] and not in_contact[j]:
            s = 9 + 3 * j
            d[j] = p + R @ h[j]
            P[s : s + 3, :] = P[6:9, :]
            P[:, s : s + 3] = P[:, 6:9]
            P[s : s + 3, s : s + 3] = P[6:9, 6:9]
            for k in range(3):
                P[s + k, s + k] += var_k
            in_contact[j] = True
    return R, v, p, d, in_contact, b, P


@njit(cache=True)
def correct_and_propagate_state_vector(
    x, h, flags, omega, a, dt: float, var_k: float, g, g_skew, noise, n: int, b0: int
):
    """One filter step on a flat state vector (``ContactAidedInvariantEkf.state_vector``:
    [R (9, row-major); v; p; d (3 K); in_contact (K); (b (6) with bias states); P
    (row-major)]): the kinematic correction (E6)-(E9) with the foot points ``h`` (K x 3, in
    the IMU frame, m) and the contact ``flags`` (K), then the IMU propagation over dt (E1)-(E5),
    (E11). ``n``: P's size (b0, or b0 + 6 with bias states). The same arithmetic as
    ``correct_kinematics_step`` then ``propagate_step`` on the unpacked state, in one call
    (the Drake wrapper's every step). Returns the new vector."""
    K = flags.shape[0]
    R = x[0:9].copy().reshape(3, 3)
    v = x[9:12].copy()
    p = x[12:15].copy()
    d = x[15 : 15 + 3 * K].copy().reshape(K, 3)
    in_contact = x[15 + 3 * K : 15 + 4 * K] > 0.5
    s = 15 + 4 * K
    b = np.zeros(6)
    if n > b0:
        b = x[s : s + 6].copy()
        s += 6
    P = x[s : s + n * n].copy().reshape(n, n)
    R, v, p, d, in_contact, b, P = correct_kinematics_step(R, v, p, d, in_contact, b, P, h, flags, var_k, b0)
    R, v, p, P = propagate_step(R, v, p, d, in_contact, b, P, omega, a, dt, g, g_skew, noise, b0)
    out = np.empty(x.shape[0])
    out[0:9] = R.reshape(9)
    out[9:12] = v
    out[12:15] = p
    out[15 : 15 + 3 * K] = d.reshape(3 * K)
    for j in range(K):
        out[15 + 3 * K + j] = 1.0 if in_contact[j] else 0.0
    s = 15 + 4 * K
    if n > b0:
        out[s : s + 6] = b
        s += 6
    out[s : s + n * n] = P.reshape(n * n)
    return out


@njit(cache=True)
def foot_slip_step(R, p, h, flags, slip, alpha: float, dt: float, slip_speed: float):
    """The slip test (E13) of the feet flagged in contact, before their correction: each
    foot point's world position from the predicted state, u_j = R̄ h_j + p̄ (m), its velocity
    (u_j − u_j⁻) / dt against the previous update's u_j⁻ low-passed, w_j ← w_j + α ((u_j −
    u_j⁻) / dt − w_j) (m/s; reset to 0 for a foot not flagged at both updates), and the feet
    flagged at both whose |w_j| exceeds ``slip_speed`` (m/s) are slipping. ``slip``: the test's
    state, [u⁻ (3 K); w (3 K); flagged at the previous update (K); slip count (K)]. Returns
    (the new ``slip``, the flags of the feet whose correction is used: flagged and not
    slipping)."""
    K = flags.shape[0]
    out = slip.copy()
    used = flags.copy()
    for j in range(K):
        u = R @ h[j] + p
        s = 3 * j
        t = 3 * K + s
        speed2 = 0.0
        if flags[j] and slip[6 * K + j] > 0.5:
            for i in range(3):
                w = slip[t + i] + alpha * ((u[i] - slip[s + i]) / dt - slip[t + i])
                out[t + i] = w
                speed2 += w * w
        else:
            for i in range(3):
                out[t + i] = 0.0
        for i in range(3):
            out[s + i] = u[i] if flags[j] else 0.0
        out[6 * K + j] = 1.0 if flags[j] else 0.0
        if flags[j] and speed2 > slip_speed * slip_speed:
            used[j] = False
            out[7 * K + j] += 1.0
    return out, used
