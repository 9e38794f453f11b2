"""Force profiles of a "human" guiding a robot by its hands (Hawley et al. 2019, Sec. 6.5):
``GuidanceProfile``, plateaus with C2 (quintic smoothstep) edges, and ``ScaledProfile``
(a fraction of a profile, e.g. per hand). Both follow the ``ForceProfile`` protocol of
``systems.simulation.disturbances`` (``value(t)`` in N, t in s) and feed its ``Push``; they
serve the force-guided walk (``systems.observer.force_guided_walking``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from systems.locomotion.walking_pattern import smoothstep5


@dataclass(frozen=True)
class GuidanceProfile:
    """Total force along x on the hands, N: a sequence of plateaus (t_on, t_off, magnitude)
    with ``ramp`` s 5th-order smoothstep edges (rising from t_on, falling from t_off),
    zero elsewhere; per hand, half of it."""

    plateaus: tuple = ((1.5, 5.5, 5.0), (7.5, 10.5, -5.0))
    ramp: float = 0.2

    def __post_init__(self):
        if not (math.isfinite(self.ramp) and self.ramp > 0):
            raise ValueError(f"ramp must be positive, got {self.ramp}")
        last = -math.inf
        for t_on, t_off, magnitude in self.plateaus:
            if not (math.isfinite(t_on) and math.isfinite(t_off) and math.isfinite(magnitude)):
                raise ValueError("plateaus must hold finite numbers")
            if not (t_on >= last and t_off >= t_on + self.ramp):
                raise ValueError(f"plateau ({t_on}, {t_off}) must start after the previous one ends and last >= ramp")
            last = t_off + self.ramp

    def value(self, t):
        t_arr = np.asarray(t, dtype=float)
        out = np.zeros_like(t_arr)
        for t_on, t_off, magnitude in self.plateaus:
            up = smoothstep5((t_arr - t_on) / self.ramp)
            down = 1.0 - smoothstep5((t_arr - t_off) / self.ramp)
            out = out + magnitude * np.minimum(up, down)
        return float(out) if np.ndim(t) == 0 else out

    def crossings(self, threshold: float) -> list[tuple[float, str, int]]:
        """(time, "on"/"off", sign) where |total| crosses ``threshold`` (1 ms grid)."""
        t = np.arange(0.0, self.end + 1.0, 1e-3)
        v = self.value(t)
        above = np.abs(v) > threshold
        out = []
        for k in np.flatnonzero(above[1:] != above[:-1]) + 1:
            out.append((float(t[k]), "on" if above[k] else "off", int(np.sign(v[k] if above[k] else v[k - 1]))))
        return out

    @property
    def end(self) -> float:
        return max((t_off + self.ramp for _, t_off, _ in self.plateaus), default=0.0)


class ScaledProfile:
    """``scale`` times a profile (e.g. 0.5: one of two hands), N."""

    def __init__(self, profile, scale: float):
        if not math.isfinite(scale):
            raise ValueError(f"ScaledProfile: scale must be finite, got {scale}")
        self._profile = profile
        self._scale = float(scale)

    def value(self, t):
        return self._scale * self._profile.value(t)


__all__ = ["GuidanceProfile", "ScaledProfile"]
