"""Model refinement from the residuals (Flacco et al. 2016, Sec. VI, future work): with no
unknown contact the residuals see only model error, so a short calibration motion of the
standing robot identifies corrections of the estimators' model, and the spurious effort
they remove is measured.

    SlowMotion (calibration) ──► station (realistic: IEKF base state, imperfections) ──► log
    log ──► identify_model_corrections (base-parameter regressor, friction, torque errors)
    station(model_corrections) + InternalResidual, ExternalResidual ──► spurious effort,
        standing and in a different slow motion, before and after

The station (``diagrams.station.humanoid_station``) applies the corrections: the refined
link inertias replace the estimators' (and the PD's gravity) model, and the motor torques
the residuals read become ``CorrectedJointTorque`` (offset, scale, friction). The
identification itself (``systems.estimation.model_identification``) runs on a plain log of
arrays, so the same call calibrates a real robot from its own recording.
"""

# No ``from __future__ import annotations``: yaml_load_typed reads the scenario's field types.

import hashlib
import os
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.residuals.wiring import add_internal_and_external_residuals
from diagrams.scenarios import scenario_as_yaml
from diagrams.simulation import simulate
from diagrams.station.config import StationConfig, check_model_refinement
from diagrams.station.humanoid_station import (
    ONLINE_DYNAMICS,
    HumanoidStation,
    add_humanoid_station,
)
from diagrams.station.motions import SlowMotion, slow_whole_body_motion
from models import robot_description
from models.description import collision_mesh_files
from systems.estimation.model_identification import (
    CalibrationLog,
    IdentificationOptions,
    ModelCorrections,
    identify_model_corrections,
)
from systems.io.update_recorder import UpdateRecorder
from systems.residuals.contact_estimation import unexplained_residuals
from systems.residuals.momentum_residuals import ExternalResidual, InternalResidual, ResidualModel
from systems.residuals.offline import replay_residuals, residual_noise_model
from systems.simulation.imperfections import rated_joint_torques

#: The issue's floor: the calibration removes at least this fraction of the RMS spurious
#: external force while standing.
SPURIOUS_FORCE_REDUCTION_FLOOR = 0.70

#: The identification's options for a calibration (``calibration_options`` adds the priors
#: that scale with each joint's rated torque): Gaussian priors of 10 % on each link's
#: deviation from its nominal (CAD) mass and first moment and on each torque sensor's scale
#: (the combinations the motion excites weakly stay near CAD instead of absorbing noise),
#: of TORQUE_OFFSET_PRIOR_FRACTION of the rated torque on the offsets and
#: COULOMB_PRIOR_FRACTION on the Coulomb friction: a datasheet's tolerances, wider than the
#: simulated errors. Everything else is the defaults of ``IdentificationOptions`` (5 Hz
#: parallel filtering, 10 ms samples). The offsets' prior is in N m of each joint, not a
#: ridge whose strength grows with the log: a ridge of that kind lets the leg offsets move
#: into the links' gravity parameters, which then err at the postures of a push. Viscous
#: friction is identified on every joint the motion moves faster than 0.5 v_s (95th
#: percentile): between 0.5 and 2 v_s the tanh's curvature tells F_c from b. With the
#: default threshold (2 v_s) the slowly moved leg joints would get no viscous term, and
#: their friction would be wrong at the slow speeds where an admittance loop follows it
#: (``tests/test_model_identification.py`` checks the identified friction).
#: The base twist comes from the stance kinematics (both soles still), not from the
#: base-state estimator: its angular velocity is the gyro's, whose noise, differentiated,
#: drives the weakly excited inertial combinations and calibrates too heavy a robot (the
#: external residual then sees a standing force and the detector is on before any push;
#: ``IdentificationOptions.base_velocity``; docs/sweeps.md has the calibrated masses).
CALIBRATION_OPTIONS = IdentificationOptions(
    inertial_prior_std=0.1, torque_scale_prior_std=0.1, viscous_min_speed=0.5, base_velocity="stance_kinematics"
)
TORQUE_OFFSET_PRIOR_FRACTION = 0.05
COULOMB_PRIOR_FRACTION = 0.1


def calibration_options(plant: MultibodyPlant) -> IdentificationOptions:
    """``CALIBRATION_OPTIONS`` with the offset and Coulomb priors of ``plant``'s joints:
    the fractions above of each joint's rated torque (its actuator's effort limit)."""
    rated = rated_joint_torques(plant)
    return replace(
        CALIBRATION_OPTIONS,
        torque_offset_prior_std=TORQUE_OFFSET_PRIOR_FRACTION * rated,
        coulomb_prior_std=COULOMB_PRIOR_FRACTION * rated,
    )


@dataclass(slots=True)
class ModelRefinementScenario:
    """The calibration and its check. SI units.

    Attributes:
        station: the robot and its world (``diagrams.station.config``; default: the
            realistic world, with the 5 % mass / 10 % CoM / 10 % inertia mismatch the
            refinement corrects, the invariant EKF, and ``model_refinement`` "none": the
            calibration starts from the unrefined model). The robot is a humanoid standing on
            its feet: F/T sensors measure their wrenches; FSRs their normal forces and
            centres of pressure (the rest unknowns of the fit).
        calibration_motion, calibration_duration: the calibration motion and its length, s.
            Its amplitudes are 1.5 times the slow motion's (torso pitch 0.3 rad, squat
            0.18 rad at the hips, arms 0.75 rad, within 80 % of the joint ranges): a
            calibration must cover the postures the experiments reach (push-and-comply
            leans the upper body 15-20 deg); at the slow motion's own amplitudes the
            realistic push-and-comply internal run left the calibrated range and fell.
            Likewise for the speeds: ``min_peak_speed`` 0.4 rad/s (4 v_s of the friction
            model) speeds up the synergies whose drawn frequency and (limit-capped)
            amplitude left a joint slower than that. Below ~v_s, F_c tanh(qdot / v_s) +
            b qdot ~ (F_c / v_s + b) qdot and the log cannot split Coulomb from viscous
            friction: the drawn motion moved the right elbow (0.24 rad, capped by its joint
            limit, at 0.062 Hz) at 0.093 rad/s at most, its viscous friction came out at
            0.43 (another calibration: 0.06) against the simulated 0.80 N m s/rad, and the
            slow motion's 0.24 rad/s elbow swings were 19 false contact detections. With the
            floor: 0.79. 0.4 rad/s also covers the slow motion's fastest joints (0.39 rad/s).
        standing_duration: the standing check (no motion, no contact), s.
        check_motion, check_duration: a different slow motion for the check, s.
        skip: the checks ignore their first ``skip`` s (residual and estimator start-up).
        internal_gain, external_gain: the residual gains K, 1/s.
        simulator_config: Drake's ``SimulatorConfig``.
    """

    station: StationConfig = field(default_factory=lambda: StationConfig.realistic(model_refinement="none"))
    calibration_motion: SlowMotion = field(
        default_factory=lambda: SlowMotion(seed=1, amplitude_scale=1.5, min_peak_speed=0.4)
    )
    calibration_duration: float = 40.0
    standing_duration: float = 10.0
    check_motion: SlowMotion = field(default_factory=lambda: SlowMotion(seed=2, amplitude_scale=0.5))
    check_duration: float = 30.0
    skip: float = 2.0
    internal_gain: float = 35.0
    external_gain: float = 35.0
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)

    def validate(self) -> "ModelRefinementScenario":
        for name in ("calibration_duration", "standing_duration", "check_duration"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive number of seconds, got {value}")
        if not (0.0 <= self.skip < min(self.standing_duration, self.check_duration)):
            raise ValueError(f"skip must be in [0, the shortest check), got {self.skip}")
        self.calibration_motion.validate()
        self.check_motion.validate()
        return self


@dataclass
class RefinementHandles:
    """What ``build_refinement_diagram`` created."""

    plant: MultibodyPlant
    station: HumanoidStation
    internal: InternalResidual | None
    external: ExternalResidual | None
    loggers: dict[str, VectorLogSink]
    #: A calibration log's recorder (``residuals`` False), else None.
    recorder: UpdateRecorder | None = None


def build_refinement_diagram(
    scenario: ModelRefinementScenario,
    motion: SlowMotion | None,
    corrections: ModelCorrections | None = None,
    *,
    residuals: bool = True,
) -> tuple[Diagram, RefinementHandles]:
    """The station of ``scenario`` (with ``corrections`` applied, if given) following
    ``motion`` (None: holding its posture), with the internal and external residuals, and
    loggers at every plant step: ``sensed_state``, ``measured_torque`` (the torque sensor's
    raw output), ``known_wrenches``, ``external_wrench_world``, ``internal_residual``,
    ``true_state``. ``residuals`` False: a calibration log, whose residuals are replayed
    offline with the refined model: no residuals, and instead of the loggers an
    ``UpdateRecorder`` of the first three, which records what the estimators' update at
    each k T reads (a logger records it as its sample k + 1, and its publish evaluates the
    sensors a second time each step: 18 % of the step's cost; tested).

    Raises:
        ValueError: a model that is not a humanoid, bad scenario fields.
    """
    scenario.validate()
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, scenario.station, model_corrections=corrections)
    if station.humanoid is None or not (station.known_wrench_frames or station.estimator.unknown_wrench_frames):
        raise ValueError(
            "model refinement needs a humanoid standing on its feet (a robot description), got "
            f"{scenario.station.model!r}: "
            "run with --ideal, or set model_refinement: none"
        )
    plant = station.plant
    if motion is None:
        reference = builder.AddSystem(ConstantVectorSource(station.q_hold))
    else:
        reference = builder.AddSystem(slow_whole_body_motion(station, motion))
    reference.set_name("posture_reference")
    builder.Connect(reference.get_output_port(), station.desired_position)
    T = scenario.station.plant_config.time_step
    logged = {"sensed_state": station.sensed_state, "measured_torque": station.raw_measured_torque}
    if station.known_wrenches is not None:  # none on feet without F/T sensors or FSRs
        logged["known_wrenches"] = station.known_wrenches
    internal = external = recorder = None
    loggers = {}
    if not residuals:
        recorder = builder.AddSystem(UpdateRecorder({name: port.size() for name, port in logged.items()}, T))
        recorder.set_name("calibration_recorder")
        for name, port in logged.items():
            builder.Connect(port, recorder.GetInputPort(name))
    else:
        loggers = {name: LogVectorOutput(port, builder, T) for name, port in logged.items()}
        loggers["true_state"] = LogVectorOutput(plant.get_state_output_port(), builder, T)
        internal, external = add_internal_and_external_residuals(
            builder, station, scenario.internal_gain, scenario.external_gain, T
        )
        loggers["external_wrench_world"] = LogVectorOutput(external.GetOutputPort("external_wrench_world"), builder, T)
        loggers["internal_residual"] = LogVectorOutput(internal.GetOutputPort("residual"), builder, T)
    diagram = builder.Build()
    diagram.set_name("model_refinement")
    return diagram, RefinementHandles(plant, station, internal, external, loggers, recorder)


def run_refinement_diagram(
    diagram: Diagram, handles: RefinementHandles, duration: float, config: SimulatorConfig
) -> Context:
    """Simulates ``diagram`` for ``duration`` s from the station's initial state with the
    simulator ``config`` (``diagrams.simulation.simulate``; a recorder's samples of an earlier
    run are cleared first); returns the root context (the loggers' logs are in it; a recorder
    holds its samples itself: the updates at 0, T, ..., ``duration`` - T).

    Raises:
        ValueError: a ``duration`` that is not positive and finite.
    """

    def set_initial_state(context: Context) -> None:
        handles.station.set_initial_state(context)
        if handles.recorder is not None:
            handles.recorder.clear()

    return simulate(diagram, duration, set_initial_state=set_initial_state, simulator_config=config).context


def calibration_log(handles: RefinementHandles, context: Context) -> CalibrationLog:
    """The run's log in the layout a robot records (``CalibrationLog``): sensed state,
    the torque sensor's raw motor torques, the F/T wrenches."""
    nq = handles.plant.num_positions()
    if handles.recorder is not None:
        recorder = handles.recorder
        times, x = recorder.times, recorder.values("sensed_state")
        torque = recorder.values("measured_torque")
        wrenches = recorder.values("known_wrenches") if "known_wrenches" in recorder.names else None
    else:
        state = handles.loggers["sensed_state"].FindLog(context)
        times, x = state.sample_times().copy(), state.data().T
        torque = handles.loggers["measured_torque"].FindLog(context).data().T.copy()
        logger = handles.loggers.get("known_wrenches")
        wrenches = None if logger is None else logger.FindLog(context).data().T.copy()
    if wrenches is None:
        wrenches = np.zeros((len(times), 0))
    return CalibrationLog(
        time=times, q=x[:, :nq].copy(), v=x[:, nq:].copy(), measured_torque=torque, known_wrenches=wrenches
    )


def calibrate_model(scenario: ModelRefinementScenario) -> tuple[ModelCorrections, CalibrationLog]:
    """Runs the calibration motion on the (uncorrected) station and identifies the model
    corrections from its log, with the residual noise model of the refined model on the same
    log (``calibrate_from_log``)."""
    diagram, handles = build_refinement_diagram(scenario, scenario.calibration_motion, residuals=False)
    context = run_refinement_diagram(diagram, handles, scenario.calibration_duration, scenario.simulator_config)
    log = calibration_log(handles, context)
    return calibrate_from_log(scenario, handles, log), log


def calibrate_from_log(
    scenario: ModelRefinementScenario, handles: RefinementHandles, log: CalibrationLog
) -> ModelCorrections:
    """The model corrections identified from ``log`` (a robot's own recording, or one of
    ``calibrate_model``), and their ``residual_noise``: the covariances of the internal and
    external residuals replayed on the log with the refined model
    (``systems.residuals.offline``), after the first ``scenario.skip`` s. ``handles``: a refinement diagram of the
    robot (its station's estimators' plant: the model before refinement, and F/T frames)."""
    station = handles.station
    estimator = station.estimator
    # The estimators' plant: its default inertias are the model before refinement.
    plant = estimator.plant
    corrections = identify_model_corrections(
        plant,
        log,
        known_wrench_frames=station.known_wrench_frames,
        options=calibration_options(plant),
        unknown_wrench_frames=estimator.unknown_wrench_frames,
        unknown_wrench_components=estimator.unknown_wrench_components,
    )
    model = ResidualModel(plant, ONLINE_DYNAMICS)  # the dynamics the stations' estimators run on
    model.set_spatial_inertias(corrections.spatial_inertias)
    period = float(np.median(np.diff(log.time)))
    replayed = replay_residuals(
        plant,
        model,
        station.known_wrench_frames,
        np.hstack((log.q, log.v)),
        corrections.corrected_torque(log.measured_torque, log.v[:, 6:]),
        log.known_wrenches,
        internal_gain=scenario.internal_gain,
        external_gain=scenario.external_gain,
        period=period,
        classical_gain=scenario.internal_gain,
        stacked=True,
    )
    internal, external = replayed.internal, replayed.external_wrench_world
    classical = replayed.classical
    if estimator.unknown_wrench_frames:
        # Feet without F/T sensors: the residuals carry the soles' changing ground wrenches;
        # the noise is what those cannot explain (the detector tests only that). The
        # classical residual has no such model here.
        force, internal = unexplained_residuals(
            plant,
            estimator.unknown_wrench_frames,
            estimator.unknown_wrench_components,
            log.q,
            external,
            internal,
            external_gain=scenario.external_gain,
            internal_gain=scenario.internal_gain,
            period=period,
        )
        external = np.concatenate((external[:, :3], force), axis=1)
        classical = None
    corrections.residual_noise = residual_noise_model(
        internal,
        external,
        internal_gain=scenario.internal_gain,
        external_gain=scenario.external_gain,
        period=period,
        skip=int(round(scenario.skip / period)),
        classical=classical,
    )
    return corrections


def spurious_effort(handles: RefinementHandles, context: Context, skip: float) -> dict:
    """The residuals' output without contact, after ``skip`` s: RMS of the external force's
    norm, N, its RMS per world axis, N, its largest norm, N, and the internal residual's RMS
    over all joints and samples and its largest joint RMS, N m (all of it is spurious)."""
    log = handles.loggers["external_wrench_world"].FindLog(context)
    keep = log.sample_times() >= skip
    force = log.data()[3:, keep]
    internal = handles.loggers["internal_residual"].FindLog(context).data()[:, keep]
    joint_rms = np.sqrt(np.mean(internal**2, axis=1))
    names = handles.station.joint_names
    return {
        "external_force_rms_N": float(np.sqrt(np.mean(np.sum(force**2, axis=0)))),
        "external_force_rms_per_axis_N": np.sqrt(np.mean(force**2, axis=1)).tolist(),
        "external_force_max_N": float(np.max(np.linalg.norm(force, axis=0))),
        "internal_rms_Nm": float(np.sqrt(np.mean(internal**2))),
        "internal_worst_joint": names[int(np.argmax(joint_rms))],
        "internal_worst_joint_rms_Nm": float(np.max(joint_rms)),
    }


def check_spurious_effort(
    scenario: ModelRefinementScenario,
    motion: SlowMotion | None,
    duration: float,
    corrections: ModelCorrections | None,
    *,
    with_trace: bool = False,
) -> dict | tuple[dict, dict]:
    """``spurious_effort`` of a run of ``duration`` s (``motion`` None: standing) with or
    without ``corrections``; ``with_trace`` also returns its time series: {"t" (s),
    "force_norm" (N, the external force's norm), "internal_norm" (N m)}."""
    diagram, handles = build_refinement_diagram(scenario, motion, corrections)
    context = run_refinement_diagram(diagram, handles, duration, scenario.simulator_config)
    effort = spurious_effort(handles, context, scenario.skip)
    if not with_trace:
        return effort
    log = handles.loggers["external_wrench_world"].FindLog(context)
    internal = handles.loggers["internal_residual"].FindLog(context).data()
    trace = {
        "t": log.sample_times(),
        "force_norm": np.linalg.norm(log.data()[3:], axis=0),
        "internal_norm": np.linalg.norm(internal, axis=0),
    }
    return effort, trace


def reduction(before: float, after: float) -> float:
    """The fraction of ``before`` removed: 1 - after / before."""
    return 1.0 - after / before if before > 0 else 0.0


def refinement_scenario_for(scenario: Any) -> ModelRefinementScenario:
    """The calibration of the robot an experiment's ``scenario`` simulates: the same model,
    imperfections (the same robot: its mismatch and torque-sensor errors), base-state source
    and plant configuration (its ``station``); the sensor noise is a different draw (seed + 1). An experiment
    whose residuals run with another gain (``residual_gain``: push-and-comply's) gets its
    residual noise model measured at that gain (``ResidualNoiseModel.check_gains``)."""
    return ModelRefinementScenario(
        station=replace(scenario.station, seed=scenario.station.seed + 1, model_refinement="none"),
        internal_gain=float(getattr(scenario, "residual_gain", ModelRefinementScenario().internal_gain)),
    )


#: Part of the calibration cache's key: changed whenever the code changes what a calibration
#: of the same scenario gives (e.g. the base-state estimator), so that old files are not reused.
CALIBRATION_REVISION = (
    "9: F/T wrenches in the estimated world frame, EKF level ground with still soles, viscous from 0.5 v_s,"
    " EKF from a standing start, calibration motion with min_peak_speed 0.4 rad/s, log of the updates' inputs,"
    " base twist from the stance kinematics"
)


#: The code a calibration runs: its sources are part of the cache's key.
_CALIBRATION_CODE = ("models", "systems", "diagrams")


def _content_digest(scenario: Any) -> str:
    """A digest of what a calibration of ``scenario``'s robot depends on beyond its scenario:
    the robot description, the model file it names and the collision meshes that file uses
    (by content, not by path), and the project's sources under ``_CALIBRATION_CODE``."""
    digest = hashlib.sha1()
    description = robot_description(scenario.station.model)
    for path in (description.source, description.model_file, *collision_mesh_files(description)):
        if path is not None:
            digest.update(Path(path).read_bytes())
    root = Path(__file__).resolve().parents[2]
    for package in _CALIBRATION_CODE:
        for source in sorted((root / package).rglob("*.py")):
            digest.update(source.relative_to(root).as_posix().encode() + source.read_bytes())
    return digest.hexdigest()


def calibration_file(scenario: Any, cache_folder: Path) -> Path:
    """Where ``refined_model`` saves the calibration of ``scenario``'s robot in
    ``cache_folder``: named by a hash of ``refinement_scenario_for(scenario)``, the
    identification's options, ``CALIBRATION_REVISION``, the robot's description, model file
    and collision meshes (their content: an edited URDF is calibrated again) and the
    project's code (any change of it calibrates again)."""
    text = (
        scenario_as_yaml(refinement_scenario_for(scenario))
        + repr((CALIBRATION_OPTIONS, TORQUE_OFFSET_PRIOR_FRACTION, COULOMB_PRIOR_FRACTION))
        + CALIBRATION_REVISION
        + _content_digest(scenario)
    )
    key = hashlib.sha1(text.encode()).hexdigest()[:16]
    return Path(cache_folder) / f"model_corrections_{key}.npz"


def refined_model(scenario: Any, cache_folder: Path | None = None) -> ModelCorrections | None:
    """The model corrections an experiment's ``scenario`` asks for with its
    ``model_refinement`` field: None for "none", the saved file's for a path, and for
    "calibrate" those of ``calibrate_model(refinement_scenario_for(scenario))``. With a
    ``cache_folder`` a calibration is saved there under a hash of its scenario and of the
    content of everything it depends on (``calibration_file``) and reused by later runs of
    the same robot (delete the folder to calibrate again); a cached file that cannot be read
    is calibrated again, with a message. The file is written atomically (a temporary file in
    the same folder, then ``os.replace``).

    Raises:
        ValueError: a bad ``model_refinement``, an unreadable corrections file, or a
            ``cache_folder`` that cannot be created or written (found before calibrating).
    """
    choice = check_model_refinement(scenario.station.model_refinement)
    if choice == "none":
        return None
    if choice != "calibrate":
        return ModelCorrections.load(choice)
    calibration = refinement_scenario_for(scenario)
    path = None
    if cache_folder is not None:
        path = calibration_file(scenario, cache_folder)
        if path.is_file():
            try:
                corrections = ModelCorrections.load(path)
            except ValueError as error:
                print(f"model refinement: the cached calibration cannot be read ({error}): calibrating again")
            else:
                print(f"model refinement: reusing {path}")
                return corrections
        _check_cache_folder(path.parent)  # before the calibration, not after it
    print(
        f"model refinement: {calibration.calibration_duration:g} s calibration motion of the standing robot, "
        "then identification ...",
        flush=True,
    )
    start = time.perf_counter()
    corrections, _ = calibrate_model(calibration)
    print(f"model refinement: done in {time.perf_counter() - start:.0f} s", flush=True)
    if path is not None:
        partial = path.with_name(f".{path.stem}.{os.getpid()}.partial.npz")
        try:
            corrections.save(partial)
            os.replace(partial, path)  # atomic: a run stopped while saving leaves no truncated file
        finally:
            partial.unlink(missing_ok=True)
    return corrections


def _check_cache_folder(folder: Path) -> None:
    """Creates ``folder`` and writes a file into it.

    Raises:
        ValueError: a file, or a folder that cannot be created or written (the reason named).
    """
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"the calibration cache '{folder}' is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise ValueError(f"cannot write into the calibration cache '{folder}': {error.strerror or error}") from None
