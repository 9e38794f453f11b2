"""Robot descriptions (models/description.py, issue 14): the built-in models as descriptions,
a public robot the project was not built on (TALOS from example-robot-data), and the errors
a bad description gives, each naming its field."""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydrake.geometry import Box, Sphere
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

import models
from diagrams.station.standing import (
    KD_STABILITY_MARGIN,
    build_standing_diagram,
    default_gains,
    set_initial_state,
    standing_metrics,
)
from models import FSR_ORDER, MODEL_NAMES, add_ground, add_humanoid, set_standing_state
from models.description import RobotDescriptionError, load_robot_description, mesh_vertices

ROOT = Path(__file__).resolve().parents[1]
TALOS = ROOT / "models" / "robots" / "talos.yaml"


def _plant():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    return plant, scene_graph


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_a_builtin_name_and_its_description_file_load_the_same_robot(name):
    handles = {}
    for robot in (name, str(models.description_file(name))):
        plant, scene_graph = _plant()
        h = add_humanoid(plant, robot, scene_graph=scene_graph)
        add_ground(plant)
        plant.Finalize()
        context = plant.CreateDefaultContext()
        set_standing_state(plant, context, h)
        handles[robot] = (plant.GetPositions(context), h.joint_names(), h.ft_sensor_joints.keys(), h.name)
    (q_a, joints_a, ft_a, name_a), (q_b, joints_b, ft_b, name_b) = handles.values()
    np.testing.assert_array_equal(q_a, q_b)
    assert joints_a == joints_b and set(ft_a) == set(ft_b) and name_a == name_b == name


def _write(tmp_path: Path, raw: dict, name: str = "robot.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def _builtin_raw(name: str, tmp_path: Path) -> dict:
    raw = yaml.safe_load(models.description_file(name).read_text())
    raw["model"] = str(models.model_file(name))
    return raw


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda r: r.update(colour="red"), r"unknown field\(s\) \['colour'\]"),
        (lambda r: r.pop("base_body"), "base_body: missing"),
        (lambda r: r.update(model="no_such_robot.urdf"), r"model: file '.*no_such_robot.urdf'.* does not exist"),
        (lambda r: r.update(model="package://no_such_package/robot.urdf"), "package 'no_such_package' .* not found"),
        (lambda r: r["feet"]["left"].update(sensing="magic"), r"feet.left.sensing: must be one of"),
        (lambda r: r["feet"]["left"].pop("force_torque_joint"), "feet.left.force_torque_joint"),
        (lambda r: r["feet"]["right"].update(contact_points=[[0, 0]]), "feet.right: needs exactly one of"),
        (lambda r: r["joint_groups"].update(left_arm=[]), "joint_groups.left_arm: must list the joints"),
        (lambda r: r["joint_groups"]["torso"].append("L_HIP_Y"), "joint 'L_HIP_Y' is also in group 'left_leg'"),
        (lambda r: r["standing_posture"].update(L_KNEE_P="bent"), r"standing_posture.L_KNEE_P: must be a finite"),
        (lambda r: r.update(gains={"legs": [3000.0, -1.0]}), r"gains.legs\[1\] \(kd\): must be >= 0"),
        (lambda r: r.update(joint_limits={"L_KNEE_P": [1.0, 0.0]}), "joint_limits.L_KNEE_P: lower 1.0 must be < upper"),
        (
            lambda r: r["feet"]["left"].update(fsr_range=100.0),
            "feet.left.fsr_range: given, but sensing is 'force_torque'",
        ),
        (
            lambda r: r["feet"]["left"].update(sensing="fsr", fsr_range=-1.0, force_torque_joint=None),
            "feet.left.fsr_range: must be > 0",
        ),
    ],
)
def test_a_bad_description_file_names_the_field(tmp_path, edit, message):
    raw = _builtin_raw("hrp4_like", tmp_path)
    edit(raw)
    with pytest.raises(RobotDescriptionError, match=message):
        load_robot_description(_write(tmp_path, raw))


def test_unreadable_and_invalid_description_files(tmp_path):
    with pytest.raises(RobotDescriptionError, match="cannot read the robot description"):
        load_robot_description(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(RobotDescriptionError, match="not valid YAML"):
        load_robot_description(bad)
    with pytest.raises(ValueError, match="robot description YAML file"):
        add_humanoid(_plant()[0], "robot.urdf")


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda r: r.update(base_body="no_body"), "base_body: the robot has no body named 'no_body'"),
        (lambda r: r.update(base_body="CHEST_P_LINK"), "'CHEST_P_LINK' is not a floating base: joint 'CHEST_P'"),
        (lambda r: r.update(imu_frame="no_imu"), "imu_frame: the robot has no frame or body named 'no_imu'"),
        (lambda r: r["feet"]["left"].update(sole_frame="x"), "feet.left.sole_frame: the robot has no frame"),
        (lambda r: r["joint_groups"]["head"].append("NECK_Z"), "joint_groups.head: the robot has no joint named"),
        (lambda r: r["joint_groups"].update(head=["NECK_Y"]), r"joints in no group: \['NECK_P'\]"),
        (lambda r: r["feet"]["left"].update(force_torque_joint="L_KNEE_P"), "is a revolute joint, not a weld"),
        (lambda r: r["feet"]["left"].update(force_torque_joint="R_FT_SENSOR"), "is not the sole frame's body"),
        (
            lambda r: r["feet"]["left"]["contact_geometries"].update(names=["a", "b", "c", "d"]),
            r"has no collision geometry named \['a', 'b', 'c', 'd'\]",
        ),
    ],
)
def test_a_description_that_does_not_fit_its_robot_names_the_field(tmp_path, edit, message):
    raw = _builtin_raw("hrp4_like", tmp_path)
    edit(raw)
    plant, scene_graph = _plant()
    with pytest.raises(RobotDescriptionError, match=message):
        add_humanoid(plant, _write(tmp_path, raw), scene_graph=scene_graph)


def _binary_stl(path: Path, vertices: np.ndarray) -> None:
    """Writes triangles (T, 3, 3) as a binary STL."""
    with path.open("wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(vertices)))
        for triangle in vertices:
            f.write(struct.pack("<3f", 0, 0, 0) + struct.pack("<9f", *triangle.ravel()) + b"\0\0")


def _arm_urdf(tmp_path: Path, collision: str) -> Path:
    """A four-link 'humanoid' (floating torso, two one-joint legs and arms) as URDF."""
    links, joints = [], []
    for name in ("torso", "l_leg", "r_leg", "l_arm", "r_arm"):
        geometry = collision if name == "l_arm" else '<box size="0.1 0.1 0.1"/>'
        links.append(
            f'<link name="{name}"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
            f'ixz="0" iyz="0"/></inertial><collision><origin xyz="0 0 0" rpy="0 0 1.5707963267948966"/>'
            f"<geometry>{geometry}</geometry></collision></link>"
        )
    for name in ("l_leg", "r_leg", "l_arm", "r_arm"):
        joints.append(
            f'<joint name="{name}_joint" type="revolute"><parent link="torso"/><child link="{name}"/>'
            '<axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
        )
    path = tmp_path / "tiny.urdf"
    path.write_text(f'<robot name="tiny">{"".join(links)}{"".join(joints)}</robot>')
    return path


def test_collision_meshes_drake_cannot_use_become_their_bounding_boxes(tmp_path):
    # A cube of sides 0.2 x 0.4 x 0.6 centred at (1, 2, 3) in the mesh frame, as triangles.
    corners = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.2, 0.2) for z in (-0.3, 0.3)]) + [1, 2, 3]
    triangles = np.array([corners[[0, 1, 2]], corners[[5, 6, 7]], corners[[3, 4, 1]]])
    _binary_stl(tmp_path / "arm.stl", triangles)
    np.testing.assert_allclose(mesh_vertices(tmp_path / "arm.stl"), triangles.reshape(-1, 3), atol=1e-6)
    urdf = _arm_urdf(tmp_path, '<mesh filename="arm.stl" scale="1 1 2"/>')
    raw = {
        "name": "tiny",
        "model": urdf.name,
        "base_body": "torso",
        "imu_frame": "torso",
        "feet": {
            side: {
                "sole_frame": f"{side[0]}_leg",
                "contact_points": [[0.05, 0.02], [0.05, -0.02], [-0.05, 0.02], [-0.05, -0.02]],
            }
            for side in ("left", "right")
        },
        "joint_groups": {
            "left_leg": ["l_leg_joint"],
            "right_leg": ["r_leg_joint"],
            "left_arm": ["l_arm_joint"],
            "right_arm": ["r_arm_joint"],
        },
        "standing_posture": {},
    }
    plant, scene_graph = _plant()
    with pytest.raises(RobotDescriptionError, match="collision_meshes: bounding_box"):
        add_humanoid(plant, _write(tmp_path, raw), scene_graph=scene_graph)

    raw["collision_meshes"] = "bounding_box"
    plant, scene_graph = _plant()
    h = add_humanoid(plant, _write(tmp_path, raw), scene_graph=scene_graph)
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    (arm,) = h.collision_geometries["l_arm"]
    shape = inspector.GetShape(arm)
    assert isinstance(shape, Box)
    np.testing.assert_allclose([shape.width(), shape.depth(), shape.height()], [0.2, 0.4, 1.2], atol=1e-6)
    # The box's centre: the scaled mesh centre (1, 2, 6), turned 90 deg about z by the origin.
    np.testing.assert_allclose(inspector.GetPoseInFrame(arm).translation(), [-2.0, 1.0, 6.0], atol=1e-6)
    # The added foot spheres sit on the sole plane at the contact points, in FSR_ORDER.
    for side in ("left", "right"):
        spheres = h.fsr_geometries[side]
        assert [inspector.GetName(g).split("::")[-1] for g in spheres] == [f"{side[0]}_contact_{n}" for n in FSR_ORDER]
        for g, (x, y) in zip(spheres, h.fsr_positions[side]):
            assert isinstance(inspector.GetShape(g), Sphere)
            np.testing.assert_allclose(inspector.GetPoseInFrame(g).translation(), [x, y, 0.005])
    # Actuators were added for the URDF's joints (it has no transmissions).
    assert plant.num_actuators() == 4


# ---------------------------------------------------------------------------------------
# TALOS (example-robot-data): a public humanoid the project was not built on.
# ---------------------------------------------------------------------------------------


def test_talos_loads_from_its_description_with_the_urdf_mass_and_joints():
    description = load_robot_description(TALOS)
    root = ET.parse(description.model_file).getroot()
    urdf_mass = sum(
        float(link.find("inertial/mass").get("value"))
        for link in root.iter("link")
        if link.find("inertial") is not None
    )
    movable = {j.get("name") for j in root.iter("joint") if j.get("type") in ("revolute", "continuous", "prismatic")}
    plant, scene_graph = _plant()
    h = add_humanoid(plant, TALOS, scene_graph=scene_graph)
    add_ground(plant)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    assert plant.CalcTotalMass(context, [h.model_instance]) == pytest.approx(urdf_mass)  # spheres: no mass
    assert set(h.joint_names()) == movable and len(movable) == 32
    assert plant.num_velocities() == 6 + 32 and plant.num_actuators() == 32
    assert set(h.ft_sensor_joints) == {"left", "right"} and h.foot_sensing == {
        "left": "force_torque",
        "right": "force_torque",
    }
    # No collision mesh is left (they became boxes), the feet touch the ground at their spheres only.
    inspector = scene_graph.model_inspector()
    shapes = [inspector.GetShape(g) for ids in h.collision_geometries.values() for g in ids]
    assert shapes and all(type(s).__name__ in ("Box", "Sphere", "Cylinder", "Capsule") for s in shapes)
    assert h.collision_geometries["leg_left_6_link"] == ()


def test_talos_stands_on_its_scaled_gains():
    diagram, handles = build_standing_diagram(str(TALOS))
    plant, humanoid = handles.plant, handles.humanoid
    kp, kd = default_gains(plant, humanoid)
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, humanoid)
    inertia = np.diag(plant.CalcMassMatrix(context))[6:]
    assert np.all(kd * plant.time_step() <= KD_STABILITY_MARGIN * inertia * (1 + 1e-12))
    assert np.all(kp > 0)
    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    set_initial_state(diagram, root, handles)
    simulator.AdvanceTo(1.0)
    metrics = standing_metrics(handles, root, settle_time=0.5)
    assert not metrics.fell
    assert metrics.base_drift_m < 0.01
    weight = plant.CalcTotalMass(plant.GetMyContextFromRoot(root)) * 9.81
    total = sum(forces.sum() for forces in metrics.sphere_forces_N.values())
    assert total == pytest.approx(weight, rel=0.02)


ZERO_INERTIA = "<inertia><ixx>0</ixx><ixy>0</ixy><ixz>0</ixz><iyy>0</iyy><iyz>0</iyz><izz>0</izz></inertia>"


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("<mass>0.05</mass>", "<mass>nan</mass>", r"link 'L_HAND_J1_LINK' has a non-physical inertia .*mass > 0"),
        ("<mass>0.05</mass>", "<mass>-2</mass>", r"link 'L_HAND_J1_LINK' has a non-physical inertia .*mass > 0"),
        ("<mass>0.05</mass>", "<mass>0</mass>", r"link 'L_HAND_J1_LINK' has a non-physical inertia .*mass > 0"),
        ("<ixx>1.20833333e-05</ixx>", "<ixx>nan</ixx>", r"link 'L_HAND_J1_LINK' has a non-physical .*Non-finite"),
        ("<ixx>1.20833333e-05</ixx>", "<ixx>1.0</ixx>", r"link 'L_HAND_J1_LINK' has a non-physical inertia"),
        (
            "<mass>0.05</mass>",
            "<mass>0</mass>" + ZERO_INERTIA,
            r"link 'L_HAND_J1_LINK' is on the moving joint of type revolute but it and the links beyond it have no",
        ),
    ],
)
def test_a_model_with_a_non_physical_link_inertia_is_refused_naming_the_link(tmp_path, old, new, message):
    """A link whose mass or inertia is not physical in the model file of a description is
    refused when the robot is loaded (Drake's parser would replace it by a made-up inertia
    and only warn), and so is a massless link at the end of a moving joint."""
    text = models.model_file("hrp4_like").read_text()
    link = text.index('<link name="L_HAND_J1_LINK">')
    start = text.index(old, link)
    edited = text[:start] + new + text[start + len(old) :]
    if "<inertia>" in new:  # the zero inertia replaces the link's own
        first = edited.index("<inertia>", start + len(new))
        edited = edited[:first] + edited[edited.index("</inertia>", first) + len("</inertia>") :]
    model = tmp_path / "robot.sdf"
    model.write_text(edited)
    raw = _builtin_raw("hrp4_like", tmp_path)
    raw["model"] = str(model)
    plant, scene_graph = _plant()
    with pytest.raises(RobotDescriptionError, match=message):
        add_humanoid(plant, _write(tmp_path, raw), scene_graph=scene_graph)


FEET = ("left", "right")


def test_a_foot_reuses_its_bodys_own_contact_geometries_and_its_sole_sits_at_their_lowest_point(tmp_path):
    """A vendor URDF's feet carry their own contact spheres and no sole frame (issue 36):
    ``contact_geometries: {body: ...}`` without names takes the body's four collision
    geometries, in FSR_ORDER by where they are, with the FSR positions where they are; and
    ``sole_offset: lowest_point`` puts the sole at their lowest point. On hrp4_like (whose
    description names its four spheres and gives a sole frame and the FSR positions) the
    same feet result from the body alone: the same geometries in the same order, the sole
    frame at the same pose, the FSRs at the same (x, y)."""

    def load(raw):
        plant, scene_graph = _plant()
        handles = add_humanoid(plant, str(_write(tmp_path, raw)), scene_graph=scene_graph)
        plant.Finalize()
        context = plant.CreateDefaultContext()
        set_standing_state(plant, context, handles)
        names = {s: [scene_graph.model_inspector().GetName(g) for g in handles.fsr_geometries[s]] for s in FEET}
        return plant, context, handles, names

    raw = _builtin_raw("hrp4_like", tmp_path)
    plant, context, named, named_geometries = load(raw)
    for side in ("left", "right"):
        foot = raw["feet"][side]
        foot["sole_frame"] = foot["contact_geometries"]["body"]  # the body, not the sole frame
        foot["sole_offset"] = "lowest_point"
        foot["contact_geometries"].pop("names")
        foot.pop("fsr_positions")
    plant2, context2, by_body, geometries = load(raw)
    assert geometries == named_geometries
    for side in ("left", "right"):
        assert by_body.sole_frames[side].name() == f"{side}_sole_at_lowest_point"
        X, X2 = (h.sole_frames[side].CalcPoseInWorld(c) for h, c in ((named, context), (by_body, context2)))
        np.testing.assert_allclose(X2.GetAsMatrix4(), X.GetAsMatrix4(), atol=1e-12)
        np.testing.assert_allclose(by_body.fsr_positions[side], named.fsr_positions[side], atol=1e-12)
    np.testing.assert_allclose(plant2.GetPositions(context2), plant.GetPositions(context), atol=1e-12)

    raw["feet"]["left"]["contact_geometries"]["body"] = "L_KNEE_P_LINK"
    with pytest.raises(RobotDescriptionError, match=r"feet.left.contact_geometries: body 'L_KNEE_P_LINK' has \d+ "):
        load(raw)
    raw = _builtin_raw("hrp4_like", tmp_path)
    raw["feet"]["left"].update(sole_offset="lowest_point", contact_points=[[0, 0]] * 4)
    raw["feet"]["left"].pop("contact_geometries")
    with pytest.raises(RobotDescriptionError, match="sole_offset: lowest_point needs contact_geometries"):
        load_robot_description(_write(tmp_path, raw))
