"""Residual tare: the residual's offset at rest, measured while nothing touches the robot and
removed from then on, as a force/torque sensor is zeroed before an experiment.

A residual (Flacco et al. 2016, eqs. 7, 11 and 16) is zero without contact only with a
perfect model and perfect sensors. On a real robot (and in the realistic world) the
estimators' inertias, the torque sensors' offsets and scale errors leave a constant offset
at the standing posture, which even after calibration can exceed the joint effort of the
push to be felt (TALOS's knees in the push-and-comply experiment). An admittance (eq. 14)
integrates that offset as if it were a push, from the first sample. ``ResidualTare``
averages the residual over the first ``duration`` seconds of the run but the first ``skip``
(while the residual converges from zero, with time constant 1/K), while the robot stands
untouched; it outputs zero over that time (the admittance holds the posture) and the
residual minus that mean afterwards.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from systems.common.checks import eval_finite_input, positive_number

_WHO = "ResidualTare"


class ResidualTare(LeafSystem):
    """Removes the residual's offset at rest, measured over the run's first ``duration`` s.

    Input:
        residual: the residual, ``size`` entries (any unit; N m for joint residuals).

    Outputs:
        tared_residual: zero while t < ``duration``, then ``residual - offset`` (direct
            feedthrough of the input; with ``duration = 0`` the input unchanged).
        offset: the mean of the residual over the samples at t_k = k ``period`` with
            ``skip`` <= t_k < ``duration`` (zero until the first sample).

    Discrete state: the running sum of the residual (``size``) and the number of samples (1),
    updated at every t_k < ``duration`` from ``skip`` on (periodic event, first at t = 0).
    """

    def __init__(self, size: int, duration: float, period: float = 1e-3, *, skip: float = 0.0):
        """Args:
        size: the residual's number of entries, >= 1.
        duration: s, >= 0: the time at the run's start over which the robot stands
            untouched and the offset is averaged; 0 turns the tare off.
        period: s, > 0: the sampling period of the average (the residual's).
        skip: s, >= 0: the samples before it are not averaged (the residual's convergence
            from its zero initial value: a momentum residual reaches e^-5 of its offset at
            5/K; the base-state estimate's, for a residual that reads it).

        Raises:
            ValueError: a size below 1, a negative or non-finite duration or skip, a
                non-positive period, or a window [skip, duration) shorter than one period
                (no sample to average).
        """
        super().__init__()
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"{_WHO}: size must be a positive integer, got {size!r}")
        self._size = int(size)
        self._duration = positive_number(duration, f"{_WHO}: duration", allow_zero=True)
        self._period = positive_number(period, f"{_WHO}: period")
        self._skip = positive_number(skip, f"{_WHO}: skip", allow_zero=True)
        if self._duration > 0.0 and self._duration - self._skip < self._period:
            raise ValueError(
                f"{_WHO}: the window from skip {self._skip} s to duration {self._duration} s is shorter than "
                f"one period ({self._period} s): no sample to average"
            )
        self._residual_port = self.DeclareVectorInputPort("residual", self._size)
        self._state_index = self.DeclareDiscreteState(BasicVector(np.zeros(self._size + 1)))
        if self._duration > 0.0:
            self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Accumulate)
        self.DeclareVectorOutputPort("tared_residual", self._size, self._CalcTaredResidual)
        self.DeclareVectorOutputPort("offset", self._size, self._CalcOffset, prerequisites_of_calc={self.xd_ticket()})

    @property
    def duration(self) -> float:
        return self._duration

    @property
    def period(self) -> float:
        return self._period

    @property
    def skip(self) -> float:
        return self._skip

    def Offset(self, context: Context) -> np.ndarray:
        """The mean residual over the samples taken so far (zero before the first)."""
        state = context.get_discrete_state(self._state_index).get_value()
        count = state[-1]
        return state[:-1] / count if count > 0 else np.zeros(self._size)

    def _Accumulate(self, context: Context, discrete_state: DiscreteValues) -> None:
        if not (self._skip <= context.get_time() < self._duration):
            return
        residual = eval_finite_input(_WHO, self._residual_port, context)
        state = context.get_discrete_state(self._state_index).get_value().copy()
        state[:-1] += residual
        state[-1] += 1.0
        discrete_state.set_value(self._state_index, state)

    def _CalcTaredResidual(self, context: Context, output: BasicVector) -> None:
        if self._duration == 0.0:
            output.SetFromVector(eval_finite_input(_WHO, self._residual_port, context))
        elif context.get_time() < self._duration:
            output.SetFromVector(np.zeros(self._size))
        else:
            output.SetFromVector(eval_finite_input(_WHO, self._residual_port, context) - self.Offset(context))

    def _CalcOffset(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.Offset(context))


__all__ = ["ResidualTare"]
