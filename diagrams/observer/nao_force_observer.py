"""Nao-like robot standing under joint position control, with the Kalman force observer of
Hawley, Rahem and Suleiman (2019) fed by its simulated FSRs, IMU and encoders.

    PushSource ─► MultibodyPlant (nao_like, flat ground, SAP 1 ms point contact)
     │ truth         ▲ actuation                 │ contact results, state, body kinematics
     │               PdGravityController ◄── q_desired (constant posture: position control)
     ▼                                           ▼
    VirtualForceTruth (eq. 11)      FsrArray ─► CenterOfPressure ─► normal_force, zmp
     ▼                              sensed state ─► SupportFootCom ─► com_position
    loggers ◄─────────────────────  IMU ─► ImuComAcceleration ─► com_acceleration
                                                   ▼
                                   LipForceObserverSystem (T = 1/60 s) ─► virtual_force

The observer reads only sensor outputs (FSRs, IMU, encoders and the base estimate of
``systems.simulation.sensors``); the true state and the applied forces reach only the ground-truth
system and the loggers. The support-foot frame F is world-aligned with its origin at the
support sole frame (see ``systems.observer.fsr_sensing``).

Timing: the observer updates at t_k = k T and reads the sensors at t_k; a logger publishes
before the discrete updates of the same time, so the estimate of sample k appears in the
``virtual_force`` log at t_{k+1}. Drake's discrete plant reports contact results only after
its first step: the observer's first sample (t = 0) reads zero FSR forces; the filters
absorb it within ~0.3 s (< 0.2 N on F_z, measured).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Rgba
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.observer.nao_sensing import OBSERVER_PERIOD, add_observer_pipeline
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from models import HumanoidHandles
from systems.simulation.disturbances import Push, PushSource
from systems.simulation.ground_truth import VirtualForceTruth
from systems.observer.force_observer import LipForceObserverSystem, LipObserverParameters
from systems.observer.fsr_sensing import CenterOfPressure, FsrArray, ImuComAcceleration, SupportFootCom
from systems.simulation.pd_gravity import joint_vector_from_names
from systems.simulation.visualization import ForceArrows



@dataclass
class NaoForceObserverHandles:
    """What ``build_nao_force_observer_diagram`` created.

    Attributes:
        station: the humanoid station (plant, scene graph, sensors, PD + gravity controller).
        support_foot: "left" or "right", the origin of the support-foot frame.
        parameters: the observer's parameters (eq. 21, robot mass, T = 1/60 s).
        fsr_array, center_of_pressure, support_foot_com, imu_com_acceleration: the
            measurement pipeline (``systems.observer.fsr_sensing``).
        observer: the LipForceObserverSystem.
        push_source: the PushSource (its ground truth goes to ``truth`` and loggers only).
        truth: the VirtualForceTruth.
        q_desired: the joint positions the PD holds (v[6:] order), rad.
        loggers: VectorLogSinks, sampled every observer period: ``virtual_force`` (estimate),
            ``valid``, ``truth`` (eq. 11), ``fsr_forces``, ``true_fsr_forces``,
            ``normal_force``, ``zmp``, ``com_position``, ``true_com_position``,
            ``com_acceleration``, ``force_world``, ``state`` (true plant state).
        meshcat_visualizer: the MeshcatVisualizer, or None.
    """

    station: HumanoidStation
    support_foot: str
    parameters: LipObserverParameters
    fsr_array: FsrArray
    center_of_pressure: CenterOfPressure
    support_foot_com: SupportFootCom
    imu_com_acceleration: ImuComAcceleration
    observer: LipForceObserverSystem
    push_source: PushSource
    truth: VirtualForceTruth
    loggers: dict[str, VectorLogSink]
    q_desired: np.ndarray
    meshcat_visualizer: MeshcatVisualizer | None = None

    def set_initial_state(self, root_context: Context, state: np.ndarray | None = None) -> None:
        """Puts the robot in ``state`` ([q; v] of the plant; default: the station's standing
        state in the nominal posture; better
        ``diagrams.observer.calibration.settle_standing_state(posture)``) in the
        diagram's root context."""
        self.station.set_initial_state(root_context, state)


def build_nao_force_observer_diagram(
    pushes: Sequence[Push] = (),
    *,
    posture: dict[str, float] | None = None,
    support_foot: str = "right",
    noise: bool = True,
    seed: int = 0,
    fsr_noise_std: float | None = None,
    observer_period: float = OBSERVER_PERIOD,
    meshcat: Meshcat | None = None,
) -> tuple[Diagram, NaoForceObserverHandles]:
    """Builds the diagram of the module docstring.

    Args:
        pushes: external forces on the robot (``systems.simulation.disturbances.Push``).
        posture: joint name -> angle (rad) overriding the model's nominal standing posture
            (e.g. ``wide_stance()``); the PD holds it (position control).
        support_foot: "left" or "right": origin of the support-foot frame.
        noise: sensor noise on (defaults of ``systems.simulation.sensors`` and ``systems.observer.fsr_sensing``).
        seed: noise seed; the FSRs use 16 seed + 5, the other sensors 16 seed + 0..4.
        fsr_noise_std: N per FSR (default ``fsr_sensing.FSR_NOISE_STD``; ignored without noise).
        observer_period: T, s (1/60 s: the paper's 16.7 ms).
        meshcat: if given, a MeshcatVisualizer and arrows for the applied forces (red) and
            the estimated virtual force at the CoM (blue) are added (32 Hz).

    Raises:
        ValueError: unknown support foot, bad pushes (unknown body), bad noise settings.
    """
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, "nao_like", noise=noise, seed=seed)
    plant, humanoid = station.plant, station.humanoid
    if support_foot not in humanoid.sole_frames:
        raise ValueError(f"unknown support foot {support_foot!r}; choose one of {sorted(humanoid.sole_frames)}")

    # Position control: the PD + gravity compensation holds the standing posture.
    q_desired = joint_vector_from_names(plant, full_posture(humanoid, posture))
    hold = builder.AddSystem(ConstantVectorSource(q_desired))
    hold.set_name("joint_position_command")
    builder.Connect(hold.get_output_port(), station.desired_position)

    push_source = builder.AddSystem(PushSource(plant, list(pushes)))
    push_source.set_name("push_source")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))

    # Measurement pipeline (sensors only) and the observer (``diagrams.observer.nao_sensing``).
    pipeline = add_observer_pipeline(builder, station, support_foot=support_foot, noise=noise, seed=seed,
                                     fsr_noise_std=fsr_noise_std, observer_period=observer_period)
    fsr, cop, com, acc = pipeline.fsr_array, pipeline.center_of_pressure, pipeline.support_foot_com, pipeline.imu_com_acceleration
    parameters, observer = pipeline.parameters, pipeline.observer

    truth = builder.AddSystem(VirtualForceTruth(plant, humanoid, support_foot=support_foot))
    truth.set_name("virtual_force_truth")
    builder.Connect(plant.get_state_output_port(), truth.GetInputPort("state"))
    builder.Connect(push_source.GetOutputPort("total_wrench_world"), truth.GetInputPort("total_wrench_world"))

    T = parameters.period
    loggers = {
        "virtual_force": LogVectorOutput(observer.GetOutputPort("virtual_force"), builder, T),
        "valid": LogVectorOutput(observer.GetOutputPort("valid"), builder, T),
        "truth": LogVectorOutput(truth.GetOutputPort("virtual_force"), builder, T),
        "fsr_forces": LogVectorOutput(fsr.GetOutputPort("fsr_forces"), builder, T),
        "true_fsr_forces": LogVectorOutput(fsr.GetOutputPort("true_fsr_forces"), builder, T),
        "normal_force": LogVectorOutput(cop.GetOutputPort("normal_force"), builder, T),
        "zmp": LogVectorOutput(cop.GetOutputPort("zmp"), builder, T),
        "com_position": LogVectorOutput(com.GetOutputPort("com_position"), builder, T),
        "true_com_position": LogVectorOutput(truth.GetOutputPort("com_position"), builder, T),
        "com_acceleration": LogVectorOutput(acc.GetOutputPort("com_acceleration"), builder, T),
        "force_world": LogVectorOutput(push_source.GetOutputPort("force_world"), builder, T),
        "state": LogVectorOutput(plant.get_state_output_port(), builder, T),
    }
    for name, logger in loggers.items():
        logger.set_name(f"log_{name}")

    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.scene_graph, meshcat, MeshcatVisualizerParams(publish_period=1.0 / 32.0))
        applied = builder.AddSystem(ForceArrows(meshcat, len(pushes), path="applied_forces", newtons_per_meter=40.0))
        applied.set_name("applied_force_arrows")
        builder.Connect(push_source.GetOutputPort("force_world"), applied.get_force_world_input_port())
        builder.Connect(push_source.GetOutputPort("point_world"), applied.get_point_world_input_port())
        estimate = builder.AddSystem(ForceArrows(meshcat, 1, path="estimated_virtual_force", newtons_per_meter=40.0,
                                                 rgba=Rgba(0.1, 0.3, 0.9, 0.9), min_force=0.3))
        estimate.set_name("estimated_force_arrow")
        builder.Connect(observer.GetOutputPort("virtual_force"), estimate.get_force_world_input_port())
        builder.Connect(truth.GetOutputPort("com_world"), estimate.get_point_world_input_port())

    diagram = builder.Build()
    diagram.set_name("nao_force_observer")
    return diagram, NaoForceObserverHandles(
        station=station,
        support_foot=support_foot,
        parameters=parameters,
        fsr_array=fsr,
        center_of_pressure=cop,
        support_foot_com=com,
        imu_com_acceleration=acc,
        observer=observer,
        push_source=push_source,
        truth=truth,
        loggers=loggers,
        q_desired=q_desired,
        meshcat_visualizer=visualizer,
    )


def wide_stance(hip_roll: float = 0.1) -> dict[str, float]:
    """Posture overrides that widen the stance: each hip rolls outwards by ``hip_roll`` rad
    and its ankle rolls back, so the soles stay flat (0.1 rad moves each foot out by
    ~2 cm). Nao's FSR polygon is only ~16 cm wide in the nominal stance: an 11 N sideways
    load near the CoM height moves the CoP ~7 cm (eq. 10), to its edge (the robot of
    ``apps.nao_force_observer``'s experiment 2 tips over in the nominal stance)."""
    return {"LHipRoll": hip_roll, "LAnkleRoll": -hip_roll, "RHipRoll": -hip_roll, "RAnkleRoll": hip_roll}


def full_posture(humanoid: HumanoidHandles, posture: dict[str, float] | None) -> dict[str, float]:
    """The humanoid's nominal posture with the ``posture`` overrides (unknown joint names
    raise ValueError)."""
    out = dict(humanoid.nominal_posture)
    for name, angle in (posture or {}).items():
        if name not in out:
            raise ValueError(f"unknown joint {name!r} in the posture")
        out[name] = float(angle)
    return out


__all__ = [
    "NaoForceObserverHandles",
    "build_nao_force_observer_diagram",
    "full_posture",
    "wide_stance",
]
