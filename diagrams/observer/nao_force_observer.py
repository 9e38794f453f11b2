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

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Rgba
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from models import HumanoidHandles, set_standing_state
from systems.simulation.disturbances import Push, PushSource
from systems.simulation.ground_truth import VirtualForceTruth
from systems.observer.force_observer import STANDING, LipForceObserverSystem, LipObserverParameters
from systems.observer.fsr_sensing import FSR_NOISE_STD, CenterOfPressure, FsrArray, ImuComAcceleration, SupportFootCom
from systems.simulation.pd_gravity import joint_vector_from_names
from systems.simulation.sensors import SEEDS_PER_CALL
from systems.simulation.visualization import ForceArrows

#: The observer's sampling period on the simulated robot, s (the paper's 16.7 ms, 60 Hz).
OBSERVER_PERIOD = 1.0 / 60.0
#: Seed offset of the FSR noise within ``systems.simulation.sensors``' per-seed block (0-4 are used).
FSR_SEED_OFFSET = 5


def nao_observer_parameters(plant: MultibodyPlant, instance=None, *, period: float = OBSERVER_PERIOD) -> LipObserverParameters:
    """The paper's standing parameters (eq. 21) with the robot's model mass and gravity and
    the period ``period``: the robot knows its own mass from its model (5.19 kg for
    ``nao_like``, the paper's M_c)."""
    context = plant.CreateDefaultContext()
    mass = plant.CalcTotalMass(context) if instance is None else plant.CalcTotalMass(context, [instance])
    gravity = float(-plant.gravity_field().gravity_vector()[2])
    return dataclasses.replace(STANDING, mass=float(mass), gravity=gravity, period=float(period))


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
        state in the nominal posture; better ``settled_standing_state(posture)``) in the
        diagram's root context."""
        self.station.set_initial_state(root_context, state)


@dataclass
class ObserverPipeline:
    """What ``add_observer_pipeline`` added (sensors to observer, paper Fig. 4)."""

    fsr_array: FsrArray
    center_of_pressure: CenterOfPressure
    support_foot_com: SupportFootCom
    imu_com_acceleration: ImuComAcceleration
    parameters: LipObserverParameters
    observer: LipForceObserverSystem


def add_observer_pipeline(
    builder: DiagramBuilder,
    station: HumanoidStation,
    *,
    support_foot: str = "right",
    origin_W: np.ndarray | None = None,
    noise: bool = True,
    seed: int = 0,
    fsr_noise_std: float | None = None,
    observer_period: float = OBSERVER_PERIOD,
    parameters: LipObserverParameters | None = None,
) -> ObserverPipeline:
    """Adds the Nao's measurement pipeline and the Kalman observer to ``builder``: FSR array
    (from the plant's contact results), CoP/ZMP and total normal force (eqs. 12-13), CoM by
    forward kinematics and CoM acceleration from the IMU (all from the sensed state, in one
    world-aligned frame F), and ``LipForceObserverSystem``.

    Args:
        station: a ``nao_like`` station (``add_humanoid_station``) with its sensors.
        support_foot: "left" or "right": origin of F (the support-foot frame, standing).
        origin_W: instead, a fixed world point as F's origin, m (walking; see
            ``systems.observer.fsr_sensing.CenterOfPressure``).
        noise, seed: FSR noise on, and the seed (the FSRs use 16 seed + 5).
        fsr_noise_std: N per FSR (default ``fsr_sensing.FSR_NOISE_STD``; ignored without noise).
        observer_period: T, s (with the default parameters).
        parameters: the observer's parameters; default eq. (21) with the model's mass at
            ``observer_period`` (``nao_observer_parameters``).
    """
    plant, humanoid = station.plant, station.humanoid
    std = (FSR_NOISE_STD if fsr_noise_std is None else fsr_noise_std) if noise else 0.0
    fsr = builder.AddSystem(FsrArray(plant, humanoid, noise_std=std, seed=SEEDS_PER_CALL * seed + FSR_SEED_OFFSET))
    fsr.set_name("fsr_array")
    builder.Connect(plant.get_contact_results_output_port(), fsr.GetInputPort("contact_results"))
    cop = builder.AddSystem(CenterOfPressure(plant, humanoid, support_foot=support_foot, origin_W=origin_W))
    cop.set_name("center_of_pressure")
    builder.Connect(fsr.GetOutputPort("fsr_forces"), cop.GetInputPort("fsr_forces"))
    builder.Connect(station.sensed_state, cop.GetInputPort("state"))
    com = builder.AddSystem(SupportFootCom(plant, humanoid, support_foot=support_foot, origin_W=origin_W))
    com.set_name("support_foot_com")
    builder.Connect(station.sensed_state, com.GetInputPort("state"))
    acc = builder.AddSystem(ImuComAcceleration(plant, humanoid.imu_frame))
    acc.set_name("imu_com_acceleration")
    builder.Connect(station.sensors.imu.linear_acceleration, acc.GetInputPort("linear_acceleration"))
    builder.Connect(station.sensed_state, acc.GetInputPort("state"))
    if parameters is None:
        parameters = nao_observer_parameters(plant, humanoid.model_instance, period=observer_period)
    observer = builder.AddSystem(LipForceObserverSystem(parameters))
    observer.set_name("lip_force_observer")
    builder.Connect(com.GetOutputPort("com_position"), observer.GetInputPort("com_position"))
    builder.Connect(acc.GetOutputPort("com_acceleration"), observer.GetInputPort("com_acceleration"))
    builder.Connect(cop.GetOutputPort("zmp"), observer.GetInputPort("zmp"))
    builder.Connect(cop.GetOutputPort("normal_force"), observer.GetInputPort("normal_force"))
    return ObserverPipeline(fsr, cop, com, acc, parameters, observer)


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

    # Measurement pipeline (sensors only) and the observer.
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


@functools.lru_cache(maxsize=8)
def _settled_state(duration: float, posture: tuple) -> tuple[float, ...]:
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, "nao_like", noise=False)
    plant, humanoid = station.plant, station.humanoid
    angles = full_posture(humanoid, dict(posture))
    hold = builder.AddSystem(ConstantVectorSource(joint_vector_from_names(plant, angles)))
    builder.Connect(hold.get_output_port(), station.desired_position)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    plant_context = plant.CreateDefaultContext()
    set_standing_state(plant, plant_context, dataclasses.replace(humanoid, nominal_posture=angles))
    station.set_initial_state(simulator.get_mutable_context(), plant.GetPositionsAndVelocities(plant_context))
    simulator.AdvanceTo(duration)
    plant_context = plant.GetMyContextFromRoot(simulator.get_context())
    return tuple(plant.GetPositionsAndVelocities(plant_context).tolist())


def settled_standing_state(posture: dict[str, float] | None = None, duration: float = 1.0) -> np.ndarray:
    """[q; v] of nao_like after standing still for ``duration`` s in ``posture`` (overrides
    of the nominal posture) under position control, without pushes or noise: a state at
    static equilibrium on the ground (contact forces balanced, velocities ~0), so that an
    experiment and its observer start without the touch-down transient. Cached."""
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be positive, got {duration}")
    return np.array(_settled_state(float(duration), tuple(sorted((posture or {}).items()))))


__all__ = [
    "ObserverPipeline",
    "add_observer_pipeline",
    "OBSERVER_PERIOD",
    "NaoForceObserverHandles",
    "build_nao_force_observer_diagram",
    "nao_observer_parameters",
    "full_posture",
    "settled_standing_state",
    "wide_stance",
]
