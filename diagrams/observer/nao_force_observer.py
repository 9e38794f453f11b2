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
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, Context, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.observer.nao_sensing import OBSERVER_PERIOD, add_observer_pipeline
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from models import HumanoidHandles
from systems.simulation.disturbances import Push, PushSource
from systems.observer.force_observer import LipForceObserverSystem, LipObserverParameters
from systems.observer.fsr_sensing import CenterOfPressure, FsrArray, ImuComAcceleration, SupportFootCom
from systems.common.checks import eval_finite_input
from systems.simulation.pd_gravity import joint_vector_from_names
from systems.simulation.visualization import ForceArrows

class VirtualForceTruth(LeafSystem):
    """Ground-truth virtual force (paper eq. 11) of the applied external wrench.

    An external force F applied at a point P of the robot moves the ZMP as the same force
    plus the moment tau = (p_P - p_Cm) x F about the CoM would (eqs. 8-10). Seen from the
    ZMP, that is the virtual force F^ = [F_x + tau_y / z_c, F_y - tau_x / z_c, F_z] applied
    at the CoM of the LIP (eq. 11), z_c being the CoM height above the ground plane in
    which the ZMP lies (the support-foot frame's z). A horizontal force at height h thus
    counts as F_x h / z_c: above the CoM it moves the ZMP more than at the CoM; a vertical
    load at a horizontal offset d from the CoM adds a horizontal virtual force -d F_z / z_c.
    At static equilibrium this is exact for the multibody robot (moments about the CoP);
    during motion the LIP neglects the rate of angular momentum.

    Inputs:
        state: the TRUE plant state [q; v].
        total_wrench_world: (6) [moment about the world origin, N m; force, N], world
            (``PushSource.total_wrench_world``).

    Outputs:
        virtual_force: (3) F^ in the world-aligned support-foot frame, N.
        com_position: (3) the true CoM in the support-foot frame F, m (for checks).
        com_world: (3) the true CoM in world, m (to draw the virtual force).
    """

    def __init__(self, plant: MultibodyPlant, handles: HumanoidHandles, *, support_foot: str = "right"):
        super().__init__()
        if support_foot not in handles.sole_frames:
            raise ValueError(f"VirtualForceTruth: unknown support foot {support_foot!r}")
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._support = handles.sole_frames[support_foot]
        self._instances = [handles.model_instance]
        self._nq = plant.num_positions()
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self._wrench = self.DeclareVectorInputPort("total_wrench_world", 6)
        self.DeclareVectorOutputPort("virtual_force", 3, self._CalcVirtualForce)
        self.DeclareVectorOutputPort("com_position", 3, self._CalcComPosition)
        self.DeclareVectorOutputPort("com_world", 3, self._CalcComWorld)

    def _com(self, context: Context) -> tuple[np.ndarray, np.ndarray]:
        x = eval_finite_input("VirtualForceTruth", self._state, context)
        self._plant.SetPositions(self._plant_context, x[: self._nq])
        p_WCm = self._plant.CalcCenterOfMassPositionInWorld(self._plant_context, self._instances)
        return p_WCm, self._support.CalcPoseInWorld(self._plant_context).translation()

    @staticmethod
    def virtual_force(wrench_world: np.ndarray, p_WCm: np.ndarray, ground_height: float) -> np.ndarray:
        """Eq. (11) from [moment about the world origin; force] and the CoM position in
        world; ``ground_height`` is the z of the plane of the ZMP (the support frame's)."""
        tau_O, force = np.asarray(wrench_world[:3], float), np.asarray(wrench_world[3:], float)
        tau = tau_O - np.cross(p_WCm, force)  # moment about the CoM
        z_c = float(p_WCm[2] - ground_height)
        return np.array([force[0] + tau[1] / z_c, force[1] - tau[0] / z_c, force[2]])

    def _CalcVirtualForce(self, context: Context, output: BasicVector) -> None:
        wrench = eval_finite_input("VirtualForceTruth", self._wrench, context)
        if not np.any(wrench):
            output.SetFromVector(np.zeros(3))
            return
        p_WCm, p_WF = self._com(context)
        output.SetFromVector(self.virtual_force(wrench, p_WCm, p_WF[2]))

    def _CalcComPosition(self, context: Context, output: BasicVector) -> None:
        p_WCm, p_WF = self._com(context)
        output.SetFromVector(p_WCm - p_WF)

    def _CalcComWorld(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._com(context)[0])


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
    "VirtualForceTruth",
    "build_nao_force_observer_diagram",
    "full_posture",
    "wide_stance",
]
