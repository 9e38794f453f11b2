"""The benchmark's peer: the three momentum residuals as a plain loop on Pinocchio.

What a user who does not take this project would write (issue 33): Flacco, Paolillo, Kheddar
(2016)'s classical (eq. 7), internal (eq. 11, with the known-force torques of eq. 10) and
external (eq. 16) residuals, one function per update on Pinocchio's C++ kernels (``crba``,
``computeCoriolisMatrix``, ``computeGeneralizedGravity``, ``computeFrameJacobian``) and numpy
for the rest: M_dot = C + C^T, and the base elimination of eq. (9) (the Schur complement
H_fb = H - F^T I0c^-1 F) written out. ``apps.benchmark`` times it beside the project's
``ClassicalResidual``/``InternalResidual``/``ExternalResidual`` bank, and the tests use it as
an independent check of those systems: it shares only the model builder
(``systems.dynamics.pinocchio_model``, for ``peer_model_from_plant``) with the project, none of
the residual or floating-base algebra.

It computes what ``systems.residuals.momentum_residuals`` computes, with the same
discretisation (its module docstring): at each update, the momentum p, the model's momentum
rate a (M_dot nu - C nu - g = C^T nu - g) and the measured generalized forces u (motor
torques minus viscous friction D qdot, plus the F/T wrenches through J^T), then

    I_k = I_{k-1}^+ + T/2 a_k + T u_k,    r_k = K (p_k - I_k),    I_k^+ = I_k + T/2 a_k + T r_k,

with I_0 = p_0 (r_0 = 0). Differences of numerics only: Pinocchio's M_dot is exact where the
project's ``fast`` decomposition takes a central difference of the mass matrix.

Coordinates are Pinocchio's: q = [x, y, z, qx, qy, qz, qw, joints], v = [v_B; w_B; joints]
(free-flyer velocity LINEAR first, in the base frame, = the project's v0 reordered), spatial
forces [force; moment]. ``PlantCoordinates`` converts a Drake plant's state, torques and the
residuals between the two, by joint name (outside the timed loop in the benchmark: a
Pinocchio user's sensors give Pinocchio's coordinates).

The robot: ``peer_model_from_urdf`` (``pin.buildModelFromUrdf`` with a free-flyer root, the
user's way) or, for a model that exists only as SDFormat (``hrp4_like``; this Pinocchio is
built without SDFormat), ``peer_model_from_plant`` (the plant's joints, frames and inertias,
rebuilt with Pinocchio's own joints, ``systems.dynamics.pinocchio_model``, the builder of the
project's ``"pinocchio"`` dynamics). ``plant_joint_parameters`` gives the project's
reflected rotor inertia (Pinocchio's ``model.armature``) and joint damping, which the
project's loader may add to what the URDF says (TALOS: its SRDF gives the grippers no rotor;
the project's description gives every joint 0.1 kg m^2).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin
from pydrake.multibody.plant import MultibodyPlant

from systems.dynamics.pinocchio_model import pinocchio_model_from_plant, plant_joint_parameters, set_joint_parameters

__all__ = [
    "PinocchioResidualPeer",
    "PlantCoordinates",
    "peer_model_from_plant",
    "peer_model_from_urdf",
    "plant_joint_parameters",
]


class PinocchioResidualPeer:
    """Classical, internal and external residuals of one robot, one ``step`` per update.

    Args:
        model: Pinocchio model with a free-flyer root joint (its ``armature`` set).
        known_wrench_frames: names of the F/T frames (Pinocchio frames), in the order of the
            ``wrenches`` given to ``step``.
        damping: viscous joint friction D (n = nv - 6 values, Pinocchio's joint order), N m s/rad.
        gains: K of the classical, internal and external residuals, 1/s.
        period: T, s.
    """

    def __init__(
        self,
        model: pin.Model,
        known_wrench_frames: Sequence[str],
        damping: np.ndarray,
        gains: tuple[float, float, float] = (35.0, 35.0, 35.0),
        period: float = 1e-3,
    ):
        if model.joints[1].shortname() != "JointModelFreeFlyer":
            raise ValueError("the peer needs a model whose first joint is a free flyer")
        self.model, self.data = model, model.createData()
        self.frame_ids = [model.getFrameId(name) for name in known_wrench_frames]
        if any(i >= len(model.frames) for i in self.frame_ids):
            raise ValueError(f"unknown frame among {list(known_wrench_frames)}")
        self.damping = np.asarray(damping, dtype=float)
        self.gains, self.period = gains, period
        self.integrals: list | None = None
        root = model.jointPlacements[1]  # the free flyer's parent placement in the world
        self._R_WP, self._p_WP = np.array(root.rotation), np.array(root.translation)

    def reset(self) -> None:
        """The next ``step`` is a first update (I_0 = p_0, r_0 = 0)."""
        self.integrals = None

    def step(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, wrenches: np.ndarray) -> tuple[np.ndarray, ...]:
        """One update at the sensed (q, v) with motor torques ``tau`` (n, without friction
        compensation) and the F/T wrenches (6 per frame: [moment about the frame origin;
        force] in world). Returns (classical (nv), internal (n), external in the base frame
        (6, [force; moment about the base origin]), external in world (6, [force; moment about
        the world origin])), Pinocchio's order."""
        model, data, T = self.model, self.data, self.period
        # Generalized force of the F/T wrenches: J^T w with the frame Jacobian at the frame's
        # origin in world-aligned axes (its base columns are in the base frame, as v).
        known = np.zeros(model.nv)
        for i, frame in enumerate(self.frame_ids):
            J = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL_WORLD_ALIGNED)
            known += J[:3].T @ wrenches[6 * i + 3 : 6 * i + 6] + J[3:].T @ wrenches[6 * i : 6 * i + 3]
        M = pin.crba(model, data, q)  # the Python binding fills both triangles
        C = pin.computeCoriolisMatrix(model, data, q, v).copy()
        g = pin.computeGeneralizedGravity(model, data, q)
        M_dot = C + C.T
        qd = v[6:]
        tau_m = tau - self.damping * qd

        # Classical residual, eq. (7): p = M nu, a = M_dot nu - (C nu + g) = C^T nu - g.
        bias = C @ v + g
        p = M @ v
        a = M_dot @ v - bias
        u = known.copy()
        u[6:] += tau_m
        # External residual, eq. (16): the base rows of the same momentum.
        p_ext, a_ext, u_ext = p[:6], a[:6], known[:6]
        # Internal residual, eq. (9)-(11): eliminate the base acceleration.
        I0c, F, H = M[:6, :6], M[:6, 6:], M[6:, 6:]
        I0c_dot, F_dot, H_dot = M_dot[:6, :6], M_dot[:6, 6:], M_dot[6:, 6:]
        G = np.linalg.solve(I0c, F)  # I0c^-1 F
        Gqd = G @ qd
        p_int = H @ qd - F.T @ Gqd  # H_fb qd, H_fb = H - F^T I0c^-1 F
        H_fb_dot_qd = H_dot @ qd - G.T @ (F_dot @ qd) - F_dot.T @ Gqd + G.T @ (I0c_dot @ Gqd)  # eq. (13)
        C_fb = bias[6:] - G.T @ bias[:6]
        a_int = H_fb_dot_qd - C_fb
        u_int = tau_m + known[6:] - G.T @ known[:6]  # tau_bar_c = J^fb^T w, eq. (10)

        rows = ((p, a, u), (p_int, a_int, u_int), (p_ext, a_ext, u_ext))
        first = self.integrals is None
        integrals, residuals = [], []
        for k, (momentum, rate, measured) in enumerate(rows):
            if first:
                integral, residual = momentum, np.zeros(momentum.shape[0])
            else:
                integral = self.integrals[k] + 0.5 * T * rate + T * measured
                residual = self.gains[k] * (momentum - integral)
            integrals.append(integral + 0.5 * T * rate + T * residual)
            residuals.append(residual)
        self.integrals = integrals
        # The external wrench in world: rotate with the base pose, move the moment to the origin.
        R = self._R_WP @ pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
        (fx, fy, fz), moment = R @ residuals[2][:3], R @ residuals[2][3:]
        px, py, pz = self._p_WP + self._R_WP @ q[:3]  # the base origin; np.cross costs more
        world = np.array((fx, fy, fz, *(moment + (py * fz - pz * fy, pz * fx - px * fz, px * fy - py * fx))))
        return residuals[0], residuals[1], residuals[2], world


def peer_model_from_urdf(
    path, armature: Mapping[str, float] | None = None, damping: Mapping[str, float] | None = None
) -> tuple[pin.Model, np.ndarray]:
    """(model, damping): the URDF with a free-flyer root; ``armature`` and ``damping``
    ({joint name: value}) replace the URDF's (default: the URDF's damping, no armature).
    The damping is returned in Pinocchio's joint order (n values)."""
    model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    return _with_joint_parameters(model, armature, damping)


def peer_model_from_plant(
    plant: MultibodyPlant, armature: Mapping[str, float] | None = None, damping: Mapping[str, float] | None = None
) -> tuple[pin.Model, np.ndarray]:
    """(model, damping) of a finalized Drake floating-base plant rebuilt with Pinocchio's
    joints (``systems.dynamics.pinocchio_model.pinocchio_model_from_plant``: the plant's
    default inertias, joint placements and axes, every frame of the plant as a Pinocchio
    frame of the same name), without armature unless ``armature`` gives it."""
    model = pinocchio_model_from_plant(plant, reflected_inertia=False).model
    return _with_joint_parameters(model, armature, damping)


def _with_joint_parameters(model: pin.Model, armature, damping) -> tuple[pin.Model, np.ndarray]:
    return model, set_joint_parameters(model, armature, damping)


class PlantCoordinates:
    """Maps a Drake floating-base plant's coordinates to the Pinocchio model's and back,
    by joint name. Drake: q = [qw, qx, qy, qz, x, y, z, joints], v = [w_WB; v_WB (world);
    joints]; the project's residuals: base entries [moment; force] in the base frame."""

    def __init__(self, plant: MultibodyPlant, model: pin.Model):
        joints = [plant.get_joint(i) for i in plant.GetJointIndices() if plant.get_joint(i).num_velocities() == 1]
        missing = [j.name() for j in joints if not model.existJointName(j.name())]
        if missing or model.nv != plant.num_velocities():
            raise ValueError(f"the Pinocchio model does not have the plant's joints (missing: {missing})")
        n = len(joints)
        # pin joint entry k (of v[6:]) <- Drake joint entry drake_index[k].
        pin_of = {j.name(): model.joints[model.getJointId(j.name())] for j in joints}
        self.q_pin = np.array([pin_of[j.name()].idx_q for j in joints])
        self.q_drake = np.array([j.position_start() for j in joints])
        self.joint_pin = np.array([pin_of[j.name()].idx_v - 6 for j in joints])  # Drake order -> pin index
        self.joint_drake = np.array([j.velocity_start() - 6 for j in joints])
        self.num_positions, self.num_joints = plant.num_positions(), n
        self.nq_pin = model.nq

    def state(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Drake's [q; v] -> Pinocchio's (q, v)."""
        nq = self.num_positions
        qd, vd = x[:nq], x[nq:]
        wxyz = qd[:4] / np.linalg.norm(qd[:4])
        R = pin.Quaternion(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).toRotationMatrix()
        q = np.zeros(self.nq_pin)
        q[:3], q[3:6], q[6] = qd[4:7], wxyz[1:], wxyz[0]
        q[self.q_pin] = qd[self.q_drake]
        v = np.zeros(vd.shape[0])
        v[:3], v[3:6] = R.T @ vd[3:6], R.T @ vd[:3]
        v[6 + self.joint_pin] = vd[6 + self.joint_drake]
        return q, v

    def joints_to_pin(self, values: np.ndarray) -> np.ndarray:
        """n joint values, Drake's v[6:] order -> Pinocchio's."""
        out = np.empty(self.num_joints)
        out[self.joint_pin] = values[self.joint_drake]
        return out

    def joints_to_drake(self, values: np.ndarray) -> np.ndarray:
        out = np.empty(self.num_joints)
        out[self.joint_drake] = values[self.joint_pin]
        return out

    def residuals_to_drake(self, residuals: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """``PinocchioResidualPeer.step``'s output in the project's coordinates: (classical
        [moment; force; joints], internal, external base [moment; force], external world)."""
        classical, internal, base, world = residuals
        return (
            np.concatenate((classical[3:6], classical[:3], self.joints_to_drake(classical[6:]))),
            self.joints_to_drake(internal),
            np.concatenate((base[3:], base[:3])),
            np.concatenate((world[3:], world[:3])),
        )
