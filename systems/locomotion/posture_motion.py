"""A slow periodic whole-body motion about a posture: a sum of sinusoidal joint synergies."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from systems.common.smoothing import smoothstep5


class SinusoidalPostureMotion(LeafSystem):
    """Joint positions q(t) = q_c + s(t) sum_i d_i a_i sin(2 pi f_i t + phi_i), rad.

    Each synergy i moves the joints along a direction d_i (n numbers, e.g. a squat: hip,
    knee and ankle pitch together so that the feet stay flat) with amplitude a_i, frequency
    f_i and phase phi_i; s(t) = smoothstep5(t / ramp_time) fades the motion in (position,
    velocity and acceleration continuous at t = 0).

    Outputs:
        position: (n) joint positions, v[6:] order, rad.

    Args:
        center: q_c, (n) rad.
        directions: (k, n) the synergies' joint directions (dimensionless).
        amplitudes, frequencies, phases: (k) each: rad (along d_i), Hz (>= 0), rad.
        ramp_time: s (> 0).
        lower, upper: optional (n) joint limits, rad: the motion must stay within them
            (checked with the worst case sum_i |d_i a_i|), else ValueError.
    """

    def __init__(
        self,
        center: np.ndarray,
        directions: np.ndarray,
        amplitudes: np.ndarray,
        frequencies: np.ndarray,
        phases: np.ndarray,
        ramp_time: float = 2.0,
        lower: np.ndarray | None = None,
        upper: np.ndarray | None = None,
    ):
        super().__init__()
        who = "SinusoidalPostureMotion"
        self._center = np.asarray(center, dtype=float).reshape(-1)
        n = self._center.size
        self._directions = np.atleast_2d(np.asarray(directions, dtype=float))
        k = self._directions.shape[0]
        if self._directions.shape != (k, n):
            raise ValueError(f"{who}: directions must be (k, {n}), got {self._directions.shape}")
        arrays = {}
        for name, value in (("amplitudes", amplitudes), ("frequencies", frequencies), ("phases", phases)):
            a = np.asarray(value, dtype=float).reshape(-1)
            if a.shape != (k,):
                raise ValueError(f"{who}: {name} must have {k} entries (one per synergy), got {a.size}")
            arrays[name] = a
        self._amplitudes, self._frequencies, self._phases = (
            arrays["amplitudes"],
            arrays["frequencies"],
            arrays["phases"],
        )
        values = (self._center, self._directions, self._amplitudes, self._frequencies, self._phases)
        if not all(np.isfinite(v).all() for v in values):
            raise ValueError(f"{who}: center, directions, amplitudes, frequencies and phases must be finite")
        if np.any(self._frequencies < 0.0):
            raise ValueError(f"{who}: frequencies must be >= 0 Hz")
        if not (np.isfinite(ramp_time) and ramp_time > 0.0):
            raise ValueError(f"{who}: ramp_time must be a positive number of seconds, got {ramp_time}")
        self._ramp_time = float(ramp_time)
        reach = np.abs(self._directions * self._amplitudes[:, None]).sum(axis=0)
        for name, limit, bad in (
            ("lower", lower, lambda lim: self._center - reach < lim),
            ("upper", upper, lambda lim: self._center + reach > lim),
        ):
            if limit is None:
                continue
            lim = np.asarray(limit, dtype=float).reshape(-1)
            if lim.shape != (n,):
                raise ValueError(f"{who}: {name} limits must have {n} entries")
            outside = np.flatnonzero(bad(lim))
            if outside.size:
                raise ValueError(
                    f"{who}: the motion leaves the {name} joint limits at joint indices {outside.tolist()}"
                )
        self.DeclareVectorOutputPort("position", n, self._CalcPosition, {self.time_ticket()})

    @property
    def peak_joint_excursion(self) -> np.ndarray:
        """The largest possible |q - q_c| per joint, rad."""
        return np.abs(self._directions * self._amplitudes[:, None]).sum(axis=0)

    @property
    def synergies(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(directions (k, n), amplitudes (k) rad, frequencies (k) Hz, phases (k) rad), copies."""
        return self._directions.copy(), self._amplitudes.copy(), self._frequencies.copy(), self._phases.copy()

    def value(self, t: float) -> np.ndarray:
        """q(t), rad."""
        ramp = smoothstep5(min(max(t / self._ramp_time, 0.0), 1.0))
        waves = self._amplitudes * np.sin(2.0 * np.pi * self._frequencies * t + self._phases)
        return self._center + ramp * (waves @ self._directions)

    def _CalcPosition(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.value(context.get_time()))


__all__ = ["SinusoidalPostureMotion"]
