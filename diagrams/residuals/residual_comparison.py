"""Residual estimation diagram: a humanoid holding its posture while pushed, its sensors, and
the three residuals of Flacco et al. (2016) fed only by those sensors.

    PushSource ──applied_spatial_forces──► MultibodyPlant (+ ground) ──state──► sensors
        ▲ true state      │ ground truth            ▲ actuation                  │ sensed state,
        └─────────────────┤ (tau_c_real, wrenches)  │                            │ motor torque,
                          ▼                         PdGravityController ◄────────┤ F/T wrenches
                       loggers                                                   ▼
                                          ClassicalResidual, InternalResidual, ExternalResidual
                                          (one shared ResidualModel) ──► loggers

For ``hrp4_like`` and ``nao_like`` the robot stands on flat ground; its F/T sensors (HRP-4)
make the ground reaction a known wrench. On a humanoid without foot F/T sensors (``sensing:
none`` or ``fsr``) the residuals hold the ground's unknown wrenches as well: two
``SoleWrenchCompensation`` systems fit the soles' wrenches with the push's link and report
the internal, classical and external residuals net of the soles' share (eq. 10 with the
soles' wrenches estimated), which the metrics compare with the push's own effort. Any other
floating-base model (an SDFormat or URDF path) floats in zero gravity with no ground,
holding its default posture.

Scenarios are YAML files loaded into ``ResidualComparisonScenario`` with
``pydrake.common.yaml.yaml_load_typed`` (``diagrams.scenarios``); the default is the paper's.
The metrics (``residual_comparison_metrics``) are relative RMS errors over the samples after
``skip`` seconds: sqrt(sum (estimate - truth)^2) / sqrt(sum truth^2), over all joints or per
joint, each against the raw truth and against the truth passed through the residual's own
first-order filter (time constant 1/K), which removes the filter's designed lag.
"""

# No ``from __future__ import annotations``: yaml_load_typed reads the scenario's field types.

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, SceneGraph
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from models import HumanoidHandles
from systems.estimation.model_identification import ModelCorrections
from systems.residuals.momentum_residuals import ClassicalResidual, ExternalResidual, InternalResidual, ResidualModel
from systems.residuals.sole_wrenches import SoleWrenchCompensation
from systems.simulation.disturbances import Push, PushSource, Sinusoid
from systems.simulation.sensors import SensorHandles


@dataclass(slots=True)
class ResidualComparisonScenario:
    """The residual comparison's settings (paper Secs. II-C, III, V). SI units.

    Attributes:
        station: the robot (``hrp4_like``, ``nao_like``, a robot description or a
            floating-base SDFormat/URDF file) and its world (``diagrams.station.config``):
            realistic by default, ideal with ``--ideal``.
        push_body: the pushed body (default: the right shoulder body of the humanoids).
        push_point: the point of the push in the body frame, m.
        push_direction: the push's world direction (normalised); with horizontal components,
            as in the paper's Fig. 7, so that it loads the chest yaw and the legs.
        push_amplitude: N; the sinusoid's amplitude. 40 N with this direction keeps the
            horizontal part (19 N) well below what tips the 39 kg robot over its feet.
            None: 10 % of the robot's weight (other models).
        push_frequency: Hz.
        push_start: s; the sinusoid starts here (from zero).
        duration: s.
        classical_gain, internal_gain, external_gain: residual gains K, 1/s. A residual is a
            first-order filter (time constant 1/K) whose output noise grows with K (velocity
            noise enters the momentum and is multiplied by K); 35/s balances the lag
            (omega/K = 1.8 % at 0.1 Hz) against the default sensor noise.
        period: the residuals' update period, s.
        log_period: the loggers' sampling period, s.
        skip: the metrics ignore the first ``skip`` s (less than ``duration``).
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``); the plant
            is discrete, so only ``target_realtime_rate`` and the publishing matter.
    """

    station: StationConfig = field(default_factory=StationConfig.realistic)
    push_body: str | None = None
    push_point: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    push_direction: list[float] = field(default_factory=lambda: [-0.4, 0.25, -0.88])
    push_amplitude: float | None = 40.0
    push_frequency: float = 0.1
    push_start: float = 0.5
    duration: float = 10.0
    classical_gain: float = 35.0
    internal_gain: float = 35.0
    external_gain: float = 35.0
    period: float = 1e-3
    log_period: float = 5e-3
    skip: float = 0.5
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)


@dataclass
class ResidualComparisonHandles:
    """What ``build_residual_comparison_diagram`` created (see the module docstring)."""

    plant: MultibodyPlant
    scene_graph: SceneGraph
    humanoid: HumanoidHandles | None
    push_source: PushSource
    sensors: SensorHandles | None
    model: ResidualModel
    classical: ClassicalResidual
    internal: InternalResidual
    external: ExternalResidual
    joint_names: tuple[str, ...]
    initial_state: np.ndarray
    loggers: dict[str, VectorLogSink]
    meshcat_visualizer: MeshcatVisualizer | None = None
    station: HumanoidStation | None = None
    sole_compensations: dict[str, SoleWrenchCompensation] = field(default_factory=dict)


def build_residual_comparison_diagram(
    scenario: ResidualComparisonScenario,
    meshcat: Meshcat | None = None,
    *,
    model_corrections: ModelCorrections | None = None,
) -> tuple[Diagram, ResidualComparisonHandles]:
    """Builds the diagram of the module docstring for ``scenario``; ``model_corrections``
    (the scenario's refined model, see ``model_refinement``) go to the station.

    Raises:
        ValueError: an unknown model or body, a model without a floating base, bad settings.
    """
    if scenario.duration <= 0 or scenario.push_frequency < 0 or scenario.log_period <= 0:
        raise ValueError("duration and log_period must be positive, push_frequency non-negative")
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, scenario.station, model_corrections=model_corrections)
    plant, humanoid = station.plant, station.humanoid
    builder.Connect(builder.AddSystem(ConstantVectorSource(station.q_hold)).get_output_port(), station.desired_position)
    amplitude = scenario.push_amplitude
    if amplitude is None:
        mass = plant.CalcTotalMass(plant.CreateDefaultContext())
        amplitude = 0.1 * mass * 9.81

    # The pusher and its ground truth.
    push_body = scenario.push_body
    if push_body is None:
        if humanoid is None:
            raise ValueError("--push-body is required for a model other than the humanoids")
        push_body = humanoid.shoulder_bodies["right"].name()
    push = Push(
        body_name=push_body,
        p_BoP_B=np.asarray(scenario.push_point, dtype=float),
        direction_W=np.asarray(scenario.push_direction, dtype=float),
        profile=Sinusoid(amplitude, scenario.push_frequency, t_start=scenario.push_start),
    )
    push_source = builder.AddSystem(PushSource(plant, [push]))
    push_source.set_name("push_source")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))

    sensed_state, measured_torque = station.sensed_state, station.measured_torque
    known_frames, known_wrenches = station.known_wrench_frames, station.known_wrenches

    # The three residuals, sharing one model (one dynamics computation per update): the
    # estimators' plant and inertias, which the PD's gravity also uses.
    estimator_plant = station.estimator.plant
    model = station.dynamics_model if station.dynamics_model is not None else ResidualModel(estimator_plant)
    classical = builder.AddSystem(
        ClassicalResidual(estimator_plant, scenario.classical_gain, scenario.period, known_frames, model=model)
    )
    internal = builder.AddSystem(
        InternalResidual(estimator_plant, scenario.internal_gain, scenario.period, known_frames, model=model)
    )
    external = builder.AddSystem(
        ExternalResidual(estimator_plant, scenario.external_gain, scenario.period, known_frames, model=model)
    )
    for name, residual in (
        ("classical_residual", classical),
        ("internal_residual", internal),
        ("external_residual", external),
    ):
        residual.set_name(name)
        builder.Connect(sensed_state, residual.GetInputPort("state"))
        if residual.HasInputPort("measured_torque"):
            builder.Connect(measured_torque, residual.GetInputPort("measured_torque"))
        if known_frames:
            builder.Connect(known_wrenches, residual.GetInputPort("known_wrenches"))

    outputs = {
        "classical": classical.GetOutputPort("residual"),
        "internal": internal.GetOutputPort("residual"),
        "external_base": external.GetOutputPort("external_wrench_base"),
        "external_world": external.GetOutputPort("external_wrench_world"),
    }
    compensations = {}
    if station.estimator.unknown_wrench_frames:
        compensations = _add_sole_wrench_compensations(builder, station, scenario, classical, internal, external)
        outputs = {
            "classical": compensations["classical"].GetOutputPort("residual"),
            "internal": compensations["internal"].GetOutputPort("residual"),
            "external_base": compensations["internal"].GetOutputPort("external_wrench_base"),
            "external_world": compensations["internal"].GetOutputPort("external_wrench_world"),
        }

    log = scenario.log_period
    loggers = {
        "state": LogVectorOutput(plant.get_state_output_port(), builder, log),
        **{name: LogVectorOutput(port, builder, log) for name, port in outputs.items()},
        "tau_c_real": LogVectorOutput(push_source.GetOutputPort("tau_c_real"), builder, log),
        "wrench_base_true": LogVectorOutput(push_source.GetOutputPort("total_wrench_base"), builder, log),
        "wrench_world_true": LogVectorOutput(push_source.GetOutputPort("total_wrench_world"), builder, log),
        "force_world_true": LogVectorOutput(push_source.GetOutputPort("force_world"), builder, log),
    }
    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(builder, station.scene_graph, meshcat)
    diagram = builder.Build()
    diagram.set_name("residual_comparison")
    return diagram, ResidualComparisonHandles(
        plant=plant,
        scene_graph=station.scene_graph,
        humanoid=humanoid,
        push_source=push_source,
        sensors=station.sensors,
        model=model,
        classical=classical,
        internal=internal,
        external=external,
        joint_names=station.joint_names,
        initial_state=station.initial_state,
        loggers=loggers,
        meshcat_visualizer=visualizer,
        station=station,
        sole_compensations=compensations,
    )


def _add_sole_wrench_compensations(
    builder: DiagramBuilder,
    station: HumanoidStation,
    scenario: ResidualComparisonScenario,
    classical: ClassicalResidual,
    internal: InternalResidual,
    external: ExternalResidual,
) -> dict[str, SoleWrenchCompensation]:
    """{"internal", "classical"}: the soles' wrench compensation of each residual on a robot
    without foot F/T sensors (module docstring); the internal one also gives the external
    residual net of the soles' share. Both fit the same soles' wrenches (the internal and
    external residuals); the push's candidate links are every link but the feet."""
    estimator = station.estimator
    if not (scenario.internal_gain == scenario.external_gain == scenario.classical_gain):
        raise ValueError(
            "without foot F/T sensors the soles' wrenches are fitted to the residuals through their common "
            f"filter: classical_gain, internal_gain and external_gain must be equal, got {scenario.classical_gain}, "
            f"{scenario.internal_gain} and {scenario.external_gain}"
        )
    compensations = {}
    for kind, residual in (("internal", internal), ("classical", classical)):
        compensation = builder.AddSystem(
            estimator.sole_wrench_compensation(scenario.internal_gain, scenario.period, kind)
        )
        compensation.set_name(f"{kind}_sole_wrench_compensation")
        builder.Connect(station.sensed_state, compensation.GetInputPort("state"))
        builder.Connect(
            external.GetOutputPort("external_wrench_world"), compensation.GetInputPort("external_wrench_world")
        )
        builder.Connect(internal.GetOutputPort("residual"), compensation.GetInputPort("internal_residual"))
        if kind == "classical":
            builder.Connect(residual.GetOutputPort("residual"), compensation.GetInputPort("classical_residual"))
        compensations[kind] = compensation
    return compensations


def set_initial_state(diagram: Diagram, context: Context, handles: ResidualComparisonHandles) -> None:
    """Puts the robot in its initial (standing) state in the diagram's ``context`` (and the
    station's held sensor sample, see ``HumanoidStation.set_initial_state``)."""
    handles.station.set_initial_state(context)


def check_metrics_window(scenario: ResidualComparisonScenario) -> None:
    """Raises a ValueError unless 0 <= ``skip`` < ``duration`` (the metrics need samples)."""
    if not 0.0 <= scenario.skip < scenario.duration:
        raise ValueError(
            f"the metrics window needs 0 <= skip < duration, got skip {scenario.skip:g} s, "
            f"duration {scenario.duration:g} s"
        )


def relative_rms_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    """sqrt(sum (estimate - truth)^2) / sqrt(sum truth^2) over every entry (nan if truth is 0)."""
    denominator = float(np.sqrt(np.sum(np.square(truth))))
    if denominator == 0.0:
        return float("nan")
    return float(np.sqrt(np.sum(np.square(estimate - truth))) / denominator)


def first_order_filter(samples: np.ndarray, gain: float, dt: float) -> np.ndarray:
    """The truth as a residual of gain K would see it: y' = K (u - y), y(0) = 0, for the
    columns of ``samples`` taken every ``dt`` seconds (exact for piecewise-constant input)."""
    a = 1.0 - np.exp(-gain * dt)
    out = np.zeros_like(samples)
    y = np.zeros(samples.shape[0])
    for k in range(1, samples.shape[1]):
        y = y + a * (samples[:, k - 1] - y)
        out[:, k] = y
    return out


def residual_comparison_metrics(
    scenario: ResidualComparisonScenario, handles: ResidualComparisonHandles, signals: dict, wall_time_s: float
) -> dict:
    """The metrics of one run (module docstring), from its logged signals (``logged_signals``:
    "t" and the loggers of ``handles``) over the samples after ``scenario.skip``, and the
    real-time factor of a run that took ``wall_time_s`` s.

    Raises:
        ValueError: ``skip`` outside [0, duration).
    """
    check_metrics_window(scenario)
    skip = scenario.skip
    t = signals["t"]
    window = t >= skip
    dt = scenario.log_period

    truth = signals["tau_c_real"]
    internal, classical = signals["internal"], signals["classical"][6:]
    internal_truth_filtered = first_order_filter(truth, scenario.internal_gain, dt)
    classical_truth_filtered = first_order_filter(truth, scenario.classical_gain, dt)
    force_truth = signals["force_world_true"]
    force_estimate = signals["external_world"][3:]
    force_truth_filtered = first_order_filter(force_truth, scenario.external_gain, dt)
    wrench_base_truth = signals["wrench_base_true"]
    wrench_base_filtered = first_order_filter(wrench_base_truth, scenario.external_gain, dt)
    names = handles.joint_names

    def per_joint(estimate, reference):
        return {name: relative_rms_error(estimate[k, window], reference[k, window]) for k, name in enumerate(names)}

    before = t < scenario.push_start  # no push yet: the residuals show only noise
    return {
        "model": scenario.station.model,
        "push_body": handles.push_source.pushes[0].body_name,
        "noise": scenario.station.noise,
        "sensors": "simulated sensors"
        if handles.sensors is not None
        else "true state (no sensor model for this robot)",
        "seed": scenario.station.seed,
        "duration_s": scenario.duration,
        "skip_s": skip,
        "gains_per_s": {
            "classical": scenario.classical_gain,
            "internal": scenario.internal_gain,
            "external": scenario.external_gain,
        },
        "internal_rel_rms_error": relative_rms_error(internal[:, window], truth[:, window]),
        "internal_rel_rms_error_per_joint": per_joint(internal, truth),
        "internal_rel_rms_error_vs_filtered_truth": relative_rms_error(
            internal[:, window], internal_truth_filtered[:, window]
        ),
        "internal_rel_rms_error_per_joint_vs_filtered_truth": per_joint(internal, internal_truth_filtered),
        "classical_rel_rms_error": relative_rms_error(classical[:, window], truth[:, window]),
        "classical_rel_rms_error_per_joint": per_joint(classical, truth),
        "classical_rel_rms_error_vs_filtered_truth": relative_rms_error(
            classical[:, window], classical_truth_filtered[:, window]
        ),
        "external_force_rel_rms_error": relative_rms_error(force_estimate[:, window], force_truth[:, window]),
        "external_force_rel_rms_error_vs_filtered_truth": relative_rms_error(
            force_estimate[:, window], force_truth_filtered[:, window]
        ),
        "external_wrench_base_rel_rms_error": relative_rms_error(
            signals["external_base"][:, window], wrench_base_truth[:, window]
        ),
        "external_wrench_base_rel_rms_error_vs_filtered_truth": relative_rms_error(
            signals["external_base"][:, window], wrench_base_filtered[:, window]
        ),
        "rms_true_joint_effort_Nm": {
            name: float(np.sqrt(np.mean(truth[k, window] ** 2))) for k, name in enumerate(names)
        },
        "rms_classical_joint_effort_Nm": {
            name: float(np.sqrt(np.mean(classical[k, window] ** 2))) for k, name in enumerate(names)
        },
        "rms_internal_noise_before_push_Nm": {
            name: float(np.sqrt(np.mean(internal[k, before & (t > 0.05)] ** 2)))
            if np.any(before & (t > 0.05))
            else None
            for k, name in enumerate(names)
        },
        "wall_time_s": wall_time_s,
        "real_time_factor": scenario.duration / wall_time_s,
    }
