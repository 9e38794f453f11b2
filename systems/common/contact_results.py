"""One reader of Drake's point-contact results, with one convention for every consumer.

Convention: for each point pair that involves a robot geometry, the **normal force on the
robot**, f_n = -f_Bc_W · n_BA_W (N, >= 0 for a compressive contact): the component of the
force the other geometry applies to the robot along the contact normal pointing out of the
other geometry into the robot. ``f_Bc_W`` is Drake's force on geometry B at the contact
point (world), ``n_BA_W`` its normal from B into A; the formula is the same whether the
robot geometry is A or B. On flat ground (normal = world z) f_n is the world-z component
of the ground's force on the robot, to the bit (the normal's x, y entries are exact zeros).
"""

from __future__ import annotations

from collections.abc import Container, Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import ContactResults


@dataclass(frozen=True)
class RobotPointContacts:
    """The robot's point contacts of one ContactResults, in Drake's pair order.

    Attributes:
        points: (m, 3) contact points, world, m.
        normal_forces: (m,) f_n, the normal force on the robot (module docstring), N.
        geometries: the robot geometry (GeometryId) of each contact.
    """

    points: np.ndarray
    normal_forces: np.ndarray
    geometries: tuple

    def summed(self, slot_of: Mapping, size: int) -> np.ndarray:
        """(size,) the normal forces summed per slot, ``slot_of`` mapping a geometry to its
        slot (e.g. FSR index or foot); geometries not in ``slot_of`` are left out. N."""
        out = np.zeros(size)
        for g, f in zip(self.geometries, self.normal_forces.tolist()):
            k = slot_of.get(g)
            if k is not None:
                out[k] += f
        return out


def robot_point_contacts(
    results: ContactResults, robot_geometries: Container, who: str = "robot_point_contacts"
) -> RobotPointContacts:
    """The point contacts of ``results`` in which a geometry of ``robot_geometries`` takes
    part (a pair of two robot geometries is read from geometry A's side), with f_n by the
    module's convention.

    Raises:
        ValueError: naming ``who``: a hydroelastic contact on a robot geometry (only point
            contact is read).
    """
    points, forces, geometries = [], [], []
    for c in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(c)
        pair = info.point_pair()
        if pair.id_A in robot_geometries:
            geometries.append(pair.id_A)
        elif pair.id_B in robot_geometries:
            geometries.append(pair.id_B)
        else:
            continue
        points.append(info.contact_point())
        forces.append(-float(np.dot(info.contact_force(), pair.nhat_BA_W)))
    for c in range(results.num_hydroelastic_contacts()):
        surface = results.hydroelastic_contact_info(c).contact_surface()
        if surface.id_M() in robot_geometries or surface.id_N() in robot_geometries:
            raise ValueError(
                f"{who}: hydroelastic contact on a robot geometry is not supported; use point contact for it"
            )
    return RobotPointContacts(
        np.array(points, dtype=float).reshape(-1, 3), np.array(forces, dtype=float), tuple(geometries)
    )
