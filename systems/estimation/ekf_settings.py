"""The invariant EKF's settings for a recorded log (``diagrams.residuals.log_estimation``):
the IMU's noise densities and bias random walks, the contact hysteresis thresholds and the
thresholds of the at-rest IMU bias initialisation, and the slip test's speed, with their
defaults and each default's justification (a data sheet or a measured sensor figure; none is
tuned on a log).

Set them for a robot's IMU in a YAML file (``apps.estimate_from_log --estimator-settings
FILE.yaml``), read by ``pydrake.common.yaml.yaml_load_typed`` on :class:`EkfSettings`; keys
left out keep their defaults, e.g.::

    gyro_noise_density: 3.5e-4        # rad/s/sqrt(Hz)
    contact_on_weight_fraction: 0.15

An unknown key, a value that is not a number, a negative, zero or non-finite value, or an
off threshold above the on threshold is refused naming the key (``load_ekf_settings``,
``check_ekf_settings``).
"""

# No ``from __future__ import annotations``: yaml_load_typed reads the fields' types.

import dataclasses
import math
from pathlib import Path

from systems.estimation.base_state_estimator import (
    ACCEL_BIAS_RANDOM_WALK,
    ACCEL_NOISE_DENSITY,
    CONTACT_OFF_WEIGHT_FRACTION,
    CONTACT_ON_WEIGHT_FRACTION,
    GYRO_BIAS_RANDOM_WALK,
    GYRO_NOISE_DENSITY,
    SLIP_SPEED,
)

#: The at-rest initialisation's defaults (``diagrams.residuals.log_estimation``'s
#: ``STILL_*`` constants are these): a still start shorter than 0.5 s is not used (over
#: 0.5 s the mean of the BMI088 gyro's white noise, 0.014 deg/s/sqrt(Hz), has a standard
#: error of 0.02 deg/s, 6 % of a 0.35 deg/s bias), s.
STILL_MIN_DURATION = 0.5
#: The largest gyro bias per axis a still robot's gyro reads: the BMI088's zero-rate
#: offset, +-1 deg/s (data sheet BST-BMI088-DS001), rad/s.
STILL_GYRO_OFFSET = math.radians(1.0)
#: A joint speed beyond this is motion, rad/s (m/s): 6 times the per-sample std (0.02 rad/s)
#: of a 17-bit encoder's position (step 2 pi / 2**17 rad, quantisation std step / sqrt(12))
#: differenced over 1 ms.
STILL_JOINT_SPEED = 0.12


@dataclasses.dataclass
class EkfSettings:
    """The invariant EKF's settings on a log. SI units; every value finite and > 0.

    Attributes:
        gyro_noise_density: σ_g, rad/s/√Hz. Default 2.44e-4 (0.014 °/s/√Hz): the Bosch
            BMI088's output noise density (data sheet BST-BMI088-DS001).
        accel_noise_density: σ_a, m/s²/√Hz. Default 1.72e-3 (175 µg/√Hz): the BMI088's.
        gyro_bias_random_walk: σ_bg, rad/s²/√Hz. Default 1.9393e-5: the ADIS16448's of the
            EuRoC MAV dataset's sensor.yaml (Burri et al., IJRR 2016, identified with
            Kalibr from the sensor's Allan deviation).
        accel_bias_random_walk: σ_ba, m/s³/√Hz. Default 3.0e-3: the same source's.
        contact_on_weight_fraction: a foot comes into contact above this fraction of the
            robot's weight m g. Default 0.10 (``CONTACT_ON_WEIGHT_FRACTION``: 5 % above the
            off threshold, wider than a force's noise, ~0.2 N on a Nao's FSR sum).
        contact_off_weight_fraction: and leaves it below this fraction. Default 0.05
            (``CONTACT_OFF_WEIGHT_FRACTION``: a foot carrying less slides or rocks on its edge
            and cannot anchor the filter; the station's, online). At most
            the on fraction.
        still_min_duration: s, the shortest still start the at-rest IMU bias is measured
            on (``STILL_MIN_DURATION``, 0.5 s).
        still_gyro_offset: rad/s, the largest gyro bias per axis the stillness test allows
            for (``STILL_GYRO_OFFSET``, the BMI088's ±1 °/s zero-rate offset).
        still_joint_speed: rad/s (m/s), a joint speed beyond it is motion
            (``STILL_JOINT_SPEED``, 0.12: 6 sigma of a 17-bit encoder differenced at 1 kHz).
        slip_speed: m/s, a foot flagged in contact whose kinematic world velocity (E13 of
            ``base_state_estimator``: from the filter's predicted state and the encoders,
            low-passed over 20 ms) exceeds it slips or rolls: its kinematic correction is
            dropped until it stops, then it is re-anchored. Default 0.1 (``SLIP_SPEED``),
            above every stance foot's speed measured in the simulated realistic world (no
            slip there; the filter's and the sensors' noise): at 1 kHz, nao_like walking 12 s
            with the realistic IMU at most 26 mm/s (99.9th percentile 25), 24 mm/s with
            14-bit encoders, hrp4_like standing 4 mm/s (22 mm/s with 14-bit encoders); the
            99 Hz jittery walking log of ``diagrams.locomotion.walking_log`` through this
            pipeline at most 43 mm/s in mid-stance and 63 mm/s at a touch-down (seeds 0 and 1,
            99.9th percentiles 43-48 mm/s). A third of a 0.3 m/s slide, which it drops after
            ~8 ms at 1 kHz (tests/test_base_state_estimator.py).
    """

    gyro_noise_density: float = GYRO_NOISE_DENSITY
    accel_noise_density: float = ACCEL_NOISE_DENSITY
    gyro_bias_random_walk: float = GYRO_BIAS_RANDOM_WALK
    accel_bias_random_walk: float = ACCEL_BIAS_RANDOM_WALK
    contact_on_weight_fraction: float = CONTACT_ON_WEIGHT_FRACTION
    contact_off_weight_fraction: float = CONTACT_OFF_WEIGHT_FRACTION
    still_min_duration: float = STILL_MIN_DURATION
    still_gyro_offset: float = STILL_GYRO_OFFSET
    still_joint_speed: float = STILL_JOINT_SPEED
    slip_speed: float = SLIP_SPEED


def check_ekf_settings(settings: EkfSettings, where: str = "EKF settings") -> EkfSettings:
    """``settings`` when every value is a finite number > 0 and the contact off fraction is
    at most the on fraction.

    Raises:
        ValueError: naming ``where`` and the first bad key.
    """
    for item in dataclasses.fields(EkfSettings):
        value = getattr(settings, item.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ValueError(f"{where}: {item.name} must be a finite number > 0, got {value!r}")
    if settings.contact_off_weight_fraction > settings.contact_on_weight_fraction:
        raise ValueError(
            f"{where}: contact_off_weight_fraction {settings.contact_off_weight_fraction} is above "
            f"contact_on_weight_fraction {settings.contact_on_weight_fraction}"
        )
    return settings


def load_ekf_settings(path: str | Path | None = None, **overrides: float | None) -> EkfSettings:
    """The ``EkfSettings`` of the YAML file ``path`` (keys left out keep their defaults; None:
    all defaults), then ``overrides`` (key: value; None values ignored: a command-line
    option not given), checked (``check_ekf_settings``).

    Raises:
        ValueError: an unreadable file or a YAML that is not a mapping of known keys to
            numbers (the file and the key named), an unknown override, a bad value.
    """
    from pydrake.common.yaml import yaml_load_file, yaml_load_typed

    settings = EkfSettings()
    where = "EKF settings"
    if path is not None:
        where = f"the EKF settings file '{path}'"
        try:
            loaded = yaml_load_file(str(path))
        except Exception as error:  # Drake raises RuntimeError with the YAML parser's message
            raise ValueError(f"cannot read {where}: {error}") from None
        if loaded is None:
            loaded = {}
        if not isinstance(loaded, dict):
            raise ValueError(f"{where} must hold a mapping of setting: value")
        names = [f.name for f in dataclasses.fields(EkfSettings)]
        unknown = sorted(str(key) for key in loaded if key not in names)
        if unknown:
            raise ValueError(f"{where}: unknown keys {unknown}; the keys are {names}")
        for key, value in loaded.items():
            number = not isinstance(value, (bool, list, dict)) and value is not None
            if isinstance(value, str):
                try:
                    float(value)
                except ValueError:
                    number = False
            if not number:
                raise ValueError(f"{where}: {key} must be a number, got {value!r}")
        try:
            settings = yaml_load_typed(schema=EkfSettings, filename=str(path), defaults=settings)
        except Exception as error:  # a value that is not a number: Drake names the key
            raise ValueError(f"{where}: {error}") from None
    names = {f.name for f in dataclasses.fields(EkfSettings)}
    for key, value in overrides.items():
        if key not in names:
            raise ValueError(f"unknown EKF setting {key!r}; the keys are {sorted(names)}")
        if value is not None:
            settings = dataclasses.replace(settings, **{key: float(value)})
    return check_ekf_settings(settings, where)


__all__ = [
    "EkfSettings",
    "STILL_GYRO_OFFSET",
    "STILL_JOINT_SPEED",
    "STILL_MIN_DURATION",
    "check_ekf_settings",
    "load_ekf_settings",
]
