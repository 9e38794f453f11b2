"""A load pulled through a cable over a pulley: the external force of Hawley et al. (2019),
Sec. 6.3, Experiment 4 (Figs. 9-11).

In the experiment a fishing line ties Nao's waist to a mass m0 ~ 0.3 kg that lies on the
ground behind the robot; as the robot walks forward the line tightens over the experimental
structure, the mass is lifted and the robot is pulled backwards by about m0 g ~ 3 N, at
about 5 deg from the x axis. ``PulleyLoad`` models it without changing the plant:

* the cable runs straight from an attachment point A fixed in a robot body to a fixed
  pulley point P (world), then vertically down to the load; its length is
  L = |p_A - p_P| + (z_P - z_0), with z_0 the load's height above the ground;
* it is an elastic line that only pulls: tension T = max(0, k (L - L_0) + c dL/dt) while
  L > L_0, else 0 (k, c: the line's stiffness and damping; L_0: its natural length);
* the load is a point mass on a vertical line below P: m0 z0'' = T - m0 g while lifted;
  it rests on the ground (z_0 = 0, at rest) while T <= m0 g. Its state [z_0, z0'] is the
  system's discrete state, integrated every ``period`` by semi-implicit Euler (the coupling
  with the plant is explicit: the step must resolve the line's vibration,
  period < 0.5 sqrt(m0 / k), checked at construction);
* the robot receives the force T u at A, with u the unit vector from A to P.

Ground truth for the observer comes out of the same system (``force_world``,
``tension``): F_x = -m0 (g + z0'') in the paper's notation while the load hangs.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem

from systems.common.checks import eval_finite_input, positive_number, vector3

__all__ = ["PulleyLoad"]

_WHO = "PulleyLoad"


class PulleyLoad(LeafSystem):
    """A load lifted through a cable over a fixed pulley, pulling a robot body (see module).

    Input:
        state: the plant's TRUE state [q; v] (nq + nv): the cable is physics, not a sensor.

    Outputs:
        applied_spatial_forces: abstract ``list[ExternallyAppliedSpatialForce]``, one entry
            (the cable force at A on ``body``); combine it with other forces through
            ``ExternallyAppliedSpatialForceMultiplexer`` before the plant's input.
        force_world: (3) the force on the robot, N, world frame (ground truth).
        point_world: (3) the attachment point A, m, world frame.
        tension: (1) T, N.
        load_height: (1) z_0, m above the ground.

    The force is computed from the state held in the discrete state (updated every
    ``period`` from the plant's state), so the output has no direct feedthrough from the
    input and the diagram has no algebraic loop.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        body_name: str,
        p_BA: np.ndarray,
        pulley_W: np.ndarray,
        *,
        load_mass: float = 0.3,
        cable_length: float,
        stiffness: float = 2000.0,
        damping: float = 5.0,
        gravity: float = 9.81,
        period: float = 1e-3,
    ):
        """Args:
            plant: the finalized plant of the robot.
            body_name: the body the cable is tied to (e.g. the torso, at the waist).
            p_BA: the attachment point A in that body's frame, m.
            pulley_W: the pulley point P in world, m (its z is the pulley's height).
            load_mass: m0, kg (0.3 kg in the paper).
            cable_length: L_0, the line's natural length from A over P down to the load, m.
            stiffness: k, N/m (a thin, stretchy line; 2000 N/m stretches 1.5 mm under 3 N).
            damping: c, N s/m.
            gravity: g, m/s^2.
            period: integration period of the load, s.

        Raises:
            ValueError: unfinalized plant, unknown body, non-finite or non-positive
                parameters, a period too long for the line's vibration.
        """
        super().__init__()
        if not isinstance(plant, MultibodyPlant) or not plant.is_finalized():
            raise ValueError(f"{_WHO}: needs a finalized MultibodyPlant")
        if not plant.HasBodyNamed(body_name):
            raise ValueError(f"{_WHO}: the plant has no body named {body_name!r}")
        self._plant = plant
        self._body = plant.GetBodyByName(body_name)
        self._p_BA = vector3(p_BA, f"{_WHO}: p_BA")
        self._pulley = vector3(pulley_W, f"{_WHO}: pulley_W")
        self._m = positive_number(load_mass, f"{_WHO}: load_mass")
        self._L0 = positive_number(cable_length, f"{_WHO}: cable_length")
        self._k = positive_number(stiffness, f"{_WHO}: stiffness")
        self._c = positive_number(damping, f"{_WHO}: damping", allow_zero=True)
        self._g = positive_number(gravity, f"{_WHO}: gravity", allow_zero=True)
        self._period = positive_number(period, f"{_WHO}: period")
        if self._period >= 0.5 * math.sqrt(self._m / self._k):
            raise ValueError(
                f"{_WHO}: period {self._period} s does not resolve the line's vibration "
                f"(needs < 0.5 sqrt(m0/k) = {0.5 * math.sqrt(self._m / self._k):.3g} s)"
            )
        if self._pulley[2] <= 0.0:
            raise ValueError(f"{_WHO}: the pulley must be above the ground (z > 0), got {self._pulley[2]}")
        self._context = plant.CreateDefaultContext()
        self._nq = plant.num_positions()

        self._state_port = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        # Discrete state: load [z0, z0dot], and the last force on the robot, point A, tension.
        self._load_index = self.DeclareDiscreteState(2)
        self._force_index = self.DeclareDiscreteState(7)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        self.DeclareInitializationDiscreteUpdateEvent(self._Initialize)
        self.DeclareAbstractOutputPort(
            "applied_spatial_forces",
            lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._CalcApplied,
            {self.xd_ticket()},
        )
        self.DeclareVectorOutputPort(
            "force_world", 3, lambda c, o: o.SetFromVector(self._held(c)[:3]), {self.xd_ticket()}
        )
        self.DeclareVectorOutputPort(
            "point_world", 3, lambda c, o: o.SetFromVector(self._held(c)[3:6]), {self.xd_ticket()}
        )
        self.DeclareVectorOutputPort("tension", 1, lambda c, o: o.SetFromVector(self._held(c)[6:7]), {self.xd_ticket()})
        self.DeclareVectorOutputPort(
            "load_height",
            1,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._load_index).get_value()[:1]),
            {self.xd_ticket()},
        )

    @property
    def load_mass(self) -> float:
        return self._m

    @property
    def pulley(self) -> np.ndarray:
        return self._pulley.copy()

    def cable(self, x: np.ndarray, z0: float, z0dot: float) -> tuple[float, np.ndarray, np.ndarray]:
        """(tension T, N; force on the robot, N, world; point A, m, world) for the plant
        state x and the load's height and velocity."""
        plant = self._plant
        plant.SetPositionsAndVelocities(self._context, x)
        X_WB = plant.EvalBodyPoseInWorld(self._context, self._body)
        V_WB = plant.EvalBodySpatialVelocityInWorld(self._context, self._body)
        p_BA_W = X_WB.rotation().multiply(self._p_BA)
        p_A = X_WB.translation() + p_BA_W
        v_A = V_WB.translational() + np.cross(V_WB.rotational(), p_BA_W)
        to_pulley = self._pulley - p_A
        d = float(np.linalg.norm(to_pulley))
        if d < 1e-9:
            return 0.0, np.zeros(3), p_A
        u = to_pulley / d
        length = d + (self._pulley[2] - z0)
        rate = -float(u @ v_A) - z0dot  # d|P - A|/dt = -u . v_A; the vertical part shortens as z0 rises
        stretch = length - self._L0
        tension = max(0.0, self._k * stretch + self._c * rate) if stretch > 0.0 else 0.0
        return tension, tension * u, p_A

    def _held(self, context: Context) -> np.ndarray:
        return context.get_discrete_state(self._force_index).get_value()

    def _Initialize(self, context: Context, discrete_state: DiscreteValues) -> None:
        x = eval_finite_input(_WHO, self._state_port, context)
        tension, force, p_A = self.cable(x, 0.0, 0.0)
        discrete_state.set_value(self._load_index, [0.0, 0.0])
        discrete_state.set_value(self._force_index, np.concatenate((force, p_A, [tension])))

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        x = eval_finite_input(_WHO, self._state_port, context)
        z0, z0dot = context.get_discrete_state(self._load_index).get_value()
        tension, force, p_A = self.cable(x, z0, z0dot)
        # The load: m0 z0'' = T - m0 g while lifted; on the ground the floor holds it.
        acceleration = tension / self._m - self._g
        z0dot_next = z0dot + self._period * acceleration
        z0_next = z0 + self._period * z0dot_next
        if z0_next <= 0.0:  # on the ground (a landing is inelastic)
            z0_next, z0dot_next = 0.0, 0.0
        discrete_state.set_value(self._load_index, [z0_next, z0dot_next])
        discrete_state.set_value(self._force_index, np.concatenate((force, p_A, [tension])))

    def _CalcApplied(self, context: Context, output: AbstractValue) -> None:
        held = self._held(context)
        applied = ExternallyAppliedSpatialForce()
        applied.body_index = self._body.index()
        applied.p_BoBq_B = self._p_BA
        applied.F_Bq_W = SpatialForce(np.zeros(3), held[:3])
        output.set_value([applied])
