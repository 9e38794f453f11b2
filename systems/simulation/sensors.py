"""Simulated sensors of a floating-base humanoid (what the estimators are allowed to see).

Every sensor is a stateless LeafSystem whose outputs are truth(t) + noise(t): direct
feedthrough, no delay, the noise being zero-mean Gaussian, held over ``period`` seconds and
a pure function of (seed, sample index) (see :mod:`systems.simulation.noise`), so runs are
reproducible and sensors with different seeds are independent. All units are SI.

Joint vectors are in the plant's joint-velocity order v[6:]: joint k is the 1-DoF joint
whose ``velocity_start()`` is 6 + k; its position is q[``position_start()``] (see
:func:`systems.simulation.pd_gravity.joints_in_velocity_order`).

* :class:`JointEncoders`: joint positions and velocities.
* :class:`MotorTorqueSensor`: the torque commanded to each actuated joint.
* :class:`FootForceTorqueSensors`: 6-axis F/T sensors in the ankle-sole welds (HRP-4),
  reporting the wrench the ground applies to the sole, in world.
* :func:`add_imu`: Drake's Gyroscope and Accelerometer on a frame, plus noise.
* :class:`BaseStateEstimator`: the free joint's pose and velocity, truth plus noise (a
  stand-in for a real base estimator).
* :class:`SensedStateAssembler`: packs the sensed base and joint values into the plant's
  [q; v] layout, the ``state`` an estimator receives.
* :func:`add_sensors`: all of the above for a humanoid, wired to the plant.

Reaction-force convention (verified numerically in tests/test_sensors.py on drake 1.51.1):
entry ``JointIndex(i)`` of ``plant.get_reaction_forces_output_port()`` is the spatial force
F_CJc_Jc that joint i's PARENT body applies to its CHILD body C, applied at the origin of
the joint's child frame Jc (``joint.frame_on_child()``) and expressed in Jc. For a
discrete plant the port is sampled: it reads zero until the first step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, Joint, JointActuatorIndex
from pydrake.systems.framework import BasicVector, Context, DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.sensors import Accelerometer, Gyroscope

from models import HumanoidHandles
from systems.common.checks import check_plant, per_joint
from systems.common.topology import floating_base_topology
from systems.simulation.imperfections import Imperfections, rated_joint_torques, torque_measurement_errors
from systems.simulation.noise import (
    NoisyVector,
    RandomWalkBias,
    SampledNoise,
    as_std_vector,
    check_finite_input,
    check_period,
    check_seed,
)

#: Default noise standard deviations (SI) of the sensors: white Gaussian noise, sampled and
#: held at 1 kHz. A momentum residual passes noise on the momentum (velocities) to its output
#: amplified by its gain K, so the velocity noises matter most; the values describe a
#: well-filtered 1 kHz state estimate (a slowly varying bias would not matter: the residual
#: sees only the momentum's rate). Torque, F/T and IMU figures are datasheet-class values.
DEFAULT_PERIOD = 1e-3  # s
ENCODER_POSITION_NOISE_STD = 1e-5  # rad (about 19-bit resolution over a turn)
ENCODER_VELOCITY_NOISE_STD = 5e-4  # rad/s (filtered differentiation of high-resolution encoders)
MOTOR_TORQUE_NOISE_STD = 0.05  # N m (motor-current torque estimate)
FT_FORCE_NOISE_STD = 0.1  # N (6-axis F/T sensor of the ATI Mini45 class)
FT_MOMENT_NOISE_STD = 0.005  # N m
GYRO_NOISE_STD = 1e-3  # rad/s
ACCEL_NOISE_STD = 0.02  # m/s^2
BASE_ORIENTATION_NOISE_STD = 5e-4  # rad (small rotation vector)
BASE_POSITION_NOISE_STD = 1e-3  # m
BASE_ANGULAR_VELOCITY_NOISE_STD = 5e-4  # rad/s
BASE_LINEAR_VELOCITY_NOISE_STD = 2e-4  # m/s (kinematic-inertial fusion, filtered)

#: Seed offsets used by add_sensors(seed=s): sensor i gets SEEDS_PER_CALL * s + offset.
SEED_OFFSETS = {"encoders": 0, "torque": 1, "ft": 2, "imu": 3, "base": 4, "fsr": 5}
SEEDS_PER_CALL = 16


# ---------------------------------------------------------------------------------------
# Helpers.
# ---------------------------------------------------------------------------------------


def _joint_indices(plant: MultibodyPlant, who: str):
    """(topology, q index per joint, v index per joint) in v[6:] order."""
    check_plant(plant, who)
    try:
        topology = floating_base_topology(plant)
    except ValueError as err:
        raise ValueError(f"{who}: {err}") from err
    q_index = np.array([j.position_start() for j in topology.joints], dtype=int)
    v_index = np.array([j.velocity_start() for j in topology.joints], dtype=int)
    return topology, q_index, v_index


def _std(value, n: int, name: str, who: str) -> np.ndarray:
    try:
        return as_std_vector(value, n, name)
    except ValueError as err:
        raise ValueError(f"{who}: {err}") from err


def _period_seed(period, seed, who: str) -> tuple[float, int]:
    try:
        return check_period(period), check_seed(seed)
    except ValueError as err:
        raise ValueError(f"{who}: {err}") from err


def _quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions [w, x, y, z]."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def rotation_vector_to_quaternion(phi: np.ndarray) -> np.ndarray:
    """Unit quaternion [w, x, y, z] of the rotation by |phi| rad about phi/|phi|."""
    phi = np.asarray(phi, dtype=float)
    angle = float(np.linalg.norm(phi))
    if angle < 1e-12:
        return np.array([1.0, 0.5 * phi[0], 0.5 * phi[1], 0.5 * phi[2]]) / np.sqrt(1.0 + 0.25 * angle * angle)
    s = np.sin(0.5 * angle) / angle
    return np.array([np.cos(0.5 * angle), s * phi[0], s * phi[1], s * phi[2]])


# ---------------------------------------------------------------------------------------
# Joint encoders.
# ---------------------------------------------------------------------------------------


class JointEncoders(LeafSystem):
    """Joint position and velocity encoders.

    Inputs:
        state: the plant's state [q; v] (nq + nv), the truth.

    Outputs:
        position: q[joints] + noise, n = nv - 6 entries in v[6:] order, rad (m for
            prismatic joints).
        velocity: v[joints] + noise, n entries in v[6:] order, rad/s (m/s).

    Noise: independent Gaussian per entry, std ``position_noise_std`` /
    ``velocity_noise_std``, held over ``period``; one stream seeded by ``seed``.

    Quantisation (``position_step`` > 0): the position output is
    step * round((q + noise) / step), an absolute encoder's reading; velocities are not
    quantised (they stand for a filtered velocity estimate).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        *,
        position_noise_std=ENCODER_POSITION_NOISE_STD,
        velocity_noise_std=ENCODER_VELOCITY_NOISE_STD,
        period: float = DEFAULT_PERIOD,
        seed: int = 0,
        position_step: float = 0.0,
    ):
        """Args:
            plant: a finalized floating-base plant (one free body, 1-DoF joints, welds).
            position_noise_std: rad, scalar or n entries (v[6:] order); default 2e-5.
            velocity_noise_std: rad/s, scalar or n entries; default 2e-3.
            period: noise sample-and-hold period, s; default 1e-3.
            seed: noise seed, non-negative integer; default 0.
            position_step: quantisation step of the positions, rad (m), >= 0; 0 (default)
                = none.

        Raises:
            ValueError: unsupported or unfinalized plant, bad std/period/seed/step.
        """
        super().__init__()
        who = "JointEncoders"
        step = float(position_step) if isinstance(position_step, (int, float, np.number)) else math.nan
        if not (math.isfinite(step) and step >= 0.0):
            raise ValueError(f"{who}: position_step must be a finite number >= 0 rad, got {position_step!r}")
        self._position_step = step
        topology, self._q_index, self._v_index = _joint_indices(plant, who)
        n = topology.num_joints
        self._n = n
        self._nq = plant.num_positions()
        self._q_select = _as_slice(self._q_index)
        self._v_select = _as_slice(self._nq + self._v_index)
        std = np.concatenate(
            [
                _std(position_noise_std, n, "position_noise_std", who),
                _std(velocity_noise_std, n, "velocity_noise_std", who),
            ]
        )
        period, seed = _period_seed(period, seed, who)
        self._noise = SampledNoise(2 * n, std, period, seed)
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self.DeclareVectorOutputPort("position", n, self._CalcPosition)
        self.DeclareVectorOutputPort("velocity", n, self._CalcVelocity)

    @property
    def noise(self) -> SampledNoise:
        """The noise stream: entries [0, n) position, [n, 2n) velocity."""
        return self._noise

    @property
    def position_step(self) -> float:
        """The position quantisation step, rad (0: none)."""
        return self._position_step

    def _eval_state(self, context: Context) -> np.ndarray:
        x = self._state.Eval(context)
        check_finite_input("JointEncoders", "state", x)
        return x

    def _CalcPosition(self, context: Context, output: BasicVector) -> None:
        q = self._eval_state(context)[self._q_select]
        if not self._noise.is_zero:
            q = q + self._noise.value(context.get_time())[: self._n]
        if self._position_step > 0.0:
            q = self._position_step * np.round(q / self._position_step)
        output.SetFromVector(q)

    def _CalcVelocity(self, context: Context, output: BasicVector) -> None:
        v = self._eval_state(context)[self._v_select]
        if not self._noise.is_zero:
            v = v + self._noise.value(context.get_time())[self._n :]
        output.SetFromVector(v)


# ---------------------------------------------------------------------------------------
# Motor torque.
# ---------------------------------------------------------------------------------------


class MotorTorqueSensor(LeafSystem):
    """Motor torque measurement: the actuation the motors applied, plus noise.

    Inputs:
        actuation: u, ``plant.num_actuated_dofs()`` entries in the plant's actuation order
            (``JointActuator.input_start()``), N m (N for prismatic joints). ``add_sensors``
            connects it to ``plant.get_net_actuation_output_port()``: on a discrete plant
            that is the actuation applied over the last time step (after effort limits), as
            a motor-current measurement at t_k reports the torque of the last period.

    Outputs:
        measured_torque: n = nv - 6 entries in v[6:] order, N m: u of the joint's
            actuator + noise; unactuated joints read exactly 0.

    What is measured is the command; any joint friction/damping of the simulated plant is
    not in it (the estimator's model of those only approximates them).

    Calibration error (``scale``, ``offset``): measured = scale ⊙ u + offset + noise per
    joint (a torque-constant and offset error of a current-based estimate).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        *,
        noise_std=MOTOR_TORQUE_NOISE_STD,
        period: float = DEFAULT_PERIOD,
        seed: int = 1,
        scale=None,
        offset=None,
    ):
        """Args:
            plant: a finalized floating-base plant whose actuators each drive one 1-DoF
                joint.
            noise_std: N m, scalar or n entries (v[6:] order); default 0.05.
            period: noise sample-and-hold period, s; default 1e-3.
            seed: noise seed; default 1.
            scale: per-joint factor (v[6:] order), scalar or n entries, finite; None = 1.
            offset: per-joint offset, N m, scalar or n entries, finite; None = 0.
                Unactuated joints read 0 regardless.

        Raises:
            ValueError: unsupported plant, bad std/period/seed/scale/offset.
        """
        super().__init__()
        who = "MotorTorqueSensor"
        topology, _, _ = _joint_indices(plant, who)
        n = topology.num_joints
        k_of_joint = {int(j.index()): k for k, j in enumerate(topology.joints)}
        na = plant.num_actuated_dofs()
        rows, cols = [], []  # measured[rows[i]] = u[cols[i]]
        for index in plant.GetJointActuatorIndices():
            actuator = plant.get_joint_actuator(JointActuatorIndex(int(index)))
            k = k_of_joint.get(int(actuator.joint().index()))
            if k is None:
                raise ValueError(
                    f"{who}: actuator {actuator.name()!r} drives joint "
                    f"{actuator.joint().name()!r}, which is not a 1-DoF joint of the tree"
                )
            rows.append(k)
            cols.append(actuator.input_start())
        self._rows = np.array(rows, dtype=int)
        self._cols = np.array(cols, dtype=int)
        std = _std(noise_std, n, "noise_std", who)
        actuated = np.zeros(n, dtype=bool)
        actuated[self._rows] = True
        std[~actuated] = 0.0
        period, seed = _period_seed(period, seed, who)
        self._noise = SampledNoise(n, std, period, seed)
        self._n = n
        self._scale = None if scale is None else per_joint(scale, n, "scale", who=who)[self._rows]
        self._offset = None if offset is None else per_joint(offset, n, "offset", who=who)[self._rows]
        self._actuation = self.DeclareVectorInputPort("actuation", na)
        self.DeclareVectorOutputPort("measured_torque", n, self._CalcTorque)

    @property
    def actuated_joints(self) -> np.ndarray:
        """Indices k (into v[6:]) of the actuated joints, in actuation order."""
        return self._rows[np.argsort(self._cols)].copy()

    def _CalcTorque(self, context: Context, output: BasicVector) -> None:
        u = self._actuation.Eval(context)
        check_finite_input("MotorTorqueSensor", "actuation", u)
        tau = np.zeros(self._n)
        tau[self._rows] = u[self._cols]
        if self._scale is not None:
            tau[self._rows] *= self._scale
        if self._offset is not None:
            tau[self._rows] += self._offset
        if not self._noise.is_zero:
            tau += self._noise.value(context.get_time())
        output.SetFromVector(tau)


# ---------------------------------------------------------------------------------------
# Foot force/torque sensors.
# ---------------------------------------------------------------------------------------


def _welded_subtree(plant: MultibodyPlant, root) -> list:
    """Bodies rigidly attached below ``root`` through weld joints only (root included)."""
    children: dict = {}
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.type_name() == "weld":
            children.setdefault(int(joint.parent_body().index()), []).append(joint.child_body())
    out, stack = [], [root]
    while stack:
        body = stack.pop()
        out.append(body)
        stack.extend(children.get(int(body.index()), []))
    return out


class FootForceTorqueSensors(LeafSystem):
    """6-axis force/torque sensors in weld joints (HRP-4's ankle F/T sensors).

    For each weld joint J (parent: the ankle side P; child: the sole side C, with child
    frame S = ``J.frame_on_child()`` = the sensor frame), the sensor reports the wrench that
    everything below the sensor (the ground) applies to the robot, as a real sensor does
    after compensating the known mass below it:

        W_ground = −W_weld_on_sole − W_gravity_on_sole,

    all about the sensor origin So and expressed in WORLD, where

    * W_weld_on_sole = the plant's reaction force of J (force of P on C at So, in S),
      re-expressed in world;
    * W_gravity_on_sole = the weight m g_W of the sole (body C plus every body welded
      below it, with their default mass properties) acting at their composite centre of
      mass, moved to So (moment p_SoCcm_W × m g_W). Omitted when
      ``compensate_sole_weight`` is False (then W = −W_weld_on_sole).

    When the sole is at rest, W_ground equals the sum of the contact wrenches on the sole
    (about So, in world); when the sole accelerates it differs by the sole's inertial
    wrench, as on a real robot. Bodies hanging below the sole through non-weld joints are
    not compensated (their weight is part of the reported wrench). Before a discrete
    plant's first step the reaction forces read zero, so the output is then −W_gravity
    (the sole's weight, pointing up). The noise is added to the world-frame components
    (a simplification of a real sensor's noise in its own axes; the stds are per axis).

    Inputs:
        reaction_forces: abstract list of SpatialForce indexed by JointIndex; connect
            ``plant.get_reaction_forces_output_port()`` (sampled for a discrete plant: zero
            before the first step).
        state: a state [q; v] of the plant, used only for the sensor frames' orientation
            in world and the sole-weight compensation: the robot's own estimate (the
            sensed state; ``add_sensors`` connects it, as a real robot expresses its
            readings with its estimated orientation) or the plant's true state.

    Outputs:
        wrenches: 6 entries per sensor, in the order of ``sensor_joints``:
            [moment about So, N m (3); force, N (3)], expressed in world, plus noise.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        sensor_joints: Sequence[Joint],
        *,
        force_noise_std=FT_FORCE_NOISE_STD,
        moment_noise_std=FT_MOMENT_NOISE_STD,
        period: float = DEFAULT_PERIOD,
        seed: int = 2,
        compensate_sole_weight: bool = True,
    ):
        """Args:
            plant: a finalized MultibodyPlant.
            sensor_joints: weld joints of ``plant`` carrying the sensors, e.g.
                ``[handles.ft_sensor_joints["right"], handles.ft_sensor_joints["left"]]``.
            force_noise_std: N, scalar or 3 entries (world x, y, z); default 0.5.
            moment_noise_std: N m, scalar or 3 entries; default 0.05.
            period: noise sample-and-hold period, s; default 1e-3.
            seed: noise seed; default 2.
            compensate_sole_weight: remove the static weight of the bodies below each
                sensor (default True).

        Raises:
            ValueError: unfinalized plant, empty/duplicate/non-weld/foreign sensor joints,
                bad std/period/seed.
        """
        super().__init__()
        who = "FootForceTorqueSensors"
        check_plant(plant, who)
        if isinstance(sensor_joints, (str, bytes, Joint)) or not isinstance(sensor_joints, Sequence):
            raise ValueError(
                f"{who}: sensor_joints must be a sequence of weld joints, got {type(sensor_joints).__name__}"
            )
        if len(sensor_joints) == 0:
            raise ValueError(f"{who}: sensor_joints is empty")
        joints = []
        for i, joint in enumerate(sensor_joints):
            if not isinstance(joint, Joint):
                raise ValueError(f"{who}: sensor_joints[{i}] is a {type(joint).__name__}, not a Joint")
            if joint.GetParentPlant() is not plant:
                raise ValueError(f"{who}: sensor_joints[{i}] ({joint.name()!r}) is not a joint of this plant")
            if joint.type_name() != "weld":
                raise ValueError(
                    f"{who}: sensor_joints[{i}] ({joint.name()!r}) is a {joint.type_name()!r} joint, not a weld joint"
                )
            if any(int(j.index()) == int(joint.index()) for j in joints):
                raise ValueError(f"{who}: sensor_joints[{i}] ({joint.name()!r}) appears twice")
            joints.append(joint)
        if not isinstance(compensate_sole_weight, (bool, np.bool_)):
            raise ValueError(f"{who}: compensate_sole_weight must be a bool, got {compensate_sole_weight!r}")
        self._plant = plant
        self._joints = tuple(joints)
        self._frames = tuple(j.frame_on_child() for j in joints)
        self._joint_index = [int(j.index()) for j in joints]
        self._max_joint_index = max(self._joint_index)
        self._compensate = bool(compensate_sole_weight)
        self._context = plant.CreateDefaultContext()
        self._nq = plant.num_positions()

        # Sole composite mass m and CoM p_SCcm_S in each sensor frame S (fixed, welded).
        gravity = np.asarray(plant.gravity_field().gravity_vector(), dtype=float)
        self._gravity = gravity
        self._sole_mass = np.zeros(len(joints))
        self._p_SCcm_S = np.zeros((len(joints), 3))
        for i, (joint, frame) in enumerate(zip(joints, self._frames)):
            mass, first_moment = 0.0, np.zeros(3)
            for body in _welded_subtree(plant, joint.child_body()):
                m = body.default_mass()
                X_SB = plant.CalcRelativeTransform(self._context, frame, body.body_frame())
                mass += m
                first_moment += m * (X_SB @ np.asarray(body.default_com(), dtype=float))
            self._sole_mass[i] = mass
            self._p_SCcm_S[i] = first_moment / mass if mass > 0 else np.zeros(3)
        self._weight = self._sole_mass[:, None] * gravity[None, :]  # m g_W per sensor, N
        # [m g]x transposed, per sensor: (row r) @ [w]x^T = ([w]x r)^T = (w x r)^T.
        self._weight_skew_T = np.array(
            [[[0.0, w[2], -w[1]], [-w[2], 0.0, w[0]], [w[1], -w[0], 0.0]] for w in self._weight]
        )

        m = len(joints)
        force_std = _std(force_noise_std, 3, "force_noise_std", who)
        moment_std = _std(moment_noise_std, 3, "moment_noise_std", who)
        period, seed = _period_seed(period, seed, who)
        self._noise = SampledNoise(6 * m, np.tile(np.concatenate([moment_std, force_std]), m), period, seed)
        self._reaction = self.DeclareAbstractInputPort("reaction_forces", AbstractValue.Make([SpatialForce()]))
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self.DeclareVectorOutputPort("wrenches", 6 * m, self._CalcWrenches)

    @property
    def sensor_joints(self) -> tuple:
        return self._joints

    @property
    def sensor_frames(self) -> tuple:
        """The sensor frames S (the welds' child frames), in output order."""
        return self._frames

    @property
    def sole_masses(self) -> np.ndarray:
        """Mass compensated below each sensor, kg."""
        return self._sole_mass.copy()

    @property
    def noise(self) -> SampledNoise:
        return self._noise

    def CalcGroundWrenches(self, reaction_forces, x: np.ndarray) -> np.ndarray:
        """Noise-free ``wrenches`` for a reaction-force list and a state x = [q; v]."""
        self._plant.SetPositions(self._context, x[: self._nq])
        if len(reaction_forces) <= self._max_joint_index:
            raise ValueError(
                f"FootForceTorqueSensors: input 'reaction_forces' has "
                f"{len(reaction_forces)} entries; the plant has joint index "
                f"{self._max_joint_index}"
            )
        # Vectorised over the sensors, one batched product: rows [tau_S; f_S; p_SCcm_S] times
        # R_WS^T give R_WS tau_S, R_WS f_S and r = R_WS p_SCcm_S; the wrench is -R_WS [tau_S; f_S]
        # with the sole weight removed (force - m g, moment - r x m g = moment + [m g]x r).
        rows = np.empty((len(self._frames), 3, 3))
        for i, index in enumerate(self._joint_index):
            F = reaction_forces[index]
            rows[i, 0] = F.rotational()
            rows[i, 1] = F.translational()
        rows[:, 2] = self._p_SCcm_S
        R_WS_T = np.array([frame.CalcRotationMatrixInWorld(self._context).matrix().T for frame in self._frames])
        rotated = rows @ R_WS_T
        moment, force = -rotated[:, 0], -rotated[:, 1]
        if self._compensate:
            force -= self._weight
            moment += (rotated[:, 2:3] @ self._weight_skew_T)[:, 0]
        out = np.concatenate((moment, force), axis=1).reshape(-1)
        if not math.isfinite(out.dot(out)) and not np.isfinite(out).all():
            for index, joint in zip(self._joint_index, self._joints):
                F = reaction_forces[index]
                if not (np.isfinite(F.rotational()).all() and np.isfinite(F.translational()).all()):
                    raise ValueError(
                        f"FootForceTorqueSensors: input 'reaction_forces' has NaN or inf at "
                        f"indices [{index}] (joint {joint.name()!r})"
                    )
            raise ValueError("FootForceTorqueSensors: non-finite wrench (check input 'state')")
        return out

    def _CalcWrenches(self, context: Context, output: BasicVector) -> None:
        x = self._state.Eval(context)
        check_finite_input("FootForceTorqueSensors", "state", x)
        wrenches = self.CalcGroundWrenches(self._reaction.Eval(context), x)
        if not self._noise.is_zero:
            wrenches += self._noise.value(context.get_time())
        output.SetFromVector(wrenches)


# ---------------------------------------------------------------------------------------
# IMU.
# ---------------------------------------------------------------------------------------


@dataclass
class Imu:
    """What add_imu() created.

    Attributes:
        frame: the IMU frame S.
        gyroscope: Drake's Gyroscope (noise-free ω_WS expressed in S).
        accelerometer: Drake's Accelerometer (noise-free R_SW (a_WS − g_W)).
        gyro_noise, accel_noise: the systems adding the white noise: a NoisyVector, or
            with a bias random walk the RandomWalkBias, which then adds both.
        angular_velocity: output port, ω_WS expressed in S + noise (+ bias), rad/s (3).
        linear_acceleration: output port, proper acceleration R_SW (a_WS − g_W) + noise
            (+ bias), m/s^2 (3); +9.81 along the sensor's up axis at rest.
        gyro_bias, accel_bias: the RandomWalkBias systems adding the noise and the bias,
            or None (no bias random walk).
    """

    frame: Frame
    gyroscope: Gyroscope
    accelerometer: Accelerometer
    gyro_noise: NoisyVector | RandomWalkBias
    accel_noise: NoisyVector | RandomWalkBias
    angular_velocity: OutputPort
    linear_acceleration: OutputPort
    gyro_bias: RandomWalkBias | None = None
    accel_bias: RandomWalkBias | None = None


def add_imu(
    builder: DiagramBuilder,
    plant: MultibodyPlant,
    frame: Frame,
    *,
    gyro_noise_std=GYRO_NOISE_STD,
    accel_noise_std=ACCEL_NOISE_STD,
    period: float = DEFAULT_PERIOD,
    seed: int = 3,
    name: str = "imu",
    gyro_bias_random_walk: float = 0.0,
    accel_bias_random_walk: float = 0.0,
    gyro_turn_on_bias=(0.0, 0.0, 0.0),
) -> Imu:
    """Adds a gyroscope and an accelerometer at ``frame`` (on its body), with noise.

    Drake's ``Gyroscope(body, X_BS)`` and ``Accelerometer(body, X_BS, g_W)`` with X_BS the
    frame's fixed pose in its body, fed by the plant's body poses, spatial velocities and
    spatial accelerations output ports; each followed by a NoisyVector (seeds ``seed`` and
    ``seed`` + 1000003 for gyro and accelerometer), or with a bias random walk by a
    RandomWalkBias that adds the same noise and the bias (one system per sensor, one
    evaluation per step; the same numbers as the NoisyVector then the RandomWalkBias).

    Args:
        builder: the DiagramBuilder holding ``plant``.
        plant: a finalized MultibodyPlant.
        frame: the IMU frame S, a frame of ``plant``.
        gyro_noise_std: rad/s, scalar or 3 entries; default 1e-3.
        accel_noise_std: m/s^2, scalar or 3 entries; default 0.02.
        period: noise sample-and-hold period, s; default 1e-3.
        seed: noise seed; default 3.
        name: prefix of the added systems' names.
        gyro_bias_random_walk: sigma of the gyro bias random walk, rad/s^2/sqrt(Hz), scalar
            or 3 entries; > 0 adds a RandomWalkBias (seed ``seed`` + 2000003) to the
            noise: bias std sigma sqrt(t). Default 0 (none).
        accel_bias_random_walk: the same for the accelerometer, m/s^3/sqrt(Hz) (seed
            ``seed`` + 3000003).
        gyro_turn_on_bias: the gyro's constant bias at start (3 entries, rad/s, IMU frame),
            the bias walk's start: non-zero adds the gyro's RandomWalkBias even without a
            walk. Default 0 (a gyro calibrated at start-up).

    Returns:
        The Imu handles (output ports ``angular_velocity``, ``linear_acceleration``).

    Raises:
        ValueError: unfinalized plant, a frame not of this plant, bad std/period/seed.
    """
    who = "add_imu"
    check_plant(plant, who)
    if not isinstance(frame, Frame):
        raise ValueError(f"{who}: frame must be a Frame, got {type(frame).__name__}")
    if frame.GetParentPlant() is not plant:
        raise ValueError(f"{who}: frame {frame.name()!r} is not a frame of this plant")
    gyro_std = _std(gyro_noise_std, 3, "gyro_noise_std", who)
    accel_std = _std(accel_noise_std, 3, "accel_noise_std", who)
    walks = {
        "gyro": _std(gyro_bias_random_walk, 3, "gyro_bias_random_walk", who),
        "accel": _std(accel_bias_random_walk, 3, "accel_bias_random_walk", who),
    }
    period, seed = _period_seed(period, seed, who)
    turn_on = {"gyro": np.asarray(gyro_turn_on_bias, dtype=float), "accel": np.zeros(3)}
    if turn_on["gyro"].shape != (3,) or not np.isfinite(turn_on["gyro"]).all():
        raise ValueError(f"{who}: gyro_turn_on_bias must be 3 finite rad/s, got {gyro_turn_on_bias!r}")
    body = frame.body()
    X_BS = RigidTransform(frame.GetFixedPoseInBodyFrame())
    gravity = np.asarray(plant.gravity_field().gravity_vector(), dtype=float)
    gyro = builder.AddSystem(Gyroscope(body, X_BS))
    gyro.set_name(f"{name}_gyroscope")
    accel = builder.AddSystem(Accelerometer(body, X_BS, gravity))
    accel.set_name(f"{name}_accelerometer")
    builder.Connect(plant.get_body_poses_output_port(), gyro.get_body_poses_input_port())
    builder.Connect(plant.get_body_spatial_velocities_output_port(), gyro.get_body_velocities_input_port())
    builder.Connect(plant.get_body_poses_output_port(), accel.get_body_poses_input_port())
    builder.Connect(plant.get_body_spatial_velocities_output_port(), accel.get_body_velocities_input_port())
    builder.Connect(plant.get_body_spatial_accelerations_output_port(), accel.get_body_accelerations_input_port())
    systems, outputs, biases = {}, {}, {}
    measurements = {"gyro": gyro.get_measurement_output_port(), "accel": accel.get_measurement_output_port()}
    stds = {"gyro": gyro_std, "accel": accel_std}
    for kind, noise_offset, bias_offset in (("gyro", 0, 2000003), ("accel", 1000003, 3000003)):
        if np.any(walks[kind] > 0.0) or np.any(turn_on[kind] != 0.0):
            system = builder.AddSystem(
                RandomWalkBias(
                    3,
                    walks[kind],
                    period,
                    seed + bias_offset,
                    white_noise_std=stds[kind],
                    white_noise_seed=seed + noise_offset,
                    initial_bias=turn_on[kind],
                )
            )
            system.set_name(f"{name}_{kind}_noise_and_bias")
            biases[kind] = system
        else:
            system = builder.AddSystem(NoisyVector(3, stds[kind], period, seed + noise_offset))
            system.set_name(f"{name}_{kind}_noise")
        builder.Connect(measurements[kind], system.get_input_port())
        systems[kind], outputs[kind] = system, system.get_output_port()
    return Imu(
        frame,
        gyro,
        accel,
        systems["gyro"],
        systems["accel"],
        outputs["gyro"],
        outputs["accel"],
        gyro_bias=biases.get("gyro"),
        accel_bias=biases.get("accel"),
    )


# ---------------------------------------------------------------------------------------
# Base state.
# ---------------------------------------------------------------------------------------


class BaseStateEstimator(LeafSystem):
    """Floating-base pose and velocity: the truth plus noise (stand-in for an estimator).

    Inputs:
        state: the plant's true state [q; v].

    Outputs:
        base_pose: 7 entries, as the free joint's q[start:start+7]: unit quaternion
            [w, x, y, z] of the base frame in the joint's parent (world) frame, then the
            base origin position, m. The orientation noise is a small rotation φ (rad,
            std ``orientation_noise_std`` per axis) applied in the base frame,
            q_sensed = q ⊗ exp(φ/2), renormalised; position noise is added.
        base_velocity: 6 entries, as v[start:start+6]: Drake's [ω_WB; v_WBo] expressed in
            the free joint's parent frame, rad/s and m/s, plus noise.

    With all stds 0 the outputs equal the state's entries exactly.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        *,
        orientation_noise_std=BASE_ORIENTATION_NOISE_STD,
        position_noise_std=BASE_POSITION_NOISE_STD,
        angular_velocity_noise_std=BASE_ANGULAR_VELOCITY_NOISE_STD,
        linear_velocity_noise_std=BASE_LINEAR_VELOCITY_NOISE_STD,
        period: float = DEFAULT_PERIOD,
        seed: int = 4,
    ):
        """Args:
            plant: a finalized floating-base plant.
            orientation_noise_std: rad, scalar or 3 entries (base-frame axes); default 1e-3.
            position_noise_std: m, scalar or 3; default 1e-3.
            angular_velocity_noise_std: rad/s, scalar or 3; default 2e-3.
            linear_velocity_noise_std: m/s, scalar or 3; default 2e-3.
            period: noise sample-and-hold period, s; default 1e-3.
            seed: noise seed; default 4.

        Raises:
            ValueError: unsupported plant, bad std/period/seed.
        """
        super().__init__()
        who = "BaseStateEstimator"
        topology, _, _ = _joint_indices(plant, who)
        self._q0 = topology.free_joint.position_start()
        self._v0 = plant.num_positions() + topology.free_joint.velocity_start()
        std = np.concatenate(
            [
                _std(orientation_noise_std, 3, "orientation_noise_std", who),
                _std(position_noise_std, 3, "position_noise_std", who),
                _std(angular_velocity_noise_std, 3, "angular_velocity_noise_std", who),
                _std(linear_velocity_noise_std, 3, "linear_velocity_noise_std", who),
            ]
        )
        period, seed = _period_seed(period, seed, who)
        self._noise = SampledNoise(12, std, period, seed)
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self.DeclareVectorOutputPort("base_pose", 7, self._CalcPose)
        self.DeclareVectorOutputPort("base_velocity", 6, self._CalcVelocity)

    @property
    def noise(self) -> SampledNoise:
        """Entries: orientation (3), position (3), angular velocity (3), linear velocity (3)."""
        return self._noise

    def _eval_state(self, context: Context) -> np.ndarray:
        x = self._state.Eval(context)
        check_finite_input("BaseStateEstimator", "state", x)
        return x

    def _CalcPose(self, context: Context, output: BasicVector) -> None:
        pose = self._eval_state(context)[self._q0 : self._q0 + 7]
        if self._noise.is_zero:
            output.SetFromVector(pose)
            return
        # q ⊗ exp(φ/2), renormalised, in scalar arithmetic (this runs twice per time step;
        # equal to _quaternion_multiply(q, rotation_vector_to_quaternion(φ)) / norm).
        noise = self._noise.value(context.get_time())
        px, py, pz, dx, dy, dz = noise[:6].tolist()
        aw, ax, ay, az, x, y, z = pose.tolist()
        angle = math.sqrt(px * px + py * py + pz * pz)
        if angle < 1e-12:
            bw, s = 1.0, 0.5
        else:
            bw, s = math.cos(0.5 * angle), math.sin(0.5 * angle) / angle
        bx, by, bz = s * px, s * py, s * pz
        w = aw * bw - ax * bx - ay * by - az * bz
        qx = aw * bx + ax * bw + ay * bz - az * by
        qy = aw * by - ax * bz + ay * bw + az * bx
        qz = aw * bz + ax * by - ay * bx + az * bw
        inv = 1.0 / math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
        output.SetFromVector((w * inv, qx * inv, qy * inv, qz * inv, x + dx, y + dy, z + dz))

    def _CalcVelocity(self, context: Context, output: BasicVector) -> None:
        velocity = np.array(self._eval_state(context)[self._v0 : self._v0 + 6])
        if not self._noise.is_zero:
            velocity += self._noise.value(context.get_time())[6:]
        output.SetFromVector(velocity)


# ---------------------------------------------------------------------------------------
# Sensed state.
# ---------------------------------------------------------------------------------------


def _as_slice(index: np.ndarray) -> slice | np.ndarray:
    """A run of consecutive indices as a slice (a view, no gather), else the indices."""
    if index.size and np.array_equal(index, np.arange(index[0], index[0] + index.size)):
        return slice(int(index[0]), int(index[0]) + index.size)
    return index


class SensedStateAssembler(LeafSystem):
    """Packs sensed base and joint values into the plant's state layout [q; v].

    Inputs:
        base_pose: 7, the free joint's [quaternion w, x, y, z; position, m].
        base_velocity: 6, the free joint's [ω, rad/s; v, m/s] (Drake's convention).
        joint_position: n = nv - 6, v[6:] order, rad (m).
        joint_velocity: n, v[6:] order, rad/s (m/s).

    Outputs:
        state: nq + nv, each value placed at its joint's position_start()/velocity_start()
            (the free joint's and the 1-DoF joints'): what estimators receive as ``state``.
    """

    def __init__(self, plant: MultibodyPlant):
        """Args:
            plant: a finalized floating-base plant.

        Raises:
            ValueError: unsupported or unfinalized plant.
        """
        super().__init__()
        who = "SensedStateAssembler"
        topology, q_index, v_index = _joint_indices(plant, who)
        nq, nv = plant.num_positions(), plant.num_velocities()
        q0 = topology.free_joint.position_start()
        v0 = topology.free_joint.velocity_start()
        self._pose_index = np.arange(q0, q0 + 7)
        self._velocity_index = nq + np.arange(v0, v0 + 6)
        self._q_index = q_index
        self._v_index = nq + v_index
        covered = np.concatenate([self._pose_index, self._velocity_index, self._q_index, self._v_index])
        if sorted(covered.tolist()) != list(range(nq + nv)):
            raise ValueError(f"{who}: the free joint and 1-DoF joints do not cover the plant's state exactly once")
        n = topology.num_joints
        self._size = nq + nv
        self._ports = (
            (self.DeclareVectorInputPort("base_pose", 7), _as_slice(self._pose_index)),
            (self.DeclareVectorInputPort("base_velocity", 6), _as_slice(self._velocity_index)),
            (self.DeclareVectorInputPort("joint_position", n), _as_slice(self._q_index)),
            (self.DeclareVectorInputPort("joint_velocity", n), _as_slice(self._v_index)),
        )
        self.DeclareVectorOutputPort("state", nq + nv, self._CalcState)

    def _CalcState(self, context: Context, output: BasicVector) -> None:
        x = np.empty(self._size)
        for port, index in self._ports:
            x[index] = port.Eval(context)
        if not math.isfinite(float(x @ x)):  # one check for all four inputs; name the culprit
            for port, index in self._ports:
                check_finite_input("SensedStateAssembler", port.get_name(), x[index])
        output.SetFromVector(x)


# ---------------------------------------------------------------------------------------
# Everything for a humanoid.
# ---------------------------------------------------------------------------------------


@dataclass
class SensorHandles:
    """What add_sensors() created.

    Attributes:
        encoders: JointEncoders.
        torque_sensor: MotorTorqueSensor, reading the plant's net actuation output.
        ft_sensors: FootForceTorqueSensors, or None if the robot has no F/T welds.
        imu: Imu handles.
        base_estimator: BaseStateEstimator, or None when ``add_sensors`` was called with
            ``base_estimator=False`` (the caller connects the assembler's base inputs).
        assembler: SensedStateAssembler.
        state: output port, the sensed [q; v] (nq + nv), for estimators' ``state`` input.
        measured_torque: output port, n (v[6:] order), N m.
        ft_wrenches: output port, 6 per F/T sensor ([moment about the sensor origin; force]
            of the ground on the sole, world), or None.
        ft_frames: the F/T sensor frames in ``ft_wrenches`` order (empty if none).
        ft_sides: the sides ("right", "left", ...) in ``ft_wrenches`` order.
        fsr_array: the feet's ``FsrArray`` (4 FSRs per foot, both feet) when a foot has
            ``sensing: fsr``, else None.
        fsr_forces: its ``fsr_forces`` output port (8, ``FSR_NAMES`` order), or None.
        seeds: the seed of each sensor.
        noise_std_factor: the factor on the default noise stds of this set (0 without
            noise, else ``add_sensors``' noise_scale), for sensors added beside it.
    """

    encoders: JointEncoders
    torque_sensor: MotorTorqueSensor
    ft_sensors: FootForceTorqueSensors | None
    imu: Imu
    base_estimator: BaseStateEstimator | None
    assembler: SensedStateAssembler
    state: OutputPort
    measured_torque: OutputPort
    ft_wrenches: OutputPort | None
    ft_frames: tuple
    ft_sides: tuple
    seeds: dict
    noise_std_factor: float = 1.0
    fsr_array: object | None = None
    fsr_forces: OutputPort | None = None


def add_sensors(
    builder: DiagramBuilder,
    plant: MultibodyPlant,
    handles: HumanoidHandles,
    *,
    noise: bool = True,
    noise_scale: float = 1.0,
    seed: int = 0,
    name_prefix: str = "",
    imperfections: Imperfections | None = None,
    base_estimator: bool = True,
) -> SensorHandles:
    """Adds a humanoid's sensors to ``builder`` and wires them to ``plant``.

    Adds JointEncoders, MotorTorqueSensor, FootForceTorqueSensors (only if
    ``handles.ft_sensor_joints`` is non-empty; sides in sorted order, i.e. left then
    right), an IMU on ``handles.imu_frame``, a BaseStateEstimator and a
    SensedStateAssembler (encoders + base estimate → sensed state), all with the default
    noise levels of this module, or none when ``noise`` is False.

    Connected: the plant's state output to the encoders and base estimator; the sensed
    state (the robot's own estimate) to the F/T sensors, which express the wrenches in
    world with it; the plant's reaction forces to the F/T sensors; the plant's body poses, velocities and
    accelerations to the IMU; the plant's net actuation (what the motors applied over the
    last step) to the torque sensor.

    Args:
        builder: the DiagramBuilder holding ``plant``.
        plant: a finalized floating-base MultibodyPlant holding the humanoid.
        handles: the humanoid's handles (``models.add_humanoid``).
        noise: False sets every noise std to 0 (outputs equal the truth).
        noise_scale: a factor on every white noise std (the defaults of this module and
            the IMU noise densities of ``imperfections``): 1 (default) the documented
            levels, 2 twice as noisy sensors. Finite, >= 0.
        seed: non-negative integer; sensor i gets seed 16 * seed + offset (SEED_OFFSETS),
            so the defaults of the individual sensors are seed = 0.
        name_prefix: prepended to the added systems' names (e.g. to add two sensor sets,
            one noisy and one not, to the same diagram).
        imperfections: the sensor groups of ``Imperfections`` (``imu``, ``encoders``,
            ``torque_sensor``; seeded by ``imperfections.seed``), applied whatever
            ``noise`` is; an IMU noise density > 0 replaces that sensor's default std.
            None or ideal: no change.
        base_estimator: True (default) adds the stand-in BaseStateEstimator (truth plus
            noise) and connects it to the assembler's ``base_pose``/``base_velocity``; False
            adds neither and leaves those two inputs for the caller to connect (e.g. a real
            floating-base estimator, ``diagrams.station.humanoid_station``).

    Returns:
        SensorHandles.

    Raises:
        ValueError: bad arguments (see the individual sensors).
    """
    who = "add_sensors"
    check_plant(plant, who)
    if not isinstance(noise, (bool, np.bool_)):
        raise ValueError(f"{who}: noise must be a bool, got {noise!r}")
    if not isinstance(name_prefix, str):
        raise ValueError(f"{who}: name_prefix must be a str, got {type(name_prefix).__name__}")
    if not isinstance(handles, HumanoidHandles):
        raise ValueError(f"{who}: handles must be HumanoidHandles, got {type(handles).__name__}")
    try:
        seed = check_seed(seed)
    except ValueError as err:
        raise ValueError(f"{who}: {err}") from err
    if isinstance(noise_scale, (bool, np.bool_)) or not isinstance(noise_scale, (int, float, np.integer, np.floating)):
        raise ValueError(f"{who}: noise_scale must be a number, got {noise_scale!r}")
    if not (math.isfinite(noise_scale) and noise_scale >= 0.0):
        raise ValueError(f"{who}: noise_scale must be finite and >= 0, got {noise_scale!r}")
    seeds = {key: SEEDS_PER_CALL * seed + offset for key, offset in SEED_OFFSETS.items()}
    on = float(noise_scale) if noise else 0.0
    imp = Imperfections() if imperfections is None else imperfections
    if not isinstance(imp, Imperfections):
        raise ValueError(f"{who}: imperfections must be Imperfections, got {type(imp).__name__}")
    imp.validate()
    torque_errors = {}
    if imp.torque_sensor.scale_error_percent > 0.0 or imp.torque_sensor.offset_percent > 0.0:
        scale, offset = torque_measurement_errors(
            rated_joint_torques(plant),
            imp.torque_sensor.scale_error_percent,
            imp.torque_sensor.offset_percent,
            imp.seed,
        )
        torque_errors = {"scale": scale, "offset": offset}
    gyro_std = on * GYRO_NOISE_STD
    if imp.imu.gyro_noise_density > 0.0:
        gyro_std = noise_scale * imp.imu.gyro_noise_density / math.sqrt(DEFAULT_PERIOD)
    accel_std = on * ACCEL_NOISE_STD
    if imp.imu.accel_noise_density > 0.0:
        accel_std = noise_scale * imp.imu.accel_noise_density / math.sqrt(DEFAULT_PERIOD)

    state_port = plant.get_state_output_port()
    encoders = builder.AddSystem(
        JointEncoders(
            plant,
            position_noise_std=on * ENCODER_POSITION_NOISE_STD,
            velocity_noise_std=on * ENCODER_VELOCITY_NOISE_STD,
            seed=seeds["encoders"],
            position_step=imp.encoders.step,
        )
    )
    encoders.set_name(f"{name_prefix}joint_encoders")
    builder.Connect(state_port, encoders.GetInputPort("state"))

    torque = builder.AddSystem(
        MotorTorqueSensor(plant, noise_std=on * MOTOR_TORQUE_NOISE_STD, seed=seeds["torque"], **torque_errors)
    )
    torque.set_name(f"{name_prefix}motor_torque_sensor")
    builder.Connect(plant.get_net_actuation_output_port(), torque.GetInputPort("actuation"))

    ft = None
    sides = tuple(sorted(handles.ft_sensor_joints))
    if sides:
        ft = builder.AddSystem(
            FootForceTorqueSensors(
                plant,
                [handles.ft_sensor_joints[s] for s in sides],
                force_noise_std=on * FT_FORCE_NOISE_STD,
                moment_noise_std=on * FT_MOMENT_NOISE_STD,
                seed=seeds["ft"],
            )
        )
        ft.set_name(f"{name_prefix}foot_force_torque_sensors")
        builder.Connect(plant.get_reaction_forces_output_port(), ft.GetInputPort("reaction_forces"))

    fsr = None
    fsr_feet = [side for side, sensing in handles.foot_sensing.items() if sensing == "fsr"]
    if fsr_feet:
        from systems.observer.fsr_sensing import FSR_NOISE_STD, FSR_SATURATION, FSR_SIDES, FsrArray

        feet = handles.description.feet if handles.description is not None else {}
        ranges = [
            feet[side].fsr_range if side in feet and feet[side].fsr_range is not None else FSR_SATURATION
            for side in FSR_SIDES
        ]
        fsr = builder.AddSystem(
            FsrArray(
                plant,
                handles,
                noise_std=on * FSR_NOISE_STD,
                saturation=np.repeat(ranges, 4),
                seed=seeds["fsr"],
            )
        )
        fsr.set_name(f"{name_prefix}foot_fsr_array")
        builder.Connect(plant.get_contact_results_output_port(), fsr.GetInputPort("contact_results"))

    imu = add_imu(
        builder,
        plant,
        handles.imu_frame,
        gyro_noise_std=gyro_std,
        accel_noise_std=accel_std,
        seed=seeds["imu"],
        name=f"{name_prefix}imu",
        gyro_bias_random_walk=imp.imu.gyro_bias_random_walk,
        accel_bias_random_walk=imp.imu.accel_bias_random_walk,
        gyro_turn_on_bias=imp.imu.gyro_turn_on_bias(),
    )

    base = None
    if base_estimator:
        base = builder.AddSystem(
            BaseStateEstimator(
                plant,
                orientation_noise_std=on * BASE_ORIENTATION_NOISE_STD,
                position_noise_std=on * BASE_POSITION_NOISE_STD,
                angular_velocity_noise_std=on * BASE_ANGULAR_VELOCITY_NOISE_STD,
                linear_velocity_noise_std=on * BASE_LINEAR_VELOCITY_NOISE_STD,
                seed=seeds["base"],
            )
        )
        base.set_name(f"{name_prefix}base_state_estimator")
        builder.Connect(state_port, base.GetInputPort("state"))

    assembler = builder.AddSystem(SensedStateAssembler(plant))
    assembler.set_name(f"{name_prefix}sensed_state")
    if base is not None:
        builder.Connect(base.GetOutputPort("base_pose"), assembler.GetInputPort("base_pose"))
        builder.Connect(base.GetOutputPort("base_velocity"), assembler.GetInputPort("base_velocity"))
    builder.Connect(encoders.GetOutputPort("position"), assembler.GetInputPort("joint_position"))
    builder.Connect(encoders.GetOutputPort("velocity"), assembler.GetInputPort("joint_velocity"))
    if ft is not None:
        # A real robot expresses its F/T readings in world with its own estimate of its
        # orientation, so the estimators see the wrenches and gravity in one frame. (Rotated
        # with the true orientation instead, a base tilt error of 0.02 deg biased a
        # calibration's hip torque offsets by up to 2 N m.)
        builder.Connect(assembler.GetOutputPort("state"), ft.GetInputPort("state"))

    return SensorHandles(
        encoders=encoders,
        torque_sensor=torque,
        ft_sensors=ft,
        imu=imu,
        base_estimator=base,
        assembler=assembler,
        state=assembler.GetOutputPort("state"),
        measured_torque=torque.GetOutputPort("measured_torque"),
        ft_wrenches=None if ft is None else ft.GetOutputPort("wrenches"),
        ft_frames=() if ft is None else ft.sensor_frames,
        ft_sides=sides,
        seeds=seeds,
        noise_std_factor=on,
        fsr_array=fsr,
        fsr_forces=None if fsr is None else fsr.GetOutputPort("fsr_forces"),
    )


__all__ = [
    "BaseStateEstimator",
    "FootForceTorqueSensors",
    "Imu",
    "JointEncoders",
    "MotorTorqueSensor",
    "SensedStateAssembler",
    "SensorHandles",
    "add_imu",
    "add_sensors",
    "rotation_vector_to_quaternion",
]
