"""UpdateRecorder: records what a periodic update reads, when it runs, across a context
restore (where a publishing logger records the restored state at the boundary)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from systems.io.update_recorder import UpdateRecorder


class _Counter(LeafSystem):
    """Counts its own updates (period 1 ms); output: the count."""

    def __init__(self):
        super().__init__()
        index = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(1e-3, 0.0, self._update)
        self.DeclareStateOutputPort("count", index)

    def _update(self, context, discrete_state):
        discrete_state.set_value(0, context.get_discrete_state(0).get_value() + 1.0)


def _counter_diagram():
    builder = DiagramBuilder()
    counter = builder.AddSystem(_Counter())
    recorder = builder.AddSystem(UpdateRecorder({"count": 1}, 1e-3))
    builder.Connect(counter.get_output_port(), recorder.GetInputPort("count"))
    return builder.Build(), recorder


def test_records_what_each_update_reads_across_a_restore():
    """Each record is the counter's value at an update (the updates that ran before it),
    with that update's time; after the context is restored to a saved one the records go
    on with the restored value (what the next update reads), none lost or duplicated."""
    diagram, recorder = _counter_diagram()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    simulator.Initialize()
    simulator.AdvanceTo(0.003)  # updates at 0, 1, 2 ms
    saved = context.Clone()
    simulator.AdvanceTo(0.0055)  # updates at 3, 4, 5 ms
    context.SetStateAndParametersFrom(saved)  # the count back to 3; the time stays
    simulator.AdvanceTo(0.008)  # updates at 6, 7 ms
    np.testing.assert_allclose(recorder.times, [0.0, 0.001, 0.002, 0.003, 0.004, 0.005, 0.006, 0.007], atol=1e-12)
    np.testing.assert_array_equal(recorder.values("count")[:, 0], [0, 1, 2, 3, 4, 5, 3, 4])
    recorder.clear()
    assert recorder.times.size == 0 and recorder.values("count").shape == (0, 1)
    with pytest.raises(KeyError, match="no input 'other'"):
        recorder.values("other")


def test_nan_input_and_bad_arguments_are_named():
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource([1.0, np.nan]))
    recorder = builder.AddSystem(UpdateRecorder({"wrenches": 2}, 1e-3))
    builder.Connect(source.get_output_port(), recorder.GetInputPort("wrenches"))
    simulator = Simulator(builder.Build())
    with pytest.raises(ValueError, match="UpdateRecorder.*wrenches"):
        simulator.AdvanceTo(0.002)
    with pytest.raises(ValueError, match="at least one input"):
        UpdateRecorder({}, 1e-3)
    with pytest.raises(ValueError, match="period must be positive"):
        UpdateRecorder({"x": 1}, 0.0)
    with pytest.raises(ValueError, match="positive size"):
        UpdateRecorder({"x": 0}, 1e-3)
