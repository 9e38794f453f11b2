"""``UpdateRecorder``: records its vector inputs at each of its periodic updates, as a
fixed-rate estimator sampling them reads them there, for estimators that run on the record
afterwards (``systems.residuals.offline``).

Why not Drake's ``VectorLogSink``: a logger publishes, and Drake handles a publish at time t
at the end of the step that reaches t, before that time's discrete updates; when a
simulation stops at t (``AdvanceTo``) and its state is changed before it goes on (a trial
restored to a saved start), the updates at t run on the changed state, and a publish-time
record cannot say which state an update read. A discrete update event runs exactly when
(and on the same state as) the estimators' own updates would.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem

from systems.common.checks import eval_finite_input


class UpdateRecorder(LeafSystem):
    """Records named vector inputs every ``period`` s (offset 0), at the update events.

    Args:
        sizes: input port name -> size (one vector input port each).
        period: the update period, s (the estimators' period).

    The records are kept in Python (``times``, ``values``), in the order the updates ran,
    whatever happens to the context in between: each record is one update that ran. The
    one discrete state entry counts the updates since the context's start (a restored
    context counts from its saved value; the records do not).

    Raises:
        ValueError: no inputs, a non-positive size or period.
    """

    def __init__(self, sizes: Mapping[str, int], period: float):
        super().__init__()
        if not sizes:
            raise ValueError("UpdateRecorder: at least one input is needed")
        if not period > 0:
            raise ValueError(f"UpdateRecorder: period must be positive, got {period}")
        self._ports = {}
        for name, size in sizes.items():
            if int(size) < 1:
                raise ValueError(f"UpdateRecorder: input {name!r} must have a positive size, got {size}")
            self._ports[name] = self.DeclareVectorInputPort(name, int(size))
        self._count = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Update)
        self._times: list[float] = []
        self._values: dict[str, list[np.ndarray]] = {name: [] for name in sizes}

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        self._times.append(context.get_time())
        for name, port in self._ports.items():
            self._values[name].append(np.array(eval_finite_input("UpdateRecorder", port, context)))
        discrete_state.set_value(self._count, context.get_discrete_state(self._count).get_value() + 1.0)

    @property
    def times(self) -> np.ndarray:
        """(N,) the times of the updates recorded so far, s."""
        return np.array(self._times)

    @property
    def names(self) -> tuple[str, ...]:
        """The recorded inputs' names."""
        return tuple(self._values)

    def values(self, name: str) -> np.ndarray:
        """(N, size) input ``name`` at each recorded update."""
        if name not in self._values:
            raise KeyError(f"UpdateRecorder has no input {name!r}; it has {sorted(self._values)}")
        records = self._values[name]
        return np.array(records) if records else np.zeros((0, self._ports[name].size()))

    def clear(self) -> None:
        """Forgets the records."""
        self._times.clear()
        for records in self._values.values():
            records.clear()
