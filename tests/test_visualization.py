"""Tests of systems.simulation.visualization: effort markers and force arrows in Meshcat, live and in
the recorded replay (read back from ``Meshcat.StaticHtml()``)."""

import numpy as np
import pytest
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame, RevoluteJoint, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Sine

from models import add_humanoid
from systems.simulation.visualization import (
    ForceArrows,
    JointEffortOverlay,
    add_effort_visualization,
    read_static_html,
)

JOINTS = ("R_SHOULDER_P", "L_KNEE_P", "CHEST_Y", "R_ANKLE_R", "NECK_P")


@pytest.fixture(scope="module")
def meshcat():
    return Meshcat()


@pytest.fixture(autouse=True)
def clean(meshcat):
    meshcat.Delete()
    meshcat.DeleteRecording()
    yield


def _plant():
    plant = MultibodyPlant(time_step=1e-3)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    return plant, handles


def _random_state(plant, handles, rng):
    context = plant.CreateDefaultContext()
    for name in handles.joint_names():
        joint = plant.GetJointByName(name)
        joint.set_angle(context, rng.uniform(-0.5, 0.5))
    plant.SetFreeBodyPose(
        context, handles.base_body, RigidTransform(RollPitchYaw(rng.uniform(-0.3, 0.3, 3)), rng.uniform(-1, 1, 3))
    )
    return context, plant.GetPositionsAndVelocities(context)


def _scene(meshcat):
    return read_static_html(meshcat.StaticHtml())


def test_markers_sit_at_joints_and_scale_with_effort(meshcat):
    plant, handles = _plant()
    rng = np.random.default_rng(1)
    plant_context, x = _random_state(plant, handles, rng)
    max_effort = np.array([10.0, 20.0, 5.0, 2.0, 1.0])
    dut = JointEffortOverlay(plant, meshcat, JOINTS, max_effort=max_effort, radius=0.06)
    n = plant.num_velocities() - 6
    effort = np.zeros(n)
    wanted = np.array([-5.0, 40.0, 2.5, 0.0, 0.3])  # half, clamped, half, zero (hidden), 0.3
    for name, e in zip(JOINTS, wanted):
        effort[plant.GetJointByName(name).velocity_start() - 6] = e
    effort[plant.GetJointByName("L_WRIST_Y").velocity_start() - 6] = 100.0  # not shown
    context = dut.CreateDefaultContext()
    dut.GetInputPort("residual").FixValue(context, effort)
    dut.GetInputPort("state").FixValue(context, x)
    dut.ForcedPublish(context)

    scene = _scene(meshcat)
    expected_scale = [0.5, 1.0, 0.5, 0.0, 0.3]
    for name, s in zip(JOINTS, expected_scale):
        path = f"/drake/effort/{name}"
        assert meshcat.HasPath(f"effort/{name}/marker")
        p_W = plant.GetJointByName(name).frame_on_child().CalcPoseInWorld(plant_context).translation()
        np.testing.assert_allclose(scene.transforms[path][:3, 3], p_W, atol=1e-12)
        np.testing.assert_allclose(scene.properties[f"{path}/marker"]["scale"], [max(s, 1e-3)] * 3, atol=1e-12)
        assert scene.properties[path]["visible"] is (s > 0)
    assert not meshcat.HasPath("effort/L_WRIST_Y")
    assert f"/drake/effort/{JOINTS[0]}/marker" in scene.objects

    # A new effort moves the scales (same time: re-sent, not held).
    effort[:] = 0.0
    effort[plant.GetJointByName("NECK_P").velocity_start() - 6] = -0.8
    dut.GetInputPort("residual").FixValue(context, effort)
    context.SetTime(0.1)
    dut.ForcedPublish(context)
    scene = _scene(meshcat)
    np.testing.assert_allclose(scene.properties["/drake/effort/NECK_P/marker"]["scale"], [0.8] * 3)
    assert scene.properties["/drake/effort/R_SHOULDER_P"]["visible"] is False


def test_classical_residual_size_and_default_radius(meshcat):
    plant, _ = _plant()
    nv = plant.num_velocities()
    dut = JointEffortOverlay(plant, meshcat, ["L_KNEE_P"], max_effort=4.0, includes_base=True)
    assert dut.GetInputPort("residual").size() == nv
    assert 0.045 < dut.radius < 0.075  # about 6 cm for a 1.5 m robot
    residual = np.zeros(nv)
    residual[plant.GetJointByName("L_KNEE_P").velocity_start()] = 1.0  # classical: index = v index
    residual[:6] = 1e3  # base entries are ignored
    np.testing.assert_allclose(dut.scales(residual), [0.25])


def test_marker_at_offset_child_frame_on_fixed_base_plant(meshcat):
    # A joint whose child frame is not its body's origin; a plant without floating base,
    # whose residual has nv entries.
    plant = MultibodyPlant(0.0)
    body = plant.AddRigidBody("link", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.5))
    X_BJ = RigidTransform(RollPitchYaw(0.3, 0.0, 0.2), [0.05, -0.02, 0.25])
    frame = plant.AddFrame(FixedOffsetFrame("joint_on_link", body.body_frame(), X_BJ))
    plant.AddJoint(RevoluteJoint("hinge", plant.world_frame(), frame, [0.0, 1.0, 0.0]))
    plant.Finalize()
    dut = JointEffortOverlay(plant, meshcat, ["hinge"], max_effort=2.0)
    assert dut.GetInputPort("residual").size() == 1
    context = dut.CreateDefaultContext()
    plant_context = plant.CreateDefaultContext()
    plant.GetJointByName("hinge").set_angle(plant_context, 0.7)
    dut.GetInputPort("state").FixValue(context, plant.GetPositionsAndVelocities(plant_context))
    dut.GetInputPort("residual").FixValue(context, [-3.0])
    dut.ForcedPublish(context)
    scene = _scene(meshcat)
    X_WB = plant.EvalBodyPoseInWorld(plant_context, body)
    p_W = frame.CalcPoseInWorld(plant_context).translation()
    assert np.linalg.norm(p_W - X_WB.translation()) > 0.2  # the test can tell them apart
    np.testing.assert_allclose(scene.transforms["/drake/effort/hinge"][:3, 3], p_W, atol=1e-12)
    np.testing.assert_allclose(scene.properties["/drake/effort/hinge/marker"]["scale"], [1.0] * 3)


def test_arrows_point_along_force_and_hide_at_zero(meshcat):
    npm = 50.0
    dut = ForceArrows(meshcat, 3, newtons_per_meter=npm, head_length=0.05)
    forces = np.array([0.0, 0.0, -20.0, 6.0, 8.0, 0.0, 0.0, 0.0, 0.0])
    points = np.array([0.1, 0.2, 1.3, -0.3, 0.0, 0.9, 0.0, 0.0, 1.0])
    context = dut.CreateDefaultContext()
    dut.GetInputPort("force_world").FixValue(context, forces)
    dut.GetInputPort("point_world").FixValue(context, points)
    dut.ForcedPublish(context)
    scene = _scene(meshcat)
    for i in range(2):
        f, p = forces[3 * i : 3 * i + 3], points[3 * i : 3 * i + 3]
        length = np.linalg.norm(f) / npm
        X = scene.transforms[f"/drake/forces/{i}"]
        np.testing.assert_allclose(X[:3, 2], f / np.linalg.norm(f), atol=1e-12)  # +z along f
        np.testing.assert_allclose(X[:3, 3], p - f / npm, atol=1e-12)  # tail
        head = scene.transforms[f"/drake/forces/{i}/head"]
        np.testing.assert_allclose(head[:3, 3], [0.0, 0.0, length], atol=1e-12)  # apex at p
        np.testing.assert_allclose(X[:3, :3] @ head[:3, 3] + X[:3, 3], p, atol=1e-12)
        np.testing.assert_allclose(head[:3, 2], [0.0, 0.0, -1.0], atol=1e-12)  # cone opens backwards
        c = min(1.0, length / 0.1)
        np.testing.assert_allclose(
            scene.properties[f"/drake/forces/{i}/shaft"]["scale"], [c, c, length - c * 0.05], atol=1e-12
        )
        assert scene.properties[f"/drake/forces/{i}"]["visible"] is True
        assert meshcat.HasPath(f"forces/{i}/head/cone") and meshcat.HasPath(f"forces/{i}/shaft/cylinder")
    assert scene.properties["/drake/forces/2"]["visible"] is False
    # Lengths are proportional to |f|: 20 N -> 0.4 m, 10 N -> 0.2 m.
    assert scene.transforms["/drake/forces/0/head"][2, 3] == pytest.approx(
        2 * scene.transforms["/drake/forces/1/head"][2, 3]
    )

    # The force goes to zero: the arrow is hidden.
    dut.GetInputPort("force_world").FixValue(context, np.zeros(9))
    context.SetTime(0.5)
    dut.ForcedPublish(context)
    assert _scene(meshcat).properties["/drake/forces/0"]["visible"] is False


def test_recorded_replay_animates_markers_and_arrows(meshcat):
    builder = DiagramBuilder()
    plant = builder.AddSystem(MultibodyPlant(time_step=1e-3))
    add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    n = plant.num_velocities() - 6
    knee = plant.GetJointByName("R_KNEE_P").velocity_start() - 6
    # Efforts 15 sin(2 pi t) N m on every joint; max 10 N m: clamped while |sin| > 2/3.
    effort = builder.AddSystem(Sine(15.0 * np.ones(n), 2 * np.pi * np.ones(n), np.zeros(n)))
    force = builder.AddSystem(Sine(np.array([0.0, 0.0, 30.0]), 2 * np.pi * np.ones(3), np.zeros(3)))
    point = builder.AddSystem(ConstantVectorSource([0.0, -0.2, 1.3]))
    out = add_effort_visualization(
        builder,
        plant,
        meshcat,
        effort.get_output_port(0),
        plant.get_state_output_port(),
        ["R_KNEE_P", "L_SHOULDER_R"],
        max_effort=10.0,
        force_port=force.get_output_port(0),
        point_port=point.get_output_port(),
        prefix="internal/",
    )
    assert set(out) == {"effort_overlay", "force_arrows"}
    diagram = builder.Build()
    simulator = Simulator(diagram)
    meshcat.StartRecording(frames_per_second=32.0)
    simulator.AdvanceTo(1.0)  # the robot falls freely (no ground): the markers move down
    meshcat.StopRecording()
    meshcat.PublishRecording()
    html = meshcat.StaticHtml()
    scene = read_static_html(html)
    for path in (
        "effort/R_KNEE_P",
        "effort/R_KNEE_P/marker",
        "effort/L_SHOULDER_R",
        "forces/0",
        "forces/0/head",
        "forces/0/shaft",
    ):
        assert f"/drake/internal/{path}" in scene.tracks

    scale = scene.tracks["/drake/internal/effort/R_KNEE_P/marker"]["scale"]
    assert len(scale) > 15 and len({round(v[0], 3) for _, v in scale}) >= 5  # many key frames and sizes
    # What the replay shows: the key frames linearly interpolated, at every frame, match
    # the effort within the hold tolerance (1 % of full size), also around the clamped
    # segments where key frames are skipped.
    key_t = np.array([t for t, _ in scale])
    key_s = np.array([v[0] for _, v in scale])
    assert np.ptp(np.diff(key_t)) > 0  # some frames were held (not sent)
    for t in np.arange(0, 32) / 32.0:
        expected = max(min(abs(15 * np.sin(2 * np.pi * t)) / 10, 1.0), 1e-3)
        assert np.interp(t, key_t, key_s) == pytest.approx(expected, abs=0.011), t
    position = scene.tracks["/drake/internal/effort/R_KNEE_P"]["position"]
    z = [v[2] for _, v in position]
    assert len(position) > 10 and z[-1] < z[0] - 3.0  # falls ~4.9 m in 1 s
    visible = scene.tracks["/drake/internal/effort/R_KNEE_P"]["visible"]
    assert {v for _, v in visible} == {True, False}  # hidden at the sine's zeros
    head = scene.tracks["/drake/internal/forces/0/head"]["position"]
    assert len(head) > 25 and max(v[2] for _, v in head) == pytest.approx(0.3, abs=0.01)  # 30 N at 100 N/m
    for t, v in head:  # the arrow's length |f| / (100 N/m) at each key frame
        assert v[2] == pytest.approx(0.3 * abs(np.sin(2 * np.pi * t)), abs=1e-3)
    arrow_visible = scene.tracks["/drake/internal/forces/0"]["visible"]
    assert {v for _, v in arrow_visible} == {True, False}
    quaternion = scene.tracks["/drake/internal/forces/0"]["quaternion"]
    assert len({tuple(np.round(v, 6)) for _, v in quaternion}) == 2  # up while f_z > 0, down after
    assert scene.fps == 32.0
    # The efforts of the effort markers: the knee's effort index is read (not another joint's).
    assert out["effort_overlay"].scales(np.eye(n)[knee]).tolist() == [0.1, 0.0]


def test_bad_inputs_raise_value_errors(meshcat):
    plant, _ = _plant()
    n = plant.num_velocities() - 6
    with pytest.raises(ValueError, match="NO_SUCH_JOINT"):
        JointEffortOverlay(plant, meshcat, ["L_KNEE_P", "NO_SUCH_JOINT"], max_effort=1.0)
    with pytest.raises(ValueError, match="1-DoF"):
        JointEffortOverlay(plant, meshcat, [_free_joint(plant)], max_effort=1.0)
    with pytest.raises(ValueError, match="twice"):
        JointEffortOverlay(plant, meshcat, ["L_KNEE_P", "L_KNEE_P"], max_effort=1.0)
    with pytest.raises(ValueError, match="max_effort"):
        JointEffortOverlay(plant, meshcat, ["L_KNEE_P", "R_KNEE_P"], max_effort=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="max_effort"):
        JointEffortOverlay(plant, meshcat, ["L_KNEE_P"], max_effort=0.0)
    with pytest.raises(ValueError, match="publish_period"):
        ForceArrows(meshcat, 1, publish_period=0.0)

    # Port sizes in the builder helper.
    builder = DiagramBuilder()
    builder.AddSystem(plant)
    wrong = builder.AddSystem(ConstantVectorSource(np.zeros(plant.num_velocities())))
    with pytest.raises(ValueError, match="residual.*size 40.*expected 34.*includes_base"):
        add_effort_visualization(
            builder,
            plant,
            meshcat,
            wrong.get_output_port(),
            plant.get_state_output_port(),
            ["L_KNEE_P"],
            max_effort=1.0,
        )
    good = builder.AddSystem(ConstantVectorSource(np.zeros(n)))
    with pytest.raises(ValueError, match="state.*expected"):
        add_effort_visualization(
            builder, plant, meshcat, good.get_output_port(), good.get_output_port(), ["L_KNEE_P"], max_effort=1.0
        )
    three = builder.AddSystem(ConstantVectorSource(np.zeros(3)))
    six = builder.AddSystem(ConstantVectorSource(np.zeros(6)))
    with pytest.raises(ValueError, match="force_port"):
        add_effort_visualization(
            builder,
            plant,
            meshcat,
            good.get_output_port(),
            plant.get_state_output_port(),
            ["L_KNEE_P"],
            max_effort=1.0,
            force_port=three.get_output_port(),
            point_port=six.get_output_port(),
        )

    # NaN inputs name the port.
    dut = JointEffortOverlay(plant, meshcat, ["L_KNEE_P"], max_effort=1.0)
    context = dut.CreateDefaultContext()
    x = plant.GetPositionsAndVelocities(plant.CreateDefaultContext())
    bad = np.zeros(n)
    bad[3] = np.nan
    dut.GetInputPort("residual").FixValue(context, bad)
    dut.GetInputPort("state").FixValue(context, x)
    with pytest.raises(ValueError, match="'residual'"):
        dut.ForcedPublish(context)
    dut.GetInputPort("residual").FixValue(context, np.zeros(n))
    x_bad = x.copy()
    x_bad[0] = np.inf
    dut.GetInputPort("state").FixValue(context, x_bad)
    with pytest.raises(ValueError, match="'state'"):
        dut.ForcedPublish(context)
    arrows = ForceArrows(meshcat, 1)
    context = arrows.CreateDefaultContext()
    arrows.GetInputPort("force_world").FixValue(context, [1.0, 0.0, 0.0])
    arrows.GetInputPort("point_world").FixValue(context, [0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="'point_world'"):
        arrows.ForcedPublish(context)


def _free_joint(plant):
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.num_velocities() == 6:
            return joint
    raise AssertionError("no free joint")
