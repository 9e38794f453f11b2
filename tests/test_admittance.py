"""Tests of systems.residuals.admittance.JointAdmittanceController (Flacco et al. 2016, eq. 14)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RevoluteJoint, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.station.standing import default_gains
from models import add_humanoid
from systems.residuals.admittance import (
    JointAdmittanceController,
    admittance_gains_by_group,
    joint_position_selector,
    soft_threshold,
)
from systems.simulation.pd_gravity import PdGravityController, joint_vector_from_names, joints_in_velocity_order

T = 1e-3
LOWER = np.array([-1.0, -0.5, -2.0])
UPPER = np.array([1.0, 0.7, 0.1])


def _chain_plant(time_step=0.0, limits=True):
    """Floating base + 3 revolute links, position limits LOWER/UPPER."""
    plant = MultibodyPlant(time_step)
    base = plant.AddRigidBody("base", SpatialInertia.SolidBoxWithMass(5.0, 0.2, 0.2, 0.2))
    parent = base
    for i in range(3):
        link = plant.AddRigidBody(f"link{i}", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.3))
        kwargs = dict(pos_lower_limit=LOWER[i], pos_upper_limit=UPPER[i]) if limits else {}
        joint = plant.AddJoint(
            RevoluteJoint(f"j{i}", parent.body_frame(), link.body_frame(), [0.0, 1.0, 0.0], **kwargs)
        )
        plant.AddJointActuator(f"a{i}", joint, 50.0)
        parent = link
    plant.Finalize()
    return plant


@pytest.fixture(scope="module")
def chain():
    return _chain_plant()


def _context(dut, residual, measured):
    """A context with fixed inputs, initialised as Simulator.Initialize would (q_d = the
    measured or the given initial position)."""
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("residual").FixValue(ctx, np.asarray(residual, dtype=float))
    dut.GetInputPort("measured_position").FixValue(ctx, np.asarray(measured, dtype=float))
    dut.ExecuteInitializationEvents(ctx)
    return ctx


def _step(dut, ctx, times=1):
    """Applies ``times`` periodic updates to ctx (the discrete state) in place."""
    for _ in range(times):
        ctx.SetDiscreteState(dut.EvalUniquePeriodicDiscreteUpdate(ctx))
        ctx.SetTime(ctx.get_time() + dut.period)
    return dut.GetOutputPort("desired_position").Eval(ctx)


Q0 = np.array([0.1, -0.2, -0.3])
R = np.array([2.0, -3.0, 0.5])


# -- ports and structure ---------------------------------------------------------------


def test_ports_and_no_direct_feedthrough(chain):
    dut = JointAdmittanceController(chain, 0.1)
    assert dut.joint_count == 3
    assert dut.get_input_port(0).get_name() == "residual" and dut.get_input_port(0).size() == 3
    assert dut.get_input_port(1).get_name() == "measured_position" and dut.get_input_port(1).size() == 3
    assert dut.get_output_port(0).get_name() == "desired_position" and dut.get_output_port(0).size() == 3
    assert not dut.HasDirectFeedthrough(0, 0)
    assert not dut.HasDirectFeedthrough(1, 0)
    assert not dut.HasAnyDirectFeedthrough()
    classical = JointAdmittanceController(chain, 0.1, residual_includes_base=True)
    assert classical.GetInputPort("residual").size() == chain.num_velocities() == 9


# -- the law -----------------------------------------------------------------------------


def test_one_update_measured_mode_is_eq14(chain):
    K = np.array([0.1, 0.2, 0.05])
    dut = JointAdmittanceController(chain, K, T, position_limits=None)
    ctx = _context(dut, R, Q0)
    q_d = _step(dut, ctx)
    np.testing.assert_array_equal(q_d, Q0 + K * R * T)
    # Measured mode does not accumulate: with the same measured q, more updates give the
    # same q_d.
    np.testing.assert_array_equal(_step(dut, ctx, 5), Q0 + K * R * T)


def test_desired_mode_integrates_residual(chain):
    K = np.array([0.1, 0.2, 0.05])
    dut = JointAdmittanceController(chain, K, 2e-3, position_limits=None, integrate_from="desired")
    ctx = _context(dut, R, Q0)
    N = 25
    q_d = _step(dut, ctx, N)
    np.testing.assert_allclose(q_d, Q0 + N * K * R * 2e-3, rtol=0, atol=1e-14)
    # It integrates from q_d, not from the measured position (which stays at Q0).
    dut.GetInputPort("measured_position").FixValue(ctx, Q0 + 1.0)
    np.testing.assert_allclose(_step(dut, ctx), Q0 + (N + 1) * K * R * 2e-3, atol=1e-14)


def test_scalar_gain_and_per_joint_zero_gain(chain):
    dut = JointAdmittanceController(chain, [0.0, 0.3, 0.0], T, position_limits=None)
    q_d = _step(dut, _context(dut, R, Q0))
    np.testing.assert_array_equal(q_d, [Q0[0], Q0[1] + 0.3 * R[1] * T, Q0[2]])
    dut = JointAdmittanceController(chain, 0.3, T, position_limits=None)
    np.testing.assert_array_equal(_step(dut, _context(dut, R, Q0)), Q0 + 0.3 * R * T)


def test_classical_residual_drops_base_entries(chain):
    K = np.array([0.1, 0.2, 0.05])
    dut = JointAdmittanceController(chain, K, T, position_limits=None, residual_includes_base=True)
    base_part = np.array([100.0, -50.0, 7.0, 30.0, 1.0, -9.0])
    q_d = _step(dut, _context(dut, np.concatenate([base_part, R]), Q0))
    np.testing.assert_array_equal(q_d, Q0 + K * R * T)


def test_first_update_and_initialisation_start_from_measured(chain):
    dut = JointAdmittanceController(chain, 0.5, T, integrate_from="desired")
    # No initialisation event: the first periodic update starts from the measured q.
    ctx = _context(dut, np.zeros(3), Q0)
    np.testing.assert_array_equal(_step(dut, ctx), Q0)
    # In a simulator, the initialisation event sets q_d = measured before any update.
    builder = DiagramBuilder()
    sys = builder.AddSystem(dut)
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(3))).get_output_port(), sys.GetInputPort("residual")
    )
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(Q0)).get_output_port(), sys.GetInputPort("measured_position")
    )
    diagram = builder.Build()
    sim = Simulator(diagram)
    sim.Initialize()
    out = sys.GetOutputPort("desired_position").Eval(sys.GetMyContextFromRoot(sim.get_context()))
    np.testing.assert_array_equal(out, Q0)
    # initial_position overrides the measured position (desired mode keeps it).
    q_init = np.array([0.3, 0.2, -0.1])
    dut2 = JointAdmittanceController(chain, 0.5, T, integrate_from="desired", initial_position=q_init)
    ctx2 = _context(dut2, np.zeros(3), Q0)
    np.testing.assert_array_equal(dut2.GetOutputPort("desired_position").Eval(ctx2), q_init)
    np.testing.assert_array_equal(_step(dut2, ctx2, 3), q_init)


def test_dead_band_is_soft_threshold(chain):
    np.testing.assert_array_equal(soft_threshold([2.0, -3.0, 0.5, -0.5, 0.0], 1.0), [1.0, -2.0, 0.0, 0.0, 0.0])
    db = np.array([1.0, 1.0, 0.6])  # per joint: the third |r| = 0.5 is inside
    dut = JointAdmittanceController(chain, 0.1, T, dead_band=db, position_limits=None)
    q_d = _step(dut, _context(dut, R, Q0))
    np.testing.assert_allclose(q_d, Q0 + 0.1 * np.array([1.0, -2.0, 0.0]) * T, atol=1e-15)
    dut = JointAdmittanceController(chain, 0.1, T, dead_band=5.0, position_limits=None)
    np.testing.assert_array_equal(_step(dut, _context(dut, R, Q0)), Q0)


def test_max_rate_clips_rate(chain):
    K = 1.0
    dut = JointAdmittanceController(chain, K, T, max_rate=[1.0, 2.5, 10.0], position_limits=None)
    q_d = _step(dut, _context(dut, R, Q0))
    # K r = [2, -3, 0.5] -> [1, -2.5, 0.5]
    np.testing.assert_allclose(q_d, Q0 + np.array([1.0, -2.5, 0.5]) * T, atol=1e-15)
    assert np.all(np.isinf(JointAdmittanceController(chain, K).max_rate))


def test_model_limits_with_margin(chain):
    margin = 0.05
    dut = JointAdmittanceController(chain, 100.0, T, integrate_from="desired", limit_margin=margin)
    np.testing.assert_allclose(dut.position_lower_limits, LOWER + margin)
    np.testing.assert_allclose(dut.position_upper_limits, UPPER - margin)
    big = np.array([1e3, -1e3, 1e3])
    q_d = _step(dut, _context(dut, big, Q0), 10)
    np.testing.assert_allclose(q_d, [UPPER[0] - margin, LOWER[1] + margin, UPPER[2] - margin])
    # Also in measured mode.
    dut = JointAdmittanceController(chain, 100.0, T, limit_margin=margin)
    q_d = _step(dut, _context(dut, -big, Q0), 10)
    np.testing.assert_allclose(q_d, [LOWER[0] + margin, UPPER[1] - margin, LOWER[2] + margin])
    # A joint resting on its model limit (inside the margin) is not pulled in (no jump)
    # and cannot go further out; it can move inwards.
    q_at_limit = np.array([UPPER[0], LOWER[1] + 0.01, 0.0])
    for mode in ("measured", "desired"):
        dut = JointAdmittanceController(chain, 1.0, T, limit_margin=margin, integrate_from=mode)
        ctx = _context(dut, [5.0, -5.0, 0.0], q_at_limit)
        np.testing.assert_array_equal(_step(dut, ctx, 3), q_at_limit)
        dut.GetInputPort("residual").FixValue(ctx, [-5.0, 5.0, 0.0])
        np.testing.assert_allclose(_step(dut, ctx), q_at_limit + [-5.0 * T, 5.0 * T, 0.0])
    # Measured mode: a measured q beyond the shrunk limit (overshoot) is pulled back.
    dut = JointAdmittanceController(chain, 1.0, T, limit_margin=margin)
    ctx = _context(dut, [5.0, -5.0, 0.0], np.zeros(3))
    _step(dut, ctx)
    dut.GetInputPort("measured_position").FixValue(ctx, q_at_limit)
    np.testing.assert_allclose(_step(dut, ctx), [UPPER[0] - margin, LOWER[1] + margin, 0.0])
    # A range narrower than two margins collapses to its middle.
    dut = JointAdmittanceController(chain, 1.0, limit_margin=0.7)
    assert dut.position_lower_limits[1] == dut.position_upper_limits[1] == pytest.approx(0.1)
    np.testing.assert_allclose(dut.position_upper_limits[[0, 2]], UPPER[[0, 2]] - 0.7)


def test_custom_limits_and_no_limits(chain):
    lo, hi = np.array([-0.01, -1.0, -np.inf]), np.array([0.2, 0.0, np.inf])
    dut = JointAdmittanceController(
        chain, 100.0, T, position_limits=(lo, hi), limit_margin=0.3, integrate_from="desired"
    )
    np.testing.assert_array_equal(dut.position_lower_limits, lo)  # margin not applied
    q_d = _step(dut, _context(dut, [1e3, 1e3, 1e3], Q0), 10)
    np.testing.assert_allclose(q_d, [0.2, 0.0, Q0[2] + 10 * 100.0 * 1e3 * T])
    dut = JointAdmittanceController(chain, 100.0, T, position_limits=None, integrate_from="desired")
    q_d = _step(dut, _context(dut, [1e3, -1e3, 1e3], Q0), 10)
    np.testing.assert_allclose(q_d, Q0 + 10 * 100.0 * np.array([1e3, -1e3, 1e3]) * T)
    # Scalar custom limits.
    dut = JointAdmittanceController(chain, 100.0, T, position_limits=(-0.05, 0.05))
    np.testing.assert_allclose(_step(dut, _context(dut, [1e3, -1e3, 0.0], np.zeros(3))), [0.05, -0.05, 0.0])


# -- humanoid helpers ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def hrp4():
    plant = MultibodyPlant(T)
    handles = add_humanoid(plant, "hrp4_like")
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    plant.Finalize()
    return plant, handles


def test_gains_by_group(hrp4):
    plant, handles = hrp4
    names = [j.name() for j in joints_in_velocity_order(plant)]
    K = admittance_gains_by_group(
        plant, handles, {"legs": 0.2, "torso": 1.0, "arms": 0.5, "left_arm": 0.7}, default=0.01
    )
    assert K.shape == (len(names),)
    for k, name in enumerate(names):
        if name in handles.joint_groups["left_arm"]:
            assert K[k] == 0.7  # later group overrides
        elif name in handles.joint_groups["arms"]:
            assert K[k] == 0.5
        elif name in handles.joint_groups["legs"]:
            assert K[k] == 0.2
        elif name in handles.joint_groups["torso"]:
            assert K[k] == 1.0
        else:
            assert K[k] == 0.01, name  # head, hands
    with pytest.raises(ValueError, match="unknown joint group or joint 'tail'"):
        admittance_gains_by_group(plant, handles, {"tail": 1.0})
    with pytest.raises(ValueError, match="group 'arms'.*non-negative"):
        admittance_gains_by_group(plant, handles, {"arms": -1.0})
    with pytest.raises(ValueError, match="default"):
        admittance_gains_by_group(plant, handles, {}, default=-0.1)


def _hrp4_zero_gravity():
    plant = MultibodyPlant(T)
    handles = add_humanoid(plant, "hrp4_like")
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    plant.Finalize()
    return plant, handles


def _simulate_push_on_joint(joint_name, effort, gains_by_group, integrate_from, duration):
    """hrp4_like in zero gravity, no ground, PD + admittance, a constant "residual" of
    ``effort`` N m on one joint. Returns (plant, k, t, q, q_d, q_start) with q, q_d logged
    (n x samples) every 10 ms."""
    plant, handles = _hrp4_zero_gravity()
    joints = joints_in_velocity_order(plant)
    k = [j.name() for j in joints].index(joint_name)
    K_a = admittance_gains_by_group(plant, handles, gains_by_group, default=0.05)
    residual = np.zeros(len(joints))
    residual[k] = effort

    builder = DiagramBuilder()
    builder.AddSystem(plant)
    kp, kd = default_gains(plant, handles)  # stable explicit 1 kHz PD per joint group
    pd = builder.AddSystem(PdGravityController(plant, kp, kd))
    adm = builder.AddSystem(JointAdmittanceController(plant, K_a, T, integrate_from=integrate_from))
    select = builder.AddSystem(joint_position_selector(plant))
    source = builder.AddSystem(ConstantVectorSource(residual))
    builder.Connect(plant.get_state_output_port(), select.get_input_port())
    builder.Connect(plant.get_state_output_port(), pd.GetInputPort("state"))
    builder.Connect(select.get_output_port(), adm.GetInputPort("measured_position"))
    builder.Connect(source.get_output_port(), adm.GetInputPort("residual"))
    builder.Connect(adm.GetOutputPort("desired_position"), pd.GetInputPort("desired_position"))
    builder.Connect(pd.get_output_port(), plant.get_actuation_input_port())
    log_q = LogVectorOutput(select.get_output_port(), builder, publish_period=0.01)
    log_qd = LogVectorOutput(adm.GetOutputPort("desired_position"), builder, publish_period=0.01)
    diagram = builder.Build()

    sim = Simulator(diagram)
    plant_ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    q_start = joint_vector_from_names(plant, handles.nominal_posture)
    for j, value in zip(joints, q_start):
        j.set_angle(plant_ctx, value)
    sim.Initialize()
    sim.AdvanceTo(duration)
    log = log_q.FindLog(sim.get_context())
    q_d = log_qd.FindLog(sim.get_context()).data()
    return plant, k, log.sample_times(), log.data(), q_d, q_start


def test_closed_loop_desired_mode_moves_with_effort_and_stops_at_limit():
    """A constant +5 N m "residual" on R_ELBOW_P (limits [-2.5, 0], start -0.3) moves that
    joint up, in desired mode, until q_d stops at the margin-shrunk upper limit 0 - 0.02
    and the PD brings the joint there; the other joints stay where they were."""
    plant, k, t, q, q_d, q_start = _simulate_push_on_joint(
        "R_ELBOW_P", 5.0, {"arms": 0.1}, "desired", 1.5
    )  # K_a r = 0.5 rad/s
    n = q.shape[0]
    joint = joints_in_velocity_order(plant)[k]
    upper = plant.GetPositionUpperLimits()[joint.position_start()] - 0.02
    assert upper == pytest.approx(-0.02)
    # No jump at start: q_d starts at the measured posture.
    np.testing.assert_allclose(q_d[:, 0], q_start, atol=1e-3)
    # q_d ramps at K_a r = 0.5 rad/s until the limit (initial elbow angle -0.3).
    i = np.searchsorted(t, 0.3)
    assert q_d[k, i] == pytest.approx(q_start[k] + 0.5 * t[i], abs=2e-3)
    # The elbow moves in the direction of the effort, monotonically up to small ripple.
    assert np.all(np.diff(q[k]) > -1e-3)
    assert q[k, i] > q_start[k] + 0.05
    # ... and stops at the shrunk limit, never beyond.
    assert np.max(q_d[k]) <= upper + 1e-12
    assert q_d[k, -1] == pytest.approx(upper, abs=1e-12)
    assert q[k, -1] == pytest.approx(upper, abs=5e-3)
    assert np.max(q[k]) < upper + 0.01
    assert np.max(np.abs(np.diff(q[k, -20:]))) < 1e-3  # at rest
    # Other joints: no residual, so (in desired mode) their references do not move, not
    # even those starting on a model limit inside the margin (the hands at 0).
    others = np.arange(n) != k
    np.testing.assert_allclose(q_d[others, -1], q_d[others, 0], atol=1e-12)
    np.testing.assert_allclose(q[others, -1], q_start[others], atol=1e-3)


def test_closed_loop_measured_mode_moves_with_effort_and_stops_at_limit():
    """Eq. 14 as in the paper (q_d = q + K_a r T): the extra PD torque K_p K_a T r
    (200 * 2 * 1e-3 * 5 = 2 N m) drives R_ELBOW_P along the effort until the clip at the
    shrunk limit holds it there."""
    plant, k, t, q, q_d, q_start = _simulate_push_on_joint("R_ELBOW_P", 5.0, {"arms": 2.0}, "measured", 2.0)
    joint = joints_in_velocity_order(plant)[k]
    upper = plant.GetPositionUpperLimits()[joint.position_start()] - 0.02
    np.testing.assert_allclose(q_d[:, 0], q_start, atol=1e-2)
    assert np.all(np.diff(q[k]) > -1e-3)
    i = np.searchsorted(t, 0.2)
    assert q[k, i] > q_start[k] + 0.02
    assert np.max(q_d[k]) <= upper + 1e-12
    assert q[k, -1] == pytest.approx(upper, abs=5e-3)
    assert np.max(np.abs(np.diff(q[k, -20:]))) < 1e-3  # at rest


# -- validation ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(gains=[0.1, 0.2]), "gains must be a scalar or have shape"),
        (dict(gains=[0.1, -0.2, 0.3]), r"gains must be non-negative; negative at joint indices \[1\]"),
        (dict(gains=np.nan), "gains has non-finite"),
        (dict(gains=0.1, dead_band=-1.0), "dead_band must be non-negative"),
        (dict(gains=0.1, max_rate=[1.0, -1.0, 1.0]), "max_rate must be non-negative"),
        (dict(gains=0.1, max_rate=[1.0, 1.0]), "max_rate must be a scalar or have shape"),
        (dict(gains=0.1, period=0.0), "period must be a positive"),
        (dict(gains=0.1, period=-1e-3), "period must be a positive"),
        (dict(gains=0.1, limit_margin=-0.1), "limit_margin must be finite and non-negative"),
        (
            dict(gains=0.1, position_limits=([0.0, 0.5, 0.0], [1.0, 0.4, 1.0])),
            r"position_limits lower > upper at joint indices \[1\] \(j1\)",
        ),
        (dict(gains=0.1, position_limits=([0.0, 0.0], [1.0, 1.0])), "position_limits lower must be"),
        (dict(gains=0.1, position_limits="urdf"), "position_limits must be 'model'"),
        (dict(gains=0.1, position_limits=(0.0,)), "position_limits must be"),
        (dict(gains=0.1, initial_position=[0.0, 0.0]), "initial_position must be a scalar or have shape"),
        (dict(gains=0.1, initial_position=[0.0, np.nan, 0.0]), "initial_position has non-finite"),
        (dict(gains=0.1, integrate_from="previous"), "integrate_from must be one of"),
    ],
)
def test_bad_parameters_raise(chain, kwargs, match):
    with pytest.raises(ValueError, match=match):
        JointAdmittanceController(chain, **kwargs)


def test_bad_plants_raise():
    with pytest.raises(ValueError, match="finalized"):
        JointAdmittanceController(MultibodyPlant(0.0), 0.1)
    fixed = MultibodyPlant(0.0)
    link = fixed.AddRigidBody("link", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1))
    fixed.AddJoint(RevoluteJoint("j", fixed.world_frame(), link.body_frame(), [0, 0, 1]))
    fixed.Finalize()
    with pytest.raises(ValueError, match="JointAdmittanceController: .*floating"):
        JointAdmittanceController(fixed, 0.1)
    with pytest.raises(ValueError, match="must be a MultibodyPlant"):
        JointAdmittanceController("plant", 0.1)


def test_nan_inputs_raise(chain):
    dut = JointAdmittanceController(chain, 0.1)
    ctx = _context(dut, [0.0, np.nan, 0.0], Q0)
    with pytest.raises(ValueError, match=r"input 'residual' has NaN or inf at indices \[1\]"):
        _step(dut, ctx)
    ctx = _context(dut, R, Q0)  # initialised, then a bad measurement arrives
    dut.GetInputPort("measured_position").FixValue(ctx, np.array([np.inf, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r"input 'measured_position' has NaN or inf at indices \[0\]"):
        _step(dut, ctx)
    # Also at initialisation (Simulator.Initialize) from a NaN measured position.
    builder = DiagramBuilder()
    sys = builder.AddSystem(JointAdmittanceController(chain, 0.1))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(3))).get_output_port(), sys.GetInputPort("residual")
    )
    builder.Connect(
        builder.AddSystem(ConstantVectorSource([np.nan, 0.0, 0.0])).get_output_port(),
        sys.GetInputPort("measured_position"),
    )
    with pytest.raises(ValueError, match="measured_position"):
        Simulator(builder.Build()).Initialize()


def test_gains_by_group_accepts_single_joint_names():
    from pydrake.multibody.plant import MultibodyPlant

    from models import add_humanoid
    from systems.residuals.admittance import admittance_gains_by_group
    from systems.simulation.pd_gravity import joints_in_velocity_order

    plant = MultibodyPlant(0.0)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    gains = admittance_gains_by_group(plant, handles, {"legs": 0.2, "R_ANKLE_P": 1.0})
    names = [j.name() for j in joints_in_velocity_order(plant)]
    assert gains[names.index("R_ANKLE_P")] == 1.0
    assert gains[names.index("L_ANKLE_P")] == 0.2
    assert gains[names.index("CHEST_P")] == 0.0


# -- closed chain (support_frames) ---------------------------------------------------------


def _relative_sole_pose(plant, context, handles, q):
    """X_RL: the left sole in the right sole's frame (independent of the base)."""
    plant.SetPositions(context, q)
    right = handles.sole_frames["right"]
    return handles.sole_frames["left"].CalcPose(context, right)


def test_closed_chain_projection_keeps_both_soles_still(hrp4):
    """Independent of the Jacobians the projection uses: moving the joints along the
    projected rate for a short time leaves the left sole's pose relative to the right sole
    unchanged to first order (forward kinematics), while the unprojected rate moves it; the
    squeeze part C^T lambda of a residual gives no motion; joints outside the legs keep
    their rate K_a r'."""
    plant, handles = hrp4
    joints = joints_in_velocity_order(plant)
    n = len(joints)
    gains = admittance_gains_by_group(plant, handles, {"legs": 0.19, "torso": 0.1, "arms": 0.3, "R_ANKLE_P": 1.0})
    soles = (handles.sole_frames["left"], handles.sole_frames["right"])
    dut = JointAdmittanceController(plant, gains, support_frames=soles, integrate_from="desired")
    free = JointAdmittanceController(plant, gains, integrate_from="desired")
    assert dut.support_frames == soles and free.support_frames is None
    rng = np.random.default_rng(3)
    context = plant.CreateDefaultContext()
    q0 = plant.GetPositions(context).copy()
    q_index = np.array([j.position_start() for j in joints])
    knee = [k for k, j in enumerate(joints) if "KNEE" in j.name()]
    q_joints = q0[q_index].copy()
    q_joints[knee] = 0.6  # a bent-knee stance
    residual = rng.normal(0.0, 1.0, n)
    projected = dut.CalcDesiredRate(residual, q_joints)
    unprojected = free.CalcDesiredRate(residual)

    def sole_drift(rate, eps=1e-6):
        q = q0.copy()
        q[q_index] = q_joints
        before = _relative_sole_pose(plant, context, handles, q)
        q[q_index] = q_joints + eps * rate
        after = _relative_sole_pose(plant, context, handles, q)
        d = before.InvertAndCompose(after)
        return (np.linalg.norm(d.translation()) + np.linalg.norm(d.rotation().ToAngleAxis().angle())) / eps

    assert sole_drift(unprojected) > 1e-2  # a random residual squeezes the legs
    assert sole_drift(projected) < 1e-4 * sole_drift(unprojected)
    C = dut.ClosedChainMatrix(q_joints)
    legs = {int(plant.GetJointByName(name).index()) for name in handles.joint_groups["legs"]}
    others = np.array([int(j.index()) not in legs for j in joints])
    np.testing.assert_array_equal(C[:, others], 0.0)
    np.testing.assert_allclose(projected[others], unprojected[others], rtol=0, atol=1e-12)
    squeeze = C.T @ rng.normal(0.0, 1.0, 6)
    np.testing.assert_allclose(dut.CalcDesiredRate(squeeze, q_joints), 0.0, atol=1e-9)
    with pytest.raises(ValueError, match="needs the joint positions"):
        dut.CalcDesiredRate(residual)
    with pytest.raises(ValueError, match="support_frames must be two frames"):
        JointAdmittanceController(plant, gains, support_frames=soles[:1])
    with pytest.raises(ValueError, match="ClosedChainMatrix needs support_frames"):
        free.ClosedChainMatrix(q_joints)


def _com_in_right_sole(plant, context, handles, q):
    """p_RG: the robot's centre of mass in the right sole's frame (independent of the base)."""
    plant.SetPositions(context, q)
    p_WG = plant.CalcCenterOfMassPositionInWorld(context, [handles.model_instance])
    return handles.sole_frames["right"].CalcPoseInWorld(context).inverse().multiply(p_WG)


def test_hold_center_of_mass_keeps_it_over_the_feet_in_the_estimators_model(hrp4):
    """Forward kinematics, independent of the Jacobians the projection uses: with
    ``hold_center_of_mass`` the projected rate keeps the CoM still in the right sole's x-y
    plane to first order (the model given as ``spatial_inertias``, here with a 3 kg heavier
    chest), and both soles still; the closed-chain projection alone moves the CoM; with the
    plant's own inertias the held CoM is the plant's, not the heavier model's."""
    plant, handles = hrp4
    joints = joints_in_velocity_order(plant)
    n = len(joints)
    gains = admittance_gains_by_group(plant, handles, {"legs": 0.19, "torso": 0.1, "arms": 0.3, "R_ANKLE_P": 1.0})
    soles = (handles.sole_frames["left"], handles.sole_frames["right"])
    chest = plant.GetBodyByName("CHEST_P_LINK", handles.model_instance)
    context = plant.CreateDefaultContext()
    M = chest.CalcSpatialInertiaInBodyFrame(context)
    heavier = SpatialInertia(M.get_mass() + 3.0, M.get_com(), M.get_unit_inertia())
    model = {int(chest.index()): heavier}
    held = JointAdmittanceController(
        plant, gains, support_frames=soles, hold_center_of_mass=True, spatial_inertias=model, integrate_from="desired"
    )
    held_plant_model = JointAdmittanceController(
        plant, gains, support_frames=soles, hold_center_of_mass=True, integrate_from="desired"
    )
    chain_only = JointAdmittanceController(plant, gains, support_frames=soles, integrate_from="desired")
    assert held.holds_center_of_mass and not chain_only.holds_center_of_mass
    model_context = plant.CreateDefaultContext()
    chest.SetSpatialInertiaInBodyFrame(model_context, heavier)

    rng = np.random.default_rng(5)
    q0 = plant.GetPositions(context).copy()
    q_index = np.array([j.position_start() for j in joints])
    q_joints = q0[q_index].copy()
    q_joints[[k for k, j in enumerate(joints) if "KNEE" in j.name()]] = 0.4
    residual = rng.normal(0.0, 1.0, n)

    def drifts(rate, ctx, eps=1e-6):
        q = q0.copy()
        q[q_index] = q_joints
        com_before = _com_in_right_sole(plant, ctx, handles, q)
        sole_before = _relative_sole_pose(plant, ctx, handles, q)
        q[q_index] = q_joints + eps * rate
        com = np.linalg.norm((_com_in_right_sole(plant, ctx, handles, q) - com_before)[:2]) / eps
        d = sole_before.InvertAndCompose(_relative_sole_pose(plant, ctx, handles, q))
        sole = (np.linalg.norm(d.translation()) + d.rotation().ToAngleAxis().angle()) / eps
        return com, sole

    com_free, _ = drifts(chain_only.CalcDesiredRate(residual, q_joints), model_context)
    com_held, sole_held = drifts(held.CalcDesiredRate(residual, q_joints), model_context)
    com_plant_held, _ = drifts(held_plant_model.CalcDesiredRate(residual, q_joints), model_context)
    com_plant_held_in_plant, _ = drifts(held_plant_model.CalcDesiredRate(residual, q_joints), context)
    assert com_free > 1e-3  # m/s per unit rate: the closed chain alone lets the CoM move
    assert com_held < 1e-4 * com_free
    assert sole_held < 1e-6
    assert com_plant_held_in_plant < 1e-4 * com_free
    assert com_plant_held > 1e2 * com_held  # a 3 kg different chest: another CoM
    assert held.ClosedChainMatrix(q_joints).shape == (8, n)
    with pytest.raises(ValueError, match="hold_center_of_mass needs support_frames"):
        JointAdmittanceController(plant, gains, hold_center_of_mass=True)
    with pytest.raises(ValueError, match="spatial_inertias are only used with support_frames"):
        JointAdmittanceController(plant, gains, spatial_inertias=model)
    with pytest.raises(ValueError, match="body indices of the plant to SpatialInertia"):
        JointAdmittanceController(plant, gains, support_frames=soles, spatial_inertias={10_000: heavier})


def test_pinocchio_kinematics_give_drakes_closed_chain_matrix(hrp4):
    """The closed-chain matrix from Pinocchio's kinematics (the default) equals Drake's
    (``kinematics="drake"``) at bent, random postures, with the plant's inertias and with a
    heavier chest model; a plant whose floating tree holds another model instance's body
    falls back to Drake's (its centre of mass is the support frames' instance only)."""
    plant, handles = hrp4
    joints = joints_in_velocity_order(plant)
    n = len(joints)
    soles = (handles.sole_frames["left"], handles.sole_frames["right"])
    chest = plant.GetBodyByName("CHEST_P_LINK", handles.model_instance)
    M = chest.default_spatial_inertia()
    heavier = {int(chest.index()): SpatialInertia(M.get_mass() + 3.0, M.get_com(), M.get_unit_inertia())}
    rng = np.random.default_rng(11)
    q_index = np.array([j.position_start() for j in joints])
    q0 = plant.GetPositions(plant.CreateDefaultContext())[q_index]
    for inertias in (None, heavier):
        kwargs = dict(support_frames=soles, hold_center_of_mass=True, spatial_inertias=inertias)
        fast = JointAdmittanceController(plant, 1.0, **kwargs)
        drake = JointAdmittanceController(plant, 1.0, kinematics="drake", **kwargs)
        assert (fast.kinematics, drake.kinematics) == ("pinocchio", "drake")
        for _ in range(5):
            q = q0 + rng.uniform(-0.3, 0.3, n)
            C_drake = drake.ClosedChainMatrix(q)
            np.testing.assert_allclose(fast.ClosedChainMatrix(q), C_drake, rtol=0, atol=1e-12 * np.abs(C_drake).max())
            residual = rng.normal(0.0, 5.0, n)
            np.testing.assert_allclose(
                fast.CalcDesiredRate(residual, q), drake.CalcDesiredRate(residual, q), atol=1e-12
            )
    assert JointAdmittanceController(plant, 1.0).kinematics is None
    with pytest.raises(ValueError, match="kinematics must be one of"):
        JointAdmittanceController(plant, 1.0, kinematics="pin")

    # A gripper of another model instance welded to the right hand: Drake's CoM leaves it out.
    two = MultibodyPlant(T)
    robot = add_humanoid(two, "hrp4_like")
    tool = two.AddModelInstance("tool")
    gripper = two.AddRigidBody("gripper", tool, SpatialInertia.SolidBoxWithMass(2.0, 0.1, 0.1, 0.1))
    hand = two.GetBodyByName("R_WRIST_Y_LINK", robot.model_instance)
    two.WeldFrames(hand.body_frame(), gripper.body_frame())
    two.Finalize()
    held = JointAdmittanceController(
        two, 1.0, support_frames=(robot.sole_frames["left"], robot.sole_frames["right"]), hold_center_of_mass=True
    )
    assert held.kinematics == "drake"


def test_symmetric_least_squares_is_lstsq():
    """The projection's small solve: a Cholesky solve where the matrix is safely invertible,
    else NumPy's least squares (a rank-deficient matrix, as two identical support rows give)."""
    from systems.residuals.admittance import _least_squares_symmetric

    rng = np.random.default_rng(2)
    B = rng.normal(size=(8, 30))
    A, b = B @ B.T, rng.normal(size=8)
    np.testing.assert_allclose(_least_squares_symmetric(A, b), np.linalg.solve(A, b), rtol=1e-12)
    B[7] = B[6]  # rank 7
    A = B @ B.T
    np.testing.assert_allclose(
        _least_squares_symmetric(A, b), np.linalg.lstsq(A, b, rcond=1e-12)[0], rtol=1e-9, atol=1e-12
    )
