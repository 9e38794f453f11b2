"""Walking pattern generator for ``nao_like``: ZMP preview control on the cart-table model
(Kajita et al., "Biped walking pattern generation by using preview control of
zero-moment point", ICRA 2003), swing-foot trajectories, and whole-body joint targets
through the analytic leg IK of ``systems.locomotion.leg_ik``; output by ``NaoWalkingController``.

Cart-table model, per horizontal axis, sampled with period T (eqs. K-1..K-2; Kajita 2003
eqs. 5-6 and 8)::

    x_{k+1} = A x_k + B u_k,   x = [c, c_dot, c_ddot] (m, m/s, m/s^2), u = jerk (m/s^3)
    A = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]],   B = [T^3/6, T^2/2, T]^T         (K-1)
    p_k = C x_k,   C = [1, 0, -z_c/g]   (the cart-table ZMP, m)                   (K-2)

Preview control with integral action (Katayama et al. 1985; Kajita 2003 eqs. 11-15): with
the augmented state [sum of p - p_ref; x] (error integral, then the state),

    A~ = [[1, C A], [0, A]],  B~ = [C B; B],  Q~ = diag(Q_e, 0, 0, 0),  R,
    P = DARE(A~, B~, Q~, R),  S = R + B~^T P B~,  [G_i, G_x] = S^-1 B~^T P A~,       (K-3)
    A_c = A~ - B~ [G_i, G_x],  X_1 = -A_c^T P I~,  G_p(1) = -G_i,
    G_p(j) = S^-1 B~^T X_{j-1},  X_j = A_c^T X_{j-1}  (j = 2..N_L),                 (K-4)
    u_k = -G_i sum_{i<=k} (p_i - p_ref,i) - G_x x_k - sum_{j=1..N_L} G_p(j) p_ref,k+j. (K-5)

Footstep plan (world frame, x forward, straight walking): both soles start on the ground,
the robot waits ``initial_wait`` s, then makes ``num_steps`` steps of ``step_duration`` s
each: a double-support phase (``double_support_ratio`` of the step) during which the ZMP
reference moves linearly from the previous support point to the next support foot, then a
single-support phase with the ZMP reference at the support sole (plus ``zmp_offset_x``
forward and ``zmp_offset_y`` towards the other foot, which narrows the lateral sway) while
the other foot swings. Footprints: step k (1-based) lands its swing foot
k * step_length ahead of the start, except the last one, which closes the stance (lands
beside the other foot). Afterwards the ZMP reference returns to the middle of the feet in
one step duration and the robot stands ``final_wait`` s.

Swing foot (eq. S-1): from footprint a to footprint b over the single-support time T_ss,
s = (t - t_lift) / T_ss in [0, 1]:

    p_xy = a + (b - a) (10 s^3 - 15 s^4 + 6 s^5),   p_z = h 64 s^3 (1 - s)^3,      (S-1)

both with zero velocity and acceleration at lift-off and touch-down (h = swing height).

Whole body (eq. W-1): the torso (floating base) stays level with a constant heading; its
position p_T is found by the fixed-point iteration

    p_T <- p_T + (c_ref - CoM(IK(p_T, soles)))                                    (W-1)

on the plant's ``CalcCenterOfMassPositionInWorld`` (a few iterations; the residual is
reported), so that the multibody robot's CoM follows the preview CoM (x, y) at the constant
height z_c; the arms and head hold the nominal posture. The cart-table model ignores the
legs' dynamics (the swing leg's angular momentum moves the ZMP of the planned motion by up to
~19 mm at 0.05 m / 0.5 s steps): as in Kajita 2003, the multibody ZMP of the planned motion
(eq. Z-1, ``multibody_zmp``) is computed and a second preview pass on the ZMP error corrects
the CoM (``correct_for_multibody_zmp``; ~4 mm left after one pass). Optionally the targets
include the static deflection of the PD-controlled joints under the planned ground reaction
(eq. W-2, ``stiffness_compensation``). The joint targets are precomputed at
construction on the pattern's grid (an open-loop pattern, as Nao's walk engine plays it)
and interpolated linearly in time by ``NaoWalkingController``.

Units: SI (m, s, rad) throughout.
"""

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from models import HumanoidHandles, set_standing_state
from systems.common.smoothing import smoothstep5
from systems.common.topology import floating_base_topology
from systems.locomotion.leg_ik import LEG_JOINTS, NaoLegGeometry, leg_ik

SIDES = ("left", "right")
#: Largest step length accepted before the IK check, m (the straight leg reaches about
#: sqrt(0.2029^2 - z^2) ~ 0.08 m horizontally from the hip at z_c = 0.255 m).
MAX_STEP_LENGTH = 0.08


def _bump(s: np.ndarray) -> np.ndarray:
    """64 s^3 (1 - s)^3 on [0, 1], 0 outside: peak 1 at s = 1/2, zero velocity and
    acceleration at both ends."""
    s = np.clip(s, 0.0, 1.0)
    return 64.0 * (s * (1.0 - s)) ** 3


@dataclass
class WalkingParameters:
    """Parameters of the walking pattern (all SI). A plain dataclass, so that a scenario can
    nest it (``diagrams.scenarios``); ``check()`` repeats ``__post_init__``'s checks on
    loaded values.

    Attributes:
        step_length: forward distance between consecutive footprints, m (negative walks
            backwards; |step_length| <= MAX_STEP_LENGTH).
        step_width: lateral distance between the two feet's footprints, m.
        step_duration: duration of one step (double + single support), s.
        double_support_ratio: fraction of each step spent in double support, in [0, 1).
        num_steps: number of steps (swing phases, the last one closing the stance), >= 1.
        swing_height: peak height of the swing sole above the ground, m.
        com_height: z_c, the CoM height kept while walking (eq. K-2), m.
        zmp_offset_x: forward offset of the ZMP reference from the sole frame origin, m
            (Nao's FSR polygon spans x in [-0.03, 0.07] in the sole frame).
        zmp_offset_y: inward offset (towards the other foot) of the single-support ZMP
            reference from the sole frame origin, m; > 0 narrows the lateral sway.
        initial_wait: time before the first step (the CoM lowers to z_c and moves over the
            feet), s.
        final_wait: time standing after the ZMP has returned between the feet, s.
        first_swing_foot: "left" or "right".
        preview_time: preview horizon N_L T, s.
        sample_period: T, the pattern's sampling period, s.
        zmp_weight, jerk_weight: Q_e and R of eq. K-3.
        gravity: g, m/s^2.
    """

    step_length: float = 0.05
    step_width: float = 0.10
    step_duration: float = 0.5
    double_support_ratio: float = 0.3
    num_steps: int = 22
    swing_height: float = 0.02
    com_height: float = 0.255
    zmp_offset_x: float = 0.01
    zmp_offset_y: float = 0.015
    initial_wait: float = 1.0
    final_wait: float = 1.0
    first_swing_foot: str = "right"
    preview_time: float = 1.2
    sample_period: float = 0.005
    zmp_weight: float = 1.0
    jerk_weight: float = 1e-6
    gravity: float = 9.81

    def __post_init__(self):
        self.check()

    def check(self) -> None:
        """Raises ValueError on a bad value (the message names it)."""
        for name in (
            "step_length",
            "step_width",
            "step_duration",
            "double_support_ratio",
            "swing_height",
            "com_height",
            "zmp_offset_x",
            "zmp_offset_y",
            "initial_wait",
            "final_wait",
            "preview_time",
            "sample_period",
            "zmp_weight",
            "jerk_weight",
            "gravity",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"WalkingParameters.{name} must be a finite number, got {value!r}")
        if self.step_duration <= 0:
            raise ValueError(f"step_duration must be positive, got {self.step_duration} s")
        if not (0.0 <= self.double_support_ratio < 1.0):
            raise ValueError(f"double_support_ratio must be in [0, 1), got {self.double_support_ratio}")
        if not (isinstance(self.num_steps, (int, np.integer)) and self.num_steps >= 1):
            raise ValueError(f"num_steps must be an integer >= 1, got {self.num_steps!r}")
        if abs(self.step_length) > MAX_STEP_LENGTH:
            raise ValueError(
                f"step_length {self.step_length} m is out of reach of nao_like's legs "
                f"(|step_length| <= {MAX_STEP_LENGTH} m)"
            )
        if not (0.06 <= self.step_width <= 0.20):
            raise ValueError(f"step_width must be in [0.06, 0.20] m (feet must not overlap), got {self.step_width}")
        if not (0.0 <= self.swing_height <= 0.05):
            raise ValueError(f"swing_height must be in [0, 0.05] m, got {self.swing_height}")
        if not (0.15 <= self.com_height <= 0.30):
            raise ValueError(f"com_height must be in [0.15, 0.30] m, got {self.com_height}")
        if self.sample_period <= 0 or self.preview_time < self.sample_period:
            raise ValueError("sample_period must be positive and preview_time >= sample_period")
        if self.single_support_time < 2 * self.sample_period:
            raise ValueError(
                f"the single-support time {self.single_support_time} s is shorter than two "
                f"samples ({self.sample_period} s): lower double_support_ratio or lengthen the step"
            )
        if not (-0.02 <= self.zmp_offset_y <= 0.5 * self.step_width - 0.01):
            raise ValueError(f"zmp_offset_y must be in [-0.02, step_width/2 - 0.01] m, got {self.zmp_offset_y}")
        if self.initial_wait < 0 or self.final_wait < 0:
            raise ValueError("initial_wait and final_wait must be non-negative")
        if self.first_swing_foot not in SIDES:
            raise ValueError(f"first_swing_foot must be 'left' or 'right', got {self.first_swing_foot!r}")
        if self.zmp_weight <= 0 or self.jerk_weight <= 0 or self.gravity <= 0:
            raise ValueError("zmp_weight, jerk_weight and gravity must be positive")

    @property
    def double_support_time(self) -> float:
        return self.step_duration * self.double_support_ratio

    @property
    def single_support_time(self) -> float:
        return self.step_duration - self.double_support_time

    @property
    def walk_start(self) -> float:
        """Start of the first step's double support, s."""
        return self.initial_wait

    @property
    def walk_end(self) -> float:
        """Touch-down of the last step, s."""
        return self.initial_wait + self.num_steps * self.step_duration

    @property
    def duration(self) -> float:
        """Length of the whole pattern, s."""
        return self.walk_end + self.step_duration + self.final_wait


# ---------------------------------------------------------------------------------------
# Footsteps and ZMP reference.
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Footstep:
    """One swing phase.

    Attributes:
        side: the swing foot, "left" or "right".
        start, end: (3,) the swing sole's footprint before and after, world, m.
        support_position: (3,) the support sole's footprint, world, m.
        t_start: start of the step's double support, s.
        t_lift, t_land: lift-off and touch-down of the swing foot, s.
        swing_height: peak height of the swing sole above the line from start to end, m.
    """

    side: str
    start: np.ndarray
    end: np.ndarray
    support_position: np.ndarray
    t_start: float
    t_lift: float
    t_land: float
    swing_height: float


def plan_footsteps(params: WalkingParameters, left0: np.ndarray, right0: np.ndarray) -> list[Footstep]:
    """The footstep plan of the module docstring from the initial sole positions (world, m).

    The footprints are at y = mid_y +- step_width / 2 around the initial feet's mid-point,
    x = mid_x + k step_length (the last step closes the stance).
    """
    feet = {"left": np.asarray(left0, float).copy(), "right": np.asarray(right0, float).copy()}
    mid = 0.5 * (feet["left"] + feet["right"])
    y_side = {"left": mid[1] + 0.5 * params.step_width, "right": mid[1] - 0.5 * params.step_width}
    swing = params.first_swing_foot
    steps = []
    for k in range(1, params.num_steps + 1):
        support = "left" if swing == "right" else "right"
        n = k if k < params.num_steps else k - 1  # the last step closes the stance
        end = np.array([mid[0] + n * params.step_length, y_side[swing], mid[2]])
        t_start = params.walk_start + (k - 1) * params.step_duration
        steps.append(
            Footstep(
                side=swing,
                start=feet[swing].copy(),
                end=end,
                support_position=feet[support].copy(),
                t_start=t_start,
                t_lift=t_start + params.double_support_time,
                t_land=t_start + params.step_duration,
                swing_height=params.swing_height,
            )
        )
        feet[swing] = end
        swing = support
    return steps


def zmp_reference_knots(
    params: WalkingParameters, steps: list[Footstep], com0_xy: np.ndarray, left0: np.ndarray, right0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Knots (times (M,), points (M, 2)) of the piecewise-linear ZMP reference, world, m.

    From the initial CoM (x, y) it moves to the feet's mid-point (+ offset) during
    ``initial_wait``; each step's double support moves it to the support sole (+
    ``zmp_offset_x`` forward, + ``zmp_offset_y`` inwards), where it stays during single
    support; it returns to the final feet's mid-point in one step duration and stays there.
    """
    off = np.array([params.zmp_offset_x, 0.0])
    mid0 = 0.5 * (np.asarray(left0, float)[:2] + np.asarray(right0, float)[:2]) + off
    times, points = [0.0], [np.asarray(com0_xy, float)[:2]]
    if params.initial_wait > 0:
        times.append(params.initial_wait)
        points.append(mid0)
    else:
        points[0] = mid0
    feet = {"left": np.asarray(left0, float), "right": np.asarray(right0, float)}
    for step in steps:
        toward_swing_side = 1.0 if step.side == "left" else -1.0  # y direction of the inner side
        support = step.support_position[:2] + off + np.array([0.0, toward_swing_side * params.zmp_offset_y])
        times += [step.t_start + params.double_support_time, step.t_land]
        points += [support, support]
        feet[step.side] = step.end
    mid_end = 0.5 * (feet["left"][:2] + feet["right"][:2]) + off
    times += [params.walk_end + params.step_duration, params.duration]
    points += [mid_end, mid_end]
    t = np.array(times)
    if np.any(np.diff(t) < 0):
        raise ValueError("internal error: ZMP knots out of order")
    return t, np.array(points)


def interpolate_knots(t: np.ndarray, times: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of (M, d) knot points at times t (K,) -> (K, d)."""
    return np.column_stack([np.interp(t, times, points[:, i]) for i in range(points.shape[1])])


def foot_trajectories(
    t: np.ndarray, steps: list[Footstep], left0: np.ndarray, right0: np.ndarray
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Sole positions (world, m) at times t (K,) per side, (K, 3), with the swing
    trajectory of eq. S-1, and the planned contact flag per side (K,) (False in swing)."""
    t = np.asarray(t, float)
    pos = {
        "left": np.tile(np.asarray(left0, float), (t.size, 1)),
        "right": np.tile(np.asarray(right0, float), (t.size, 1)),
    }
    contact = {side: np.ones(t.size, dtype=bool) for side in SIDES}
    for step in steps:
        p = pos[step.side]
        during = (t > step.t_lift) & (t < step.t_land)
        after = t >= step.t_land
        s = (t[during] - step.t_lift) / (step.t_land - step.t_lift)
        p[during] = step.start + np.outer(smoothstep5(s), step.end - step.start)
        p[during, 2] += step.swing_height * _bump(s)
        p[after] = step.end
        contact[step.side][during] = False
    return pos, contact


# ---------------------------------------------------------------------------------------
# Preview control (eqs. K-1..K-5).
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PreviewGains:
    """Cart-table model and preview gains (eqs. K-1..K-4).

    Attributes:
        A (3, 3), B (3,), C (3,): the discrete cart-table model.
        Gi: integral gain (scalar, 1/m^... jerk per m of summed error).
        Gx: (3,) state gain.
        Gp: (N_L,) preview gains on p_ref(k + 1 .. k + N_L).
        sample_period: T, s; com_height: z_c, m; gravity: g, m/s^2.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    Gi: float
    Gx: np.ndarray
    Gp: np.ndarray
    sample_period: float
    com_height: float
    gravity: float


def preview_gains(
    sample_period: float,
    com_height: float,
    preview_time: float,
    *,
    zmp_weight: float = 1.0,
    jerk_weight: float = 1e-6,
    gravity: float = 9.81,
) -> PreviewGains:
    """The gains of eqs. K-3..K-4 from the discrete algebraic Riccati equation.

    Raises:
        ValueError: non-positive period, height, horizon or weights.
    """
    for name, value in (
        ("sample_period", sample_period),
        ("com_height", com_height),
        ("preview_time", preview_time),
        ("zmp_weight", zmp_weight),
        ("jerk_weight", jerk_weight),
        ("gravity", gravity),
    ):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"preview_gains: {name} must be positive, got {value}")
    T = float(sample_period)
    A = np.array([[1.0, T, T * T / 2.0], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
    B = np.array([T**3 / 6.0, T * T / 2.0, T])
    C = np.array([1.0, 0.0, -com_height / gravity])
    At = np.zeros((4, 4))
    At[0, 0] = 1.0
    At[0, 1:] = C @ A
    At[1:, 1:] = A
    Bt = np.concatenate([[C @ B], B]).reshape(4, 1)
    Qt = np.diag([zmp_weight, 0.0, 0.0, 0.0])
    R = np.array([[jerk_weight]])
    P = scipy.linalg.solve_discrete_are(At, Bt, Qt, R)
    S = float(R[0, 0] + (Bt.T @ P @ Bt)[0, 0])
    K = (Bt.T @ P @ At).reshape(4) / S
    Gi, Gx = float(K[0]), K[1:].copy()
    Ac = At - Bt @ K.reshape(1, 4)
    n_preview = max(1, int(round(preview_time / T)))
    Gp = np.empty(n_preview)
    Gp[0] = -Gi
    X = -Ac.T @ P @ np.array([1.0, 0.0, 0.0, 0.0])
    for j in range(1, n_preview):
        Gp[j] = float(Bt[:, 0] @ X) / S
        X = Ac.T @ X
    return PreviewGains(
        A=A, B=B, C=C, Gi=Gi, Gx=Gx, Gp=Gp, sample_period=T, com_height=float(com_height), gravity=float(gravity)
    )


def preview_control(gains: PreviewGains, zmp_ref: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Runs the preview controller (eq. K-5) on the cart-table model (eq. K-1).

    Args:
        gains: from ``preview_gains``.
        zmp_ref: (K, d) ZMP reference at t_k = k T for d independent axes, m; beyond the
            end it is held at its last value.
        x0: (d,) initial CoM position (at rest), m, or (3, d) initial state.

    Returns:
        (states (K, 3, d): [c, c_dot, c_ddot] per axis at t_k; zmp (K, d): the cart-table
        ZMP p_k = C x_k, m).
    """
    ref = np.asarray(zmp_ref, float)
    if ref.ndim == 1:
        ref = ref[:, None]
    K, d = ref.shape
    N = gains.Gp.size
    padded = np.vstack([ref, np.repeat(ref[-1:], N + 1, axis=0)])
    x = np.zeros((3, d))
    x0 = np.asarray(x0, float)
    if x0.ndim == 1:
        x[0] = x0
    else:
        x[:] = x0
    states = np.empty((K, 3, d))
    zmp = np.empty((K, d))
    error_sum = np.zeros(d)
    A, B, C, Gx, Gp, Gi = gains.A, gains.B, gains.C, gains.Gx, gains.Gp, gains.Gi
    for k in range(K):
        p = C @ x
        states[k], zmp[k] = x, p
        error_sum += p - ref[k]
        u = -Gi * error_sum - Gx @ x - Gp @ padded[k + 1 : k + 1 + N]
        x = A @ x + np.outer(B, u)
    return states, zmp


# ---------------------------------------------------------------------------------------
# The pattern (LIP level).
# ---------------------------------------------------------------------------------------


@dataclass
class WalkingPattern:
    """The pattern on its time grid (module docstring); world frame, SI.

    Attributes:
        params: the parameters.
        t: (K,) grid times k T, s.
        steps: the footstep plan.
        zmp_reference: (K, 2) ZMP reference, m.
        zmp: (K, 2) the cart-table ZMP of the preview CoM (eq. K-2), m.
        com: (K, 3) CoM reference (x, y from preview control; z lowering to z_c), m.
        com_velocity, com_acceleration: (K, 2) horizontal, m/s and m/s^2.
        soles: side -> (K, 3) sole frame origins, m.
        contact: side -> (K,) planned contact flags.
        gains: the preview gains.
    """

    params: WalkingParameters
    t: np.ndarray
    steps: list
    zmp_reference: np.ndarray
    zmp: np.ndarray
    com: np.ndarray
    com_velocity: np.ndarray
    com_acceleration: np.ndarray
    soles: dict
    contact: dict
    gains: PreviewGains


def make_walking_pattern(
    params: WalkingParameters, left0: np.ndarray, right0: np.ndarray, com0: np.ndarray
) -> WalkingPattern:
    """Footsteps, ZMP reference, preview CoM and swing trajectories (no robot model).

    Args:
        params: the parameters.
        left0, right0: (3,) initial sole frame origins, world, m (on flat ground).
        com0: (3,) initial CoM, world, m; its height lowers smoothly to ``com_height``
            over the first half of ``initial_wait``.
    """
    left0, right0, com0 = (np.asarray(v, float).reshape(3) for v in (left0, right0, com0))
    steps = plan_footsteps(params, left0, right0)
    T = params.sample_period
    K = int(round(params.duration / T)) + 1
    t = np.arange(K) * T
    knots_t, knots_p = zmp_reference_knots(params, steps, com0[:2], left0, right0)
    zmp_ref = interpolate_knots(t, knots_t, knots_p)
    gains = preview_gains(
        T,
        params.com_height,
        params.preview_time,
        zmp_weight=params.zmp_weight,
        jerk_weight=params.jerk_weight,
        gravity=params.gravity,
    )
    states, zmp = preview_control(gains, zmp_ref, com0[:2])
    ground = 0.5 * (left0[2] + right0[2])
    lower_time = 0.5 * params.initial_wait
    blend = smoothstep5(t / lower_time) if lower_time > 0 else np.ones_like(t)
    z = com0[2] + (ground + params.com_height - com0[2]) * blend
    soles, contact = foot_trajectories(t, steps, left0, right0)
    return WalkingPattern(
        params=params,
        t=t,
        steps=steps,
        zmp_reference=zmp_ref,
        zmp=zmp,
        com=np.column_stack([states[:, 0, :], z]),
        com_velocity=states[:, 1, :],
        com_acceleration=states[:, 2, :],
        soles=soles,
        contact=contact,
        gains=gains,
    )


# ---------------------------------------------------------------------------------------
# Whole body (eq. W-1) and the controller system.
# ---------------------------------------------------------------------------------------


@dataclass
class WholeBodyTrajectory:
    """Joint targets on the pattern's grid.

    Attributes:
        t: (K,) s.
        q_joints: (K, n) joint targets in the plant's v[6:] order, rad.
        torso_position: (K, 3) base (torso) origin, world, m (torso level, heading 0).
        com_error: (K,) |CoM(q) - c_ref| of the multibody model after the iterations, m.
        joint_names: the n joint names, v[6:] order.
        compensation: (K, n) the PD compensation included in q_joints (eqs. W-2, W-3),
            rad (zeros without ``joint_stiffness``).
    """

    t: np.ndarray
    q_joints: np.ndarray
    torso_position: np.ndarray
    com_error: np.ndarray
    joint_names: tuple
    compensation: np.ndarray


def whole_body_trajectory(
    plant: MultibodyPlant,
    humanoid: HumanoidHandles,
    pattern: WalkingPattern,
    initial_positions: np.ndarray,
    *,
    iterations: int = 3,
    joint_stiffness: np.ndarray | None = None,
    joint_damping: np.ndarray | None = None,
) -> WholeBodyTrajectory:
    """Joint targets that put the soles on ``pattern.soles`` and the multibody CoM on
    ``pattern.com`` (eq. W-1), legs by ``systems.locomotion.leg_ik``, other joints at their values in
    ``initial_positions``.

    Args:
        plant: a finalized plant with ``nao_like`` (its own context is created here).
        humanoid: the robot's handles.
        pattern: from ``make_walking_pattern``.
        initial_positions: (nq,) the plant positions at t = 0 (torso level, heading 0).
        iterations: fixed-point iterations of eq. W-1 (>= 1).
        joint_stiffness: (n,) the joint PD's K_p (N m/rad, v[6:] order), or None. When
            given, the targets include the static deflection of the position-controlled
            joints under the planned ground reaction (eq. W-2 of ``stiffness_compensation``).
        joint_damping: (n,) the PD's K_d (N m s/rad), used with ``joint_stiffness``: the
            PD damps towards zero velocity (u = K_p (q_d - q) - K_d q_dot), so tracking
            q_ref(t) at velocity q_dot_ref needs the lead

                q_d = q_ref + K_p^-1 K_d q_dot_ref                                   (W-3)

            (q_dot_ref by central differences on the grid).

    Raises:
        ValueError: a sole target out of reach, a joint target outside its limits, a torso
            that is not level with heading 0.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    topology = floating_base_topology(plant)
    joints = list(topology.joints)
    names = tuple(j.name() for j in joints)
    index = {n: k for k, n in enumerate(names)}
    q0 = np.asarray(initial_positions, float).reshape(-1)
    if q0.size != plant.num_positions():
        raise ValueError(f"initial_positions must have {plant.num_positions()} entries")
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q0)
    base = humanoid.base_body
    X_WB0 = plant.EvalBodyPoseInWorld(context, base)
    if not np.allclose(X_WB0.rotation().matrix(), np.eye(3), atol=1e-6):
        raise ValueError("whole_body_trajectory: the initial torso must be level with heading 0 (R_WB = I)")
    q_start = np.array([j.position_start() for j in joints])
    q_joints0 = q0[q_start]
    geometry = NaoLegGeometry.from_plant(plant, humanoid.model_instance)
    prefix = {"left": "L", "right": "R"}
    leg_cols = {side: np.array([index[prefix[side] + n] for n in LEG_JOINTS]) for side in SIDES}

    com0 = plant.CalcCenterOfMassPositionInWorld(context, [humanoid.model_instance])
    torso = pattern.com + (X_WB0.translation() - com0)  # initial guess
    K = pattern.t.size
    q = np.tile(q_joints0, (K, 1))
    free_start = topology.free_joint.position_start()
    positions = np.tile(q0, (K, 1))
    positions[:, free_start : free_start + 4] = [1.0, 0.0, 0.0, 0.0]

    def solve_legs(torso_pos):
        for side in SIDES:
            try:
                q[:, leg_cols[side]] = leg_ik(geometry, pattern.soles[side] - torso_pos, side)
            except ValueError as error:
                raise ValueError(
                    f"walking pattern: {error} (step_length {pattern.params.step_length} m, "
                    f"com_height {pattern.params.com_height} m: shorten the step or lower the CoM)"
                ) from None
        positions[:, q_start] = q
        positions[:, free_start + 4 : free_start + 7] = torso_pos

    def com_of_all():
        out = np.empty((K, 3))
        for k in range(K):
            plant.SetPositions(context, positions[k])
            out[k] = plant.CalcCenterOfMassPositionInWorld(context, [humanoid.model_instance])
        return out

    for _ in range(iterations):
        solve_legs(torso)
        torso = torso + (pattern.com - com_of_all())  # eq. W-1
    solve_legs(torso)
    com_error = np.linalg.norm(com_of_all() - pattern.com, axis=1)

    compensation = np.zeros_like(q)
    if joint_stiffness is not None:
        kp = np.asarray(joint_stiffness, float).reshape(-1)
        if kp.shape != (len(joints),) or np.any(kp <= 0) or not np.isfinite(kp).all():
            raise ValueError(f"joint_stiffness must be {len(joints)} positive numbers (v[6:] order)")
        mass = plant.CalcTotalMass(context, [humanoid.model_instance])
        compensation = stiffness_compensation(plant, humanoid, pattern, positions, kp, mass)
        if joint_damping is not None:
            kd = np.asarray(joint_damping, float).reshape(-1)
            if kd.shape != kp.shape or np.any(kd < 0) or not np.isfinite(kd).all():
                raise ValueError(f"joint_damping must be {len(joints)} non-negative numbers (v[6:] order)")
            compensation = compensation + (kd / kp) * np.gradient(q, pattern.t, axis=0)  # eq. W-3
        q = q + compensation

    lower = np.array([j.position_lower_limits()[0] for j in joints])
    upper = np.array([j.position_upper_limits()[0] for j in joints])
    bad = (q < lower - 1e-9) | (q > upper + 1e-9)
    if bad.any():
        k, j = np.argwhere(bad)[0]
        raise ValueError(
            f"walking pattern: joint {names[j]} target {q[k, j]:.3f} rad at t = {pattern.t[k]:.3f} s "
            f"is outside its limits [{lower[j]:.3f}, {upper[j]:.3f}]"
        )
    return WholeBodyTrajectory(
        t=pattern.t.copy(),
        q_joints=q.copy(),
        torso_position=torso.copy(),
        com_error=com_error,
        joint_names=names,
        compensation=compensation,
    )


def planned_ground_forces(pattern: WalkingPattern, mass: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Quasi-static ground reaction per foot on the pattern grid (LIP, eq. K-2).

    The total reaction is f = m [c_ddot_x, c_ddot_y, g] (N) at the ZMP reference. In single
    support it acts on the support foot; in double support it is split between the feet's
    reference points a_L, a_R (sole + ``zmp_offset_x``) by the ZMP's position along the
    segment: f_R = alpha f, f_L = (1 - alpha) f, alpha = clip((p - a_L).(a_R - a_L) / |a_R - a_L|^2).

    Returns:
        side -> (force (K, 3) N, application point (K, 3) m), world.
    """
    params = pattern.params
    K = pattern.t.size
    total = mass * np.column_stack([pattern.com_acceleration, np.full(K, params.gravity)])
    off = np.array([params.zmp_offset_x, 0.0, 0.0])
    a = {side: pattern.soles[side] + off for side in SIDES}
    d = a["right"][:, :2] - a["left"][:, :2]
    alpha = np.einsum("ij,ij->i", pattern.zmp_reference - a["left"][:, :2], d) / np.einsum("ij,ij->i", d, d)
    alpha = np.clip(alpha, 0.0, 1.0)
    left_only = pattern.contact["left"] & ~pattern.contact["right"]
    right_only = pattern.contact["right"] & ~pattern.contact["left"]
    alpha[left_only], alpha[right_only] = 0.0, 1.0
    out = {}
    for side, share in (("left", 1.0 - alpha), ("right", alpha)):
        point = a[side].copy()
        single = left_only if side == "left" else right_only
        point[single, :2] = pattern.zmp_reference[single]
        out[side] = (share[:, None] * total, point)
    return out


def stiffness_compensation(
    plant: MultibodyPlant,
    humanoid: HumanoidHandles,
    pattern: WalkingPattern,
    positions: np.ndarray,
    joint_stiffness: np.ndarray,
    mass: float,
) -> np.ndarray:
    """Joint target offsets that cancel the static deflection of the PD-controlled joints
    under the planned ground reaction (eq. W-2).

    At static equilibrium the joint rows of the dynamics give u = -tau_g - (J^T f) for the
    foot forces f (J: translational Jacobian of the contact point w.r.t. v); the PD with
    gravity compensation supplies u = -tau_g + K_p (q_d - q), hence q = q_d + K_p^-1 (J^T f)_j:
    the joint sags by K_p^-1 (J^T f)_j. Commanding

        q_d = q_ref - K_p^-1 (J^T f)_j                                            (W-2)

    puts it at q_ref. Forces from ``planned_ground_forces`` (quasi-static LIP).

    Args:
        positions: (K, nq) plant positions of the planned motion.
        joint_stiffness: (n,) K_p, N m/rad, v[6:] order.
        mass: the robot's mass, kg.

    Returns:
        (K, n) offsets, rad, v[6:] order.
    """
    forces = planned_ground_forces(pattern, mass)
    context = plant.CreateDefaultContext()
    world = plant.world_frame()
    K = positions.shape[0]
    out = np.zeros((K, plant.num_velocities() - 6))
    for k in range(K):
        plant.SetPositions(context, positions[k])
        tau = np.zeros(plant.num_velocities())
        for side in SIDES:
            f, point = forces[side][0][k], forces[side][1][k]
            if not f.any():
                continue
            frame = humanoid.sole_frames[side]
            p_SP = frame.CalcPoseInWorld(context).inverse().multiply(point)
            J = plant.CalcJacobianTranslationalVelocity(context, JacobianWrtVariable.kV, frame, p_SP, world, world)
            tau += J.T @ f
        out[k] = -tau[6:] / joint_stiffness
    return out


def standing_positions(plant: MultibodyPlant, humanoid: HumanoidHandles) -> np.ndarray:
    """The plant positions of ``models.set_standing_state`` (nominal posture, soles on z = 0)."""
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, humanoid)
    return plant.GetPositions(context)


def multibody_zmp(
    plant: MultibodyPlant, humanoid: HumanoidHandles, trajectory: WholeBodyTrajectory, initial_positions: np.ndarray
) -> np.ndarray:
    """ZMP (world x, y on the ground z = 0, m) of the planned whole-body motion (eq. Z-1).

    With the total ground reaction f = m (c_ddot + g e_z) and the rate of the centroidal
    angular momentum L_dot (the moment of f about the CoM c), the point p on the ground
    with zero horizontal moment is

        p_x = c_x - (c_z f_x + L_dot_y) / f_z,   p_y = c_y - (c_z f_y - L_dot_x) / f_z.   (Z-1)

    For the cart-table model (L_dot = 0, c_z = z_c, c_ddot_z = 0) this is eq. K-2. The
    positions are the trajectory's (torso level), the velocities its central differences;
    c from ``CalcCenterOfMassPositionInWorld``, L from ``CalcSpatialMomentumInWorldAboutPoint``
    about c; c_ddot and L_dot by central differences on the grid.
    """
    topology = floating_base_topology(plant)
    joints = list(topology.joints)
    q_index = np.array([j.position_start() for j in joints])
    v_index = np.array([j.velocity_start() for j in joints])
    free_q = topology.free_joint.position_start()
    free_v = topology.free_joint.velocity_start()
    t = trajectory.t
    K = t.size
    positions = np.tile(np.asarray(initial_positions, float), (K, 1))
    positions[:, free_q : free_q + 4] = [1.0, 0.0, 0.0, 0.0]
    positions[:, free_q + 4 : free_q + 7] = trajectory.torso_position
    positions[:, q_index] = trajectory.q_joints
    velocities = np.zeros((K, plant.num_velocities()))
    velocities[:, free_v + 3 : free_v + 6] = np.gradient(trajectory.torso_position, t, axis=0)
    velocities[:, v_index] = np.gradient(trajectory.q_joints, t, axis=0)
    context = plant.CreateDefaultContext()
    instances = [humanoid.model_instance]
    mass = plant.CalcTotalMass(context, instances)
    com, momentum = np.empty((K, 3)), np.empty((K, 3))
    for k in range(K):
        plant.SetPositions(context, positions[k])
        plant.SetVelocities(context, velocities[k])
        com[k] = plant.CalcCenterOfMassPositionInWorld(context, instances)
        momentum[k] = plant.CalcSpatialMomentumInWorldAboutPoint(context, instances, com[k]).rotational()
    gravity = float(-plant.gravity_field().gravity_vector()[2])
    f = mass * (np.gradient(np.gradient(com, t, axis=0), t, axis=0) + np.array([0.0, 0.0, gravity]))
    L_dot = np.gradient(momentum, t, axis=0)
    return np.column_stack(
        [
            com[:, 0] - (com[:, 2] * f[:, 0] + L_dot[:, 1]) / f[:, 2],
            com[:, 1] - (com[:, 2] * f[:, 1] - L_dot[:, 0]) / f[:, 2],
        ]
    )


def correct_for_multibody_zmp(pattern: WalkingPattern, zmp_multibody: np.ndarray) -> WalkingPattern:
    """Kajita et al. 2003's second preview pass: the preview controller (eq. K-5), run on the
    ZMP error e = p_ref - p_multibody from rest, gives a CoM correction dc whose cart-table
    ZMP is ~e; the returned pattern has CoM c + dc (x, y; velocity and acceleration too)."""
    error = pattern.zmp_reference - zmp_multibody
    states, zmp = preview_control(pattern.gains, error, np.zeros(2))
    return WalkingPattern(
        params=pattern.params,
        t=pattern.t,
        steps=pattern.steps,
        zmp_reference=pattern.zmp_reference,
        zmp=pattern.zmp + zmp,
        com=pattern.com + np.column_stack([states[:, 0, :], np.zeros(pattern.t.size)]),
        com_velocity=pattern.com_velocity + states[:, 1, :],
        com_acceleration=pattern.com_acceleration + states[:, 2, :],
        soles=pattern.soles,
        contact=pattern.contact,
        gains=pattern.gains,
    )


class NaoWalkingController(LeafSystem):
    """Open-loop walking pattern for ``nao_like`` (module docstring): the joint targets are
    computed at construction and interpolated linearly in time.

    Inputs: none (a time-driven source).

    Outputs:
        desired_position: (n) joint targets in the plant's v[6:] order, rad (connect to the
            station's PD ``desired_position``).
        zmp_reference: (2) ZMP reference (x, y), world, m.
        com_reference: (3) CoM reference, world, m.
        sole_targets: (6) left then right sole frame origin targets, world, m.
        planned_contact: (2) 1.0 where the plan has the left / right foot on the ground.

    Before t = ``start_delay`` (the pattern's t = 0) and after the pattern's end the first /
    last sample is held.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        humanoid: HumanoidHandles,
        parameters: WalkingParameters | None = None,
        *,
        initial_positions: np.ndarray | None = None,
        iterations: int = 3,
        joint_stiffness: np.ndarray | None = None,
        joint_damping: np.ndarray | None = None,
        zmp_correction_passes: int = 1,
        start_delay: float = 0.0,
    ):
        """Builds the pattern and the joint targets.

        Args:
            plant: a finalized plant with ``nao_like`` (used at construction only).
            humanoid: its handles.
            parameters: the walking parameters (default ``WalkingParameters()``).
            initial_positions: (nq,) plant positions at t = 0 (default: the standing state
                of ``models.set_standing_state``); the soles must be level on the ground.
            iterations: fixed-point iterations of eq. W-1.
            joint_stiffness: (n,) the PD's K_p (N m/rad, v[6:] order) for the stiffness
                compensation of eq. W-2, or None (no compensation).
            joint_damping: (n,) the PD's K_d (N m s/rad) for the velocity lead of eq. W-3
                (only with ``joint_stiffness``), or None.
            zmp_correction_passes: passes of ``correct_for_multibody_zmp`` (Kajita 2003's
                multibody ZMP correction; 0 = the cart-table CoM only).
            start_delay: s (>= 0) the robot stands in the pattern's first posture before the
                pattern starts (a standing start, as a real log's).

        Raises:
            ValueError: bad parameters, unreachable steps, joint limits (see
                ``whole_body_trajectory``).
        """
        super().__init__()
        if humanoid.name != "nao_like":
            raise ValueError(f"NaoWalkingController supports nao_like only, got {humanoid.name!r}")
        self.parameters = parameters if parameters is not None else WalkingParameters()
        q0 = standing_positions(plant, humanoid) if initial_positions is None else np.asarray(initial_positions, float)
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, q0)
        soles0 = {s: humanoid.sole_frames[s].CalcPoseInWorld(context).translation() for s in SIDES}
        com0 = plant.CalcCenterOfMassPositionInWorld(context, [humanoid.model_instance])
        if not (isinstance(zmp_correction_passes, (int, np.integer)) and zmp_correction_passes >= 0):
            raise ValueError(f"zmp_correction_passes must be an integer >= 0, got {zmp_correction_passes!r}")
        if not (isinstance(start_delay, (int, float)) and math.isfinite(start_delay) and start_delay >= 0.0):
            raise ValueError(f"start_delay must be a finite number of seconds >= 0, got {start_delay!r}")
        #: s the first posture is held before the pattern starts.
        self.start_delay = float(start_delay)
        pattern = make_walking_pattern(self.parameters, soles0["left"], soles0["right"], com0)
        #: The cart-table pattern before the multibody ZMP correction.
        self.cart_table_pattern = pattern
        for _ in range(zmp_correction_passes):
            trajectory = whole_body_trajectory(plant, humanoid, pattern, q0, iterations=iterations)
            pattern = correct_for_multibody_zmp(pattern, multibody_zmp(plant, humanoid, trajectory, q0))
        self.pattern = pattern
        self.trajectory = whole_body_trajectory(
            plant,
            humanoid,
            self.pattern,
            q0,
            iterations=iterations,
            joint_stiffness=joint_stiffness,
            joint_damping=joint_damping,
        )
        plain = (
            self.trajectory
            if joint_stiffness is None
            else whole_body_trajectory(plant, humanoid, self.pattern, q0, iterations=iterations)
        )
        #: (K, 2) ZMP of the planned whole-body motion (eq. Z-1), m.
        self.planned_multibody_zmp = multibody_zmp(plant, humanoid, plain, q0)
        p = self.pattern
        self._t = p.t
        self._q = self.trajectory.q_joints
        self._zmp = p.zmp_reference
        self._com = p.com
        self._soles = np.hstack([p.soles["left"], p.soles["right"]])
        self._contact = np.column_stack([p.contact["left"], p.contact["right"]]).astype(float)
        n = self._q.shape[1]
        self.DeclareVectorOutputPort("desired_position", n, self._CalcDesiredPosition)
        self.DeclareVectorOutputPort("zmp_reference", 2, self._CalcZmp)
        self.DeclareVectorOutputPort("com_reference", 3, self._CalcCom)
        self.DeclareVectorOutputPort("sole_targets", 6, self._CalcSoles)
        self.DeclareVectorOutputPort("planned_contact", 2, self._CalcContact)

    @property
    def duration(self) -> float:
        """Length of the pattern plus ``start_delay``, s."""
        return self.start_delay + float(self._t[-1])

    def sample(self, table: np.ndarray, t: float) -> np.ndarray:
        """Linear interpolation of a (K, m) table on the pattern grid at time t of the
        simulation (the pattern's t - ``start_delay``; held at the ends)."""
        T = self.parameters.sample_period
        s = min(max((t - self.start_delay) / T, 0.0), self._t.size - 1.0)
        k = min(int(s), self._t.size - 2)
        a = s - k
        return (1.0 - a) * table[k] + a * table[k + 1]

    def _CalcDesiredPosition(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.sample(self._q, context.get_time()))

    def _CalcZmp(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.sample(self._zmp, context.get_time()))

    def _CalcCom(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.sample(self._com, context.get_time()))

    def _CalcSoles(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.sample(self._soles, context.get_time()))

    def _CalcContact(self, context: Context, output: BasicVector) -> None:
        t = context.get_time() - self.start_delay
        k = min(max(int(round(t / self.parameters.sample_period)), 0), self._t.size - 1)
        output.SetFromVector(self._contact[k])


__all__ = [
    "MAX_STEP_LENGTH",
    "correct_for_multibody_zmp",
    "multibody_zmp",
    "Footstep",
    "NaoWalkingController",
    "PreviewGains",
    "WalkingParameters",
    "WalkingPattern",
    "WholeBodyTrajectory",
    "foot_trajectories",
    "interpolate_knots",
    "make_walking_pattern",
    "plan_footsteps",
    "planned_ground_forces",
    "stiffness_compensation",
    "preview_control",
    "preview_gains",
    "standing_positions",
    "whole_body_trajectory",
    "zmp_reference_knots",
]
