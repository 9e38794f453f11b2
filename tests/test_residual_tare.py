"""ResidualTare: the residual's offset at rest is the mean of the samples in the tare window,
and it is removed afterwards."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from systems.residuals.tare import ResidualTare


def _simulator(tare: ResidualTare, value):
    context = tare.CreateDefaultContext()
    port = tare.GetInputPort("residual").FixValue(context, np.asarray(value, float))
    simulator = Simulator(tare, context)
    simulator.Initialize()
    return simulator, port


def test_offset_is_the_mean_of_the_samples_in_the_window_and_is_removed_afterwards():
    a, b, push = np.array([1.0, -2.0, 0.5]), np.array([3.0, 0.0, 0.5]), np.array([0.25, 4.0, -1.0])
    tare = ResidualTare(3, duration=1.0, period=1e-3)
    simulator, port = _simulator(tare, a)
    context = simulator.get_context()
    simulator.AdvanceTo(0.5)  # samples at 0, 1, ..., 499 ms read a
    # While the tare runs the admittance sees nothing: the robot stands still.
    np.testing.assert_array_equal(tare.GetOutputPort("tared_residual").Eval(context), np.zeros(3))
    np.testing.assert_allclose(tare.GetOutputPort("offset").Eval(context), a, rtol=0, atol=1e-12)
    port.GetMutableData().set_value(b)  # samples at 500, ..., 999 ms read b
    simulator.AdvanceTo(1.2)
    offset = tare.GetOutputPort("offset").Eval(context)
    np.testing.assert_allclose(offset, 0.5 * (a + b), rtol=0, atol=1e-12)
    # After the window: the residual minus its offset at rest, and the offset no longer moves.
    port.GetMutableData().set_value(0.5 * (a + b) + push)
    np.testing.assert_allclose(tare.GetOutputPort("tared_residual").Eval(context), push, rtol=0, atol=1e-12)
    simulator.AdvanceTo(3.0)
    np.testing.assert_allclose(tare.GetOutputPort("offset").Eval(context), offset, rtol=0, atol=0)
    np.testing.assert_allclose(tare.GetOutputPort("tared_residual").Eval(context), push, rtol=0, atol=1e-12)


def test_samples_before_skip_are_not_averaged():
    """The residual's convergence from zero is left out: only samples from ``skip`` on count."""
    transient, settled = np.array([0.0, 0.0]), np.array([2.0, -3.0])
    tare = ResidualTare(2, duration=1.0, period=1e-3, skip=0.4)
    simulator, port = _simulator(tare, transient)
    simulator.AdvanceTo(0.4)  # samples at 0, ..., 399 ms: skipped
    port.GetMutableData().set_value(settled)
    simulator.AdvanceTo(1.5)
    np.testing.assert_allclose(tare.GetOutputPort("offset").Eval(simulator.get_context()), settled, rtol=0, atol=1e-12)


def test_a_noisy_offset_is_estimated_to_its_standard_error():
    """Control against the statistics of the mean: a constant offset plus white noise,
    sampled 2000 times, is found to within 4 standard errors."""
    rng = np.random.default_rng(3)
    offset, sigma = np.array([0.8, -1.4]), 0.3
    tare = ResidualTare(2, duration=2.0, period=1e-3)
    simulator, port = _simulator(tare, offset)
    context = simulator.get_context()
    for k in range(2000):
        port.GetMutableData().set_value(offset + sigma * rng.standard_normal(2))
        simulator.AdvanceTo((k + 1) * 1e-3)
    simulator.AdvanceTo(2.5)
    error = tare.GetOutputPort("offset").Eval(context) - offset
    assert np.all(np.abs(error) < 4 * sigma / np.sqrt(2000))
    assert np.any(np.abs(error) > 0)  # it is a mean of noisy samples, not the true value


def test_zero_duration_passes_the_residual_through():
    tare = ResidualTare(2, duration=0.0)
    simulator, _ = _simulator(tare, [1.5, -0.5])
    simulator.AdvanceTo(0.3)
    np.testing.assert_array_equal(tare.GetOutputPort("tared_residual").Eval(simulator.get_context()), [1.5, -0.5])
    np.testing.assert_array_equal(tare.GetOutputPort("offset").Eval(simulator.get_context()), [0.0, 0.0])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"size": 0, "duration": 1.0}, "size must be a positive integer"),
        ({"size": 2.5, "duration": 1.0}, "size must be a positive integer"),
        ({"size": 3, "duration": -1.0}, "duration must be non-negative"),
        ({"size": 3, "duration": float("nan")}, "duration must be non-negative"),
        ({"size": 3, "duration": 1.0, "period": 0.0}, "period must be positive"),
        ({"size": 3, "duration": 1e-4, "period": 1e-3}, "shorter than one period"),
        ({"size": 3, "duration": 1.0, "skip": 1.0}, "shorter than one period"),
        ({"size": 3, "duration": 1.0, "skip": -0.1}, "skip must be non-negative"),
    ],
)
def test_bad_parameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ResidualTare(**kwargs)


def test_nan_in_the_residual_is_refused_with_the_port_named():
    tare = ResidualTare(2, duration=1.0)
    simulator, port = _simulator(tare, [0.0, 0.0])
    port.GetMutableData().set_value(np.array([0.0, np.nan]))
    with pytest.raises(Exception, match="ResidualTare.*residual"):
        simulator.AdvanceTo(0.01)
