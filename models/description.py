"""Robot descriptions: a short YAML file beside a robot's URDF or SDFormat file that names what
the project needs of the robot (issue 14). ``load_robot_description(path)`` reads and checks it;
``models.add_humanoid(plant, path)`` adds the robot to a plant and returns its semantic handles.
The two built-in models are two such files (``models/hrp4_like.yaml``, ``models/nao_like.yaml``).

The YAML reference (lengths in m, angles in rad, gains in N m/rad and N m s/rad)::

    name: talos                     # the model instance's name
    model: package://example-robot-data/robots/talos_data/robots/talos_reduced.urdf
                                    # URDF or SDFormat: a path relative to this file, or a
                                    # package:// URI (see ``packages``)
    packages:                       # optional: package name -> folder (relative to this file).
      my_robot_description: ../share/my_robot_description
                                    # Not listed: found in ROS_PACKAGE_PATH, AMENT_PREFIX_PATH
                                    # or an installed (cmeel) Python package's share/ folder.
    base_body: base_link            # the floating base (a body with no parent joint)
    imu_frame: imu_link             # a frame or body on the robot (the IMU's axes)
    collision_meshes: bounding_box  # keep (default) | bounding_box: URDF collision meshes
                                    # Drake cannot use for contact (.stl, .dae) become boxes
    feet:
      left:
        sole_frame: left_sole_link  # frame or body at the sole's centre, x forward, z up
        sole_offset: [0, 0, -0.035] # optional: the sole is this far (m) from sole_frame, in
                                    # its axes (a URDF without a sole frame: its ankle link);
                                    # or lowest_point: at the contact geometries' lowest point
                                    # (x, y their centres' mean) in sole_frame's axes
        sensing: force_torque       # force_torque | fsr | none
        force_torque_joint: leg_left_sole_fix_joint
                                    # force_torque: the weld whose reaction the sensor measures
                                    # (the sole frame's body is its child)
        contact_points: [[0.1, 0.06], [0.1, -0.06], [-0.1, 0.06], [-0.1, -0.06]]
                                    # four (x, y) in the sole frame, in FSR_ORDER (front left,
                                    # front right, rear left, rear right): a small sphere is
                                    # added at each, touching the sole plane. Or, instead,
        # contact_geometries: {body: l_ankle, names: [l_fsr_front_left, ...]}
                                    # four existing collision geometries, in FSR_ORDER; without
                                    # names: the body's four spheres (else its four geometries,
                                    # spheres or boxes), ordered by where they are in the sole
                                    # frame, the FSRs there unless fsr_positions says otherwise
        contact_sphere_radius: 0.005  # optional (default 0.005)
        fsr_positions: [[...], ...]   # optional (x, y) of the four FSRs in the sole frame
                                    # (default: the contact points / geometries)
        fsr_range: 25.0             # optional, sensing fsr: each FSR's upper range, N
                                    # (default 25, Nao's); readings clip there
        remove_collisions: [leg_left_6_link]
                                    # optional, URDF only: bodies whose collision geometries
                                    # are dropped (the foot touches the ground at its spheres)
      right: {...}
    joint_groups:                   # every 1-DoF joint of the model in exactly one group
      left_leg: [...]               # hip to ankle; six joints: the hip's three, knee,
                                    # ankle pitch, ankle roll (groups knees, ankle_pitch)
      right_leg: [...]
      torso: [...]                  # may be empty
      head: [...]
      left_arm: [...]               # shoulder first
      right_arm: [...]
      left_hand: [...]              # may be empty
      right_hand: [...]
    shoulders: {left: arm_left_1_link, right: arm_right_1_link}
                                    # optional (default: the child body of each arm's first joint)
    standing_posture: {leg_left_4_joint: 0.6, ...}
                                    # a standing posture with both soles level (others 0)
    gains:                          # optional PD gains per group [kp, kd]; missing groups are
      legs: [3000.0, 30.0]          # scaled from the robot's mass and height (see
      torso: [...]                  # ``diagrams.station.standing.default_gains``)
      head: [...]
      arms: [...]
      wrists: [...]                 # arm joints with "wrist" in their name
      hands: [...]
    actuators:                      # optional: for joints the model file gives no actuator
      rotor_inertia: {legs: 0.1, knee_joint: 0.2}
                                    # reflected rotor inertia per group or per joint (a joint
                                    # wins over its group), kg m^2 (default 0)
    joint_limits: {joint: [lower, upper]}      # optional overrides, rad
    joint_damping: {joint: b}                  # optional viscous friction overrides, N m s/rad
    link_inertias:                  # optional: replace the model file's inertia of these links
      RShoulderYawLink: {mass: 0.57, com: [0.09, -0.01, 0.0], inertia: [ixx, iyy, izz, ixy, ixz, iyz]}
                                    # kg; the centre of mass in the link frame, m; the inertia
                                    # about it in the link's axes, kg m^2 (a URDF <inertial>
                                    # with rpy 0); for a file whose inertia is wrong

Every error names the file and the field.
"""

from __future__ import annotations

import math
import os
import site
import sys
import sysconfig
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from pydrake.math import RollPitchYaw

#: The groups every description has, in the order their joints are listed.
JOINT_GROUPS = ("left_leg", "right_leg", "torso", "head", "left_arm", "right_arm", "left_hand", "right_hand")
#: Gain groups (``gains``): the joint groups merged by kind, wrists apart.
GAIN_GROUPS = ("legs", "torso", "head", "arms", "wrists", "hands")
#: ``sole_offset``'s value that puts the sole at the foot's contact geometries' lowest point.
SOLE_AT_LOWEST_POINT = "lowest_point"
FOOT_SENSING = ("force_torque", "fsr", "none")
COLLISION_MESH_POLICIES = ("keep", "bounding_box")
SIDES = ("left", "right")
DEFAULT_CONTACT_SPHERE_RADIUS = 0.005  # m

_TOP_LEVEL = {
    "name",
    "model",
    "packages",
    "base_body",
    "imu_frame",
    "collision_meshes",
    "feet",
    "joint_groups",
    "shoulders",
    "standing_posture",
    "gains",
    "actuators",
    "joint_limits",
    "joint_damping",
    "link_inertias",
}
_FOOT_FIELDS = {
    "sole_frame",
    "sensing",
    "force_torque_joint",
    "contact_points",
    "contact_geometries",
    "contact_sphere_radius",
    "fsr_positions",
    "fsr_range",
    "remove_collisions",
    "sole_offset",
}


class RobotDescriptionError(ValueError):
    """A robot description that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class FootDescription:
    """One foot of a ``RobotDescription`` (see the module docstring's reference).

    Attributes:
        sole_frame: frame (or body) name at the sole's centre, x forward, z up (or, with
            ``sole_offset``, the frame the sole is offset from).
        sole_offset: (3,) the sole's position in ``sole_frame``'s axes, m,
            ``SOLE_AT_LOWEST_POINT`` (the contact geometries' lowest point, x and y their
            centres' mean), or None (the sole is ``sole_frame`` itself); the loader adds the
            sole as a frame there.
        sensing: one of FOOT_SENSING.
        force_torque_joint: the F/T weld joint's name (sensing force_torque), else None.
        contact_points: (4, 2) sole-frame (x, y) where spheres are added, m, or None.
        contact_geometry_body: the body of ``contact_geometry_names``, or None.
        contact_geometry_names: four existing collision geometries in FSR_ORDER, or (): the
            body's own four spheres (else its four geometries), ordered by their positions
            in the sole frame.
        contact_sphere_radius: m.
        fsr_positions: (4, 2) the FSRs' (x, y) in the sole frame, m, or None (default: the
            contact points, or the contact geometries' positions).
        remove_collisions: bodies whose collision geometries are dropped (URDF only).
        fsr_range: each FSR's upper range, N (sensing fsr), or None (Nao's 25 N,
            ``systems.observer.fsr_sensing.FSR_SATURATION``).
    """

    sole_frame: str
    sensing: str
    force_torque_joint: str | None
    contact_points: np.ndarray | None
    contact_geometry_body: str | None
    contact_geometry_names: tuple[str, ...]
    contact_sphere_radius: float
    fsr_positions: np.ndarray | None
    remove_collisions: tuple[str, ...]
    sole_offset: np.ndarray | str | None = None
    fsr_range: float | None = None


@dataclass(frozen=True)
class RobotDescription:
    """A robot description read from YAML (``load_robot_description``).

    Attributes:
        name: the model instance name.
        source: the YAML file (or None when built in code).
        model_file: the URDF/SDFormat file, resolved to a path.
        packages: package name -> folder for package:// URIs.
        base_body, imu_frame: names on the robot.
        collision_meshes: one of COLLISION_MESH_POLICIES.
        feet: ``left``/``right`` FootDescription.
        joint_groups: group -> joint names, the keys JOINT_GROUPS.
        shoulders: ``left``/``right`` body names, or {} (derived from the arms).
        standing_posture: joint -> angle, rad.
        gains: gain group -> (kp, kd), only the groups the file gives.
        rotor_inertia: gain group or joint name -> reflected rotor inertia for the
            actuators the loader adds, kg m^2 (a joint's entry wins over its group's).
        joint_limits: joint -> (lower, upper), rad.
        joint_damping: joint -> viscous damping, N m s/rad.
        link_inertias: link -> (mass kg, centre of mass in the link frame m, inertia about it
            in the link's axes [ixx, iyy, izz, ixy, ixz, iyz] kg m^2), replacing the model
            file's (``models.add_humanoid``).
    """

    name: str
    source: Path | None
    model_file: Path
    packages: dict = field(default_factory=dict)
    base_body: str = ""
    imu_frame: str = ""
    collision_meshes: str = "keep"
    feet: dict = field(default_factory=dict)
    joint_groups: dict = field(default_factory=dict)
    shoulders: dict = field(default_factory=dict)
    standing_posture: dict = field(default_factory=dict)
    gains: dict = field(default_factory=dict)
    rotor_inertia: dict = field(default_factory=dict)
    joint_limits: dict = field(default_factory=dict)
    joint_damping: dict = field(default_factory=dict)
    link_inertias: dict = field(default_factory=dict)

    def joint_names(self) -> tuple[str, ...]:
        """Every group's joints, in JOINT_GROUPS order."""
        return tuple(j for g in JOINT_GROUPS for j in self.joint_groups[g])

    def gain_group(self, joint: str) -> str:
        """The gain group (GAIN_GROUPS) of a joint."""
        for group in JOINT_GROUPS:
            if joint in self.joint_groups[group]:
                kind = group.split("_")[-1]
                kind = {"leg": "legs", "arm": "arms", "hand": "hands"}.get(kind, kind)
                return "wrists" if kind == "arms" and "WRIST" in joint.upper() else kind
        raise KeyError(joint)


def _error(where: str, message: str) -> RobotDescriptionError:
    return RobotDescriptionError(f"{where}: {message}")


def _string(value, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise _error(where, f"must be a non-empty string, got {value!r}")
    return value


def _number(value, where: str, *, positive: bool = False, non_negative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _error(where, f"must be a finite number, got {value!r}")
    if positive and not value > 0.0:
        raise _error(where, f"must be > 0, got {value!r}")
    if non_negative and value < 0.0:
        raise _error(where, f"must be >= 0, got {value!r}")
    return float(value)


def _points(value, where: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != 4:
        raise _error(where, f"must be four [x, y] pairs (front left, front right, rear left, rear right): {value!r}")
    return np.array([[_number(c, f"{where}[{i}]") for c in _pair(p, f"{where}[{i}]")] for i, p in enumerate(value)])


def _pair(value, where: str) -> list:
    if not isinstance(value, list) or len(value) != 2:
        raise _error(where, f"must be a pair [a, b], got {value!r}")
    return value


def _mapping(value, where: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _error(where, f"must be a mapping, got {type(value).__name__}")
    return value


def _unknown_keys(mapping: dict, allowed: set, where: str) -> None:
    unknown = sorted(set(mapping) - allowed)
    if unknown:
        raise _error(where, f"unknown field(s) {unknown}; allowed: {sorted(allowed)}")


def _foot(raw, where: str) -> FootDescription:
    raw = _mapping(raw, where)
    _unknown_keys(raw, _FOOT_FIELDS, where)
    if "sole_frame" not in raw:
        raise _error(f"{where}.sole_frame", "missing")
    sensing = raw.get("sensing", "none")
    if sensing not in FOOT_SENSING:
        raise _error(f"{where}.sensing", f"must be one of {FOOT_SENSING}, got {sensing!r}")
    ft_joint = raw.get("force_torque_joint")
    if sensing == "force_torque":
        ft_joint = _string(ft_joint, f"{where}.force_torque_joint (needed by sensing: force_torque)")
    elif ft_joint is not None:
        raise _error(f"{where}.force_torque_joint", f"given, but sensing is {sensing!r}, not 'force_torque'")
    points = raw.get("contact_points")
    geometries = raw.get("contact_geometries")
    if (points is None) == (geometries is None):
        raise _error(where, "needs exactly one of contact_points (spheres added) or contact_geometries (existing)")
    body, names = None, ()
    if points is not None:
        points = _points(points, f"{where}.contact_points")
    else:
        geometries = _mapping(geometries, f"{where}.contact_geometries")
        _unknown_keys(geometries, {"body", "names"}, f"{where}.contact_geometries")
        body = _string(geometries.get("body"), f"{where}.contact_geometries.body")
        names = geometries.get("names")
        if names is None:
            names = ()
        elif not isinstance(names, list) or len(names) != 4:
            raise _error(f"{where}.contact_geometries.names", f"must list four geometry names, got {names!r}")
        names = tuple(_string(n, f"{where}.contact_geometries.names") for n in names)
    fsr = raw.get("fsr_positions")
    offset = raw.get("sole_offset")
    if offset == SOLE_AT_LOWEST_POINT:
        if geometries is None:
            raise _error(f"{where}.sole_offset", f"{SOLE_AT_LOWEST_POINT} needs contact_geometries (the points)")
    elif offset is not None:
        if not isinstance(offset, list) or len(offset) != 3:
            raise _error(f"{where}.sole_offset", f"must be [x, y, z] in m or {SOLE_AT_LOWEST_POINT!r}, got {offset!r}")
        offset = np.array([_number(x, f"{where}.sole_offset") for x in offset])
    fsr_range = raw.get("fsr_range")
    if fsr_range is not None:
        if sensing != "fsr":
            raise _error(f"{where}.fsr_range", f"given, but sensing is {sensing!r}, not 'fsr'")
        fsr_range = _number(fsr_range, f"{where}.fsr_range", positive=True)
    remove = raw.get("remove_collisions", []) or []
    if not isinstance(remove, list):
        raise _error(f"{where}.remove_collisions", f"must be a list of body names, got {remove!r}")
    return FootDescription(
        sole_frame=_string(raw["sole_frame"], f"{where}.sole_frame"),
        sensing=sensing,
        force_torque_joint=ft_joint,
        contact_points=points,
        contact_geometry_body=body,
        contact_geometry_names=names,
        contact_sphere_radius=_number(
            raw.get("contact_sphere_radius", DEFAULT_CONTACT_SPHERE_RADIUS),
            f"{where}.contact_sphere_radius",
            positive=True,
        ),
        fsr_positions=None if fsr is None else _points(fsr, f"{where}.fsr_positions"),
        remove_collisions=tuple(_string(b, f"{where}.remove_collisions") for b in remove),
        sole_offset=offset,
        fsr_range=fsr_range,
    )


def load_robot_description(path: str | os.PathLike) -> RobotDescription:
    """Reads and checks a robot description YAML file (the module docstring's reference).

    Checks the file's own content: fields, types, the model file's existence and the
    packages' folders. Names on the robot (bodies, frames, joints) are checked when the
    robot is added to a plant (``models.add_humanoid``).

    Raises:
        RobotDescriptionError (a ValueError): an unreadable file, bad YAML, a missing or
            unknown field, a wrong type, a model file or package folder that does not exist;
            the message names the file and the field.
    """
    path = Path(path)
    where = str(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise RobotDescriptionError(f"cannot read the robot description '{path}': {error.strerror or error}") from error
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise RobotDescriptionError(f"{where}: not valid YAML: {error}") from error
    raw = _mapping(raw, where)
    _unknown_keys(raw, _TOP_LEVEL, where)
    for required in ("name", "model", "base_body", "imu_frame", "feet", "joint_groups", "standing_posture"):
        if required not in raw:
            raise _error(f"{where}: {required}", "missing (required)")
    folder = path.resolve().parent

    packages = {}
    for name, value in _mapping(raw.get("packages"), f"{where}: packages").items():
        package_dir = (folder / _string(value, f"{where}: packages.{name}")).resolve()
        if not package_dir.is_dir():
            raise _error(f"{where}: packages.{name}", f"folder '{package_dir}' does not exist")
        packages[str(name)] = package_dir
    model_file = resolve_model_uri(_string(raw["model"], f"{where}: model"), folder, packages, f"{where}: model")

    policy = raw.get("collision_meshes", "keep")
    if policy not in COLLISION_MESH_POLICIES:
        raise _error(f"{where}: collision_meshes", f"must be one of {COLLISION_MESH_POLICIES}, got {policy!r}")
    feet_raw = _mapping(raw["feet"], f"{where}: feet")
    _unknown_keys(feet_raw, set(SIDES), f"{where}: feet")
    for side in SIDES:
        if side not in feet_raw:
            raise _error(f"{where}: feet.{side}", "missing (both feet are needed)")
    feet = {side: _foot(feet_raw[side], f"{where}: feet.{side}") for side in SIDES}

    groups_raw = _mapping(raw["joint_groups"], f"{where}: joint_groups")
    _unknown_keys(groups_raw, set(JOINT_GROUPS), f"{where}: joint_groups")
    groups = {}
    for group in JOINT_GROUPS:
        joints = groups_raw.get(group, []) or []
        if not isinstance(joints, list):
            raise _error(f"{where}: joint_groups.{group}", f"must be a list of joint names, got {joints!r}")
        groups[group] = tuple(_string(j, f"{where}: joint_groups.{group}") for j in joints)
    for group in ("left_leg", "right_leg", "left_arm", "right_arm"):
        if not groups[group]:
            raise _error(f"{where}: joint_groups.{group}", "must list the joints (it is empty)")
    seen = {}
    for group in JOINT_GROUPS:
        for j in groups[group]:
            if j in seen:
                raise _error(f"{where}: joint_groups.{group}", f"joint {j!r} is also in group {seen[j]!r}")
            seen[j] = group

    shoulders = _mapping(raw.get("shoulders"), f"{where}: shoulders")
    _unknown_keys(shoulders, set(SIDES), f"{where}: shoulders")
    posture = {
        str(j): _number(a, f"{where}: standing_posture.{j}")
        for j, a in _mapping(raw["standing_posture"], f"{where}: standing_posture").items()
    }
    for j in posture:
        if j not in seen:
            raise _error(f"{where}: standing_posture.{j}", "is in no joint group")
    gains = {}
    for group, value in _mapping(raw.get("gains"), f"{where}: gains").items():
        if group not in GAIN_GROUPS:
            raise _error(f"{where}: gains.{group}", f"unknown gain group; valid: {GAIN_GROUPS}")
        kp, kd = _pair(value, f"{where}: gains.{group}")
        gains[group] = (
            _number(kp, f"{where}: gains.{group}[0] (kp)", positive=True),
            _number(kd, f"{where}: gains.{group}[1] (kd)", non_negative=True),
        )
    actuators = _mapping(raw.get("actuators"), f"{where}: actuators")
    _unknown_keys(actuators, {"rotor_inertia"}, f"{where}: actuators")
    rotor = {}
    for key, value in _mapping(actuators.get("rotor_inertia"), f"{where}: actuators.rotor_inertia").items():
        # A gain group, or a joint name (checked against the robot's joints by the loader).
        rotor[str(key)] = _number(value, f"{where}: actuators.rotor_inertia.{key}", non_negative=True)
    limits = {}
    for j, value in _mapping(raw.get("joint_limits"), f"{where}: joint_limits").items():
        lower, upper = _pair(value, f"{where}: joint_limits.{j}")
        lower, upper = _number(lower, f"{where}: joint_limits.{j}"), _number(upper, f"{where}: joint_limits.{j}")
        if not lower < upper:
            raise _error(f"{where}: joint_limits.{j}", f"lower {lower} must be < upper {upper}")
        limits[str(j)] = (lower, upper)
    damping = {
        str(j): _number(b, f"{where}: joint_damping.{j}", non_negative=True)
        for j, b in _mapping(raw.get("joint_damping"), f"{where}: joint_damping").items()
    }
    inertias = {
        str(link): _link_inertia(value, f"{where}: link_inertias.{link}")
        for link, value in _mapping(raw.get("link_inertias"), f"{where}: link_inertias").items()
    }
    return RobotDescription(
        name=_string(raw["name"], f"{where}: name"),
        source=path.resolve(),
        model_file=model_file,
        packages=packages,
        base_body=_string(raw["base_body"], f"{where}: base_body"),
        imu_frame=_string(raw["imu_frame"], f"{where}: imu_frame"),
        collision_meshes=policy,
        feet=feet,
        joint_groups=groups,
        shoulders={s: _string(b, f"{where}: shoulders.{s}") for s, b in shoulders.items()},
        standing_posture=posture,
        gains=gains,
        rotor_inertia=rotor,
        joint_limits=limits,
        joint_damping=damping,
        link_inertias=inertias,
    )


def _link_inertia(value, where: str) -> tuple[float, tuple[float, ...], tuple[float, ...]]:
    """(mass, com, inertia) of a ``link_inertias`` entry; physical validity (positive
    definite, triangle inequality) is checked when the robot is loaded."""
    entry = _mapping(value, where)
    _unknown_keys(entry, {"mass", "com", "inertia"}, where)
    for key in ("mass", "com", "inertia"):
        if key not in entry:
            raise _error(f"{where}.{key}", "missing (required)")
    mass = _number(entry["mass"], f"{where}.mass", positive=True)
    com, inertia = entry["com"], entry["inertia"]
    if not isinstance(com, list) or len(com) != 3:
        raise _error(f"{where}.com", f"must be [x, y, z] in m, got {com!r}")
    if not isinstance(inertia, list) or len(inertia) != 6:
        raise _error(f"{where}.inertia", f"must be [ixx, iyy, izz, ixy, ixz, iyz] in kg m^2, got {inertia!r}")
    return (
        mass,
        tuple(_number(c, f"{where}.com") for c in com),
        tuple(_number(i, f"{where}.inertia") for i in inertia),
    )


# ---------------------------------------------------------------------------------------
# package:// URIs.
# ---------------------------------------------------------------------------------------


def package_search_folders() -> list[Path]:
    """Where a package not listed in ``packages`` is looked for, in order: each entry of
    ROS_PACKAGE_PATH (the package is a sub-folder, or the entry itself), each
    AMENT_PREFIX_PATH prefix's share/, and the share/ folders of installed cmeel Python
    packages (e.g. ``example-robot-data`` from PyPI: site-packages/cmeel.prefix/share)."""
    folders = [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    folders += [Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    site_dirs = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"], *site.getsitepackages()]
    for directory in dict.fromkeys(site_dirs):
        folders.append(Path(directory) / "cmeel.prefix" / "share")
    folders.append(Path(sys.prefix) / "share")
    return folders


def find_package(name: str, packages: dict) -> Path | None:
    """The folder of package ``name``: ``packages[name]``, else the first of
    ``package_search_folders()`` that holds it; None if none does."""
    if name in packages:
        return Path(packages[name])
    for folder in package_search_folders():
        if folder.name == name and folder.is_dir():
            return folder
        if (folder / name).is_dir():
            return folder / name
    return None


def resolve_model_uri(uri: str, folder: Path, packages: dict, where: str) -> Path:
    """A model (or mesh) reference as a path: ``package://name/rest`` through ``find_package``,
    ``file://`` and plain paths relative to ``folder``.

    Raises:
        RobotDescriptionError: an unknown package or a file that does not exist.
    """
    if uri.startswith("package://"):
        name, _, rest = uri[len("package://") :].partition("/")
        root = find_package(name, packages)
        if root is None:
            raise _error(
                where,
                f"package {name!r} of {uri!r} not found: list it under 'packages:', set ROS_PACKAGE_PATH, "
                f"or install the Python package that ships it (e.g. pip install {name})",
            )
        path = root / rest
    else:
        path = Path(uri[len("file://") :] if uri.startswith("file://") else uri)
        path = path if path.is_absolute() else folder / path
    if not path.is_file():
        raise _error(where, f"file '{path}' ({uri}) does not exist")
    return path.resolve()


# ---------------------------------------------------------------------------------------
# URDF preparation: collision meshes Drake cannot use, collisions removed.
# ---------------------------------------------------------------------------------------

#: Mesh formats Drake uses for contact (its convex hull); others need ``bounding_box``.
DRAKE_CONTACT_MESH_SUFFIXES = (".obj", ".vtk", ".gltf")


def mesh_vertices(path: Path) -> np.ndarray:
    """(V, 3) vertices of an STL (binary or ASCII), OBJ or COLLADA (.dae, its scene's node
    transforms and unit applied) mesh file, in its own units.

    Raises:
        RobotDescriptionError: another format, or a file that cannot be read.
    """
    suffix = path.suffix.lower()
    try:
        data = path.read_bytes()
    except OSError as error:
        raise RobotDescriptionError(f"cannot read the mesh '{path}': {error.strerror or error}") from error
    if suffix == ".stl":
        if len(data) >= 84:
            count = int(np.frombuffer(data[80:84], dtype="<u4")[0])
            if 84 + 50 * count == len(data):
                record = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
                return np.frombuffer(data, dtype=record, count=count, offset=84)["v"].reshape(-1, 3).astype(float)
        text = data.decode("ascii", errors="replace").split()
        vertices = [text[i + 1 : i + 4] for i, word in enumerate(text) if word == "vertex"]
        if vertices:
            return np.array(vertices, dtype=float)
    elif suffix == ".obj":
        lines = data.decode("utf-8", errors="replace").splitlines()
        vertices = [line.split()[1:4] for line in lines if line.startswith("v ")]
        if vertices:
            return np.array(vertices, dtype=float)
    elif suffix == ".dae":  # COLLADA through coal (assimp), which pin ships: node transforms and units applied
        import coal

        try:
            vertices = np.asarray(coal.MeshLoader().load(str(path), np.ones(3)).vertices(), dtype=float)
        except Exception as error:  # coal raises ValueError or RuntimeError with assimp's message
            raise RobotDescriptionError(f"cannot read the mesh '{path}': {error}") from error
        if len(vertices):
            return vertices
    raise RobotDescriptionError(
        f"cannot take a bounding box of the mesh '{path}': only STL, OBJ and DAE files are read (replace it with "
        "a primitive, or an .obj, in the URDF)"
    )


def _model_xml(description: RobotDescription, kind: str):
    """(the model file's XML root, its path, the error prefix) of ``description``.

    Raises:
        RobotDescriptionError: the file cannot be read or is not XML (``kind`` names it).
    """
    import xml.etree.ElementTree as ET

    path = description.model_file
    where = f"{description.source or path}: model"
    try:
        return ET.fromstring(path.read_text()), path, where
    except (OSError, ET.ParseError) as error:
        raise _error(where, f"cannot read {kind}'{path}': {error}") from error


def collision_mesh_files(description: RobotDescription) -> list[Path]:
    """The mesh files the description's model uses for collision (URDF ``<collision>``'s
    ``<mesh filename>``, SDFormat's ``<mesh><uri>``), resolved to paths, sorted, each once:
    with the model file, what the simulated robot's contact geometry is read from.

    Raises:
        RobotDescriptionError: a model that is not XML, an unknown package, a missing mesh.
    """
    root, path, where = _model_xml(description, "")
    uris = set()
    for collision in root.iter("collision"):
        for mesh in collision.iter("mesh"):
            uri = mesh.get("filename") or mesh.findtext("uri") or ""
            if uri.strip():
                uris.add(uri.strip())
    return sorted({resolve_model_uri(uri, path.parent, description.packages, where) for uri in uris})


def prepare_urdf(description: RobotDescription) -> str:
    """The description's URDF text, ready for Drake's parser: mesh file names made absolute
    (package:// URIs resolved), the ``remove_collisions`` bodies' collision elements dropped,
    ``<mimic>`` removed from fixed joints (a reduced model's leftovers, which Drake refuses),
    ``<dynamics friction>`` dropped (MultibodyPlant does not simulate Coulomb joint friction and
    warns once per joint; the realistic world's friction is ``Imperfections.friction``),
    and with ``collision_meshes: bounding_box`` every collision mesh Drake cannot use for
    contact replaced by its axis-aligned bounding box in the mesh's frame (scale applied).

    Raises:
        RobotDescriptionError: unreadable or invalid URDF, a missing mesh, a removed body
            that is not a link.
    """
    import xml.etree.ElementTree as ET

    root, path, where = _model_xml(description, "the URDF ")
    links = {link.get("name"): link for link in root.iter("link")}
    for joint in root.iter("joint"):
        if joint.get("type") == "fixed":  # a reduced model's fixed joints keep <mimic>, which Drake refuses
            for mimic in joint.findall("mimic"):
                joint.remove(mimic)
        for dynamics in joint.findall("dynamics"):  # Coulomb friction: MultibodyPlant ignores it, with a warning
            dynamics.attrib.pop("friction", None)
    for side, foot in description.feet.items():
        for body in foot.remove_collisions:
            if body not in links:
                raise _error(
                    f"{description.source}: feet.{side}.remove_collisions",
                    f"{body!r} is not a link of '{path.name}'",
                )
            for collision in links[body].findall("collision"):
                links[body].remove(collision)
    for link in links.values():
        for kind in ("visual", "collision"):
            for element in link.findall(kind):
                mesh = element.find("geometry/mesh")
                if mesh is None:
                    continue
                file = resolve_model_uri(mesh.get("filename", ""), path.parent, description.packages, where)
                mesh.set("filename", file.as_uri())
                if (
                    kind == "collision"
                    and description.collision_meshes == "bounding_box"
                    and file.suffix.lower() not in DRAKE_CONTACT_MESH_SUFFIXES
                ):
                    scale = np.array([float(s) for s in (mesh.get("scale") or "1 1 1").split()])
                    vertices = mesh_vertices(file) * scale
                    low, high = vertices.min(axis=0), vertices.max(axis=0)
                    origin = element.find("origin")
                    if origin is None:
                        origin = ET.SubElement(element, "origin")
                    xyz = np.array([float(s) for s in (origin.get("xyz") or "0 0 0").split()])
                    rpy = np.array([float(s) for s in (origin.get("rpy") or "0 0 0").split()])
                    center = xyz + RollPitchYaw(rpy).ToRotationMatrix().matrix() @ (0.5 * (low + high))
                    origin.set("xyz", " ".join(f"{c:.9g}" for c in center))
                    geometry = element.find("geometry")
                    geometry.remove(mesh)
                    size = np.maximum(high - low, 1e-4)
                    ET.SubElement(geometry, "box", size=" ".join(f"{s:.9g}" for s in size))
    return ET.tostring(root, encoding="unicode")


__all__ = [
    "COLLISION_MESH_POLICIES",
    "FOOT_SENSING",
    "GAIN_GROUPS",
    "SOLE_AT_LOWEST_POINT",
    "JOINT_GROUPS",
    "FootDescription",
    "RobotDescription",
    "RobotDescriptionError",
    "collision_mesh_files",
    "find_package",
    "load_robot_description",
    "mesh_vertices",
    "prepare_urdf",
    "resolve_model_uri",
]
