"""The station's settings in one place (``StationConfig``, taken by
``diagrams.station.humanoid_station.add_humanoid_station``) and the two worlds an experiment
runs in: "realistic" (the default of the hrp4_like experiments) and "ideal" (``--ideal``).

* realistic: the base pose and velocity from the contact-aided invariant EKF
  (``base_state: invariant_ekf``), ``Imperfections.realistic()`` (IMU noise and bias walks,
  14-bit encoders, unmodelled joint friction, motor-torque scale and offset errors, 5 %
  mass / 10 % CoM / 10 % inertia mismatch of the estimators' model) and the model refined
  from a calibration motion (``model_refinement: calibrate``, see
  ``diagrams.residuals.model_refinement``).
* ideal: the simulator's base state plus white noise, no imperfections, no refinement:
  the world the estimators were first measured in.

Every experiment scenario with a station nests one ``StationConfig`` as its ``station``
field (YAML: ``station: {model: ..., seed: 3}``); ``StationConfig.in_world`` sets its world.
"""

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydrake.multibody.plant import MultibodyPlantConfig

from diagrams.station.plant_config import check_plant_config, default_plant_config
from systems.estimation.ekf_settings import STILL_MIN_DURATION
from systems.simulation.imperfections import Imperfections

#: The sources of the sensed state's base pose and velocity (``StationConfig.base_state``).
BASE_STATE_SOURCES = ("truth_plus_noise", "invariant_ekf")
#: ``model_refinement`` values besides a path to a saved ``ModelCorrections`` file.
MODEL_REFINEMENTS = ("none", "calibrate")
#: The worlds of ``StationConfig.in_world``.
WORLDS = ("ideal", "realistic")


def check_model_refinement(value: str) -> str:
    """``value`` if it is one of ``MODEL_REFINEMENTS`` or an existing file, else ValueError."""
    if value in MODEL_REFINEMENTS or Path(value).is_file():
        return value
    raise ValueError(
        f"model_refinement must be one of {MODEL_REFINEMENTS} or a saved model-corrections file, got {value!r}"
    )


@dataclass(slots=True)
class StationConfig:
    """The simulated world of an experiment: the robot, Drake's plant, the sensors and their
    noise, the robot's imperfections, the sensed base state's source and the estimators'
    model refinement. SI units.

    Attributes:
        model: the robot: ``hrp4_like``, ``nao_like``, a robot description (``.yaml``,
            ``models.description``) or a floating-base SDFormat/URDF file (it floats in zero
            gravity, without sensors).
        plant_config: Drake's ``MultibodyPlantConfig`` (default ``default_plant_config()``:
            1 ms steps, point contact, SAP). Its ``time_step`` is the plant's discrete step,
            s, and its ``discrete_contact_approximation`` one of
            ``plant_config.CONTACT_APPROXIMATIONS``.
        noise, seed: the sensors' noise (defaults of ``systems.simulation.sensors``) and its
            seed (>= 0).
        noise_scale: a factor on every sensor's noise std (> 0; 1: the defaults).
        imperfections: ``systems.simulation.imperfections.Imperfections`` (default: none).
            Friction acts on the simulated plant, the sensor groups on the sensors, the
            model mismatch on the estimators' model. Sensor and model imperfections need a
            humanoid.
        base_state: the sensed base pose and velocity's source, one of
            ``BASE_STATE_SOURCES``: "truth_plus_noise" (the simulator's plus white noise) or
            "invariant_ekf" (needs foot F/T sensors or FSRs, or estimated foot contact).
        model_refinement: the estimators' model refinement before the experiment, one of
            ``MODEL_REFINEMENTS`` ("none"; "calibrate": from a calibration motion,
            ``diagrams.residuals.model_refinement.refined_model``) or a saved
            ``ModelCorrections`` file. An experiment reads it before it builds the station,
            and passes the corrections to ``add_humanoid_station``.
        at_rest_duration: s the robot stands still from its start: the invariant EKF with
            bias states measures the IMU bias over it (default ``STILL_MIN_DURATION``);
            None for a robot that moves at once.
    """

    model: str = "hrp4_like"
    plant_config: MultibodyPlantConfig = field(default_factory=default_plant_config)
    noise: bool = True
    noise_scale: float = 1.0
    seed: int = 0
    imperfections: Imperfections = field(default_factory=Imperfections)
    base_state: str = "truth_plus_noise"
    model_refinement: str = "none"
    at_rest_duration: float | None = STILL_MIN_DURATION

    @classmethod
    def realistic(cls, **fields) -> "StationConfig":
        """The realistic world's station (module docstring), then ``fields`` set."""
        return dataclasses.replace(cls().in_world("realistic"), **fields)

    def in_world(self, world: str) -> "StationConfig":
        """A copy in ``world`` (one of ``WORLDS``): its ``base_state``, ``imperfections`` and
        ``model_refinement`` set to that world's (module docstring), the rest kept.

        Raises:
            ValueError: an unknown world.
        """
        if world not in WORLDS:
            raise ValueError(f"world must be one of {WORLDS}, got {world!r}")
        if world == "ideal":
            return dataclasses.replace(
                self, base_state="truth_plus_noise", imperfections=Imperfections(), model_refinement="none"
            )
        return dataclasses.replace(
            self, base_state="invariant_ekf", imperfections=Imperfections.realistic(), model_refinement="calibrate"
        )

    @property
    def is_ideal(self) -> bool:
        """True in the ideal world: true base state plus noise, no imperfections, no refinement."""
        return self.base_state == "truth_plus_noise" and self.imperfections.is_ideal and self.model_refinement == "none"

    def check(self) -> "StationConfig":
        """Returns self when every field is valid.

        Raises:
            ValueError: a bad field, named (``station.<field>``).
        """
        if not isinstance(self.model, str) or not self.model:
            raise ValueError(f"station.model must name a robot, got {self.model!r}")
        if not isinstance(self.plant_config, MultibodyPlantConfig):
            raise ValueError(f"station.plant_config must be a MultibodyPlantConfig, got {self.plant_config!r}")
        check_plant_config(self.plant_config)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"station.seed must be a non-negative integer, got {self.seed!r}")
        scale = self.noise_scale
        if isinstance(scale, bool) or not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
            raise ValueError(f"station.noise_scale must be a positive number, got {self.noise_scale!r}")
        if not isinstance(self.imperfections, Imperfections):
            raise ValueError(f"station.imperfections must be Imperfections, got {type(self.imperfections).__name__}")
        self.imperfections.validate()
        if self.base_state not in BASE_STATE_SOURCES:
            raise ValueError(f"station.base_state must be one of {BASE_STATE_SOURCES}, got {self.base_state!r}")
        check_model_refinement(self.model_refinement)
        rest = self.at_rest_duration
        if rest is not None and not (isinstance(rest, (int, float)) and math.isfinite(rest) and rest >= 0):
            raise ValueError(f"station.at_rest_duration must be None or a non-negative number of seconds, got {rest!r}")
        return self


def replace_station(scenario: Any, **fields: Any) -> Any:
    """A copy of the dataclass ``scenario`` whose ``station`` has ``fields`` replaced (e.g. a
    trial's noise ``seed``)."""
    return dataclasses.replace(scenario, station=dataclasses.replace(scenario.station, **fields))


__all__ = [
    "BASE_STATE_SOURCES",
    "MODEL_REFINEMENTS",
    "WORLDS",
    "StationConfig",
    "check_model_refinement",
    "replace_station",
]
