"""Where and how hard: contact force estimation, contact detection and single-contact
localization from the residuals of Flacco, Paolillo, Kheddar (2016), Secs. V-VI.

* ``ContactForceEstimator``: forces at contact points from the residuals, three modes:
  ``"external"`` eq. (19), the single unknown contact's force from the external residual;
  ``"stacked"`` eq. (20), k known contact points from the external AND internal residuals
  by a (weighted, optionally damped) pseudo-inverse; ``"classical"`` eq. (15), the
  pseudo-inverse of the classical residual (the baseline).
* ``ContactDetector``: contact / no contact from the residuals' Mahalanobis norms with
  thresholds from the sensor noise (chi-square quantiles) and hysteresis; time of detection.
* ``ContactLocalizer``: Sec. VI and Fig. 9: the line of action of the estimated force
  (eq. 22), its entry points into the robot's collision primitives, and the candidate whose
  predicted joint effort J^fb,T f_hat (eq. 12) best matches the internal residual.
* ``predicted_residual_covariances``: the noise of the internal and external residuals
  predicted from the sensor noise (what the detector's default thresholds come from).

Conventions (as ``systems.residuals.momentum_residuals``): joint vectors in the plant's v[6:] order (the free
joint's velocities first); ``external_wrench_world`` = [moment about the WORLD origin, N m;
force, N], world frame; ``residual`` (internal) = n = nv - 6 joint efforts, N m; the
classical residual = nv entries, [moment about the F0 origin; force] in F0, then joints.
A point force f at p on body B has the world wrench [p x f; f], the classical residual
J^T f = [R_WF0^T (p - p_F0) x f; R_WF0^T f; J_j^T f] and the internal residual
J^fb,T f with J^fb = J_j - J_b M_bb^-1 M_bj (eq. 12, ``FloatingBaseDynamics``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.containers import namedview
from pydrake.common.value import AbstractValue
from pydrake.geometry import SceneGraph, SceneGraphInspector
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, Frame, JacobianWrtVariable, RigidBody
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem, ValueProducer
from scipy.optimize import nnls
from scipy.signal import lfilter
from scipy.stats import chi2

from systems.common.checks import eval_finite_input, positive_number, resolve_body
from systems.common.spatial import cross, skew
from systems.common.topology import floating_base_topology, rigid_link_of_bodies, same_rigid_link
from systems.residuals.geometry_intersection import (
    BOX,
    CAPSULE,
    CYLINDER,
    SPHERE,
    RobotGeometry,
    line_intersections,
    outward_normals,
    signed_distances,
)
from systems.residuals.momentum_residuals import check_wrench_frames
from systems.simulation import sensors as _sensors

DEFAULT_PERIOD = 1e-3  # s

__all__ = [
    "ALL_WRENCH_COMPONENTS",
    "ContactDetector",
    "ContactForceEstimator",
    "ContactLocalizer",
    "GatedEstimate",
    "LocalizationResult",
    "SOLE_SHEAR_AND_YAW",
    "STATUS_REASONS",
    "UnknownWrenches",
    "first_order_filter",
    "predicted_residual_covariances",
    "unexplained_residuals",
    "unknown_wrench_columns",
    "wrench_maps",
    "wrench_maps_of_samples",
]


# ---------------------------------------------------------------------------------------
# Shared kinematics: Jacobians and the floating-base elimination at one sensed q.
# ---------------------------------------------------------------------------------------


class _SensedConfiguration:
    """A private plant context at the sensed positions: body poses, translational Jacobians,
    the base elimination A = M_bb^-1 M_bj (computed once per q), F0's pose."""

    def __init__(self, plant: MultibodyPlant, who: str):
        if not plant.is_finalized():
            raise ValueError(f"{who}: the plant must be finalized")
        self.topology = floating_base_topology(plant)  # ValueError without a floating base
        if self.topology.free_joint.velocity_start() != 0 or self.topology.free_joint.position_start() != 0:
            raise ValueError(f"{who}: the free joint's coordinates must come first (q[:7], v[:6])")
        self.plant = plant
        self.context = plant.CreateDefaultContext()
        self.nq, self.nv = plant.num_positions(), plant.num_velocities()
        self.n = self.nv - 6
        self._q_key: bytes | None = None
        self._A: np.ndarray | None = None
        self._world = plant.world_frame()
        self._pinocchio = None  # ``pinocchio``

    def set_positions(self, q: np.ndarray) -> None:
        key = q.tobytes()
        if key != self._q_key:
            self.plant.SetPositions(self.context, q)
            self._q_key = key
            self._A = None

    def elimination(self) -> np.ndarray:
        """A = M_bb^-1 M_bj (6 x n) at the current q: J^fb = J_j - J_b A."""
        if self._A is None:
            M = self.plant.CalcMassMatrix(self.context)
            self._A = np.linalg.solve(M[:6, :6], M[:6, 6:])
        return self._A

    def jacobian(self, body: RigidBody, p_BoP_B: np.ndarray) -> np.ndarray:
        """(3, nv) translational Jacobian of point P of ``body`` w.r.t. v, world."""
        return self.plant.CalcJacobianTranslationalVelocity(
            self.context, JacobianWrtVariable.kV, body.body_frame(), p_BoP_B, self._world, self._world
        )

    def floating_jacobian(self, body: RigidBody, p_BoP_B: np.ndarray) -> np.ndarray:
        """(3, n) J^fb of point P (eq. 12): tau = J^fb^T f_W."""
        J = self.jacobian(body, p_BoP_B)
        return J[:, 6:] - J[:, :6] @ self.elimination()

    def body_pose(self, body: RigidBody) -> np.ndarray:
        return self.plant.EvalBodyPoseInWorld(self.context, body).GetAsMatrix34()

    def base_pose(self) -> np.ndarray:
        return self.topology.base_frame.CalcPoseInWorld(self.context).GetAsMatrix34()

    @property
    def pinocchio(self):
        """Pinocchio's kinematics and mass matrix of the plant (``PinocchioFloatingBaseDynamics``),
        built on first use: the computations over many samples at once (``wrench_maps_of_samples``)."""
        if self._pinocchio is None:
            from systems.dynamics.pinocchio_dynamics import PinocchioFloatingBaseDynamics

            self._pinocchio = PinocchioFloatingBaseDynamics(self.plant)
        return self._pinocchio


def _unknown_frames(plant: MultibodyPlant, frames: Sequence, who: str) -> tuple[Frame, ...]:
    """``check_wrench_frames`` for unknown wrench frames, its message prefixed by ``who``."""
    try:
        return check_wrench_frames(plant, frames, "unknown wrench frame")
    except ValueError as error:
        raise ValueError(f"{who}: {error}") from None


def _skews(r: np.ndarray) -> np.ndarray:
    """(m, 3, 3) skew matrices of (m, 3) vectors: skew(r) f = r x f."""
    S = np.zeros((len(r), 3, 3))
    S[:, 0, 1], S[:, 0, 2] = -r[:, 2], r[:, 1]
    S[:, 1, 0], S[:, 1, 2] = r[:, 2], -r[:, 0]
    S[:, 2, 0], S[:, 2, 1] = -r[:, 1], r[:, 0]
    return S


def wrench_maps(kin: _SensedConfiguration, frames: Sequence[Frame]) -> np.ndarray:
    """(m, 6 + n, 6): for each frame F, the map T_F of a wrench w_F = [m_F (about F's
    origin); f] (world, N m and N) into the stacked residuals [r_ext (moment about the
    world origin; force); r_int], at the positions last set on ``kin``:

        T_F = [[I, skew(p_F)]; [0, I]; J^fb_F^T]

    (the world wrench [m_F + p_F x f; f] to the external residual, eq. 16, and J^fb_F^T w_F
    to the internal one, eq. 12; J^fb_F = J_j - J_b M_bb^-1 M_bj of F's spatial Jacobian
    [angular; translational])."""
    plant = kin.plant
    world = plant.world_frame()
    if not frames:
        return np.zeros((0, 6 + kin.n, 6))
    E = kin.elimination()
    p_F = np.array([frame.CalcPoseInWorld(kin.context).translation() for frame in frames])
    J_fb = np.empty((len(frames), 6, kin.n))
    for i, frame in enumerate(frames):
        J = plant.CalcJacobianSpatialVelocity(kin.context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world)
        J_fb[i] = J[:, 6:] - J[:, :6] @ E
    return _assemble_wrench_maps(p_F, J_fb)


def _assemble_wrench_maps(p_F: np.ndarray, J_fb: np.ndarray) -> np.ndarray:
    """T_F = [[I, skew(p_F)]; [0, I]; J^fb_F^T] (..., 6 + n, 6) of frame origins p_F (..., 3)
    and their floating Jacobians J^fb_F (..., 6, n) (``wrench_maps``)."""
    lead, n = p_F.shape[:-1], J_fb.shape[-1]
    T = np.zeros((*lead, 6 + n, 6))
    T[..., :3, :3] = np.eye(3)
    T[..., :3, 3:] = _skews(p_F.reshape(-1, 3)).reshape(*lead, 3, 3)
    T[..., 3:6, 3:] = np.eye(3)
    T[..., 6:, :] = np.swapaxes(J_fb, -1, -2)
    return T


def wrench_maps_of_samples(dynamics, frames: Sequence[Frame], q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``wrench_maps`` at each of K positions q (K, nq) at once, (K, m, 6 + n, 6), and the
    frames' rotations R_WF (K, m, 3, 3), from ``dynamics``, a ``PinocchioFloatingBaseDynamics``
    of the plant (``floating_frame_jacobians_of_samples``: Pinocchio's kinematics and mass
    matrix per sample, the rest stacked); the same numbers as ``wrench_maps`` to rounding."""
    q = np.asarray(q, dtype=float)
    J_fb, p_WF, R_WF = dynamics.floating_frame_jacobians_of_samples(q, dynamics.frame_ids(frames))
    return _assemble_wrench_maps(p_WF, J_fb), R_WF


def unknown_wrench_columns(kin: _SensedConfiguration, frames: Sequence[Frame]) -> np.ndarray:
    """(6 + n, 6 m) map of m unknown wrenches at known frames (the feet of a robot without
    foot F/T sensors: the ground's wrench on each sole) into the stacked residuals, at the
    positions last set on ``kin``: the ``wrench_maps`` side by side. Eq. (10) subtracts
    these with measured wrenches; without F/T sensors they stay unknowns of the fit.
    """
    return np.concatenate(list(wrench_maps(kin, frames)), axis=1) if frames else np.zeros((6 + kin.n, 0))


#: The six components of a wrench [m_x, m_y, m_z, f_x, f_y, f_z] (moment about the frame's
#: origin; force) in a frame's own axes, by index: every component is unknown.
ALL_WRENCH_COMPONENTS = (0, 1, 2, 3, 4, 5)
#: What a sole's force-sensing resistors leave unknown: the moment about the sole's normal
#: (m_z) and the shear force (f_x, f_y), in the sole's axes. The FSRs measure the normal
#: force f_z and, through where they sit, the moments m_x and m_y (the centre of pressure):
#: the known wrench of ``systems.observer.fsr_sensing.FsrSoleWrenches``.
SOLE_SHEAR_AND_YAW = (2, 3, 4)


def _component_basis(R_WF: np.ndarray, chosen: Sequence[int]) -> np.ndarray:
    """(..., 6, k) the world directions [moment; force] of a frame's wrench components
    ``chosen`` (indices in its own axes' [m_x, m_y, m_z, f_x, f_y, f_z]), its rotation R_WF (..., 3, 3)."""
    B = np.zeros((*R_WF.shape[:-2], 6, 6))
    B[..., :3, :3], B[..., 3:, 3:] = R_WF, R_WF
    return B[..., list(chosen)]


def first_order_filter(samples: np.ndarray, factor: float, previous: np.ndarray) -> np.ndarray:
    """``y[k] = (1 - a) y[k-1] + a x[k]`` along the first axis of ``samples`` (a = ``factor``),
    from ``y[-1] = previous``: the residuals' own filter (a = K T) as ``ContactDetector`` and
    ``SoleWrenchCompensation`` apply it to columns update by update, and the localizer's
    running means (a = T / tau), the same arithmetic as their updates."""
    return lfilter([factor], [1.0, -(1.0 - factor)], samples, axis=0, zi=((1.0 - factor) * previous)[None])[0]


class UnknownWrenches:
    """Unknown wrenches at known frames (the ground's wrench on each sole of a robot
    without foot F/T sensors), whole or in part: the columns they add to the stacked
    residuals [r_ext; r_int] and the world wrenches of the values fitted to them.

    A frame whose ``components`` are all six (``ALL_WRENCH_COMPONENTS``) has its wrench
    [moment about its origin; force] in world as six unknowns, the columns T_F of
    ``wrench_maps``. A frame with fewer has only those components of its wrench in its own
    axes as unknowns (its sole's FSRs measure the others, subtracted with the known
    wrenches), the columns T_F diag(R_WF, R_WF) S (S the selected columns of I_6).

    Args:
        plant: the estimators' finalized plant.
        frames: frames or names, each at most once.
        components: per frame, the unknown components' indices in [m_x, m_y, m_z, f_x, f_y,
            f_z] of the frame's axes (``SOLE_SHEAR_AND_YAW`` for a sole with FSRs); None:
            all six for every frame.
        who: the owner's name, for the error messages.

    Raises:
        ValueError: a frame the plant does not have or given twice; ``components`` not one
            non-empty set of distinct indices 0-5 per frame.
    """

    def __init__(self, plant: MultibodyPlant, frames: Sequence, components: Sequence | None, who: str):
        self.frames = _unknown_frames(plant, frames, who)
        if components is None:
            components = [ALL_WRENCH_COMPONENTS] * len(self.frames)
        components = list(components)
        if len(components) != len(self.frames):
            raise ValueError(
                f"{who}: unknown_wrench_components has {len(components)} entries for {len(self.frames)} "
                "unknown wrench frames"
            )
        checked = []
        for frame, chosen in zip(self.frames, components):
            try:
                chosen = tuple(sorted(int(i) for i in chosen))
            except (TypeError, ValueError):
                chosen = None
            if not chosen or len(set(chosen)) != len(chosen) or not all(0 <= i < 6 for i in chosen):
                raise ValueError(
                    f"{who}: unknown_wrench_components for '{frame.name()}' must be distinct indices 0-5 of "
                    f"[m_x, m_y, m_z, f_x, f_y, f_z] in its axes, got {components[len(checked)]!r}"
                )
            checked.append(chosen)
        self.components = tuple(checked)
        self._partial = tuple(c != ALL_WRENCH_COMPONENTS for c in self.components)
        self.size = sum(len(c) for c in self.components)

    def __bool__(self) -> bool:
        return bool(self.frames)

    def __len__(self) -> int:
        return len(self.frames)

    def _bases(self, kin: _SensedConfiguration) -> list[np.ndarray | None]:
        return self.world_bases(kin.context)

    def world_bases(self, context: Context) -> list[np.ndarray | None]:
        """Per frame, the (6, k) world directions [moment; force] of its unknown components
        at the positions of ``context`` (the plant's), or None for all six (the identity)."""
        return [
            _component_basis(frame.CalcPoseInWorld(context).rotation().matrix(), chosen) if partial else None
            for frame, chosen, partial in zip(self.frames, self.components, self._partial)
        ]

    def columns(self, kin: _SensedConfiguration) -> np.ndarray:
        """(6 + n, size) their columns in the stacked residuals at the positions last set on
        ``kin``: per frame T_F (all six, world components) or T_F diag(R_WF, R_WF) S."""
        if not self.frames:
            return np.zeros((6 + kin.n, 0))
        T = wrench_maps(kin, self.frames)
        parts = [T_F if B is None else T_F @ B for T_F, B in zip(T, self._bases(kin))]
        return np.concatenate(parts, axis=1)

    def columns_of_samples(self, dynamics, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``columns`` and ``world_map`` at each of K positions q (K, nq) at once: (K, 6 + n,
        size) and (K, 6 m, size), from ``dynamics``, a ``PinocchioFloatingBaseDynamics`` of
        the plant (``wrench_maps_of_samples``), the same numbers to rounding."""
        K = q.shape[0]
        T, R_WF = wrench_maps_of_samples(dynamics, self.frames, q)
        columns = np.empty((K, T.shape[2], self.size))
        world = np.zeros((K, 6 * len(self.frames), self.size))
        start = 0
        for i, (chosen, partial) in enumerate(zip(self.components, self._partial)):
            stop = start + len(chosen)
            if not partial:
                columns[:, :, start:stop] = T[:, i]
                world[:, 6 * i : 6 * i + 6, start:stop] = np.eye(6)
            else:
                B = _component_basis(R_WF[:, i], chosen)
                columns[:, :, start:stop] = T[:, i] @ B
                world[:, 6 * i : 6 * i + 6, start:stop] = B
            start = stop
        return columns, world

    def world_map(self, kin: _SensedConfiguration) -> np.ndarray:
        """(6 m, size) from the unknowns' values to the m wrenches [moment about the frame's
        origin; force] in world, stacked, at the positions last set on ``kin`` (a frame's
        measured components get 0 here: the FSRs' share is among the known wrenches)."""
        out = np.zeros((6 * len(self.frames), self.size))
        start = 0
        for i, (chosen, B) in enumerate(zip(self.components, self._bases(kin))):
            out[6 * i : 6 * i + 6, start : start + len(chosen)] = np.eye(6) if B is None else B
            start += len(chosen)
        return out

    def world_wrenches(self, kin: _SensedConfiguration, values: np.ndarray) -> np.ndarray:
        """(m, 6) ``world_map`` applied to fitted unknowns ``values`` (size,)."""
        return (self.world_map(kin) @ np.asarray(values, dtype=float)).reshape(-1, 6)


def _bounding_radii(geometry: RobotGeometry) -> np.ndarray:
    """(g,) the radius of each primitive's bounding sphere about its frame's origin, m:
    a sphere's radius, a box's half diagonal, a cylinder's hypot(radius, half length), a
    capsule's radius plus half length; inf for a convex hull (never bounded)."""
    kinds, p = geometry.kinds, geometry.params
    return np.select(
        [kinds == SPHERE, kinds == BOX, kinds == CYLINDER, kinds == CAPSULE],
        [p[:, 0], np.linalg.norm(p, axis=1), np.hypot(p[:, 0], p[:, 1]), p[:, 0] + p[:, 1]],
        np.inf,
    )


def candidate_geometry(
    plant: MultibodyPlant,
    scene_graph: SceneGraph | SceneGraphInspector,
    bodies: Sequence | None,
    exclude_bodies: Sequence,
    who: str,
    skip_unsupported_shapes: bool = False,
) -> tuple[RobotGeometry, list[RigidBody]]:
    """The collision primitives of a localizer's candidate links and those links (in the
    geometry's ``bodies`` order): ``bodies`` (RigidBody, names or indices; default every
    body with a collision geometry) less ``exclude_bodies``.

    Raises:
        ValueError: a bad scene graph, an unknown body, no candidate left, an unsupported
            shape (unless ``skip_unsupported_shapes``); the message starts with ``who``.
    """
    inspector = scene_graph.model_inspector() if isinstance(scene_graph, SceneGraph) else scene_graph
    if not isinstance(inspector, SceneGraphInspector):
        raise ValueError(f"{who}: scene_graph must be a SceneGraph or SceneGraphInspector")
    excluded = {int(resolve_body(plant, b, who).index()) for b in exclude_bodies}
    if bodies is None:
        candidates = [plant.get_body(BodyIndex(i)) for i in range(1, plant.num_bodies())]
        candidates = [b for b in candidates if plant.GetCollisionGeometriesForBody(b)]
    else:
        candidates = [resolve_body(plant, b, who) for b in bodies]
    candidates = [b for b in candidates if int(b.index()) not in excluded]
    if not candidates:
        raise ValueError(f"{who}: no candidate link left")
    geometry = RobotGeometry.from_plant(plant, inspector, candidates, skip_unsupported=skip_unsupported_shapes)
    return geometry, [plant.get_body(BodyIndex(int(i))) for i in geometry.bodies]


class _JointStops:
    """The position limits of the 1-DoF joints (v[6:] order), to tell which rest on a stop."""

    def __init__(self, joints: Sequence, margin: float):
        self._q_index = np.array([j.position_start() for j in joints], dtype=int)
        self._lower = np.array([j.position_lower_limits()[0] for j in joints], dtype=float)
        self._upper = np.array([j.position_upper_limits()[0] for j in joints], dtype=float)
        self._margin = float(margin)  # -inf: no joint rests on a stop

    def limited(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(indices, signs) of the joints within the margin of a limit at the positions q:
        +1 at a lower limit (the stop can only push the joint up), -1 at an upper one."""
        qj = np.asarray(q, dtype=float)[self._q_index]
        at_lower = qj <= self._lower + self._margin
        at_upper = qj >= self._upper - self._margin
        index = np.flatnonzero(at_lower | at_upper)
        return index, np.where(at_lower[index], 1.0, -1.0)


#: ContactDetector's state: contact (1/0), detection time (s, -1: none), consecutive samples
#: above the on-thresholds, time below the off-thresholds (s), the two test statistics.
_DetectorState = namedview(
    "_DetectorState",
    ("detected", "detection_time", "samples_above", "time_below", "statistic_external", "statistic_internal"),
)


def _weights(value, size: int, what: str) -> np.ndarray:
    w = np.asarray(value, dtype=float)
    if w.ndim == 0:
        w = np.full(size, float(w))
    if w.shape != (size,) or not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise ValueError(
            f"{what} must be a non-negative scalar or {size} non-negative finite numbers, got shape {w.shape}"
        )
    return w


# ---------------------------------------------------------------------------------------
# ContactForceEstimator: eqs. (15), (19), (20).
# ---------------------------------------------------------------------------------------


class ContactForceEstimator(LeafSystem):
    """Forces at contact points from the momentum residuals (paper Sec. V).

    Modes:

    * ``"external"``, eq. (19): one unknown contact; its force is the force part of the
      external residual, f_1 = r_ext,f (world). Needs no contact point.
    * ``"stacked"``, eq. (20): k known points (body B_c, p_c): solve
      [[p_1 x .. p_k x], [1 .. 1], [J^fb_1^T .. J^fb_k^T]] [f_1; ..; f_k] = [r_ext; r_int]
      (top: the world wrench about the world origin; bottom: eq. 12) in the least-squares
      sense with weights W = diag(external_weight (6), internal_weight (n)) (the paper
      suggests weighting the residuals by their different noise, Sec. V) and Tikhonov
      damping: f = (A^T W^2 A + damping^2 I)^-1 A^T W^2 b; with damping 0 the minimum-norm
      weighted pseudo-inverse (W A)^# W b.

      Without foot F/T sensors (``unknown_wrench_frames``: the soles), eq. (10) has no
      measured wrench to subtract and the residuals carry the ground's wrenches too: they
      join the unknowns, A = [A_forces, T_F1 .. T_Fm] (``unknown_wrench_columns``), solved
      for in the same least squares: 3 k + 6 m unknowns from 6 + n rows.
    * ``"classical"``, eq. (15): f = [J_1^T .. J_k^T]^# r with J_c the Jacobian of model
      (8) (base velocity = F0's twist in F0), i.e. J_c^T f = [R^T (p_c - p_F0) x f; R^T f;
      J_j,c^T f], weights ``classical_weight`` (nv), same damping.

    Inputs (by mode):
        ``state`` (stacked, classical): the sensed [q; v] (only q is used).
        ``external_wrench_world`` (external, stacked): ExternalResidual's output, 6.
        ``residual`` (stacked: InternalResidual's, n; classical: ClassicalResidual's, nv).

        ``contact_points`` (stacked, classical, when no points are given at construction):
            4 k numbers, [body index, p_x, p_y, p_z] per contact, p in the body frame, m.

    Outputs (direct feedthrough, no state: a static map of the residuals, solved once per
    change of the inputs and cached):

        ``contact_forces_world``: 3 k, the forces f_c in world, N.

        ``fit_error``: 1, ||W (A f - b)||, the weighted mismatch (0 when the points explain
            the residuals exactly; large when the assumed points are wrong). 0 in mode
            ``"external"``.

        ``unknown_wrenches_world`` (only with ``unknown_wrench_frames``): 6 m, the wrench
            [moment about the frame's origin, N m; force, N] (world) at each frame.

    Args:
        plant: finalized floating-base plant (free joint coordinates first).
        mode: "external", "stacked" or "classical".
        contact_points: (body, p_B) pairs (body: RigidBody, name or index; p_B: 3 numbers,
            m), or None to read them from the ``contact_points`` port.
        num_contacts: k when the points come from the port (default 1).
        external_weight, internal_weight, classical_weight: per-residual weights (scalar or
            per entry), dimensionless relative weights; e.g. 1 / noise std.
        damping: Tikhonov damping, >= 0 (N m per N units of the weighted rows).
        unknown_wrench_frames: frames (or names) whose wrenches are unknowns of the fit
            (mode "stacked" only): the soles of a robot without foot F/T sensors, whose
            residuals were computed without ``known_wrench_frames``. Output
            ``unknown_wrenches_world`` has their wrenches (6 per frame, [moment about the
            frame's origin; force], world; a measured component's share is 0 there).
        unknown_wrench_components: per unknown wrench frame, the indices of its unknown
            components in [m_x, m_y, m_z, f_x, f_y, f_z] of its axes (``UnknownWrenches``;
            ``SOLE_SHEAR_AND_YAW`` for a sole whose FSRs' wrench is among the known ones);
            None: all six.

    Raises:
        ValueError: unknown mode, unknown body, frame or world body, wrong sizes, negative
            weights, unknown wrench frames in a mode other than "stacked".
    """

    MODES = ("external", "stacked", "classical")

    def __init__(
        self,
        plant: MultibodyPlant,
        mode: str,
        contact_points: Sequence[tuple] | None = None,
        *,
        num_contacts: int | None = None,
        external_weight=1.0,
        internal_weight=1.0,
        classical_weight=1.0,
        damping: float = 0.0,
        unknown_wrench_frames: Sequence = (),
        unknown_wrench_components: Sequence | None = None,
    ):
        super().__init__()
        who = self._who = "ContactForceEstimator"
        if mode not in self.MODES:
            raise ValueError(f"{who}: unknown mode {mode!r}; choose one of {self.MODES}")
        self._mode = mode
        self._kin = _SensedConfiguration(plant, who)
        self._unknown = UnknownWrenches(plant, unknown_wrench_frames, unknown_wrench_components, who)
        if self._unknown and mode != "stacked":
            raise ValueError(
                f"{who}: unknown_wrench_frames need mode 'stacked' (eq. 20 with the feet's wrenches as "
                f"unknowns), got mode {mode!r}"
            )
        nq, nv, n = self._kin.nq, self._kin.nv, self._kin.n
        self._damping = float(damping)
        if not math.isfinite(self._damping) or self._damping < 0.0:
            raise ValueError(f"{who}: damping must be a non-negative number, got {damping}")
        if contact_points is not None:
            points = []
            for i, item in enumerate(contact_points):
                try:
                    body, p = item
                except (TypeError, ValueError):
                    raise ValueError(f"{who}: contact_points[{i}] must be a (body, point) pair") from None
                p = np.asarray(p, dtype=float).reshape(-1)
                if p.shape != (3,) or not np.all(np.isfinite(p)):
                    raise ValueError(f"{who}: contact_points[{i}] point must be 3 finite numbers")
                points.append((resolve_body(plant, body, who), p))
            if not points:
                raise ValueError(f"{who}: contact_points is empty")
            if num_contacts is not None and num_contacts != len(points):
                raise ValueError(f"{who}: num_contacts={num_contacts} but {len(points)} contact points given")
            self._points = tuple(points)
            k = len(points)
        else:
            self._points = None
            if num_contacts is not None and (int(num_contacts) != num_contacts or num_contacts < 1):
                raise ValueError(f"{who}: num_contacts must be a positive integer, got {num_contacts}")
            k = 1 if num_contacts is None else int(num_contacts)
        if mode == "external" and k != 1:
            raise ValueError(f"{who}: mode 'external' (eq. 19) estimates exactly one contact, got {k}")
        self._k = k
        self._w_ext = _weights(external_weight, 6, f"{who}: external_weight")
        self._w_int = _weights(internal_weight, n, f"{who}: internal_weight")
        self._w_cls = _weights(classical_weight, nv, f"{who}: classical_weight")

        self._state_port = self._wrench_port = self._residual_port = self._points_port = None
        if mode in ("stacked", "classical"):
            self._state_port = self.DeclareVectorInputPort("state", nq + nv)
        if mode in ("external", "stacked"):
            self._wrench_port = self.DeclareVectorInputPort("external_wrench_world", 6)
        if mode == "stacked":
            self._residual_port = self.DeclareVectorInputPort("residual", n)
        if mode == "classical":
            self._residual_port = self.DeclareVectorInputPort("residual", nv)
        if mode != "external" and self._points is None:
            self._points_port = self.DeclareVectorInputPort("contact_points", 4 * k)
        # One solve per input change, shared by the outputs: [f (3 k); unknown wrenches (6 m,
        # world); fit error].
        size = 3 * k + 6 * len(self._unknown) + 1
        self._solution = self.DeclareCacheEntry(
            "forces and fit error",
            ValueProducer(allocate=lambda: AbstractValue.Make(np.zeros(size)), calc=self._CalcSolution),
            prerequisites_of_calc={self.all_input_ports_ticket()},
        )
        inputs = {self.all_input_ports_ticket()}
        self.DeclareVectorOutputPort("contact_forces_world", 3 * k, self._CalcForces, inputs)
        self.DeclareVectorOutputPort("fit_error", 1, self._CalcFitError, inputs)
        if self._unknown:
            self.DeclareVectorOutputPort(
                "unknown_wrenches_world",
                6 * len(self._unknown),
                lambda c, o: o.SetFromVector(self._solution.Eval(c)[3 * k : -1]),
                inputs,
            )

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def num_contacts(self) -> int:
        return self._k

    @property
    def unknown_wrench_frames(self) -> tuple[Frame, ...]:
        """The frames whose wrenches are unknowns of the fit (() with foot F/T sensors)."""
        return self._unknown.frames

    def _contact_points(self, context: Context) -> list[tuple[RigidBody, np.ndarray]]:
        if self._points is not None:
            return list(self._points)
        raw = eval_finite_input(self._who, self._points_port, context).reshape(self._k, 4)
        plant = self._kin.plant
        out = []
        for i, row in enumerate(raw):
            if row[0] != round(row[0]):
                raise ValueError(
                    f"{self._who}: input 'contact_points' entry {i}: body index {row[0]} is not an integer"
                )
            out.append(
                (
                    resolve_body(plant, int(round(row[0])), f"{self._who}: input 'contact_points' entry {i}"),
                    row[1:].copy(),
                )
            )
        return out

    def system_matrix(
        self, q: np.ndarray, points: Sequence[tuple[RigidBody, np.ndarray]]
    ) -> tuple[np.ndarray, np.ndarray]:
        """(A, w): the linear map from the stacked forces [f_1; ..; f_k] (world), then the
        unknown wrenches' components (``UnknownWrenches.columns``), to the residuals this mode
        reads, and the row weights. Mode "stacked": (6 + n) rows; "classical": nv rows."""
        kin = self._kin
        kin.set_positions(q)
        k = len(points)
        if self._mode == "stacked":
            A = np.zeros((6 + kin.n, 3 * k))
            E = kin.elimination()
            for c, (body, p_B) in enumerate(points):
                X = kin.body_pose(body)
                p_W = X[:, :3] @ p_B + X[:, 3]
                J = kin.jacobian(body, p_B)
                A[:3, 3 * c : 3 * c + 3] = skew(p_W)
                A[3:6, 3 * c : 3 * c + 3] = np.eye(3)
                A[6:, 3 * c : 3 * c + 3] = (J[:, 6:] - J[:, :6] @ E).T
            A = np.concatenate((A, self._unknown.columns(kin)), axis=1)
            return A, np.concatenate((self._w_ext, self._w_int))
        # classical, model (8)
        X_WF0 = kin.base_pose()
        R, p_F0 = X_WF0[:, :3], X_WF0[:, 3]
        A = np.zeros((kin.nv, 3 * k))
        for c, (body, p_B) in enumerate(points):
            X = kin.body_pose(body)
            p_W = X[:, :3] @ p_B + X[:, 3]
            J = kin.jacobian(body, p_B)
            A[:3, 3 * c : 3 * c + 3] = R.T @ skew(p_W - p_F0)
            A[3:6, 3 * c : 3 * c + 3] = R.T
            A[6:, 3 * c : 3 * c + 3] = J[:, 6:].T
        return A, self._w_cls

    def solve(self, A: np.ndarray, w: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
        """Weighted, damped least squares (see the class docstring): (f, ||W (A f - b)||)."""
        WA, Wb = w[:, None] * A, w * b
        if self._damping > 0.0:
            H = WA.T @ WA + self._damping**2 * np.eye(A.shape[1])
            f = np.linalg.solve(H, WA.T @ Wb)
        else:
            f = np.linalg.lstsq(WA, Wb, rcond=None)[0]
        return f, float(np.linalg.norm(WA @ f - Wb))

    def _estimate(self, context: Context) -> tuple[np.ndarray, float]:
        if self._mode == "external":
            w = eval_finite_input(self._who, self._wrench_port, context)
            return np.array(w[3:]), 0.0
        x = eval_finite_input(self._who, self._state_port, context)
        r = eval_finite_input(self._who, self._residual_port, context)
        if self._mode == "stacked":
            b = np.concatenate((eval_finite_input(self._who, self._wrench_port, context), r))
        else:
            b = np.asarray(r)
        A, w = self.system_matrix(x[: self._kin.nq], self._contact_points(context))
        f, fit = self.solve(A, w, b)
        if self._unknown:  # the unknowns' components -> world wrenches
            k3 = 3 * self._k
            f = np.concatenate((f[:k3], self._unknown.world_wrenches(self._kin, f[k3:]).ravel()))
        return f, fit

    def _CalcSolution(self, context: Context, value: AbstractValue) -> None:
        f, fit = self._estimate(context)
        value.set_value(np.concatenate((f, [fit])))

    def _CalcForces(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._solution.Eval(context)[: 3 * self._k])

    def _CalcFitError(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._solution.Eval(context)[-1:])


# ---------------------------------------------------------------------------------------
# Residual noise predicted from the sensor noise; ContactDetector.
# ---------------------------------------------------------------------------------------


def predicted_residual_covariances(
    plant: MultibodyPlant,
    *,
    internal_gain: float,
    external_gain: float,
    period: float = DEFAULT_PERIOD,
    q: np.ndarray | None = None,
    known_wrench_frames: Sequence = (),
    encoder_velocity_std: float = _sensors.ENCODER_VELOCITY_NOISE_STD,
    base_angular_velocity_std: float = _sensors.BASE_ANGULAR_VELOCITY_NOISE_STD,
    base_linear_velocity_std: float = _sensors.BASE_LINEAR_VELOCITY_NOISE_STD,
    torque_std: float = _sensors.MOTOR_TORQUE_NOISE_STD,
    ft_force_std: float = _sensors.FT_FORCE_NOISE_STD,
    ft_moment_std: float = _sensors.FT_MOMENT_NOISE_STD,
) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state noise covariances of the internal residual (n x n, N^2 m^2) and of the
    external residual's force in the world (3 x 3, N^2), predicted from the sensor noise.

    Model (systems.residuals.momentum_residuals' discrete observer, gain K, period T, white sensor noise held
    over T): the residual obeys r_k = (1 - K T) r_{k-1} + K (dp_k - dp_{k-1}) - K T du_k,
    with dp the momentum noise and du the noise of the measured rates. Its steady variance
    is K^2 Cov(dp) 2 / (2 - K T) + (K T)^2 Cov(du) / (1 - (1 - K T)^2).

    * internal: dp = H^fb dqdot (encoder velocity noise); du = motor torque noise plus the
      F/T noise through J^fb^T of the sensor frames (eq. 10).
    * external: dp = I0c dv0 + F dqdot (base velocity estimate and encoders, F0); du = the
      F/T force noise summed over the sensors. Rotated to world with the base orientation
      at ``q``.

    The sensed base orientation noise (gravity direction) and quantisation are neglected.

    Args:
        plant: finalized floating-base plant.
        internal_gain, external_gain: the residual gains K, 1/s.
        period: T, s.
        q: positions where the inertias are evaluated (default: the plant's default).
        known_wrench_frames: the F/T sensor frames (Frame objects).
        *_std: the sensor noise standard deviations (defaults: ``systems.simulation.sensors``).
    """
    from systems.dynamics.floating_base import FloatingBaseDynamics

    kin = _SensedConfiguration(plant, "predicted_residual_covariances")
    if q is None:
        q = plant.GetPositions(kin.context)
    q = np.asarray(q, dtype=float)
    terms = FloatingBaseDynamics(plant).compute(q, np.zeros(plant.num_velocities()))
    T = positive_number(period, "period")
    n = kin.n
    cov_qdot = encoder_velocity_std**2 * np.eye(n)

    def steady(K: float, cov_p: np.ndarray, cov_u: np.ndarray) -> np.ndarray:
        KT = K * T
        return K**2 * cov_p * 2.0 / (2.0 - KT) + KT**2 * cov_u / (1.0 - (1.0 - KT) ** 2)

    # Internal.
    cov_p_int = terms.H_fb @ cov_qdot @ terms.H_fb.T
    cov_u_int = torque_std**2 * np.eye(n)
    kin.set_positions(q)
    cov_w = np.diag([ft_moment_std**2] * 3 + [ft_force_std**2] * 3)
    world = plant.world_frame()
    E = kin.elimination()
    for frame in known_wrench_frames:
        J = plant.CalcJacobianSpatialVelocity(kin.context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world)
        Jfb = J[:, 6:] - J[:, :6] @ E
        cov_u_int += Jfb.T @ cov_w @ Jfb
    cov_int = steady(positive_number(internal_gain, "internal_gain"), cov_p_int, cov_u_int)
    # External (F0), force block, then world.
    cov_v0 = np.diag([base_angular_velocity_std**2] * 3 + [base_linear_velocity_std**2] * 3)
    cov_p_ext = terms.I0c @ cov_v0 @ terms.I0c.T + terms.F @ cov_qdot @ terms.F.T
    cov_u_ext = np.zeros((6, 6))
    cov_u_ext[3:, 3:] = len(known_wrench_frames) * ft_force_std**2 * np.eye(3)
    cov_ext = steady(positive_number(external_gain, "external_gain"), cov_p_ext, cov_u_ext)[3:, 3:]
    R = terms.R_WB
    return cov_int, R @ cov_ext @ R.T


def _filter_columns(
    kin: _SensedConfiguration, unknown: UnknownWrenches, gain: np.ndarray, start: np.ndarray, positions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The force and internal rows of the unknown wrenches' columns through the residuals'
    first-order filter (``ContactDetector``), along positions (N, nq): (the value before
    each update (N, 3 + n, k), the value after the last), from ``start``; ``gain`` the
    rows' K T (3 + n)."""
    positions = np.asarray(positions, dtype=float)
    current = np.asarray(start, dtype=float).reshape(3 + kin.n, unknown.size)
    if not len(positions):
        return np.empty((0, *current.shape)), current
    gain = np.broadcast_to(np.asarray(gain, dtype=float), (3 + kin.n,))
    # Every update's columns at once, then the recursion Tbar_k = (1 - KT) Tbar_k-1 + KT T_k,
    # term for term, as a first-order filter per distinct gain.
    columns = unknown.columns_of_samples(kin.pinocchio, positions)[0][:, 3:]
    after = np.empty_like(columns)
    for value in np.unique(gain):
        rows = gain == value
        after[:, rows] = first_order_filter(columns[:, rows], value, current[rows])
    return np.concatenate((current[None], after[:-1])), after[-1]


def unexplained_residuals(
    plant: MultibodyPlant,
    unknown_wrench_frames: Sequence,
    unknown_wrench_components: Sequence | None,
    positions: np.ndarray,
    external_wrench_world: np.ndarray,
    internal: np.ndarray,
    *,
    external_gain: float,
    internal_gain: float,
    period: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The external force and internal residuals of a log (N samples, the residuals after
    each update at positions q (N, nq), from zero) without what the unknown wrenches
    explain: per sample minus the least-squares fit of their columns, filtered as the
    residuals filter them (``ContactDetector``'s columns). What a noise model of the
    residuals of a robot without foot F/T sensors is measured on: the ground's wrenches on
    its soles change as it moves, the sensors' noise does not. Returns (force (N, 3),
    internal (N, n))."""
    who = "unexplained_residuals"
    kin = _SensedConfiguration(plant, who)
    unknown = UnknownWrenches(plant, unknown_wrench_frames, unknown_wrench_components, who)
    gain = np.concatenate((np.full(3, float(external_gain)), np.full(kin.n, float(internal_gain)))) * float(period)
    used, last = _filter_columns(kin, unknown, gain, np.zeros((3 + kin.n) * unknown.size), positions)
    after = np.concatenate((used[1:], last[None]))  # the columns each sample's residuals saw
    b = np.concatenate(
        (np.asarray(external_wrench_world, dtype=float)[:, 3:], np.asarray(internal, dtype=float)), axis=1
    )
    fit = np.einsum("snk,sk->sn", after, np.einsum("skn,sn->sk", np.linalg.pinv(after), b))
    rest = b - fit
    return rest[:, :3], rest[:, 3:]


class ContactDetector(LeafSystem):
    """Contact / no contact from the residuals (paper Secs. III, V: a residual that leaves
    its noise band means an unknown external force), with hysteresis.

    Test statistics (squared Mahalanobis norms, chi-square distributed without contact if
    the noise is Gaussian with the given covariances)::

        s_ext = r_ext,f^T S_ext^-1 r_ext,f   (3 dof; the external residual's force, world)
        s_int = r_int^T S_int^-1 r_int       (n dof; the internal residual)

    Contact switches ON when s_ext > chi2.isf(p_on, 3) or s_int > chi2.isf(p_on, n) for
    ``on_samples`` consecutive updates, and OFF when both stay below chi2.isf(p_off, dof)
    for ``release_time`` seconds.

    Without foot F/T sensors (``unknown_wrench_frames``: the soles, m of them), the
    residuals carry the ground's wrenches, which change with every shift of weight; a test
    of the residuals' size would fire all the time. One joint test replaces both:

        s_int = ||(I - C C^+) z||^2,  z = [L_f^-1 r_ext,f; L_int^-1 r_int],
        C = [L_f^-1 Tbar_F,f; L_int^-1 Tbar_F,int]   (3 + n - 6 m dof)

    the whitened force and internal residuals with every wrench the m frames could carry
    projected out: what no ground wrench explains. It is reported as s_int (s_ext is 0 and
    not tested). Tbar_F are the frames' columns (``unknown_wrench_columns``) at the sensed
    q (input ``state``) passed through the residuals' own first-order filter, Tbar_k =
    (1 - K T) Tbar_k-1 + K T T_F(q_k) (K the external or internal gain, rows alike, from 0
    as the residuals): the residuals see J^T w through that filter, and with w of a few
    hundred N the lag of the instantaneous columns would be more than the noise as soon
    as the robot moves (J-dot^T w / K; ``tests/test_unknown_foot_wrenches.py`` moves the
    arms and torso of a standing hrp4_like). Exact for ground wrenches constant over 1/K;
    a change of w itself stays in the span.

    Defaults from the sensor noise: when the covariances are not given they come from
    ``predicted_residual_covariances`` with the default noise of ``systems.simulation.sensors`` and
    the residual gains; p_on = 1e-9 per update and per test (about one false alarm in
    16 days at 1 kHz for Gaussian noise; a margin against the non-Gaussian tails of real
    noise), p_off = 1e-2. E.g. on ``hrp4_like`` with K = 35/s: the external force noise is
    about 0.28 N per axis, so s_ext's threshold 44.8 means about 1.9 N; a 5 N push is then
    detected ~14 ms after it starts by the external test alone, usually sooner by the
    internal one.

    Inputs:
        ``external_wrench_world`` (6): ExternalResidual's output (the force part is used).
        ``residual`` (n): InternalResidual's output.
        ``state`` (nq + nv, only with ``unknown_wrench_frames``): the sensed [q; v].
    State (discrete): [detected (0/1), detection time (s, -1 before the first detection),
        consecutive samples above, time since both went below (s), s_ext, s_int], then
        with ``unknown_wrench_frames`` the filtered columns Tbar ((3 + n) x 6 m, row-major).

    Outputs:
        ``contact_detected`` (1): 1.0 in contact, else 0.0.
        ``detection_time`` (1): time of the most recent OFF->ON switch, s; -1 if none yet.
        ``test_statistics`` (2): [s_ext, s_int] of the last update (dimensionless).

    The residuals are read at the update time; in a diagram where they too update at that
    time the detector sees the values of the previous update (one period of delay).

    Args:
        plant: finalized floating-base plant.
        internal_gain, external_gain: the residuals' gains K, 1/s (for the defaults).
        covariance_internal: n x n (or n stds as a vector), N^2 m^2 (N m); None: predicted.
        covariance_external_force: 3 x 3 (or 3 stds), world, N^2 (N); None: predicted.
        known_wrench_frames: the F/T frames (for the predicted covariances).
        nominal_positions: q for the predicted covariances (default: plant's default).
        false_alarm_probability: p_on. release_probability: p_off.
        on_samples: consecutive updates above threshold to switch on (default 1).
        release_time: s below the off thresholds to switch off (default 0.02).
        period: update period, s.
        use_external, use_internal: which tests to run.
        startup_time: s, no detection before this time (the estimators' start-up: the
            residuals start at 0 and a base-state estimator converges over its first steps).
            Default 0.
        unknown_wrench_frames: frames (or names) whose wrenches are unknown (the soles of a
            robot without foot F/T sensors; the residuals computed without
            ``known_wrench_frames``): the joint test above. Needs ``use_internal``.
        unknown_wrench_components: per unknown wrench frame, the indices of its unknown
            components in [m_x, m_y, m_z, f_x, f_y, f_z] of its axes (``UnknownWrenches``;
            ``SOLE_SHEAR_AND_YAW`` for a sole whose FSRs' wrench is among the known ones);
            None: all six.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        *,
        internal_gain: float = 35.0,
        external_gain: float = 35.0,
        covariance_internal=None,
        covariance_external_force=None,
        known_wrench_frames: Sequence = (),
        nominal_positions: np.ndarray | None = None,
        false_alarm_probability: float = 1e-9,
        release_probability: float = 1e-2,
        on_samples: int = 1,
        release_time: float = 0.02,
        period: float = DEFAULT_PERIOD,
        use_external: bool = True,
        use_internal: bool = True,
        startup_time: float = 0.0,
        unknown_wrench_frames: Sequence = (),
        unknown_wrench_components: Sequence | None = None,
    ):
        super().__init__()
        who = self._who = "ContactDetector"
        self._kin = kin = _SensedConfiguration(plant, who)
        n = kin.n
        self._unknown = UnknownWrenches(plant, unknown_wrench_frames, unknown_wrench_components, who)
        try:
            known_wrench_frames = check_wrench_frames(plant, known_wrench_frames, "known wrench frame")
        except ValueError as error:
            raise ValueError(f"{who}: {error}") from None
        if self._unknown:
            whole = {
                int(frame.index())
                for frame, chosen in zip(self._unknown.frames, self._unknown.components)
                if chosen == ALL_WRENCH_COMPONENTS
            }
            both = [frame for frame in known_wrench_frames if int(frame.index()) in whole]
            if both:
                raise ValueError(
                    f"{who}: the wrench at '{both[0].name()}' is both known and wholly unknown; a frame among the "
                    "known wrench frames can have only the components its sensor does not measure as unknowns"
                )
            if not use_internal:
                raise ValueError(f"{who}: unknown_wrench_frames need use_internal (the joint test)")
            use_external = False
        joint_dof = 3 + n - self._unknown.size
        self._column_shape = (3 + n, self._unknown.size)
        if joint_dof < 1:
            raise ValueError(
                f"{who}: {len(self._unknown)} unknown wrenches ({self._unknown.size} components) leave no degree "
                f"of freedom in the 3 + {n} force and internal residual rows"
            )
        if not (use_external or use_internal):
            raise ValueError(f"{who}: at least one of use_external, use_internal must be True")
        for name, p in (
            ("false_alarm_probability", false_alarm_probability),
            ("release_probability", release_probability),
        ):
            if not 0.0 < float(p) < 1.0:
                raise ValueError(f"{who}: {name} must be in (0, 1), got {p}")
        if not float(release_probability) > float(false_alarm_probability):
            raise ValueError(f"{who}: release_probability must exceed false_alarm_probability (hysteresis)")
        if int(on_samples) != on_samples or on_samples < 1:
            raise ValueError(f"{who}: on_samples must be a positive integer, got {on_samples}")
        self._period = positive_number(period, f"{who}: period")
        self._release_time = float(release_time)
        if not math.isfinite(self._release_time) or self._release_time < 0.0:
            raise ValueError(f"{who}: release_time must be >= 0, got {release_time}")
        self._on_samples = int(on_samples)
        self._startup_time = float(startup_time)
        if not math.isfinite(self._startup_time) or self._startup_time < 0.0:
            raise ValueError(f"{who}: startup_time must be >= 0, got {startup_time}")
        if covariance_internal is None or covariance_external_force is None:
            cov_int, cov_ext = predicted_residual_covariances(
                plant,
                internal_gain=internal_gain,
                external_gain=external_gain,
                period=self._period,
                q=nominal_positions,
                known_wrench_frames=known_wrench_frames,
            )
            if covariance_internal is None:
                covariance_internal = cov_int
            if covariance_external_force is None:
                covariance_external_force = cov_ext
        self._L_int = self._whitener(covariance_internal, n, "covariance_internal")
        self._L_ext = self._whitener(covariance_external_force, 3, "covariance_external_force")
        self._use = (bool(use_external), bool(use_internal))
        dof_int = joint_dof if self._unknown else n
        self._on = (chi2.isf(false_alarm_probability, 3), chi2.isf(false_alarm_probability, dof_int))
        self._off = (chi2.isf(release_probability, 3), chi2.isf(release_probability, dof_int))

        self._wrench_port = self.DeclareVectorInputPort("external_wrench_world", 6)
        self._residual_port = self.DeclareVectorInputPort("residual", n)
        self._state_port = self.DeclareVectorInputPort("state", kin.nq + kin.nv) if self._unknown else None
        # The filters' factors K T of the columns' rows (force rows: external; joints: internal).
        self._column_gain = (
            np.concatenate((np.full(3, float(external_gain)), np.full(n, float(internal_gain)))) * self._period
        )
        if self._unknown and not np.all((self._column_gain > 0.0) & (self._column_gain < 1.0)):
            raise ValueError(f"{who}: the residual gains times the period must be in (0, 1) to filter the columns")
        columns0 = np.zeros(self._column_shape[0] * self._column_shape[1] if self._unknown else 0)
        self._state_index = self.DeclareDiscreteState(
            np.concatenate(([0.0, -1.0, 0.0, 0.0, 0.0, 0.0], columns0))  # _DetectorState, Tbar
        )
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        xd = {self.xd_ticket()}
        self.DeclareVectorOutputPort("contact_detected", 1, lambda c, o: o.SetFromVector([self._s(c).detected]), xd)
        self.DeclareVectorOutputPort("detection_time", 1, lambda c, o: o.SetFromVector([self._s(c).detection_time]), xd)
        self.DeclareVectorOutputPort(
            "test_statistics",
            2,
            lambda c, o: o.SetFromVector([self._s(c).statistic_external, self._s(c).statistic_internal]),
            xd,
        )

    def _whitener(self, cov, size: int, name: str) -> np.ndarray:
        """W with W^T W = cov^-1 (inverse Cholesky factor), from a covariance or stds."""
        c = np.asarray(cov, dtype=float)
        if c.shape == (size,):
            c = np.diag(c**2)
        if c.shape != (size, size) or not np.all(np.isfinite(c)):
            raise ValueError(
                f"{self._who}: {name} must be {size} stds or a {size}x{size} covariance, got shape {c.shape}"
            )
        c = 0.5 * (c + c.T)
        try:
            L = np.linalg.cholesky(c)
        except np.linalg.LinAlgError:
            raise ValueError(f"{self._who}: {name} must be positive definite") from None
        return np.linalg.inv(L)

    @property
    def startup_time(self) -> float:
        """s: no detection before this time."""
        return self._startup_time

    @property
    def thresholds(self) -> dict:
        """The chi-square thresholds: {"on": (ext, int), "off": (ext, int)}."""
        return {"on": self._on, "off": self._off}

    @property
    def unknown_wrench_frames(self) -> tuple[Frame, ...]:
        """The frames whose wrenches are unknown (() with foot F/T sensors)."""
        return self._unknown.frames

    def statistics(
        self, wrench: np.ndarray, residual: np.ndarray, columns: np.ndarray | None = None
    ) -> tuple[float, float]:
        """(s_ext, s_int) of the class docstring; with ``unknown_wrench_frames`` the
        filtered columns Tbar ((3 + n) x 6 m) are needed (``unknown_columns`` at q for a
        robot at rest, ``filtered_columns`` along a motion)."""
        z_ext = self._L_ext @ np.asarray(wrench)[3:]
        z_int = self._L_int @ np.asarray(residual)
        if self._unknown:
            return 0.0, float(self._joint_statistics(self._checked_columns(columns)[None], z_ext[None], z_int[None])[0])
        return float(z_ext @ z_ext), float(z_int @ z_int)

    def statistics_of_samples(
        self, wrenches: np.ndarray, residuals: np.ndarray, columns: np.ndarray | None = None
    ) -> np.ndarray:
        """(N, 2) [s_ext, s_int] of N samples of the inputs ((N, 6) and (N, n); with
        ``unknown_wrench_frames`` also their filtered columns (N, 3 + n, 6 m),
        ``filtered_columns``) at once: ``statistics`` of each, to rounding."""
        z_ext = np.asarray(wrenches)[:, 3:] @ self._L_ext.T
        z_int = np.asarray(residuals) @ self._L_int.T
        if self._unknown:
            if columns is None or np.shape(columns) != (len(z_ext), *self._column_shape):
                raise ValueError(
                    f"{self._who}: with unknown_wrench_frames the samples' filtered columns "
                    f"(N, {self._column_shape[0]}, {self._column_shape[1]}) are needed"
                )
            joint = self._joint_statistics(np.asarray(columns, dtype=float), z_ext, z_int)
            return np.stack((np.zeros(len(z_ext)), joint), axis=1)
        return np.stack((np.einsum("ij,ij->i", z_ext, z_ext), np.einsum("ij,ij->i", z_int, z_int)), axis=1)

    def unknown_columns(self, q: np.ndarray) -> np.ndarray:
        """((3 + n), 6 m) the unknown wrenches' columns at positions q (force and internal
        rows of ``unknown_wrench_columns``): the filtered columns of a robot at rest."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self._kin.nq,):
            raise ValueError(f"{self._who}: q must have shape ({self._kin.nq},), got {q.shape}")
        self._kin.set_positions(q)
        return self._unknown.columns(self._kin)[3:]

    def filtered_columns(self, start: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The filtered columns along N updates (class docstring), without a Context
        (``systems.residuals.offline``): from ``start`` (Tbar before the first update, as
        the state holds it; zeros at the start) and the positions q_k the updates read
        ((N, nq)), (the Tbar each update's test uses (N, 3 + n, 6 m): the value before
        it, Tbar_k-1; Tbar after the last update)."""
        return _filter_columns(self._kin, self._unknown, self._column_gain, start, positions)

    def _checked_columns(self, columns) -> np.ndarray:
        if columns is None or np.shape(columns) != self._column_shape:
            raise ValueError(
                f"{self._who}: with unknown_wrench_frames the statistics need the filtered columns "
                f"({self._column_shape[0]}, {self._column_shape[1]})"
            )
        return np.asarray(columns, dtype=float)

    def _joint_statistics(self, columns: np.ndarray, z_ext: np.ndarray, z_int: np.ndarray) -> np.ndarray:
        """(N,) the joint test's statistics (class docstring) of N samples of the whitened
        force (N, 3) and internal (N, n) residuals with their filtered columns (N, 3 + n,
        6 m), all at once."""
        C = np.concatenate((self._L_ext @ columns[:, :3], self._L_int @ columns[:, 3:]), axis=1)
        z = np.concatenate((z_ext, z_int), axis=1)
        # The first update's columns are 0 (the filter, as the residuals, starts at 0):
        # nothing to project out there.
        started = np.any(C != 0.0, axis=(1, 2))
        e = z.copy()
        if started.any():
            Q = np.linalg.qr(C[started]).Q
            zs = z[started]
            e[started] = zs - np.einsum("nrc,nc->nr", Q, np.einsum("nrc,nr->nc", Q, zs))
        return np.einsum("nr,nr->n", e, e)

    def _s(self, context: Context) -> _DetectorState:
        return _DetectorState(context.get_discrete_state(self._state_index).get_value()[:6])

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        w = eval_finite_input(self._who, self._wrench_port, context)
        r = eval_finite_input(self._who, self._residual_port, context)
        stored = context.get_discrete_state(self._state_index).get_value()
        if self._state_port is None:
            discrete_state.set_value(self._state_index, self.advance(stored, self.statistics(w, r), context.get_time()))
            return
        q = eval_finite_input(self._who, self._state_port, context)[: self._kin.nq]
        columns = stored[6:].reshape(self._column_shape)
        state = self.advance(stored[:6], self.statistics(w, r, columns), context.get_time())
        _, after = self.filtered_columns(stored[6:], q[None])
        discrete_state.set_value(self._state_index, np.concatenate((state, after.ravel())))

    def advance(self, state: Sequence[float], s: tuple[float, float], t: float) -> list[float]:
        """One update without a Context (``systems.residuals.offline`` replays logs with
        it): the detector's next state (the layout of the class docstring) from its
        ``state``, the test statistics ``s`` = (s_ext, s_int) of this update's inputs
        (``statistics``) and the time t, s."""
        use = self._use
        is_above = t >= self._startup_time and any(u and si > th for u, si, th in zip(use, s, self._on))
        is_below = all((not u) or si < th for u, si, th in zip(use, s, self._off))
        return [*self._transition(*(float(v) for v in state[:4]), is_above, is_below, t), s[0], s[1]]

    def replay(
        self, state: Sequence[float], statistics: np.ndarray, times: np.ndarray
    ) -> tuple[np.ndarray, list[float]]:
        """``advance`` over N successive updates from ``state``: (N,) the detector's flag
        after each and its state after the last (``state`` itself for N = 0), from the test
        statistics (N, 2) of their inputs (``statistics_of_samples``) and their times (N,),
        s. Equal to stepping ``advance``: the threshold tests, which read only each update's
        statistics and time, are made for all updates at once, and only the switching logic
        (``_transition``, ``advance``'s own) runs update by update."""
        statistics = np.asarray(statistics, dtype=float)
        times = np.asarray(times, dtype=float)
        use = np.array(self._use)
        above = (times >= self._startup_time) & ((statistics > np.array(self._on)) & use).any(axis=1)
        below = ((statistics < np.array(self._off)) | ~use).all(axis=1)
        flags = np.empty(len(times), dtype=bool)
        state = list(state)
        switching, transition = tuple(float(v) for v in state[:4]), self._transition
        for k, (is_above, is_below, t) in enumerate(zip(above.tolist(), below.tolist(), times.tolist())):
            switching = transition(*switching, is_above, is_below, t)
            flags[k] = switching[0] > 0.5
        state[:4] = switching
        if len(times):
            state[4:6] = statistics[-1].tolist()
        return flags, state

    def _transition(
        self,
        detected: float,
        t_detect: float,
        above: float,
        below_time: float,
        is_above: bool,
        is_below: bool,
        t: float,
    ) -> tuple[float, float, float, float]:
        """The switching logic of ``advance``: the next (detected, detection time, updates
        above, time below) from the current ones (the first four _DetectorState fields),
        given whether this update's statistics are above the on thresholds (after the
        start-up) and below the off ones."""
        if detected < 0.5:
            above = above + 1.0 if is_above else 0.0
            if above >= self._on_samples:
                detected, t_detect, below_time = 1.0, t, 0.0
        else:
            above = 0.0
            below_time = below_time + self._period if is_below else 0.0
            if below_time >= self._release_time - 1e-12 and is_below:
                detected, below_time = 0.0, 0.0
        return detected, t_detect, above, below_time


# ---------------------------------------------------------------------------------------
# ContactLocalizer: Sec. VI, eq. (22), Fig. 9.
# ---------------------------------------------------------------------------------------

#: ContactLocalizer's averaging state: averaging (1/0), samples averaged, onset time (s), time
#: of the last localization (s; -inf before the first of a contact).
_Averaging = namedview("_Averaging", ("active", "count", "onset", "localized"))

VALID, NO_CONTACT, FORCE_TOO_SMALL, NO_INTERSECTION, AMBIGUOUS = 0, 1, 2, 3, 4
STATUS_REASONS = {
    VALID: "valid",
    NO_CONTACT: "no contact detected",
    FORCE_TOO_SMALL: "estimated force too small for a line of action",
    NO_INTERSECTION: "the line of action does not enter the robot's surface",
    AMBIGUOUS: "ambiguous: another link explains the internal residual about as well",
}


@dataclass
class LocalizationResult:
    """One localization (see ``ContactLocalizer``). Units: m, N, N m.

    Attributes:
        status: VALID, NO_CONTACT, FORCE_TOO_SMALL, NO_INTERSECTION or AMBIGUOUS.
        body_index: plant BodyIndex of the chosen link, -1 if none.
        point_W: the contact point (zeros if none).
        force_W: the force estimate r_ext,f (eq. 19).
        score: ||W (J^fb^T f - r_int)|| of the chosen candidate (inf if none).
        runner_up_score: the best score on another link (inf if none).
        line_point_W: the line's point closest to the world origin (eq. 22), zeros if none.
        candidates: (body index, point_W, score, l) of every surface entry point kept.
        runner_up_body_index: the link of ``runner_up_score`` (-1 if none); with AMBIGUOUS
            the two links that explain the residuals about equally are this and
            ``body_index``.
        runner_up_point_W: its first entry point along the force (zeros if none).
        limited_joints: indices (v[6:] order) of the joints taken as resting on a position
            limit, whose stop's reaction the fit left free (see ``ContactLocalizer``).
    """

    status: int
    body_index: int = -1
    point_W: np.ndarray = field(default_factory=lambda: np.zeros(3))
    force_W: np.ndarray = field(default_factory=lambda: np.zeros(3))
    score: float = math.inf
    runner_up_score: float = math.inf
    line_point_W: np.ndarray = field(default_factory=lambda: np.zeros(3))
    candidates: list = field(default_factory=list)
    runner_up_body_index: int = -1
    runner_up_point_W: np.ndarray = field(default_factory=lambda: np.zeros(3))
    limited_joints: tuple = ()

    @property
    def reason(self) -> str:
        return STATUS_REASONS[self.status]

    @property
    def valid(self) -> bool:
        return self.status == VALID


class ContactLocalizer(LeafSystem):
    """Single unknown contact: its link, point and force (paper Sec. VI, Fig. 9).

    Each update:

    1. f_hat = r_ext,f and m = r_ext,m (moment about the world origin) from
       ``external_wrench_world`` (eq. 19). Since m = p x f for a force f at p, the line of
       action is l(s) = (f x m) / |f|^2 + s f / |f| (eq. 22; (f x m)/|f|^2 is its point
       closest to the world origin).
    2. The line is intersected with every collision primitive of the candidate links at the
       sensed pose (``systems.residuals.geometry_intersection``, vectorised). Of each primitive only
       the ENTRY point is kept: there the force points into the surface (f . n < 0).
       Entry points buried deeper than ``surface_tolerance`` inside another link's
       primitive are not on the robot's surface and are dropped.
    3. Each candidate c on link B_c gets the score ||W (J^fb_c^T f_hat - r_int - mu)|| (eq.
       12; W = diag(score_weights)). mu is the reaction of the joint stops: a joint within
       ``limit_margin`` of a position limit (e.g. HRP-4's hand joints, which rest on theirs)
       may carry any stop torque that pushes it away from that limit, which the internal
       residual sees as external effort; the fit leaves it free (one sign-constrained
       column per such joint: with a diagonal W that row's misfit is zero when its sign is
       the stop's, else unchanged). All points of a line on the same link give the same
       J^T f (the moment of a line about any axis does not depend on the point), so links
       are ranked by score and, on the best link, the first entry along f is taken (the
       pusher comes from outside, against f). Links that tie, e.g. a hand and its wrist
       when only the hand joint's row told them apart and it rests on its stop, are ranked
       by the stop torque their fit needs (least first: a hand pushed away from its stop
       leaves it, so its row is informative) and then by that first entry; a tie is
       reported AMBIGUOUS with both links (a hand pressed into its stop moves with its
       wrist as one body: no residual can tell them apart).
    4. Status: NO_CONTACT when ``contact_detected`` is 0; FORCE_TOO_SMALL when |f_hat| <
       ``min_force``; NO_INTERSECTION without candidates; AMBIGUOUS when another link's
       best score is within ``ambiguity_margin`` of the best (bodies joined by welds are
       one rigid link: ``systems.common.topology.rigid_link_of_bodies``); else VALID. Degenerate inputs
       never raise (only NaN/inf inputs do, as everywhere in this package).

    Without foot F/T sensors (``unknown_wrench_frames``: the soles), r_ext also carries
    the ground's wrenches and its line of action is not the contact's. Steps 1-3 then run
    per link B instead, on the rows W [r_ext; r_int] (W = diag(external_weights,
    score_weights)) with the ground wrenches (``unknown_wrench_columns``) as free unknowns
    and the stops' reactions as sign-constrained ones (non-negative least squares): B's
    wrench [m_B; f] (moment about B's origin; its map T_B = [[I, skew(p_B)]; [0, I];
    J^fb_B^T]) fitted with them; eq. (22) on that wrench, p_B + (f x m_B) / |f|^2 + s f /
    |f|; the first entry into B's own primitives; and the score, the weighted misfit of the
    point force at that entry (f_c refitted with the same unknowns). f_hat is the best
    link's f_c; ties go to the least stop torque, then to the first entry. A link's
    free-wrench misfit bounds every score a point force on it could reach (its line may
    miss it under noise), so the runner-up is the best of the other links' scores AND
    free-wrench misfits: the answer is VALID only when no other link could explain the
    residuals about as well. On a stance leg most of a push looks like a change of the
    ground's wrench (only the joints between the link and its sole see the rest), and the
    base and the other leg links explain it too: such pushes come out AMBIGUOUS.

    Averaging: after the contact has been detected for ``settle_time`` (the residuals'
    first-order rise, a few 1/K), the localizer averages its inputs (residuals and state)
    from then on (running mean, or an exponential window of ``averaging_time_constant``):
    a momentum residual's noise is dominated by the white momentum noise times K, which
    the mean removes, while a steady contact's wrench is constant. Before that it uses
    the latest inputs. The mean is reset when the contact ends. The averaging runs at every
    update; the localization itself (steps 1-4) at the first update of a contact and then
    every ``localization_period`` (the outputs hold the last one in between).

    Inputs:
        ``state`` (nq + nv): sensed [q; v].
        ``external_wrench_world`` (6): ExternalResidual's output.
        ``residual`` (n): InternalResidual's output.
        ``contact_detected`` (1): ContactDetector's output (only if ``use_detector``).
    State (discrete): the averaging [active, count, onset time, last localization time],
        the means [wrench (6), residual (n), q (nq)], the inputs of the last localization
        (same layout) and the result [status, body, point (3), force (3), score, runner-up
        score, runner-up body, runner-up point (3)].

    Outputs:
        ``contact_body`` (1): BodyIndex of the link, -1 if none.
        ``contact_point_world`` (3), m. ``contact_force_world`` (3), N.
        ``score`` (1), ``runner_up_score`` (1): N m (inf when there is none).
        ``runner_up_body`` (1): BodyIndex of the runner-up link, -1 if none.
        ``runner_up_point_world`` (3), m.
        ``valid`` (1): 1.0 if status is VALID. ``status`` (1): the code (STATUS_REASONS).

    Args:
        plant: finalized floating-base plant.
        scene_graph: its SceneGraph (or a SceneGraphInspector): the collision shapes.
        bodies: candidate links (RigidBody, names or indices); default every body with a
            collision geometry except ``exclude_bodies``.
        exclude_bodies: links never considered (e.g. the soles below F/T sensors: a force
            there is part of the measured wrench and invisible to the residuals).
        period: update period, s.
        localization_period: s between two localizations while in contact (None: every
            update). The mean is updated every ``period`` all the same; a slower
            localization rate only delays the output by up to this (e.g. 0.01 s: 100 Hz).
        use_detector: declare the ``contact_detected`` input.
        min_force: N (default 1.0, about 3.5 times the external force noise at K = 35/s).
        settle_time: s after detection before averaging (default 0.1 = 3.5/K at K = 35/s).
        averaging_time_constant: s, None for a plain running mean (default).
        ambiguity_margin: N m (default 0.01, about 5 std of the averaged internal residual's
            norm difference on hrp4_like).
        surface_tolerance: m (default 0.01).
        limit_margin: rad (m for prismatic joints): a joint whose sensed position is within
            this of a limit of the plant is taken as resting on it (default 0.01); None: no
            joint is (the paper's fit).
        score_weights: n weights (default 1): e.g. 1 / internal residual noise std.
        skip_unsupported_shapes: ignore meshes etc. instead of raising.
        unknown_wrench_frames: frames (or names) whose wrenches are unknown (the soles of a
            robot without foot F/T sensors, the residuals computed without
            ``known_wrench_frames``): the per-link mode above. Default ().
        unknown_wrench_components: per unknown wrench frame, the indices of its unknown
            components in [m_x, m_y, m_z, f_x, f_y, f_z] of its axes (``UnknownWrenches``;
            ``SOLE_SHEAR_AND_YAW`` for a sole whose FSRs' wrench is among the known ones);
            None: all six.
        external_weights: 6 weights of the external residual's rows [moment; force] in that
            mode (default 1; e.g. 1 / its noise std).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        scene_graph: SceneGraph | SceneGraphInspector,
        *,
        bodies: Sequence | None = None,
        exclude_bodies: Sequence = (),
        period: float = DEFAULT_PERIOD,
        localization_period: float | None = None,
        use_detector: bool = True,
        min_force: float = 1.0,
        settle_time: float = 0.1,
        averaging_time_constant: float | None = None,
        ambiguity_margin: float = 0.01,
        surface_tolerance: float = 0.01,
        limit_margin: float | None = 0.01,
        score_weights=1.0,
        skip_unsupported_shapes: bool = False,
        unknown_wrench_frames: Sequence = (),
        unknown_wrench_components: Sequence | None = None,
        external_weights=1.0,
    ):
        super().__init__()
        who = self._who = "ContactLocalizer"
        self._kin = kin = _SensedConfiguration(plant, who)
        self._unknown = UnknownWrenches(plant, unknown_wrench_frames, unknown_wrench_components, who)
        self._external_w = _weights(external_weights, 6, f"{who}: external_weights")
        self._geometry, self._bodies = candidate_geometry(
            plant, scene_graph, bodies, exclude_bodies, who, skip_unsupported_shapes
        )
        self._period = positive_number(period, f"{who}: period")
        self._localization_period = (
            self._period
            if localization_period is None
            else positive_number(localization_period, f"{who}: localization_period")
        )
        self._min_force = positive_number(min_force, f"{who}: min_force")
        self._settle_time = float(settle_time)
        if not math.isfinite(self._settle_time) or self._settle_time < 0.0:
            raise ValueError(f"{who}: settle_time must be >= 0")
        self._tau = (
            None
            if averaging_time_constant is None
            else positive_number(averaging_time_constant, f"{who}: averaging_time_constant")
        )
        self._margin = float(ambiguity_margin)
        self._tolerance = float(surface_tolerance)
        if not (
            math.isfinite(self._margin)
            and self._margin >= 0.0
            and math.isfinite(self._tolerance)
            and self._tolerance >= 0.0
        ):
            raise ValueError(f"{who}: ambiguity_margin and surface_tolerance must be non-negative")
        n, nq, nv = kin.n, kin.nq, kin.nv
        self._score_w = _weights(score_weights, n, f"{who}: score_weights")
        self._limit_margin = -math.inf if limit_margin is None else float(limit_margin)
        if not (limit_margin is None or (math.isfinite(self._limit_margin) and self._limit_margin >= 0.0)):
            raise ValueError(f"{who}: limit_margin must be finite and non-negative, got {limit_margin}")
        self._stops = _JointStops(kin.topology.joints, self._limit_margin)
        self._same_body = self._geometry.body_indices[:, None] == self._geometry.body_indices[None, :]
        # The squared radius, a hair wider, of each primitive's bounding sphere about its origin.
        self._bounding_radius2 = (_bounding_radii(self._geometry) * (1.0 + 1e-9) + 1e-9) ** 2
        self._rigid_link = rigid_link_of_bodies(plant)  # welded bodies are one link

        self._state_port = self.DeclareVectorInputPort("state", nq + nv)
        self._wrench_port = self.DeclareVectorInputPort("external_wrench_world", 6)
        self._residual_port = self.DeclareVectorInputPort("residual", n)
        self._detected_port = self.DeclareVectorInputPort("contact_detected", 1) if use_detector else None
        # Averaging state: _Averaging, then the means of the wrench (6), residual (n) and q (nq).
        self._avg_index = self.DeclareDiscreteState(len(_Averaging.get_fields()))
        self._means_index = self.DeclareDiscreteState(6 + n + nq)
        # The inputs of the last localization [wrench (6), residual (n), q (nq)].
        self._localized_index = self.DeclareDiscreteState(6 + n + nq)
        result0 = np.array([NO_CONTACT, -1, 0, 0, 0, 0, 0, 0, np.inf, np.inf, -1, 0, 0, 0], dtype=float)
        self._result_index = self.DeclareDiscreteState(result0)
        self._n, self._nq = n, nq
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        ticket = {self.xd_ticket()}
        for name, lo, hi in (
            ("contact_body", 1, 2),
            ("contact_point_world", 2, 5),
            ("contact_force_world", 5, 8),
            ("score", 8, 9),
            ("runner_up_score", 9, 10),
            ("runner_up_body", 10, 11),
            ("runner_up_point_world", 11, 14),
            ("status", 0, 1),
        ):
            self.DeclareVectorOutputPort(
                name, hi - lo, lambda c, o, lo=lo, hi=hi: o.SetFromVector(self._r(c)[lo:hi]), ticket
            )
        self.DeclareVectorOutputPort("valid", 1, lambda c, o: o.SetFromVector([float(self._r(c)[0] == VALID)]), ticket)

    # -- public ---------------------------------------------------------------------------
    @property
    def geometry(self) -> RobotGeometry:
        return self._geometry

    def same_link(self, body_a: int, body_b: int) -> bool:
        """Whether two BodyIndex values are one rigid link (the same body, or welded: no
        joint effort tells them apart)."""
        return same_rigid_link(self._rigid_link, body_a, body_b)

    @property
    def candidate_bodies(self) -> list[RigidBody]:
        return list(self._bodies)

    def limited_joints(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(indices, signs) of the joints within ``limit_margin`` of a position limit at the
        positions ``q`` (v[6:] order): sign +1 at a lower limit (the stop can only push the
        joint up), -1 at an upper one."""
        return self._stops.limited(q)

    def localize(self, q: np.ndarray, wrench_W: np.ndarray, residual: np.ndarray) -> LocalizationResult:
        """Steps 1-4 of the class docstring for one (q, external wrench, internal residual),
        contact assumed detected. Never raises for finite inputs of the right sizes.

        The geometric queries skip the primitives whose bounding sphere (about the
        primitive's origin) the line of action misses, or, for the buried-point test, that
        holds none of the candidate points, since neither can change the result: such a
        line misses the primitive, and such a point lies outside it (a positive signed
        distance, never below the tolerance); convex hulls are never skipped. The numbers
        of the primitives queried are those of querying all (row by row)."""
        wrench_W = np.asarray(wrench_W, dtype=float)
        if self._unknown:
            return self._localize_per_link(np.asarray(q, dtype=float), wrench_W, np.asarray(residual, dtype=float))
        m, f = wrench_W[:3], wrench_W[3:]
        f2 = float(f @ f)
        if not f2 >= self._min_force**2:
            return LocalizationResult(FORCE_TOO_SMALL, force_W=f.copy())
        fn = math.sqrt(f2)
        d = f / fn
        p0 = cross(f, m) / f2  # eq. (22)
        kin, geo = self._kin, self._geometry
        kin.set_positions(np.asarray(q, dtype=float))
        X_WB = np.array([kin.body_pose(b) for b in self._bodies])
        R_WG, p_WG = geo.world_poses(X_WB)
        index, l_in, pts_W = self._line_entries(p0, d, R_WG, p_WG, np.arange(len(geo)))
        if index.size == 0:
            return LocalizationResult(NO_INTERSECTION, force_W=f.copy(), line_point_W=p0)
        body_of = geo.body_indices[index]
        r = np.asarray(residual, dtype=float)
        limited, stop_sign = self.limited_joints(q)
        E = kin.elimination()
        scores = np.empty(index.size)
        reactions = np.zeros(index.size)  # ||W mu||: the stop torque each link's fit needs
        for b in np.unique(body_of):
            rows = np.flatnonzero(body_of == b)
            body = self._bodies[int(np.searchsorted(geo.bodies, b))]
            X = X_WB[int(np.searchsorted(geo.bodies, b))]
            p_B = X[:, :3].T @ (pts_W[rows[0]] - X[:, 3])
            J = kin.jacobian(body, p_B)
            g = J.T @ f
            misfit = g[6:] - E.T @ g[:6] - r  # J^fb^T f (eq. 12) - r_int
            # A stop's reaction mu (r = J^fb^T f + mu, mu of the stop's sign) takes the rest.
            stopped = limited[stop_sign * misfit[limited] <= 0.0]
            reactions[rows] = float(np.linalg.norm(self._score_w[stopped] * misfit[stopped]))
            misfit[stopped] = 0.0
            scores[rows] = float(np.linalg.norm(self._score_w * misfit))
        # Ties (within rounding) go to the link that needs the least stop torque, then to the
        # first entry along f.
        order = np.lexsort((l_in, np.round(reactions, 12), np.round(scores, 12)))
        best = order[0]
        link_of = self._rigid_link[body_of]
        other = np.flatnonzero(link_of[order] != link_of[best])  # the runner-up is on another rigid link
        runner = order[other[0]] if other.size else None
        runner_up = float(scores[runner]) if runner is not None else math.inf
        status = AMBIGUOUS if runner_up - scores[best] < self._margin else VALID
        candidates = [(int(body_of[i]), pts_W[i].copy(), float(scores[i]), float(l_in[i])) for i in order]
        return LocalizationResult(
            status,
            int(body_of[best]),
            pts_W[best].copy(),
            f.copy(),
            float(scores[best]),
            runner_up,
            p0,
            candidates,
            runner_up_body_index=int(body_of[runner]) if runner is not None else -1,
            runner_up_point_W=pts_W[runner].copy() if runner is not None else np.zeros(3),
            limited_joints=tuple(int(k) for k in limited),
        )

    def _line_entries(
        self, p0: np.ndarray, d: np.ndarray, R_WG: np.ndarray, p_WG: np.ndarray, prims: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Step 2 for lines p0 + l d (d unit vectors; one line (3,) for every primitive of
        ``prims``, or one per primitive (len(prims), 3)): (primitive indices, l, points
        (world)) of the entries (f . n < 0) not buried deeper than ``surface_tolerance`` in
        another link's primitive."""
        geo = self._geometry
        p0 = np.broadcast_to(p0, (len(prims), 3))
        d = np.broadcast_to(d, (len(prims), 3))
        o_G = np.einsum("gji,gj->gi", R_WG[prims], p0 - p_WG[prims])
        d_G = np.einsum("gji,gj->gi", R_WG[prims], d)
        rel = p_WG[prims] - p0
        off_line = rel - np.einsum("gi,gi->g", rel, d)[:, None] * d
        near = np.flatnonzero(np.einsum("gi,gi->g", off_line, off_line) <= self._bounding_radius2[prims])
        l_in, hit = np.full(len(prims), np.inf), np.zeros(len(prims), dtype=bool)
        g = prims[near]
        l_in[near], _, hit[near] = line_intersections(o_G[near], d_G[near], geo.kinds[g], geo.params[g], geo.planes[g])
        keep = np.flatnonzero(hit & np.isfinite(l_in))
        if keep.size:
            g = prims[keep]
            pts_G = o_G[keep] + l_in[keep, None] * d_G[keep]
            normals = outward_normals(pts_G, geo.kinds[g], geo.params[g], geo.planes[g])
            keep = keep[np.einsum("ij,ij->i", normals, d_G[keep]) < -1e-9]  # f . n < 0
        index, l_in = prims[keep], l_in[keep]
        pts_W = p0[keep] + l_in[:, None] * d[keep]
        if index.size:
            # Buried in another link's primitive?  (m, g) signed distances, of the primitives
            # of other links whose bounding sphere holds one of the points.
            rel = pts_W[:, None, :] - p_WG[None, :, :]
            holds = np.einsum("mgi,mgi->mg", rel, rel) <= self._bounding_radius2
            near = np.flatnonzero((holds & ~self._same_body[index]).any(axis=0))
            sd = np.full(holds.shape, np.inf)
            if near.size:
                local = np.einsum("gji,mgj->mgi", R_WG[near], rel[:, near])
                sd[:, near] = signed_distances(local, geo.kinds[near], geo.params[near], geo.planes[near])
            sd[self._same_body[index]] = np.inf
            outer = sd.min(axis=1) >= -self._tolerance
            index, l_in, pts_W = index[outer], l_in[outer], pts_W[outer]
        return index, l_in, pts_W

    def _localize_per_link(self, q: np.ndarray, wrench_W: np.ndarray, residual: np.ndarray) -> LocalizationResult:
        """``localize`` with unknown ground wrenches (the class docstring's per-link mode),
        for every link at once: the ground's and the stops' columns (shared by all links)
        projected out, then each link's few unknowns; the stops' sign constraints by
        non-negative least squares only for the links whose free fit breaks them."""
        kin, geo = self._kin, self._geometry
        kin.set_positions(q)
        X_WB = np.array([kin.body_pose(b) for b in self._bodies])
        R_WG, p_WG = geo.world_poses(X_WB)
        n, B = self._n, len(self._bodies)
        w = np.concatenate((self._external_w, self._score_w))
        limited, signs = self.limited_joints(q)
        L = len(limited)
        stops = np.zeros((6 + n, L))
        stops[6 + limited, np.arange(L)] = w[6 + limited] * signs
        shared = np.concatenate((w[:, None] * self._unknown.columns(kin), stops), axis=1)
        Q, R = np.linalg.qr(shared)
        b = w * np.concatenate((wrench_W, residual))
        T = wrench_maps(kin, [body.body_frame() for body in self._bodies]) * w[:, None]  # weighted T_B

        def fit(columns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            """For (B, rows, c) columns: (coefficients (B, c), weighted misfits (B,), stop
            torques (B,)) with the ground wrenches free and the stops' reactions of their
            signs."""
            Cp = columns - Q @ (Q.T @ columns)
            x = np.einsum("bcr,r->bc", np.linalg.pinv(Cp, rtol=1e-10), b)  # minimum norm where degenerate
            rest = b - np.einsum("brc,bc->br", columns, x)
            shared_x = np.linalg.solve(R, (rest @ Q).T).T  # (B, 12 + L): ground, then stops
            misfit = np.linalg.norm(rest - shared_x @ shared.T, axis=1)
            mu = shared_x[:, shared.shape[1] - L :]
            stop = np.linalg.norm(mu, axis=1)
            pulls = np.any(mu < -1e-9 * max(1.0, float(np.linalg.norm(b))), axis=1)  # beyond rounding
            for k in np.flatnonzero(pulls):  # a stop pulls: constrain its sign
                free = np.concatenate((columns[k], shared[:, : shared.shape[1] - L]), axis=1)
                Qf, _ = np.linalg.qr(free)
                mu_k, _ = nnls(stops - Qf @ (Qf.T @ stops), b - Qf @ (Qf.T @ b))
                rhs = b - stops @ mu_k
                y = np.linalg.lstsq(free, rhs, rcond=None)[0]
                x[k], misfit[k], stop[k] = y[: columns.shape[2]], np.linalg.norm(free @ y - rhs), np.linalg.norm(mu_k)
            return x, misfit, stop

        wrenches, free_misfit, _ = fit(T)
        m, f = wrenches[:, :3], wrenches[:, 3:]
        f2 = np.einsum("bi,bi->b", f, f)
        best_force = f[int(np.argmax(f2))] if B else np.zeros(3)
        strong = f2 >= self._min_force**2
        safe = np.where(strong, f2, 1.0)
        d = f / np.sqrt(safe)[:, None]
        p_line = X_WB[:, :, 3] + np.cross(f, m) / safe[:, None]  # eq. (22) on each link's own wrench
        prims = np.flatnonzero(strong[geo.slot])
        index, l_in, pts_W = self._line_entries(p_line[geo.slot[prims]], d[geo.slot[prims]], R_WG, p_WG, prims)
        # Each link's first entry.
        first = {}
        for i in np.argsort(l_in, kind="stable"):
            first.setdefault(int(geo.slot[index[i]]), i)
        slots = np.array(sorted(first), dtype=int)
        rows = []  # (score, stop torque, l, body index, point, force, line point)
        if slots.size:
            chosen = np.array([first[s] for s in slots])
            points = pts_W[chosen]
            r_B = points - X_WB[slots, :, 3]
            columns = T[slots, :, :3] @ _skews(r_B) + T[slots, :, 3:]  # the point forces' columns
            forces, scores, stops_needed = fit(columns)
            for k, slot in enumerate(slots):
                line_point = p_line[slot] - (p_line[slot] @ d[slot]) * d[slot]
                rows.append(
                    (
                        float(scores[k]),
                        float(stops_needed[k]),
                        float(l_in[chosen[k]]),
                        int(self._bodies[slot].index()),
                        points[k],
                        forces[k],
                        line_point,
                    )
                )
        if not rows:
            status = FORCE_TOO_SMALL if not strong.any() else NO_INTERSECTION
            return LocalizationResult(status, force_W=best_force.copy(), limited_joints=tuple(int(k) for k in limited))
        rows.sort(key=lambda row: (round(row[0], 12), round(row[1], 9), row[2]))
        best = rows[0]
        link = self._rigid_link[best[3]]
        others = [(row[0], row[3], row[4]) for row in rows if self._rigid_link[row[3]] != link]
        others += [
            (float(free_misfit[slot]), int(body.index()), X_WB[slot, :, 3].copy())
            for slot, body in enumerate(self._bodies)
            if self._rigid_link[int(body.index())] != link
        ]
        runner = min(others, key=lambda other: other[0]) if others else None
        runner_up = runner[0] if runner is not None else math.inf
        return LocalizationResult(
            AMBIGUOUS if runner_up - best[0] < self._margin else VALID,
            best[3],
            best[4].copy(),
            best[5].copy(),
            best[0],
            runner_up,
            best[6].copy(),
            [(row[3], row[4].copy(), row[0], row[2]) for row in rows],
            runner_up_body_index=runner[1] if runner is not None else -1,
            runner_up_point_W=runner[2].copy() if runner is not None else np.zeros(3),
            limited_joints=tuple(int(k) for k in limited),
        )

    @property
    def unknown_wrench_frames(self) -> tuple[Frame, ...]:
        """The frames whose wrenches are unknown (() with foot F/T sensors)."""
        return self._unknown.frames

    def localization_inputs(self, context: Context) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, external wrench in world, internal residual) that the localizer's current
        result was computed from: the running means once averaging had started, else the
        inputs of that update (zeros before the first localization). With them
        ``localize`` replays the result offline (e.g. to study its settings)."""
        return self.split_localized(np.array(context.get_discrete_state(self._localized_index).get_value()))

    def _split_means(self, means: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, wrench, residual) of the averaging state's means; q's quaternion (the mean
        of nearby unit quaternions) renormalised."""
        n = self._n
        q = means[6 + n :].copy()
        q[:4] /= np.linalg.norm(q[:4])
        return q, means[:6], means[6 : 6 + n]

    def averaging_start(self, averaging: np.ndarray) -> float | None:
        """The time (s) from which the means of the averaging state ``averaging`` (the
        first group of ``initial_state``'s layout) average the inputs, or None when they do
        not (no contact, or not settled yet)."""
        avg = _Averaging(np.asarray(averaging, dtype=float))
        if avg.active < 0.5 or avg.count < 1.0:
            return None
        return float(avg.onset + self._settle_time)

    def estimate(self, context: Context) -> LocalizationResult:
        """The localization stored in ``context``'s state (without candidates)."""
        return self.unpack(self._r(context))

    # -- system -----------------------------------------------------------------------------
    def _r(self, context: Context) -> np.ndarray:
        return context.get_discrete_state(self._result_index).get_value()

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        who = self._who
        x = eval_finite_input(who, self._state_port, context)
        w = eval_finite_input(who, self._wrench_port, context)
        r = eval_finite_input(who, self._residual_port, context)
        detected = True
        if self._detected_port is not None:
            detected = float(eval_finite_input(who, self._detected_port, context)[0]) > 0.5
        groups = (self._avg_index, self._means_index, self._localized_index, self._result_index)
        state = tuple(context.get_discrete_state(i).get_value() for i in groups)
        for index, value in zip(groups, self.advance(state, context.get_time(), x, w, r, detected)):
            discrete_state.set_value(index, value)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The discrete state of a new context, as ``advance`` takes it: (averaging, means,
        inputs of the last localization, result)."""
        context = self.CreateDefaultContext()
        groups = (self._avg_index, self._means_index, self._localized_index, self._result_index)
        return tuple(np.array(context.get_discrete_state(i).get_value()) for i in groups)

    def advance(
        self,
        state: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        t: float,
        x: np.ndarray,
        w: np.ndarray,
        r: np.ndarray,
        detected: bool,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One update without a Context (``systems.residuals.offline`` replays logs with
        it): the next (averaging, means, inputs of the last localization, result) from
        ``state`` (as ``initial_state``), the time t (s) and this update's inputs: the
        sensed state x, the external wrench w, the internal residual r and the detector's
        flag. Inputs are not checked."""
        avg_state, means, localized, result = state
        q = x[: self._nq]
        avg = _Averaging(np.array(avg_state))
        if not detected:
            return (
                np.zeros(len(_Averaging.get_fields())),
                means,
                localized,
                self._pack(LocalizationResult(NO_CONTACT, force_W=np.array(w[3:]))),
            )
        if avg.active < 0.5:
            avg.active, avg.count, avg.onset, avg.localized = 1.0, 0.0, t, -math.inf
        if t - avg.onset >= self._settle_time - 1e-12:
            avg.count += 1.0
            alpha = 1.0 / avg.count
            if self._tau is not None:
                alpha = max(alpha, self._period / self._tau)
            sample = np.concatenate((w, r, q))
            means = np.array(means)
            means += alpha * (sample - means)
            q, w, r = self._split_means(means)
        if t - avg.localized >= self._localization_period - 1e-9:
            avg.localized = t
            localized = np.concatenate((w, r, q))
            result = self._pack(self.localize(q, w, r))
        return avg[:], means, localized, result

    def replay(
        self, times: np.ndarray, x: np.ndarray, w: np.ndarray, r: np.ndarray, detected: np.ndarray
    ) -> np.ndarray:
        """(N, 14) the packed result of N successive ``advance`` calls from
        ``initial_state`` (times (N,), s; x, w, r, detected per sample as ``advance``
        takes them), without stepping each sample: a contact's averaged inputs are running
        means (cumulative sums; past ``averaging_time_constant``, its exponential filter),
        needed only where a localization happens. Equal to stepping ``advance`` to
        rounding (tests). Inputs are not checked."""
        return self.replay_from(None, times, x, w, r, detected)[0]

    def replay_from(
        self,
        start: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
        times: np.ndarray,
        x: np.ndarray,
        w: np.ndarray,
        r: np.ndarray,
        detected: np.ndarray,
        *,
        end_only: bool = False,
    ) -> tuple[np.ndarray | None, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """``replay`` from the state ``start`` (as ``advance`` takes it; None:
        ``initial_state``), e.g. where a replay of the samples before left off: returns the
        (N, 14) packed results and the state after the last sample, as stepping
        ``advance`` would (to rounding). A ``start`` in the middle of an averaging is
        stepped sample by sample (exact by construction); otherwise as ``replay``.
        ``end_only``: only the state after the last sample is wanted (the results are
        None): of the localizations only the last one runs, the one that state holds
        (each localization depends on its own averaged inputs only); the state's running
        means are then those of the last contact (an averaging restarts from its first
        sample, so earlier ones do not matter)."""
        N = len(times)
        out = np.empty((N, 14))
        detected = np.asarray(detected, dtype=bool)
        state = self.initial_state() if start is None else tuple(np.array(part) for part in start)
        if N == 0:
            return out, state
        if _Averaging(state[0]).active > 0.5:
            for k in range(N):
                state = self.advance(state, float(times[k]), x[k], w[k], r[k], bool(detected[k]))
                out[k] = state[3]
            return (None if end_only else out), state
        _, means_end, localized, _ = state
        idle = ~detected
        out[idle] = self._pack(LocalizationResult(NO_CONTACT, force_W=np.zeros(3)))
        out[idle, 5:8] = w[idle, 3:]
        samples = np.concatenate((w, r, x[:, : self._nq]), axis=1)
        edges = np.flatnonzero(np.diff(np.concatenate(([0], detected.astype(np.int8), [0]))))
        avg_end = np.zeros(len(_Averaging.get_fields()))
        intervals = list(zip(edges[::2].tolist(), edges[1::2].tolist()))
        for a, b in intervals[-1:] if end_only else intervals:
            t = times[a:b]
            settled = np.flatnonzero(t - t[0] >= self._settle_time - 1e-12)
            first = int(settled[0]) if settled.size else b - a
            means = None
            if settled.size:
                s = samples[a + first : b]
                count = np.arange(1.0, len(s) + 1.0)
                means = np.cumsum(s, axis=0) / count[:, None]
                if self._tau is not None:
                    beta = self._period / self._tau
                    tail = np.flatnonzero(1.0 / count < beta)  # alpha = max(1/count, T/tau) = beta
                    if tail.size:
                        c = int(tail[0])
                        y0 = means[c - 1] if c > 0 else np.zeros(s.shape[1])
                        means[c:] = first_order_filter(s[c:], beta, y0)
                means_end = means[-1]
            # The localizations: at the first sample, then each one localization period
            # after the last (the ticks depend on the times only).
            ticks, last = [], -math.inf
            for i, ti in enumerate(t.tolist()):
                if ti - last >= self._localization_period - 1e-9:
                    ticks.append(i)
                    last = ti
            for i in ticks[-1:] if end_only else ticks:
                if i >= first:
                    q, wi, ri = self._split_means(means[i - first])
                else:
                    q, wi, ri = x[a + i, : self._nq], w[a + i], r[a + i]
                localized = np.concatenate((wi, ri, q))
                out[a + i] = self._pack(self.localize(q, wi, ri))
            if end_only:
                out[b - 1] = out[a + ticks[-1]]
            else:
                localized_at = set(ticks)
                for i in range(1, b - a):  # between localizations the result holds
                    if i not in localized_at:
                        out[a + i] = out[a + i - 1]
            if b == N:  # still averaging after the last sample
                avg_end = np.array([1.0, float(max(b - a - first, 0)), float(t[0]), last])
        return (None if end_only else out), (avg_end, np.array(means_end), np.array(localized), out[-1].copy())

    @staticmethod
    def unpack(s: np.ndarray) -> LocalizationResult:
        """The localization of a packed result (a row of ``replay``, the last part of
        ``advance``'s state), without candidates."""
        return LocalizationResult(
            int(s[0]),
            int(s[1]),
            np.array(s[2:5]),
            np.array(s[5:8]),
            float(s[8]),
            float(s[9]),
            runner_up_body_index=int(s[10]),
            runner_up_point_W=np.array(s[11:14]),
        )

    def split_localized(self, localized: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, external wrench in world, internal residual) of the inputs of the last
        localization as ``advance``'s state holds them (``localization_inputs``)."""
        n = self._n
        return localized[6 + n :], localized[:6], localized[6 : 6 + n]

    @staticmethod
    def _pack(result: LocalizationResult) -> np.ndarray:
        return np.concatenate(
            (
                [float(result.status), float(result.body_index)],
                result.point_W,
                result.force_W,
                [result.score, result.runner_up_score, float(result.runner_up_body_index)],
                result.runner_up_point_W,
            )
        )


class GatedEstimate(LeafSystem):
    """The localizer's force and point, zeroed while the result is not valid (so the
    estimate's arrow hides). Inputs ``force``, ``point``, ``valid``; outputs ``force_world``,
    ``point_world``."""

    def __init__(self):
        super().__init__()
        self._f = self.DeclareVectorInputPort("force", 3)
        self._p = self.DeclareVectorInputPort("point", 3)
        self._v = self.DeclareVectorInputPort("valid", 1)
        self.DeclareVectorOutputPort("force_world", 3, self._CalcForce)
        self.DeclareVectorOutputPort("point_world", 3, lambda c, o: o.SetFromVector(self._p.Eval(c)))

    def _CalcForce(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._f.Eval(context) if self._v.Eval(context)[0] > 0.5 else np.zeros(3))
