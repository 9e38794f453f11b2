"""Momentum residuals of Flacco, Paolillo, Kheddar (2016) as Drake systems.

* ``ClassicalResidual``: eq. (7) applied to the virtual-joint model (8), size nv.
* ``InternalResidual``: eq. (11) with the known-force torques of eq. (10), size n = nv - 6;
  it estimates the true joint effort of the unknown external forces, tau_c,real (eq. 12).
* ``ExternalResidual``: eq. (16); it estimates the total unknown external wrench on the
  floating base, eq. (17), reported in the base frame and in the world.
* ``ResidualBank``: the three in one system (one update, one read of each input), with
  the same outputs bit for bit.

Residuals that share one ``ResidualModel`` share its per-state work: the dynamics, the
known wrenches' generalized forces and the momenta and model rates.

All three are discrete-time momentum observers (what runs on a real robot). At each update
k (period T) they read the momentum p_k of the sensed state, the model's momentum rate a_k
(M_dot nu - bias: a smooth function of the state), and the measured generalized forces u_k:
the motor torques minus friction and the known wrenches, as a sensor reports them at t_k,
i.e. averaged over the last period (t_{k-1}, t_k] (a motor-current or F/T sample; on a
discrete Drake plant, its net actuation and reaction forces of the last step). Then

    I_k = I_{k-1}^+ + T/2 a_k + T u_k,    r_k = K (p_k - I_k),    I_k^+ = I_k + T/2 a_k + T r_k,

with I_0 = p_0, so r_0 = 0. The trapezoidal rule on a_k makes the integral second-order
accurate for a continuously moving robot. Since the true momentum obeys
p_k = p_{k-1} + T (mean rate + u_k + tau_ext), the residual is the first-order filter
r_k = (1 - K T) r_{k-1} + K T tau_ext of the unknown external effort (time constant about
1/K). K T must be in (0, 1).

The timing matters in a closed loop: a torque read at t_k that the motors will apply over
the NEXT period would differ from the applied one by K_p times the change of the PD target
within the period, and an admittance loop driven by the residual (eq. 14) would feed that
error back into itself.

Model and coordinates (see ``systems.dynamics.floating_base_terms``): the base velocity is the
paper's v0 in the base frame F0, so the generalized momentum of model (8) is
M_F0 [v0; qdot] with M_F0 = [[I0c, F], [F^T, H]], and its rate is
M_F0_dot [v0; qdot] - [p^; C^] + generalized forces. That is eq. (7)'s
tau_m + C^T qdot - g, written with M_dot - C = C^T, which costs no O(n^2) Christoffel
symbols. The classical residual's base entries are therefore [moment about the F0 origin;
force] in F0, and its joint entries J_j^T f are the same as for any other choice of virtual
joints.

Inputs (shared names):

* ``state``: the plant's [q; v] as estimated from sensors (never the simulator's truth).
* ``measured_torque`` (classical and internal only): the motor torques in the plant's
  joint-velocity order v[6:], N m (N for prismatic joints), WITHOUT friction compensation:
  the friction model tau_mu = D qdot (viscous, ``joint_damping``) is applied inside, so that
  tau_m = tau - tau_mu + tau_bar_c as in the paper.
* ``known_wrenches``: 6 numbers per frame of ``known_wrench_frames`` (the F/T sensors), the
  measured wrench that the environment applies to the robot, [moment about the frame origin;
  force], expressed in the world, N m and N.

The external residual does not use the motor torques (the paper's point in Sec. V), so it
has no ``measured_torque`` input.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, JacobianWrtVariable, SpatialInertia
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem
from scipy.linalg import lapack

from systems.common.checks import eval_finite_input
from systems.dynamics.floating_base import FloatingBaseDynamics
from systems.dynamics.floating_base_kernels import floating_state_rates
from systems.dynamics.floating_base_terms import FloatingBaseTerms

#: Default update period of the residuals [s].
DEFAULT_PERIOD = 1e-3

_ONE = np.ones(1)  # the "initialised" flag's value


class StateRates(NamedTuple):
    """What the three residuals need at one sensed state x = [q; v]
    (``ResidualModel.state_rates``), in F0 coordinates (module docstring). SI units.

    Attributes:
        R_WB: F0's rotation in world. v0: [w_B; v_B] in F0.
        classical: (p, a) of the virtual-joint model (8), size nv: p = M_F0 [v0; qdot],
            a = M_F0_dot [v0; qdot] - [p^; C^] (eq. 7 with M_dot - C = C^T).
        internal: (H_fb qdot, H_fb_dot qdot - C_fb), size n: the floating-base joint
            momentum and its model rate of eq. (11) (eq. 9, 13).
        base: (p0, a0), the base rows of ``classical`` ([moment about the F0 origin;
            force] in F0): the external residual's (eq. 16).
        F: (6, n) the base-joint block of M_F0. I0c_factor: (6, 6) the Cholesky factor of
            I0c (upper, LAPACK ``dpotrf``): with F, G^T w = F^T I0c^-1 w (eq. 10).
    """

    R_WB: np.ndarray
    v0: np.ndarray
    classical: tuple[np.ndarray, np.ndarray]
    internal: tuple[np.ndarray, np.ndarray]
    base: tuple[np.ndarray, np.ndarray]
    F: np.ndarray
    I0c_factor: np.ndarray


class ResidualModel:
    """The dynamics the residuals need at one sensed state, computed once per state.

    Several residual systems can share one ``ResidualModel`` (pass it as ``model=``): the
    floating-base decomposition and the Jacobians of the known-wrench frames are then
    computed once per update for all of them.

    Args:
        plant: the robot's finalized plant (any plant ``FloatingBaseDynamics`` accepts).
        implementation: ``"fast"``, ``"pinocchio"`` or ``"reference"`` (see ``FloatingBaseDynamics``).
    """

    def __init__(self, plant: MultibodyPlant, implementation: str = "fast"):
        self.plant = plant
        self.dynamics = FloatingBaseDynamics(plant, implementation)
        self.num_joints = self.dynamics.num_joints
        self.joints = self.dynamics.topology.joints
        self.num_positions = plant.num_positions()
        self.num_velocities = plant.num_velocities()
        self.joint_velocity_start = 6
        context_F0 = self.dynamics.context_F0
        if context_F0 is not None:
            # After compute(q, v) the F0 context holds q's joints at the identity base pose.
            self._context_F0 = context_F0
            self._context_is_current = True
        else:
            self._context_F0 = plant.CreateDefaultContext()
            self._context_is_current = False
        self._q_F0 = plant.GetPositions(self._context_F0).copy()
        self._q_F0[:7] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        free_parent = self.dynamics.topology.free_joint.frame_on_parent()
        X_WP = free_parent.CalcPoseInWorld(plant.CreateDefaultContext())
        self._p_WP = X_WP.translation().copy()
        self._R_WP = X_WP.rotation().matrix().copy()
        # The usual case: the free joint's parent frame is the world (p_WBo = the q[4:7]).
        self._parent_is_world = bool(np.array_equal(self._R_WP, np.eye(3)) and not self._p_WP.any())
        self._qdot_start = self.num_positions + self.joint_velocity_start
        self._key: bytes | None = None
        self._context_synced = self._context_is_current
        self._q_joints = self._q_F0[7:].copy()  # q's joints of the last evaluate (own context)
        self._impl_at_key = False
        # Per-state results (None: not computed at the state ``_key`` yet).
        self._terms: FloatingBaseTerms | None = None
        self._rates: StateRates | None = None
        self._jacobians: dict = {}  # per state: frame index or frames key -> Jacobian
        self._known_cache: dict = {}
        self._frame_ids: dict = {}  # frames key -> the implementation's frame ids

    def forget_state(self) -> None:
        """Drops the per-state results: for a caller that moved the dynamics' own context or
        kinematics outside this model (``FloatingBaseDynamics.mass_matrix_terms_of_samples``,
        as ``systems.residuals.offline`` does), so that no later call at the same state reads
        them (the Jacobians of the known-wrench frames)."""
        self._key = None
        self._terms = self._rates = None
        self._jacobians = {}
        self._known_cache = {}

    def set_spatial_inertias(self, inertias: Mapping[int, SpatialInertia]) -> None:
        """Makes this model differ from the plant: the bodies' spatial inertias M_BBo_B
        (``{body index: SpatialInertia}``) replace the plant's defaults in every dynamics
        computation (mass matrix, bias, gravity); the plant is not changed.

        Raises:
            ValueError: the "reference" implementation.
        """
        self.dynamics.set_spatial_inertias(inertias)
        self._key = None

    def check_frames(self, frames: Sequence[Frame | str]) -> tuple[Frame, ...]:
        """See ``check_wrench_frames``."""
        return check_wrench_frames(self.plant, frames)

    def _at_state(self, x: np.ndarray) -> None:
        """Makes x = [q; v] the current state: the per-state results are reset when it is new."""
        key = x.tobytes()
        if key != self._key:
            self._terms = self._rates = None
            self._jacobians = {}
            self._known_cache = {}
            self._key = key
            self._context_synced = self._context_is_current  # else set by spatial_jacobian_F0
            if not self._context_is_current:
                self._q_joints = x[7 : self.num_positions].copy()

    def evaluate(self, x: np.ndarray) -> FloatingBaseTerms:
        """The floating-base terms of eq. (9) and (13) at the sensed state x = [q; v], as
        matrices (cached per state; the residuals need only ``state_rates``)."""
        self._at_state(x)
        if self._terms is None:
            nq = self.num_positions
            self._terms = self.dynamics.compute(x[:nq], x[nq:])
            self._impl_at_key = not self._context_is_current  # its own kinematics are of x
        return self._terms

    def state_rates(self, x: np.ndarray) -> StateRates:
        """The momenta and model rates of the three residuals at the sensed state x = [q; v]
        (``StateRates``), computed once per state for every residual sharing this model.

        From the dynamics' (M, M_dot, bias) (``FloatingBaseDynamics.mass_matrix_terms``), the
        elimination of eq. (9) and its derivative (eq. 13) applied to vectors rather than
        formed: with G = I0c^-1 F, H_fb qdot = H qdot - F^T G qdot, H_fb_dot qdot = H_dot
        qdot - G^T F_dot qdot - F_dot^T G qdot + G^T I0c_dot G qdot and C_fb = C^ - G^T p^,
        G never formed (two Cholesky solves with I0c, of one and three right-hand sides;
        compiled, ``systems.dynamics.floating_base_kernels``): the same numbers as ``evaluate``'s matrices times
        qdot, to rounding (tests), at a fraction of the cost (``systems.residuals.offline``
        does the same over a log).

        Raises:
            ValueError: I0c is not positive definite (a model without mass).
        """
        self._at_state(x)
        rates = self._rates
        if rates is not None:
            return rates
        nq = self.num_positions
        M, M_dot, bias, R_WB, v0 = self.dynamics.mass_matrix_terms(x[:nq], x[nq:])
        self._impl_at_key = not self._context_is_current  # its own kinematics are of x
        qdot = x[self._qdot_start :]
        p_c, a_c, p_i, a_i, I0c_factor, positive = floating_state_rates(M, M_dot, bias, v0, qdot)
        if not positive:
            raise ValueError("the composite inertia I0c is not positive definite (a model without mass)")
        F = M[:6, 6:]
        classical, internal, base = (p_c, a_c), (p_i, a_i), (p_c[:6], a_c[:6])
        rates = StateRates(R_WB, v0, classical, internal, base, F, I0c_factor)
        self._rates = rates
        return rates

    @staticmethod
    def eliminated_base_wrench(rates: StateRates, w_F0: np.ndarray) -> np.ndarray:
        """G^T w = F^T I0c^-1 w (n) of a base wrench w_F0 (6) at the state of ``rates``:
        the joint torques eq. (10) removes with the base's elimination (tau_bar_c = J^fb^T
        w = J_j^T w - G^T w_base)."""
        return rates.F.T @ lapack.dpotrs(rates.I0c_factor, w_F0)[0]

    def gravity_joint_torques(self, x: np.ndarray) -> np.ndarray:
        """The joint entries (v[6:] order) of Drake's generalized gravity force tau_g
        (``CalcGravityGeneralizedForces``) of this model (its inertias, not the plant's
        defaults) at the state x = [q; v], N m.

        One Drake call (``FloatingBaseDynamics.gravity_generalized_forces``), whatever was
        evaluated before: a PD controller computes the same torque whether or not residual
        systems share this model (the contact study simulates its sensors without them and
        runs the estimators on the log afterwards, ``diagrams.residuals.contact_study``).
        """
        self._impl_at_key = False  # the gravity call may move the implementation's kinematics
        return self.dynamics.gravity_generalized_forces(x[: self.num_positions])[6:]

    def spatial_jacobian_F0(self, frame: Frame) -> np.ndarray:
        """(6, nv) Jacobian of ``frame``'s origin w.r.t. [v0; qdot], expressed in F0, rows
        [angular; linear]: J^T [m; f] (wrench at the frame origin, in F0) is the wrench's
        generalized force (base rows: [moment about the F0 origin; force] in F0). Valid for
        the state of the last ``evaluate``."""
        index = int(frame.index())
        J = self._jacobians.get(index)
        if J is None:
            # An implementation that keeps its own kinematics of the state (the "pinocchio"
            # one) gives the Jacobian itself; else Drake's, on the F0 context.
            own = self.dynamics.own_spatial_jacobian_F0 if self._impl_at_key else None
            if own is not None:
                J = own(frame)
            else:
                if not self._context_synced:  # q's joints at the identity base pose
                    self._q_F0[7:] = self._q_joints
                    self.plant.SetPositions(self._context_F0, self._q_F0)
                    self._context_synced = True
                world = self.plant.world_frame()
                J = self.plant.CalcJacobianSpatialVelocity(
                    self._context_F0, JacobianWrtVariable.kV, frame, np.zeros(3), world, world
                )
                if not self._parent_is_world:
                    # F0 is the free joint's parent frame P at the identity base pose: rows
                    # from world to F0 axes (the columns, Drake's base velocities, are in P).
                    J = np.vstack((self._R_WP.T @ J[:3], self._R_WP.T @ J[3:]))
            self._jacobians[index] = J
        return J

    def _stacked_world_jacobian(self, frames: Sequence[Frame], frames_key) -> np.ndarray | None:
        """The frames' Jacobians stacked in world axes (``FloatingBaseDynamics.
        own_stacked_world_jacobian``) at the current state, from the implementation's own
        kinematics of it (cached per state), or None (Drake's "fast": per frame, in F0)."""
        own = self.dynamics.own_stacked_world_jacobian if self._impl_at_key else None
        if own is None:
            return None
        J = self._jacobians.get(frames_key)
        if J is None:
            frame_ids = self._frame_ids.get(frames_key)
            if frame_ids is None:
                frame_ids = self._frame_ids[frames_key] = self.dynamics.own_frame_ids(frames)
            J = self._jacobians[frames_key] = own(frame_ids)
        return J

    def known_wrench_forces(
        self, terms: StateRates | FloatingBaseTerms, frames: Sequence[Frame], wrenches_W: np.ndarray, frames_key=None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Generalized forces of measured wrenches (F/T sensors) at the last evaluated state.

        Args:
            terms: the result of ``state_rates`` or ``evaluate`` for this state.
            frames: the frames at whose origins the wrenches act.
            wrenches_W: (6 k,) [moment about the frame origin; force] per frame, in world.
            frames_key: a hashable that identifies ``frames`` (their indices by default).

        Returns:
            (w_F0, tau_joints): their sum as a base wrench in F0 about the F0 origin
            ([moment; force], the paper's f_bar_sum of eq. 16), and their joint torques
            J_j^T w (the joint part of the classical model's generalized force). Cached:
            residuals sharing this model with the same frames and wrenches reuse it.
        """
        if frames_key is None:
            frames_key = tuple(int(f.index()) for f in frames)
        key = (frames_key, wrenches_W.tobytes())
        cached = self._known_cache.get(key)
        if cached is not None:
            return cached
        stacked = self._stacked_world_jacobian(frames, frames_key) if frames else None
        if stacked is not None:  # world axes: J^T w with the world wrenches as they are
            generalized = stacked.T @ wrenches_W
        else:
            # Rotate every [m; f] into F0 (the Jacobians are expressed in F0, at the frame origins).
            w_B = (wrenches_W.reshape(-1, 3) @ terms.R_WB).ravel()
            generalized = np.zeros(self.num_velocities)
            for i, frame in enumerate(frames):
                generalized += self.spatial_jacobian_F0(frame).T @ w_B[6 * i : 6 * i + 6]
        result = (generalized[:6], generalized[6:])
        self._known_cache[key] = result
        return result

    def base_wrench_to_world(
        self, terms: StateRates | FloatingBaseTerms, x: np.ndarray, w_F0: np.ndarray
    ) -> np.ndarray:
        """[moment about the F0 origin; force] in F0 -> [moment about the world origin; force]
        in world."""
        mx, my, mz, fx, fy, fz = (w_F0.reshape(2, 3) @ terms.R_WB.T).ravel().tolist()  # rows: R m, R f
        if self._parent_is_world:
            px, py, pz = x[4:7].tolist()  # p_WBo, m
        else:
            px, py, pz = (self._p_WP + self._R_WP @ x[4:7]).tolist()
        # + p_WBo x f, in floats (one array at the end).
        return np.array((mx + (py * fz - pz * fy), my + (pz * fx - px * fz), mz + (px * fy - py * fx), fx, fy, fz))


def check_wrench_frames(
    plant: MultibodyPlant, frames: Sequence[Frame | str], what: str = "known wrench frame"
) -> tuple[Frame, ...]:
    """Resolves frame names and checks that each frame is on a moving body of the plant,
    and named once (``what`` names the frames in the messages).

    Raises:
        ValueError: an unknown frame name, a frame of another plant, a frame fixed to the
            world, or a frame given twice.
    """
    resolved = []
    for frame in frames:
        if isinstance(frame, str):
            if not plant.HasFrameNamed(frame):
                raise ValueError(f"{what} '{frame}' is not a frame of the plant")
            frame = plant.GetFrameByName(frame)
        if not isinstance(frame, Frame):
            raise ValueError(f"{what}s must be Frame objects or names, got {type(frame).__name__}")
        if (
            int(frame.index()) >= plant.num_frames()
            or plant.get_frame(frame.index()).name() != frame.name()
            or (plant.get_frame(frame.index()).body().name() != frame.body().name())
        ):
            raise ValueError(f"{what} '{frame.name()}' does not belong to this plant")
        if frame.body().index() == plant.world_body().index():
            raise ValueError(f"{what} '{frame.name()}' is fixed to the world, not to the robot")
        if any(frame.index() == other.index() for other in resolved):
            raise ValueError(f"{what} '{frame.name()}' is given twice")
        resolved.append(frame)
    return tuple(resolved)


class FixedBaseModel:
    """The dynamics of a fixed-base robot (no floating base) for the classical residual,
    the original De Luca et al. momentum observer that eq. (7) recalls: M(q) qdot,
    M_dot qdot (central difference of M along qdot) and the bias C qdot - tau_g, all from
    Drake. Joint velocities are the whole v; known wrenches map through J^T.
    """

    def __init__(self, plant: MultibodyPlant, derivative_step: float = 1e-5):
        for index in plant.GetJointIndices():
            joint = plant.get_joint(index)
            if joint.num_velocities() > 1 or joint.type_name() == "quaternion_floating":
                raise ValueError(
                    f"joint '{joint.name()}' ({joint.type_name()}) is not a 1-DoF joint: the fixed-base "
                    "classical residual needs revolute or prismatic joints only"
                )
        self.plant = plant
        self.num_positions = plant.num_positions()
        self.num_velocities = plant.num_velocities()
        self.num_joints = plant.num_velocities()
        self.joint_velocity_start = 0
        self.joints = tuple(
            sorted(
                (plant.get_joint(i) for i in plant.GetJointIndices() if plant.get_joint(i).num_velocities() == 1),
                key=lambda j: j.velocity_start(),
            )
        )
        self._step = derivative_step
        self._context = plant.CreateDefaultContext()
        self._key: bytes | None = None
        self._value = None

    def check_frames(self, frames: Sequence[Frame | str]) -> tuple[Frame, ...]:
        return check_wrench_frames(self.plant, frames)

    def evaluate(self, x: np.ndarray):
        """(M, M_dot qdot - (C qdot - tau_g)) at x = [q; qdot] (cached per state)."""
        key = x.tobytes()
        if key != self._key:
            plant, context, nq = self.plant, self._context, self.num_positions
            q, qdot = x[:nq], x[nq:]
            speed = float(np.linalg.norm(qdot))
            M_dot_qdot = np.zeros(self.num_velocities)
            if speed > 0.0:
                h = self._step / speed
                plant.SetPositions(context, q + h * qdot)
                M_dot_qdot = plant.CalcMassMatrix(context) @ qdot
                plant.SetPositions(context, q - h * qdot)
                M_dot_qdot = (M_dot_qdot - plant.CalcMassMatrix(context) @ qdot) / (2.0 * h)
            plant.SetPositions(context, q)
            plant.SetVelocities(context, qdot)
            M = plant.CalcMassMatrix(context)
            bias = plant.CalcBiasTerm(context) - plant.CalcGravityGeneralizedForces(context)
            self._value = (M, M_dot_qdot - bias)
            self._key = key
        return self._value

    def state_rates(self, x: np.ndarray):
        """``evaluate``: the residual systems call this name on either model."""
        return self.evaluate(x)

    def known_wrench_forces(self, terms, frames: Sequence[Frame], wrenches_W: np.ndarray, frames_key=None):
        """(None, J^T w): generalized forces of wrenches [moment about the frame origin; force]
        in world, at the last evaluated state (``frames_key`` is unused)."""
        world = self.plant.world_frame()
        tau = np.zeros(self.num_velocities)
        for i, frame in enumerate(frames):
            J = self.plant.CalcJacobianSpatialVelocity(
                self._context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world
            )
            tau += J.T @ wrenches_W[6 * i : 6 * i + 6]
        return None, tau


class _ResidualParameters:
    """The parameters a residual system (or ``ResidualBank``) exposes: its dynamics model
    (possibly shared), its known-wrench frames and its update period."""

    _model: ResidualModel
    _frames: tuple[Frame, ...]
    _period: float

    @property
    def model(self) -> ResidualModel:
        """The (possibly shared) dynamics model."""
        return self._model

    @property
    def known_wrench_frames(self) -> tuple[Frame, ...]:
        return self._frames

    @property
    def period(self) -> float:
        """The update period T, s."""
        return self._period


class _MomentumResidual(_ResidualParameters, LeafSystem):
    """Common machinery: ports, discrete state, the observer update (see module docstring)."""

    def __init__(
        self,
        plant: MultibodyPlant,
        gain,
        period: float,
        known_wrench_frames: Sequence[Frame | str],
        *,
        size: int,
        uses_torque: bool,
        joint_damping,
        model: ResidualModel | None,
        implementation: str,
    ):
        super().__init__()
        if not plant.is_finalized():
            raise ValueError(f"{type(self).__name__}: the plant must be finalized")
        self._model = model if model is not None else ResidualModel(plant, implementation)
        if self._model.plant is not plant:
            raise ValueError(f"{type(self).__name__}: the shared ResidualModel was built for another plant")
        period = float(period)
        if not np.isfinite(period) or period <= 0.0:
            raise ValueError(f"{type(self).__name__}: period must be a positive number of seconds, got {period}")
        self._period = period
        self._half_period = 0.5 * period  # T/2 of the trapezoidal rule, s
        self._size = size
        self._name = type(self).__name__
        self._gain = _vector_parameter(gain, size, f"{type(self).__name__}: gain")
        if np.any(self._gain <= 0.0) or np.any(self._gain * period >= 1.0):
            raise ValueError(
                f"{type(self).__name__}: each gain K must satisfy 0 < K T < 1 (T = {period} s), "
                f"got K in [{self._gain.min()}, {self._gain.max()}] 1/s"
            )
        self._frames = self._model.check_frames(known_wrench_frames)
        self._frames_key = tuple(int(f.index()) for f in self._frames)
        self._has_frames = bool(self._frames)
        n = self._model.num_joints
        nx = self._model.num_positions + self._model.num_velocities
        self._num_positions = self._model.num_positions
        self._qdot_start = self._model.num_positions + self._model.joint_velocity_start
        if uses_torque:
            if joint_damping is None:
                joint_damping = _plant_joint_damping(self._model)
            self._damping = _vector_parameter(joint_damping, n, f"{type(self).__name__}: joint_damping")
            if np.any(self._damping < 0.0):
                raise ValueError(f"{type(self).__name__}: joint_damping must be non-negative")

        self._state_port = self.DeclareVectorInputPort("state", nx)
        self._torque_port = self.DeclareVectorInputPort("measured_torque", n) if uses_torque else None
        self._wrench_port = self.DeclareVectorInputPort("known_wrenches", 6 * len(self._frames))
        # Discrete state: [initialised flag], momentum integral I, residual r.
        self._flag_index = self.DeclareDiscreteState(1)
        self._integral_index = self.DeclareDiscreteState(size)
        self._residual_index = self.DeclareDiscreteState(size)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Update)

    # -- subclass hooks -------------------------------------------------------------------
    def _momentum_and_rates(self, terms, x, tau_m, known) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(momentum p, model rate a, measured generalized forces u) at one sensed state."""
        raise NotImplementedError  # pragma: no cover - abstract

    # -- helpers --------------------------------------------------------------------------
    def _checked_input(self, port, context: Context) -> np.ndarray:
        return eval_finite_input(type(self).__name__, port, context)

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        name = self._name
        x = eval_finite_input(name, self._state_port, context)
        torque = eval_finite_input(name, self._torque_port, context) if self._torque_port is not None else None
        wrenches = eval_finite_input(name, self._wrench_port, context) if self._has_frames else None
        # Drake passes discrete_state initialised to the context's values: read them there.
        flag = discrete_state.get_value(self._flag_index)[0]
        previous = discrete_state.get_value(self._integral_index) if flag > 0.5 else None
        integral, residual, terms = self.advance(x, torque, wrenches, previous)
        if flag != 1.0:
            discrete_state.set_value(self._flag_index, _ONE)
        discrete_state.set_value(self._integral_index, integral)
        discrete_state.set_value(self._residual_index, residual)
        self._after_update(discrete_state, terms, x, residual)

    def advance(
        self, x: np.ndarray, measured_torque: np.ndarray | None, known_wrenches: np.ndarray | None, integral
    ) -> tuple[np.ndarray, np.ndarray, object]:
        """One update of the observer (module docstring) without a Context: what the
        periodic update computes (``systems.residuals.offline`` replays logs with it).

        Args:
            x: the sensed [q; v]. measured_torque: n motor torques (None for the external
                residual). known_wrenches: 6 per F/T frame, world (None without frames).
            integral: the momentum integral I^+ of the previous update, or None at the
                first update (I_0 = p_0, r_0 = 0).

        Returns:
            (I^+ of this update, the residual r, the model's ``StateRates`` at x). Inputs
            are not checked (the caller checks them once).
        """
        terms = self._model.state_rates(x)
        tau_m = None
        if self._torque_port is not None:
            tau_m = measured_torque - self._damping * x[self._qdot_start :]
        known = None
        if self._has_frames:
            known = self._model.known_wrench_forces(terms, self._frames, known_wrenches, self._frames_key)
        momentum, model_rate, measured_rate = self._momentum_and_rates(terms, x, tau_m, known)

        integral, residual = _observer_step(
            momentum, self._half_period * model_rate, measured_rate, integral, self._gain, self._period
        )
        return integral, residual, terms

    def _after_update(self, discrete_state: DiscreteValues, terms, x, residual) -> None:
        """Hook for subclasses that keep more discrete state."""

    def _residual(self, context: Context) -> np.ndarray:
        return context.get_discrete_state(self._residual_index).get_value()

    def _declare_residual_output(self) -> None:
        """The ``residual`` output port (classical and internal residuals): the discrete
        state group itself, copied by Drake without a Python call."""
        self.DeclareStateOutputPort("residual", self._residual_index)


class ClassicalResidual(_MomentumResidual):
    """Classical momentum residual, paper eq. (7), on the virtual-joint model (8).

    On a plant without a floating base (a fixed-base arm) it is eq. (7) itself, the
    residual of De Luca et al.: r ~ tau_c = J^T f, size nv, no base entries.

    r ~ tau_c of model (8): the generalized force of the unknown external forces with the
    base treated as 6 virtual joints. Its joint entries are J_j^T f, the fixed-base
    Jacobian transposed: a push on a shoulder loads only the joints between the contact and
    the base, never the legs (the paper's negative result, Sec. II-C).

    Inputs: ``state`` (nq + nv), ``measured_torque`` (n), ``known_wrenches`` (6 per frame).
    State: discrete, [flag; momentum integral (nv); residual (nv)], updated every ``period``.
    Output: ``residual`` (nv): [base moment about the F0 origin, base force, both in F0;
    joint efforts in v[6:] order], N m and N.

    Args:
        plant: finalized floating-base plant (see ``FloatingBaseDynamics``).
        gain: K, scalar or nv-vector, 1/s; 0 < K period < 1.
        period: update period T, s (default 1 ms).
        known_wrench_frames: frames (or names) of the F/T sensors, in ``known_wrenches`` order.
        joint_damping: viscous friction model D (scalar or n-vector, N m s/rad), subtracted
            inside (tau_mu = D qdot); default: the plant's joint damping.
        model: a ``ResidualModel`` shared with other residuals of the same plant.
        implementation: ``"fast"``, ``"pinocchio"`` or ``"reference"`` dynamics, when ``model`` is None.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        gain,
        period: float = DEFAULT_PERIOD,
        known_wrench_frames: Sequence[Frame | str] = (),
        *,
        joint_damping=None,
        model: ResidualModel | FixedBaseModel | None = None,
        implementation: str = "fast",
    ):
        if model is None and plant.is_finalized() and not _has_free_joint(plant):
            model = FixedBaseModel(plant)  # the fixed-base arm: eq. (7) as in De Luca et al.
        super().__init__(
            plant,
            gain,
            period,
            known_wrench_frames,
            size=plant.num_velocities(),
            uses_torque=True,
            joint_damping=joint_damping,
            model=model,
            implementation=implementation,
        )
        self._declare_residual_output()

    def _momentum_and_rates(self, terms, x, tau_m, known):
        if isinstance(self._model, FixedBaseModel):
            M, rate = terms
            qdot = x[self._qdot_start :]
            if known is not None:
                tau_m = tau_m + known[1]
            return M @ qdot, rate, tau_m
        momentum, model_rate = terms.classical
        if known is None:
            measured = np.zeros(self._size)
            measured[6:] = tau_m
        else:  # [f_bar_sum; tau_m + J_j^T w]
            measured = np.concatenate((known[0], tau_m + known[1]))
        return momentum, model_rate, measured


class InternalResidual(_MomentumResidual):
    """Internal (floating-base) residual, paper eq. (11), with tau_bar_c of eq. (10).

    r_int ~ tau_c,real = sum_c J^fb_c^T f_c (eq. 12): the true joint effort of the unknown
    external forces, legs included.

    Inputs: ``state`` (nq + nv), ``measured_torque`` (n), ``known_wrenches`` (6 per frame).
    State: discrete, [flag; momentum integral (n); residual (n)], updated every ``period``.
    Output: ``residual`` (n), joint efforts in v[6:] order, N m (N for prismatic joints).

    Args: as ``ClassicalResidual``, with ``gain`` a scalar or an n-vector.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        gain,
        period: float = DEFAULT_PERIOD,
        known_wrench_frames: Sequence[Frame | str] = (),
        *,
        joint_damping=None,
        model: ResidualModel | None = None,
        implementation: str = "fast",
    ):
        super().__init__(
            plant,
            gain,
            period,
            known_wrench_frames,
            size=plant.num_velocities() - 6,
            uses_torque=True,
            joint_damping=joint_damping,
            model=model,
            implementation=implementation,
        )
        self._declare_residual_output()

    def _momentum_and_rates(self, terms, x, tau_m, known):
        momentum, model_rate = terms.internal
        measured = tau_m
        if known is not None:
            w_F0, tau_joints = known
            # tau_bar_c = J^fb^T w (eq. 10)
            measured = tau_m + tau_joints - self._model.eliminated_base_wrench(terms, w_F0)
        return momentum, model_rate, measured


class ExternalResidual(_MomentumResidual):
    """External (floating-base) residual, paper eq. (16).

    r_ext ~ sum_c 0X*_ref f_c (eq. 17): the total unknown external wrench on the robot,
    about the base origin, in the base frame F0. It needs no motor torques.

    Inputs: ``state`` (nq + nv), ``known_wrenches`` (6 per frame).
    State: discrete, [flag; momentum integral (6); residual (6); residual in world (6)],
    updated every ``period``.

    Outputs:
        ``external_wrench_base``: [moment about the F0 origin; force], in F0, N m and N.
        ``external_wrench_world``: the same wrench as [moment about the world origin;
            force], in world (rotated with the sensed base pose).

    Args: as ``ClassicalResidual`` without ``joint_damping``; ``gain`` scalar or 6-vector.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        gain,
        period: float = DEFAULT_PERIOD,
        known_wrench_frames: Sequence[Frame | str] = (),
        *,
        model: ResidualModel | None = None,
        implementation: str = "fast",
    ):
        super().__init__(
            plant,
            gain,
            period,
            known_wrench_frames,
            size=6,
            uses_torque=False,
            joint_damping=None,
            model=model,
            implementation=implementation,
        )
        # The world-frame wrench uses the sensed base pose of the same update.
        self._world_index = self.DeclareDiscreteState(6)
        self.DeclareStateOutputPort("external_wrench_base", self._residual_index)
        self.DeclareStateOutputPort("external_wrench_world", self._world_index)

    def _momentum_and_rates(self, terms, x, tau_m, known):
        momentum, model_rate = terms.base
        return momentum, model_rate, (np.zeros(6) if known is None else known[0])

    def _after_update(self, discrete_state: DiscreteValues, terms, x, residual) -> None:
        discrete_state.set_value(self._world_index, self._model.base_wrench_to_world(terms, x, residual))

    def world_wrench(self, terms, x: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """``external_wrench_world`` of the residual ``residual`` (``advance``'s) at x."""
        return self._model.base_wrench_to_world(terms, x, residual)


class ResidualBank(_ResidualParameters, LeafSystem):
    """The classical (eq. 7), internal (eq. 11) and external (eq. 16) residuals of one robot
    in one system: one periodic discrete update computes all three at the sensed state.

    Its outputs equal those of a ``ClassicalResidual``, an ``InternalResidual`` and an
    ``ExternalResidual`` with the same parameters fed the same inputs, bit for bit: the same
    momenta and rates (the shared ``ResidualModel``'s), the same measured forces, and the
    observer recursion of the module docstring applied entrywise to the three stacked. It
    costs one Drake update, one evaluation and check of each input, one friction term and
    one recursion instead of three.

    Inputs: ``state`` (nq + nv), ``measured_torque`` (n), ``known_wrenches`` (6 per frame),
    as the three systems'.
    State: discrete groups [flag; I_classical (nv); I_internal (n); I_external (6)] (the
    flag and the momentum integrals), r_classical (nv), r_internal (n), r_external (6) and
    r_external in world (6), updated every ``period``.

    Outputs (state output ports):
        ``classical_residual`` (nv): ``ClassicalResidual``'s ``residual``, N m and N.
        ``internal_residual`` (n): ``InternalResidual``'s ``residual``, N m (N prismatic).
        ``external_wrench_base``, ``external_wrench_world`` (6): ``ExternalResidual``'s.

    Args:
        plant: finalized floating-base plant (see ``FloatingBaseDynamics``).
        gain: K, 1/s: a scalar for all three residuals, or a tuple of three gains
            (classical: scalar or nv-vector; internal: scalar or n-vector; external: scalar
            or 6-vector); 0 < K period < 1.
        period, known_wrench_frames, joint_damping, model, implementation: as
            ``ClassicalResidual``'s (one ``ResidualModel`` serves the three residuals).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        gain,
        period: float = DEFAULT_PERIOD,
        known_wrench_frames: Sequence[Frame | str] = (),
        *,
        joint_damping=None,
        model: ResidualModel | None = None,
        implementation: str = "fast",
    ):
        super().__init__()
        gains = tuple(gain) if isinstance(gain, tuple) and len(gain) == 3 else (gain, gain, gain)
        try:
            if not isinstance(plant, MultibodyPlant):
                raise ValueError(f"plant must be a MultibodyPlant, got {type(plant).__name__}")
            if plant.is_finalized() and not _has_free_joint(plant):
                raise ValueError("the plant has no floating base (use ClassicalResidual for a fixed-base robot)")
            if model is None and plant.is_finalized():
                model = ResidualModel(plant, implementation)
            common = dict(period=period, known_wrench_frames=known_wrench_frames, model=model)
            classical = ClassicalResidual(plant, gains[0], joint_damping=joint_damping, **common)
            internal = InternalResidual(plant, gains[1], joint_damping=joint_damping, **common)
            external = ExternalResidual(plant, gains[2], **common)
        except ValueError as error:
            raise ValueError(f"ResidualBank: {error}") from None
        self._residuals = (classical, internal, external)
        self._model = classical.model
        self._frames = classical.known_wrench_frames
        self._frames_key = classical._frames_key
        self._period = classical.period
        self._half_period = classical._half_period
        self._damping = classical._damping  # = internal's (same joint_damping)
        self._gain = np.concatenate((classical._gain, internal._gain, external._gain))
        nv, n = plant.num_velocities(), plant.num_velocities() - 6
        self._qdot_start = classical._qdot_start
        self._sizes = (nv, n, 6)
        self._zeros = np.zeros(nv + n + 6)
        self._state_port = self.DeclareVectorInputPort("state", plant.num_positions() + nv)
        self._torque_port = self.DeclareVectorInputPort("measured_torque", n)
        self._wrench_port = self.DeclareVectorInputPort("known_wrenches", 6 * len(self._frames))
        self._integral_index = self.DeclareDiscreteState(1 + nv + n + 6)
        names = ("classical_residual", "internal_residual", "external_wrench_base", "external_wrench_world")
        self._residual_indices = tuple(self.DeclareDiscreteState(size) for size in (nv, n, 6, 6))
        for name, index in zip(names, self._residual_indices):
            self.DeclareStateOutputPort(name, index)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)

    @property
    def residuals(self) -> tuple[ClassicalResidual, InternalResidual, ExternalResidual]:
        """Equivalent separate systems (the same parameters and model; in no diagram)."""
        return self._residuals

    def advance(
        self, x: np.ndarray, measured_torque: np.ndarray, known_wrenches: np.ndarray | None, integral
    ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray], StateRates]:
        """One update of the three observers without a Context (as ``_MomentumResidual.advance``).

        Args:
            x: the sensed [q; v]. measured_torque: n motor torques. known_wrenches: 6 per
                F/T frame, world (None without frames).
            integral: [I_classical; I_internal; I_external]^+ of the previous update, or
                None at the first update.

        Returns:
            ([I_classical; I_internal; I_external]^+ of this update, (r_classical,
            r_internal, r_external), the model's ``StateRates`` at x). Inputs are not checked.
        """
        model = self._model
        terms = model.state_rates(x)
        (p_c, a_c), (p_i, a_i), (p_e, a_e) = terms.classical, terms.internal, terms.base
        tau_m = measured_torque - self._damping * x[self._qdot_start :]  # tau - tau_mu
        if self._frames:
            w_F0, tau_joints = model.known_wrench_forces(terms, self._frames, known_wrenches, self._frames_key)
            joint_c = tau_m + tau_joints  # tau_m + J_j^T w (classical joint entries)
            # Internal: tau_m + tau_bar_c, tau_bar_c = J^fb^T w (eq. 10).
            measured = np.concatenate((w_F0, joint_c, joint_c - model.eliminated_base_wrench(terms, w_F0), w_F0))
        else:
            measured = self._zeros.copy()
            nv, n, _ = self._sizes
            measured[6:nv] = tau_m
            measured[nv : nv + n] = tau_m
        momentum = np.concatenate((p_c, p_i, p_e))
        half_step = self._half_period * np.concatenate((a_c, a_i, a_e))
        integral, residual = _observer_step(momentum, half_step, measured, integral, self._gain, self._period)
        nv, n, _ = self._sizes
        return integral, (residual[:nv], residual[nv : nv + n], residual[nv + n :]), terms

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        x = eval_finite_input("ResidualBank", self._state_port, context)
        torque = eval_finite_input("ResidualBank", self._torque_port, context)
        wrenches = eval_finite_input("ResidualBank", self._wrench_port, context) if self._frames else None
        # Drake passes discrete_state initialised to the context's values: read them there.
        stored = discrete_state.get_value(self._integral_index)
        integral, (r_c, r_i, r_e), terms = self.advance(x, torque, wrenches, stored[1:] if stored[0] > 0.5 else None)
        discrete_state.set_value(self._integral_index, np.concatenate((_ONE, integral)))
        i_c, i_i, i_e, i_w = self._residual_indices
        discrete_state.set_value(i_c, r_c)
        discrete_state.set_value(i_i, r_i)
        discrete_state.set_value(i_e, r_e)
        discrete_state.set_value(i_w, self._model.base_wrench_to_world(terms, x, r_e))


def _observer_step(
    momentum: np.ndarray,
    half_step: np.ndarray,
    measured_rate: np.ndarray,
    integral: np.ndarray | None,
    gain: np.ndarray,
    period: float,
) -> tuple[np.ndarray, np.ndarray]:
    """One update of the discrete momentum observer (module docstring) from the momentum p_k,
    T/2 times the model rate a_k, and the measured rate u_k: I_k = I_{k-1}^+ + T/2 a_k +
    T u_k, r_k = K (p_k - I_k), and I_k^+ = I_k + T/2 a_k + T r_k; at the first update
    (``integral`` None) I_0 = p_0 and r_0 = 0 (no measured period yet). Returns (I_k^+, r_k)."""
    if integral is not None:
        integral = integral + half_step + period * measured_rate
        residual = gain * (momentum - integral)
    else:
        integral = momentum
        residual = np.zeros(momentum.shape[0])
    return integral + half_step + period * residual, residual


def _has_free_joint(plant: MultibodyPlant) -> bool:
    return any(plant.get_joint(i).num_velocities() == 6 for i in plant.GetJointIndices())


def _vector_parameter(value, size: int, what: str) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        array = np.full(size, float(array))
    if array.shape != (size,):
        raise ValueError(f"{what} must be a scalar or have {size} entries, got shape {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{what} must be finite")
    return array


def _plant_joint_damping(model: ResidualModel | FixedBaseModel) -> np.ndarray:
    """The plant's viscous joint damping per joint, v[6:] order (N m s/rad)."""
    return np.array([float(j.default_damping()) for j in model.joints])
