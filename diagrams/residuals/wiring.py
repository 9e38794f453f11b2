"""The internal and external residuals wired to a humanoid station's sensors, as the
contact study and the model refinement use them."""

from __future__ import annotations

from pydrake.systems.framework import DiagramBuilder

from diagrams.station.humanoid_station import HumanoidStation
from systems.residuals.momentum_residuals import ExternalResidual, InternalResidual, ResidualModel


def add_internal_and_external_residuals(
    builder: DiagramBuilder, station: HumanoidStation, internal_gain: float, external_gain: float, period: float
) -> tuple[InternalResidual, ExternalResidual]:
    """The ``InternalResidual`` (eq. 11) and ``ExternalResidual`` (eq. 16), gains K in 1/s,
    update period in s, on the station's sensed state, F/T wrenches (as known wrenches) and
    motor torques, built on the estimators' plant and sharing the station's dynamics model
    (the estimators' inertias, which the PD's gravity also uses)."""
    plant, frames = station.estimator.plant, station.known_wrench_frames
    model = station.dynamics_model if station.dynamics_model is not None else ResidualModel(plant)
    internal = builder.AddSystem(InternalResidual(plant, internal_gain, period, frames, model=model))
    external = builder.AddSystem(ExternalResidual(plant, external_gain, period, frames, model=model))
    internal.set_name("internal_residual")
    external.set_name("external_residual")
    for residual in (internal, external):
        builder.Connect(station.sensed_state, residual.GetInputPort("state"))
        if frames:
            builder.Connect(station.known_wrenches, residual.GetInputPort("known_wrenches"))
    builder.Connect(station.measured_torque, internal.GetInputPort("measured_torque"))
    return internal, external
