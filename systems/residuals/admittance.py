"""Joint admittance control driven by a residual (Flacco et al. 2016, Sec. IV, eq. 14).

The paper makes HRP-4 move along unknown external forces by feeding the estimated joint
effort of those forces, r (the internal residual of eq. 11, or the classical one of eq. 7
for the comparison of Figs. 5-6), to a diagonal joint admittance that generates the
desired joint positions of the low-level PD controller:

    q̇_d = K_a r,    q_d = q + q̇_d T                                      (14)

with K_a a diagonal gain matrix and T the sampling time. ``JointAdmittanceController``
implements it as a discrete Drake system, with a few safety additions that are all off (or
as permissive as the model) by default except the joint-limit clip:

1. dead-band on the residual (soft threshold): r' = sign(r) max(|r| - d, 0), so residual
   noise and model errors below d (N m) do not make the robot drift;
2. q̇_d = K_a r' clipped to ±max_rate (rad/s);
3. the integration step, see below;
4. q_d clipped into the joint position limits (the model's, shrunk by ``limit_margin``,
   or given ones), so that the PD never drives a joint into its end stop and, in
   "desired" mode, the integrator cannot wind up beyond a limit. A joint whose previous
   q_d is outside these limits — e.g. one that starts resting on its model limit, within
   the margin, as HRP-4's hand joints in the nominal posture — is not pulled in (that
   would be a jump of up to the margin at the first update): its q_d just may not move
   further out, i.e. the clip interval is [min(lower, q_d,prev), max(upper, q_d,prev)].
   Once q_d is inside the limits it stays inside.

Closed chain (``support_frames``, off by default): with both feet on the ground the legs
and the floor form a closed chain, so joint rates that move one sole relative to the other
(C q̇ ≠ 0 below) cannot happen; the PD then fights the ground and builds internal forces
(a squeeze or a twist between the feet). Those load the joints, and any torque-sensor
scale error the estimators did not calibrate turns them into residual, which the
admittance follows: with the realistic torque errors this loop ran a pushed robot's hip
yaw and roll into the ground. With two support frames (the soles), q̇_d is projected, in
the admittance's own metric K_a⁻¹, onto the rates that keep both soles still:

    C = J_L,j − J_L,b J_R,b⁻¹ J_R,j,   q̇_d = K_a (r' − Cᵀ λ),   λ = (C K_a Cᵀ)⁻¹ C K_a r',

J_s,b and J_s,j the base and joint columns of sole s's spatial-velocity Jacobian (the base
velocity that keeps the right sole still leaves the left sole moving at C q̇). Cᵀ λ is the
part of the residual that is a squeeze between the feet, which the robot cannot comply
with. Only the leg joints appear in C; the rate limit is applied after the projection.

Balance (``hold_center_of_mass``, with ``support_frames``; an addition to the paper): the
projection also keeps the centre of mass still over the feet, in the support plane:

    C_G = S (J_G,j − J_G,b J_R,b⁻¹ J_R,j),

J_G the centre of mass's translational-velocity Jacobian (in the estimators' model:
``spatial_inertias``) expressed in the right support frame, S its first two rows (the
support frames' z axes are the floor normal). C_G is stacked under C in the projection
above. Without it eq. (14) bends the knees under a downward push with the ankles nearly
still, which tilts the legs and moves the CoM back: measured in the ideal world 77 mm back
in 7 s, to 85 mm from the sole centre with the heel edge at 110 mm; the same run with a 5 %
model error went on to 117 mm and fell backwards. With it the robot complies by moving
down, with ankle and hip flexion keeping the CoM where it was.

Integration (``integrate_from``):

* ``"measured"`` (default, the paper's eq. 14): q_d(k+1) = q(k) + q̇_d T starts from the
  MEASURED joint positions q. The desired position is only a step T q̇_d ahead of where
  the robot is, so the PD spring term becomes K_p (q_d - q) = K_p K_a T r': the position
  stiffness of the PD about the current posture disappears and what moves the robot is
  its own compliance under the PD (gravity compensation + damping) plus this extra torque
  along the residual, i.e. along the external effort. When the residual vanishes, q_d = q
  and the PD holds (with damping only) wherever the robot is. With this law the useful
  K_a is of order 1 / (K_p T) (K_p in N m/rad): e.g. K_p = 300 N m/rad, T = 1 ms gives
  K_p K_a T = 0.3 for K_a = 1 rad/(N m s).
* ``"desired"``: q_d(k+1) = q_d(k) + q̇_d T, a pure integrator of the residual
  (classical admittance). The PD's steady-state error (e.g. under an external load)
  then does not pull the reference back to the measured position; the posture keeps
  changing as long as the residual is above the dead-band, and stops at the joint limits.

Joint order: everything is in the plant's joint-velocity order v[6:] (joint k is the 1-DoF
joint whose ``velocity_start()`` is 6 + k), as in ``systems.simulation.pd_gravity`` and
``systems.residuals.momentum_residuals``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, Frame, JacobianWrtVariable, SpatialInertia
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem
from pydrake.systems.primitives import MatrixGain
from scipy.linalg.lapack import dgesv as _lu_solve
from scipy.linalg.lapack import dpotrf as _cholesky
from scipy.linalg.lapack import dpotrs as _cholesky_solve

from systems.common.checks import eval_finite_input, per_joint
from systems.simulation.pd_gravity import joints_in_velocity_order

#: Default update period T of the admittance [s] (the residuals' period).
DEFAULT_PERIOD = 1e-3
#: Default distance kept from the model's joint position limits [rad] (m for prismatic).
DEFAULT_LIMIT_MARGIN = 0.02

_WHO = "JointAdmittanceController"
_INTEGRATE_FROM = ("measured", "desired")
_KINEMATICS = ("pinocchio", "drake")


def _pinocchio_kinematics(plant: MultibodyPlant, com_instance, spatial_inertias: Mapping):
    """The Pinocchio kinematics of ``plant`` (``PinocchioFloatingBaseDynamics.support_jacobians``,
    cheaper than Drake's two frame Jacobians and centre-of-mass Jacobian) with the
    given spatial inertias, or None where it would not give Drake's numbers: a plant Pinocchio's
    model cannot represent (other joint types), or one whose floating tree holds bodies of
    another model instance than ``com_instance`` (Drake's centre of mass is that instance's)."""
    try:
        from systems.dynamics.pinocchio_dynamics import PinocchioFloatingBaseDynamics

        kinematics = PinocchioFloatingBaseDynamics(plant)
    except ValueError:
        return None
    if any(plant.get_body(BodyIndex(i)).model_instance() != com_instance for i in kinematics.pinocchio.bodies):
        return None
    if spatial_inertias:
        kinematics.set_spatial_inertias(spatial_inertias)
    return kinematics


def _least_squares_symmetric(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x minimising |A x - b| for a symmetric positive semi-definite A: a Cholesky solve when
    its pivots are within a factor 1e6 of each other (A safely invertible: the same x as
    ``lstsq`` to rounding, in a fraction of its time), else ``lstsq`` with rcond 1e-12."""
    L, info = _cholesky(A, lower=True, clean=False)
    if info == 0:
        pivots = np.abs(np.diagonal(L))
        if pivots.min() > 1e-6 * pivots.max():
            return _cholesky_solve(L, b, lower=True)[0]
    return np.linalg.lstsq(A, b, rcond=1e-12)[0]


def soft_threshold(r: np.ndarray, dead_band) -> np.ndarray:
    """Dead-band with continuity: entries with |r| <= dead_band become 0, the others shrink
    toward 0 by dead_band, i.e. sign(r) max(|r| - dead_band, 0)."""
    r = np.asarray(r, dtype=float)
    out = np.abs(r)
    out -= dead_band
    np.maximum(out, 0.0, out=out)
    return np.copysign(out, r, out=out)  # a new array; this runs at every step


def admittance_gains_by_group(
    plant: MultibodyPlant, handles, gains: Mapping[str, float], default: float = 0.0
) -> np.ndarray:
    """Per-joint admittance gains K_a (v[6:] order) from gains per joint group.

    Args:
        plant: the finalized plant holding the humanoid of ``handles``.
        handles: ``models.HumanoidHandles`` of the humanoid.
        gains: {group or joint name: gain}, group names of ``handles.joint_groups`` (legs,
            torso, head, arms, hands, left_leg, right_arm, ...) or single joint names of
            the humanoid (e.g. ``R_ANKLE_P``), gains in rad/(N m s) (m/(N s) for prismatic
            joints), non-negative. Entries are applied in the mapping's order, so a later
            one overrides an earlier one for the joints they share (e.g.
            ``{"arms": 0.5, "left_arm": 0.0}``).
        default: gain of the joints in no listed group (and of joints of the plant that
            belong to no group or to another model instance), rad/(N m s).

    Returns:
        (n,) gains in the plant's joint-velocity order v[6:].

    Raises:
        ValueError: unknown group name, negative or non-finite gain, a group joint that
            is not a 1-DoF joint of the plant.
    """
    who = "admittance_gains_by_group"
    joints = joints_in_velocity_order(plant)
    k_of_joint = {int(j.index()): k for k, j in enumerate(joints)}
    default = float(default)
    if not np.isfinite(default) or default < 0:
        raise ValueError(f"{who}: default must be a finite non-negative gain, got {default}")
    out = np.full(len(joints), default)
    groups = dict(handles.joint_groups)
    for group in gains:
        if group not in groups and plant.HasJointNamed(group, handles.model_instance):
            groups[group] = (group,)  # a single joint
    for group, gain in gains.items():
        if group not in groups:
            raise ValueError(
                f"{who}: unknown joint group or joint {group!r};"
                f" valid groups: {', '.join(sorted(handles.joint_groups))}"
            )
        try:
            gain = float(gain)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{who}: gain of group {group!r} must be a number, got {gain!r}") from err
        if not np.isfinite(gain) or gain < 0:
            raise ValueError(f"{who}: gain of group {group!r} must be finite and non-negative, got {gain}")
        for name in groups[group]:
            if not plant.HasJointNamed(name, handles.model_instance):
                raise ValueError(f"{who}: group {group!r} joint {name!r} is not in the plant")
            joint = plant.GetJointByName(name, handles.model_instance)
            k = k_of_joint.get(int(joint.index()))
            if k is None:
                raise ValueError(f"{who}: group {group!r} joint {name!r} is not a 1-DoF joint of the plant")
            out[k] = gain
    return out


def joint_position_selector(plant: MultibodyPlant) -> MatrixGain:
    """A MatrixGain mapping the plant's state [q; v] to the n joint positions in v[6:]
    order (the ``measured_position`` input of ``JointAdmittanceController``), for when no
    encoder model (``systems.simulation.sensors.JointEncoders``) is in the loop."""
    joints = joints_in_velocity_order(plant)
    nx = plant.num_positions() + plant.num_velocities()
    D = np.zeros((len(joints), nx))
    for k, j in enumerate(joints):
        D[k, j.position_start()] = 1.0
    return MatrixGain(D)


class JointAdmittanceController(LeafSystem):
    """Residual-driven joint admittance, Flacco et al. 2016 eq. (14); see the module doc.

    Inputs:
        residual: the estimated joint effort of the external forces, N m: n entries
            (``InternalResidual``), or nv = 6 + n (``ClassicalResidual``) when
            ``residual_includes_base`` — then the first 6 (the virtual joints of the
            base) are dropped. v[6:] order.
        measured_position: the n measured joint positions, v[6:] order, rad.

    Outputs:
        desired_position: q_d, n entries, v[6:] order, rad — for
            ``PdGravityController``'s ``desired_position`` input. It reads the discrete
            state only (no direct feedthrough), so closing the loop through the PD, the
            plant and the residual makes no algebraic loop.

    Discrete state: q_d (n). The initialization event (``Simulator.Initialize``, or
    ``ExecuteInitializationEvents`` on a context stepped by hand) sets q_d to
    ``initial_position`` if given, else to the measured position, so nothing jumps at
    start; a context never initialised starts from ``initial_position`` (zeros if None).
    Each periodic update (period T, first at t = 0) then computes

        r' = soft_threshold(r, dead_band),  q̇_d = clip(K_a r', ±max_rate),
        q_d <- clip(base + q̇_d T, min(lower, q_d), max(upper, q_d)),

    with base = the measured q ("measured", eq. 14) or the previous q_d ("desired").
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        gains,
        period: float = DEFAULT_PERIOD,
        *,
        residual_includes_base: bool = False,
        dead_band=0.0,
        max_rate=None,
        position_limits="model",
        limit_margin: float = DEFAULT_LIMIT_MARGIN,
        initial_position=None,
        integrate_from: str = "measured",
        support_frames: tuple[Frame, Frame] | None = None,
        hold_center_of_mass: bool = False,
        spatial_inertias: Mapping[int, SpatialInertia] | None = None,
        kinematics: str = "pinocchio",
    ):
        """Constructs the controller.

        Args:
            plant: a finalized floating-base MultibodyPlant (one free body + 1-DoF
                joints + welds); only its joint order and position limits are used.
            gains: K_a (diagonal), rad/(N m s): scalar or n entries in v[6:] order,
                non-negative (0 freezes a joint at its measured/previous position). See
                ``admittance_gains_by_group``.
            period: T, s, > 0 (paper: the sampling time); default 1 ms.
            residual_includes_base: the residual input has nv entries (classical
                residual) whose first 6 are dropped.
            dead_band: soft threshold on the residual, N m, scalar or n entries, >= 0.
            max_rate: bound on |q̇_d|, rad/s, scalar or n entries, >= 0 (inf allowed);
                None: no bound.
            position_limits: "model" (the plant's joint position limits shrunk by
                ``limit_margin``; a joint whose range is narrower than 2 margins is held
                at its mid-range; infinite limits stay infinite), None (no limits), or a
                pair (lower, upper) of scalars or n-arrays, rad (inf allowed), used as
                given.
            limit_margin: rad, >= 0, only for position_limits="model".
            initial_position: q_d before the first update, n entries, rad; default: the
                measured position at initialisation.
            integrate_from: "measured" (eq. 14, default) or "desired" (integrator).
            support_frames: None (default), or two frames of ``plant`` (the soles) that
                stay still on the ground: q̇_d is projected onto the rates that keep them
                still (see the module doc).
            hold_center_of_mass: with ``support_frames``, the projection also keeps the
                centre of mass of the support frames' model instance still in the support
                plane (see the module doc).
            spatial_inertias: ``{body index: SpatialInertia}`` (M_BBo_B) of the model the
                centre of mass is computed with (the estimators' model); None: the plant's.
            kinematics: what computes the support frames' and the centre of mass's Jacobians:
                "pinocchio" (default; Pinocchio's kernels on a model built from the plant, the
                same numbers as Drake's to rounding at a fraction of the cost, where that model
                holds the same bodies as the support frames' model instance; else Drake's) or
                "drake".

        Raises:
            ValueError: unsupported/unfinalized plant, wrong sizes, negative gains,
                dead-band, rates or margin, lower > upper, non-finite values, bad
                period or integrate_from — the message names the parameter.
        """
        super().__init__()
        if not isinstance(plant, MultibodyPlant):
            raise ValueError(f"{_WHO}: plant must be a MultibodyPlant, got {type(plant).__name__}")
        if not plant.is_finalized():
            raise ValueError(f"{_WHO}: the plant must be finalized")
        try:
            joints = joints_in_velocity_order(plant)
        except ValueError as err:
            raise ValueError(f"{_WHO}: {err}") from err
        n = len(joints)
        self._n = n
        self._joint_names = tuple(j.name() for j in joints)

        try:
            period = float(period)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{_WHO}: period must be a positive number of seconds, got {period!r}") from err
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"{_WHO}: period must be a positive finite number of seconds, got {period}")
        self._period = period

        if integrate_from not in _INTEGRATE_FROM:
            raise ValueError(f"{_WHO}: integrate_from must be one of {_INTEGRATE_FROM}, got {integrate_from!r}")
        self._integrate_from = integrate_from

        self._gains = per_joint(gains, n, "gains", who=_WHO, sign="non-negative")
        self._dead_band = per_joint(dead_band, n, "dead_band", who=_WHO, sign="non-negative")
        if max_rate is None:
            self._max_rate = np.full(n, np.inf)
        else:
            self._max_rate = per_joint(max_rate, n, "max_rate", who=_WHO, allow_inf=True, sign="non-negative")
        self._neg_max_rate = -self._max_rate

        try:
            limit_margin = float(limit_margin)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{_WHO}: limit_margin must be a number, got {limit_margin!r}") from err
        if not (np.isfinite(limit_margin) and limit_margin >= 0):
            raise ValueError(f"{_WHO}: limit_margin must be finite and non-negative, got {limit_margin}")
        self._limit_margin = limit_margin
        self._lower, self._upper = self._resolve_limits(plant, joints, position_limits, limit_margin)

        if initial_position is None:
            self._initial_position = None
        else:
            self._initial_position = per_joint(initial_position, n, "initial_position", who=_WHO)

        if kinematics not in _KINEMATICS:
            raise ValueError(f"{_WHO}: kinematics must be one of {_KINEMATICS}, got {kinematics!r}")
        self._plant = plant
        self._support_frames = None
        if support_frames is not None:
            frames = tuple(support_frames)
            if len(frames) != 2 or not all(isinstance(f, Frame) for f in frames):
                raise ValueError(f"{_WHO}: support_frames must be two frames (the soles), got {support_frames!r}")
            for f in frames:
                if (
                    not plant.HasFrameNamed(f.name(), f.model_instance())
                    or plant.GetFrameByName(f.name(), f.model_instance()).index() != f.index()
                ):
                    raise ValueError(f"{_WHO}: support frame {f.name()!r} is not a frame of the plant")
            self._support_frames = frames
            self._plant_context = plant.CreateDefaultContext()
            for index, M in (spatial_inertias or {}).items():
                if not (0 < int(index) < plant.num_bodies()) or not isinstance(M, SpatialInertia):
                    raise ValueError(
                        f"{_WHO}: spatial_inertias must map body indices of the plant to SpatialInertia, "
                        f"got {index!r}: {type(M).__name__}"
                    )
                plant.get_body(BodyIndex(int(index))).SetSpatialInertiaInBodyFrame(self._plant_context, M)
            self._com_instances = [frames[0].model_instance()]
            self._q_index = np.array([j.position_start() for j in joints], dtype=int)
            # C does not depend on the base pose: the default one (a valid quaternion) will do.
            self._q_template = plant.GetPositions(self._plant_context).copy()
            self._kinematics = None
            if kinematics == "pinocchio":
                self._kinematics = _pinocchio_kinematics(plant, self._com_instances[0], spatial_inertias or {})
            if self._kinematics is not None:
                self._support_frame_ids = self._kinematics.frame_ids(frames)

        self._hold_center_of_mass = bool(hold_center_of_mass)
        if self._hold_center_of_mass and self._support_frames is None:
            raise ValueError(f"{_WHO}: hold_center_of_mass needs support_frames (the soles)")
        if spatial_inertias is not None and self._support_frames is None:
            raise ValueError(f"{_WHO}: spatial_inertias are only used with support_frames")

        self._residual_includes_base = bool(residual_includes_base)
        residual_size = n + 6 if self._residual_includes_base else n
        self._residual_port = self.DeclareVectorInputPort("residual", residual_size)
        self._measured_port = self.DeclareVectorInputPort("measured_position", n)
        default_q_d = self._initial_position if self._initial_position is not None else np.zeros(n)
        self._q_d_index = self.DeclareDiscreteState(BasicVector(default_q_d))
        self.DeclareInitializationDiscreteUpdateEvent(self._Initialize)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Update)
        self.DeclareStateOutputPort("desired_position", self._q_d_index)

    # -- configuration --------------------------------------------------------------

    @staticmethod
    def _resolve_limits(plant, joints, position_limits, margin):
        n = len(joints)
        if position_limits is None:
            return np.full(n, -np.inf), np.full(n, np.inf)
        if isinstance(position_limits, str):
            if position_limits != "model":
                raise ValueError(
                    f"{_WHO}: position_limits must be 'model', None or (lower, upper), got {position_limits!r}"
                )
            q_index = np.array([j.position_start() for j in joints], dtype=int)
            lower = plant.GetPositionLowerLimits()[q_index] + margin
            upper = plant.GetPositionUpperLimits()[q_index] - margin
            narrow = lower > upper
            mid = 0.5 * (plant.GetPositionLowerLimits()[q_index] + plant.GetPositionUpperLimits()[q_index])
            lower[narrow] = mid[narrow]
            upper[narrow] = mid[narrow]
            return lower, upper
        try:
            lower, upper = position_limits
        except (TypeError, ValueError) as err:
            raise ValueError(f"{_WHO}: position_limits must be 'model', None or a pair (lower, upper)") from err
        lower = per_joint(lower, n, "position_limits lower", who=_WHO, allow_inf=True)
        upper = per_joint(upper, n, "position_limits upper", who=_WHO, allow_inf=True)
        bad = np.flatnonzero(lower > upper)
        if bad.size:
            raise ValueError(
                f"{_WHO}: position_limits lower > upper at joint indices {bad.tolist()} "
                f"({', '.join(joints[k].name() for k in bad)})"
            )
        return lower, upper

    @property
    def joint_count(self) -> int:
        """n = nv - 6, the size of measured_position and desired_position."""
        return self._n

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names in v[6:] order."""
        return self._joint_names

    @property
    def period(self) -> float:
        """T, s."""
        return self._period

    @property
    def gains(self) -> np.ndarray:
        """K_a diagonal, rad/(N m s), v[6:] order (a copy)."""
        return self._gains.copy()

    @property
    def dead_band(self) -> np.ndarray:
        return self._dead_band.copy()

    @property
    def max_rate(self) -> np.ndarray:
        """|q̇_d| bound, rad/s (inf: none)."""
        return self._max_rate.copy()

    @property
    def position_lower_limits(self) -> np.ndarray:
        """The lower clip of q_d, rad (margin already applied for "model")."""
        return self._lower.copy()

    @property
    def position_upper_limits(self) -> np.ndarray:
        return self._upper.copy()

    @property
    def integrate_from(self) -> str:
        return self._integrate_from

    @property
    def support_frames(self) -> tuple[Frame, Frame] | None:
        """The two frames kept still by the closed-chain projection, or None."""
        return self._support_frames

    @property
    def holds_center_of_mass(self) -> bool:
        return self._hold_center_of_mass

    @property
    def kinematics(self) -> str | None:
        """What computes the closed-chain matrix's Jacobians ("pinocchio" or "drake"), None
        without ``support_frames``."""
        if self._support_frames is None:
            return None
        return "drake" if self._kinematics is None else "pinocchio"

    def ClosedChainMatrix(self, joint_positions: np.ndarray) -> np.ndarray:
        """C (6 x n): the left support frame's spatial velocity relative to the right one's
        for joint rates q̇ when the base moves so that the right one is still (v[6:] order);
        with ``hold_center_of_mass`` C_G (2 x n, the CoM's velocity in the right support
        frame's x-y plane) is stacked under it (8 x n). Needs ``support_frames``."""
        if self._support_frames is None:
            raise ValueError(f"{_WHO}: ClosedChainMatrix needs support_frames")
        q = self._q_template.copy()
        q[self._q_index] = joint_positions
        if self._kinematics is not None:
            J, J_G_W, (_, R_WR) = self._kinematics.support_jacobians(q, self._support_frame_ids)
            J_left, J_right = J[:6], J[6:]
        else:
            J_left, J_right, J_G_W, R_WR = self._drake_support_jacobians(q)
        if self._hold_center_of_mass:
            # C does not depend on the base pose, but the CoM's support-plane axes do: express
            # it in the right support frame (still, so measured in world = relative to that sole).
            J_left = np.vstack([J_left, R_WR[:, :2].T @ J_G_W])
        # The base velocity that keeps the right support frame still, per unit joint rate, is
        # -base_rate.
        _, _, base_rate, info = _lu_solve(J_right[:, :6], J_right[:, 6:])
        if info != 0:
            raise np.linalg.LinAlgError(f"{_WHO}: the right support frame's base Jacobian is singular")
        return J_left[:, 6:] - J_left[:, :6] @ base_rate

    def _drake_support_jacobians(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Drake's J_left, J_right (spatial velocity of each support frame's origin, world
        axes), J_G (the CoM of the support frames' model instance, world axes) and R_WR (the
        right support frame) at the positions q; the columns are v's."""
        plant, context = self._plant, self._plant_context
        plant.SetPositions(context, q)
        world = plant.world_frame()
        J_left, J_right = (
            plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, f, np.zeros(3), world, world)
            for f in self._support_frames
        )
        J_G = plant.CalcJacobianCenterOfMassTranslationalVelocity(
            context, self._com_instances, JacobianWrtVariable.kV, world, world
        )
        R_WR = self._support_frames[1].CalcRotationMatrixInWorld(context).matrix()
        return J_left, J_right, J_G, R_WR

    # -- the law ----------------------------------------------------------------------

    def CalcDesiredRate(self, residual: np.ndarray, joint_positions: np.ndarray | None = None) -> np.ndarray:
        """q̇_d = clip(K_a soft_threshold(r), ±max_rate) for an n-entry (joint) residual;
        with ``support_frames``, K_a r' is first projected onto the rates that keep them
        still at ``joint_positions`` (required then; see the module doc)."""
        rate = soft_threshold(residual, self._dead_band)
        rate *= self._gains
        if self._support_frames is not None:
            if joint_positions is None:
                raise ValueError(f"{_WHO}: CalcDesiredRate needs the joint positions with support_frames")
            if rate.any():  # (the projection of a zero rate is zero)
                C = self.ClosedChainMatrix(joint_positions)
                CK = C * self._gains  # C K_a
                rate -= CK.T @ _least_squares_symmetric(CK @ C.T, C @ rate)
        np.minimum(rate, self._max_rate, out=rate)
        np.maximum(rate, self._neg_max_rate, out=rate)
        return rate

    def CalcNextDesiredPosition(
        self, residual: np.ndarray, measured_position: np.ndarray, previous_desired: np.ndarray
    ) -> np.ndarray:
        """One update: q_d = base + q̇_d T clipped into the limits (a previous q_d
        outside them is not pulled in, see the module doc),
        base = measured q or previous q_d.

        ``residual`` has the size of the residual input (nv when it includes the base)."""
        r = np.asarray(residual, dtype=float)
        if self._residual_includes_base:
            r = r[6:]
        base = measured_position if self._integrate_from == "measured" else previous_desired
        q_d = self.CalcDesiredRate(r, measured_position)
        q_d *= self._period
        q_d += np.asarray(base, dtype=float)
        # A previous q_d outside [lower, upper] (e.g. the start posture of a joint resting on
        # its model limit, inside the margin) is not pulled in: q_d may not go further out.
        previous = np.asarray(previous_desired, dtype=float)
        np.maximum(q_d, np.minimum(self._lower, previous), out=q_d)
        np.minimum(q_d, np.maximum(self._upper, previous), out=q_d)
        return q_d

    def _eval_input(self, port, context: Context) -> np.ndarray:
        return eval_finite_input(_WHO, port, context)

    def _start_position(self, context: Context) -> np.ndarray:
        if self._initial_position is not None:
            return self._initial_position
        return self._eval_input(self._measured_port, context)

    def _Initialize(self, context: Context, discrete_state: DiscreteValues) -> None:
        discrete_state.set_value(self._q_d_index, self._start_position(context))

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        previous = context.get_discrete_state(self._q_d_index).get_value()
        residual = self._eval_input(self._residual_port, context)
        measured = self._eval_input(self._measured_port, context)
        discrete_state.set_value(self._q_d_index, self.CalcNextDesiredPosition(residual, measured, previous))


__all__ = [
    "DEFAULT_PERIOD",
    "DEFAULT_LIMIT_MARGIN",
    "JointAdmittanceController",
    "admittance_gains_by_group",
    "joint_position_selector",
    "soft_threshold",
]
