"""Walking pattern generator (systems.locomotion.walking_pattern) and leg IK (systems.locomotion.leg_ik): preview
control on the cart-table model, footstep plan and swing trajectories, analytic IK against
Drake's forward kinematics, whole-body targets against Drake's CoM. No simulation here."""

import dataclasses

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from models import add_humanoid
from systems.locomotion.leg_ik import LEG_JOINTS, NaoLegGeometry, leg_fk, leg_ik
from systems.locomotion.walking_pattern import (
    NaoWalkingController,
    WalkingParameters,
    foot_trajectories,
    make_walking_pattern,
    plan_footsteps,
    preview_control,
    preview_gains,
    standing_positions,
)

LEFT0 = np.array([0.0, 0.05, 0.0])
RIGHT0 = np.array([0.0, -0.05, 0.0])
COM0 = np.array([0.0088, 0.0, 0.2677])


@pytest.fixture(scope="module")
def nao():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    humanoid = add_humanoid(plant, "nao_like", scene_graph=scene_graph)
    plant.Finalize()
    return plant, humanoid


# ---------------------------------------------------------------------------------------
# Preview control.
# ---------------------------------------------------------------------------------------


def test_preview_zmp_tracks_the_reference_after_the_transient():
    params = WalkingParameters()
    pattern = make_walking_pattern(params, LEFT0, RIGHT0, COM0)
    error = np.abs(pattern.zmp - pattern.zmp_reference)
    after = pattern.t > 0.5
    assert error[after].max() < 0.004  # m: a few mm, including the corners of the reference
    assert np.sqrt(np.mean(error[after] ** 2)) < 0.001
    # The cart-table ZMP recomputed from the CoM by finite differences: p = c - z_c/g c_ddot.
    T = params.sample_period
    c = pattern.com[:, :2]
    c_ddot = (c[2:] - 2 * c[1:-1] + c[:-2]) / T**2
    p = c[1:-1] - params.com_height / params.gravity * c_ddot
    assert np.abs(p - pattern.zmp[1:-1])[after[1:-1]].max() < 2e-4
    # The CoM ends at rest over the final ZMP reference.
    assert np.linalg.norm(pattern.com[-1, :2] - pattern.zmp_reference[-1]) < 5e-4
    assert np.abs(pattern.com_velocity[-1]).max() < 1e-3


def test_preview_integral_action_removes_steady_state_error():
    gains = preview_gains(0.005, 0.25, 1.2)
    t = np.arange(0, 4.0, 0.005)
    ref = np.where(t >= 1.0, 0.05, 0.0)
    states, zmp = preview_control(gains, ref, np.zeros(1))
    assert abs(zmp[-1, 0] - 0.05) < 1e-5 and abs(states[-1, 0, 0] - 0.05) < 1e-5
    # Preview: the CoM starts moving before the reference steps (anticipation).
    assert states[np.searchsorted(t, 0.95), 0, 0] > 1e-3
    # The preview gains decay over the horizon.
    assert abs(gains.Gp[-1]) < 5e-3 * abs(gains.Gp[0])


def test_preview_gains_reject_bad_arguments():
    with pytest.raises(ValueError, match="sample_period"):
        preview_gains(-0.005, 0.25, 1.0)
    with pytest.raises(ValueError, match="com_height"):
        preview_gains(0.005, 0.0, 1.0)


# ---------------------------------------------------------------------------------------
# Footsteps and swing trajectories.
# ---------------------------------------------------------------------------------------


def test_footstep_plan_geometry_and_timing():
    params = WalkingParameters(
        num_steps=5, step_length=0.04, step_width=0.11, step_duration=0.6, double_support_ratio=0.25, initial_wait=0.8
    )
    steps = plan_footsteps(params, LEFT0, RIGHT0)
    assert [s.side for s in steps] == ["right", "left", "right", "left", "right"]
    np.testing.assert_allclose([s.end[0] for s in steps], [0.04, 0.08, 0.12, 0.16, 0.16], atol=1e-12)
    np.testing.assert_allclose([s.end[1] for s in steps], [-0.055, 0.055, -0.055, 0.055, -0.055], atol=1e-12)
    for k, s in enumerate(steps):
        assert s.t_start == pytest.approx(0.8 + 0.6 * k)
        assert s.t_lift == pytest.approx(s.t_start + 0.15) and s.t_land == pytest.approx(s.t_start + 0.6)
        other = "left" if s.side == "right" else "right"
        previous = [p.end for p in steps[:k] if p.side == other]
        np.testing.assert_allclose(
            s.support_position, previous[-1] if previous else {"left": LEFT0, "right": RIGHT0}[other]
        )
    # Last step closes the stance: both feet at the same x.
    assert steps[-1].end[0] == pytest.approx(steps[-2].end[0])


def test_zmp_reference_lies_in_the_support_foot_during_single_support():
    params = WalkingParameters(num_steps=6)
    pattern = make_walking_pattern(params, LEFT0, RIGHT0, COM0)
    for step in pattern.steps:
        during = (pattern.t > step.t_lift + 1e-9) & (pattern.t < step.t_land - 1e-9)
        offset = pattern.zmp_reference[during] - step.support_position[:2]
        inward = 1.0 if step.side == "left" else -1.0
        np.testing.assert_allclose(
            offset, np.tile([params.zmp_offset_x, inward * params.zmp_offset_y], (during.sum(), 1)), atol=1e-12
        )
        assert (
            not pattern.contact[step.side][during].any()
            and pattern.contact[{"left": "right", "right": "left"}[step.side]][during].all()
        )


def test_swing_trajectory_is_smooth_with_zero_touchdown_velocity():
    params = WalkingParameters(num_steps=3, swing_height=0.02)
    steps = plan_footsteps(params, LEFT0, RIGHT0)
    step = steps[1]
    t = np.linspace(step.t_lift, step.t_land, 2001)
    feet, contact = foot_trajectories(t, steps, LEFT0, RIGHT0)
    p = feet[step.side]
    v = np.gradient(p, t, axis=0)
    np.testing.assert_allclose(p[0], step.start, atol=1e-12)
    np.testing.assert_allclose(p[-1], step.end, atol=1e-12)
    assert np.abs(v[[0, -1]]).max() < 1e-3  # m/s, at lift-off and touch-down
    assert p[:, 2].max() == pytest.approx(0.02, abs=1e-6)
    assert p[1000, 2] == pytest.approx(0.02, abs=1e-9)  # mid-swing peak
    assert np.all(np.diff(p[:, 0]) >= -1e-15)  # moves forward monotonically
    assert np.all(p[:, 2] >= 0)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(step_duration=-0.5), "step_duration"),
        (dict(step_length=0.2), "out of reach"),
        (dict(double_support_ratio=1.0), "double_support_ratio"),
        (dict(num_steps=0), "num_steps"),
        (dict(step_width=0.02), "step_width"),
        (dict(swing_height=-0.01), "swing_height"),
        (dict(com_height=0.5), "com_height"),
        (dict(step_duration=0.01, double_support_ratio=0.5), "single-support"),
        (dict(first_swing_foot="middle"), "first_swing_foot"),
        (dict(step_length=float("nan")), "finite"),
    ],
)
def test_bad_walking_parameters_raise(change, message):
    with pytest.raises(ValueError, match=message):
        WalkingParameters(**change)


# ---------------------------------------------------------------------------------------
# Leg IK vs Drake forward kinematics.
# ---------------------------------------------------------------------------------------


def _set_leg(plant, context, side, angles):
    prefix = "L" if side == "left" else "R"
    for name, angle in zip(LEG_JOINTS, angles):
        plant.GetJointByName(prefix + name).set_angle(context, angle)


def test_leg_geometry_read_from_the_plant(nao):
    plant, humanoid = nao
    g = NaoLegGeometry.from_plant(plant, humanoid.model_instance)
    assert g.hip_offset == pytest.approx((0.0, 0.05, -0.085))
    assert (g.thigh, g.tibia, g.sole_depth) == pytest.approx((0.100, 0.1029, 0.04519))


@pytest.mark.parametrize("side", ["left", "right"])
def test_leg_ik_inverts_drake_forward_kinematics(nao, side):
    plant, humanoid = nao
    g = NaoLegGeometry.from_plant(plant, humanoid.model_instance)
    context = plant.CreateDefaultContext()
    torso = humanoid.base_body.body_frame()
    sole = humanoid.sole_frames[side]
    rng = np.random.default_rng(7 if side == "left" else 8)
    for _ in range(100):
        # A random reachable target: Drake FK of random leg angles with the foot parallel to the torso.
        hr, hp, k = rng.uniform(-0.35, 0.35), rng.uniform(-1.2, 0.4), rng.uniform(0.15, 2.0)
        _set_leg(plant, context, side, [0.0, hr, hp, k, -(hp + k), -hr])
        target = plant.CalcRelativeTransform(context, torso, sole).translation()
        angles = leg_ik(g, target, side)
        _set_leg(plant, context, side, angles)
        X = plant.CalcRelativeTransform(context, torso, sole)
        np.testing.assert_allclose(X.translation(), target, atol=1e-9)
        np.testing.assert_allclose(X.rotation().matrix(), np.eye(3), atol=1e-9)
        np.testing.assert_allclose(angles, [0.0, hr, hp, k, -(hp + k), -hr], atol=1e-9)
        np.testing.assert_allclose(leg_fk(g, angles, side), target, atol=1e-12)


def test_leg_ik_vectorised_and_unreachable(nao):
    plant, humanoid = nao
    g = NaoLegGeometry.from_plant(plant, humanoid.model_instance)
    hip = g.hip("left")
    targets = hip + np.array([[0.0, 0.0, -0.23], [0.03, 0.01, -0.22], [-0.04, -0.02, -0.21]])
    angles = leg_ik(g, targets, "left")
    assert angles.shape == (3, 6)
    np.testing.assert_allclose(leg_fk(g, angles, "left"), targets, atol=1e-12)
    with pytest.raises(ValueError, match="out of reach"):
        leg_ik(g, hip + np.array([0.0, 0.0, -0.21 - g.sole_depth]), "left")
    with pytest.raises(ValueError, match="side"):
        leg_ik(g, targets, "middle")


# ---------------------------------------------------------------------------------------
# Whole body and the controller system.
# ---------------------------------------------------------------------------------------


def test_controller_targets_put_soles_and_com_on_the_pattern(nao):
    plant, humanoid = nao
    params = WalkingParameters(num_steps=4)
    dut = NaoWalkingController(plant, humanoid, params)
    context = dut.CreateDefaultContext()
    q0 = standing_positions(plant, humanoid)
    plant_context = plant.CreateDefaultContext()
    joints = dut.trajectory.joint_names
    assert len(joints) == 26 and dut.GetOutputPort("desired_position").size() == 26
    # t = 0: the standing posture (no jump at the start).
    names_q0 = {j: plant.GetJointByName(j).get_angle(_ctx(plant, q0)) for j in joints}
    np.testing.assert_allclose(
        dut.GetOutputPort("desired_position").Eval(context), [names_q0[j] for j in joints], atol=1e-9
    )
    mid_swing = 0.5 * (dut.pattern.steps[1].t_lift + dut.pattern.steps[1].t_land)
    for t in (0.3, mid_swing, dut.pattern.steps[2].t_start + 0.05):
        context.SetTime(t)
        q = dut.GetOutputPort("desired_position").Eval(context)
        k = int(round(t / params.sample_period))
        positions = q0.copy()
        positions[4:7] = dut.trajectory.torso_position[k]
        for name, angle in zip(joints, q):
            positions[plant.GetJointByName(name).position_start()] = angle
        plant.SetPositions(plant_context, positions)
        soles = dut.GetOutputPort("sole_targets").Eval(context)
        for i, side in enumerate(("left", "right")):
            X = humanoid.sole_frames[side].CalcPoseInWorld(plant_context)
            np.testing.assert_allclose(X.translation(), soles[3 * i : 3 * i + 3], atol=1e-9)
            np.testing.assert_allclose(X.rotation().matrix(), np.eye(3), atol=1e-9)
        com = plant.CalcCenterOfMassPositionInWorld(plant_context)
        np.testing.assert_allclose(com, dut.GetOutputPort("com_reference").Eval(context), atol=5e-4)
    assert dut.trajectory.com_error.max() < 5e-4
    np.testing.assert_allclose(dut.GetOutputPort("planned_contact").Eval(context), [1.0, 1.0])


def _ctx(plant, q):
    c = plant.CreateDefaultContext()
    plant.SetPositions(c, q)
    return c


def test_stiffness_compensation_offsets_stance_joints(nao):
    plant, humanoid = nao
    params = WalkingParameters(num_steps=2)
    kp = np.full(plant.num_velocities() - 6, 40.0)
    dut = NaoWalkingController(plant, humanoid, params, joint_stiffness=kp)
    plain = NaoWalkingController(plant, humanoid, params)
    comp = dut.trajectory.compensation
    np.testing.assert_allclose(dut.trajectory.q_joints - comp, plain.trajectory.q_joints, atol=1e-12)
    names = dut.trajectory.joint_names
    step = dut.pattern.steps[0]  # right swings: the left leg carries the robot
    k = int(round(0.5 * (step.t_lift + step.t_land) / params.sample_period))
    knee_l, knee_r = names.index("LKneePitch"), names.index("RKneePitch")
    assert abs(comp[k, knee_l]) > 0.02  # rad: the whole weight on the stance knee
    assert abs(comp[k, knee_r]) < 1e-12  # the swing leg carries no ground force
    arm = names.index("LShoulderPitch")
    assert np.abs(comp[:, arm]).max() == 0.0
    with pytest.raises(ValueError, match="joint_stiffness"):
        NaoWalkingController(plant, humanoid, params, joint_stiffness=-kp)
    # Velocity lead (eq. W-3): K_d / K_p times the reference joint velocity.
    kd = np.full_like(kp, 0.4)
    lead = NaoWalkingController(plant, humanoid, params, joint_stiffness=kp, joint_damping=kd)
    q_ref = plain.trajectory.q_joints
    velocity = np.gradient(q_ref, plain.trajectory.t, axis=0)
    np.testing.assert_allclose(lead.trajectory.compensation - comp, 0.01 * velocity, atol=1e-12)
    assert np.abs(0.01 * velocity).max() > 1e-3


def test_unreachable_pattern_raises(nao):
    plant, humanoid = nao
    with pytest.raises(ValueError, match="out of reach|outside its limits"):
        NaoWalkingController(plant, humanoid, WalkingParameters(num_steps=3, step_length=0.08, com_height=0.29))
    with pytest.raises(ValueError, match="nao_like"):
        NaoWalkingController(plant, dataclasses.replace(humanoid, name="hrp4_like"))


def test_multibody_zmp_correction(nao):
    """Kajita 2003's second preview pass: the ZMP of the planned whole-body motion (eq. Z-1,
    swing-leg dynamics included) is ~19 mm off the reference with the cart-table CoM, a few
    mm after one pass; standing still it is the CoM's ground projection."""
    from systems.locomotion.walking_pattern import multibody_zmp

    plant, humanoid = nao
    params = WalkingParameters(num_steps=6)
    raw = NaoWalkingController(plant, humanoid, params, zmp_correction_passes=0)
    corrected = NaoWalkingController(plant, humanoid, params, zmp_correction_passes=1)
    after = raw.pattern.t > 0.5
    error_raw = np.abs(raw.planned_multibody_zmp - raw.pattern.zmp_reference)[after]
    error = np.abs(corrected.planned_multibody_zmp - corrected.pattern.zmp_reference)[after]
    assert error_raw[:, 0].max() > 0.01  # the cart-table model misses the swing leg
    assert error.max() < 0.005 and error.max() < 0.3 * error_raw.max()
    np.testing.assert_allclose(corrected.cart_table_pattern.com, raw.pattern.com)
    # Standing still (first samples, before the CoM moves): ZMP = CoM (x, y).
    q0 = standing_positions(plant, humanoid)
    still = dataclasses.replace(
        raw.trajectory,
        t=raw.trajectory.t[:20],
        q_joints=np.tile(raw.trajectory.q_joints[0], (20, 1)),
        torso_position=np.tile(raw.trajectory.torso_position[0], (20, 1)),
    )
    p = multibody_zmp(plant, humanoid, still, q0)
    np.testing.assert_allclose(p, np.tile(COM0[:2], (20, 1)), atol=2e-4)
    with pytest.raises(ValueError, match="zmp_correction_passes"):
        NaoWalkingController(plant, humanoid, params, zmp_correction_passes=-1)
