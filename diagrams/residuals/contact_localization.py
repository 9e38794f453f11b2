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

A robot's feet have F/T sensors (``hrp4_like``), FSRs or no sensing: the estimators take
what no sensor measures of the ground's wrench on each sole (all of it, or with FSRs its
shear and yaw moment) as unknowns at the sole (``EstimatorPlant.unknown_wrench_frames`` and
``unknown_wrench_components``). The soles (below the F/T sensors, or the whole feet without
them) are not candidate links: a force there is part of the ground's wrench.

The Monte Carlo study (``apps.contact_localization``) samples random contacts
(``sample_trials``), runs one diagram per trial and one without contact, and computes its
metrics here (``trial_result``, ``no_contact_result``, ``contact_localization_metrics``).
By default (``estimation: offline``) its diagrams hold the robot, its sensors and its
base-state estimator only, and an ``UpdateRecorder`` of the estimators' inputs at each
update; the residuals, the detector and the localizer, which do not act on the robot here,
run on that record afterwards (``estimate_run``: their own update code, the residuals
stacked over the samples, ``systems.residuals.offline``). They report the same as in the
loop, to rounding (``tests/test_contact_localization.py``), for a fraction of the cost of
Python systems stepped at 1 kHz.
Scenarios are YAML files loaded into ``ContactLocalizationScenario`` with
``pydrake.common.yaml.yaml_load_typed`` (``diagrams.scenarios``).

Metric definitions: ``detection_rate`` = trials whose contact was detected during the push
(a detection before the push counts as a false detection, not as this trial's);
``correct_link_rate`` and the position errors are over ALL trials (a trial without a
localization counts as a wrong link and an infinite position error); force errors are over
the detected trials: |f_hat - f| / |f| and the angle between f_hat and f.
"""

# No ``from __future__ import annotations``: yaml_load_typed reads the scenario's field types.

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, Rgba, SceneGraph
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.residuals.study_statistics import (
    CONFIDENCE_LEVEL,
    percentile_with_inf,
    proportion_interval,
    quantile_interval,
    rate_table,
)
from diagrams.residuals.wiring import add_internal_and_external_residuals
from diagrams.simulation import simulate
from diagrams.station.config import StationConfig, replace_station
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from diagrams.station.motions import SlowMotion, slow_whole_body_motion
from diagrams.station.standing import foot_sphere_normal_forces
from models import is_humanoid, robot_description
from systems.estimation.model_identification import ModelCorrections
from systems.io.update_recorder import UpdateRecorder
from systems.observer.fsr_sensing import FSR_SIDES, FsrArray
from systems.residuals.contact_estimation import (
    VALID,
    ContactDetector,
    ContactLocalizer,
    GatedEstimate,
    LocalizationResult,
    UnknownWrenches,
    _SensedConfiguration,
    candidate_geometry,
)
from systems.residuals.geometry_intersection import inward_direction, sample_surface, surface_areas
from systems.residuals.momentum_residuals import ExternalResidual, InternalResidual, ResidualModel
from systems.residuals.multi_contact import MultiContactLocalizer
from systems.residuals.offline import ReplayedEstimation, ReplayState, replay_contact_estimation
from systems.simulation.disturbances import Push, PushSource, Step
from systems.simulation.visualization import add_force_arrows

TRUE_RGBA = Rgba(0.1, 0.8, 0.1, 0.5)  # wide and translucent: the estimate shows inside it
ESTIMATE_RGBA = Rgba(0.85, 0.0, 0.0, 1.0)


#: Issue 12's single-contact floors on the stacked fit (``MultiContactLocalizer`` as a
#: single-contact localizer, once per push on the averaged inputs: ``multi_contact_result``).
STACKED_FIT_FLOORS = {
    "fit_correct_link_rate": (">=", 0.97),
    "fit_valid_precision": (">=", 0.995),
    "fit_valid_rate": (">=", 0.90),
    "fit_median_position_error_m": ("<=", 0.01),
    "fit_p95_position_error_m": ("<=", 0.03),
}

#: The floors on the study's totals in the ideal world: (comparison, value). Issue 5's,
#: raised by issue 12 (right link, position, valid precision and coverage, and "more than
#: one contact" on single contacts).
FLOORS = {
    "detection_rate": (">=", 0.99),
    "median_detection_delay_s": ("<=", 0.020),
    "false_detections": ("<=", 0),
    "correct_link_rate": (">=", 0.97),
    "median_position_error_m": ("<=", 0.01),
    "p95_position_error_m": ("<=", 0.03),
    "median_force_error_rel": ("<=", 0.05),
    "median_angle_error_deg": ("<=", 5.0),
    "valid_precision": (">=", 0.995),
    "valid_rate": (">=", 0.90),
    "more_than_one_contact_rate": ("<=", 0.02),
    "median_localizer_update_ms": ("<=", 2.0),
    **STACKED_FIT_FLOORS,
}

#: The floors for the realistic world, after model refinement: issue 11's (detection,
#: false detections, force), raised by issue 12's single-contact floors, which hold for
#: "the default noisy column" too (right link, position, valid precision and coverage,
#: "more than one contact", update time).
REALISTIC_FLOORS = {
    "detection_rate": (">=", 0.98),
    "false_detections": ("<=", 0),
    "correct_link_rate": (">=", 0.97),
    "median_position_error_m": ("<=", 0.01),
    "p95_position_error_m": ("<=", 0.03),
    "median_force_error_rel": ("<=", 0.10),
    "valid_precision": (">=", 0.995),
    "valid_rate": (">=", 0.90),
    "more_than_one_contact_rate": ("<=", 0.02),
    "median_localizer_update_ms": ("<=", 2.0),
    **STACKED_FIT_FLOORS,
}

#: Issue 12's floors for two simultaneous contacts (``contacts`` 2), in both worlds.
TWO_CONTACT_FLOORS = {
    "detection_rate": (">=", 0.99),
    "false_detections": ("<=", 0),
    "both_links_right_rate": (">=", 0.80),
    "median_contact_position_error_m": ("<=", 0.03),
    "median_contact_force_error_rel": ("<=", 0.10),
    "more_than_one_contact_rate": (">=", 0.90),
}


#: Issue 36's floors for one contact on a robot without foot F/T sensors (the ground's
#: wrenches unknowns of the estimators), per body region (``REGIONS``), in both worlds.
NO_FOOT_FT_FLOORS = {
    "detection_rate": (">=", 0.99),
    "false_detections": ("<=", 0),
    "correct_link_rate_arms": (">=", 0.90),
    "correct_link_rate_torso": (">=", 0.90),
    "correct_link_rate_legs": (">=", 0.70),
    "fit_correct_link_rate_arms": (">=", 0.90),
    "fit_correct_link_rate_torso": (">=", 0.90),
    "fit_correct_link_rate_legs": (">=", 0.70),
    "median_position_error_m": ("<=", 0.02),
    "fit_median_position_error_m": ("<=", 0.02),
    "foot_normal_force_rms_error_valid_of_weight": ("<=", 0.05),
}

#: ``NO_FOOT_FT_FLOORS`` for a robot whose feet have FSRs: their normal forces are measured,
#: not estimated, so the sole force floor has nothing to judge.
FSR_FEET_FLOORS = {k: v for k, v in NO_FOOT_FT_FLOORS.items() if not k.startswith("foot_normal_force")}


def lacks_foot_ft_sensors(model: str) -> bool:
    """Whether the humanoid ``model`` (a built-in name or a robot description) has a foot
    without an F/T sensor (False for anything else)."""
    if not is_humanoid(model):
        return False
    return any(foot.sensing != "force_torque" for foot in robot_description(model).feet.values())


def has_fsr_feet(model: str) -> bool:
    """Whether the humanoid ``model`` has a foot with FSRs (``sensing: fsr``): their normal
    forces are measurements, not estimates of the study (False for anything else)."""
    if not is_humanoid(model):
        return False
    return any(foot.sensing == "fsr" for foot in robot_description(model).feet.values())


def floors_for(scenario: "ContactLocalizationScenario") -> dict:
    """``TWO_CONTACT_FLOORS`` for two contacts; ``NO_FOOT_FT_FLOORS`` on a robot without
    foot F/T sensors (``FSR_FEET_FLOORS`` where FSRs measure the sole forces); else ``FLOORS``
    in the ideal world, ``REALISTIC_FLOORS`` otherwise (any imperfection, the EKF base state
    or a refined model)."""
    if scenario.contacts == 2:
        return TWO_CONTACT_FLOORS
    if lacks_foot_ft_sensors(scenario.station.model):
        return FSR_FEET_FLOORS if has_fsr_feet(scenario.station.model) else NO_FOOT_FT_FLOORS
    return FLOORS if scenario.station.is_ideal else REALISTIC_FLOORS


#: The random contacts of the localization study (``sample_trials``): force magnitude, N,
#: and the largest angle between the force and the surface's inward normal, deg.
MIN_FORCE, MAX_FORCE, MAX_ANGLE_DEG = 5.0, 40.0, 60.0


@dataclass
class ContactLocalizationScenario:
    """The contact study, and one run of its diagram. SI units.

    Attributes:
        station: the robot (``hrp4_like``, or any humanoid description: its feet with F/T
            sensors, FSRs or no sensing) and its world (``diagrams.station.config``):
            realistic by default, ideal with ``--ideal``. Its ``seed`` is the sensor noise
            seed of one run; the study's first seed, from which it samples the trials and
            derives each run's noise seed.
        push_body: the pushed link, or None for a run without contact (the study sets each
            trial's push_body, push_point, push_force and seed from ``sample_trials``).
        push_point: the contact point in the link's body frame, m.
        push_force: the (constant) force in world, N.
        push_start: s; the force is on for push_start <= t < push_start + push_duration
            (the study: the first trial of each run).
        push_duration: s (the study's contact duration).
        trial_gap: the study's pause between two trials of one run, s (with
            ``trials_per_run`` > 1).
        trials_per_run: the study's trials simulated one after another in one run
            (``run_schedule``), ``trial_gap`` apart, the robot and the residuals coming
            back to rest in between; 1 (default): each trial from the standing start, as
            in the paper. Runs of several trials test a robot that has been pushed
            before (when this was measured its feet slipped, and the realistic world's
            detector did not always release within the gap; see the git history of
            BENCHMARKS.md).
        shared_standing_start: with ``trials_per_run`` 1, the study simulates the standing
            start (the first ``push_start`` seconds) once per job of trials and restores its
            state before each trial's push (``diagrams.residuals.contact_trials.run_trials``): the
            same start as simulating it for each trial, at a third less simulated time per
            trial (1 s pushes). The trials' pushes then follow one another in time, so each
            push sees sensor noise of its own; what the trials of one job share is the
            noise of the start. False: each trial simulates its own standing start.
        num_seeds: the study samples its trials from the seeds s, s + 1, ...,
            s + num_seeds - 1 (s: ``station.seed``) (``trials`` split evenly; a figure that holds on one seed
            only is not a result).
        trials: the study's number of random contacts (over all its seeds).
        contacts: contacts per trial: 1, or 2 (two links pushed at once; ``sample_trials``).
        force_range: the pushes' magnitudes are drawn uniformly in [min, max], N.
        multi_contact: the study also localizes each trial's averaged inputs with the
            one-or-two-contact ``MultiContactLocalizer`` (``multi_contact_result``; always
            with ``contacts`` 2): how often it says "more than one contact". Its tests
            whiten with the averaged sensor noise (``averaged_input_covariances``) and the
            model error under load measured on the other seeds' trials, whose contacts
            are known (``load_model_error``, ``cross_fitting_folds``).
        no_contact_duration: the study's run without contact, standing (false detections),
            s; 0 skips it.
        slow_motion_duration: the study's run without contact during ``slow_motion`` (false
            detections while the whole body moves slowly), s; 0 skips it.
        slow_motion: that run's motion (``diagrams.station.motions``; a different seed from
            the calibration motion's).
        motion: the posture motion of one run (None: holding the standing posture; the
            study sets it for its slow-motion run).
        internal_gain, external_gain: residual gains K, 1/s.
        period: residual/detector/localizer period, s.
        settle_time: the localizer's wait after detection before averaging, s.
        localization_period: s between two localizations while in contact (the localizer
            averages its inputs every ``period`` all the same; None: every update).
        detector_release_probability: the detector's p_off (``ContactDetector``'s
            release_probability): it switches off when both test statistics stay below
            their chi-square (1 - p_off)-quantiles for 20 ms.
        detector_startup_time: the detector stays off for this long after the start, s (the
            residuals' and the base-state estimator's start-up; a push that starts earlier is
            detected only from then on).
        log_period: period of the loggers (detector outputs, residuals), s; the localizer's
            outputs are logged every ``localization_period`` (its rate of estimates).
        estimation: where the residuals, the detector and the localizer run: "offline"
            (the study's default) simulates the robot, its sensors and its base-state
            estimator with the estimators' inputs logged at every update, and runs the
            estimators on that log afterwards (``systems.residuals.offline``, their own
            update code, stacked over the samples); "online" runs them in the diagram. They
            do not act on the robot here (no admittance), so both give the same results to
            rounding (``tests/test_contact_localization.py``); offline costs a fraction
            of the per-step time of Python systems in the loop. The Meshcat replays run
            online (they draw the estimate as it comes).
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``); the plant
            is discrete, so only ``target_realtime_rate`` and the publishing matter.
    """

    station: StationConfig = field(default_factory=StationConfig.realistic)
    push_body: str | None = None
    push_point: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    push_force: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    push_start: float = 0.5
    push_duration: float = 0.5
    trial_gap: float = 0.4
    trials_per_run: int = 1
    shared_standing_start: bool = True
    num_seeds: int = 5
    trials: int = 1000
    contacts: int = 1
    force_range: list[float] = field(default_factory=lambda: [MIN_FORCE, MAX_FORCE])
    multi_contact: bool = True
    no_contact_duration: float = 60.0
    slow_motion_duration: float = 60.0
    slow_motion: SlowMotion = field(default_factory=lambda: SlowMotion(seed=3, amplitude_scale=0.5))
    motion: SlowMotion | None = None
    internal_gain: float = 35.0
    external_gain: float = 35.0
    period: float = 1e-3
    settle_time: float = 0.1
    localization_period: float | None = 0.01
    detector_release_probability: float = 1e-2
    detector_startup_time: float = 0.1
    log_period: float = 1e-3
    estimation: str = "offline"
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)


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


#: ``ContactLocalizationScenario.estimation`` values.
ESTIMATIONS = ("offline", "online")


def scenario_push(scenario: ContactLocalizationScenario) -> Push:
    """The push of a one-push ``scenario`` (its push_body, push_point, push_force,
    push_start and push_duration).

    Raises:
        ValueError: a zero force.
    """
    force = np.asarray(scenario.push_force, dtype=float)
    magnitude = float(np.linalg.norm(force))
    if magnitude == 0.0:
        raise ValueError("push_force must be non-zero (use push_body=None for no contact)")
    return Push(
        scenario.push_body,
        np.asarray(scenario.push_point, dtype=float),
        force / magnitude,
        Step(magnitude, scenario.push_start, scenario.push_start + scenario.push_duration),
    )


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


#: Body regions of the study's per-region table (``body_regions``).
REGIONS = ("arms", "torso", "legs")
_GROUP_REGIONS = {
    "left_arm": "arms",
    "right_arm": "arms",
    "left_hand": "arms",
    "right_hand": "arms",
    "torso": "torso",
    "head": "torso",
    "left_leg": "legs",
    "right_leg": "legs",
}


def body_regions(plant: MultibodyPlant, humanoid) -> dict[str, str]:
    """Body name -> "arms", "torso" or "legs", from the joint group of the first grouped
    joint inboard of the body (``HumanoidHandles.joint_groups``; hands count as arms, the
    head as torso); the base and bodies inboard of every grouped joint are "torso"."""
    group_of = {
        j: _GROUP_REGIONS[g] for g, joints in humanoid.joint_groups.items() if g in _GROUP_REGIONS for j in joints
    }
    inboard = {}
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        inboard[int(joint.child_body().index())] = joint
    regions = {}
    for b in range(plant.num_bodies()):
        body, region = plant.get_body(BodyIndex(b)), "torso"
        joint = inboard.get(b)
        while joint is not None:
            if joint.name() in group_of:
                region = group_of[joint.name()]
                break
            joint = inboard.get(int(joint.parent_body().index()))
        regions[body.name()] = region
    return regions


def sample_trials(
    model: str,
    trials: int,
    seed: int,
    contacts: int = 1,
    force_range: Sequence[float] = (MIN_FORCE, MAX_FORCE),
) -> list[dict]:
    """Random contacts at the standing pose: link uniform over the candidate links, point
    uniform (by area) on the link's collision surface but not inside another link's
    primitive (the outer surface), direction within 60 deg of the inward normal, magnitude
    uniform in ``force_range`` (default [5, 40] N); with ``contacts`` = 2, two such contacts on two different links
    (pushed together). Deterministic from ``seed`` (trial i draws from
    ``default_rng([seed, i])``; a two-contact trial's first contact is the one-contact
    trial's); builds the diagram once, does not simulate.

    Returns one dict per trial: ``trial``, ``noise_seed``, ``contacts`` (one dict per
    contact: ``body``, ``body_index``, ``region`` (``body_regions``), ``geometry``,
    ``point_body`` (m, body frame), ``point_world_nominal`` (m), ``force_world`` (N)), and
    the first contact's fields at the top level.

    Raises:
        ValueError: ``contacts`` other than 1 or 2, or a ``force_range`` that is not
            [min, max] with 0 < min <= max, finite.
    """
    if contacts not in (1, 2):
        raise ValueError(f"contacts must be 1 or 2, got {contacts!r}")
    low, high = check_force_range(force_range)
    _, handles = build_contact_localization_diagram(
        ContactLocalizationScenario(station=StationConfig(model=model, noise=False))
    )
    # The contacts are drawn on the simulated robot's own collision surfaces (the localizer's
    # candidate links: every link but the soles).
    plant = handles.plant
    geo, bodies = candidate_geometry(plant, handles.scene_graph, None, handles.excluded_bodies, "sample_trials")
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, handles.station.initial_state)
    X_WB = np.array([plant.EvalBodyPoseInWorld(context, b).GetAsMatrix34() for b in bodies])
    R_WG, p_WG = geo.world_poses(X_WB)
    areas = surface_areas(geo.kinds, geo.params)
    links = np.unique(geo.body_indices)
    regions = body_regions(plant, handles.station.humanoid)

    def draw(rng: np.random.Generator, other_than: int | None) -> dict:
        for _ in range(1000):
            link = rng.choice(links)
            if link == other_than:
                continue
            rows = np.flatnonzero(geo.body_indices == link)
            g = rng.choice(rows, p=areas[rows] / areas[rows].sum())
            p_G, n_G = sample_surface(geo.kinds[g], geo.params[g], rng)
            p_W = R_WG[g] @ p_G + p_WG[g]
            if geo.outside_other_links(p_W, R_WG, p_WG, link) and p_W[2] > 0.02:  # outer surface, above the ground
                break
        n_W = R_WG[g] @ n_G
        X = X_WB[int(np.searchsorted(geo.bodies, link))]
        force = rng.uniform(low, high) * inward_direction(n_W, rng, MAX_ANGLE_DEG)
        name = plant.get_body(BodyIndex(int(link))).name()
        return {
            "body": name,
            "body_index": int(link),
            "region": regions[name],
            "geometry": geo.names[g],
            "point_body": (X[:, :3].T @ (p_W - X[:, 3])).tolist(),
            "point_world_nominal": p_W.tolist(),
            "force_world": force.tolist(),
        }

    specs = []
    for i in range(trials):
        rng = np.random.default_rng([seed, i])
        drawn = [draw(rng, None)]
        if contacts == 2:
            drawn.append(draw(rng, drawn[0]["body_index"]))
        specs.append({"trial": i, **drawn[0], "contacts": drawn, "noise_seed": (seed * 100003 + i) % (2**31 - 1)})
    return specs


def check_force_range(force_range: Sequence[float]) -> tuple[float, float]:
    """(min, max) of a push magnitude range, N.

    Raises:
        ValueError: not two finite numbers with 0 < min <= max.
    """
    try:
        low, high = (float(f) for f in force_range)
    except (TypeError, ValueError):
        raise ValueError(f"force_range must be [min, max] in N, got {force_range!r}") from None
    if not (math.isfinite(high) and 0.0 < low <= high):
        raise ValueError(f"force_range must be [min, max] with 0 < min <= max, finite, got {list(force_range)!r}")
    return low, high


def sample_study_trials(scenario: ContactLocalizationScenario) -> list[dict]:
    """The study's ``trials`` random contacts over its ``num_seeds`` seeds (``sample_trials``
    of seed, seed + 1, ...; the trials split as evenly as they go, the first seeds taking
    the remainder), numbered 0, 1, ... across the seeds; each spec also names its
    ``seed``."""
    specs = []
    per_seed, extra = divmod(scenario.trials, scenario.num_seeds)
    for k in range(scenario.num_seeds):
        count = per_seed + (1 if k < extra else 0)
        seed = scenario.station.seed + k
        trials = (
            sample_trials(scenario.station.model, count, seed, scenario.contacts, scenario.force_range) if count else []
        )
        for spec in trials:
            specs.append({**spec, "trial": len(specs), "seed": seed, "trial_of_seed": spec["trial"]})
    return specs


def trial_scenario(scenario: ContactLocalizationScenario, spec: dict) -> ContactLocalizationScenario:
    """The run of the trial ``spec`` (``sample_trials``) alone: ``scenario`` with its push and
    noise seed."""
    return dataclasses.replace(
        replace_station(scenario, seed=spec["noise_seed"]),
        push_body=spec["body"],
        push_point=list(spec["point_body"]),
        push_force=list(spec["force_world"]),
    )


def run_schedule(
    scenario: ContactLocalizationScenario, specs: Sequence[dict]
) -> tuple[list[Push], list[tuple], list[list[int]]]:
    """The trials ``specs`` one after another in one run: trial k pushes (each of its
    contacts) from push_start + k (push_duration + trial_gap) for push_duration. Returns
    the pushes, each trial's window (previous trial's end or 0, push start, push end, s)
    and the indices of each trial's pushes in the push list."""
    pushes, windows, indices = [], [], []
    previous_end = 0.0
    for k, spec in enumerate(specs):
        start = scenario.push_start + k * (scenario.push_duration + scenario.trial_gap)
        one = dataclasses.replace(scenario, push_start=start)
        indices.append([])
        for contact in spec.get("contacts", [spec]):
            indices[-1].append(len(pushes))
            pushes.append(scenario_push(trial_scenario(one, {**contact, "noise_seed": spec["noise_seed"]})))
        windows.append((previous_end, start, start + scenario.push_duration))
        previous_end = start + scenario.push_duration
    return pushes, windows, indices


def no_contact_scenario(scenario: ContactLocalizationScenario) -> ContactLocalizationScenario:
    """The study's run without contact, standing: no push, its own noise seed (derived from
    the study's)."""
    seed = (scenario.station.seed * 100003 + 99991) % (2**31 - 1)
    return dataclasses.replace(replace_station(scenario, seed=seed), push_body=None, motion=None)


def slow_motion_scenario(scenario: ContactLocalizationScenario) -> ContactLocalizationScenario:
    """The study's run without contact during its slow whole-body motion (``slow_motion``,
    ``slow_motion_duration``): no push, its own noise seed."""
    seed = (scenario.station.seed * 100003 + 99989) % (2**31 - 1)
    return dataclasses.replace(
        replace_station(scenario, seed=seed),
        push_body=None,
        motion=scenario.slow_motion,
        no_contact_duration=scenario.slow_motion_duration,
    )


#: The averaged-input noise calibration's run without contact: its length and the start-up
#: it leaves out, s.
AVERAGED_NOISE_RUN_S, AVERAGED_NOISE_STARTUP_S = 3.0, 0.5


def averaged_input_covariances(
    scenario: ContactLocalizationScenario, model_corrections: ModelCorrections | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The noise of the localizer's averaged inputs without contact, for the multi-contact
    fit's chi-square tests: (external wrench 6 x 6 ([moment about the world origin; force],
    N m, N), internal residual n x n). Measured on a 3 s run without contact (its own noise
    seed; the first 0.5 s left out) as mu mu^T + Sigma 2 / (K T): the residuals' mean mu
    (model error: averaging does not remove it) plus their sample covariance Sigma scaled
    to the variance of a mean over T = push_duration - settle_time (a first-order residual
    of gain K, driven by white noise, has var(mean over T) = Sigma 2 / (K T) for T >> 1/K).
    On a robot without foot F/T sensors the residuals carry the ground's wrenches, which
    are unknowns of the fit, not model error: mu is the mean after each sample's
    least-squares ground wrenches (at the run's mean posture) are taken out (Sigma stays
    the raw residuals', whose sway of the ground wrenches the fit's projection removes).
    """
    seed = (scenario.station.seed * 100003 + 99971) % (2**31 - 1)
    calibration = dataclasses.replace(replace_station(scenario, seed=seed), push_body=None, motion=None)
    diagram, handles = build_contact_localization_diagram(
        calibration, model_corrections=model_corrections, online=False
    )
    simulate(diagram, AVERAGED_NOISE_RUN_S, set_initial_state=handles.station.set_initial_state)
    inputs = estimator_log(handles)
    replay = estimate_run(handles, inputs)
    keep = inputs.log_times >= AVERAGED_NOISE_STARTUP_S
    raw = np.concatenate((replay.external_wrench_world, replay.internal), axis=1)[keep]
    unexplained = raw
    estimator = handles.station.estimator
    if estimator.unknown_wrench_frames:
        kin = _SensedConfiguration(estimator.plant, "averaged_input_covariances")
        q = inputs.state[keep, : kin.nq].mean(axis=0)
        q[:4] /= np.linalg.norm(q[:4])
        kin.set_positions(q)
        unknown = UnknownWrenches(
            estimator.plant,
            estimator.unknown_wrench_frames,
            estimator.unknown_wrench_components,
            "averaged_input_covariances",
        )
        U = unknown.columns(kin)
        unexplained = raw - (U @ np.linalg.lstsq(U, raw.T, rcond=None)[0]).T
    blocks = []
    for rows, gain in ((slice(0, 6), scenario.external_gain), (slice(6, None), scenario.internal_gain)):
        x = raw[:, rows].T
        mean = unexplained[:, rows].mean(axis=0)
        averaging = max(scenario.push_duration - scenario.settle_time, scenario.period)
        blocks.append(np.outer(mean, mean) + np.cov(x) * min(1.0, 2.0 / (gain * averaging)))
    return blocks[0], blocks[1]


def multi_contact_localizer(
    handles: ContactLocalizationHandles,
    covariances: tuple[np.ndarray, np.ndarray],
    load_covariances: tuple[np.ndarray, np.ndarray] | None = None,
) -> MultiContactLocalizer:
    """The study's one-or-two-contact localizer on the estimators' plant of ``handles`` (keep
    them alive with it), the soles excluded, with the averaged inputs' ``covariances``
    (``averaged_input_covariances``) and, if given, the model error under load
    (``load_model_error``). On a robot without foot F/T sensors the soles' ground wrenches
    are its unknowns, and the load model is left out: it scales with the external
    residual's force, there the robot's weight as much as the push."""
    estimator = handles.station.estimator
    unknown = estimator.unknown_wrench_frames
    load_ext, load_int = (None, None) if load_covariances is None or unknown else load_covariances
    return MultiContactLocalizer(
        estimator.plant,
        estimator.scene_graph,
        exclude_bodies=handles.excluded_bodies,
        covariance_external=covariances[0],
        covariance_internal=covariances[1],
        load_covariance_external=load_ext,
        load_covariance_internal=load_int,
        unknown_wrench_frames=unknown,
        unknown_wrench_components=estimator.unknown_wrench_components,
    )


#: The fewest detected pushes of known force ``load_model_error`` measures the model error
#: on (fewer: the multi-contact fit whitens with the sensor noise alone).
MIN_LOAD_CALIBRATION_TRIALS = 20


def load_model_error(plant: MultibodyPlant, trials: Sequence[dict]) -> tuple[np.ndarray, np.ndarray]:
    """The residuals' error under load, per N^2 of the total external force, measured on
    pushes of known points and forces (the study's trials: each with its
    ``localizer_inputs`` and its ``contacts``): for trial k, e_k = b_k - sum_c A_c f_c, b_k
    the averaged [external wrench; internal residual] its localization used and A_c f_c
    what the true contact c predicts at the averaged q (eq. 20: [p_c x f_c; f_c] and
    J^fb_c^T f_c). Returns (sum_k e_ext e_ext^T, sum_k e_int e_int^T) / sum_k |F_k|^2, F_k
    the trial's total force: the ``load_covariance_external`` and ``_internal`` of
    ``MultiContactLocalizer``. The model error of a refined model under load (friction,
    inertial and torque-scale errors; the base-state estimator's errors) grows with the
    load; e_k also holds the averaged sensor noise, which makes the figure an upper bound.

    Raises:
        ValueError: no trial, or a trial without its inputs or contacts.
    """
    if not trials:
        raise ValueError("load_model_error needs at least one push of known force")
    kin = _SensedConfiguration(plant, "load_model_error")
    n = plant.num_velocities() - 6
    sum_ext, sum_int, load = np.zeros((6, 6)), np.zeros((n, n)), 0.0
    for trial in trials:
        try:
            inputs, contacts = trial["localizer_inputs"], trial.get("contacts", [trial])
            q = np.asarray(inputs["q"], dtype=float)
            wrench = np.asarray(inputs["external_wrench_world"], dtype=float)
            residual = np.asarray(inputs["residual"], dtype=float)
        except KeyError as missing:
            raise ValueError(f"load_model_error: trial {trial.get('trial')!r} has no {missing}") from None
        kin.set_positions(q)
        predicted_ext, predicted_int, total = np.zeros(6), np.zeros(n), np.zeros(3)
        for contact in contacts:
            body = plant.get_body(BodyIndex(int(contact["body_index"])))
            p_B = np.asarray(contact["point_body"], dtype=float)
            X_WB = kin.body_pose(body)
            p_W = X_WB[:, :3] @ p_B + X_WB[:, 3]
            f_W = np.asarray(contact["force_world"], dtype=float)
            predicted_ext += np.concatenate((np.cross(p_W, f_W), f_W))
            predicted_int += kin.floating_jacobian(body, p_B).T @ f_W
            total += f_W
        e_ext, e_int = wrench - predicted_ext, residual - predicted_int
        sum_ext += np.outer(e_ext, e_ext)
        sum_int += np.outer(e_int, e_int)
        load += float(total @ total)
    if not load > 0.0:
        raise ValueError("load_model_error: the pushes' total force is zero")
    return sum_ext / load, sum_int / load


def cross_fitting_folds(trials: Sequence[dict]) -> list[list[int]]:
    """The folds of the study's cross-fitting: the indices of ``trials`` per seed (with two
    or more seeds), else the even and the odd trials. Each fold's multi-contact fit uses the
    model error measured on the other folds (``load_model_error``), never on its own trials."""
    seeds = sorted({trial.get("seed", 0) for trial in trials})
    if len(seeds) >= 2:
        return [[i for i, trial in enumerate(trials) if trial.get("seed", 0) == seed] for seed in seeds]
    return [list(range(0, len(trials), 2)), list(range(1, len(trials), 2))]


def time_localizer_update(handles: ContactLocalizationHandles, context: Context, repeats: int = 20) -> float:
    """Median wall time [s] of one ContactLocalizer update with the trial's final inputs,
    each call at a slightly different q (so that no pose or mass matrix is reused)."""
    localizer = handles.localizer
    lc = localizer.GetMyContextFromRoot(context)
    x = np.array(localizer.GetInputPort("state").Eval(lc))
    probe = localizer.CreateDefaultContext()
    state_value = localizer.GetInputPort("state").FixValue(probe, x)
    for name in ("external_wrench_world", "residual", "contact_detected"):
        localizer.GetInputPort(name).FixValue(probe, np.array(localizer.GetInputPort(name).Eval(lc)))
    localizer.GetInputPort("contact_detected").FixValue(probe, [1.0])

    def update(x2: np.ndarray) -> None:
        state_value.GetMutableData().set_value(x2)
        localizer.EvalUniquePeriodicDiscreteUpdate(probe)

    return _median_update_time(update, x, handles.plant.num_positions(), repeats)


def time_localizer_advance(
    localizer: ContactLocalizer, x: np.ndarray, w: np.ndarray, r: np.ndarray, repeats: int = 20
) -> float:
    """``time_localizer_update`` without a diagram (offline estimation): the median wall
    time [s] of one update (``advance``, the code of the periodic update) from a new
    context's state with contact detected, at the inputs x, w, r."""
    start = localizer.initial_state()

    def update(x2: np.ndarray) -> None:
        localizer.advance(start, 0.0, x2, w, r, True)

    nq = len(x) - (len(r) + 6)  # x = [q; v], v = 6 base + n joint velocities
    return _median_update_time(update, np.array(x), nq, repeats)


def _median_update_time(update, x: np.ndarray, nq: int, repeats: int) -> float:
    rng = np.random.default_rng(0)
    samples = []
    for _ in range(repeats):
        x2 = x.copy()
        x2[7:nq] += 1e-6 * rng.normal(size=nq - 7)
        start = time.perf_counter()
        update(x2)
        samples.append(time.perf_counter() - start)
    return float(np.median(samples))


@dataclass
class EstimatorLog:
    """The estimators' inputs at every update of a run built with ``online=False``, in the
    order the updates ran: their times (N,), s, the times the online systems' outputs of
    each update would be logged (the next update's), and per update the sensed state
    [q; v], the motor torque the internal residual reads and the F/T wrenches in world.
    On a robot without foot F/T sensors also the simulator's normal force on each foot
    contact sphere (``FSR_NAMES`` order, N): ground truth for the metrics, which no
    estimator reads ((N, 0) otherwise)."""

    update_times: np.ndarray
    log_times: np.ndarray
    state: np.ndarray
    torque: np.ndarray
    wrenches: np.ndarray
    true_fsr_forces: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def estimator_log(handles: ContactLocalizationHandles) -> EstimatorLog:
    """The ``EstimatorLog`` of a run so far (its ``recorder``'s records)."""
    recorder = handles.recorder
    if recorder is None:
        raise ValueError("estimator_log: the estimators ran in the diagram (online): nothing was recorded")
    times = recorder.times
    period = handles.internal.period
    return EstimatorLog(
        update_times=times,
        log_times=np.append(times[1:], times[-1] + period) if times.size else times,
        state=recorder.values("state"),
        torque=recorder.values("torque"),
        wrenches=recorder.values("wrenches") if "wrenches" in recorder.names else np.zeros((times.size, 0)),
        true_fsr_forces=recorder.values("true_fsr_forces")
        if "true_fsr_forces" in recorder.names
        else np.zeros((times.size, 0)),
    )


def estimate_run(
    handles: ContactLocalizationHandles, log: EstimatorLog, start: ReplayState | None = None
) -> ReplayedEstimation:
    """The handles' residuals, detector and localizer run on the updates of ``log``
    (``replay_contact_estimation``), going on from ``start`` (the ``end`` of the updates
    before them; None: the run's first updates). The localizer's result is its
    state after the last update (what the study reads at a trial's end: ``end``)."""
    return replay_contact_estimation(
        handles.internal,
        handles.external,
        lambda *_: handles.detector,
        handles.localizer,
        log.state,
        log.torque,
        log.wrenches,
        start=start,
        times=log.update_times,
        localize_end_only=True,
    )


@dataclass
class OfflineTrial:
    """One trial's estimation from the log (``estimate_run``), as ``trial_result`` reads
    it: per logged update (log times, the window's updates and, for a run's first trial,
    the standing start's before them) the detector's flag and the time its detection began,
    the localization at the end, the inputs it was computed from ((q, wrench, residual),
    ``ContactLocalizer.localization_inputs``), and the last sensed state, external wrench
    and internal residual (the localizer's update time is measured at them)."""

    log_times: np.ndarray
    detected: np.ndarray
    detection_time: np.ndarray
    estimate: LocalizationResult
    localization_inputs: tuple[np.ndarray, np.ndarray, np.ndarray]
    last_inputs: tuple[np.ndarray, np.ndarray, np.ndarray]
    true_fsr_forces: np.ndarray | None = None


def offline_trial(
    handles: ContactLocalizationHandles,
    segments: Sequence[tuple[EstimatorLog, ReplayedEstimation]],
    detected_before: bool,
) -> OfflineTrial:
    """The ``OfflineTrial`` of one trial's replayed segments ``(log, replay)``
    (``estimate_run``), in time order, the last one ending at the trial's end;
    ``detected_before``: the detector's flag before the first of them."""
    times = np.concatenate([log.log_times for log, _ in segments])
    update_times = np.concatenate([log.update_times for log, _ in segments])
    detected = np.concatenate([replay.contact_detected for _, replay in segments])
    # The detector's detection_time output: the time of the update at which it last switched on.
    rising = np.flatnonzero(np.diff(np.concatenate(([detected_before], detected)).astype(np.int8)) > 0)
    since = np.full(detected.size, -1)
    since[rising] = rising
    since = np.maximum.accumulate(since)
    detection_time = np.where(since >= 0, update_times[np.maximum(since, 0)], 0.0)
    log, last = segments[-1]
    localizer = handles.localizer
    end = last.end.localizer
    truth = None
    forces = np.concatenate([log.true_fsr_forces for log, _ in segments])
    if forces.size:
        # The truth over the window the localizer's means average (else the last update).
        start = localizer.averaging_start(end[0])
        inside = update_times >= start if start is not None else np.zeros(update_times.size, dtype=bool)
        truth = forces[inside].mean(axis=0) if inside.any() else forces[-1]
    return OfflineTrial(
        log_times=times,
        detected=detected.astype(float),
        detection_time=detection_time,
        estimate=localizer.unpack(end[3]),
        localization_inputs=localizer.split_localized(end[2]),
        last_inputs=(log.state[-1], last.external_wrench_world[-1], last.internal[-1]),
        true_fsr_forces=truth,
    )


def trial_result(
    scenario: ContactLocalizationScenario,
    spec: dict,
    handles: ContactLocalizationHandles,
    context: Context,
    wall_time_s: float,
    *,
    push_indices: Sequence[int] = (0,),
    window: tuple[float, float, float] | None = None,
    restored_at_start: bool = False,
    detected_at_start: bool = False,
    offline: OfflineTrial | None = None,
) -> dict:
    """The results of the trial ``spec`` at the end of its push, from the simulator's root
    ``context``: detection and its delay, the localized link and point, the force errors,
    and the localizer's update time (module docstring); ``wall_time_s``: the simulation's
    wall time. The trial is the pushes ``push_indices`` of the run (one per contact; the
    single-contact localizer's figures are for the first), in ``window`` (previous
    trial's end, push start, push end; default: the scenario's one push,
    ``trial_scenario``): a detection in the window before the push is a false detection,
    and a detector still on at the push's start (a contact that never ended) leaves the
    push undetected. ``localizer_inputs`` holds the (averaged) q, external wrench and
    internal residual of the final localization, as arrays
    (``ContactLocalizer.localization_inputs``: the study's localizations can be replayed
    offline; the study's one-or-two-contact localization, ``multi_contact_result``, runs on
    them after all trials). ``restored_at_start``: the run's state was
    restored to its standing start at the window's start (``shared_standing_start``), so
    the detector's flag there is the saved start's, ``detected_at_start``, whatever the
    log's last sample before it says. ``offline``:
    the trial's estimation from the log (``online=False`` diagrams), read instead of the
    online estimators' loggers and state."""
    if window is None:
        window = (0.0, scenario.push_start, scenario.push_start + scenario.push_duration)
    previous_end, push_start, t_end = window
    if offline is None:
        estimate = handles.localizer.estimate(handles.localizer.GetMyContextFromRoot(context))
        log = handles.loggers["contact_detected"].FindLog(context)
        t, detected = log.sample_times(), log.data()[0]
        times = handles.loggers["detection_time"].FindLog(context).data()[0]
    else:
        estimate = offline.estimate
        t, detected, times = offline.log_times, offline.detected, offline.detection_time
    pc = handles.push_source.GetMyContextFromRoot(context)
    points = np.array(handles.push_source.GetOutputPort("point_world").Eval(pc)).reshape(-1, 3)
    true_points = points[list(push_indices)]
    true_point = true_points[0]
    f_true = np.asarray(spec["force_world"])

    before = t <= previous_end
    if restored_at_start:
        state_before = 1.0 if detected_at_start else 0.0
    else:
        state_before = detected[before][-1] if before.any() else 0.0
    inside = ~before & (t <= t_end)
    t, detected, times = t[inside], detected[inside], times[inside]
    rising = np.flatnonzero(np.diff(np.concatenate(([state_before], detected))) > 0.5)
    false_before = int(np.sum(t[rising] < push_start))
    at_start = t < push_start
    on_at_start = bool(detected[at_start][-1] > 0.5) if at_start.any() else state_before > 0.5
    during = (t >= push_start) & (detected > 0.5)
    result = {
        **spec,
        "detected": bool(during.any()) and not on_at_start,
        "detector_on_at_push_start": on_at_start,
        "false_detections_before_push": false_before,
        "detection_delay_s": None,
        "status": estimate.status,
        "status_reason": estimate.reason,
        "estimated_body_index": estimate.body_index,
        "estimated_body": handles.plant.get_body(BodyIndex(estimate.body_index)).name()
        if estimate.body_index >= 0
        else None,
        "correct_link": handles.localizer.same_link(estimate.body_index, spec["body_index"]),
        "position_error_m": None,
        "force_error_rel": None,
        "angle_error_deg": None,
        "score": estimate.score if math.isfinite(estimate.score) else None,
        "runner_up_score": estimate.runner_up_score if math.isfinite(estimate.runner_up_score) else None,
        "true_point_world": true_point.tolist(),
        "estimated_point_world": estimate.point_W.tolist(),
        "estimated_force_world": estimate.force_W.tolist(),
        "simulation_wall_s": wall_time_s,
    }
    if result["detected"]:
        first = np.flatnonzero(during)[0]
        result["detection_delay_s"] = float(times[first] - push_start)
        f_hat = estimate.force_W
        result["force_error_rel"] = float(np.linalg.norm(f_hat - f_true) / np.linalg.norm(f_true))
        cos = float(f_hat @ f_true / max(np.linalg.norm(f_hat) * np.linalg.norm(f_true), 1e-300))
        result["angle_error_deg"] = math.degrees(math.acos(min(1.0, max(-1.0, cos))))
    if estimate.body_index >= 0:
        result["position_error_m"] = float(np.linalg.norm(estimate.point_W - true_point))
    if offline is None:
        result["localizer_update_s"] = time_localizer_update(handles, context)
        q, wrench, residual = handles.localizer.localization_inputs(handles.localizer.GetMyContextFromRoot(context))
    else:
        result["localizer_update_s"] = time_localizer_advance(handles.localizer, *offline.last_inputs)
        q, wrench, residual = offline.localization_inputs
    result["localizer_inputs"] = {"q": q, "external_wrench_world": wrench, "residual": residual}
    result["true_points_world"] = true_points.tolist()
    if handles.station.estimator.unknown_wrench_frames and not handles.station.estimator.fsr_sides:
        # The ground's normal force on each sole without F/T sensors or FSRs (sides sorted,
        # as the estimators' unknown wrench frames): what the fits estimate (FSRs measure it). Averaged over the
        # window the localizer's means average when the estimators ran offline, else at
        # the push's end.
        plant, humanoid = handles.plant, handles.station.humanoid
        plant_context = plant.GetMyContextFromRoot(context)
        sides = [s for s in sorted(humanoid.sole_frames) if s not in humanoid.ft_sensor_joints]
        if offline is not None and offline.true_fsr_forces is not None:
            per_sphere = offline.true_fsr_forces.reshape(len(FSR_SIDES), -1)
            forces = {side: per_sphere[FSR_SIDES.index(side)] for side in sides}
        else:
            forces = foot_sphere_normal_forces(plant, plant_context, humanoid)
        result["true_foot_normal_forces_N"] = [float(np.sum(forces[s])) for s in sides]
        result["robot_weight_N"] = float(
            plant.CalcTotalMass(plant_context) * -plant.gravity_field().gravity_vector()[2]
        )
    return result


def _not_localized(contacts: int) -> dict:
    """``multi_contact_result`` of a trial without inputs to localize: no contact found."""
    out = {
        "contacts_estimated": 0,
        "p_value_one": None,
        "estimated_contact_bodies": [],
        "estimated_contact_body_names": [],
    }
    if contacts == 1:
        out.update(fit_correct_link=False, fit_valid=False, fit_position_error_m=None)
    else:
        out.update(
            contact_position_errors_m=[math.inf, math.inf],
            contact_force_errors_rel=[math.inf, math.inf],
            two_contact_fit_links_right=False,
            contact_links_right=False,
        )
    return out


def multi_contact_result(
    multi_contact: MultiContactLocalizer,
    q: np.ndarray,
    wrench_W: np.ndarray,
    residual: np.ndarray,
    true_bodies: Sequence[int],
    true_points_W: np.ndarray,
    true_forces_W: np.ndarray,
) -> dict:
    """One trial's one-or-two-contact localization (``MultiContactLocalizer.localize`` on
    the localizer's averaged inputs) against its true contacts: ``contacts_estimated`` (0,
    1 or 2), ``p_value_one`` (the single-contact fit's chi-square p-value); for one true
    contact, the stacked fit as a single-contact localizer: ``fit_correct_link`` (one
    contact reported, on the true link), ``fit_valid`` (``MultiContactResult.valid``) and
    ``fit_position_error_m`` (None unless one contact is reported); and, for two true
    contacts, ``contact_links_right`` (two contacts reported, on the two true
    links) and the position and force errors of the two-contact fit's contacts matched to
    the true ones (the pairing with the smaller total position error)."""
    if not np.any(q):  # the trial was never localized (no detection): its inputs are zeros
        return _not_localized(len(true_bodies))
    estimate = multi_contact.localize(q, wrench_W, residual, max_contacts=2)
    out = {
        "contacts_estimated": int(estimate.num_contacts),
        "p_value_one": None if math.isnan(estimate.p_value_one) else float(estimate.p_value_one),
        "estimated_contact_bodies": [int(b) for b in estimate.body_indices],
        "estimated_contact_body_names": [multi_contact.body_name(b) for b in estimate.body_indices],
    }
    if estimate.one is not None and estimate.one.unknown_wrenches.size and not multi_contact.partly_known_wrenches:
        # The ground's normal force on each sole of the single-contact fit (world z; FSRs
        # measure it where the soles' wrenches are partly known).
        out["foot_normal_forces_N"] = [float(w[5]) for w in estimate.one.unknown_wrenches]
    if len(true_bodies) == 1:
        one = estimate.num_contacts == 1
        out["fit_correct_link"] = bool(one and multi_contact.same_link(estimate.body_indices[0], true_bodies[0]))
        out["fit_valid"] = bool(estimate.valid)
        out["fit_position_error_m"] = float(np.linalg.norm(estimate.points_W[0] - true_points_W[0])) if one else None
    if len(true_bodies) == 2:
        two = estimate.two if estimate.two is not None else multi_contact.fit_two(q, wrench_W, residual)
        if len(two.body_indices) == 2:
            pairs = [(0, 1), (1, 0)]
            errors = [
                [float(np.linalg.norm(two.points_W[e] - true_points_W[t])) for t, e in enumerate(order)]
                for order in pairs
            ]
            best = int(np.argmin([sum(e) for e in errors]))
            order = pairs[best]
            out["contact_position_errors_m"] = errors[best]
            out["contact_force_errors_rel"] = [
                float(np.linalg.norm(two.forces_W[e] - true_forces_W[t]) / np.linalg.norm(true_forces_W[t]))
                for t, e in enumerate(order)
            ]
            out["two_contact_fit_links_right"] = all(two.body_indices[e] == true_bodies[t] for t, e in enumerate(order))
        else:
            out["contact_position_errors_m"] = [math.inf, math.inf]
            out["contact_force_errors_rel"] = [math.inf, math.inf]
            out["two_contact_fit_links_right"] = False
        out["contact_links_right"] = estimate.num_contacts == 2 and sorted(estimate.body_indices) == sorted(true_bodies)
    return out


def no_contact_result(
    scenario: ContactLocalizationScenario, handles: ContactLocalizationHandles, context: Context
) -> dict:
    """The run without contact (``no_contact_scenario``) of ``scenario.no_contact_duration`` s:
    the number of OFF->ON switches of the detector, and the largest test statistics over
    their thresholds after the detector's start-up time (before it the detector ignores
    them: the residuals and the base-state estimator start). A run built with
    ``online=False`` runs its estimators on its log here (``estimate_run``)."""
    if handles.online:
        log = handles.loggers["contact_detected"].FindLog(context)
        detected = log.data()[0]
        stats_log = handles.loggers["test_statistics"].FindLog(context)
        stats = stats_log.data()[:, stats_log.sample_times() >= handles.detector.startup_time]
    else:
        inputs = estimator_log(handles)
        replay = estimate_run(handles, inputs)
        detected = replay.contact_detected.astype(float)
        stats = replay.test_statistics[inputs.log_times >= handles.detector.startup_time].T
    on = handles.detector.thresholds["on"]
    return {
        "duration_s": scenario.no_contact_duration,
        "motion": "standing" if scenario.motion is None else "slow whole-body motion",
        "noise_seed": scenario.station.seed,
        "false_detections": int(np.sum(np.diff(np.concatenate(([0.0], detected))) > 0.5)),
        "max_statistic_over_threshold": [float(stats[0].max() / on[0]), float(stats[1].max() / on[1])],
    }


def _multi_contact_metrics(results: list[dict]) -> dict:
    """The one-or-two-contact localization's totals (``multi_contact_result``), where the
    trials went through it: ``more_than_one_contact_rate`` (trials it said 2 contacts),
    and for two-contact trials ``both_links_right_rate``, the two-contact fit's own
    ``two_contact_fit_links_right_rate`` and its per-contact position and force errors
    (median, p95; over all contacts of all trials)."""
    checked = [r for r in results if "contacts_estimated" in r]
    if not checked:
        return {}
    out = {
        "multi_contact_trials": len(checked),
        "more_than_one_contact_rate": float(np.mean([r["contacts_estimated"] == 2 for r in checked])),
        "p_value_one_below_0.05_rate": float(
            np.mean([r["p_value_one"] is not None and r["p_value_one"] < 0.05 for r in checked])
        ),
    }
    single = [r for r in checked if "fit_correct_link" in r]
    if single:
        valid = [r for r in single if r["fit_valid"]]
        positions = np.array(
            [math.inf if r["fit_position_error_m"] is None else r["fit_position_error_m"] for r in single]
        )
        out.update(
            {
                "fit_correct_link_rate": float(np.mean([r["fit_correct_link"] for r in single])),
                "fit_valid_rate": len(valid) / len(single),
                "fit_valid_precision": float(np.mean([r["fit_correct_link"] for r in valid])) if valid else None,
                "fit_median_position_error_m": percentile_with_inf(positions, 50),
                "fit_p95_position_error_m": percentile_with_inf(positions, 95),
            }
        )
    two = [r for r in checked if "contact_links_right" in r]
    if two:
        positions = np.concatenate([r["contact_position_errors_m"] for r in two])
        forces = np.concatenate([r["contact_force_errors_rel"] for r in two])
        out.update(
            {
                "both_links_right_rate": float(np.mean([r["contact_links_right"] for r in two])),
                "two_contact_fit_links_right_rate": float(np.mean([r["two_contact_fit_links_right"] for r in two])),
                "median_contact_position_error_m": float(np.median(positions)),
                "p95_contact_position_error_m": percentile_with_inf(positions, 95),
                "median_contact_force_error_rel": float(np.median(forces)),
                "p95_contact_force_error_rel": percentile_with_inf(forces, 95),
            }
        )
    return out


def _intervals_and_tables(results: list[dict], detected: list, valid: list, positions, forces) -> dict:
    """The study's 95 % intervals (``study_statistics``: Clopper-Pearson for the rates,
    order statistics for the quantiles), its per-link table of the right-link rate, and the
    confusion list of its misses (true link -> estimated link or status, with counts)."""
    n = len(results)
    if n == 0:
        return {"intervals": {}, "per_link": [], "confusion": []}
    intervals = {
        "detection_rate": proportion_interval(len(detected), n),
        "correct_link_rate": proportion_interval(sum(r["correct_link"] for r in results), n),
        "valid_rate": proportion_interval(len(valid), n),
        "median_position_error_m": quantile_interval(positions, 0.5),
        "p95_position_error_m": quantile_interval(positions, 0.95),
    }
    if valid:
        intervals["valid_precision"] = proportion_interval(sum(r["correct_link"] for r in valid), len(valid))
    checked = [r for r in results if "contacts_estimated" in r]
    if checked:
        intervals["more_than_one_contact_rate"] = proportion_interval(
            sum(r["contacts_estimated"] == 2 for r in checked), len(checked)
        )
    single = [r for r in checked if "fit_correct_link" in r]
    if single:
        valid = [r for r in single if r["fit_valid"]]
        intervals["fit_correct_link_rate"] = proportion_interval(
            sum(r["fit_correct_link"] for r in single), len(single)
        )
        intervals["fit_valid_rate"] = proportion_interval(len(valid), len(single))
        if valid:
            intervals["fit_valid_precision"] = proportion_interval(
                sum(r["fit_correct_link"] for r in valid), len(valid)
            )
        fit_positions = [math.inf if r["fit_position_error_m"] is None else r["fit_position_error_m"] for r in single]
        intervals["fit_median_position_error_m"] = quantile_interval(fit_positions, 0.5)
        intervals["fit_p95_position_error_m"] = quantile_interval(fit_positions, 0.95)
    two = [r for r in checked if "contact_links_right" in r]
    if two:
        intervals["both_links_right_rate"] = proportion_interval(sum(r["contact_links_right"] for r in two), len(two))
        positions = np.concatenate([r["contact_position_errors_m"] for r in two])
        intervals["median_contact_position_error_m"] = quantile_interval(positions, 0.5)
    if forces:
        intervals["median_force_error_rel"] = quantile_interval(forces, 0.5)
    confusion: dict[tuple[str, str], int] = {}
    if two and len(two) == n:
        # Two contacts per trial: a trial is right when both links are; a pushed link is
        # found when the answer has two contacts and names it.
        for r in results:
            if not r["contact_links_right"]:
                found = r.get("estimated_contact_body_names", [])
                shown = " + ".join(sorted(found)) if found else "no contact"
                if len(found) == 1:
                    shown += " (one contact)"
                key = (" + ".join(sorted(c["body"] for c in r["contacts"])), shown)
                confusion[key] = confusion.get(key, 0) + 1
        pushed = [
            {
                "body": c["body"],
                "found": r["contacts_estimated"] == 2 and c["body"] in r["estimated_contact_body_names"],
            }
            for r in results
            for c in r["contacts"]
        ]
        per_link = rate_table(pushed, lambda p: p["body"], lambda p: p["found"])
        per_seed = rate_table(results, lambda r: str(r.get("seed", "")), lambda r: r["contact_links_right"])
    else:
        for r in results:
            if not r["correct_link"]:
                key = (r["body"], r["estimated_body"] or f"none ({r['status_reason']})")
                confusion[key] = confusion.get(key, 0) + 1
        per_link = rate_table(results, lambda r: r["body"], lambda r: r["correct_link"])
        per_seed = rate_table(results, lambda r: str(r.get("seed", "")), lambda r: r["correct_link"])
    fit_tables = {}
    if single and len(single) == n:  # the stacked fit as the single-contact localizer
        fit_tables = {
            "fit_per_link": rate_table(single, lambda r: r["body"], lambda r: r["fit_correct_link"]),
            "fit_per_seed": rate_table(single, lambda r: str(r.get("seed", "")), lambda r: r["fit_correct_link"]),
        }
    return {
        "intervals": {k: [float(a), float(b)] for k, (a, b) in intervals.items()},
        "interval_level": CONFIDENCE_LEVEL,
        **fit_tables,
        "per_link": per_link,
        "per_seed": per_seed,
        "confusion": [
            {"true": t, "estimated": e, "count": c}
            for (t, e), c in sorted(confusion.items(), key=lambda item: (-item[1], item[0]))
        ],
    }


def _region_table(results: list[dict]) -> list[dict]:
    """Per body region (``REGIONS``, of the first contact): trials, detection rate, the
    eq. (22) localizer's right-link rate and median position error (inf counted for a
    trial without localization), and the stacked fit's where it ran."""
    table = []
    for region in REGIONS:
        rows = [r for r in results if r.get("region") == region]
        if not rows:
            continue
        positions = [math.inf if r["position_error_m"] is None else r["position_error_m"] for r in rows]
        entry = {
            "region": region,
            "trials": len(rows),
            "detection_rate": float(np.mean([r["detected"] for r in rows])),
            "correct_link_rate": float(np.mean([r["correct_link"] for r in rows])),
            "median_position_error_m": float(np.median(positions)),
        }
        sole_forces = _sole_force_rms(rows)
        if sole_forces is not None:
            entry["foot_normal_force_rms_error_of_weight"] = sole_forces[1]
        fits = [r for r in rows if "fit_correct_link" in r]
        if fits:
            entry["fit_correct_link_rate"] = float(np.mean([r["fit_correct_link"] for r in fits]))
            entry["fit_median_position_error_m"] = float(
                np.median([math.inf if r["fit_position_error_m"] is None else r["fit_position_error_m"] for r in fits])
            )
        table.append(entry)
    return table


def _sole_force_rms(results: list[dict]) -> tuple[float, float] | None:
    """(RMS error N, the same of the robot's weight) of the stacked fit's ground normal
    force per sole against the simulator's, over the detected ``results`` that have both
    (None when none has)."""
    errors, weights = [], []
    for r in results:
        if r["detected"] and "foot_normal_forces_N" in r and "true_foot_normal_forces_N" in r:
            errors.extend(np.subtract(r["foot_normal_forces_N"], r["true_foot_normal_forces_N"]).tolist())
            weights.append(r["robot_weight_N"])
    if not errors:
        return None
    rms = float(np.sqrt(np.mean(np.square(errors))))
    return rms, rms / float(np.mean(weights))


def _foot_force_metrics(results: list[dict]) -> dict:
    """Without foot F/T sensors: the sole normal force RMS error (``_sole_force_rms``) over
    the detected trials, and over those whose eq. (22) localization is VALID: the
    localizer's claim that the residuals tell the contact from the ground's wrenches. A
    push on a stance leg is not told from them, and its fit may trade the push for the
    ground's wrench (errors of kilonewtons); the eq. (22) localizer's per-link rivals do
    not call one valid, while the stacked fit's own ``valid`` sometimes does (its
    runner-up comes from the refitted links only). {} without such trials."""
    every = _sole_force_rms(results)
    if every is None:
        return {}
    out = {"foot_normal_force_rms_error_N": every[0], "foot_normal_force_rms_error_of_weight": every[1]}
    valid = _sole_force_rms([r for r in results if r["status"] == VALID])
    if valid is not None:
        out["foot_normal_force_rms_error_valid_N"] = valid[0]
        out["foot_normal_force_rms_error_valid_of_weight"] = valid[1]
    return out


def contact_localization_metrics(
    results: list[dict], no_contact: dict | None, slow_motion: dict | None = None, floors: dict | None = None
) -> dict:
    """The study's totals (module docstring) from its trials' ``trial_result``s and the
    ``no_contact_result`` of its standing run and of its slow-motion run (None: skipped),
    and whether each meets its floor (``floors``, default ``FLOORS``; see ``floors_for``;
    None: not measured). ``false_detections`` counts all three; its floor is judged only
    with a standing run without contact (``no_contact`` of a positive duration): the
    trials' quiet starts alone do not make it met."""
    floors = FLOORS if floors is None else floors
    n = len(results)
    detected = [r for r in results if r["detected"]]
    delays = [r["detection_delay_s"] for r in detected]
    positions = np.array([r["position_error_m"] if r["position_error_m"] is not None else np.inf for r in results])
    forces = [r["force_error_rel"] for r in detected]
    angles = [r["angle_error_deg"] for r in detected]
    updates = np.array([r["localizer_update_s"] for r in results]) * 1e3

    def median(values):
        return float(np.median(values)) if len(values) else None

    metrics = {
        "trials": n,
        "detection_rate": len(detected) / n if n else None,
        "median_detection_delay_s": median(delays),
        "p95_detection_delay_s": float(np.percentile(delays, 95)) if delays else None,
        "false_detections": (no_contact["false_detections"] if no_contact else 0)
        + (slow_motion["false_detections"] if slow_motion else 0)
        + sum(r["false_detections_before_push"] for r in results),
        "false_detections_no_contact_run": no_contact["false_detections"] if no_contact else None,
        "no_contact_run_s": no_contact["duration_s"] if no_contact else None,
        "false_detections_slow_motion_run": slow_motion["false_detections"] if slow_motion else None,
        "slow_motion_run_s": slow_motion["duration_s"] if slow_motion else None,
        "false_detections_before_push_in_trials": sum(r["false_detections_before_push"] for r in results),
        "correct_link_rate": float(np.mean([r["correct_link"] for r in results])) if n else None,
        "valid_rate": float(np.mean([r["status"] == 0 for r in results])) if n else None,
        "ambiguous_rate": float(np.mean([r["status"] == 4 for r in results])) if n else None,
        "median_position_error_m": float(np.median(positions)) if n else None,
        "p95_position_error_m": percentile_with_inf(positions, 95) if n else None,
        "median_position_error_correct_link_m": median([r["position_error_m"] for r in results if r["correct_link"]]),
        "median_force_error_rel": median(forces),
        "p95_force_error_rel": float(np.percentile(forces, 95)) if forces else None,
        "median_angle_error_deg": median(angles),
        "p95_angle_error_deg": float(np.percentile(angles, 95)) if angles else None,
        "median_localizer_update_ms": float(np.median(updates)) if n else None,
        "max_localizer_update_ms": float(np.max(updates)) if n else None,
        "status_counts": {
            reason: sum(r["status_reason"] == reason for r in results)
            for reason in sorted({r["status_reason"] for r in results})
        },
        "wrong_links": [
            {"trial": r["trial"], "true": r["body"], "estimated": r["estimated_body"], "status": r["status_reason"]}
            for r in results
            if not r["correct_link"]
        ],
    }
    valid = [r for r in results if r["status"] == 0]
    metrics["valid_precision"] = float(np.mean([r["correct_link"] for r in valid])) if valid else None
    metrics["per_region"] = _region_table(results)
    for row in metrics["per_region"]:  # flat, for the floors
        for key in ("correct_link_rate", "fit_correct_link_rate"):
            if key in row:
                metrics[f"{key}_{row['region']}"] = row[key]
    metrics.update(_foot_force_metrics(results))
    metrics.update(_multi_contact_metrics(results))
    metrics.update(_intervals_and_tables(results, detected, valid, positions, forces))
    checks = {}
    for key, (op, floor) in floors.items():
        value = metrics.get(key)
        checks[key] = None if value is None else bool(value >= floor if op == ">=" else value <= floor)
    if "false_detections" in checks and not (no_contact and no_contact["duration_s"] > 0):
        checks["false_detections"] = None  # no standing run without contact: the floor is not judged
    metrics["floors"] = {k: f"{op} {v}" for k, (op, v) in floors.items()}
    metrics["meets_floors"] = checks
    return metrics
