"""Which part of the robot touched the ground first, other than its feet: the diagnosis of a
robot that falls while standing (``apps.standing``) or starts with a shin in the ground."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import GeometryId
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from systems.common.checks import positive_number

#: The state before any watched contact: no time, no geometry, no depth.
_NONE = (-1.0, -1.0, 0.0)


class FirstUnexpectedContact(LeafSystem):
    """Records the first point contact of a watched geometry (e.g. every robot collision
    geometry but the feet's contact spheres): its time, which geometry, and its penetration
    depth then. Every ``period`` s it reads the plant's contact results; once a contact is
    recorded it is kept.

    Input:
        contact_results: the plant's ``ContactResults`` (point contact).

    Output:
        first_contact: 3, [time (s, -1 while none), index into ``labels`` (-1 while none),
            penetration depth at that time (m)].

    Args:
        watched: {GeometryId: label} of the geometries to watch (the label, e.g.
            "body/geometry", names it in ``describe``).
        period: s between checks (the plant's step).

    Raises:
        ValueError: no geometry to watch, a bad period.
    """

    def __init__(self, watched: Mapping[GeometryId, str], period: float):
        super().__init__()
        if not watched:
            raise ValueError("FirstUnexpectedContact: no geometry to watch")
        self._period = positive_number(period, "FirstUnexpectedContact: period")
        self._ids = list(watched)
        self.labels = tuple(watched[g] for g in self._ids)
        self._index = {g: k for k, g in enumerate(self._ids)}
        self._results = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self._state = self.DeclareDiscreteState(np.array(_NONE))
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
        self.DeclareVectorOutputPort("first_contact", 3, self._output, prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context: Context, discrete_state: DiscreteValues) -> None:
        if context.get_discrete_state(self._state).value()[0] >= 0.0:
            return
        results = self._results.Eval(context)
        first, depth = None, 0.0
        for c in range(results.num_point_pair_contacts()):
            pair = results.point_pair_contact_info(c).point_pair()
            for g in (pair.id_A, pair.id_B):
                k = self._index.get(g)
                if k is not None and (first is None or pair.depth > depth):
                    first, depth = k, float(pair.depth)
        if first is not None:
            discrete_state.set_value(self._state, [context.get_time(), float(first), depth])

    def _output(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(context.get_discrete_state(self._state).value())

    def describe(self, first_contact: np.ndarray) -> str | None:
        """The ``first_contact`` output in words, or None when there was none."""
        time, index, depth = (float(x) for x in first_contact)
        if time < 0.0:
            return None
        return f"{self.labels[int(index)]} touched the ground first, at {time:.3f} s ({1e3 * depth:.1f} mm deep)"


__all__ = ["FirstUnexpectedContact"]
