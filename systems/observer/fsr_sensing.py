"""Measurement pipeline of the Kalman force observer (Hawley, Rahem, Suleiman 2019, Sec. 4)
on a simulated small humanoid: what a Nao computes from its foot FSRs, IMU and encoders.

    contact results ─► FsrArray ─► fsr_forces (8) ─► CenterOfPressure ─► normal_force f_n^o (eq. 12)
                                                          ▲ state      └─► zmp = CoP (eq. 13)
    sensed state ─► SupportFootCom ─► com_position (forward kinematics, Sec. 4.4)
    accelerometer + sensed state ─► ImuComAcceleration ─► com_acceleration (Fig. 4)

Frame convention (all outputs that carry positions): the observer works in the
*support-foot frame* F, a world-aligned frame (axes parallel to the world's: x forward,
z up on flat ground) whose origin is the origin of the support sole frame
(``HumanoidHandles.sole_frames[support_foot]``, the centre of the sole plane, i.e. on the
ground while the foot is flat). So z_c is the CoM height above the ground and the CoP
lies in z = 0, as the LIP/ZMP model of eqs. (2)-(13) needs. Its orientation uses the
sensed base orientation (IMU-based estimate in ``systems.simulation.sensors``), never the true state.

FSR model: each FSR is one of the robot's foot contact spheres (4 per foot, documented Nao
positions in ``HumanoidHandles.fsr_positions``); it reads the normal component of the
contact force on its sphere, plus zero-mean Gaussian noise (sampled and held, seeded, see
``systems.simulation.noise``), clipped to the sensor's range [0, 25] N (Nao's FSR range, Sec. 4.1).
Only point contact (the station's contact model) is read; a hydroelastic contact on an FSR
sphere raises a ValueError rather than reading zero.

Units are SI throughout (N, m, m/s^2).
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.multibody.tree import Frame
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from models import FSR_ORDER, HumanoidHandles
from systems.common.checks import check_plant, eval_finite_input
from systems.common.contact_results import robot_point_contacts
from systems.simulation.noise import SampledNoise, as_std_vector, check_period, check_seed

#: Nao's FSR range (paper Sec. 4.1), N.
FSR_SATURATION = 25.0
#: Default FSR noise standard deviation, N per sensor. In the authors' two real recordings
#: (``data/hawley2019-nao`` in the repository, first 2 s, at rest, scaled to newtons by their
#: calibration) each foot's summed reading varies from sample to sample by 0.15-0.30 N
#: (std), i.e. 0.08-0.15 N per sensor if the 4 are independent: hence 0.1 N.
FSR_NOISE_STD = 0.1
#: Default sample-and-hold period of the FSR noise, s (the other sensors' 1 kHz).
FSR_NOISE_PERIOD = 1e-3
#: Below this total normal force, N, the CoP is undefined (feet off the ground): the
#: ``zmp`` output is then the frame origin (0, 0) and the observer flags its output invalid.
MIN_CONTACT_FORCE = 0.5
#: Order of the 8 FSRs in every ``fsr_forces`` vector: left foot then right foot, each in
#: ``models.FSR_ORDER`` (front_left, front_right, rear_left, rear_right).
FSR_SIDES = ("left", "right")
FSR_NAMES = tuple(f"{side}_{name}" for side in FSR_SIDES for name in FSR_ORDER)


def _check_handles(handles, who: str) -> HumanoidHandles:
    if not isinstance(handles, HumanoidHandles):
        raise ValueError(f"{who}: handles must be HumanoidHandles, got {type(handles).__name__}")
    for side in FSR_SIDES:
        if side not in handles.sole_frames or side not in handles.fsr_positions:
            raise ValueError(f"{who}: the humanoid has no '{side}' sole frame / FSR positions")
        if np.asarray(handles.fsr_positions[side]).shape != (len(FSR_ORDER), 2):
            raise ValueError(f"{who}: fsr_positions['{side}'] must be 4 x 2")
    return handles


def _support_frame(handles: HumanoidHandles, support_foot, who: str) -> Frame:
    if support_foot not in handles.sole_frames:
        raise ValueError(f"{who}: unknown support foot {support_foot!r}; choose one of {sorted(handles.sole_frames)}")
    return handles.sole_frames[support_foot]


class FsrArray(LeafSystem):
    """The 8 foot force-sensing resistors: normal force of each FSR contact sphere.

    Inputs:
        contact_results: abstract ``ContactResults`` of the plant
            (``plant.get_contact_results_output_port()``).

    Outputs:
        fsr_forces: (8) N, order ``FSR_NAMES`` (left foot then right foot, each front_left,
            front_right, rear_left, rear_right): clip(f_n,i + noise_i(t), 0, saturation),
            where f_n,i >= 0 is the normal component of the contact force on sphere i
            (along the contact normal, pushing the sphere out of the ground), summed over
            its point pairs; 0 without contact (then only noise, clipped at 0).
        true_fsr_forces: (8) N, the same without noise and saturation (ground truth, for
            tests and metrics only).

    Args:
        plant: the finalized plant holding the humanoid.
        handles: the humanoid's handles (``fsr_geometries``: the sphere GeometryIds).
        noise_std: N, scalar or 8 entries (default ``FSR_NOISE_STD``); 0 for an ideal sensor.
        saturation: the sensors' upper range, N (default 25 N, Nao), scalar or 8 entries;
            readings are clipped to [0, saturation].
        period: noise sample-and-hold period, s.
        seed: noise seed (non-negative integer).

    Raises:
        ValueError: plant not finalized, handles without the 8 FSR GeometryIds (plant
            without SceneGraph), bad noise_std / saturation / period / seed; at evaluation,
            a hydroelastic contact on an FSR sphere.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        handles: HumanoidHandles,
        *,
        noise_std=FSR_NOISE_STD,
        saturation: float = FSR_SATURATION,
        period: float = FSR_NOISE_PERIOD,
        seed: int = 0,
    ):
        super().__init__()
        who = type(self).__name__
        check_plant(plant, who)
        _check_handles(handles, who)
        ids = []
        for side in FSR_SIDES:
            side_ids = tuple(handles.fsr_geometries.get(side, ()))
            if len(side_ids) != len(FSR_ORDER):
                raise ValueError(
                    f"{who}: the humanoid has no 4 FSR geometries on the {side} foot "
                    "(was the plant registered with a SceneGraph?)"
                )
            ids.extend(side_ids)
        self._index = {gid: i for i, gid in enumerate(ids)}
        try:
            std = as_std_vector(noise_std, len(ids), "noise_std")
            period, seed = check_period(period), check_seed(seed)
        except ValueError as err:
            raise ValueError(f"{who}: {err}") from err
        saturation = np.asarray(saturation, dtype=float)
        positive = np.isfinite(saturation).all() and (saturation > 0.0).all()
        if saturation.shape not in ((), (len(ids),)) or not positive:
            raise ValueError(
                f"{who}: saturation must be a positive number of newtons or {len(ids)} of them, got {saturation}"
            )
        self._saturation = float(saturation) if saturation.shape == () else saturation
        self._noise = SampledNoise(len(ids), std, period, seed)
        self._contact = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self.DeclareVectorOutputPort("fsr_forces", len(ids), self._CalcFsrForces)
        self.DeclareVectorOutputPort("true_fsr_forces", len(ids), self._CalcTrueForces)

    @property
    def saturation(self) -> float | np.ndarray:
        """The sensors' upper range, N: a number, or one per FSR (``FSR_NAMES`` order)."""
        return self._saturation

    @property
    def noise(self) -> SampledNoise:
        return self._noise

    def normal_forces(self, results: ContactResults) -> np.ndarray:
        """(8) noise-free normal force of each FSR sphere in ``results``, N (>= 0 for
        compressive contact): the force on the sphere along the contact normal pointing
        out of the other geometry (``systems.common.contact_results``' convention)."""
        return robot_point_contacts(results, self._index, "FsrArray").summed(self._index, len(self._index))

    def _CalcTrueForces(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.normal_forces(self._contact.Eval(context)))

    def _CalcFsrForces(self, context: Context, output: BasicVector) -> None:
        forces = self.normal_forces(self._contact.Eval(context))
        if not self._noise.is_zero:
            forces += self._noise.value(context.get_time())
        output.SetFromVector(np.clip(forces, 0.0, self._saturation))


class _KinematicsSystem(LeafSystem):
    """Shared part: a ``state`` input (sensed [q; v]) and a private plant context."""

    def __init__(self, plant: MultibodyPlant, who: str):
        super().__init__()
        check_plant(plant, who)
        self._plant = plant
        self._who = who
        self._plant_context = plant.CreateDefaultContext()
        self._nq = plant.num_positions()
        self._state = self.DeclareVectorInputPort("state", plant.num_positions() + plant.num_velocities())

    def _set_positions(self, context: Context) -> None:
        x = eval_finite_input(self._who, self._state, context)
        self._plant.SetPositions(self._plant_context, x[: self._nq])

    def _frame_origin(self, handles: HumanoidHandles, support_foot, origin_W) -> None:
        """F's origin: the support sole frame's origin (standing), or the fixed world point
        ``origin_W`` (walking: a frame that followed the support foot would make the
        observer's CoM state jump by a step length at every change of support)."""
        if origin_W is None:
            self._support = self._check_frame(_support_frame(handles, support_foot, self._who), "support sole frame")
            self._origin_W = None
        else:
            origin = np.asarray(origin_W, dtype=float).reshape(-1)
            if origin.shape != (3,) or not np.isfinite(origin).all():
                raise ValueError(f"{self._who}: origin_W must be 3 finite numbers (m), got {origin_W!r}")
            self._support, self._origin_W = None, origin

    def _p_WF(self) -> np.ndarray:
        """The origin of F in world at the context's positions (after ``_set_positions``)."""
        if self._origin_W is not None:
            return self._origin_W
        return self._support.CalcPoseInWorld(self._plant_context).translation()

    def _check_frame(self, frame, name: str) -> Frame:
        if not isinstance(frame, Frame):
            raise ValueError(f"{self._who}: {name} must be a Frame, got {type(frame).__name__}")
        if frame.GetParentPlant() is not self._plant:
            raise ValueError(f"{self._who}: {name} {frame.name()!r} is not a frame of this plant")
        return frame


class CenterOfPressure(_KinematicsSystem):
    """Total normal force (eq. 12) and CoP = ZMP (eq. 13) from the 8 FSR readings.

    Inputs:
        fsr_forces: (8) N, order ``FSR_NAMES`` (``FsrArray``'s output).
        state: the SENSED plant state [q; v] (encoders + base estimate): places each FSR in
            the support-foot frame F by forward kinematics of its sole frame.

    Outputs:
        normal_force: (1) f_n^o = -(sum of the 8 readings) (eq. 12), N: -M g at rest (the
            paper's sign, the observer's ``normal_force`` input).
        zmp: (2) [p_x, p_y] = sum_i F_i (x_i, y_i) / |f_n^o| (eq. 13), m, with (x_i, y_i) the
            FSR positions in F (world-aligned, origin at the support sole frame); (0, 0)
            when |f_n^o| < ``min_contact_force`` (no CoP without contact).

    Args:
        plant: the finalized plant.
        handles: the humanoid's handles (sole frames, FSR positions in the sole frames).
        support_foot: "left" or "right", the sole frame at the origin of F.
        origin_W: instead, a fixed world point as F's origin, m (for a walking robot:
            CoM and ZMP stay continuous when the support foot changes).
        min_contact_force: N, see ``zmp``.

    Raises:
        ValueError: unfinalized plant, unknown support foot, bad handles; NaN/inf on an
            input at evaluation.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        handles: HumanoidHandles,
        *,
        support_foot: str = "right",
        origin_W: np.ndarray | None = None,
        min_contact_force: float = MIN_CONTACT_FORCE,
    ):
        super().__init__(plant, type(self).__name__)
        _check_handles(handles, self._who)
        self._frame_origin(handles, support_foot, origin_W)
        self._soles = [self._check_frame(handles.sole_frames[side], f"sole_frames['{side}']") for side in FSR_SIDES]
        # FSR positions in their sole frame, homogeneous: (4, 3) per side, z = 0 (sole plane).
        self._fsr_S = [
            np.column_stack((np.asarray(handles.fsr_positions[side], float), np.zeros(4))) for side in FSR_SIDES
        ]
        self._min_force = float(min_contact_force)
        if not (np.isfinite(self._min_force) and self._min_force > 0.0):
            raise ValueError(f"{self._who}: min_contact_force must be positive, got {min_contact_force}")
        self._fsr = self.DeclareVectorInputPort("fsr_forces", len(FSR_NAMES))
        self.DeclareVectorOutputPort(
            "normal_force",
            1,
            self._CalcNormalForce,
            prerequisites_of_calc={self.input_port_ticket(self._fsr.get_index())},
        )
        self.DeclareVectorOutputPort("zmp", 2, self._CalcZmp)

    def fsr_positions(self, context: Context) -> np.ndarray:
        """(8, 3) the FSR positions in F (world-aligned), m, from the ``state`` input."""
        self._set_positions(context)
        p_WF = self._p_WF()
        rows = []
        for sole, p_S in zip(self._soles, self._fsr_S):
            X_WS = sole.CalcPoseInWorld(self._plant_context)
            rows.append(p_S @ X_WS.rotation().matrix().T + (X_WS.translation() - p_WF))
        return np.vstack(rows)

    def _CalcNormalForce(self, context: Context, output: BasicVector) -> None:
        forces = eval_finite_input(self._who, self._fsr, context)
        output.SetFromVector([-float(np.sum(forces))])

    def _CalcZmp(self, context: Context, output: BasicVector) -> None:
        forces = np.asarray(eval_finite_input(self._who, self._fsr, context))
        total = float(np.sum(forces))
        if abs(total) < self._min_force:
            output.SetFromVector(np.zeros(2))
            return
        positions = self.fsr_positions(context)
        output.SetFromVector(forces @ positions[:, :2] / abs(total))


class SupportFootCom(_KinematicsSystem):
    """CoM position in the support-foot frame by forward kinematics (paper Sec. 4.4).

    Inputs:
        state: the SENSED plant state [q; v] (encoders + base estimate).

    Outputs:
        com_position: (3) p_FoCm expressed in F = p_WCm - p_WFo in world axes, m (F is
            world-aligned with its origin at the support sole frame, so z is the CoM height
            above the ground while that foot is flat).

    Args:
        plant: the finalized plant.
        handles: the humanoid's handles (its model instance defines the CoM).
        support_foot: "left" or "right".
        origin_W: instead, a fixed world point as F's origin, m (see ``CenterOfPressure``).

    Raises:
        ValueError: unfinalized plant, unknown support foot, bad origin; NaN/inf on ``state``.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        handles: HumanoidHandles,
        *,
        support_foot: str = "right",
        origin_W: np.ndarray | None = None,
    ):
        super().__init__(plant, type(self).__name__)
        if not isinstance(handles, HumanoidHandles):
            raise ValueError(f"{self._who}: handles must be HumanoidHandles, got {type(handles).__name__}")
        self._frame_origin(handles, support_foot, origin_W)
        self._instances = [handles.model_instance]
        self.DeclareVectorOutputPort("com_position", 3, self._CalcCom)

    def _CalcCom(self, context: Context, output: BasicVector) -> None:
        self._set_positions(context)
        ctx = self._plant_context
        p_WCm = self._plant.CalcCenterOfMassPositionInWorld(ctx, self._instances)
        output.SetFromVector(p_WCm - self._p_WF())


class ImuComAcceleration(_KinematicsSystem):
    """CoM acceleration from the IMU accelerometer (paper Sec. 4.3 and Fig. 4): the reading
    is projected to the inertial frame and gravity-compensated; the CoM is assumed to move
    with the IMU (the paper's assumption).

    Inputs:
        linear_acceleration: (3) accelerometer reading in the IMU frame S, R_SW (a_WS - g_W),
            m/s^2 (+9.81 along S's up axis at rest), e.g. ``add_imu(...)
            .linear_acceleration``.
        state: the SENSED plant state [q; v]: gives R_WS (base orientation estimate times
            the IMU's fixed mounting).

    Outputs:
        com_acceleration: (3) a_W = R_WS f_S + g_W, m/s^2, world axes (= the support-foot
            frame's, which is world-aligned); ~0 at rest.

    Args:
        plant: the finalized plant.
        imu_frame: the IMU frame S (``HumanoidHandles.imu_frame``).

    Raises:
        ValueError: unfinalized plant, a frame not of this plant; NaN/inf on an input.
    """

    def __init__(self, plant: MultibodyPlant, imu_frame: Frame):
        super().__init__(plant, type(self).__name__)
        self._imu = self._check_frame(imu_frame, "imu_frame")
        self._g_W = np.asarray(plant.gravity_field().gravity_vector(), dtype=float).copy()
        self._accel = self.DeclareVectorInputPort("linear_acceleration", 3)
        self.DeclareVectorOutputPort("com_acceleration", 3, self._CalcAcceleration)

    def _CalcAcceleration(self, context: Context, output: BasicVector) -> None:
        f_S = np.asarray(eval_finite_input(self._who, self._accel, context))
        self._set_positions(context)
        R_WS = self._imu.CalcRotationMatrixInWorld(self._plant_context).matrix()
        output.SetFromVector(R_WS @ f_S + self._g_W)


class FsrSoleWrenches(_KinematicsSystem):
    """The wrench the FSRs of each sole measure: the ground's normal force and its centre of
    pressure, as a wrench at the sole frame, for the estimators' eq. (10) (the known
    wrenches of a foot without F/T sensor; its shear and yaw moment stay unknowns,
    ``systems.residuals.contact_estimation.SOLE_SHEAR_AND_YAW``).

    With n = R_WS e_z the sole's normal and p_i = R_WS [x_i, y_i, 0] the FSRs' positions
    from the sole frame's origin (world), the readings F_i give

        f = (sum_i F_i) n,   m = sum_i p_i x (F_i n)

    i.e. the normal force f_z and the moments m_x, m_y about the sole's axes; its m_z, f_x
    and f_y are 0. Exact for a flat foot whose contact forces act at the FSRs (a shear
    force in the sole plane adds only m_z and f_x, f_y about the sole's origin).

    Inputs:
        fsr_forces: (8) N, order ``FSR_NAMES`` (``FsrArray``'s output).
        state: the sensed [q; v] of ``plant`` (the sole's orientation).

    Outputs:
        wrenches: 6 per side of ``sides``: [moment about the sole frame's origin, N m (3);
            force, N (3)], world (the F/T sensors' convention).

    Args:
        plant: the estimators' finalized plant.
        handles: its humanoid handles (sole frames, FSR positions in the sole frames).
        sides: the feet whose wrenches to output, in that order (default both, ``FSR_SIDES``).

    Raises:
        ValueError: an unfinalized plant, bad handles, an unknown side; NaN or inf on an
            input at evaluation.
    """

    def __init__(self, plant: MultibodyPlant, handles: HumanoidHandles, sides=FSR_SIDES):
        super().__init__(plant, type(self).__name__)
        _check_handles(handles, self._who)
        sides = tuple(sides)
        unknown = [side for side in sides if side not in FSR_SIDES]
        if unknown or not sides or len(set(sides)) != len(sides):
            raise ValueError(f"{self._who}: sides must be distinct entries of {FSR_SIDES}, got {sides!r}")
        self._sides = sides
        self._soles = [self._check_frame(handles.sole_frames[side], f"sole_frames['{side}']") for side in sides]
        # Per side: (4, 3) FSR positions in the sole frame (z = 0) and the 4 readings' slots.
        self._p_S = np.array(
            [np.column_stack((np.asarray(handles.fsr_positions[side], float), np.zeros(4))) for side in sides]
        )
        self._slots = np.array([[FSR_NAMES.index(f"{side}_{name}") for name in FSR_ORDER] for side in sides])
        self._fsr = self.DeclareVectorInputPort("fsr_forces", len(FSR_NAMES))
        self.DeclareVectorOutputPort("wrenches", 6 * len(sides), self._CalcWrenches)

    @property
    def sides(self) -> tuple[str, ...]:
        return self._sides

    def sole_wrenches(self, readings: np.ndarray, R_WS: np.ndarray) -> np.ndarray:
        """(k, 6) the class docstring's wrenches from the 8 ``readings`` and the k soles'
        rotations R_WS (k, 3, 3); or (N, k, 6) of N samples at once, readings (N, 8) and R_WS
        (N, k, 3, 3)."""
        F = np.asarray(readings, dtype=float)[..., self._slots]  # ([N,] k, 4)
        n = R_WS[..., :, 2]  # ([N,] k, 3)
        force = F.sum(axis=-1)[..., None] * n
        # sum_i F_i (R p_i) x n = R (sum_i F_i p_i) x n: the readings' first moment in the sole.
        first_moment = np.einsum("...ki,kij->...kj", F, self._p_S)  # ([N,] k, 3) in the sole frame
        moment = np.cross(np.einsum("...kij,...kj->...ki", R_WS, first_moment), n)
        return np.concatenate((moment, force), axis=-1)

    def _CalcWrenches(self, context: Context, output: BasicVector) -> None:
        self._set_positions(context)
        readings = eval_finite_input(self._who, self._fsr, context)
        R_WS = np.array([sole.CalcRotationMatrixInWorld(self._plant_context).matrix() for sole in self._soles])
        output.SetFromVector(self.sole_wrenches(readings, R_WS).ravel())


__all__ = [
    "FSR_NAMES",
    "FsrSoleWrenches",
    "FSR_NOISE_STD",
    "FSR_SATURATION",
    "CenterOfPressure",
    "FsrArray",
    "ImuComAcceleration",
    "SupportFootCom",
]
