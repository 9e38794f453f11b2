"""Floating-base decomposition of a humanoid's dynamics: Flacco et al. (2016) eq. (9).

``FloatingBaseDynamics(plant, implementation)`` computes, at a state (q, v) in Drake's
coordinates, the paper's H, F, I0c, C^, p^0c (Algorithm 1), their time derivatives
(Algorithm 2), the floating inertia H^fb, its derivative (eq. 13), the floating bias C^fb,
and the floating Jacobian J^fb of a point (eq. 12). Two implementations give the same numbers:

* ``"fast"``: Drake's C++ kernels (mass matrix, bias term, gravity, Jacobians) plus the
  derivative of the mass matrix along the joint velocities by a central difference of two
  extra mass matrices, vectorised numpy, no per-body Python loop.
* ``"reference"``: the paper's recursive Algorithms 1-2 in spatial-vector algebra
  (``systems.dynamics.floating_base_reference``), a faithful and slower O(n depth) implementation.
* ``"pinocchio"``: Pinocchio's C++ kernels on a model built from the plant
  (``systems.dynamics.pinocchio_dynamics``): the mass matrix, the Coriolis matrix (the
  derivative of the mass matrix exactly, C + C^T) and the bias; equal to "fast" to its
  central difference's error (~1e-10 relative) and to "reference" to rounding.

Coordinates of the outputs: see ``systems.dynamics.floating_base_terms`` (the paper's base frame F0
for F, I0c, p^ and the base velocity; joint order = the plant's ``v[6:]``). The floating
Jacobian is returned in world coordinates.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, Frame, JacobianWrtVariable, SpatialInertia
from pydrake.systems.framework import Context

from systems.common.topology import floating_base_topology, uniform_gravity
from systems.dynamics.base_state import checked_state, quaternion_to_rotation, quaternions_to_rotations
from systems.dynamics.floating_base_terms import FloatingBaseTerms, reduce_to_floating_terms

IMPLEMENTATIONS = ("fast", "reference", "pinocchio")

#: Length of the configuration-space step of the mass-matrix central difference [rad or m].
#: Truncation error ~ step^2, rounding error ~ 1e-16 / step: 1e-5 balances both (~1e-10).
MASS_MATRIX_DERIVATIVE_STEP = 1e-5


class DrakeFloatingBaseDynamics:
    """The ``"fast"`` implementation: Drake's mass matrix, bias and gravity kernels.

    F0-expressed H, F and I0c depend only on the joint positions, so the mass matrix is
    evaluated with the base at the world origin with identity rotation (there Drake's
    world-aligned base coordinates coincide with F0's). Its time derivative along the
    motion is the directional derivative along the joint velocities, taken by a central
    difference of two more mass matrices (relative error ~1e-10). The bias at the same
    identity pose with the base velocity expressed in F0 is Drake's C v in F0; gravity and
    the change to Featherstone's base acceleration are added through M (see ``compute``).
    """

    def __init__(self, plant: MultibodyPlant, derivative_step: float = MASS_MATRIX_DERIVATIVE_STEP):
        self.topology = floating_base_topology(plant)
        self._plant = plant
        self._n = self.topology.num_joints
        self._step = float(derivative_step)
        # Context at the identity base pose: mass matrices and bias in F0.
        self._context_F0 = plant.CreateDefaultContext()
        # Context at the true base pose: Jacobians in the world.
        self._context_W = plant.CreateDefaultContext()
        self._gravity_W = uniform_gravity(plant)
        R_WP = self.topology.free_joint.frame_on_parent().CalcPoseInWorld(self._context_W).rotation().matrix()
        self._R_WP = None if np.array_equal(R_WP, np.eye(3)) else R_WP
        self._sizes = (plant.num_positions(), plant.num_velocities())
        self._q_F0 = plant.GetPositions(self._context_F0).copy()
        self._q_F0[:7] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]

    @property
    def context_F0(self) -> Context:
        """The plant context at the identity base pose (F0 = world); after ``compute(q, v)``
        it holds q's joint positions (for F0-expressed Jacobians of the same q)."""
        return self._context_F0

    def set_spatial_inertias(self, inertias: Mapping[int, SpatialInertia]) -> None:
        """Uses the spatial inertias M_BBo_B (``{body index: SpatialInertia}``) in this
        model's contexts instead of the plant's defaults (a model that differs from the
        simulated robot); the plant itself is not changed."""
        for index, M in inertias.items():
            body = self._plant.get_body(BodyIndex(int(index)))
            for context in (self._context_F0, self._context_W):
                body.SetSpatialInertiaInBodyFrame(context, M)

    def _mass_matrix_F0(self, q_joints: np.ndarray) -> np.ndarray:
        self._q_F0[7:] = q_joints
        self._plant.SetPositions(self._context_F0, self._q_F0)
        return self._plant.CalcMassMatrix(self._context_F0)

    def compute(self, q: np.ndarray, v: np.ndarray) -> FloatingBaseTerms:
        """The decomposition of eq. (9) at (q, v), in the coordinates of ``FloatingBaseTerms``."""
        M, M_dot, bias, R_WB, v0 = self.mass_matrix_terms(q, v)
        return reduce_to_floating_terms(
            H=M[6:, 6:],
            F=M[:6, 6:],
            I0c=M[:6, :6],
            C_hat=bias[6:],
            p_hat=bias[:6],
            H_dot=M_dot[6:, 6:],
            F_dot=M_dot[:6, 6:],
            I0c_dot=M_dot[:6, :6],
            R_WB=R_WB,
            v0=v0,
        )

    def mass_matrix_terms(
        self, q: np.ndarray, v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(M, M_dot, bias, R_WB, v0) at (q, v), before the elimination of eq. (9): the mass
        matrix in F0 coordinates [[I0c, F], [F^T, H]], its derivative along the motion, the
        bias [p^; C^] (gravity included), F0's rotation and the base velocity [w; v] in
        F0 (``compute`` reduces them; ``mass_matrix_terms_of_samples`` does many at once)."""
        plant, n = self._plant, self._n
        q, v = checked_state(plant, q, v, self._sizes)
        # Drake's free joint gives the pose of F0 (its child frame M) in its parent frame P,
        # which is fixed in the world (usually the world frame itself), and velocities
        # expressed in P.
        R_PB = quaternion_to_rotation(q[:4])
        R_WB = R_PB if self._R_WP is None else self._R_WP @ R_PB
        v0 = (v[:6].reshape(2, 3) @ R_PB).reshape(6)  # [R_PB^T w_PB_P; R_PB^T v_PBo_P]
        q_joints, qdot = q[7:], v[6:]

        # Mass matrix derivative along the joint motion (the only thing F0 blocks depend on).
        speed = math.sqrt(float(qdot @ qdot))
        if speed > 0.0:
            h = self._step / speed
            dq = h * qdot
            M_dot = self._mass_matrix_F0(q_joints + dq)
            M_dot -= self._mass_matrix_F0(q_joints - dq)
            M_dot *= 0.5 / h
        else:
            M_dot = np.zeros((6 + n, 6 + n))

        M = self._mass_matrix_F0(q_joints)
        v_F0 = v.copy()
        v_F0[:6] = v0
        plant.SetVelocities(self._context_F0, v_F0)
        Cv = plant.CalcBiasTerm(self._context_F0)
        # Paper's bias C v + g in F0 coordinates (Algorithm 1). Two facts make it cheap:
        # * uniform gravity's generalized force is M[:, 3:6] g_B (the base's translational
        #   columns of M are m J_com^T), with g_B the gravity expressed in F0;
        # * Featherstone's base acceleration (derivative of F0 coordinates) differs from
        #   Drake's world-aligned one by [0; w_B x v_B], adding M[:, 3:6] (w_B x v_B).
        # Together they are Algorithm 1's fictitious base acceleration a_0^vp = -a_g.
        wx, wy, wz, vx, vy, vz = v0.tolist()
        gx, gy, gz = (self._gravity_W @ R_WB).tolist()
        a_fictitious = np.array((wy * vz - wz * vy - gx, wz * vx - wx * vz - gy, wx * vy - wy * vx - gz))
        bias = Cv + M[:, 3:6] @ a_fictitious
        return M, M_dot, bias, R_WB, v0

    def mass_matrix_terms_of_samples(
        self, q: np.ndarray, v: np.ndarray, frames: Sequence[Frame] = ()
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``mass_matrix_terms`` of K checked samples (q (K, nq), v (K, nv), unit
        quaternions) at once: per sample only Drake's calls (three mass matrices, the bias
        and, for each of ``frames``, the spatial-velocity Jacobian of its origin in F0
        coordinates, world-aligned F0 axes), the rest stacked over the samples. Returns
        (M, M_dot, bias, R_WB, v0) as in ``mass_matrix_terms`` with a leading K axis, and J
        (K, len(frames), 6, nv); equal to ``mass_matrix_terms`` to rounding (tests): the same
        Drake calls at the same F0 configurations, the same central difference
        (M(q + h qdot) - M(q - h qdot)) * (0.5 / h). The F0 configurations [q + h qdot,
        q - h qdot] and the F0 state [q; v_F0] of every sample are stacked before the loop
        over the samples, which makes only Drake's calls (four per sample and one per frame)
        and writes their results in place.
        """
        plant, n, context = self._plant, self._n, self._context_F0
        K = q.shape[0]
        R_PB = quaternions_to_rotations(q[:, :4])
        R_WB = R_PB if self._R_WP is None else self._R_WP @ R_PB
        v0 = (v[:, None, :6].reshape(K, 2, 3) @ R_PB).reshape(K, 6)
        q_joints, qdot = q[:, 7:], v[:, 6:]
        speed = np.sqrt(np.einsum("ki,ki->k", qdot, qdot))
        moving = speed > 0.0
        h = np.where(moving, self._step / np.where(moving, speed, 1.0), 0.0)
        scale = (0.5 / np.where(moving, h, 1.0)).tolist()  # the difference's 0.5 / h
        dq = h[:, None] * qdot
        # Per sample, the F0 configurations [q + dq, q - dq] of the difference and the F0
        # state [q; v_F0] of M, the bias and the Jacobians (the base at the identity pose).
        q_F0 = np.empty((K, 2, q.shape[1]))
        q_F0[:, :, :7] = self._q_F0[:7]
        q_F0[:, 0, 7:] = q_joints + dq
        q_F0[:, 1, 7:] = q_joints - dq
        x_F0 = np.concatenate((q, v), axis=1)
        x_F0[:, :7] = self._q_F0[:7]
        x_F0[:, q.shape[1] : q.shape[1] + 6] = v0
        M, M_dot, Cv = np.empty((K, 6 + n, 6 + n)), np.empty((K, 6 + n, 6 + n)), np.empty((K, 6 + n))
        J = np.empty((K, len(frames), 6, 6 + n))
        world, origin, kV = plant.world_frame(), np.zeros(3), JacobianWrtVariable.kV
        for k, is_moving in enumerate(moving.tolist()):
            if is_moving:
                plant.SetPositions(context, q_F0[k, 0])
                M_plus = plant.CalcMassMatrix(context)
                plant.SetPositions(context, q_F0[k, 1])
                np.subtract(M_plus, plant.CalcMassMatrix(context), out=M_dot[k])
                M_dot[k] *= scale[k]
            else:
                M_dot[k] = 0.0
            plant.SetPositionsAndVelocities(context, x_F0[k])
            M[k] = plant.CalcMassMatrix(context)
            Cv[k] = plant.CalcBiasTerm(context)
            for f, frame in enumerate(frames):
                J[k, f] = plant.CalcJacobianSpatialVelocity(context, kV, frame, origin, world, world)
        if self._R_WP is not None and frames:
            # At the identity base pose F0 is the free joint's parent frame P, not the world:
            # rows from world to F0 axes (the columns are already F0's: Drake's base
            # velocities are expressed in P).
            J = np.einsum("ji,kfsjn->kfsin", self._R_WP, J.reshape(K, len(frames), 2, 3, 6 + n)).reshape(J.shape)
        # The bias of ``mass_matrix_terms``: Cv + M[:, 3:6] a, a = w x v - g (in F0).
        g = np.einsum("i,kij->kj", self._gravity_W, R_WB)
        wx, wy, wz, vx, vy, vz = v0.T
        a = np.stack((wy * vz - wz * vy - g[:, 0], wz * vx - wx * vz - g[:, 1], wx * vy - wy * vx - g[:, 2]), axis=1)
        bias = Cv + (M[:, :, 3:6] @ a[:, :, None])[:, :, 0]
        return M, M_dot, bias, R_WB, v0, J

    def gravity_generalized_forces(self, q: np.ndarray) -> np.ndarray:
        """Drake's generalized gravity force tau_g (nv, ``CalcGravityGeneralizedForces``) at
        the positions q, with this model's inertias (``set_spatial_inertias``), N m / N.
        Inputs are not checked (a PD controller calls it at every step)."""
        self._plant.SetPositions(self._context_W, q)
        return self._plant.CalcGravityGeneralizedForces(self._context_W)

    def floating_jacobian(self, q: np.ndarray, frame: Frame, p_FoP: np.ndarray, *, spatial: bool = False) -> np.ndarray:
        """J^fb of point P fixed in ``frame``, in world coordinates (eq. 12: tau = J^fb^T f_W).

        Args:
            q: the plant's positions.
            frame: a frame of the plant; P is fixed in it.
            p_FoP: position of P in ``frame`` [m].
            spatial: False for the (3, n) Jacobian of a force at P; True for the (6, n)
                Jacobian of a wrench [moment about P; force], both in world coordinates.
        """
        plant = self._plant
        q, _ = checked_state(plant, q, np.zeros(plant.num_velocities()))
        p_FoP = np.asarray(p_FoP, dtype=float).reshape(3)
        plant.SetPositions(self._context_W, q)
        world = plant.world_frame()
        if spatial:
            J = plant.CalcJacobianSpatialVelocity(self._context_W, JacobianWrtVariable.kV, frame, p_FoP, world, world)
        else:
            J = plant.CalcJacobianTranslationalVelocity(
                self._context_W, JacobianWrtVariable.kV, frame, p_FoP, world, world
            )
        M = plant.CalcMassMatrix(self._context_W)
        # Coordinate-invariant elimination of the base: J_j - J_b M_bb^-1 M_bj.
        return J[:, 6:] - J[:, :6] @ np.linalg.solve(M[:6, :6], M[:6, 6:])


class FloatingBaseDynamics:
    """Floating-base decomposition (paper eq. 9, Algorithms 1-2, eq. 13) of a Drake plant.

    The plant must be finalized and have exactly one floating base (a quaternion free
    joint) and otherwise only 1-DoF (revolute, prismatic) and weld joints; anything else
    raises ``ValueError`` at construction (see ``systems.common.topology``).

    Args:
        plant: the robot's finalized MultibodyPlant (its own contexts are created here).
        implementation: ``"fast"`` (Drake kernels), ``"pinocchio"`` (Pinocchio's C++
            kernels on a model built from the plant; the module docstring) or
            ``"reference"`` (the paper's recursive algorithms).
    """

    def __init__(self, plant: MultibodyPlant, implementation: str = "fast"):
        if implementation not in IMPLEMENTATIONS:
            raise ValueError(f"unknown implementation '{implementation}'; choose one of {IMPLEMENTATIONS}")
        self.implementation = implementation
        if implementation == "fast":
            self._impl = DrakeFloatingBaseDynamics(plant)
        elif implementation == "pinocchio":
            from systems.dynamics.pinocchio_dynamics import PinocchioFloatingBaseDynamics

            self._impl = PinocchioFloatingBaseDynamics(plant)
        else:
            from systems.dynamics.floating_base_reference import RecursiveFloatingBaseDynamics

            self._impl = RecursiveFloatingBaseDynamics(plant)
        self.topology = self._impl.topology  # one walk of the plant's tree (``floating_base_topology``)
        self.plant = plant
        self._gravity_context: Context | None = None  # the "reference" implementation's

    @property
    def num_joints(self) -> int:
        """n, the number of joint velocities (nv - 6)."""
        return self.topology.num_joints

    @property
    def context_F0(self) -> Context | None:
        """The "fast" implementation's plant context at the identity base pose, holding the
        joint positions of the last ``compute`` (see ``DrakeFloatingBaseDynamics.context_F0``);
        None for the "reference" implementation, which keeps no such context."""
        return self._impl.context_F0 if isinstance(self._impl, DrakeFloatingBaseDynamics) else None

    def gravity_generalized_forces(self, q: np.ndarray) -> np.ndarray:
        """See ``DrakeFloatingBaseDynamics.gravity_generalized_forces``; the "reference"
        implementation reads the plant's default inertias (it has no others)."""
        if hasattr(self._impl, "gravity_generalized_forces"):  # "fast", "pinocchio"
            return self._impl.gravity_generalized_forces(q)
        if self._gravity_context is None:
            self._gravity_context = self.plant.CreateDefaultContext()
        self.plant.SetPositions(self._gravity_context, q)
        return self.plant.CalcGravityGeneralizedForces(self._gravity_context)

    def set_spatial_inertias(self, inertias: Mapping[int, SpatialInertia]) -> None:
        """See ``DrakeFloatingBaseDynamics.set_spatial_inertias``; "fast" implementation only.

        Raises:
            ValueError: the "reference" implementation (it reads the plant's defaults).
        """
        if not hasattr(self._impl, "set_spatial_inertias"):
            raise ValueError(
                "set_spatial_inertias: only the 'fast' and 'pinocchio' implementations support a perturbed model"
            )
        self._impl.set_spatial_inertias(inertias)

    def compute(self, q: np.ndarray, v: np.ndarray) -> FloatingBaseTerms:
        """All terms of eq. (9) and their derivatives at (q, v) (Drake's coordinates in)."""
        return self._impl.compute(q, v)

    @property
    def own_spatial_jacobian_F0(self):
        """The implementation's F0 spatial-velocity Jacobian of a frame at the state of its
        last ``compute``, read from the kinematics that pass left (``"pinocchio"``:
        ``PinocchioFloatingBaseDynamics.spatial_jacobian_F0``, a callable of the frame), or
        None: the caller takes Drake's on a context of its own."""
        return getattr(self._impl, "spatial_jacobian_F0", None)

    @property
    def own_stacked_world_jacobian(self):
        """The implementation's stacked world-axes Jacobians of frames at the state of its last
        ``compute`` (``"pinocchio"``: ``PinocchioFloatingBaseDynamics.stacked_world_jacobian``,
        a callable of the frame ids its ``frame_ids`` gives), or None."""
        return getattr(self._impl, "stacked_world_jacobian", None)

    def own_frame_ids(self, frames: Sequence[Frame]):
        """The implementation's ids of ``frames`` for ``own_stacked_world_jacobian``, or None."""
        frame_ids = getattr(self._impl, "frame_ids", None)
        return None if frame_ids is None else frame_ids(frames)

    def mass_matrix_terms(
        self, q: np.ndarray, v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(M, M_dot, bias, R_WB, v0) at (q, v) before eq. (9)'s elimination: the F0 mass
        matrix [[I0c, F], [F^T, H]], its derivative along the motion, the bias [p^; C^]
        (gravity included), F0's rotation and v0 = [w_B; v_B] in F0
        (``DrakeFloatingBaseDynamics.mass_matrix_terms``); "reference": assembled from the
        blocks of its ``compute``."""
        impl = self._impl
        if hasattr(impl, "mass_matrix_terms"):
            return impl.mass_matrix_terms(q, v)
        t = impl.compute(q, v)
        M = np.block([[t.I0c, t.F], [t.F.T, t.H]])
        M_dot = np.block([[t.I0c_dot, t.F_dot], [t.F_dot.T, t.H_dot]])
        return M, M_dot, np.concatenate((t.p_hat, t.C_hat)), t.R_WB, t.v0

    def mass_matrix_terms_of_samples(self, q: np.ndarray, v: np.ndarray, frames: Sequence[Frame] = ()):
        """See ``DrakeFloatingBaseDynamics.mass_matrix_terms_of_samples``; "fast" and
        "pinocchio" implementations (None for "reference")."""
        if not hasattr(self._impl, "mass_matrix_terms_of_samples"):
            return None
        return self._impl.mass_matrix_terms_of_samples(q, v, frames)

    def floating_jacobian(self, q: np.ndarray, frame: Frame, p_FoP: np.ndarray, *, spatial: bool = False) -> np.ndarray:
        """J^fb (3 x n, or 6 x n with ``spatial``) of a point fixed in ``frame``, world coordinates."""
        return self._impl.floating_jacobian(q, frame, p_FoP, spatial=spatial)
