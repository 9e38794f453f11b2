"""Reference implementation of the paper's recursive floating-base algorithms.

Flacco, Paolillo, Kheddar, "Residual-based contacts estimation for humanoid robots",
Humanoids 2016, Sec. III: eq. (9), Algorithm 1 (C^, p^0c), Algorithm 2 (H, F, I0c and their
time derivatives), eq. (12) (floating Jacobian), eq. (13) (H_fb_dot, via
``reduce_to_floating_terms``). Written for clarity and faithfulness, not speed: plain Python
loops over 6x6 numpy matrices, O(n * depth). The fast implementation in
``systems.dynamics.floating_base`` is checked against this one (and this one against Drake and
Pinocchio in ``tests/test_floating_base_reference.py``).

Model extracted from the Drake plant at construction (parameters from a default context):

* Link 0 is the floating base; its frame is F0, the free joint's child frame.
* Link ``k`` (1-based) is the body moved by the 1-DoF joint owning velocity ``v[6 + k - 1]``;
  **its link frame is that joint's child frame M** (fixed in the child body, coincident with
  the joint's parent-side frame F at q = 0). Hence ``X_J`` is a rotation about / translation
  along the joint axis ``a`` (Drake gives it in F, equal to M's coordinates), and the motion
  subspace is ``S = [a; 0]`` (revolute) or ``S = [0; a]`` (prismatic), constant in M.
* The tree transform ``X_T(k) = ^F X_{lambda(k)}`` maps the parent link's frame to F. The
  parent link is the link of the joint's parent body (welded bodies belong to the link of the
  body they are welded to).
* Welded bodies (and their welded descendants) are lumped into the link they are welded to:
  their spatial inertias are transformed into that link frame and added. Their frames remain
  usable in ``floating_jacobian``.
* Joint actuators' reflected inertia (rotor inertia x gear ratio^2, from the default
  context) is added to H's diagonal, as Drake's ``CalcMassMatrix`` and its dynamics do; the
  paper's H is the rigid-body part only (identical when the plant has no rotor inertia).
* Bodies not hanging from the floating base (e.g. welded to the world) do not move and carry
  no dynamics here.

Paper typo corrected: in Algorithm 2's inner loop the off-diagonal element is
``H_{i j} = S_j^T F_i`` (F_i already transformed to the ancestor frame j), as in
Featherstone's CRBA (RBDA Table 6.2), not ``S_i^T F_i``. The same applies to ``H_dot``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame

from systems.common.spatial import crf, crm, plucker, skew, spatial_inertia, transform_inertia
from systems.common.topology import floating_base_topology, uniform_gravity
from systems.dynamics.base_state import checked_state, quaternion_to_rotation
from systems.dynamics.floating_base_terms import FloatingBaseTerms, reduce_to_floating_terms

_REVOLUTE = "revolute"
_PRISMATIC = "prismatic"


@dataclass(frozen=True)
class _Link:
    """Constant data of one moving link (1-based index ``k``) of the tree."""

    joint_name: str
    kind: str  # "revolute" or "prismatic"
    parent: int  # lambda(k), 0 = floating base
    X_T: np.ndarray  # (6, 6) ^F X_parent
    axis: np.ndarray  # (3,) unit axis in F (= in M)
    S: np.ndarray  # (6,) motion subspace in the link frame M


def _motion_transform(X_AB: RigidTransform) -> np.ndarray:
    """``^B X_A`` from the pose ``X_AB`` of frame B in frame A."""
    return plucker(X_AB.rotation().matrix().T, X_AB.translation())


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` about unit ``axis`` (R_FM of a revolute joint)."""
    K = skew(axis)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


class RecursiveFloatingBaseDynamics:
    """The paper's Algorithms 1 and 2 on a Drake plant's kinematic tree (reference version).

    Conventions (see ``systems.dynamics.floating_base_terms``): base velocity ``v0 = [w_WB_B; v_WBo_B]``,
    spatial quantities in F0 about its origin, ``[angular; linear]`` / ``[moment; force]``,
    joints in the plant's velocity order ``v[6:]``.

    Args:
        plant: a finalized MultibodyPlant accepted by ``floating_base_topology``. Mass,
            inertia and frame-offset parameters are read once, from a default context.

    Raises:
        ValueError: the plant is not a single floating-base tree of 1-DoF joints, or gravity
            is disabled for some of its model instances.
    """

    def __init__(self, plant: MultibodyPlant):
        topo = floating_base_topology(plant)
        self._plant = plant
        self.topology = topo
        self._n = topo.num_joints
        self._nq = plant.num_positions()
        self._nv = plant.num_velocities()
        if self._nq != 7 + self._n or self._nv != 6 + self._n:
            raise ValueError(f"unexpected sizes nq={self._nq}, nv={self._nv} for {self._n} joints")
        ctx = plant.CreateDefaultContext()
        self._default_context = ctx
        world_index = plant.world_body().index()

        # Free joint: F0 = its child frame M0; its parent frame Fw is fixed in the world.
        free = topo.free_joint
        self._R_W_Fw = free.frame_on_parent().CalcPoseInWorld(ctx).rotation().matrix()
        # Uniform gravity is assumed (a_0^vp = -^0 a_g for every link).
        self._g_W = uniform_gravity(plant)

        # Link of each body and the pose of the body in its link frame.
        base_body = topo.base_body
        X_B0_F0 = topo.base_frame.CalcPoseInBodyFrame(ctx)
        self._body_link: dict = {base_body.index(): (0, X_B0_F0.inverse())}

        velocity_link = {j.index(): k + 1 for k, j in enumerate(topo.joints)}
        children: dict = {}
        for index in plant.GetJointIndices():
            joint = plant.get_joint(index)
            if joint.index() == free.index() or joint.parent_body().index() == world_index:
                continue
            children.setdefault(joint.parent_body().index(), []).append(joint)

        links: list = [None] * (self._n + 1)
        order: list[int] = []  # 1-DoF links, parents before children (breadth first)
        queue = [base_body.index()]
        while queue:
            body_index = queue.pop(0)
            parent_link, X_LP = self._body_link[body_index]
            for joint in children.get(body_index, []):
                child = joint.child_body()
                X_PF = joint.frame_on_parent().CalcPoseInBodyFrame(ctx)
                X_CM = joint.frame_on_child().CalcPoseInBodyFrame(ctx)
                kind = joint.type_name()
                if kind == "weld":
                    X_FM = joint.X_FM()
                    X_LC = X_LP.multiply(X_PF).multiply(X_FM).multiply(X_CM.inverse())
                    self._body_link[child.index()] = (parent_link, X_LC)
                elif kind in (_REVOLUTE, _PRISMATIC):
                    k = velocity_link[joint.index()]
                    if kind == _REVOLUTE:
                        axis = np.array(joint.revolute_axis(), dtype=float)
                        S = np.concatenate((axis, np.zeros(3)))
                    else:
                        axis = np.array(joint.translation_axis(), dtype=float)
                        S = np.concatenate((np.zeros(3), axis))
                    X_LF = X_LP.multiply(X_PF)
                    links[k] = _Link(
                        joint_name=joint.name(),
                        kind=kind,
                        parent=parent_link,
                        X_T=_motion_transform(X_LF),
                        axis=axis,
                        S=S,
                    )
                    self._body_link[child.index()] = (k, X_CM.inverse())
                    order.append(k)
                else:  # floating_base_topology already refuses these.
                    raise ValueError(f"joint '{joint.name()}' of type '{kind}' is not supported")
                queue.append(child.index())
        if len(order) != self._n:
            raise ValueError(
                f"found {len(order)} of the {self._n} 1-DoF joints below the floating base; "
                "is a joint's parent body farther from the base than its child?"
            )
        self._links = links
        self._order = order
        self._parent = np.array([0] + [links[k].parent for k in range(1, self._n + 1)])
        self._S = [np.zeros(6)] + [links[k].S for k in range(1, self._n + 1)]

        # Link spatial inertias (bodies lumped by welds), about each link frame's origin.
        inertia = [np.zeros((6, 6)) for _ in range(self._n + 1)]
        for body_index, (k, X_LB) in self._body_link.items():
            M_BBo_B = plant.get_body(body_index).CalcSpatialInertiaInBodyFrame(ctx)
            mass = M_BBo_B.get_mass()
            com = np.array(M_BBo_B.get_com())
            I_com = M_BBo_B.Shift(com).CalcRotationalInertia().CopyToFullMatrix3()
            I_B = spatial_inertia(mass, com, I_com)
            inertia[k] += transform_inertia(_motion_transform(X_LB.inverse()), I_B)
        self._I = inertia

        # Actuator reflected inertia (rotor inertia x gear ratio^2), which Drake adds to the
        # diagonal of the mass matrix; constant, so it adds nothing to H_dot.
        self._reflected = np.zeros(self._n)
        for actuator_index in plant.GetJointActuatorIndices():
            actuator = plant.get_joint_actuator(actuator_index)
            k = velocity_link.get(actuator.joint().index())
            if k is not None:
                self._reflected[k - 1] += actuator.calc_reflected_inertia(ctx)

    # ------------------------------------------------------------------ properties
    @property
    def num_joints(self) -> int:
        """n, the number of 1-DoF joints."""
        return self._n

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names in velocity order (the order of H's rows)."""
        return tuple(self._links[k].joint_name for k in range(1, self._n + 1))

    @property
    def parents(self) -> np.ndarray:
        """lambda(k) for k = 0..n (entry 0 is 0 by convention)."""
        return self._parent.copy()

    # ------------------------------------------------------------------ helpers
    def _validate(self, q: np.ndarray, v: np.ndarray | None = None):
        """Shared checks of ``systems.dynamics.base_state.checked_state`` (sizes, NaN, unit quaternion)."""
        q, v_checked = checked_state(self._plant, q, np.zeros(self._nv) if v is None else v, (self._nq, self._nv))
        return q, (None if v is None else v_checked)

    def _base_rotation(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R_Fw_F0, R_W_F0) from Drake's (normalised) quaternion q[0:4]."""
        R_FwM = quaternion_to_rotation(q[:4])
        return R_FwM, self._R_W_Fw @ R_FwM

    def _joint_transform(self, k: int, qk: float) -> np.ndarray:
        """jcalc: ``X_J = ^M X_F`` of joint k at position qk."""
        link = self._links[k]
        if link.kind == _REVOLUTE:
            return plucker(_rodrigues(link.axis, qk).T, np.zeros(3))
        return plucker(np.eye(3), qk * link.axis)

    def _tree_transforms(self, qj: np.ndarray) -> list:
        """``^k X_lambda(k) = X_J X_T(k)`` for every link (index 0 unused)."""
        Xup = [np.eye(6)] * (self._n + 1)
        for k in self._order:
            Xup[k] = self._joint_transform(k, qj[k - 1]) @ self._links[k].X_T
        return Xup

    # ------------------------------------------------------------------ Algorithms 1 and 2
    def _algorithm1(self, Xup, qdot, v0, a_g0):
        """Paper Algorithm 1: C^ (n,) and p^0c (6,)."""
        n, S, I, lam = self._n, self._S, self._I, self._parent
        vel = [None] * (n + 1)
        acc = [None] * (n + 1)
        f = [None] * (n + 1)
        vel[0] = v0
        acc[0] = -a_g0  # a_0^vp = -^0 a_g
        for i in self._order:
            vJ = S[i] * qdot[i - 1]
            vel[i] = Xup[i] @ vel[lam[i]] + vJ
            acc[i] = Xup[i] @ acc[lam[i]] + crm(vel[i]) @ vJ
            f[i] = I[i] @ acc[i] + crf(vel[i]) @ (I[i] @ vel[i])
        f[0] = I[0] @ acc[0] + crf(vel[0]) @ (I[0] @ vel[0])
        C_hat = np.zeros(n)
        for i in reversed(self._order):
            C_hat[i - 1] = S[i] @ f[i]
            f[lam[i]] = f[lam[i]] + Xup[i].T @ f[i]
        return C_hat, f[0]

    def _algorithm2(self, Xup, qdot):
        """Paper Algorithm 2: H, F, I0c and their time derivatives (all in F0 for F, I0c)."""
        n, S, lam = self._n, self._S, self._parent
        H = np.zeros((n, n))
        H_dot = np.zeros((n, n))
        F = np.zeros((6, n))
        F_dot = np.zeros((6, n))
        Xdot = [np.zeros((6, 6))] * (n + 1)
        Ic = [Ii.copy() for Ii in self._I]  # I_i^c = I_i, I_0^c = I_0
        Ic_dot = [np.zeros((6, 6)) for _ in range(n + 1)]
        for i in self._order:
            vJ = S[i] * qdot[i - 1]
            Xdot[i] = -crm(vJ) @ Xup[i]  # ^i Xdot_lambda(i) = -v_J x ^i X_lambda(i)
        for i in reversed(self._order):
            p, X, Xd = lam[i], Xup[i], Xdot[i]
            Ic[p] = Ic[p] + X.T @ Ic[i] @ X
            Ic_dot[p] = Ic_dot[p] + X.T @ Ic_dot[i] @ X + Xd.T @ Ic[i] @ X + X.T @ Ic[i] @ Xd
            Fi = Ic[i] @ S[i]
            Fi_dot = Ic_dot[i] @ S[i]
            H[i - 1, i - 1] = S[i] @ Fi
            H_dot[i - 1, i - 1] = S[i] @ Fi_dot
            j = i
            while lam[j] != 0:
                Fi_dot = Xup[j].T @ Fi_dot + Xdot[j].T @ Fi
                Fi = Xup[j].T @ Fi
                j = lam[j]
                H[i - 1, j - 1] = H[j - 1, i - 1] = S[j] @ Fi
                H_dot[i - 1, j - 1] = H_dot[j - 1, i - 1] = S[j] @ Fi_dot
            # Last line of Algorithm 2: express F_i (and its derivative) in frame 0.
            F_dot[:, i - 1] = Xup[j].T @ Fi_dot + Xdot[j].T @ Fi
            F[:, i - 1] = Xup[j].T @ Fi
        H[np.diag_indices(n)] += self._reflected
        return H, F, Ic[0], H_dot, F_dot, Ic_dot[0]

    # ------------------------------------------------------------------ public API
    def compute(self, q: np.ndarray, v: np.ndarray) -> FloatingBaseTerms:
        """Floating-base terms at Drake's state (q, v) (Algorithms 1-2, eqs. 9 and 13).

        Args:
            q: (7 + n,) Drake positions [quaternion w,x,y,z of F0; position of F0; joints].
                The quaternion is normalised here (its norm must be within
                ``systems.dynamics.base_state.QUATERNION_NORM_TOLERANCE`` of 1).
            v: (6 + n,) Drake velocities [w_WB_W; v_WBo_W; joint rates] (world-aligned; for
                a free joint whose parent frame is not the world frame, expressed in that
                parent frame, as Drake does).

        Raises:
            ValueError: wrong sizes, NaN or inf entries, or a non-unit quaternion.
        """
        q, v = self._validate(q, v)
        R_FwM, R_WB = self._base_rotation(q)
        v0 = np.concatenate((R_FwM.T @ v[0:3], R_FwM.T @ v[3:6]))
        a_g0 = np.concatenate((np.zeros(3), R_WB.T @ self._g_W))
        qj, qdot = q[7:], v[6:]
        Xup = self._tree_transforms(qj)
        C_hat, p_hat = self._algorithm1(Xup, qdot, v0, a_g0)
        H, F, I0c, H_dot, F_dot, I0c_dot = self._algorithm2(Xup, qdot)
        return reduce_to_floating_terms(H, F, I0c, C_hat, p_hat, H_dot, F_dot, I0c_dot, R_WB, v0)

    def floating_jacobian(self, q: np.ndarray, frame: Frame, p_FoP: np.ndarray, *, spatial: bool = False) -> np.ndarray:
        """Floating Jacobian J^fb of a point P fixed in ``frame`` (paper eq. 12).

        ``J^fb,T = J_{0,c}^T - F^T (I0c)^-1`` acts on the F0 spatial force ``^0X*_ref f``;
        this returns it composed with that transform, so that the joint effort of a force
        ``f_W`` (world coordinates) applied at P is ``tau = J^fb^T f_W``.

        Args:
            q: (7 + n,) Drake positions.
            frame: a frame of the plant fixed in a body of the floating-base tree (frames of
                welded bodies are fine).
            p_FoP: (3,) position of P in ``frame`` [m].
            spatial: if True, return the (6, n) Jacobian for a wrench ``[moment about P;
                force]`` in world coordinates (``tau = J^fb^T w``).

        Returns:
            (3, n), or (6, n) with ``spatial=True``.
        """
        q, _ = self._validate(q)
        p_FoP = np.asarray(p_FoP, dtype=float).reshape(-1)
        if p_FoP.shape != (3,) or not np.all(np.isfinite(p_FoP)):
            raise ValueError(f"p_FoP must be 3 finite numbers, got {p_FoP}")
        body = frame.body()
        if body.index() not in self._body_link:
            raise ValueError(
                f"frame '{frame.name()}' is on body '{body.name()}', which is not part of the floating-base tree"
            )
        link, X_LB = self._body_link[body.index()]
        X_BFr = frame.CalcPoseInBodyFrame(self._default_context)
        p_L = X_LB.multiply(X_BFr).multiply(p_FoP)

        _, R_WB = self._base_rotation(q)
        n, S, lam = self._n, self._S, self._parent
        Xup = self._tree_transforms(q[7:])
        # ^k X_0 for every link, parents first.
        X_k0 = [np.eye(6)] * (n + 1)
        for k in self._order:
            X_k0[k] = Xup[k] @ X_k0[lam[k]]
        # Pose of link L in F0 from ^L X_0 = [[E, 0], [-E r x, E]]: R_0L = E^T, p_0L = r.
        E = X_k0[link][:3, :3]
        r_cross = -E.T @ X_k0[link][3:, :3]
        p_0L = np.array([r_cross[2, 1], r_cross[0, 2], r_cross[1, 0]])
        p_0P = p_0L + E.T @ p_L

        # J_{0,c}: spatial velocity (in F0, at F0's origin) of the link carrying P w.r.t. F0.
        J0 = np.zeros((6, n))
        k = link
        while k != 0:
            X_0k = np.linalg.inv(X_k0[k])
            J0[:, k - 1] = X_0k @ S[k]
            k = lam[k]
        _, F, I0c, _, _, _ = self._algorithm2(Xup, np.zeros(n))
        G = J0 - np.linalg.solve(I0c, F)
        # ^0 f = Phi w for a world wrench w = [m_P; f] at P: Phi = [[R^T, p x R^T], [0, R^T]].
        Phi = np.zeros((6, 6))
        Phi[:3, :3] = R_WB.T
        Phi[3:, 3:] = R_WB.T
        Phi[:3, 3:] = skew(p_0P) @ R_WB.T
        J6 = Phi.T @ G
        return J6 if spatial else J6[3:, :]
