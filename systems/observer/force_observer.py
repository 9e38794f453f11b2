"""Kalman-filter external force observer for small humanoids (Hawley, Rahem, Suleiman 2019).

The core is plain Python + numpy, usable outside Drake; each Kalman step is written in
closed form on the structure of A, Q and C (about 4x faster than 5x5 numpy products, the
same arithmetic up to rounding: see ``_predict`` and ``_correct``). Two Kalman filters on
the LIP/ZMP model, sampling period T (16.7 ms on Nao):

* the z filter (eqs. 14-18): state Z = [z_c, dz_c, ddz_c, F_z, dF_z], output
  Y_z = [z_c, ddz_c, f_n + M g] with C_z = [[1,0,0,0,0], [0,0,1,0,0], [0,0,-M,1,0]];
* the x and y filters (eqs. 19-20): state X = [x_c, dx_c, ddx_c, F_x, dF_x], output
  Y_x = [x_c, ddx_c, p_x] with the time-varying third row
  [1, 0, M z^/f^_n, -z^/f^_n, 0], where z^ and f^_n = -M g - M ddz^ + F^_z come from the z
  filter's corrected estimate of the same step (likewise for y).

A = constant-jerk / constant-force-rate transition, Q = B diag(sigma^2) B^T (eq. 17), R and
sigma^2 from eq. (21) (standing, default) or eq. (22) (``WALKING``). Each step predicts, then
corrects with the textbook gain. The outputs are the virtual force F^ = [F^_x, F^_y, F^_z]
(eq. 11) in the world-aligned CoM frame, N.

Sign convention of the paper: f_n^o = -(sum of the FSR normal forces) (eq. 12), so
f_n^o = -M g at rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from systems.common.checks import eval_finite_input, vector3

#: Gravity and Nao's mass used by Hawley et al.
GRAVITY = 9.81
NAO_MASS = 5.19
NAO_PERIOD = 0.0167


@dataclass(frozen=True)
class LipObserverParameters:
    """Parameters of the observer (SI units). Defaults: the paper's eq. (21) on Nao.

    Attributes:
        mass: M_c, kg.
        gravity: g, m/s^2.
        period: T, s.
        jerk_variance: sigma^2 of the CoM jerk (all axes), (m/s^3)^2.
        force_rate_variance: sigma^2 of the second derivative of the force, (N/s^2)^2.
        R_z: (3, 3) measurement covariance of the z filter.
        R_xy: (3, 3) measurement covariance of the x and y filters.
        initial_covariance: P(0) = this times the identity.
        min_normal_force_fraction: |f^_n| below this fraction of M g (robot lifted, feet off
            the ground) makes the output invalid: the x/y corrections are skipped.
    """

    mass: float = NAO_MASS
    gravity: float = GRAVITY
    period: float = NAO_PERIOD
    jerk_variance: float = 1e3
    force_rate_variance: float = 1e3
    R_z: tuple = ((0.01, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    R_xy: tuple = ((0.01, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.01))
    initial_covariance: float = 100.0
    min_normal_force_fraction: float = 0.1

    def __post_init__(self):
        for name in ("mass", "gravity", "period", "jerk_variance", "force_rate_variance", "initial_covariance"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"LipObserverParameters: {name} must be a positive number, got {value}")
        for name in ("R_z", "R_xy"):
            matrix = np.asarray(getattr(self, name), dtype=float)
            if matrix.shape != (3, 3) or not np.all(np.linalg.eigvalsh(0.5 * (matrix + matrix.T)) > 0):
                raise ValueError(f"LipObserverParameters: {name} must be a 3x3 positive definite matrix")


#: The paper's eq. (21): standing experiments.
STANDING = LipObserverParameters()
#: The paper's eq. (22): walking (Exp. 4).
WALKING = LipObserverParameters(
    jerk_variance=1e2,
    R_z=((0.1, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    R_xy=((0.1, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.1)),
)


def transition_matrices(period: float) -> tuple[np.ndarray, np.ndarray]:
    """A and B of eq. (15) for the state [c, dc, ddc, F, dF] and input [jerk, ddF]."""
    T = period
    A = np.array(
        [
            [1.0, T, T * T / 2.0, 0.0, 0.0],
            [0.0, 1.0, T, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0, T],
            [0.0, 0.0, 0.0, 0.0, 1.0],
        ]
    )
    B = np.array([[T**3 / 6.0, 0.0], [T * T / 2.0, 0.0], [T, 0.0], [0.0, T * T / 2.0], [0.0, T]])
    return A, B


class _KalmanState:
    """One filter's state estimate and covariance, as plain floats (scalar math beats numpy
    on 5x5 matrices by an order of magnitude: a numpy call costs ~1 us, a flop ~30 ns).

    Attributes:
        x: (5,) tuple, the state [c, dc, ddc, F, dF].
        p: (15,) tuple, the upper triangle of the symmetric covariance P, row by row
            (P00, P01, P02, P03, P04, P11, ..., P44).
    """

    __slots__ = ("x", "p")

    def __init__(self, x, P):
        self.x = tuple(float(v) for v in np.asarray(x, dtype=float).reshape(5))
        P = np.asarray(P, dtype=float).reshape(5, 5)
        self.p = tuple(float(P[i, j]) for i, j in _UPPER)

    @classmethod
    def from_entries(cls, row) -> _KalmanState:
        """From 20 floats: x (5) then p (15), as ``entries``."""
        state = cls.__new__(cls)
        state.x, state.p = tuple(row[:5]), tuple(row[5:])
        return state

    @property
    def entries(self) -> tuple:
        """x (5) then p (15), 20 floats."""
        return self.x + self.p

    @property
    def P(self) -> np.ndarray:
        """The (5, 5) covariance as a new numpy array."""
        P = np.empty((5, 5))
        for value, (i, j) in zip(self.p, _UPPER):
            P[i, j] = P[j, i] = value
        return P


#: (row, column) of the entries of ``_KalmanState.p``.
_UPPER = tuple((i, j) for i in range(5) for j in range(i, 5))
#: Entries per filter in ``LipForceObserver.state()``: the state (5), then the upper
#: triangle of the covariance (15).
FILTER_STATE_SIZE = 20


def _predict(x, p, T, T2, q):
    """Prediction x = A x, P = A P A^T + Q of eq. (15)-(17) in closed form.

    A is block diagonal ([[1, T, T^2/2], [0, 1, T], [0, 0, 1]] on the CoM states and
    [[1, T], [0, 1]] on the force states) and so is Q: M = A P is three row operations and
    M A^T three column operations; only the upper triangle is formed (P is symmetric).
    ``q`` = (Q00, Q01, Q02, Q11, Q12, Q22, Q33, Q34, Q44), ``T2`` = T^2 / 2.
    """
    x0, x1, x2, x3, x4 = x
    p00, p01, p02, p03, p04, p11, p12, p13, p14, p22, p23, p24, p33, p34, p44 = p
    # M = A P, rows 0, 1 and 3 (rows 2 and 4 are P's).
    m00 = p00 + T * p01 + T2 * p02
    m01 = p01 + T * p11 + T2 * p12
    m02 = p02 + T * p12 + T2 * p22
    m03 = p03 + T * p13 + T2 * p23
    m04 = p04 + T * p14 + T2 * p24
    m11 = p11 + T * p12
    m12 = p12 + T * p22
    m13 = p13 + T * p23
    m14 = p14 + T * p24
    m33 = p33 + T * p34
    m34 = p34 + T * p44
    # N = M A^T + Q, upper triangle (N_ij = sum_l M_il A_jl); row 2 of M is P's row 2
    # (p02, p12, p22, p23, p24) and row 4 is P's row 4 (p04, p14, p24, p34, p44).
    q00, q01, q02, q11, q12, q22, q33, q34, q44 = q
    return (
        (x0 + T * x1 + T2 * x2, x1 + T * x2, x2, x3 + T * x4, x4),
        (
            m00 + T * m01 + T2 * m02 + q00,
            m01 + T * m02 + q01,
            m02 + q02,
            m03 + T * m04,
            m04,
            m11 + T * m12 + q11,
            m12 + q12,
            m13 + T * m14,
            m14,
            p22 + q22,
            p23 + T * p24,
            p24,
            m33 + T * m34 + q33,
            m34 + q34,
            p44 + q44,
        ),
    )


def _correct(x, p, h0, h2, h3, y0, y1, y2, r):
    """Correction with the textbook gain K = P C^T (C P C^T + R)^-1, x += K (y - C x),
    P -= K C P, for C = [[1,0,0,0,0], [0,0,1,0,0], [h0,0,h2,h3,0]]: the z filter's C_z
    (eq. 15: h = (0, -M, 1)) and the x/y filters' C_x (eq. 19: h = (1, M z^/f^_n,
    -z^/f^_n)). ``r`` = (R00, R01, R02, R11, R12, R22) of the symmetric R.

    Raises:
        numpy.linalg.LinAlgError: a singular innovation covariance.
    """
    x0, x1, x2, x3, x4 = x
    p00, p01, p02, p03, p04, p11, p12, p13, p14, p22, p23, p24, p33, p34, p44 = p
    # U = P C^T (5 x 3): columns P[:, 0], P[:, 2], h0 P[:, 0] + h2 P[:, 2] + h3 P[:, 3].
    u02 = h0 * p00 + h2 * p02 + h3 * p03
    u12 = h0 * p01 + h2 * p12 + h3 * p13
    u22 = h0 * p02 + h2 * p22 + h3 * p23
    u32 = h0 * p03 + h2 * p23 + h3 * p33
    u42 = h0 * p04 + h2 * p24 + h3 * p34
    r00, r01, r02, r11, r12, r22 = r
    # S = C P C^T + R (symmetric 3 x 3) and its inverse by cofactors.
    s00 = p00 + r00
    s01 = p02 + r01
    s02 = u02 + r02
    s11 = p22 + r11
    s12 = u22 + r12
    s22 = h0 * u02 + h2 * u22 + h3 * u32 + r22
    c00 = s11 * s22 - s12 * s12
    c01 = s02 * s12 - s01 * s22
    c02 = s01 * s12 - s02 * s11
    det = s00 * c00 + s01 * c01 + s02 * c02
    if det == 0.0:
        raise np.linalg.LinAlgError("singular innovation covariance")
    d = 1.0 / det
    i00, i01, i02 = c00 * d, c01 * d, c02 * d
    i11 = (s00 * s22 - s02 * s02) * d
    i12 = (s01 * s02 - s00 * s12) * d
    i22 = (s00 * s11 - s01 * s01) * d
    # K = U S^-1 (5 x 3); the rows of U are (P[i, 0], P[i, 2], u_i2).
    k00 = p00 * i00 + p02 * i01 + u02 * i02
    k01 = p00 * i01 + p02 * i11 + u02 * i12
    k02 = p00 * i02 + p02 * i12 + u02 * i22
    k10 = p01 * i00 + p12 * i01 + u12 * i02
    k11 = p01 * i01 + p12 * i11 + u12 * i12
    k12 = p01 * i02 + p12 * i12 + u12 * i22
    k20 = p02 * i00 + p22 * i01 + u22 * i02
    k21 = p02 * i01 + p22 * i11 + u22 * i12
    k22 = p02 * i02 + p22 * i12 + u22 * i22
    k30 = p03 * i00 + p23 * i01 + u32 * i02
    k31 = p03 * i01 + p23 * i11 + u32 * i12
    k32 = p03 * i02 + p23 * i12 + u32 * i22
    k40 = p04 * i00 + p24 * i01 + u42 * i02
    k41 = p04 * i01 + p24 * i11 + u42 * i12
    k42 = p04 * i02 + p24 * i12 + u42 * i22
    # Innovation y - C x.
    v0 = y0 - x0
    v1 = y1 - x2
    v2 = y2 - (h0 * x0 + h2 * x2 + h3 * x3)
    # P - K U^T (upper triangle; K C P = K U^T since P is symmetric).
    return (
        (
            x0 + k00 * v0 + k01 * v1 + k02 * v2,
            x1 + k10 * v0 + k11 * v1 + k12 * v2,
            x2 + k20 * v0 + k21 * v1 + k22 * v2,
            x3 + k30 * v0 + k31 * v1 + k32 * v2,
            x4 + k40 * v0 + k41 * v1 + k42 * v2,
        ),
        (
            p00 - (k00 * p00 + k01 * p02 + k02 * u02),
            p01 - (k00 * p01 + k01 * p12 + k02 * u12),
            p02 - (k00 * p02 + k01 * p22 + k02 * u22),
            p03 - (k00 * p03 + k01 * p23 + k02 * u32),
            p04 - (k00 * p04 + k01 * p24 + k02 * u42),
            p11 - (k10 * p01 + k11 * p12 + k12 * u12),
            p12 - (k10 * p02 + k11 * p22 + k12 * u22),
            p13 - (k10 * p03 + k11 * p23 + k12 * u32),
            p14 - (k10 * p04 + k11 * p24 + k12 * u42),
            p22 - (k20 * p02 + k21 * p22 + k22 * u22),
            p23 - (k20 * p03 + k21 * p23 + k22 * u32),
            p24 - (k20 * p04 + k21 * p24 + k22 * u42),
            p33 - (k30 * p03 + k31 * p23 + k32 * u32),
            p34 - (k30 * p04 + k31 * p24 + k32 * u42),
            p44 - (k40 * p04 + k41 * p24 + k42 * u42),
        ),
    )


def _symmetric_entries(matrix: np.ndarray, indices) -> tuple:
    return tuple(float(matrix[i, j]) for i, j in indices)


class LipForceObserver:
    """The observer core (numpy interface, scalar arithmetic inside): call ``reset`` once,
    then ``update`` at every sample.

    Each step is the closed form of the textbook predict/correct (``_predict``,
    ``_correct``) on the structure of A, Q and C (eqs. 15, 17, 19): the same arithmetic as
    the matrix form up to floating-point rounding (the authors' output is reproduced to
    ~1e-12 N), about 4x faster than numpy on 5x5 matrices.

    Args:
        parameters: ``STANDING`` (eq. 21, default), ``WALKING`` (eq. 22) or custom.
    """

    def __init__(self, parameters: LipObserverParameters = STANDING):
        self.parameters = parameters
        self._A, B = transition_matrices(parameters.period)
        self._Q = B @ np.diag([parameters.jerk_variance, parameters.force_rate_variance]) @ B.T
        self._R_z = np.asarray(parameters.R_z, dtype=float)
        self._R_xy = np.asarray(parameters.R_xy, dtype=float)
        T = float(parameters.period)
        self._T, self._T2 = T, T * T / 2.0
        self._q = _symmetric_entries(self._Q, ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2), (3, 3), (3, 4), (4, 4)))
        pairs = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
        # R is used as symmetric: its symmetric part (what a covariance is).
        self._r_z = _symmetric_entries(0.5 * (self._R_z + self._R_z.T), pairs)
        self._r_xy = _symmetric_entries(0.5 * (self._R_xy + self._R_xy.T), pairs)
        self._mass, self._gravity = float(parameters.mass), float(parameters.gravity)
        self._min_normal_force = float(parameters.min_normal_force_fraction) * self._mass * self._gravity
        self._filters: list[_KalmanState] | None = None

    def reset(self, com_position: np.ndarray, com_acceleration: np.ndarray) -> None:
        """Initial states [c(0), 0, ddc(0), 0, 0] per axis and P = p0 I (as the authors)."""
        com_position = vector3(com_position, "com_position")
        com_acceleration = vector3(com_acceleration, "com_acceleration")
        P0 = self.parameters.initial_covariance * np.eye(5)
        self._filters = [
            _KalmanState(np.array([com_position[i], 0.0, com_acceleration[i], 0.0, 0.0]), P0) for i in range(3)
        ]

    def state(self) -> np.ndarray:
        """The three filters (x, y, z) as a new (3, FILTER_STATE_SIZE) array: per row the
        filter's state [c, dc, ddc, F, dF] (eqs. 18, 20; m, m/s, m/s^2, N, N/s), then the
        upper triangle of its covariance P, row by row (15 entries).

        Raises:
            RuntimeError: before ``reset`` or the first ``update`` (no filters yet).
        """
        if self._filters is None:
            raise RuntimeError("LipForceObserver: no filter state before reset() or the first update()")
        return np.array([f.entries for f in self._filters])

    def set_state(self, state: np.ndarray) -> None:
        """Loads filters saved by ``state()`` (e.g. kept in a Drake context).

        Raises:
            ValueError: not a finite (3, FILTER_STATE_SIZE) array.
        """
        s = np.asarray(state, dtype=float)
        if s.shape != (3, FILTER_STATE_SIZE) or not math.isfinite(float(s.sum())):
            raise ValueError(
                f"LipForceObserver: state must be a finite (3, {FILTER_STATE_SIZE}) array, got shape {s.shape}"
            )
        self._filters = [_KalmanState.from_entries(row) for row in s.tolist()]

    def update(
        self, com_position: np.ndarray, com_acceleration: np.ndarray, zmp: np.ndarray, normal_force: float
    ) -> tuple[np.ndarray, bool]:
        """One sample: CoM position (m) and acceleration (m/s^2, gravity-compensated, in the
        inertial frame), ZMP = CoP (m), f_n^o (N, the paper's sign: -M g at rest).

        Returns:
            (F^ = [F^_x, F^_y, F^_z] in N, valid). ``valid`` is False when the estimated
            normal force is too small (feet off the ground): the x/y filters then only
            predict, as no ZMP exists.
        """
        if self._filters is None:
            self.reset(com_position, com_acceleration)
        c = vector3(com_position, "com_position")
        a = vector3(com_acceleration, "com_acceleration")
        p = np.asarray(zmp, dtype=float).reshape(-1)
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise ValueError(f"zmp must be 2 finite numbers, got {zmp}")
        fn = float(normal_force)
        if not np.isfinite(fn):
            raise ValueError(f"normal_force must be finite, got {normal_force}")
        force, valid = self._update(c, a, p, fn)
        return np.array(force), valid

    def _update(self, c, a, p, fn: float) -> tuple[tuple[float, float, float], bool]:
        """``update`` without the input checks (for callers that checked whole recordings):
        ``c``, ``a`` (3 floats), ``p`` (2 floats) as any sequences. Returns (F^ as a tuple, valid)."""
        cx, cy, cz = c[0], c[1], c[2]
        M, g, T, T2, q = self._mass, self._gravity, self._T, self._T2, self._q
        fx, fy, fz = self._filters
        # z filter (eqs. 14-18): Y_z = [z_c, ddz_c, f_n + M g], C_z third row [0, 0, -M, 1, 0].
        x, P = _predict(fz.x, fz.p, T, T2, q)
        fz.x, fz.p = _correct(x, P, 0.0, -M, 1.0, cz, a[2], fn + M * g, self._r_z)
        z_hat, _, zdd_hat, Fz_hat, _ = fz.x
        fn_hat = -M * g - M * zdd_hat + Fz_hat
        valid = abs(fn_hat) >= self._min_normal_force
        if valid:  # x and y filters (eqs. 19-20), third row [1, 0, M z^/f^_n, -z^/f^_n, 0]
            h2, h3 = M * z_hat / fn_hat, -z_hat / fn_hat
            x, P = _predict(fx.x, fx.p, T, T2, q)
            fx.x, fx.p = _correct(x, P, 1.0, h2, h3, cx, a[0], p[0], self._r_xy)
            x, P = _predict(fy.x, fy.p, T, T2, q)
            fy.x, fy.p = _correct(x, P, 1.0, h2, h3, cy, a[1], p[1], self._r_xy)
        else:  # no ZMP without a normal force: predict only
            fx.x, fx.p = _predict(fx.x, fx.p, T, T2, q)
            fy.x, fy.p = _predict(fy.x, fy.p, T, T2, q)
        return (fx.x[3], fy.x[3], fz.x[3]), bool(valid)


def calibrated_normal_force(fsr_total: np.ndarray, mass: float = NAO_MASS, gravity: float = GRAVITY) -> np.ndarray:
    """f_n^o = -(sum of the FSR readings) (eq. 12), scaled once so that the first sample
    equals the robot's weight (the authors' calibration; assumes no external force then).

    Raises:
        ValueError: the first sample's total is zero.
    """
    fn = -np.asarray(fsr_total, dtype=float)
    if fn[0] == 0.0:
        raise ValueError("cannot calibrate the FSR scale: the first sample's total force is zero")
    return fn * (mass * gravity / abs(fn[0]))


def estimate_virtual_forces(
    com_position: np.ndarray,
    com_acceleration: np.ndarray,
    zmp: np.ndarray,
    normal_force: np.ndarray,
    parameters: LipObserverParameters = STANDING,
) -> tuple[np.ndarray, np.ndarray]:
    """Runs the observer over a recording: (N, 3) positions, (N, 3) accelerations, (N, 2)
    ZMP, (N,) f_n^o. Returns ((N, 3) F^, (N,) valid flags)."""
    com_position = np.asarray(com_position, dtype=float)
    com_acceleration = np.asarray(com_acceleration, dtype=float)
    zmp = np.asarray(zmp, dtype=float)
    normal_force = np.asarray(normal_force, dtype=float).reshape(-1)
    n = len(normal_force)
    for name, array, columns in (
        ("com_position", com_position, 3),
        ("com_acceleration", com_acceleration, 3),
        ("zmp", zmp, 2),
    ):
        if array.shape != (n, columns):
            raise ValueError(f"{name} has shape {array.shape}; expected ({n}, {columns})")
        if not np.all(np.isfinite(array)):
            raise ValueError(
                f"{name} has NaN or inf in rows {np.flatnonzero(~np.all(np.isfinite(array), axis=1)).tolist()}"
            )
    if not np.all(np.isfinite(normal_force)):
        raise ValueError(f"normal_force has NaN or inf at {np.flatnonzero(~np.isfinite(normal_force)).tolist()}")
    observer = LipForceObserver(parameters)
    observer.reset(com_position[0], com_acceleration[0])
    step = observer._update
    results = [
        step(c, a, p, fn)
        for c, a, p, fn in zip(com_position.tolist(), com_acceleration.tolist(), zmp.tolist(), normal_force.tolist())
    ]
    forces = np.array([r[0] for r in results], dtype=float).reshape(n, 3)
    valid = np.array([r[1] for r in results], dtype=bool)
    return forces, valid


class LipForceObserverSystem(LeafSystem):
    """The observer as a Drake system, updated every ``parameters.period`` seconds.

    Inputs:
        com_position: (3,) CoM position in the support-foot frame, m.
        com_acceleration: (3,) CoM acceleration in the inertial frame, gravity-compensated, m/s^2.
        zmp: (2,) ZMP = CoP of the FSRs (eq. 13), m.
        normal_force: (1,) f_n^o = -(sum of the FSR normal forces) (eq. 12), N (-M g at rest).
    State: discrete groups ``filters`` (3 x FILTER_STATE_SIZE: the x, y and z filters as
        ``LipForceObserver.state()``), ``valid`` (1) and ``initialised`` (1: 0 before the
        first update).

    Outputs:
        virtual_force: (3,) F^ = [F^_x, F^_y, F^_z] (eq. 11), N, world-aligned CoM frame.
        valid: (1,) 1 when the normal force allows the x/y estimate, else 0 (feet off the
            ground: the x/y filters only predict).
        filter_states: (15,) the z, x and y filters' states (eq. 18, 20).

    The first update (t = 0) initialises the filters from its inputs as the authors do
    (``LipForceObserver.reset``), then runs one predict/correct step. Not an initialization
    event: at ``Simulator.Initialize`` the discrete plant has not taken its first step, so
    the sensors read other values than at the first update (measured: the estimates change
    by up to 1e-6 relative, 6e-4 on the walking robot's small pre-pull mean).
    """

    def __init__(self, parameters: LipObserverParameters = STANDING):
        super().__init__()
        self._core = LipForceObserver(parameters)
        self._period = parameters.period
        self._ports = {
            "com_position": self.DeclareVectorInputPort("com_position", 3),
            "com_acceleration": self.DeclareVectorInputPort("com_acceleration", 3),
            "zmp": self.DeclareVectorInputPort("zmp", 2),
            "normal_force": self.DeclareVectorInputPort("normal_force", 1),
        }
        self._filters_index = self.DeclareDiscreteState(3 * FILTER_STATE_SIZE)
        self._valid_index = self.DeclareDiscreteState(1)
        self._initialised_index = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        self.DeclareVectorOutputPort("virtual_force", 3, self._CalcVirtualForce, {self.xd_ticket()})
        self.DeclareStateOutputPort("valid", self._valid_index)
        self.DeclareVectorOutputPort("filter_states", 15, self._CalcFilterStates, {self.xd_ticket()})

    def _filters(self, context: Context) -> np.ndarray:
        """(3, FILTER_STATE_SIZE) the x, y, z filters of ``context``."""
        return context.get_discrete_state(self._filters_index).get_value().reshape(3, FILTER_STATE_SIZE)

    def _CalcVirtualForce(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._filters(context)[:, 3])  # F of the x, y, z filters

    def _CalcFilterStates(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._filters(context)[[2, 0, 1], :5].reshape(-1))  # z, x, y

    def _inputs(self, context: Context):
        return {
            name: np.array(eval_finite_input("LipForceObserverSystem", port, context))
            for name, port in self._ports.items()
        }

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        u = self._inputs(context)
        core = self._core
        if context.get_discrete_state(self._initialised_index).GetAtIndex(0) == 0.0:
            core.reset(u["com_position"], u["com_acceleration"])
        else:
            core.set_state(self._filters(context))
        _, valid = core._update(u["com_position"], u["com_acceleration"], u["zmp"], float(u["normal_force"][0]))
        discrete_state.set_value(self._filters_index, core.state().reshape(-1))
        discrete_state.set_value(self._valid_index, [float(valid)])
        discrete_state.set_value(self._initialised_index, [1.0])
