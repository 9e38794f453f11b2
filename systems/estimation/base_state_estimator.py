"""Floating-base state estimation: the contact-aided invariant EKF (InEKF) of

    R. Hartley, M. Ghaffari, R. M. Eustice, J. W. Grizzle, "Contact-aided invariant
    extended Kalman filtering for robot state estimation", Int. J. Robotics Research
    39(4):402-430, 2020 (arXiv:1904.09251),

in its right-invariant form with kinematic (leg odometry) corrections and contact switching,
bias-free by default and optionally with IMU bias states (E11, the paper's "imperfect"
InEKF of its section on IMU biases). The equation labels (E1)-(E13) are this module's;
(E1)-(E11) each name the part of the paper they implement, (E12)-(E13) are additions.

State (the IMU frame I in world W, all in SI units), an element of SE_{2+K}(3)::

    X = [[R, v, p, d_1 ... d_K],     R = R_WI, v = v_WIo (m/s), p = p_WIo (m),
         [0, I_{2+K}         ]]      d_j = p_W of the j-th foot point in contact (m).

IMU model (continuous, white noises w_g, w_a; contact points fixed up to a white velocity
noise w_c; the paper's process model)::

    R' = R [ω̃ − w_g]×,   v' = R (ã − w_a) + g,   p' = v,   d_j' = −w_c,j.

(E1)-(E4) Mean propagation over dt with ω̃, ã held (exact for constant ω̃, ã; the paper's
discretisation), with Γ_1, Γ_2 the SO(3) integrals of :func:`so3_gamma`::

    R⁺ = R Exp(ω̃ dt),  v⁺ = v + R Γ_1(ω̃ dt) ã dt + g dt,
    p⁺ = p + v dt + R Γ_2(ω̃ dt) ã dt² + ½ g dt²,  d⁺ = d.

(E5) Right-invariant error η = X̄ X⁻¹ = Exp(ξ), ξ = [ξ_R; ξ_v; ξ_p; ξ_d1; ...] ∈ R^{9+3K}. Its
linearised dynamics ξ' = A ξ + Ad_X̄ w are independent of the state but for the noise term
(A has [g]× in block (v, R) and I in block (p, v)); A is nilpotent (A³ = 0), so the
discrete transition is exactly Φ = I + A dt + ½ A² dt², and (the paper's discrete noise)
P⁺ = Φ P Φᵀ + Φ Ad_X̄ Q_c Ad_X̄ᵀ Φᵀ dt, with Q_c = blkdiag(σ_g² I, σ_a² I, 0, σ_c² I ...)
the noise densities squared and Ad_X̄ rows [R], [[v]×R, R], [[p]×R, 0, R], [[d_j]×R, 0, 0, R].

(E6) Right-invariant kinematic measurement: forward kinematics of the encoders gives the
foot point in the IMU frame, h_j = R_WIᵀ (d_j − p) + n_j, n_j ~ N(0, σ_k² I). Innovation and
Jacobian (the paper's right-invariant observation Y = X⁻¹ b + V)::

    r_j = R̄ h_j − (d̄_j − p̄),   H_j = [0, 0, −I, 0 .. I (at d_j) .. 0],   N_j = R̄ σ_k² I R̄ᵀ = σ_k² I.

(E7) Update: S = H P Hᵀ + N, K = P Hᵀ S⁻¹, δ = K r, X⁺ = Exp(δ) X̄ (left multiplication:
R⁺ = Exp(δ_R) R̄, v⁺ = Exp(δ_R) v̄ + J_l(δ_R) δ_v, likewise p and d_j), Joseph form
P⁺ = (I − KH) P (I − KH)ᵀ + K N Kᵀ. Exp of SE_{2+K}(3) in closed form (:func:`so3_exp`,
J_l = Γ_1).

(E8) Contact made by foot j: d_j = p̄ + R̄ h_j; its error is ξ_dj = ξ_p + R̄ n_j, so the
covariance is augmented by copying the p rows and columns and adding σ_k² I to the new
diagonal block (the paper's state augmentation). (E9) Contact lost: the d_j rows and
columns are removed (marginalised; here zeroed in a fixed-size slot).

(E10) Base frame B (the free joint's child frame) from the IMU frame I fixed in it (X_BI
constant): R_WB = R_WI R_BIᵀ, p_WBo = p_WIo − R_WB p_BI, ω_W = R_WI ω̃ (gyro, I frame),
v_WBo = v_WIo + ω_W × (p_WBo − p_WIo) (rigid-body lever arm).

(E11) IMU biases (optional, ``estimate_imu_bias``): ω̃ = ω + b_g + w_g, ã = a + b_a + w_a,
with θ = [b_g; b_a] (IMU frame, rad/s and m/s²) random walks θ' = w_θ, w_θ white of
densities σ_bg (rad/s²/√Hz) and σ_ba (m/s³/√Hz). The state is (X, θ); X's error stays
right-invariant, θ's is additive, ζ = θ̄ − θ (as in the paper; not a group error), and
the error vector is [ξ; ζ] ∈ R^{15+3K}. The mean propagates (E1)-(E4) with ω̃ − b̄_g and
ã − b̄_a (θ̄ constant). The linearised dynamics gain bias columns,

    A = [[A_X, B], [0, 0]],  B = −[[R̄, 0], [[v̄]×R̄, R̄], [[p̄]×R̄, 0], [[d̄_j]×R̄, 0] ...]

(rows ξ_R, ξ_v, ξ_p, ξ_dj; columns ζ_g, ζ_a), still nilpotent (A⁴ = 0), so with X̄ held over
the step Φ = I + A dt + ½ A² dt² + ⅙ A³ dt³ exactly: its bias columns are
B dt + A_X B dt²/2 + A_X² B dt³/6. The noise map is blkdiag(Ad_X̄, I_6) and Q_c gains
σ_bg² I, σ_ba² I. The kinematic H has zero bias columns; the update adds θ⁺ = θ̄ + δ_θ.
Defaults: the random walks of ``Imperfections.realistic().imu`` (EuRoC's ADIS16448 figures),
initial bias std 0.1 °/s and 0.05 m/s², the bias estimate starting at 0 or at a given
``initial_imu_bias`` (on a log, the bias measured while the robot stands still at its start:
``diagrams.residuals.log_estimation.at_rest_imu_bias``); online, a still start of
``at_rest_duration`` s measures the gyro bias about the vertical (``imu_bias_at_rest``; the
station's filter, whose realistic IMU has ``Imperfections.realistic()``'s turn-on bias).

Observability (a property of the filter, tested in tests/test_base_state_estimator.py):
roll, pitch and velocity are observable through gravity and the contact kinematics; yaw
and the absolute position are not, so an initial yaw error stays and yaw and position
random-walk with the gyro and contact noise. With bias states (standing, IMU upright):

* the gyro bias about the world's horizontal axes is observable through gravity (a
  roll/pitch rate would tilt the estimate): it converges in seconds;
* the gyro bias about the vertical (a yaw rate) is observable only through the leg
  kinematics of two or more separated contact points (the points, fixed in world, would
  move in the IMU frame), and weakly, since the model lets them slide with σ_c: an injected
  0.01 rad/s is 38 % estimated after 10 s on hrp4_like's feet (tested), ~80 % after 60 s
  (measured on synthetic signals, two points 0.2 m apart). With a single contact point it
  is unobservable (a yaw about the vertical through the point leaves the kinematics
  unchanged): its estimate keeps the prior and yaw drifts at its rate;
* the accelerometer bias along the vertical is observable; its horizontal part is not
  separable from tilt while the robot stays upright (a horizontal bias b reads as a tilt
  of b / |g|, both filters alike).

(E12) Level ground (optional, ``level_ground_tilt_std``): a foot in flat contact with a
level floor has its sole normal along world z. With n_j = R_IF_j e_z the sole normal in the
IMU frame from forward kinematics, the measurement R n_j = e_z is a right-invariant
observation of a known world direction (as a magnetometer's in Barrau & Bonnabel's
InEKF)::

    r_j = (R̄ n_j − e_z)_xy = ([e_z]× ξ_R)_xy,   H_j = [[0, −1, 0], [1, 0, 0]] on ξ_R,
    N_j = σ_t² I₂,

σ_t the floor's and the sole's tilt per update, rad. It is applied every
``level_ground_period`` (0.1 s: a sole's tilt error is slow, not white), to each foot
whose sole is still: its world normal R̄ n_j turned less than ``LEVEL_GROUND_MAX_RATE``
times that period since the last update (a pushed robot rocks on its sole edges; a robot
that squats or swings its arms with its soles flat keeps them still), and a foot whose
r_jᵀ S_j⁻¹ r_j exceeds a chi-square gate is left out. (A first version waited for the
whole base to be at rest, its gyro averaged over the period below the same rate, and so
fused nothing during a slow whole-body motion with the soles flat.) Only tilt is observed
(no yaw). It makes the horizontal accelerometer bias observable while standing (else it
reads as a tilt of b / |g|, see E11's observability): the flat-floor assumption of
humanoid tilt estimators (e.g. Benallegue, Chitour, Tanguy, "A new kinematics-inertial
tilt estimator for humanoid robots", Humanoids 2017 / RA-L 2020, whose kinematic tilt
comes from the support foot).
On a floor tilted by α the estimated tilt follows the floor: an error of about α.

(E13) Slip test (optional, ``slip_speed``): a foot that slips or rolls breaks E6's fixed
contact point, and trusted it drags the base estimate along. At each update, before the
correction, each foot flagged in contact has its world point from the predicted state and
the encoders, u_j = R̄ h_j + p̄ (the foot point E8 anchors), and its velocity differenced
between consecutive updates and low-passed over τ = ``SLIP_SPEED_TIME_CONSTANT`` (20 ms)::

    w_j ← w_j + α ((u_j − u_j⁻) / Δt − w_j),   α = min(1, Δt / τ),   w_j = 0 at touch-down.

A foot with |w_j| > ``slip_speed`` is slipping: its correction is dropped and it leaves the
state (E9) for as long as it slips; once below, it comes back as a new contact (E8),
anchored where it now stands, so the filter does not pull the base back to where the foot
was. A stance foot's |w_j| is the filter's own noise: at most 26 mm/s on nao_like's
realistic walk at 1 kHz, 63 mm/s on its 99 Hz log (``EkfSettings.slip_speed``). A single
difference (no low-pass) is too noisy: a 14-bit encoder's step moves the foot point by
~0.1 mm, 0.1 m/s over 1 ms (measured: up to 0.5 m/s on hrp4_like standing); the low-pass
bounds a step's effect to step / τ and detects a 0.3 m/s slide in ~0.4 τ.

Default noises: a Bosch BMI088-class IMU (Bosch Sensortec, "BMI088 6-axis Motion Tracking
for High-performance Applications", data sheet BST-BMI088-DS001: gyro output noise density
0.014 °/s/√Hz, accelerometer noise density 175 µg/√Hz), contact-point velocity noise
0.01 m/s/√Hz (small foot slip and sole compliance) and forward-kinematics noise 2 mm (sole
rocking and link flexibility, far above the encoders' 1e-5 rad).

Contact flags: :func:`contact_flags_from_wrenches` / :class:`FootContactFromForceTorque`
turn the HRP-4 ankle F/T sensors' world-frame wrenches
(``systems.simulation.sensors.FootForceTorqueSensors``) into one flag per foot: in contact
when the normal (world z) force of the ground on the sole exceeds a threshold. A Nao has no
F/T sensor but four FSRs per foot (``systems.observer.fsr_sensing.FsrArray``):
:func:`contact_flags_from_fsr` / :class:`FootContactFromFsr` apply the same test to the sum
of a foot's four FSR forces, with the threshold a fraction of the robot's weight
(``CONTACT_WEIGHT_FRACTION``, 5 %). Both take an off threshold below it (hysteresis, as
:class:`ContactHysteresis`), which the station sets as on logs.

Offline, on a recorded log (``diagrams.residuals.log_estimation``), and online in the
station (``diagrams.station.humanoid_station``), the flags come from whatever the robot
senses per foot (a 6-axis wrench's normal force, a normal-force-only sensor, or the sum of
the foot's FSRs) through :class:`ContactHysteresis`' rule: on above
``CONTACT_ON_WEIGHT_FRACTION`` (10 %) of the robot's weight, off below
``CONTACT_OFF_WEIGHT_FRACTION`` (5 %), so that a foot's force hovering about one threshold
during a step's loading or unloading does not toggle the filter's contact on and off.

Without any foot in contact the filter propagates on the IMU alone (E1-E5) and the
``valid`` output is 0: the velocity then drifts by g · (tilt error) · t plus the
accelerometer's random walk σ_a √t, and the position by one power of t more.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem, ValueProducer

from systems.common.checks import check_plant, eval_finite_input, positive_number
from systems.common.spatial import cross, skew
from systems.common.topology import floating_base_topology
from systems.dynamics.base_state import quaternion_to_rotation
from systems.estimation import invariant_ekf_steps as steps

#: BMI088 gyro output noise density, 0.014 °/s/√Hz, in rad/s/√Hz (data sheet, see module).
GYRO_NOISE_DENSITY = 0.014 * math.pi / 180.0
#: BMI088 accelerometer noise density, 175 µg/√Hz, in m/s²/√Hz.
ACCEL_NOISE_DENSITY = 175e-6 * 9.80665
#: White velocity noise of a contact point, m/s/√Hz (slip, sole compliance).
CONTACT_NOISE_DENSITY = 0.01
#: Forward-kinematics position noise of a foot point in the IMU frame, m (std per axis).
KINEMATICS_NOISE_STD = 2e-3
#: Initial standard deviations: orientation (rad), velocity (m/s), position (m).
INITIAL_ORIENTATION_STD = 0.05
INITIAL_VELOCITY_STD = 0.1
INITIAL_POSITION_STD = 0.01
#: Bias random walks of the optional bias states (Kalibr's model: the bias drifts with std
#: σ_b √t), the ADIS16448 figures of the EuRoC MAV dataset's sensor.yaml (Burri et al., IJRR
#: 2016), equal to ``systems.simulation.imperfections.Imperfections.realistic().imu``:
#: gyro σ_bg, rad/s²/√Hz, and accelerometer σ_ba, m/s³/√Hz.
GYRO_BIAS_RANDOM_WALK = 1.9393e-5
ACCEL_BIAS_RANDOM_WALK = 3.0e-3
#: Initial bias standard deviations of the bias states: gyro, rad/s (0.1 °/s, what remains
#: of the BMI088's ±1 °/s zero-rate offset after a start-up calibration at rest), and
#: accelerometer, m/s² (~5 mg, a quarter of its ±20 mg zero-g offset).
INITIAL_GYRO_BIAS_STD = 0.1 * math.pi / 180.0
INITIAL_ACCEL_BIAS_STD = 0.05
#: σ_t of the level-ground correction (E12) per foot and update, rad (0.5°: a sole rocking on
#: its contact points and a floor level to a few tenths of a degree).
LEVEL_GROUND_TILT_STD = 0.5 * math.pi / 180.0
#: Initial standard deviations of a robot that starts standing still with its soles flat on
#: level ground (the station's start): its tilt is what the soles' kinematics give on that
#: floor, known to the level-ground tolerance (rad), and it is at rest to 1 cm/s (m/s). With
#: the generic INITIAL_* (2.9°, 0.1 m/s) the filter's first 0.2 s of gains are large, and
#: the noise they let through moves the base estimate by more than the converged filter's.
STANDING_START_ORIENTATION_STD = LEVEL_GROUND_TILT_STD
STANDING_START_VELOCITY_STD = 0.01
#: Period of the level-ground corrections (E12), s.
LEVEL_GROUND_PERIOD = 0.1
#: Floor of the at-rest gyro bias's std, rad/s: Earth's rotation (7.29e-5 rad/s), which the
#: at-rest mean takes for bias (a still gyro reads it), rounded up. Earth's rotation is far
#: below what matters here: 0.0042 deg/s turns yaw by 0.05 deg in 12 s.
STILL_GYRO_BIAS_STD_FLOOR = 1e-4


def imu_bias_at_rest(
    gyro_mean: np.ndarray,
    gyro_standard_error: np.ndarray,
    specific_force_mean: np.ndarray,
    gravity: float,
) -> tuple[np.ndarray, np.ndarray, float]:
    """The IMU bias a still robot's IMU shows, from its readings' means over the still
    window: ([b_g (rad/s); b_a (m/s^2)] (6), the gyro bias's std (3, rad/s), the
    accelerometer's magnitude error |f̄| - |g| (m/s^2)).

    At rest the true angular velocity is 0 (but for Earth's rotation, taken for bias), so
    the mean gyro reading is the gyro bias on all three axes, to its standard error
    (combined with ``STILL_GYRO_BIAS_STD_FLOOR``): the only way to learn the bias about the
    vertical, to which the filter is blind while standing on flat ground (E11). The
    accelerometer reads R_WIᵀ(−g) + b_a: with the tilt unknown only |f̄| − |g| is
    identifiable, the bias along the measured vertical; its horizontal part is
    indistinguishable from a tilt and stays 0 (the level-ground correction observes it).
    """
    gyro_mean = np.asarray(gyro_mean, dtype=float).reshape(3)
    f = np.asarray(specific_force_mean, dtype=float).reshape(3)
    norm = float(np.linalg.norm(f))
    error = norm - float(gravity)
    accel_bias = error * f / norm if norm > 0.0 else np.zeros(3)
    std = np.hypot(np.asarray(gyro_standard_error, dtype=float).reshape(3), STILL_GYRO_BIAS_STD_FLOOR)
    return np.concatenate((gyro_mean, accel_bias)), std, error


#: The level-ground correction (E12) uses a foot whose sole's world normal turned by less
#: than this rate times level_ground_period since the previous update, rad/s (0.57 °/s): a
#: robot rocking on its feet (pushed) has no flat sole; over 0.1 s the BMI088's gyro noise
#: turns the estimate by ~1e-3 rad/s.
LEVEL_GROUND_MAX_RATE = 0.01
#: Chi-square gate (2 dof, 1e-3 false rejection) of a foot's level-ground innovation: a foot
#: beyond it is not flat on the floor and is left out of (E12).
LEVEL_GROUND_GATE = 13.8155
#: The slip test's (E13) default speed threshold on a log, m/s: above the stance feet's
#: speeds measured in the simulated realistic world (at most 26 mm/s at 1 kHz, 63 mm/s on a
#: 99 Hz log), see ``EkfSettings.slip_speed``.
SLIP_SPEED = 0.1
#: Time constant of the slip test's low-pass filter on a foot's velocity (E13), s: a 14-bit
#: encoder's step (3.8e-4 rad, ~0.1-0.3 mm at a foot 0.3-0.7 m away) changes w_j by at most
#: step / τ, 5-15 mm/s, where a single 1 ms difference reads 0.1-0.3 m/s; a 0.3 m/s slide
#: crosses 0.1 m/s after τ ln 1.5 = 8 ms (2.4 mm of slide trusted).
SLIP_SPEED_TIME_CONSTANT = 0.02
#: Default normal-force threshold of the F/T contact test, N.
CONTACT_FORCE_THRESHOLD = 20.0
#: Default contact threshold of :class:`FootContactFromFsr` as a fraction of the robot's
#: weight (the F/T default 20 N is 5 % of HRP-4's ~390 N): 2.5 N on a 5.19 kg Nao, 12 times
#: the std (0.2 N) of the sum of a foot's four FSR noises.
CONTACT_WEIGHT_FRACTION = 0.05
#: :class:`ContactHysteresis`'s thresholds as fractions of the robot's weight m g: a foot
#: comes into contact when its normal force exceeds 10 % of the weight and leaves it when
#: the force falls below 5 %. A foot carrying less than a few percent of the weight cannot
#: anchor the filter: it slides or rocks on its edge (the contact-velocity model of E6-E9
#: assumes a foot at rest), so 5 % (19 N on HRP-4, 2.5 N on a Nao) is the floor, and the
#: 5 % band between the two keeps a force hovering about one threshold (a step's touch-down
#: or lift-off, sensor noise of ~0.2 N on a Nao's FSR sum) from toggling the contact.
#: Dimensionless. The station's online flags use them too.
CONTACT_ON_WEIGHT_FRACTION = 0.10
CONTACT_OFF_WEIGHT_FRACTION = 0.05
DEFAULT_GRAVITY = np.array([0.0, 0.0, -9.81])
_I3 = np.eye(3)
_I3.flags.writeable = False


# ---------------------------------------------------------------------------------------
# Lie-group helpers (closed form).
# ---------------------------------------------------------------------------------------


def so3_gamma(phi: np.ndarray, order: int) -> np.ndarray:
    """Γ_m(φ) = Σ_n [φ]×ⁿ / (n + m)!, m = 0, 1, 2 (closed form; Γ_0 = Exp, Γ_1 = J_l).

    Args:
        phi: rotation vector, rad (3).
        order: m in {0, 1, 2}.
    """
    phi = np.asarray(phi, dtype=float)
    theta2 = float(phi @ phi)
    K = skew(phi)
    K2 = K @ K
    if order == 0:
        if theta2 < 1e-12:
            return _I3 + K + 0.5 * K2
        theta = math.sqrt(theta2)
        return _I3 + (math.sin(theta) / theta) * K + ((1.0 - math.cos(theta)) / theta2) * K2
    if order == 1:
        if theta2 < 1e-12:
            return _I3 + 0.5 * K + K2 / 6.0
        theta = math.sqrt(theta2)
        return _I3 + ((1.0 - math.cos(theta)) / theta2) * K + ((theta - math.sin(theta)) / (theta2 * theta)) * K2
    if order == 2:
        if theta2 < 1e-12:
            return 0.5 * _I3 + K / 6.0 + K2 / 24.0
        theta = math.sqrt(theta2)
        return (
            0.5 * _I3
            + ((theta - math.sin(theta)) / (theta2 * theta)) * K
            + ((theta2 + 2.0 * math.cos(theta) - 2.0) / (2.0 * theta2 * theta2)) * K2
        )
    raise ValueError(f"so3_gamma: order must be 0, 1 or 2, got {order!r}")


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """Exp(φ) ∈ SO(3) of a rotation vector φ (rad), Rodrigues' formula."""
    return so3_gamma(phi, 0)


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion [w, x, y, z] with w >= 0 of a rotation matrix (Shepperd's method)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(R, dtype=float).tolist()  # floats: fast
    trace = r00 + r11 + r22
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    elif r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        q = ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    elif r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        q = ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        q = ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[0] < 0.0:
        norm = -norm
    return np.array((q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm))


def imu_to_base(
    R_WI: np.ndarray,
    p_WI: np.ndarray,
    v_WI: np.ndarray,
    omega_I: np.ndarray,
    R_BI: np.ndarray,
    p_BI: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(E10) The free joint's (base_pose (7), base_velocity (6)) from the IMU frame's state.

    Args:
        R_WI, p_WI, v_WI: IMU orientation, origin position (m) and velocity (m/s) in world.
        omega_I: angular velocity in the IMU frame (the gyro), rad/s.
        R_BI, p_BI: the IMU frame's fixed pose in the base frame B.

    Returns:
        base_pose [quaternion w, x, y, z of R_WB; p_WBo, m], base_velocity [ω_W; v_WBo], Drake's
        free-joint layouts.
    """
    R_WB = R_WI @ R_BI.T
    r = R_WB @ p_BI  # p_BoIo_W
    omega_W = R_WI @ omega_I
    pose = np.concatenate([rotation_to_quaternion(R_WB), p_WI - r])
    velocity = np.concatenate([omega_W, v_WI - cross(omega_W, r)])
    return pose, velocity


def base_to_imu(
    base_pose: np.ndarray, base_velocity: np.ndarray, R_BI: np.ndarray, p_BI: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`imu_to_base`: (R_WI, p_WI, v_WI) from the base's pose (7) and velocity (6)."""
    base_pose = np.asarray(base_pose, dtype=float)
    base_velocity = np.asarray(base_velocity, dtype=float)
    R_WB = quaternion_to_rotation(base_pose[:4] / np.linalg.norm(base_pose[:4]))
    r = R_WB @ p_BI
    return R_WB @ R_BI, base_pose[4:7] + r, base_velocity[3:6] + np.cross(base_velocity[:3], r)


# ---------------------------------------------------------------------------------------
# Numpy core.
# ---------------------------------------------------------------------------------------


class ContactAidedInvariantEkf:
    """The contact-aided right-invariant EKF of the module docstring, in numpy.

    The state is the IMU frame's R, v, p in world and one fixed slot per foot (d_j, m), used
    while the foot is in contact. The covariance P ((9 + 3 K_max)²) is over the right-invariant
    error ξ = [ξ_R; ξ_v; ξ_p; ξ_d1; ...]; the rows and columns of a foot out of contact are 0.

    With ``estimate_imu_bias`` the state also holds the IMU biases θ = [b_g; b_a] (E11) and P
    ((15 + 3 K_max)²) is over [ξ; ζ], ζ = θ̄ − θ after the foot slots. Without it the filter
    is exactly the bias-free one (same arithmetic, same state vector).
    """

    def __init__(
        self,
        num_feet: int,
        *,
        rotation: np.ndarray | None = None,
        velocity: np.ndarray | None = None,
        position: np.ndarray | None = None,
        gravity: np.ndarray = DEFAULT_GRAVITY,
        gyro_noise_density: float = GYRO_NOISE_DENSITY,
        accel_noise_density: float = ACCEL_NOISE_DENSITY,
        contact_noise_density: float = CONTACT_NOISE_DENSITY,
        kinematics_noise_std: float = KINEMATICS_NOISE_STD,
        initial_orientation_std: float = INITIAL_ORIENTATION_STD,
        initial_velocity_std: float = INITIAL_VELOCITY_STD,
        initial_position_std: float = INITIAL_POSITION_STD,
        estimate_imu_bias: bool = False,
        gyro_bias_random_walk: float = GYRO_BIAS_RANDOM_WALK,
        accel_bias_random_walk: float = ACCEL_BIAS_RANDOM_WALK,
        initial_gyro_bias_std: float = INITIAL_GYRO_BIAS_STD,
        initial_accel_bias_std: float = INITIAL_ACCEL_BIAS_STD,
    ):
        """Args:
            num_feet: K_max, the number of feet (contact slots), >= 1.
            rotation, velocity, position: initial R_WI, v_WIo (m/s), p_WIo (m); default I, 0, 0.
            gravity: g in world, m/s² (3).
            gyro_noise_density: σ_g, rad/s/√Hz (default BMI088, 2.44e-4).
            accel_noise_density: σ_a, m/s²/√Hz (default BMI088, 1.72e-3).
            contact_noise_density: σ_c, m/s/√Hz (default 0.01).
            kinematics_noise_std: σ_k, m (default 2e-3).
            initial_orientation_std, initial_velocity_std, initial_position_std: the initial
                P's diagonal stds, rad, m/s, m (defaults 0.05, 0.1, 0.01).
            estimate_imu_bias: add the gyro and accelerometer bias states (E11); default
                False (the bias-free filter).
            gyro_bias_random_walk: σ_bg, rad/s²/√Hz (default 1.9393e-5, EuRoC ADIS16448).
            accel_bias_random_walk: σ_ba, m/s³/√Hz (default 3.0e-3, EuRoC ADIS16448).
            initial_gyro_bias_std, initial_accel_bias_std: the initial P's bias stds, rad/s
                and m/s² (defaults 1.75e-3 = 0.1 °/s and 0.05). The bias estimate starts at 0.
                The four bias arguments are checked but unused without ``estimate_imu_bias``.

        Raises:
            ValueError: a bad number of feet, a non-positive or non-finite noise.
        """
        who = "ContactAidedInvariantEkf"
        if isinstance(num_feet, bool) or not isinstance(num_feet, (int, np.integer)) or num_feet < 1:
            raise ValueError(f"{who}: num_feet must be a positive integer, got {num_feet!r}")
        if not isinstance(estimate_imu_bias, (bool, np.bool_)):
            raise ValueError(f"{who}: estimate_imu_bias must be a bool, got {estimate_imu_bias!r}")
        self._K = int(num_feet)
        self._bias = bool(estimate_imu_bias)
        #: First index of ζ = [ζ_g; ζ_a] in ξ (after the foot slots), when estimated.
        self._b0 = 9 + 3 * self._K
        self._dim = self._b0 + (6 if self._bias else 0)
        self._g = np.array(gravity, dtype=float).reshape(3)
        self._var_g = positive_number(gyro_noise_density, f"{who}: gyro_noise_density") ** 2
        self._var_a = positive_number(accel_noise_density, f"{who}: accel_noise_density") ** 2
        self._var_c = positive_number(contact_noise_density, f"{who}: contact_noise_density") ** 2
        self._var_k = positive_number(kinematics_noise_std, f"{who}: kinematics_noise_std") ** 2
        self._initial_std = np.array(
            [
                positive_number(initial_orientation_std, f"{who}: initial_orientation_std"),
                positive_number(initial_velocity_std, f"{who}: initial_velocity_std"),
                positive_number(initial_position_std, f"{who}: initial_position_std"),
            ]
        )
        self._var_bg = positive_number(gyro_bias_random_walk, f"{who}: gyro_bias_random_walk") ** 2
        self._var_ba = positive_number(accel_bias_random_walk, f"{who}: accel_bias_random_walk") ** 2
        self._initial_bias_std = np.array(
            [
                positive_number(initial_gyro_bias_std, f"{who}: initial_gyro_bias_std"),
                positive_number(initial_accel_bias_std, f"{who}: initial_accel_bias_std"),
            ]
        )
        # Φ = I + A dt + ½ A² dt² (E5): the pieces that do not change with dt.
        self._g_skew = skew(self._g)
        self._noise = np.array([self._var_g, self._var_a, self._var_c, self._var_bg, self._var_ba])
        self.reset(rotation, velocity, position)

    # -- state --------------------------------------------------------------------------

    def reset(
        self,
        rotation: np.ndarray | None = None,
        velocity: np.ndarray | None = None,
        position: np.ndarray | None = None,
        imu_bias: np.ndarray | None = None,
    ) -> None:
        """Sets R, v, p (defaults I, 0, 0), no foot in contact, P = the initial covariance and,
        with bias states, the bias estimate [b_g (rad/s); b_a (m/s²)] (default 0)."""
        self._R = np.eye(3) if rotation is None else np.array(rotation, dtype=float).reshape(3, 3)
        self._v = np.zeros(3) if velocity is None else np.array(velocity, dtype=float).reshape(3)
        self._p = np.zeros(3) if position is None else np.array(position, dtype=float).reshape(3)
        self._d = np.zeros((self._K, 3))
        self._in_contact = np.zeros(self._K, dtype=bool)
        self._P = np.zeros((self._dim, self._dim))
        self._P[:9, :9] = np.diag(np.repeat(self._initial_std**2, 3))
        self._b = np.zeros(6)
        if imu_bias is not None:
            if not self._bias:
                raise ValueError("ContactAidedInvariantEkf.reset: imu_bias given but the filter has no bias states")
            self._b = np.array(imu_bias, dtype=float).reshape(6)
        if self._bias:
            b0 = self._b0
            self._P[b0:, b0:] = np.diag(np.repeat(self._initial_bias_std**2, 3))

    def set_gyro_bias_along(self, direction: np.ndarray, value: float, std: float) -> None:
        """Sets the gyro bias's component along the unit ``direction`` (IMU frame) to
        ``value`` (rad/s) with variance ``std``² and no correlation with the rest of the
        state; the components across it keep their estimate and covariance (e.g. the
        bias about the vertical measured at rest, ``imu_bias_at_rest``)."""
        if not self._bias:
            raise ValueError("ContactAidedInvariantEkf.set_gyro_bias_along: the filter has no bias states")
        n = np.asarray(direction, dtype=float).reshape(3)
        n = n / np.linalg.norm(n)
        self._b[:3] += (float(value) - n @ self._b[:3]) * n
        g = slice(self._b0, self._b0 + 3)
        across = np.eye(3) - np.outer(n, n)
        self._P[g, :] = across @ self._P[g, :]
        self._P[:, g] = self._P[:, g] @ across
        self._P[g, g] += float(std) ** 2 * np.outer(n, n)

    def rotate_about_vertical(self, angle: float) -> None:
        """Turns the estimate about the world's vertical (against gravity) through the IMU's
        position by ``angle`` (rad): R, v and the feet in contact (d_j about p); P is kept
        (for the fraction of a degree of an at-rest yaw correction)."""
        turn = so3_exp(-angle * self._g / np.linalg.norm(self._g))
        self._R = turn @ self._R
        self._v = turn @ self._v
        self._d = self._p + (self._d - self._p) @ turn.T

    @property
    def num_feet(self) -> int:
        return self._K

    @property
    def estimates_imu_bias(self) -> bool:
        """True with the bias states (E11)."""
        return self._bias

    @property
    def gyro_bias(self) -> np.ndarray:
        """b̄_g, the gyro bias estimate in the IMU frame, rad/s (0 without bias states)."""
        return self._b[:3].copy()

    @property
    def accel_bias(self) -> np.ndarray:
        """b̄_a, the accelerometer bias estimate in the IMU frame, m/s² (0 without bias states)."""
        return self._b[3:].copy()

    @property
    def num_contacts(self) -> int:
        """Feet currently in the state (in contact at the last correction)."""
        return int(self._in_contact.sum())

    @property
    def in_contact(self) -> np.ndarray:
        """One bool per foot: in the state (in contact at the last correction)."""
        return self._in_contact.copy()

    @property
    def rotation(self) -> np.ndarray:
        """R_WI (3x3)."""
        return self._R.copy()

    @property
    def velocity(self) -> np.ndarray:
        """v_WIo, m/s."""
        return self._v.copy()

    @property
    def position(self) -> np.ndarray:
        """p_WIo, m."""
        return self._p.copy()

    @property
    def foot_positions(self) -> np.ndarray:
        """d_j (K_max x 3), m; rows of feet out of contact are stale."""
        return self._d.copy()

    @property
    def covariance(self) -> np.ndarray:
        """P over ξ = [ξ_R; ξ_v; ξ_p; ξ_d1; ...] (right-invariant error), then ζ = [ζ_g; ζ_a]
        with bias states."""
        return self._P.copy()

    def state_vector(self) -> np.ndarray:
        """[R (row-major 9); v; p; d (3 K); in_contact (K); (b_g; b_a with bias states);
        P (row-major)], for Drake's state."""
        parts = [self._R.reshape(-1), self._v, self._p, self._d.reshape(-1), self._in_contact.astype(float)]
        if self._bias:
            parts.append(self._b)
        parts.append(self._P.reshape(-1))
        return np.concatenate(parts)

    def set_state_vector(self, x: np.ndarray) -> None:
        """Inverse of :meth:`state_vector`."""
        K = self._K
        R, v, p = self.navigation_state(x)
        self._R, self._v, self._p = R.copy(), v.copy(), p.copy()
        self._d = x[15 : 15 + 3 * K].reshape(K, 3).copy()
        self._in_contact = self.in_contact_of(x)
        self._b = self.imu_bias_of(x).copy()
        self._P = self.covariance_of(x).copy()

    @staticmethod
    def navigation_state(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(R_WI, v_WIo, p_WIo) of a :meth:`state_vector` (views, no copy)."""
        return x[:9].reshape(3, 3), x[9:12], x[12:15]

    def in_contact_of(self, x: np.ndarray) -> np.ndarray:
        """The feet in the state (K bools) of a :meth:`state_vector`."""
        return x[15 + 3 * self._K : 15 + 4 * self._K] > 0.5

    def imu_bias_of(self, x: np.ndarray) -> np.ndarray:
        """[b_g (rad/s); b_a (m/s²)] of a :meth:`state_vector` (a view; zeros without bias states)."""
        if not self._bias:
            return np.zeros(6)
        s = 15 + 4 * self._K
        return x[s : s + 6]

    def covariance_of(self, x: np.ndarray) -> np.ndarray:
        """P of a :meth:`state_vector` (a view, no copy)."""
        return x[self.state_size - self._dim**2 :].reshape(self._dim, self._dim)

    @property
    def state_size(self) -> int:
        return 15 + 4 * self._K + (6 if self._bias else 0) + self._dim**2

    # -- propagation --------------------------------------------------------------------
    # The arithmetic is compiled (``invariant_ekf_steps``); these methods hold the state.

    def transition_matrix(self, dt: float) -> np.ndarray:
        """Φ over dt at the current state (E5; with bias states its bias columns, E11): the
        linearised error ξ(t + dt) = Φ ξ(t) without noise, X̄ held over the step."""
        Ad = steps.adjoint(self._R, self._v, self._p, self._d, self._in_contact, self._dim, self._b0)
        return steps.transition(self._R, Ad, self._g_skew, float(dt), self._dim, self._b0)

    def propagate(self, omega: np.ndarray, a: np.ndarray, dt: float) -> None:
        """IMU propagation over dt (E1)-(E5), measurements held over the step; with bias states
        the measurements are first corrected by the bias estimate, ω̃ − b̄_g and ã − b̄_a, and
        the covariance propagated with the bias columns and noises (E11).

        Args:
            omega: gyro ω̃, angular velocity of I in world expressed in I, rad/s (3).
            a: accelerometer ã, specific force R_WIᵀ (a_WIo − g) in I, m/s² (3).
            dt: s, > 0.
        """
        # Contiguous float64 arrays: one compiled signature (another layout would compile anew).
        omega = np.ascontiguousarray(omega, dtype=float).reshape(3)
        a = np.ascontiguousarray(a, dtype=float).reshape(3)
        self._R, self._v, self._p, self._P = steps.propagate_step(
            self._R, self._v, self._p, self._d, self._in_contact, self._b, self._P,
            omega, a, float(dt), self._g, self._g_skew, self._noise, self._b0,
        )  # fmt: skip

    def correct_and_propagate(
        self,
        x: np.ndarray,
        foot_positions: np.ndarray,
        in_contact: np.ndarray,
        omega: np.ndarray,
        a: np.ndarray,
        dt: float,
    ) -> np.ndarray:
        """One step on a :meth:`state_vector` x, in one compiled call: the new state vector
        of ``set_state_vector(x)``, ``correct_kinematics(foot_positions, in_contact)``,
        ``propagate(omega, a, dt)`` (the same arithmetic, bit for bit). This object's own
        state is left as it was."""
        # Writable contiguous copies: one compiled signature whatever the caller passes (a
        # Drake state's value is read-only, which numba would compile for anew).
        return steps.correct_and_propagate_state_vector(
            np.array(x, dtype=float),
            np.array(foot_positions, dtype=float).reshape(self._K, 3),
            np.array(in_contact, dtype=bool).reshape(self._K),
            np.array(omega, dtype=float).reshape(3),
            np.array(a, dtype=float).reshape(3),
            float(dt), self._var_k, self._g, self._g_skew, self._noise, self._dim, self._b0,
        )  # fmt: skip

    # -- correction ---------------------------------------------------------------------

    def _update(self, H: np.ndarray, r: np.ndarray, var: float) -> None:
        """(E7) with measurement noise var I (``invariant_ekf_steps.update_step``)."""
        self._R, self._v, self._p, self._d, self._b, self._P = steps.update_step(
            self._R, self._v, self._p, self._d, self._in_contact, self._b, self._P,
            np.ascontiguousarray(H, dtype=float), np.ascontiguousarray(r, dtype=float), float(var), self._b0,
        )  # fmt: skip

    def correct_level_ground(
        self,
        sole_normals: np.ndarray,
        tilt_std: float,
        gate: float = LEVEL_GROUND_GATE,
        still: np.ndarray | None = None,
    ) -> int:
        """Level-ground tilt correction (E12) with the feet in contact and in the state; a
        foot whose innovation fails the gate r_jᵀ S_j⁻¹ r_j <= ``gate`` (chi-square, 2 dof)
        is left out: it is not flat (it rolls on an edge, e.g. under a push). Returns the
        number of feet used.

        Args:
            sole_normals: n_j, each foot's sole normal in the IMU frame (K_max x 3, unit);
                rows of feet not in contact are ignored.
            tilt_std: σ_t, rad (> 0).
            gate: the chi-square gate (default: 1e-3 false rejection).
            still: optional (K_max) booleans, the feet whose soles are still (the others
                are left out); default: all.
        """
        in_contact = self._in_contact if still is None else self._in_contact & np.asarray(still, dtype=bool)
        feet = np.flatnonzero(in_contact)
        if not feet.size:
            return 0
        var = float(tilt_std) ** 2
        rows = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])  # H of one foot on ξ_R
        P_R = self._P[0:3, 0:3]
        S_one = rows @ P_R @ rows.T + var * np.eye(2)
        n = np.asarray(sole_normals, dtype=float).reshape(self._K, 3)[feet]
        r_all = (n @ self._R.T)[:, :2]  # (R̄ n_j − e_z)_xy per foot
        accepted = np.einsum("ki,ij,kj->k", r_all, np.linalg.inv(S_one), r_all) <= gate
        if not accepted.any():
            return 0
        r = r_all[accepted].reshape(-1)
        m = int(accepted.sum())
        H = np.zeros((2 * m, self._dim))
        H[:, 0:3] = np.tile(rows, (m, 1))  # one foot's rows per accepted foot
        self._update(H, r, var)
        return m

    def correct_kinematics(self, foot_positions: np.ndarray, in_contact: np.ndarray) -> None:
        """Kinematic correction and contact switching (E6)-(E9).

        Feet that left contact are removed (E9); feet in contact already in the state
        correct it (E6, E7), all in one stacked update; feet that made contact are added
        (E8). With no foot in contact nothing is corrected (IMU-only propagation).

        Args:
            foot_positions: h_j, the foot points in the IMU frame from forward kinematics,
                m (K_max x 3); rows of feet not in contact are ignored.
            in_contact: one flag per foot (K_max).
        """
        h = np.ascontiguousarray(foot_positions, dtype=float).reshape(self._K, 3)
        flags = np.ascontiguousarray(in_contact, dtype=bool).reshape(self._K)
        self._R, self._v, self._p, self._d, self._in_contact, self._b, self._P = steps.correct_kinematics_step(
            self._R, self._v, self._p, self._d, self._in_contact, self._b, self._P,
            h, flags, self._var_k, self._b0,
        )  # fmt: skip


def load_compiled_filter_steps() -> None:
    """Loads the filter's compiled steps (``invariant_ekf_steps``) into this process: one
    step of a small filter through each of them. A process's first filter step otherwise
    spends ~1 s loading them from numba's cache (longer on a machine's first run, which
    compiles them); a worker pool can do it at start-up, while other work runs."""
    ekf = ContactAidedInvariantEkf(2, estimate_imu_bias=True)
    feet, flags = np.array([[0.0, 0.1, -0.7], [0.0, -0.1, -0.7]]), np.array([True, True])
    specific_force = -np.asarray(DEFAULT_GRAVITY, dtype=float)
    ekf.set_state_vector(ekf.correct_and_propagate(ekf.state_vector(), feet, flags, np.zeros(3), specific_force, 1e-3))
    ekf.correct_kinematics(feet, flags)
    ekf.correct_level_ground(np.tile([0.0, 0.0, 1.0], (2, 1)), LEVEL_GROUND_TILT_STD)
    ekf.propagate(np.zeros(3), specific_force, 1e-3)
    steps.foot_slip_step(np.eye(3), np.zeros(3), feet, flags, np.zeros(16), 0.05, 1e-3, SLIP_SPEED)


# ---------------------------------------------------------------------------------------
# Contact flags from the F/T sensors or the FSRs.
# ---------------------------------------------------------------------------------------


def contact_flags_from_wrenches(wrenches: np.ndarray, threshold: float = CONTACT_FORCE_THRESHOLD) -> np.ndarray:
    """One flag per foot: 1.0 where the ground's normal (world z) force on the sole > threshold.

    Args:
        wrenches: 6 per foot, [moment (3); force (3)] of the ground on the sole in world
            (``FootForceTorqueSensors``' ``wrenches`` output), N m and N.
        threshold: N.
    """
    w = np.asarray(wrenches, dtype=float).reshape(-1, 6)
    return (w[:, 5] > threshold).astype(float)


class ContactHysteresis:
    """Contact flags with hysteresis from per-foot normal forces: a foot's flag turns on
    when its normal force exceeds ``on_threshold`` and off when it falls below
    ``off_threshold`` (between the two it keeps its previous flag); every foot starts out
    of contact. ``from_weight`` scales the thresholds to the robot's weight
    (``CONTACT_ON_WEIGHT_FRACTION``, ``CONTACT_OFF_WEIGHT_FRACTION``).

    Args:
        num_feet: >= 1.
        on_threshold, off_threshold: N, 0 < off <= on.

    Raises:
        ValueError: a non-positive count or threshold, off above on.
    """

    def __init__(self, num_feet: int, on_threshold: float, off_threshold: float):
        who = "ContactHysteresis"
        if isinstance(num_feet, bool) or not isinstance(num_feet, (int, np.integer)) or num_feet < 1:
            raise ValueError(f"{who}: num_feet must be a positive integer, got {num_feet!r}")
        self.on_threshold = positive_number(on_threshold, f"{who}: on_threshold")
        self.off_threshold = positive_number(off_threshold, f"{who}: off_threshold")
        if self.off_threshold > self.on_threshold:
            raise ValueError(f"{who}: off_threshold {off_threshold} N is above on_threshold {on_threshold} N")
        self._flags = np.zeros(int(num_feet), dtype=bool)

    @classmethod
    def from_weight(
        cls,
        num_feet: int,
        robot_weight: float,
        on_fraction: float = CONTACT_ON_WEIGHT_FRACTION,
        off_fraction: float = CONTACT_OFF_WEIGHT_FRACTION,
    ) -> ContactHysteresis:
        """Thresholds ``on_fraction`` and ``off_fraction`` of ``robot_weight`` (m |g|, N)."""
        weight = positive_number(robot_weight, "ContactHysteresis: robot_weight")
        return cls(num_feet, on_fraction * weight, off_fraction * weight)

    def update(self, normal_forces: np.ndarray) -> np.ndarray:
        """The flags (1.0 in contact, 0.0 not) after reading one sample of the feet's
        normal forces (N, the ground pushing up on each foot), in the order of the feet."""
        f = np.asarray(normal_forces, dtype=float).reshape(-1)
        if f.size != self._flags.size:
            raise ValueError(f"ContactHysteresis: {f.size} normal forces for {self._flags.size} feet")
        self._flags = np.where(self._flags, f >= self.off_threshold, f > self.on_threshold)
        return self._flags.astype(float)


def contact_flags_with_hysteresis(normal_forces: np.ndarray, on_threshold: float, off_threshold: float) -> np.ndarray:
    """(N, k) flags of (N, k) normal forces (N samples of k feet, N) through a
    :class:`ContactHysteresis` of these thresholds (N), starting out of contact."""
    forces = np.asarray(normal_forces, dtype=float)
    hysteresis = ContactHysteresis(forces.shape[1], on_threshold, off_threshold)
    return np.array([hysteresis.update(f) for f in forces]).reshape(forces.shape)


class _FootContactFlags(LeafSystem):
    """One contact flag per foot from its normal force, with :class:`ContactHysteresis`'s
    rule: a foot comes into contact above ``on_threshold`` and leaves it below
    ``off_threshold`` (between the two it keeps its flag, held as discrete state updated
    every ``period``; every foot starts out of contact). With ``off_threshold`` equal to
    ``on_threshold`` the flag is the plain test force > threshold (no state). The flag
    output reads the current input and the flags of the last update (direct feedthrough,
    no delay). ``normal_forces(context)`` gives the feet's normal forces (N, one per foot)
    from the subclass's input port."""

    def __init__(
        self,
        who: str,
        num_feet: int,
        on_threshold: float,
        off_threshold: float | None,
        period: float,
        normal_forces: Callable[[Context], np.ndarray],
    ):
        super().__init__()
        self._normal_forces = normal_forces
        if isinstance(num_feet, bool) or not isinstance(num_feet, (int, np.integer)) or num_feet < 1:
            raise ValueError(f"{who}: num_feet must be a positive integer, got {num_feet!r}")
        self._who = who
        self._on = positive_number(on_threshold, f"{who}: threshold")
        self._off = self._on if off_threshold is None else positive_number(off_threshold, f"{who}: off_threshold")
        if self._off > self._on:
            raise ValueError(f"{who}: off_threshold {off_threshold} N is above the threshold {on_threshold} N")
        self._state = None
        if self._off < self._on:
            self._state = self.DeclareDiscreteState(int(num_feet))
            self.DeclarePeriodicDiscreteUpdateEvent(positive_number(period, f"{who}: period"), 0.0, self._Update)
        self.DeclareVectorOutputPort("foot_contact", int(num_feet), self._CalcContact)

    @property
    def threshold(self) -> float:
        """The normal force above which a foot comes into contact, N."""
        return self._on

    @property
    def off_threshold(self) -> float:
        """The normal force below which a foot in contact leaves it, N."""
        return self._off

    def _flags(self, context: Context) -> np.ndarray:
        f = self._normal_forces(context)
        if self._state is None:
            return (f > self._on).astype(float)
        previous = context.get_discrete_state(self._state).value() > 0.5
        return np.where(previous, f >= self._off, f > self._on).astype(float)

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        discrete_state.set_value(self._state, self._flags(context))

    def _CalcContact(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._flags(context))


class FootContactFromForceTorque(_FootContactFlags):
    """Contact flags from foot F/T sensors: the ground's normal (world z) force on each sole
    (:func:`contact_flags_from_wrenches` without hysteresis).

    Inputs:
        wrenches: 6 per foot, the ``FootForceTorqueSensors`` output (world frame).

    Outputs:
        foot_contact: one flag per foot (1.0 in contact, 0.0 not), in the sensors' order.

    For a Nao's FSRs see :class:`FootContactFromFsr`.
    """

    def __init__(
        self,
        num_feet: int,
        threshold: float = CONTACT_FORCE_THRESHOLD,
        *,
        off_threshold: float | None = None,
        period: float = 1e-3,
    ):
        """Args:
        num_feet: number of F/T sensors (feet), >= 1.
        threshold: the normal force above which a foot comes into contact, N (default 20 N,
            ~5 % of HRP-4's weight).
        off_threshold: below which it leaves contact, N (<= ``threshold``; default: the
            threshold, no hysteresis). The station uses ``CONTACT_ON_WEIGHT_FRACTION`` and
            ``CONTACT_OFF_WEIGHT_FRACTION`` of the robot's weight, as on logs.
        period: the hysteresis' update period, s (the estimator's).
        """
        who = "FootContactFromForceTorque"
        super().__init__(who, num_feet, threshold, off_threshold, period, self._world_normal_forces)
        self._wrenches = self.DeclareVectorInputPort("wrenches", 6 * int(num_feet))

    def _world_normal_forces(self, context: Context) -> np.ndarray:
        w = eval_finite_input("FootContactFromForceTorque", self._wrenches, context)
        return np.asarray(w, dtype=float).reshape(-1, 6)[:, 5]


def contact_flags_from_fsr(forces: np.ndarray, threshold: float, sensors_per_foot: int = 4) -> np.ndarray:
    """One flag per foot: 1.0 where the sum of the foot's FSR normal forces > threshold.

    Args:
        forces: ``sensors_per_foot`` readings per foot, foot by foot (``FsrArray``'s
            ``fsr_forces``: left then right, each in ``models.FSR_ORDER``), N.
        threshold: N.
        sensors_per_foot: FSRs per foot (4 on a Nao).
    """
    f = np.asarray(forces, dtype=float).reshape(-1, sensors_per_foot)
    return (f.sum(axis=1) > threshold).astype(float)


class FootContactFromFsr(_FootContactFlags):
    """Contact flags from foot force-sensing resistors (:func:`contact_flags_from_fsr`
    without hysteresis).

    A foot comes into contact when the sum of its FSR readings exceeds ``weight_fraction``
    times the robot's weight (default ``CONTACT_WEIGHT_FRACTION`` = 5 %: 2.5 N on a 5.19 kg
    Nao; the F/T default 20 N is the same 5 % of HRP-4's weight) and, with
    ``off_weight_fraction``, leaves it below that fraction (hysteresis).

    Inputs:
        fsr_forces: ``sensors_per_foot`` per foot, N, foot by foot (``FsrArray``'s
            ``fsr_forces``: left foot then right foot, each front_left, front_right,
            rear_left, rear_right).

    Outputs:
        foot_contact: one flag per foot (1.0 in contact, 0.0 not), in the input's foot order.

    Every input is checked: NaN or inf raises a ValueError naming the port.
    """

    def __init__(
        self,
        robot_weight: float,
        *,
        weight_fraction: float = CONTACT_WEIGHT_FRACTION,
        off_weight_fraction: float | None = None,
        num_feet: int = 2,
        sensors_per_foot: int = 4,
        period: float = 1e-3,
    ):
        """Args:
        robot_weight: the robot's weight m |g|, N.
        weight_fraction: the contact threshold as a fraction of ``robot_weight``, in (0, 1).
        off_weight_fraction: the release threshold's fraction (<= ``weight_fraction``;
            default: the same, no hysteresis).
        num_feet: number of feet, >= 1 (default 2).
        sensors_per_foot: FSRs per foot, >= 1 (default 4, Nao).
        period: the hysteresis' update period, s.

        Raises:
            ValueError: a non-positive weight, a fraction outside (0, 1), bad counts.
        """
        who = "FootContactFromFsr"
        for name, value in (("num_feet", num_feet), ("sensors_per_foot", sensors_per_foot)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{who}: {name} must be a positive integer, got {value!r}")
        fraction = positive_number(weight_fraction, f"{who}: weight_fraction")
        if fraction >= 1.0:
            raise ValueError(f"{who}: weight_fraction must be below 1, got {weight_fraction!r}")
        weight = positive_number(robot_weight, f"{who}: robot_weight")
        off = None
        if off_weight_fraction is not None:
            off = positive_number(off_weight_fraction, f"{who}: off_weight_fraction") * weight
        super().__init__(who, num_feet, fraction * weight, off, period, self._fsr_sums)
        self._per_foot = int(sensors_per_foot)
        self._forces = self.DeclareVectorInputPort("fsr_forces", self._per_foot * int(num_feet))

    def _fsr_sums(self, context: Context) -> np.ndarray:
        f = eval_finite_input("FootContactFromFsr", self._forces, context)
        return np.asarray(f, dtype=float).reshape(-1, self._per_foot).sum(axis=1)


# ---------------------------------------------------------------------------------------
# Drake wrapper.
# ---------------------------------------------------------------------------------------


class InvariantEkfBaseStateEstimator(LeafSystem):
    """Floating-base state estimate from IMU, encoders and foot contact (the InEKF above).

    A drop-in replacement for ``systems.simulation.sensors.BaseStateEstimator``'s outputs.
    Every ``period`` seconds it reads its inputs, corrects with the kinematics of the feet in
    contact (E6-E9), then propagates over ``period`` with the IMU sample (E1-E5): the state
    at t_k + period is the prediction for that time. The outputs depend on the state only.

    Inputs:
        angular_velocity: gyro, ω of the IMU frame I expressed in I, rad/s (3)
            (``Imu.angular_velocity``).
        linear_acceleration: accelerometer, specific force R_WIᵀ (a_WIo − g) in I, m/s² (3)
            (``Imu.linear_acceleration``).
        joint_positions: n = nv − 6 encoder positions in the plant's v[6:] joint order (the
            ``JointEncoders`` ``position`` output), rad (m).
        foot_contact: one flag per foot of ``foot_frames`` (> 0.5: in contact).

    Outputs:
        base_pose: 7, the free joint's q layout: quaternion [w, x, y, z] of R_WB, then p_WBo, m.
        base_velocity: 6, the free joint's v layout: [ω_WB; v_WBo] in world, rad/s and m/s (E10).
        valid: 1, 1.0 when at least one foot was in contact at the last update (its point is
            in the state and anchors it; with the slip test, one not slipping), 0.0 when the
            filter runs on the IMU alone.
        standard_deviation: 9, sqrt of P's diagonal for ξ_R (rad), ξ_v (m/s), ξ_p (m)
            (always 9, with or without bias states).
        imu_bias: 6, the bias estimate [b̄_g (rad/s); b̄_a (m/s²)] in the IMU frame I, the
            amounts subtracted from the gyro and accelerometer (E11); 0 without bias states.
        imu_bias_standard_deviation: 6, sqrt of P's diagonal for ζ_g (rad/s) and ζ_a
            (m/s²); 0 without bias states (the bias is then taken as known, 0).
        foot_speed: one per foot, |w_j| of the slip test (E13), m/s (0 for a foot not in
            contact at the last two updates, and always without the test).
        slip_count: one per foot, the updates whose correction of that foot was dropped as a
            slip (E13) since the start (0 without the test).

    With bias states the output angular velocity uses the corrected gyro ω̃ − b̄_g.
    Every input is checked: NaN or inf raises a ValueError naming the port.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        imu_frame: Frame,
        foot_frames: Sequence[Frame],
        *,
        initial_base_pose: np.ndarray | None = None,
        initial_base_velocity: np.ndarray | None = None,
        period: float = 1e-3,
        gyro_noise_density: float = GYRO_NOISE_DENSITY,
        accel_noise_density: float = ACCEL_NOISE_DENSITY,
        contact_noise_density: float = CONTACT_NOISE_DENSITY,
        kinematics_noise_std: float = KINEMATICS_NOISE_STD,
        initial_orientation_std: float = INITIAL_ORIENTATION_STD,
        initial_velocity_std: float = INITIAL_VELOCITY_STD,
        initial_position_std: float = INITIAL_POSITION_STD,
        estimate_imu_bias: bool = False,
        gyro_bias_random_walk: float = GYRO_BIAS_RANDOM_WALK,
        accel_bias_random_walk: float = ACCEL_BIAS_RANDOM_WALK,
        initial_gyro_bias_std: float = INITIAL_GYRO_BIAS_STD,
        initial_accel_bias_std: float = INITIAL_ACCEL_BIAS_STD,
        initial_imu_bias: np.ndarray | None = None,
        level_ground_tilt_std: float | None = None,
        level_ground_period: float = LEVEL_GROUND_PERIOD,
        slip_speed: float | None = None,
        at_rest_duration: float | None = None,
    ):
        """Args:
            plant: a finalized floating-base plant (for forward kinematics and gravity).
            imu_frame: the IMU frame I, fixed in the base body.
            foot_frames: the foot points' frames (e.g. the sole frames), one per contact flag.
            initial_base_pose: 7, the free joint's q at the start; default the plant's
                default free-joint pose (use :meth:`SetInitialBaseState` on a context).
            initial_base_velocity: 6, default 0.
            period: update period, s (default 1 ms).
            gyro_noise_density ... initial_accel_bias_std: see :class:`ContactAidedInvariantEkf`
                (``estimate_imu_bias`` False, the default: the bias-free filter).
            initial_imu_bias: 6, the bias estimate the filter starts from (and
                :meth:`SetInitialBaseState` resets to), [b_g, rad/s; b_a, m/s²] in the IMU
                frame, e.g. measured at rest (``diagrams.residuals.log_estimation.
                at_rest_imu_bias``); default 0. Only with ``estimate_imu_bias``.
            level_ground_tilt_std: σ_t of the level-ground correction (E12), rad: the feet
                in contact are flat on a level floor (their frames' z axes are the sole
                normals). None (default): no such correction.
            level_ground_period: s between level-ground corrections (default 0.1 s), rounded
                to the nearest multiple of ``period`` (at least one): a log at 99 Hz (10.104 ms)
                corrects every 10 updates, 101 ms (``level_ground_period_used``). A sole's tilt
                error (floor, sole rocking) is slow, not white: fused at 1 kHz it would count a
                thousand times a second.
            slip_speed: the slip test (E13), m/s: a foot flagged in contact whose world
                velocity, from the predicted state and the encoders and low-passed over
                ``SLIP_SPEED_TIME_CONSTANT``, exceeds it slips or rolls, and its kinematic
                correction is dropped (the foot leaves the state, E9) until it is below it
                again, when it is re-anchored where it stands (E8). None (default): no test,
                every flagged foot corrects (the online station's filter). ``SLIP_SPEED``
                (0.1 m/s) is the logs' default (``EkfSettings.slip_speed``).
            at_rest_duration: s, the robot stands still for this long from its start (the
                online counterpart of a log's ``at_rest_imu_bias``, causal): the filter
                runs and averages the gyro and accelerometer meanwhile; at the window's end
                its gyro bias about the vertical becomes the mean reading's (its variance
                the standard error's) and the yaw that bias turned the estimate by over the
                window is turned back. With bias states only. None (default): no window.

        Raises:
            ValueError: bad plant or frames, bad noise parameters or period, an
                ``at_rest_duration`` without bias states or shorter than two periods.
        """
        super().__init__()
        who = "InvariantEkfBaseStateEstimator"
        self._who = who
        check_plant(plant, who)
        topology = floating_base_topology(plant)
        frames = list(foot_frames)
        if not frames:
            raise ValueError(f"{who}: foot_frames is empty")
        for f in [imu_frame, *frames]:
            if not isinstance(f, Frame) or f.GetParentPlant() is not plant:
                raise ValueError(f"{who}: {f!r} is not a frame of this plant")
        if imu_frame.body().index() != topology.base_frame.body().index():
            raise ValueError(f"{who}: the IMU frame {imu_frame.name()!r} is not fixed in the base body")
        self._period = positive_number(period, f"{who}: period")
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._imu_frame = imu_frame
        self._foot_frames = tuple(frames)
        self._q_index = np.array([j.position_start() for j in topology.joints], dtype=int)
        self._positions = plant.GetPositions(self._plant_context)  # q of the foot kinematics
        X_BI = imu_frame.CalcPose(self._plant_context, topology.base_frame)
        self._R_BI = X_BI.rotation().matrix()
        self._p_BI = X_BI.translation().copy()
        q0 = topology.free_joint.position_start()
        if initial_base_pose is None:
            initial_base_pose = plant.GetPositions(self._plant_context)[q0 : q0 + 7]
        self._core = ContactAidedInvariantEkf(
            len(frames),
            gravity=np.asarray(plant.gravity_field().gravity_vector(), dtype=float),
            gyro_noise_density=gyro_noise_density,
            accel_noise_density=accel_noise_density,
            contact_noise_density=contact_noise_density,
            kinematics_noise_std=kinematics_noise_std,
            initial_orientation_std=initial_orientation_std,
            initial_velocity_std=initial_velocity_std,
            initial_position_std=initial_position_std,
            estimate_imu_bias=estimate_imu_bias,
            gyro_bias_random_walk=gyro_bias_random_walk,
            accel_bias_random_walk=accel_bias_random_walk,
            initial_gyro_bias_std=initial_gyro_bias_std,
            initial_accel_bias_std=initial_accel_bias_std,
        )
        self._initial_bias = None
        if initial_imu_bias is not None:
            bias = np.asarray(initial_imu_bias, dtype=float).reshape(-1)
            if not estimate_imu_bias:
                raise ValueError(f"{who}: initial_imu_bias given without estimate_imu_bias")
            if bias.shape != (6,) or not np.isfinite(bias).all():
                raise ValueError(f"{who}: initial_imu_bias must be 6 finite numbers, got {initial_imu_bias!r}")
            self._initial_bias = bias
        self._tilt_std = None
        if level_ground_tilt_std is not None:
            self._tilt_std = positive_number(level_ground_tilt_std, f"{who}: level_ground_tilt_std")
        every = positive_number(level_ground_period, f"{who}: level_ground_period") / self._period
        self._level_ground_every = max(1, int(round(every)))
        self._slip_speed = None
        if slip_speed is not None:
            self._slip_speed = positive_number(slip_speed, f"{who}: slip_speed")
        self._rest_steps = 0
        if at_rest_duration is not None:
            duration = positive_number(at_rest_duration, f"{who}: at_rest_duration")
            if not estimate_imu_bias:
                raise ValueError(f"{who}: at_rest_duration needs estimate_imu_bias (the bias it measures)")
            self._rest_steps = int(round(duration / self._period))
            if self._rest_steps < 2:
                raise ValueError(f"{who}: at_rest_duration {duration} s is shorter than two periods")
        # The slip test's low-pass gain per update (E13).
        self._slip_alpha = min(1.0, self._period / SLIP_SPEED_TIME_CONSTANT)
        x0 = self._initial_state(initial_base_pose, initial_base_velocity)
        n = topology.num_joints
        self._omega = self.DeclareVectorInputPort("angular_velocity", 3)
        self._accel = self.DeclareVectorInputPort("linear_acceleration", 3)
        self._joints = self.DeclareVectorInputPort("joint_positions", n)
        self._contact = self.DeclareVectorInputPort("foot_contact", len(frames))
        # Discrete state groups: the filter (the core's state_vector, with the bias estimate
        # when on), the last gyro sample, bias-corrected (3, rad/s, for the output angular
        # velocity), valid (1: a foot in contact) and the gyro mean (3, below).
        self._filter_index = self.DeclareDiscreteState(x0[0])
        self._gyro_index = self.DeclareDiscreteState(x0[1])
        self._valid_index = self.DeclareDiscreteState(x0[2])
        # The soles' world normals R̄ n_j at the last level-ground update (K x 3; zero rows:
        # unknown): E12 uses the feet whose soles have not turned since.
        self._normals_index = self.DeclareDiscreteState(np.zeros(3 * len(frames)))
        # The slip test's state (E13, ``invariant_ekf_steps.foot_slip_step``): the feet's
        # world points u_j at the last update (3 K, m), their low-passed velocities w_j (3 K,
        # m/s), flagged at the last update (K), and the updates dropped as a slip (K).
        self._slip_index = self.DeclareDiscreteState(np.zeros(8 * len(frames)))
        # The at-rest window: [updates seen, sum of the gyro (3), of its squares (3), of the
        # specific force (3)] (IMU frame; the count stops at the window's length + 1).
        self._rest_index = self.DeclareDiscreteState(np.zeros(10))
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        xd = {self.xd_ticket()}
        # The base pose and velocity (E10), computed once per state for both outputs.
        self._base_state = self.DeclareCacheEntry(
            "base pose and velocity",
            ValueProducer(allocate=lambda: AbstractValue.Make(np.zeros(13)), calc=self._CalcBaseState),
            prerequisites_of_calc=xd,
        )
        self.DeclareVectorOutputPort("base_pose", 7, self._CalcPose, prerequisites_of_calc=xd)
        self.DeclareVectorOutputPort("base_velocity", 6, self._CalcVelocity, prerequisites_of_calc=xd)
        self.DeclareVectorOutputPort("valid", 1, self._CalcValid, prerequisites_of_calc=xd)
        self.DeclareVectorOutputPort("standard_deviation", 9, self._CalcStd, prerequisites_of_calc=xd)
        self.DeclareVectorOutputPort("imu_bias", 6, self._CalcBias, prerequisites_of_calc=xd)
        self.DeclareVectorOutputPort("imu_bias_standard_deviation", 6, self._CalcBiasStd, prerequisites_of_calc=xd)
        K = len(frames)
        self.DeclareVectorOutputPort(
            "foot_speed", K, lambda c, o: self._CalcSlipPart(c, o, "speed"), prerequisites_of_calc=xd
        )
        self.DeclareVectorOutputPort(
            "slip_count", K, lambda c, o: self._CalcSlipPart(c, o, "count"), prerequisites_of_calc=xd
        )

    @property
    def period(self) -> float:
        return self._period

    @property
    def foot_frames(self) -> tuple:
        return self._foot_frames

    @property
    def estimates_imu_bias(self) -> bool:
        """True with the IMU bias states (E11)."""
        return self._core.estimates_imu_bias

    @property
    def level_ground_period_used(self) -> float:
        """The period of the level-ground correction, s: ``level_ground_period`` rounded to a
        multiple of the update period."""
        return self._level_ground_every * self._period

    def _initial_state(self, base_pose, base_velocity) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        who = self._who
        pose = np.asarray(base_pose, dtype=float).reshape(-1)
        velocity = np.zeros(6) if base_velocity is None else np.asarray(base_velocity, dtype=float).reshape(-1)
        if pose.shape != (7,) or not np.isfinite(pose).all() or np.linalg.norm(pose[:4]) < 1e-9:
            raise ValueError(f"{who}: initial base pose must be 7 finite numbers with a non-zero quaternion")
        if velocity.shape != (6,) or not np.isfinite(velocity).all():
            raise ValueError(f"{who}: initial base velocity must be 6 finite numbers")
        R, p, v = base_to_imu(pose, velocity, self._R_BI, self._p_BI)
        self._core.reset(R, v, p, imu_bias=self._initial_bias)
        return self._core.state_vector(), velocity[:3] @ R, np.zeros(1)

    def SetInitialBaseState(
        self, context: Context, base_pose: np.ndarray, base_velocity: np.ndarray | None = None
    ) -> None:
        """Resets the filter in ``context`` (this system's) to a base pose (7) and velocity (6)."""
        for index, value in zip(
            (self._filter_index, self._gyro_index, self._valid_index), self._initial_state(base_pose, base_velocity)
        ):
            context.SetDiscreteState(index, value)
        context.SetDiscreteState(self._normals_index, np.zeros(3 * len(self._foot_frames)))
        context.SetDiscreteState(self._slip_index, np.zeros(8 * len(self._foot_frames)))
        context.SetDiscreteState(self._rest_index, np.zeros(10))

    @property
    def level_ground_tilt_std(self) -> float | None:
        """σ_t of the level-ground correction (E12), rad; None when off."""
        return self._tilt_std

    @property
    def slip_speed(self) -> float | None:
        """The slip test's speed threshold (E13), m/s; None when off."""
        return self._slip_speed

    def _foot_kinematics(
        self, joint_positions: np.ndarray, with_normals: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """h_j, the foot frames' origins in the IMU frame, m (K x 3) (E6), and n_j, their z
        axes in the IMU frame (K x 3) (E12; None unless ``with_normals``)."""
        q = self._positions  # the base's part stays the default pose: only relative poses are read
        q[self._q_index] = joint_positions
        self._plant.SetPositions(self._plant_context, q)
        poses = [f.CalcPose(self._plant_context, self._imu_frame) for f in self._foot_frames]
        h = np.array([X.translation() for X in poses])
        normals = np.array([X.rotation().matrix()[:, 2] for X in poses]) if with_normals else None
        return h, normals

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        who = self._who
        omega = eval_finite_input(who, self._omega, context)
        accel = eval_finite_input(who, self._accel, context)
        joints = eval_finite_input(who, self._joints, context)
        flags = eval_finite_input(who, self._contact, context) > 0.5
        core = self._core
        x = context.get_discrete_state(self._filter_index).value()
        if self._rest_steps:
            rest = context.get_discrete_state(self._rest_index).value()
            if rest[0] < self._rest_steps:  # at rest: average the IMU (the filter runs on)
                discrete_state.set_value(self._rest_index, rest + np.concatenate(([1.0], omega, omega**2, accel)))
            elif rest[0] == self._rest_steps:  # the window is over
                discrete_state.set_value(self._rest_index, rest + np.eye(10)[0])
                x = self._vertical_gyro_bias_from_rest(x, rest)
        step = int(round(context.get_time() / self._period))
        level_ground = self._tilt_std is not None and step % self._level_ground_every == 0
        if flags.any():
            h, normals = self._foot_kinematics(joints, with_normals=level_ground)
        else:
            h = normals = np.zeros((core.num_feet, 3))
        world_normals = context.get_discrete_state(self._normals_index).value()
        if self._slip_speed is not None:
            # E13: the feet that slip are left out of the correction (and the state).
            R, _, p = core.navigation_state(x)
            slip, flags = steps.foot_slip_step(
                np.array(R), np.array(p), np.ascontiguousarray(h, dtype=float), flags,
                np.array(context.get_discrete_state(self._slip_index).value()),
                self._slip_alpha, self._period, self._slip_speed,
            )  # fmt: skip
            discrete_state.set_value(self._slip_index, slip)
        if not level_ground:
            # Most steps: the correction (E6-E9) and the propagation in one compiled call.
            x = core.correct_and_propagate(x, h, flags, omega, accel, self._period)
        else:
            core.set_state_vector(x)
            core.correct_kinematics(h, flags)  # with no flag set this only removes feet (E9)
            # E12 on the feet in contact whose soles turned by less than the rate limit
            # since the previous update (a zero row: no previous normal, not still).
            previous = world_normals.reshape(-1, 3)
            turned = np.linalg.norm(normals @ core.rotation.T - previous, axis=1)
            still = (np.linalg.norm(previous, axis=1) > 0.5) & (
                turned < LEVEL_GROUND_MAX_RATE * self._level_ground_every * self._period
            )
            core.correct_level_ground(normals, self._tilt_std, still=still)
            world_normals = (normals @ core.rotation.T if flags.any() else np.zeros_like(normals)).reshape(-1)
            core.propagate(omega, accel, self._period)
            x = core.state_vector()
        # The propagation changes neither the feet in the state nor the bias estimate: both
        # are read from the new state, as the correction left them.
        valid = 1.0 if core.in_contact_of(x).any() else 0.0
        # The gyro sample of the output angular velocity, corrected by the bias this
        # propagation used (E11).
        omega_corrected = omega - core.imu_bias_of(x)[:3] if core.estimates_imu_bias else omega
        discrete_state.set_value(self._filter_index, x)
        discrete_state.set_value(self._gyro_index, omega_corrected)
        discrete_state.set_value(self._valid_index, [valid])
        discrete_state.set_value(self._normals_index, world_normals)

    def _vertical_gyro_bias_from_rest(self, x: np.ndarray, rest: np.ndarray) -> np.ndarray:
        """The filter state ``x`` at the end of the at-rest window whose sums are ``rest``:
        its gyro bias about the vertical (the measured specific force's direction) set to
        the mean gyro reading's component (as ``imu_bias_at_rest``; the only bias the filter
        cannot observe standing on flat ground, E11), and the yaw the filter integrated from
        that bias over the window turned back. The horizontal components stay the filter's
        (gravity and the level ground observe them, and a robot settling on its feet at the
        start rotates about them: its mean rate is not all bias)."""
        n = rest[0]
        gyro_mean = rest[1:4] / n
        variance = np.maximum(rest[4:7] - n * gyro_mean**2, 0.0) / (n - 1.0)
        up = rest[7:10] / np.linalg.norm(rest[7:10])  # in I; at rest the specific force is -g
        core = self._core
        core.set_state_vector(x)
        vertical_bias = float(up @ gyro_mean)
        drift = vertical_bias - float(up @ core.imu_bias_of(x)[:3])  # rad/s integrated as yaw rate
        standard_error = math.sqrt(float(up**2 @ variance) / n)
        core.set_gyro_bias_along(up, vertical_bias, math.hypot(standard_error, STILL_GYRO_BIAS_STD_FLOOR))
        core.rotate_about_vertical(-drift * n * self._period)
        return core.state_vector()

    @property
    def at_rest_duration(self) -> float | None:
        """The at-rest window, s (a whole number of periods); None when off."""
        return self._rest_steps * self._period if self._rest_steps else None

    def _CalcBaseState(self, context: Context, value: AbstractValue) -> None:
        # imu_to_base (E10): [base_pose (7); base_velocity (6)].
        R, v, p = self._core.navigation_state(context.get_discrete_state(self._filter_index).value())
        R_WB = R @ self._R_BI.T
        r = R_WB @ self._p_BI  # p_BoIo_W
        omega_W = R @ context.get_discrete_state(self._gyro_index).value()
        value.set_value(np.concatenate([rotation_to_quaternion(R_WB), p - r, omega_W, v - cross(omega_W, r)]))

    def _CalcPose(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._base_state.Eval(context)[:7])

    def _CalcVelocity(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._base_state.Eval(context)[7:])

    def _CalcValid(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(context.get_discrete_state(self._valid_index).value())

    def _CalcStd(self, context: Context, output: BasicVector) -> None:
        P = self._core.covariance_of(context.get_discrete_state(self._filter_index).value())
        output.SetFromVector(np.sqrt(np.maximum(np.diag(P)[:9], 0.0)))

    def _CalcSlipPart(self, context: Context, output: BasicVector, part: str) -> None:
        K = len(self._foot_frames)
        slip = context.get_discrete_state(self._slip_index).value()
        if part == "speed":
            output.SetFromVector(np.linalg.norm(slip[3 * K : 6 * K].reshape(K, 3), axis=1))
        else:
            output.SetFromVector(slip[7 * K :])

    def _CalcBias(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._core.imu_bias_of(context.get_discrete_state(self._filter_index).value()))

    def _CalcBiasStd(self, context: Context, output: BasicVector) -> None:
        if not self._core.estimates_imu_bias:
            output.SetFromVector(np.zeros(6))
            return
        P = self._core.covariance_of(context.get_discrete_state(self._filter_index).value())
        output.SetFromVector(np.sqrt(np.maximum(np.diag(P)[-6:], 0.0)))


__all__ = [
    "ContactAidedInvariantEkf",
    "FootContactFromForceTorque",
    "FootContactFromFsr",
    "InvariantEkfBaseStateEstimator",
    "base_to_imu",
    "contact_flags_from_fsr",
    "contact_flags_from_wrenches",
    "contact_flags_with_hysteresis",
    "ContactHysteresis",
    "CONTACT_ON_WEIGHT_FRACTION",
    "CONTACT_OFF_WEIGHT_FRACTION",
    "imu_to_base",
    "load_compiled_filter_steps",
    "rotation_to_quaternion",
    "so3_exp",
    "so3_gamma",
]
