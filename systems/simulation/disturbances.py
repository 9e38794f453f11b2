"""External pushes on a humanoid: force profiles, push descriptions and a Drake source.

Flacco et al. (2016) test their residuals with known pushes: a sinusoidal force on the
right shoulder of HRP-4 (Secs. II-C, IV, V) and two downward forces on the shoulders with
a polynomial profile that rises from t = 5 s to its maximum (5 N) at t = 8.5 s and returns
to zero at t = 12 s (Sec. IV). This module describes such pushes and applies them to a
``MultibodyPlant``:

* force profiles (scalar magnitude [N] as a function of time [s]): ``Sinusoid``,
  ``PolynomialRampUpDown`` (quintic smoothstep up and down), ``Step``;
* ``Push``: a profile times a fixed world direction, applied at a point fixed in a body;
* ``PushSource``: a ``LeafSystem`` whose abstract output feeds
  ``plant.get_applied_spatial_force_input_port()``, plus ground-truth outputs (forces,
  application points, total wrench in world and in the base frame F0, the true joint
  effort tau_c,real of eq. 12) for loggers and metrics. Estimators must never read those.

Typical use::

    pushes = [Push("R_SHOULDER_P_LINK", [0.0, -0.05, 0.0], [0.0, 0.0, -1.0],
                   PolynomialRampUpDown(peak=5.0, t_start=5.0, t_peak=8.5, t_end=12.0))]
    source = builder.AddSystem(PushSource(plant, pushes))
    builder.Connect(source.GetOutputPort("applied_spatial_forces"),
                    plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), source.GetInputPort("state"))
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable, RigidBody
from pydrake.systems.framework import BasicVector, Context, LeafSystem, ValueProducer
from scipy.linalg import lapack

from systems.common.checks import resolve_body, vector3
from systems.common.smoothing import smoothstep5
from systems.common.spatial import cross
from systems.dynamics.floating_base import FloatingBaseDynamics

__all__ = [
    "ForceProfile",
    "PolynomialRampUpDown",
    "Push",
    "PushSource",
    "Sinusoid",
    "SmoothPiecewise",
    "Step",
    "profile_support",
]


# ---------------------------------------------------------------------------------------
# Force profiles.
# ---------------------------------------------------------------------------------------


def _finite(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return x


def _finite_or_inf(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if math.isnan(x) or x == -math.inf:
        raise ValueError(f"{name} must be a finite number or +inf, got {value!r}")
    return x


def _is_scalar(t) -> bool:
    return isinstance(t, (int, float)) or np.ndim(t) == 0


@runtime_checkable
class ForceProfile(Protocol):
    """Anything with ``value(t)``: the push magnitude [N] at time t [s] (scalar or array)."""

    def value(self, t): ...


@dataclass(frozen=True)
class Sinusoid:
    """``offset + amplitude sin(2π frequency_hz (t - t_start) + phase)`` on [t_start, t_end].

    Zero outside the closed interval [t_start, t_end]. The phase is measured from t_start,
    so the default (phase = offset = 0) starts continuously from zero.

    Attributes:
        amplitude: N (any sign).
        frequency_hz: Hz, >= 0.
        phase: rad, at t = t_start.
        offset: N, added while active.
        t_start: s, finite.
        t_end: s, > t_start (may be inf).
    """

    amplitude: float
    frequency_hz: float
    phase: float = 0.0
    offset: float = 0.0
    t_start: float = 0.0
    t_end: float = math.inf

    def __post_init__(self):
        for name in ("amplitude", "frequency_hz", "phase", "offset", "t_start"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        object.__setattr__(self, "t_end", _finite_or_inf("t_end", self.t_end))
        if self.frequency_hz < 0.0:
            raise ValueError(f"frequency_hz must be >= 0, got {self.frequency_hz}")
        if not self.t_end > self.t_start:
            raise ValueError(f"t_end ({self.t_end}) must be greater than t_start ({self.t_start})")

    def value(self, t):
        """Magnitude [N] at t [s]: float for a scalar t, array for an array t."""
        w = 2.0 * math.pi * self.frequency_hz
        if _is_scalar(t):
            t = float(t)
            if t < self.t_start or t > self.t_end:
                return 0.0
            return self.offset + self.amplitude * math.sin(w * (t - self.t_start) + self.phase)
        t = np.asarray(t, dtype=float)
        on = (t >= self.t_start) & (t <= self.t_end)
        return np.where(on, self.offset + self.amplitude * np.sin(w * (t - self.t_start) + self.phase), 0.0)


@dataclass(frozen=True)
class PolynomialRampUpDown:
    """Rise from 0 at t_start to ``peak`` at t_peak, back to 0 at t_end, zero outside.

    Each half is a quintic smoothstep s(x) = 10x³ - 15x⁴ + 6x⁵ of the normalised time, so
    the profile is C2 (value, slope and curvature continuous everywhere, slope zero at
    t_start, t_peak and t_end). The paper's shoulder push (Sec. IV) is
    ``PolynomialRampUpDown(peak=5.0, t_start=5.0, t_peak=8.5, t_end=12.0)``.

    Attributes:
        peak: N (any sign), the value at t_peak.
        t_start, t_peak, t_end: s, finite, t_start < t_peak < t_end.
    """

    peak: float
    t_start: float
    t_peak: float
    t_end: float

    def __post_init__(self):
        for name in ("peak", "t_start", "t_peak", "t_end"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        if not (self.t_start < self.t_peak < self.t_end):
            raise ValueError(
                f"need t_start < t_peak < t_end, got t_start={self.t_start}, t_peak={self.t_peak}, t_end={self.t_end}"
            )

    def value(self, t):
        """Magnitude [N] at t [s]: float for a scalar t, array for an array t."""
        t0, t1, t2 = self.t_start, self.t_peak, self.t_end
        if _is_scalar(t):
            t = float(t)
            if t <= t0 or t >= t2:
                return 0.0
            x = (t - t0) / (t1 - t0) if t <= t1 else (t2 - t) / (t2 - t1)
            return self.peak * smoothstep5(x)
        t = np.asarray(t, dtype=float)
        x = np.where(t <= t1, (t - t0) / (t1 - t0), (t2 - t) / (t2 - t1))
        return self.peak * smoothstep5(x)


@dataclass(frozen=True)
class Step:
    """``magnitude`` for t_on <= t < t_off, zero otherwise.

    Attributes:
        magnitude: N (any sign).
        t_on: s, finite.
        t_off: s, > t_on (may be inf).
    """

    magnitude: float
    t_on: float
    t_off: float = math.inf

    def __post_init__(self):
        object.__setattr__(self, "magnitude", _finite("magnitude", self.magnitude))
        object.__setattr__(self, "t_on", _finite("t_on", self.t_on))
        object.__setattr__(self, "t_off", _finite_or_inf("t_off", self.t_off))
        if not self.t_off > self.t_on:
            raise ValueError(f"t_off ({self.t_off}) must be greater than t_on ({self.t_on})")

    def value(self, t):
        """Magnitude [N] at t [s]: float for a scalar t, array for an array t."""
        if _is_scalar(t):
            t = float(t)
            return self.magnitude if self.t_on <= t < self.t_off else 0.0
        t = np.asarray(t, dtype=float)
        return np.where((t >= self.t_on) & (t < self.t_off), self.magnitude, 0.0)


@dataclass(frozen=True)
class SmoothPiecewise:
    """A force profile through knots (t_i, v_i): constant before the first and after the
    last knot, a quintic smoothstep (C2) from each knot's value to the next's. A knot time
    given twice is a step: the value jumps there from the first knot's value to the second's
    (the value at that time is the second's).

    Attributes:
        times: non-decreasing knot times (no time more than twice), s.
        values: the values at the knots (N, or rad for an angle).
    """

    times: tuple
    values: tuple

    def __post_init__(self):
        if len(self.times) != len(self.values) or len(self.times) < 1:
            raise ValueError("SmoothPiecewise needs as many values as times (>= 1)")
        if any(b < a for a, b in zip(self.times, self.times[1:])) or any(
            a == c for a, c in zip(self.times, self.times[2:])
        ):
            raise ValueError(f"SmoothPiecewise times must increase (a time given twice is a step), got {self.times}")

    def value(self, t):
        if np.ndim(t) == 0:  # scalar path: called by the plant's force input every step
            t = float(t)
            k = bisect.bisect_right(self.times, t)
            if k == 0:
                return float(self.values[0])
            if k == len(self.times):
                return float(self.values[-1])
            t0, t1, v0, v1 = self.times[k - 1], self.times[k], self.values[k - 1], self.values[k]
            x = (t - t0) / (t1 - t0)
            return float(v0 + (v1 - v0) * smoothstep5(x))
        times, values = np.asarray(self.times, float), np.asarray(self.values, float)
        t_arr = np.asarray(t, dtype=float)
        out = np.full(t_arr.shape, values[0])
        for (t0, v0), (t1, v1) in zip(zip(times, values), zip(times[1:], values[1:])):
            if t1 == t0:  # a step: the next segment (or the last value) starts at t0
                continue
            out = np.where(t_arr >= t0, v0 + (v1 - v0) * smoothstep5((t_arr - t0) / (t1 - t0)), out)
        out = np.where(t_arr >= times[-1], values[-1], out)
        return float(out) if np.ndim(t) == 0 else out

    def plateaus(self, min_length: float) -> list[tuple[float, float]]:
        """Intervals between consecutive equal-valued knots lasting >= min_length, s."""
        return [
            (a, b)
            for (a, va), (b, vb) in zip(zip(self.times, self.values), zip(self.times[1:], self.values[1:]))
            if va == vb and b - a >= min_length
        ]


Profile = Sinusoid | PolynomialRampUpDown | Step | SmoothPiecewise | ForceProfile


def profile_support(profile: Profile) -> tuple[float, float]:
    """(t_a, t_b), s: the closed interval outside which ``profile`` is zero, for the
    profiles of this module (``Step``: [t_on, t_off], ``Sinusoid`` and
    ``PolynomialRampUpDown``: [t_start, t_end]); (-inf, inf) for any other profile
    (``SmoothPiecewise``, user profiles), which is then always evaluated."""
    if isinstance(profile, Step):
        return profile.t_on, profile.t_off
    if isinstance(profile, (Sinusoid, PolynomialRampUpDown)):
        return profile.t_start, profile.t_end
    return -math.inf, math.inf


# ---------------------------------------------------------------------------------------
# Push.
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Push:
    """A force of fixed world direction and time-varying magnitude on a point of a body.

    f_W(t) = profile.value(t) · direction_W, applied at the point P fixed in body B.

    Attributes:
        body_name: name of body B in the plant.
        p_BoP_B: (3,) position of P in B's body frame, m (read-only array).
        direction_W: (3,) unit direction in world (normalised at construction; read-only).
        profile: the magnitude profile, N (``Sinusoid``, ``PolynomialRampUpDown``, ``Step``
            or any object with a ``value(t)`` method).
        model_instance_name: the body's model instance, to disambiguate body names shared
            by several instances; None searches all instances.

    Raises:
        ValueError: empty body name, non-finite or wrongly sized vectors, zero direction,
            or a profile without ``value``.
    """

    body_name: str
    p_BoP_B: np.ndarray
    direction_W: np.ndarray
    profile: Profile
    model_instance_name: str | None = None

    def __post_init__(self):
        if not isinstance(self.body_name, str) or not self.body_name:
            raise ValueError(f"body_name must be a non-empty string, got {self.body_name!r}")
        if self.model_instance_name is not None and not isinstance(self.model_instance_name, str):
            raise ValueError(f"model_instance_name must be a string or None, got {self.model_instance_name!r}")
        p = vector3(self.p_BoP_B, "p_BoP_B")
        d = vector3(self.direction_W, "direction_W")
        norm = float(np.linalg.norm(d))
        if norm < 1e-12:
            raise ValueError(f"direction_W must be non-zero, got {self.direction_W!r}")
        d = d / norm
        p.flags.writeable = False
        d.flags.writeable = False
        object.__setattr__(self, "p_BoP_B", p)
        object.__setattr__(self, "direction_W", d)
        if not callable(getattr(self.profile, "value", None)):
            raise ValueError(f"profile must have a value(t) method, got {self.profile!r}")

    def force_W(self, t):
        """f_W(t) [N]: (3,) for a scalar t, (len(t), 3) for an array t."""
        m = self.profile.value(t)
        if np.ndim(m) == 0:
            return float(m) * self.direction_W
        return np.asarray(m)[..., None] * self.direction_W

    def __eq__(self, other):
        if not isinstance(other, Push):
            return NotImplemented
        return (
            self.body_name == other.body_name
            and self.model_instance_name == other.model_instance_name
            and np.array_equal(self.p_BoP_B, other.p_BoP_B)
            and np.array_equal(self.direction_W, other.direction_W)
            and self.profile == other.profile
        )

    def __hash__(self):
        return hash(
            (
                self.body_name,
                self.model_instance_name,
                tuple(self.p_BoP_B.tolist()),
                tuple(self.direction_W.tolist()),
                self.profile,
            )
        )


# ---------------------------------------------------------------------------------------
# The Drake source.
# ---------------------------------------------------------------------------------------


class _PushGroundTruth:
    """Cached ground truth shared by the wrench outputs (one per context)."""

    __slots__ = ("forces", "points", "active", "R_WF0", "p_WF0", "q")

    def __init__(self, k: int, nq: int):
        self.q = np.zeros(nq)  # plant positions the points were computed at
        self.forces = np.zeros((k, 3))  # f_W per push, N
        self.points = np.zeros((k, 3))  # p_WP per push, m
        self.active = np.zeros(k, dtype=bool)  # non-zero force
        self.R_WF0 = np.eye(3)  # base frame orientation in world
        self.p_WF0 = np.zeros(3)  # base frame origin in world, m


def _push_body(plant: MultibodyPlant, push: Push) -> RigidBody:
    return resolve_body(
        plant,
        push.body_name,
        f"push on body {push.body_name!r}",
        model_instance=push.model_instance_name,
        allow_world=True,
    )


def _tree_bodies(plant: MultibodyPlant, root: RigidBody) -> set:
    """Indices of the bodies of the subtree rooted at ``root`` (``root`` included)."""
    children: dict = {}
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        children.setdefault(joint.parent_body().index(), []).append(joint.child_body().index())
    out, stack = set(), [root.index()]
    while stack:
        body = stack.pop()
        out.add(body)
        stack.extend(children.get(body, []))
    return out


class PushSource(LeafSystem):
    """Applies a list of ``Push`` to a plant and reports their ground truth.

    Inputs:
        state: the TRUE plant state [q; v] (nq + nv). Read only by the ground-truth
            outputs; ``applied_spatial_forces`` does not depend on it.

    Outputs:
        applied_spatial_forces: abstract ``list[ExternallyAppliedSpatialForce]``, one per
            push whose force is non-zero at t (in the order given; pushes at zero are left
            out, so a study with many scheduled pushes hands the plant only the active
            one): body index, ``p_BoBq_B`` = the push's p_BoP_B, ``F_Bq_W`` = [0; f_W(t)].
            Depends on time only (no algebraic loop); connect to
            ``plant.get_applied_spatial_force_input_port()``.
        force_world: (3k) each push's force f_W, N, stacked in push order.
        point_world: (3k) each application point p_WP, m.
        total_wrench_world: (6) [Σ p_WP × f_W; Σ f_W]: moment about the world origin,
            N m, and force, N, in world.
        total_wrench_base: (6) the same wrench with the moment taken about the origin of
            the base frame F0 (``dynamics.topology.base_frame``) and both parts expressed
            in F0: what the external residual r_ext estimates (paper eqs. 17-18).
        tau_c_real: (n) Σ_c J^fb_c^T f_c (paper eq. 12), the true joint effort of the
            pushes, N m (joint order v[6:]).

    The ground-truth outputs (all but ``applied_spatial_forces``) are for loggers and
    metrics only: estimators must not read them. Pushes on bodies outside the floating-base
    tree (e.g. a body welded to the world) are applied and appear in ``force_world`` and
    ``point_world`` but are left out of ``total_wrench_*`` and ``tau_c_real``, which
    describe the external forces on the robot (see ``on_robot``).

    Cost (``hrp4_like``, two shoulder pushes, per evaluation after a time step, 2-core
    machine): the applied forces ~15 µs (25 scheduled pushes, one of them on, as in the
    contact study's runs: ~8 µs; ~150 µs when every push was handed over); the ground-truth
    outputs share one cached kinematics evaluation (~25 µs); ``tau_c_real`` adds ~40 µs:
    one translational Jacobian per push whose force is non-zero at t, one mass matrix and
    one 6x6 solve (nothing when all forces are zero). Log ground truth at the rate you need. ``tau_c_real`` equals
    Σ_c (``dynamics.floating_jacobian(q, B_c, p_c)``)^T f_c, summed before the base
    elimination so that k pushes need one mass matrix rather than k.
    """

    def __init__(self, plant: MultibodyPlant, pushes: Sequence[Push], *, dynamics: FloatingBaseDynamics | None = None):
        """Constructs the source.

        Args:
            plant: the finalized plant the pushes act on (one floating base, see
                ``systems.common.topology``).
            pushes: the pushes (may be empty).
            dynamics: a ``FloatingBaseDynamics(plant)`` to share; created if None.

        Raises:
            ValueError: plant not finalized or not a floating-base tree, a push that is not
                a ``Push``, an unknown or ambiguous body name, or ``dynamics`` built on
                another plant.
        """
        super().__init__()
        if not plant.is_finalized():
            raise ValueError("PushSource needs a finalized plant")
        pushes = tuple(pushes)
        for i, push in enumerate(pushes):
            if not isinstance(push, Push):
                raise ValueError(f"pushes[{i}] is a {type(push).__name__}, not a Push")
        if dynamics is None:
            dynamics = FloatingBaseDynamics(plant)
        elif dynamics.plant is not plant:
            raise ValueError("dynamics was built on a different plant")
        self._plant = plant
        self._dynamics = dynamics
        self._pushes = pushes
        self._bodies = tuple(_push_body(plant, p) for p in pushes)
        tree = _tree_bodies(plant, dynamics.topology.base_body)
        self._on_robot = np.array([b.index() in tree for b in self._bodies], dtype=bool)
        self._base_frame = dynamics.topology.base_frame
        self._nq = plant.num_positions()
        self._n = dynamics.num_joints
        self._plant_context = plant.CreateDefaultContext()
        k = len(pushes)
        self._k = k

        self._state_port = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())
        # Body index and point of each push's ExternallyAppliedSpatialForce.
        template = []
        for push, body in zip(pushes, self._bodies):
            f = ExternallyAppliedSpatialForce()
            f.body_index = body.index()
            f.p_BoBq_B = push.p_BoP_B.copy()
            f.F_Bq_W = SpatialForce(np.zeros(3), np.zeros(3))
            template.append(f)
        self._template = template
        # When each push can be non-zero (``profile_support``): the applied forces evaluate
        # only the profiles whose support holds t.
        support = np.array([profile_support(p.profile) for p in pushes], dtype=float).reshape(k, 2)
        self._support_start, self._support_end = support[:, 0].copy(), support[:, 1].copy()

        time_only = {self.time_ticket()}
        truth = {self.time_ticket(), self.input_port_ticket(self._state_port.get_index())}
        self.DeclareAbstractOutputPort(
            "applied_spatial_forces",
            lambda: _ForceListValue([]),
            self._CalcAppliedForces,
            prerequisites_of_calc=time_only,
        )
        self._kinematics = self.DeclareCacheEntry(
            "push ground truth (forces, points)",
            ValueProducer(
                allocate=lambda: AbstractValue.Make(_PushGroundTruth(k, self._nq)), calc=self._CalcKinematics
            ),
            prerequisites_of_calc=truth,
        )
        self.DeclareVectorOutputPort("force_world", 3 * k, self._CalcForceWorld, prerequisites_of_calc=time_only)
        self.DeclareVectorOutputPort("point_world", 3 * k, self._CalcPointWorld, prerequisites_of_calc=truth)
        self.DeclareVectorOutputPort("total_wrench_world", 6, self._CalcWrenchWorld, prerequisites_of_calc=truth)
        self.DeclareVectorOutputPort("total_wrench_base", 6, self._CalcWrenchBase, prerequisites_of_calc=truth)
        self.DeclareVectorOutputPort("tau_c_real", self._n, self._CalcTauCReal, prerequisites_of_calc=truth)

    # -- accessors ------------------------------------------------------------------------

    @property
    def pushes(self) -> tuple[Push, ...]:
        return self._pushes

    @property
    def bodies(self) -> tuple[RigidBody, ...]:
        """The resolved body of each push."""
        return self._bodies

    @property
    def on_robot(self) -> np.ndarray:
        """(k,) bool: whether each push's body belongs to the floating-base tree."""
        return self._on_robot.copy()

    @property
    def dynamics(self) -> FloatingBaseDynamics:
        return self._dynamics

    def forces_at(self, t: float) -> np.ndarray:
        """(k, 3) world forces of the pushes at time t, N."""
        out = np.zeros((self._k, 3))
        for i, (push, magnitude) in enumerate(zip(self._pushes, self._magnitudes(t))):
            if magnitude != 0.0:
                out[i] = magnitude * push.direction_W
        return out

    def _magnitudes(self, t: float) -> list[float]:
        """Each push's profile value at time t, N (plain floats)."""
        return [float(push.profile.value(t)) for push in self._pushes]

    # -- calculations ---------------------------------------------------------------------

    def _CalcAppliedForces(self, context: Context, output: AbstractValue) -> None:
        t = context.get_time()
        # The plant copies the list: the template's force objects, refilled (magnitude times
        # direction, as ``forces_at``), only for the pushes that are on.
        applied = []
        for i in np.flatnonzero((self._support_start <= t) & (t <= self._support_end)).tolist():
            magnitude = float(self._pushes[i].profile.value(t))
            if magnitude != 0.0:
                force = self._template[i]
                force.F_Bq_W = SpatialForce(_ZERO3, magnitude * self._pushes[i].direction_W)
                applied.append(force)
        output.set_value(applied)

    def _CalcKinematics(self, context: Context, value: AbstractValue) -> None:
        kin = value.get_mutable_value()
        kin.forces[:] = self.forces_at(context.get_time())
        kin.active[:] = kin.forces.any(axis=1)
        kin.q[:] = self._state_port.Eval(context)[: self._nq]
        plant, ctx = self._plant, self._plant_context
        plant.SetPositions(ctx, kin.q)
        X_WF0 = self._base_frame.CalcPoseInWorld(ctx).GetAsMatrix34()
        kin.R_WF0[:] = X_WF0[:, :3]
        kin.p_WF0[:] = X_WF0[:, 3]
        for i, (push, body) in enumerate(zip(self._pushes, self._bodies)):
            X_WB = plant.EvalBodyPoseInWorld(ctx, body).GetAsMatrix34()
            kin.points[i] = X_WB[:, :3] @ push.p_BoP_B + X_WB[:, 3]

    def _eval_kinematics(self, context: Context) -> _PushGroundTruth:
        return self._kinematics.Eval(context)

    def _CalcForceWorld(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.forces_at(context.get_time()).reshape(-1))

    def _CalcPointWorld(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._eval_kinematics(context).points.reshape(-1))

    def _wrench_world(self, kin: _PushGroundTruth) -> np.ndarray:
        """[Σ p × f; Σ f] over the active pushes on the robot, world, about the world origin."""
        w = np.zeros(6)
        for i in np.flatnonzero(kin.active & self._on_robot):
            w[:3] += cross(kin.points[i], kin.forces[i])
            w[3:] += kin.forces[i]
        return w

    def _CalcWrenchWorld(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._wrench_world(self._eval_kinematics(context)))

    def _CalcWrenchBase(self, context: Context, output: BasicVector) -> None:
        kin = self._eval_kinematics(context)
        w = self._wrench_world(kin)
        if w.any():
            # Shift the moment to the F0 origin (still in world), then express both in F0.
            w[:3] -= cross(kin.p_WF0, w[3:])
            R_F0W = kin.R_WF0.T
            w[:3] = R_F0W @ w[:3]
            w[3:] = R_F0W @ w[3:]
        output.SetFromVector(w)

    def _CalcTauCReal(self, context: Context, output: BasicVector) -> None:
        """Eq. (12): τ = Σ_c J^fb_c^T f_c with J^fb = J_j - J_b M_bb^-1 M_bj (world coordinates).

        Summed before the base elimination: with g = Σ_c J_c^T f_c (all nv coordinates),
        τ = g_j - M_bj^T M_bb^-1 g_b, one mass matrix and one 6x6 solve for all pushes.
        """
        kin = self._eval_kinematics(context)
        use = np.flatnonzero(kin.active & self._on_robot)
        if use.size == 0:
            output.SetFromVector(np.zeros(self._n))
            return
        plant, ctx = self._plant, self._plant_context
        plant.SetPositions(ctx, kin.q)  # the shared plant context may hold another state
        world = plant.world_frame()
        g = np.zeros(plant.num_velocities())
        for i in use:
            J = plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, self._bodies[i].body_frame(), self._pushes[i].p_BoP_B, world, world
            )
            g += J.T @ kin.forces[i]
        M = plant.CalcMassMatrix(ctx)
        _, y, info = lapack.dposv(M[:6, :6], g[:6])
        if info != 0:
            y = np.linalg.solve(M[:6, :6], g[:6])
        output.SetFromVector(g[6:] - M[:6, 6:].T @ y)


_ZERO3 = np.zeros(3)
#: The plant's applied_spatial_force input type (typed even for an empty push list).
_ForceListValue = Value[list[ExternallyAppliedSpatialForce]]
