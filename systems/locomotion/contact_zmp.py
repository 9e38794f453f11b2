"""The measured ZMP of a walking robot from the plant's contact results (ground truth for
the walking metrics; no estimator reads it)."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from models import HumanoidHandles
from systems.common.contact_results import robot_point_contacts

#: Below this total normal force (N) the ZMP is undefined and reported as NaN.
MIN_NORMAL_FORCE = 0.5


class ContactZmp(LeafSystem):
    """ZMP (centre of pressure on the flat ground) from the plant's point-contact results.

    On flat ground at z = 0 the ZMP is the normal-force-weighted mean of the contact points:
    p_zmp = sum_i f_n,i p_i / sum_i f_n,i (m), f_n,i the ground's normal force on the
    robot at contact point p_i (world; ``systems.common.contact_results``' convention, on
    flat ground the world-z component).

    Inputs:
        contact_results: the plant's ContactResults (point contact).

    Outputs:
        zmp: (2) world x, y, m; NaN when the total normal force < MIN_NORMAL_FORCE.
        foot_normal_forces: (2) ground normal force on the left / right foot spheres, N.
        normal_force: (1) total ground normal force on the robot, N.
    """

    def __init__(self, plant: MultibodyPlant, humanoid: HumanoidHandles):
        super().__init__()
        self._robot = {g for ids in humanoid.collision_geometries.values() for g in ids}
        self._foot_of = {g: k for k, side in enumerate(("left", "right")) for g in humanoid.fsr_geometries[side]}
        self._contact = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self.DeclareVectorOutputPort("zmp", 2, self._CalcZmp)
        self.DeclareVectorOutputPort("foot_normal_forces", 2, self._CalcFootForces)
        self.DeclareVectorOutputPort("normal_force", 1, self._CalcNormalForce)

    def contacts(self, context: Context) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points (m, 3), normal forces on the robot (m,), foot index (m,), -1 if not a
        foot sphere) of the current contact results."""
        contacts = robot_point_contacts(self._contact.Eval(context), self._robot, "ContactZmp")
        foot = np.array([self._foot_of.get(g, -1) for g in contacts.geometries], dtype=int)
        return contacts.points, contacts.normal_forces, foot

    def _CalcZmp(self, context: Context, output: BasicVector) -> None:
        points, forces, _ = self.contacts(context)
        total = forces.sum()
        output.SetFromVector(forces @ points[:, :2] / total if total >= MIN_NORMAL_FORCE else np.full(2, np.nan))

    def _CalcFootForces(self, context: Context, output: BasicVector) -> None:
        _, forces, foot = self.contacts(context)
        output.SetFromVector(np.array([forces[foot == 0].sum(), forces[foot == 1].sum()]))

    def _CalcNormalForce(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector([self.contacts(context)[1].sum()])


__all__ = ["ContactZmp", "MIN_NORMAL_FORCE"]
