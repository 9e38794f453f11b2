"""A real robot's walking log, simulated with its truth: the test bed of base-state
estimation from logs (issue 32).

``nao_like`` stands still for ``standing_start`` s, then walks (``diagrams.locomotion.
nao_walk``) in the realistic world's sensing: the BMI088-like IMU noise and EuRoC bias walks
plus a constant gyro turn-on bias (``gyro_bias_deg_s``, 0.35 deg/s about the vertical by
default, the size real humanoid IMUs show), 14-bit encoders, the station's joint-velocity
noise. Its log holds what such a robot logs and nothing more:

* joint positions and velocities, the IMU (gyro, accelerometer) and each foot's normal force
  (the sum of its four FSRs, as ``wrench_<sole frame>_fz``); no joint torques, no base state;
* at ``rate_hz`` (99 Hz: a period that divides no round number), sampled at the 1 kHz
  simulation tick nearest each nominal instant k / rate + a jitter of ``sampling_jitter_s``
  std, stamped with that instant plus a stamp noise of ``stamp_noise_s`` std: jittery and
  unevenly spaced, as a non-real-time logger's stamps are.

The truth (``WalkingLog.truth_*``) is the simulated base state every 1 ms; ``base_state_
errors`` compares an estimate (``apps.estimate_from_log``'s ``estimates.csv`` columns) with it:
the issue's floors' figures.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from diagrams.locomotion.nao_walk import NaoWalkScenario, build_nao_walk_diagram
from diagrams.simulation import simulate
from diagrams.station.config import StationConfig
from systems.common.topology import floating_base_topology
from systems.io.robot_log import RobotLog, quaternion_to_rotation
from systems.locomotion.walking_pattern import WalkingParameters
from systems.simulation.imperfections import (
    REALISTIC_GYRO_BIAS_DEG_S,
    EncoderImperfections,
    Imperfections,
    ImuImperfections,
)

#: The robot of the test bed: the one with a walking controller.
ROBOT = "nao_like"


@dataclass
class WalkingLogSettings:
    """The test bed's walking log (SI units but the gyro bias, deg/s).

    Attributes:
        standing_start: s standing still before the walk starts.
        walking: s of walking logged after the standing start (the pattern's 1 s initial
            wait, its CoM shift, included).
        rate_hz: the log's nominal rate, Hz.
        sampling_jitter_s: std of the sampling instants around k / rate_hz, s (taken at the
            nearest 1 ms simulation tick).
        stamp_noise_s: std of the stamps' noise around the sampling instants, s.
        gyro_bias_deg_s: the gyro's constant turn-on bias per IMU axis, deg/s.
        seed: the sensors' noise seed (and the jitter's).
    """

    standing_start: float = 3.0
    walking: float = 10.0
    rate_hz: float = 99.0
    sampling_jitter_s: float = 0.4e-3
    stamp_noise_s: float = 0.3e-3
    gyro_bias_deg_s: tuple[float, float, float] = REALISTIC_GYRO_BIAS_DEG_S
    seed: int = 0

    def check(self) -> None:
        """Raises ValueError naming a bad value."""
        for name in ("standing_start", "walking", "rate_hz", "sampling_jitter_s", "stamp_noise_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"WalkingLogSettings.{name} must be a finite number >= 0, got {value!r}")
        if not self.walking > 0.0 or not self.rate_hz > 0.0:
            raise ValueError(f"WalkingLogSettings: walking and rate_hz must be > 0, got {self.walking}, {self.rate_hz}")
        if self.rate_hz > 500.0:
            raise ValueError(f"WalkingLogSettings.rate_hz must be <= 500 Hz (1 kHz simulation), got {self.rate_hz}")
        if len(self.gyro_bias_deg_s) != 3 or not np.isfinite(self.gyro_bias_deg_s).all():
            raise ValueError(f"WalkingLogSettings.gyro_bias_deg_s must be 3 finite deg/s, got {self.gyro_bias_deg_s!r}")

    @property
    def duration(self) -> float:
        return self.standing_start + self.walking


@dataclass
class WalkingLog:
    """A simulated walking log and its truth.

    Attributes:
        log: what the robot logs (module docstring).
        truth_time: (M,) s, every 1 ms of the simulation.
        truth_base_pose: (M, 7) Drake's free-joint q [qw qx qy qz x y z] of the base.
        truth_base_velocity: (M, 6) [w_WB; v_WBo], world frame, rad/s and m/s.
        gyro_bias_rad_s: (3,) the gyro's turn-on bias, rad/s, IMU frame.
        settings: the ``WalkingLogSettings``.
    """

    log: RobotLog
    truth_time: np.ndarray
    truth_base_pose: np.ndarray
    truth_base_velocity: np.ndarray
    gyro_bias_rad_s: np.ndarray
    settings: WalkingLogSettings

    def truth_table(self) -> dict[str, np.ndarray]:
        """The truth as columns ``time`` and ``base_qw`` .. ``base_vz`` (``estimates.csv``'s
        names and units)."""
        names = ("qw", "qx", "qy", "qz", "x", "y", "z", "wx", "wy", "wz", "vx", "vy", "vz")
        base = np.hstack((self.truth_base_pose, self.truth_base_velocity))
        return {"time": self.truth_time} | {f"base_{a}": base[:, i] for i, a in enumerate(names)}


def walking_log_scenario(settings: WalkingLogSettings) -> NaoWalkScenario:
    """The walk of the test bed: nao_like's default walk, long enough for the log, after a
    standing start, in the realistic world's sensing (module docstring), logging its sensors
    every 1 ms."""
    steps = int(math.ceil(settings.walking / WalkingParameters.step_duration)) + 1
    realistic = Imperfections.realistic(seed=settings.seed).imu
    bias = np.radians(np.asarray(settings.gyro_bias_deg_s, dtype=float))
    imu = ImuImperfections(
        gyro_noise_density=realistic.gyro_noise_density,
        gyro_bias_random_walk=realistic.gyro_bias_random_walk,
        accel_noise_density=realistic.accel_noise_density,
        accel_bias_random_walk=realistic.accel_bias_random_walk,
        gyro_bias_x=float(bias[0]),
        gyro_bias_y=float(bias[1]),
        gyro_bias_z=float(bias[2]),
    )
    imperfections = Imperfections(imu=imu, encoders=EncoderImperfections(bits=14), seed=settings.seed)
    return NaoWalkScenario(
        station=StationConfig(model="nao_like", noise=True, seed=settings.seed, imperfections=imperfections),
        walking=WalkingParameters(num_steps=steps),
        log_period=0.001,
        standing_start=settings.standing_start,
        log_sensors=True,
    )


def simulate_walking_log(settings: WalkingLogSettings | None = None) -> WalkingLog:
    """Simulates the walk of ``walking_log_scenario`` and returns its log and truth
    (module docstring).

    Raises:
        ValueError: bad settings (``WalkingLogSettings.check``).
    """
    settings = settings or WalkingLogSettings()
    settings.check()
    scenario = walking_log_scenario(settings)
    diagram, handles = build_nao_walk_diagram(scenario)
    context = simulate(diagram, settings.duration + 0.002, set_initial_state=handles.set_initial_state).context
    station = handles.station
    plant = station.plant
    data = {name: handles.loggers[name].FindLog(context).data().T for name in ("state", "sensed_state", "gyro")}
    data |= {name: handles.loggers[name].FindLog(context).data().T for name in ("accel", "fsr_forces")}
    times = handles.loggers["state"].FindLog(context).sample_times()
    topology = floating_base_topology(plant)
    nq = plant.num_positions()
    q0, v0 = topology.free_joint.position_start(), nq + topology.free_joint.velocity_start()
    rng = np.random.default_rng([settings.seed, 32])
    period = 1.0 / settings.rate_hz
    count = int(math.floor(settings.duration / period)) + 1
    nominal = np.arange(count) * period
    instants = nominal + settings.sampling_jitter_s * rng.standard_normal(count)
    index = np.clip(np.round(np.interp(instants, times, np.arange(times.size))).astype(int), 0, times.size - 1)
    index = np.unique(index)  # a sample once, in time order
    stamps = times[index] + settings.stamp_noise_s * rng.standard_normal(index.size)
    keep = np.concatenate(([True], np.diff(stamps) > 0.0))  # strictly increasing stamps
    index, stamps = index[keep], stamps[keep]
    sensed = data["sensed_state"][index]
    joints = topology.joints
    humanoid = station.estimator.humanoid
    fsr = data["fsr_forces"][index]
    sole_names = {side: humanoid.sole_frames[side].name() for side in ("left", "right")}
    log = RobotLog(
        time=stamps,
        joint_names=tuple(j.name() for j in joints),
        joint_positions=sensed[:, [j.position_start() for j in joints]],
        joint_velocities=sensed[:, [nq + j.velocity_start() for j in joints]],
        joint_torques=None,
        normal_forces={sole_names["left"]: fsr[:, :4].sum(axis=1), sole_names["right"]: fsr[:, 4:].sum(axis=1)},
        imu_angular_velocity=data["gyro"][index],
        imu_linear_acceleration=data["accel"][index],
    )
    state = data["state"]
    return WalkingLog(
        log=log,
        truth_time=times.copy(),
        truth_base_pose=state[:, q0 : q0 + 7].copy(),
        truth_base_velocity=state[:, v0 : v0 + 6].copy(),
        gyro_bias_rad_s=scenario.station.imperfections.imu.gyro_turn_on_bias(),
        settings=dataclasses.replace(settings),
    )


def _yaw(R: np.ndarray) -> np.ndarray:
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def base_state_errors(
    time: np.ndarray,
    base_pose: np.ndarray,
    base_velocity: np.ndarray,
    truth_time: np.ndarray,
    truth_base_pose: np.ndarray,
    truth_base_velocity: np.ndarray,
    walking_start: float,
    yaw_time: float = 12.0,
) -> dict:
    """The estimate's errors against the truth (the truth linearly interpolated to the
    estimate's times; quaternions normalised), in the issue's figures:

    * ``tilt_rms_deg``: RMS over the log of the angle between the estimated and true base z
      axes (roll and pitch: observable, so absolute), deg;
    * ``yaw_error_deg``: the yaw's drift at ``yaw_time`` (or the log's end if shorter):
      (estimated - true) yaw change since the first sample, deg (the start's yaw is not
      observable: the estimate starts at 0);
    * ``horizontal_drift_m`` and ``drift_percent``: the error of the estimated horizontal
      displacement of the base since the first sample at the end, m, and in percent of the
      true horizontal distance walked, start to end (``displacement_m``; the base's path,
      sway included, ``path_length_m``, is longer);
    * ``velocity_rms_m_s``: RMS of the base origin's world velocity error while walking
      (from ``walking_start``), m/s; ``velocity_rms_standing_m_s`` before.
    """
    time = np.asarray(time, dtype=float)

    def at(values):
        return np.column_stack([np.interp(time, truth_time, values[:, i]) for i in range(values.shape[1])])

    pose_true, velocity_true = at(truth_base_pose), at(truth_base_velocity)
    quaternion = pose_true[:, :4] / np.linalg.norm(pose_true[:, :4], axis=1, keepdims=True)
    R_true = quaternion_to_rotation(quaternion)
    R_est = quaternion_to_rotation(base_pose[:, :4] / np.linalg.norm(base_pose[:, :4], axis=1, keepdims=True))
    tilt = np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", R_true[:, :, 2], R_est[:, :, 2]), -1.0, 1.0)))
    yaw_change_true = np.unwrap(_yaw(R_true)) - _yaw(R_true[0])
    yaw_change_est = np.unwrap(_yaw(R_est)) - _yaw(R_est[0])
    k_yaw = min(int(np.searchsorted(time, yaw_time)), time.size - 1)
    displacement_true = pose_true[:, 4:6] - pose_true[0, 4:6]
    displacement_est = base_pose[:, 4:6] - base_pose[0, 4:6]
    drift = float(np.linalg.norm(displacement_est[-1] - displacement_true[-1]))
    path = np.diff(truth_base_pose[:, 4:6], axis=0)
    inside = (truth_time[1:] >= time[0]) & (truth_time[1:] <= time[-1])
    walked = float(np.linalg.norm(path[inside], axis=1).sum())
    straight = float(np.linalg.norm(displacement_true[-1]))
    velocity_error = np.linalg.norm(base_velocity[:, 3:] - velocity_true[:, 3:], axis=1)
    walking = time >= walking_start
    return {
        "tilt_rms_deg": float(np.sqrt(np.mean(tilt**2))),
        "tilt_max_deg": float(tilt.max()),
        "yaw_error_deg": float(np.degrees(yaw_change_est[k_yaw] - yaw_change_true[k_yaw])),
        "yaw_error_time_s": float(time[k_yaw]),
        "horizontal_drift_m": drift,
        "displacement_m": straight,
        "path_length_m": walked,
        "drift_percent": 100.0 * drift / straight if straight > 0 else float("nan"),
        "velocity_rms_m_s": float(np.sqrt(np.mean(velocity_error[walking] ** 2))) if walking.any() else float("nan"),
        "velocity_rms_standing_m_s": float(np.sqrt(np.mean(velocity_error[~walking] ** 2)))
        if (~walking).any()
        else float("nan"),
    }


#: Issue 32's floors on the test bed's log.
FLOORS = {
    "tilt_rms_deg": 1.0,
    "yaw_error_deg": 2.0,
    "drift_percent": 10.0,
    "velocity_rms_m_s": 0.08,
}


def floors_met(errors: dict) -> dict[str, bool]:
    """{figure: met} for ``FLOORS`` (the yaw error by its magnitude)."""
    return {name: bool(abs(errors[name]) <= bound) for name, bound in FLOORS.items()}


__all__ = [
    "FLOORS",
    "ROBOT",
    "WalkingLog",
    "WalkingLogSettings",
    "base_state_errors",
    "floors_met",
    "simulate_walking_log",
    "walking_log_scenario",
]
