"""Ground truth of the observer experiments: the virtual force (Hawley et al. 2019, eq. 11)
of the applied external forces, from the TRUE state (for the loggers and metrics only; no
estimator reads it)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from models import HumanoidHandles
from systems.common.checks import eval_finite_input


class VirtualForceTruth(LeafSystem):
    """Ground-truth virtual force (paper eq. 11) of the applied external wrench.

    An external force F applied at a point P of the robot moves the ZMP as the same force
    plus the moment tau = (p_P - p_Cm) x F about the CoM would (eqs. 8-10). Seen from the
    ZMP, that is the virtual force F^ = [F_x + tau_y / z_c, F_y - tau_x / z_c, F_z] applied
    at the CoM of the LIP (eq. 11), z_c being the CoM height above the ground plane in
    which the ZMP lies (the support-foot frame's z). A horizontal force at height h thus
    counts as F_x h / z_c: above the CoM it moves the ZMP more than at the CoM; a vertical
    load at a horizontal offset d from the CoM adds a horizontal virtual force -d F_z / z_c.
    At static equilibrium this is exact for the multibody robot (moments about the CoP);
    during motion the LIP neglects the rate of angular momentum.

    Inputs:
        state: the TRUE plant state [q; v].
        total_wrench_world: (6) [moment about the world origin, N m; force, N], world
            (``PushSource.total_wrench_world``).

    Outputs:
        virtual_force: (3) F^ in the world-aligned support-foot frame, N.
        com_position: (3) the true CoM in the support-foot frame F, m (for checks).
        com_world: (3) the true CoM in world, m (to draw the virtual force).
    """

    def __init__(self, plant: MultibodyPlant, handles: HumanoidHandles, *, support_foot: str = "right"):
        super().__init__()
        if support_foot not in handles.sole_frames:
            raise ValueError(f"VirtualForceTruth: unknown support foot {support_foot!r}")
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._support = handles.sole_frames[support_foot]
        self._instances = [handles.model_instance]
        self._nq = plant.num_positions()
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self._wrench = self.DeclareVectorInputPort("total_wrench_world", 6)
        self.DeclareVectorOutputPort("virtual_force", 3, self._CalcVirtualForce)
        self.DeclareVectorOutputPort("com_position", 3, self._CalcComPosition)
        self.DeclareVectorOutputPort("com_world", 3, self._CalcComWorld)

    def _com(self, context: Context) -> tuple[np.ndarray, np.ndarray]:
        x = eval_finite_input("VirtualForceTruth", self._state, context)
        self._plant.SetPositions(self._plant_context, x[: self._nq])
        p_WCm = self._plant.CalcCenterOfMassPositionInWorld(self._plant_context, self._instances)
        return p_WCm, self._support.CalcPoseInWorld(self._plant_context).translation()

    @staticmethod
    def virtual_force(wrench_world: np.ndarray, p_WCm: np.ndarray, ground_height: float) -> np.ndarray:
        """Eq. (11) from [moment about the world origin; force] and the CoM position in
        world; ``ground_height`` is the z of the plane of the ZMP (the support frame's)."""
        tau_O, force = np.asarray(wrench_world[:3], float), np.asarray(wrench_world[3:], float)
        tau = tau_O - np.cross(p_WCm, force)  # moment about the CoM
        z_c = float(p_WCm[2] - ground_height)
        return np.array([force[0] + tau[1] / z_c, force[1] - tau[0] / z_c, force[2]])

    def _CalcVirtualForce(self, context: Context, output: BasicVector) -> None:
        wrench = eval_finite_input("VirtualForceTruth", self._wrench, context)
        if not np.any(wrench):
            output.SetFromVector(np.zeros(3))
            return
        p_WCm, p_WF = self._com(context)
        output.SetFromVector(self.virtual_force(wrench, p_WCm, p_WF[2]))

    def _CalcComPosition(self, context: Context, output: BasicVector) -> None:
        p_WCm, p_WF = self._com(context)
        output.SetFromVector(p_WCm - p_WF)

    def _CalcComWorld(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._com(context)[0])


class CableVirtualForceTruth(LeafSystem):
    """Ground truth: the virtual force (eq. 11) of the cable's force F applied at A, with the
    TRUE CoM and the ground plane at ``ground_height`` (F0's z = 0):
    F^ = [F_x + tau_y / z_c, F_y - tau_x / z_c, F_z], tau = (p_A - p_Cm) x F,
    z_c = z_Cm - ground_height (``VirtualForceTruth.virtual_force``).

    Inputs:
        state: the TRUE plant state [q; v].
        force_world: (3) the force on the robot, N (``PulleyLoad.force_world``).
        point_world: (3) its point of application A, m (``PulleyLoad.point_world``).

    Outputs:
        virtual_force: (3) F^, N, world-aligned.
        com_world: (3) the true CoM, m (to draw the estimate at the CoM).
    """

    def __init__(self, plant: MultibodyPlant, humanoid: HumanoidHandles, ground_height: float = 0.0):
        super().__init__()
        if not math.isfinite(ground_height):
            raise ValueError(f"CableVirtualForceTruth: ground_height must be finite, got {ground_height}")
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._nq = plant.num_positions()
        self._instances = [humanoid.model_instance]
        self._ground = float(ground_height)
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self._force = self.DeclareVectorInputPort("force_world", 3)
        self._point = self.DeclareVectorInputPort("point_world", 3)
        self.DeclareVectorOutputPort("virtual_force", 3, self._CalcVirtual)
        self.DeclareVectorOutputPort("com_world", 3, self._CalcCom)

    def _com(self, context: Context) -> np.ndarray:
        x = eval_finite_input("CableVirtualForceTruth", self._state, context)
        self._plant.SetPositions(self._plant_context, x[: self._nq])
        return self._plant.CalcCenterOfMassPositionInWorld(self._plant_context, self._instances)

    def _CalcVirtual(self, context: Context, output: BasicVector) -> None:
        force = np.asarray(eval_finite_input("CableVirtualForceTruth", self._force, context))
        if not force.any():
            output.SetFromVector(np.zeros(3))
            return
        point = np.asarray(eval_finite_input("CableVirtualForceTruth", self._point, context))
        wrench = np.concatenate([np.cross(point, force), force])  # moment about the world origin; force
        output.SetFromVector(VirtualForceTruth.virtual_force(wrench, self._com(context), self._ground))

    def _CalcCom(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._com(context))


__all__ = ["CableVirtualForceTruth", "VirtualForceTruth"]
