"""Slow whole-body motions of a standing humanoid, feet flat: the calibration motion of the
model refinement and the "slow motion" run of the contact study (without contact, the
residuals must stay quiet).

The motion is ``systems.locomotion.posture_motion.SinusoidalPostureMotion`` about the
station's posture: two leg synergies that keep both soles flat and the pelvis level (a
squat: hip, knee and ankle pitch in the ratio -1 : 2 : -1; a lateral sway: hip and ankle
roll in the ratio 1 : -1 on both legs) and one sinusoid per torso, head and arm joint.
Frequencies and phases are drawn from ``SlowMotion.seed``; amplitudes are scaled by
``amplitude_scale`` and capped at 80 % of the distance to the nearest joint limit (a joint
resting on a limit, such as the hand joints of ``hrp4_like``, does not move). With
``SlowMotion.min_peak_speed`` a synergy too slow for it (a small or limit-capped amplitude
at a low drawn frequency) is sped up: a calibration motion must move every joint fast
enough to tell its Coulomb from its viscous friction.
"""

# No ``from __future__ import annotations``: yaml_load_typed reads SlowMotion's field types.

from dataclasses import dataclass

import numpy as np

from diagrams.station.humanoid_station import HumanoidStation
from systems.locomotion.posture_motion import SinusoidalPostureMotion

#: Peak amplitude per joint group at amplitude_scale 1, rad.
GROUP_AMPLITUDES = {"torso": 0.2, "head": 0.4, "arms": 0.5}
#: Leg synergies at amplitude_scale 1: squat (knee amplitude 2x this), lateral sway, rad.
SQUAT_AMPLITUDE, SWAY_AMPLITUDE = 0.12, 0.05
#: The fraction of the distance to the nearest joint limit the motion may use.
LIMIT_FRACTION = 0.8


@dataclass
class SlowMotion:
    """A slow whole-body motion (see the module docstring). SI units.

    Attributes:
        seed: draws the synergies' frequencies and phases (non-negative integer).
        amplitude_scale: scales every amplitude (0 = stand still).
        min_frequency, max_frequency: each synergy's frequency is uniform in this band, Hz.
        ramp_time: the motion fades in over this time, s.
        min_peak_speed: rad/s (>= 0): each synergy's frequency is raised, if needed and
            within ``max_frequency``, until its fastest joint's peak speed 2 pi f a |d_j|
            reaches this value (the drawn frequencies and phases are kept otherwise; 0:
            the drawn frequencies). For a calibration: below a few times the friction
            model's smoothing velocity v_s, F_c tanh(qdot / v_s) + b qdot ~ (F_c / v_s + b)
            qdot and the log cannot split Coulomb from viscous friction, so a joint whose
            drawn motion is slow (the right elbow of the default calibration: 0.24 rad
            capped by its joint limit at 0.062 Hz, 0.093 rad/s) gets a split that errs at
            the faster motions of the experiments.
    """

    seed: int = 0
    amplitude_scale: float = 1.0
    min_frequency: float = 0.05
    max_frequency: float = 0.25
    ramp_time: float = 2.0
    min_peak_speed: float = 0.0

    def validate(self) -> "SlowMotion":
        if int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"motion.seed must be a non-negative integer, got {self.seed!r}")
        if not (np.isfinite(self.amplitude_scale) and self.amplitude_scale >= 0.0):
            raise ValueError(f"motion.amplitude_scale must be >= 0, got {self.amplitude_scale}")
        if not (0.0 <= self.min_frequency <= self.max_frequency and np.isfinite(self.max_frequency)):
            raise ValueError(
                f"motion: need 0 <= min_frequency <= max_frequency, got {self.min_frequency}, {self.max_frequency}"
            )
        if not (np.isfinite(self.ramp_time) and self.ramp_time > 0.0):
            raise ValueError(f"motion.ramp_time must be positive, got {self.ramp_time}")
        if not (np.isfinite(self.min_peak_speed) and self.min_peak_speed >= 0.0):
            raise ValueError(f"motion.min_peak_speed must be >= 0 rad/s, got {self.min_peak_speed}")
        return self


def slow_whole_body_motion(station: HumanoidStation, motion: SlowMotion) -> SinusoidalPostureMotion:
    """The ``SinusoidalPostureMotion`` of ``motion`` about ``station.q_hold`` (not added to a
    builder). Needs a humanoid station (its joint groups).

    Raises:
        ValueError: a station without a humanoid, bad ``motion`` fields.
    """
    motion.validate()
    if station.humanoid is None:
        raise ValueError("slow_whole_body_motion needs a humanoid station (hrp4_like, nao_like)")
    names = station.joint_names
    index = {name: i for i, name in enumerate(names)}
    n = len(names)
    center = np.asarray(station.q_hold, dtype=float)
    lower = np.array([j.position_lower_limits()[0] for j in station.topology.joints])
    upper = np.array([j.position_upper_limits()[0] for j in station.topology.joints])
    room = LIMIT_FRACTION * np.minimum(center - lower, upper - center)  # per joint, rad (inf: no limit)
    room = np.maximum(room, 0.0)
    groups = station.humanoid.joint_groups
    scale = float(motion.amplitude_scale)

    directions, amplitudes = [], []

    def add(direction: np.ndarray, amplitude: float) -> None:
        moving = direction != 0.0
        if not moving.any():
            return
        # The largest amplitude whose excursion |d_j| a stays within each joint's room.
        cap = float(np.min(room[moving] / np.abs(direction[moving])))
        a = min(amplitude, cap)
        if a > 0.0:
            directions.append(direction)
            amplitudes.append(a)

    # Leg synergies (both legs' joint order: hip yaw, hip roll, hip pitch, knee, ankle pitch, ankle roll).
    squat, sway = np.zeros(n), np.zeros(n)
    for side in ("left_leg", "right_leg"):
        leg = [index[name] for name in groups.get(side, ())]
        if len(leg) == 6:
            squat[[leg[2], leg[3], leg[4]]] = (-1.0, 2.0, -1.0)
            sway[[leg[1], leg[5]]] = (1.0, -1.0)
    add(squat, SQUAT_AMPLITUDE * scale)
    add(sway, SWAY_AMPLITUDE * scale)
    for group, amplitude in GROUP_AMPLITUDES.items():
        for name in groups.get(group, ()):
            direction = np.zeros(n)
            direction[index[name]] = 1.0
            add(direction, amplitude * scale)

    rng = np.random.default_rng([int(motion.seed), 11])
    k = len(directions)
    frequencies = rng.uniform(motion.min_frequency, motion.max_frequency, k)
    phases = rng.uniform(0.0, 2.0 * np.pi, k)
    if k and motion.min_peak_speed > 0.0:
        reach = np.array([a * np.max(np.abs(d)) for d, a in zip(directions, amplitudes)])  # rad
        moving = reach > 0.0  # a synergy of zero amplitude keeps its frequency
        needed = motion.min_peak_speed / (2.0 * np.pi * reach[moving])  # Hz
        frequencies[moving] = np.maximum(frequencies[moving], np.minimum(needed, motion.max_frequency))
    if k == 0:  # standing still: one synergy of zero amplitude keeps the system's shape
        directions, amplitudes, frequencies, phases = [np.zeros(n)], [0.0], [0.0], [0.0]
    return SinusoidalPostureMotion(
        center,
        np.array(directions),
        np.array(amplitudes),
        np.asarray(frequencies),
        np.asarray(phases),
        ramp_time=motion.ramp_time,
        lower=lower,
        upper=upper,
    )
