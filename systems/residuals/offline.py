"""The momentum residuals run on a recorded log instead of in a simulation, and the
residual noise model a calibration log gives the contact detector.

``replay_residuals`` steps the same ``InternalResidual`` and ``ExternalResidual`` systems
(and optionally the ``ClassicalResidual``)
(``systems.residuals.momentum_residuals``) through the log's samples, so a log replays
exactly as the robot's estimators would have run on it. ``replay_contact_estimation`` adds
the ``ContactDetector`` and the ``ContactLocalizer`` (``systems.residuals.contact_estimation``)
with the one-update delay they have in a diagram. Both run each system's own update code
(its ``advance`` method, which its periodic update event also runs, or the same algebra and
logic over all samples at once: ``_stacked_residuals``, ``ContactDetector.replay``,
``ContactLocalizer.replay_from``) without the framework's contexts and fixed input ports,
whose per-sample cost would exceed the dynamics' (the floor of issue 14: a 1 kHz log of a
34-joint robot at 5x real time on one core). Without an unknown contact, what
they report is model error plus sensor noise: ``residual_noise_model`` takes their
covariance over a calibration log as the detector's noise model (``ContactDetector``'s
``covariance_internal`` and ``covariance_external_force``), in place of the covariance
predicted from white sensor noise alone, which a real robot's estimators exceed (base-state
estimation error, model error left after refinement, friction).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame

from systems.dynamics.base_state import QUATERNION_NORM_TOLERANCE
from systems.residuals.contact_estimation import ContactDetector, ContactLocalizer
from systems.residuals.momentum_residuals import ClassicalResidual, ExternalResidual, InternalResidual, ResidualModel

#: The dynamics implementations whose ``mass_matrix_terms_of_samples`` the stacked replay
#: runs on ("reference" has none: it replays sample by sample). "pinocchio" gives M_dot
#: exactly (C + C^T), "fast" by the central difference the live systems use.
STACKED_IMPLEMENTATIONS = ("fast", "pinocchio")


@dataclass
class ResidualNoiseModel:
    """Covariances of the residuals without unknown contact, measured on a log.

    Attributes:
        internal_gain, external_gain: the residual gains K they hold for, 1/s.
        period: the residuals' update period, s.
        covariance_internal: (n, n) of the internal residual, N^2 m^2.
        covariance_external_force: (3, 3) of the external residual's force in world, N^2.
        samples: how many samples they were computed from.
        covariance_classical: (n, n) of the classical residual's joint entries (eq. 7,
            gain ``internal_gain``), N^2 m^2, or None if it was not replayed.
    """

    internal_gain: float
    external_gain: float
    period: float
    covariance_internal: np.ndarray
    covariance_external_force: np.ndarray
    samples: int
    covariance_classical: np.ndarray | None = None

    def check_gains(self, internal_gain: float, external_gain: float, period: float, who: str) -> None:
        """ValueError unless the residuals that use this model run with its gains and period."""
        if not np.allclose(
            (self.internal_gain, self.external_gain, self.period), (internal_gain, external_gain, period), rtol=1e-12
        ):
            raise ValueError(
                f"{who}: the residual noise model was measured with gains {self.internal_gain:g}, "
                f"{self.external_gain:g} 1/s and period {self.period:g} s; these residuals use {internal_gain:g}, "
                f"{external_gain:g} 1/s and {period:g} s: calibrate again with the same gains"
            )

    def as_arrays(self) -> dict[str, np.ndarray]:
        """Its fields as arrays (for ``np.savez``; see ``from_arrays``)."""
        arrays = {
            "noise_gains_period": np.array([self.internal_gain, self.external_gain, self.period, self.samples]),
            "noise_covariance_internal": self.covariance_internal,
            "noise_covariance_external_force": self.covariance_external_force,
        }
        if self.covariance_classical is not None:
            arrays["noise_covariance_classical"] = self.covariance_classical
        return arrays

    @classmethod
    def from_arrays(cls, data) -> ResidualNoiseModel | None:
        """The model saved by ``as_arrays`` in the mapping ``data``, or None if absent."""
        if "noise_gains_period" not in data:
            return None
        gains = np.asarray(data["noise_gains_period"], dtype=float)
        return cls(
            internal_gain=float(gains[0]),
            external_gain=float(gains[1]),
            period=float(gains[2]),
            covariance_internal=np.array(data["noise_covariance_internal"], dtype=float),
            covariance_external_force=np.array(data["noise_covariance_external_force"], dtype=float),
            samples=int(gains[3]),
            covariance_classical=(
                np.array(data["noise_covariance_classical"], dtype=float)
                if "noise_covariance_classical" in data
                else None
            ),
        )


class ReplayedResiduals(NamedTuple):
    """What ``replay_residuals`` returns: per log sample, the internal residual (N, n), the
    external residual's wrench in world (N, 6), and the classical residual (N, nv) or None."""

    internal: np.ndarray
    external_wrench_world: np.ndarray
    classical: np.ndarray | None


def replay_residuals(
    plant: MultibodyPlant,
    model: ResidualModel,
    known_wrench_frames: Sequence[Frame],
    state: np.ndarray,
    joint_torque: np.ndarray,
    known_wrenches: np.ndarray,
    *,
    internal_gain: float,
    external_gain: float,
    period: float,
    classical_gain: float | None = None,
    stacked: bool = False,
) -> ReplayedResiduals:
    """The internal residual (N, n) and the external residual's ``external_wrench_world``
    (N, 6) at each of the N samples of a log taken every ``period`` s, and with
    ``classical_gain`` the classical residual (eq. 7, N x nv) too.

    Args:
        plant, model: the plant and the estimators' dynamics model (refined or not).
        known_wrench_frames: the F/T frames, in the order of ``known_wrenches``.
        state: (N, nq + nv) the sensed [q; v].
        joint_torque: (N, n) the joint torques the internal residual reads (the motor
            torques, corrected if the model is refined), v[6:] order, N m.
        known_wrenches: (N, 6 k) the F/T wrenches, world.
        internal_gain, external_gain: K, 1/s. period: T, s.
        classical_gain: K of the classical residual, 1/s; None: not replayed.
        stacked: True: the whole log at once (``_stacked_residuals``; 2.4x faster,
            ``make benchmark``), equal to the per-sample updates to rounding (9e-14 N m
            on ``make benchmark``'s 2 s push log, of residuals up to 24 N m: the same
            Drake calls, the algebra in another order); False (default): the systems' own
            updates, sample by sample.

    Raises:
        ValueError: arrays of inconsistent sizes or non-finite values (naming them).
    """
    state = np.asarray(state, dtype=float)
    joint_torque = np.asarray(joint_torque, dtype=float)
    known_wrenches = np.asarray(known_wrenches, dtype=float)
    frames = tuple(known_wrench_frames)
    n = plant.num_velocities() - 6
    expected = {
        "state": (state, plant.num_positions() + plant.num_velocities()),
        "joint_torque": (joint_torque, n),
        "known_wrenches": (known_wrenches, 6 * len(frames)),
    }
    samples = state.shape[0] if state.ndim == 2 else -1
    for name, (array, width) in expected.items():
        if array.ndim != 2 or array.shape != (samples, width):
            raise ValueError(f"replay_residuals: {name} must be (N, {width}) with N = {samples}, got {array.shape}")
        if not np.isfinite(array).all():
            raise ValueError(f"replay_residuals: {name} holds NaN or inf")
    internal = InternalResidual(plant, internal_gain, period, frames, model=model)
    external = ExternalResidual(plant, external_gain, period, frames, model=model)
    classical = None
    if classical_gain is not None:
        classical = ClassicalResidual(plant, classical_gain, period, frames, model=model)
    replayed = None
    if stacked:
        replayed = _stacked_residuals(internal, external, state, joint_torque, known_wrenches, classical=classical)
    if replayed is None:
        replayed = _replay_residuals(internal, external, classical, state, joint_torque, known_wrenches)
    return replayed[0]


def _replay_residuals(
    internal: InternalResidual,
    external: ExternalResidual,
    classical: ClassicalResidual | None,
    state: np.ndarray,
    joint_torque: np.ndarray,
    known_wrenches: np.ndarray,
    integral: np.ndarray | None = None,
) -> tuple[ReplayedResiduals, np.ndarray | None]:
    """The residual systems' updates (``advance``: the code of their periodic update,
    without the framework's contexts and ports) at every sample, one after another on the
    shared model (one dynamics evaluation per sample). ``integral`` and the second result:
    the internal and external observers' I^+ before the first and after the last sample,
    as ``_stacked_residuals``'s (the classical residual starts afresh)."""
    samples = state.shape[0]
    n = joint_torque.shape[1]
    wrenches = known_wrenches if internal.known_wrench_frames else [None] * samples
    out_internal = np.empty((samples, n))
    out_external = np.empty((samples, 6))
    out_classical = None if classical is None else np.empty((samples, n + 6))
    integrals = [None, None, None]
    if integral is not None:
        integrals[:2] = [np.array(integral[:n], dtype=float), np.array(integral[n:], dtype=float)]
    for k in range(samples):
        x, w = state[k], wrenches[k]
        integrals[0], out_internal[k], _ = internal.advance(x, joint_torque[k], w, integrals[0])
        integrals[1], residual, terms = external.advance(x, None, w, integrals[1])
        out_external[k] = external.world_wrench(terms, x, residual)
        if classical is not None:
            integrals[2], out_classical[k], _ = classical.advance(x, joint_torque[k], w, integrals[2])
    end = None if integrals[0] is None else np.concatenate(integrals[:2])
    return ReplayedResiduals(out_internal, out_external, out_classical), end


def residual_noise_model(
    internal: np.ndarray,
    external_wrench_world: np.ndarray,
    *,
    internal_gain: float,
    external_gain: float,
    period: float,
    skip: int = 0,
    shrinkage: float = 0.1,
    classical: np.ndarray | None = None,
) -> ResidualNoiseModel:
    """The residuals' covariances over the samples after the first ``skip`` (the start-up),
    each shrunk toward its diagonal: (1 - shrinkage) C + shrinkage diag(C) (a stable
    estimate from correlated samples; the residuals' samples are correlated over 1/K s).
    ``classical``: the classical residual (N, nv) replayed with gain ``internal_gain``, whose
    joint entries give ``covariance_classical``.

    Raises:
        ValueError: fewer than 100 samples left, or a shrinkage outside [0, 1].
    """
    internal = np.asarray(internal, dtype=float)[skip:]
    force = np.asarray(external_wrench_world, dtype=float)[skip:, 3:]
    if internal.shape[0] < 100:
        raise ValueError(f"residual_noise_model: need at least 100 samples after skip, got {internal.shape[0]}")
    if not 0.0 <= shrinkage <= 1.0:
        raise ValueError(f"residual_noise_model: shrinkage must be in [0, 1], got {shrinkage}")

    def covariance(x: np.ndarray) -> np.ndarray:
        c = np.cov(x, rowvar=False)
        return (1.0 - shrinkage) * c + shrinkage * np.diag(np.diag(c))

    return ResidualNoiseModel(
        internal_gain=float(internal_gain),
        external_gain=float(external_gain),
        period=float(period),
        covariance_internal=covariance(internal),
        covariance_external_force=covariance(force),
        samples=int(internal.shape[0]),
        covariance_classical=None if classical is None else covariance(np.asarray(classical, dtype=float)[skip:, 6:]),
    )


def _stacked_residuals(
    internal: InternalResidual,
    external: ExternalResidual,
    state: np.ndarray,
    joint_torque: np.ndarray,
    known_wrenches: np.ndarray,
    chunk: int = 128,
    integral: np.ndarray | None = None,
    classical: ClassicalResidual | None = None,
) -> tuple[ReplayedResiduals, np.ndarray] | None:
    """The internal (eq. 11) and external (eq. 16) residuals of the whole log at once: per
    sample only what needs the plant (the mass matrix, its derivative and the bias of
    ``DrakeFloatingBaseDynamics.mass_matrix_terms_of_samples``, the F/T frames' Jacobians); the
    elimination of eq. (9) (``reduce_to_floating_terms``), eq. (10)'s known-wrench
    torques, the momenta and rates of ``_momentum_and_rates`` and the world wrench of
    ``ResidualModel.base_wrench_to_world`` over all samples as stacked numpy; then the
    observer recursion of ``advance`` as the linear filter it is. Equal to the systems'
    own updates to rounding (the tests compare them). ``integral``: the observers' momentum
    integral I^+ [internal (n); external (6)] of the update before the first sample (None:
    the first sample is the first update). With ``classical`` the classical residual (eq. 7)
    too, from the same terms, starting afresh at the first sample. Returns the residuals and
    I^+ after the last sample; None when the model's dynamics is not one of
    ``STACKED_IMPLEMENTATIONS`` or the residuals do not share the model and period (then ``advance``
    runs per sample). ``chunk``: samples stacked at a time (the numbers do not depend on it):
    128 keeps a chunk's mass matrices (2 x 1.6 MB for 34 joints) near the cache and in
    memory reused from chunk to chunk (1000: 5000 page faults per estimation of
    ``make benchmark``'s 2 s log, 128: none)."""
    model = internal.model
    if external.model is not model or internal.period != external.period:
        return None
    if classical is not None and (classical.model is not model or classical.period != internal.period):
        return None
    dynamics = model.dynamics
    if dynamics.implementation not in STACKED_IMPLEMENTATIONS:
        return None
    nq, n = model.num_positions, model.num_joints
    off = np.flatnonzero(np.abs(np.linalg.norm(state[:, :4], axis=1) - 1.0) > QUATERNION_NORM_TOLERANCE)
    if off.size:
        raise ValueError(f"replay: the base quaternion of sample {int(off[0])} is not of unit norm")
    frames = internal.known_wrench_frames
    samples = state.shape[0]
    out_internal, out_external = np.empty((samples, n)), np.empty((samples, 6))
    period = internal.period
    gain = np.concatenate((internal._gain, external._gain))
    previous = None if integral is None else np.array(integral, dtype=float)  # I^+ of the last update
    out_classical, previous_classical = None, None
    if classical is not None:
        out_classical = np.empty((samples, n + 6))
    model.forget_state()  # the samples' dynamics move its context or kinematics
    for start in range(0, samples, chunk):
        rows = range(start, min(start + chunk, samples))
        K = len(rows)
        M, M_dot, bias, R_WB, v0, J = dynamics.mass_matrix_terms_of_samples(
            state[rows.start : rows.stop, :nq], state[rows.start : rows.stop, nq:], frames
        )
        x = state[rows.start : rows.stop]
        qdot = x[:, nq + 6 :, None]
        I0c, F, H = M[:, :6, :6], M[:, :6, 6:], M[:, 6:, 6:]
        I0c_dot, F_dot, H_dot = M_dot[:, :6, :6], M_dot[:, :6, 6:], M_dot[:, 6:, 6:]
        FT, F_dot_T = F.transpose(0, 2, 1), F_dot.transpose(0, 2, 1)
        p_hat, C_hat = bias[:, :6, None], bias[:, 6:, None]
        # ResidualModel.known_wrench_forces: [m; f] per frame rotated into F0, through J^T.
        generalized = np.zeros((K, n + 6, 1))
        if frames:
            w = known_wrenches[rows.start : rows.stop].reshape(K, len(frames), 2, 3) @ R_WB[:, None]
            generalized = (J.transpose(0, 1, 3, 2) @ w.reshape(K, len(frames), 6, 1)).sum(axis=1)
        w_F0, tau_joints = generalized[:, :6], generalized[:, 6:]
        # Eq. (9)'s elimination (``reduce_to_floating_terms``) applied to vectors rather than
        # formed: with G = I0c^-1 F, H_fb qdot = H qdot - F^T G qdot, H_fb_dot qdot (eq. 13) =
        # H_dot qdot - G^T F_dot qdot - F_dot^T G qdot + G^T I0c_dot G qdot, C_fb = C^ - G^T p^,
        # and eq. (10)'s known-wrench torques take G^T w_F0. G itself is never formed: G qdot
        # and G^T x = F^T I0c^-1 x (I0c is symmetric) are two solves with I0c of one and four
        # right-hand sides, equal to forming G to rounding and 4x cheaper than its n columns.
        H_qdot, H_dot_qdot = H @ qdot, H_dot @ qdot
        F_qdot, F_dot_qdot = F @ qdot, F_dot @ qdot
        G_qdot = np.linalg.solve(I0c, F_qdot)
        GT_F_dot_qdot, GT_I0c_dot_G_qdot, GT_p_hat, GT_w_F0 = np.split(
            FT @ np.linalg.solve(I0c, np.concatenate((F_dot_qdot, I0c_dot @ G_qdot, p_hat, w_F0), axis=2)), 4, axis=2
        )
        H_fb_qdot = H_qdot - FT @ G_qdot
        H_fb_dot_qdot = H_dot_qdot - GT_F_dot_qdot - F_dot_T @ G_qdot + GT_I0c_dot_G_qdot
        C_fb = C_hat - GT_p_hat
        # InternalResidual and ExternalResidual._momentum_and_rates.
        tau_m = joint_torque[rows.start : rows.stop, :, None] - internal._damping[:, None] * qdot
        v0c = v0[:, :, None]
        momentum = np.concatenate((H_fb_qdot, I0c @ v0c + F_qdot), axis=1)[:, :, 0]
        rate = np.concatenate((H_fb_dot_qdot - C_fb, I0c_dot @ v0c + F_dot_qdot - p_hat), axis=1)[:, :, 0]
        measured = np.concatenate((tau_m + tau_joints - GT_w_F0, w_F0), axis=1)[:, :, 0]
        residual, previous = _momentum_observer(gain, period, momentum, rate, measured, previous)
        out_internal[rows.start : rows.stop] = residual[:, :n]
        if classical is not None:
            # ClassicalResidual._momentum_and_rates: the virtual-joint model's momentum and
            # rates, [base (F0), the external residual's rows; joints], with its own damping.
            tau_c = joint_torque[rows.start : rows.stop, :, None] - classical._damping[:, None] * qdot
            joints_momentum = (FT @ v0c + H_qdot)[:, :, 0]
            joints_rate = (F_dot_T @ v0c + H_dot_qdot - C_hat)[:, :, 0]
            momentum_c = np.concatenate((momentum[:, n:], joints_momentum), axis=1)
            rate_c = np.concatenate((rate[:, n:], joints_rate), axis=1)
            measured_c = np.concatenate((measured[:, n:], (tau_c + tau_joints)[:, :, 0]), axis=1)
            out_classical[rows.start : rows.stop], previous_classical = _momentum_observer(
                classical._gain, period, momentum_c, rate_c, measured_c, previous_classical
            )
        # ResidualModel.base_wrench_to_world, stacked.
        moment_W = (R_WB @ residual[:, n : n + 3, None])[:, :, 0]
        force_W = (R_WB @ residual[:, n + 3 :, None])[:, :, 0]
        p_WBo = model._p_WP + x[:, 4:7] @ model._R_WP.T
        out_external[rows.start : rows.stop] = np.concatenate((moment_W + np.cross(p_WBo, force_W), force_W), axis=1)
    return ReplayedResiduals(out_internal, out_external, out_classical), previous


def _momentum_observer(
    gain: np.ndarray,
    period: float,
    momentum: np.ndarray,
    rate: np.ndarray,
    measured: np.ndarray,
    previous: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """``_MomentumResidual.advance``'s recursion over K samples (K, m), as the first-order
    linear filter it is: with y_k its state I^+ after update k and a_k = T/2 rate_k +
    T measured_k,
      I_k = y_{k-1} + a_k,  r_k = K (p_k - I_k),  y_k = I_k + T/2 rate_k + T r_k,
    so y_k = c y_{k-1} + u_k with c = 1 - K T and u_k = c a_k + T/2 rate_k + K T p_k
    (the first update, ``previous`` None: I_0 = p_0, r_0 = 0, y_0 = p_0 + T/2 rate_0).
    Returns the residuals (K, m) and y after the last sample."""
    half_step = 0.5 * period * rate
    a = half_step + period * measured
    c = 1.0 - gain * period
    u = c * a + half_step + (gain * period) * momentum
    first = 0
    if previous is None:
        previous = momentum[0] + half_step[0]
        first = 1
    y = np.empty_like(momentum)
    if first:
        y[0] = previous
    y[first:] = _first_order_filter(c, u[first:], previous)
    y_before = np.concatenate((previous[None] if not first else y[:1], y[:-1]), axis=0)
    residual = gain * (momentum - (y_before + a))
    if first:
        residual[0] = 0.0
    return residual, y[-1]


def _first_order_filter(c: np.ndarray, u: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """(K, m) y_k = c * y_{k-1} + u_k for k = 1..K from y_0 (per column, c (m,) the pole of
    each column): scipy.signal.lfilter once per distinct pole."""
    from scipy.signal import lfilter

    y = np.empty_like(u)
    for pole in np.unique(c):
        cols = np.flatnonzero(c == pole)
        y[:, cols], _ = lfilter([1.0], [1.0, -pole], u[:, cols], axis=0, zi=(pole * y0[cols])[None, :])
    return y


class ReplayState(NamedTuple):
    """Where a ``replay_contact_estimation`` left off, to continue from (its ``start``):
    the observers' momentum integral I^+ [internal (n); external (6)] of the last update,
    that update's internal residual (n,) and external wrench in world (6,) (the detector's
    and the localizer's next inputs), the detector's state and flag, and the localizer's
    state (as ``ContactLocalizer.advance`` takes it, or None)."""

    integral: np.ndarray
    internal: np.ndarray
    external_wrench_world: np.ndarray
    detector: np.ndarray
    detected: bool
    localizer: tuple | None


class ReplayedEstimation(NamedTuple):
    """What ``replay_contact_estimation`` returns, per log sample (N): the residuals (as
    ``ReplayedResiduals``), the detector's flag (N,) and test statistics (N, 2), and the
    localizer's outputs ({"status", "body_index", "point_world", "force_world"}), or None;
    and the state after the last sample (``ReplayState``; None for an empty log)."""

    internal: np.ndarray
    external_wrench_world: np.ndarray
    contact_detected: np.ndarray
    test_statistics: np.ndarray
    localization: dict | None
    end: ReplayState | None = None


def replay_contact_estimation(
    internal: InternalResidual,
    external: ExternalResidual,
    make_detector: Callable[[np.ndarray, np.ndarray], ContactDetector],
    localizer: ContactLocalizer | None,
    state: np.ndarray,
    joint_torque: np.ndarray,
    known_wrenches: np.ndarray,
    *,
    start: ReplayState | None = None,
    times: np.ndarray | None = None,
    localize_end_only: bool = False,
) -> ReplayedEstimation:
    """The residuals (eqs. 11, 16), the ContactDetector and the ContactLocalizer (Sec. VI)
    stepped through a log of N samples taken every ``internal``'s period T, in the order
    and with the timing they have in a diagram (``diagrams.residuals.log_estimation``):
    at update k (time k T) the residuals read sample k, while the detector and the
    localizer read the residuals' (and the detector's) outputs of update k - 1 (zeros at
    k = 0) and the localizer sample k's state. Each system runs its own update code over
    the whole log: the residuals stacked (``_stacked_residuals``: ``advance``'s algebra and
    recursion over all samples at once), the detector's ``replay`` (its ``advance``'s
    switching logic, the threshold tests of all samples at once) and the localizer's
    ``replay_from``, so the outputs equal what the systems report online, to rounding.

    Args:
        internal, external: the residual systems (sharing one ``ResidualModel``).
        make_detector: (internal residual (N, n), external wrench (N, 6)) -> the
            ContactDetector to run (its noise model may be measured on them).
        localizer: the ContactLocalizer, or None (no localization).
        state, joint_torque, known_wrenches: the log as ``replay_residuals`` takes it.
        start: the ``end`` of a replay of the samples just before these (None: these
            are the first updates): the systems go on from it, as they do online.
        times: (N,) the updates' times, s, one period apart (default k T): the detector's
            start-up and detection time and the localizer's settling and localization
            period read them.
        localize_end_only: only the localizer's state after the last sample is wanted
            (``ContactLocalizer.replay_from``'s ``end_only``; no per-sample localization).

    Raises:
        ValueError: arrays of inconsistent sizes or non-finite values (naming them).
    """
    plant = internal.model.plant
    n = plant.num_velocities() - 6
    state = np.asarray(state, dtype=float)
    joint_torque = np.asarray(joint_torque, dtype=float)
    known_wrenches = np.asarray(known_wrenches, dtype=float)
    samples = state.shape[0] if state.ndim == 2 else -1
    expected = {
        "state": (state, plant.num_positions() + plant.num_velocities()),
        "joint_torque": (joint_torque, n),
        "known_wrenches": (known_wrenches, 6 * len(internal.known_wrench_frames)),
    }
    for name, (array, width) in expected.items():
        if array.ndim != 2 or array.shape != (samples, width):
            raise ValueError(
                f"replay_contact_estimation: {name} must be (N, {width}) with N = {samples}, got {array.shape}"
            )
        if not np.isfinite(array).all():
            raise ValueError(f"replay_contact_estimation: {name} holds NaN or inf")
    integral = None if start is None else start.integral
    stacked = _stacked_residuals(internal, external, state, joint_torque, known_wrenches, integral=integral)
    if stacked is None:
        stacked = _replay_residuals(internal, external, None, state, joint_torque, known_wrenches, integral)
    residuals, integral_end = stacked
    detector = make_detector(residuals.internal, residuals.external_wrench_world)
    period = internal.period
    if times is None:
        times = np.arange(samples) * period
    times = np.asarray(times, dtype=float)
    if times.shape != (samples,):
        raise ValueError(f"replay_contact_estimation: times must be ({samples},), got {times.shape}")
    # The detector and the localizer see the residuals one update late (see above).
    before_internal = np.zeros((1, n)) if start is None else np.asarray(start.internal, dtype=float)[None]
    before_external = np.zeros((1, 6)) if start is None else np.asarray(start.external_wrench_world, dtype=float)[None]
    late_internal = np.vstack((before_internal, residuals.internal[:-1]))
    late_external = np.vstack((before_external, residuals.external_wrench_world[:-1]))
    if start is None:
        detector_state = detector.CreateDefaultContext().get_discrete_state_vector().CopyToVector()
    else:
        detector_state = np.array(start.detector, dtype=float)
    columns = end_columns = None
    if detector.unknown_wrench_frames:  # the ground's wrenches: columns filtered as the residuals
        columns, end_columns = detector.filtered_columns(detector_state[6:], state[:, : plant.num_positions()])
    statistics = detector.statistics_of_samples(late_external, late_internal, columns)
    detected, detector_state = detector.replay(detector_state, statistics, times)
    if end_columns is not None:
        detector_state[6:] = end_columns.ravel().tolist()
    localization = None
    localizer_end = None
    if localizer is not None:
        before = False if start is None else bool(start.detected)
        late_detected = np.concatenate(([before], detected[:-1]))
        results, localizer_end = localizer.replay_from(
            None if start is None else start.localizer,
            times,
            state,
            late_external,
            late_internal,
            late_detected,
            end_only=localize_end_only,
        )
        if results is not None:
            localization = {
                "status": results[:, 0].copy(),
                "body_index": results[:, 1].copy(),
                "point_world": results[:, 2:5].copy(),
                "force_world": results[:, 5:8].copy(),
            }
    end = None
    if samples:
        end = ReplayState(
            integral=integral_end,
            internal=residuals.internal[-1].copy(),
            external_wrench_world=residuals.external_wrench_world[-1].copy(),
            detector=np.array(detector_state, dtype=float),
            detected=bool(detected[-1]),
            localizer=localizer_end,
        )
    return ReplayedEstimation(
        residuals.internal, residuals.external_wrench_world, detected, statistics, localization, end
    )
