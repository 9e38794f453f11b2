"""Compliant arms driven by an external-force estimate (Hawley, Rahem, Suleiman 2019, Sec. 6.4).

The paper's Fig. 13, as Drake systems (all ports SI, forces in N, world axes unless named):

* ``JointTorqueFromPositionError`` (eq. 27): the motor torque of each arm joint from its
  position error, tau_m^i = K_m^i (q_d^i - q^i).
* ``ArmExternalForceEstimator`` (eqs. 25-26): the force on each hand from the arm's joint
  torques minus the model's, F = -(J^T)^+ (tau_m - tau_hat).
* ``ObserverHandForce``: the Kalman observer's virtual force at the CoM (eq. 11) turned
  back into the force on the hands (eq. 11 inverted for a force applied at the hands).
* ``CompliantArmBlender`` (eq. 28): F = K1 F_observer + K2 F_joint, K1 = K_a / K_t, K2 = 1 - K1.
* ``HandComplianceController`` (eq. 29): x_h = x_h^0 + F_x / k, realised by a damped
  least-squares IK of each arm, output as the station PD's ``desired_position``.
* ``fit_motor_constants``: K_m of eq. 27 from the rest states of a static test (the test
  itself, a simulation, is ``diagrams.observer.calibration.identify_motor_constant``).

What eq. 27 measures here. The station's controller (``systems.simulation.pd_gravity``) applies
u = -tau_g(q) + K_p (q_d - q) - K_d v: gravity is compensated by a model feed-forward, so
K_m (q_d - q) is the PD's proportional torque only, not the motor's total torque. With
Drake's arm rows of M v_dot + C v = tau_g + u + J^T F, the proportional torque is

    K_p (q_d - q) = M_a v_dot + (C v)_a + (K_d + b) v_a - J_a^T F     (b: joint damping),

so tau_hat of eq. 25 keeps the inertia, Coriolis/centrifugal and damping terms and drops
gravity (``gravity_compensated=True``, the default; set it False for a controller without
gravity feed-forward, then tau_hat also holds g(q) = -tau_g). At rest K_m identifies as K_p
(``diagrams.observer.calibration.identify_motor_constant``). Sign: the paper's F^ext
(eq. 25, tau_m = tau_hat + J^T F^ext) is the force the hand exerts on the environment; the
systems here output the force applied TO the hand (the push), F = -F^ext.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, JacobianWrtVariable
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from systems.common.checks import eval_finite_input, per_joint, positive_number
from systems.common.topology import floating_base_topology

#: Nao's number of FSRs, K_t of eq. (28).
NAO_FSR_COUNT = 8
#: An FSR reading above this counts as "in contact" for K_a of eq. (28), N (the readings
#: carry ~0.1 N of noise, clipped at 0; a standing Nao loads each FSR with ~6 N).
FSR_CONTACT_THRESHOLD = 1.0
#: The paper's virtual spring of eq. (29), N/m.
DEFAULT_STIFFNESS = 50.0
#: Update period of the estimator and of the compliance controller, s (Nao's DCM cycle).
DEFAULT_PERIOD = 0.01


@dataclass(frozen=True)
class ArmChain:
    """One arm as a kinematic chain for eqs. (25)-(29).

    Attributes:
        side: a label ("left" / "right").
        joint_names: the arm joints whose torques and positions are used, shoulder to wrist.
        hand_body: the body holding the hand point H.
        p_HP: (3) the hand point (where the force acts and whose position eq. 29 sets) in
            the hand body's frame, m.
    """

    side: str
    joint_names: tuple
    hand_body: str
    p_HP: tuple = (0.0, 0.0, 0.0)


#: nao_like's arms: the five arm joints (the gripper joint carries no load) and the gripper
#: body origin as the hand point.
NAO_ARM_CHAINS = (
    ArmChain("left", ("LShoulderPitch", "LShoulderRoll", "LElbowYaw", "LElbowRoll", "LWristYaw"), "l_gripper"),
    ArmChain("right", ("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw"), "r_gripper"),
)


class _ResolvedChain:
    """An ArmChain's plant handles: joint index k in v[6:], position/velocity indices, frame."""

    def __init__(self, plant: MultibodyPlant, chain: ArmChain, k_of_name: dict, who: str):
        if not isinstance(chain, ArmChain):
            raise ValueError(f"{who}: chains must be ArmChain, got {type(chain).__name__}")
        missing = [n for n in chain.joint_names if n not in k_of_name]
        if missing or not chain.joint_names:
            raise ValueError(f"{who}: chain {chain.side!r}: unknown or no joints {missing}")
        if not plant.HasBodyNamed(chain.hand_body):
            raise ValueError(f"{who}: chain {chain.side!r}: no body named {chain.hand_body!r}")
        p = np.asarray(chain.p_HP, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"{who}: chain {chain.side!r}: p_HP must be 3 finite numbers")
        self.chain = chain
        self.k = np.array([k_of_name[n] for n in chain.joint_names], dtype=int)
        joints = [plant.GetJointByName(n) for n in chain.joint_names]
        self.q_index = np.array([j.position_start() for j in joints], dtype=int)
        self.v_index = np.array([j.velocity_start() for j in joints], dtype=int)
        self.lower = np.array([j.position_lower_limits()[0] for j in joints])
        self.upper = np.array([j.position_upper_limits()[0] for j in joints])
        self.frame: Frame = plant.GetBodyByName(chain.hand_body).body_frame()
        self.p_HP = p


def _resolve(plant: MultibodyPlant, chains: Sequence[ArmChain], who: str):
    if not isinstance(plant, MultibodyPlant) or not plant.is_finalized():
        raise ValueError(f"{who}: plant must be a finalized MultibodyPlant")
    topology = floating_base_topology(plant)
    k_of_name = {j.name(): k for k, j in enumerate(topology.joints)}
    chains = tuple(chains)
    if not chains:
        raise ValueError(f"{who}: at least one arm chain is needed")
    resolved = [_ResolvedChain(plant, c, k_of_name, who) for c in chains]
    all_k = np.concatenate([r.k for r in resolved])
    if len(set(all_k.tolist())) != all_k.size:
        raise ValueError(f"{who}: the chains share joints")
    return topology, resolved, all_k


def _joint_names(resolved) -> list[str]:
    return [n for r in resolved for n in r.chain.joint_names]


# ---------------------------------------------------------------------------------------
# Eq. (27).
# ---------------------------------------------------------------------------------------


class JointTorqueFromPositionError(LeafSystem):
    """Motor torque from the position error, eq. (27): tau_m^i = K_m^i (q_d^i - q^i).

    Inputs:
        desired_position: (n) q_d, every joint in v[6:] order (the PD's command), rad.
        state: the SENSED plant state [q; v].

    Outputs:
        motor_torque: (m) tau_m of the chains' joints, chain after chain, N m. With the
            station's PD + gravity compensation this is the PD's proportional torque (see
            the module docstring), not the motor's total torque.

    Args:
        plant: the finalized plant.
        motor_constants: K_m, N m/rad: scalar, m values in chain-joint order, or
            {joint name: K_m} (``fit_motor_constants(...).as_dict()``).
        chains: the arms (default ``NAO_ARM_CHAINS``).

    Raises:
        ValueError: bad plant or chains, K_m not positive; NaN/inf on an input.
    """

    def __init__(self, plant: MultibodyPlant, motor_constants, chains: Sequence[ArmChain] = NAO_ARM_CHAINS):
        super().__init__()
        who = type(self).__name__
        self._who = who
        topology, resolved, self._k = _resolve(plant, chains, who)
        self._q_index = np.concatenate([r.q_index for r in resolved])
        self.joint_names = tuple(_joint_names(resolved))
        self._km = per_joint(motor_constants, self.joint_names, "motor_constants", who=who, sign="positive")
        self._desired = self.DeclareVectorInputPort("desired_position", len(topology.joints))
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self.DeclareVectorOutputPort("motor_torque", len(self._k), self._CalcTorque)

    @property
    def motor_constants(self) -> np.ndarray:
        return self._km.copy()

    def _CalcTorque(self, context: Context, output: BasicVector) -> None:
        q_d = eval_finite_input(self._who, self._desired, context)
        x = eval_finite_input(self._who, self._state, context)
        output.SetFromVector(self._km * (q_d[self._k] - x[self._q_index]))


# ---------------------------------------------------------------------------------------
# Eqs. (25)-(26).
# ---------------------------------------------------------------------------------------


class ArmExternalForceEstimator(LeafSystem):
    """External force on each hand from the arm joint torques, eqs. (25)-(26):

        F_c = -(J_c^T)^+ (tau_m,c - tau_hat_c),   tau_hat = M_a v_dot + (C v)_a + (K_d + b) v_a [+ g_a],

    for each chain c, with J_c the translational Jacobian of its hand point in world with
    respect to the chain's joint velocities (3 x m_c; its transpose maps a hand force to the
    chain's joint torques, exactly, on the floating-base robot: the rows of the other
    branches, base and feet do not enter), (.)^+ the pseudo-inverse (least squares over
    the m_c >= 3 joints), M_a / (C v)_a the chain's rows of the floating-base mass matrix
    and bias (the base coupling included), v_dot a backward difference of the sensed
    velocity over one period, K_d the PD's damping (eq. 27 measures only the proportional
    torque), b the model's viscous joint damping (0.01 N m s/rad on nao_like) and g_a the
    gravity rows, only with ``gravity_compensated=False``.

    For a quasi-static push (smooth ramps of ~1 s, hand accelerations below ~0.5 m/s^2)
    the inertia term is small (arm inertia ~5e-3 kg m^2); it is kept because the controller
    of eq. (29) changes q_d, and right after a change of q_d the PD torque goes into
    accelerating the arm, which without M v_dot would read as an external force. The raw
    estimate is low-pass filtered (first order, ``filter_time_constant``).

    Inputs:
        motor_torque: (m) tau_m of eq. (27), chain after chain, N m.
        state: the SENSED plant state [q; v].

    State (discrete groups, updated every ``period``, first at t = 0): ``force`` F (3 per
    chain), ``velocity`` v of the last sample, ``initialised`` (0 before the first update,
    which takes the raw estimate with v_dot = 0; later ones low-pass filter it with v_dot
    from the last sample's v). Not an initialization event: at ``Simulator.Initialize``
    the discrete plant has not taken its first step, so the inputs differ from the first
    update's.

    Outputs:
        hand_forces: (3 per chain) the filtered force applied TO each hand, world axes, N
            (the paper's F^ext with the opposite sign).

    Args:
        plant: the finalized plant.
        chains: the arms (default ``NAO_ARM_CHAINS``).
        damping: K_d of the position controller per chain joint, N m s/rad (scalar, m
            values or {name: value}); 0 if the controller has none.
        gravity_compensated: True if the position controller cancels gravity itself (the
            station's PD does): tau_hat then omits g(q).
        period: update period, s.
        filter_time_constant: first-order low-pass on the estimate, s (0: none).
        rcond: relative cut-off of the pseudo-inverse's singular values.

    Raises:
        ValueError: bad plant/chains/parameters; NaN/inf on an input.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        chains: Sequence[ArmChain] = NAO_ARM_CHAINS,
        *,
        damping=0.0,
        gravity_compensated: bool = True,
        period: float = DEFAULT_PERIOD,
        filter_time_constant: float = 0.1,
        rcond: float = 1e-3,
    ):
        super().__init__()
        who = type(self).__name__
        self._who = who
        _, self._chains, _ = _resolve(plant, chains, who)
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._world = plant.world_frame()
        self._nq, self._nv = plant.num_positions(), plant.num_velocities()
        names = _joint_names(self._chains)
        self._m = len(names)
        self._kd = per_joint(damping, names, "damping", who=who, sign="non-negative")
        # The model's viscous joint damping (SDFormat <damping>), part of tau_hat as well.
        self._joint_damping = np.concatenate(
            [[plant.GetJointByName(n).default_damping_vector()[0] for n in r.chain.joint_names] for r in self._chains]
        )
        self._gravity_compensated = bool(gravity_compensated)
        self._period = positive_number(period, f"{who}: period")
        tau_f = positive_number(filter_time_constant, f"{who}: filter_time_constant", allow_zero=True)
        self._alpha = 1.0 if tau_f == 0.0 else 1.0 - math.exp(-self._period / tau_f)
        self._rcond = positive_number(rcond, f"{who}: rcond")
        self._rows = np.concatenate([r.v_index for r in self._chains])
        self._nf = 3 * len(self._chains)
        self._torque = self.DeclareVectorInputPort("motor_torque", self._m)
        self._state = self.DeclareVectorInputPort("state", self._nq + self._nv)
        self._force_index = self.DeclareDiscreteState(self._nf)
        self._velocity_index = self.DeclareDiscreteState(self._nv)
        self._initialised_index = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        self.DeclareStateOutputPort("hand_forces", self._force_index)

    @property
    def period(self) -> float:
        return self._period

    def hand_forces(self, x: np.ndarray, motor_torque: np.ndarray, v_dot: np.ndarray | None = None) -> np.ndarray:
        """The unfiltered eq. (26) at state ``x`` = [q; v], for ``motor_torque`` (m, N m)
        and the generalized acceleration ``v_dot`` (nv; None: zero). Returns (3 per chain)
        the force on each hand in world, N."""
        x = np.asarray(x, dtype=float)
        tau_m = np.asarray(motor_torque, dtype=float)
        plant, ctx = self._plant, self._plant_context
        plant.SetPositionsAndVelocities(ctx, x)
        v = x[self._nq :]
        tau_hat = plant.CalcBiasTerm(ctx)[self._rows] + (self._kd + self._joint_damping) * v[self._rows]
        if v_dot is not None:
            tau_hat += plant.CalcMassMatrix(ctx)[self._rows] @ np.asarray(v_dot, dtype=float)
        if not self._gravity_compensated:
            tau_hat -= plant.CalcGravityGeneralizedForces(ctx)[self._rows]
        residual = tau_m - tau_hat
        out = np.empty(self._nf)
        start = 0
        for i, chain in enumerate(self._chains):
            J = plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, chain.frame, chain.p_HP, self._world, self._world
            )[:, chain.v_index]
            m = chain.v_index.size
            out[3 * i : 3 * i + 3] = -np.linalg.pinv(J.T, rcond=self._rcond) @ residual[start : start + m]
            start += m
        return out

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        tau_m = eval_finite_input(self._who, self._torque, context)
        x = eval_finite_input(self._who, self._state, context)
        v = x[self._nq :]
        if context.get_discrete_state(self._initialised_index).GetAtIndex(0) == 0.0:  # the first sample
            force = self.hand_forces(x, tau_m)
        else:
            v_last = context.get_discrete_state(self._velocity_index).get_value()
            raw = self.hand_forces(x, tau_m, (v - v_last) / self._period)
            force = context.get_discrete_state(self._force_index).get_value()
            force = force + self._alpha * (raw - force)
        discrete_state.set_value(self._force_index, force)
        discrete_state.set_value(self._velocity_index, v)
        discrete_state.set_value(self._initialised_index, [1.0])


# ---------------------------------------------------------------------------------------
# The observer's virtual force as a force on the hands.
# ---------------------------------------------------------------------------------------


class ObserverHandForce(LeafSystem):
    """The Kalman observer's virtual force (eq. 11) read as a force shared by the hands.

    The observer estimates F^ = [F_x + tau_y / z_c, F_y - tau_x / z_c, F_z] at the CoM, where
    tau is the moment of the external force about the CoM (eq. 11). If the external force F
    acts at the hands (their mean position p_h; tau = (p_h - p_c) x F with r = p_h - p_c),
    then F^_x = (h F_x - r_x F_z) / z_c and F^_y = (h F_y - r_y F_z) / z_c, h = z_c + r_z the
    hands' height above the ground, so

        F_z = F^_z,   F_x = (z_c F^_x + r_x F_z) / h,   F_y = (z_c F^_y + r_y F_z) / h,

    shared equally by the hands (a push on both hands). On nao_like h / z_c = 0.8 at the
    nominal posture: without this, the observer would read a hand push 20 % low.

    Inputs:
        virtual_force: (3) F^ of the observer (support-foot frame = world axes), N.
        state: the SENSED plant state [q; v] (CoM and hand positions by kinematics).

    Outputs:
        hand_forces: (3 per chain) F / (number of chains) for each hand, world axes, N.

    Raises:
        ValueError: bad plant/chains/support frame; NaN/inf on an input; at evaluation, a
            hand at or below the ground plane (h <= 1 cm).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        support_frame: Frame,
        chains: Sequence[ArmChain] = NAO_ARM_CHAINS,
        *,
        model_instances=None,
    ):
        super().__init__()
        who = type(self).__name__
        self._who = who
        _, self._chains, _ = _resolve(plant, chains, who)
        if not isinstance(support_frame, Frame) or support_frame.GetParentPlant() is not plant:
            raise ValueError(f"{who}: support_frame must be a frame of this plant")
        self._support = support_frame
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._instances = None if model_instances is None else list(model_instances)
        self._nq = plant.num_positions()
        self._force = self.DeclareVectorInputPort("virtual_force", 3)
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self.DeclareVectorOutputPort("hand_forces", 3 * len(self._chains), self._CalcForces)

    @staticmethod
    def hand_force_from_virtual(
        virtual_force: np.ndarray, p_com: np.ndarray, p_hand: np.ndarray, ground_height: float
    ) -> np.ndarray:
        """Eq. (11) inverted for a force F at ``p_hand`` (world, m) given the CoM ``p_com``
        (world, m) and the height of the ZMP plane, m. Returns F, N."""
        Fv = np.asarray(virtual_force, dtype=float)
        r = np.asarray(p_hand, dtype=float) - np.asarray(p_com, dtype=float)
        z_c = float(p_com[2] - ground_height)
        h = float(p_hand[2] - ground_height)
        if h <= 0.01 or z_c <= 0.01:
            raise ValueError(f"ObserverHandForce: hand ({h:.3g} m) or CoM ({z_c:.3g} m) not above the ground")
        F_z = Fv[2]
        return np.array([(z_c * Fv[0] + r[0] * F_z) / h, (z_c * Fv[1] + r[1] * F_z) / h, F_z])

    def _CalcForces(self, context: Context, output: BasicVector) -> None:
        Fv = eval_finite_input(self._who, self._force, context)
        x = eval_finite_input(self._who, self._state, context)
        plant, ctx = self._plant, self._plant_context
        plant.SetPositions(ctx, x[: self._nq])
        p_com = (
            plant.CalcCenterOfMassPositionInWorld(ctx)
            if self._instances is None
            else plant.CalcCenterOfMassPositionInWorld(ctx, self._instances)
        )
        p_hand = np.mean([c.frame.CalcPoseInWorld(ctx) @ c.p_HP for c in self._chains], axis=0)
        ground = float(self._support.CalcPoseInWorld(ctx).translation()[2])
        F = self.hand_force_from_virtual(Fv, p_com, p_hand, ground)
        output.SetFromVector(np.tile(F / len(self._chains), len(self._chains)))


# ---------------------------------------------------------------------------------------
# Eq. (28).
# ---------------------------------------------------------------------------------------


class CompliantArmBlender(LeafSystem):
    """Blends the two estimates, eq. (28): F = K1 F_observer + K2 F_joint, K2 = 1 - K1, with
    K1 = K_a / K_t (K_a: FSRs reading above ``fsr_threshold``; K_t = ``total_fsr``, 8 on
    Nao), or a constant K1. With all FSRs loaded the observer alone is used; the joint-level
    estimate takes over as the feet lose contact.

    Inputs:
        observer_force: (size) the observer's estimate (e.g. ``ObserverHandForce``), N.
        joint_force: (size) the joint-level estimate (``ArmExternalForceEstimator``), N.
        fsr_forces: (total_fsr) FSR readings, N.

    Outputs:
        blended_force: (size) F, N.
        k1: (1) K1.

    Args:
        size: length of the force vectors (3 per hand).
        total_fsr: K_t.
        fsr_threshold: N, a reading above it counts as an FSR in contact.
        constant_k1: None for eq. (28)'s dynamic K1, or a constant in [0, 1].
        saturation_guard: None (the paper's eq. 28) or the FSRs' range, N: an extension,
            not in the paper. A reading at or above it means the CoP and normal force the
            observer uses are wrong (the FSR clips), so K1 = 0 while any FSR saturates.

    Raises:
        ValueError: bad parameters; NaN/inf on an input.
    """

    def __init__(
        self,
        size: int = 6,
        *,
        total_fsr: int = NAO_FSR_COUNT,
        fsr_threshold: float = FSR_CONTACT_THRESHOLD,
        constant_k1: float | None = None,
        saturation_guard: float | None = None,
    ):
        super().__init__()
        who = type(self).__name__
        self._who = who
        if not (isinstance(size, (int, np.integer)) and size > 0):
            raise ValueError(f"{who}: size must be a positive integer, got {size!r}")
        if not (isinstance(total_fsr, (int, np.integer)) and total_fsr > 0):
            raise ValueError(f"{who}: total_fsr must be a positive integer, got {total_fsr!r}")
        self._total = int(total_fsr)
        self._threshold = positive_number(fsr_threshold, f"{who}: fsr_threshold", allow_zero=True)
        if constant_k1 is not None:
            k1 = float(constant_k1)
            if not (0.0 <= k1 <= 1.0):
                raise ValueError(f"{who}: constant_k1 must be in [0, 1], got {constant_k1!r}")
            constant_k1 = k1
        self._constant = constant_k1
        self._saturation = (
            None if saturation_guard is None else positive_number(saturation_guard, f"{who}: saturation_guard")
        )
        self._observer = self.DeclareVectorInputPort("observer_force", int(size))
        self._joint = self.DeclareVectorInputPort("joint_force", int(size))
        self._fsr = self.DeclareVectorInputPort("fsr_forces", self._total)
        self.DeclareVectorOutputPort("blended_force", int(size), self._CalcBlend)
        self.DeclareVectorOutputPort("k1", 1, lambda c, o: o.SetFromVector([self.k1(c)]))

    def gain(self, fsr_forces: np.ndarray) -> float:
        """K1 for the readings ``fsr_forces`` (eq. 28)."""
        if self._constant is not None:
            return self._constant
        readings = np.asarray(fsr_forces)
        if self._saturation is not None and np.any(readings >= self._saturation):
            return 0.0
        return int(np.count_nonzero(readings > self._threshold)) / self._total

    def k1(self, context: Context) -> float:
        if self._constant is not None:
            return self._constant
        return self.gain(eval_finite_input(self._who, self._fsr, context))

    def _CalcBlend(self, context: Context, output: BasicVector) -> None:
        k1 = self.k1(context)
        F_o = eval_finite_input(self._who, self._observer, context)
        F_j = eval_finite_input(self._who, self._joint, context)
        output.SetFromVector(k1 * F_o + (1.0 - k1) * F_j)


# ---------------------------------------------------------------------------------------
# Eq. (29).
# ---------------------------------------------------------------------------------------


class HandComplianceController(LeafSystem):
    """Hand compliance, eq. (29): x_h = x_h^0 + F_x / k for each hand, as arm joint targets.

    Every ``period``: the force on each hand is expressed in the base (torso) frame B, its
    component along B's x axis gives the hand target p_BH = p_BH^0 + (F_x / k) e_x (clipped
    to +-``max_displacement``), and a damped least-squares IK of the arm (torso-relative
    kinematics, warm-started from the previous solution, ``ik_iterations`` steps
    dq = J^T (J J^T + lambda^2 I)^-1 (p_target - p(q)), joint limits enforced) gives the
    arm joint positions q_ik. The other joints keep their nominal targets.

    Deflection compensation (``motor_constants`` given): a position-controlled arm with a
    finite stiffness K_m yields under the load by K_m^-1 J^T F, which would add to the
    commanded displacement (on nao_like, arm PD 5 N m/rad, that is F / 115 N/m along x, 43 %
    more than F / 50 N/m). The command q_d = q_ik - K_m^-1 J_B^T F_B (J_B: the hand's
    Jacobian in B at q_ik) makes the arm settle at q_ik when the force estimate is right.

    Inputs:
        hand_forces: (3 per chain) the force on each hand (eq. 28's blend), world axes, N.
        state: the SENSED plant state [q; v] (the base orientation, to express the forces
            in B; the measured hand positions).
        nominal_position: (n) the posture for all joints, v[6:] order, rad; the chains'
            entries are replaced (optional: unconnected, the constructor's nominal).

    State (discrete): [q_ik (m); q_d of the chains (m); hand targets p_BH (3 per chain)].

    Outputs:
        desired_position: (n) the PD's command, v[6:] order, rad.
        hand_target: (3 per chain) the targets p_BH of eq. (29), torso frame, m.
        hand_position: (3 per chain) the hands' positions p_BH from the sensed state, m.

    Args:
        plant: the finalized plant.
        nominal_position: (n) the nominal posture (v[6:] order); its arm entries define the
            rest positions x_h^0.
        chains: the arms (default ``NAO_ARM_CHAINS``).
        stiffness: k of eq. (29), N/m (the paper's 50).
        motor_constants: K_m for the deflection compensation (scalar, per joint or
            {name: value}), or None for none.
        period, ik_iterations, ik_damping (lambda, m), max_displacement (m).

    Raises:
        ValueError: bad parameters; NaN/inf on an input.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        nominal_position: np.ndarray,
        chains: Sequence[ArmChain] = NAO_ARM_CHAINS,
        *,
        stiffness: float = DEFAULT_STIFFNESS,
        motor_constants=None,
        period: float = DEFAULT_PERIOD,
        ik_iterations: int = 3,
        ik_damping: float = 1e-3,
        max_displacement: float = 0.1,
    ):
        super().__init__()
        who = type(self).__name__
        self._who = who
        topology, self._chains, self._k = _resolve(plant, chains, who)
        self._n = len(topology.joints)
        nominal = np.asarray(nominal_position, dtype=float).reshape(-1)
        if nominal.shape != (self._n,) or not np.all(np.isfinite(nominal)):
            raise ValueError(f"{who}: nominal_position must be {self._n} finite joint positions (v[6:] order)")
        self._nominal = nominal.copy()
        self._stiffness = positive_number(stiffness, f"{who}: stiffness")
        self._period = positive_number(period, f"{who}: period")
        if not (isinstance(ik_iterations, (int, np.integer)) and ik_iterations >= 1):
            raise ValueError(f"{who}: ik_iterations must be a positive integer, got {ik_iterations!r}")
        self._iterations = int(ik_iterations)
        self._lambda2 = positive_number(ik_damping, f"{who}: ik_damping", allow_zero=True) ** 2
        self._max_dx = positive_number(max_displacement, f"{who}: max_displacement")
        names = _joint_names(self._chains)
        self._m = len(names)
        self._km = (
            None
            if motor_constants is None
            else per_joint(motor_constants, names, "motor_constants", who=who, sign="positive")
        )
        self._plant = plant
        self._base = topology.base_body.body_frame()
        self._nq = plant.num_positions()
        # Torso-relative kinematics on a private context (the base pose does not matter).
        self._ik_context = plant.CreateDefaultContext()
        q0 = plant.GetPositions(self._ik_context)
        for j, k in zip(topology.joints, range(self._n)):
            q0[j.position_start()] = nominal[k]
        plant.SetPositions(self._ik_context, q0)
        self._sensed_context = plant.CreateDefaultContext()
        self._q_arm0 = nominal[self._k].copy()
        self._p0 = np.concatenate([self._hand_positions(self._q_arm0)[0]])
        self._nf = 3 * len(self._chains)

        self._forces = self.DeclareVectorInputPort("hand_forces", self._nf)
        self._state = self.DeclareVectorInputPort("state", self._nq + plant.num_velocities())
        self._nominal_port = self.DeclareVectorInputPort("nominal_position", self._n)
        initial = np.concatenate([self._q_arm0, self._q_arm0, self._p0])
        self._xd = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        xd = {self.xd_ticket()}
        self.DeclareVectorOutputPort(
            "desired_position",
            self._n,
            self._CalcDesired,
            {self.xd_ticket(), self.input_port_ticket(self._nominal_port.get_index())},
        )
        self.DeclareVectorOutputPort(
            "hand_target",
            self._nf,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._xd).get_value()[2 * self._m :]),
            xd,
        )
        self.DeclareVectorOutputPort("hand_position", self._nf, self._CalcHandPosition)

    @property
    def rest_hand_positions(self) -> np.ndarray:
        """x_h^0: (3 per chain) the hands' positions p_BH at the nominal arm posture, m."""
        return self._p0.copy()

    @property
    def stiffness(self) -> float:
        return self._stiffness

    def _hand_positions(self, q_arm: np.ndarray, *, jacobians: bool = False):
        """Hand points in B (3 per chain) at arm joints q_arm, and optionally their
        Jacobians w.r.t. each chain's joints (list of 3 x m_c)."""
        plant, ctx = self._plant, self._ik_context
        q = plant.GetPositions(ctx)
        start = 0
        for chain in self._chains:
            m = chain.q_index.size
            q[chain.q_index] = q_arm[start : start + m]
            start += m
        plant.SetPositions(ctx, q)
        p = np.concatenate(
            [plant.CalcPointsPositions(ctx, c.frame, c.p_HP, self._base).reshape(-1) for c in self._chains]
        )
        if not jacobians:
            return p, None
        J = [
            plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, c.frame, c.p_HP, self._base, self._base
            )[:, c.v_index]
            for c in self._chains
        ]
        return p, J

    def hand_targets(self, hand_forces_B: np.ndarray) -> np.ndarray:
        """Eq. (29) for forces in B (3 per chain, N): p_BH^0 + clip(F_x / k) e_x, m."""
        F = np.asarray(hand_forces_B, dtype=float).reshape(-1, 3)
        dx = np.clip(F[:, 0] / self._stiffness, -self._max_dx, self._max_dx)
        target = self._p0.reshape(-1, 3).copy()
        target[:, 0] += dx
        return target.reshape(-1)

    def solve_ik(self, target: np.ndarray, q_start: np.ndarray) -> tuple[np.ndarray, list]:
        """Damped least-squares IK of each chain towards ``target`` (3 per chain, in B) from
        ``q_start`` (m). Returns (q, Jacobians at q)."""
        q = np.array(q_start, dtype=float)
        lower = np.concatenate([c.lower for c in self._chains])
        upper = np.concatenate([c.upper for c in self._chains])
        for _ in range(self._iterations):
            p, J = self._hand_positions(q, jacobians=True)
            start = 0
            for i, Jc in enumerate(J):
                m = Jc.shape[1]
                e = target[3 * i : 3 * i + 3] - p[3 * i : 3 * i + 3]
                q[start : start + m] += Jc.T @ np.linalg.solve(Jc @ Jc.T + self._lambda2 * np.eye(3), e)
                start += m
            q = np.clip(q, lower, upper)
        _, J = self._hand_positions(q, jacobians=True)
        return q, J

    def _rotation_WB(self, x: np.ndarray) -> np.ndarray:
        self._plant.SetPositions(self._sensed_context, x[: self._nq])
        return self._base.CalcRotationMatrixInWorld(self._sensed_context).matrix()

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        F_W = eval_finite_input(self._who, self._forces, context).reshape(-1, 3)
        x = eval_finite_input(self._who, self._state, context)
        s = context.get_discrete_state(self._xd).get_value()
        m = self._m
        F_B = F_W @ self._rotation_WB(x)  # rows: R_WB^T F_W
        target = self.hand_targets(F_B)
        q_ik, J = self.solve_ik(target, s[:m])
        q_d = q_ik.copy()
        if self._km is not None:
            start = 0
            for i, Jc in enumerate(J):
                mc = Jc.shape[1]
                q_d[start : start + mc] -= (Jc.T @ F_B[i]) / self._km[start : start + mc]
                start += mc
        discrete_state.set_value(self._xd, np.concatenate([q_ik, q_d, target]))

    def _CalcDesired(self, context: Context, output: BasicVector) -> None:
        if self._nominal_port.HasValue(context):
            q = np.array(eval_finite_input(self._who, self._nominal_port, context), dtype=float)
        else:
            q = self._nominal.copy()
        q[self._k] = context.get_discrete_state(self._xd).get_value()[self._m : 2 * self._m]
        output.SetFromVector(q)

    def _CalcHandPosition(self, context: Context, output: BasicVector) -> None:
        x = eval_finite_input(self._who, self._state, context)
        plant, ctx = self._plant, self._sensed_context
        plant.SetPositions(ctx, x[: self._nq])
        output.SetFromVector(
            np.concatenate(
                [plant.CalcPointsPositions(ctx, c.frame, c.p_HP, self._base).reshape(-1) for c in self._chains]
            )
        )


# ---------------------------------------------------------------------------------------
# K_m identification (eq. 27).
# ---------------------------------------------------------------------------------------


@dataclass
class MotorConstantIdentification:
    """Result of ``fit_motor_constants``.

    Attributes:
        joint_names: the identified joints (chain order).
        motor_constants: K_m per joint, N m/rad (least squares over the loads).
        position_errors: (loads, m) steady-state q_d - q, rad.
        load_torques: (loads, m) the loads' joint torques J^T F, N m.
        residual_rms: RMS of K_m (q_d - q) + J^T F over all samples, N m.
    """

    joint_names: tuple
    motor_constants: np.ndarray
    position_errors: np.ndarray
    load_torques: np.ndarray
    residual_rms: float

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.joint_names, self.motor_constants.tolist()))


def fit_motor_constants(
    plant: MultibodyPlant,
    q_desired: np.ndarray,
    rest_states: np.ndarray,
    loads: np.ndarray,
    *,
    chains: Sequence[ArmChain] = NAO_ARM_CHAINS,
    load_point: Sequence[float] = (0.02, 0.02, 0.02),
) -> MotorConstantIdentification:
    """K_m of eq. (27) from a static test (no simulation here; the test itself is
    ``diagrams.observer.calibration.identify_motor_constant``): under load i (force
    ``loads[i]``, N, world, applied to every hand at ``load_point`` in the hand body's
    frame, m) the robot rests in ``rest_states[i]`` ([q; v], a mean over a window; its base
    quaternion is renormalised here). Per arm joint, the position error e = q_d - q and the
    load's joint torque tau_L = J^T F (at the rest state) satisfy K_m e = -tau_L at rest
    (gravity compensated by the controller's feed-forward), so K_m = -sum(e tau_L) / sum(e^2)
    over the loads.

    Args:
        plant: the finalized plant of the test.
        q_desired: (n) the PD's constant command, v[6:] order, rad.
        rest_states: (loads, nq + nv) the mean state under each load.
        loads: (loads, 3) the forces, N.

    Raises:
        ValueError: bad chains, mismatched shapes, or a joint that no load moves.
    """
    topology, resolved, k_all = _resolve(plant, chains, "fit_motor_constants")
    loads = np.asarray(loads, dtype=float)
    rest_states = np.asarray(rest_states, dtype=float)
    if loads.ndim != 2 or loads.shape[1] != 3 or rest_states.shape != (len(loads), plant.num_multibody_states()):
        raise ValueError(
            f"fit_motor_constants: need one [q; v] per load, got loads {loads.shape} and states {rest_states.shape}"
        )
    quaternion = topology.free_joint.position_start()
    q_index = np.concatenate([r.q_index for r in resolved])
    v_index = np.concatenate([r.v_index for r in resolved])
    ctx = plant.CreateDefaultContext()
    errors, torques = [], []
    point = np.asarray(load_point, dtype=float)
    for F, x_mean in zip(loads, rest_states):
        x_mean = x_mean.copy()
        x_mean[quaternion : quaternion + 4] /= np.linalg.norm(x_mean[quaternion : quaternion + 4])
        plant.SetPositionsAndVelocities(ctx, x_mean)
        tau = np.zeros(plant.num_velocities())
        for c in resolved:
            J = plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, c.frame, point, plant.world_frame(), plant.world_frame()
            )
            tau += J.T @ F
        errors.append(np.asarray(q_desired)[k_all] - x_mean[q_index])
        torques.append(tau[v_index])
    E, T = np.array(errors), np.array(torques)
    denominator = np.sum(E * E, axis=0)
    if np.any(denominator < 1e-12):
        raise ValueError("fit_motor_constants: a joint is not moved by any load; add loads")
    km = -np.sum(E * T, axis=0) / denominator
    residual = float(np.sqrt(np.mean((km * E + T) ** 2)))
    return MotorConstantIdentification(tuple(_joint_names(resolved)), km, E, T, residual)


__all__ = [
    "ArmChain",
    "ArmExternalForceEstimator",
    "CompliantArmBlender",
    "DEFAULT_STIFFNESS",
    "FSR_CONTACT_THRESHOLD",
    "HandComplianceController",
    "JointTorqueFromPositionError",
    "MotorConstantIdentification",
    "NAO_ARM_CHAINS",
    "NAO_FSR_COUNT",
    "ObserverHandForce",
    "fit_motor_constants",
]
