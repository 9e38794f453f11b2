"""Realistic imperfections of the simulated robot, each an option that is OFF by default.

``Imperfections()`` is the ideal robot (every field 0: the station is bit-identical to one
built without imperfections); ``Imperfections.realistic()`` returns the documented values
below. The groups:

* :class:`ImuImperfections`: white noise and a bias random walk on the gyroscope and the
  accelerometer (Kalibr's IMU noise model: sigma_d = N / sqrt(T) for white noise of
  density N sampled every T seconds; bias b(t) with std sigma_b sqrt(t)).
* :class:`EncoderImperfections`: quantisation of the joint positions (an absolute encoder
  of ``bits`` bits per joint turn).
* :class:`FrictionImperfections`: Coulomb + viscous joint friction in the SIMULATED plant,
  which the estimators do not model (see :class:`JointFriction`).
* :class:`TorqueSensorImperfections`: a per-joint scale and offset error of the
  motor-torque estimate (what the residuals read as the applied torque).
* :class:`ModelMismatch`: the estimators' (and the PD's gravity) model has every link's
  mass, centre of mass and rotational inertia perturbed (``perturbed_spatial_inertias``);
  the simulated plant stays nominal.

The errors drawn once (torque-sensor scale/offset, model mismatch) are a pure function of
``Imperfections.seed`` and the group; the IMU bias walks are time signals seeded like the
sensor noise (the station's ``seed``), see ``systems.simulation.sensors.add_imu``. The dataclasses load from YAML
with ``yaml_load_typed`` (no tuples; this module deliberately has no ``from __future__
import annotations``). All units SI; "percent" fields are in [0, 100).
"""

import math
from dataclasses import dataclass, field, fields

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, JointActuatorIndex, RotationalInertia, SpatialInertia
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from systems.common.checks import check_finite_input, check_plant, per_joint, positive_number
from systems.common.topology import floating_base_topology
from systems.simulation.noise import check_seed

#: Seed streams of the groups: np.random.default_rng([seed, GROUP_STREAMS[group]]).
GROUP_STREAMS = {"torque_sensor": 3, "model_mismatch": 4}

_DEG = math.pi / 180.0
#: The realistic IMU's gyro turn-on bias per axis (x, y, z of the IMU frame), deg/s: within
#: the 0.1-0.5 deg/s of real humanoid IMUs, the largest about the vertical.
REALISTIC_GYRO_BIAS_DEG_S = (0.12, -0.08, 0.35)
_G = 9.80665  # m/s^2 (standard gravity, for datasheet figures in g)


@dataclass
class ImuImperfections:
    """Gyroscope and accelerometer noise beyond the ideal IMU.

    Attributes:
        gyro_noise_density: white-noise density N_g, rad/s/sqrt(Hz); > 0 replaces the
            sensor suite's gyro std by N_g / sqrt(T) (T = the 1 ms sensor period).
            Realistic: 0.014 deg/s/sqrt(Hz) = 2.44e-4 (Bosch BMI088 datasheet,
            BST-BMI088-DS001, gyroscope noise density, typ.).
        gyro_bias_random_walk: sigma_bg, rad/s^2/sqrt(Hz) (rad/s per sqrt(s)): the gyro
            bias is a random walk with std sigma_bg sqrt(t). Realistic: 1.9393e-5 (the
            ADIS16448 value of the EuRoC MAV dataset's sensor.yaml, Burri et al., IJRR
            2016, a Kalibr Allan-variance figure; the BMI088 datasheet gives no random
            walk).
        accel_noise_density: N_a, m/s^2/sqrt(Hz); > 0 replaces the suite's accelerometer
            std by N_a / sqrt(T). Realistic: 175 ug/sqrt(Hz) = 1.716e-3 (BMI088 datasheet,
            accelerometer noise density in the +-3 g range, typ.).
        accel_bias_random_walk: sigma_ba, m/s^3/sqrt(Hz). Realistic: 3.0e-3 (EuRoC
            sensor.yaml, ADIS16448).
        gyro_bias_x, gyro_bias_y, gyro_bias_z: the gyro's constant turn-on bias per IMU
            axis, rad/s (any sign), from the start of the run (the bias walk starts there).
            Real humanoid IMUs show 0.1-0.5 deg/s (e.g. the BMI088's zero-rate offset is
            +-1 deg/s max. after soldering). Realistic: ``REALISTIC_GYRO_BIAS_DEG_S``,
            (0.12, -0.08, 0.35) deg/s, the largest about the vertical, to which the EKF is
            blind standing on flat ground (the station's filter measures it over the
            robot's still start, ``InvariantEkfBaseStateEstimator``'s ``at_rest_duration``;
            the log test bed ``diagrams.locomotion.walking_log`` uses the same values).
    """

    gyro_noise_density: float = 0.0
    gyro_bias_random_walk: float = 0.0
    accel_noise_density: float = 0.0
    accel_bias_random_walk: float = 0.0
    gyro_bias_x: float = 0.0
    gyro_bias_y: float = 0.0
    gyro_bias_z: float = 0.0

    def gyro_turn_on_bias(self) -> np.ndarray:
        """(3,) rad/s: [gyro_bias_x, gyro_bias_y, gyro_bias_z]."""
        return np.array([self.gyro_bias_x, self.gyro_bias_y, self.gyro_bias_z], dtype=float)


@dataclass
class EncoderImperfections:
    """Joint-position quantisation.

    Attributes:
        bits: resolution of an absolute encoder on the joint, bits per turn: the position
            reads step * round(q / step) with step = 2 pi / 2^bits rad (applied after the
            suite's position noise; prismatic joints: step in m). 0 = no quantisation.
            The velocities are unchanged (they stand for a filtered velocity estimate,
            with the suite's velocity noise). Realistic: 14 (e.g. ams AS5047P, 14-bit
            magnetic absolute encoder: 3.8e-4 rad steps).
    """

    bits: int = 0

    @property
    def step(self) -> float:
        """The quantisation step, rad (0 when ``bits`` is 0)."""
        return 0.0 if self.bits == 0 else 2.0 * math.pi / 2.0**self.bits


@dataclass
class FrictionImperfections:
    """Joint friction in the simulated plant (not modelled by the estimators).

    tau_f = -(F_c tanh(v / v_s) + b v) on every actuated joint, with F_c and b a fraction of
    the joint's rated torque tau_r, taken as its actuator's effort limit
    (``JointActuator.effort_limit()``; HRP-4-like: 2-200 N m, Nao-like: the model's limits).

    Attributes:
        coulomb_percent: F_c = coulomb_percent / 100 * tau_r, N m. Realistic: 3 (assumed: a
            few percent of rated torque, the order of harmonic-drive joint friction).
        viscous_percent: b = viscous_percent / 100 * tau_r / (1 rad/s), N m s/rad (the
            viscous torque at 1 rad/s in percent of tau_r). Realistic: 2 (assumed).
        smoothing_velocity: v_s, rad/s (> 0): the Coulomb term is smoothed for the discrete
            solver. The friction is explicit (evaluated at x_k), so v_s must keep
            F_c T / (v_s M_kk) well below 2: 0.1 rad/s gives <= 0.6 on both robots.
    """

    coulomb_percent: float = 0.0
    viscous_percent: float = 0.0
    smoothing_velocity: float = 0.1


@dataclass
class TorqueSensorImperfections:
    """Scale and offset errors of the motor-torque estimate (current x torque constant).

    measured_k = (1 + s_k) tau_k + o_k on actuated joint k, with s_k ~ N(0, (scale/100)^2)
    and o_k ~ N(0, (offset/100 tau_r,k)^2) drawn once per joint (seeded); unactuated joints
    read 0.

    Attributes:
        scale_error_percent: std of s_k, percent. Realistic: 5 (assumed: torque-constant
            tolerance plus gear efficiency, the order of current-based torque estimates).
        offset_percent: std of o_k, percent of the rated torque tau_r,k (see
            FrictionImperfections). Realistic: 1 (assumed).
    """

    scale_error_percent: float = 0.0
    offset_percent: float = 0.0


@dataclass
class ModelMismatch:
    """The estimators' model differs from the simulated robot (seeded, per link).

    Each link's mass is scaled by (1 +- p_m), its centre of mass moved by p_c times its
    central radius of gyration in a random direction, and each of its three central second
    moments of mass (principal axes kept) scaled by (1 +- p_I), random signs: the inertia
    stays physically valid (positive definite, triangle inequality). Applied to
    ``HumanoidStation.dynamics_model`` (residuals, observer and the PD's gravity).

    Attributes:
        mass_percent: p_m, percent. Realistic: 5 (assumed: CAD vs identified link masses).
        com_percent: p_c, percent of the radius of gyration. Realistic: 10 (assumed).
        inertia_percent: p_I, percent. Realistic: 10 (assumed).
    """

    mass_percent: float = 0.0
    com_percent: float = 0.0
    inertia_percent: float = 0.0


@dataclass
class Imperfections:
    """All imperfections; the default is the ideal robot (see the module docstring).

    Attributes:
        imu, encoders, friction, torque_sensor, model_mismatch: the groups.
        seed: non-negative integer for the errors drawn once (torque sensor, model
            mismatch); the IMU bias walks follow the station's sensor seed.
    """

    imu: ImuImperfections = field(default_factory=ImuImperfections)
    encoders: EncoderImperfections = field(default_factory=EncoderImperfections)
    friction: FrictionImperfections = field(default_factory=FrictionImperfections)
    torque_sensor: TorqueSensorImperfections = field(default_factory=TorqueSensorImperfections)
    model_mismatch: ModelMismatch = field(default_factory=ModelMismatch)
    seed: int = 0

    @classmethod
    def realistic(cls, seed: int = 0) -> "Imperfections":
        """The documented realistic values of every group (see their docstrings)."""
        return cls(
            imu=ImuImperfections(
                gyro_noise_density=0.014 * _DEG,
                gyro_bias_random_walk=1.9393e-5,
                accel_noise_density=175e-6 * _G,
                accel_bias_random_walk=3.0e-3,
                gyro_bias_x=REALISTIC_GYRO_BIAS_DEG_S[0] * _DEG,
                gyro_bias_y=REALISTIC_GYRO_BIAS_DEG_S[1] * _DEG,
                gyro_bias_z=REALISTIC_GYRO_BIAS_DEG_S[2] * _DEG,
            ),
            encoders=EncoderImperfections(bits=14),
            friction=FrictionImperfections(coulomb_percent=3.0, viscous_percent=2.0, smoothing_velocity=0.1),
            torque_sensor=TorqueSensorImperfections(scale_error_percent=5.0, offset_percent=1.0),
            model_mismatch=ModelMismatch(mass_percent=5.0, com_percent=10.0, inertia_percent=10.0),
            seed=seed,
        )

    def validate(self) -> "Imperfections":
        """Returns self; raises ValueError naming the field (e.g. ``imperfections.imu.
        gyro_noise_density``) for a NaN/inf, a negative std or density, a percentage outside
        [0, 100), a non-positive smoothing velocity, bits outside 0..52 or a bad seed."""
        check_seed(self.seed, "imperfections.seed")
        if not isinstance(self.encoders, EncoderImperfections):
            raise ValueError(f"imperfections.encoders must be an EncoderImperfections, got {self.encoders!r}")
        _check_int(self.encoders.bits, "imperfections.encoders.bits", 0, 52)
        for name, kind in _GROUPS.items():
            group = getattr(self, name)
            if not isinstance(group, kind):
                raise ValueError(f"imperfections.{name} must be a {kind.__name__}, got {type(group).__name__}")
            for f in fields(group):
                path = f"imperfections.{name}.{f.name}"
                value = _check_number(getattr(group, f.name), path)
                if f.name.endswith("_percent") and not 0.0 <= value < 100.0:
                    raise ValueError(f"{path} must be a percentage in [0, 100), got {value!r}")
                if f.name == "smoothing_velocity" and not value > 0.0:
                    raise ValueError(f"{path} must be > 0 rad/s, got {value!r}")
                if value < 0.0 and not f.name.startswith("gyro_bias_"):
                    raise ValueError(f"{path} must be >= 0, got {value!r}")
        return self

    @property
    def is_ideal(self) -> bool:
        """True when no imperfection is on."""
        return (
            not any(getattr(self.imu, f.name) for f in fields(self.imu))
            and self.encoders.bits == 0
            and not (self.friction.coulomb_percent or self.friction.viscous_percent)
            and not any(getattr(self.torque_sensor, f.name) for f in fields(self.torque_sensor))
            and not any(getattr(self.model_mismatch, f.name) for f in fields(self.model_mismatch))
        )


_GROUPS = {
    "imu": ImuImperfections,
    "friction": FrictionImperfections,
    "torque_sensor": TorqueSensorImperfections,
    "model_mismatch": ModelMismatch,
}


def _check_number(value, path: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{path} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{path} must be finite, got {value!r}")
    return value


def _check_int(value, path: str, low: int, high: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{path} must be an integer, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{path} must be in [{low}, {high}], got {value!r}")
    return int(value)


def group_rng(seed: int, group: str) -> np.random.Generator:
    """The random generator of one group (``GROUP_STREAMS``) for ``Imperfections.seed``."""
    return np.random.default_rng([int(seed), GROUP_STREAMS[group]])


# ---------------------------------------------------------------------------------------
# Per-joint values.
# ---------------------------------------------------------------------------------------


def rated_joint_torques(plant: MultibodyPlant) -> np.ndarray:
    """tau_r per joint in v[6:] order, N m (N): the effort limit of the joint's actuator, 0
    for unactuated joints.

    Raises:
        ValueError: an actuated joint without a finite effort limit.
    """
    check_plant(plant, "rated_joint_torques")
    topology = floating_base_topology(plant)
    k_of_joint = {int(j.index()): k for k, j in enumerate(topology.joints)}
    rated = np.zeros(topology.num_joints)
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(JointActuatorIndex(int(index)))
        k = k_of_joint.get(int(actuator.joint().index()))
        limit = actuator.effort_limit()
        if k is None:
            continue
        if not math.isfinite(limit):
            raise ValueError(f"rated_joint_torques: actuator {actuator.name()!r} has no finite effort limit")
        rated[k] = limit
    return rated


def torque_measurement_errors(
    rated: np.ndarray, scale_error_percent: float, offset_percent: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """(scale, offset) per joint: measured = scale * tau + offset (see
    TorqueSensorImperfections); scale = 1 + s, offset in N m; zero rated torque (unactuated)
    gives scale 1, offset 0."""
    rated = np.asarray(rated, dtype=float)
    draws = group_rng(seed, "torque_sensor").standard_normal((2, rated.size))
    actuated = rated > 0.0
    scale = 1.0 + np.where(actuated, 0.01 * scale_error_percent * draws[0], 0.0)
    offset = np.where(actuated, 0.01 * offset_percent * rated * draws[1], 0.0)
    return scale, offset


# ---------------------------------------------------------------------------------------
# Joint friction.
# ---------------------------------------------------------------------------------------


def friction_torque(v: np.ndarray, coulomb: np.ndarray, viscous: np.ndarray, smoothing_velocity: float) -> np.ndarray:
    """tau_f = -(F_c tanh(v / v_s) + b v), N m, per joint (all arrays in the same order)."""
    v = np.asarray(v, dtype=float)
    return -(coulomb * np.tanh(v / smoothing_velocity) + viscous * v)


class JointFriction(LeafSystem):
    """Smoothed Coulomb + viscous friction on the 1-DoF joints of a floating-base plant.

    Inputs:
        state: the plant's state [q; v] (nq + nv).

    Outputs:
        generalized_force: nv entries, N m (N): 0 on the free base, ``friction_torque`` on
            each joint (v[6:] order), for ``plant.get_applied_generalized_force_input_port()``.

    Args:
        plant: a finalized floating-base plant.
        coulomb: F_c per joint (v[6:] order), N m, scalar or n entries, >= 0.
        viscous: b per joint, N m s/rad, scalar or n entries, >= 0.
        smoothing_velocity: v_s, rad/s, > 0.

    Raises:
        ValueError: bad plant or values (naming them).
    """

    def __init__(self, plant: MultibodyPlant, coulomb, viscous, smoothing_velocity: float = 0.1):
        super().__init__()
        who = "JointFriction"
        check_plant(plant, who)
        topology = floating_base_topology(plant)
        n = topology.num_joints
        self.coulomb = per_joint(coulomb, n, "coulomb", who=who, sign="non-negative")
        self.viscous = per_joint(viscous, n, "viscous", who=who, sign="non-negative")
        self.smoothing_velocity = positive_number(smoothing_velocity, f"{who}: smoothing_velocity")
        self._nq = plant.num_positions()
        self._v_index = self._nq + np.array([j.velocity_start() for j in topology.joints], dtype=int)
        self._out_index = self._v_index - self._nq
        self._nv = plant.num_velocities()
        self._state = self.DeclareVectorInputPort("state", self._nq + self._nv)
        self.DeclareVectorOutputPort("generalized_force", self._nv, self._CalcForce)

    def _CalcForce(self, context: Context, output: BasicVector) -> None:
        x = self._state.Eval(context)
        check_finite_input("JointFriction", "state", x)
        tau = np.zeros(self._nv)
        tau[self._out_index] = friction_torque(x[self._v_index], self.coulomb, self.viscous, self.smoothing_velocity)
        output.SetFromVector(tau)


# ---------------------------------------------------------------------------------------
# Model mismatch.
# ---------------------------------------------------------------------------------------


def perturb_spatial_inertia(
    M: SpatialInertia, mass_factor: float, com_shift: np.ndarray, moment_factors: np.ndarray
) -> SpatialInertia:
    """A physically valid perturbation of M_BBo_B (about the body origin, in the body).

    mass m' = mass_factor m; CoM c' = c + com_shift (m, body frame); the central inertia's
    principal second moments of mass d_i = (tr I / 2 - lambda_i) (>= 0 for a real body)
    scaled by ``moment_factors`` (> 0) in the same principal axes, then by mass_factor, so
    I' = R diag(lambda') R^T is positive semi-definite and satisfies the triangle
    inequality."""
    m = M.get_mass()
    c = M.get_com()
    I_cm = M.CalcRotationalInertia().ShiftToCenterOfMass(m, c).CopyToFullMatrix3()
    lam, R = np.linalg.eigh(0.5 * (I_cm + I_cm.T))
    d = 0.5 * lam.sum() - lam  # second moments of mass along the principal axes
    d = np.maximum(d, 0.0) * np.asarray(moment_factors, dtype=float) * mass_factor
    lam_new = d.sum() - d
    I_new = R @ np.diag(lam_new) @ R.T
    m_new = m * mass_factor
    return SpatialInertia.MakeFromCentralInertia(
        m_new, c + np.asarray(com_shift, dtype=float), RotationalInertia(*_moments_products(I_new))
    )


def _moments_products(I: np.ndarray) -> tuple[float, ...]:
    return I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]


def perturbed_spatial_inertias(plant: MultibodyPlant, mismatch: ModelMismatch, seed: int) -> dict[int, SpatialInertia]:
    """{body index: perturbed M_BBo_B} for every body of ``plant`` with mass (the world
    and massless bodies excluded), after ``ModelMismatch`` with random signs and directions
    from ``seed``. Reads the plant's default spatial inertias; the plant is not changed."""
    check_plant(plant, "perturbed_spatial_inertias")
    rng = group_rng(seed, "model_mismatch")
    p_m, p_c, p_i = 0.01 * mismatch.mass_percent, 0.01 * mismatch.com_percent, 0.01 * mismatch.inertia_percent
    out = {}
    for index in range(1, plant.num_bodies()):  # body 0 is the world
        signs = rng.choice([-1.0, 1.0], size=4)  # drawn for every body: stable streams
        direction = rng.standard_normal(3)
        M = plant.get_body(BodyIndex(index)).default_spatial_inertia()
        m = M.get_mass()
        if not (m > 0.0 and math.isfinite(m)):
            continue
        I_cm = M.CalcRotationalInertia().ShiftToCenterOfMass(m, M.get_com()).CopyToFullMatrix3()
        radius = math.sqrt(max(np.trace(I_cm), 0.0) / (2.0 * m))
        direction /= max(np.linalg.norm(direction), 1e-12)
        out[index] = perturb_spatial_inertia(M, 1.0 + p_m * signs[0], p_c * radius * direction, 1.0 + p_i * signs[1:])
    return out


__all__ = [
    "EncoderImperfections",
    "FrictionImperfections",
    "Imperfections",
    "ImuImperfections",
    "JointFriction",
    "ModelMismatch",
    "TorqueSensorImperfections",
    "friction_torque",
    "group_rng",
    "perturb_spatial_inertia",
    "perturbed_spatial_inertias",
    "rated_joint_torques",
    "torque_measurement_errors",
]
