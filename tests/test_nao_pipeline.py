"""The force observer's measurement pipeline (systems.observer.fsr_sensing) and the Nao standing
diagram (diagrams.observer.nao_force_observer), checked against physics: weight, static equilibrium,
known accelerations, eq. (11); plus the observer core's closed-form Kalman step against
the textbook matrix form and its convergence on exact LIP data with a 3-D force."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.observer.calibration import settle_standing_state
from diagrams.observer.nao_force_observer import build_nao_force_observer_diagram, wide_stance
from diagrams.observer.nao_sensing import OBSERVER_PERIOD
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from models import add_ground, add_humanoid
from systems.observer.force_observer import STANDING, LipForceObserver, transition_matrices
from systems.observer.fsr_sensing import (
    FSR_NAMES,
    FSR_SATURATION,
    CenterOfPressure,
    FsrArray,
    ImuComAcceleration,
    SupportFootCom,
)
from systems.simulation.disturbances import Push
from systems.simulation.ground_truth import VirtualForceTruth

GRAVITY = 9.81


@pytest.fixture(scope="module")
def standing_run():
    """The full diagram, noisy sensors, no push: 2 s from the settled standing state."""
    diagram, handles = build_nao_force_observer_diagram(station=StationConfig(model="nao_like", seed=3))
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.set_initial_state(context, settle_standing_state())
    simulator.AdvanceTo(2.0)
    logs = {name: logger.FindLog(context).data() for name, logger in handles.loggers.items()}
    return handles, logs


def test_total_normal_force_is_the_weight(standing_run):
    handles, logs = standing_run
    plant = handles.station.plant
    weight = plant.CalcTotalMass(plant.CreateDefaultContext()) * GRAVITY
    true_total = logs["true_fsr_forces"][:, 1:].sum(axis=0)  # sample 0 precedes the first contact step
    assert np.abs(true_total - weight).max() < 1e-3 * weight
    fn = logs["normal_force"][0, 1:]  # eq. (12): f_n^o = -sum, -M g at rest
    noise = np.sqrt(8) * 0.1
    assert abs(fn.mean() + weight) < 4 * noise / np.sqrt(len(fn))
    assert 0.5 * noise < fn.std() < 1.5 * noise
    assert np.all(logs["fsr_forces"] >= 0.0) and np.all(logs["fsr_forces"] <= FSR_SATURATION)


def test_cop_lies_under_the_com_and_the_com_is_sensed(standing_run):
    """Static equilibrium on flat ground: the CoP (eq. 13) is the CoM's ground projection
    and the CoM does not accelerate."""
    _, logs = standing_run
    true_com = logs["true_com_position"][:, 1:]
    assert np.abs(logs["zmp"][:, 1:].mean(axis=1) - true_com[:2].mean(axis=1)).max() < 5e-4
    assert np.abs(logs["com_position"][:, 1:] - true_com).max() < 2e-3  # base estimate noise 5e-4 rad
    assert 0.2 < true_com[2].mean() < 0.3  # CoM height above the ground (Nao: ~0.27 m)
    acc = logs["com_acceleration"][:, 1:]
    assert np.abs(acc.mean(axis=1)).max() < 0.01 and acc.std(axis=1).max() < 0.05  # IMU noise 0.02 m/s^2


def test_observer_estimates_no_force_on_a_standing_robot(standing_run):
    _, logs = standing_run
    estimate = logs["virtual_force"][:, 30:]
    assert np.abs(estimate).max() < 0.3 and np.all(logs["valid"][0, 1:] == 1.0)
    assert np.all(logs["truth"] == 0.0)


def _station_with(builder_hook, duration=0.2, posture_state=None):
    """Station (no noise) holding the nominal posture + systems added by ``builder_hook``."""
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model="nao_like", noise=False))
    hold = builder.AddSystem(ConstantVectorSource(station.q_hold))
    builder.Connect(hold.get_output_port(), station.desired_position)
    extra = builder_hook(builder, station)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context, settle_standing_state() if posture_state is None else posture_state)
    simulator.AdvanceTo(duration)
    return station, extra, context


def test_fsr_readings_saturate_and_never_go_negative():
    def hook(builder, station):
        plant, humanoid = station.plant, station.humanoid
        out = {}
        for name, kwargs in {
            "low_range": dict(saturation=5.0, noise_std=0.0),
            "noisy": dict(noise_std=20.0, seed=7),
        }.items():
            fsr = builder.AddSystem(FsrArray(plant, humanoid, **kwargs))
            builder.Connect(plant.get_contact_results_output_port(), fsr.GetInputPort("contact_results"))
            out[name] = (
                fsr,
                LogVectorOutput(fsr.GetOutputPort("fsr_forces"), builder, 0.01),
                LogVectorOutput(fsr.GetOutputPort("true_fsr_forces"), builder, 0.01),
            )
        return out

    _, systems, context = _station_with(hook)
    fsr, log, true_log = systems["low_range"]
    readings, truth = log.FindLog(context).data()[:, 1:], true_log.FindLog(context).data()[:, 1:]
    assert truth.max() > 6.0  # the heel sensors carry more than 5 N ...
    np.testing.assert_array_equal(readings, np.minimum(truth, 5.0))  # ... and read 5 N
    _, log, _ = systems["noisy"]
    readings = log.FindLog(context).data()
    assert readings.min() == 0.0 and readings.max() == FSR_SATURATION
    assert FSR_NAMES[0] == "left_front_left" and len(FSR_NAMES) == 8


_KEEP_ALIVE = []


def _plant_with_nao():
    """A finalized plant with nao_like and ground; returns (plant, handles, the SceneGraph's
    inspector), keeping the builder alive for the inspector."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    handles = add_humanoid(plant, "nao_like", scene_graph=scene_graph)
    add_ground(plant)
    plant.Finalize()
    _KEEP_ALIVE.append(builder)
    return plant, handles, scene_graph.model_inspector()


def test_cop_equals_the_force_weighted_sphere_positions():
    """Eq. (13) against the sphere geometries themselves (SceneGraph poses, not the
    documented positions the system uses): one reading on one FSR puts the CoP there;
    both feet's readings average by force."""
    plant, handles, sg_inspector = _plant_with_nao()
    x = settle_standing_state(wide_stance())
    cop = CenterOfPressure(plant, handles, support_foot="left")
    context = cop.CreateDefaultContext()
    cop.GetInputPort("state").FixValue(context, x)
    plant_context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(plant_context, x)
    ids = list(handles.fsr_geometries["left"]) + list(handles.fsr_geometries["right"])
    centers = []
    for gid in ids:
        body = plant.GetBodyFromFrameId(sg_inspector.GetFrameId(gid))
        X_BG = sg_inspector.GetPoseInFrame(gid)
        centers.append(plant.EvalBodyPoseInWorld(plant_context, body).multiply(X_BG).translation())
    centers = np.array(centers)
    origin = handles.sole_frames["left"].CalcPoseInWorld(plant_context).translation()
    forces = np.zeros(8)
    forces[6] = 12.0  # right foot, rear_left
    cop.GetInputPort("fsr_forces").FixValue(context, forces)
    np.testing.assert_allclose(cop.GetOutputPort("zmp").Eval(context), (centers[6] - origin)[:2], atol=2e-4)
    assert cop.GetOutputPort("normal_force").Eval(context)[0] == -12.0
    forces = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
    cop.GetInputPort("fsr_forces").FixValue(context, forces)
    expected = forces @ (centers[:, :2] - origin[:2]) / forces.sum()
    np.testing.assert_allclose(cop.GetOutputPort("zmp").Eval(context), expected, atol=2e-4)
    cop.GetInputPort("fsr_forces").FixValue(context, np.zeros(8))  # feet off the ground
    np.testing.assert_array_equal(cop.GetOutputPort("zmp").Eval(context), [0.0, 0.0])


def test_imu_acceleration_is_projected_to_world_and_gravity_compensated():
    """A known world acceleration a_W on a tilted robot: the accelerometer reads
    R_SW (a_W - g_W) (Drake's convention); the system returns a_W."""
    plant, handles, _ = _plant_with_nao()
    system = ImuComAcceleration(plant, handles.imu_frame)
    context = system.CreateDefaultContext()
    plant_context = plant.CreateDefaultContext()
    X_WB = RigidTransform(RollPitchYaw(0.1, -0.2, 0.7), [0.1, 0.2, 0.3])
    plant.SetFreeBodyPose(plant_context, handles.base_body, X_WB)
    R_WS = X_WB.rotation().multiply(handles.imu_frame.GetFixedPoseInBodyFrame().rotation()).matrix()
    a_W = np.array([0.3, -0.2, 0.5])
    reading = R_WS.T @ (a_W - np.array([0.0, 0.0, -GRAVITY]))
    system.GetInputPort("state").FixValue(context, plant.GetPositionsAndVelocities(plant_context))
    system.GetInputPort("linear_acceleration").FixValue(context, reading)
    np.testing.assert_allclose(system.GetOutputPort("com_acceleration").Eval(context), a_W, atol=1e-12)


def test_support_foot_com_is_the_com_relative_to_the_sole_in_world_axes():
    plant, handles, _ = _plant_with_nao()
    x = settle_standing_state()
    plant_context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(plant_context, x)
    p_WCm = plant.CalcCenterOfMassPositionInWorld(plant_context)
    for side in ("left", "right"):
        system = SupportFootCom(plant, handles, support_foot=side)
        context = system.CreateDefaultContext()
        system.GetInputPort("state").FixValue(context, x)
        com = system.GetOutputPort("com_position").Eval(context)
        sole = handles.sole_frames[side].CalcPoseInWorld(plant_context).translation()
        np.testing.assert_allclose(com, p_WCm - sole, atol=1e-12)
        assert abs(sole[2]) < 2e-4 and abs(com[1] - (0.05 if side == "right" else -0.05)) < 5e-3


def test_bad_inputs_and_arguments_give_clear_errors():
    plant, handles, _ = _plant_with_nao()
    with pytest.raises(ValueError, match="unknown support foot 'middle'"):
        CenterOfPressure(plant, handles, support_foot="middle")
    with pytest.raises(ValueError, match="unknown support foot"):
        SupportFootCom(plant, handles, support_foot="front")
    other = MultibodyPlant(0.0)
    other_handles = add_humanoid(other, "nao_like")
    other.Finalize()
    with pytest.raises(ValueError, match="not a frame of this plant"):
        ImuComAcceleration(plant, other_handles.imu_frame)
    with pytest.raises(ValueError, match="no 4 FSR geometries"):
        FsrArray(other, other_handles)  # no SceneGraph: no GeometryIds
    with pytest.raises(ValueError, match="noise_std"):
        FsrArray(plant, handles, noise_std=[0.1, 0.2])
    with pytest.raises(ValueError, match="saturation"):
        FsrArray(plant, handles, saturation=0.0)
    unfinalized = MultibodyPlant(0.0)
    with pytest.raises(ValueError, match="finalized"):
        ImuComAcceleration(unfinalized, handles.imu_frame)

    cop = CenterOfPressure(plant, handles)
    context = cop.CreateDefaultContext()
    cop.GetInputPort("state").FixValue(context, settle_standing_state())
    cop.GetInputPort("fsr_forces").FixValue(context, [1.0, 2.0, np.nan, 4.0, 5.0, 6.0, 7.0, 8.0])
    with pytest.raises(ValueError, match="CenterOfPressure: input 'fsr_forces' has NaN or inf at indices \\[2\\]"):
        cop.GetOutputPort("zmp").Eval(context)
    acc = ImuComAcceleration(plant, handles.imu_frame)
    context = acc.CreateDefaultContext()
    x = settle_standing_state().copy()
    x[5] = np.inf
    acc.GetInputPort("state").FixValue(context, x)
    acc.GetInputPort("linear_acceleration").FixValue(context, [0.0, 0.0, 9.81])
    with pytest.raises(ValueError, match="ImuComAcceleration: input 'state' has NaN or inf at indices \\[5\\]"):
        acc.GetOutputPort("com_acceleration").Eval(context)


def test_virtual_force_truth_follows_eq_11():
    """A horizontal force at height h through the CoM's vertical moves the ZMP as F h / z_c
    at the CoM would; a vertical load beside the CoM adds -d F_z / z_c (eq. 10-11)."""
    p_WCm = np.array([0.01, -0.02, 0.25])
    h, F = 0.35, np.array([2.0, -1.0, 0.0])
    p = np.array([p_WCm[0], p_WCm[1], h])
    wrench = np.concatenate((np.cross(p, F), F))
    np.testing.assert_allclose(VirtualForceTruth.virtual_force(wrench, p_WCm, 0.0), F * h / 0.25, rtol=1e-12)
    d = np.array([0.06, -0.12, 0.0])
    F = np.array([0.0, 0.0, -11.0])
    wrench = np.concatenate((np.cross(p_WCm + d, F), F))
    np.testing.assert_allclose(
        VirtualForceTruth.virtual_force(wrench, p_WCm, 0.0),
        [-d[0] * F[2] / 0.25, -d[1] * F[2] / 0.25, F[2]],
        rtol=1e-12,
    )


def test_statics_of_a_pushed_robot_match_the_virtual_force():
    """Ground truth against physics: with a steady push the true FSR forces' total
    (eq. 12) and CoP (eq. 13) satisfy eq. (10) with the virtual force of eq. (11) (on
    average over a second: the position-controlled robot keeps swaying by ~0.1 mm)."""
    from systems.simulation.disturbances import SmoothPiecewise

    push = Push("torso", (0.05, 0.0, -0.05), (0.6, 0.0, 0.8), SmoothPiecewise((0.0, 1.0), (0.0, 3.0)))
    diagram, handles = build_nao_force_observer_diagram([push], station=StationConfig(model="nao_like", noise=False))
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.set_initial_state(context, settle_standing_state())
    simulator.AdvanceTo(3.0)
    plant = handles.station.plant
    mass = plant.CalcTotalMass(plant.CreateDefaultContext())
    t = handles.loggers["truth"].FindLog(context).sample_times()
    window = t >= 2.0
    log = {name: logger.FindLog(context).data()[:, window] for name, logger in handles.loggers.items()}
    F_hat, com, forces = log["truth"], log["true_com_position"], log["true_fsr_forces"]
    fn = -mass * GRAVITY + F_hat[2]
    np.testing.assert_allclose(-forces.sum(axis=0), fn, atol=0.01)
    cop_expected = com[:2] - com[2] / fn * F_hat[:2]  # eq. (10) at rest, with F^ (eq. 11)
    cop = handles.center_of_pressure
    positions = cop.fsr_positions(cop.GetMyContextFromRoot(context))[:, :2]
    cop_measured = (positions.T @ forces) / forces.sum(axis=0)
    np.testing.assert_allclose((cop_measured - cop_expected).mean(axis=1), 0.0, atol=2e-4)
    assert np.abs(cop_measured - cop_expected).max() < 1e-3
    assert abs(F_hat[0].mean() - 1.8) > 0.1  # the torso point is off the CoM: eq. (11) matters
    shift = np.abs(cop_expected[0] - com[0]).mean()
    assert shift > 5e-3  # the push moves the CoP by several mm: the check above is not trivial


# ---------------------------------------------------------------------------------------
# The observer core.
# ---------------------------------------------------------------------------------------


def _textbook_observer(c, a, p, fn, parameters=STANDING):
    """Eqs. (14)-(21) in matrix form, straight from the paper (slow, for reference)."""
    M, g = parameters.mass, parameters.gravity
    A, B = transition_matrices(parameters.period)
    Q = B @ np.diag([parameters.jerk_variance, parameters.force_rate_variance]) @ B.T
    Rz, Rxy = np.array(parameters.R_z), np.array(parameters.R_xy)
    X = [np.array([c[0, i], 0.0, a[0, i], 0.0, 0.0]) for i in range(3)]
    P = [parameters.initial_covariance * np.eye(5) for _ in range(3)]

    def step(i, C, R, y):
        x_pred, P_pred = A @ X[i], A @ P[i] @ A.T + Q
        K = P_pred @ C.T @ np.linalg.inv(C @ P_pred @ C.T + R)
        X[i] = x_pred + K @ (y - C @ x_pred)
        P[i] = P_pred - K @ C @ P_pred

    out = []
    for k in range(len(fn)):
        step(
            2,
            np.array([[1, 0, 0, 0, 0], [0, 0, 1, 0, 0], [0, 0, -M, 1, 0]], float),
            Rz,
            np.array([c[k, 2], a[k, 2], fn[k] + M * g]),
        )
        z, zdd, Fz = X[2][0], X[2][2], X[2][3]
        fn_hat = -M * g - M * zdd + Fz
        C = np.array([[1, 0, 0, 0, 0], [0, 0, 1, 0, 0], [1, 0, M * z / fn_hat, -z / fn_hat, 0]], float)
        for i in (0, 1):
            step(i, C, Rxy, np.array([c[k, i], a[k, i], p[k, i]]))
        out.append([X[0][3], X[1][3], X[2][3]])
    return np.array(out)


def test_closed_form_kalman_step_equals_the_textbook_matrix_form():
    rng = np.random.default_rng(11)
    n = 400
    c = np.column_stack((0.01 * rng.normal(size=n), 0.01 * rng.normal(size=n), 0.3 + 1e-3 * rng.normal(size=n)))
    a = 0.2 * rng.normal(size=(n, 3))
    p = 0.02 * rng.normal(size=(n, 2))
    fn = -50.0 + 2.0 * rng.normal(size=n)
    observer = LipForceObserver()
    fast = np.array([observer.update(c[k], a[k], p[k], fn[k])[0] for k in range(n)])
    reference = _textbook_observer(c, a, p, fn)
    assert np.abs(fast - reference).max() < 1e-9 * max(1.0, np.abs(reference).max())


def test_observer_converges_to_a_constant_3d_force_on_an_exact_lip():
    """Exact LIP at rest (eqs. 5 and 7 with zero CoM acceleration): f_n = -M g + F_z and
    p = c_xy - z_c F_xy / f_n; all three components are recovered."""
    M, g, z = STANDING.mass, STANDING.gravity, 0.28
    F = np.array([1.5, -4.0, -8.0])
    fn = -M * g + F[2]
    com = np.array([0.01, -0.02, z])
    zmp = com[:2] - z / fn * F[:2]
    observer = LipForceObserver()
    for _ in range(int(15.0 / STANDING.period)):
        estimate, valid = observer.update(com, np.zeros(3), zmp, fn)
    assert valid
    np.testing.assert_allclose(estimate, F, atol=0.01)


def test_observer_period_is_the_papers():
    diagram, handles = build_nao_force_observer_diagram(station=StationConfig(model="nao_like", noise=False))
    assert handles.parameters.period == OBSERVER_PERIOD and abs(OBSERVER_PERIOD - 0.0167) < 1e-4
    assert abs(handles.parameters.mass - 5.19) < 1e-9
