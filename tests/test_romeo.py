"""Aldebaran's Romeo (models/robots/romeo.yaml, from example-robot-data's romeo_description), a
third public humanoid with 6-axis foot F/T sensors: its description reads, names the robot's
joints, sole frames and F/T welds, and the robot stands.

romeo.yaml loads romeo_small.urdf (romeo.urdf without its fingers, whose links are massless),
whose RShoulderYawLink and RElbowYawLink inertias break the triangle inequality (romeo.urdf
has them right): the description's ``link_inertias`` give romeo.urdf's."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydrake.geometry import Box, Sphere
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from diagrams.station.standing import default_gains
from models import add_ground, add_humanoid, set_standing_state
from models.description import RobotDescriptionError, load_robot_description, mesh_vertices

ROOT = Path(__file__).resolve().parents[1]
ROMEO = ROOT / "models" / "robots" / "romeo.yaml"
LEG_JOINTS = ("HipYaw", "HipRoll", "HipPitch", "KneePitch", "AnklePitch", "AnkleRoll")


def test_romeo_description_reads_with_its_joints_soles_and_force_torque_welds():
    d = load_robot_description(ROMEO)
    assert d.name == "romeo" and d.model_file.name == "romeo_small.urdf" and d.model_file.is_file()
    assert d.collision_meshes == "bounding_box"
    assert len(d.joint_names()) == 31
    for side, prefix in (("left", "L"), ("right", "R")):
        assert d.joint_groups[f"{side}_leg"] == tuple(prefix + j for j in LEG_JOINTS)
        assert len(d.joint_groups[f"{side}_arm"]) == 7 and d.joint_groups[f"{side}_hand"] == ()
        foot = d.feet[side]
        assert foot.sole_frame == f"{side[0]}_sole" and foot.sensing == "force_torque"
        assert foot.force_torque_joint == f"{side[0]}_sole_joint"
    # Half-sitting: knees bent, the same on both legs.
    assert d.standing_posture["LKneePitch"] == d.standing_posture["RKneePitch"] > 0.3


def test_a_collada_mesh_is_read_with_its_scene_scale(tmp_path):
    # LAnkleRoll.dae stores centimetres under a node scaled by 0.01: the foot is 0.24 m long.
    folder = load_robot_description(ROMEO).model_file.parents[1] / "meshes" / "V1" / "collision"
    vertices = mesh_vertices(folder / "LAnkleRoll.dae")
    np.testing.assert_allclose(vertices.min(axis=0), [-0.0889, -0.0559, -0.0675], atol=1e-3)
    np.testing.assert_allclose(vertices.max(axis=0), [0.1554, 0.0706, 0.0432], atol=1e-3)
    (tmp_path / "broken.dae").write_text("not COLLADA")
    with pytest.raises(RobotDescriptionError, match="cannot read the mesh"):
        mesh_vertices(tmp_path / "broken.dae")


def test_romeo_loads_with_a_floating_base_foot_force_torque_welds_and_box_collisions(tmp_path):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    h = add_humanoid(plant, ROMEO, scene_graph=scene_graph)
    add_ground(plant)
    plant.Finalize()
    assert plant.num_positions(h.model_instance) == 7 + 31 and plant.num_actuators(h.model_instance) == 31
    assert h.base_body.name() == "base_link" and h.base_body.is_floating_base_body()
    assert h.imu_frame.body().index() == h.base_body.index()
    assert {s: j.name() for s, j in h.ft_sensor_joints.items()} == {"left": "l_sole_joint", "right": "r_sole_joint"}
    assert all(j.type_name() == "weld" for j in h.ft_sensor_joints.values())
    mass = sum(plant.get_body(i).default_mass() for i in plant.GetBodyIndices(h.model_instance))
    assert mass == pytest.approx(40.53, abs=0.01)
    # The COLLADA collision meshes became boxes; the feet touch the ground at their spheres only.
    inspector = scene_graph.model_inspector()
    shapes = {b: [type(inspector.GetShape(g)) for g in ids] for b, ids in h.collision_geometries.items() if ids}
    assert all(s == Box for b, kinds in shapes.items() if b not in ("l_sole", "r_sole") for s in kinds)
    assert shapes["l_sole"] == shapes["r_sole"] == [Sphere] * 4 and "l_ankle" not in shapes
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, h)
    for side in ("left", "right"):
        X_WS = h.sole_frames[side].CalcPoseInWorld(context)
        assert abs(X_WS.translation()[2]) < 1e-9 and X_WS.rotation().matrix()[2, 2] == pytest.approx(1.0)
    assert plant.CalcCenterOfMassPositionInWorld(context, [h.model_instance])[2] == pytest.approx(0.66, abs=0.01)
    # The rotor inertias keep the explicit PD's damping cap off the light ankles and wrists: every
    # leg joint gets the legs' scaled gain.
    kp, _ = default_gains(plant, h)
    legs = [plant.GetJointByName(j, h.model_instance).velocity_start() - 6 for j in h.joint_groups["legs"]]
    np.testing.assert_allclose(kp[legs], kp[legs[0]])


def test_link_inertias_replace_the_urdf_wrong_ones(tmp_path):
    """romeo_small.urdf's RShoulderYawLink inertia breaks the triangle inequality: without the
    description's link_inertias the loader refuses it, naming the link; with them the link
    carries romeo.urdf's inertia."""
    raw = yaml.safe_load(ROMEO.read_text())
    assert sorted(raw["link_inertias"]) == ["RElbowYawLink", "RShoulderYawLink"]
    folder = load_robot_description(ROMEO).model_file.parent
    raw["model"] = str(folder / "romeo_small.urdf")
    without = dict(raw)
    del without["link_inertias"]
    (tmp_path / "without.yaml").write_text(yaml.safe_dump(without, sort_keys=False))
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    with pytest.raises(RobotDescriptionError, match="RShoulderYawLink|RElbowYawLink"):
        add_humanoid(plant, tmp_path / "without.yaml")
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    h = add_humanoid(plant, ROMEO)
    plant.Finalize()
    full = {link.get("name"): link for link in ET.parse(folder / "romeo.urdf").getroot().iter("link")}
    for name in ("RShoulderYawLink", "RElbowYawLink"):
        inertial = full[name].find("inertial")
        mass = float(inertial.find("mass").get("value"))
        com = np.array(inertial.find("origin").get("xyz").split(), dtype=float)
        M = plant.GetBodyByName(name, h.model_instance).default_spatial_inertia()
        assert M.get_mass() == pytest.approx(mass) and np.allclose(M.get_com(), com)
        I = M.CalcRotationalInertia().ShiftToCenterOfMass(mass, com).CopyToFullMatrix3()
        attributes = inertial.find("inertia").attrib
        assert I[0, 0] == pytest.approx(float(attributes["ixx"])) and I[0, 1] == pytest.approx(float(attributes["ixy"]))
    # A bad entry is refused naming the field.
    raw["link_inertias"]["RElbowYawLink"]["inertia"] = [1.0, 1.0, 5.0, 0.0, 0.0, 0.0]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    with pytest.raises(RobotDescriptionError, match="link_inertias.RElbowYawLink"):
        add_humanoid(plant, tmp_path / "bad.yaml")
    raw["link_inertias"]["RElbowYawLink"] = {"mass": 1.0, "com": [0, 0]}
    (tmp_path / "short.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))
    with pytest.raises(RobotDescriptionError, match="link_inertias.RElbowYawLink"):
        load_robot_description(tmp_path / "short.yaml")


def test_romeo_stands(tmp_path):
    from apps import standing

    assert standing.main(["--robot", str(ROMEO), "--duration", "2", "--no-meshcat", "--out", str(tmp_path)]) == 0
    row = json.loads((tmp_path / "standing" / "romeo.json").read_text())
    assert row["fell"] is False and row["feet_flat"] is True
    assert np.isfinite(row["base_drift_cm"]) and row["base_drift_cm"] < 1.0


def _romeo_variant(tmp_path: Path, edit) -> Path:
    """romeo.yaml with ``edit`` applied, written beside a copy (the model's package:// URI
    resolves the same)."""
    raw = yaml.safe_load(ROMEO.read_text())
    edit(raw)
    path = tmp_path / "romeo_variant.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def _standing_plant(robot):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    handles = add_humanoid(plant, str(robot), scene_graph=scene_graph)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    return plant, context, handles


def test_a_sole_offset_from_the_ankle_places_the_sole_where_the_urdf_frame_is(tmp_path):
    """A URDF without a sole frame (issue 36): ``sole_offset`` places the sole in the ankle
    link's axes. Romeo's own l_sole/r_sole frames are 0.0684 m below the ankle links' origins
    (romeo.urdf's fixed sole joints); the offset frame lands on them and the robot stands the
    same (the soles are its contact frames)."""
    plant, context, handles = _standing_plant(ROMEO)
    expected = {s: handles.sole_frames[s].CalcPoseInWorld(context) for s in ("left", "right")}
    offsets = {}
    for side in ("left", "right"):
        ankle = plant.GetBodyByName(f"{side[0]}_ankle")
        X_AS = handles.sole_frames[side].CalcPose(context, ankle.body_frame())
        assert np.allclose(X_AS.rotation().matrix(), np.eye(3))
        offsets[side] = X_AS.translation().tolist()

    def edit(raw):
        for side in ("left", "right"):
            foot = raw["feet"][side]
            foot.update(sole_frame=f"{side[0]}_ankle", sole_offset=offsets[side], sensing="none")
            foot.pop("force_torque_joint")

    plant2, context2, handles2 = _standing_plant(_romeo_variant(tmp_path, edit))
    for side in ("left", "right"):
        frame = handles2.sole_frames[side]
        assert frame.name() == f"{side}_sole_from_{side[0]}_ankle"
        X = frame.CalcPoseInWorld(context2)
        np.testing.assert_allclose(X.translation(), expected[side].translation(), atol=1e-12)
        np.testing.assert_allclose(X.rotation().matrix(), expected[side].rotation().matrix(), atol=1e-12)
    np.testing.assert_allclose(plant2.GetPositions(context2), plant.GetPositions(context), atol=1e-12)
    bad = _romeo_variant(tmp_path, lambda raw: raw["feet"]["left"].update(sole_offset=[0.0, 0.1]))
    with pytest.raises(RobotDescriptionError, match=r"feet.left.sole_offset: must be \[x, y, z\]"):
        load_robot_description(bad)


def test_rotor_inertia_per_joint_wins_over_its_group(tmp_path):
    """``actuators.rotor_inertia`` takes joint names as well as groups (hip, knee and ankle
    motors differ): the knee's own entry, its group's for the other leg joints; a key that
    is neither a joint nor a group is refused naming it."""

    def edit(raw):
        raw["actuators"]["rotor_inertia"]["LKneePitch"] = 0.25

    plant, _, _ = _standing_plant(_romeo_variant(tmp_path, edit))
    rotor = {
        plant.get_joint_actuator(a).joint().name(): plant.get_joint_actuator(a).default_rotor_inertia()
        for a in plant.GetJointActuatorIndices()
    }
    assert rotor["LKneePitch"] == 0.25 and rotor["RKneePitch"] == 0.1 and rotor["LHipPitch"] == 0.1
    assert rotor["TrunkYaw"] == 0.1 and rotor["NeckYaw"] == 0.01
    bad = _romeo_variant(tmp_path, lambda raw: raw["actuators"]["rotor_inertia"].update(Knee=0.2))
    with pytest.raises(RobotDescriptionError, match=r"actuators.rotor_inertia.Knee: .*nor is it a gain group"):
        _standing_plant(bad)


def test_standing_explains_a_foot_box_in_the_ground_and_gains_the_stability_cap_lowered(tmp_path, capsys):
    """``apps.standing`` explains a robot that cannot stand (issue 36). A new user's first
    try at a URDF without sole frames: the soles put at the ankle links' origins (6.8 cm
    above Romeo's real soles) and the ankles' collision boxes kept: the robot starts with
    the boxes in the ground, and the run says which touched it first, at 0 s, and how deep.
    Without the description's rotor inertia the explicit PD's stability cap lowers the light
    ankle-roll gains, and the metrics name those joints."""
    from pydrake.systems.analysis import Simulator

    from diagrams.station.standing import StandingScenario, build_standing_diagram, gains_and_caps, standing_run_metrics
    from diagrams.station.standing import set_initial_state as set_standing

    def keep_boxes(raw):
        for side in ("left", "right"):
            foot = raw["feet"][side]
            foot.update(sole_frame=f"{side[0]}_ankle", sensing="none")
            for key in ("remove_collisions", "force_torque_joint"):
                foot.pop(key)

    robot = _romeo_variant(tmp_path, keep_boxes)
    diagram, handles = build_standing_diagram(str(robot))
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_standing(diagram, context, handles)
    simulator.Initialize()
    simulator.AdvanceTo(0.05)
    row = standing_run_metrics(StandingScenario(duration=0.05, settle_time=0.0), handles, context, 1.0)
    first = row["first_unexpected_contact"]
    assert first is not None and first.startswith(("l_ankle/", "r_ankle/")) and " at 0.000 s " in first
    depth_mm = float(first.split("(")[1].split(" mm")[0])
    assert 50.0 < depth_mm < 80.0  # the box's bottom, at the real sole, 68 mm under the ankle
    assert row["stability_capped_gains"] == {}

    from apps import standing as stand

    args = ["--robot", str(robot), "--duration", "0.3", "--no-meshcat", "--out", str(tmp_path)]
    status = stand.main(args)
    printed = capsys.readouterr().out
    assert status in (0, 1)
    assert "romeo: l_ankle/" in printed or "romeo: r_ankle/" in printed
    assert "touched the ground first, at 0.000 s" in printed

    plant, _, romeo = _standing_plant(ROMEO)
    assert gains_and_caps(plant, romeo)[2] == {}
    plant, _, bare = _standing_plant(_romeo_variant(tmp_path, lambda raw: raw.pop("actuators")))
    capped = gains_and_caps(plant, bare)[2]
    assert {"LAnkleRoll", "RAnkleRoll"} <= set(capped)
    assert all(cap < scaled for scaled, cap in capped.values())
