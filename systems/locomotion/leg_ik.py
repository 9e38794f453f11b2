"""Analytic leg inverse kinematics of ``nao_like`` for straight walking.

Leg chain (all joint frames aligned with the torso at zero angle, checked by
``NaoLegGeometry.from_plant``)::

    torso ─(hip offset (0, ±0.05, -0.085))─ HipYawPitch ─ HipRoll (x) ─ HipPitch (y)
          ─ thigh (0, 0, -L1) ─ KneePitch (y) ─ tibia (0, 0, -L2) ─ AnklePitch (y)
          ─ AnkleRoll (x) ─ sole frame (0, 0, -d)

With HipYawPitch = 0 and the torso and the foot both level with the same heading (the
straight-walking case: torso frame T and sole frame S parallel), the foot orientation
R_TS = Rx(q_hr) Ry(q_hp + q_k + q_ap) Rx(q_ar) = I gives

    q_ap = -(q_hp + q_k),   q_ar = -q_hr,                                        (IK-1)

and the ankle is d above the sole. With r = p_ankle - p_hip (torso frame, m), the leg's
pitch plane is rolled by q_hr about x and contains r:

    q_hr = atan2(r_y, -r_z),   u = (r_x, -sqrt(r_y^2 + r_z^2))  (x, z in that plane),  (IK-2)
    cos q_k = (|u|^2 - L1^2 - L2^2) / (2 L1 L2),   q_k in [0, pi]  (knee bends forward), (IK-3)
    q_hp = atan2(u_x, u_z) - atan2(w_x, w_z),  w = (-L2 sin q_k, -L1 - L2 cos q_k),    (IK-4)

since Ry(q) rotates the (x, z) angle atan2(x, z) by +q. Angles in rad, lengths in m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

#: Leg joint order of the IK outputs (Nao's order; HipYawPitch is always 0 here).
LEG_JOINTS = ("HipYawPitch", "HipRoll", "HipPitch", "KneePitch", "AnklePitch", "AnkleRoll")
SIDES = ("left", "right")


@dataclass(frozen=True)
class NaoLegGeometry:
    """Leg dimensions of ``nao_like``, m.

    Attributes:
        hip_offset: (3,) position of the left HipYawPitch joint in the torso frame; the
            right hip is its mirror image in y.
        thigh: L1, hip pitch to knee.
        tibia: L2, knee to ankle pitch.
        sole_depth: d, ankle roll axis to the sole frame (straight below).
    """

    hip_offset: tuple = (0.0, 0.05, -0.085)
    thigh: float = 0.100
    tibia: float = 0.1029
    sole_depth: float = 0.04519

    def hip(self, side: str) -> np.ndarray:
        """The hip joint position of ``side`` in the torso frame, m."""
        _check_side(side)
        p = np.array(self.hip_offset, dtype=float)
        if side == "right":
            p[1] = -p[1]
        return p

    @property
    def max_reach(self) -> float:
        """L1 + L2: hip-to-ankle distance of the straight (singular) leg, m."""
        return self.thigh + self.tibia

    @classmethod
    def from_plant(cls, plant: MultibodyPlant, model_instance=None) -> NaoLegGeometry:
        """Reads the leg dimensions from a finalized plant holding ``nao_like``.

        Raises:
            ValueError: if the legs do not have the structure of the module docstring
                (joint offsets, axes, identity joint frame rotations, symmetric sides).
        """

        def joint(name):
            if model_instance is None:
                return plant.GetJointByName(name)
            return plant.GetJointByName(name, model_instance)

        out = {}
        for side, prefix in (("left", "L"), ("right", "R")):
            j = {n: joint(prefix + n) for n in LEG_JOINTS}
            pos = {n: j[n].frame_on_parent().GetFixedPoseInBodyFrame() for n in LEG_JOINTS}
            for n in LEG_JOINTS:
                child = j[n].frame_on_child().GetFixedPoseInBodyFrame()
                if not (
                    np.allclose(pos[n].rotation().matrix(), np.eye(3), atol=1e-12)
                    and np.allclose(child.GetAsMatrix4(), np.eye(4), atol=1e-12)
                ):
                    raise ValueError(f"leg joint {prefix + n}: joint frames are not aligned with its parent")
            axes = {
                "HipRoll": (1, 0, 0),
                "HipPitch": (0, 1, 0),
                "KneePitch": (0, 1, 0),
                "AnklePitch": (0, 1, 0),
                "AnkleRoll": (1, 0, 0),
            }
            for n, axis in axes.items():
                if not np.allclose(j[n].revolute_axis(), axis, atol=1e-12):
                    raise ValueError(f"leg joint {prefix + n}: axis {j[n].revolute_axis()} is not {axis}")
            for n in ("HipRoll", "HipPitch", "AnkleRoll"):
                if not np.allclose(pos[n].translation(), 0.0, atol=1e-12):
                    raise ValueError(f"leg joint {prefix + n}: not at its parent's origin")
            knee, ankle = pos["KneePitch"].translation(), pos["AnklePitch"].translation()
            if not (np.allclose(knee[:2], 0.0) and np.allclose(ankle[:2], 0.0)):
                raise ValueError(f"{side} leg: thigh/tibia not along -z")
            frame_name = f"{prefix.lower()}_sole_frame"
            frame = (
                plant.GetFrameByName(frame_name)
                if model_instance is None
                else plant.GetFrameByName(frame_name, model_instance)
            )
            X = frame.GetFixedPoseInBodyFrame()
            if frame.body().index() != j["AnkleRoll"].child_body().index():
                raise ValueError(f"{frame_name} is not on the ankle roll body")
            if not (
                np.allclose(X.rotation().matrix(), np.eye(3), atol=1e-12) and np.allclose(X.translation()[:2], 0.0)
            ):
                raise ValueError(f"{frame_name} is not straight below the ankle roll axis")
            sole = -X.translation()[2]
            out[side] = (
                tuple(float(c) for c in pos["HipYawPitch"].translation()),
                float(-knee[2]),
                float(-ankle[2]),
                float(sole),
            )
        left, right = out["left"], out["right"]
        mirrored = (left[0][0], -left[0][1], left[0][2])
        if not (np.allclose(right[0], mirrored) and np.allclose(left[1:], right[1:])):
            raise ValueError("the two legs are not mirror images")
        return cls(hip_offset=left[0], thigh=left[1], tibia=left[2], sole_depth=left[3])


def _check_side(side: str) -> None:
    if side not in SIDES:
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")


def leg_ik(geometry: NaoLegGeometry, p_torso_sole: np.ndarray, side: str) -> np.ndarray:
    """Joint angles of one leg that put its sole frame at ``p_torso_sole``, foot parallel to
    the torso, HipYawPitch = 0 (eqs. IK-1..IK-4 of the module docstring). Vectorised.

    Args:
        geometry: the leg dimensions.
        p_torso_sole: (..., 3) sole frame origin in the torso frame, m.
        side: "left" or "right".

    Returns:
        (..., 6) angles in LEG_JOINTS order, rad.

    Raises:
        ValueError: a target out of reach (hip-ankle distance above L1 + L2 or below
            |L1 - L2|), or non-finite targets.
    """
    _check_side(side)
    p = np.asarray(p_torso_sole, dtype=float)
    if p.shape[-1] != 3:
        raise ValueError(f"p_torso_sole must have shape (..., 3), got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("leg_ik: non-finite sole target")
    L1, L2 = geometry.thigh, geometry.tibia
    r = p + np.array([0.0, 0.0, geometry.sole_depth]) - geometry.hip(side)  # hip -> ankle
    q_hr = np.arctan2(r[..., 1], -r[..., 2])  # (IK-2)
    ux = r[..., 0]
    uz = -np.hypot(r[..., 1], r[..., 2])
    cos_k = (ux * ux + uz * uz - L1 * L1 - L2 * L2) / (2.0 * L1 * L2)  # (IK-3)
    if np.any(cos_k > 1.0) or np.any(cos_k < -1.0):
        dist = np.sqrt(ux * ux + uz * uz)
        raise ValueError(
            f"leg_ik: {side} sole target out of reach: hip-ankle distance {dist.max():.4f} m "
            f"(min {dist.min():.4f} m) outside [{abs(L1 - L2):.4f}, {L1 + L2:.4f}] m"
        )
    q_k = np.arccos(cos_k)
    wx, wz = -L2 * np.sin(q_k), -L1 - L2 * np.cos(q_k)
    q_hp = np.arctan2(ux, uz) - np.arctan2(wx, wz)  # (IK-4)
    q_hp = (q_hp + np.pi) % (2.0 * np.pi) - np.pi
    q_ap = -(q_hp + q_k)  # (IK-1)
    q_ar = -q_hr
    return np.stack([np.zeros_like(q_hr), q_hr, q_hp, q_k, q_ap, q_ar], axis=-1)


def leg_fk(geometry: NaoLegGeometry, angles: np.ndarray, side: str) -> np.ndarray:
    """Sole frame origin in the torso frame (m) for (..., 6) leg angles with HipYawPitch = 0
    (the same chain as the module docstring; for tests and checks, Drake is the reference)."""
    _check_side(side)
    q = np.asarray(angles, dtype=float)
    if np.any(np.abs(q[..., 0]) > 0):
        raise ValueError("leg_fk supports HipYawPitch = 0 only")
    q_hr, q_hp, q_k, q_ap, q_ar = (q[..., i] for i in range(1, 6))
    L1, L2, d = geometry.thigh, geometry.tibia, geometry.sole_depth
    # In the hip-roll frame: the x-z plane chain.
    a1, a2, a3 = q_hp, q_hp + q_k, q_hp + q_k + q_ap
    x = -L1 * np.sin(a1) - L2 * np.sin(a2)
    z = -L1 * np.cos(a1) - L2 * np.cos(a2)
    # Sole: d along -z of the ankle-roll frame R = Ry(a3) Rx(q_ar).
    sx = -d * np.sin(a3) * np.cos(q_ar)
    sy = d * np.sin(q_ar)
    sz = -d * np.cos(a3) * np.cos(q_ar)
    px, pz0 = x + sx, z + sz
    # Roll about x by q_hr.
    c, s = np.cos(q_hr), np.sin(q_hr)
    py = c * sy - s * pz0
    pz = s * sy + c * pz0
    return np.stack([px, py, pz], axis=-1) + geometry.hip(side)


__all__ = ["LEG_JOINTS", "NaoLegGeometry", "leg_ik", "leg_fk"]
