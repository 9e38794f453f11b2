"""Joint PD control with gravity compensation for a floating-base humanoid.

The low-level control of Flacco et al. 2016: each joint tracks a desired position with a
PD law on top of gravity compensation,

    u = clip( -τ_g(q)[joints] + K_p (q_d - q) - K_d q̇ ,  ±τ_max ),

where τ_g = ``plant.CalcGravityGeneralizedForces`` (= -g(q) in the paper's notation), so
-τ_g cancels the joints' share of gravity of the free-floating robot. (Drake's
``InverseDynamicsController`` refuses floating-base plants, hence this system.)

Joint order: the n = nv - 6 joint coordinates are taken in the plant's joint-velocity
order, i.e. joint k is the 1-DoF joint whose ``velocity_start()`` is 6 + k. Its position
index is its ``position_start()`` (one more than the velocity index, because the base
quaternion has 4 coordinates and the angular velocity 3).
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Joint, JointActuatorIndex
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from systems.common.checks import eval_finite_input, per_joint
from systems.common.topology import floating_base_topology
from systems.dynamics.base_state import QUATERNION_NORM_TOLERANCE


def joints_in_velocity_order(plant: MultibodyPlant) -> list[Joint]:
    """Returns the plant's 1-DoF joints ordered by velocity index, i.e. v[6:].

    Raises:
        ValueError: if the plant is not one floating base with 1-DoF joints (see
            ``systems.common.topology.floating_base_topology``).
    """
    return list(floating_base_topology(plant).joints)


def joint_vector_from_names(plant: MultibodyPlant, values: dict[str, float], default: float = 0.0) -> np.ndarray:
    """Packs ``{joint name: value}`` into a vector in the v[6:] joint order.

    Joints missing from ``values`` get ``default``. Unknown names raise ValueError.
    """
    joints = joints_in_velocity_order(plant)
    index = {j.name(): k for k, j in enumerate(joints)}
    out = np.full(len(joints), float(default))
    for name, value in values.items():
        if name not in index:
            raise ValueError(f"no 1-DoF joint named {name!r} in the plant")
        out[index[name]] = value
    return out


class PdGravityController(LeafSystem):
    """PD on the joint position error plus gravity compensation (Flacco et al. 2016).

    Inputs:
        desired_position: q_d, the n = nv - 6 joint positions in v[6:] order, rad.
        state: the plant's full state [q; v] (quaternion floating base first).

    Outputs:
        actuation: u, size ``plant.num_actuated_dofs()``, in the plant's actuation order
            (actuator ``input_start()``), N m; each actuated joint gets its entry of
            -τ_g + K_p (q_d - q) - K_d q̇, clipped to ±effort limit.

    The system is stateless and direct-feedthrough; it evaluates gravity on its own plant
    context, created once, or through a ``gravity_model`` shared with the estimators.
    """

    def __init__(self, plant: MultibodyPlant, kp, kd, *, effort_limits=None, gravity_model=None):
        """Constructs the controller.

        Args:
            plant: a finalized floating-base MultibodyPlant (one free body + 1-DoF joints).
            kp: proportional gain, N m/rad: scalar or array of n (v[6:] order).
            kd: derivative gain, N m s/rad: scalar or array of n.
            effort_limits: |u| bound per joint, N m, scalar or array of n (v[6:] order);
                default: each actuator's ``effort_limit()`` (inf for unactuated joints).
            gravity_model: optional object with ``plant`` (this plant) and
                ``gravity_joint_torques(x)`` returning tau_g[6:] at a state, e.g. the
                ``systems.residuals.momentum_residuals.ResidualModel`` the residuals of the same diagram use
                (gravity from the estimators' model, e.g. a refined or mismatched one).

        Raises:
            ValueError: bad gain/limit shapes, negative values, or an unsupported plant.
        """
        super().__init__()
        if not plant.is_finalized():
            raise ValueError("PdGravityController needs a finalized plant")
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        if gravity_model is not None and (
            getattr(gravity_model, "plant", None) is not plant or not hasattr(gravity_model, "gravity_joint_torques")
        ):
            raise ValueError(
                "PdGravityController: gravity_model must have gravity_joint_torques(x) and be "
                "built on the controller's plant"
            )
        self._gravity_model = gravity_model
        joints = joints_in_velocity_order(plant)
        n = len(joints)
        self._n = n
        self._kp = per_joint(kp, n, "kp", who="PdGravityController", sign="non-negative")
        self._kd = per_joint(kd, n, "kd", who="PdGravityController", sign="non-negative")
        self._q_index = np.array([j.position_start() for j in joints], dtype=int)
        self._v_index = np.array([j.velocity_start() for j in joints], dtype=int)
        self._nq = plant.num_positions()
        self._quaternion_start = floating_base_topology(plant).free_joint.position_start()

        # Actuation order: actuator -> joint k (index into v[6:]).
        k_of_joint = {int(j.index()): k for k, j in enumerate(joints)}
        na = plant.num_actuated_dofs()
        self._act_rows = np.zeros(na, dtype=int)  # u[a] = tau[act_rows[a]]
        model_limits = np.full(n, np.inf)
        for i in plant.GetJointActuatorIndices():
            actuator = plant.get_joint_actuator(JointActuatorIndex(int(i)))
            jidx = int(actuator.joint().index())
            if jidx not in k_of_joint:
                raise ValueError(f"actuator {actuator.name()!r} drives an unsupported joint")
            k = k_of_joint[jidx]
            self._act_rows[actuator.input_start()] = k
            model_limits[k] = actuator.effort_limit()
        if effort_limits is None:
            self._limits = model_limits
        else:
            self._limits = per_joint(
                effort_limits, n, "effort_limits", who="PdGravityController", allow_inf=True, sign="non-negative"
            )
        self._neg_limits = -self._limits

        self._desired_port = self.DeclareVectorInputPort("desired_position", n)
        self._state_port = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        self.DeclareVectorOutputPort("actuation", na, self._CalcActuation)

    @property
    def joint_count(self) -> int:
        """n = nv - 6, the size of desired_position."""
        return self._n

    def CalcJointTorques(self, q_desired: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Returns the clipped joint torques (n, v[6:] order) for desired q and state x."""
        q = x[: self._nq]
        v = x[self._nq :]
        if self._gravity_model is not None:
            tau_g = self._gravity_model.gravity_joint_torques(x)
        else:
            self._plant.SetPositions(self._context, q)
            tau_g = self._plant.CalcGravityGeneralizedForces(self._context)[self._v_index]
        tau = self._kp * (q_desired - q[self._q_index])
        tau -= tau_g
        tau -= self._kd * v[self._v_index]
        np.minimum(tau, self._limits, out=tau)
        np.maximum(tau, self._neg_limits, out=tau)
        return tau

    def _CalcActuation(self, context: Context, output: BasicVector) -> None:
        q_desired = eval_finite_input("PdGravityController", self._desired_port, context)
        x = eval_finite_input("PdGravityController", self._state_port, context)
        s = self._quaternion_start
        qw, qx, qy, qz = x[s : s + 4].tolist()
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
            raise ValueError(
                f"PdGravityController: input 'state' has a base quaternion of norm {norm:.6g}, not a pose "
                "(an uninitialised state? HumanoidStation.set_initial_state sets the robot and the held "
                "sensor sample before Simulator.Initialize)"
            )
        tau = self.CalcJointTorques(q_desired, x)
        output.SetFromVector(tau[self._act_rows])
