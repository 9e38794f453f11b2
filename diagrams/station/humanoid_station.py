"""The humanoid station shared by the experiment diagrams: a discrete MultibodyPlant (1 ms,
SAP, point contact) with the robot (and flat ground for the humanoids), the robot's sensors
and its PD + gravity-compensation joint controller, whose ``desired_position`` input the
caller connects (a constant posture, or an admittance controller).

For ``hrp4_like`` and ``nao_like`` the robot stands on flat ground with its simulated sensors
(``systems.simulation.sensors``); any other floating-base model (an SDFormat or URDF path) floats in zero
gravity with no ground, and its "sensed" state is the true state (no sensor suite).

The base part of the sensed state (``base_state``, one of ``BASE_STATE_SOURCES``) comes by
default ("truth_plus_noise") from the stand-in ``systems.simulation.sensors.BaseStateEstimator``
(the true base state plus white noise); "invariant_ekf" replaces it with the contact-aided
invariant EKF ``systems.estimation.base_state_estimator.InvariantEkfBaseStateEstimator`` fed by
the station's IMU, encoders and foot contact from the ankle F/T sensors (hrp4_like) or, on a
robot without them, from its four foot FSRs per foot (nao_like: the sensors' ``FsrArray``),
with IMU bias states when the simulated IMU has a bias random walk.

``model_corrections`` (a model refined from a calibration log, ``systems.estimation.
model_identification``) replace the estimators' link inertias and correct the motor torques
they read (``HumanoidStation.measured_torque``; the sensor's own output stays available as
``raw_measured_torque``).

The estimators never see the simulated plant: the station parses the robot's description a
second time into the estimators' own plant (``HumanoidStation.estimator``, carrying the
mismatched or refined inertias as its defaults), and builds the PD's gravity compensation,
the base-state EKF and the torque correction from it; the experiment diagrams build their
residuals, detectors, localizers and admittance from it too. The simulated ``plant`` serves
the simulator, the sensors and the ground-truth systems.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import SceneGraph
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.systems.framework import Context, DiagramBuilder, InputPort, OutputPort
from pydrake.systems.primitives import MatrixGain, Multiplexer, ZeroOrderHold

from diagrams.station.config import StationConfig
from diagrams.station.estimator_plant import (
    EstimatorPlant,
    add_model_file,
    build_estimator_plant,
    set_posture_inside_limits,
)
from diagrams.station.standing import default_gains
from models import (
    HumanoidHandles,
    add_ground,
    add_humanoid,
    is_humanoid,
    point_contact_scene_graph_config,
    set_standing_state,
)
from systems.common.topology import FloatingBaseTopology, floating_base_topology
from systems.estimation.base_state_estimator import (
    CONTACT_OFF_WEIGHT_FRACTION,
    CONTACT_ON_WEIGHT_FRACTION,
    LEVEL_GROUND_TILT_STD,
    STANDING_START_ORIENTATION_STD,
    STANDING_START_VELOCITY_STD,
    FootContactFromForceTorque,
    FootContactFromFsr,
    InvariantEkfBaseStateEstimator,
)
from systems.estimation.model_identification import CorrectedJointTorque, ModelCorrections
from systems.residuals.momentum_residuals import ResidualModel
from systems.simulation.imperfections import (
    Imperfections,
    JointFriction,
    perturbed_spatial_inertias,
    rated_joint_torques,
)
from systems.simulation.pd_gravity import PdGravityController
from systems.simulation.sensors import SensorHandles, add_sensors

#: The implementation of the estimators' dynamics on a humanoid (``HumanoidStation.dynamics_model``
#: and the estimated contact flags' residuals; ``FloatingBaseDynamics``): Pinocchio's C++ kernels
#: on a model built from the estimators' plant, M-dot exact from one Coriolis pass, equal to
#: Drake's "fast" to ~1e-10 (tests/test_pinocchio_dynamics.py) and cheaper per step: one
#: Coriolis pass instead of two more mass matrices (BENCHMARKS.md).
ONLINE_DYNAMICS = "pinocchio"


@dataclass
class HumanoidStation:
    """What ``add_humanoid_station`` added.

    Attributes:
        plant, scene_graph: the finalized simulated plant and its SceneGraph: for the
            simulator, the sensors, disturbances and ground truth only.
        humanoid: the simulated robot's handles, or None for a model loaded from a file.
        estimator: the estimators' own plant (``diagrams.station.estimator_plant``), parsed
            from the same description with the estimators' inertias: build every estimator,
            controller and localizer from it (its ``humanoid`` has the frames they need).
        topology: the simulated plant's floating-base topology (joints in v[6:] order; the
            estimators' plant has the same indices: ``estimator.topology``).
        controller: the PdGravityController (built on ``estimator.plant``); its
            ``desired_position`` input is NOT connected.
        desired_position: that input port.
        sensors: the sensor suite, or None (model from a file).
        sensed_state: output port of the sensed [q; v] (the true state without sensors).
        measured_torque: output port of the motor torques, v[6:] order.
        known_wrench_frames: the F/T sensor frames of ``estimator.plant`` (empty without F/T
            sensors), in the order of ``known_wrenches``.
        known_wrenches: output port of their wrenches, or None.
        initial_state: the plant's initial [q; v] (standing, or the posture held in space).
        q_hold: the initial joint positions, v[6:] order, rad.
        sensed_state_hold: the ZeroOrderHold between the sensors and the PD (humanoids), or
            None. Its held sample is set by ``set_initial_state``: call it before
            ``Simulator.Initialize``.
        dynamics_model: the ``ResidualModel`` of ``estimator.plant`` (``ONLINE_DYNAMICS``)
            whose gravity the PD uses (humanoids), or None. Give it to the diagram's residuals (``model=``): the
            PD reads the sample they evaluated one step earlier, so the dynamics at each
            sensed state are computed once for the PD and all residuals.
        imperfections: the Imperfections the station was built with (ideal by default).
        friction: the JointFriction system feeding the plant's applied generalized force,
            or None.
        base_state: the source of the sensed base state, one of ``BASE_STATE_SOURCES``.
        base_state_estimator: the InvariantEkfBaseStateEstimator (``base_state`` =
            "invariant_ekf"), or None. ``set_initial_state`` starts it at the initial state.
        foot_contact: the FootContactFromForceTorque (or, without F/T sensors,
            FootContactFromFsr) feeding it its contact flags, or None.
        model_corrections: the ``ModelCorrections`` whose inertias ``estimator`` carries and
            which correct ``measured_torque`` (see ``add_humanoid_station``), or None.
        raw_measured_torque: the torque sensor's own output (before the corrections; the
            same port as ``measured_torque`` without them): what a calibration log records.
        estimator_inertias: {body index: SpatialInertia} of the estimators' model before any
            refinement: the model mismatch's perturbed links, or None (the description's).
    """

    plant: MultibodyPlant
    scene_graph: SceneGraph
    humanoid: HumanoidHandles | None
    topology: FloatingBaseTopology
    controller: PdGravityController
    desired_position: InputPort
    sensors: SensorHandles | None
    sensed_state: OutputPort
    measured_torque: OutputPort
    known_wrench_frames: tuple
    known_wrenches: OutputPort | None
    initial_state: np.ndarray
    q_hold: np.ndarray
    sensed_state_hold: ZeroOrderHold | None = None
    dynamics_model: ResidualModel | None = None
    imperfections: Imperfections = field(default_factory=Imperfections)
    friction: JointFriction | None = None
    base_state: str = "truth_plus_noise"
    base_state_estimator: InvariantEkfBaseStateEstimator | None = None
    foot_contact: FootContactFromForceTorque | None = None
    model_corrections: ModelCorrections | None = None
    raw_measured_torque: OutputPort | None = None
    estimator_inertias: dict | None = None
    estimator: EstimatorPlant | None = None

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name() for j in self.topology.joints)

    def set_initial_state(self, root_context: Context, state: np.ndarray | None = None) -> None:
        """Puts the robot in ``state`` ([q; v], default ``initial_state``) in the diagram's
        ``root_context``, the PD's held sensor sample at that state (noise-free: the
        first reading) and, with ``base_state`` = "invariant_ekf", the base estimator at
        that state's base pose and velocity. Use this rather than setting the plant's state alone: a hold left
        at zero makes the PD raise a ValueError at the first step.

        Raises:
            ValueError: ``state`` of the wrong size or not finite.
        """
        x = self.initial_state if state is None else np.asarray(state, dtype=float).reshape(-1)
        if x.shape != self.initial_state.shape or not np.isfinite(x).all():
            raise ValueError(f"set_initial_state: state must be {self.initial_state.size} finite numbers [q; v]")
        self.plant.SetPositionsAndVelocities(self.plant.GetMyMutableContextFromRoot(root_context), x)
        if self.sensed_state_hold is not None:
            self.sensed_state_hold.GetMyMutableContextFromRoot(root_context).SetDiscreteState(x)
        if self.base_state_estimator is not None:
            q0 = self.topology.free_joint.position_start()
            v0 = self.plant.num_positions() + self.topology.free_joint.velocity_start()
            self.base_state_estimator.SetInitialBaseState(
                self.base_state_estimator.GetMyMutableContextFromRoot(root_context),
                x[q0 : q0 + 7],
                x[v0 : v0 + 6],
            )


def add_humanoid_station(
    builder: DiagramBuilder,
    config: StationConfig | None = None,
    *,
    model_corrections: ModelCorrections | None = None,
) -> HumanoidStation:
    """Adds the station of the module docstring, as ``config`` says (default
    ``StationConfig()``: hrp4_like, noisy sensors, the ideal world), to ``builder``.

    Args:
        config: the robot, plant, sensors, imperfections, base-state source
            (``diagrams.station.config.StationConfig``). Its ``model_refinement`` is the
            caller's to act on: the station takes the result as ``model_corrections``.
        model_corrections: a refined model (``systems.estimation.model_identification``,
            identified from a calibration log of this robot, e.g. by
            ``diagrams.residuals.model_refinement.calibrate_model``), or None. Its link
            inertias replace the ``dynamics_model``'s (after any model mismatch: they are the
            estimators' refined model), and ``measured_torque`` becomes its
            ``CorrectedJointTorque``: the motor torque with the identified offset and scale
            removed and the identified joint friction added. Needs a humanoid.

    Raises:
        ValueError: a bad ``config`` field (named: an unknown or unreadable model, a model
            without a floating base, an unknown contact approximation, bad imperfections, an
            unknown ``base_state``), or "invariant_ekf" on a model with neither foot F/T
            sensors nor FSRs.
    """
    config = StationConfig() if config is None else config
    if not isinstance(config, StationConfig):
        raise ValueError(f"add_humanoid_station takes a StationConfig, got {type(config).__name__}")
    config.check()
    model, plant_config, noise, seed = config.model, config.plant_config, config.noise, config.seed
    imperfections, base_state, noise_scale = config.imperfections, config.base_state, config.noise_scale
    at_rest_duration = config.at_rest_duration
    time_step = plant_config.time_step
    plant, scene_graph = AddMultibodyPlant(
        plant_config,
        point_contact_scene_graph_config(),
        builder,
    )
    humanoid = _load(plant, scene_graph, model)
    plant.Finalize()
    topology = floating_base_topology(plant)  # clear ValueError for a model without a floating base

    context = plant.CreateDefaultContext()
    if humanoid is not None:
        set_standing_state(plant, context, humanoid)
    else:
        set_posture_inside_limits(plant, context, topology)
    initial_state = plant.GetPositionsAndVelocities(context)
    q_hold = np.array([initial_state[j.position_start()] for j in topology.joints])

    # The estimators' own plant (diagrams.station.estimator_plant), parsed from the same
    # description with the estimators' inertias as its defaults: the controller, the
    # base-state EKF and every estimator a diagram adds are built from it, never from `plant`.
    estimator = build_estimator_plant(model, time_step)
    mismatch = imperfections.model_mismatch
    estimator_inertias = None
    link_inertias = {}
    if mismatch.mass_percent or mismatch.com_percent or mismatch.inertia_percent:
        if humanoid is None:
            raise ValueError(
                "imperfections.model_mismatch needs a humanoid station (hrp4_like, nao_like): run with --ideal"
            )
        estimator_inertias = perturbed_spatial_inertias(estimator.plant, mismatch, imperfections.seed)
        link_inertias.update(estimator.link_inertias_by_name(estimator_inertias))
    if model_corrections is not None:
        if humanoid is None:
            raise ValueError("model_corrections need a humanoid station (hrp4_like, nao_like)")
        if not isinstance(model_corrections, ModelCorrections):
            raise ValueError(f"model_corrections must be ModelCorrections, got {type(model_corrections).__name__}")
        link_inertias.update(estimator.link_inertias_by_name(model_corrections.spatial_inertias))
    if link_inertias:
        estimator = build_estimator_plant(model, time_step, link_inertias=link_inertias)
    if humanoid is not None:
        kp, kd = default_gains(estimator.plant, estimator.humanoid)
    else:
        kp, kd = _generic_gains(estimator.plant, estimator.standing_state, time_step)
    # Humanoids: gravity from the dynamics model the estimators share (see HumanoidStation).
    dynamics_model = ResidualModel(estimator.plant, ONLINE_DYNAMICS) if humanoid is not None else None
    friction = None
    if imperfections.friction.coulomb_percent or imperfections.friction.viscous_percent:
        rated = rated_joint_torques(plant)
        friction = builder.AddSystem(
            JointFriction(
                plant,
                coulomb=0.01 * imperfections.friction.coulomb_percent * rated,
                viscous=0.01 * imperfections.friction.viscous_percent * rated,
                smoothing_velocity=imperfections.friction.smoothing_velocity,
            )
        )
        friction.set_name("joint_friction")
        builder.Connect(plant.get_state_output_port(), friction.get_input_port())
        builder.Connect(friction.get_output_port(), plant.get_applied_generalized_force_input_port())
    controller = builder.AddSystem(PdGravityController(estimator.plant, kp, kd, gravity_model=dynamics_model))
    controller.set_name("pd_gravity_controller")
    base_state_estimator = foot_contact = None
    builder.Connect(controller.GetOutputPort("actuation"), plant.get_actuation_input_port())
    if humanoid is not None:
        fsr_feet = all(
            humanoid.foot_sensing.get(side) == "fsr" and len(humanoid.fsr_geometries.get(side, ())) == 4
            for side in ("left", "right")
        )
        measured_feet = bool(humanoid.ft_sensor_joints) or fsr_feet
        sensors = add_sensors(
            builder,
            plant,
            humanoid,
            noise=noise,
            noise_scale=noise_scale,
            seed=seed,
            imperfections=imperfections,
            base_estimator=(base_state == "truth_plus_noise"),
        )
        if base_state == "invariant_ekf" and measured_feet:
            base_state_estimator, foot_contact = _add_invariant_ekf(
                builder, plant, humanoid, estimator, sensors, at_rest_duration
            )
        sensed_state, measured_torque = sensors.state, sensors.measured_torque
        if model_corrections is not None:
            corrected = builder.AddSystem(CorrectedJointTorque(estimator.plant, model_corrections))
            corrected.set_name("corrected_joint_torque")
            builder.Connect(sensors.measured_torque, corrected.GetInputPort("measured_torque"))
            builder.Connect(sensors.state, corrected.GetInputPort("state"))
            measured_torque = corrected.GetOutputPort("joint_torque")
        if base_state == "invariant_ekf" and not measured_feet:
            # No foot force sensing: the contact flags from the soles' wrenches estimated
            # from residuals of the estimators' own (SoleWrenchCompensation).
            contact = _add_estimated_foot_contact(builder, estimator, sensors.state, measured_torque, time_step)
            base_state_estimator, foot_contact = _add_invariant_ekf(
                builder, plant, humanoid, estimator, sensors, at_rest_duration, contact=contact
            )
        if len(estimator.ft_frames) != len(sensors.ft_frames):
            raise ValueError("the estimators' plant and the simulated robot have different F/T sensors")
        known_frames, known_wrenches = estimator.ft_frames, sensors.ft_wrenches
        if estimator.fsr_sides:
            known_frames, known_wrenches = _add_fsr_sole_wrenches(builder, estimator, sensors)
    else:
        sensors = None
        sensed_state = plant.get_state_output_port()
        # The torque the motors applied over the last step, in joint order (v[6:]).
        to_joint_torque = builder.AddSystem(MatrixGain(plant.MakeActuationMatrix()[6:, :]))
        builder.Connect(plant.get_net_actuation_output_port(), to_joint_torque.get_input_port())
        measured_torque = to_joint_torque.get_output_port()
        known_frames, known_wrenches = (), None
        sensor_groups = (imperfections.imu, imperfections.encoders, imperfections.torque_sensor)
        if any(group != type(group)() for group in sensor_groups):
            raise ValueError(
                "imperfections.imu/encoders/torque_sensor need a humanoid station (a model from a file has no "
                "sensors): run with --ideal"
            )
        if base_state != "truth_plus_noise":
            raise ValueError(
                f"base_state {base_state!r} needs a humanoid station (a model from a file has no sensors): "
                "run with --ideal"
            )
    sensed_state_hold = None
    if sensors is not None:
        # One sensor reading per step, shared by the PD and the estimators. In a discrete
        # MultibodyPlant diagram Drake evaluates the plant's actuation input (the PD and,
        # through it, the whole Python sensor chain) before the plant's step, and the other
        # periodic updates (residuals, admittance) after it, at the same time stamp, on the
        # new state. Without a hold the sensor chain would run twice per step on two states;
        # with it the chain runs once, in the update pass, and the PD reads at t_k + T the
        # sample the estimators saw at t_k: the same plant state x(t_k + T), so the closed
        # loop is unchanged (bit for bit without noise; measured), at ~9 % less time per step.
        sensed_state_hold = builder.AddSystem(ZeroOrderHold(time_step, len(initial_state)))
        sensed_state_hold.set_name("sensed_state_hold")
        builder.Connect(sensed_state, sensed_state_hold.get_input_port())
        builder.Connect(sensed_state_hold.get_output_port(), controller.GetInputPort("state"))
    else:
        builder.Connect(sensed_state, controller.GetInputPort("state"))
    return HumanoidStation(
        plant=plant,
        scene_graph=scene_graph,
        humanoid=humanoid,
        topology=topology,
        controller=controller,
        desired_position=controller.GetInputPort("desired_position"),
        sensors=sensors,
        sensed_state=sensed_state,
        measured_torque=measured_torque,
        known_wrench_frames=known_frames,
        known_wrenches=known_wrenches,
        initial_state=initial_state,
        q_hold=q_hold,
        sensed_state_hold=sensed_state_hold,
        dynamics_model=dynamics_model,
        imperfections=imperfections,
        friction=friction,
        base_state=base_state,
        base_state_estimator=base_state_estimator,
        foot_contact=foot_contact,
        model_corrections=model_corrections,
        estimator_inertias=estimator_inertias,
        estimator=estimator,
        raw_measured_torque=sensors.measured_torque if sensors is not None else measured_torque,
    )


def _add_invariant_ekf(
    builder: DiagramBuilder,
    plant: MultibodyPlant,
    humanoid: HumanoidHandles,
    estimator: EstimatorPlant,
    sensors: SensorHandles,
    at_rest_duration: float | None,
    contact: FootContactFromForceTorque | None = None,
) -> tuple[InvariantEkfBaseStateEstimator, FootContactFromForceTorque | FootContactFromFsr]:
    """The contact-aided invariant EKF as the source of the assembler's base pose and velocity:
    gyro and accelerometer from the IMU, joint positions from the encoders, one contact flag
    per foot (its sole frame is the foot point) from its normal force, with the logs'
    hysteresis (on above ``CONTACT_ON_WEIGHT_FRACTION``, 10 %, of the estimators' model's
    weight, off below ``CONTACT_OFF_WEIGHT_FRACTION``, 5 %; ``ContactHysteresis``): from the
    F/T sensors when the robot has them (hrp4_like, ``FootContactFromForceTorque``), else
    from the sum of each foot's four FSRs (nao_like, ``FootContactFromFsr``). The FSRs are
    the sensors' ``FsrArray`` (``add_sensors``), with the noise and seed (16 seed + 5) that
    ``diagrams.observer.nao_sensing`` gives its own, so both read the same sensors. The
    filter estimates the IMU biases (its default random walks, ``Imperfections.realistic()``'s)
    when the simulated IMU has a bias random walk, and is the bias-free filter otherwise (the
    ideal default IMU). With the bias states it
    also takes the soles in contact as flat on level ground (E12, ``LEVEL_GROUND_TILT_STD``):
    without that the horizontal accelerometer bias reads as a base tilt, which the refined
    model absorbs during the calibration and the internal residual then shows as gravity
    torque on every pitch joint. The station's robot starts standing still on level ground,
    so the filter starts with that prior (``STANDING_START_ORIENTATION_STD``,
    ``STANDING_START_VELOCITY_STD``) rather than the generic one. The FSRs are sensors of
    the simulated ``plant`` (``humanoid``: its handles); the filter, the contact flags' weight
    threshold and the filter's start are the estimators' (``estimator``). ``contact``: flags
    of the caller's instead (a robot without foot force sensing: ``_add_estimated_foot_contact``,
    one per sole, sides sorted)."""
    from systems.observer.fsr_sensing import FSR_SIDES

    weight = _model_weight(estimator)
    period = plant.time_step()
    if contact is not None:
        sides = tuple(sorted(estimator.humanoid.sole_frames))
    elif sensors.ft_sides:
        sides = sensors.ft_sides
        contact = builder.AddSystem(
            FootContactFromForceTorque(
                len(sides),
                CONTACT_ON_WEIGHT_FRACTION * weight,
                off_threshold=CONTACT_OFF_WEIGHT_FRACTION * weight,
                period=period,
            )
        )
        contact.set_name("foot_contact_from_force_torque")
        builder.Connect(sensors.ft_wrenches, contact.GetInputPort("wrenches"))
    else:
        sides = FSR_SIDES
        fsr = sensors.fsr_array  # the feet's FSRs (sensing: fsr; the station refuses the EKF without them)
        contact = builder.AddSystem(
            FootContactFromFsr(
                weight,
                weight_fraction=CONTACT_ON_WEIGHT_FRACTION,
                off_weight_fraction=CONTACT_OFF_WEIGHT_FRACTION,
                num_feet=len(sides),
                period=period,
            )
        )
        contact.set_name("foot_contact_from_fsr")
        builder.Connect(fsr.GetOutputPort("fsr_forces"), contact.GetInputPort("fsr_forces"))
    topology, initial_state = estimator.topology, estimator.standing_state
    q0 = topology.free_joint.position_start()
    v0 = estimator.plant.num_positions() + topology.free_joint.velocity_start()
    estimate_bias = sensors.imu.gyro_bias is not None or sensors.imu.accel_bias is not None
    estimator = builder.AddSystem(
        InvariantEkfBaseStateEstimator(
            estimator.plant,
            estimator.humanoid.imu_frame,
            [estimator.humanoid.sole_frames[side] for side in sides],
            initial_base_pose=initial_state[q0 : q0 + 7],
            initial_base_velocity=initial_state[v0 : v0 + 6],
            initial_orientation_std=STANDING_START_ORIENTATION_STD,
            initial_velocity_std=STANDING_START_VELOCITY_STD,
            estimate_imu_bias=estimate_bias,
            level_ground_tilt_std=LEVEL_GROUND_TILT_STD if estimate_bias else None,
            at_rest_duration=at_rest_duration if estimate_bias else None,
        )
    )
    estimator.set_name("invariant_ekf_base_state_estimator")
    builder.Connect(sensors.imu.angular_velocity, estimator.GetInputPort("angular_velocity"))
    builder.Connect(sensors.imu.linear_acceleration, estimator.GetInputPort("linear_acceleration"))
    builder.Connect(sensors.encoders.GetOutputPort("position"), estimator.GetInputPort("joint_positions"))
    builder.Connect(contact.GetOutputPort("foot_contact"), estimator.GetInputPort("foot_contact"))
    builder.Connect(estimator.GetOutputPort("base_pose"), sensors.assembler.GetInputPort("base_pose"))
    builder.Connect(estimator.GetOutputPort("base_velocity"), sensors.assembler.GetInputPort("base_velocity"))
    return estimator, contact


def _add_fsr_sole_wrenches(
    builder: DiagramBuilder, estimator: EstimatorPlant, sensors: SensorHandles
) -> tuple[tuple, OutputPort]:
    """The known wrenches of a robot with FSR feet: the F/T sensors' (if any), then each FSR
    sole's normal force and centre of pressure (``FsrSoleWrenches``, from the estimators'
    model and the sensed state); returns (their frames, one port of all of them)."""
    from systems.observer.fsr_sensing import FsrSoleWrenches

    if sensors.fsr_forces is None:
        raise ValueError("the estimators' plant has FSR feet but the simulated robot has no FSRs")
    soles = builder.AddSystem(FsrSoleWrenches(estimator.plant, estimator.humanoid, estimator.fsr_sides))
    soles.set_name("fsr_sole_wrenches")
    builder.Connect(sensors.fsr_forces, soles.GetInputPort("fsr_forces"))
    builder.Connect(sensors.state, soles.GetInputPort("state"))
    if sensors.ft_wrenches is None:
        return estimator.fsr_frames, soles.GetOutputPort("wrenches")
    both = builder.AddSystem(Multiplexer([6 * len(estimator.ft_frames), 6 * len(estimator.fsr_frames)]))
    both.set_name("known_wrenches")
    builder.Connect(sensors.ft_wrenches, both.get_input_port(0))
    builder.Connect(soles.GetOutputPort("wrenches"), both.get_input_port(1))
    return estimator.known_wrench_frames, both.get_output_port()


def _model_weight(estimator: EstimatorPlant) -> float:
    """The humanoid's weight in the estimators' model, N."""
    model = estimator.plant
    mass = model.CalcTotalMass(model.CreateDefaultContext(), [estimator.humanoid.model_instance])
    return mass * float(np.linalg.norm(model.gravity_field().gravity_vector()))


#: The gain of the residuals a robot without foot force sensing estimates its soles' wrenches
#: from for the EKF's contact flags, 1/s (the contact detector's: a sole's normal force
#: reaches the 10 % contact threshold 3 ms after it appears).
ESTIMATED_CONTACT_RESIDUAL_GAIN = 35.0


def _add_estimated_foot_contact(
    builder: DiagramBuilder,
    estimator: EstimatorPlant,
    sensed_state: OutputPort,
    measured_torque: OutputPort,
    period: float,
) -> FootContactFromForceTorque:
    """Contact flags of a robot without foot F/T sensors or FSRs, from its soles' wrenches
    estimated from the internal and external residuals (eqs. 11, 16; ``SoleWrenchCompensation``
    with one contact link's free wrench, gain ``ESTIMATED_CONTACT_RESIDUAL_GAIN``), with the
    F/T flags' thresholds (``CONTACT_ON_WEIGHT_FRACTION``, ``CONTACT_OFF_WEIGHT_FRACTION`` of
    the model's weight). The residuals read the sensed state, whose base part the EKF these
    flags feed estimates: their outputs come from their discrete state, so the loop has a
    step's delay and no algebraic loop."""
    from systems.residuals.momentum_residuals import ExternalResidual, InternalResidual

    gain = ESTIMATED_CONTACT_RESIDUAL_GAIN
    model = ResidualModel(estimator.plant, ONLINE_DYNAMICS)
    internal = builder.AddSystem(InternalResidual(estimator.plant, gain, period, model=model))
    external = builder.AddSystem(ExternalResidual(estimator.plant, gain, period, model=model))
    for name, residual in (("contact_internal_residual", internal), ("contact_external_residual", external)):
        residual.set_name(name)
        builder.Connect(sensed_state, residual.GetInputPort("state"))
        if residual.HasInputPort("measured_torque"):
            builder.Connect(measured_torque, residual.GetInputPort("measured_torque"))
    soles = builder.AddSystem(estimator.sole_wrench_compensation(gain, period))
    soles.set_name("contact_sole_wrenches")
    builder.Connect(sensed_state, soles.GetInputPort("state"))
    builder.Connect(external.GetOutputPort("external_wrench_world"), soles.GetInputPort("external_wrench_world"))
    builder.Connect(internal.GetOutputPort("residual"), soles.GetInputPort("internal_residual"))
    weight = _model_weight(estimator)
    contact = builder.AddSystem(
        FootContactFromForceTorque(
            len(estimator.unknown_wrench_frames),
            CONTACT_ON_WEIGHT_FRACTION * weight,
            off_threshold=CONTACT_OFF_WEIGHT_FRACTION * weight,
            period=period,
        )
    )
    contact.set_name("foot_contact_from_estimated_wrenches")
    builder.Connect(soles.GetOutputPort("sole_wrenches_world"), contact.GetInputPort("wrenches"))
    return contact


def _load(plant: MultibodyPlant, scene_graph: SceneGraph, model: str) -> HumanoidHandles | None:
    if is_humanoid(model):
        handles = add_humanoid(plant, model, scene_graph=scene_graph)
        add_ground(plant)
        return handles
    add_model_file(plant, model)
    return None


def _generic_gains(plant: MultibodyPlant, x: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """PD gains for any robot, from its joint-space inertia H_fb at the posture: kd = 0.2 H/T
    and kp = 10 kd keep the explicit 1 kHz PD stable (kd T / H well below 2)."""
    from systems.dynamics.floating_base import FloatingBaseDynamics

    nq = plant.num_positions()
    inertia = np.diag(FloatingBaseDynamics(plant).compute(x[:nq], x[nq:]).H_fb)
    kd = 0.2 * inertia / period
    return 10.0 * kd, kd
