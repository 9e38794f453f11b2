"""Kalman-filter external force observer for small humanoids (Hawley, Rahem, Suleiman 2019).

The core is plain numpy, usable outside Drake. Two Kalman filters on the LIP/ZMP model,
sampling period T (16.7 ms on Nao):

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

from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem

from systems.inputs import eval_finite_input

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


@dataclass
class _KalmanState:
    x: np.ndarray
    P: np.ndarray = field(default_factory=lambda: np.zeros((5, 5)))


class LipForceObserver:
    """The observer core (numpy): call ``reset`` once, then ``update`` at every sample.

    Args:
        parameters: ``STANDING`` (eq. 21, default), ``WALKING`` (eq. 22) or custom.
    """

    def __init__(self, parameters: LipObserverParameters = STANDING):
        self.parameters = parameters
        self._A, B = transition_matrices(parameters.period)
        self._Q = B @ np.diag([parameters.jerk_variance, parameters.force_rate_variance]) @ B.T
        self._R_z = np.asarray(parameters.R_z, dtype=float)
        self._R_xy = np.asarray(parameters.R_xy, dtype=float)
        M = parameters.mass
        self._C_z = np.array([[1.0, 0, 0, 0, 0], [0, 0, 1.0, 0, 0], [0, 0, -M, 1.0, 0]])
        self._C_xy = np.array([[1.0, 0, 0, 0, 0], [0, 0, 1.0, 0, 0], [1.0, 0, 0, 0, 0]])
        self._filters: list[_KalmanState] | None = None

    def reset(self, com_position: np.ndarray, com_acceleration: np.ndarray) -> None:
        """Initial states [c(0), 0, ddc(0), 0, 0] per axis and P = p0 I (as the authors)."""
        com_position = _vector3("com_position", com_position)
        com_acceleration = _vector3("com_acceleration", com_acceleration)
        P0 = self.parameters.initial_covariance * np.eye(5)
        self._filters = [
            _KalmanState(np.array([com_position[i], 0.0, com_acceleration[i], 0.0, 0.0]), P0.copy()) for i in range(3)
        ]

    def _step(self, state: _KalmanState, C: np.ndarray, R: np.ndarray, y: np.ndarray) -> None:
        """Predict, then correct with the textbook Kalman gain K = P C^T (C P C^T + R)^-1."""
        A = self._A
        x = A @ state.x
        P = A @ state.P @ A.T + self._Q
        PCt = P @ C.T
        K = PCt @ _inverse_3x3(C @ PCt + R)
        state.x = x + K @ (y - C @ x)
        state.P = P - K @ (C @ P)

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
        c = _vector3("com_position", com_position)
        a = _vector3("com_acceleration", com_acceleration)
        p = np.asarray(zmp, dtype=float).reshape(-1)
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise ValueError(f"zmp must be 2 finite numbers, got {zmp}")
        fn = float(normal_force)
        if not np.isfinite(fn):
            raise ValueError(f"normal_force must be finite, got {normal_force}")
        return self._update(c, a, p, fn)

    def _update(self, c: np.ndarray, a: np.ndarray, p: np.ndarray, fn: float) -> tuple[np.ndarray, bool]:
        """``update`` without the input checks (for callers that checked whole recordings)."""
        M, g = self.parameters.mass, self.parameters.gravity
        fz, fx, fy = self._filters[2], self._filters[0], self._filters[1]
        self._step(fz, self._C_z, self._R_z, np.array([c[2], a[2], fn + M * g]))
        z_hat, zdd_hat, Fz_hat = fz.x[0], fz.x[2], fz.x[3]
        fn_hat = -M * g - M * zdd_hat + Fz_hat
        valid = abs(fn_hat) >= self.parameters.min_normal_force_fraction * M * g
        if valid:
            C = self._C_xy  # its third row varies with the z filter's estimate (eq. 19)
            C[2, 2] = M * z_hat / fn_hat
            C[2, 3] = -z_hat / fn_hat
            for axis, state in ((0, fx), (1, fy)):
                self._step(state, C, self._R_xy, np.array([c[axis], a[axis], p[axis]]))
        else:
            for state in (fx, fy):
                state.x = self._A @ state.x
                state.P = self._A @ state.P @ self._A.T + self._Q
        return np.array([fx.x[3], fy.x[3], fz.x[3]]), bool(valid)


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
    for name, array, columns in (("com_position", com_position, 3), ("com_acceleration", com_acceleration, 3), ("zmp", zmp, 2)):
        if array.shape != (n, columns):
            raise ValueError(f"{name} has shape {array.shape}; expected ({n}, {columns})")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name} has NaN or inf in rows {np.flatnonzero(~np.all(np.isfinite(array), axis=1)).tolist()}")
    if not np.all(np.isfinite(normal_force)):
        raise ValueError(f"normal_force has NaN or inf at {np.flatnonzero(~np.isfinite(normal_force)).tolist()}")
    observer = LipForceObserver(parameters)
    observer.reset(com_position[0], com_acceleration[0])
    forces = np.empty((n, 3))
    valid = np.empty(n, dtype=bool)
    for k, fn in enumerate(normal_force.tolist()):
        forces[k], valid[k] = observer._update(com_position[k], com_acceleration[k], zmp[k], fn)
    return forces, valid


def _inverse_3x3(S: np.ndarray) -> np.ndarray:
    """Inverse of a 3x3 matrix by cofactors (a numpy call costs more than these flops)."""
    (a, b, c), (d, e, f), (g, h, i) = S.tolist()
    co = (e * i - f * h, f * g - d * i, d * h - e * g)
    det = a * co[0] + b * co[1] + c * co[2]
    if det == 0.0:
        raise np.linalg.LinAlgError("singular innovation covariance")
    r = 1.0 / det
    return np.array(
        (
            (co[0] * r, (c * h - b * i) * r, (b * f - c * e) * r),
            (co[1] * r, (a * i - c * g) * r, (c * d - a * f) * r),
            (co[2] * r, (b * g - a * h) * r, (a * e - b * d) * r),
        )
    )


def _vector3(name: str, value) -> np.ndarray:
    v = np.asarray(value, dtype=float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value}")
    return v


class LipForceObserverSystem(LeafSystem):
    """The observer as a Drake system, updated every ``parameters.period`` seconds.

    Inputs:
        com_position: (3,) CoM position in the support-foot frame, m.
        com_acceleration: (3,) CoM acceleration in the inertial frame, gravity-compensated, m/s^2.
        zmp: (2,) ZMP = CoP of the FSRs (eq. 13), m.
        normal_force: (1,) f_n^o = -(sum of the FSR normal forces) (eq. 12), N (-M g at rest).
    State: discrete, [initialised flag; per filter (z, x, y) its 5 states and 5x5 covariance].
    Outputs:
        virtual_force: (3,) F^ = [F^_x, F^_y, F^_z] (eq. 11), N, world-aligned CoM frame.
        valid: (1,) 1 when the normal force allows the x/y estimate, else 0 (feet off the
            ground: the x/y filters only predict).
        filter_states: (15,) the z, x and y filters' states (eq. 18, 20).

    The first update initialises the filters from the inputs as the authors do
    (``LipForceObserver.reset``), then runs one predict/correct step.
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
        # [flag, valid, 3 x (x (5), P (25))]
        self._state_index = self.DeclareDiscreteState(2 + 3 * 30)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        xd = {self.xd_ticket()}
        self.DeclareVectorOutputPort("virtual_force", 3, lambda c, o: o.SetFromVector(self._unpacked(c)[2][[8, 13, 3]]), xd)
        self.DeclareVectorOutputPort("valid", 1, lambda c, o: o.SetFromVector([self._unpacked(c)[1]]), xd)
        self.DeclareVectorOutputPort("filter_states", 15, lambda c, o: o.SetFromVector(self._unpacked(c)[2]), xd)

    def _unpacked(self, context: Context):
        s = context.get_discrete_state(self._state_index).get_value()
        states = np.concatenate([s[2 + 30 * i : 7 + 30 * i] for i in range(3)])  # z, x, y
        return s[0], s[1], states

    def _inputs(self, context: Context):
        return {
            name: np.array(eval_finite_input("LipForceObserverSystem", port, context))
            for name, port in self._ports.items()
        }

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        u = self._inputs(context)
        s = context.get_discrete_state(self._state_index).get_value()
        core = self._core
        if s[0] < 0.5:
            core.reset(u["com_position"], u["com_acceleration"])
        else:  # load the filters of this context (order z, x, y) into the core
            if core._filters is None:
                core.reset(np.zeros(3), np.zeros(3))
            for i, state in zip(range(3), (core._filters[2], core._filters[0], core._filters[1])):
                block = s[2 + 30 * i : 32 + 30 * i]
                state.x = block[:5].copy()
                state.P = block[5:].reshape(5, 5).copy()
        _, valid = core._update(u["com_position"], u["com_acceleration"], u["zmp"], float(u["normal_force"][0]))
        out = np.empty_like(s)
        out[0], out[1] = 1.0, float(valid)
        for i, state in zip(range(3), (core._filters[2], core._filters[0], core._filters[1])):
            out[2 + 30 * i : 7 + 30 * i] = state.x
            out[7 + 30 * i : 32 + 30 * i] = state.P.reshape(-1)
        discrete_state.set_value(self._state_index, out)
