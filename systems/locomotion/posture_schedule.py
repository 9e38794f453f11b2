"""A joint posture reference through timed knots."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from systems.common.smoothing import smoothstep5


class PostureSchedule(LeafSystem):
    """Joint posture through knots (t_i, q_i): constant outside, a quintic smoothstep (C2)
    between consecutive knots.

    Outputs:
        position: (n) joint positions, v[6:] order, rad.

    Args:
        times: increasing knot times, s (>= 1).
        positions: (len(times), n) the postures at the knots, rad.
    """

    def __init__(self, times: Sequence[float], positions: np.ndarray):
        super().__init__()
        self._t = np.asarray(times, dtype=float).reshape(-1)
        self._q = np.atleast_2d(np.asarray(positions, dtype=float))
        if self._t.size < 1 or self._q.shape[0] != self._t.size or not np.all(np.isfinite(self._q)):
            raise ValueError("PostureSchedule: need one finite posture per knot time")
        if np.any(np.diff(self._t) <= 0) or not np.all(np.isfinite(self._t)):
            raise ValueError("PostureSchedule: knot times must be finite and increasing")
        self.DeclareVectorOutputPort("position", self._q.shape[1], self._CalcPosition, {self.time_ticket()})

    def value(self, t: float) -> np.ndarray:
        k = int(np.searchsorted(self._t, t, side="right"))
        if k == 0:
            return self._q[0].copy()
        if k == self._t.size:
            return self._q[-1].copy()
        s = (t - self._t[k - 1]) / (self._t[k] - self._t[k - 1])
        s = smoothstep5(s)
        return self._q[k - 1] + s * (self._q[k] - self._q[k - 1])

    def _CalcPosition(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.value(context.get_time()))


__all__ = ["PostureSchedule"]
