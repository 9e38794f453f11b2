"""The compiled floating-base kernels (systems.dynamics.floating_base_kernels) against the
numpy formulas they replace, on random matrices of a humanoid's size."""

import numpy as np
import pytest
from scipy.linalg import lapack

from systems.dynamics.floating_base_kernels import floating_state_rates, gather_mass_matrix_terms


def _spd(rng: np.random.Generator, nv: int) -> np.ndarray:
    A = rng.normal(size=(nv, nv))
    return A @ A.T + nv * np.eye(nv)


def _numpy_state_rates(M, M_dot, bias, v0, qdot):
    """ResidualModel.state_rates's elimination of eq. (9) and (13), written with numpy and LAPACK."""
    nv = M.shape[0]
    nu = np.concatenate((v0, qdot))
    I0c, F = M[:6, :6], M[:6, 6:]
    G = np.linalg.solve(I0c, F)  # I0c^-1 F
    H_fb = M[6:, 6:] - F.T @ G
    F_dot, I0c_dot = M_dot[:6, 6:], M_dot[:6, :6]
    H_fb_dot = M_dot[6:, 6:] - G.T @ F_dot - F_dot.T @ G + G.T @ I0c_dot @ G
    C_fb = bias[6:] - G.T @ bias[:6]
    assert nv == 6 + qdot.size
    return M @ nu, M_dot @ nu - bias, H_fb @ qdot, H_fb_dot @ qdot - C_fb


@pytest.mark.parametrize("nv", [12, 40])
def test_state_rates_kernel_equals_the_formulas(nv):
    rng = np.random.default_rng(nv)
    M = _spd(rng, nv)
    S = rng.normal(size=(nv, nv))
    M_dot = S + S.T
    bias, v0, qdot = rng.normal(size=nv), rng.normal(size=6), rng.normal(size=nv - 6)
    p_c, a_c, p_i, a_i, U, positive = floating_state_rates(M, M_dot, bias, v0, qdot)
    assert positive
    for got, expected in zip((p_c, a_c, p_i, a_i), _numpy_state_rates(M, M_dot, bias, v0, qdot)):
        np.testing.assert_allclose(got, expected, rtol=1e-11, atol=1e-11 * np.abs(expected).max())
    # U is LAPACK's upper factor: dpotrs solves with it as the residual model does.
    np.testing.assert_allclose(U.T @ U, M[:6, :6], rtol=1e-13, atol=1e-12)
    assert np.array_equal(U, np.triu(U))
    w = rng.normal(size=6)
    np.testing.assert_allclose(lapack.dpotrs(U, w)[0], np.linalg.solve(M[:6, :6], w), rtol=1e-11)


def test_state_rates_kernel_reports_an_inertia_that_is_not_positive_definite():
    M = np.eye(8)
    M[2, 2] = 0.0  # a base direction without inertia
    *_, positive = floating_state_rates(M, np.zeros((8, 8)), np.zeros(8), np.zeros(6), np.zeros(2))
    assert not positive


def test_gather_kernel_equals_the_permuted_matrices():
    rng = np.random.default_rng(3)
    nv = 13
    M_pin, C = _spd(rng, nv), rng.normal(size=(nv, nv))
    v_pin, g_B = rng.normal(size=nv), rng.normal(size=3)
    P = np.concatenate((rng.permutation(6), 6 + rng.permutation(nv - 6)))
    M, M_dot, bias = gather_mass_matrix_terms(M_pin, C, v_pin, P, g_B)
    np.testing.assert_array_equal(M, M_pin[P][:, P])
    np.testing.assert_allclose(M_dot, (C + C.T)[P][:, P], rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(bias, (C @ v_pin)[P] - M[:, 3:6] @ g_B, rtol=1e-12, atol=1e-12)
