"""Offline contact estimation on a recorded log (issue 14): the residuals (Flacco et al. 2016,
eqs. 11, 16), the force estimate (eq. 19), the contact detector and the single-contact
localizer (Sec. VI, eq. 22), run on a ``RobotLog`` (``systems.io.robot_log``) instead of in a
simulation. On a robot without foot F/T sensors the soles' ground wrenches are unknowns of
the detector and the localizer (with FSRs, only their shear and yaw: the FSRs' readings give
the rest, ``fsr_sole_wrenches``), and ``SoleWrenchCompensation.replay`` estimates them with
the contact and takes them out of the reported residuals and force.

    RobotLog ──log_inputs──► sensed [q; v], motor torques, F/T wrenches (world), plant order
                 │
                 ▼  replay_contact_estimation (systems.residuals.offline)
      InternalResidual, ExternalResidual ──► ContactDetector ──► ContactLocalizer
                 │
                 ▼
            LogEstimates (per sample: residuals, force, detection, link and point)

The estimators are the online systems themselves, built here by ``add_online_estimators``'s
twin ``build_offline_estimators`` with the same ``LogEstimationSettings``; the replay steps
them sample by sample (``systems.residuals.offline``), so a log replays as the robot's
estimators would have run on it. ``simulate_push_log`` simulates a standing humanoid under a
known push (``diagrams.station.humanoid_station``, the ideal world with sensor noise), and
returns its log (what the estimators read, sample by sample) and what the same estimators
reported online: the data of the tests and of ``apps.estimate_from_log --write-demo-log``.

The log's base pose and velocity are the estimators' base state. A log without them (no
base_* columns, no nav_msgs/Odometry) but with the IMU and a force per foot gets them from
the contact-aided invariant EKF (``systems.estimation.base_state_estimator``, Hartley et
al. 2020) replayed on the log as the station runs it online (``base_state``
"invariant_ekf"): gyro, accelerometer, joint positions and contact flags from each foot's
normal force (a 6-axis F/T wrench's, a normal-force-only sensor's, or the sum of the foot's
FSRs; ``foot_force_sources``) with hysteresis (``ContactHysteresis``: on above 10 % of the
robot's weight, off below 5 %, as the station's online flags), starting
at rest, standing on level ground. With IMU bias states the filter starts from the bias
measured over the log's still start (``at_rest_imu_bias``: the mean gyro reading is the gyro
bias, the only way to learn its vertical part, to which the filter is blind while standing;
of the accelerometer bias only its part along gravity), over the window given
(``noise_calibration_time``, the app's ``--calibrate-first``) or detected (the first still
span long enough, ``still_mask``, ``first_still_window``), and keeps tracking it. A stance
foot that slips or rolls drops its kinematic correction (``EkfSettings.slip_speed``). The
filter's noise densities, bias random walks, contact and stillness thresholds and slip
speed are ``LogEstimationSettings.ekf`` (``systems.estimation.ekf_settings``).

What the log lacks, the estimation goes without, and ``LogEstimates.not_estimated`` says
which estimates it could not make and why: without joint torques the internal residual
(eq. 11), hence the detector and the localizer, are not computed, while the external
residual (eq. 16) and its force (eq. 19) need none (on a robot with foot F/T sensors:
without them the soles' wrenches are estimated from both residuals); without every F/T
foot's full 6-axis wrench (a foot logging only its normal force, or nothing) neither
residual runs (both subtract the feet's wrenches as known wrenches); a foot with FSRs whose
readings the log lacks has its whole sole wrench unknown (``fsr_sides_logged``); the
base-state EKF runs on any of them.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, Rgba
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import Context, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, ZeroOrderHold

from diagrams.residuals.wiring import add_internal_and_external_residuals
from diagrams.simulation import simulate
from diagrams.station.config import StationConfig
from diagrams.station.estimator_plant import EstimatorPlant, build_estimator_plant
from diagrams.station.humanoid_station import add_humanoid_station
from models import add_ground, add_humanoid, point_contact_scene_graph_config
from systems.common.topology import floating_base_topology
from systems.estimation.base_state_estimator import (
    LEVEL_GROUND_TILT_STD,
    STANDING_START_ORIENTATION_STD,
    STANDING_START_VELOCITY_STD,
    ContactHysteresis,
    InvariantEkfBaseStateEstimator,
    imu_bias_at_rest,
)
from systems.estimation.ekf_settings import (
    STILL_GYRO_OFFSET,
    STILL_JOINT_SPEED,
    STILL_MIN_DURATION,
    EkfSettings,
    check_ekf_settings,
)
from systems.io.robot_log import RobotLog, StampTiming, resample_uniform, stamp_timing
from systems.observer.fsr_sensing import FSR_NAMES, FsrSoleWrenches
from systems.residuals.contact_estimation import (
    ALL_WRENCH_COMPONENTS,
    STATUS_REASONS,
    VALID,
    ContactDetector,
    ContactLocalizer,
)
from systems.residuals.momentum_residuals import ExternalResidual, InternalResidual, ResidualModel
from systems.residuals.offline import (
    STACKED_IMPLEMENTATIONS,
    ReplayedEstimation,
    replay_contact_estimation,
    replay_residuals,
    residual_noise_model,
)
from systems.residuals.sole_wrenches import ReplayedCompensation
from systems.simulation.disturbances import Push, PushSource, Step
from systems.simulation.visualization import ForceArrows

__all__ = [
    "AtRestCalibration",
    "EstimatorPlant",
    "STILL_GYRO_OFFSET",
    "STILL_JOINT_SPEED",
    "STILL_MIN_DURATION",
    "at_rest_imu_bias",
    "first_still_window",
    "still_mask",
    "still_samples",
    "LogEstimates",
    "LogEstimationSettings",
    "OnlineEstimates",
    "build_estimator_plant",
    "estimate_from_log",
    "log_from_signals",
    "log_inputs",
    "plausibility_bounds",
    "robot_size",
    "simulate_push_log",
]


@dataclass
class LogEstimationSettings:
    """The estimators' settings (those of the contact study,
    ``diagrams.residuals.contact_study``). SI units.

    Attributes:
        internal_gain, external_gain: the residual gains K, 1/s (eqs. 11, 16).
        settle_time: the localizer's wait after a detection before averaging, s.
        localization_period: s between two localizations while in contact (the averaging
            runs every sample all the same, so a longer period only delays the estimate by
            up to it). 0.02 s (the contact study's online localizer: 0.01 s): one
            localization costs about four updates of the residuals (``make benchmark``),
            and at 100 Hz it would take a quarter of the offline time in contact, below
            issue 14's floor of 5x real time on one core.
        detector_startup_time: no detection before this time from the log's start, s.
        detector_release_probability: the detector's p_off.
        noise_calibration_time: None: the detector's noise model is predicted from the
            default sensor noise; a time T > 0: measured on the log's first T seconds,
            which must then be free of contact (``residual_noise_model``), as for a real
            robot whose noise exceeds the white-noise prediction.
        uniform_tolerance: the largest relative deviation of a time step from the median
            one that is used as is; a log whose steps deviate more is either evenly spaced
            rows with noisy stamps, run on the stamps of the line fitted to stamp vs row
            (its data not interpolated), or unevenly sampled, resampled to the median period
            first (``systems.io.robot_log.stamp_timing``, ``resample_uniform``).
        estimate_imu_bias: for a log without base state, the invariant EKF estimates the
            IMU biases (with the level-ground correction), as on a real robot (the
            station's realistic world); False: the bias-free filter (an ideal IMU).
        at_rest_bias: with ``estimate_imu_bias``, the EKF starts from the IMU bias measured
            over the log's still start (``at_rest_imu_bias``): the window
            [0, ``noise_calibration_time``) when that is given (the app's
            ``--calibrate-first``), else the detected still span (``first_still_window``,
            at least ``STILL_MIN_DURATION``), with a prior std of the gyro bias equal to its standard
            error (floored; the largest of the three axes', the filter's prior being one std
            for all three); False: from a zero bias with the estimator's default prior
            (``INITIAL_GYRO_BIAS_STD``).
        ekf: the EKF's noise densities, bias random walks, contact hysteresis thresholds
            and stillness thresholds (``systems.estimation.ekf_settings.EkfSettings``: the
            defaults and their justification; the app's ``--estimator-settings FILE.yaml``).
        dynamics: the residuals' floating-base dynamics (``FloatingBaseDynamics``'s
            implementation): ``"pinocchio"`` (the default offline: Pinocchio's ``crba`` and
            ``computeCoriolisMatrix`` per sample, M_dot exact, about half the cost of
            ``"fast"``'s three Drake mass matrices, ``make benchmark``), or ``"fast"`` (the
            online systems' own: M_dot by central difference; the two agree to about 1e-9
            relative, the difference's rounding).
    """

    internal_gain: float = 35.0
    external_gain: float = 35.0
    settle_time: float = 0.1
    localization_period: float | None = 0.02
    detector_startup_time: float = 0.1
    detector_release_probability: float = 1e-2
    noise_calibration_time: float | None = None
    uniform_tolerance: float = 0.01
    estimate_imu_bias: bool = True
    at_rest_bias: bool = True
    ekf: EkfSettings = field(default_factory=EkfSettings)
    dynamics: str = "pinocchio"

    def __post_init__(self) -> None:
        if self.dynamics not in STACKED_IMPLEMENTATIONS:
            raise ValueError(
                f"LogEstimationSettings: dynamics must be one of {list(STACKED_IMPLEMENTATIONS)}, got {self.dynamics!r}"
            )


def make_detector(
    robot: EstimatorPlant, settings: LogEstimationSettings, period: float, covariances: dict | None = None
) -> ContactDetector:
    """The ContactDetector of ``settings`` (``covariances``: its ``covariance_internal`` and
    ``covariance_external_force``, default predicted from the sensor noise)."""
    return ContactDetector(
        robot.plant,
        internal_gain=settings.internal_gain,
        external_gain=settings.external_gain,
        known_wrench_frames=robot.known_wrench_frames,
        nominal_positions=robot.standing_state[: robot.plant.num_positions()],
        period=period,
        startup_time=settings.detector_startup_time,
        release_probability=settings.detector_release_probability,
        unknown_wrench_frames=robot.unknown_wrench_frames,
        unknown_wrench_components=robot.unknown_wrench_components,
        **(covariances or {}),
    )


#: The estimates ``LogEstimates.not_estimated`` names when they cannot run.
LOCALIZATION = "contact localization (link, point, localized force)"
INTERNAL_RESIDUAL = "internal residual (eq. 11)"
EXTERNAL_RESIDUAL = "external residual (eq. 16) and its contact force (eq. 19)"
DETECTION = "contact detection"


def localization_unavailable(robot: EstimatorPlant) -> str | None:
    """Why the localizer cannot run on ``robot``, or None when it can: no feet (a model
    file, not a humanoid description: no soles whose ground wrenches to measure or
    estimate), or no collision geometry on any link above them (no surface to localize a
    contact on). Feet without F/T sensors are fine: their soles' wrenches are unknowns of
    the localizer (``EstimatorPlant.unknown_wrench_frames``)."""
    if not robot.ft_frames and not robot.unknown_wrench_frames:
        return "no feet (a model file, not a humanoid description): no ground wrenches to tell a contact from"
    plant = robot.plant
    excluded = set(robot.excluded_bodies)
    bodies = [plant.get_body(BodyIndex(i)) for i in range(1, plant.num_bodies())]
    if not any(plant.GetCollisionGeometriesForBody(b) for b in bodies if b.name() not in excluded):
        return (
            "the model's links have no collision geometry (the feet below the F/T sensors aside): no surface to "
            "localize a contact on"
        )
    return None


def make_localizer(robot: EstimatorPlant, settings: LogEstimationSettings, period: float) -> ContactLocalizer | None:
    """The ContactLocalizer of ``settings``, the soles excluded; None when it cannot run
    (``localization_unavailable``: no feet, no collision geometry)."""
    if localization_unavailable(robot) is not None:
        return None
    return ContactLocalizer(
        robot.plant,
        robot.scene_graph,
        exclude_bodies=robot.excluded_bodies,
        period=period,
        localization_period=settings.localization_period,
        settle_time=settings.settle_time,
        unknown_wrench_frames=robot.unknown_wrench_frames,
        unknown_wrench_components=robot.unknown_wrench_components,
    )


# ---------------------------------------------------------------------------------------
# The log in the plant's coordinates.
# ---------------------------------------------------------------------------------------


@dataclass
class LogInputs:
    """A log in the estimators' layout: per sample the sensed state [q; v] (plant order),
    the motor torques (v[6:] order, N m; None: not logged) and the F/T wrenches ([moment
    about the sensor origin; force] per frame of ``EstimatorPlant.ft_frames``, world, N m
    and N; None unless every F/T frame logged its full wrench: ``missing_wrenches`` then
    names the frames without one); with the
    base estimated by the invariant EKF with bias states, its IMU bias estimate per sample
    (``imu_bias``, (N, 6) [gyro, rad/s; accelerometer, m/s^2], else None). ``timing``: how
    the log's stamps were spaced (``StampTiming``: uniform, stamp noise, whose fitted
    stamps are ``time``, or uneven, ``resampled`` to ``period``). ``contact_sources``:
    with the base estimated, {foot side: what its contact flags came from}. ``at_rest``:
    with the base estimated with bias states, the at-rest IMU bias initialisation
    (``AtRestCalibration``), else None. ``slip_updates``: with the base estimated with the
    slip test (``EkfSettings.slip_speed``), {foot side: the updates whose contact correction
    it dropped as a slip}, else empty."""

    time: np.ndarray
    period: float
    state: np.ndarray
    joint_torque: np.ndarray | None
    known_wrenches: np.ndarray | None
    resampled: bool
    timing: StampTiming | None = None
    base_estimated: bool = False
    imu_bias: np.ndarray | None = None
    missing_wrenches: tuple[str, ...] = ()
    contact_sources: dict = field(default_factory=dict)
    at_rest: AtRestCalibration | None = None
    slip_updates: dict[str, int] = field(default_factory=dict)


#: A step of the log's time longer than this many median periods is a gap: refused, never
#: interpolated across (the estimators are observers of a fixed period).
MAX_GAP_PERIODS = 5.0
#: A joint velocity beyond this multiple of the robot's velocity limit, or beyond
#: ``MAX_JOINT_SPEED`` where the model has none, is not physical (rad/s or m/s).
VELOCITY_LIMIT_FACTOR = 10.0
MAX_JOINT_SPEED = 100.0
#: An IMU reading beyond these is not physical: 2000 deg/s and 16 g, the widest ranges of
#: the MEMS IMUs humanoids carry (rad/s, m/s^2).
MAX_GYRO_RATE = math.radians(2000.0)
MAX_ACCELERATION = 16.0 * 9.81
#: A joint position outside the model's limits widened by this margin (rad, or m for a
#: prismatic joint), or beyond +-``MAX_UNLIMITED_JOINT_POSITION`` (two turns) for a joint
#: without limits, is not physical: an encoder overflow or a unit mistake.
POSITION_LIMIT_MARGIN = 0.5
MAX_UNLIMITED_JOINT_POSITION = 4.0 * math.pi
#: A joint torque beyond this multiple of the joint's effort limit is not physical; for a
#: joint without one the bound is ``TORQUE_LIMIT_FACTOR`` times the robot's weight times
#: its size (m g L, N m: the torque of holding the whole robot at arm's length, with L the
#: extent of its links' origins standing, ``robot_size``).
TORQUE_LIMIT_FACTOR = 10.0
#: An F/T force component beyond this multiple of the robot's weight m g (N), or a moment
#: component beyond it times m g L (N m), is not physical (a landing from a jump loads a
#: foot with a few times the weight).
WRENCH_WEIGHT_FACTOR = 10.0
#: A logged base speed beyond this (m/s; the fastest humans run 12 m/s) is not physical;
#: the base's angular velocity is bounded as the gyro (``MAX_GYRO_RATE``).
MAX_BASE_SPEED = 20.0
STANDARD_GRAVITY = 9.81


def robot_size(robot: EstimatorPlant) -> float:
    """L, m: the diagonal of the box around the robot's link origins at its standing state
    (about its height for a humanoid); at least 0.1 m."""
    plant = robot.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, robot.standing_state[: plant.num_positions()])
    points = np.array(
        [
            plant.EvalBodyPoseInWorld(context, plant.get_body(BodyIndex(i))).translation()
            for i in range(1, plant.num_bodies())
        ]
    )
    return max(0.1, float(np.linalg.norm(points.max(axis=0) - points.min(axis=0))))


@dataclass
class PlausibilityBounds:
    """The bounds beyond which a logged value is refused (``_check_plausible``), per
    channel of the log's joint columns (its order) or per axis. SI units.

    Attributes:
        position_lower, position_upper: (n,) rad or m (``POSITION_LIMIT_MARGIN``,
            ``MAX_UNLIMITED_JOINT_POSITION``).
        velocity: (n,) rad/s or m/s (``VELOCITY_LIMIT_FACTOR``, ``MAX_JOINT_SPEED``).
        torque: (n,) N m or N (``TORQUE_LIMIT_FACTOR``).
        wrench: (6,) [moment, N m; force, N] per component (``WRENCH_WEIGHT_FACTOR``).
        base_velocity: (6,) [angular, rad/s; linear, m/s] per component.
        gyro: rad/s. acceleration: m/s^2. weight: m g, N. size: L, m (``robot_size``).
    """

    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity: np.ndarray
    torque: np.ndarray
    wrench: np.ndarray
    base_velocity: np.ndarray
    gyro: float
    acceleration: float
    weight: float
    size: float


def plausibility_bounds(robot: EstimatorPlant, column_order: Sequence) -> PlausibilityBounds:
    """The ``PlausibilityBounds`` of ``robot`` for the log's joints ``column_order``
    (the plant's 1-DoF joints, in the log's column order), from the model's position,
    velocity and effort limits, its mass and its size (see the constants above)."""
    plant = robot.plant
    lower = np.array([j.position_lower_limits()[0] for j in column_order])
    upper = np.array([j.position_upper_limits()[0] for j in column_order])
    limited = np.isfinite(lower) & np.isfinite(upper)
    position_lower = np.where(limited, lower - POSITION_LIMIT_MARGIN, -MAX_UNLIMITED_JOINT_POSITION)
    position_upper = np.where(limited, upper + POSITION_LIMIT_MARGIN, MAX_UNLIMITED_JOINT_POSITION)
    speed = np.array([j.velocity_upper_limits()[0] for j in column_order])
    given = np.isfinite(speed) & (speed > 0.0)
    velocity = np.where(given, VELOCITY_LIMIT_FACTOR * np.where(given, speed, 1.0), MAX_JOINT_SPEED)
    weight = float(plant.CalcTotalMass(plant.CreateDefaultContext())) * STANDARD_GRAVITY
    size = robot_size(robot)
    effort = {}
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        effort[actuator.joint().index()] = actuator.effort_limit()
    limit = np.array([effort.get(j.index(), math.inf) for j in column_order])
    given = np.isfinite(limit) & (limit > 0.0)
    torque = TORQUE_LIMIT_FACTOR * np.where(given, limit, weight * size)
    force = WRENCH_WEIGHT_FACTOR * weight
    return PlausibilityBounds(
        position_lower=position_lower,
        position_upper=position_upper,
        velocity=velocity,
        torque=torque,
        wrench=np.array([force * size] * 3 + [force] * 3),
        base_velocity=np.array([MAX_GYRO_RATE] * 3 + [MAX_BASE_SPEED] * 3),
        gyro=MAX_GYRO_RATE,
        acceleration=MAX_ACCELERATION,
        weight=weight,
        size=size,
    )


def _check_no_gap(time: np.ndarray, period: float) -> None:
    """Raises ValueError naming the first step of ``time`` longer than ``MAX_GAP_PERIODS``
    median periods."""
    steps = np.diff(time)
    gaps = np.flatnonzero(steps > MAX_GAP_PERIODS * period)
    if gaps.size:
        k = int(gaps[0])
        raise ValueError(
            f"the log has a gap of {steps[k]:.6g} s after t = {time[k]:.6g} s ({gaps.size} gap(s) longer than "
            f"{MAX_GAP_PERIODS:g} times its median period of {period:.6g} s): the estimators cannot run across it; "
            "split the log into its segments"
        )


def _check_plausible(robot: EstimatorPlant, log: RobotLog, column_order: list) -> None:
    """Raises ValueError naming the channel, the first time and the bound of a value beyond
    physical plausibility (``plausibility_bounds``): a joint position outside the model's
    limits widened by ``POSITION_LIMIT_MARGIN`` (+-``MAX_UNLIMITED_JOINT_POSITION``
    without limits), a joint velocity beyond ``VELOCITY_LIMIT_FACTOR`` times the joint's
    limit (``MAX_JOINT_SPEED`` without one), a joint torque beyond ``TORQUE_LIMIT_FACTOR``
    times its effort limit (times m g L without one; when the log has torques), an F/T
    force or moment, a normal force or an FSR reading beyond ``WRENCH_WEIGHT_FACTOR`` times
    the weight (times L for moments), a logged base velocity
    beyond ``MAX_GYRO_RATE`` / ``MAX_BASE_SPEED``, an IMU rate or acceleration beyond its
    range."""
    bounds = plausibility_bounds(robot, column_order)
    joints = log.joint_names
    prismatic = [j.type_name() == "prismatic" for j in column_order]
    position_units = ["m" if p else "rad" for p in prismatic]
    checks = [
        ("joint_positions", log.joint_positions, bounds.position_lower, bounds.position_upper, joints, position_units),
        (
            "joint_velocities",
            log.joint_velocities,
            -bounds.velocity,
            bounds.velocity,
            joints,
            [u + "/s" for u in position_units],
        ),
    ]
    if log.joint_torques is not None:
        torque_units = ["N" if p else "N m" for p in prismatic]
        checks.append(("joint_torques", log.joint_torques, -bounds.torque, bounds.torque, joints, torque_units))
    wrench_units = ["N m"] * 3 + ["N"] * 3
    for frame, wrench in log.wrenches.items():
        checks.append(
            (
                f"wrenches[{frame!r}]",
                wrench,
                -bounds.wrench,
                bounds.wrench,
                ("tx", "ty", "tz", "fx", "fy", "fz"),
                wrench_units,
            )
        )
    for frame, force in log.normal_forces.items():
        limit = bounds.wrench[5]
        checks.append((f"normal_forces[{frame!r}]", force[:, None], -limit, limit, ("fz",), ["N"]))
    if log.fsr_forces is not None:
        limit = bounds.wrench[5]
        checks.append(("fsr_forces", log.fsr_forces, -limit, limit, log.fsr_names, ["N"] * len(log.fsr_names)))
    if log.base_velocity is not None:
        axes, units = ("wx", "wy", "wz", "vx", "vy", "vz"), ["rad/s"] * 3 + ["m/s"] * 3
        checks.append(("base_velocity", log.base_velocity, -bounds.base_velocity, bounds.base_velocity, axes, units))
    if log.imu_angular_velocity is not None:
        checks.append(
            ("imu_angular_velocity", log.imu_angular_velocity, -bounds.gyro, bounds.gyro, "xyz", ["rad/s"] * 3)
        )
    if log.imu_linear_acceleration is not None:
        accel = bounds.acceleration
        checks.append(("imu_linear_acceleration", log.imu_linear_acceleration, -accel, accel, "xyz", ["m/s^2"] * 3))
    for name, values, low, high, channels, units in checks:
        beyond = (values < low) | (values > high)
        if beyond.any():
            k, c = (int(i) for i in np.argwhere(beyond)[0])
            lo = float(np.broadcast_to(low, values.shape[1:])[c])
            hi = float(np.broadcast_to(high, values.shape[1:])[c])
            unit = units[c]
            plausible = f"+-{hi:.6g} {unit}" if lo == -hi else f"[{lo:.6g}, {hi:.6g}] {unit}"
            raise ValueError(
                f"the log's {name} (channel {channels[c]!r}) is {values[k, c]:.6g} {unit} at t = {log.time[k]:.6g} s, "
                f"beyond the physically plausible {plausible}"
            )


def foot_force_sources(robot: EstimatorPlant, log: RobotLog) -> dict[str, tuple[str, tuple[str, ...]]]:
    """{foot side: (kind, names)} of what gives each foot's normal force for the EKF's
    contact flags, the first the log has of: "wrench" (the side's F/T frame's 6-axis
    wrench, (name,)), "normal force" (a normal-force-only sensor,
    ``RobotLog.normal_forces``, at the side's F/T frame or its sole frame, (name,)) or "fsr" (the sum
    of the FSRs named ``<side>_*``, their names). A foot with none of them is left out:
    the EKF needs every foot (``log_inputs`` refuses the log). Empty for a model that is not
    a humanoid description (no feet)."""
    humanoid = robot.humanoid
    if humanoid is None:
        return {}
    sources = {}
    for side in sorted(humanoid.sole_frames):
        ft = humanoid.ft_sensor_frames.get(side)
        ft_name = None if ft is None else ft.name()
        normal = [n for n in (ft_name, humanoid.sole_frames[side].name()) if n is not None and n in log.normal_forces]
        fsr = tuple(name for name in log.fsr_names if name.startswith(f"{side}_"))
        if ft_name is not None and ft_name in log.wrenches:
            sources[side] = ("wrench", (ft_name,))
        elif normal:
            sources[side] = ("normal force", (normal[0],))
        elif fsr:
            sources[side] = ("fsr", fsr)
    return sources


def fsr_sides_logged(robot: EstimatorPlant, log: RobotLog) -> EstimatorPlant:
    """``robot`` as the log can serve it: a foot with FSRs (``EstimatorPlant.fsr_sides``)
    whose four readings the log lacks (``fsr_<side>_<name>`` columns) has its sole's whole
    wrench unknown, as a foot with ``sensing: none``; ``robot`` itself when every FSR foot's
    readings are logged."""
    logged = set(log.fsr_names)
    unlogged = [side for side in robot.fsr_sides if not {n for n in FSR_NAMES if n.startswith(f"{side}_")} <= logged]
    if not unlogged:
        return robot
    side_of = {robot.humanoid.sole_frames[side].name(): side for side in robot.humanoid.sole_frames}
    sides = [side_of[frame.name()] for frame in robot.unknown_wrench_frames]
    fsr_sides = tuple(side for side in robot.fsr_sides if side not in unlogged)
    return replace(
        robot,
        unknown_wrench_components=tuple(
            ALL_WRENCH_COMPONENTS if side in unlogged else components
            for side, components in zip(sides, robot.unknown_wrench_components)
        ),
        fsr_sides=fsr_sides,
        fsr_frames=tuple(robot.humanoid.sole_frames[side] for side in fsr_sides),
    )


def fsr_sole_wrenches(robot: EstimatorPlant, log: RobotLog, positions: np.ndarray) -> np.ndarray:
    """(N, 6 k) the wrenches the FSRs of the k feet ``robot.fsr_sides`` measure at their
    soles (``FsrSoleWrenches``: normal force and centre of pressure, [moment about the sole
    frame's origin; force], world), from the log's readings and the positions (N, nq)."""
    readings = np.zeros((log.num_samples, len(FSR_NAMES)))
    column = {name: i for i, name in enumerate(log.fsr_names)}
    for slot, name in enumerate(FSR_NAMES):
        if name in column:
            readings[:, slot] = log.fsr_forces[:, column[name]]
    soles = FsrSoleWrenches(robot.plant, robot.humanoid, robot.fsr_sides)
    R_WS = robot.frame_rotations(robot.fsr_frames, positions)
    return soles.sole_wrenches(readings, R_WS).reshape(log.num_samples, -1)


def log_inputs(
    robot: EstimatorPlant,
    log: RobotLog,
    settings: LogEstimationSettings | None = None,
    initial_base_pose: np.ndarray | None = None,
) -> LogInputs:
    """The log's joints mapped to the plant's q and v order, its base state (or, without
    one, the invariant EKF's estimate: module docstring; ``initial_base_pose`` (7, Drake's
    free-joint q) its start, default standing on level ground with the log's first joint
    positions), and its F/T wrenches rotated from their sensor frames to the world with the
    logged configuration (None, with the frames named in ``missing_wrenches``, unless every
    F/T frame logged its full wrench); the joint torques None when the log has none. With
    steps that are not uniform (``settings``): on the fitted
    uniform stamps when only the stamps are noisy, else resampled to its median period
    (``stamp_timing``).

    Raises:
        ValueError: a joint of the log not on the robot, a robot joint missing from the
            log, no base pose or velocity nor the IMU and a normal force for every foot
            (``foot_force_sources``), an F/T or normal-force frame that is not the robot's;
            a gap in its time (``MAX_GAP_PERIODS``); a joint
            position, velocity or torque, an F/T wrench, a logged base velocity or an IMU
            reading beyond physical plausibility (``plausibility_bounds``; the channel,
            time and bound named).
    """
    settings = settings or LogEstimationSettings()
    plant = robot.plant
    topology = floating_base_topology(plant)
    joints = {j.name(): j for j in topology.joints}
    unknown = [name for name in log.joint_names if name not in joints]
    if unknown:
        raise ValueError(
            f"the log's joints {unknown} are not joints of the robot {robot.humanoid.name!r} "
            f"(its joints: {sorted(joints)})"
        )
    missing = [name for name in joints if name not in log.joint_names]
    if missing:
        raise ValueError(f"the log has no data for the robot's joints {missing}")
    ft_names = [f.name() for f in robot.ft_frames]
    feet = sorted(robot.humanoid.sole_frames) if robot.humanoid is not None else []
    foreign = [name for name in log.wrenches if name not in ft_names]
    if foreign:
        raise ValueError(f"the log's wrenches {foreign} are not F/T frames of the robot (its F/T frames: {ft_names})")
    normal_frames = ft_names + ([robot.humanoid.sole_frames[s].name() for s in feet] if feet else [])
    foreign = [name for name in log.normal_forces if name not in normal_frames]
    if foreign:
        raise ValueError(
            f"the log's normal forces {foreign} are not at F/T or sole frames of the robot "
            f"(its frames: {normal_frames})"
        )
    has_imu = log.imu_angular_velocity is not None and log.imu_linear_acceleration is not None
    sources = foot_force_sources(robot, log)
    if (log.base_pose is None or log.base_velocity is None) and not (has_imu and feet and len(sources) == len(feet)):
        without = [side for side in feet if side not in sources]
        raise ValueError(
            "the log has no base pose and velocity (columns base_*, or a nav_msgs/Odometry topic), nor the IMU and "
            "foot F/T wrenches (or each foot's normal force or FSRs) to estimate them"
            + (" (no IMU)" if not has_imu else "")
            + (f" (no force for the feet {without})" if without else "")
            + ": the estimators need the floating base's state"
        )
    missing_wrenches = tuple(name for name in ft_names if name not in log.wrenches)
    steps = np.diff(log.time)
    period = float(np.median(steps))
    _check_no_gap(log.time, period)
    _check_plausible(robot, log, column_order=[joints[name] for name in log.joint_names])
    timing = stamp_timing(log.time, settings.uniform_tolerance)
    resampled = timing.case == "uneven"
    if resampled:
        log = resample_uniform(log, period)
    elif timing.case == "stamp noise":
        period = timing.period
        log = replace(log, time=timing.fitted_stamps(log.num_samples))
    N, nq, nv = log.num_samples, plant.num_positions(), plant.num_velocities()
    state = np.zeros((N, nq + nv))
    q0, v0 = topology.free_joint.position_start(), topology.free_joint.velocity_start()
    column = {name: i for i, name in enumerate(log.joint_names)}
    order = np.array([column[j.name()] for j in topology.joints])
    state[:, [j.position_start() for j in topology.joints]] = log.joint_positions[:, order]
    state[:, [nq + j.velocity_start() for j in topology.joints]] = log.joint_velocities[:, order]
    base_estimated = log.base_pose is None or log.base_velocity is None
    imu_bias = at_rest = None
    slips = {}
    if base_estimated:
        imu_bias, at_rest, slips = _estimate_base_state(robot, log, state, period, settings, initial_base_pose)
    else:
        state[:, q0 : q0 + 7] = log.base_pose
        state[:, nq + v0 : nq + v0 + 6] = log.base_velocity
    wrenches = None if missing_wrenches else np.zeros((N, 6 * len(ft_names)))
    if ft_names and not missing_wrenches:
        R_WS = robot.frame_rotations(robot.ft_frames, state[:, :nq])
        for j, name in enumerate(ft_names):
            w = log.wrenches[name].reshape(N, 2, 3)
            wrenches[:, 6 * j : 6 * j + 6] = np.einsum("nij,nkj->nki", R_WS[:, j], w).reshape(N, 6)
    if wrenches is not None and robot.fsr_frames:
        wrenches = np.concatenate((wrenches, fsr_sole_wrenches(robot, log, state[:, :nq])), axis=1)
    return LogInputs(
        time=log.time,
        period=period,
        state=state,
        joint_torque=None if log.joint_torques is None else log.joint_torques[:, order],
        known_wrenches=wrenches,
        resampled=resampled,
        timing=timing,
        base_estimated=base_estimated,
        imu_bias=imu_bias,
        missing_wrenches=missing_wrenches,
        contact_sources={side: kind for side, (kind, _) in sources.items()} if base_estimated else {},
        at_rest=at_rest,
        slip_updates=slips,
    )


def standing_base_pose(robot: EstimatorPlant, q: np.ndarray) -> np.ndarray:
    """Drake's free-joint q (7) of the robot at the positions ``q`` standing on level
    ground: the left sole level, the soles' midpoint at the world origin
    (``models.set_standing_state``'s pose, for any joint positions)."""
    plant = robot.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    base = robot.humanoid.base_body
    plant.SetFreeBodyPose(context, base, RigidTransform())
    X_BL = robot.humanoid.sole_frames["left"].CalcPose(context, base.body_frame())
    X_BR = robot.humanoid.sole_frames["right"].CalcPose(context, base.body_frame())
    R_WB = X_BL.rotation().inverse()
    plant.SetFreeBodyPose(
        context, base, RigidTransform(R_WB, -R_WB.multiply(0.5 * (X_BL.translation() + X_BR.translation())))
    )
    free = floating_base_topology(plant).free_joint.position_start()
    return plant.GetPositions(context)[free : free + 7].copy()


# The at-rest IMU bias initialisation (``at_rest_imu_bias``): its defaults
# ``STILL_MIN_DURATION`` (0.5 s), ``STILL_GYRO_OFFSET`` (the BMI088's +-1 deg/s zero-rate
# offset) and ``STILL_JOINT_SPEED`` (0.12 rad/s) are ``systems.estimation.ekf_settings``'s,
# justified there, and settings (``EkfSettings``). The stillness threshold on the norm of
# the gyro averaged over ``STILL_AVERAGING_TIME`` is sqrt(3) times the offset plus
# ``STILL_NOISE_SIGMAS`` times the averaged noise's std per axis (the noise density over
# sqrt(averaging time)) times sqrt(3), so that neither an uncalibrated gyro nor its noise
# reads as motion (2.2 deg/s with the BMI088's figures). A slower steady rotation is not
# told from a bias by the gyro: the joint speeds are the stillness test of a standing robot
# (its base cannot turn with its feet on the ground and its joints still), the gyro's that
# of a robot carried or hanging.

#: The gyro is averaged over this time before the stillness test, s (causal; fewer samples
#: at the log's start): 0.1 s cuts the noise std by sqrt(0.1 s / period), 10 times at 1 kHz.
STILL_AVERAGING_TIME = 0.1
#: Multiple of the averaged gyro noise's std per axis (sigma) in the stillness threshold:
#: the norm of three axes' noise exceeds 6 sigma with probability 7.5e-8 per sample
#: (chi-square, 3 dof, above 36), and the threshold, 6 sqrt(3) sigma, far less: noise alone
#: never reads as motion over a still start of seconds at 1 kHz.
STILL_NOISE_SIGMAS = 6.0


@dataclass
class AtRestCalibration:
    """The IMU bias measured while the robot stands still at the log's start
    (``at_rest_imu_bias``). SI units, IMU frame.

    Attributes:
        source: "given" (``LogEstimationSettings.noise_calibration_time``, the app's
            ``--calibrate-first``), "detected" (``first_still_window``), or "none" (no still
            span of ``STILL_MIN_DURATION``: the EKF starts from a zero bias; ``reason`` says
            why).
        start_s, end_s: the still window from the log's first sample, s (with "none": 0 and
            the length of the still initial span found, too short).
        samples: the window's samples.
        gyro_bias: (3,) rad/s, the window's mean gyro reading; None with "none".
        gyro_bias_std: (3,) rad/s, its standard error (sample std / sqrt(samples), white
            noise) combined with ``base_state_estimator.STILL_GYRO_BIAS_STD_FLOOR``; None with "none".
        accel_magnitude_error: m/s^2, |mean specific force| - |g| (the model's gravity),
            the accelerometer's bias along the measured vertical; None with "none".
        accel_bias: (3,) m/s^2, that error along the mean specific force's direction (the
            accelerometer bias's observable part; 0 across it); None with "none".
        reason: why no window was used ("" otherwise).
    """

    source: str
    start_s: float
    end_s: float
    samples: int
    gyro_bias: np.ndarray | None = None
    gyro_bias_std: np.ndarray | None = None
    accel_magnitude_error: float | None = None
    accel_bias: np.ndarray | None = None
    reason: str = ""

    @property
    def used(self) -> bool:
        return self.gyro_bias is not None

    def imu_bias(self) -> np.ndarray:
        """[b_g (rad/s); b_a (m/s^2)] to start the EKF from: the gyro bias and the
        accelerometer's magnitude error along the mean specific force (its only observable
        part, see ``at_rest_imu_bias``)."""
        return np.concatenate((self.gyro_bias, self.accel_bias))


def still_mask(
    gyro: np.ndarray,
    joint_velocities: np.ndarray,
    period: float,
    gyro_noise_density: float | None = None,
    gyro_offset: float = STILL_GYRO_OFFSET,
    joint_speed: float = STILL_JOINT_SPEED,
) -> np.ndarray:
    """(N,) bool: the samples at which the robot is still: the norm of the gyro averaged
    over the last ``STILL_AVERAGING_TIME`` (fewer samples at the start) at most sqrt(3)
    (``gyro_offset`` + ``STILL_NOISE_SIGMAS`` sigma), sigma = ``gyro_noise_density`` /
    sqrt(the averaging time) rad/s the averaged noise's std per axis, and every joint speed
    at most ``joint_speed``.

    Args:
        gyro: (N, 3) rad/s. joint_velocities: (N, n) rad/s (m/s). period: s.
        gyro_noise_density: rad/s/sqrt(Hz); None: ``EkfSettings``' default (the BMI088's).
        gyro_offset: rad/s (default ``STILL_GYRO_OFFSET``). joint_speed: rad/s (m/s)
            (default ``STILL_JOINT_SPEED``).
    """
    if gyro_noise_density is None:
        gyro_noise_density = EkfSettings().gyro_noise_density
    n = max(1, int(round(STILL_AVERAGING_TIME / period)))
    counts = np.minimum(np.arange(1, gyro.shape[0] + 1), n)
    sums = np.cumsum(np.vstack((np.zeros((1, 3)), gyro)), axis=0)
    averaged = (sums[1:] - sums[np.arange(gyro.shape[0]) + 1 - counts]) / counts[:, None]
    sigma = gyro_noise_density / np.sqrt(counts * period)
    limit = math.sqrt(3.0) * (gyro_offset + STILL_NOISE_SIGMAS * sigma)
    still = np.linalg.norm(averaged, axis=1) <= limit
    if joint_velocities.size:
        still &= np.abs(joint_velocities).max(axis=1) <= joint_speed
    return still


def still_samples(
    gyro: np.ndarray,
    joint_velocities: np.ndarray,
    period: float,
    gyro_noise_density: float | None = None,
    gyro_offset: float = STILL_GYRO_OFFSET,
    joint_speed: float = STILL_JOINT_SPEED,
) -> int:
    """The number of samples of the log's longest initial span that is still
    (``still_mask``, same arguments). 0 when the log starts in motion."""
    still = still_mask(gyro, joint_velocities, period, gyro_noise_density, gyro_offset, joint_speed)
    moving = np.flatnonzero(~still)
    return int(moving[0]) if moving.size else len(still)


def first_still_window(still: np.ndarray, min_samples: int) -> tuple[int, int] | None:
    """[start, end) of the first run of at least ``min_samples`` consecutive still samples
    (``still_mask``), or None. A log may start with the robot settling, or standing up: its
    first still span of enough length serves all the same, its IMU bias being constant over
    minutes."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], still.astype(np.int8), [0]))))
    starts, ends = edges[0::2], edges[1::2]
    long_enough = np.flatnonzero(ends - starts >= max(1, min_samples))
    if not long_enough.size:
        return None
    return int(starts[long_enough[0]]), int(ends[long_enough[0]])


def at_rest_imu_bias(
    gyro: np.ndarray,
    specific_force: np.ndarray,
    joint_velocities: np.ndarray,
    period: float,
    gravity: float,
    window: float | None = None,
    settings: EkfSettings | None = None,
) -> AtRestCalibration:
    """The IMU bias measured over the log's still start: the window [0, ``window``) when
    given (the robot is known to stand still then), else the first still span of at least
    ``settings.still_min_duration`` (default ``STILL_MIN_DURATION``; ``still_mask`` with
    ``settings``' gyro noise density and stillness thresholds, ``first_still_window``):
    from the log's first sample when it starts still, or after the robot has settled.

    What rest makes observable (the gyro bias on all three axes, the accelerometer's along
    the measured vertical): ``systems.estimation.base_state_estimator.imu_bias_at_rest``,
    whose floor and vertical part the online station's filter uses too (``at_rest_duration``).

    Args:
        gyro, specific_force: (N, 3) rad/s, m/s^2 (IMU frame). joint_velocities: (N, n).
        period: s. gravity: |g|, m/s^2. window: s, or None to detect it.
        settings: the ``EkfSettings`` (default: their defaults).

    Raises:
        ValueError: a ``window`` longer than the log or of fewer than 2 samples.
    """
    settings = settings or EkfSettings()
    N = gyro.shape[0]
    if window is not None:
        samples = int(round(window / period))
        if samples > N or samples < 2:
            raise ValueError(
                f"the still window of {window} s (--calibrate-first) has {samples} samples; the log has {N}: "
                "it needs 2 to the log's length"
            )
        source, start = "given", 0
    else:
        still = still_mask(
            gyro,
            joint_velocities,
            period,
            settings.gyro_noise_density,
            settings.still_gyro_offset,
            settings.still_joint_speed,
        )
        window_samples = first_still_window(still, int(math.ceil(settings.still_min_duration / period - 1e-9)))
        if window_samples is None:
            moving = np.flatnonzero(~still)
            samples = int(moving[0]) if moving.size else N
            return AtRestCalibration(
                "none",
                0.0,
                samples * period,
                samples,
                reason=(
                    f"the log is never still for {settings.still_min_duration:g} s (the gyro and the joint speeds "
                    f"against EkfSettings' stillness thresholds; it starts still for {samples * period:.3g} s): "
                    "the EKF starts from a zero IMU bias"
                ),
            )
        start, end = window_samples
        samples = end - start
        source = "detected"
    w = gyro[start : start + samples]
    bias, gyro_bias_std, error = imu_bias_at_rest(
        w.mean(axis=0),
        w.std(axis=0, ddof=1) / math.sqrt(samples),
        specific_force[start : start + samples].mean(axis=0),
        gravity,
    )
    return AtRestCalibration(
        source,
        start * period,
        (start + samples) * period,
        samples,
        gyro_bias=bias[:3],
        gyro_bias_std=gyro_bias_std,
        accel_magnitude_error=error,
        accel_bias=bias[3:],
    )


def _estimate_base_state(
    robot: EstimatorPlant,
    log: RobotLog,
    state: np.ndarray,
    period: float,
    settings: LogEstimationSettings,
    initial_base_pose: np.ndarray | None,
) -> tuple[np.ndarray | None, AtRestCalibration | None, dict[str, int]]:
    """Fills the base part of ``state`` (whose joint part is filled) with the invariant
    EKF's estimate, replayed as the station runs it: at update k the residuals read the
    filter's output of update k - 1 (the initial state at k = 0), the F/T sensors express
    their wrenches in the world with that sensed state, and the filter then reads sample
    k's gyro, accelerometer, joint positions and contact flags: each foot's normal force
    (``foot_force_sources``: the world z force of its F/T wrench, expressed in the world
    with that sensed state; of a normal-force-only sensor, its fz along the sensor's z
    axis, whose world z component it contributes; or its FSRs' sum) through a
    ``ContactHysteresis`` scaled to the robot's weight. With bias states and
    ``settings.at_rest_bias`` the filter starts from the bias measured over the log's still
    start (``at_rest_imu_bias``). A foot that slips drops its kinematic correction
    (``settings.ekf.slip_speed``, the filter's E13). Returns the filter's IMU bias estimate
    read with the base state at each sample ((N, 6)), or None without bias states
    (``settings.estimate_imu_bias``), the ``AtRestCalibration`` (None unless both), and
    {foot side: the updates its correction was dropped as a slip} (``LogInputs.
    slip_updates``)."""
    plant = robot.plant
    topology = floating_base_topology(plant)
    nq = plant.num_positions()
    q0, v0 = topology.free_joint.position_start(), topology.free_joint.velocity_start()
    joints_q = [j.position_start() for j in topology.joints]
    sources = foot_force_sources(robot, log)
    sides = sorted(sources)
    if initial_base_pose is None:
        initial_base_pose = standing_base_pose(robot, np.concatenate(([1.0, 0, 0, 0, 0, 0, 0], state[0, 7:nq])))
    ekf = check_ekf_settings(settings.ekf)
    at_rest = None
    bias_start = {}
    if settings.estimate_imu_bias and settings.at_rest_bias:
        at_rest = at_rest_imu_bias(
            log.imu_angular_velocity,
            log.imu_linear_acceleration,
            state[:, nq:][:, [j.velocity_start() for j in topology.joints]],
            period,
            float(np.linalg.norm(plant.gravity_field().gravity_vector())),
            window=settings.noise_calibration_time,
            settings=settings.ekf,
        )
        if at_rest.used:
            bias_start = {
                "initial_imu_bias": at_rest.imu_bias(),
                "initial_gyro_bias_std": float(at_rest.gyro_bias_std.max()),
            }
    estimator = InvariantEkfBaseStateEstimator(
        plant,
        robot.humanoid.imu_frame,
        [robot.humanoid.sole_frames[side] for side in sides],
        initial_base_pose=initial_base_pose,
        initial_base_velocity=np.zeros(6),
        period=period,
        initial_orientation_std=STANDING_START_ORIENTATION_STD,
        initial_velocity_std=STANDING_START_VELOCITY_STD,
        gyro_noise_density=ekf.gyro_noise_density,
        accel_noise_density=ekf.accel_noise_density,
        gyro_bias_random_walk=ekf.gyro_bias_random_walk,
        accel_bias_random_walk=ekf.accel_bias_random_walk,
        estimate_imu_bias=settings.estimate_imu_bias,
        level_ground_tilt_std=LEVEL_GROUND_TILT_STD if settings.estimate_imu_bias else None,
        slip_speed=ekf.slip_speed,
        **bias_start,
    )
    context = estimator.CreateDefaultContext()
    estimator.SetInitialBaseState(context, initial_base_pose, np.zeros(6))
    ports = [estimator.GetInputPort(name) for name in ("angular_velocity", "linear_acceleration", "joint_positions")]
    contact_port = estimator.GetInputPort("foot_contact")
    pose_port, velocity_port = estimator.GetOutputPort("base_pose"), estimator.GetOutputPort("base_velocity")
    bias_port = estimator.GetOutputPort("imu_bias")
    imu_bias = np.zeros((state.shape[0], 6)) if settings.estimate_imu_bias else None
    plant_context = plant.CreateDefaultContext()
    weight = float(plant.CalcTotalMass(plant_context)) * STANDARD_GRAVITY
    hysteresis = ContactHysteresis.from_weight(
        len(sides), weight, ekf.contact_on_weight_fraction, ekf.contact_off_weight_fraction
    )
    frames = {f.name(): f for f in robot.ft_frames}
    frames |= {robot.humanoid.sole_frames[side].name(): robot.humanoid.sole_frames[side] for side in sides}
    fsr_column = {name: i for i, name in enumerate(log.fsr_names)}

    def normal_force(side: str, k: int) -> float:
        """N, the ground's force on the foot along the world z at sample k."""
        kind, names = sources[side]
        if kind == "fsr":
            return float(sum(log.fsr_forces[k, fsr_column[name]] for name in names))
        R_WS = frames[names[0]].CalcPoseInWorld(plant_context).rotation().matrix()
        if kind == "wrench":
            return float(R_WS[2] @ log.wrenches[names[0]][k, 3:])
        return float(R_WS[2, 2] * log.normal_forces[names[0]][k])

    for k in range(state.shape[0]):
        state[k, q0 : q0 + 7] = pose_port.Eval(context)
        state[k, nq + v0 : nq + v0 + 6] = velocity_port.Eval(context)
        if imu_bias is not None:
            imu_bias[k] = bias_port.Eval(context)
        plant.SetPositions(plant_context, state[k, :nq])
        flags = hysteresis.update([normal_force(side, k) for side in sides])
        for port, value in zip(
            ports, (log.imu_angular_velocity[k], log.imu_linear_acceleration[k], state[k, joints_q])
        ):
            port.FixValue(context, value)
        contact_port.FixValue(context, flags)
        context.SetTime(k * period)
        context.SetDiscreteState(estimator.EvalUniquePeriodicDiscreteUpdate(context))
    slips = {}
    if estimator.slip_speed is not None:
        counts = estimator.GetOutputPort("slip_count").Eval(context)
        slips = {side: int(round(count)) for side, count in zip(sides, counts)}
    return imu_bias, at_rest, slips


# ---------------------------------------------------------------------------------------
# Offline estimation.
# ---------------------------------------------------------------------------------------


@dataclass
class LogEstimates:
    """What ``estimate_from_log`` found, per log sample (N) unless said otherwise.

    Attributes:
        time: s, from the log's first sample.
        joint_names: the plant's joints in v[6:] order (the residual's columns).
        internal_residual: (N, n) eq. (11), N m; None when not estimated (no joint
            torques, or not every F/T foot's full wrench: ``not_estimated`` says).
        external_wrench_world: (N, 6) eq. (16) in world, [moment about the world origin;
            force], N m and N; None when not estimated (not every F/T foot's full wrench).
        force_world: (N, 3) the single contact's force, eq. (19), N (the external
            residual's force); None with it.
        contact_detected: (N,) bool. test_statistics: (N, 2) [s_ext, s_int]. Both None
            when the detector did not run (it needs both residuals).
        localization: the localizer's outputs, or None (``not_estimated`` says why):
            ``status`` (N,) int (``STATUS_REASONS``), ``body_index`` (N,), ``point_world``
            (N, 3) m, ``force_world`` (N, 3) N, the averaged estimate (eq. 19).
        body_names: {body index: name} of the plant.
        period: s. resampled: whether the log was resampled to a uniform period.
        timing: how the log's stamps were spaced (``StampTiming``: its case, the fitted
            period and the stamps' RMS deviation from the fitted line, s).
        noise_model: the detector's (predicted, or calibrated on the log's start).
        base_state: "logged", or the invariant EKF's estimate (a log without base state),
            naming what its contact flags came from per foot.
        base_pose: (N, 7) the base pose the estimators used, Drake's free-joint q [w, x, y,
            z; x, y, z] (m), logged or estimated. base_velocity: (N, 6) its velocity, world
            frame [angular, rad/s; linear, m/s].
        imu_bias: (N, 6) the EKF's IMU bias estimate [gyro, rad/s; accelerometer, m/s^2]
            when it estimated the base with bias states, else None.
        at_rest: the at-rest IMU bias initialisation of that EKF (``AtRestCalibration``:
            the still window used and the initial gyro bias), else None.
        slip_updates: with the base estimated with the EKF's slip test, {foot side: the
            updates whose contact correction it dropped as a slip}, else empty.
        not_estimated: {estimate: why it was not made}, in the order ``INTERNAL_RESIDUAL``
            (no joint torques, or not every F/T foot's full wrench), ``EXTERNAL_RESIDUAL``
            (not every F/T foot's full wrench), ``DETECTION`` (a residual missing),
            ``LOCALIZATION`` (no detection, or ``localization_unavailable``); empty when
            everything ran.
        wall_time_s: the replay's wall time; real_time_factor = log duration / it.
        sole_frames: the soles whose ground wrenches were estimated (a robot without foot
            F/T sensors; empty otherwise). Their wrenches, fitted every update with one
            link's free wrench (``SoleWrenchCompensation.replay``, as the system runs
            online), are taken out of ``internal_residual``,
            ``external_wrench_world`` and ``force_world``, which then hold the contacts'
            share alone, as with F/T sensors (the detector and the localizer fit the soles'
            wrenches themselves, from the raw residuals).
        sole_wrenches_world: (N, 6 m) the soles' estimated wrenches, [moment about the
            sole frame's origin; force] per sole, world (FSRs' measured components are
            not in it: 0 there); None with F/T sensors.
        sole_contact_body_index: (N,) the link whose free wrench was fitted with the soles'
            (-1: none), or None.
    """

    time: np.ndarray
    joint_names: tuple[str, ...]
    internal_residual: np.ndarray | None
    external_wrench_world: np.ndarray | None
    force_world: np.ndarray | None
    contact_detected: np.ndarray | None
    test_statistics: np.ndarray | None
    localization: dict | None
    body_names: dict
    period: float
    resampled: bool
    wall_time_s: float
    timing: StampTiming | None = None
    noise_model: str = "predicted"
    base_state: str = "logged"
    base_pose: np.ndarray | None = None
    base_velocity: np.ndarray | None = None
    imu_bias: np.ndarray | None = None
    not_estimated: dict = field(default_factory=dict)
    at_rest: AtRestCalibration | None = None
    slip_updates: dict[str, int] = field(default_factory=dict)
    sole_frames: tuple[str, ...] = ()
    sole_wrenches_world: np.ndarray | None = None
    sole_contact_body_index: np.ndarray | None = None

    @property
    def real_time_factor(self) -> float:
        duration = self.period * len(self.time)
        return duration / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def contacts(self) -> list[dict]:
        """One dict per detected contact interval: ``start``, ``end`` (s), the mean force
        (eq. 19) over its second half (N), and the last valid localization in it (link,
        point), if any. Empty when the detector did not run (``not_estimated``)."""
        out = []
        if self.contact_detected is None:
            return out
        flags = np.concatenate(([False], self.contact_detected, [False]))
        starts = np.flatnonzero(~flags[:-1] & flags[1:])
        ends = np.flatnonzero(flags[:-1] & ~flags[1:])
        for a, b in zip(starts, ends):
            half = slice(a + (b - a) // 2, b)
            item = {
                "start_s": float(self.time[a]),
                "end_s": float(self.time[b - 1]),
                "mean_force_world_N": self.force_world[half].mean(axis=0).tolist(),
                "link": None,
                "point_world_m": None,
            }
            if self.localization is not None:
                valid = np.flatnonzero(self.localization["status"][a:b] == 0)
                if valid.size:
                    k = a + int(valid[-1])
                    item["link"] = self.body_names[int(self.localization["body_index"][k])]
                    item["point_world_m"] = self.localization["point_world"][k].tolist()
                    item["localized_force_world_N"] = self.localization["force_world"][k].tolist()
            out.append(item)
        return out


def build_offline_estimators(
    robot: EstimatorPlant, settings: LogEstimationSettings, period: float
) -> tuple[ResidualModel, InternalResidual, ExternalResidual]:
    """The residual systems of ``settings`` on one shared ``ResidualModel``, as
    ``diagrams.residuals.wiring`` builds them online."""
    model = ResidualModel(robot.plant, settings.dynamics)
    frames = robot.known_wrench_frames
    internal = InternalResidual(robot.plant, settings.internal_gain, period, frames, model=model)
    external = ExternalResidual(robot.plant, settings.external_gain, period, frames, model=model)
    return model, internal, external


def estimate_from_log(
    robot: str | EstimatorPlant,
    log: RobotLog,
    settings: LogEstimationSettings | None = None,
    initial_base_pose: np.ndarray | None = None,
) -> LogEstimates:
    """Runs the residuals, the force estimate (eq. 19), the detector and (with foot F/T
    sensors and collision geometry on the links above them) the localizer on ``log`` (see
    the module docstring); what cannot run for want of data (joint torques, the feet's
    full wrenches) or of model (``localization_unavailable``) is left out and listed in
    ``LogEstimates.not_estimated`` (``skipped_estimates``). The residuals run stacked over
    the whole log (``systems.residuals.offline``: the same Drake calls per sample, the
    algebra over all samples at once), equal to the systems' per-sample updates to rounding
    (tests/test_offline_speed_paths.py).

    Raises:
        ValueError: see ``log_inputs``; a noise calibration window with fewer than 100
            samples or longer than the log.
    """
    settings = settings or LogEstimationSettings()
    robot = robot if isinstance(robot, EstimatorPlant) else build_estimator_plant(robot)
    robot = fsr_sides_logged(robot, log)
    if robot.unknown_wrench_frames and settings.internal_gain != settings.external_gain:
        raise ValueError(
            "without foot F/T sensors the soles' wrenches are fitted to both residuals through their common filter: "
            f"internal_gain and external_gain must be equal, got {settings.internal_gain} and "
            f"{settings.external_gain}"
        )
    start = _time.perf_counter()
    inputs = log_inputs(robot, log, settings, initial_base_pose)
    period = inputs.period
    model, internal, external = build_offline_estimators(robot, settings, period)
    skipped = skipped_estimates(robot, inputs)
    if INTERNAL_RESIDUAL in skipped:
        external_wrench = None
        if EXTERNAL_RESIDUAL not in skipped:
            # Eq. (16) reads no joint torque: zeros stand in for them, the internal residual is dropped.
            external_wrench = replay_residuals(
                robot.plant,
                model,
                robot.known_wrench_frames,
                inputs.state,
                np.zeros((inputs.state.shape[0], robot.plant.num_velocities() - 6)),
                inputs.known_wrenches,
                internal_gain=settings.internal_gain,
                external_gain=settings.external_gain,
                period=period,
                stacked=True,
            ).external_wrench_world
        replay = ReplayedEstimation(None, external_wrench, None, None, None)
        return _estimates(robot, inputs, replay, _time.perf_counter() - start, settings, skipped)

    def detector_for(internal_residual: np.ndarray, external_wrench: np.ndarray) -> ContactDetector:
        covariances = None
        if settings.noise_calibration_time is not None:
            samples = int(round(settings.noise_calibration_time / period))
            if samples > len(inputs.time):
                raise ValueError(
                    f"noise_calibration_time {settings.noise_calibration_time} s is longer than the log "
                    f"({len(inputs.time) * period:.3f} s)"
                )
            skip = min(int(round(settings.detector_startup_time / period)), samples // 2)
            noise = residual_noise_model(
                internal_residual[:samples],
                external_wrench[:samples],
                internal_gain=settings.internal_gain,
                external_gain=settings.external_gain,
                period=period,
                skip=skip,
            )
            covariances = {
                "covariance_internal": noise.covariance_internal,
                "covariance_external_force": noise.covariance_external_force,
            }
        return make_detector(robot, settings, period, covariances)

    replay = replay_contact_estimation(
        internal,
        external,
        detector_for,
        make_localizer(robot, settings, period),
        inputs.state,
        inputs.joint_torque,
        inputs.known_wrenches,
    )
    soles = None
    if robot.unknown_wrench_frames:
        # The soles' wrenches fitted with the localizer's link where it found one (a link
        # chosen by misfit alone can be a leg's as a foot unloads), else the best fitting link.
        links = None
        if replay.localization is not None:
            located = replay.localization
            links = np.where(located["status"] == VALID, located["body_index"], -1.0)
        soles = robot.sole_wrench_compensation(settings.internal_gain, period).replay(
            inputs.state[:, : robot.plant.num_positions()], replay.external_wrench_world, replay.internal, links=links
        )
    wall = _time.perf_counter() - start
    return _estimates(robot, inputs, replay, wall, settings, skipped, soles)


def skipped_estimates(robot: EstimatorPlant, inputs: LogInputs) -> dict[str, str]:
    """{estimate: why it cannot be made} on the log ``inputs``
    (``LogEstimates.not_estimated``): the internal residual without joint torques or without every F/T
    foot's full wrench, the external residual without the latter (or, on a robot without
    foot F/T sensors, without joint torques: the soles' unknown wrenches are estimated from
    both residuals), the detector without both residuals, the localizer without the
    detector or on a model it cannot run on (``localization_unavailable``)."""
    skipped = {}
    wrenches = None
    if inputs.known_wrenches is None:
        wrenches = (
            f"the feet {list(inputs.missing_wrenches)} have no 6-axis F/T wrench in the log (a normal force at most): "
            "the residuals subtract the feet's full wrenches as known wrenches"
        )
    if inputs.joint_torque is None:
        skipped[INTERNAL_RESIDUAL] = (
            "the log has no joint torques (tau_<joint> columns, JointState effort): eq. 11 needs the motor torques"
        )
        if wrenches is None and robot.unknown_wrench_frames:
            wrenches = (
                "the robot has no foot F/T sensors and the log no joint torques: the ground's wrenches on its soles "
                "are estimated from both residuals, and the external one alone would report them as a contact"
            )
    elif wrenches is not None:
        skipped[INTERNAL_RESIDUAL] = wrenches
    if wrenches is not None:
        skipped[EXTERNAL_RESIDUAL] = wrenches
    if skipped:
        missing = [e for e in (INTERNAL_RESIDUAL, EXTERNAL_RESIDUAL) if e in skipped]
        verb = "is" if len(missing) == 1 else "are"
        skipped[DETECTION] = f"it tests both residuals, and the {' and the '.join(missing)} {verb} not estimated"
        skipped[LOCALIZATION] = "it runs on a detected contact, and the contact detection is not estimated"
    else:
        unavailable = localization_unavailable(robot)
        if unavailable is not None:
            skipped[LOCALIZATION] = unavailable
    return skipped


def _estimates(
    robot: EstimatorPlant,
    inputs: LogInputs,
    replay: ReplayedEstimation,
    wall: float,
    settings,
    skipped: dict,
    soles: ReplayedCompensation | None = None,
) -> LogEstimates:
    plant = robot.plant
    free_joint = robot.topology.free_joint
    q0, v0, nq = free_joint.position_start(), free_joint.velocity_start(), plant.num_positions()
    localization = None
    if replay.localization is not None:
        localization = dict(replay.localization)
        localization["status"] = localization["status"].astype(int)
        localization["body_index"] = localization["body_index"].astype(int)
    internal, external = replay.internal, replay.external_wrench_world
    if soles is not None:  # net of the soles' estimated wrenches
        internal, external = soles.internal, soles.external_wrench_world
    return LogEstimates(
        time=inputs.time - inputs.time[0],
        joint_names=robot.joint_names,
        internal_residual=internal,
        external_wrench_world=external,
        force_world=None if external is None else external[:, 3:].copy(),
        contact_detected=replay.contact_detected,
        test_statistics=replay.test_statistics,
        localization=localization,
        body_names={
            int(b.index()): b.name()
            for b in (plant.get_body(i) for i in plant.GetBodyIndices(robot.humanoid.model_instance))
        }
        | {-1: ""},
        period=inputs.period,
        resampled=inputs.resampled,
        timing=inputs.timing,
        wall_time_s=wall,
        noise_model="predicted" if settings.noise_calibration_time is None else "calibrated on the log's start",
        base_state=_base_state_source(inputs),
        base_pose=inputs.state[:, q0 : q0 + 7].copy(),
        base_velocity=inputs.state[:, nq + v0 : nq + v0 + 6].copy(),
        imu_bias=inputs.imu_bias,
        not_estimated=dict(skipped),
        at_rest=inputs.at_rest,
        slip_updates=dict(inputs.slip_updates),
        sole_frames=tuple(frame.name() for frame in robot.unknown_wrench_frames) if soles is not None else (),
        sole_wrenches_world=None if soles is None else soles.sole_wrenches_world,
        sole_contact_body_index=None if soles is None else soles.body_index.astype(int),
    )


def _base_state_source(inputs: LogInputs) -> str:
    """``LogEstimates.base_state``: "logged", or the EKF naming each foot's contact source."""
    if not inputs.base_estimated:
        return "logged"
    words = {"wrench": "F/T wrench", "normal force": "normal force", "fsr": "FSR sum"}
    feet = ", ".join(f"{side} {words[kind]}" for side, kind in sorted(inputs.contact_sources.items()))
    return f"invariant EKF (IMU, joints, foot contact from: {feet})"


# ---------------------------------------------------------------------------------------
# A simulated log with a known push.
# ---------------------------------------------------------------------------------------


@dataclass
class OnlineEstimates:
    """What the estimators reported in the simulation, per log sample: the internal
    residual (N, n), the external wrench (N, 6), the detector's flag (N,) and, per sample,
    the localizer's status, body, point (N, 3) and force (N, 3); and the push's truth."""

    internal_residual: np.ndarray
    external_wrench_world: np.ndarray
    contact_detected: np.ndarray
    status: np.ndarray
    body_index: np.ndarray
    point_world: np.ndarray
    force_world: np.ndarray
    push: Push
    push_start: float
    push_end: float
    extra: dict = field(default_factory=dict)


#: The demo log's push: 28 N on the outside of the right upper arm's collision surface
#: (a contact of the contact study's sampler, ``sample_trials("hrp4_like", 12, 7)[5]``), in
#: the link frame, m, and in world, N.
DEMO_PUSH_BODY, DEMO_PUSH_POINT, DEMO_PUSH_FORCE = "R_SHOULDER_Y_LINK", (-0.0387, 0.0099, -0.1225), (17.5, -22.1, -0.4)


def demo_push(robot: str, seed: int = 0) -> tuple[str, tuple[float, ...], tuple[float, ...]]:
    """(body, point in its frame (m), force in world (N)) of the demo log's push: on
    hrp4_like the fixed ``DEMO_PUSH_*``; on another robot one random contact of the contact
    study (``sample_trials``: a point of a link's outer surface, 5-40 N into it). Those forces
    are an HRP-4-sized robot's; on a lighter robot the push is capped at the study's largest
    force scaled by its mass (``size_ratios``, as push-and-comply scales its push): the study's
    11 N on nao_like's wrist, held for the demo's second, tips it over."""
    if robot == "hrp4_like":
        return DEMO_PUSH_BODY, DEMO_PUSH_POINT, DEMO_PUSH_FORCE
    from diagrams.residuals.contact_study import MAX_FORCE, sample_trials
    from diagrams.station.standing import size_ratios

    (spec,) = sample_trials(robot, 1, seed)
    estimator = build_estimator_plant(robot)
    force = np.asarray(spec["force_world"])
    cap = MAX_FORCE * size_ratios(estimator.plant, estimator.humanoid)[0]
    force *= min(1.0, cap / float(np.linalg.norm(force)))
    return spec["body"], tuple(spec["point_body"]), tuple(force.tolist())


def simulate_push_log(
    robot: str = "hrp4_like",
    *,
    duration: float = 1.5,
    push_body: str = DEMO_PUSH_BODY,
    push_point: Sequence[float] = DEMO_PUSH_POINT,
    push_force: Sequence[float] = DEMO_PUSH_FORCE,
    push_start: float = 0.5,
    push_end: float = 1.5,
    noise: bool = True,
    seed: int = 0,
    base_state: str = "truth_plus_noise",
    settings: LogEstimationSettings | None = None,
) -> tuple[RobotLog, OnlineEstimates]:
    """Simulates ``robot`` standing (ideal world: the default sensor noise, the sensed base
    state from ``base_state``, ``diagrams.station.humanoid_station.BASE_STATE_SOURCES``)
    under a constant push ``push_force`` (N, world) at ``push_point``
    (m, in ``push_body``'s frame) for push_start <= t < push_end, with the estimators of
    ``settings`` running online, and returns the log (every 1 ms: the sensed joint and base
    state, motor torques, F/T wrenches in their sensor frames, IMU) and what the estimators
    reported. Each logged sample is what the estimators read at that update (sample-and-
    holds on their inputs), so the log replays them exactly.

    On a robot without foot F/T sensors the log has no wrenches (the FSRs' readings on a
    robot with FSRs), and ``OnlineEstimates.extra`` holds the online
    ``SoleWrenchCompensation``'s outputs (``EstimatorPlant.sole_wrench_compensation``): "sole_internal",
    "sole_external", "sole_wrenches" and "sole_body".

    Raises:
        ValueError: a zero force or a bad body (see ``Push``); a robot without collision
            geometry (``localization_unavailable``).
    """
    settings = settings or LogEstimationSettings()
    force = np.asarray(push_force, dtype=float)
    magnitude = float(np.linalg.norm(force))
    if magnitude == 0.0:
        raise ValueError("simulate_push_log: push_force must be non-zero")
    push = Push(
        push_body, np.asarray(push_point, dtype=float), force / magnitude, Step(magnitude, push_start, push_end)
    )
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model=robot, noise=noise, seed=seed, base_state=base_state))
    unavailable = localization_unavailable(station.estimator)
    if unavailable is not None:
        raise ValueError(f"simulate_push_log: {robot!r} cannot be localized on: {unavailable}")
    plant = station.plant
    period = plant.time_step()
    posture = builder.AddSystem(ConstantVectorSource(station.q_hold))
    builder.Connect(posture.get_output_port(), station.desired_position)
    source = builder.AddSystem(PushSource(plant, [push]))
    builder.Connect(source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), source.GetInputPort("state"))
    internal, external = add_internal_and_external_residuals(
        builder, station, settings.internal_gain, settings.external_gain, period
    )
    robot_view = station.estimator  # the estimators know the robot through their own plant
    detector = builder.AddSystem(make_detector(robot_view, settings, period))
    localizer = builder.AddSystem(make_localizer(robot_view, settings, period))
    builder.Connect(external.GetOutputPort("external_wrench_world"), detector.GetInputPort("external_wrench_world"))
    builder.Connect(internal.GetOutputPort("residual"), detector.GetInputPort("residual"))
    if detector.HasInputPort("state"):  # the soles' columns (no foot F/T sensors) move with q
        builder.Connect(station.sensed_state, detector.GetInputPort("state"))
    builder.Connect(station.sensed_state, localizer.GetInputPort("state"))
    builder.Connect(external.GetOutputPort("external_wrench_world"), localizer.GetInputPort("external_wrench_world"))
    builder.Connect(internal.GetOutputPort("residual"), localizer.GetInputPort("residual"))
    builder.Connect(detector.GetOutputPort("contact_detected"), localizer.GetInputPort("contact_detected"))
    compensation = None
    if robot_view.unknown_wrench_frames:  # the soles' wrenches estimated (no foot F/T sensors)
        compensation = builder.AddSystem(robot_view.sole_wrench_compensation(settings.internal_gain, period))
        builder.Connect(station.sensed_state, compensation.GetInputPort("state"))
        builder.Connect(
            external.GetOutputPort("external_wrench_world"), compensation.GetInputPort("external_wrench_world")
        )
        builder.Connect(internal.GetOutputPort("residual"), compensation.GetInputPort("internal_residual"))
    sensors = station.sensors
    # Sample-and-holds: their output after the update at t_k is what the estimators read then.
    held = {
        "state": station.sensed_state,
        "torque": station.measured_torque,
        "gyro": sensors.imu.angular_velocity,
        "accel": sensors.imu.linear_acceleration,
    }
    if station.known_wrenches is not None:
        held["wrenches"] = station.known_wrenches
    if robot_view.fsr_sides:
        held["fsr"] = sensors.fsr_forces
    loggers = {}
    for name, port in held.items():
        hold = builder.AddSystem(ZeroOrderHold(period, port.size()))
        hold.set_name(f"log_hold_{name}")
        builder.Connect(port, hold.get_input_port())
        loggers[name] = LogVectorOutput(hold.get_output_port(), builder, period)
    outputs = {
        "internal": internal.GetOutputPort("residual"),
        "external": external.GetOutputPort("external_wrench_world"),
        "detected": detector.GetOutputPort("contact_detected"),
        "status": localizer.GetOutputPort("status"),
        "body": localizer.GetOutputPort("contact_body"),
        "point": localizer.GetOutputPort("contact_point_world"),
        "force": localizer.GetOutputPort("contact_force_world"),
    }
    if compensation is not None:
        outputs |= {
            "sole_internal": compensation.GetOutputPort("residual"),
            "sole_external": compensation.GetOutputPort("external_wrench_world"),
            "sole_wrenches": compensation.GetOutputPort("sole_wrenches_world"),
            "sole_body": compensation.GetOutputPort("contact_body_index"),
        }
    for name, port in outputs.items():
        loggers[name] = LogVectorOutput(port, builder, period)
    diagram = builder.Build()

    def set_initial_state(context: Context) -> None:
        station.set_initial_state(context)
        for name in held:
            hold = diagram.GetSubsystemByName(f"log_hold_{name}")
            hold.GetMyMutableContextFromRoot(context).SetDiscreteState(np.zeros(hold.get_output_port().size()))

    context = simulate(diagram, duration, set_initial_state=set_initial_state).context
    data = {name: logger.FindLog(context).data().T.copy() for name, logger in loggers.items()}
    times = loggers["state"].FindLog(context).sample_times()
    # The first logged sample precedes the first update (the holds' initial zeros): drop it.
    first = int(np.searchsorted(times, period * 0.5))
    data = {name: values[first:] for name, values in data.items()}
    times = times[first:] - times[first]
    log = log_from_signals(
        robot_view,
        times,
        data["state"],
        data["torque"],
        data.get("wrenches"),
        data["gyro"],
        data["accel"],
        fsr_forces=data.get("fsr"),
    )
    online = OnlineEstimates(
        internal_residual=data["internal"],
        external_wrench_world=data["external"],
        contact_detected=data["detected"][:, 0] > 0.5,
        status=data["status"][:, 0].astype(int),
        body_index=data["body"][:, 0].astype(int),
        point_world=data["point"],
        force_world=data["force"],
        push=push,
        push_start=push_start,
        push_end=push_end,
        extra={name: values for name, values in data.items() if name.startswith("sole_")},
    )
    return log, online


def log_from_signals(
    robot: EstimatorPlant,
    time: np.ndarray,
    state: np.ndarray,
    joint_torque: np.ndarray,
    known_wrenches: np.ndarray | None,
    gyro: np.ndarray | None = None,
    accel: np.ndarray | None = None,
    fsr_forces: np.ndarray | None = None,
) -> RobotLog:
    """The ``RobotLog`` of the estimators' inputs in the plant's layout (the inverse of
    ``log_inputs``): the sensed state (N, nq + nv), the motor torques (N, n), the known
    wrenches in world (N, 6 k, ``robot.known_wrench_frames`` order: the F/T wrenches,
    rotated to their sensor frames with the sensed configuration, are logged; the FSR
    soles' are not: the FSRs' readings are), the IMU (N, 3 each, IMU frame) and the FSRs'
    readings (N, 8, ``FSR_NAMES`` order, N) on a robot with FSRs."""
    plant = robot.plant
    topology = floating_base_topology(plant)
    nq = plant.num_positions()
    q0, v0 = topology.free_joint.position_start(), topology.free_joint.velocity_start()
    N = state.shape[0]
    wrenches = {}
    if robot.ft_frames:
        R_WS = robot.frame_rotations(robot.ft_frames, state[:, :nq])
        for j, frame in enumerate(robot.ft_frames):
            w_W = known_wrenches[:, 6 * j : 6 * j + 6].reshape(N, 2, 3)
            wrenches[frame.name()] = np.einsum("nji,nkj->nki", R_WS[:, j], w_W).reshape(N, 6)
    fsr = {}
    if fsr_forces is not None:
        fsr = {"fsr_names": FSR_NAMES, "fsr_forces": np.asarray(fsr_forces, dtype=float)}
    return RobotLog(
        time=time,
        joint_names=tuple(j.name() for j in topology.joints),
        joint_positions=state[:, [j.position_start() for j in topology.joints]],
        joint_velocities=state[:, [nq + j.velocity_start() for j in topology.joints]],
        joint_torques=joint_torque,
        base_pose=state[:, q0 : q0 + 7],
        base_velocity=state[:, nq + v0 : nq + v0 + 6],
        wrenches=wrenches,
        imu_angular_velocity=gyro,
        imu_linear_acceleration=accel,
        **fsr,
    )


#: The replay's arrow of the estimated contact force (red, as the contact study's estimate).
ESTIMATE_ARROW = {"path": "estimated_force", "rgba": Rgba(0.85, 0.0, 0.0, 1.0), "min_force": 0.5, "shaft_radius": 0.006}


def record_replay(
    meshcat: Meshcat,
    robot: str | EstimatorPlant,
    log: RobotLog,
    estimates: LogEstimates,
    *,
    frames_per_second: float = 32.0,
) -> None:
    """Records into ``meshcat`` (then published: ``meshcat.StaticHtml()`` is the replay) the
    robot moving through the log's configurations, on the ground, with an arrow for the
    estimated contact force (eq. 19) ending at the localized point while the localization
    is valid (at the external residual's line-of-action point nearest the base, eq. 22,
    while a contact is detected but not localized; no arrow without contact).

    Raises:
        ValueError: ``estimates`` of another length than the log (see ``log_inputs``).
    """
    estimator = robot if isinstance(robot, EstimatorPlant) else build_estimator_plant(robot)
    inputs = log_inputs(estimator, log)
    if inputs.state.shape[0] != len(estimates.time):
        raise ValueError(f"record_replay: {len(estimates.time)} estimates for a log of {inputs.state.shape[0]} samples")
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=0.0), point_contact_scene_graph_config(), builder
    )
    add_humanoid(plant, estimator.robot, scene_graph=scene_graph)
    add_ground(plant)
    plant.Finalize()
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    arrows = builder.AddSystem(ForceArrows(meshcat, 1, **ESTIMATE_ARROW))
    builder.ExportInput(arrows.GetInputPort("force_world"), "force_world")
    builder.ExportInput(arrows.GetInputPort("point_world"), "point_world")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    force_port, point_port = diagram.GetInputPort("force_world"), diagram.GetInputPort("point_world")
    nq = plant.num_positions()
    meshcat.Delete()
    meshcat.DeleteRecording()
    meshcat.StartRecording(frames_per_second=frames_per_second, set_visualizations_while_recording=False)
    force_port.FixValue(context, np.zeros(3))
    point_port.FixValue(context, np.zeros(3))
    diagram.ExecuteInitializationEvents(context)
    times = estimates.time
    frame_times = np.arange(0.0, times[-1] + 1e-9, 1.0 / frames_per_second)
    for t in frame_times:
        k = min(int(np.searchsorted(times, t - 1e-9)), len(times) - 1)
        force, point = np.zeros(3), np.zeros(3)
        if estimates.contact_detected is not None and estimates.contact_detected[k]:
            force = estimates.force_world[k]
            valid = estimates.localization is not None and estimates.localization["status"][k] == 0
            if valid:
                point = estimates.localization["point_world"][k]
                force = estimates.localization["force_world"][k]
            else:
                m, f = estimates.external_wrench_world[k, :3], force
                f2 = float(f @ f)
                base = inputs.state[k, 4:7]
                p0 = np.cross(f, m) / f2 if f2 > 0 else base  # eq. (22): the line of action
                point = p0 + (f @ (base - p0)) / f2 * f if f2 > 0 else base
        context.SetTime(float(t))
        plant.SetPositions(plant_context, inputs.state[k, :nq])
        force_port.FixValue(context, force)
        point_port.FixValue(context, point)
        diagram.ForcedPublish(context)
    meshcat.StopRecording()
    meshcat.PublishRecording()


def status_reason(status: int) -> str:
    """The localizer's status code in words."""
    return STATUS_REASONS.get(int(status), f"unknown status {status}")


__all__ += [
    "DEMO_PUSH_BODY",
    "DETECTION",
    "EXTERNAL_RESIDUAL",
    "INTERNAL_RESIDUAL",
    "LOCALIZATION",
    "foot_force_sources",
    "skipped_estimates",
    "demo_push",
    "localization_unavailable",
    "record_replay",
    "status_reason",
]
