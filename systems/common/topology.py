"""Checks that a MultibodyPlant is a single floating-base tree of 1-DoF joints.

Every floating-base algorithm of this package (paper eq. 9, Algorithms 1-2) assumes:

* exactly one free (6-DoF, quaternion) joint, connecting the world to the base body;
* every other degree of freedom belongs to a 1-DoF joint (revolute or prismatic) of the
  tree hanging from that base; weld joints are allowed anywhere;
* the free joint's coordinates come first: q = [q_w, q_x, q_y, q_z, x, y, z, joints...],
  v = [w_WB_W, v_WBo_W, joints...].

``floating_base_topology`` raises ``ValueError`` with a message that names the problem when
any of these does not hold, so that no algorithm ever returns a silently wrong answer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, Frame, Joint, ModelInstanceIndex, RigidBody

#: Joint type names (``Joint.type_name()``) accepted as the tree's 1-DoF joints.
ONE_DOF_JOINT_TYPES = ("revolute", "prismatic")
#: Zero-DoF joints accepted anywhere in the tree.
WELD_JOINT_TYPE = "weld"
#: The only accepted floating joint.
FREE_JOINT_TYPE = "quaternion_floating"


@dataclass(frozen=True)
class FloatingBaseTopology:
    """What the floating-base algorithms need to know about a plant's tree.

    Attributes:
        free_joint: the quaternion floating joint between the world and the base body.
        base_body: the floating base body.
        base_frame: F0, the free joint's child frame (the base body frame by default).
        joints: the 1-DoF joints ordered by velocity index (joints[k] owns v[6 + k]).
        num_joints: n, the number of joint coordinates (nv - 6).
    """

    free_joint: Joint
    base_body: RigidBody
    base_frame: Frame
    joints: tuple[Joint, ...]
    num_joints: int


def floating_base_topology(plant: MultibodyPlant) -> FloatingBaseTopology:
    """Validates ``plant`` (see the module docstring) and returns its floating-base topology.

    Raises:
        ValueError: the plant is not finalized, has no floating base, has more than one, has
            a joint with more than one degree of freedom besides the free joint (ball,
            planar, universal, ...), or an RPY floating joint.
    """
    if not plant.is_finalized():
        raise ValueError("the MultibodyPlant must be finalized before its floating-base dynamics can be built")

    free_joints: list[Joint] = []
    one_dof: list[Joint] = []
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        type_name = joint.type_name()
        if type_name == FREE_JOINT_TYPE:
            free_joints.append(joint)
        elif type_name in ONE_DOF_JOINT_TYPES:
            one_dof.append(joint)
        elif type_name == WELD_JOINT_TYPE:
            continue
        else:
            raise ValueError(
                f"joint '{joint.name()}' is a '{type_name}' joint with {joint.num_velocities()} "
                "degrees of freedom; the floating-base dynamics accept only one quaternion "
                f"floating joint plus {', '.join(ONE_DOF_JOINT_TYPES)} and weld joints"
            )

    if not free_joints:
        raise ValueError(
            "the plant has no floating base: no body is connected to the world by a free "
            "(quaternion floating) joint; is the robot's root welded to the world?"
        )
    if len(free_joints) > 1:
        names = ", ".join(f"'{j.child_body().name()}'" for j in free_joints)
        raise ValueError(
            f"the plant has {len(free_joints)} floating bases ({names}); the floating-base dynamics need exactly one"
        )
    free_joint = free_joints[0]
    if free_joint.parent_body().index() != plant.world_body().index():
        raise ValueError(f"the free joint '{free_joint.name()}' must connect the world to the base body")
    if free_joint.position_start() != 0 or free_joint.velocity_start() != 0:
        raise ValueError(
            f"the free joint '{free_joint.name()}' must own the first coordinates "
            f"(position_start={free_joint.position_start()}, velocity_start={free_joint.velocity_start()})"
        )

    base_body = free_joint.child_body()
    base_subtree = set(_subtree_bodies(plant, base_body))
    for joint in one_dof:
        if joint.child_body().index() not in base_subtree:
            raise ValueError(
                f"joint '{joint.name()}' moves body '{joint.child_body().name()}', which does not "
                f"hang from the floating base '{base_body.name()}'; every degree of freedom must "
                "belong to the floating-base tree"
            )

    joints = tuple(sorted(one_dof, key=lambda j: j.velocity_start()))
    starts = [j.velocity_start() for j in joints]
    if starts != list(range(6, 6 + len(joints))):
        raise ValueError(f"unexpected joint velocity layout {starts}; expected 6..{5 + len(joints)}")
    return FloatingBaseTopology(
        free_joint=free_joint,
        base_body=base_body,
        base_frame=free_joint.frame_on_child(),
        joints=joints,
        num_joints=len(joints),
    )


def _subtree_bodies(plant: MultibodyPlant, root: RigidBody) -> list:
    """Indices of the bodies in the subtree rooted at ``root`` (``root`` included)."""
    children: dict = {}
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        children.setdefault(joint.parent_body().index(), []).append(joint.child_body().index())
    out, stack = [], [root.index()]
    while stack:
        body = stack.pop()
        out.append(body)
        stack.extend(children.get(body, []))
    return out


def uniform_gravity(plant: MultibodyPlant) -> np.ndarray:
    """The plant's gravity vector in world [m/s^2]; refuses gravity disabled per model."""
    field = plant.gravity_field()
    for index in range(plant.num_model_instances()):
        if not field.is_enabled(ModelInstanceIndex(index)):
            raise ValueError(
                f"gravity is disabled for model instance '{plant.GetModelInstanceName(ModelInstanceIndex(index))}'; "
                "the floating-base dynamics assume uniform gravity on every body"
            )
    return np.asarray(field.gravity_vector(), dtype=float).copy()


def same_rigid_link(rigid_link: np.ndarray, body_a: int, body_b: int) -> bool:
    """Whether two BodyIndex values (-1: none) are one rigid link of ``rigid_link``
    (``rigid_link_of_bodies``): the same body, or welded to each other."""
    return body_a >= 0 and body_b >= 0 and bool(rigid_link[int(body_a)] == rigid_link[int(body_b)])


def rigid_link_of_bodies(plant: MultibodyPlant) -> np.ndarray:
    """(num_bodies,) int: for each BodyIndex, the smallest BodyIndex of the bodies welded to it
    (``GetBodiesWeldedTo``): bodies joined by weld joints (a URDF's fixed joints, e.g. a
    gripper's fingers fixed in a reduced model) move as one rigid link, on which no joint
    effort can tell one from another. A finalized plant."""
    link = np.arange(plant.num_bodies())
    for index in range(plant.num_bodies()):
        welded = plant.GetBodiesWeldedTo(plant.get_body(BodyIndex(index)))
        link[index] = min(int(b.index()) for b in welded)
    return link
