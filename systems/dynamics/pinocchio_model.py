"""A Pinocchio model built from a Drake floating-base plant (the plant stays the one model).

``pinocchio_model_from_plant`` rebuilds the plant's tree with Pinocchio's own joints: its
joints (placements, axes), frames and spatial inertias (the plant's defaults, or those of a
given context), and, optionally, the actuators' reflected rotor inertia as Pinocchio's
``model.armature`` (Drake adds it to the mass matrix diagonal). Nothing is read from a file.

Pinocchio's conventions (pin 3.x/4.x) against Drake's and the project's:

* Free flyer: q = [x, y, z, qx, qy, qz, qw] (pose of the free joint's child frame, = the
  project's F0, in the joint's parent placement), v = [v_B; w_B] (LINEAR first, both in F0).
  Drake: q = [qw, qx, qy, qz, x, y, z], v = [w; v] expressed in the joint's parent frame.
* Spatial forces are [force; moment] in Pinocchio, [moment; force] in the project.
* Joints are added depth first: Pinocchio's CRBA needs every subtree's velocities
  contiguous (a breadth-first order gives a wrong mass matrix while ``rnea`` stays right).
* Every plant frame on a moving body becomes a Pinocchio frame of the same name (the first
  of several frames of one name keeps it; the others get ``name#<Drake frame index>``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FrameIndex, SpatialInertia
from pydrake.systems.framework import Context


def _se3(X: RigidTransform) -> pin.SE3:
    return pin.SE3(np.array(X.rotation().matrix()), np.array(X.translation()))


def pinocchio_inertia(M_BBo_B: SpatialInertia) -> pin.Inertia:
    """Pinocchio's inertia of a body (about its origin, in its frame) from Drake's M_BBo_B
    (mass kg, centre of mass m, rotational inertia kg m^2)."""
    com = np.array(M_BBo_B.get_com())
    return pin.Inertia(M_BBo_B.get_mass(), com, M_BBo_B.Shift(com).CalcRotationalInertia().CopyToFullMatrix3())


@dataclass
class PlantPinocchioModel:
    """A Pinocchio model of a Drake plant and where the plant's bodies and frames are in it.

    Attributes:
        model: the Pinocchio model (free-flyer root joint, the plant's gravity).
        free_joint_name: the plant's free joint, the free flyer's name.
        bodies: Drake body index -> (Pinocchio joint id, X_JB: the body's pose in that joint's frame).
        body_inertias: Drake body index -> its Pinocchio inertia in its own frame.
        frames: Drake frame index -> Pinocchio frame id.
    """

    model: pin.Model
    free_joint_name: str
    bodies: dict[int, tuple[int, pin.SE3]]
    body_inertias: dict[int, pin.Inertia]
    frames: dict[int, int]

    def set_body_inertias(self, inertias: Mapping[int, pin.Inertia]) -> None:
        """Replaces the inertias of the given bodies ({Drake body index: inertia in the body
        frame}) and recomputes the joints' inertias (the sum of their bodies', ``X_JB.act``)."""
        unknown = [int(i) for i in inertias if int(i) not in self.bodies]
        if unknown:
            raise ValueError(f"bodies {unknown} are not on the floating tree of the Pinocchio model")
        self.body_inertias.update({int(i): Y for i, Y in inertias.items()})
        joint_ids = {self.bodies[int(i)][0] for i in inertias}
        totals = {jid: pin.Inertia.Zero() for jid in joint_ids}
        for body, (jid, X_JB) in self.bodies.items():
            if jid in totals:
                totals[jid] += X_JB.act(self.body_inertias[body])
        for jid, Y in totals.items():
            self.model.inertias[jid] = Y


def pinocchio_model_from_plant(
    plant: MultibodyPlant,
    *,
    reflected_inertia: bool = True,
    context: Context | None = None,
    reverse_siblings: bool = False,
) -> PlantPinocchioModel:
    """The Pinocchio model of a finalized Drake plant with one quaternion free joint and
    otherwise revolute, prismatic and weld joints.

    Args:
        plant: the finalized plant.
        reflected_inertia: True to set ``model.armature`` to the actuators' reflected rotor
            inertia (``plant_joint_parameters``); False leaves it zero.
        context: the plant context whose parameters (inertias, reflected inertias) are read;
            the plant's defaults if None.
        reverse_siblings: False adds the child joints of a body in the plant's joint order,
            True in reverse (another valid depth-first order: Pinocchio's joint order then
            differs from the plant's).

    Raises:
        ValueError: another joint type, not exactly one free joint, or a joint that is not
            on the floating tree.
    """
    ctx = context if context is not None else plant.CreateDefaultContext()
    model = pin.Model()
    model.gravity = pin.Motion(np.concatenate((plant.gravity_field().gravity_vector(), np.zeros(3))))
    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    free = [j for j in joints if j.type_name() == "quaternion_floating"]
    if len(free) != 1:
        raise ValueError(
            f"pinocchio_model_from_plant: the plant needs exactly one quaternion free joint, got {len(free)}"
        )
    (free,) = free
    root = model.addJoint(0, pin.JointModelFreeFlyer(), _se3(free.frame_on_parent().CalcPoseInWorld(ctx)), free.name())
    base = free.child_body()
    bodies = {int(base.index()): (root, _se3(free.frame_on_child().CalcPoseInBodyFrame(ctx)).inverse())}
    inertias: dict[int, pin.Inertia] = {}

    def append(body, jid: int, X_JB: pin.SE3) -> None:
        bodies[int(body.index())] = (jid, X_JB)
        inertias[int(body.index())] = pinocchio_inertia(body.CalcSpatialInertiaInBodyFrame(ctx))
        model.appendBodyToJoint(jid, inertias[int(body.index())], X_JB)

    append(base, *bodies[int(base.index())])
    children: dict = {}
    for joint in joints:
        if joint is not free and joint.parent_body().index() != plant.world_body().index():
            children.setdefault(int(joint.parent_body().index()), []).append(joint)

    def add_subtree(body_index: int) -> None:  # depth first
        siblings = children.get(body_index, [])
        for joint in reversed(siblings) if reverse_siblings else siblings:
            parent, X_JP = bodies[body_index]
            X_JF = X_JP * _se3(joint.frame_on_parent().CalcPoseInBodyFrame(ctx))
            X_MC = _se3(joint.frame_on_child().CalcPoseInBodyFrame(ctx)).inverse()
            child = joint.child_body()
            if joint.type_name() == "weld":
                append(child, parent, X_JF * _se3(joint.X_FM()) * X_MC)
            else:
                if joint.type_name() == "revolute":
                    kind = pin.JointModelRevoluteUnaligned(np.array(joint.revolute_axis()))
                elif joint.type_name() == "prismatic":
                    kind = pin.JointModelPrismaticUnaligned(np.array(joint.translation_axis()))
                else:
                    raise ValueError(f"pinocchio_model_from_plant: unsupported joint type {joint.type_name()}")
                append(child, model.addJoint(parent, kind, X_JF, joint.name()), X_MC)
            add_subtree(int(child.index()))

    add_subtree(int(base.index()))
    if model.nv != plant.num_velocities():
        raise ValueError("pinocchio_model_from_plant: some joints are not reachable from the floating base")
    frames = {}
    for index in range(plant.num_frames()):
        frame = plant.get_frame(FrameIndex(index))
        body = int(frame.body().index())
        if body in bodies:
            jid, X_JB = bodies[body]
            name = frame.name() if not model.existFrame(frame.name()) else f"{frame.name()}#{index}"
            X_JFr = X_JB * _se3(frame.CalcPoseInBodyFrame(ctx))
            frames[index] = model.addFrame(pin.Frame(name, jid, X_JFr, pin.FrameType.OP_FRAME))
    if reflected_inertia:
        set_joint_parameters(model, plant_joint_parameters(plant, ctx)[0], None)
    return PlantPinocchioModel(model, free.name(), bodies, inertias, frames)


def set_joint_parameters(
    model: pin.Model, armature: Mapping[str, float] | None, damping: Mapping[str, float] | None
) -> np.ndarray:
    """Sets ``model.armature`` (kg m^2 or kg) and ``model.damping`` (N m s/rad or N s/m) of
    the named 1-DoF joints ({joint name: value}); returns the damping of the n joints in
    Pinocchio's joint order."""
    for name, value in (armature or {}).items():
        model.armature[model.joints[model.getJointId(name)].idx_v] = value
    for name, value in (damping or {}).items():
        model.damping[model.joints[model.getJointId(name)].idx_v] = value
    return np.array(model.damping[6:], dtype=float)


def plant_joint_parameters(
    plant: MultibodyPlant, context: Context | None = None
) -> tuple[dict[str, float], dict[str, float]]:
    """({joint: reflected rotor inertia}, {joint: viscous damping}) of the plant's 1-DoF
    joints: what Drake adds to the mass matrix's diagonal (kg m^2 or kg), and the project
    residuals' default friction model (N m s/rad or N s/m)."""
    ctx = context if context is not None else plant.CreateDefaultContext()
    armature = {}
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        armature[actuator.joint().name()] = actuator.calc_reflected_inertia(ctx)
    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    damping = {j.name(): float(j.default_damping()) for j in joints if j.num_velocities() == 1}
    return armature, damping
