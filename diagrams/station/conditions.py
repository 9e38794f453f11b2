"""The two worlds an experiment runs in: "realistic" (the default of the hrp4_like
experiments) and "ideal" (``--ideal``).

* realistic: the base pose and velocity from the contact-aided invariant EKF
  (``base_state: invariant_ekf``), ``Imperfections.realistic()`` (IMU noise and bias walks,
  14-bit encoders, unmodelled joint friction, motor-torque scale and offset errors, 5 %
  mass / 10 % CoM / 10 % inertia mismatch of the estimators' model) and the model refined
  from a calibration motion (``model_refinement: calibrate``, see
  ``diagrams.residuals.model_refinement``).
* ideal: the simulator's base state plus white noise, no imperfections, no refinement:
  the world the estimators were first measured in.

A scenario takes part through whichever of the fields ``base_state``, ``imperfections``
and ``model_refinement`` it has.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from systems.simulation.imperfections import Imperfections

#: ``model_refinement`` values besides a path to a saved ``ModelCorrections`` file.
MODEL_REFINEMENTS = ("none", "calibrate")


def set_ideal_conditions(scenario: Any) -> Any:
    """Sets ``scenario``'s condition fields to the ideal world (in place); returns it."""
    if hasattr(scenario, "base_state"):
        scenario.base_state = "truth_plus_noise"
    if hasattr(scenario, "imperfections"):
        scenario.imperfections = Imperfections()
    if hasattr(scenario, "model_refinement"):
        scenario.model_refinement = "none"
    return scenario


def is_ideal(scenario: Any) -> bool:
    """True when every condition field ``scenario`` has is at its ideal value."""
    return (
        getattr(scenario, "base_state", "truth_plus_noise") == "truth_plus_noise"
        and getattr(scenario, "imperfections", Imperfections()).is_ideal
        and getattr(scenario, "model_refinement", "none") == "none"
    )


def check_model_refinement(value: str) -> str:
    """``value`` if it is one of ``MODEL_REFINEMENTS`` or an existing file, else ValueError."""
    if value in MODEL_REFINEMENTS or Path(value).is_file():
        return value
    raise ValueError(
        f"model_refinement must be one of {MODEL_REFINEMENTS} or a saved model-corrections file, got {value!r}"
    )
