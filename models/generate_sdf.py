"""Generates the SDFormat humanoid models from compact Python specs.

Run ``python -m models.generate_sdf`` to (re)write ``models/hrp4_like.sdf``,
``models/nao_like.sdf`` and its variant ``models/nao_like_recorded.sdf``.
``tests/test_models.py`` checks that the committed files equal this generator's output,
so edit the specs here, never the .sdf files.

Conventions shared by both models:

* In the zero configuration every link frame is aligned with the model frame
  (x forward, y left, z up); a child link's frame sits at its parent joint's origin.
  Joint axes are expressed in the child link frame (= the joint frame).
* Each link's inertia is that of a uniform solid primitive (its "mass shape", one of the
  link's collision shapes) with the link's mass; the centre of mass is that primitive's
  centre. Every link has collision and visual geometry made of the same primitives.
* Every actuated joint carries ``drake:rotor_inertia`` and ``drake:gear_ratio``: the
  reflected motor inertia rho * N^2 that Drake adds to the mass-matrix diagonal. Real
  harmonic-drive (HRP-4) and spur-gear (Nao) joints have it; it also keeps an explicit
  1 kHz PD stable on the light distal links.
* Foot contact uses four small spheres per foot (bottoms exactly on the sole plane) with
  explicit point-contact properties; the foot box's bottom is 2 mm above them.
* All robot-robot collisions are filtered by a ``drake:collision_filter_group``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.multibody.tree import SpatialInertia

MODELS_DIR = Path(__file__).resolve().parent

#: Order of the four foot contact spheres, everywhere in the project.
FSR_ORDER = ("front_left", "front_right", "rear_left", "rear_right")


@dataclass
class Shape:
    """A primitive. kind: box (size = x, y, z), sphere (r,), cylinder/capsule (r, length)."""

    kind: str
    size: tuple
    xyz: tuple = (0.0, 0.0, 0.0)
    axis: str = "z"  # long axis of cylinders and capsules
    name: str | None = None  # collision name (default: <link>_collision_<i>)
    contact: dict | None = None  # explicit drake:proximity_properties


@dataclass
class Link:
    name: str
    mass: float  # kg
    shapes: list
    mass_shape: int = 0  # index into shapes of the primitive giving the inertia
    color: tuple = (0.7, 0.7, 0.75, 1.0)
    com_offset: tuple = (0.0, 0.0, 0.0)  # CoM minus the mass shape's centre, link frame, m


@dataclass
class Joint:
    name: str
    parent: str
    child: str
    xyz: tuple  # child link frame origin in the parent link frame, m
    axis: tuple = (0.0, 0.0, 1.0)
    lower: float = -math.pi  # rad
    upper: float = math.pi  # rad
    effort: float = 0.0  # N m; 0 means a weld (type fixed)
    velocity: float = 6.0  # rad/s
    damping: float = 0.0  # N m s / rad
    rotor_inertia: float = 0.0  # kg m^2 (motor side)
    gear_ratio: float = 1.0
    fixed: bool = False


@dataclass
class ModelSpec:
    name: str
    base: str
    base_height: float  # base origin height in the zero (straight-legged) posture, m
    links: list
    joints: list
    frames: list = field(default_factory=list)  # (name, attached_to, xyz)
    comment: str = ""


def _contact(stiffness: float, dissipation: float, friction: float) -> dict:
    return {
        "point_contact_stiffness": stiffness,  # N/m
        "hunt_crossley_dissipation": dissipation,  # s/m
        "relaxation_time": 0.002,  # s (used by SAP's contact model)
        "mu_dynamic": friction,
        "mu_static": friction,
    }


# --------------------------------------------------------------------------------------
# HRP-4-like.
# Structure, 34 joint DoF, total mass 39 kg and height 1.51 m: Kaneko et al., "Humanoid
# robot HRP-4 - Humanoid robotics platform with lightweight and slim body", IROS 2011.
# Per-link masses and lengths are NOT published there: they are plausible values chosen
# here (waist 5.5, thigh 3.0, shank 1.8, chest 9.0, head 1.0, arm 3.9 kg per side) so that
# the totals match. Effort limits, damping and rotor inertias are rough guesses of the
# right order of magnitude for harmonic-drive joints.
# --------------------------------------------------------------------------------------

_HRP4_ANKLE_HEIGHT = 0.09  # ankle axis above the sole plane, m
_HRP4_FT_ABOVE_SOLE = 0.04  # F/T sensor (sole body origin) above the sole plane, m
_HRP4_FOOT = dict(length=0.22, width=0.13, x_center=0.015)  # m, sole frame in ankle x
_HRP4_SPHERE_R = 0.005
_HRP4_FOOT_CONTACT = _contact(5e5, 20.0, 1.0)
_HRP4_FSR_XY = np.array(
    [[0.10, 0.055], [0.10, -0.055], [-0.10, 0.055], [-0.10, -0.055]]
)  # corner spheres in the sole frame (front_left, front_right, rear_left, rear_right)


def _hrp4_leg(side: str) -> tuple[list, list]:
    s = 1.0 if side == "L" else -1.0
    lo = side.lower()
    big = dict(damping=0.2, rotor_inertia=1.0e-5, gear_ratio=120.0)
    links = [
        Link(f"{side}_HIP_Y_LINK", 0.6, [Shape("cylinder", (0.04, 0.04))]),
        Link(f"{side}_HIP_R_LINK", 0.6, [Shape("box", (0.08, 0.08, 0.08))]),
        Link(f"{side}_HIP_P_LINK", 3.0, [Shape("capsule", (0.055, 0.19), (0, 0, -0.15))]),
        Link(f"{side}_KNEE_P_LINK", 1.8, [Shape("capsule", (0.045, 0.21), (0, 0, -0.15))]),
        Link(f"{side}_ANKLE_P_LINK", 0.4, [Shape("sphere", (0.035,))]),
        Link(f"{side}_ANKLE_R_LINK", 0.6, [Shape("cylinder", (0.03, 0.08), axis="x")]),
    ]
    z_s = -_HRP4_FT_ABOVE_SOLE  # sole plane in the sole body frame
    xc = _HRP4_FOOT["x_center"]
    shapes = [
        Shape(
            "sphere",
            (_HRP4_SPHERE_R,),
            (xc + x, y, z_s + _HRP4_SPHERE_R),
            name=f"{lo}_contact_{n}",
            contact=_HRP4_FOOT_CONTACT,
        )
        for n, (x, y) in zip(FSR_ORDER, _HRP4_FSR_XY)
    ]
    shapes.append(
        Shape(
            "box",
            (_HRP4_FOOT["length"], _HRP4_FOOT["width"], 0.03),
            (xc, 0.0, z_s + 0.002 + 0.015),
            name=f"{lo}_foot_box",
            contact=_HRP4_FOOT_CONTACT,
        )
    )
    links.append(Link(f"{lo}_sole", 0.5, shapes, mass_shape=4, color=(0.3, 0.3, 0.35, 1)))
    roll = (-0.5, 0.35) if side == "L" else (-0.35, 0.5)
    yaw = (-0.5, 0.8) if side == "L" else (-0.8, 0.5)
    joints = [
        Joint(
            f"{side}_HIP_Y", "waist", f"{side}_HIP_Y_LINK", (0, s * 0.0875, -0.07), (0, 0, 1), *yaw, effort=60, **big
        ),
        Joint(
            f"{side}_HIP_R",
            f"{side}_HIP_Y_LINK",
            f"{side}_HIP_R_LINK",
            (0, 0, -0.03),
            (1, 0, 0),
            *roll,
            effort=120,
            **big,
        ),
        Joint(
            f"{side}_HIP_P",
            f"{side}_HIP_R_LINK",
            f"{side}_HIP_P_LINK",
            (0, 0, 0),
            (0, 1, 0),
            -2.0,
            0.8,
            effort=150,
            **big,
        ),
        Joint(
            f"{side}_KNEE_P",
            f"{side}_HIP_P_LINK",
            f"{side}_KNEE_P_LINK",
            (0, 0, -0.3),
            (0, 1, 0),
            0.0,
            2.4,
            effort=200,
            **big,
        ),
        Joint(
            f"{side}_ANKLE_P",
            f"{side}_KNEE_P_LINK",
            f"{side}_ANKLE_P_LINK",
            (0, 0, -0.3),
            (0, 1, 0),
            -1.3,
            0.9,
            effort=120,
            **big,
        ),
        Joint(
            f"{side}_ANKLE_R",
            f"{side}_ANKLE_P_LINK",
            f"{side}_ANKLE_R_LINK",
            (0, 0, 0),
            (1, 0, 0),
            -0.6,
            0.6,
            effort=80,
            **big,
        ),
        Joint(
            f"{side}_FT_SENSOR",
            f"{side}_ANKLE_R_LINK",
            f"{lo}_sole",
            (0, 0, -(_HRP4_ANKLE_HEIGHT - _HRP4_FT_ABOVE_SOLE)),
            fixed=True,
        ),
    ]
    return links, joints


def _hrp4_arm(side: str) -> tuple[list, list]:
    s = 1.0 if side == "L" else -1.0
    arm = dict(damping=0.05, rotor_inertia=4.0e-6, gear_ratio=120.0)
    wrist = dict(damping=0.02, rotor_inertia=1.0e-6, gear_ratio=100.0)
    hand = dict(damping=0.005, rotor_inertia=1.0e-7, gear_ratio=100.0)
    links = [
        Link(f"{side}_SHOULDER_P_LINK", 0.6, [Shape("sphere", (0.045,), (0, s * 0.01, 0))]),
        Link(f"{side}_SHOULDER_R_LINK", 0.6, [Shape("cylinder", (0.04, 0.06), axis="x")]),
        Link(f"{side}_SHOULDER_Y_LINK", 1.0, [Shape("capsule", (0.04, 0.14), (0, 0, -0.11))]),
        Link(f"{side}_ELBOW_P_LINK", 0.6, [Shape("cylinder", (0.04, 0.07), axis="y")]),
        Link(f"{side}_WRIST_Y_LINK", 0.5, [Shape("capsule", (0.035, 0.13), (0, 0, -0.1))]),
        Link(f"{side}_WRIST_P_LINK", 0.2, [Shape("sphere", (0.025,))]),
        Link(f"{side}_WRIST_R_LINK", 0.3, [Shape("box", (0.06, 0.04, 0.08), (0, 0, -0.05))]),
        Link(f"{side}_HAND_J0_LINK", 0.05, [Shape("box", (0.015, 0.02, 0.05), (0, 0, -0.025))]),
        Link(f"{side}_HAND_J1_LINK", 0.05, [Shape("box", (0.015, 0.02, 0.05), (0, 0, -0.025))]),
    ]
    roll = (-0.2, 2.8) if side == "L" else (-2.8, 0.2)
    syaw = (-2.0, 2.0)
    joints = [
        Joint(
            f"{side}_SHOULDER_P",
            "CHEST_Y_LINK",
            f"{side}_SHOULDER_P_LINK",
            (0, s * 0.18, 0.27),
            (0, 1, 0),
            -3.1,
            1.0,
            effort=60,
            **arm,
        ),
        Joint(
            f"{side}_SHOULDER_R",
            f"{side}_SHOULDER_P_LINK",
            f"{side}_SHOULDER_R_LINK",
            (0, s * 0.03, 0),
            (1, 0, 0),
            *roll,
            effort=60,
            **arm,
        ),
        Joint(
            f"{side}_SHOULDER_Y",
            f"{side}_SHOULDER_R_LINK",
            f"{side}_SHOULDER_Y_LINK",
            (0, 0, 0),
            (0, 0, 1),
            *syaw,
            effort=40,
            **arm,
        ),
        Joint(
            f"{side}_ELBOW_P",
            f"{side}_SHOULDER_Y_LINK",
            f"{side}_ELBOW_P_LINK",
            (0, 0, -0.22),
            (0, 1, 0),
            -2.5,
            0.0,
            effort=40,
            **arm,
        ),
        Joint(
            f"{side}_WRIST_Y",
            f"{side}_ELBOW_P_LINK",
            f"{side}_WRIST_Y_LINK",
            (0, 0, 0),
            (0, 0, 1),
            -2.5,
            2.5,
            effort=10,
            **wrist,
        ),
        Joint(
            f"{side}_WRIST_P",
            f"{side}_WRIST_Y_LINK",
            f"{side}_WRIST_P_LINK",
            (0, 0, -0.2),
            (0, 1, 0),
            -1.4,
            1.4,
            effort=10,
            **wrist,
        ),
        Joint(
            f"{side}_WRIST_R",
            f"{side}_WRIST_P_LINK",
            f"{side}_WRIST_R_LINK",
            (0, 0, 0),
            (1, 0, 0),
            -1.4,
            1.4,
            effort=10,
            **wrist,
        ),
        Joint(
            f"{side}_HAND_J0",
            f"{side}_WRIST_R_LINK",
            f"{side}_HAND_J0_LINK",
            (0.02, 0, -0.09),
            (0, 1, 0),
            -1.0,
            0.0,
            effort=2,
            **hand,
        ),
        Joint(
            f"{side}_HAND_J1",
            f"{side}_WRIST_R_LINK",
            f"{side}_HAND_J1_LINK",
            (-0.02, 0, -0.09),
            (0, 1, 0),
            0.0,
            1.0,
            effort=2,
            **hand,
        ),
    ]
    return links, joints


def hrp4_like_spec() -> ModelSpec:
    trunk = dict(damping=0.2, rotor_inertia=1.0e-5, gear_ratio=120.0)
    neck = dict(damping=0.02, rotor_inertia=1.0e-6, gear_ratio=100.0)
    links = [
        Link("waist", 5.5, [Shape("box", (0.16, 0.24, 0.14), (0, 0, -0.01))], color=(0.85, 0.85, 0.9, 1)),
        Link("CHEST_P_LINK", 0.5, [Shape("cylinder", (0.04, 0.1), axis="y")]),
        Link("CHEST_Y_LINK", 9.0, [Shape("box", (0.2, 0.28, 0.3), (-0.01, 0, 0.17))], color=(0.85, 0.85, 0.9, 1)),
        Link("NECK_Y_LINK", 0.2, [Shape("cylinder", (0.025, 0.04), (0, 0, 0.02))]),
        Link("NECK_P_LINK", 1.0, [Shape("box", (0.16, 0.14, 0.18), (0.01, 0, 0.11))], color=(0.85, 0.85, 0.9, 1)),
    ]
    joints = [
        Joint("CHEST_P", "waist", "CHEST_P_LINK", (0, 0, 0.10), (0, 1, 0), -0.3, 0.8, effort=150, **trunk),
        Joint("CHEST_Y", "CHEST_P_LINK", "CHEST_Y_LINK", (0, 0, 0.02), (0, 0, 1), -1.0, 1.0, effort=100, **trunk),
        Joint("NECK_Y", "CHEST_Y_LINK", "NECK_Y_LINK", (0, 0, 0.36), (0, 0, 1), -1.4, 1.4, effort=10, **neck),
        Joint("NECK_P", "NECK_Y_LINK", "NECK_P_LINK", (0, 0, 0.04), (0, 1, 0), -0.5, 0.8, effort=10, **neck),
    ]
    for side in ("R", "L"):
        lk, jt = _hrp4_leg(side)
        links += lk
        joints += jt
    for side in ("R", "L"):
        lk, jt = _hrp4_arm(side)
        links += lk
        joints += jt
    xc = _HRP4_FOOT["x_center"]
    frames = [
        ("imu", "waist", (0.0, 0.0, 0.05)),
        ("r_sole_frame", "r_sole", (xc, 0.0, -_HRP4_FT_ABOVE_SOLE)),
        ("l_sole_frame", "l_sole", (xc, 0.0, -_HRP4_FT_ABOVE_SOLE)),
        ("head_top", "NECK_P_LINK", (0.01, 0.0, 0.20)),
    ]
    base_height = 0.07 + 0.03 + 0.3 + 0.3 + _HRP4_ANKLE_HEIGHT
    return ModelSpec(
        "hrp4_like",
        "waist",
        base_height,
        links,
        joints,
        frames,
        comment="HRP-4-like humanoid, 34 actuated DoF (Kaneko et al. 2011)",
    )


# --------------------------------------------------------------------------------------
# Nao-like (Nao H25 V3.3/V4 documentation, Aldebaran "NAO - Links" / "Masses" pages):
# dimensions in m, link masses in kg. The torso mass is scaled so that the total is the
# 5.19 kg used by Hawley et al. 2019 (the variant nao_like_recorded: see
# NAO_RECORDED_LEG_MASS_SCALE). The gripper finger (0.01 kg) is taken out of the
# documented Hand mass. On the real Nao LHipYawPitch and RHipYawPitch share one motor;
# here they are two independent joints (26 joints instead of 25 DoF).
# Effort limits are approximate stall torques; rotor inertia is of the order of Nao's
# Maxon RE-max motors times the gear ratio squared.
# --------------------------------------------------------------------------------------

NAO_DIMS = dict(
    NeckOffsetZ=0.1265,
    ShoulderOffsetY=0.098,
    ShoulderOffsetZ=0.100,
    UpperArmLength=0.105,
    ElbowOffsetY=0.015,
    LowerArmLength=0.05595,
    HandOffsetX=0.05775,
    HipOffsetY=0.050,
    HipOffsetZ=0.085,
    ThighLength=0.100,
    TibiaLength=0.1029,
    FootHeight=0.04519,
)
NAO_MASSES = dict(
    Torso=1.0496,
    Neck=0.07842,
    Head=0.60533,
    Shoulder=0.09304,
    Biceps=0.15777,
    Elbow=0.06483,
    ForeArm=0.07761,
    Hand=0.18533,
    Pelvis=0.06981,
    Hip=0.14053,
    Thigh=0.38968,
    Tibia=0.29142,
    Ankle=0.13416,
    Foot=0.16184,
)
NAO_TOTAL_MASS = 5.19  # kg, Hawley et al. 2019
_NAO_FINGER_MASS = 0.01
#: Documented FSR positions in the foot (sole) frame, m: FL, FR, RL, RR.
NAO_FSR_XY = {
    "left": np.array([[0.07025, 0.0299], [0.07025, -0.0231], [-0.03025, 0.0299], [-0.02965, -0.0191]]),
    "right": np.array([[0.07025, 0.0231], [0.07025, -0.0299], [-0.03025, 0.0191], [-0.02965, -0.0299]]),
}
_NAO_SPHERE_R = 0.005
_NAO_FOOT_CONTACT = _contact(1e5, 20.0, 1.0)


#: ``nao_like_recorded``: the same robot with the standing CoM height of Hawley et al.'s
#: recordings (``data/hawley2019-nao``, ``CoM_Pos.mat``: 0.314 m above the support sole; the
#: paper's eq. 24 implies the same). The documented link masses put it at 0.268 m in the
#: nominal standing posture (``nao_like``): the documented legs are heavy and the documented
#: torso light for the recordings. The variant moves mass from the legs to the torso (each
#: leg link keeps ``NAO_RECORDED_LEG_MASS_SCALE`` of its documented mass) and raises the
#: torso's CoM by ``NAO_RECORDED_TORSO_COM_RAISE`` within its box, keeping the 5.19 kg total;
#: ``tests/test_models.py`` checks its standing CoM against the recordings (issue 31: fix
#: the model's mass distribution, not the observer). The walking experiments stay on
#: ``nao_like``: their pattern and gains are tuned to its mass distribution.
NAO_RECORDED_LEG_MASS_SCALE = 0.685
NAO_RECORDED_TORSO_COM_RAISE = 0.043  # m, along the torso's z
_NAO_LEG_LINKS = ("Pelvis", "Hip", "Thigh", "Tibia", "Ankle", "Foot")


def _nao_torso_mass(leg_scale: float) -> float:
    m = NAO_MASSES
    arm = m["Shoulder"] + m["Biceps"] + m["Elbow"] + m["ForeArm"] + m["Hand"]
    leg = leg_scale * sum(m[link] for link in _NAO_LEG_LINKS)
    return NAO_TOTAL_MASS - (m["Neck"] + m["Head"] + 2 * (arm + leg))


def _nao_arm(side: str) -> tuple[list, list]:
    s = 1.0 if side == "L" else -1.0
    lo = side.lower()
    m, d = NAO_MASSES, NAO_DIMS
    act = dict(damping=0.01, rotor_inertia=1.0e-7, gear_ratio=140.0)
    links = [
        Link(f"{side}Shoulder", m["Shoulder"], [Shape("sphere", (0.02,))]),
        Link(f"{side}Bicep", m["Biceps"], [Shape("capsule", (0.025, 0.06), (0.05, 0, 0), "x")]),
        Link(f"{side}Elbow", m["Elbow"], [Shape("sphere", (0.02,))]),
        Link(f"{side}ForeArm", m["ForeArm"], [Shape("capsule", (0.02, 0.03), (0.03, 0, 0), "x")]),
        Link(f"{lo}_wrist", m["Hand"] - _NAO_FINGER_MASS, [Shape("box", (0.06, 0.04, 0.03), (0.03, 0, 0))]),
        Link(f"{lo}_gripper", _NAO_FINGER_MASS, [Shape("box", (0.03, 0.02, 0.01), (0.015, 0, 0))]),
    ]
    roll = (-0.3142, 1.3265) if side == "L" else (-1.3265, 0.3142)
    eroll = (-1.5446, -0.0349) if side == "L" else (0.0349, 1.5446)
    joints = [
        Joint(
            f"{side}ShoulderPitch",
            "torso",
            f"{side}Shoulder",
            (0, s * d["ShoulderOffsetY"], d["ShoulderOffsetZ"]),
            (0, 1, 0),
            -2.0857,
            2.0857,
            effort=1.5,
            **act,
        ),
        Joint(f"{side}ShoulderRoll", f"{side}Shoulder", f"{side}Bicep", (0, 0, 0), (0, 0, 1), *roll, effort=1.5, **act),
        Joint(
            f"{side}ElbowYaw",
            f"{side}Bicep",
            f"{side}Elbow",
            (d["UpperArmLength"], s * d["ElbowOffsetY"], 0),
            (1, 0, 0),
            -2.0857,
            2.0857,
            effort=1.5,
            **act,
        ),
        Joint(f"{side}ElbowRoll", f"{side}Elbow", f"{side}ForeArm", (0, 0, 0), (0, 0, 1), *eroll, effort=1.5, **act),
        Joint(
            f"{side}WristYaw",
            f"{side}ForeArm",
            f"{lo}_wrist",
            (d["LowerArmLength"], 0, 0),
            (1, 0, 0),
            -1.8238,
            1.8238,
            effort=0.4,
            **act,
        ),
        Joint(
            f"{side}Hand",
            f"{lo}_wrist",
            f"{lo}_gripper",
            (d["HandOffsetX"], 0, 0),
            (0, 1, 0),
            0.0,
            1.0,
            effort=0.3,
            **act,
        ),
    ]
    return links, joints


def _nao_leg(side: str, leg_scale: float) -> tuple[list, list]:
    s = 1.0 if side == "L" else -1.0
    lo = side.lower()
    m, d = NAO_MASSES, NAO_DIMS
    act = dict(damping=0.02, rotor_inertia=3.0e-7, gear_ratio=130.0)
    z_s = -d["FootHeight"]
    fsr = NAO_FSR_XY["left" if side == "L" else "right"]
    shapes = [
        Shape("sphere", (_NAO_SPHERE_R,), (x, y, z_s + _NAO_SPHERE_R), name=f"{lo}_fsr_{n}", contact=_NAO_FOOT_CONTACT)
        for n, (x, y) in zip(FSR_ORDER, fsr)
    ]
    shapes.append(
        Shape(
            "box",
            (0.16, 0.088, 0.04),
            (0.02, s * 0.0034, z_s + 0.002 + 0.02),
            name=f"{lo}_foot_box",
            contact=_NAO_FOOT_CONTACT,
        )
    )
    links = [
        Link(f"{side}Pelvis", leg_scale * m["Pelvis"], [Shape("sphere", (0.02,))]),
        Link(f"{side}Hip", leg_scale * m["Hip"], [Shape("sphere", (0.025,))]),
        Link(f"{side}Thigh", leg_scale * m["Thigh"], [Shape("capsule", (0.035, 0.04), (0, 0, -0.05))]),
        Link(f"{side}Tibia", leg_scale * m["Tibia"], [Shape("capsule", (0.03, 0.04), (0, 0, -0.05))]),
        Link(f"{side}Ankle", leg_scale * m["Ankle"], [Shape("sphere", (0.02,))]),
        Link(f"{lo}_ankle", leg_scale * m["Foot"], shapes, mass_shape=4, color=(0.3, 0.3, 0.35, 1)),
    ]
    r2 = 1.0 / math.sqrt(2.0)
    hyp_axis = (0, r2, -r2) if side == "L" else (0, r2, r2)
    hroll = (-0.379, 0.790) if side == "L" else (-0.790, 0.379)
    aroll = (-0.3978, 0.769) if side == "L" else (-0.769, 0.3978)
    joints = [
        Joint(
            f"{side}HipYawPitch",
            "torso",
            f"{side}Pelvis",
            (0, s * d["HipOffsetY"], -d["HipOffsetZ"]),
            hyp_axis,
            -1.1453,
            0.7408,
            effort=5.0,
            **act,
        ),
        Joint(f"{side}HipRoll", f"{side}Pelvis", f"{side}Hip", (0, 0, 0), (1, 0, 0), *hroll, effort=5.0, **act),
        Joint(f"{side}HipPitch", f"{side}Hip", f"{side}Thigh", (0, 0, 0), (0, 1, 0), -1.5359, 0.484, effort=5.0, **act),
        Joint(
            f"{side}KneePitch",
            f"{side}Thigh",
            f"{side}Tibia",
            (0, 0, -d["ThighLength"]),
            (0, 1, 0),
            -0.0923,
            2.1125,
            effort=5.0,
            **act,
        ),
        Joint(
            f"{side}AnklePitch",
            f"{side}Tibia",
            f"{side}Ankle",
            (0, 0, -d["TibiaLength"]),
            (0, 1, 0),
            -1.1895,
            0.9227,
            effort=5.0,
            **act,
        ),
        Joint(f"{side}AnkleRoll", f"{side}Ankle", f"{lo}_ankle", (0, 0, 0), (1, 0, 0), *aroll, effort=5.0, **act),
    ]
    return links, joints


def nao_like_spec(recorded_com: bool = False) -> ModelSpec:
    """``nao_like``, or with ``recorded_com`` its variant ``nao_like_recorded`` (above)."""
    d = NAO_DIMS
    leg_scale = NAO_RECORDED_LEG_MASS_SCALE if recorded_com else 1.0
    torso_raise = NAO_RECORDED_TORSO_COM_RAISE if recorded_com else 0.0
    act = dict(damping=0.01, rotor_inertia=1.0e-7, gear_ratio=140.0)
    links = [
        Link(
            "torso",
            _nao_torso_mass(leg_scale),
            [Shape("box", (0.09, 0.13, 0.17), (-0.005, 0, 0.035))],
            color=(0.9, 0.9, 0.9, 1),
            com_offset=(0.0, 0.0, torso_raise),
        ),
        Link("Neck", NAO_MASSES["Neck"], [Shape("cylinder", (0.015, 0.03), (0, 0, -0.015))]),
        Link("Head", NAO_MASSES["Head"], [Shape("sphere", (0.059,), (0, 0, 0.055))], color=(0.9, 0.9, 0.9, 1)),
    ]
    joints = [
        Joint("HeadYaw", "torso", "Neck", (0, 0, d["NeckOffsetZ"]), (0, 0, 1), -2.0857, 2.0857, effort=1.5, **act),
        Joint("HeadPitch", "Neck", "Head", (0, 0, 0), (0, 1, 0), -0.672, 0.5149, effort=1.5, **act),
    ]
    for side in ("L", "R"):
        lk, jt = _nao_arm(side)
        links += lk
        joints += jt
    for side in ("L", "R"):
        lk, jt = _nao_leg(side, leg_scale)
        links += lk
        joints += jt
    frames = [
        ("imu", "torso", (-0.008, 0.006, 0.029)),
        ("l_sole_frame", "l_ankle", (0.0, 0.0, -d["FootHeight"])),
        ("r_sole_frame", "r_ankle", (0.0, 0.0, -d["FootHeight"])),
        ("head_top", "Head", (0.0, 0.0, 0.114)),
    ]
    base_height = d["HipOffsetZ"] + d["ThighLength"] + d["TibiaLength"] + d["FootHeight"]
    return ModelSpec(
        "nao_like_recorded" if recorded_com else "nao_like",
        "torso",
        base_height,
        links,
        joints,
        frames,
        comment="Nao-H25-like humanoid, 26 revolute joints (Aldebaran docs)"
        + (", mass moved from the legs to the torso: standing CoM at the recorded 0.314 m" if recorded_com else ""),
    )


SPECS = {
    "hrp4_like": hrp4_like_spec,
    "nao_like": nao_like_spec,
    "nao_like_recorded": functools.partial(nao_like_spec, recorded_com=True),
}


# --------------------------------------------------------------------------------------
# SDFormat writer.
# --------------------------------------------------------------------------------------


def _f(x: float) -> str:
    x = float(x)
    if abs(x) < 1e-15:
        x = 0.0
    return f"{x:.9g}"


def _vec(v) -> str:
    return " ".join(_f(x) for x in v)


_AXIS_RPY = {"z": (0.0, 0.0, 0.0), "x": (0.0, math.pi / 2, 0.0), "y": (math.pi / 2, 0.0, 0.0)}
_AXIS_VEC = {"z": [0.0, 0.0, 1.0], "x": [1.0, 0.0, 0.0], "y": [0.0, 1.0, 0.0]}


def _geometry_xml(shape: Shape, ind: str) -> str:
    if shape.kind == "box":
        body = f"<box><size>{_vec(shape.size)}</size></box>"
    elif shape.kind == "sphere":
        body = f"<sphere><radius>{_f(shape.size[0])}</radius></sphere>"
    elif shape.kind in ("cylinder", "capsule"):
        body = f"<{shape.kind}><radius>{_f(shape.size[0])}</radius><length>{_f(shape.size[1])}</length></{shape.kind}>"
    else:
        raise ValueError(f"unknown shape kind {shape.kind!r}")
    return f"{ind}<geometry>{body}</geometry>\n"


def _inertia(link: Link) -> tuple[tuple, np.ndarray]:
    shape = link.shapes[link.mass_shape]
    m = link.mass
    if shape.kind == "box":
        M = SpatialInertia.SolidBoxWithMass(m, *shape.size)
    elif shape.kind == "sphere":
        M = SpatialInertia.SolidSphereWithMass(m, shape.size[0])
    elif shape.kind == "cylinder":
        M = SpatialInertia.SolidCylinderWithMass(m, shape.size[0], shape.size[1], _AXIS_VEC[shape.axis])
    elif shape.kind == "capsule":
        M = SpatialInertia.SolidCapsuleWithMass(m, shape.size[0], shape.size[1], _AXIS_VEC[shape.axis])
    else:
        raise ValueError(shape.kind)
    com = tuple(float(a + b) for a, b in zip(shape.xyz, link.com_offset))
    return com, M.CalcRotationalInertia().CopyToFullMatrix3()


def _link_xml(link: Link, pose_xml: str) -> str:
    out = [f'    <link name="{link.name}">\n', pose_xml]
    com, I = _inertia(link)
    out.append(
        "      <inertial>\n"
        f"        <pose>{_vec(com)} 0 0 0</pose>\n"
        f"        <mass>{_f(link.mass)}</mass>\n"
        f"        <inertia><ixx>{_f(I[0, 0])}</ixx><ixy>{_f(I[0, 1])}</ixy>"
        f"<ixz>{_f(I[0, 2])}</ixz><iyy>{_f(I[1, 1])}</iyy><iyz>{_f(I[1, 2])}</iyz>"
        f"<izz>{_f(I[2, 2])}</izz></inertia>\n"
        "      </inertial>\n"
    )
    for i, shape in enumerate(link.shapes):
        cname = shape.name or f"{link.name}_collision_{i}"
        pose = f"        <pose>{_vec(shape.xyz)} {_vec(_AXIS_RPY[shape.axis])}</pose>\n"
        color = (0.8, 0.1, 0.1, 1.0) if shape.contact and shape.kind == "sphere" else link.color
        out.append(
            f'      <visual name="{cname}_visual">\n'
            + pose
            + _geometry_xml(shape, "        ")
            + f"        <material><diffuse>{_vec(color)}</diffuse></material>\n"
            "      </visual>\n"
        )
        out.append(f'      <collision name="{cname}">\n' + pose + _geometry_xml(shape, "        "))
        if shape.contact:
            out.append("        <drake:proximity_properties>\n")
            for k, v in shape.contact.items():
                out.append(f"          <drake:{k}>{_f(v)}</drake:{k}>\n")
            out.append("        </drake:proximity_properties>\n")
        out.append("      </collision>\n")
    out.append("    </link>\n")
    return "".join(out)


def _joint_xml(j: Joint) -> str:
    if j.fixed:
        return (
            f'    <joint name="{j.name}" type="fixed">\n'
            f"      <parent>{j.parent}</parent>\n      <child>{j.child}</child>\n"
            "    </joint>\n"
        )
    axis = np.asarray(j.axis, float)
    axis = axis / np.linalg.norm(axis)
    return (
        f'    <joint name="{j.name}" type="revolute">\n'
        f"      <parent>{j.parent}</parent>\n      <child>{j.child}</child>\n"
        "      <axis>\n"
        f"        <xyz>{_vec(axis)}</xyz>\n"
        f"        <limit><lower>{_f(j.lower)}</lower><upper>{_f(j.upper)}</upper>"
        f"<effort>{_f(j.effort)}</effort><velocity>{_f(j.velocity)}</velocity></limit>\n"
        f"        <dynamics><damping>{_f(j.damping)}</damping></dynamics>\n"
        "      </axis>\n"
        f"      <drake:rotor_inertia>{_f(j.rotor_inertia)}</drake:rotor_inertia>\n"
        f"      <drake:gear_ratio>{_f(j.gear_ratio)}</drake:gear_ratio>\n"
        "    </joint>\n"
    )


def generate(name: str) -> str:
    """Returns the SDFormat text of model ``name`` (one of ``SPECS``)."""
    spec = SPECS[name]()
    parent_of = {j.child: j for j in spec.joints}
    out = [
        '<?xml version="1.0"?>\n',
        "<!-- Generated by `python -m models.generate_sdf`; do not edit by hand. -->\n",
        f"<!-- {spec.comment}. Sources: see models/generate_sdf.py. -->\n",
        '<sdf version="1.9" xmlns:drake="http://drake.mit.edu">\n',
        f'  <model name="{spec.name}">\n',
    ]
    for link in spec.links:
        if link.name == spec.base:
            pose = f"      <pose>0 0 {_f(spec.base_height)} 0 0 0</pose>\n"
        else:
            j = parent_of[link.name]
            pose = f'      <pose relative_to="{j.parent}">{_vec(j.xyz)} 0 0 0</pose>\n'
        out.append(_link_xml(link, pose))
    for j in spec.joints:
        out.append(_joint_xml(j))
    for fname, attached, xyz in spec.frames:
        out.append(
            f'    <frame name="{fname}" attached_to="{attached}">\n'
            f'      <pose relative_to="{attached}">{_vec(xyz)} 0 0 0</pose>\n'
            "    </frame>\n"
        )
    out.append('    <drake:collision_filter_group name="robot_self">\n')
    for link in spec.links:
        out.append(f"      <drake:member>{link.name}</drake:member>\n")
    out.append("      <drake:ignored_collision_filter_group>robot_self</drake:ignored_collision_filter_group>\n")
    out.append("    </drake:collision_filter_group>\n")
    out.append("  </model>\n</sdf>\n")
    return "".join(out)


def model_path(name: str) -> Path:
    return MODELS_DIR / f"{name}.sdf"


def main() -> None:
    for name in SPECS:
        path = model_path(name)
        path.write_text(generate(name))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
