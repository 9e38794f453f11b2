"""A humanoid's recorded sensor log as numpy arrays (``RobotLog``), read from and written to
CSV, Parquet, MCAP, ROS 1 bags and ROS 2 bag folders (``read_log``, ``write_log``, by the
path's extension).

Quantities and frames (SI units throughout):

* ``time`` (N,): s, strictly increasing (the joint-state stamps for ROS logs).
* ``joint_positions``, ``joint_velocities`` (N, n): rad and rad/s (m, m/s for prismatic
  joints), in the order of ``joint_names`` (any order; the estimators map them to the plant).
* ``joint_torques`` (N, n), optional: the measured motor torques, N m, without friction
  compensation (None: not logged; the residuals that need them are then not estimated).
* ``base_pose`` (N, 7), optional: the floating base's pose in the world, Drake's q order
  [qw, qx, qy, qz, x, y, z]: the unit quaternion of R_WB and p_WBo, m.
* ``base_velocity`` (N, 6), optional: Drake's floating-base v, [w_WB; v_WBo], the base's
  angular velocity and its origin's velocity, BOTH expressed in the WORLD frame, rad/s, m/s.
  (A nav_msgs/Odometry twist is expressed in its child frame, the base: ``read_log``
  rotates it to the world with the same message's orientation, ``write_log`` back.)
* ``wrenches``: per F/T sensor frame name, (N, 6) [tx, ty, tz, fx, fy, fz]: the wrench the
  environment (the ground, below the sensor) applies to the robot, moment about the sensor
  frame's origin, N m, and force, N, both expressed in the SENSOR frame (as a 6-axis
  sensor and a geometry_msgs/WrenchStamped with that ``frame_id`` report it).
* ``normal_forces``: per foot force-sensor frame logging only its normal force (the
  estimators take the robot's F/T frame names or its sole frames' names), (N,) fz, N: the
  force of the environment on the robot along the SENSOR frame's z axis (the sole's
  normal; a load cell or a 1-axis foot sensor). A frame is in ``wrenches`` or in
  ``normal_forces``, not both.
* ``fsr_forces`` (N, k), optional, with ``fsr_names``: foot force-sensing resistors, N
  (pressing force, >= 0). A name ``<side>_<anything>`` (side ``left`` or ``right``, as
  ``systems.observer.fsr_sensing.FSR_NAMES``) belongs to that foot.
* ``imu_angular_velocity``, ``imu_linear_acceleration`` (N, 3), optional: gyro, rad/s, and
  proper acceleration (+9.81 up at rest), m/s^2, both in the IMU frame.

Table layout (``.csv``, ``.parquet``), one row per sample, float64 columns:

    time
    q_<joint>, v_<joint>                                 one of each per joint
    tau_<joint>                                          one per joint (all, or none)
    base_qw base_qx base_qy base_qz base_x base_y base_z  (all seven, or none)
    base_wx base_wy base_wz base_vx base_vy base_vz        (all six, or none)
    wrench_<frame>_tx _ty _tz _fx _fy _fz                  per F/T frame (all six) ...
    wrench_<frame>_fz                                      ... or its normal force only
    fsr_<name>                                             per FSR
    imu_wx imu_wy imu_wz, imu_ax imu_ay imu_az             (each triple all or none)

Any other column is an error (it names it), so that a misspelt column is not silently
dropped.

ROS messages (``.bag``: ROS 1; a folder with ``metadata.yaml``: ROS 2, sqlite3 or mcap
storage; ``.mcap``: a single ROS 2 MCAP file), by role, topic names from ``topics`` (a
mapping or a YAML file with the keys of ``DEFAULT_TOPICS``; missing keys keep the defaults)::

    joint_states: sensor_msgs/JointState (name, position, velocity[, effort]) required
                  (effort empty in every message: no joint torques; in some only: refused)
    odometry:     nav_msgs/Odometry (pose in world, twist in the base frame)  optional
    imu:          sensor_msgs/Imu (angular_velocity, linear_acceleration)     optional
    wrenches:     {frame name: topic} of geometry_msgs/WrenchStamped           optional
                  (default: every WrenchStamped topic, named by its header.frame_id)

Stamps are the messages' header stamps. Topics of other rates (or phases) are linearly
interpolated to the joint-state stamps (quaternions: normalised linear interpolation along
the shorter arc); joint-state samples outside another topic's time span are dropped, not
extrapolated, and a gap inside it (a step longer than ``MAX_TOPIC_GAP_PERIODS`` = 5 of
that topic's median periods) is refused naming the topic and the time, not interpolated
across. FSR forces and normal-force-only feet have no standard ROS message and are read
from tables only.

Reading needs ``pyarrow`` (tables), ``rosbags`` (bags; its typestores also serialise the
messages written to MCAP) and ``mcap`` + ``mcap-ros2-support`` (MCAP).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

__all__ = [
    "DEFAULT_TOPICS",
    "LogFormatError",
    "LOG_FORMATS",
    "MAX_TOPIC_GAP_PERIODS",
    "RobotLog",
    "StampTiming",
    "load_topics",
    "log_format",
    "read_log",
    "resample_uniform",
    "stamp_timing",
    "write_log",
]

#: The formats ``read_log``/``write_log`` know, by path: extension or ROS 2 bag folder.
LOG_FORMATS = ("csv", "parquet", "mcap", "ros1", "ros2")

#: Default topic per role (see the module docstring); ``wrenches`` None: every
#: geometry_msgs/WrenchStamped topic, named by its header.frame_id.
DEFAULT_TOPICS: dict = {
    "joint_states": "/joint_states",
    "odometry": "/odom",
    "imu": "/imu/data",
    "wrenches": None,
}

_JOINT_STATE = "sensor_msgs/msg/JointState"
_ODOMETRY = "nav_msgs/msg/Odometry"
_IMU = "sensor_msgs/msg/Imu"
_WRENCH = "geometry_msgs/msg/WrenchStamped"
_BASE_POSE_COLUMNS = ("base_qw", "base_qx", "base_qy", "base_qz", "base_x", "base_y", "base_z")
_BASE_VELOCITY_COLUMNS = ("base_wx", "base_wy", "base_wz", "base_vx", "base_vy", "base_vz")
_WRENCH_AXES = ("tx", "ty", "tz", "fx", "fy", "fz")
_IMU_GYRO_COLUMNS = ("imu_wx", "imu_wy", "imu_wz")
_IMU_ACCEL_COLUMNS = ("imu_ax", "imu_ay", "imu_az")
#: A step between two messages of a topic other than the joint states longer than this
#: many of that topic's median periods, inside the joint states' time span, is a gap:
#: refused, never interpolated across (as the joint states' own gaps,
#: ``diagrams.residuals.log_estimation.MAX_GAP_PERIODS``).
MAX_TOPIC_GAP_PERIODS = 5.0


class LogFormatError(ValueError):
    """A log whose content does not fit the layout (the message names the problem)."""


@dataclass
class RobotLog:
    """A humanoid's sensor log: N samples of n joints (see the module docstring for the
    frames and units of each field). Checked on construction.

    Raises:
        ValueError: arrays of the wrong shape, NaN or inf in a sensor (naming the sensor,
            the channel and the first time), time not strictly increasing, duplicate
            joint names, a base quaternion that is not of unit norm, a frame with both a
            wrench and a normal force.
    """

    time: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    joint_velocities: np.ndarray
    joint_torques: np.ndarray | None = None
    base_pose: np.ndarray | None = None
    base_velocity: np.ndarray | None = None
    wrenches: dict[str, np.ndarray] = field(default_factory=dict)
    normal_forces: dict[str, np.ndarray] = field(default_factory=dict)
    fsr_names: tuple[str, ...] = ()
    fsr_forces: np.ndarray | None = None
    imu_angular_velocity: np.ndarray | None = None
    imu_linear_acceleration: np.ndarray | None = None

    def __post_init__(self):
        self.time = np.asarray(self.time, dtype=float).reshape(-1)
        self.joint_names = tuple(str(name) for name in self.joint_names)
        self.fsr_names = tuple(str(name) for name in self.fsr_names)
        N, n = self.time.size, len(self.joint_names)
        if N < 2:
            raise ValueError(f"RobotLog: need at least 2 samples, got {N}")
        if n == 0:
            raise ValueError("RobotLog: no joints")
        duplicates = sorted({name for name in self.joint_names if self.joint_names.count(name) > 1})
        if duplicates:
            raise ValueError(f"RobotLog: duplicate joint names {duplicates}")
        _check_channels("time", self.time[:, None], ("time",), self.time)
        steps = np.diff(self.time)
        if not np.all(steps > 0.0):
            k = int(np.flatnonzero(~(steps > 0.0))[0])
            raise ValueError(
                f"RobotLog: time is not strictly increasing at sample {k + 1} "
                f"(t = {float(self.time[k])!r} s, then {float(self.time[k + 1])!r} s)"
            )
        for name in ("joint_positions", "joint_velocities"):
            setattr(self, name, _checked(name, getattr(self, name), (N, n), self.joint_names, self.time))
        self.joint_torques = _checked_optional("joint_torques", self.joint_torques, (N, n), self.joint_names, self.time)
        self.base_pose = _checked_optional("base_pose", self.base_pose, (N, 7), _BASE_POSE_COLUMNS, self.time)
        if self.base_pose is not None:
            norms = np.linalg.norm(self.base_pose[:, :4], axis=1)
            bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
            if bad.size:
                raise ValueError(
                    f"RobotLog: base_pose's quaternion [qw, qx, qy, qz] has norm {norms[bad[0]]:.6g} at "
                    f"t = {float(self.time[bad[0]])!r} s (a unit quaternion is expected)"
                )
            off = np.abs(norms - 1.0) > 1e-12  # leaves the bits of an already normalised log alone
            self.base_pose[off, :4] /= norms[off, None]
        self.base_velocity = _checked_optional(
            "base_velocity", self.base_velocity, (N, 6), _BASE_VELOCITY_COLUMNS, self.time
        )
        self.wrenches = {
            str(frame): _checked(f"wrenches[{frame!r}]", w, (N, 6), _WRENCH_AXES, self.time)
            for frame, w in dict(self.wrenches).items()
        }
        self.normal_forces = {
            str(frame): _checked(f"normal_forces[{frame!r}]", np.reshape(f, (-1, 1)), (N, 1), ("fz",), self.time)[:, 0]
            for frame, f in dict(self.normal_forces).items()
        }
        both = sorted(set(self.wrenches) & set(self.normal_forces))
        if both:
            raise ValueError(f"RobotLog: the frames {both} have both a wrench and a normal force (one or the other)")
        if (self.fsr_forces is None) != (len(self.fsr_names) == 0):
            raise ValueError("RobotLog: fsr_forces and fsr_names go together (both given or neither)")
        self.fsr_forces = _checked_optional(
            "fsr_forces", self.fsr_forces, (N, len(self.fsr_names)), self.fsr_names, self.time
        )
        self.imu_angular_velocity = _checked_optional(
            "imu_angular_velocity", self.imu_angular_velocity, (N, 3), _IMU_GYRO_COLUMNS, self.time
        )
        self.imu_linear_acceleration = _checked_optional(
            "imu_linear_acceleration", self.imu_linear_acceleration, (N, 3), _IMU_ACCEL_COLUMNS, self.time
        )

    @property
    def num_samples(self) -> int:
        return self.time.size

    @property
    def duration(self) -> float:
        """s, from the first sample to the last."""
        return float(self.time[-1] - self.time[0])

    def select(self, index) -> RobotLog:
        """The log at the samples ``index`` (a slice, boolean mask or indices)."""

        def take(x):
            return None if x is None else x[index]

        return replace(
            self,
            time=self.time[index],
            joint_positions=self.joint_positions[index],
            joint_velocities=self.joint_velocities[index],
            joint_torques=take(self.joint_torques),
            base_pose=take(self.base_pose),
            base_velocity=take(self.base_velocity),
            wrenches={frame: w[index] for frame, w in self.wrenches.items()},
            normal_forces={frame: f[index] for frame, f in self.normal_forces.items()},
            fsr_forces=take(self.fsr_forces),
            imu_angular_velocity=take(self.imu_angular_velocity),
            imu_linear_acceleration=take(self.imu_linear_acceleration),
        )


def _checked(name: str, array, shape: tuple[int, int], channels: Sequence[str], time: np.ndarray) -> np.ndarray:
    try:
        array = np.array(array, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"RobotLog: {name} is not numeric ({error})") from None
    if array.shape != shape:
        raise ValueError(f"RobotLog: {name} must have shape {shape}, got {array.shape}")
    _check_channels(name, array, channels, time)
    return array


def _checked_optional(name, array, shape, channels, time) -> np.ndarray | None:
    return None if array is None else _checked(name, array, shape, channels, time)


def _check_channels(name: str, array: np.ndarray, channels: Sequence[str], time: np.ndarray) -> None:
    finite = np.isfinite(array)
    if not finite.all():
        k, c = (int(i) for i in np.argwhere(~finite)[0])
        what = "NaN" if np.isnan(array[k, c]) else "inf"
        raise ValueError(
            f"RobotLog: {what} in {name} (channel {channels[c]!r}) at sample {k} (t = {float(time[k])!r} s)"
        )


#: Stamp noise (rows evenly spaced, stamps noisy) when the deviations of the stamps from
#: the straight line fitted to stamp vs row index are small: each within this fraction of
#: the fitted period ...
STAMP_NOISE_MAX_DEVIATION = 0.25
#: ... zero-mean along the log: on each block of ``STAMP_BLOCK_ROWS`` consecutive rows
#: their mean within this many standard errors (RMS / sqrt(rows)) of zero (a drifting rate
#: bends the stamps away from the line over many rows) ...
STAMP_MEAN_STANDARD_ERRORS = 5.0
#: ... and the period fitted on each block within this relative deviation of the whole
#: log's (a steady period).
STAMP_PERIOD_STEADINESS = 0.01
STAMP_BLOCK_ROWS = 100


@dataclass(frozen=True)
class StampTiming:
    """How a log's stamps are spaced (``stamp_timing``).

    Attributes:
        case: "uniform" (every step within the tolerance of the median step: used as is),
            "stamp noise" (evenly spaced rows with noisy stamps: the fitted uniform stamps
            are used, the data are not interpolated) or "uneven" (genuinely uneven
            sampling: resampled to the median step, ``resample_uniform``).
        period: s, the period the estimators run at: the median step ("uniform",
            "uneven") or the fitted one ("stamp noise").
        fitted_period: s, the slope of the least-squares line of stamp vs row index.
        jitter_rms: s, the RMS of the stamps' deviations from that line.
        max_deviation: s, the largest such deviation.
    """

    case: str
    period: float
    fitted_period: float
    jitter_rms: float
    max_deviation: float
    offset: float = 0.0

    def fitted_stamps(self, count: int) -> np.ndarray:
        """The fitted line's stamps of rows 0 .. count - 1, s."""
        return self.offset + self.fitted_period * np.arange(count)


def stamp_timing(time: np.ndarray, uniform_tolerance: float = 0.01) -> StampTiming:
    """Classifies the stamps ``time`` (s, strictly increasing): "uniform" when every step
    is within ``uniform_tolerance`` (relative) of the median step; else "stamp noise" when
    the rows are evenly spaced and only their stamps noisy (every stamp within
    ``STAMP_NOISE_MAX_DEVIATION`` periods of the straight line fitted to stamp vs row
    index; on blocks of ``STAMP_BLOCK_ROWS`` rows, the deviations' mean within
    ``STAMP_MEAN_STANDARD_ERRORS`` standard errors of zero and the fitted period within
    ``STAMP_PERIOD_STEADINESS`` of the whole log's); else "uneven"."""
    time = np.asarray(time, dtype=float)
    steps = np.diff(time)
    median = float(np.median(steps))
    rows = np.arange(time.size, dtype=float)
    centred = rows - rows.mean()
    fitted = float(centred @ (time - time.mean()) / (centred @ centred))
    offset = float(time.mean() - fitted * rows.mean())
    residuals = time - (offset + fitted * rows)
    rms, largest = float(np.sqrt(np.mean(residuals**2))), float(np.max(np.abs(residuals)))
    common = {"fitted_period": fitted, "jitter_rms": rms, "max_deviation": largest, "offset": offset}
    if np.max(np.abs(steps - median)) <= uniform_tolerance * median:
        return StampTiming("uniform", median, **common)
    steady = largest <= STAMP_NOISE_MAX_DEVIATION * fitted
    mean_bound = STAMP_MEAN_STANDARD_ERRORS * rms / math.sqrt(STAMP_BLOCK_ROWS)
    for start in range(0, time.size - STAMP_BLOCK_ROWS + 1, STAMP_BLOCK_ROWS):
        block = slice(start, start + STAMP_BLOCK_ROWS)
        slope = np.polyfit(rows[block], time[block], 1)[0]
        steady = steady and abs(slope - fitted) <= STAMP_PERIOD_STEADINESS * fitted
        steady = steady and abs(float(np.mean(residuals[block]))) <= mean_bound
    if steady:
        return StampTiming("stamp noise", fitted, **common)
    return StampTiming("uneven", median, **common)


def resample_uniform(log: RobotLog, period: float) -> RobotLog:
    """``log`` linearly interpolated to the times t_0 + k ``period`` within its span (the
    base quaternion by normalised linear interpolation). For an unevenly sampled log
    (``stamp_timing``): the residuals are discrete-time observers of a fixed period
    (eqs. 11, 16)."""
    period = float(period)
    if not (math.isfinite(period) and period > 0.0):
        raise ValueError(f"resample_uniform: period must be a positive number of seconds, got {period}")
    count = int(math.floor(log.duration / period + 1e-9)) + 1
    times = log.time[0] + period * np.arange(count)
    return _interpolated(log, times)


def _interpolated(log: RobotLog, times: np.ndarray) -> RobotLog:
    def lerp(x):
        return None if x is None else _interpolate(log.time, x, times)

    base_pose = None
    if log.base_pose is not None:
        base_pose = np.concatenate(
            (_interpolate_quaternions(log.time, log.base_pose[:, :4], times), lerp(log.base_pose[:, 4:])), axis=1
        )
    return replace(
        log,
        time=times,
        joint_positions=lerp(log.joint_positions),
        joint_velocities=lerp(log.joint_velocities),
        joint_torques=lerp(log.joint_torques),
        base_pose=base_pose,
        base_velocity=lerp(log.base_velocity),
        wrenches={frame: lerp(w) for frame, w in log.wrenches.items()},
        normal_forces={frame: lerp(f[:, None])[:, 0] for frame, f in log.normal_forces.items()},
        fsr_forces=lerp(log.fsr_forces),
        imu_angular_velocity=lerp(log.imu_angular_velocity),
        imu_linear_acceleration=lerp(log.imu_linear_acceleration),
    )


def _interpolate(t_source: np.ndarray, values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Columns of ``values`` (sampled at ``t_source``) linearly interpolated at ``t``."""
    if t_source.shape == t.shape and np.array_equal(t_source, t):
        return np.array(values, dtype=float)
    index = np.clip(np.searchsorted(t_source, t, side="right") - 1, 0, t_source.size - 2)
    weight = ((t - t_source[index]) / (t_source[index + 1] - t_source[index]))[:, None]
    return (1.0 - weight) * values[index] + weight * values[index + 1]


def _interpolate_quaternions(t_source: np.ndarray, quaternions: np.ndarray, t: np.ndarray) -> np.ndarray:
    q = np.array(quaternions, dtype=float)
    if t_source.shape == t.shape and np.array_equal(t_source, t):
        return q
    # One hemisphere along the sequence (q and -q are the same rotation).
    flips = np.cumprod(np.where(np.einsum("ij,ij->i", q[1:], q[:-1]) < 0.0, -1.0, 1.0))
    q[1:] *= flips[:, None]
    out = _interpolate(t_source, q, t)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of (N, 4) unit quaternions [w, x, y, z]."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), axis=-1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), axis=-1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), axis=-1),
        ),
        axis=-2,
    )


# ---------------------------------------------------------------------------------------
# Dispatch.
# ---------------------------------------------------------------------------------------


def log_format(path: str | Path) -> str:
    """One of ``LOG_FORMATS`` for ``path``: by extension (.csv, .parquet, .mcap, .bag), or
    "ros2" for a folder (a ROS 2 bag: metadata.yaml and its storage files).

    Raises:
        ValueError: an unknown extension.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    known = {".csv": "csv", ".parquet": "parquet", ".mcap": "mcap", ".bag": "ros1"}
    if suffix in known and not path.is_dir():
        return known[suffix]
    if path.is_dir() or suffix == "":
        return "ros2"
    raise ValueError(
        f"unknown log format {suffix!r} of '{path}': use .csv, .parquet, .mcap, .bag (ROS 1) or a ROS 2 bag folder"
    )


def read_log(path: str | Path, topics: Mapping | str | Path | None = None) -> RobotLog:
    """The ``RobotLog`` stored at ``path`` (format by ``log_format``). ``topics``: the ROS
    topic of each role (mapping or YAML file, see ``load_topics``); tables ignore it.

    Raises:
        ValueError: a missing or unreadable file, an unknown extension, a missing column or
            topic, NaN in a sensor, non-increasing time, a gap inside a ROS topic other than the
            joint states (``MAX_TOPIC_GAP_PERIODS``; each message names the problem).
    """
    path = Path(path)
    kind = log_format(path)
    if not path.exists():
        raise LogFormatError(f"log '{path}' does not exist")
    if kind == "ros2" and not (path / "metadata.yaml").is_file():
        raise ValueError(f"'{path}' is a folder without metadata.yaml: not a ROS 2 bag")
    if kind in ("csv", "parquet"):
        return _table_to_log(_read_table(path, kind), path)
    roles = load_topics(topics)
    if kind == "mcap":
        streams = _read_mcap(path, roles)
    else:
        streams = _read_bag(path, roles)
    return _streams_to_log(streams, roles, path)


def write_log(log: RobotLog, path: str | Path, topics: Mapping | str | Path | None = None) -> Path:
    """Writes ``log`` to ``path`` (format by ``log_format``; an existing file or bag is
    replaced). ROS formats use the topics of ``topics`` (default ``DEFAULT_TOPICS``; F/T
    frame F on ``/wrench/F`` unless mapped) and hold no FSR forces nor normal-force-only
    feet; without joint torques their JointState messages have an empty ``effort``.

    Raises:
        ValueError: an unknown extension; FSR forces or normal forces in a ROS format; wrench topics that
            do not name the log's F/T frames.
    """
    path = Path(path)
    kind = log_format(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind in ("csv", "parquet"):
        _write_table(_log_to_table(log), path, kind)
        return path
    if log.fsr_forces is not None:
        raise ValueError(f"write_log: FSR forces have no standard ROS message; write '{path.name}' as .csv or .parquet")
    if log.normal_forces:
        raise ValueError(
            f"write_log: normal-force-only feet {sorted(log.normal_forces)} have no standard ROS message; write "
            f"'{path.name}' as .csv or .parquet"
        )
    roles = load_topics(topics)
    wrench_topics = roles["wrenches"] or {frame: f"/wrench/{frame}" for frame in log.wrenches}
    missing = sorted(set(log.wrenches) - set(wrench_topics))
    if missing:
        raise ValueError(f"write_log: no wrench topic for the F/T frames {missing} (topics: {wrench_topics})")
    roles = {**roles, "wrenches": {frame: wrench_topics[frame] for frame in log.wrenches}}
    _remove(path)
    if kind == "mcap":
        _write_mcap(log, path, roles)
    else:
        _write_bag(log, path, roles, ros1=(kind == "ros1"))
    return path


def load_topics(topics: Mapping | str | Path | None) -> dict:
    """``DEFAULT_TOPICS`` updated with ``topics``: a mapping or a YAML file of role: topic
    (``wrenches``: a mapping frame name: topic).

    Raises:
        ValueError: an unreadable file, an unknown role, a topic that is not a string.
    """
    if topics is None:
        return dict(DEFAULT_TOPICS)
    if isinstance(topics, (str, Path)):
        from pydrake.common.yaml import yaml_load_file

        try:
            loaded = yaml_load_file(str(topics))
        except Exception as error:  # Drake raises RuntimeError with the YAML parser's message
            raise ValueError(f"cannot read the topics file '{topics}': {error}") from None
        if not isinstance(loaded, Mapping):
            raise ValueError(f"the topics file '{topics}' must hold a mapping of role: topic")
        topics = loaded
    unknown = sorted(set(topics) - set(DEFAULT_TOPICS))
    if unknown:
        raise ValueError(f"unknown topic roles {unknown}; the roles are {sorted(DEFAULT_TOPICS)}")
    roles = {**DEFAULT_TOPICS, **dict(topics)}
    for role in ("joint_states", "odometry", "imu"):
        if roles[role] is not None and not isinstance(roles[role], str):
            raise ValueError(f"topic of {role!r} must be a string, got {roles[role]!r}")
    if roles["wrenches"] is not None:
        if not isinstance(roles["wrenches"], Mapping) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in roles["wrenches"].items()
        ):
            raise ValueError("'wrenches' must map F/T frame names to topic names")
        roles["wrenches"] = dict(roles["wrenches"])
    return roles


def _remove(path: Path) -> None:
    import shutil

    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()


# ---------------------------------------------------------------------------------------
# Tables: CSV and Parquet.
# ---------------------------------------------------------------------------------------


def _log_to_table(log: RobotLog):
    import pyarrow as pa

    columns = {"time": log.time}
    for prefix, array in (("q", log.joint_positions), ("v", log.joint_velocities), ("tau", log.joint_torques)):
        if array is None:
            continue
        columns.update({f"{prefix}_{name}": array[:, i] for i, name in enumerate(log.joint_names)})
    groups = [(_BASE_POSE_COLUMNS, log.base_pose), (_BASE_VELOCITY_COLUMNS, log.base_velocity)]
    groups += [(tuple(f"wrench_{frame}_{a}" for a in _WRENCH_AXES), w) for frame, w in log.wrenches.items()]
    groups += [((f"wrench_{frame}_fz",), f[:, None]) for frame, f in log.normal_forces.items()]
    groups += [(tuple(f"fsr_{name}" for name in log.fsr_names), log.fsr_forces)]
    groups += [(_IMU_GYRO_COLUMNS, log.imu_angular_velocity), (_IMU_ACCEL_COLUMNS, log.imu_linear_acceleration)]
    for names, array in groups:
        if array is not None:
            columns.update({name: array[:, i] for i, name in enumerate(names)})
    return pa.table({name: pa.array(values, type=pa.float64()) for name, values in columns.items()})


def _write_table(table, path: Path, kind: str) -> None:
    if kind == "csv":
        import pyarrow.csv as csv

        csv.write_csv(table, str(path))
    else:
        import pyarrow.parquet as pq

        pq.write_table(table, str(path))


def _read_table(path: Path, kind: str):
    import pyarrow as pa

    try:
        if kind == "csv":
            import pyarrow.csv as csv

            table = csv.read_csv(str(path))
        else:
            import pyarrow.parquet as pq

            table = pq.read_table(str(path))
    except (OSError, pa.ArrowException) as error:
        raise ValueError(f"cannot read the {kind} log '{path}': {error}") from None
    return table


def _table_to_log(table, path: Path) -> RobotLog:
    import pyarrow as pa

    names = list(table.column_names)

    def column(name: str) -> np.ndarray:
        data = table.column(name)
        if not (pa.types.is_floating(data.type) or pa.types.is_integer(data.type)) and data.null_count < len(data):
            raise LogFormatError(f"log '{path}': column {name!r} is not numeric ({data.type})")
        return data.to_numpy(zero_copy_only=False).astype(float)  # nulls become NaN

    if "time" not in names:
        raise LogFormatError(f"log '{path}': no 'time' column (columns: {names[:8]}{' ...' if len(names) > 8 else ''})")
    joints = [name[2:] for name in names if name.startswith("q_")]
    if not joints:
        raise LogFormatError(f"log '{path}': no joint position column q_<joint>")
    used = {"time"}
    missing = []

    def group(columns: Sequence[str], required: bool = False) -> np.ndarray | None:
        present = [c for c in columns if c in names]
        if not present and not required:
            return None
        absent = [c for c in columns if c not in names]
        if absent:
            missing.extend(absent)
            return None
        used.update(columns)
        return np.stack([column(c) for c in columns], axis=1)

    arrays = {prefix: group([f"{prefix}_{joint}" for joint in joints], required=True) for prefix in ("q", "v")}
    arrays["tau"] = group([f"tau_{joint}" for joint in joints])  # all or none
    base_pose = group(_BASE_POSE_COLUMNS)
    base_velocity = group(_BASE_VELOCITY_COLUMNS)
    frames = []
    for name in names:
        if name.startswith("wrench_") and name.endswith("_fx"):
            frames.append(name[len("wrench_") : -len("_fx")])
    for name in names:
        if name.startswith("wrench_") and name[len("wrench_") : name.rfind("_")] not in frames:
            frames.append(name[len("wrench_") : name.rfind("_")])  # reported missing below

    # A frame with its fz column alone logs only its normal force; any other subset is incomplete.
    def frame_columns(frame: str) -> list[str]:
        return [n for n in names if n.startswith("wrench_") and n[len("wrench_") : n.rfind("_")] == frame]

    normal_only = [frame for frame in frames if frame_columns(frame) == [f"wrench_{frame}_fz"]]
    wrenches = {
        frame: group([f"wrench_{frame}_{a}" for a in _WRENCH_AXES], required=True)
        for frame in frames
        if frame not in normal_only
    }
    normal_forces = {frame: group([f"wrench_{frame}_fz"])[:, 0] for frame in normal_only}
    fsr_names = tuple(name[len("fsr_") :] for name in names if name.startswith("fsr_"))
    fsr = group([f"fsr_{n}" for n in fsr_names]) if fsr_names else None
    gyro, accel = group(_IMU_GYRO_COLUMNS), group(_IMU_ACCEL_COLUMNS)
    if missing:
        raise LogFormatError(f"log '{path}': missing column(s) {missing}")
    unknown = [name for name in names if name not in used]
    if unknown:
        raise LogFormatError(
            f"log '{path}': unknown column(s) {unknown} (see systems.io.robot_log for the layout: time, q_<joint>, "
            "v_<joint>, tau_<joint>, base_*, wrench_<frame>_*, fsr_<name>, imu_*)"
        )
    return RobotLog(
        time=column("time"),
        joint_names=tuple(joints),
        joint_positions=arrays["q"],
        joint_velocities=arrays["v"],
        joint_torques=arrays["tau"],
        base_pose=base_pose,
        base_velocity=base_velocity,
        wrenches={frame: w for frame, w in wrenches.items() if w is not None},
        normal_forces=normal_forces,
        fsr_names=fsr_names,
        fsr_forces=fsr,
        imu_angular_velocity=gyro,
        imu_linear_acceleration=accel,
    )


# ---------------------------------------------------------------------------------------
# ROS messages: one stream of (stamps, values) per role, then aligned to the joint states.
# ---------------------------------------------------------------------------------------


class _Stream:
    """Samples of one topic: stamps (s) and per-message value rows."""

    def __init__(self, topic: str):
        self.topic = topic
        self.stamps: list[float] = []
        self.rows: list[np.ndarray] = []
        self.names: tuple[str, ...] | None = None
        self.has_effort: bool | None = None  # JointState: whether its messages carry effort

    def arrays(self, path: Path) -> tuple[np.ndarray, np.ndarray]:
        """(stamps, rows) sorted by stamp.

        Raises:
            ValueError: two messages with the same stamp.
        """
        t = np.array(self.stamps)
        order = np.argsort(t, kind="stable")
        t = t[order]
        repeated = np.flatnonzero(np.diff(t) <= 0.0)
        if repeated.size:
            raise LogFormatError(
                f"log '{path}': topic {self.topic} has two messages stamped {float(t[repeated[0]])!r} s"
            )
        return t, np.array(self.rows, dtype=float)[order]


def _stamp(header) -> float:
    return int(header.stamp.sec) + int(header.stamp.nanosec) * 1e-9


def _xyz(v) -> tuple[float, float, float]:
    return (float(v.x), float(v.y), float(v.z))


def _add_message(streams: dict, key, msgtype: str, message, path: Path) -> None:
    """Appends one decoded message to its stream (``key``: role, or ("wrench", frame))."""
    stream = streams[key]
    if msgtype == _JOINT_STATE:
        names = tuple(message.name)
        if stream.names is None:
            stream.names = names
        elif names != stream.names:
            raise LogFormatError(f"log '{path}': {stream.topic} changes its joint names from {stream.names} to {names}")
        parts = [np.asarray(message.position, dtype=float)]
        for what in ("velocity", "effort"):
            values = np.asarray(getattr(message, what), dtype=float)
            if what == "effort" and values.size == 0:
                # No torques logged: every message of the topic must then have none.
                has_effort = False
            elif values.size != len(names):
                raise LogFormatError(
                    f"log '{path}': {stream.topic} has {values.size} {what} values for {len(names)} joints "
                    f"(the estimators need position and velocity, and effort for every joint or none)"
                )
            else:
                has_effort = True
            parts.append(values)
        if stream.has_effort is None:
            stream.has_effort = has_effort
        elif stream.has_effort != has_effort:
            raise LogFormatError(
                f"log '{path}': {stream.topic} has effort in some messages and none in others (at t = "
                f"{_stamp(message.header)!r} s): log the joint torques in every message or in none"
            )
        if parts[0].size != len(names):
            raise LogFormatError(f"log '{path}': {stream.topic} has {parts[0].size} positions for {len(names)} joints")
        row = np.concatenate(parts)
    elif msgtype == _ODOMETRY:
        pose, twist = message.pose.pose, message.twist.twist
        o = pose.orientation
        quaternion = np.array([o.w, o.x, o.y, o.z], dtype=float)
        R = quaternion_to_rotation(quaternion / np.linalg.norm(quaternion))
        # The twist is in the child (base) frame: to world, as Drake's floating-base v.
        row = np.concatenate(
            (quaternion, _xyz(pose.position), R @ np.array(_xyz(twist.angular)), R @ np.array(_xyz(twist.linear)))
        )
    elif msgtype == _IMU:
        row = np.array(_xyz(message.angular_velocity) + _xyz(message.linear_acceleration))
    elif msgtype == _WRENCH:
        w = message.wrench
        row = np.array(_xyz(w.torque) + _xyz(w.force))
        if stream.names is None:
            stream.names = (str(message.header.frame_id),)
    else:
        raise LogFormatError(f"log '{path}': topic {stream.topic} has type {msgtype}, not one the estimators read")
    stream.stamps.append(_stamp(message.header))
    stream.rows.append(row)


def _normalised_type(msgtype: str) -> str:
    """'sensor_msgs/JointState' (ROS 1, MCAP schemas) -> 'sensor_msgs/msg/JointState'."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[-1]}" if len(parts) == 2 else msgtype


def _select_topics(available: dict[str, str], roles: dict, path: Path) -> dict:
    """{topic: key} of the topics to read; ``available``: {topic: message type}."""
    wanted = {}
    joint_topic = roles["joint_states"]
    if joint_topic not in available:
        raise LogFormatError(
            f"log '{path}': no joint-state topic {joint_topic!r} (topics: {sorted(available)}); name it in the "
            "topics YAML (joint_states: TOPIC)"
        )
    expected = {"joint_states": _JOINT_STATE, "odometry": _ODOMETRY, "imu": _IMU}
    for role, msgtype in expected.items():
        topic = roles[role]
        if topic in available:
            if available[topic] != msgtype:
                raise LogFormatError(f"log '{path}': topic {topic} ({role}) has type {available[topic]}, not {msgtype}")
            wanted[topic] = role
    if roles["wrenches"] is None:
        wanted.update({t: ("wrench", None, t) for t, kind in available.items() if kind == _WRENCH})
    else:
        for frame, topic in roles["wrenches"].items():
            if topic not in available:
                raise LogFormatError(f"log '{path}': no wrench topic {topic!r} for F/T frame {frame!r}")
            if available[topic] != _WRENCH:
                raise LogFormatError(f"log '{path}': topic {topic} has type {available[topic]}, not {_WRENCH}")
            wanted[topic] = ("wrench", frame, topic)
    return wanted


def _read_bag(path: Path, roles: dict) -> dict:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.ROS2_HUMBLE)
    try:
        with AnyReader([path], default_typestore=store) as reader:
            available = {c.topic: _normalised_type(c.msgtype) for c in reader.connections}
            wanted = _select_topics(available, roles, path)
            streams = {key: _Stream(topic) for topic, key in wanted.items()}
            connections = [c for c in reader.connections if c.topic in wanted]
            for connection, _, raw in reader.messages(connections=connections):
                message = reader.deserialize(raw, connection.msgtype)
                _add_message(streams, wanted[connection.topic], available[connection.topic], message, path)
    except LogFormatError:
        raise
    except Exception as error:  # rosbags' own errors: a damaged or foreign file
        raise ValueError(f"cannot read the bag '{path}': {type(error).__name__}: {error}") from None
    return streams


def _read_mcap(path: Path, roles: dict) -> dict:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    try:
        with open(path, "rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            if summary is None:
                raise LogFormatError(
                    f"cannot read the MCAP file '{path}': no summary section (an unfinished recording?)"
                )
            available = {
                channel.topic: _normalised_type(summary.schemas[channel.schema_id].name)
                for channel in summary.channels.values()
            }
            wanted = _select_topics(available, roles, path)
            streams = {key: _Stream(topic) for topic, key in wanted.items()}
            for _, channel, _, message in reader.iter_decoded_messages(topics=list(wanted)):
                _add_message(streams, wanted[channel.topic], available[channel.topic], message, path)
    except LogFormatError:
        raise
    except Exception as error:  # mcap's own errors: a damaged or foreign file
        raise ValueError(f"cannot read the MCAP file '{path}': {type(error).__name__}: {error}") from None
    return streams


def _check_topic_gaps(topic: str, stamps: np.ndarray, t: np.ndarray, path: Path) -> None:
    """Raises LogFormatError naming ``topic`` and the time of its first step between two
    messages (``stamps``, s) longer than ``MAX_TOPIC_GAP_PERIODS`` of its median periods
    across which a joint-state stamp of ``t`` would be interpolated."""
    steps = np.diff(stamps)
    period = float(np.median(steps))
    inside = np.searchsorted(t, stamps[1:], side="left") - np.searchsorted(t, stamps[:-1], side="right")
    gaps = np.flatnonzero((steps > MAX_TOPIC_GAP_PERIODS * period) & (inside > 0))
    if gaps.size:
        k = int(gaps[0])
        raise LogFormatError(
            f"log '{path}': topic {topic} has a gap of {steps[k]:.6g} s after t = {stamps[k]:.6g} s "
            f"({gaps.size} gap(s) longer than {MAX_TOPIC_GAP_PERIODS:g} times its median period of {period:.6g} s) "
            "inside the joint states' time span: its values cannot be interpolated across it; split the log into "
            "its segments"
        )


def _streams_to_log(streams: dict, roles: dict, path: Path) -> RobotLog:
    joints = streams["joint_states"]
    if not joints.stamps:
        raise LogFormatError(f"log '{path}': the joint-state topic {joints.topic} holds no message")
    t, rows = joints.arrays(path)
    n = len(joints.names)
    others = {}
    for key, stream in streams.items():
        if key == "joint_states":
            continue
        if len(stream.stamps) < 2:
            raise LogFormatError(f"log '{path}': topic {stream.topic} holds {len(stream.stamps)} message(s), need 2")
        others[key] = stream.arrays(path)
    # Keep the joint-state stamps inside every other topic's span (no extrapolation).
    keep = np.ones(t.size, dtype=bool)
    for stamps, _ in others.values():
        keep &= (t >= stamps[0] - 1e-9) & (t <= stamps[-1] + 1e-9)
    if keep.sum() < 2:
        raise LogFormatError(f"log '{path}': the topics' time spans do not overlap")
    t, rows = t[keep], rows[keep]
    for key, (stamps, _) in others.items():
        _check_topic_gaps(streams[key].topic, stamps, t, path)

    def aligned(key, columns=slice(None)):
        stamps, values = others[key]
        return _interpolate(stamps, values[:, columns], np.clip(t, stamps[0], stamps[-1]))

    base_pose = base_velocity = gyro = accel = None
    if "odometry" in others:
        stamps, values = others["odometry"]
        quaternion = _interpolate_quaternions(stamps, values[:, :4], np.clip(t, stamps[0], stamps[-1]))
        base_pose = np.concatenate((quaternion, aligned("odometry", slice(4, 7))), axis=1)
        base_velocity = aligned("odometry", slice(7, 13))
    if "imu" in others:
        gyro, accel = aligned("imu", slice(0, 3)), aligned("imu", slice(3, 6))
    wrenches = {}
    for key, stream in streams.items():
        if isinstance(key, tuple):
            frame = key[1] if key[1] is not None else stream.names[0]
            if not frame:
                raise LogFormatError(
                    f"log '{path}': wrench topic {stream.topic} has no header.frame_id: name its F/T frame in the "
                    "topics YAML (wrenches: {FRAME: TOPIC})"
                )
            if frame in wrenches:
                raise LogFormatError(f"log '{path}': two wrench topics for the F/T frame {frame!r}")
            wrenches[frame] = aligned(key)
    return RobotLog(
        time=t,
        joint_names=joints.names,
        joint_positions=rows[:, :n],
        joint_velocities=rows[:, n : 2 * n],
        joint_torques=rows[:, 2 * n :] if joints.has_effort else None,
        base_pose=base_pose,
        base_velocity=base_velocity,
        wrenches=wrenches,
        imu_angular_velocity=gyro,
        imu_linear_acceleration=accel,
    )


def _messages(log: RobotLog, roles: dict, store, ros1: bool):
    """(topic, message type, stamp ns, message) of every message of ``log``, time-ordered."""
    types = store.types
    Time, Header = types["builtin_interfaces/msg/Time"], types["std_msgs/msg/Header"]
    Vector3, Point, Quaternion = (
        types["geometry_msgs/msg/Vector3"],
        types["geometry_msgs/msg/Point"],
        types["geometry_msgs/msg/Quaternion"],
    )
    nanoseconds = np.round(log.time * 1e9).astype(np.int64)

    def header(k: int, frame: str):
        stamp = Time(sec=int(nanoseconds[k] // 1_000_000_000), nanosec=int(nanoseconds[k] % 1_000_000_000))
        return Header(seq=k, stamp=stamp, frame_id=frame) if ros1 else Header(stamp=stamp, frame_id=frame)

    def vector(v) -> object:
        return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))

    zero_covariance = {9: np.zeros(9), 36: np.zeros(36)}
    R = quaternion_to_rotation(log.base_pose[:, :4]) if log.base_pose is not None else None
    for k in range(log.num_samples):
        yield (
            roles["joint_states"],
            _JOINT_STATE,
            nanoseconds[k],
            types[_JOINT_STATE](
                header=header(k, ""),
                name=list(log.joint_names),
                position=log.joint_positions[k].copy(),
                velocity=log.joint_velocities[k].copy(),
                effort=np.zeros(0) if log.joint_torques is None else log.joint_torques[k].copy(),
            ),
        )
        if log.base_pose is not None and log.base_velocity is not None:
            qw, qx, qy, qz, x, y, z = log.base_pose[k]
            w_B, v_B = R[k].T @ log.base_velocity[k, :3], R[k].T @ log.base_velocity[k, 3:]
            pose = types["geometry_msgs/msg/PoseWithCovariance"](
                pose=types["geometry_msgs/msg/Pose"](
                    position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)
                ),
                covariance=zero_covariance[36],
            )
            twist = types["geometry_msgs/msg/TwistWithCovariance"](
                twist=types["geometry_msgs/msg/Twist"](linear=vector(v_B), angular=vector(w_B)),
                covariance=zero_covariance[36],
            )
            odometry = types[_ODOMETRY](header=header(k, "world"), child_frame_id="base", pose=pose, twist=twist)
            yield roles["odometry"], _ODOMETRY, nanoseconds[k], odometry
        if log.imu_angular_velocity is not None and log.imu_linear_acceleration is not None:
            imu = types[_IMU](
                header=header(k, "imu"),
                orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.array([-1.0] + [0.0] * 8),  # -1: no orientation estimate
                angular_velocity=vector(log.imu_angular_velocity[k]),
                angular_velocity_covariance=zero_covariance[9],
                linear_acceleration=vector(log.imu_linear_acceleration[k]),
                linear_acceleration_covariance=zero_covariance[9],
            )
            yield roles["imu"], _IMU, nanoseconds[k], imu
        for frame, w in log.wrenches.items():
            wrench = types["geometry_msgs/msg/Wrench"](force=vector(w[k, 3:]), torque=vector(w[k, :3]))
            yield (
                roles["wrenches"][frame],
                _WRENCH,
                nanoseconds[k],
                types[_WRENCH](header=header(k, frame), wrench=wrench),
            )


def _check_complete_base(log: RobotLog, path: Path) -> None:
    if (log.base_pose is None) != (log.base_velocity is None):
        raise ValueError(f"write_log: '{path}': nav_msgs/Odometry needs both base_pose and base_velocity")
    if (log.imu_angular_velocity is None) != (log.imu_linear_acceleration is None):
        raise ValueError(f"write_log: '{path}': sensor_msgs/Imu needs both the gyro and the accelerometer")


def _write_bag(log: RobotLog, path: Path, roles: dict, *, ros1: bool) -> None:
    from rosbags.typesys import Stores, get_typestore

    _check_complete_base(log, path)
    if ros1:
        from rosbags.rosbag1 import Writer

        store = get_typestore(Stores.ROS1_NOETIC)
        writer, serialize = Writer(path), store.serialize_ros1
    else:
        from rosbags.rosbag2 import Writer

        store = get_typestore(Stores.ROS2_HUMBLE)
        writer, serialize = Writer(path, version=9), store.serialize_cdr
    connections = {}
    with writer:
        for topic, msgtype, stamp, message in _messages(log, roles, store, ros1):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(connections[topic], int(stamp), serialize(message, msgtype))


def _write_mcap(log: RobotLog, path: Path, roles: dict) -> None:
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    _check_complete_base(log, path)
    store = get_typestore(Stores.ROS2_HUMBLE)
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="humanoid-contact-observers")
        schemas, channels = {}, {}
        for topic, msgtype, stamp, message in _messages(log, roles, store, ros1=False):
            if msgtype not in schemas:
                schemas[msgtype] = writer.register_schema(
                    msgtype, "ros2msg", store.generate_msgdef(msgtype, ros_version=2)[0].encode()
                )
            if topic not in channels:
                channels[topic] = writer.register_channel(topic, "cdr", schemas[msgtype])
            writer.add_message(channels[topic], int(stamp), bytes(store.serialize_cdr(message, msgtype)), int(stamp))
        writer.finish()
