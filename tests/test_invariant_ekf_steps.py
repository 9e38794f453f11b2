"""The invariant EKF's compiled steps (systems.estimation.invariant_ekf_steps) against
independent oracles: the mean propagation against a numerical integration of the IMU
kinematics (scipy's solve_ivp), the transition against the matrix exponential of the
continuous error dynamics (scipy's expm, eqs. E5 and E11 of base_state_estimator), the
covariance against the paper's discrete formula built from those, and the update against
the textbook Kalman update with the closed-form SO(3) functions of base_state_estimator."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from systems.estimation import invariant_ekf_steps as steps
from systems.estimation.base_state_estimator import so3_exp, so3_gamma

G = np.array([0.0, 0.0, -9.81])
K = 2  # feet
B0 = 9 + 3 * K
N = B0 + 6  # with the IMU bias states


def _skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _random_state(rng, in_contact=(True, False)):
    R = so3_exp(rng.normal(size=3))
    v, p = rng.normal(size=3), rng.normal(size=3)
    d = rng.normal(size=(K, 3))
    b = 0.01 * rng.normal(size=6)
    L = rng.normal(size=(N, N))
    P = L @ L.T / N + 0.1 * np.eye(N)
    for j, on in enumerate(in_contact):
        if not on:  # a slot out of contact holds nothing (E9)
            s = 9 + 3 * j
            P[s : s + 3, :] = 0.0
            P[:, s : s + 3] = 0.0
    return R, v, p, d, np.array(in_contact), b, P


def _continuous_error_dynamics(R, v, p, d, in_contact):
    """A = [[A_X, B], [0, 0]] (E5, E11) and the noise map blkdiag(Ad_X̄, I_6), written out
    from the module docstring's block formulas."""
    A = np.zeros((N, N))
    A[3:6, 0:3] = _skew(G)
    A[6:9, 3:6] = np.eye(3)
    Ad = np.zeros((N, N))
    Ad[0:3, 0:3] = R
    Ad[3:6, 0:3], Ad[3:6, 3:6] = _skew(v) @ R, R
    Ad[6:9, 0:3], Ad[6:9, 6:9] = _skew(p) @ R, R
    A[0:3, B0 : B0 + 3] = -R
    A[3:6, B0 : B0 + 3], A[3:6, B0 + 3 :] = -_skew(v) @ R, -R
    A[6:9, B0 : B0 + 3] = -_skew(p) @ R
    for j in range(K):
        if in_contact[j]:
            s = 9 + 3 * j
            Ad[s : s + 3, 0:3], Ad[s : s + 3, s : s + 3] = _skew(d[j]) @ R, R
            A[s : s + 3, B0 : B0 + 3] = -_skew(d[j]) @ R
    Ad[B0:, B0:] = np.eye(6)
    return A, Ad


def test_transition_is_the_exponential_of_the_error_dynamics():
    rng = np.random.default_rng(0)
    R, v, p, d, on, b, P = _random_state(rng)
    A, Ad = _continuous_error_dynamics(R, v, p, d, on)
    dt = 0.01
    Ad_kernel = steps.adjoint(R, v, p, d, on, N, B0)
    np.testing.assert_allclose(Ad_kernel, Ad, atol=1e-14)
    Phi = steps.transition(R, Ad_kernel, _skew(G), dt, N, B0)
    np.testing.assert_allclose(Phi, expm(A * dt), atol=1e-13)


def test_propagation_against_integrated_imu_kinematics_and_the_discrete_covariance():
    rng = np.random.default_rng(1)
    R, v, p, d, on, b, P = _random_state(rng)
    omega, a, dt = rng.normal(size=3), rng.normal(size=3) + [0.0, 0.0, 9.81], 0.02
    noise = np.array([1e-4, 2e-3, 1e-2, 1e-5, 3e-3]) ** 2
    R1, v1, p1, P1 = steps.propagate_step(R, v, p, d, on, b, P, omega, a, dt, G, _skew(G), noise, B0)

    # The mean: R' = R [ω − b_g]×, v' = R (a − b_a) + g, p' = v, integrated numerically.
    w, f = omega - b[:3], a - b[3:]

    def rates(_, x):
        Rx = x[:9].reshape(3, 3)
        return np.concatenate([(Rx @ _skew(w)).reshape(-1), Rx @ f + G, x[9:12]])

    x = solve_ivp(rates, (0.0, dt), np.concatenate([R.reshape(-1), v, p]), rtol=1e-12, atol=1e-13).y[:, -1]
    np.testing.assert_allclose(R1, x[:9].reshape(3, 3), atol=1e-10)
    np.testing.assert_allclose(v1, x[9:12], atol=1e-10)
    np.testing.assert_allclose(p1, x[12:15], atol=1e-10)

    # The covariance: Φ P Φᵀ + Φ Ad Q_c Adᵀ Φᵀ dt (E5, E11), Φ = expm(A dt) at X̄.
    A, Ad = _continuous_error_dynamics(R, v, p, d, on)
    Phi = expm(A * dt)
    q = np.zeros(N)
    q[0:3], q[3:6], q[B0 : B0 + 3], q[B0 + 3 :] = noise[0], noise[1], noise[3], noise[4]
    for j in range(K):
        if on[j]:
            q[9 + 3 * j : 12 + 3 * j] = noise[2]
    expected = Phi @ P @ Phi.T + Phi @ Ad @ np.diag(q) @ Ad.T @ Phi.T * dt
    np.testing.assert_allclose(P1, expected, rtol=1e-11, atol=1e-13)


def test_update_is_the_textbook_kalman_update_applied_on_the_group():
    rng = np.random.default_rng(2)
    R, v, p, d, on, b, P = _random_state(rng, in_contact=(True, True))
    H = rng.normal(size=(6, N))
    r, var = rng.normal(size=6), 0.3
    before = [x.copy() for x in (R, v, p, d, b, P)]
    R1, v1, p1, d1, b1, P1 = steps.update_step(R, v, p, d, on, b, P, H, r, var, B0)

    S = H @ P @ H.T + var * np.eye(6)
    gain = P @ H.T @ np.linalg.inv(S)
    delta = gain @ r
    IKH = np.eye(N) - gain @ H
    np.testing.assert_allclose(P1, IKH @ P @ IKH.T + var * gain @ gain.T, atol=1e-12)
    # X⁺ = Exp(δ) X̄ (E7): R⁺ = Exp(δ_R) R̄, v⁺ = Exp(δ_R) v̄ + J_l(δ_R) δ_v, likewise p, d_j.
    E, J = so3_exp(delta[:3]), so3_gamma(delta[:3], 1)
    np.testing.assert_allclose(R1, E @ R, atol=1e-12)
    np.testing.assert_allclose(v1, E @ v + J @ delta[3:6], atol=1e-12)
    np.testing.assert_allclose(p1, E @ p + J @ delta[6:9], atol=1e-12)
    for j in range(K):
        s = 9 + 3 * j
        np.testing.assert_allclose(d1[j], E @ d[j] + J @ delta[s : s + 3], atol=1e-12)
    np.testing.assert_allclose(b1, b + delta[B0:], atol=1e-14)
    # The arguments are not modified.
    for x, x0 in zip((R, v, p, d, b, P), before):
        np.testing.assert_array_equal(x, x0)
