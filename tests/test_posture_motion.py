"""SinusoidalPostureMotion (systems.locomotion.posture_motion) and the slow whole-body motion
built from a station's joint groups (diagrams.station.motions)."""

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder

from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from diagrams.station.motions import SlowMotion, slow_whole_body_motion
from systems.locomotion.posture_motion import SinusoidalPostureMotion


def _output(system, t):
    context = system.CreateDefaultContext()
    context.SetTime(t)
    return system.get_output_port().Eval(context)


def test_sum_of_sinusoids_with_a_smooth_fade_in():
    center = np.array([0.1, -0.2])
    directions = np.array([[1.0, 0.0], [1.0, -2.0]])
    motion = SinusoidalPostureMotion(center, directions, [0.3, 0.1], [0.5, 0.2], [0.4, 1.0], ramp_time=1.0)
    np.testing.assert_allclose(_output(motion, 0.0), center)
    t = 3.7  # after the ramp: the plain sum
    expected = center + 0.3 * np.sin(2 * np.pi * 0.5 * t + 0.4) * directions[0]
    expected += 0.1 * np.sin(2 * np.pi * 0.2 * t + 1.0) * directions[1]
    np.testing.assert_allclose(_output(motion, t), expected, rtol=1e-12)
    # Velocity continuous at t = 0 (the ramp's zero slope): a finite difference of ~0.
    assert np.all(np.abs(_output(motion, 1e-4) - center) < 1e-8)
    np.testing.assert_allclose(motion.peak_joint_excursion, [0.4, 0.2])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(directions=np.ones((1, 3))), "directions"),
        (dict(amplitudes=[0.1, 0.2]), "amplitudes"),
        (dict(frequencies=[-1.0]), "frequencies"),
        (dict(phases=[np.nan]), "finite"),
        (dict(ramp_time=0.0), "ramp_time"),
        (dict(upper=[0.05, 1.0]), "upper joint limits"),
    ],
)
def test_bad_motions_are_refused(kwargs, message):
    args = dict(
        center=np.zeros(2), directions=np.array([[1.0, 0.0]]), amplitudes=[0.1], frequencies=[0.2], phases=[0.0]
    )
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        SinusoidalPostureMotion(**args)


@pytest.fixture(scope="module")
def station():
    return add_humanoid_station(DiagramBuilder(), StationConfig(model="hrp4_like", noise=False))


def test_slow_motion_stays_inside_the_limits_and_keeps_the_soles_flat(station):
    motion = slow_whole_body_motion(station, SlowMotion(seed=5))
    lower = np.array([j.position_lower_limits()[0] for j in station.topology.joints])
    upper = np.array([j.position_upper_limits()[0] for j in station.topology.joints])
    excursion = motion.peak_joint_excursion
    assert np.all(station.q_hold - excursion >= lower - 1e-12)
    assert np.all(station.q_hold + excursion <= upper + 1e-12)
    names = station.joint_names
    # The hand joints rest on a limit and the synergies leave the hip yaw alone: they do not
    # move. Every other joint does.
    for name, value in zip(names, excursion):
        assert (value == 0.0) == ("HAND" in name or "HIP_Y" in name), name
    # The leg synergies keep each sole's orientation relative to the pelvis (hip, knee and
    # ankle pitch sum to zero; hip and ankle roll cancel), so both soles stay flat.
    plant = station.plant
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, station.initial_state)
    base = station.humanoid.base_body.body_frame()
    soles = station.humanoid.sole_frames
    nominal = {side: frame.CalcPose(context, base).rotation() for side, frame in soles.items()}
    for t in (1.3, 7.1, 20.4):
        q = plant.GetPositions(context)
        for joint, value in zip(station.topology.joints, _output(motion, t)):
            q[joint.position_start()] = value
        plant.SetPositions(context, q)
        for side, frame in soles.items():
            R = frame.CalcPose(context, base).rotation()
            np.testing.assert_allclose(R.matrix(), nominal[side].matrix(), atol=1e-9, err_msg=f"{side} at {t} s")


def test_the_seed_changes_the_motion_and_zero_scale_stands_still(station):
    a = _output(slow_whole_body_motion(station, SlowMotion(seed=1)), 9.0)
    b = _output(slow_whole_body_motion(station, SlowMotion(seed=2)), 9.0)
    assert np.max(np.abs(a - b)) > 0.05
    still = slow_whole_body_motion(station, SlowMotion(amplitude_scale=0.0))
    np.testing.assert_array_equal(_output(still, 9.0), station.q_hold)
    with pytest.raises(ValueError, match="amplitude_scale"):
        slow_whole_body_motion(station, SlowMotion(amplitude_scale=-1.0))


def test_min_peak_speed_speeds_up_only_the_slow_synergies(station):
    drawn = slow_whole_body_motion(station, SlowMotion(seed=1, amplitude_scale=1.5))
    fast = slow_whole_body_motion(station, SlowMotion(seed=1, amplitude_scale=1.5, min_peak_speed=0.4))
    directions, amplitudes, drawn_frequencies, phases = drawn.synergies
    fast_directions, fast_amplitudes, fast_frequencies, fast_phases = fast.synergies
    np.testing.assert_array_equal(fast_directions, directions)
    np.testing.assert_array_equal(fast_amplitudes, amplitudes)
    np.testing.assert_array_equal(fast_phases, phases)
    reach = np.abs(directions).max(axis=1) * amplitudes
    peak = 2.0 * np.pi * fast_frequencies * reach  # each synergy's fastest joint, rad/s
    # Every synergy reaches 0.4 rad/s unless the band's top (0.25 Hz) stops it first; the
    # synergies already faster keep their drawn frequency.
    at_top = np.isclose(fast_frequencies, 0.25)
    assert np.all((peak >= 0.4 - 1e-12) | at_top)
    np.testing.assert_array_equal(fast_frequencies >= drawn_frequencies, True)
    kept = 2.0 * np.pi * drawn_frequencies * reach >= 0.4
    assert kept.any() and (~kept).any()
    np.testing.assert_array_equal(fast_frequencies[kept], drawn_frequencies[kept])
    # The default calibration's right elbow: 0.24 rad (its joint limit) at a drawn 0.062 Hz
    # peaks at 0.093 rad/s, at 0.25 Hz at 0.377 rad/s.
    elbow = station.joint_names.index("R_ELBOW_P")
    k = int(np.flatnonzero(directions[:, elbow])[0])
    assert 2.0 * np.pi * drawn_frequencies[k] * reach[k] < 0.1
    assert 2.0 * np.pi * fast_frequencies[k] * reach[k] > 0.35
    with pytest.raises(ValueError, match="min_peak_speed"):
        slow_whole_body_motion(station, SlowMotion(min_peak_speed=-0.1))
