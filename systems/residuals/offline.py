"""The momentum residuals run on a recorded log instead of in a simulation, and the
residual noise model a calibration log gives the contact detector.

``replay_residuals`` steps the same ``InternalResidual`` and ``ExternalResidual`` systems
(and optionally the ``ClassicalResidual``)
(``systems.residuals.momentum_residuals``) through the log's samples, so a log replays
exactly as the robot's estimators would have run on it. Without an unknown contact, what
they report is model error plus sensor noise: ``residual_noise_model`` takes their
covariance over a calibration log as the detector's noise model (``ContactDetector``'s
``covariance_internal`` and ``covariance_external_force``), in place of the covariance
predicted from white sensor noise alone, which a real robot's estimators exceed (base-state
estimation error, model error left after refinement, friction).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame

from systems.residuals.momentum_residuals import ClassicalResidual, ExternalResidual, InternalResidual, ResidualModel


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
    systems = [
        (InternalResidual(plant, internal_gain, period, frames, model=model), "residual", n),
        (ExternalResidual(plant, external_gain, period, frames, model=model), "external_wrench_world", 6),
    ]
    if classical_gain is not None:
        systems.append((ClassicalResidual(plant, classical_gain, period, frames, model=model), "residual", n + 6))
    outputs = [np.empty((samples, width)) for _, _, width in systems]
    contexts = [system.CreateDefaultContext() for system, _, _ in systems]
    state_values = [s.GetInputPort("state").FixValue(c, state[0]) for (s, _, _), c in zip(systems, contexts)]
    wrench_values = [
        s.GetInputPort("known_wrenches").FixValue(c, known_wrenches[0]) for (s, _, _), c in zip(systems, contexts)
    ]
    torque_values = [
        s.GetInputPort("measured_torque").FixValue(c, joint_torque[0])
        for (s, _, _), c in zip(systems, contexts)
        if s.HasInputPort("measured_torque")
    ]
    ports = [s.GetOutputPort(name) for s, name, _ in systems]
    for k in range(samples):
        for value in state_values:
            value.GetMutableData().set_value(state[k])
        for value in wrench_values:
            value.GetMutableData().set_value(known_wrenches[k])
        for value in torque_values:
            value.GetMutableData().set_value(joint_torque[k])
        for (system, _, _), context, port, out in zip(systems, contexts, ports, outputs):
            context.SetTime(k * period)
            context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
            out[k] = port.Eval(context)
    return ReplayedResiduals(outputs[0], outputs[1], outputs[2] if classical_gain is not None else None)


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
