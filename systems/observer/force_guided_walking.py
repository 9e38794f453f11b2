"""Force-guided walking (Hawley, Rahem and Suleiman 2019, Sec. 6.5, Fig. 15): while a force
along x above a threshold pulls (or pushes) the robot, it walks in that direction; when the
force falls below the threshold it finishes the current step, closes its stance with one
more step and stops.

The walking pattern of ``systems.locomotion.walking_pattern`` is computed open loop (ZMP preview control
needs the future footsteps), so the controller plays precomputed SEGMENTS and switches
between them at run time:

* standing -> walking: when F_x (the estimate on the ``force_estimate`` input) stays beyond
  +-``threshold`` with one sign for ``start_debounce`` s (``ForceTrigger``, eq. G-1), a
  segment of ``max_steps`` steps of ``step_length`` in the force's direction is computed
  from the current standing posture (``NaoWalkingController``'s pattern, with a short
  ``initial_wait``) and played from that instant t_0;
* walking -> stopping: when sign * F_x stays below the threshold for ``stop_debounce`` s at
  time t_d, let j be the step in progress (or the first step, before it starts); the
  segment's variant with k = j + 1 steps (the same footsteps, the k-th step closing the
  stance) is computed and the joint targets cross-fade from the long segment to it,

      q_d(t) = (1 - s(t)) q_long(t - t_0) + s(t) q_k(t - t_0),
      s = smoothstep5((t - t_d) / (t_lift,k - t_d))                                (G-2)

  finishing before step k's lift-off t_lift,k, the first instant the two plans' footsteps
  differ. Before that they differ only through the preview: the CoM reference differs by
  the response of the preview controller (eq. K-5) to ZMP references that part at step k's
  touch-down, >= t_lift,k + single-support time in the future (measured: a few mm at most);
* lean (eq. G-3): a force F at about the CoM height moves the ZMP of the robot by
  z_c F / (m g) (LIP, eq. 10 of Hawley et al.); pushed backwards at the hands while walking
  backwards, the real ZMP would sit ~2 cm behind the planned one, near the heel sensors
  (the FSR polygon spans x in [-0.03, 0.07] m of the sole frame). Each segment's ZMP
  reference offset is therefore

      zmp_offset_x = zmp_offset_x,0 - clip(z_c F_0 / (m g), -max_lean, max_lean)      (G-3)

  with F_0 the estimate at the start decision, so that the pushed robot's ZMP stays at
  zmp_offset_x,0 (the preview controller moves the CoM accordingly, keeping the pattern
  dynamically consistent); ``max_lean = 0`` (the default) disables it (measured worse when
  it was tried; see the git history of BENCHMARKS.md); the default instead puts the ZMP
  reference at the centre of the FSR polygon (``GUIDED_WALKING``), which leaves ~5 cm of
  margin both ways;
* stopping -> standing: at the end of the variant (ZMP back between the feet, then
  ``final_wait``) the last targets are held; a new segment can start from there;
* a segment that runs out of steps while the force persists ends like a stop, and a new
  one starts after the debounce.

Before any segment, the controller lowers the CoM from the station's standing posture to the
walking height z_c over ``crouch_time`` (a quasi-static pattern through
``whole_body_trajectory``, eq. W-1), so that each segment starts at rest at z_c.

Eq. G-1 (``ForceTrigger``): with F the force estimate, T_on the threshold,
    start at t when |F(tau)| > T_on and sign F(tau) = d for all tau in [t - start_debounce, t];
    stop at t when d F(tau) < T_on for all tau in [t - stop_debounce, t] (d: walking direction).

Segments are built inside the discrete update (a few tenths of a second of wall time each:
the simulation waits) and kept in a list on the system; the discrete state holds only
numbers (mode, direction, indices into that list, times). Units: SI.
"""

import math
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.containers import namedview
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from models import HumanoidHandles
from systems.common.checks import eval_finite_input
from systems.common.smoothing import smoothstep5
from systems.common.topology import floating_base_topology
from systems.locomotion.walking_pattern import (
    SIDES,
    NaoWalkingController,
    WalkingParameters,
    WalkingPattern,
    preview_gains,
    whole_body_trajectory,
)

#: Default segment parameters: the committed walk (0.05 m, 0.5 s steps) with a short
#: initial wait (the first step's double support starts 0.2 s after the start decision),
#: a short final wait, and the ZMP reference at the centre of the FSR polygon
#: (x in [-0.03, 0.07] m of the sole frame): the hands' force moves the real ZMP forwards or
#: backwards by ~z_c F / (m g) (~2 cm for 5 N), and the centre leaves the same margin both ways.
GUIDED_WALKING = WalkingParameters(initial_wait=0.2, final_wait=0.3, zmp_offset_x=0.02)

#: Modes of the controller (entry 0 of its ``walking_state`` output).
STANDING, WALKING, STOPPING = 0, 1, 2


@dataclass
class TriggerParameters:
    """Force trigger of eq. G-1. A plain dataclass, so that a scenario can nest it;
    ``check()`` repeats ``__post_init__``'s checks on loaded values.

    Attributes:
        threshold: T_on, N (> 0).
        start_debounce: time |F| must stay above the threshold (one sign) to start, s (>= 0).
        stop_debounce: time the force along the walking direction must stay below the
            threshold to stop, s (>= 0).
    """

    threshold: float = 2.0
    start_debounce: float = 0.1
    stop_debounce: float = 0.05

    def __post_init__(self):
        self.check()

    def check(self) -> None:
        """Raises ValueError on a bad value (the message names it)."""
        if not (math.isfinite(self.threshold) and self.threshold > 0):
            raise ValueError(f"TriggerParameters.threshold must be positive, got {self.threshold}")
        for name in ("start_debounce", "stop_debounce"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"TriggerParameters.{name} must be a non-negative number of seconds, got {value}")


class ForceTrigger:
    """Eq. G-1 as a pure function of (memory, time, force); no Drake.

    The memory is (above_since, above_sign, below_since): the time the force went beyond the
    threshold with its sign (NaN if it is not), and the time the force along the walking
    direction went below it (NaN if it is not).
    """

    def __init__(self, parameters: TriggerParameters | None = None):
        self.parameters = parameters if parameters is not None else TriggerParameters()

    @staticmethod
    def initial_memory() -> tuple[float, float, float]:
        return (math.nan, 0.0, math.nan)

    def update(
        self, memory: tuple[float, float, float], t: float, force: float, direction: float
    ) -> tuple[tuple[float, float, float], int]:
        """One sample.

        Args:
            memory: from ``initial_memory`` or the previous call.
            t: time, s; force: F_x, N.
            direction: 0 while standing, +1 / -1 while walking forwards / backwards.

        Returns:
            (new memory, event): event +1 / -1 = start walking in that direction (only while
            standing), 2 = stop (only while walking), 0 = nothing.

        Raises:
            ValueError: non-finite time or force, direction not in {-1, 0, 1}.
        """
        if not (math.isfinite(t) and math.isfinite(force)):
            raise ValueError(f"ForceTrigger: t and force must be finite, got t={t}, force={force}")
        if direction not in (-1, 0, 1):
            raise ValueError(f"ForceTrigger: direction must be -1, 0 or 1, got {direction}")
        p = self.parameters
        above_since, above_sign, below_since = memory
        sign = 1.0 if force > p.threshold else (-1.0 if force < -p.threshold else 0.0)
        if sign == 0.0:
            above_since, above_sign = math.nan, 0.0
        elif sign != above_sign or math.isnan(above_since):
            above_since, above_sign = t, sign
        event = 0
        if direction == 0:
            below_since = math.nan
            if sign != 0.0 and t - above_since >= p.start_debounce - 1e-12:
                event = int(sign)
        else:
            if direction * force < p.threshold:
                if math.isnan(below_since):
                    below_since = t
                if t - below_since >= p.stop_debounce - 1e-12:
                    event = 2
            else:
                below_since = math.nan
        return (above_since, above_sign, below_since), event


@dataclass
class Plan:
    """A precomputed segment on its grid (times relative to the segment's start).

    Attributes:
        t: (K,) s; q: (K, n) joint targets (v[6:] order), rad; zmp: (K, 2), com: (K, 3),
        soles: (K, 6) left then right, world, m; contact: (K, 2) planned contact flags.
        steps: the footsteps (``Footstep``), times relative to the segment's start.
        final_positions: (nq) the plant positions of the last sample (without the PD
            compensation): the standing posture the next segment starts from.
        sample_period: the grid's period, s.
        initial_positions: (nq) the plant positions the segment starts from.
    """

    t: np.ndarray
    q: np.ndarray
    zmp: np.ndarray
    com: np.ndarray
    soles: np.ndarray
    contact: np.ndarray
    steps: list
    final_positions: np.ndarray
    sample_period: float
    initial_positions: np.ndarray | None = None

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def sample(self, table: np.ndarray, t: float) -> np.ndarray:
        """Linear interpolation at t (held at the ends)."""
        s = min(max(t / self.sample_period, 0.0), self.t.size - 1.0)
        k = min(int(s), self.t.size - 2)
        a = s - k
        return (1.0 - a) * table[k] + a * table[k + 1]


def _final_positions(plant: MultibodyPlant, q0: np.ndarray, torso: np.ndarray, q_joints: np.ndarray) -> np.ndarray:
    topology = floating_base_topology(plant)
    out = np.asarray(q0, float).copy()
    free = topology.free_joint.position_start()
    out[free : free + 4] = [1.0, 0.0, 0.0, 0.0]
    out[free + 4 : free + 7] = torso
    out[[j.position_start() for j in topology.joints]] = q_joints
    return out


def plan_from_controller(plant: MultibodyPlant, controller: NaoWalkingController, q0: np.ndarray) -> Plan:
    """The tables of a ``NaoWalkingController`` (built, not added to a diagram) as a Plan."""
    p, tr = controller.pattern, controller.trajectory
    return Plan(
        t=p.t,
        q=tr.q_joints,
        zmp=p.zmp_reference,
        com=p.com,
        soles=np.hstack([p.soles["left"], p.soles["right"]]),
        contact=np.column_stack([p.contact["left"], p.contact["right"]]).astype(float),
        steps=list(p.steps),
        final_positions=_final_positions(plant, q0, tr.torso_position[-1], tr.q_joints[-1] - tr.compensation[-1]),
        sample_period=controller.parameters.sample_period,
        initial_positions=np.asarray(q0, float).copy(),
    )


def crouch_plan(
    plant: MultibodyPlant,
    humanoid: HumanoidHandles,
    parameters: WalkingParameters,
    q0: np.ndarray,
    duration: float,
    joint_stiffness: np.ndarray | None,
) -> Plan:
    """Quasi-static lowering from ``q0`` (standing, soles on the ground) to the walking CoM
    height z_c above the feet's mid-point plus ``zmp_offset_x`` (where a segment's ZMP
    reference starts), along a 5th-order smoothstep over ``duration`` s (eq. W-1 targets)."""
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"crouch duration must be positive, got {duration}")
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q0)
    soles = {s: humanoid.sole_frames[s].CalcPoseInWorld(context).translation() for s in SIDES}
    com0 = plant.CalcCenterOfMassPositionInWorld(context, [humanoid.model_instance])
    T = parameters.sample_period
    t = np.arange(int(round(duration / T)) + 1) * T
    s = smoothstep5(t / duration)[:, None]
    mid = 0.5 * (soles["left"] + soles["right"])
    goal = np.array([mid[0] + parameters.zmp_offset_x, mid[1], mid[2] + parameters.com_height])
    com = com0 + s * (goal - com0)
    K = t.size
    pattern = WalkingPattern(
        params=parameters,
        t=t,
        steps=[],
        zmp_reference=com[:, :2].copy(),
        zmp=com[:, :2].copy(),
        com=com,
        com_velocity=np.zeros((K, 2)),
        com_acceleration=np.zeros((K, 2)),
        soles={side: np.tile(soles[side], (K, 1)) for side in SIDES},
        contact={side: np.ones(K, dtype=bool) for side in SIDES},
        gains=preview_gains(T, parameters.com_height, parameters.preview_time),
    )
    tr = whole_body_trajectory(plant, humanoid, pattern, q0, joint_stiffness=joint_stiffness)
    return Plan(
        t=t,
        q=tr.q_joints,
        zmp=pattern.zmp_reference,
        com=com,
        soles=np.hstack([pattern.soles["left"], pattern.soles["right"]]),
        contact=np.ones((K, 2)),
        steps=[],
        final_positions=_final_positions(plant, q0, tr.torso_position[-1], tr.q_joints[-1] - tr.compensation[-1]),
        sample_period=T,
        initial_positions=np.asarray(q0, float).copy(),
    )


def stop_step(steps: list, elapsed: float) -> int:
    """k (1-based) of the closing step when the stop is decided ``elapsed`` s after the
    segment's start: the step after the one in progress (the first step if none started)."""
    return 1 + sum(1 for step in steps if step.t_start <= elapsed)


#: The controller's discrete state: mode (STANDING/WALKING/STOPPING), walking direction
#: (+1 forward, -1 backward), the current segment's start time t0 (s) and index in ``plans``,
#: the stop variant's index (-1: none) and its cross-fade window (s), the trigger's memory
#: (``ForceTrigger.update``), the segment's end time (s) and its ZMP lean (m, eq. G-3).
_ControllerState = namedview(
    "ControllerState",
    [
        "mode",
        "direction",
        "t0",
        "segment",
        "stop_segment",
        "blend_start",
        "blend_end",
        "trigger_above",
        "trigger_sign",
        "trigger_below",
        "t_end",
        "lean",
    ],
)


class ForceGuidedWalkingController(LeafSystem):
    """Walks along x while the estimated force exceeds a threshold (module docstring).

    Inputs:
        force_estimate: (3) the estimated external force, N (e.g. the total force on the
            hands from the arm joints, ``systems.observer.arm_compliance.ArmExternalForceEstimator``,
            or the LIP observer's ``virtual_force``); only x is used.

    State: discrete (mode, direction, segment start t_0, segment and stop-variant indices,
        cross-fade interval, trigger memory, end time), updated every ``period``.

    Outputs:
        desired_position: (n) joint targets, v[6:] order, rad.
        zmp_reference: (2) m; com_reference: (3) m; sole_targets: (6) m (world);
        planned_contact: (2) (1 = the plan has that foot on the ground).
        walking_state: (3) [mode (0 standing, 1 walking, 2 stopping), direction (+1/-1/0),
            segment start t_0 (s, NaN before any)].

    The outputs depend only on the state and time (no feedthrough from the input).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        humanoid: HumanoidHandles,
        parameters: WalkingParameters | None = None,
        trigger: TriggerParameters | None = None,
        *,
        initial_positions: np.ndarray,
        joint_stiffness: np.ndarray | None = None,
        max_steps: int = 20,
        crouch_time: float = 1.0,
        period: float = 0.01,
        max_lean: float = 0.0,
    ):
        """Args:
            plant, humanoid: the finalized plant with ``nao_like`` and its handles.
            parameters: walking parameters of every segment: |step_length| (its sign is
                ignored: the force chooses the direction), timing, initial_wait (the delay
                from the start decision to the first step's double support), final_wait.
                ``num_steps`` is ignored (``max_steps`` per segment). Default:
                ``GUIDED_WALKING``.
            trigger: eq. G-1's parameters.
            initial_positions: (nq) the plant's positions at t = 0 (standing).
            joint_stiffness: the PD's K_p for the stiffness compensation (eq. W-2), or None.
            max_steps: steps per segment (>= 2).
            crouch_time: time to lower to z_c at the start, s; no segment starts before.
            period: update period of the trigger and the segment logic, s.
            max_lean: bound of eq. G-3's ZMP offset change, m (0 disables the lean).

        Raises:
            ValueError: bad parameters (and those of ``WalkingParameters``).
        """
        super().__init__()
        base = parameters if parameters is not None else GUIDED_WALKING
        if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 2):
            raise ValueError(f"max_steps must be an integer >= 2, got {max_steps!r}")
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be positive, got {period}")
        if abs(base.step_length) <= 0:
            raise ValueError("step_length must be non-zero")
        self._plant, self._humanoid = plant, humanoid
        self._params = replace(base, step_length=abs(base.step_length), num_steps=int(max_steps))
        self._trigger = ForceTrigger(trigger)
        self._kp = joint_stiffness
        self._max_steps = int(max_steps)
        if not (math.isfinite(max_lean) and 0.0 <= max_lean <= 0.03):
            raise ValueError(f"max_lean must be in [0, 0.03] m, got {max_lean}")
        self._max_lean = float(max_lean)
        self._mass = plant.CalcTotalMass(plant.CreateDefaultContext(), [humanoid.model_instance])
        self._period = float(period)
        q0 = np.asarray(initial_positions, float).reshape(-1)
        self._crouch_time = float(crouch_time)
        #: Segment list: index 0 is the crouch; the state refers to entries by index.
        self.plans: list[Plan] = [crouch_plan(plant, humanoid, self._params, q0, crouch_time, joint_stiffness)]
        #: Log of decisions: (time, event, detail) tuples, for reports.
        self.events: list[tuple[float, str, dict]] = []
        n = self.plans[0].q.shape[1]
        x0 = _ControllerState(np.full(len(_ControllerState.get_fields()), np.nan))
        x0.mode, x0.direction, x0.t0, x0.segment = STANDING, 0.0, 0.0, 0.0
        x0.stop_segment, x0.trigger_sign, x0.lean = -1.0, 0.0, 0.0
        self._state = self.DeclareDiscreteState(x0[:])
        self._force = self.DeclareVectorInputPort("force_estimate", 3)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        xd = {self.xd_ticket(), self.time_ticket()}
        self.DeclareVectorOutputPort("desired_position", n, lambda c, o: o.SetFromVector(self._sample(c, "q")), xd)
        self.DeclareVectorOutputPort("zmp_reference", 2, lambda c, o: o.SetFromVector(self._sample(c, "zmp")), xd)
        self.DeclareVectorOutputPort("com_reference", 3, lambda c, o: o.SetFromVector(self._sample(c, "com")), xd)
        self.DeclareVectorOutputPort("sole_targets", 6, lambda c, o: o.SetFromVector(self._sample(c, "soles")), xd)
        self.DeclareVectorOutputPort("planned_contact", 2, self._CalcContact, xd)
        self.DeclareVectorOutputPort("walking_state", 3, self._CalcState, {self.xd_ticket()})

    @property
    def walking_parameters(self) -> WalkingParameters:
        return self._params

    # ----- plans ---------------------------------------------------------------------
    def lean(self, force: float) -> float:
        """Eq. G-3's change of the ZMP offset for a force estimate ``force`` (N), m."""
        p = self._params
        return -float(np.clip(p.com_height * force / (self._mass * p.gravity), -self._max_lean, self._max_lean))

    def _segment(self, q0: np.ndarray, direction: int, num_steps: int, lean: float) -> Plan:
        params = replace(
            self._params,
            step_length=direction * self._params.step_length,
            num_steps=num_steps,
            zmp_offset_x=self._params.zmp_offset_x + lean,
        )
        controller = NaoWalkingController(
            self._plant, self._humanoid, params, initial_positions=q0, joint_stiffness=self._kp
        )
        return plan_from_controller(self._plant, controller, q0)

    def _sample(self, context: Context, name: str) -> np.ndarray:
        s = _ControllerState(context.get_discrete_state(self._state).get_value())
        t = context.get_time()
        plan = self.plans[int(s.segment)]
        t0 = s.t0
        value = plan.sample(getattr(plan, name), t - t0)
        if s.stop_segment >= 0:  # cross-fade to the stop variant (eq. G-2)
            variant = self.plans[int(s.stop_segment)]
            w = float(smoothstep5(np.array((t - s.blend_start) / max(s.blend_end - s.blend_start, 1e-9))))
            value = (1.0 - w) * value + w * variant.sample(getattr(variant, name), t - t0)
        return value

    def _CalcContact(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector((self._sample(context, "contact") > 0.5).astype(float))

    def _CalcState(self, context: Context, output: BasicVector) -> None:
        s = _ControllerState(context.get_discrete_state(self._state).get_value())
        output.SetFromVector([s.mode, s.direction, s.t0 if s.segment > 0 else np.nan])

    # ----- logic ---------------------------------------------------------------------
    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        s = _ControllerState(context.get_discrete_state(self._state).get_value().copy())
        t = context.get_time()
        force = float(eval_finite_input("ForceGuidedWalkingController", self._force, context)[0])
        mode = int(s.mode)
        direction = int(s.direction) if mode == WALKING else 0
        memory = (s.trigger_above, s.trigger_sign, s.trigger_below)
        memory, event = self._trigger.update(memory, t, force, direction)
        s.trigger_above, s.trigger_sign, s.trigger_below = memory
        current = self.plans[int(s.segment)]
        if mode == STANDING:
            ready = t >= self._crouch_time - 1e-9 if s.segment == 0 else True
            if event in (1, -1) and ready:
                final = self.plans[int(s.stop_segment)] if s.stop_segment >= 0 else current
                lean = self.lean(force)
                self.plans.append(self._segment(final.final_positions, event, self._max_steps, lean))
                s.segment, s.stop_segment, s.t0, s.lean = len(self.plans) - 1, -1, t, lean
                s.mode, s.direction = WALKING, event
                s.t_end = t + self.plans[-1].duration
                s.trigger_below = np.nan
                self.events.append((t, "start", {"direction": event, "force": force, "lean_m": lean}))
        elif mode == WALKING:
            elapsed = t - s.t0
            if event == 2:
                k = stop_step(current.steps, elapsed)
                if k >= len(current.steps):  # the segment's own last step closes the stance
                    s.mode = STOPPING
                    self.events.append(
                        (t, "stop", {"closing_step": len(current.steps), "force": force, "variant": False})
                    )
                else:
                    self.plans.append(self._segment(current.initial_positions, int(s.direction), k, float(s.lean)))
                    variant = self.plans[-1]
                    s.stop_segment, s.blend_start = len(self.plans) - 1, t
                    s.blend_end = s.t0 + variant.steps[k - 1].t_lift - 0.02
                    s.t_end = s.t0 + variant.duration
                    s.mode = STOPPING
                    jump = float(
                        np.abs(variant.sample(variant.com, elapsed) - current.sample(current.com, elapsed)).max()
                    )
                    self.events.append(
                        (
                            t,
                            "stop",
                            {
                                "closing_step": k,
                                "force": force,
                                "variant": True,
                                "com_difference_at_switch_m": jump,
                                "blend_until": float(s.blend_end),
                            },
                        )
                    )
            elif t >= s.t_end:  # out of steps: stand (a new segment starts after the debounce)
                s.mode = STANDING
                self.events.append((t, "segment_end", {}))
        elif mode == STOPPING and t >= s.t_end:
            s.mode = STANDING
            self.events.append((t, "standing", {}))
        if int(s.mode) != WALKING:
            s.direction = s.direction if int(s.mode) == STOPPING else 0.0
        discrete_state.set_value(self._state, s[:])


__all__ = [
    "GUIDED_WALKING",
    "STANDING",
    "WALKING",
    "STOPPING",
    "ForceGuidedWalkingController",
    "ForceTrigger",
    "Plan",
    "TriggerParameters",
    "crouch_plan",
    "plan_from_controller",
    "stop_step",
]
