"""Push-and-comply diagram (Flacco et al. 2016, Sec. IV, Figs. 5-6): the humanoid is pushed
down on both shoulders and complies through a joint admittance controller (eq. 14) driven
by a residual, the classical one (eq. 7) or the internal one (eq. 11).

    PushSource ─► MultibodyPlant (+ ground) ─► sensors ─► residual ─► ResidualTare ─► JointAdmittanceController
        ▲ truth        ▲ actuation                │                      (eq. 14: q_d = q + K_a r T)
        └── loggers    └── PdGravityController ◄──┴── sensed state     │ desired_position
                                   ▲ desired_position ◄────────────────┘

Scenarios are YAML files loaded into ``PushAndComplyScenario`` with
``pydrake.common.yaml.yaml_load_typed``; the default is the paper's.
"""

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from diagrams.scenarios import load_scenario as _load_scenario
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from diagrams.station.standing import size_ratios
from systems.estimation.model_identification import ModelCorrections
from systems.residuals.admittance import JointAdmittanceController, admittance_gains_by_group, joint_position_selector
from systems.residuals.momentum_residuals import ClassicalResidual, ExternalResidual, InternalResidual
from systems.residuals.sole_wrenches import SoleWrenchCompensation
from systems.residuals.tare import ResidualTare
from systems.simulation.disturbances import PolynomialRampUpDown, Push, PushSource

RESIDUAL_KINDS = ("internal", "classical")
#: A run counts as upright while the pelvis keeps this fraction of its height and tilts less.
UPRIGHT_HEIGHT_FRACTION = 0.7
UPRIGHT_MAX_TILT_DEG = 30.0

#: Issue 31's floors of a robot (``make robots``): the internal run stays upright with both
#: knees bent by at least this much (deg); the classical run stays upright and bends them
#: less than this.
FLOOR_INTERNAL_KNEE_DEG = 5.0
FLOOR_CLASSICAL_KNEE_DEG = 1.0


def meets_robot_floors(internal: dict, classical: dict) -> bool:
    """Whether a robot meets the floors (``FLOOR_INTERNAL_KNEE_DEG``,
    ``FLOOR_CLASSICAL_KNEE_DEG``), from its two runs' ``push_and_comply_metrics``."""
    return bool(
        internal["upright"]
        and internal["knee_pitch_flexion_deg"] >= FLOOR_INTERNAL_KNEE_DEG
        and classical["upright"]
        and abs(classical["knee_pitch_flexion_deg"]) < FLOOR_CLASSICAL_KNEE_DEG
    )


@dataclass(slots=True)
class PushAndComplyScenario:
    """The experiment's settings (SI units). Defaults: the paper's scenario, Sec. IV.

    Attributes:
        station: the robot (``hrp4_like``) and its world (``diagrams.station.config``):
            realistic by default (the invariant EKF, ``Imperfections.realistic()``, the model
            calibrated first), ideal with ``--ideal``.
        duration: s (15 s in the paper).
        push_start, push_peak_time, push_end: the polynomial force profile's times, s
            (5, 8.5 and 12 s in the paper).
        push_peak_force: N on each shoulder. The paper uses 5 N with ideal sensors; with the
            default sensor noise the knee effort of a 5 N push (0.06 N m peak in the
            floating-base model) is within 4 sigma of the residual's noise (0.016 N m RMS),
            so an admittance gain that bends the knees also drifts on noise alone; 20 N
            (about 5 % of the robot's weight per shoulder) gives a 4x larger signal.
        push_direction: world direction of both forces (downward in the paper).
        push_point: the point of each shoulder body that is pushed, in its frame, m.
        residual_gain: K of the residual, 1/s: the residual follows the external joint
            effort through a first-order lag of bandwidth K. Eq. (14) integrates the
            residual, so the admittance needs only the push's band (a force that rises over
            seconds; 5/s lags it by 0.2 s), and the residual's noise above that band only
            widens the dead band (``dead_band_sigmas``: the noise model is measured by the
            calibration at this gain). At 35/s, the contact detector's gain (a 0.1 s
            detection), measured on TALOS: knee residual noise 0.09 N m RMS at rest (0.017
            at 5/s), knee dead bands of 0.18-0.22 N m (0.09-0.17 at 5/s) against the push's
            0.56 N m knee effort, and 4.5 deg of knee flexion (5.5 at 5/s).
        admittance_gains: K_a per joint group of ``HumanoidHandles.joint_groups`` (legs, torso,
            head, arms, hands) or per joint name, rad / (N m s).
        dead_band: residual dead band of the admittance controller, N m (about the
            residual's noise level, so that noise alone does not move the robot).
        scale_to_robot: the force, the admittance gains and the dead band above are
            hrp4_like's (the paper's robot, HRP-4); on another robot the force scales with
            its mass (m / m_ref), the dead band with its gravitational moment
            (s = m h / (m_ref h_ref), h the centre of mass height standing) and the gains
            with 1 / s, so the experiment is the paper's at the robot's size (exactly the
            values above on hrp4_like; ``diagrams.station.standing.size_ratios``).
        dead_band_sigmas: with a refined model that carries a residual noise model
            (``ModelCorrections.residual_noise``, measured on the calibration log), each
            joint's dead band is at least this many of its internal-residual standard
            deviations (the realistic world's residual noise is well above the sensors'
            white noise that ``dead_band`` was chosen for); the classical run likewise with
            the classical residual's noise, which the base-state estimate's velocity error
            dominates (eq. 7 reads the base velocity, the internal residual does not). With
            the tare (``tare_duration``) removing the residual's offset, the dead band only
            has zero-mean noise to stop: a soft threshold is odd, so noise past it moves a
            joint back and forth rather than away, and two standard deviations suffice
            (three, before the tare, also had to cover the offsets).
        max_rate: joint velocity limit of the admittance controller, rad/s.
        tare_duration: s, <= push_start: the robot stands untouched for this long at the
            start while ``ResidualTare`` measures the residual's offset at rest (over the
            second half of it, once the residual has converged from zero; what the
            estimators' model and the torque sensors get wrong at the standing posture),
            which is removed from the residual the admittance gets from then on; 0 (the
            paper) drives the admittance with the raw residual. Without it, an offset above
            the dead band is integrated as a push from the first sample (measured on TALOS:
            its knees bent until it crouched, `make robots` before the tare).
        integrate_from: "measured" (eq. 14 as printed: q_d = q + K_a r T) or "desired"
            (q_d integrates K_a r). With "measured" the PD keeps no stiffness, and a robot
            whose gravity compensation ignores the ground reaction collapses under its own
            weight (measured: the knees buckle); "desired" keeps the posture's stiffness.
        closed_chain_projection: the admittance moves the legs only along rates that keep
            both soles still (``JointAdmittanceController``'s ``support_frames``); without
            it, leg motions that do not respect the closed chain build internal forces
            between the feet, which the realistic world's uncalibrated torque-scale errors
            turn into residual (measured: the internal run twisted its hips and fell).
        hold_center_of_mass: with ``closed_chain_projection``, the admittance also keeps
            the centre of mass (of the estimators' model) still over the feet
            (``JointAdmittanceController``'s ``hold_center_of_mass``); without it the
            knees bend with the ankles nearly still and the CoM moves back towards the
            heels (measured: 85 mm of the 110 mm to the heel edge in the ideal world; a
            robot with a 5 % model error went past it and fell backwards).
        log_period: loggers' sampling period, s.
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``); the plant
            is discrete, so only ``target_realtime_rate`` and the publishing matter.
    """

    station: StationConfig = dataclasses.field(default_factory=StationConfig.realistic)
    duration: float = 15.0
    push_start: float = 5.0
    push_peak_time: float = 8.5
    push_end: float = 12.0
    push_peak_force: float = 20.0
    push_direction: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, -1.0])
    push_point: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 0.0])
    residual_gain: float = 5.0
    admittance_gains: dict[str, float] = dataclasses.field(
        default_factory=lambda: {
            "legs": 0.19,
            "torso": 0.1,
            "arms": 0.3,
            "head": 0.0,
            "hands": 0.0,
            "ankle_pitch": 1.0,
        }
    )
    dead_band: float = 0.02
    scale_to_robot: bool = True
    dead_band_sigmas: float = 2.0
    max_rate: float = 0.5
    tare_duration: float = 2.0
    integrate_from: str = "desired"
    closed_chain_projection: bool = True
    hold_center_of_mass: bool = True
    log_period: float = 0.01
    simulator_config: SimulatorConfig = dataclasses.field(default_factory=SimulatorConfig)


def load_scenario(path: str | Path | None = None, text: str | None = None) -> PushAndComplyScenario:
    """The default scenario overridden by the YAML file ``path`` and the YAML text ``text``
    (missing keys keep their defaults; see ``diagrams.scenarios``).

    Raises:
        ScenarioError (a ValueError): an unreadable file or a malformed scenario (the message
            says which).
    """
    return _load_scenario(PushAndComplyScenario, filename=path, text=text)


@dataclass
class PushAndComplyHandles:
    """What ``build_push_and_comply_diagram`` created."""

    station: HumanoidStation
    residual_kind: str
    residual: ClassicalResidual | InternalResidual
    tare: ResidualTare
    admittance: JointAdmittanceController
    push_source: PushSource
    loggers: dict[str, VectorLogSink]
    meshcat_visualizer: MeshcatVisualizer | None
    overlay: dict | None
    push_peak_force: float = 0.0  # N on each shoulder, after ``scale_to_robot``


def admittance_dead_band(
    scenario: PushAndComplyScenario,
    residual_kind: str,
    model_corrections: ModelCorrections | None,
    dead_band: float | None = None,
) -> float | np.ndarray:
    """The admittance's dead band, N m: ``dead_band`` (default ``scenario.dead_band``),
    raised per joint to ``dead_band_sigmas`` standard deviations of the ``residual_kind``
    residual's noise when the refined model carries a noise model of it (measured on the
    calibration log)."""
    dead_band = scenario.dead_band if dead_band is None else dead_band
    noise = model_corrections.residual_noise if model_corrections is not None else None
    if noise is None:
        return dead_band
    covariance = noise.covariance_internal if residual_kind == "internal" else noise.covariance_classical
    if covariance is None:
        return dead_band
    noise.check_gains(
        scenario.residual_gain, noise.external_gain, scenario.station.plant_config.time_step, "push-and-comply"
    )
    sigma = np.sqrt(np.diag(covariance))
    return np.maximum(dead_band, scenario.dead_band_sigmas * sigma)


def robot_scaled_push(plant, humanoid, scenario: PushAndComplyScenario) -> tuple[float, float, float]:
    """(push peak force, N; admittance gain factor; dead band, N m) on this robot: the
    scenario's own values, scaled to the robot's size when ``scale_to_robot``."""
    if not scenario.scale_to_robot:
        return scenario.push_peak_force, 1.0, scenario.dead_band
    mass_ratio, moment_ratio = size_ratios(plant, humanoid)
    return scenario.push_peak_force * mass_ratio, 1.0 / moment_ratio, scenario.dead_band * moment_ratio


def _add_sole_wrench_compensation(
    builder: DiagramBuilder,
    station: HumanoidStation,
    scenario: PushAndComplyScenario,
    residual_kind: str,
    residual,
) -> SoleWrenchCompensation:
    """The soles' wrench compensation of a robot without foot F/T sensors, on the internal
    and external residuals at the scenario's gain (the internal one is ``residual`` itself in
    the internal run), the push's candidate links every link but the feet."""
    estimator = station.estimator
    model = residual.model
    frames = station.known_wrench_frames
    inputs = {
        "external": ExternalResidual(estimator.plant, scenario.residual_gain, known_wrench_frames=frames, model=model)
    }
    if residual_kind != "internal":
        inputs["internal"] = InternalResidual(
            estimator.plant, scenario.residual_gain, known_wrench_frames=frames, model=model
        )
    for name, system in inputs.items():
        builder.AddSystem(system)
        system.set_name(f"{name}_residual")
        builder.Connect(station.sensed_state, system.GetInputPort("state"))
        if system.HasInputPort("measured_torque"):
            builder.Connect(station.measured_torque, system.GetInputPort("measured_torque"))
        if station.known_wrenches is not None:
            builder.Connect(station.known_wrenches, system.GetInputPort("known_wrenches"))
    internal = residual if residual_kind == "internal" else inputs["internal"]
    compensation = builder.AddSystem(
        estimator.sole_wrench_compensation(scenario.residual_gain, residual.period, residual_kind)
    )
    compensation.set_name("sole_wrench_compensation")
    builder.Connect(station.sensed_state, compensation.GetInputPort("state"))
    builder.Connect(
        inputs["external"].GetOutputPort("external_wrench_world"), compensation.GetInputPort("external_wrench_world")
    )
    builder.Connect(internal.GetOutputPort("residual"), compensation.GetInputPort("internal_residual"))
    if residual_kind == "classical":
        builder.Connect(residual.GetOutputPort("residual"), compensation.GetInputPort("classical_residual"))
    return compensation


def build_push_and_comply_diagram(
    scenario: PushAndComplyScenario,
    residual_kind: str,
    meshcat: Meshcat | None = None,
    *,
    model_corrections: ModelCorrections | None = None,
) -> tuple[Diagram, PushAndComplyHandles]:
    """Builds the closed loop of the module docstring with the ``residual_kind`` residual
    ("internal" or "classical") driving the admittance controller; ``model_corrections``
    (the scenario's refined model, see ``model_refinement``) go to the station. On a robot
    without foot F/T sensors the admittance reads the residual net of the soles' estimated
    wrenches (``_add_sole_wrench_compensation``).

    Raises:
        ValueError: an unknown residual kind, model or joint group; bad scenario values.
    """
    if residual_kind not in RESIDUAL_KINDS:
        raise ValueError(f"unknown residual '{residual_kind}'; choose one of {RESIDUAL_KINDS}")
    if not (0.0 <= scenario.push_start < scenario.push_peak_time < scenario.push_end <= scenario.duration):
        raise ValueError("the scenario needs 0 <= push_start < push_peak_time < push_end <= duration")
    if not (0.0 <= scenario.tare_duration <= scenario.push_start):
        raise ValueError(
            f"the scenario needs 0 <= tare_duration <= push_start (the tare must not average the push), "
            f"got tare_duration {scenario.tare_duration} s and push_start {scenario.push_start} s "
            "(set tare_duration to at most push_start; 0 turns the tare off)"
        )
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, scenario.station, model_corrections=model_corrections)
    plant, humanoid = station.plant, station.humanoid
    if humanoid is None:
        raise ValueError("push-and-comply needs one of the humanoid models (its shoulders and joint groups)")
    # The residual and the admittance know the robot through the estimators' plant only.
    model, model_humanoid = station.estimator.plant, station.estimator.humanoid

    # Two downward forces on the shoulders, polynomial profile (the paper's Sec. IV), sized to
    # the simulated robot; the admittance's gain factor and dead band to the estimators' model.
    peak_force = robot_scaled_push(plant, humanoid, scenario)[0]
    _, gain_factor, dead_band = robot_scaled_push(model, model_humanoid, scenario)
    profile = PolynomialRampUpDown(peak_force, scenario.push_start, scenario.push_peak_time, scenario.push_end)
    pushes = [
        Push(body.name(), np.asarray(scenario.push_point, float), np.asarray(scenario.push_direction, float), profile)
        for body in (humanoid.shoulder_bodies["right"], humanoid.shoulder_bodies["left"])
    ]
    push_source = builder.AddSystem(PushSource(plant, pushes))
    push_source.set_name("push_source")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))

    # The residual, from the sensors only.
    residual_type = InternalResidual if residual_kind == "internal" else ClassicalResidual
    residual = builder.AddSystem(
        residual_type(
            model, scenario.residual_gain, known_wrench_frames=station.known_wrench_frames, model=station.dynamics_model
        )
    )
    residual.set_name(f"{residual_kind}_residual")
    builder.Connect(station.sensed_state, residual.GetInputPort("state"))
    builder.Connect(station.measured_torque, residual.GetInputPort("measured_torque"))
    if station.known_wrenches is not None:
        builder.Connect(station.known_wrenches, residual.GetInputPort("known_wrenches"))
    residual_port = residual.GetOutputPort("residual")
    if station.estimator.unknown_wrench_frames:
        # Feet without F/T sensors: eq. (10) with the soles' wrenches estimated from the
        # internal and external residuals (SoleWrenchCompensation), which the admittance
        # then reads net of them.
        compensation = _add_sole_wrench_compensation(builder, station, scenario, residual_kind, residual)
        residual_port = compensation.GetOutputPort("residual")

    # Joint admittance (eq. 14) on the measured joint positions.
    gains = gain_factor * admittance_gains_by_group(model, model_humanoid, scenario.admittance_gains)
    admittance = builder.AddSystem(
        JointAdmittanceController(
            model,
            gains,
            residual_includes_base=(residual_kind == "classical"),
            dead_band=admittance_dead_band(scenario, residual_kind, model_corrections, dead_band),
            max_rate=scenario.max_rate,
            integrate_from=scenario.integrate_from,
            support_frames=(
                (model_humanoid.sole_frames["left"], model_humanoid.sole_frames["right"])
                if scenario.closed_chain_projection
                else None
            ),
            hold_center_of_mass=scenario.closed_chain_projection and scenario.hold_center_of_mass,
        )
    )
    admittance.set_name("joint_admittance_controller")
    measured_position = builder.AddSystem(joint_position_selector(model))
    builder.Connect(station.sensed_state, measured_position.get_input_port())
    # The residual's offset at rest, measured while the robot stands untouched, is removed; the
    # first half of the tare lets the residual (1/K) and the base-state estimate converge.
    tare = builder.AddSystem(
        ResidualTare(
            residual_port.size(),
            scenario.tare_duration,
            residual.period,
            skip=0.5 * scenario.tare_duration,
        )
    )
    tare.set_name("residual_tare")
    builder.Connect(residual_port, tare.GetInputPort("residual"))
    builder.Connect(tare.GetOutputPort("tared_residual"), admittance.GetInputPort("residual"))
    builder.Connect(measured_position.get_output_port(), admittance.GetInputPort("measured_position"))
    builder.Connect(admittance.GetOutputPort("desired_position"), station.desired_position)

    log = scenario.log_period
    loggers = {
        "state": LogVectorOutput(plant.get_state_output_port(), builder, log),
        "sensed_state": LogVectorOutput(station.sensed_state, builder, log),
        "residual": LogVectorOutput(residual_port, builder, log),
        "tared_residual": LogVectorOutput(tare.GetOutputPort("tared_residual"), builder, log),
        "tau_c_real": LogVectorOutput(push_source.GetOutputPort("tau_c_real"), builder, log),
        "desired_position": LogVectorOutput(admittance.GetOutputPort("desired_position"), builder, log),
        "force_world": LogVectorOutput(push_source.GetOutputPort("force_world"), builder, log),
    }
    visualizer = overlay = None
    if meshcat is not None:
        from systems.simulation.visualization import add_effort_visualization

        # 32 Hz, the replay's frame rate: publishing faster only costs simulation time.
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.scene_graph, meshcat, MeshcatVisualizerParams(publish_period=1.0 / 32.0)
        )
        overlay = add_effort_visualization(
            builder,
            plant,
            meshcat,
            residual_port,
            plant.get_state_output_port(),
            list(station.topology.joints),
            max_effort=2.0,
            force_port=push_source.GetOutputPort("force_world"),
            point_port=push_source.GetOutputPort("point_world"),
            includes_base=(residual_kind == "classical"),
        )
    diagram = builder.Build()
    diagram.set_name(f"push_and_comply_{residual_kind}")
    return diagram, PushAndComplyHandles(
        station=station,
        residual_kind=residual_kind,
        residual=residual,
        tare=tare,
        admittance=admittance,
        push_source=push_source,
        loggers=loggers,
        meshcat_visualizer=visualizer,
        overlay=overlay,
        push_peak_force=peak_force,
    )


def push_and_comply_metrics(
    scenario: PushAndComplyScenario, handles: PushAndComplyHandles, s: dict, wall_time_s: float
) -> dict:
    """The metrics of one run, from its logged signals ``s`` (``logged_signals``: "t" and
    the loggers of ``handles``): knee flexion and joints moved from the posture at the push's
    start, CoM and pelvis height drop, the CoM's largest horizontal travel, foot slip, base
    tilt, whether it stayed upright, and the real-time factor of a run that took
    ``wall_time_s`` s; the admittance's dead band at the knees and the push's peak true
    effort there (eq. 12), N m."""
    station = handles.station
    plant, humanoid = station.plant, station.humanoid
    t, x = s["t"], s["state"]
    names = station.joint_names
    q = np.array([x[j.position_start()] for j in station.topology.joints])
    reference = int(np.searchsorted(t, scenario.push_start))  # posture when the push begins
    displacement = q - q[:, [reference]]
    max_displacement_deg = {
        n: float(np.degrees(np.abs(displacement[k, reference:]).max())) for k, n in enumerate(names)
    }
    knees = list(humanoid.joint_groups["knees"])
    flexion = {n: float(np.degrees(displacement[names.index(n), reference:].max())) for n in knees}
    # The admittance's dead band at the knees, against the push's own effort there (the true
    # joint effort, eq. 12): a soft threshold, it takes that much of the knees' residual.
    dead_band = np.broadcast_to(handles.admittance.dead_band, (len(names),))
    admittance_names = list(handles.admittance.joint_names)
    knee_dead_band = {n: float(dead_band[admittance_names.index(n)]) for n in knees}
    effort = np.abs(s["tau_c_real"][:, reference:]).max(axis=1) if "tau_c_real" in s else None
    knee_push_effort = {n: float(effort[names.index(n)]) for n in knees} if effort is not None else {}

    context = plant.CreateDefaultContext()
    com, pelvis_z, tilt_deg, soles = [], [], [], {side: [] for side in humanoid.sole_frames}
    for k in range(reference, x.shape[1]):
        plant.SetPositionsAndVelocities(context, x[:, k])
        com.append(plant.CalcCenterOfMassPositionInWorld(context))
        X_WB = humanoid.base_body.EvalPoseInWorld(context)
        pelvis_z.append(X_WB.translation()[2])
        tilt_deg.append(np.degrees(np.arccos(np.clip(X_WB.rotation().matrix()[2, 2], -1.0, 1.0))))
        for side, frame in humanoid.sole_frames.items():
            soles[side].append(frame.CalcPoseInWorld(context).translation())
    com, pelvis_z = np.array(com), np.array(pelvis_z)
    com_z = com[:, 2]
    slip = {
        side: float(np.linalg.norm(np.array(p)[:, :2] - np.array(p)[0, :2], axis=1).max()) for side, p in soles.items()
    }
    upright = bool(pelvis_z.min() > UPRIGHT_HEIGHT_FRACTION * pelvis_z[0] and max(tilt_deg) < UPRIGHT_MAX_TILT_DEG)
    return {
        "residual": handles.residual_kind,
        "push_peak_force_N": handles.push_peak_force,
        "knee_pitch_flexion_deg": min(flexion.values()) if flexion else None,
        "knee_pitch_flexion_per_knee_deg": flexion,
        "knee_dead_band_N_m": knee_dead_band,
        "knee_push_effort_N_m": knee_push_effort,
        "joints_moved_over_1deg": int(sum(v > 1.0 for v in max_displacement_deg.values())),
        "com_height_drop_m": float(com_z[0] - com_z.min()),
        "com_horizontal_travel_m": float(np.linalg.norm(com[:, :2] - com[0, :2], axis=1).max()),
        "pelvis_height_drop_m": float(pelvis_z[0] - pelvis_z.min()),
        "max_foot_slip_m": max(slip.values()),
        "foot_slip_m": slip,
        "max_base_tilt_deg": float(max(tilt_deg)),
        "upright": upright,
        "real_time_factor": scenario.duration / wall_time_s,
        "wall_time_s": wall_time_s,
        "max_joint_displacement_deg": max_displacement_deg,
    }
