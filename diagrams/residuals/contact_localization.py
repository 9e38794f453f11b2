"""Contact study diagram: a standing humanoid pushed at one point, its noisy sensors, the
internal and external residuals, and the contact detector and localizer fed only by them
(Flacco et al. 2016, Secs. V-VI, Fig. 9).

    PushSource (step force on a body point) ──► MultibodyPlant (+ ground) ──► sensors
        │ ground truth                             ▲ actuation                │ sensed state,
        ▼                                          PdGravityController ◄──────┤ motor torque,
      loggers                                                                 │ F/T wrenches
                                  InternalResidual, ExternalResidual ◄────────┘
                                        │ residual, external_wrench_world
                                        ▼
                              ContactDetector ──contact_detected──► ContactLocalizer ──► loggers

Only robots with foot F/T sensors (``hrp4_like``) are supported: without them the ground
reaction is an unknown external force for the residuals and no single contact can be
isolated. The soles (below the F/T sensors) are not candidate links: a force there is part
of the measured wrench and invisible to the residuals.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, Rgba, SceneGraph
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from systems.residuals.contact_estimation import ContactDetector, ContactLocalizer, GatedEstimate
from systems.simulation.disturbances import Push, PushSource, Step
from systems.residuals.momentum_residuals import ExternalResidual, InternalResidual, ResidualModel
from systems.simulation.visualization import ForceArrows

TRUE_RGBA = Rgba(0.1, 0.8, 0.1, 0.5)  # wide and translucent: the estimate shows inside it
ESTIMATE_RGBA = Rgba(0.85, 0.0, 0.0, 1.0)


@dataclass
class ContactLocalizationConfig:
    """One trial of the contact study. SI units.

    Attributes:
        model: ``hrp4_like`` (needs foot F/T sensors).
        push_body: the pushed link, or None for a run without contact.
        push_point: the contact point in the link's body frame, m.
        push_force: the (constant) force in world, N.
        push_start: s; the force is on for push_start <= t < push_start + push_duration.
        push_duration: s.
        noise: sensor noise on (systems.simulation.sensors defaults) or off. seed: its seed.
        internal_gain, external_gain: residual gains K, 1/s.
        time_step: plant step, s. period: residual/detector/localizer period, s.
        settle_time: the localizer's wait after detection before averaging, s.
        log_period: period of the loggers (detector and localizer outputs, truth), s.
    """

    model: str = "hrp4_like"
    push_body: str | None = None
    push_point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    push_force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    push_start: float = 0.5
    push_duration: float = 1.0
    noise: bool = True
    seed: int = 0
    internal_gain: float = 35.0
    external_gain: float = 35.0
    time_step: float = 1e-3
    period: float = 1e-3
    settle_time: float = 0.1
    log_period: float = 1e-3


@dataclass
class ContactLocalizationHandles:
    plant: MultibodyPlant
    scene_graph: SceneGraph
    station: HumanoidStation
    push_source: PushSource
    model: ResidualModel
    internal: InternalResidual
    external: ExternalResidual
    detector: ContactDetector
    localizer: ContactLocalizer
    excluded_bodies: tuple[str, ...]
    loggers: dict[str, VectorLogSink] = field(default_factory=dict)
    meshcat_visualizer: MeshcatVisualizer | None = None


def sole_bodies(station: HumanoidStation) -> tuple[str, ...]:
    """Names of the links outboard of the F/T sensors (the soles)."""
    return tuple(j.child_body().name() for j in (station.humanoid.ft_sensor_joints or {}).values())


def build_contact_localization_diagram(
    config: ContactLocalizationConfig, meshcat: Meshcat | None = None
) -> tuple[Diagram, ContactLocalizationHandles]:
    """Builds the diagram of the module docstring for ``config``.

    Raises:
        ValueError: a model without foot F/T sensors, an unknown or excluded push body,
            bad settings.
    """
    if config.push_duration <= 0 or config.push_start < 0 or config.log_period <= 0:
        raise ValueError("push_duration and log_period must be positive, push_start non-negative")
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, config.model, time_step=config.time_step, noise=config.noise, seed=config.seed)
    if station.humanoid is None or not station.known_wrench_frames:
        raise ValueError(f"the contact study needs a humanoid with foot F/T sensors (hrp4_like), got {config.model!r}")
    plant = station.plant
    builder.Connect(builder.AddSystem(ConstantVectorSource(station.q_hold)).get_output_port(), station.desired_position)
    excluded = sole_bodies(station)

    pushes = []
    if config.push_body is not None:
        if config.push_body in excluded:
            raise ValueError(f"push body {config.push_body!r} is below an F/T sensor: invisible to the residuals")
        force = np.asarray(config.push_force, dtype=float)
        magnitude = float(np.linalg.norm(force))
        if magnitude == 0.0:
            raise ValueError("push_force must be non-zero (use push_body=None for no contact)")
        pushes.append(Push(config.push_body, np.asarray(config.push_point, dtype=float), force / magnitude,
                           Step(magnitude, config.push_start, config.push_start + config.push_duration)))
    push_source = builder.AddSystem(PushSource(plant, pushes))
    push_source.set_name("push_source")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))

    frames = station.known_wrench_frames
    # The station's model: the PD's gravity comes from the same per-state computation.
    model = station.dynamics_model if station.dynamics_model is not None else ResidualModel(plant)
    internal = builder.AddSystem(InternalResidual(plant, config.internal_gain, config.period, frames, model=model))
    external = builder.AddSystem(ExternalResidual(plant, config.external_gain, config.period, frames, model=model))
    internal.set_name("internal_residual")
    external.set_name("external_residual")
    for residual in (internal, external):
        builder.Connect(station.sensed_state, residual.GetInputPort("state"))
        builder.Connect(station.known_wrenches, residual.GetInputPort("known_wrenches"))
    builder.Connect(station.measured_torque, internal.GetInputPort("measured_torque"))

    nq = plant.num_positions()
    detector = builder.AddSystem(ContactDetector(
        plant, internal_gain=config.internal_gain, external_gain=config.external_gain, known_wrench_frames=frames,
        nominal_positions=station.initial_state[:nq], period=config.period))
    detector.set_name("contact_detector")
    builder.Connect(external.GetOutputPort("external_wrench_world"), detector.GetInputPort("external_wrench_world"))
    builder.Connect(internal.GetOutputPort("residual"), detector.GetInputPort("residual"))
    localizer = builder.AddSystem(ContactLocalizer(
        plant, station.scene_graph, exclude_bodies=excluded, period=config.period, settle_time=config.settle_time))
    localizer.set_name("contact_localizer")
    builder.Connect(station.sensed_state, localizer.GetInputPort("state"))
    builder.Connect(external.GetOutputPort("external_wrench_world"), localizer.GetInputPort("external_wrench_world"))
    builder.Connect(internal.GetOutputPort("residual"), localizer.GetInputPort("residual"))
    builder.Connect(detector.GetOutputPort("contact_detected"), localizer.GetInputPort("contact_detected"))

    log = config.log_period
    loggers = {
        "contact_detected": LogVectorOutput(detector.GetOutputPort("contact_detected"), builder, log),
        "detection_time": LogVectorOutput(detector.GetOutputPort("detection_time"), builder, log),
        "test_statistics": LogVectorOutput(detector.GetOutputPort("test_statistics"), builder, log),
        "status": LogVectorOutput(localizer.GetOutputPort("status"), builder, log),
        "contact_point_world": LogVectorOutput(localizer.GetOutputPort("contact_point_world"), builder, log),
        "contact_force_world": LogVectorOutput(localizer.GetOutputPort("contact_force_world"), builder, log),
        "contact_body": LogVectorOutput(localizer.GetOutputPort("contact_body"), builder, log),
    }
    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(builder, station.scene_graph, meshcat)
        true_arrows = builder.AddSystem(ForceArrows(meshcat, 1, path="true_force", rgba=TRUE_RGBA, min_force=0.5,
                                                    shaft_radius=0.016, head_radius=0.035))
        builder.Connect(push_source.GetOutputPort("force_world"), true_arrows.get_force_world_input_port())
        builder.Connect(push_source.GetOutputPort("point_world"), true_arrows.get_point_world_input_port())
        gate = builder.AddSystem(GatedEstimate())
        builder.Connect(localizer.GetOutputPort("contact_force_world"), gate.GetInputPort("force"))
        builder.Connect(localizer.GetOutputPort("contact_point_world"), gate.GetInputPort("point"))
        builder.Connect(localizer.GetOutputPort("valid"), gate.GetInputPort("valid"))
        estimate_arrows = builder.AddSystem(ForceArrows(meshcat, 1, path="estimated_force", rgba=ESTIMATE_RGBA,
                                                        min_force=0.5, shaft_radius=0.005))
        builder.Connect(gate.GetOutputPort("force_world"), estimate_arrows.get_force_world_input_port())
        builder.Connect(gate.GetOutputPort("point_world"), estimate_arrows.get_point_world_input_port())
    diagram = builder.Build()
    diagram.set_name("contact_localization")
    return diagram, ContactLocalizationHandles(
        plant=plant, scene_graph=station.scene_graph, station=station, push_source=push_source, model=model,
        internal=internal, external=external, detector=detector, localizer=localizer, excluded_bodies=excluded,
        loggers=loggers, meshcat_visualizer=visualizer)
