"""Nao-like robot with compliant arms (Hawley, Rahem, Suleiman 2019, Sec. 6.4, Fig. 13).

    PushSource (both hands) ─► MultibodyPlant (nao_like, SAP 1 ms point contact) ◄─ PdGravityController
                                   │ contact results, state, IMU                         ▲ desired_position
    FsrArray ─► CenterOfPressure ─► LipForceObserverSystem ─► ObserverHandForce ─┐       │
       │ fsr_forces (K_a)         SupportFootCom, ImuComAcceleration             ▼       │
       └──────────────────────────────────────────────────────────► CompliantArmBlender ─► HandComplianceController
    JointTorqueFromPositionError (eq. 27) ─► ArmExternalForceEstimator (eqs. 25-26) ─┘   (eq. 29 + arm IK)
          ▲ desired_position (the controller's own command), sensed state                ▲ nominal_position
                                                                                     PostureSchedule (stance, lean)

Every estimator reads only sensor outputs (FSRs, IMU, encoders, base estimate) and the
commanded joint positions; the pushes' truth goes to loggers only. The postures, the gains,
the controller and every estimator are built from the robot's model (the station's
estimators' plant, ``station.estimator``), never from the simulated plant. Rates: plant and PD
1 kHz, observer 60 Hz (the paper's), joint-level estimator and compliance controller 100 Hz.
"""

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from diagrams.observer.nao_force_observer import full_posture, wide_stance
from diagrams.observer.nao_sensing import OBSERVER_PERIOD, add_observer_pipeline
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from diagrams.station.standing import default_gains
from systems.locomotion.posture_schedule import PostureSchedule
from systems.observer.arm_compliance import (
    DEFAULT_PERIOD,
    DEFAULT_STIFFNESS,
    FSR_CONTACT_THRESHOLD,
    NAO_ARM_CHAINS,
    ArmExternalForceEstimator,
    CompliantArmBlender,
    HandComplianceController,
    JointTorqueFromPositionError,
    ObserverHandForce,
)
from systems.observer.force_observer import LipForceObserverSystem
from systems.observer.fsr_sensing import CenterOfPressure, FsrArray, ImuComAcceleration, SupportFootCom
from systems.simulation.disturbances import Push, PushSource, SmoothPiecewise
from systems.simulation.ground_truth import VirtualForceTruth
from systems.simulation.pd_gravity import joint_vector_from_names
from systems.simulation.visualization import ESTIMATE_RGBA, add_force_arrows


def lean_posture(delta: float, posture: dict[str, float] | None = None) -> dict[str, float]:
    """A scripted sideways lean: both hips roll by ``delta`` and both ankles by -``delta``
    (rad), on top of ``posture`` (default ``wide_stance()``). Kinematically a parallelogram
    that shifts the pelvis (negative delta: towards -y, the right foot); on nao_like, whose
    ankle PD is soft (40 N m/rad), the feet also roll onto their edges, so FSRs lose
    contact (``apps.nao_compliant_arms`` prints the resulting K1 of case b)."""
    out = dict(wide_stance() if posture is None else posture)
    for name in ("LHipRoll", "RHipRoll"):
        out[name] = out.get(name, 0.0) + delta
    for name in ("LAnkleRoll", "RAnkleRoll"):
        out[name] = out.get(name, 0.0) - delta
    return out


@dataclass
class NaoCompliantArmsHandles:
    """What ``build_nao_compliant_arms_diagram`` created.

    Attributes:
        station: plant, sensors, PD + gravity controller.
        pushes, push_source: the pushes and their source (truth to loggers only).
        posture_schedule: the nominal posture source.
        fsr_array, center_of_pressure, support_foot_com, imu_com_acceleration, observer:
            the observer pipeline (``diagrams.observer.nao_sensing.add_observer_pipeline``).
        observer_hand_force: ObserverHandForce.
        joint_torque: JointTorqueFromPositionError (eq. 27).
        joint_estimator: ArmExternalForceEstimator (eqs. 25-26).
        blender: CompliantArmBlender (eq. 28).
        controller: HandComplianceController (eq. 29).
        truth: VirtualForceTruth (eq. 11, for the observer's own comparison).
        motor_constants: {joint: K_m} used by eq. 27 and the deflection compensation.
        loggers: VectorLogSinks sampled every ``log_period``: ``observer_force``,
            ``joint_force``, ``blended_force`` (3 per hand, world), ``k1``, ``hand_target``,
            ``hand_position`` (torso frame, sensed), ``force_world`` (true pushes),
            ``virtual_force`` / ``virtual_truth`` (eq. 11), ``fsr_forces``,
            ``true_fsr_forces``, ``state`` (true plant state), ``desired_position``.
        meshcat_visualizer: or None.
    """

    station: HumanoidStation
    pushes: tuple
    push_source: PushSource
    posture_schedule: PostureSchedule
    fsr_array: FsrArray
    center_of_pressure: CenterOfPressure
    support_foot_com: SupportFootCom
    imu_com_acceleration: ImuComAcceleration
    observer: LipForceObserverSystem
    observer_hand_force: ObserverHandForce
    joint_torque: JointTorqueFromPositionError
    joint_estimator: ArmExternalForceEstimator
    blender: CompliantArmBlender
    controller: HandComplianceController
    truth: VirtualForceTruth
    motor_constants: dict
    loggers: dict[str, VectorLogSink]
    meshcat_visualizer: MeshcatVisualizer | None = None

    def set_initial_state(self, root_context: Context, state: np.ndarray | None = None) -> None:
        """Robot state [q; v] (default: the station's) and the PD's held sensor sample."""
        self.station.set_initial_state(root_context, state)


def build_nao_compliant_arms_diagram(
    pushes: Sequence[Push] = (),
    *,
    posture: dict[str, float] | None = None,
    posture_knots: Sequence[tuple[float, dict[str, float]]] = (),
    stiffness: float = DEFAULT_STIFFNESS,
    motor_constants: Mapping[str, float] | None = None,
    compensate_deflection: bool = True,
    constant_k1: float | None = None,
    fsr_threshold: float = FSR_CONTACT_THRESHOLD,
    saturation_guard: bool = False,
    station: StationConfig | None = None,
    period: float = DEFAULT_PERIOD,
    filter_time_constant: float = 0.1,
    support_foot: str = "right",
    log_period: float = 0.01,
    meshcat: Meshcat | None = None,
) -> tuple[Diagram, NaoCompliantArmsHandles]:
    """Builds the diagram of the module docstring.

    Args:
        pushes: external forces (e.g. on both hands along x).
        posture: overrides of the nominal posture (default ``wide_stance()``); its arm
            entries set the hands' rest positions x_h^0.
        posture_knots: optional (time, posture overrides) knots of a scripted posture change
            (e.g. ``lean_posture``); the posture is ``posture`` before the first knot.
        stiffness: k of eq. (29), N/m.
        motor_constants: {joint: K_m}, N m/rad, required: e.g.
            ``dict(diagrams.observer.calibration.identified_motor_constants())`` (a
            calibration run the caller makes; this builder does not simulate).
        compensate_deflection: the controller offsets q_d by K_m^-1 J^T F (see
            ``HandComplianceController``).
        constant_k1: None for eq. (28)'s K1 = K_a / K_t, else a constant.
        fsr_threshold: N, FSR "in contact" threshold of K_a.
        saturation_guard: K1 = 0 while an FSR saturates (an extension of eq. 28, see
            ``CompliantArmBlender``).
        station: the robot (``nao_like``) and its world (``diagrams.station.config``;
            default ``StationConfig(model="nao_like")``: noisy sensors, FSRs 0.1 N, see
            ``systems.simulation.sensors``; the ideal world).
        period: estimator and controller period, s.
        filter_time_constant: the joint-level estimate's low-pass, s.
        support_foot: the observer's support-foot frame.
        log_period: s.
        meshcat: adds a visualizer and force arrows (red: applied, blue: blended estimate).
    """
    if motor_constants is None:
        raise ValueError(
            "build_nao_compliant_arms_diagram: motor_constants is required ({arm joint: K_m}, N m/rad): "
            "pass dict(diagrams.observer.calibration.identified_motor_constants()) or your own"
        )
    config = StationConfig(model="nao_like") if station is None else station
    if config.model != "nao_like":
        raise ValueError(f"station.model must be nao_like (the compliant arms' robot), got {config.model!r}")
    noise, seed = config.noise, config.seed
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, config)
    # The simulated robot (plant, pushes, ground truth) and the robot's own model (the
    # estimators' plant: postures, gains, the controller and every estimator, issue 31).
    plant, humanoid = station.plant, station.humanoid
    model, model_humanoid = station.estimator.plant, station.estimator.humanoid
    if support_foot not in model_humanoid.sole_frames:
        raise ValueError(f"unknown support foot {support_foot!r}")
    posture = wide_stance() if posture is None else dict(posture)
    q_nominal = joint_vector_from_names(model, full_posture(model_humanoid, posture))
    times, postures = [0.0], [q_nominal]
    for t, overrides in posture_knots:
        if float(t) <= times[-1]:
            raise ValueError("posture_knots: times must be positive and increasing")
        times.append(float(t))
        postures.append(joint_vector_from_names(model, full_posture(model_humanoid, overrides)))
    schedule = builder.AddSystem(PostureSchedule(times, np.array(postures)))
    schedule.set_name("posture_schedule")

    names = [n for c in NAO_ARM_CHAINS for n in c.joint_names]
    _, kd = default_gains(model, model_humanoid)  # the station's PD gains (v[6:] order)
    kd_by_name = dict(zip(station.estimator.joint_names, kd.tolist()))
    damping = [kd_by_name[n] for n in names]

    controller = builder.AddSystem(
        HandComplianceController(
            model,
            q_nominal,
            NAO_ARM_CHAINS,
            stiffness=stiffness,
            motor_constants=motor_constants if compensate_deflection else None,
            period=period,
        )
    )
    controller.set_name("hand_compliance_controller")
    builder.Connect(schedule.get_output_port(), controller.GetInputPort("nominal_position"))
    builder.Connect(controller.GetOutputPort("desired_position"), station.desired_position)
    builder.Connect(station.sensed_state, controller.GetInputPort("state"))

    push_source = builder.AddSystem(PushSource(plant, list(pushes)))
    push_source.set_name("push_source")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))

    # Joint-level estimate (eqs. 25-27).
    joint_torque = builder.AddSystem(JointTorqueFromPositionError(model, motor_constants, NAO_ARM_CHAINS))
    joint_torque.set_name("joint_torque_from_position_error")
    builder.Connect(controller.GetOutputPort("desired_position"), joint_torque.GetInputPort("desired_position"))
    builder.Connect(station.sensed_state, joint_torque.GetInputPort("state"))
    estimator = builder.AddSystem(
        ArmExternalForceEstimator(
            model, NAO_ARM_CHAINS, damping=damping, period=period, filter_time_constant=filter_time_constant
        )
    )
    estimator.set_name("arm_external_force_estimator")
    builder.Connect(joint_torque.GetOutputPort("motor_torque"), estimator.GetInputPort("motor_torque"))
    builder.Connect(station.sensed_state, estimator.GetInputPort("state"))

    # Observer pipeline (as diagrams.observer.nao_force_observer).
    pipeline = add_observer_pipeline(
        builder, station, support_foot=support_foot, noise=noise, seed=seed, observer_period=OBSERVER_PERIOD
    )
    fsr, cop, com, acc = (
        pipeline.fsr_array,
        pipeline.center_of_pressure,
        pipeline.support_foot_com,
        pipeline.imu_com_acceleration,
    )
    observer = pipeline.observer
    hand_force = builder.AddSystem(
        ObserverHandForce(
            model,
            model_humanoid.sole_frames[support_foot],
            NAO_ARM_CHAINS,
            model_instances=[model_humanoid.model_instance],
        )
    )
    hand_force.set_name("observer_hand_force")
    builder.Connect(observer.GetOutputPort("virtual_force"), hand_force.GetInputPort("virtual_force"))
    builder.Connect(station.sensed_state, hand_force.GetInputPort("state"))

    # Eq. (28) and into eq. (29).
    size = 3 * len(NAO_ARM_CHAINS)
    blender = builder.AddSystem(
        CompliantArmBlender(
            size,
            fsr_threshold=fsr_threshold,
            constant_k1=constant_k1,
            saturation_guard=fsr.saturation if saturation_guard else None,
        )
    )
    blender.set_name("compliant_arm_blender")
    builder.Connect(hand_force.GetOutputPort("hand_forces"), blender.GetInputPort("observer_force"))
    builder.Connect(estimator.GetOutputPort("hand_forces"), blender.GetInputPort("joint_force"))
    builder.Connect(fsr.GetOutputPort("fsr_forces"), blender.GetInputPort("fsr_forces"))
    builder.Connect(blender.GetOutputPort("blended_force"), controller.GetInputPort("hand_forces"))

    truth = builder.AddSystem(VirtualForceTruth(plant, humanoid, support_foot=support_foot))
    truth.set_name("virtual_force_truth")
    builder.Connect(plant.get_state_output_port(), truth.GetInputPort("state"))
    builder.Connect(push_source.GetOutputPort("total_wrench_world"), truth.GetInputPort("total_wrench_world"))

    sources = {
        "observer_force": hand_force.GetOutputPort("hand_forces"),
        "joint_force": estimator.GetOutputPort("hand_forces"),
        "blended_force": blender.GetOutputPort("blended_force"),
        "k1": blender.GetOutputPort("k1"),
        "hand_target": controller.GetOutputPort("hand_target"),
        "hand_position": controller.GetOutputPort("hand_position"),
        "desired_position": controller.GetOutputPort("desired_position"),
        "force_world": push_source.GetOutputPort("force_world"),
        "virtual_force": observer.GetOutputPort("virtual_force"),
        "virtual_truth": truth.GetOutputPort("virtual_force"),
        "fsr_forces": fsr.GetOutputPort("fsr_forces"),
        "true_fsr_forces": fsr.GetOutputPort("true_fsr_forces"),
        "state": plant.get_state_output_port(),
    }
    loggers = {}
    for name, port in sources.items():
        loggers[name] = LogVectorOutput(port, builder, log_period)
        loggers[name].set_name(f"log_{name}")

    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.scene_graph, meshcat, MeshcatVisualizerParams(publish_period=1.0 / 32.0)
        )
        add_force_arrows(
            builder,
            meshcat,
            push_source.GetOutputPort("force_world"),
            push_source.GetOutputPort("point_world"),
            name="applied_force_arrows",
            path="applied_forces",
            newtons_per_meter=20.0,
        )
        if len(pushes) == len(NAO_ARM_CHAINS):
            add_force_arrows(
                builder,
                meshcat,
                blender.GetOutputPort("blended_force"),
                push_source.GetOutputPort("point_world"),
                name="estimated_force_arrows",
                path="estimated_hand_forces",
                newtons_per_meter=20.0,
                rgba=ESTIMATE_RGBA,
                min_force=0.2,
            )

    diagram = builder.Build()
    diagram.set_name("nao_compliant_arms")
    return diagram, NaoCompliantArmsHandles(
        station=station,
        pushes=tuple(pushes),
        push_source=push_source,
        posture_schedule=schedule,
        fsr_array=fsr,
        center_of_pressure=cop,
        support_foot_com=com,
        imu_com_acceleration=acc,
        observer=observer,
        observer_hand_force=hand_force,
        joint_torque=joint_torque,
        joint_estimator=estimator,
        blender=blender,
        controller=controller,
        truth=truth,
        motor_constants=dict(motor_constants),
        loggers=loggers,
        meshcat_visualizer=visualizer,
    )


def hand_pushes(profile, direction=(-1.0, 0.0, 0.0)) -> list[Push]:
    """The same push on both hands (gripper origins, the chains' hand points), world
    ``direction``, magnitude ``profile`` per hand, N."""
    return [Push(c.hand_body, c.p_HP, direction, profile) for c in NAO_ARM_CHAINS]


# --- Scenarios a and b of Sec. 6.4 (Fig. 14) ---------------------------------------------

#: Push per hand, N (along -x: towards the robot), and the schedule, s.
DEFAULT_FORCE = 1.5
PUSH_ON, PUSH_FULL, PUSH_OFF, PUSH_GONE, DURATION = 3.0, 5.0, 11.0, 13.0, 14.0
#: Steady-state window (last second of the hold) and the baseline window before the push.
STEADY_WINDOW = (PUSH_OFF - 1.0, PUSH_OFF)
BASELINE_WINDOW = (PUSH_ON - 1.0, PUSH_ON)
#: Scenario b's lean: knots (s) and hip-roll angle (rad).
LEAN_START, LEAN_END, LEAN_ANGLE = 0.5, 2.5, -0.1
#: Floor: relative error of the steady-state hand displacement vs F / k.
DISPLACEMENT_FLOOR = 0.10
SIDES = tuple(c.side for c in NAO_ARM_CHAINS)
CASE_NAMES = ("a", "b")


@dataclass(slots=True)
class NaoCompliantArmsScenario:
    """The settings of ``apps.nao_compliant_arms`` (SI units). Defaults: the paper's
    Sec. 6.4 with a 1.5 N push per hand.

    Attributes:
        cases: which of the paper's scenarios run, in order: "a" (standing, all FSRs
            loaded) and/or "b" (leaning sideways, feet partly off the ground).
        force: push per hand along -x, N (in (0, 4]: the arms' effort limits).
        lean: scenario b's hip-roll lean, rad (``lean_posture``; within +-0.3).
        stiffness: k of eq. (29), N/m.
        compensate_deflection: the controller offsets q_d by K_m^-1 J^T F (False: the
            ablation without it).
        saturation_guard: K1 = 0 while an FSR saturates (an extension of eq. 28).
        station: the robot (``nao_like``) and its world (``diagrams.station.config``): the
            sensors' noise and seed, Drake's plant configuration (the settled initial state
            uses the same). The K_m identification
            (``diagrams.observer.calibration.identified_motor_constants``) runs on the
            station's default plant.
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``).
    """

    station: StationConfig = field(default_factory=lambda: StationConfig(model="nao_like"))
    cases: list[str] = field(default_factory=lambda: list(CASE_NAMES))
    force: float = DEFAULT_FORCE
    lean: float = LEAN_ANGLE
    stiffness: float = DEFAULT_STIFFNESS
    compensate_deflection: bool = True
    saturation_guard: bool = False
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)


@dataclass(frozen=True)
class HandPushCase:
    """Scenario a or b of Sec. 6.4: its name, title, push per hand (N) and lean (rad, or
    None: no lean)."""

    name: str
    title: str
    force: float
    lean: float | None

    def pushes(self) -> list[Push]:
        profile = SmoothPiecewise(
            (0.0, PUSH_ON, PUSH_FULL, PUSH_OFF, PUSH_GONE), (0.0, 0.0, self.force, self.force, 0.0)
        )
        return hand_pushes(profile, direction=(-1.0, 0.0, 0.0))

    def posture_knots(self) -> tuple:
        if self.lean is None:
            return ()
        return ((LEAN_START, wide_stance()), (LEAN_END, lean_posture(self.lean)))


def make_scenario(name: str, force: float = DEFAULT_FORCE, lean: float = LEAN_ANGLE) -> HandPushCase:
    """Scenario ``name`` ("a" or "b") with ``force`` N per hand; ``lean`` is b's hip-roll
    lean, rad (``lean_posture``).

    * a: standing (wide stance), all 8 FSRs loaded: K1 = 1, the observer drives eq. 29;
    * b: the robot first leans sideways (t = 0.5-2.5 s, both hip rolls ``lean``, ankle rolls
      -``lean``): the soft ankles let both feet roll onto their edges and FSRs lose contact,
      so K1 = K_a / K_t < 1 and the joint-level estimate takes part of the weight.

    Raises:
        ValueError: an unknown scenario, a force outside (0, 4] N, a lean beyond +-0.3 rad.
    """
    if name not in CASE_NAMES:
        raise ValueError(f"unknown scenario {name!r}; choose a or b")
    if not (math.isfinite(force) and 0.0 < force <= 4.0):
        raise ValueError(f"force must be in (0, 4] N per hand (arm effort limits), got {force}")
    if not (math.isfinite(lean) and abs(lean) <= 0.3):
        raise ValueError(f"lean must be within +-0.3 rad (joint limits), got {lean}")
    if name == "a":
        return HandPushCase("a", f"a: {force:g} N per hand along -x, standing (all FSRs loaded)", force, None)
    title = f"b: {force:g} N per hand along -x while leaning {lean:g} rad (feet partly off)"
    return HandPushCase("b", title, force, lean)


def scenario_cases(scenario: NaoCompliantArmsScenario) -> list[HandPushCase]:
    """The cases of ``scenario``, in its order (``make_scenario`` of each).

    Raises:
        ValueError: no case, a bad case (see ``make_scenario``), a negative seed, a
            non-positive stiffness.
    """
    if not scenario.cases:
        raise ValueError("the scenario runs no case; choose one or both of a, b")
    scenario.station.check()
    if not (math.isfinite(scenario.stiffness) and scenario.stiffness > 0):
        raise ValueError(f"stiffness must be positive, got {scenario.stiffness}")
    return [make_scenario(name, scenario.force, scenario.lean) for name in scenario.cases]


def build_case_diagram(
    scenario: NaoCompliantArmsScenario,
    case: HandPushCase,
    motor_constants: Mapping[str, float],
    meshcat: Meshcat | None = None,
) -> tuple[Diagram, NaoCompliantArmsHandles]:
    """``build_nao_compliant_arms_diagram`` for ``case`` with the scenario's settings and
    the caller's ``motor_constants`` (e.g.
    ``dict(diagrams.observer.calibration.identified_motor_constants())``). Its initial state
    is the caller's too: ``settle_standing_state(wide_stance(), plant_config=...)``."""
    return build_nao_compliant_arms_diagram(
        case.pushes(),
        posture_knots=case.posture_knots(),
        stiffness=scenario.stiffness,
        motor_constants=dict(motor_constants),
        compensate_deflection=scenario.compensate_deflection,
        saturation_guard=scenario.saturation_guard,
        station=scenario.station,
        meshcat=meshcat,
    )


def true_hand_kinematics(run: dict) -> tuple[np.ndarray, np.ndarray]:
    """From the TRUE state log: (samples, 3 per hand) hand positions in the torso frame B, m,
    and (samples, 3, 3) R_WB."""
    handles = run["handles"]
    plant = handles.station.plant
    base = handles.station.humanoid.base_body.body_frame()
    frames = [plant.GetBodyByName(c.hand_body).body_frame() for c in NAO_ARM_CHAINS]
    points = [np.asarray(c.p_HP, float) for c in NAO_ARM_CHAINS]
    ctx = plant.CreateDefaultContext()
    X = run["signals"]["state"].T
    nq = plant.num_positions()
    p = np.empty((len(X), 3 * len(frames)))
    R = np.empty((len(X), 3, 3))
    for i, x in enumerate(X):
        plant.SetPositions(ctx, x[:nq])
        for j, (frame, point) in enumerate(zip(frames, points, strict=True)):
            p[i, 3 * j : 3 * j + 3] = plant.CalcPointsPositions(ctx, frame, point, base).reshape(-1)
        R[i] = base.CalcRotationMatrixInWorld(ctx).matrix()
    return p, R


def _to_base(forces_W: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(samples, 3 per hand) world forces -> torso frame, with R (samples, 3, 3) = R_WB."""
    F = forces_W.reshape(len(forces_W), -1, 3)
    return np.einsum("nji,nkj->nki", R, F).reshape(len(forces_W), -1)


def scenario_metrics(case: HandPushCase, run: dict, stiffness: float = DEFAULT_STIFFNESS) -> dict:
    """The metrics of one case's run {"signals": logged signals (times of "state"),
    "handles": NaoCompliantArmsHandles, "wall": wall-clock s}, with the plotted series
    under "_series" (the caller pops it before writing).

    Measured quantity: each hand's displacement along the torso's x axis, from the TRUE
    plant state (torso-frame kinematics), relative to its mean over the second before the
    push. Its mean over the last second of the hold is compared with F_true / k (the
    applied force in the torso frame) and with F_est / k (the mean blended estimate that the
    controller used). Floor (issue 7): within 10 % of F / k in steady state, against both."""
    s = run["signals"]
    t = s["t"]
    p, R = true_hand_kinematics(run)
    base = (t >= BASELINE_WINDOW[0]) & (t < BASELINE_WINDOW[1])
    steady = (t >= STEADY_WINDOW[0]) & (t < STEADY_WINDOW[1])
    hold = (t >= PUSH_FULL) & (t < PUSH_OFF)
    dx = p - p[base].mean(axis=0)
    F_true = _to_base(s["force_world"].T, R)
    estimates = {name: _to_base(s[name].T, R) for name in ("observer_force", "joint_force", "blended_force")}
    hands = {}
    worst_true, worst_est = 0.0, 0.0
    for j, side in enumerate(SIDES):
        x = 3 * j
        disp = float(dx[steady, x].mean())
        f_true = float(F_true[steady, x].mean())
        f_est = float(estimates["blended_force"][steady, x].mean())
        rel_true = abs(disp - f_true / stiffness) / abs(f_true / stiffness)
        rel_est = abs(disp - f_est / stiffness) / abs(f_est / stiffness)
        worst_true, worst_est = max(worst_true, rel_true), max(worst_est, rel_est)
        errors = {}
        for name, F in estimates.items():
            e = F[:, x] - F_true[:, x]
            errors[name] = {
                "steady_state_mean_error_N": float(e[steady].mean()),
                "hold_rms_error_N": float(np.sqrt(np.mean(e[hold] ** 2))),
            }
        hands[side] = {
            "displacement_m": disp,
            "F_true_x_N": f_true,
            "F_est_x_N": f_est,
            "F_true_over_k_m": f_true / stiffness,
            "F_est_over_k_m": f_est / stiffness,
            "relative_error_vs_true": rel_true,
            "relative_error_vs_estimate": rel_est,
            "estimate_errors_x": errors,
        }
    k1 = s["k1"][0]
    fsr = s["fsr_forces"]
    handles = run["handles"]
    x = s["state"]
    z_base = x[handles.station.humanoid.base_body.floating_positions_start() + 6]
    return {
        "title": case.title,
        "force_per_hand_N": case.force,
        "stiffness_N_per_m": stiffness,
        "steady_window_s": list(STEADY_WINDOW),
        "hands": hands,
        "worst_relative_error_vs_true": worst_true,
        "worst_relative_error_vs_estimate": worst_est,
        "floor_relative_error": DISPLACEMENT_FLOOR,
        "meets_floor": bool(worst_true <= DISPLACEMENT_FLOOR and worst_est <= DISPLACEMENT_FLOOR),
        "k1_steady_mean": float(k1[steady].mean()),
        "k1_min_after_first_step": float(k1[t >= 0.05].min()),
        "k1_before_push_mean": float(k1[base].mean()),
        "fsr_steady_mean_N": fsr[:, steady].mean(axis=1).tolist(),
        "fsr_saturated_samples": int(np.sum(np.any(fsr >= handles.fsr_array.saturation - 1e-9, axis=0))),
        "base_height_drop_m": float(z_base[0] - z_base.min()),
        "wall_time_s": run["wall"],
        "real_time_factor": DURATION / run["wall"],
        "_series": {"t": t, "dx": dx, "F_true": F_true, **estimates, "k1": k1},
    }


def arms_summary(scenario: NaoCompliantArmsScenario, metrics: dict, motor_constants: Mapping[str, float]) -> dict:
    """The "summary" entry of the app's metrics: every floor met, and the run's settings."""
    return {
        "all_floors_met": all(m["meets_floor"] for m in metrics.values()),
        "seed": scenario.station.seed,
        "motor_constants_N_m_per_rad": dict(motor_constants),
        "controller": f"eq. 29 with k = {scenario.stiffness:g} N/m, damped least-squares arm IK, "
        + (
            "deflection compensation K_m^-1 J^T F"
            if scenario.compensate_deflection
            else "no deflection compensation (ablation)"
        ),
        "deflection_compensation": scenario.compensate_deflection,
        "blend": "eq. 28, K1 = K_a / 8, FSR in contact above 1 N",
        "lean_rad": scenario.lean,
        "saturation_guard": scenario.saturation_guard,
    }


__all__ = [
    "BASELINE_WINDOW",
    "CASE_NAMES",
    "DEFAULT_FORCE",
    "DISPLACEMENT_FLOOR",
    "DURATION",
    "LEAN_ANGLE",
    "SIDES",
    "STEADY_WINDOW",
    "HandPushCase",
    "NaoCompliantArmsHandles",
    "NaoCompliantArmsScenario",
    "arms_summary",
    "build_case_diagram",
    "make_scenario",
    "scenario_cases",
    "scenario_metrics",
    "true_hand_kinematics",
    "build_nao_compliant_arms_diagram",
    "hand_pushes",
    "lean_posture",
]
