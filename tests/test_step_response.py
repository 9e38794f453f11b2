"""systems.observer.step_response against closed forms: an underdamped second-order step
response, whose overshoot is exp(-pi zeta / sqrt(1 - zeta^2)) and whose settling time into
a band is found by bisection on its envelope-free exact formula; and the load times of the
real recordings from their ZMP."""

import math

import numpy as np
import pytest

from systems.observer.nao_dataset import RECORDINGS, load_recording, published_dataset_dir
from systems.observer.step_response import load_steps_from_zmp, step_responses, summary


def _second_order(t, zeta, omega):
    """Unit step response of omega^2 / (s^2 + 2 zeta omega s + omega^2), t >= 0."""
    wd = omega * math.sqrt(1 - zeta**2)
    phase = math.acos(zeta)
    y = 1 - np.exp(-zeta * omega * t) / math.sqrt(1 - zeta**2) * np.sin(wd * t + phase)
    return np.where(t >= 0, y, 0.0)


def test_overshoot_and_settling_of_a_second_order_response():
    zeta, omega, size, t_step = 0.4, 3.0, -11.0, 2.0
    t = np.arange(0.0, 12.0, 1e-3)
    y = 0.5 + size * _second_order(t - t_step, zeta, omega)  # a step from 0.5 N to -10.5 N
    estimate = np.column_stack([y, np.zeros_like(t), 0.2 * y])  # z changes by 2.2 N, y not at all
    (x, z) = step_responses(t, estimate, [t_step], [12.0])
    assert (x.component, z.component) == ("x", "z")
    expected = 100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))  # 25.4 %
    assert x.overshoot_percent == pytest.approx(expected, abs=0.01)
    assert z.overshoot_percent == pytest.approx(expected, abs=0.01)
    # The last second still rings (1e-4 N).
    assert x.before_N == pytest.approx(0.5) and x.after_N == pytest.approx(-10.5, abs=1e-3)
    # Settling into 10 %: the last time |y - 1| > 0.1, from the exact response.
    late = np.flatnonzero(np.abs(_second_order(t - t_step, zeta, omega) - 1) > 0.1)[-1]
    assert x.settling_time_s == pytest.approx(t[late + 1] - t_step, abs=2e-3)
    assert 1.0 < x.settling_time_s < 4.0 / (zeta * omega)
    assert summary([x, z])["mean_overshoot_percent"] == pytest.approx(expected, abs=0.01)


def test_no_overshoot_never_settled_and_bad_windows():
    t = np.arange(0.0, 10.0, 0.01)
    ramp = np.clip(t - 2.0, 0.0, 3.0)[:, None]  # a ramp of 3 N: no overshoot
    (response,) = step_responses(t, ramp, [2.0], [10.0], components=("x",))
    assert response.overshoot_percent == 0.0 and response.settling_time_s == pytest.approx(2.7, abs=0.011)
    ringing = (2.0 + np.where(t > 2.0, np.sin(5 * t), -2.0))[:, None]  # never within 10 %
    (response,) = step_responses(t, ringing, [2.0], [10.0], components=("x",))
    assert math.isnan(response.settling_time_s) and response.as_dict()["settling_time_s"] is None
    assert step_responses(t, 0.3 * ramp, [2.0], [10.0], components=("x",)) == []  # 0.9 N < MIN_STEP
    with pytest.raises(ValueError, match="needs"):
        step_responses(t, ramp, [0.5], [10.0], components=("x",))
    with pytest.raises(ValueError, match="columns"):
        step_responses(t, ramp, [2.0], [10.0])


def test_load_times_of_the_real_recordings_from_their_zmp():
    """Force_Y_data: the load acts from ~8.5 s to ~17.6 s (the authors' estimate passes half
    its loaded level within a second of these times); Force_Z_data: ~2.5 s to ~17.9 s."""
    for name, (on, off) in zip(RECORDINGS, [(8.5, 17.6), (2.4, 17.9)], strict=True):
        zmp = load_recording(published_dataset_dir() / name)["ZMP"]
        t = np.arange(len(zmp)) / 60.0
        starts, ends = load_steps_from_zmp(t, zmp)
        assert starts == pytest.approx([on, off], abs=0.15), name
        assert ends == pytest.approx([starts[1] - 0.5, t[-1]])
    with pytest.raises(ValueError, match="no load"):
        load_steps_from_zmp(t, np.zeros_like(zmp))
