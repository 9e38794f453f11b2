"""Meshcat overlays of the estimated joint efforts and of the external forces.

Flacco, Paolillo, Kheddar (2016), Figs. 5-6, show the robot with each joint "gradually
highlighted in red in proportion to the effort" estimated by a residual, and the external
forces as red lines. This module draws both in Meshcat, live and in a recorded replay:

* ``JointEffortOverlay``: one translucent red sphere per chosen joint, centred on the
  origin of the joint's child frame, whose size grows with |effort| / max_effort (hidden at
  zero effort, full ``radius`` at and above ``max_effort``);
* ``ForceArrows``: one red arrow per external force, its head ending at the application
  point (the force pushes INTO the body there), its length |f| / newtons_per_meter, hidden
  when the force is about zero;
* ``add_effort_visualization``: wires both into a ``DiagramBuilder``;
* ``read_static_html``: decodes a ``Meshcat.StaticHtml()`` page (scene commands and the
  recorded animation tracks), for tests and for checking replays without a browser.

What replays in a recording (Drake 1.51.1, checked by ``tests/test_visualization.py`` and
by rendering replays in headless Chromium): ``SetTransform`` and ``SetProperty`` of "scale"
(vector3) and "visible" (boolean) with ``time_in_recording`` become animation tracks;
recorded "color" does not. The overlays therefore animate only transforms, scales and
visibility. Three.js' ``Object3D.matrix.decompose`` resets a node's scale whenever its
transform is set, so no node gets both: every scaled node is a child of a transformed one.

Meshcat tree (paths relative to ``/drake``)::

    <path>/<joint>            transform: translation to the joint (world), animated; visible
    <path>/<joint>/marker     scale [s, s, s], animated; the sphere geometry below it
    <path>/<i>                transform X_WA: origin at the arrow's TAIL, +z along f
    <path>/<i>/shaft          scale [c, c, L - c h] (unit cylinder below it, z in [0, 1])
    <path>/<i>/head           transform: translation (0, 0, L), flipped (apex at the point)
    <path>/<i>/head/cone      scale [c, c, c] (c < 1 shrinks arrows shorter than 2 h)

Both systems publish periodically (default 32 Hz), on ``ForcedPublish`` and at
initialization, passing the context time as ``time_in_recording`` (as
``MeshcatVisualizer`` does; Meshcat ignores it when not recording). To keep replays small,
a value that has not changed by more than a tolerance since it was last sent is not sent
again; when it changes, the held value is first re-sent at the previous publish time so
that the replay's linear interpolation stays within the tolerance (0.5 mm for positions,
1 % of full size for scales).
"""

from __future__ import annotations

import base64
import math
import re
import struct
from collections.abc import Sequence

import numpy as np
from pydrake.geometry import Cylinder, Meshcat, MeshcatCone, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Joint
from pydrake.systems.framework import Context, DiagramBuilder, EventStatus, LeafSystem, OutputPort

from systems.common.checks import eval_finite_input, positive_number

__all__ = [
    "DEFAULT_PUBLISH_PERIOD",
    "ForceArrows",
    "JointEffortOverlay",
    "StaticHtmlScene",
    "ESTIMATE_RGBA",
    "add_effort_visualization",
    "add_force_arrows",
    "read_static_html",
]

#: Default publish period of the overlays [s] (32 Hz, the apps' recording rate).
DEFAULT_PUBLISH_PERIOD = 1.0 / 32.0
#: The paper's red, translucent for the effort markers.
EFFORT_RGBA = Rgba(0.9, 0.05, 0.05, 0.55)
FORCE_RGBA = Rgba(0.85, 0.0, 0.0, 1.0)
#: Blue, for an estimate drawn beside the applied (red) forces.
ESTIMATE_RGBA = Rgba(0.1, 0.3, 0.9, 0.9)

_POSITION_TOL = 5e-4  # m: a marker or arrow that moved less is not re-sent
_SCALE_TOL = 1e-2  # fraction of full size
_MIN_SCALE = 1e-3  # Three.js dislikes exactly zero scales (singular normal matrix)


# ---------------------------------------------------------------------------------------
# Sending with hold compression.
# ---------------------------------------------------------------------------------------


class _Track:
    """One Meshcat value (a node's transform, scale or visibility) sent with hold
    compression: unchanged values are skipped; before a change, the held value is re-sent
    at the last skipped publish time, so that interpolating the recorded key frames
    reproduces the held segment."""

    __slots__ = ("send", "tol", "value", "time", "skipped_time")

    def __init__(self, send, tol: float):
        self.send = send  # send(value, time)
        self.tol = tol
        self.reset()

    def reset(self) -> None:
        self.value = None
        self.time = -math.inf
        self.skipped_time = None

    def update(self, value, t: float) -> None:
        """``value``: a bool, a float, or a tuple/list of floats (plain Python numbers: this
        runs for every marker at every publish)."""
        if t < self.time:  # a new simulation (time went back): start over
            self.reset()
        held = self.value
        if held is not None:
            if isinstance(value, bool):
                same = value == held
            elif isinstance(value, float):
                same = abs(value - held) <= self.tol
            else:
                same = max(abs(a - b) for a, b in zip(value, held)) <= self.tol
            if same:
                self.skipped_time = t
                return
            if self.skipped_time is not None and self.skipped_time > self.time:
                self.send(self.value, self.skipped_time)
        self.send(value, t)
        self.value = value
        self.time = t
        self.skipped_time = None


def _checked(system: LeafSystem, port, context: Context) -> np.ndarray:
    return eval_finite_input(type(system).__name__, port, context)


def _period(period: float, who: str) -> float:
    period = float(period)
    if not math.isfinite(period) or period <= 0.0:
        raise ValueError(f"{who}: publish_period must be a positive number of seconds, got {period}")
    return period


def _node_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", name) or "_"


def _base_velocities(plant: MultibodyPlant) -> int:
    """6 if the plant's first 6 velocities belong to a floating (6-DoF) joint, else 0."""
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.num_velocities() == 6 and joint.velocity_start() == 0:
            return 6
    return 0


class _MeshcatOverlay(LeafSystem):
    """Shared part of the overlays: a Meshcat path whose nodes carry ``_Track``s, published
    at a fixed period, on forced publishes and at initialization (which (re)creates the
    objects, so that a new simulation starts from a clean scene and fresh tracks).
    Subclasses set ``_meshcat``, ``_path``, ``_tracks`` and implement ``_add_objects`` and
    ``_Publish``, then call ``_declare_overlay_events``."""

    def _declare_overlay_events(self, period: float) -> None:
        self._objects_set = False
        self._visible = True
        self.DeclarePeriodicPublishEvent(period, 0.0, self._Publish)
        self.DeclareForcedPublishEvent(self._Publish)
        self.DeclareInitializationPublishEvent(self._Initialize)

    def set_visible(self, visible: bool, time_in_recording: float | None = None) -> None:
        """Shows or hides the whole overlay (the root path's "visible" property)."""
        self._visible = bool(visible)
        self._meshcat.SetProperty(self._path, "visible", self._visible, time_in_recording)

    def _set_objects(self) -> None:
        self._meshcat.Delete(self._path)
        self._add_objects()
        self._meshcat.SetProperty(self._path, "visible", self._visible)
        for tracks in self._tracks:
            for track in tracks:
                track.reset()
        self._objects_set = True

    def _ensure_objects(self) -> None:
        if not self._objects_set:
            self._set_objects()

    def _Initialize(self, context: Context) -> EventStatus:
        self._set_objects()
        return self._Publish(context)


# ---------------------------------------------------------------------------------------
# Joint effort markers.
# ---------------------------------------------------------------------------------------


class JointEffortOverlay(_MeshcatOverlay):
    """Red spheres at chosen joints, sized by the estimated joint effort (paper Figs. 5-6).

    Inputs:
        residual: joint efforts, N m (N for prismatic joints), in the plant's joint
            velocity order v[6:] (entry k belongs to the joint whose velocity_start is
            6 + k): the internal residual's output, size n = nv - 6. With
            ``includes_base=True`` it is the classical residual's size nv (its first 6
            base entries are ignored). On a plant without a floating base: size nv.
        state: the plant's [q; v] (nq + nv), for the joint positions in world.

    State: none. On each publish (periodic, forced, initialization) every marker is placed
    at its joint's child-frame origin in world with scale s = min(|effort| / max_effort, 1)
    (radius s * ``radius``) and is hidden while s < 1 %.

    Args:
        plant: the finalized plant (used with its own context, created once).
        meshcat: the Meshcat instance.
        joints: the 1-DoF joints (``Joint`` objects or unique names) to show.
        max_effort: effort at which a marker reaches full size, N m; scalar or one per
            joint (in ``joints`` order).
        path: the Meshcat path of the overlay (relative paths live under /drake).
        radius: full-size sphere radius, m; default 4.7 % of the robot's extent at the
            plant's default posture (6 cm for hrp4_like, 2.3 cm for nao_like).
        publish_period: s, default 1/32.
        includes_base: the residual is the classical one, size nv (see Inputs).
        rgba: the spheres' colour (translucent red by default).

    Raises:
        ValueError: plant not finalized, unknown/ambiguous/duplicate joint names, joints
            that are not 1-DoF or not in the plant, a bad max_effort, radius or period.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        meshcat: Meshcat,
        joints: Sequence[Joint | str],
        *,
        max_effort,
        path: str = "effort",
        radius: float | None = None,
        publish_period: float = DEFAULT_PUBLISH_PERIOD,
        includes_base: bool = False,
        rgba: Rgba = EFFORT_RGBA,
    ):
        super().__init__()
        who = type(self).__name__
        if not plant.is_finalized():
            raise ValueError(f"{who}: the plant must be finalized")
        self._plant = plant
        self._meshcat = meshcat
        self._path = path.rstrip("/")
        self._rgba = rgba
        self._joints = _resolve_joints(plant, joints, who)
        k = len(self._joints)
        max_effort = np.asarray(max_effort, dtype=float)
        if max_effort.ndim == 0:
            max_effort = np.full(k, float(max_effort))
        if max_effort.shape != (k,):
            raise ValueError(
                f"{who}: max_effort must be a scalar or have one entry per joint ({k}), got shape {max_effort.shape}"
            )
        if not (np.isfinite(max_effort).all() and (max_effort > 0).all()):
            raise ValueError(f"{who}: max_effort must be positive and finite, got {max_effort}")
        self._inv_max = 1.0 / max_effort
        self._context = plant.CreateDefaultContext()
        self.radius = (
            positive_number(radius, f"{who}: radius") if radius is not None else _default_radius(plant, self._context)
        )
        period = _period(publish_period, who)

        base_nv = _base_velocities(plant)
        nv = plant.num_velocities()
        self._size = nv if includes_base else nv - base_nv
        offset = 0 if includes_base else base_nv
        self._indices = np.array([j.velocity_start() - offset for j in self._joints], dtype=int)
        # Each marker's place: the child frame's origin, fixed in the child body.
        self._bodies = [j.frame_on_child().body() for j in self._joints]
        self._p_BF = [j.frame_on_child().GetFixedPoseInBodyFrame().translation().copy() for j in self._joints]
        self._names = _unique_node_names([j.name() for j in self._joints])
        self._nodes = [f"{self._path}/{n}" for n in self._names]
        self._tracks = []
        for node in self._nodes:
            marker = f"{node}/marker"
            self._tracks.append(
                (
                    _Track(lambda p, t, node=node: meshcat.SetTransform(node, RigidTransform(p), t), _POSITION_TOL),
                    _Track(lambda s, t, m=marker: meshcat.SetProperty(m, "scale", [s, s, s], t), _SCALE_TOL),
                    _Track(lambda v, t, node=node: meshcat.SetProperty(node, "visible", v, t), 0.0),
                )
            )
        self._residual_port = self.DeclareVectorInputPort("residual", self._size)
        self._state_port = self.DeclareVectorInputPort("state", plant.num_positions() + nv)
        self._declare_overlay_events(period)

    # -- accessors ------------------------------------------------------------------------
    @property
    def joints(self) -> tuple[Joint, ...]:
        return self._joints

    @property
    def paths(self) -> tuple[str, ...]:
        """Meshcat path of each joint's marker node (transform and visibility)."""
        return tuple(self._nodes)

    def scales(self, effort: np.ndarray) -> np.ndarray:
        """Marker scales (fraction of ``radius``) for a ``residual`` input value."""
        return np.minimum(np.abs(np.asarray(effort)[self._indices]) * self._inv_max, 1.0)

    def joint_positions(self, x: np.ndarray) -> np.ndarray:
        """(k, 3) world positions of the markers for a plant state x = [q; v]."""
        self._plant.SetPositions(self._context, x[: self._plant.num_positions()])
        out = np.empty((len(self._joints), 3))
        for i, (body, p_BF) in enumerate(zip(self._bodies, self._p_BF)):
            out[i] = self._plant.EvalBodyPoseInWorld(self._context, body).multiply(p_BF)
        return out

    # -- events ---------------------------------------------------------------------------
    def _add_objects(self) -> None:
        sphere = Sphere(self.radius)
        for node in self._nodes:
            self._meshcat.SetObject(f"{node}/marker", sphere, self._rgba)

    def _Publish(self, context: Context) -> EventStatus:
        effort = _checked(self, self._residual_port, context)
        x = _checked(self, self._state_port, context)
        self._ensure_objects()
        t = context.get_time()
        positions = self.joint_positions(x).tolist()
        for (where, scale, visible), p, s in zip(self._tracks, positions, self.scales(effort).tolist()):
            where.update(p, t)
            scale.update(max(s, _MIN_SCALE), t)
            visible.update(s >= 0.01, t)
        return EventStatus.Succeeded()


def _resolve_joints(plant: MultibodyPlant, joints, who: str) -> tuple[Joint, ...]:
    if isinstance(joints, (str, Joint)):
        joints = [joints]
    out = []
    for item in joints:
        if isinstance(item, str):
            if not plant.HasJointNamed(item):
                raise ValueError(f"{who}: the plant has no joint named '{item}'")
            try:
                joint = plant.GetJointByName(item)
            except RuntimeError as error:
                raise ValueError(f"{who}: joint name '{item}' is ambiguous ({error}); pass the Joint") from error
        elif isinstance(item, Joint):
            joint = item
            if (
                int(joint.index()) >= plant.num_joints()
                or plant.get_joint(joint.index()).name() != joint.name()
                or plant.get_joint(joint.index()).model_instance() != joint.model_instance()
            ):
                raise ValueError(f"{who}: joint '{joint.name()}' does not belong to this plant")
        else:
            raise ValueError(f"{who}: joints must be Joint objects or names, got {type(item).__name__}")
        if joint.num_velocities() != 1:
            raise ValueError(
                f"{who}: joint '{joint.name()}' has {joint.num_velocities()} DoF; only 1-DoF joints are supported"
            )
        out.append(joint)
    indices = [int(j.index()) for j in out]
    if len(set(indices)) != len(indices):
        dup = sorted({out[i].name() for i, v in enumerate(indices) if indices.count(v) > 1})
        raise ValueError(f"{who}: joints listed twice: {dup}")
    if not out:
        raise ValueError(f"{who}: no joints given")
    return tuple(out)


def _unique_node_names(names: Sequence[str]) -> list[str]:
    out, seen = [], set()
    for name in names:
        node, i = _node_name(name), 1
        while node in seen:
            i += 1
            node = f"{_node_name(name)}_{i}"
        seen.add(node)
        out.append(node)
    return out


def _default_radius(plant: MultibodyPlant, context) -> float:
    """4.7 % of the largest extent of the body origins at the default posture (>= 5 mm)."""
    points = np.array(
        [
            plant.EvalBodyPoseInWorld(context, plant.get_joint(j).child_body()).translation()
            for j in plant.GetJointIndices()
        ]
    )
    if len(points) == 0:
        return 0.05
    extent = float(np.max(points.max(axis=0) - points.min(axis=0)))
    return max(0.047 * extent, 0.005)


# ---------------------------------------------------------------------------------------
# Force arrows.
# ---------------------------------------------------------------------------------------


class ForceArrows(_MeshcatOverlay):
    """Red arrows for external forces, each ending at its application point (paper Figs.
    5-6's "red lines").

    Inputs:
        force_world: (3 k) forces f_W, N (``PushSource``'s ground truth or an estimate).
        point_world: (3 k) application points p_WP, m.

    State: none. On each publish an arrow i runs from its tail p - f / newtons_per_meter to
    its head's apex at p (it points along f, into the body the force pushes on); it is
    hidden while |f| < ``min_force``. Its frame's origin is the tail and its +z axis is
    f / |f| (``MakeFromOneVector``), so the length is |p - tail|.

    Args:
        meshcat: the Meshcat instance.
        num_forces: k.
        path: the Meshcat path (relative paths live under /drake).
        newtons_per_meter: arrow length scale, N per m of arrow (default 100: a 40 N push
            is 40 cm long).
        rgba: colour (red).
        publish_period: s, default 1/32.
        shaft_radius, head_radius, head_length: m.
        min_force: forces below this norm, N, hide their arrow.
    """

    def __init__(
        self,
        meshcat: Meshcat,
        num_forces: int,
        *,
        path: str = "forces",
        newtons_per_meter: float = 100.0,
        rgba: Rgba = FORCE_RGBA,
        publish_period: float = DEFAULT_PUBLISH_PERIOD,
        shaft_radius: float = 0.008,
        head_radius: float = 0.02,
        head_length: float = 0.05,
        min_force: float = 1e-3,
    ):
        super().__init__()
        who = type(self).__name__
        if int(num_forces) != num_forces or num_forces < 0:
            raise ValueError(f"{who}: num_forces must be a non-negative integer, got {num_forces}")
        self._k = k = int(num_forces)
        self._meshcat = meshcat
        self._path = path.rstrip("/")
        self._rgba = rgba
        self._meters_per_newton = 1.0 / positive_number(newtons_per_meter, f"{who}: newtons_per_meter")
        self._shaft_radius = positive_number(shaft_radius, f"{who}: shaft_radius")
        self._head_radius = positive_number(head_radius, f"{who}: head_radius")
        self._head_length = positive_number(head_length, f"{who}: head_length")
        self._min_force = float(min_force)
        if not math.isfinite(self._min_force) or self._min_force < 0:
            raise ValueError(f"{who}: min_force must be non-negative, got {min_force}")
        period = _period(publish_period, who)
        self._nodes = [f"{self._path}/{i}" for i in range(k)]
        flip = RotationMatrix.MakeXRotation(math.pi)
        self._tracks = []
        for node in self._nodes:
            self._tracks.append(
                (
                    _Track(lambda X, t, n=node: meshcat.SetTransform(n, _pose_from_vector(X), t), _POSITION_TOL),
                    _Track(lambda s, t, n=f"{node}/shaft": meshcat.SetProperty(n, "scale", list(s), t), _POSITION_TOL),
                    _Track(
                        lambda L, t, n=f"{node}/head": meshcat.SetTransform(n, RigidTransform(flip, [0, 0, L]), t),
                        _POSITION_TOL,
                    ),
                    _Track(
                        lambda c, t, n=f"{node}/head/cone": meshcat.SetProperty(n, "scale", [c, c, c], t), _SCALE_TOL
                    ),
                    _Track(lambda v, t, n=node: meshcat.SetProperty(n, "visible", v, t), 0.0),
                )
            )
        self._force_port = self.DeclareVectorInputPort("force_world", 3 * k)
        self._point_port = self.DeclareVectorInputPort("point_world", 3 * k)
        self._declare_overlay_events(period)

    @property
    def paths(self) -> tuple[str, ...]:
        """Meshcat path of each arrow's root node."""
        return tuple(self._nodes)

    def arrow(self, f_W: np.ndarray, p_W: np.ndarray):
        """(tail, R_WA, length, cone scale c): the arrow drawn for one force."""
        f_W = np.asarray(f_W, dtype=float)
        norm = float(np.linalg.norm(f_W))
        length = norm * self._meters_per_newton
        if norm > 0.0:
            R = RotationMatrix.MakeFromOneVector(f_W / norm, 2)
        else:
            R = RotationMatrix()
        c = min(1.0, length / (2.0 * self._head_length))
        return np.asarray(p_W, dtype=float) - length * R.col(2), R, length, c

    def _add_objects(self) -> None:
        m = self._meshcat
        shaft = Cylinder(self._shaft_radius, 1.0)
        cone = MeshcatCone(self._head_length, self._head_radius, self._head_radius)
        for node in self._nodes:
            m.SetObject(f"{node}/shaft/cylinder", shaft, self._rgba)
            m.SetTransform(f"{node}/shaft/cylinder", RigidTransform([0.0, 0.0, 0.5]))
            m.SetObject(f"{node}/head/cone", cone, self._rgba)

    def _Publish(self, context: Context) -> EventStatus:
        forces = _checked(self, self._force_port, context)
        points = _checked(self, self._point_port, context)
        self._ensure_objects()
        t = context.get_time()
        for i, (pose, shaft, head, cone, visible) in enumerate(self._tracks):
            f = forces[3 * i : 3 * i + 3]
            fx, fy, fz = f.tolist()
            norm = math.sqrt(fx * fx + fy * fy + fz * fz)
            shown = norm >= self._min_force and norm > 0.0
            visible.update(shown, t)
            if not shown:
                continue  # a hidden arrow keeps its last pose
            tail, R, length, c = self.arrow(f, points[3 * i : 3 * i + 3])
            pose.update(R.matrix().ravel().tolist() + tail.tolist(), t)
            c = max(float(c), _MIN_SCALE)
            shaft.update((c, c, max(float(length) - c * self._head_length, _MIN_SCALE)), t)
            head.update(float(length), t)
            cone.update(c, t)
        return EventStatus.Succeeded()


def _pose_from_vector(v: np.ndarray) -> RigidTransform:
    """RigidTransform from [R (row-major, 9); p (3)]."""
    return RigidTransform(RotationMatrix(np.reshape(v[:9], (3, 3))), v[9:])


# ---------------------------------------------------------------------------------------
# Builder helper.
# ---------------------------------------------------------------------------------------


def add_effort_visualization(
    builder: DiagramBuilder,
    plant: MultibodyPlant,
    meshcat: Meshcat,
    residual_port: OutputPort,
    state_port: OutputPort,
    joints: Sequence[Joint | str],
    *,
    max_effort,
    force_port: OutputPort | None = None,
    point_port: OutputPort | None = None,
    includes_base: bool = False,
    prefix: str = "",
    radius: float | None = None,
    newtons_per_meter: float = 100.0,
    publish_period: float = DEFAULT_PUBLISH_PERIOD,
) -> dict:
    """Adds a ``JointEffortOverlay`` (and ``ForceArrows`` if ``force_port`` is given) and
    connects them.

    Args:
        builder: the diagram builder holding the ports' systems.
        plant: the finalized plant.
        meshcat: the Meshcat instance.
        residual_port: joint efforts (size nv - 6, or nv with ``includes_base``).
        state_port: the plant's [q; v].
        joints: the joints to show (Joint objects or names).
        max_effort: N m at full marker size, scalar or per joint.
        force_port, point_port: (3 k) forces and application points in world (e.g.
            ``PushSource``'s ``force_world`` and ``point_world``); both or neither.
        includes_base: the residual has the classical residual's nv entries.
        prefix: prepended to the Meshcat paths ("effort", "forces") and the system names,
            so that several overlays (e.g. one per residual) can coexist.
        radius, newtons_per_meter, publish_period: see the systems.

    Returns:
        {"effort_overlay": JointEffortOverlay, "force_arrows": ForceArrows or None}.

    Raises:
        ValueError: port sizes that do not match the plant, only one of force/point ports,
            and everything the systems' constructors reject.
    """
    overlay = JointEffortOverlay(
        plant,
        meshcat,
        joints,
        max_effort=max_effort,
        path=f"{prefix}effort",
        radius=radius,
        publish_period=publish_period,
        includes_base=includes_base,
    )
    for port, mine in (
        (residual_port, overlay.GetInputPort("residual")),
        (state_port, overlay.GetInputPort("state")),
    ):
        if port.size() != mine.size():
            raise ValueError(
                f"add_effort_visualization: the {mine.get_name()} port "
                f"'{port.get_system().get_name()}.{port.get_name()}' has size {port.size()}, "
                f"expected {mine.size()}"
                + (" (set includes_base for the classical residual)" if mine.get_name() == "residual" else "")
            )
    overlay.set_name(f"{prefix}joint_effort_overlay")
    builder.AddSystem(overlay)
    builder.Connect(residual_port, overlay.GetInputPort("residual"))
    builder.Connect(state_port, overlay.GetInputPort("state"))
    arrows = None
    if (force_port is None) != (point_port is None):
        raise ValueError("add_effort_visualization: give both force_port and point_port, or neither")
    if force_port is not None:
        arrows = add_force_arrows(
            builder,
            meshcat,
            force_port,
            point_port,
            name=f"{prefix}force_arrows",
            path=f"{prefix}forces",
            newtons_per_meter=newtons_per_meter,
            publish_period=publish_period,
        )
    return {"effort_overlay": overlay, "force_arrows": arrows}


def add_force_arrows(
    builder: DiagramBuilder,
    meshcat: Meshcat,
    force_port: OutputPort,
    point_port: OutputPort,
    *,
    name: str,
    **arrow_options,
) -> ForceArrows:
    """Adds ``ForceArrows`` named ``name`` to ``builder``, one arrow per force of
    ``force_port`` (3 k forces in world, N) drawn at the points of ``point_port`` (3 k, m);
    ``arrow_options`` go to ``ForceArrows`` (path, newtons_per_meter, rgba, min_force, ...).

    Raises:
        ValueError: ports of different sizes, or a size that is not a multiple of 3.
    """
    if force_port.size() != point_port.size() or force_port.size() % 3:
        raise ValueError(
            f"{name}: force_port (size {force_port.size()}) and point_port "
            f"(size {point_port.size()}) must have the same size, a multiple of 3"
        )
    arrows = ForceArrows(meshcat, force_port.size() // 3, **arrow_options)
    arrows.set_name(name)
    builder.AddSystem(arrows)
    builder.Connect(force_port, arrows.GetInputPort("force_world"))
    builder.Connect(point_port, arrows.GetInputPort("point_world"))
    return arrows


# ---------------------------------------------------------------------------------------
# Reading a StaticHtml page back (tests, replay checks).
# ---------------------------------------------------------------------------------------


class StaticHtmlScene:
    """The Meshcat commands embedded in a ``StaticHtml()`` page.

    Attributes (paths are absolute, e.g. "/drake/effort/KNEE"):
        transforms: path -> 4x4 matrix of the last ``set_transform``.
        properties: path -> {property: last value}.
        objects: paths that received ``set_object``.

        tracks: path -> {property ("position", "quaternion", "scale", "visible"):
            list of (time s, value)} from the recorded animation.

        fps: the animation's frames per second (None without one).
    """

    def __init__(self):
        self.transforms: dict[str, np.ndarray] = {}
        self.properties: dict[str, dict] = {}
        self.objects: set[str] = set()
        self.tracks: dict[str, dict[str, list]] = {}
        self.fps: float | None = None


def read_static_html(html: str) -> StaticHtmlScene:
    """Decodes the msgpack commands of a ``Meshcat.StaticHtml()`` page."""
    scene = StaticHtmlScene()
    for blob in re.findall(r'data:application/octet-binary;base64,([A-Za-z0-9+/=]*)"', html):
        msg = _unpack(base64.b64decode(blob))
        if not isinstance(msg, dict):
            continue
        kind, path = msg.get("type"), msg.get("path")
        if kind == "set_transform":
            scene.transforms[path] = np.array(msg["matrix"], dtype=float).reshape(4, 4).T
        elif kind == "set_property":
            scene.properties.setdefault(path, {})[msg["property"]] = msg["value"]
        elif kind == "set_object":
            scene.objects.add(path)
        elif kind == "set_animation":
            for animation in msg.get("animations", []):
                clip = animation["clip"]
                fps = float(clip.get("fps", 1.0))
                scene.fps = fps
                for track in clip.get("tracks", []):
                    keys = [(float(key["time"]) / fps, key["value"]) for key in track["keys"]]
                    scene.tracks.setdefault(animation["path"], {})[track["name"].lstrip(".")] = keys
    return scene


def _unpack(data: bytes):
    """A minimal msgpack decoder (ext types are returned as (type, bytes))."""
    value, _ = _unpack_at(data, 0)
    return value


def _unpack_at(b: bytes, i: int):  # a format table
    c = b[i]
    i += 1
    if c <= 0x7F:
        return c, i
    if c >= 0xE0:
        return c - 0x100, i
    if 0x80 <= c <= 0x8F:
        return _unpack_map(b, i, c & 0x0F)
    if 0x90 <= c <= 0x9F:
        return _unpack_array(b, i, c & 0x0F)
    if 0xA0 <= c <= 0xBF:
        n = c & 0x1F
        return b[i : i + n].decode("utf-8", "replace"), i + n
    if c == 0xC0:
        return None, i
    if c == 0xC2:
        return False, i
    if c == 0xC3:
        return True, i
    if c in (0xC4, 0xC5, 0xC6, 0xD9, 0xDA, 0xDB):
        width = {0xC4: 1, 0xC5: 2, 0xC6: 4, 0xD9: 1, 0xDA: 2, 0xDB: 4}[c]
        n = int.from_bytes(b[i : i + width], "big")
        i += width
        raw = b[i : i + n]
        return (raw.decode("utf-8", "replace") if c >= 0xD9 else bytes(raw)), i + n
    if c in (0xC7, 0xC8, 0xC9):
        width = {0xC7: 1, 0xC8: 2, 0xC9: 4}[c]
        n = int.from_bytes(b[i : i + width], "big")
        i += width
        return (b[i], bytes(b[i + 1 : i + 1 + n])), i + 1 + n
    if 0xD4 <= c <= 0xD8:
        n = 1 << (c - 0xD4)
        return (b[i], bytes(b[i + 1 : i + 1 + n])), i + 1 + n
    if c == 0xCA:
        return struct.unpack(">f", b[i : i + 4])[0], i + 4
    if c == 0xCB:
        return struct.unpack(">d", b[i : i + 8])[0], i + 8
    if 0xCC <= c <= 0xCF:
        n = 1 << (c - 0xCC)
        return int.from_bytes(b[i : i + n], "big"), i + n
    if 0xD0 <= c <= 0xD3:
        n = 1 << (c - 0xD0)
        return int.from_bytes(b[i : i + n], "big", signed=True), i + n
    if c in (0xDC, 0xDD):
        width = 2 if c == 0xDC else 4
        return _unpack_array(b, i + width, int.from_bytes(b[i : i + width], "big"))
    if c in (0xDE, 0xDF):
        width = 2 if c == 0xDE else 4
        return _unpack_map(b, i + width, int.from_bytes(b[i : i + width], "big"))
    raise ValueError(f"msgpack: unsupported type byte 0x{c:02x} at {i - 1}")


def _unpack_array(b: bytes, i: int, n: int):
    out = []
    for _ in range(n):
        value, i = _unpack_at(b, i)
        out.append(value)
    return out, i


def _unpack_map(b: bytes, i: int, n: int):
    out = {}
    for _ in range(n):
        key, i = _unpack_at(b, i)
        value, i = _unpack_at(b, i)
        out[key if isinstance(key, (str, int, bool)) or key is None else repr(key)] = value
    return out, i
