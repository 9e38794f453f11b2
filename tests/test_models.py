"""Tests of the humanoid models and their loader (models/)."""

import dataclasses
import shutil

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JointIndex
from pydrake.systems.framework import DiagramBuilder

import models
from models import FSR_ORDER, MODEL_NAMES, add_ground, add_humanoid, generate_sdf, set_standing_state

GROUP_KEYS = {
    "left_leg",
    "right_leg",
    "legs",
    "torso",
    "head",
    "left_arm",
    "right_arm",
    "arms",
    "left_hand",
    "right_hand",
    "hands",
    "knees",
    "ankle_pitch",
}
EXPECTED = {
    # revolute joints, welds, mass kg, head-top height straight / nominal posture (m)
    "hrp4_like": dict(revolute=34, welds=2, mass=39.0, height=1.51),
    "nao_like": dict(revolute=26, welds=0, mass=5.19, height=0.5732),
}
NAO_FSR = {
    "left": [[0.07025, 0.0299], [0.07025, -0.0231], [-0.03025, 0.0299], [-0.02965, -0.0191]],
    "right": [[0.07025, 0.0231], [0.07025, -0.0299], [-0.03025, 0.0191], [-0.02965, -0.0299]],
}


def _build(name, with_scene_graph=True):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap", contact_model="point"), builder
    )
    handles = add_humanoid(plant, name, scene_graph=scene_graph if with_scene_graph else None)
    add_ground(plant)
    plant.Finalize()
    return plant, scene_graph, handles


@pytest.fixture(scope="module", params=MODEL_NAMES)
def loaded(request):
    return _build(request.param)


def _model_joints(plant, handles):
    return [plant.get_joint(JointIndex(int(i))) for i in plant.GetJointIndices(handles.model_instance)]


def test_generator_output_equals_committed_files():
    for name in MODEL_NAMES:
        committed = models.model_file(name).read_text()
        assert committed == generate_sdf.generate(name), f"{name}.sdf is stale: run `python -m models.generate_sdf`"
    assert (models.MODELS_DIR / "package.xml").read_text().count("<name>humanoid_contact_observers_models</name>") == 1


def test_joint_counts(loaded):
    plant, _, h = loaded
    joints = _model_joints(plant, h)
    revolute = [j for j in joints if j.type_name() == "revolute"]
    welds = [j for j in joints if j.type_name() == "weld"]
    exp = EXPECTED[h.name]
    assert len(revolute) == exp["revolute"]
    assert len(welds) == exp["welds"]
    assert plant.num_actuated_dofs(h.model_instance) == exp["revolute"]
    assert plant.num_velocities() == exp["revolute"] + 6  # floating base, not welded
    assert h.base_body.is_floating_base_body()
    actuated = {plant.get_joint_actuator(i).joint().name() for i in plant.GetJointActuatorIndices(h.model_instance)}
    assert actuated == {j.name() for j in revolute}
    for i in plant.GetJointActuatorIndices(h.model_instance):
        assert 0 < plant.get_joint_actuator(i).effort_limit() < np.inf


def test_total_mass(loaded):
    plant, _, h = loaded
    mass = plant.CalcTotalMass(plant.CreateDefaultContext(), [h.model_instance])
    tol = 1.0 if h.name == "hrp4_like" else 0.01
    assert abs(mass - EXPECTED[h.name]["mass"]) < tol
    for i in plant.GetBodyIndices(h.model_instance):
        assert plant.get_body(i).default_mass() > 0


def test_standing_heights(loaded):
    plant, _, h = loaded
    ctx = plant.CreateDefaultContext()
    head_top = plant.GetFrameByName("head_top", h.model_instance)
    # Straight legs: the documented height.
    set_standing_state(plant, ctx, h)
    for j in h.joint_groups["legs"]:
        plant.GetJointByName(j, h.model_instance).set_angle(ctx, 0.0)
    plant.SetFreeBodyPose(ctx, h.base_body, plant.GetDefaultFloatingBaseBodyPose(h.base_body))
    base = plant.GetFreeBodyPose(ctx, h.base_body)
    sole_z = h.sole_frames["left"].CalcPoseInWorld(ctx).translation()[2]
    straight = head_top.CalcPoseInWorld(ctx).translation()[2] - sole_z
    assert abs(straight - EXPECTED[h.name]["height"]) < 0.01
    # Nominal posture: knees bent, a few cm lower, soles flat on z = 0.
    set_standing_state(plant, ctx, h)
    nominal = head_top.CalcPoseInWorld(ctx).translation()[2]
    assert 0.0 < EXPECTED[h.name]["height"] - nominal < 0.04
    for side in ("left", "right"):
        X = h.sole_frames[side].CalcPoseInWorld(ctx)
        assert abs(X.translation()[2]) < 1e-12
        np.testing.assert_allclose(X.rotation().matrix(), np.eye(3), atol=1e-12)
    assert plant.GetFreeBodyPose(ctx, h.base_body).translation()[2] < base.translation()[2]
    np.testing.assert_array_equal(plant.GetVelocities(ctx), 0.0)


def test_nao_like_recorded_stands_with_its_com_at_the_recorded_height():
    """Hawley et al.'s recordings (``data/hawley2019-nao``, CoM_Pos.mat: the Nao's CoM in its
    support-foot frame while it stands) put the CoM 0.314 m above the sole. ``nao_like``
    (documented link masses) stands with it 4.6 cm lower; its variant ``nao_like_recorded``,
    with mass moved from the legs to the torso, within 2 mm of the recordings. Both weigh the
    paper's 5.19 kg and have the same kinematics (issue 31)."""
    from systems.observer.nao_dataset import RECORDINGS, load_recording, published_dataset_dir

    recorded = np.mean([load_recording(published_dataset_dir() / name)["Xc_Yc_Zc"][:, 2].mean() for name in RECORDINGS])
    heights, masses, soles = {}, {}, {}
    for robot in ("nao_like", models.MODELS_DIR / "nao_like_recorded.yaml"):
        builder = DiagramBuilder()
        plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
        h = add_humanoid(plant, robot)
        plant.Finalize()
        ctx = plant.CreateDefaultContext()
        set_standing_state(plant, ctx, h)
        sole = h.sole_frames["right"].CalcPoseInWorld(ctx).translation()
        heights[h.name] = plant.CalcCenterOfMassPositionInWorld(ctx, [h.model_instance])[2] - sole[2]
        masses[h.name] = plant.CalcTotalMass(ctx, [h.model_instance])
        soles[h.name] = sole
    assert abs(heights["nao_like_recorded"] - recorded) < 2e-3, (heights, recorded)
    assert 0.04 < recorded - heights["nao_like"] < 0.05
    assert masses["nao_like"] == pytest.approx(5.19, abs=1e-9) and masses["nao_like_recorded"] == pytest.approx(5.19)
    np.testing.assert_allclose(soles["nao_like"], soles["nao_like_recorded"], atol=1e-12)
    # Its description is nao_like's but for the name and the model file (feet, FSRs, groups,
    # posture, gains): a field changed in one and not the other fails here.
    nao, recorded = (models.robot_description(r) for r in ("nao_like", models.MODELS_DIR / "nao_like_recorded.yaml"))
    ignored = {"name", "source", "model_file"}
    for field in dataclasses.fields(nao):
        if field.name not in ignored:
            assert repr(getattr(nao, field.name)) == repr(getattr(recorded, field.name)), field.name


def test_every_body_has_collision_and_visual(loaded):
    plant, _, h = loaded
    names = {plant.get_body(i).name() for i in plant.GetBodyIndices(h.model_instance)}
    assert set(h.collision_geometries) == names
    for i in plant.GetBodyIndices(h.model_instance):
        body = plant.get_body(i)
        assert len(plant.GetCollisionGeometriesForBody(body)) >= 1, body.name()
        assert len(plant.GetVisualGeometriesForBody(body)) >= 1, body.name()
        assert h.collision_geometries[body.name()] == tuple(plant.GetCollisionGeometriesForBody(body))


def test_fsr_spheres(loaded):
    plant, scene_graph, h = loaded
    inspector = scene_graph.model_inspector()
    prefix = "l_fsr_" if h.name == "nao_like" else "l_contact_"
    if h.name == "nao_like":
        for side in ("left", "right"):
            np.testing.assert_array_equal(h.fsr_positions[side], NAO_FSR[side])
    for side in ("left", "right"):
        ids = h.fsr_geometries[side]
        assert len(ids) == 4
        sole = h.sole_frames[side]
        X_BS = sole.GetFixedPoseInBodyFrame()
        box_bottom = None
        for gid in plant.GetCollisionGeometriesForBody(sole.body()):
            if inspector.GetShape(gid).__class__.__name__ == "Box":
                X_BG = inspector.GetPoseInFrame(gid)
                p_SG = X_BS.inverse().multiply(X_BG.translation())
                box_bottom = p_SG[2] - inspector.GetShape(gid).height() / 2
        assert box_bottom == pytest.approx(0.002, abs=1e-9)
        for k, gid in enumerate(ids):
            name = inspector.GetName(gid).split("::")[-1]
            assert name == f"{side[0]}{prefix[1:]}{FSR_ORDER[k]}"
            shape = inspector.GetShape(gid)
            assert shape.radius() == pytest.approx(0.005)
            assert inspector.GetFrameId(gid) == plant.GetBodyFrameIdOrThrow(sole.body().index())
            p_SG = X_BS.inverse().multiply(inspector.GetPoseInFrame(gid).translation())
            np.testing.assert_allclose(p_SG[:2], h.fsr_positions[side][k], atol=1e-12)
            assert p_SG[2] - shape.radius() == pytest.approx(0.0, abs=1e-12)  # bottom on sole
            props = inspector.GetProximityProperties(gid)
            k_contact = props.GetProperty("material", "point_contact_stiffness")
            assert 1e5 <= k_contact <= 1e6
            mu = props.GetProperty("material", "coulomb_friction")
            assert mu.static_friction() == pytest.approx(1.0)


def test_fsr_registration_order_without_scene_graph():
    """Without a SceneGraph the loader relies on SDF registration order: check it."""
    for name in MODEL_NAMES:
        plant, scene_graph, h = _build(name, with_scene_graph=False)
        inspector = scene_graph.model_inspector()
        for side in ("left", "right"):
            names = [inspector.GetName(g).split("::")[-1] for g in h.fsr_geometries[side]]
            assert names == [_name_of(h, side, k) for k in range(4)]


def _name_of(h, side, k):
    prefix = "fsr" if h.name == "nao_like" else "contact"
    return f"{side[0]}_{prefix}_{FSR_ORDER[k]}"


def test_self_collisions_filtered(loaded):
    plant, scene_graph, h = loaded
    inspector = scene_graph.model_inspector()
    ids = [g for gs in h.collision_geometries.values() for g in gs]
    ground = [g for g in inspector.GetAllGeometryIds() if inspector.GetName(g) == "ground"]
    assert len(ground) == 1
    for a in ids[::3]:
        for b in ids[1::3]:
            if a != b:
                assert inspector.CollisionFiltered(a, b)
        assert not inspector.CollisionFiltered(a, ground[0])


def test_self_collisions_filtered_by_model_file_alone():
    plant, scene_graph, h = _build("nao_like", with_scene_graph=False)
    inspector = scene_graph.model_inspector()
    hand = h.collision_geometries["l_wrist"][0]
    thigh = h.collision_geometries["LThigh"][0]
    assert inspector.CollisionFiltered(hand, thigh)


def test_handles_complete(loaded):
    plant, _, h = loaded
    mi = h.model_instance
    assert set(h.joint_groups) == GROUP_KEYS
    g = h.joint_groups
    assert g["legs"] == g["left_leg"] + g["right_leg"]
    assert g["arms"] == g["left_arm"] + g["right_arm"]
    assert all("KNEE" in j.upper() for j in g["knees"]) and len(g["knees"]) == 2
    assert all("ANKLE" in j.upper() and "P" in j.upper() for j in g["ankle_pitch"]) and len(g["ankle_pitch"]) == 2
    assert g["hands"] == g["left_hand"] + g["right_hand"]
    assert len(g["left_leg"]) == len(g["right_leg"]) == 6
    every = g["legs"] + g["torso"] + g["head"] + g["arms"] + g["hands"]
    assert len(every) == len(set(every)) == EXPECTED[h.name]["revolute"]
    assert set(every) == {j.name() for j in _model_joints(plant, h) if j.num_velocities() == 1}
    if h.name == "hrp4_like":
        assert g["right_leg"] == ("R_HIP_Y", "R_HIP_R", "R_HIP_P", "R_KNEE_P", "R_ANKLE_P", "R_ANKLE_R")
        assert len(g["left_arm"]) == 7 and len(g["left_hand"]) == 2
        assert g["torso"] == ("CHEST_P", "CHEST_Y") and g["head"] == ("NECK_Y", "NECK_P")
        assert h.base_body.name() == "waist"
        for side, jname in (("left", "L_FT_SENSOR"), ("right", "R_FT_SENSOR")):
            joint = h.ft_sensor_joints[side]
            assert joint.name() == jname and joint.type_name() == "weld"
            assert h.ft_sensor_frames[side].index() == joint.frame_on_child().index()
            assert joint.child_body().index() == h.sole_frames[side].body().index()
    else:
        assert h.base_body.name() == "torso"
        assert h.ft_sensor_joints == {} and h.ft_sensor_frames == {}
        axis_l = plant.GetJointByName("LHipYawPitch", mi).revolute_axis()
        np.testing.assert_allclose(axis_l, [0, np.sqrt(0.5), -np.sqrt(0.5)], atol=1e-12)
    assert h.imu_frame.body().index() == h.base_body.index()
    assert set(h.sole_frames) == set(h.shoulder_bodies) == set(h.fsr_geometries) == {"left", "right"}
    for side in ("left", "right"):
        assert h.fsr_positions[side].shape == (4, 2)
    assert set(h.nominal_posture) == set(every)
    for jname, angle in h.nominal_posture.items():
        joint = plant.GetJointByName(jname, mi)
        assert joint.position_lower_limits()[0] <= angle <= joint.position_upper_limits()[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        h.name = "other"


def test_unknown_model_name():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    with pytest.raises(ValueError, match="hrp4_like, nao_like"):
        add_humanoid(plant, "atlas")


def test_missing_frame_in_model_file(tmp_path, monkeypatch):
    for name in MODEL_NAMES:
        shutil.copy(models.model_file(name), tmp_path / f"{name}.sdf")
        shutil.copy(models.description_file(name), tmp_path / f"{name}.yaml")
    path = tmp_path / "nao_like.sdf"
    text = path.read_text()
    assert '<frame name="imu"' in text
    path.write_text(text.replace('<frame name="imu"', '<frame name="not_the_imu"'))
    monkeypatch.setattr(models, "MODELS_DIR", tmp_path)
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    with pytest.raises(ValueError, match="imu_frame: the robot has no frame or body named 'imu'"):
        add_humanoid(plant, "nao_like")


def test_two_instances_in_one_plant():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    a = add_humanoid(plant, "nao_like", scene_graph=scene_graph)
    b = add_humanoid(plant, "nao_like", model_instance_name="nao_2", scene_graph=scene_graph)
    plant.Finalize()
    assert a.model_instance != b.model_instance
    assert plant.GetModelInstanceName(b.model_instance) == "nao_2"
    assert set(a.fsr_geometries["left"]).isdisjoint(b.fsr_geometries["left"])


def _ground_has_resolution_hint(scene_graph_config) -> bool:
    """Whether the ground's proximity properties, as SceneGraph fills them in a context,
    carry a hydroelastic resolution hint (what prepares geometry for deformable contact)."""
    builder = DiagramBuilder()
    config = MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap", contact_model="point")
    if scene_graph_config is None:
        plant, scene_graph = AddMultibodyPlant(config, builder)
    else:
        plant, scene_graph = AddMultibodyPlant(config, scene_graph_config, builder)
    ground = add_ground(plant)
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    inspector = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context)).inspector()
    return inspector.GetProximityProperties(ground).HasProperty("hydroelastic", "resolution_hint")


def test_point_contact_scene_graph_config_drops_the_default_resolution_hint():
    """Drake's default SceneGraph config gives the ground half space a resolution hint, and
    with it a warning that half spaces cannot take part in deformable contact; the project's
    point-contact config does not."""
    assert _ground_has_resolution_hint(None)
    assert not _ground_has_resolution_hint(models.point_contact_scene_graph_config())
