"""Random floating-base kinematic trees built programmatically in Drake (test fixtures).

``make_random_floating_tree`` returns a finalized MultibodyPlant (no SceneGraph) whose root
body floats, with revolute and prismatic joints on random unit axes, random offset frames on
both sides of every joint, weld joints with offsets (welded bodies can carry further joints)
and random physically valid spatial inertias.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    RotationalInertia,
    SpatialInertia,
    WeldJoint,
)


def random_rotation(rng: np.random.Generator) -> RotationMatrix:
    """A uniformly distributed rotation."""
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    return RotationMatrix(Quaternion(quat))


def random_transform(rng: np.random.Generator, scale: float = 0.3) -> RigidTransform:
    """A random pose: uniform rotation, translation with components in [-scale, scale]."""
    return RigidTransform(random_rotation(rng), rng.uniform(-scale, scale, size=3))


def random_spatial_inertia(rng: np.random.Generator) -> SpatialInertia:
    """A random valid spatial inertia about the body origin (central inertia from random
    principal moments that satisfy the triangle inequality, in random principal axes)."""
    mass = rng.uniform(0.2, 5.0)
    com = rng.uniform(-0.15, 0.15, size=3)
    while True:
        moments = rng.uniform(0.002, 0.1, size=3)
        a, b, c = moments
        if a + b > 1.05 * c and b + c > 1.05 * a and a + c > 1.05 * b:
            break
    R = random_rotation(rng).matrix()
    I_com = R @ np.diag(moments) @ R.T
    I_com = 0.5 * (I_com + I_com.T)
    rot = RotationalInertia(I_com[0, 0], I_com[1, 1], I_com[2, 2], I_com[0, 1], I_com[0, 2], I_com[1, 2])
    return SpatialInertia.MakeFromCentralInertia(mass, com, rot)


def _unit(rng: np.random.Generator) -> np.ndarray:
    axis = rng.normal(size=3)
    return axis / np.linalg.norm(axis)


def make_random_floating_tree(
    num_joints: int,
    seed: int,
    *,
    prismatic_fraction: float = 0.2,
    weld_fraction: float = 0.1,
    gravity: bool = True,
    explicit_free_joint: bool | None = None,
    shape: str | None = None,
):
    """Builds a random floating-base tree with ``num_joints`` 1-DoF joints (plus welds).

    Args:
        num_joints: number of revolute/prismatic joints, 0..60 or more.
        seed: random seed (the same seed gives the same plant).
        prismatic_fraction: probability that a 1-DoF joint is prismatic.
        weld_fraction: probability that an added body is welded (not counted in num_joints).
        gravity: if False, the plant's gravity is zero.
        explicit_free_joint: if True, add a QuaternionFloatingJoint between random offset
            frames on the world and the base body; if False, let Drake add the free joint at
            Finalize(); if None, decide from the seed.
        shape: "chain" (every body on the previous one), "long" (mostly chain-like), "wide"
            (uniformly random earlier parent), "mixed"; None decides from the seed.

    Returns:
        (plant, context): the finalized plant and a default context.
    """
    rng = np.random.default_rng(seed)
    if explicit_free_joint is None:
        explicit_free_joint = bool(rng.integers(2))
    plant = MultibodyPlant(time_step=0.0)
    if not gravity:
        plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])

    base = plant.AddRigidBody("base", random_spatial_inertia(rng))
    bodies = [base]
    if explicit_free_joint:
        F = plant.AddFrame(FixedOffsetFrame("world_offset", plant.world_frame(), random_transform(rng, 1.0)))
        M = plant.AddFrame(FixedOffsetFrame("base_offset", base.body_frame(), random_transform(rng)))
        plant.AddJoint(QuaternionFloatingJoint("free", F, M))

    shapes = ("long", "wide", "mixed")
    if shape is None:
        shape = shapes[int(rng.integers(3))]
    if shape not in shapes + ("chain",):
        raise ValueError(f"unknown tree shape {shape!r}")
    added = 0
    welds = 0
    while added < num_joints:
        if shape == "chain":
            parent = bodies[-1]
        elif shape == "long":
            parent = bodies[-1] if rng.uniform() < 0.85 else bodies[rng.integers(len(bodies))]
        elif shape == "wide":
            parent = bodies[rng.integers(len(bodies))]
        else:
            parent = bodies[-1] if rng.uniform() < 0.5 else bodies[rng.integers(len(bodies))]
        name = f"body{len(bodies)}"
        child = plant.AddRigidBody(name, random_spatial_inertia(rng))
        F = plant.AddFrame(FixedOffsetFrame(f"{name}_F", parent.body_frame(), random_transform(rng)))
        M = plant.AddFrame(FixedOffsetFrame(f"{name}_M", child.body_frame(), random_transform(rng)))
        u = rng.uniform()
        if u < weld_fraction:
            plant.AddJoint(WeldJoint(f"weld{welds}", F, M, random_transform(rng, 0.1)))
            welds += 1
        elif u < weld_fraction + (1.0 - weld_fraction) * prismatic_fraction:
            plant.AddJoint(PrismaticJoint(f"joint{added}", F, M, _unit(rng)))
            added += 1
        else:
            plant.AddJoint(RevoluteJoint(f"joint{added}", F, M, _unit(rng)))
            added += 1
        bodies.append(child)
    plant.Finalize()
    return plant, plant.CreateDefaultContext()


def random_state(plant: MultibodyPlant, rng: np.random.Generator, *, scale: float = 1.0):
    """Random (q, v): unit base quaternion, position, joint positions in [-pi, pi] (revolute)
    or [-0.3, 0.3] m (prismatic), velocities ~ N(0, scale^2)."""
    q = np.zeros(plant.num_positions())
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        start, count = joint.position_start(), joint.num_positions()
        if joint.type_name() == "quaternion_floating":
            quat = rng.normal(size=4)
            q[start : start + 4] = quat / np.linalg.norm(quat)
            q[start + 4 : start + 7] = rng.uniform(-1.0, 1.0, size=3)
        elif joint.type_name() == "revolute":
            q[start : start + count] = rng.uniform(-np.pi, np.pi, size=count)
        elif joint.type_name() == "prismatic":
            q[start : start + count] = rng.uniform(-0.3, 0.3, size=count)
    v = scale * rng.normal(size=plant.num_velocities())
    return q, v
