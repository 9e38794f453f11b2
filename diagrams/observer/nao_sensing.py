"""The Nao's measurement pipeline and Kalman force observer as builders of their own
(Hawley, Rahem and Suleiman 2019, Fig. 4), shared by every Nao observer diagram
(``nao_force_observer``, ``nao_walk_pulled``, ``nao_compliant_arms``, ``nao_force_guided_walk``).

    station: contact results ─► FsrArray ─► CenterOfPressure ─► normal_force f_n^o, zmp p (eqs. 12-13)
             sensed state ───────────────► SupportFootCom ───► com_position x_c
             IMU + sensed state ─────────► ImuComAcceleration ► com_acceleration
                                                               ▼
                                           LipForceObserverSystem (T = 1/60 s) ─► virtual_force

Everything here reads sensor outputs only (FSRs, IMU, encoders and the base estimate of
``systems.simulation.sensors``), in one world-aligned frame F: at the support sole
(standing) or at a fixed world point ``origin_W`` (walking; see
``systems.observer.fsr_sensing``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from diagrams.station.humanoid_station import HumanoidStation
from systems.observer.force_observer import STANDING, LipForceObserverSystem, LipObserverParameters
from systems.observer.fsr_sensing import FSR_NOISE_STD, CenterOfPressure, FsrArray, ImuComAcceleration, SupportFootCom
from systems.simulation.ground_truth import VirtualForceTruth
from systems.simulation.sensors import SEEDS_PER_CALL
from systems.simulation.visualization import ESTIMATE_RGBA, add_force_arrows

#: The observer's sampling period on the simulated robot, s (the paper's 16.7 ms, 60 Hz).
OBSERVER_PERIOD = 1.0 / 60.0
#: Seed offset of the FSR noise within ``systems.simulation.sensors``' per-seed block (0-4 are used).
FSR_SEED_OFFSET = 5


def nao_observer_parameters(
    plant: MultibodyPlant, instance=None, *, period: float = OBSERVER_PERIOD
) -> LipObserverParameters:
    """The paper's standing parameters (eq. 21) with the robot's model mass and gravity and
    the period ``period``: the robot knows its own mass from its model (5.19 kg for
    ``nao_like``, the paper's M_c)."""
    context = plant.CreateDefaultContext()
    mass = plant.CalcTotalMass(context) if instance is None else plant.CalcTotalMass(context, [instance])
    gravity = float(-plant.gravity_field().gravity_vector()[2])
    return dataclasses.replace(STANDING, mass=float(mass), gravity=gravity, period=float(period))


@dataclass
class NaoMeasurementPipeline:
    """What ``add_nao_measurement_pipeline`` added: the observer's four measurements
    (``com_position``, ``com_acceleration``, ``zmp``, ``normal_force``) and the raw FSRs."""

    fsr_array: FsrArray
    center_of_pressure: CenterOfPressure
    support_foot_com: SupportFootCom
    imu_com_acceleration: ImuComAcceleration


def add_nao_measurement_pipeline(
    builder: DiagramBuilder,
    station: HumanoidStation,
    *,
    support_foot: str = "right",
    origin_W: np.ndarray | None = None,
    noise: bool = True,
    seed: int = 0,
    fsr_noise_std: float | None = None,
) -> NaoMeasurementPipeline:
    """Adds the Nao's measurement pipeline to ``builder``: FSR array (from the plant's
    contact results), CoP/ZMP and total normal force (eqs. 12-13), CoM by forward
    kinematics and CoM acceleration from the IMU (all from the sensed state, in one
    world-aligned frame F).

    Args:
        station: a ``nao_like`` station (``add_humanoid_station``) with its sensors.
        support_foot: "left" or "right": origin of F (the support-foot frame, standing).
        origin_W: instead, a fixed world point as F's origin, m (walking; see
            ``systems.observer.fsr_sensing.CenterOfPressure``).
        noise, seed: FSR noise on, and the seed (the FSRs use 16 seed + 5).
        fsr_noise_std: N per FSR (default ``fsr_sensing.FSR_NOISE_STD``; ignored without noise).

    Raises:
        ValueError: the station has no IMU (not a sensed ``nao_like`` station), or the
            systems' own checks (unknown support foot, bad noise settings).
    """
    plant, humanoid = station.plant, station.humanoid
    if station.sensors is None or humanoid is None or humanoid.imu_frame is None:
        raise ValueError(
            "add_nao_measurement_pipeline: the station needs a humanoid with its sensors and IMU (e.g. nao_like)"
        )
    std = (FSR_NOISE_STD if fsr_noise_std is None else fsr_noise_std) if noise else 0.0
    fsr = builder.AddSystem(FsrArray(plant, humanoid, noise_std=std, seed=SEEDS_PER_CALL * seed + FSR_SEED_OFFSET))
    fsr.set_name("fsr_array")
    builder.Connect(plant.get_contact_results_output_port(), fsr.GetInputPort("contact_results"))
    # The FSRs are sensors of the simulated robot; what the observer computes from them and
    # from the sensed state uses the estimators' plant (the robot's model) only.
    model, model_humanoid = station.estimator.plant, station.estimator.humanoid
    cop = builder.AddSystem(CenterOfPressure(model, model_humanoid, support_foot=support_foot, origin_W=origin_W))
    cop.set_name("center_of_pressure")
    builder.Connect(fsr.GetOutputPort("fsr_forces"), cop.GetInputPort("fsr_forces"))
    builder.Connect(station.sensed_state, cop.GetInputPort("state"))
    com = builder.AddSystem(SupportFootCom(model, model_humanoid, support_foot=support_foot, origin_W=origin_W))
    com.set_name("support_foot_com")
    builder.Connect(station.sensed_state, com.GetInputPort("state"))
    acc = builder.AddSystem(ImuComAcceleration(model, model_humanoid.imu_frame))
    acc.set_name("imu_com_acceleration")
    builder.Connect(station.sensors.imu.linear_acceleration, acc.GetInputPort("linear_acceleration"))
    builder.Connect(station.sensed_state, acc.GetInputPort("state"))
    return NaoMeasurementPipeline(fsr, cop, com, acc)


def add_lip_force_observer(
    builder: DiagramBuilder, measurements: NaoMeasurementPipeline, parameters: LipObserverParameters
) -> LipForceObserverSystem:
    """Adds ``LipForceObserverSystem(parameters)`` fed by ``measurements``."""
    observer = builder.AddSystem(LipForceObserverSystem(parameters))
    observer.set_name("lip_force_observer")
    builder.Connect(measurements.support_foot_com.GetOutputPort("com_position"), observer.GetInputPort("com_position"))
    builder.Connect(
        measurements.imu_com_acceleration.GetOutputPort("com_acceleration"), observer.GetInputPort("com_acceleration")
    )
    builder.Connect(measurements.center_of_pressure.GetOutputPort("zmp"), observer.GetInputPort("zmp"))
    builder.Connect(
        measurements.center_of_pressure.GetOutputPort("normal_force"), observer.GetInputPort("normal_force")
    )
    return observer


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
    """``add_nao_measurement_pipeline`` followed by the Kalman observer
    (``add_lip_force_observer``).

    Args:
        station, support_foot, origin_W, noise, seed, fsr_noise_std: as
            ``add_nao_measurement_pipeline``.
        observer_period: T, s (with the default parameters).
        parameters: the observer's parameters; default eq. (21) with the model's mass (the
            station's estimators' plant) at ``observer_period`` (``nao_observer_parameters``).
    """
    measurements = add_nao_measurement_pipeline(
        builder,
        station,
        support_foot=support_foot,
        origin_W=origin_W,
        noise=noise,
        seed=seed,
        fsr_noise_std=fsr_noise_std,
    )
    if parameters is None:  # the robot's mass from its model: the estimators' plant
        estimator = station.estimator
        parameters = nao_observer_parameters(estimator.plant, estimator.humanoid.model_instance, period=observer_period)
    observer = add_lip_force_observer(builder, measurements, parameters)
    return ObserverPipeline(
        measurements.fsr_array,
        measurements.center_of_pressure,
        measurements.support_foot_com,
        measurements.imu_com_acceleration,
        parameters,
        observer,
    )


def add_virtual_force_arrows(
    builder: DiagramBuilder,
    meshcat: Meshcat,
    observer: LipForceObserverSystem,
    truth: VirtualForceTruth,
    *,
    newtons_per_meter: float,
) -> None:
    """Draws the observer's virtual force estimate (eq. 11, blue) at the true CoM (``truth``'s
    ``com_world``), where the LIP applies it, ``newtons_per_meter`` N per metre of arrow."""
    add_force_arrows(
        builder,
        meshcat,
        observer.GetOutputPort("virtual_force"),
        truth.GetOutputPort("com_world"),
        name="estimated_force_arrow",
        path="estimated_virtual_force",
        newtons_per_meter=newtons_per_meter,
        rgba=ESTIMATE_RGBA,
        min_force=0.3,
    )


__all__ = [
    "add_virtual_force_arrows",
    "FSR_SEED_OFFSET",
    "NaoMeasurementPipeline",
    "OBSERVER_PERIOD",
    "ObserverPipeline",
    "add_lip_force_observer",
    "add_nao_measurement_pipeline",
    "add_observer_pipeline",
    "nao_observer_parameters",
]
