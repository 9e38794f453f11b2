"""Identification of the estimators' dynamic model from a calibration log (issue 11, item 3).

With no unknown contact, the momentum residuals measure model error: what the model says
the robot needs, M vdot + C v - tau_g, differs from what the motors and the F/T sensors
report. This module fits, from a short log of a humanoid standing on its F/T-instrumented
feet and moving slowly, the corrections that remove that difference: the links' masses and
first moments of mass, joint friction, and the motor-torque offset and scale.

Inverse dynamics is linear in the inertial parameters (Atkeson, An, Hollerbach, "Estimation
of inertial parameters of manipulator loads and links", IJRR 5(3), 1986; Khalil & Dombre,
"Modeling, Identification and Control of Robots", 2002, ch. 12). Per body B, with
pi_B = [m, m c_x, m c_y, m c_z, Ixx, Iyy, Izz, Ixy, Ixz, Iyz] (c: CoM in B, m; I: rotational
inertia about the body origin Bo in B, kg m^2), the Newton-Euler wrench the body needs,
[moment about Bo; force] in B, is

    f_B = m (a - g) + alpha x mc + w x (w x mc),
    n_B = I alpha + w x (I w) + mc x (a - g)          = A(w, alpha, a - g) pi_B,     (R1)

with w, alpha the body's angular velocity and acceleration and a the acceleration of Bo,
all in B, g gravity in B. Summed over the bodies with their spatial Jacobians J_B (6 x nv,
[angular; translational of Bo]),

    M vdot + C v - tau_g = sum_B J_B^T A_B pi_B = Y(q, v, vdot) pi                     (R2)

in Drake's generalized coordinates (``plant.CalcInverseDynamics`` minus the gravity
generalized forces). Drake's mass matrix also holds the actuators' reflected inertia
(rotor inertia x gear ratio^2) on the diagonal, and the plant applies its joints' damping
D qdot: both are treated as KNOWN model terms (``known_joint_force``), not parameters.

Calibration equation (one per sample k, nv rows; Gautier's IDIM, "Dynamic identification
of robots with power model", ICRA 1997, with the F/T sensors as in Ayusawa, Venture,
Nakamura, "Identifiability and identification of inertial parameters using the underactuated
base-link dynamics for legged multibody systems", IJRR 33(3), 2014)::

    Y pi + I_r vdot + D qdot + S^T (F_c tanh(qdot / v_s) + b qdot) = S^T tau + sum_s J_s^T W_s,
    tau_m = (1 + s) tau + o.                                                             (R3)

The 6 base rows (Drake's free-joint coordinates: [moment about the base origin; force],
world) hold no joint torque: with the F/T wrenches they pin the inertial parameters
(Ayusawa et al.); the joint rows then give friction, offsets and scales. The joint rows are
fitted as written, tau_m = (1 + s) tau_model(pi, F_c, b) + o, so that the noisy measured
torque stays on the output side (a column of tau_m multiplying 1/(1 + s) would bias s by
its noise: errors in variables); the scale enters bilinearly and is solved EXACTLY (no
linearisation) by Gauss-Newton from s = 0, o = 0 (3 steps to 1e-7 on the tests' logs). The
rotational inertias stay at their nominal values (their columns move to the known side)
unless ``IdentificationOptions.identify_rotational_inertia``. Friction columns are
parallel-filtered like the torques (see ``_filtered_log``).

Only identifiable combinations are solved for: the base parameters of the stacked inertial
columns, by QR with column pivoting (Gautier & Khalil, "Direct calculation of minimum set
of inertial parameters of serial robots", IEEE T-RA 6(3), 1990; Gautier, "Numerical
calculation of the base inertial parameters of robots", J. Robotic Systems 8(4), 1991):
Y P = Q R, rank r, Y_dep = Y_ind beta, pi_base = pi_ind + beta pi_dep. Per-link values are
then the nominal ones plus the minimum-norm deviation (in parameters scaled by the nominal
mass and radius of gyration) that reproduces the identified base parameters: what the data
cannot see keeps its nominal value.
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.linalg
import scipy.signal
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    BodyIndex,
    Frame,
    JacobianWrtVariable,
    JointActuatorIndex,
    RotationalInertia,
    SpatialInertia,
)
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from systems.common.checks import check_plant, eval_finite_input, per_joint, positive_number
from systems.common.topology import floating_base_topology, uniform_gravity
from systems.residuals.contact_estimation import UnknownWrenches
from systems.residuals.offline import ResidualNoiseModel

#: Order of a body's 10 inertial parameters (I about the body origin, body frame).
PARAMETER_NAMES = ("m", "mc_x", "mc_y", "mc_z", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
#: The mass and first-moment parameters (identified by default) and the rotational ones.
MASS_AND_FIRST_MOMENT = (0, 1, 2, 3)
ROTATIONAL = (4, 5, 6, 7, 8, 9)
#: Relative singular-value cut-off of the least-squares solver (numerical zeros only; the
#: weakly excited inertial combinations are handled by the rank tolerance and the prior).
SOLVER_RCOND = 1e-10
#: Most Gauss-Newton steps of the bilinear torque-scale problem, and the relative step size
#: (in the column-normalised unknowns) that ends them (3 steps on the tests' logs).
GAUSS_NEWTON_STEPS = 5
GAUSS_NEWTON_TOLERANCE = 1e-7
#: Weight of the prior rows that hold an unknown at its nominal value (a viscous coefficient
#: the log cannot identify), on the column-normalised unknowns.
PINNED_WEIGHT = 1e6
#: Fewest samples a calibration log may have.
MIN_LOG_SAMPLES = 20
#: The sources of the base twist ``IdentificationOptions.base_velocity`` accepts.
BASE_VELOCITY_SOURCES = ("log", "stance_kinematics")


def _skew(x: np.ndarray) -> np.ndarray:
    """[x]x for a stack (..., 3) of vectors: (..., 3, 3)."""
    out = np.zeros(x.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -x[..., 2], x[..., 1]
    out[..., 1, 0], out[..., 1, 2] = x[..., 2], -x[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -x[..., 1], x[..., 0]
    return out


def _inertia_operator(w: np.ndarray) -> np.ndarray:
    """L(w) (..., 3, 6) with I w = L(w) [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]."""
    out = np.zeros(w.shape[:-1] + (3, 6))
    wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
    out[..., 0, 0], out[..., 0, 3], out[..., 0, 4] = wx, wy, wz
    out[..., 1, 1], out[..., 1, 3], out[..., 1, 5] = wy, wx, wz
    out[..., 2, 2], out[..., 2, 4], out[..., 2, 5] = wz, wx, wy
    return out


def newton_euler_matrix(w: np.ndarray, alpha: np.ndarray, a_minus_g: np.ndarray) -> np.ndarray:
    """A (..., 6, 10) of (R1): the wrench [moment about Bo; force] (body frame) that a body
    with parameters pi_B needs is A pi_B, for w (rad/s), alpha (rad/s^2) and the body
    origin's acceleration minus gravity (m/s^2), all (..., 3) in the body frame."""
    A = np.zeros(w.shape[:-1] + (6, 10))
    W = _skew(w)
    A[..., 3:6, 0] = a_minus_g
    A[..., 3:6, 1:4] = _skew(alpha) + W @ W
    A[..., 0:3, 1:4] = -_skew(a_minus_g)
    A[..., 0:3, 4:10] = _inertia_operator(alpha) + W @ _inertia_operator(w)
    return A


def inertial_parameters(M: SpatialInertia) -> np.ndarray:
    """pi_B (10,) of M_BBo_B in ``PARAMETER_NAMES`` order (kg, kg m, kg m^2)."""
    m = M.get_mass()
    I = M.CalcRotationalInertia()
    return np.concatenate(([m], m * np.asarray(M.get_com()), I.get_moments(), I.get_products()))


def central_unit_inertia(M: SpatialInertia) -> np.ndarray:
    """G_Bcm (3, 3): the rotational inertia about the CoM per unit mass, m^2 (0 if massless)."""
    m = M.get_mass()
    if not m > 0.0:
        return np.zeros((3, 3))
    return M.CalcRotationalInertia().ShiftToCenterOfMass(m, M.get_com()).CopyToFullMatrix3() / m


def _rotational_inertia(I: np.ndarray) -> RotationalInertia:
    return RotationalInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])


class InertialParameterRegressor:
    """Y(q, v, vdot) of (R2) for a floating-base plant: M vdot + C v - tau_g = Y pi.

    Columns: 10 per body, bodies = every body but the world in BodyIndex order (massless
    bodies keep their columns), parameters in ``PARAMETER_NAMES`` order. v and vdot are
    Drake's (as in ``plant.CalcInverseDynamics``); gravity is included. The reflected
    inertia and joint damping of the plant are not in Y: see ``known_joint_force``.

    Args:
        plant: a finalized floating-base MultibodyPlant (double).
    """

    def __init__(self, plant: MultibodyPlant):
        check_plant(plant, "InertialParameterRegressor")
        self.topology = floating_base_topology(plant)
        self.plant = plant
        self.context = plant.CreateDefaultContext()
        self.body_indices = np.arange(1, plant.num_bodies(), dtype=int)
        self.bodies = tuple(plant.get_body(BodyIndex(int(i))) for i in self.body_indices)
        self.num_bodies = len(self.bodies)
        self.num_parameters = 10 * self.num_bodies
        self.num_velocities = plant.num_velocities()
        self._gravity_W = uniform_gravity(plant)
        self._world = plant.world_frame()
        self._origin = np.zeros(3)
        nv = self.num_velocities
        # Known joint terms: reflected inertia (Drake's mass-matrix diagonal) and damping.
        self.reflected_inertia = np.zeros(nv)
        for index in plant.GetJointActuatorIndices():
            actuator = plant.get_joint_actuator(JointActuatorIndex(int(index)))
            start = actuator.joint().velocity_start()
            self.reflected_inertia[start] += actuator.calc_reflected_inertia(self.context)
        self.joint_damping = np.zeros(nv)
        for joint in self.topology.joints:
            self.joint_damping[joint.velocity_start()] = joint.GetDampingVector(self.context)[0]

    def _kinematics(self, q: np.ndarray, v: np.ndarray, vdot: np.ndarray):
        """Sets the state; returns R_WB (nb,3,3), J_W (nb,6,nv) and A_B (nb,6,10)."""
        plant, ctx = self.plant, self.context
        plant.SetPositions(ctx, q)
        plant.SetVelocities(ctx, v)
        poses = plant.get_body_poses_output_port().Eval(ctx)
        velocities = plant.get_body_spatial_velocities_output_port().Eval(ctx)
        accelerations = plant.CalcSpatialAccelerationsFromVdot(ctx, vdot)
        idx = self.body_indices
        R = np.array([poses[i].rotation().matrix() for i in idx])
        kin_W = np.array(
            [
                np.concatenate(
                    (velocities[i].rotational(), accelerations[i].rotational(), accelerations[i].translational())
                )
                for i in idx
            ]
        ).reshape(-1, 3, 3)
        kin_W[:, 2] -= self._gravity_W
        kin_B = np.einsum("bji,bkj->bki", R, kin_W)  # R^T x for w, alpha, a - g
        A = newton_euler_matrix(kin_B[:, 0], kin_B[:, 1], kin_B[:, 2])
        J = np.array(
            [
                plant.CalcJacobianSpatialVelocity(
                    ctx, JacobianWrtVariable.kV, body.body_frame(), self._origin, self._world, self._world
                )
                for body in self.bodies
            ]
        )
        return R, J, A

    def regressor_blocks(self, q: np.ndarray, v: np.ndarray, vdot: np.ndarray) -> np.ndarray:
        """Y as (nv, nb, 10): block [:, b, :] multiplies body b's pi_B."""
        R, J, A = self._kinematics(np.asarray(q, float), np.asarray(v, float), np.asarray(vdot, float))
        F_W = np.concatenate((R @ A[:, 0:3], R @ A[:, 3:6]), axis=1)  # wrench in world
        return np.einsum("bkn,bkp->nbp", J, F_W)

    def regressor(self, q: np.ndarray, v: np.ndarray, vdot: np.ndarray) -> np.ndarray:
        """Y(q, v, vdot), (nv, 10 nb), of (R2); units of each column: those of the
        generalized force per unit parameter."""
        return self.regressor_blocks(q, v, vdot).reshape(self.num_velocities, self.num_parameters)

    def known_joint_force(self, v: np.ndarray, vdot: np.ndarray) -> np.ndarray:
        """I_r vdot + D v (nv,): the reflected inertia and joint damping of the plant, the
        model terms of (R3) that are not in Y (N m)."""
        return self.reflected_inertia * np.asarray(vdot, float) + self.joint_damping * np.asarray(v, float)

    def parameters(self, inertias: Mapping[int, SpatialInertia] | None = None) -> np.ndarray:
        """pi (10 nb,): the bodies' parameters from ``inertias`` ({body index: M_BBo_B}),
        the plant's default spatial inertia for any body not in it."""
        inertias = {} if inertias is None else inertias
        out = np.zeros((self.num_bodies, 10))
        for k, body in enumerate(self.bodies):
            M = inertias.get(int(body.index()))
            out[k] = inertial_parameters(M if M is not None else body.default_spatial_inertia())
        return out.reshape(-1)

    def spatial_inertias(
        self,
        pi: np.ndarray,
        bodies: Sequence[int] | None = None,
        *,
        nominal_inertias: Mapping[int, SpatialInertia] | None = None,
        use_parameter_inertia: bool = False,
    ) -> dict[int, SpatialInertia]:
        """{body index: M_BBo_B} from pi (10 nb,), for ``bodies`` (default: every body with
        a positive mass in pi).

        Mass m' and CoM c' = (m c)' / m' come from pi. The rotational inertia is, by
        default, the nominal one about the CoM per unit mass times m' (physically valid
        whenever the nominal is; ``nominal_inertias`` or the plant's defaults); with
        ``use_parameter_inertia`` it is pi's I about Bo, shifted to the CoM and projected
        onto the valid set (principal second moments of mass clipped at 0, as in
        ``systems.simulation.imperfections.perturb_spatial_inertia``).

        Raises:
            ValueError: wrong size of pi, or a requested body with mass <= 0.
        """
        pi = np.asarray(pi, dtype=float).reshape(-1)
        if pi.shape != (self.num_parameters,):
            raise ValueError(f"spatial_inertias: pi must have {self.num_parameters} entries, got {pi.size}")
        per_body = pi.reshape(self.num_bodies, 10)
        nominal_inertias = {} if nominal_inertias is None else nominal_inertias
        position = {int(i): k for k, i in enumerate(self.body_indices)}
        if bodies is None:
            bodies = [int(i) for k, i in enumerate(self.body_indices) if per_body[k, 0] > 0.0]
        out = {}
        for index in bodies:
            k = position[int(index)]
            m = per_body[k, 0]
            if not (m > 0.0 and math.isfinite(m)):
                raise ValueError(f"spatial_inertias: body {self.bodies[k].name()!r} has mass {m!r}; must be > 0")
            c = per_body[k, 1:4] / m
            if use_parameter_inertia:
                I_o = _rotational_inertia_matrix(per_body[k, 4:10])
                I_cm = I_o - m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
                I_cm = _physically_valid(I_cm)
            else:
                M_nom = nominal_inertias.get(int(index))
                M_nom = M_nom if M_nom is not None else self.bodies[k].default_spatial_inertia()
                I_cm = m * central_unit_inertia(M_nom)
            out[int(index)] = SpatialInertia.MakeFromCentralInertia(m, c, _rotational_inertia(I_cm))
        return out


def _rotational_inertia_matrix(p: np.ndarray) -> np.ndarray:
    """3x3 from [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]."""
    return np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])


def _physically_valid(I_cm: np.ndarray) -> np.ndarray:
    lam, R = np.linalg.eigh(0.5 * (I_cm + I_cm.T))
    d = np.maximum(0.5 * lam.sum() - lam, 0.0)  # principal second moments of mass
    return R @ np.diag(d.sum() - d) @ R.T


# ---------------------------------------------------------------------------------------
# Base parameters.
# ---------------------------------------------------------------------------------------


def _triangular_factor(A: np.ndarray) -> np.ndarray:
    """R (min(rows, cols), cols) of A = Q R (unpivoted Householder, BLAS-3): A tall stacked
    regressor has the same column geometry (R^T R = A^T A) in a square matrix, so the
    pivoted QR and the least squares run on R instead of the tall A."""
    if A.shape[0] <= A.shape[1]:
        return A
    return scipy.linalg.qr(A, mode="r", overwrite_a=False, check_finite=False)[0][: A.shape[1]]


@dataclass(frozen=True)
class BaseParameterMap:
    """Base parameters of a stacked regressor (Gautier & Khalil 1990; Gautier 1991).

    Attributes:
        rank: r, the numerical rank.
        independent: the r column indices of Y_ind (the QR pivot order).
        dependent: the other column indices.
        beta: (r, p - r), Y_dep = Y_ind beta.
        pivots_abs: |R_ii| of the pivoted QR (diagnostic; decreasing).
    """

    rank: int
    independent: np.ndarray
    dependent: np.ndarray
    beta: np.ndarray
    pivots_abs: np.ndarray

    def base_parameters(self, pi: np.ndarray) -> np.ndarray:
        """pi_base = pi_ind + beta pi_dep (r,)."""
        pi = np.asarray(pi, dtype=float)
        return pi[self.independent] + self.beta @ pi[self.dependent]

    def reduce(self, Y: np.ndarray) -> np.ndarray:
        """Y_ind (rows, r), with Y pi = Y_ind pi_base."""
        return np.asarray(Y)[:, self.independent]

    def combination_matrix(self) -> np.ndarray:
        """K (r, p) with pi_base = K pi."""
        K = np.zeros((self.rank, self.independent.size + self.dependent.size))
        K[:, self.independent] = np.eye(self.rank)
        K[:, self.dependent] = self.beta
        return K


def base_parameter_map(Y_stacked: np.ndarray, tol: float = 1e-8) -> BaseParameterMap:
    """The base parameters of ``Y_stacked`` (rows, p) by QR with column pivoting.

    Y P = Q R; the rank r counts |R_ii| > tol |R_00| (``tol`` relative; scale the columns
    first if their units differ); P's first r columns are independent and
    beta = R_11^-1 R_12 gives Y_dep = Y_ind beta, so Y pi = Y_ind (pi_ind + beta pi_dep).

    Raises:
        ValueError: not a finite 2-D array, or tol not in (0, 1).
    """
    Y = np.asarray(Y_stacked, dtype=float)
    if Y.ndim != 2 or Y.size == 0 or not np.isfinite(Y).all():
        raise ValueError(f"base_parameter_map: Y_stacked must be a finite non-empty 2-D array, got shape {Y.shape}")
    if not 0.0 < tol < 1.0:
        raise ValueError(f"base_parameter_map: tol must be in (0, 1), got {tol!r}")
    R, P = scipy.linalg.qr(_triangular_factor(Y), mode="r", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.count_nonzero(diag > tol * diag[0])) if diag.size and diag[0] > 0.0 else 0
    independent, dependent = P[:rank].copy(), P[rank:].copy()
    if rank:
        beta = scipy.linalg.solve_triangular(R[:rank, :rank], R[:rank, rank:])
    else:
        beta = np.zeros((0, dependent.size))
    return BaseParameterMap(rank, independent, dependent, beta, diag)


# ---------------------------------------------------------------------------------------
# The calibration log.
# ---------------------------------------------------------------------------------------

_LOG_FIELDS = ("time", "q", "v", "measured_torque", "known_wrenches")


@dataclass
class CalibrationLog:
    """A robot's calibration log: plain arrays, one row per sample, SI units.

    Attributes:
        time: (N,) s, strictly increasing, uniformly sampled (the filter assumes it).
        q: (N, nq) Drake positions (base quaternion, position, joints), as estimated.
        v: (N, nv) Drake velocities ([w_WB; v_WBo] in world, joint rates), as estimated.
        measured_torque: (N, n) motor torques in v[6:] order (N m), as the robot reports
            them (no friction compensation); 0 on unactuated joints.
        known_wrenches: (N, 6 k) per F/T frame [moment about its origin; force], world,
            applied by the environment on the robot (N m, N), in ``known_wrench_frames``
            order.
    """

    time: np.ndarray
    q: np.ndarray
    v: np.ndarray
    measured_torque: np.ndarray
    known_wrenches: np.ndarray

    def validate(self, plant: MultibodyPlant, num_wrench_frames: int) -> CalibrationLog:
        """Returns self; raises ValueError naming the field for a wrong shape, NaN/inf,
        non-increasing time or fewer than ``MIN_LOG_SAMPLES`` samples."""
        arrays = {}
        for name in _LOG_FIELDS:
            try:
                arrays[name] = np.asarray(getattr(self, name), dtype=float)
            except (TypeError, ValueError) as err:
                raise ValueError(f"CalibrationLog.{name} must be a numeric array") from err
        N = arrays["time"].shape[0] if arrays["time"].ndim == 1 else -1
        if N < 0:
            raise ValueError(f"CalibrationLog.time must be 1-D (N,), got shape {arrays['time'].shape}")
        nv = plant.num_velocities()
        widths = {
            "q": plant.num_positions(),
            "v": nv,
            "measured_torque": nv - 6,
            "known_wrenches": 6 * int(num_wrench_frames),
        }
        for name, width in widths.items():
            if arrays[name].shape != (N, width):
                raise ValueError(f"CalibrationLog.{name} must have shape ({N}, {width}), got {arrays[name].shape}")
        for name, x in arrays.items():
            bad = np.argwhere(~np.isfinite(x))
            if bad.size:
                raise ValueError(f"CalibrationLog.{name} has NaN or inf (first at index {bad[0].tolist()})")
        if N < MIN_LOG_SAMPLES:
            raise ValueError(f"CalibrationLog.time: the log is too short ({N} samples, need >= {MIN_LOG_SAMPLES})")
        steps = np.diff(arrays["time"])
        if not (steps > 0.0).all():
            raise ValueError(f"CalibrationLog.time must be strictly increasing (sample {int(np.argmin(steps)) + 1})")
        for name, x in arrays.items():
            setattr(self, name, x)
        return self

    def to_npz(self, path: str | Path) -> None:
        """Writes the five arrays to ``path`` (numpy .npz, no pickle)."""
        np.savez(path, **{name: np.asarray(getattr(self, name), dtype=float) for name in _LOG_FIELDS})

    @classmethod
    def from_npz(cls, path: str | Path) -> CalibrationLog:
        """Reads a log written by ``to_npz`` (or any .npz with the five arrays).

        Raises:
            ValueError: unreadable file (naming it) or missing arrays (naming them).
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = [name for name in _LOG_FIELDS if name not in data.files]
                if missing:
                    raise ValueError(f"CalibrationLog.from_npz: {str(path)!r} has no array {missing}")
                arrays = {name: np.array(data[name], dtype=float) for name in _LOG_FIELDS}
        except (OSError, EOFError, zipfile.BadZipFile, TypeError) as err:
            raise ValueError(f"CalibrationLog.from_npz: cannot read {str(path)!r} as an .npz log: {err}") from err
        except ValueError as err:
            if str(err).startswith("CalibrationLog"):
                raise
            raise ValueError(f"CalibrationLog.from_npz: cannot read {str(path)!r} as an .npz log: {err}") from err
        return cls(**arrays)


# ---------------------------------------------------------------------------------------
# Identification.
# ---------------------------------------------------------------------------------------


@dataclass
class IdentificationOptions:
    """Options of ``identify_model_corrections`` (SI units).

    Attributes:
        cutoff_frequency: Hz, of the zero-phase Butterworth low-pass applied to q, v, the
            torques and the wrenches alike (Gautier's parallel filtering: both sides of
            (R3) see the same filter). 5 Hz keeps a slow calibration motion (<= 1 Hz)
            undistorted (|H| > 0.9999) and removes the differentiation noise.
        filter_order: order of the Butterworth filter (applied forward and backward).
        decimation_period: s, spacing of the samples that enter the regression.
        edge_time: s, dropped at each end of the log (filter transients).
        smoothing_velocity: v_s of the Coulomb model, rad/s (known, not identified; the
            default is ``FrictionImperfections``').
        moment_std, force_std: noise scale of the base moment rows (N m) and base force
            rows (N); torque_std: of the joint rows (N m), a scalar or one per joint (v[6:]
            order). Each row of (R3) is weighted by 1/std.
        identify_rotational_inertia: also identify the 6 rotational parameters per body
            (default: they stay nominal, their columns go to the known side).
        identify_friction, identify_torque_errors: fit F_c, b and s, o.
        include_joint_damping: the plant's joint damping D qdot is a known model term
            (then b is the friction beyond it; the residuals apply D qdot themselves).
        base_velocity: the base twist the regression uses: "log" (the log's v[:6], e.g. a
            base-state estimator's) or "stance_kinematics" (``stance_base_velocity``: the
            twist that keeps every known-wrench frame still, from the log's base
            orientation and joint rates; for a calibration standing on both feet). The
            estimator's angular velocity is the gyro's: its white noise, differentiated,
            is as large as the base's angular acceleration in a slow calibration, and that
            noise in the regressor (errors in variables) drives the weakly excited inertial
            combinations (masses clipped, a robot several percent too heavy); the encoders
            the stance kinematics use are ~10 times quieter.
        rank_tolerance: relative tolerance |R_ii| > tol |R_00| of the base-parameter rank
            (on the weighted columns scaled by the nominal mass m, m r and m r^2, r the
            radius of gyration about the body origin).
        inertial_prior_std: sigma_p >= 0, a Gaussian prior (Tikhonov) on the per-link
            deviations from the nominal model, in the scaled parameters: (m' - m)/m and
            ((m c)' - m c)/(m r) ~ N(0, sigma_p^2) independently, hence
            x_base - x_base,nominal ~ N(0, sigma_p^2 K K^T) with pi_base = K pi (rows
            U^-1 (x - x_nominal)/sigma_p, K K^T = U U^T). It holds the weakly excited
            combinations near nominal (e.g. 0.1: links within ~10 % of CAD). Its strength
            is relative to the row weights 1/std. 0: plain weighted least squares.
        joint_prior_weight: lambda >= 0, ridge toward F_c = 0, b = 0, s = 0, o = 0 on
            the column-normalised joint unknowns: rows sqrt(lambda) ||col_i|| (x_i -
            x_i,nominal); for joints whose torque barely changes over the log (scale and
            offset then collinear). 0: none.
        torque_scale_prior_std, torque_offset_prior_std, coulomb_prior_std: a Gaussian
            prior on each joint's s (dimensionless), o (N m) and F_c (N m) about 0, scalar
            or one per joint (v[6:] order); 0: none. Unlike ``joint_prior_weight`` its
            strength does not grow with the log: it is what a datasheet says of the
            actuators (e.g. a torque constant known to 10 %, an offset within a few percent
            of the rated torque). In a standing calibration the offsets are nearly collinear
            with the links' gravity parameters (a link that barely rotates), so the two
            priors decide the split: a ridge that grows with the data pulls the offsets to
            0 and moves them into the links, which then err at other postures.
        min_mass_fraction: every corrected mass is clipped to >= this fraction of its
            nominal mass (a safeguard; the count is in the diagnostics).
        viscous_min_speed: the viscous coefficient b of a joint is identified only if the
            log moves it faster than this many v_s (95th percentile of |qdot|); else b = 0
            and the Coulomb term carries its friction (the diagnostics list those joints).
    """

    cutoff_frequency: float = 5.0
    filter_order: int = 4
    decimation_period: float = 0.01
    edge_time: float = 0.5
    smoothing_velocity: float = 0.1
    moment_std: float = 0.1
    force_std: float = 1.0
    torque_std: float | np.ndarray = 0.1
    identify_rotational_inertia: bool = False
    identify_friction: bool = True
    identify_torque_errors: bool = True
    include_joint_damping: bool = True
    base_velocity: str = "log"
    rank_tolerance: float = 1e-6
    inertial_prior_std: float = 0.0
    joint_prior_weight: float = 0.0
    torque_scale_prior_std: float | np.ndarray = 0.0
    torque_offset_prior_std: float | np.ndarray = 0.0
    coulomb_prior_std: float | np.ndarray = 0.0
    min_mass_fraction: float = 0.2
    viscous_min_speed: float = 2.0

    def validate(self) -> IdentificationOptions:
        who = "IdentificationOptions"
        for name in (
            "cutoff_frequency",
            "decimation_period",
            "smoothing_velocity",
            "moment_std",
            "force_std",
            "rank_tolerance",
        ):
            positive_number(getattr(self, name), f"{who}.{name}")
        for name in ("edge_time", "inertial_prior_std", "joint_prior_weight", "min_mass_fraction", "viscous_min_speed"):
            positive_number(getattr(self, name), f"{who}.{name}", allow_zero=True)
        for name in ("torque_scale_prior_std", "torque_offset_prior_std", "coulomb_prior_std"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.ndim > 1 or not np.all(np.isfinite(value)) or np.any(value < 0.0):
                raise ValueError(f"{who}.{name} must be >= 0 (a scalar or one per joint), got {getattr(self, name)!r}")
        if self.base_velocity not in BASE_VELOCITY_SOURCES:
            raise ValueError(f"{who}.base_velocity must be one of {BASE_VELOCITY_SOURCES}, got {self.base_velocity!r}")
        if not isinstance(self.filter_order, int) or not 1 <= self.filter_order <= 10:
            raise ValueError(f"{who}.filter_order must be an integer in 1..10, got {self.filter_order!r}")
        return self


@dataclass
class ModelCorrections:
    """The identified model (see the module docstring), per-joint arrays in v[6:] order.

    Attributes:
        spatial_inertias: {body index: corrected M_BBo_B}: mass m', CoM c' = (m c)'/m', and
            (unless the rotational parameters were identified) rotational inertia about
            the CoM = nominal inertia about the CoM per unit mass x m' (physically valid).
        coulomb: F_c, N m. viscous: b, N m s/rad (beyond the plant's joint damping when
            ``include_joint_damping``). smoothing_velocity: v_s, rad/s.
        torque_offset: o, N m; torque_scale: s (measured = (1 + s) tau + o); 0 on
            unactuated joints.
        body_names: {body index: name}, to check the plant a saved file is used with.
        residual_noise: optional ``systems.residuals.offline.ResidualNoiseModel``: the
            covariances of the residuals on the calibration log with this model (the
            contact detector's noise model); None if not measured.
        diagnostics: rank, num_samples, num_clipped_masses, joints_without_viscous,
            joint_speed_p95 (each joint's 95th-percentile |qdot| in the log, rad/s: the
            friction is calibrated up to about this speed and extrapolates beyond it; a
            joint below ~2 v_s has a poorly determined Coulomb/viscous split) and the RMS
            of the regression residual of (R3) with the nominal model (``rms_before``) and
            the corrected one (``rms_after``), per row group: ``base_force`` (N), ``base_moment`` (N m),
            ``joints`` (N m); with ``base_velocity`` "stance_kinematics", also
            ``stance_frame_speed_p95`` (m/s, ``stance_base_velocity``'s frame speed by the
            log's own base twist, 95th percentile: how still the feet were).
    """

    spatial_inertias: dict[int, SpatialInertia]
    coulomb: np.ndarray
    viscous: np.ndarray
    smoothing_velocity: float
    torque_offset: np.ndarray
    torque_scale: np.ndarray
    body_names: dict[int, str] = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)
    residual_noise: ResidualNoiseModel | None = None

    def corrected_torque(self, measured_torque: np.ndarray, v_joints: np.ndarray) -> np.ndarray:
        """The joint effort (N m): (tau_m - o)/(1 + s) - F_c tanh(qdot/v_s) - b qdot, for
        (n,) or (N, n) arrays of measured torques and joint velocities qdot = v[6:]."""
        tau_m = np.asarray(measured_torque, dtype=float)
        qdot = np.asarray(v_joints, dtype=float)
        friction = self.coulomb * np.tanh(qdot / self.smoothing_velocity) + self.viscous * qdot
        return (tau_m - self.torque_offset) / (1.0 + self.torque_scale) - friction

    def save(self, path: str | Path) -> None:
        """Writes the corrections to ``path`` (.npz, no pickle): reload with ``load``."""
        indices = np.array(sorted(self.spatial_inertias), dtype=int)
        per_body = np.zeros((indices.size, 10))
        for k, index in enumerate(indices):
            M = self.spatial_inertias[int(index)]
            m = M.get_mass()
            G = m * central_unit_inertia(M)
            per_body[k] = np.concatenate(([m], M.get_com(), np.diag(G), [G[0, 1], G[0, 2], G[1, 2]]))
        np.savez(
            path,
            body_indices=indices,
            mass_com_central_inertia=per_body,
            body_names=np.array(json.dumps({str(k): v for k, v in self.body_names.items()})),
            coulomb=self.coulomb,
            viscous=self.viscous,
            smoothing_velocity=np.array(self.smoothing_velocity),
            torque_offset=self.torque_offset,
            torque_scale=self.torque_scale,
            diagnostics=np.array(json.dumps(self.diagnostics)),
            **(self.residual_noise.as_arrays() if self.residual_noise is not None else {}),
        )

    @classmethod
    def load(cls, path: str | Path) -> ModelCorrections:
        """Reads corrections written by ``save``.

        Raises:
            ValueError: unreadable or incomplete file (naming it).
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                indices = data["body_indices"]
                per_body = data["mass_com_central_inertia"]
                inertias = {
                    int(i): SpatialInertia.MakeFromCentralInertia(
                        row[0], row[1:4], RotationalInertia(*(float(x) for x in row[4:10]))
                    )
                    for i, row in zip(indices, per_body)
                }
                return cls(
                    spatial_inertias=inertias,
                    coulomb=np.array(data["coulomb"], dtype=float),
                    viscous=np.array(data["viscous"], dtype=float),
                    smoothing_velocity=float(data["smoothing_velocity"]),
                    torque_offset=np.array(data["torque_offset"], dtype=float),
                    torque_scale=np.array(data["torque_scale"], dtype=float),
                    body_names={int(k): v for k, v in json.loads(str(data["body_names"])).items()},
                    diagnostics=json.loads(str(data["diagnostics"])),
                    residual_noise=ResidualNoiseModel.from_arrays(data),
                )
        except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile, json.JSONDecodeError) as err:
            raise ValueError(f"ModelCorrections.load: cannot read {str(path)!r}: {err}") from err


def _filtered_log(log: CalibrationLog, options: IdentificationOptions):
    """Zero-phase low-pass of every regression signal, vdot by differentiation, then the
    decimated sample indices away from the edges. The friction columns tanh(qdot/v_s) and
    qdot are computed at the log's rate and filtered too (parallel filtering, Gautier 1997):
    the low-pass of a nearly discontinuous Coulomb torque in tau_m is matched only by the
    low-pass of its column. Returns (q, v, vdot, tau_m, W, coulomb_column, viscous_column,
    rows)."""
    t = log.time
    steps = np.diff(t)
    period = float(np.median(steps))
    if np.max(np.abs(steps - period)) > 0.1 * period:
        raise ValueError("CalibrationLog.time must be uniformly sampled (jitter > 10 % of the period); resample it")
    nyquist = 0.5 / period
    if not options.cutoff_frequency < nyquist:
        raise ValueError(
            f"IdentificationOptions.cutoff_frequency ({options.cutoff_frequency} Hz) must be below the log's "
            f"Nyquist frequency ({nyquist:.3g} Hz)"
        )
    sos = scipy.signal.butter(options.filter_order, options.cutoff_frequency / nyquist, output="sos")
    padlen = 3 * (2 * sos.shape[0] + 1)
    if t.size <= padlen:
        raise ValueError(f"CalibrationLog.time: the log is too short for the filter ({t.size} samples)")

    def lowpass(x):
        return scipy.signal.sosfiltfilt(sos, x, axis=0)

    q = lowpass(log.q)
    q[:, :4] /= np.linalg.norm(q[:, :4], axis=1, keepdims=True)
    v = lowpass(log.v)
    vdot = np.gradient(v, t, axis=0)
    tau_m = lowpass(log.measured_torque)
    W = lowpass(log.known_wrenches)
    coulomb_column = lowpass(np.tanh(v[:, 6:] / options.smoothing_velocity))
    viscous_column = lowpass(v[:, 6:])
    stride = max(1, int(round(options.decimation_period / period)))
    keep = np.flatnonzero((t >= t[0] + options.edge_time) & (t <= t[-1] - options.edge_time))[::stride]
    return q, v, vdot, tau_m, W, coulomb_column, viscous_column, keep


def _known_wrench_force(plant: MultibodyPlant, context: Context, frames: Sequence[Frame], W: np.ndarray) -> np.ndarray:
    """sum_s J_s^T W_s (nv,), W_s = [moment about the frame origin; force] in world."""
    world = plant.world_frame()
    out = np.zeros(plant.num_velocities())
    for s, frame in enumerate(frames):
        J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world)
        out += J.T @ W[6 * s : 6 * s + 6]
    return out


def _unknown_wrench_columns(plant: MultibodyPlant, context: Context, unknown: UnknownWrenches) -> np.ndarray:
    """(nv, k) sum over the unknown wrench frames of J_F^T B_F: their components' generalized
    forces at the context's positions (B_F their world directions, ``world_bases``)."""
    world = plant.world_frame()
    parts = []
    for frame, basis in zip(unknown.frames, unknown.world_bases(context)):
        J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world)
        parts.append(J.T if basis is None else J.T @ basis)
    return np.concatenate(parts, axis=1)


def stance_base_velocity(
    plant: MultibodyPlant, context: Context, frames: Sequence[Frame], q: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The base twist [w_WB; v_WBo] (N, 6) that keeps every frame of ``frames`` still (the
    soles of a robot standing on both feet): the least-squares solution of
    J_s,base v_base = -J_s,joints qdot over the stacked frame Jacobians (6 per frame), at
    each sample of q (N, nq) and v (N, nv) (its joint rates; its base twist is not used).
    Also returns each sample's largest frame speed with the log's own v (N,), m/s (a
    frame's angular speed times 0.1 m counts as a speed): how still the frames were by the
    log's own base twist.

    Raises:
        ValueError: no frames, or frames that do not determine the base twist (fewer than 6
            independent constraints).
    """
    if not frames:
        raise ValueError("stance_base_velocity: needs at least one frame that stays still (the feet)")
    world = plant.world_frame()
    count, rows = q.shape[0], 6 * len(frames)
    twist = np.empty((count, 6))
    frame_speed = np.empty(count)
    weight = np.tile([0.1] * 3 + [1.0] * 3, len(frames))
    origin = np.zeros(3)
    for start in range(0, count, _STANCE_CHUNK):  # the Jacobians of a chunk of samples, then batched algebra
        stop = min(start + _STANCE_CHUNK, count)
        J = np.empty((stop - start, rows, v.shape[1]))
        for k in range(start, stop):
            plant.SetPositions(context, q[k])
            for f, frame in enumerate(frames):
                J[k - start, 6 * f : 6 * f + 6] = plant.CalcJacobianSpatialVelocity(
                    context, JacobianWrtVariable.kV, frame, origin, world, world
                )
        if start == 0 and np.linalg.matrix_rank(J[0, :, :6]) < 6:
            raise ValueError("stance_base_velocity: the frames do not determine the base twist (rank < 6)")
        # Least squares of each sample by its normal equations (the base columns have full
        # rank: the same twist as lstsq to rounding).
        base_T = J[:, :, :6].transpose(0, 2, 1)
        rhs = -np.einsum("sij,sj->si", J[:, :, 6:], v[start:stop, 6:])
        twist[start:stop] = np.linalg.solve(base_T @ J[:, :, :6], np.einsum("sji,si->sj", base_T, rhs)[..., None])[
            ..., 0
        ]
        frame_speed[start:stop] = np.max(np.abs(np.einsum("sij,sj->si", J, v[start:stop]) * weight), axis=1)
    return twist, frame_speed


#: Samples per batch of ``stance_base_velocity``'s algebra (bounds its memory: 12 x 40 doubles each).
_STANCE_CHUNK = 4096


def _joint_prior_rows(
    options: IdentificationOptions, groups: list[str], act: np.ndarray, n: int, r: int, size: int
) -> np.ndarray:
    """Rows (x_i - 0) / std_i of the Gaussian priors on s, o and F_c (zero std: no row)."""
    rows = []
    for name, field_name in (
        ("scale", "torque_scale_prior_std"),
        ("offset", "torque_offset_prior_std"),
        ("coulomb", "coulomb_prior_std"),
    ):
        if name not in groups:
            continue
        std = np.asarray(getattr(options, field_name), dtype=float)
        if std.ndim == 0:
            std = np.full(n, float(std))
        if std.shape != (n,):
            raise ValueError(f"IdentificationOptions.{field_name} must be a scalar or {n} values, got {std.shape}")
        std = std[act]
        for k in np.flatnonzero(std > 0.0):
            row = np.zeros(size)
            row[r + groups.index(name) * act.size + k] = 1.0 / std[k]
            rows.append(row)
    return np.array(rows).reshape(-1, size)


def identify_model_corrections(
    plant: MultibodyPlant,
    log: CalibrationLog,
    *,
    known_wrench_frames: Sequence[Frame],
    nominal_inertias: Mapping[int, SpatialInertia] | None = None,
    options: IdentificationOptions | None = None,
    unknown_wrench_frames: Sequence[Frame] = (),
    unknown_wrench_components: Sequence | None = None,
) -> ModelCorrections:
    """Fits (R3) to a calibration log and returns the corrected model.

    Args:
        plant: the estimators' finalized floating-base plant (its default spatial inertias
            are the nominal model unless ``nominal_inertias`` overrides some bodies).
        log: the calibration log (checked with ``CalibrationLog.validate``).
        known_wrench_frames: the F/T frames, in the order of ``log.known_wrenches``.
        nominal_inertias: {body index: M_BBo_B} of the nominal model (e.g. the model the
            estimators use today); default: the plant's.
        options: ``IdentificationOptions`` (defaults when None).
        unknown_wrench_frames, unknown_wrench_components: contacts whose wrenches (or some
            of their components, ``systems.residuals.contact_estimation.UnknownWrenches``)
            no sensor measures: the soles of feet without F/T sensors (with FSRs: their
            shear and yaw moment), which stay still. Each sample's equations are projected
            onto the complement of those wrenches' columns J_F^T B_F (weighted as the fit;
            the floating-base identification with unknown contact forces of Mistry, Schaal
            and Yamane, 2009), so only what no such wrench can explain is fitted; the frames
            also join the stance frames of ``stance_kinematics``.

    Returns:
        ``ModelCorrections``. The per-link masses and first moments are the nominal ones
        plus the minimum-norm deviation (relative to the nominal mass and, for m c, to
        mass x radius of gyration) reproducing the identified base parameters.

    Raises:
        ValueError: bad log (naming the field), options, or too few samples.
    """
    who = "identify_model_corrections"
    check_plant(plant, who)
    options = (IdentificationOptions() if options is None else options).validate()
    frames = tuple(known_wrench_frames)
    log.validate(plant, len(frames))
    unknown = UnknownWrenches(plant, unknown_wrench_frames, unknown_wrench_components, who)
    regressor = InertialParameterRegressor(plant)
    topology, nv, nb = regressor.topology, regressor.num_velocities, regressor.num_bodies
    n = topology.num_joints
    nominal_inertias = dict(nominal_inertias or {})
    pi_nominal = regressor.parameters(nominal_inertias).reshape(nb, 10)

    stance_speed = None
    if options.base_velocity == "stance_kinematics":
        v_stance = np.array(log.v, dtype=float)
        still = frames + tuple(f for f in unknown.frames if all(f.index() != k.index() for k in frames))
        v_stance[:, :6], frame_speed = stance_base_velocity(plant, regressor.context, still, log.q, log.v)
        stance_speed = float(np.percentile(frame_speed, 95))
        log = replace(log, v=v_stance)
    q, v, vdot, tau_m, W, coulomb_column, viscous_column, keep = _filtered_log(log, options)
    if keep.size * nv < 2 * (4 * nb + 4 * n):
        raise ValueError(f"{who}: too few samples after filtering and decimation ({keep.size}); log a longer motion")
    # Coulomb and viscous friction are told apart only by speeds well beyond v_s: below,
    # F_c tanh(qdot / v_s) + b qdot ~ (F_c / v_s + b) qdot and any split fits. A joint the
    # log never moves that fast keeps b = 0 (its slope goes to F_c), so that its friction
    # does not extrapolate with a wrong b to faster motions.
    joint_speed = np.percentile(np.abs(v[keep, 6:]), 95, axis=0)
    slow_joints = joint_speed < options.viscous_min_speed * options.smoothing_velocity
    viscous_column = viscous_column.copy()
    viscous_column[:, slow_joints] = 0.0

    # Which columns are identified (per body) and their scales (nominal m, m r, m r^2).
    identified = np.array(MASS_AND_FIRST_MOMENT + (ROTATIONAL if options.identify_rotational_inertia else ()))
    fixed = np.array([] if options.identify_rotational_inertia else ROTATIONAL, dtype=int)
    mass = pi_nominal[:, 0]
    radius = np.zeros(nb)
    for k in range(nb):
        if mass[k] > 0.0:
            radius[k] = math.sqrt(max(pi_nominal[k, 4:7].sum(), 0.0) / (2.0 * mass[k]))  # about Bo
    scale_per_body = np.stack([mass, mass * radius, mass * radius, mass * radius] + [mass * radius**2] * 6, axis=1)
    scale = scale_per_body[:, identified].reshape(-1)

    actuated = np.zeros(n, dtype=bool)
    for index in plant.GetJointActuatorIndices():
        joint = plant.get_joint_actuator(JointActuatorIndex(int(index))).joint()
        if joint.num_velocities() == 1:
            actuated[joint.velocity_start() - 6] = True
    act = np.flatnonzero(actuated)
    na = act.size
    v_s = options.smoothing_velocity
    torque_std = per_joint(options.torque_std, n, "torque_std", who="IdentificationOptions", sign="positive")
    row_weight = 1.0 / np.concatenate(([options.moment_std] * 3, [options.force_std] * 3, torque_std))

    # The regressor and the known side of (R3) at the retained samples.
    S = keep.size
    Y_id = np.empty((S, nv, identified.size * nb))
    rhs = np.empty((S, nv))
    U_unknown = np.empty((S, nv, unknown.size))  # the unknown wrenches' generalized-force columns
    for row, i in enumerate(keep):
        blocks = regressor.regressor_blocks(q[i], v[i], vdot[i])
        Y_id[row] = blocks[:, :, identified].reshape(nv, -1)
        if unknown:
            U_unknown[row] = _unknown_wrench_columns(plant, regressor.context, unknown)
        known = _known_wrench_force(plant, regressor.context, frames, W[i])
        if fixed.size:
            known -= np.einsum("nbp,bp->n", blocks[:, :, fixed], pi_nominal[:, fixed])
        if options.include_joint_damping:
            known -= regressor.known_joint_force(v[i], vdot[i])
        else:
            known -= regressor.reflected_inertia * vdot[i]
        rhs[row] = known

    def weighted_unknown_columns(gain: np.ndarray | None = None) -> np.ndarray:
        """(S, nv, k) each sample's unknown wrench columns J_F^T B_F in the weighted rows:
        times the row weight and ``gain`` (the actuated rows' 1 + s, which multiplies them
        as it multiplies the model's torques)."""
        return U_unknown * (row_weight if gain is None else row_weight * gain)[:, None]

    def project(weighted: np.ndarray, gain: np.ndarray | None = None) -> np.ndarray:
        """Weighted rows (S, nv[, p]) without what the unknown wrenches explain: minus
        their projection on each sample's weighted columns."""
        if not unknown:
            return weighted
        Q = np.linalg.qr(weighted_unknown_columns(gain))[0]  # (S, nv, k)
        if weighted.ndim == 2:
            return weighted - np.einsum("snk,sk->sn", Q, np.einsum("snk,sn->sk", Q, weighted))
        return weighted - np.einsum("snk,skp->snp", Q, np.einsum("snk,snp->skp", Q, weighted))

    # Base parameters of the weighted, scaled inertial columns (zero-mass bodies excluded).
    live = scale > 0.0
    Y_scaled = Y_id[:, :, live] * scale[live]
    base = base_parameter_map(project(Y_scaled * row_weight[:, None]).reshape(S * nv, -1), tol=options.rank_tolerance)
    Y_base = Y_scaled[:, :, base.independent]  # (S, nv, r): Y pi = Y_base theta_base
    del Y_scaled
    theta_nominal = pi_nominal[:, identified].reshape(-1)[live] / scale[live]
    K = base.combination_matrix()
    r = base.rank

    # Unknowns x = [theta_base, F_c, b, s, o] (the last four per actuated joint).
    tau_a = tau_m[keep][:, act]
    coulomb_a, viscous_a = coulomb_column[keep][:, act], viscous_column[keep][:, act]
    groups = (["coulomb", "viscous"] if options.identify_friction else []) + (
        ["scale", "offset"] if options.identify_torque_errors else []
    )
    x_nominal = np.concatenate((K @ theta_nominal, np.zeros(len(groups) * na)))
    rows_a = 6 + act

    def unpack(x):
        values = {"coulomb": np.zeros(na), "viscous": np.zeros(na), "scale": np.zeros(na), "offset": np.zeros(na)}
        for g, name in enumerate(groups):
            values[name] = x[r + g * na : r + (g + 1) * na]
        return values

    def residual_and_jacobian(x):
        """Weighted residual of (R3') and its Jacobian: base and unactuated rows
        Y pi - rhs; actuated rows (1 + s) tau_model + o - tau_m."""
        p = unpack(x)
        model = np.einsum("snr,r->sn", Y_base, x[:r]) - rhs
        model[:, rows_a] += p["coulomb"] * coulomb_a + p["viscous"] * viscous_a
        gain = np.ones(nv)
        gain[rows_a] += p["scale"]

        def output_error(model):
            e = model.copy()
            e[:, rows_a] = (1.0 + p["scale"]) * model[:, rows_a] + p["offset"] - tau_a
            return e

        e = output_error(model)
        if unknown:
            # Variable projection: the unknown wrenches' best fit u* per sample, in the
            # model (so the scale column is the model's torque net of them: Kaufman's
            # Jacobian, which with these columns in the model converges to the truth).
            C = weighted_unknown_columns(gain)
            u = np.einsum("skn,sn->sk", np.linalg.pinv(C), e * row_weight)
            model = model - np.einsum("snk,sk->sn", U_unknown, u)
            e = output_error(model)
        J = np.zeros((S, nv, x.size))
        J[:, :, :r] = Y_base * gain[:, None]
        cols = {
            "coulomb": (1.0 + p["scale"]) * coulomb_a,
            "viscous": (1.0 + p["scale"]) * viscous_a,
            "scale": model[:, rows_a],
            "offset": np.ones_like(tau_a),
        }
        for g, name in enumerate(groups):
            J[:, rows_a, r + g * na + np.arange(na)] = cols[name]
        w = row_weight[:, None]
        return (e * row_weight).reshape(-1), project(J * w, gain).reshape(S * nv, -1)

    # Gauss-Newton on the column-normalised problem (the measured torque stays on the
    # output side: a column of tau_m would bias s by its noise, errors-in-variables); the
    # first step on the triangular factor of [J, e] (the same solution, a small SVD), with the
    # prior rows: theta - theta_nominal ~ N(0, sigma_p^2 I) gives x_base - x_base,nominal
    # ~ N(0, sigma_p^2 K K^T), rows U^-1 (x - x_nominal) / sigma_p with K K^T = U U^T.
    prior = np.zeros((0, x_nominal.size))
    if options.inertial_prior_std > 0.0:
        U = np.linalg.cholesky(K @ K.T)
        prior_inertial = scipy.linalg.solve_triangular(U, np.eye(r), lower=True) / options.inertial_prior_std
        prior = np.vstack((prior, np.hstack((prior_inertial, np.zeros((r, x_nominal.size - r))))))
    x = x_nominal.copy()
    norms = None
    steps = GAUSS_NEWTON_STEPS if options.identify_torque_errors else 1
    for _step in range(steps):
        e, J = residual_and_jacobian(x)
        if norms is None:
            norms = np.linalg.norm(J, axis=0)
            norms[norms == 0.0] = 1.0
            if options.joint_prior_weight > 0.0:
                ridge = math.sqrt(options.joint_prior_weight) * np.diag(norms)[r:]
                prior = np.vstack((prior, ridge))
            prior = np.vstack((prior, _joint_prior_rows(options, groups, act, n, r, x_nominal.size)))
            if "viscous" in groups and slow_joints[act].any():  # b = 0 exactly (its column is 0)
                pinned = r + groups.index("viscous") * na + np.flatnonzero(slow_joints[act])
                pin_rows = np.zeros((pinned.size, x_nominal.size))
                pin_rows[np.arange(pinned.size), pinned] = PINNED_WEIGHT
                prior = np.vstack((prior, pin_rows))
        J /= norms
        prior_n, prior_e = prior / norms, -prior @ (x - x_nominal)
        if _step == 0:  # the large step: least squares on the triangular factor of [J, -e]
            Rb = _triangular_factor(np.hstack((J, -e[:, None])))
            A_n = np.vstack((Rb[:, :-1], prior_n))
            dz = np.linalg.lstsq(A_n, np.concatenate((Rb[:, -1], prior_e)), rcond=SOLVER_RCOND)[0]
        else:  # small corrections: normal equations (their error scales with the step)
            G = J.T @ J + prior_n.T @ prior_n
            dz = np.linalg.lstsq(G, -J.T @ e + prior_n.T @ prior_e, rcond=SOLVER_RCOND**2)[0]
        dx = dz / norms
        x = x + dx
        if np.max(np.abs(dx * norms)) < GAUSS_NEWTON_TOLERANCE * max(1.0, np.max(np.abs(x * norms))):
            break
    del J

    if "viscous" in groups:  # the pinned coefficients: exactly 0, not the solver's 1e-15
        x[r + groups.index("viscous") * na + np.flatnonzero(slow_joints[act])] = 0.0

    # Per-link parameters: the minimum-norm (scaled) deviation reproducing pi_base.
    delta = K.T @ np.linalg.solve(K @ K.T, x[:r] - K @ theta_nominal)
    pi_identified = pi_nominal[:, identified].reshape(-1).copy()
    pi_identified[np.flatnonzero(live)] += scale[live] * delta
    pi_corrected = pi_nominal.copy()
    pi_corrected[:, identified] = pi_identified.reshape(nb, -1)
    floor = options.min_mass_fraction * pi_nominal[:, 0]
    clipped = (pi_nominal[:, 0] > 0.0) & (pi_corrected[:, 0] < floor)
    pi_corrected[clipped, 0] = floor[clipped]
    corrected = regressor.spatial_inertias(
        pi_corrected.reshape(-1),
        [int(i) for k, i in enumerate(regressor.body_indices) if pi_nominal[k, 0] > 0.0],
        nominal_inertias=nominal_inertias,
        use_parameter_inertia=options.identify_rotational_inertia,
    )

    # Joint parameters (v[6:] order; unactuated joints: 0 friction, s = 0, o = 0).
    values = unpack(x)
    coulomb, viscous, torque_scale, torque_offset = (np.zeros(n) for _ in range(4))
    coulomb[act], viscous[act] = values["coulomb"], values["viscous"]
    torque_scale[act], torque_offset[act] = values["scale"], values["offset"]
    bad = np.flatnonzero(~(torque_scale > -1.0))
    if bad.size:
        names = [topology.joints[k].name() for k in bad]
        raise ValueError(
            f"{who}: the log does not determine the torque scale of joints {names} (1 + s <= 0); "
            "excite them more, or set IdentificationOptions.joint_prior_weight > 0 or identify_torque_errors=False"
        )

    # Diagnostics: the unweighted residual of (R3) in generalized-force units (joint rows:
    # the corrected torque minus the model's), nominal model vs corrected (rotational
    # inertias nominal in both unless identified; the corrected masses after clipping).
    def residual(pi_per_body, fc, bv, s_, o_):
        e = np.einsum("snp,p->sn", Y_id, pi_per_body[:, identified].reshape(-1)) - rhs
        e[:, rows_a] += fc[act] * coulomb_a + bv[act] * viscous_a - (tau_a - o_[act]) / (1.0 + s_[act])
        return e

    def rms(e):
        e = project(e * row_weight) / row_weight  # what the unknown wrenches do not explain
        return {
            "base_moment": float(np.sqrt(np.mean(e[:, 0:3] ** 2))),
            "base_force": float(np.sqrt(np.mean(e[:, 3:6] ** 2))),
            "joints": float(np.sqrt(np.mean(e[:, 6:] ** 2))),
        }

    zeros = np.zeros(n)
    diagnostics = {
        "rank": int(base.rank),
        "joints_without_viscous": [topology.joints[k].name() for k in np.flatnonzero(slow_joints)],
        "joint_speed_p95": [float(x) for x in joint_speed],
        "num_inertial_columns": int(live.sum()),
        "num_samples": int(S),
        "num_clipped_masses": int(clipped.sum()),
        "rms_before": rms(residual(pi_nominal, zeros, zeros, zeros, zeros)),
        "rms_after": rms(residual(pi_corrected, coulomb, viscous, torque_scale, torque_offset)),
    }
    if stance_speed is not None:
        diagnostics["stance_frame_speed_p95"] = stance_speed
    return ModelCorrections(
        spatial_inertias=corrected,
        coulomb=coulomb,
        viscous=viscous,
        smoothing_velocity=v_s,
        torque_offset=torque_offset,
        torque_scale=torque_scale,
        body_names={int(i): plant.get_body(BodyIndex(int(i))).name() for i in corrected},
        diagnostics=diagnostics,
    )


# ---------------------------------------------------------------------------------------
# The corrected joint torque as a Drake system.
# ---------------------------------------------------------------------------------------


class CorrectedJointTorque(LeafSystem):
    """The joint effort from the measured motor torques, with identified corrections.

    Inputs:
        measured_torque: n = nv - 6, motor torques in v[6:] order, N m.
        state: the plant's [q; v] (nq + nv), as estimated.

    Outputs:
        joint_torque: n, N m: ``corrections.corrected_torque(measured_torque, v[6:])``
            (direct feedthrough of both inputs).

    Raises:
        ValueError: a plant that is not floating-base, corrections of the wrong size, or
            (at evaluation) NaN/inf on an input, naming the port.
    """

    def __init__(self, plant: MultibodyPlant, corrections: ModelCorrections):
        super().__init__()
        who = "CorrectedJointTorque"
        check_plant(plant, who)
        n = floating_base_topology(plant).num_joints
        for name in ("coulomb", "viscous", "torque_offset", "torque_scale"):
            value = np.asarray(getattr(corrections, name), dtype=float)
            if value.shape != (n,) or not np.isfinite(value).all():
                raise ValueError(f"{who}: corrections.{name} must be {n} finite values, got shape {value.shape}")
        positive_number(corrections.smoothing_velocity, f"{who}: corrections.smoothing_velocity")
        self.corrections = corrections
        self._nq = plant.num_positions()
        self._measured = self.DeclareVectorInputPort("measured_torque", n)
        self._state = self.DeclareVectorInputPort("state", self._nq + plant.num_velocities())
        self.DeclareVectorOutputPort("joint_torque", n, self._calc_torque)

    def _calc_torque(self, context: Context, output: BasicVector) -> None:
        tau_m = eval_finite_input("CorrectedJointTorque", self._measured, context)
        x = eval_finite_input("CorrectedJointTorque", self._state, context)
        output.SetFromVector(self.corrections.corrected_torque(tau_m, x[self._nq + 6 :]))


__all__ = [
    "PARAMETER_NAMES",
    "BaseParameterMap",
    "CalibrationLog",
    "CorrectedJointTorque",
    "IdentificationOptions",
    "InertialParameterRegressor",
    "ModelCorrections",
    "base_parameter_map",
    "stance_base_velocity",
    "central_unit_inertia",
    "identify_model_corrections",
    "inertial_parameters",
    "newton_euler_matrix",
]
