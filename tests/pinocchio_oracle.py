"""An independent Pinocchio model of a Drake floating-base plant (test oracle).

Built from the Drake plant's joints, frames and default spatial inertias, with Pinocchio's
own kinematics (no code shared with ``systems.dynamics.floating_base_reference``). Coordinates are
matched BY JOINT NAME through ``model.getJointId(name)``, ``idx_q`` and ``idx_v``.

Joints are added depth first: Pinocchio's CRBA assumes each subtree owns a contiguous block
of velocity indices (a breadth-first order silently gives a wrong mass matrix while rnea
stays right). Drake's actuator reflected inertia (rotor inertia x gear ratio^2, which Drake
adds to the mass matrix diagonal) becomes Pinocchio's ``model.armature``.

Pinocchio's conventions (pin 3.x/4.x) and how they map to ours:

* Free flyer: q = [x, y, z, qx, qy, qz, qw] (pose of the joint frame, = our F0, in the
  joint's parent placement), v = [v_local; w_local] (LINEAR first, both in F0). Ours are
  Drake's q = [qw, qx, qy, qz, x, y, z] and the base-frame v0 = [w_B; v_B] (ANGULAR first).
* Spatial forces/momenta are [linear; angular] in Pinocchio, [angular; linear] here.
* Free-flyer acceleration: Pinocchio's a for the free flyer is the spatial acceleration of
  the base expressed in the base frame, which equals the time derivative of the local
  velocity [v_local; w_local] (the base-frame coordinates of a spatial velocity have that
  property: d/dt(^B v) = ^B a - ^B v x ^B v = ^B a). So Pinocchio's a is exactly our a0 =
  d/dt v0 (reordered), and ``pin.rnea(q, v, 0)`` equals our [p^; C^] with NO extra term.
  Drake's world-aligned v_dot differs by [0; w_B x v_B] (see ``tests/test_floating_base_
  reference.py``, which verifies this numerically with ``pin.aba`` against Drake).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant


def _se3(X: RigidTransform) -> pin.SE3:
    return pin.SE3(np.array(X.rotation().matrix()), np.array(X.translation()))


def _pin_inertia(spatial_inertia) -> pin.Inertia:
    """Pinocchio inertia (about the body origin, body frame) from a Drake SpatialInertia."""
    mass = spatial_inertia.get_mass()
    com = np.array(spatial_inertia.get_com())
    I_about_com = spatial_inertia.Shift(com).CalcRotationalInertia().CopyToFullMatrix3()
    return pin.Inertia(mass, com, I_about_com)


@dataclass
class PinocchioOracle:
    """A Pinocchio model of a Drake plant plus the coordinate maps between the two.

    Attributes:
        model, data: Pinocchio model and data.
        plant: the Drake plant.
        free_joint_name: name of the free joint (same name in both).
        perm: index array with ``x_ours = x_pin[perm]`` for any velocity-space vector, where
            ours = [w_B; v_B; joints in Drake velocity order].
        body_placement: Drake body index -> (pinocchio joint id, SE3 of the body in the
            joint frame).
    """

    model: pin.Model
    data: pin.Data
    plant: MultibodyPlant
    free_joint_name: str
    perm: np.ndarray
    body_placement: dict
    R_W_Fw: np.ndarray

    # ------------------------------------------------------------ state conversion
    def to_pinocchio(self, q_drake: np.ndarray, v_drake: np.ndarray):
        """Drake (q, v) -> Pinocchio (q, v), mapped by joint name."""
        plant, model = self.plant, self.model
        q = np.zeros(model.nq)
        v = np.zeros(model.nv)
        for index in plant.GetJointIndices():
            joint = plant.get_joint(index)
            if joint.num_velocities() == 0:
                continue
            jm = model.joints[model.getJointId(joint.name())]
            qs, vs = joint.position_start(), joint.velocity_start()
            if joint.type_name() == "quaternion_floating":
                wxyz = q_drake[qs : qs + 4] / np.linalg.norm(q_drake[qs : qs + 4])
                q[jm.idx_q : jm.idx_q + 3] = q_drake[qs + 4 : qs + 7]
                q[jm.idx_q + 3 : jm.idx_q + 7] = [wxyz[1], wxyz[2], wxyz[3], wxyz[0]]
                R_FM = pin.Quaternion(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).toRotationMatrix()
                v[jm.idx_v : jm.idx_v + 3] = R_FM.T @ v_drake[vs + 3 : vs + 6]
                v[jm.idx_v + 3 : jm.idx_v + 6] = R_FM.T @ v_drake[vs : vs + 3]
            else:
                q[jm.idx_q] = q_drake[qs]
                v[jm.idx_v] = v_drake[vs]
        return q, v

    def vector_to_ours(self, x_pin: np.ndarray) -> np.ndarray:
        """Velocity/force-space vector from Pinocchio's order to ours."""
        return np.asarray(x_pin)[self.perm]

    def matrix_to_ours(self, A_pin: np.ndarray) -> np.ndarray:
        """nv x nv matrix (mass matrix, C, ...) from Pinocchio's coordinates to ours."""
        return np.asarray(A_pin)[np.ix_(self.perm, self.perm)]

    def momentum_matrix_to_ours(self, A_pin: np.ndarray) -> np.ndarray:
        """6 x nv momentum matrix ([linear; angular] rows) to ours ([angular; linear] rows)."""
        return np.asarray(A_pin)[np.ix_([3, 4, 5, 0, 1, 2], self.perm)]

    # ------------------------------------------------------------ quantities in our order
    def mass_matrix(self, q_pin):
        M = pin.crba(self.model, self.data, q_pin)
        M = np.triu(M) + np.triu(M, 1).T
        return self.matrix_to_ours(M)

    def bias(self, q_pin, v_pin):
        """C v + g at zero acceleration (pin.rnea), in our order."""
        tau = pin.rnea(self.model, self.data, q_pin, v_pin, np.zeros(self.model.nv))
        return self.vector_to_ours(tau)

    def gravity(self, q_pin):
        return self.vector_to_ours(pin.computeGeneralizedGravity(self.model, self.data, q_pin))

    def mass_matrix_derivative(self, q_pin, v_pin):
        """dM/dt = C + C^T (pin.computeCoriolisMatrix), in our order."""
        C = pin.computeCoriolisMatrix(self.model, self.data, q_pin, v_pin)
        return self.matrix_to_ours(C + C.T)

    def centroidal(self, q_pin, v_pin):
        """(Ag, dAg/dt) with rows [angular; linear] about the CoM in world-aligned axes."""
        Ag = pin.ccrba(self.model, self.data, q_pin, v_pin).copy()
        pin.dccrba(self.model, self.data, q_pin, v_pin)
        dAg = np.array(self.data.dAg).copy()
        return self.momentum_matrix_to_ours(Ag), self.momentum_matrix_to_ours(dAg)

    def forward_dynamics(self, q_pin, v_pin, tau_ours=None):
        """pin.aba with joint torques (ours order, base entries zero), result in our order."""
        tau_pin = np.zeros(self.model.nv)
        if tau_ours is not None:
            tau_pin[self.perm] = tau_ours
        return self.vector_to_ours(pin.aba(self.model, self.data, q_pin, v_pin, tau_pin))


def build_pinocchio_oracle(plant: MultibodyPlant) -> PinocchioOracle:
    """Builds the Pinocchio model of a finalized Drake floating-base plant."""
    ctx = plant.CreateDefaultContext()
    model = pin.Model()
    model.gravity = pin.Motion(np.concatenate((plant.gravity_field().gravity_vector(), np.zeros(3))))
    world = plant.world_body().index()

    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    free = [j for j in joints if j.type_name() == "quaternion_floating"]
    assert len(free) == 1, "the oracle handles exactly one free joint"
    free = free[0]
    X_W_Fw = free.frame_on_parent().CalcPoseInWorld(ctx)
    ff_id = model.addJoint(0, pin.JointModelFreeFlyer(), _se3(X_W_Fw), free.name())
    base = free.child_body()
    # Body placement in its Pinocchio joint frame: base body in frame M of the free joint.
    X_B_M = free.frame_on_child().CalcPoseInBodyFrame(ctx)
    placements = {base.index(): (ff_id, _se3(X_B_M.inverse()))}
    model.appendBodyToJoint(ff_id, _pin_inertia(base.CalcSpatialInertiaInBodyFrame(ctx)), placements[base.index()][1])

    # Pinocchio's CRBA assumes every subtree owns a contiguous block of velocities, so
    # joints are added depth first (a breadth-first order gives a wrong mass matrix).
    children: dict = {}
    for joint in joints:
        if joint.index() != free.index() and joint.parent_body().index() != world:
            children.setdefault(joint.parent_body().index(), []).append(joint)

    def add_subtree(body_index):
        for joint in children.get(body_index, []):
            parent_id, X_Jp_P = placements[body_index]
            X_P_F = _se3(joint.frame_on_parent().CalcPoseInBodyFrame(ctx))
            X_C_M = _se3(joint.frame_on_child().CalcPoseInBodyFrame(ctx))
            child = joint.child_body()
            inertia = _pin_inertia(child.CalcSpatialInertiaInBodyFrame(ctx))
            kind = joint.type_name()
            if kind == "weld":
                X_Jp_C = X_Jp_P * X_P_F * _se3(joint.X_FM()) * X_C_M.inverse()
                placements[child.index()] = (parent_id, X_Jp_C)
                model.appendBodyToJoint(parent_id, inertia, X_Jp_C)
            else:
                if kind == "revolute":
                    jmodel = pin.JointModelRevoluteUnaligned(np.array(joint.revolute_axis()))
                elif kind == "prismatic":
                    jmodel = pin.JointModelPrismaticUnaligned(np.array(joint.translation_axis()))
                else:
                    raise ValueError(f"oracle: unsupported joint type {kind}")
                jid = model.addJoint(parent_id, jmodel, X_Jp_P * X_P_F, joint.name())
                placements[child.index()] = (jid, X_C_M.inverse())
                model.appendBodyToJoint(jid, inertia, X_C_M.inverse())
            add_subtree(child.index())

    add_subtree(base.index())
    if model.nv != plant.num_velocities():
        raise ValueError("oracle: some joints are not reachable from the floating base")

    # Actuator reflected inertia (Drake adds it to the mass matrix diagonal) = armature.
    armature = np.array(model.armature).copy()
    for actuator_index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(actuator_index)
        jm = model.joints[model.getJointId(actuator.joint().name())]
        armature[jm.idx_v] += actuator.calc_reflected_inertia(ctx)
    model.armature = armature

    # Velocity permutation, by joint name.
    ff = model.joints[model.getJointId(free.name())]
    perm = np.zeros(plant.num_velocities(), dtype=int)
    perm[0:3] = np.arange(ff.idx_v + 3, ff.idx_v + 6)  # angular
    perm[3:6] = np.arange(ff.idx_v, ff.idx_v + 3)  # linear
    for joint in joints:
        if joint.num_velocities() == 1:
            perm[joint.velocity_start()] = model.joints[model.getJointId(joint.name())].idx_v
    assert sorted(perm.tolist()) == list(range(model.nv))
    return PinocchioOracle(
        model=model,
        data=model.createData(),
        plant=plant,
        free_joint_name=free.name(),
        perm=perm,
        body_placement=placements,
        R_W_Fw=np.array(X_W_Fw.rotation().matrix()),
    )
