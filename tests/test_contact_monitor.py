"""FirstUnexpectedContact (systems/simulation/contact_monitor.py): its ports, its state before
any contact, and its refusals. Contacts themselves: tests/test_standing.py (a collapsing
robot) and tests/test_romeo.py (ankle boxes in the ground at 0 s)."""

import numpy as np
import pytest
from pydrake.geometry import GeometryId
from pydrake.multibody.plant import ContactResults

from systems.simulation.contact_monitor import FirstUnexpectedContact


def test_no_contact_leaves_it_empty_and_bad_arguments_are_refused():
    monitor = FirstUnexpectedContact({GeometryId.get_new_id(): "shin/box"}, 1e-3)
    assert monitor.labels == ("shin/box",)
    context = monitor.CreateDefaultContext()
    monitor.get_input_port().FixValue(context, ContactResults())
    context.SetDiscreteState(monitor.EvalUniquePeriodicDiscreteUpdate(context))
    value = monitor.get_output_port().Eval(context)
    np.testing.assert_array_equal(value, [-1.0, -1.0, 0.0])
    assert monitor.describe(value) is None
    described = monitor.describe(np.array([0.25, 0.0, 0.012]))
    assert described == "shin/box touched the ground first, at 0.250 s (12.0 mm deep)"
    with pytest.raises(ValueError, match="no geometry to watch"):
        FirstUnexpectedContact({}, 1e-3)
    with pytest.raises(ValueError, match="period"):
        FirstUnexpectedContact({GeometryId.get_new_id(): "a"}, 0.0)
