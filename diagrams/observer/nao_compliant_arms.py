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
commanded joint positions; the pushes' truth goes to loggers only. Rates: plant and PD
1 kHz, observer 60 Hz (the paper's), joint-level estimator and compliance controller 100 Hz.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Rgba
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from diagrams.station.standing import default_gains
from diagrams.observer.nao_force_observer import full_posture, wide_stance
from diagrams.observer.nao_sensing import OBSERVER_PERIOD, add_observer_pipeline
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
from systems.simulation.disturbances import Push, PushSource
from systems.simulation.ground_truth import VirtualForceTruth
from systems.locomotion.posture_schedule import PostureSchedule
from systems.observer.force_observer import LipForceObserverSystem
from systems.observer.fsr_sensing import CenterOfPressure, FsrArray, ImuComAcceleration, SupportFootCom
from systems.simulation.pd_gravity import joint_vector_from_names
from systems.simulation.visualization import ForceArrows


def lean_posture(delta: float, posture: dict[str, float] | None = None) -> dict[str, float]:
    """A scripted sideways lean: both hips roll by ``delta`` and both ankles by -``delta``
    (rad), on top of ``posture`` (default ``wide_stance()``). Kinematically a parallelogram
    that shifts the pelvis (negative delta: towards -y, the right foot); on nao_like, whose
    ankle PD is soft (40 N m/rad), the feet also roll onto their edges, so FSRs lose
    contact (measured: delta = -0.1 leaves 2 of the 8 FSRs below 1 N, and 4 once
    ``apps.nao_compliant_arms`` pushes each hand backwards by 1.5 N)."""
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
    noise: bool = True,
    seed: int = 0,
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
        noise, seed: sensor noise (FSRs: 0.1 N; see ``systems.simulation.sensors``).
        period: estimator and controller period, s.
        filter_time_constant: the joint-level estimate's low-pass, s.
        support_foot: the observer's support-foot frame.
        log_period: s.
        meshcat: adds a visualizer and force arrows (red: applied, blue: blended estimate).
    """
    if motor_constants is None:
        raise ValueError("build_nao_compliant_arms_diagram: motor_constants is required ({arm joint: K_m}, N m/rad): "
                         "pass dict(diagrams.observer.calibration.identified_motor_constants()) or your own")
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, "nao_like", noise=noise, seed=seed)
    plant, humanoid = station.plant, station.humanoid
    if support_foot not in humanoid.sole_frames:
        raise ValueError(f"unknown support foot {support_foot!r}")
    posture = wide_stance() if posture is None else dict(posture)
    q_nominal = joint_vector_from_names(plant, full_posture(humanoid, posture))
    times, postures = [0.0], [q_nominal]
    for t, overrides in posture_knots:
        if float(t) <= times[-1]:
            raise ValueError("posture_knots: times must be positive and increasing")
        times.append(float(t))
        postures.append(joint_vector_from_names(plant, full_posture(humanoid, overrides)))
    schedule = builder.AddSystem(PostureSchedule(times, np.array(postures)))
    schedule.set_name("posture_schedule")

    names = [n for c in NAO_ARM_CHAINS for n in c.joint_names]
    _, kd = default_gains(plant, humanoid)  # the station's PD gains (v[6:] order)
    kd_by_name = dict(zip(station.joint_names, kd.tolist()))
    damping = [kd_by_name[n] for n in names]

    controller = builder.AddSystem(HandComplianceController(
        plant, q_nominal, NAO_ARM_CHAINS, stiffness=stiffness,
        motor_constants=motor_constants if compensate_deflection else None, period=period))
    controller.set_name("hand_compliance_controller")
    builder.Connect(schedule.get_output_port(), controller.GetInputPort("nominal_position"))
    builder.Connect(controller.GetOutputPort("desired_position"), station.desired_position)
    builder.Connect(station.sensed_state, controller.GetInputPort("state"))

    push_source = builder.AddSystem(PushSource(plant, list(pushes)))
    push_source.set_name("push_source")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))

    # Joint-level estimate (eqs. 25-27).
    joint_torque = builder.AddSystem(JointTorqueFromPositionError(plant, motor_constants, NAO_ARM_CHAINS))
    joint_torque.set_name("joint_torque_from_position_error")
    builder.Connect(controller.GetOutputPort("desired_position"), joint_torque.GetInputPort("desired_position"))
    builder.Connect(station.sensed_state, joint_torque.GetInputPort("state"))
    estimator = builder.AddSystem(ArmExternalForceEstimator(
        plant, NAO_ARM_CHAINS, damping=damping, period=period, filter_time_constant=filter_time_constant))
    estimator.set_name("arm_external_force_estimator")
    builder.Connect(joint_torque.GetOutputPort("motor_torque"), estimator.GetInputPort("motor_torque"))
    builder.Connect(station.sensed_state, estimator.GetInputPort("state"))

    # Observer pipeline (as diagrams.observer.nao_force_observer).
    pipeline = add_observer_pipeline(builder, station, support_foot=support_foot, noise=noise, seed=seed,
                                     observer_period=OBSERVER_PERIOD)
    fsr, cop, com, acc = pipeline.fsr_array, pipeline.center_of_pressure, pipeline.support_foot_com, pipeline.imu_com_acceleration
    observer = pipeline.observer
    hand_force = builder.AddSystem(ObserverHandForce(plant, humanoid.sole_frames[support_foot], NAO_ARM_CHAINS,
                                                     model_instances=[humanoid.model_instance]))
    hand_force.set_name("observer_hand_force")
    builder.Connect(observer.GetOutputPort("virtual_force"), hand_force.GetInputPort("virtual_force"))
    builder.Connect(station.sensed_state, hand_force.GetInputPort("state"))

    # Eq. (28) and into eq. (29).
    size = 3 * len(NAO_ARM_CHAINS)
    blender = builder.AddSystem(CompliantArmBlender(
        size, fsr_threshold=fsr_threshold, constant_k1=constant_k1,
        saturation_guard=fsr.saturation if saturation_guard else None))
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
            builder, station.scene_graph, meshcat, MeshcatVisualizerParams(publish_period=1.0 / 32.0))
        applied = builder.AddSystem(ForceArrows(meshcat, len(pushes), path="applied_forces", newtons_per_meter=20.0))
        applied.set_name("applied_force_arrows")
        builder.Connect(push_source.GetOutputPort("force_world"), applied.get_force_world_input_port())
        builder.Connect(push_source.GetOutputPort("point_world"), applied.get_point_world_input_port())
        if len(pushes) == len(NAO_ARM_CHAINS):
            estimate = builder.AddSystem(ForceArrows(meshcat, len(NAO_ARM_CHAINS), path="estimated_hand_forces",
                                                     newtons_per_meter=20.0, rgba=Rgba(0.1, 0.3, 0.9, 0.9),
                                                     min_force=0.2))
            estimate.set_name("estimated_force_arrows")
            builder.Connect(blender.GetOutputPort("blended_force"), estimate.get_force_world_input_port())
            builder.Connect(push_source.GetOutputPort("point_world"), estimate.get_point_world_input_port())

    diagram = builder.Build()
    diagram.set_name("nao_compliant_arms")
    return diagram, NaoCompliantArmsHandles(
        station=station, pushes=tuple(pushes), push_source=push_source, posture_schedule=schedule,
        fsr_array=fsr, center_of_pressure=cop, support_foot_com=com, imu_com_acceleration=acc,
        observer=observer, observer_hand_force=hand_force, joint_torque=joint_torque, joint_estimator=estimator,
        blender=blender, controller=controller, truth=truth, motor_constants=dict(motor_constants),
        loggers=loggers, meshcat_visualizer=visualizer)


def hand_pushes(profile, direction=(-1.0, 0.0, 0.0)) -> list[Push]:
    """The same push on both hands (gripper origins, the chains' hand points), world
    ``direction``, magnitude ``profile`` per hand, N."""
    return [Push(c.hand_body, c.p_HP, direction, profile) for c in NAO_ARM_CHAINS]


__all__ = [
    "NaoCompliantArmsHandles",
    "build_nao_compliant_arms_diagram",
    "hand_pushes",
    "lean_posture",
]
