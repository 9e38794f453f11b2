"""The floating-base decomposition (Flacco et al. 2016, eq. 9, 13) on Pinocchio's C++ kernels.

``PinocchioFloatingBaseDynamics(plant)`` gives what ``DrakeFloatingBaseDynamics`` gives (the
``FloatingBaseTerms`` of ``systems.dynamics.floating_base_terms``, the same coordinates, Drake's
q and v in) from a Pinocchio model BUILT FROM the plant (``systems.dynamics.pinocchio_model``:
its joints, frames, spatial inertias, and the actuators' reflected rotor inertia as armature).

Three facts make it three kernels and a few numpy gathers per state:

* Pinocchio's free-flyer velocity [v_B; w_B] is the base velocity in F0 (the free joint's
  child frame), so its mass matrix (``crba``) is the project's F0 mass matrix
  [[I0c, F], [F^T, H]] up to a fixed permutation P of the velocity coordinates
  (angular/linear order of the base, joint order by name): M_F0 = M_pin[P][:, P].
* ``computeCoriolisMatrix`` gives Pinocchio's C with M_dot = C + C^T exactly (no central
  difference), so H_dot, F_dot and I0c_dot (Algorithm 2) are exact.
* The time derivative of the base-frame velocity [v_B; w_B] is Pinocchio's free-flyer
  acceleration, so ``nonLinearEffects`` (``rnea`` at zero acceleration, the plant's uniform
  gravity) is Algorithm 1's bias [p^0c; C^] (eq. 9) with no extra term.

Then ``reduce_to_floating_terms`` gives H_fb, C_fb and H_fb_dot (eq. 9, 13). Units: kg, m,
s (kg m^2 for rotational inertia, N m / N for generalized forces).

Per state the C++ work is ``crba``, ``computeCoriolisMatrix`` and ``nonLinearEffects``
(together one to two Drake ``CalcMassMatrix`` on the 32-34-joint humanoids, where "fast" makes
three mass matrices, the bias and gravity); the rest is numpy that "fast" does as well (the
state check, the coordinate change, the elimination of eq. 9). ``computeCoriolisMatrix``
leaves the joint Jacobians in ``data``, so ``spatial_jacobian_F0`` of a frame after
``compute`` costs no kinematics pass.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, SpatialInertia

from systems.common.topology import floating_base_topology
from systems.dynamics.base_state import checked_state, quaternion_to_rotation, quaternions_to_rotations
from systems.dynamics.floating_base_kernels import gather_mass_matrix_terms
from systems.dynamics.floating_base_terms import FloatingBaseTerms, reduce_to_floating_terms
from systems.dynamics.pinocchio_model import PlantPinocchioModel, pinocchio_inertia, pinocchio_model_from_plant


class PinocchioFloatingBaseDynamics:
    """The ``"pinocchio"`` implementation of ``FloatingBaseDynamics`` (module docstring).

    Args:
        plant: the finalized plant; its free joint must own q[0:7] and v[0:6] (Drake's
            order for a floating base) and its other joints be revolute, prismatic or welds
            (``systems.common.topology``).
        model: the Pinocchio model of ``plant`` (``pinocchio_model_from_plant``, with the
            reflected rotor inertia); built from the plant's defaults if None.

    Attributes:
        topology: the plant's ``FloatingBaseTopology``.
        pinocchio: the ``PlantPinocchioModel`` (model, body and frame maps).
        permutation: P, (nv,) with x_F0 = x_pin[P] for a velocity or generalized-force
            vector; x_F0 = [w_B; v_B; joints in v[6:] order] (forces [moment; force; joints]).
    """

    def __init__(self, plant: MultibodyPlant, model: PlantPinocchioModel | None = None):
        self.topology = floating_base_topology(plant)
        free = self.topology.free_joint
        if free.position_start() != 0 or free.velocity_start() != 0:
            raise ValueError("PinocchioFloatingBaseDynamics: the free joint must own q[0:7] and v[0:6]")
        self._plant = plant
        self._n = self.topology.num_joints
        self.pinocchio = model if model is not None else pinocchio_model_from_plant(plant)
        self.model = self.pinocchio.model
        self.data = self.model.createData()
        self._sizes = (plant.num_positions(), plant.num_velocities())
        model, nv = self.model, plant.num_velocities()
        ff = model.joints[model.getJointId(free.name())]
        if ff.idx_q != 0 or ff.idx_v != 0:
            raise ValueError("PinocchioFloatingBaseDynamics: the free flyer must be the model's first joint")
        # q_pin = q_drake[q_source]; x_F0 = x_pin[P]; v_pin = v_F0[P^-1].
        q_source = np.empty(model.nq, dtype=int)
        q_source[ff.idx_q : ff.idx_q + 7] = (4, 5, 6, 1, 2, 3, 0)
        P = np.empty(nv, dtype=int)
        P[0:3], P[3:6] = np.arange(ff.idx_v + 3, ff.idx_v + 6), np.arange(ff.idx_v, ff.idx_v + 3)
        for joint in self.topology.joints:
            pin_joint = model.joints[model.getJointId(joint.name())]
            q_source[pin_joint.idx_q] = joint.position_start()
            P[joint.velocity_start()] = pin_joint.idx_v
        if sorted(P.tolist()) != list(range(nv)) or sorted(q_source.tolist()) != list(range(model.nq)):
            raise ValueError(
                "PinocchioFloatingBaseDynamics: the Pinocchio model does not match the plant's coordinates"
            )
        self._q_source = q_source
        self._use_permutation(P)
        X_WP = free.frame_on_parent().CalcPoseInWorld(plant.CreateDefaultContext())
        R_WP = X_WP.rotation().matrix()
        self._R_WP = None if np.array_equal(R_WP, np.eye(3)) else R_WP
        self._R_WB_last: np.ndarray | None = None  # F0 rotation of the last compute
        self._gravity_W = np.array(self.model.gravity.linear)  # the plant's, world axes (m/s^2)
        self._support_gather: np.ndarray | None = None  # _stacked_gather's last gather

    def _use_permutation(self, P: np.ndarray) -> None:
        """Sets P and the gathers derived from it (the tests' controls pass a wrong one)."""
        nv = P.size
        self.permutation = P
        # compute(): the base rows of M_pin in F0 order, and the gather to Drake's joint
        # order with the base left in Pinocchio's order (None when the orders agree).
        self._base_swap = P[:6].copy()
        joints_first = np.concatenate((np.arange(6), P[6:]))
        in_order = np.array_equal(P[6:], np.arange(6, nv)) and np.array_equal(np.sort(P[:6]), np.arange(6))
        self._joint_flat = None if in_order else (joints_first[:, None] * nv + joints_first[None, :]).ravel()
        self._v_source = np.argsort(P)
        self._flat = (P[:, None] * nv + P[None, :]).ravel()  # M_F0 = M_pin.take(flat)

    def _frame_id(self, frame: Frame) -> int:
        frame_id = self.pinocchio.frames.get(int(frame.index()))
        if frame_id is None:
            raise ValueError(f"frame '{frame.name()}' is not on the floating tree of the Pinocchio model")
        return frame_id

    @property
    def context_F0(self) -> None:
        """None: this implementation keeps no Drake context (``ResidualModel`` then keeps its
        own for the F/T frames' Jacobians)."""
        return None

    def set_spatial_inertias(self, inertias: Mapping[int, SpatialInertia]) -> None:
        """Uses the spatial inertias M_BBo_B ({body index: SpatialInertia}, kg, m, kg m^2)
        instead of the plant's defaults in every computation here; the plant is not changed."""
        self.pinocchio.set_body_inertias({int(i): pinocchio_inertia(M) for i, M in inertias.items()})

    def _pinocchio_state(self, q: np.ndarray, v: np.ndarray):
        """(q_pin, v_pin, R_WB, v0) of checked Drake (q, v)."""
        R_PB = quaternion_to_rotation(q[:4])
        R_WB = R_PB if self._R_WP is None else self._R_WP @ R_PB
        v_F0 = v.copy()
        v_F0[:6] = (v[:6].reshape(2, 3) @ R_PB).reshape(6)  # [R_PB^T w_PB_P; R_PB^T v_PBo_P]
        return q[self._q_source], v_F0[self._v_source], R_WB, v_F0[:6]

    def mass_matrix_terms(
        self, q: np.ndarray, v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(M, M_dot, bias, R_WB, v0) at (q, v) as ``DrakeFloatingBaseDynamics.mass_matrix_terms``:
        the F0 mass matrix [[I0c, F], [F^T, H]], its exact derivative C + C^T, the bias
        [p^0c; C^] (gravity included, Algorithm 1: C v + g(q), with g read off M as in
        ``mass_matrix_terms_of_samples``), F0's rotation and v0 = [w_B; v_B]. Two kernels,
        ``crba`` and ``computeCoriolisMatrix``; the latter leaves the joint Jacobians in
        ``data`` for ``spatial_jacobian_F0``."""
        q, v = checked_state(self._plant, q, v, self._sizes)
        q_pin, v_pin, R_WB, v0 = self._pinocchio_state(q, v)
        self._R_WB_last = R_WB
        model, data = self.model, self.data
        M_pin = pin.crba(model, data, q_pin)
        C = pin.computeCoriolisMatrix(model, data, q_pin, v_pin)
        M, M_dot, bias = gather_mass_matrix_terms(M_pin, C, v_pin, self.permutation, self._gravity_W @ R_WB)
        return M, M_dot, bias, R_WB, v0

    def compute(self, q: np.ndarray, v: np.ndarray) -> FloatingBaseTerms:
        """The decomposition of eq. (9) at (q, v), in the coordinates of ``FloatingBaseTerms``:
        the blocks of M_F0 = M_pin[P][:, P] and of M_dot = C + C^T gathered directly (6-row
        gathers and an n x n sum; a whole-matrix gather only if the joint orders differ)."""
        q, v = checked_state(self._plant, q, v, self._sizes)
        q_pin, v_pin, R_WB, v0 = self._pinocchio_state(q, v)
        self._R_WB_last = R_WB
        model, data, s = self.model, self.data, self._base_swap
        M = pin.crba(model, data, q_pin)  # a new array (the binding copies data.M)
        C = pin.computeCoriolisMatrix(model, data, q_pin, v_pin)
        bias = pin.nonLinearEffects(model, data, q_pin, v_pin)[self.permutation]
        if self._joint_flat is not None:  # Drake's joint order: whole-matrix gathers
            nv = v.size
            M, C = M.take(self._joint_flat).reshape(nv, nv), C.take(self._joint_flat).reshape(nv, nv)
        M_base, C_base, C_joints = M[s], C[s], C[6:, 6:]
        I0c_dot = C_base[:, s]
        return reduce_to_floating_terms(
            H=M[6:, 6:],
            F=M_base[:, 6:],
            I0c=M_base[:, s],
            C_hat=bias[6:],
            p_hat=bias[:6],
            H_dot=C_joints + C_joints.T,
            F_dot=C_base[:, 6:] + C[6:, s].T,
            I0c_dot=I0c_dot + I0c_dot.T,
            R_WB=R_WB,
            v0=v0,
        )

    def spatial_jacobian_F0(self, frame: Frame) -> np.ndarray:
        """(6, nv) Jacobian of ``frame``'s origin w.r.t. [v0; qdot] at the state of the last
        ``compute``, rows [angular; linear] expressed in F0 (``ResidualModel.spatial_jacobian_F0``'s
        contract): ``computeCoriolisMatrix`` has left the joint Jacobians in ``data``."""
        if self._R_WB_last is None:
            raise ValueError("spatial_jacobian_F0: call compute(q, v) first")
        R_BW = self._R_WB_last.T
        J_W = pin.getFrameJacobian(self.model, self.data, self._frame_id(frame), pin.LOCAL_WORLD_ALIGNED)
        J = np.empty((6, J_W.shape[1]))
        J[:3], J[3:] = R_BW @ J_W[3:], R_BW @ J_W[:3]
        return J[:, self.permutation]

    def stacked_world_jacobian(self, frame_ids: Sequence[int]) -> np.ndarray:
        """(6 k, nv) the frames' spatial-velocity Jacobians of their origins at the state of
        the last ``compute`` or ``mass_matrix_terms``, stacked: each frame's rows [angular;
        linear] in WORLD axes, columns in F0 order (``support_jacobians``' layout), so that
        J^T [m_W; f_W] is the generalized force of wrenches given in world, about the frames'
        origins, with no rotation. ``frame_ids`` from ``frame_ids``."""
        if self._R_WB_last is None:
            raise ValueError("stacked_world_jacobian: call compute(q, v) first")
        model, data = self.model, self.data
        stacked = np.concatenate(
            [pin.getFrameJacobian(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED) for frame_id in frame_ids]
        )
        return stacked.take(self._stacked_gather(len(frame_ids)))

    def _stacked_gather(self, count: int) -> np.ndarray:
        """The flat gather of ``count`` stacked Pinocchio frame Jacobians (6 rows each,
        [linear; angular]) into rows [angular; linear] and columns in F0 order."""
        gather = self._support_gather
        if gather is None or gather.shape[0] != 6 * count:
            nv = self.model.nv
            one = np.array((3, 4, 5, 0, 1, 2))[:, None] * nv + self.permutation[None, :]
            gather = self._support_gather = np.concatenate([one + 6 * nv * k for k in range(count)])
        return gather

    def floating_frame_jacobians_of_samples(
        self, q: np.ndarray, frame_ids: Sequence[int]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At K positions q (K, nq; Drake's order, unit quaternions, not checked), for each
        frame (``frame_ids``, from ``frame_ids``): J^fb (K, m, 6, n), the floating Jacobian of
        eq. (12) of its origin, rows [angular; linear] in world axes (J^fb^T [m; f] is the
        internal residual's share of a wrench at the origin), its origin p_WF (K, m, 3) and
        its rotation R_WF (K, m, 3, 3). Per sample ``computeJointJacobians`` and ``crba``;
        J^fb = J_j - J_b M_bb^-1 M_bj (any base coordinates: Pinocchio's here) stacked over
        the samples."""
        model, data = self.model, self.data
        K, m, nv = q.shape[0], len(frame_ids), model.nv
        M = np.empty((K, nv, nv))
        J = np.empty((K, m, 6, nv))
        p_WF, R_WF = np.empty((K, m, 3)), np.empty((K, m, 3, 3))
        joint_jacobians, crba = pin.computeJointJacobians, pin.crba
        frame_jacobian, aligned = pin.getFrameJacobian, pin.LOCAL_WORLD_ALIGNED
        for k, q_k in enumerate(q[:, self._q_source]):
            joint_jacobians(model, data, q_k)
            M[k] = crba(model, data, q_k)
            for f, frame_id in enumerate(frame_ids):
                J[k, f] = frame_jacobian(model, data, frame_id, aligned)  # updates data.oMf[frame_id]
                placement = data.oMf[frame_id]
                p_WF[k, f], R_WF[k, f] = placement.translation, placement.rotation
        M = self._to_F0_order(M)
        J = J[..., self.permutation][:, :, (3, 4, 5, 0, 1, 2)]  # F0 columns, rows [angular; linear]
        E = np.linalg.solve(M[:, :6, :6], M[:, :6, 6:])  # (K, 6, n)
        return J[..., 6:] - J[..., :6] @ E[:, None], p_WF, R_WF

    def frame_ids(self, frames: Sequence[Frame]) -> tuple[int, ...]:
        """The Pinocchio frame ids of the plant's ``frames`` (for ``support_jacobians``).

        Raises:
            ValueError: a frame that is not on the floating tree."""
        return tuple(self._frame_id(frame) for frame in frames)

    def support_jacobians(self, q: np.ndarray, frame_ids: Sequence[int]) -> tuple[np.ndarray, np.ndarray, list]:
        """At the positions q (Drake's order, not checked), one kinematics pass: the frames'
        spatial-velocity Jacobians of their origins stacked (6 k, nv; each frame's rows
        [angular; linear] in world axes), the centre of mass's translational-velocity Jacobian
        (3, nv; world axes; every body of the model) and each frame's R_WF. ``frame_ids`` from
        ``frame_ids``. Columns in F0 order: the base [w_B; v_B] in F0 axes, then the joints in
        v[6:] order (a base-invariant quantity, such as a frame's velocity relative to another
        frame held still, reads the same as from Drake's columns)."""
        model, data = self.model, self.data
        J_G = pin.jacobianCenterOfMass(model, data, q[self._q_source], False)  # also fills data.J
        stacked = np.concatenate(
            [pin.getFrameJacobian(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED) for frame_id in frame_ids]
        )
        rotations = [pin.updateFramePlacement(model, data, frame_id).rotation for frame_id in frame_ids]
        return stacked.take(self._stacked_gather(len(frame_ids))), J_G[:, self.permutation], rotations

    def mass_matrix_terms_of_samples(
        self, q: np.ndarray, v: np.ndarray, frames: Sequence[Frame] = ()
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``mass_matrix_terms`` of K checked samples (q (K, nq), v (K, nv)) stacked on a
        leading axis, and J (K, len(frames), 6, nv): each frame origin's spatial-velocity
        Jacobian w.r.t. [v0; qdot], rows [angular; linear] expressed in F0 (the contract of
        ``DrakeFloatingBaseDynamics.mass_matrix_terms_of_samples``).

        Per sample two C++ kernels, ``crba`` and ``computeCoriolisMatrix`` (which leaves the
        joint Jacobians in ``data`` for ``getFrameJacobian``), written in place in Pinocchio's
        coordinates; the rest is stacked over the samples: the gathers to F0 order, M_dot =
        C + C^T, and the bias C v + g(q) with the gravity term read off the mass matrix
        (g(q) = -M[:, 3:6] R_WB^T g_W in F0 order: a free fall from rest, base acceleration
        R_WB^T g_W and no joint acceleration, has M a + g = 0), equal to ``nonLinearEffects``
        to rounding (tests) for a third of its cost.
        """
        K, nv = q.shape[0], v.shape[1]
        model, data, P = self.model, self.data, self.permutation
        R_PB = quaternions_to_rotations(q[:, :4])
        R_WB = R_PB if self._R_WP is None else self._R_WP @ R_PB
        v_F0 = v.copy()
        v_F0[:, :6] = (v[:, None, :6].reshape(K, 2, 3) @ R_PB).reshape(K, 6)
        q_pin, v_pin = q[:, self._q_source], v_F0[:, self._v_source]
        M_pin, C_pin = np.empty((K, nv, nv)), np.empty((K, nv, nv))
        frame_ids = [self._frame_id(f) for f in frames]
        J_W = np.empty((K, len(frame_ids), 6, nv))
        crba, coriolis = pin.crba, pin.computeCoriolisMatrix
        frame_jacobian, aligned = pin.getFrameJacobian, pin.LOCAL_WORLD_ALIGNED
        for k, (q_k, v_k) in enumerate(zip(q_pin, v_pin)):
            M_pin[k] = crba(model, data, q_k)
            C_pin[k] = coriolis(model, data, q_k, v_k)
            for f, frame_id in enumerate(frame_ids):  # rows [linear; angular], world axes
                J_W[k, f] = frame_jacobian(model, data, frame_id, aligned)
        Cv = (C_pin @ v_pin[:, :, None])[:, P, 0]
        M_dot = np.add(C_pin, C_pin.transpose(0, 2, 1), out=C_pin)
        M, M_dot = self._to_F0_order(M_pin), self._to_F0_order(M_dot)
        g_B = np.einsum("i,kij->kj", self._gravity_W, R_WB)  # R_WB^T g_W
        bias = Cv - (M[:, :, 3:6] @ g_B[:, :, None])[:, :, 0]
        J = np.empty((K, len(frame_ids), 6, nv))
        if frame_ids:
            J_W = J_W[..., P]
            R_BW = R_WB.transpose(0, 2, 1)[:, None]
            J[:, :, :3], J[:, :, 3:] = R_BW @ J_W[:, :, 3:], R_BW @ J_W[:, :, :3]
        return M, M_dot, bias, R_WB, v_F0[:, :6], J

    def _to_F0_order(self, A: np.ndarray) -> np.ndarray:
        """A (K, nv, nv) in Pinocchio's velocity order -> A[:, P][:, :, P], in place when the
        joints' orders agree (only the base's six rows and columns swap: a sixth of the
        work of the whole gather and no new array)."""
        if self._joint_flat is not None:
            P = self.permutation
            return A[:, P[:, None], P[None, :]]
        s = self._base_swap
        A[:, :6] = A[:, s]
        A[:, :, :6] = A[:, :, s]
        return A

    def frame_rotations_of_samples(self, q: np.ndarray, frames: Sequence[Frame]) -> np.ndarray:
        """(K, len(frames), 3, 3) R_WF of each frame at each of the K checked positions q
        (K, nq): one forward-kinematics pass per sample (``forwardKinematics``, then
        ``updateFramePlacement`` of the frames only)."""
        model, data = self.model, self.data
        frame_ids = [self._frame_id(f) for f in frames]
        out = np.empty((q.shape[0], len(frame_ids), 3, 3))
        kinematics, placement = pin.forwardKinematics, pin.updateFramePlacement
        for k, q_k in enumerate(q[:, self._q_source]):
            kinematics(model, data, q_k)
            for f, frame_id in enumerate(frame_ids):
                out[k, f] = placement(model, data, frame_id).rotation
        return out

    def gravity_generalized_forces(self, q: np.ndarray) -> np.ndarray:
        """Drake's generalized gravity force tau_g (nv, the convention of
        ``CalcGravityGeneralizedForces``: base entries [torque; force] in the free joint's
        parent frame) at the positions q, with this model's inertias, N m / N. Not checked."""
        q = np.asarray(q, dtype=float)
        R_PB = quaternion_to_rotation(q[:4] / np.linalg.norm(q[:4]))
        g = pin.computeGeneralizedGravity(self.model, self.data, q[self._q_source])[self.permutation]
        tau = -g
        tau[:6] = (-(g[:6].reshape(2, 3)) @ R_PB.T).reshape(6)  # base rows F0 -> parent frame
        return tau

    def floating_jacobian(self, q: np.ndarray, frame: Frame, p_FoP: np.ndarray, *, spatial: bool = False) -> np.ndarray:
        """J^fb (eq. 12) of point P fixed in ``frame`` (p_FoP in the frame, m), in world
        coordinates: (3, n) for a force at P, or (6, n) with ``spatial`` for a wrench
        [moment about P; force]. J^fb = J_j - J_b I0c^-1 F in any base coordinates."""
        q, _ = checked_state(self._plant, q, np.zeros(self._sizes[1]), self._sizes)
        model, data, P = self.model, self.data, self.permutation
        q_pin = q[self._q_source]
        frame_id = self._frame_id(frame)
        M = pin.crba(model, data, q_pin)
        J = pin.computeFrameJacobian(model, data, q_pin, frame_id, pin.LOCAL_WORLD_ALIGNED)[:, P]
        R_WF = data.oMf[frame_id].rotation
        p_W = R_WF @ np.asarray(p_FoP, dtype=float).reshape(3)
        # Linear velocity of P: v_Fo + w x p = J_lin - [p]x J_ang; rows [angular; linear].
        skew = np.array(((0.0, -p_W[2], p_W[1]), (p_W[2], 0.0, -p_W[0]), (-p_W[1], p_W[0], 0.0)))
        J_P = np.vstack((J[3:], J[:3] - skew @ J[3:]))
        if not spatial:
            J_P = J_P[3:]
        M_F0 = M.take(self._flat).reshape(P.size, P.size)
        return J_P[:, 6:] - J_P[:, :6] @ np.linalg.solve(M_F0[:6, :6], M_F0[:6, 6:])
