"""The contact study's diagram: a standing humanoid pushed at one point, its noisy sensors, the
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

A robot's feet have F/T sensors (``hrp4_like``), FSRs or no sensing: the estimators take
what no sensor measures of the ground's wrench on each sole (all of it, or with FSRs its
shear and yaw moment) as unknowns at the sole (``EstimatorPlant.unknown_wrench_frames`` and
``unknown_wrench_components``). The soles (below the F/T sensors, or the whole feet without
them) are not candidate links: a force there is part of the ground's wrench.

By default (``estimation: offline``) the study's diagrams hold the robot, its sensors and its
base-state estimator only, and an ``UpdateRecorder`` of the estimators' inputs at each
update; the residuals, the detector and the localizer, which do not act on the robot here,
run on that record afterwards (``diagrams.residuals.contact_study.offline``).
"""

from collections.abc import Sequence
from dataclasses import dataclass, field

from pydrake.geometry import Meshcat, MeshcatVisualizer, Rgba, SceneGraph
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.residuals.contact_study.scenario import ESTIMATIONS, ContactLocalizationScenario, scenario_push
from diagrams.residuals.wiring import add_internal_and_external_residuals
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from diagrams.station.motions import slow_whole_body_motion
from systems.estimation.model_identification import ModelCorrections
from systems.io.update_recorder import UpdateRecorder
from systems.observer.fsr_sensing import FsrArray
from systems.residuals.contact_estimation import ContactDetector, ContactLocalizer, GatedEstimate
from systems.residuals.momentum_residuals import ExternalResidual, InternalResidual, ResidualModel
from systems.simulation.disturbances import Push, PushSource
from systems.simulation.visualization import add_force_arrows

TRUE_RGBA = Rgba(0.1, 0.8, 0.1, 0.5)  # wide and translucent: the estimate shows inside it
ESTIMATE_RGBA = Rgba(0.85, 0.0, 0.0, 1.0)


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
    recorder: UpdateRecorder | None = None

    @property
    def online(self) -> bool:
        """The estimators run in the diagram (else on the ``recorder``'s record)."""
        return self.recorder is None


def build_contact_localization_diagram(
    scenario: ContactLocalizationScenario,
    meshcat: Meshcat | None = None,
    *,
    model_corrections: ModelCorrections | None = None,
    pushes: Sequence[Push] | None = None,
    online: bool | None = None,
) -> tuple[Diagram, ContactLocalizationHandles]:
    """Builds the diagram of the module docstring for ``scenario`` (one run: its push, or
    none; its posture held, or following ``scenario.motion``) with the refined model
    ``model_corrections`` (the scenario's ``model_refinement``), if given. ``pushes``, if
    given, replaces the scenario's push (e.g. the trials of one run, ``run_schedule``).
    ``online``: the estimators in the diagram (default: ``scenario.estimation``
    "online", or a ``meshcat`` to draw in); otherwise the handles' residuals, detector and
    localizer are built outside it, and the diagram records their inputs at every update
    instead (the handles' ``recorder``: ``estimator_log``, ``estimate_run``).

    Raises:
        ValueError: a model without foot F/T sensors, an unknown or excluded push body,
            bad settings.
    """
    if scenario.push_duration <= 0 or scenario.push_start < 0 or scenario.log_period <= 0:
        raise ValueError("push_duration and log_period must be positive, push_start non-negative")
    if scenario.trial_gap < 0 or scenario.trials_per_run < 1 or scenario.num_seeds < 1:
        raise ValueError("trial_gap must be non-negative, trials_per_run and num_seeds at least 1")
    if scenario.estimation not in ESTIMATIONS:
        raise ValueError(f"estimation must be one of {ESTIMATIONS}, got {scenario.estimation!r}")
    if online is None:
        online = scenario.estimation == "online" or meshcat is not None
    if meshcat is not None and not online:
        raise ValueError("a Meshcat replay draws the estimate as it comes: build it with online=True")
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, scenario.station, model_corrections=model_corrections)
    estimator = station.estimator
    if station.humanoid is None or not (station.known_wrench_frames or estimator.unknown_wrench_frames):
        raise ValueError(
            f"the contact study needs a humanoid (a robot description with feet), got {scenario.station.model!r}"
        )
    plant = station.plant
    if scenario.motion is None:
        reference = builder.AddSystem(ConstantVectorSource(station.q_hold))
    else:
        reference = builder.AddSystem(slow_whole_body_motion(station, scenario.motion))
    reference.set_name("posture_reference")
    builder.Connect(reference.get_output_port(), station.desired_position)
    excluded = estimator.excluded_bodies

    if pushes is None:
        pushes = [] if scenario.push_body is None else [scenario_push(scenario)]
    pushes = list(pushes)
    for push in pushes:
        if push.body_name in excluded:
            raise ValueError(
                f"push body {push.body_name!r} is part of a foot (below an F/T sensor, or a sole whose ground "
                "wrench is unknown): its push is part of the ground's wrench, invisible to the residuals"
            )
    push_source = builder.AddSystem(PushSource(plant, pushes))
    push_source.set_name("push_source")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))

    frames = station.known_wrench_frames
    unknown = estimator.unknown_wrench_frames  # the soles without F/T sensors
    # Every estimator knows the robot through the estimators' plant alone.
    if online:
        internal, external = add_internal_and_external_residuals(
            builder, station, scenario.internal_gain, scenario.external_gain, scenario.period
        )
    else:
        model = station.dynamics_model
        internal = InternalResidual(estimator.plant, scenario.internal_gain, scenario.period, frames, model=model)
        external = ExternalResidual(estimator.plant, scenario.external_gain, scenario.period, frames, model=model)
    model = internal.model

    nq = estimator.plant.num_positions()
    # The detector's noise model: measured on the calibration log when the model was refined
    # (systems.residuals.offline), else predicted from the white sensor noise.
    noise = model_corrections.residual_noise if model_corrections is not None else None
    covariances = {}
    if noise is not None:
        noise.check_gains(scenario.internal_gain, scenario.external_gain, scenario.period, "contact study")
        covariances = {
            "covariance_internal": noise.covariance_internal,
            "covariance_external_force": noise.covariance_external_force,
        }
    detector = ContactDetector(
        estimator.plant,
        internal_gain=scenario.internal_gain,
        external_gain=scenario.external_gain,
        known_wrench_frames=frames,
        nominal_positions=estimator.standing_state[:nq],
        period=scenario.period,
        startup_time=scenario.detector_startup_time,
        release_probability=scenario.detector_release_probability,
        unknown_wrench_frames=unknown,
        unknown_wrench_components=estimator.unknown_wrench_components,
        **covariances,
    )
    detector.set_name("contact_detector")
    localizer = ContactLocalizer(
        estimator.plant,
        estimator.scene_graph,
        exclude_bodies=excluded,
        period=scenario.period,
        localization_period=scenario.localization_period,
        settle_time=scenario.settle_time,
        unknown_wrench_frames=unknown,
        unknown_wrench_components=estimator.unknown_wrench_components,
    )
    localizer.set_name("contact_localizer")
    handles = {
        "plant": plant,
        "scene_graph": station.scene_graph,
        "station": station,
        "push_source": push_source,
        "model": model,
        "internal": internal,
        "external": external,
        "detector": detector,
        "localizer": localizer,
        "excluded_bodies": excluded,
    }
    if not online:
        diagram, recorder = _build_with_estimator_recorder(builder, station, scenario.period)
        return diagram, ContactLocalizationHandles(**handles, recorder=recorder)
    builder.AddSystem(detector)
    builder.AddSystem(localizer)
    builder.Connect(external.GetOutputPort("external_wrench_world"), detector.GetInputPort("external_wrench_world"))
    builder.Connect(internal.GetOutputPort("residual"), detector.GetInputPort("residual"))
    if unknown:
        builder.Connect(station.sensed_state, detector.GetInputPort("state"))
    builder.Connect(station.sensed_state, localizer.GetInputPort("state"))
    builder.Connect(external.GetOutputPort("external_wrench_world"), localizer.GetInputPort("external_wrench_world"))
    builder.Connect(internal.GetOutputPort("residual"), localizer.GetInputPort("residual"))
    builder.Connect(detector.GetOutputPort("contact_detected"), localizer.GetInputPort("contact_detected"))

    log = scenario.log_period
    # The localizer's estimate is recomputed once per localization: logged at that rate.
    estimate_log = max(log, scenario.localization_period or 0.0)
    loggers = {
        "contact_detected": LogVectorOutput(detector.GetOutputPort("contact_detected"), builder, log),
        "detection_time": LogVectorOutput(detector.GetOutputPort("detection_time"), builder, log),
        "test_statistics": LogVectorOutput(detector.GetOutputPort("test_statistics"), builder, log),
        "status": LogVectorOutput(localizer.GetOutputPort("status"), builder, estimate_log),
        "contact_point_world": LogVectorOutput(localizer.GetOutputPort("contact_point_world"), builder, estimate_log),
        "contact_force_world": LogVectorOutput(localizer.GetOutputPort("contact_force_world"), builder, estimate_log),
        "contact_body": LogVectorOutput(localizer.GetOutputPort("contact_body"), builder, estimate_log),
    }
    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(builder, station.scene_graph, meshcat)
        add_force_arrows(
            builder,
            meshcat,
            push_source.GetOutputPort("force_world"),
            push_source.GetOutputPort("point_world"),
            name="true_force_arrow",
            path="true_force",
            rgba=TRUE_RGBA,
            min_force=0.5,
            shaft_radius=0.016,
            head_radius=0.035,
        )
        gate = builder.AddSystem(GatedEstimate())
        builder.Connect(localizer.GetOutputPort("contact_force_world"), gate.GetInputPort("force"))
        builder.Connect(localizer.GetOutputPort("contact_point_world"), gate.GetInputPort("point"))
        builder.Connect(localizer.GetOutputPort("valid"), gate.GetInputPort("valid"))
        add_force_arrows(
            builder,
            meshcat,
            gate.GetOutputPort("force_world"),
            gate.GetOutputPort("point_world"),
            name="estimated_force_arrow",
            path="estimated_force",
            rgba=ESTIMATE_RGBA,
            min_force=0.5,
            shaft_radius=0.005,
        )
    diagram = builder.Build()
    diagram.set_name("contact_localization")
    return diagram, ContactLocalizationHandles(**handles, loggers=loggers, meshcat_visualizer=visualizer)


def _build_with_estimator_recorder(
    builder: DiagramBuilder, station: HumanoidStation, period: float
) -> tuple[Diagram, UpdateRecorder]:
    """Builds the diagram with the estimators' inputs recorded instead of the estimators:
    an ``UpdateRecorder`` updated when they would be, reading what they would read (the
    sensed state, the motor torque the internal residual reads, the F/T wrenches)."""
    sizes = {"state": station.sensed_state.size(), "torque": station.measured_torque.size()}
    if station.known_wrenches is not None:  # the F/T wrenches (none without F/T sensors)
        sizes["wrenches"] = station.known_wrenches.size()
    truth = None
    if station.estimator.unknown_wrench_frames:
        # Ground truth for the metrics only (never an estimator's input): the normal force
        # on each foot contact sphere, from the simulator's contact results.
        truth = builder.AddSystem(FsrArray(station.plant, station.humanoid, noise_std=0.0))
        truth.set_name("true_sole_forces")
        builder.Connect(station.plant.get_contact_results_output_port(), truth.GetInputPort("contact_results"))
        sizes["true_fsr_forces"] = truth.GetOutputPort("true_fsr_forces").size()
    recorder = builder.AddSystem(UpdateRecorder(sizes, period))
    recorder.set_name("estimator_input_recorder")
    builder.Connect(station.sensed_state, recorder.GetInputPort("state"))
    builder.Connect(station.measured_torque, recorder.GetInputPort("torque"))
    if station.known_wrenches is not None:
        builder.Connect(station.known_wrenches, recorder.GetInputPort("wrenches"))
    if truth is not None:
        builder.Connect(truth.GetOutputPort("true_fsr_forces"), recorder.GetInputPort("true_fsr_forces"))
    diagram = builder.Build()
    diagram.set_name("contact_localization_sensing")
    return diagram, recorder
