"""Realistic imperfections (systems.simulation.imperfections), each on its own, against
physics: the friction law and its dissipation, encoder quantisation, the IMU bias random
walk's sqrt(t) growth, exact torque-sensor errors, a physically valid mismatched model; the
default (ideal) station is bit-identical to one built without imperfections."""

import math

import numpy as np
import pytest
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, RevoluteJoint, SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from systems.simulation.imperfections import (
    EncoderImperfections,
    FrictionImperfections,
    Imperfections,
    ImuImperfections,
    JointFriction,
    ModelMismatch,
    TorqueSensorImperfections,
    friction_torque,
    perturbed_spatial_inertias,
    rated_joint_torques,
    torque_measurement_errors,
)
from systems.simulation.noise import NoisyVector, RandomWalkBias
from systems.simulation.sensors import JointEncoders, MotorTorqueSensor


def _two_body_plant(time_step: float = 1e-3) -> MultibodyPlant:
    """A free-floating base with one link on a revolute joint, in zero gravity."""
    plant = MultibodyPlant(time_step)
    base = plant.AddRigidBody("base", SpatialInertia(2.0, np.zeros(3), UnitInertia.SolidBox(0.2, 0.2, 0.2)))
    link = plant.AddRigidBody("link", SpatialInertia.SolidBoxWithMass(0.5, 0.2, 0.03, 0.03))
    plant.AddJoint(
        RevoluteJoint("hinge", base.body_frame(), link.body_frame(), [0.0, 0.0, 1.0], damping=0.0)
    ).set_default_angle(0.0)
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    plant.Finalize()
    return plant


def _station(model: str = "hrp4_like", noise: bool = True, **kwargs):
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model=model, noise=noise, **kwargs))
    source = builder.AddSystem(ConstantVectorSource(station.q_hold))
    builder.Connect(source.get_output_port(), station.desired_position)
    return builder, station


# ---------------------------------------------------------------------------------------
# Friction.
# ---------------------------------------------------------------------------------------


def test_friction_follows_the_coulomb_viscous_law():
    plant = _two_body_plant()
    friction = JointFriction(plant, coulomb=0.3, viscous=0.05, smoothing_velocity=0.1)
    context = friction.CreateDefaultContext()
    nq, nv = plant.num_positions(), plant.num_velocities()
    for v_joint in (-2.0, -0.05, 0.0, 0.02, 1.5):
        x = np.zeros(nq + nv)
        x[0] = 1.0
        x[nq:] = [0.1, -0.2, 0.3, 0.4, 0.5, 0.6, v_joint]
        friction.get_input_port().FixValue(context, x)
        tau = friction.get_output_port().Eval(context)
        np.testing.assert_array_equal(tau[:6], 0.0)
        assert tau[6] == pytest.approx(-(0.3 * math.tanh(v_joint / 0.1) + 0.05 * v_joint), abs=1e-15)
    # Far above v_s the smoothed law is Coulomb + viscous.
    assert friction_torque(np.array([5.0]), 0.3, 0.05, 0.1)[0] == pytest.approx(-(0.3 + 0.25), rel=1e-12)


def _swing_energy(with_friction: bool) -> np.ndarray:
    plant = _two_body_plant()
    builder = DiagramBuilder()
    builder.AddSystem(plant)
    if with_friction:
        friction = builder.AddSystem(JointFriction(plant, coulomb=0.02, viscous=0.01, smoothing_velocity=0.1))
        builder.Connect(plant.get_state_output_port(), friction.get_input_port())
        builder.Connect(friction.get_output_port(), plant.get_applied_generalized_force_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    v = np.zeros(plant.num_velocities())
    v[6] = 3.0  # the link swings relative to the base
    plant.SetVelocities(plant_context, v)
    energies = []
    for k in range(1, 101):
        simulator.AdvanceTo(0.01 * k)
        energies.append(plant.CalcKineticEnergy(plant_context))
    return np.array(energies)


def test_friction_makes_a_free_swinging_joint_lose_energy():
    """Zero gravity, no contact: without friction the kinetic energy is conserved; with it
    the energy never increases and most of it is gone after 1 s (what remains is the rigid
    motion that conserves the momentum once the joint has stopped)."""
    ideal = _swing_energy(False)
    lossy = _swing_energy(True)
    assert np.ptp(ideal) < 1e-3 * ideal[0]
    assert np.all(np.diff(lossy) <= 1e-12 * lossy[0]) and lossy[10] < lossy[0]
    assert lossy[-1] < 0.5 * ideal[-1]


def test_station_friction_uses_the_rated_torques():
    imperfections = Imperfections(friction=FrictionImperfections(coulomb_percent=3.0, viscous_percent=2.0))
    builder, station = _station(noise=False, imperfections=imperfections)
    plant = station.plant
    rated = rated_joint_torques(plant)
    effort = {
        a.joint().name(): a.effort_limit() for a in map(plant.get_joint_actuator, plant.GetJointActuatorIndices())
    }
    np.testing.assert_array_equal(rated, [effort[name] for name in station.joint_names])
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    x = station.initial_state.copy()
    nq = plant.num_positions()
    v_joints = np.linspace(-1.0, 1.0, station.topology.num_joints)
    x[nq + 6 :] = v_joints
    station.set_initial_state(context, x)
    tau = station.friction.get_output_port().Eval(station.friction.GetMyContextFromRoot(context))
    expected = -(0.03 * rated * np.tanh(v_joints / 0.1) + 0.02 * rated * v_joints)
    np.testing.assert_allclose(tau[6:], expected, rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(tau[:6], 0.0)


# ---------------------------------------------------------------------------------------
# Encoders.
# ---------------------------------------------------------------------------------------


def test_quantised_positions_are_whole_steps_within_half_a_step():
    _, station = _station(noise=False, imperfections=Imperfections(encoders=EncoderImperfections(bits=14)))
    plant = station.plant
    step = 2.0 * math.pi / 2**14
    assert station.sensors.encoders.position_step == step
    encoders = JointEncoders(plant, position_noise_std=0.0, velocity_noise_std=0.0, position_step=step)
    context = encoders.CreateDefaultContext()
    rng = np.random.default_rng(0)
    q_index = [j.position_start() for j in station.topology.joints]
    for _ in range(20):
        x = station.initial_state.copy()
        x[q_index] += rng.uniform(-1.0, 1.0, len(q_index))
        encoders.GetInputPort("state").FixValue(context, x)
        q = encoders.GetOutputPort("position").Eval(context)
        counts = q / step
        np.testing.assert_allclose(counts, np.round(counts), rtol=0.0, atol=1e-9)
        assert np.all(np.abs(q - x[q_index]) <= 0.5 * step + 1e-15)
        v = encoders.GetOutputPort("velocity").Eval(context)
        np.testing.assert_array_equal(v, x[plant.num_positions() + 6 :])  # velocities as before


# ---------------------------------------------------------------------------------------
# IMU bias random walk.
# ---------------------------------------------------------------------------------------


def test_bias_random_walk_grows_as_sigma_sqrt_t():
    """400 independent walks, sigma = 0.01 / sqrt(s): the bias std is sigma sqrt(t) at
    t = 0.25 s and 1 s (sample std of 400 normals: ~3.5 % relative error; bound 15 %), the
    walks have zero mean, and the output is input + bias."""
    sigma, size = 0.01, 400
    walk = RandomWalkBias(size, sigma, period=1e-3, seed=7)
    simulator = Simulator(walk)
    context = simulator.get_mutable_context()
    clean = np.linspace(-1.0, 1.0, size)
    walk.get_input_port().FixValue(context, clean)
    for t in (0.25, 1.0):
        simulator.AdvanceTo(t)
        bias = walk.get_bias(context)
        assert np.std(bias) == pytest.approx(sigma * math.sqrt(t), rel=0.15)
        assert abs(np.mean(bias)) < 4.0 * sigma * math.sqrt(t / size)
        np.testing.assert_array_equal(walk.get_output_port().Eval(context), clean + bias)
    # The same seed reproduces the walk.
    again = RandomWalkBias(size, sigma, period=1e-3, seed=7)
    simulator2 = Simulator(again)
    again.get_input_port().FixValue(simulator2.get_mutable_context(), clean)
    simulator2.AdvanceTo(1.0)
    np.testing.assert_array_equal(again.get_bias(simulator2.get_context()), walk.get_bias(context))


def test_bias_with_white_noise_equals_a_noisy_vector_then_the_bias_bit_for_bit():
    """RandomWalkBias with white_noise_std (the IMU's one system per sensor) gives the
    numbers of NoisyVector followed by RandomWalkBias, at every step."""
    size, sigma, std = 3, [0.02, 0.0, 0.05], [1e-3, 2e-3, 0.0]
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(np.array([0.3, -1.2, 9.81])))
    noisy = builder.AddSystem(NoisyVector(size, std, 1e-3, 11))
    chained = builder.AddSystem(RandomWalkBias(size, sigma, 1e-3, 29))
    fused = builder.AddSystem(RandomWalkBias(size, sigma, 1e-3, 29, white_noise_std=std, white_noise_seed=11))
    builder.Connect(source.get_output_port(), noisy.get_input_port())
    builder.Connect(noisy.get_output_port(), chained.get_input_port())
    builder.Connect(source.get_output_port(), fused.get_input_port())
    logs = [LogVectorOutput(system.get_output_port(), builder, 1e-3) for system in (chained, fused)]
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    a, b = (log.FindLog(context).data() for log in logs)
    assert a.shape == b.shape and a.shape[1] > 250
    np.testing.assert_array_equal(a, b)
    assert np.all(np.abs(np.diff(a, axis=1)).max(axis=1) > 0.0)  # each entry noisy, biased or both
    assert fused.noise.seed == 11 and fused.noise.std.tolist() == std
    assert chained.noise.is_zero and RandomWalkBias(size, sigma, white_noise_std=0.0, white_noise_seed=1).noise.is_zero
    with pytest.raises(ValueError, match="go together"):
        RandomWalkBias(size, sigma, white_noise_std=std)
    with pytest.raises(ValueError, match="go together"):
        RandomWalkBias(size, sigma, white_noise_seed=3)
    with pytest.raises(ValueError, match="white_noise_std"):
        RandomWalkBias(size, sigma, white_noise_std=[-1.0, 0.0, 0.0], white_noise_seed=3)


def test_station_imu_gets_the_bias_and_the_datasheet_noise():
    realistic = Imperfections.realistic().imu
    _, station = _station(imperfections=Imperfections(imu=realistic))
    imu = station.sensors.imu
    assert imu.gyro_bias is not None and imu.accel_bias is not None
    assert imu.gyro_bias.increments.std[0] == pytest.approx(realistic.gyro_bias_random_walk * math.sqrt(1e-3))
    assert imu.gyro_noise.noise.std[0] == pytest.approx(0.014 * math.pi / 180.0 / math.sqrt(1e-3))
    assert imu.accel_noise.noise.std[0] == pytest.approx(175e-6 * 9.80665 / math.sqrt(1e-3))
    _, ideal = _station()
    assert ideal.sensors.imu.gyro_bias is None and ideal.sensors.imu.accel_bias is None


def test_random_walk_starts_from_its_initial_bias():
    """b_0 = initial_bias (scalar or per entry), then the walk; a walk of 0 holds it; bad
    initial biases are refused naming the argument."""
    walk = RandomWalkBias(3, 0.0, period=1e-3, seed=1, initial_bias=[0.01, -0.02, 0.03])
    simulator = Simulator(walk)
    context = simulator.get_mutable_context()
    walk.get_input_port().FixValue(context, np.ones(3))
    np.testing.assert_array_equal(walk.get_bias(context), [0.01, -0.02, 0.03])
    simulator.AdvanceTo(0.5)
    np.testing.assert_array_equal(walk.get_output_port().Eval(context), [1.01, 0.98, 1.03])
    moving = RandomWalkBias(3, 0.01, period=1e-3, seed=7, initial_bias=0.5)
    plain = RandomWalkBias(3, 0.01, period=1e-3, seed=7)
    both = [Simulator(system) for system in (moving, plain)]
    for simulator_, system in zip(both, (moving, plain)):
        system.get_input_port().FixValue(simulator_.get_mutable_context(), np.zeros(3))
        simulator_.AdvanceTo(0.2)
    np.testing.assert_allclose(
        moving.get_bias(both[0].get_context()) - plain.get_bias(both[1].get_context()), 0.5, atol=1e-15
    )
    for bad in ([0.0, 1.0], [math.nan, 0.0, 0.0], "a"):
        with pytest.raises(ValueError, match="initial_bias"):
            RandomWalkBias(3, 0.0, initial_bias=bad)


def test_station_gyro_reads_its_constant_turn_on_bias_at_rest():
    """ImuImperfections' gyro_bias_x/y/z (any sign) reach the station's gyro as a constant
    bias from t = 0: a robot standing still reads it (mean over 0.3 s within 5 standard
    errors of the white noise), with or without a bias walk; zero keeps the ideal IMU's
    systems (no bias system added)."""
    bias = np.radians([0.12, -0.08, 0.35])
    imu = ImuImperfections(gyro_bias_x=bias[0], gyro_bias_y=bias[1], gyro_bias_z=bias[2])
    assert not Imperfections(imu=imu).validate().is_ideal
    builder, station = _station(imperfections=Imperfections(imu=imu))
    assert station.sensors.imu.gyro_bias is not None and station.sensors.imu.accel_bias is None
    log = LogVectorOutput(station.sensors.imu.angular_velocity, builder, 1e-3)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.AdvanceTo(0.4)
    gyro = log.FindLog(context).data()[:, 100:]
    standard_error = gyro.std(axis=1) / math.sqrt(gyro.shape[1])
    assert np.all(np.abs(gyro.mean(axis=1) - bias) < 5.0 * standard_error + 2e-4), (gyro.mean(axis=1), bias)
    _, ideal = _station()
    assert ideal.sensors.imu.gyro_bias is None


# ---------------------------------------------------------------------------------------
# Torque sensor.
# ---------------------------------------------------------------------------------------


def test_torque_scale_and_offset_are_applied_exactly():
    imperfections = Imperfections(torque_sensor=TorqueSensorImperfections(5.0, 1.0), seed=3)
    _, station = _station(noise=False, imperfections=imperfections)
    plant = station.plant
    rated = rated_joint_torques(plant)
    scale, offset = torque_measurement_errors(rated, 5.0, 1.0, 3)
    assert np.std(scale - 1.0) == pytest.approx(0.05, rel=0.5) and np.all(np.abs(offset) < 0.05 * rated)
    sensor = station.sensors.torque_sensor
    context = sensor.CreateDefaultContext()
    u = np.random.default_rng(1).uniform(-20.0, 20.0, plant.num_actuated_dofs())
    sensor.GetInputPort("actuation").FixValue(context, u)
    measured = sensor.GetOutputPort("measured_torque").Eval(context)
    truth = plant.MakeActuationMatrix()[6:, :] @ u
    np.testing.assert_array_equal(measured, scale * truth + offset)
    # Standalone, scalar values.
    plain = MotorTorqueSensor(plant, noise_std=0.0, scale=1.1, offset=-0.5)
    context = plain.CreateDefaultContext()
    plain.GetInputPort("actuation").FixValue(context, u)
    np.testing.assert_array_equal(plain.GetOutputPort("measured_torque").Eval(context), 1.1 * truth - 0.5)


# ---------------------------------------------------------------------------------------
# Model mismatch.
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["hrp4_like", "nao_like"])
def test_mismatched_model_is_physically_valid_and_the_plant_stays_nominal(model):
    mismatch = ModelMismatch(mass_percent=5.0, com_percent=10.0, inertia_percent=10.0)
    _, station = _station(model, noise=False, imperfections=Imperfections(model_mismatch=mismatch, seed=2))
    plant = station.plant
    inertias = perturbed_spatial_inertias(plant, mismatch, 2)
    nominal = {i: plant.get_body(BodyIndex(i)).default_spatial_inertia() for i in inertias}
    ratios = np.array([inertias[i].get_mass() / nominal[i].get_mass() for i in inertias])
    np.testing.assert_allclose(np.abs(ratios - 1.0), 0.05, rtol=1e-12)  # each link +-5 %
    assert 0 < np.sum(ratios > 1.0) < len(ratios)
    expected_mass = sum(M.get_mass() for M in inertias.values())
    # The estimators' own plant carries the perturbed inertias as its defaults.
    model = station.estimator.plant
    assert station.dynamics_model.plant is model and model is not plant
    nominal_context = plant.CreateDefaultContext()
    total = plant.CalcTotalMass(nominal_context)
    assert model.CalcTotalMass(model.CreateDefaultContext()) == pytest.approx(expected_mass, rel=1e-12)
    assert abs(expected_mass - total) <= 0.05 * total and expected_mass != pytest.approx(total, rel=1e-6)
    for M in inertias.values():
        assert M.IsPhysicallyValid()
        moments = np.linalg.eigvalsh(
            M.CalcRotationalInertia().ShiftToCenterOfMass(M.get_mass(), M.get_com()).CopyToFullMatrix3()
        )
        assert moments[0] > 0.0 and moments[0] + moments[1] >= moments[2] * (1.0 - 1e-12)
    # The model's mass matrix at the standing state: symmetric positive definite, and not
    # the plant's.
    x = station.initial_state
    terms = station.dynamics_model.evaluate(x)
    plant.SetPositionsAndVelocities(nominal_context, x)
    M_plant = plant.CalcMassMatrix(nominal_context)
    model_context = model.CreateDefaultContext()
    model.SetPositionsAndVelocities(model_context, x)
    M_model = model.CalcMassMatrix(model_context)
    np.testing.assert_allclose(M_model, M_model.T, atol=1e-12 * np.abs(M_model).max())
    assert np.linalg.eigvalsh(M_model).min() > 0.0
    assert np.abs(M_model - M_plant).max() > 1e-3 * np.abs(M_plant).max()
    assert np.linalg.eigvalsh(0.5 * (terms.H + terms.H.T)).min() > 0.0
    # The plant itself keeps the nominal inertias.
    assert total == pytest.approx(sum(M.get_mass() for M in nominal.values()), rel=1e-12)


# ---------------------------------------------------------------------------------------
# Defaults, YAML, errors.
# ---------------------------------------------------------------------------------------


def _logs(imperfections_given: bool):
    kwargs = {"imperfections": Imperfections()} if imperfections_given else {}
    builder, station = _station(noise=True, seed=1, **kwargs)
    state_log = LogVectorOutput(station.sensed_state, builder)
    torque_log = LogVectorOutput(station.measured_torque, builder)
    plant_log = LogVectorOutput(station.plant.get_state_output_port(), builder)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.AdvanceTo(0.1)
    names = sorted(s.get_name().split("@")[0] for s in diagram.GetSystems())
    return names, [log.FindLog(context).data() for log in (state_log, torque_log, plant_log)]


def test_default_imperfections_leave_the_station_bit_identical():
    assert Imperfections().is_ideal and not Imperfections.realistic().is_ideal
    names_none, logs_none = _logs(False)
    names_default, logs_default = _logs(True)
    assert names_none == names_default
    for a, b in zip(logs_none, logs_default):
        np.testing.assert_array_equal(a, b)


def test_realistic_station_stands():
    """All realistic imperfections at once: the Nao-like robot still stands (stable explicit
    friction, sane sensors)."""
    builder, station = _station("nao_like", imperfections=Imperfections.realistic(seed=1))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.AdvanceTo(0.3)
    x = station.plant.GetPositionsAndVelocities(station.plant.GetMyContextFromRoot(context))
    assert np.abs(x[station.plant.num_positions() :]).max() < 0.1
    assert abs(x[6] - station.initial_state[6]) < 0.01


def test_yaml_round_trip():
    realistic = Imperfections.realistic(seed=4)
    loaded = yaml_load_typed(schema=Imperfections, data=yaml_dump_typed(realistic))
    assert loaded == realistic
    partial = yaml_load_typed(schema=Imperfections, data="{encoders: {bits: 12}, friction: {coulomb_percent: 1.5}}")
    assert partial.encoders.bits == 12 and partial.friction.coulomb_percent == 1.5 and partial.imu == ImuImperfections()


@pytest.mark.parametrize(
    "imperfections, field",
    [
        (Imperfections(imu=ImuImperfections(gyro_noise_density=-1e-3)), "imperfections.imu.gyro_noise_density"),
        (
            Imperfections(imu=ImuImperfections(accel_bias_random_walk=math.nan)),
            "imperfections.imu.accel_bias_random_walk",
        ),
        (Imperfections(model_mismatch=ModelMismatch(mass_percent=100.0)), "imperfections.model_mismatch.mass_percent"),
        (
            Imperfections(model_mismatch=ModelMismatch(inertia_percent=-1.0)),
            "imperfections.model_mismatch.inertia_percent",
        ),
        (
            Imperfections(torque_sensor=TorqueSensorImperfections(offset_percent=math.inf)),
            "imperfections.torque_sensor.offset_percent",
        ),
        (
            Imperfections(friction=FrictionImperfections(coulomb_percent=150.0)),
            "imperfections.friction.coulomb_percent",
        ),
        (
            Imperfections(friction=FrictionImperfections(smoothing_velocity=0.0)),
            "imperfections.friction.smoothing_velocity",
        ),
        (Imperfections(encoders=EncoderImperfections(bits=-1)), "imperfections.encoders.bits"),
        (Imperfections(seed=-2), "imperfections.seed"),
        (Imperfections(imu=ImuImperfections(gyro_bias_z=math.nan)), "imperfections.imu.gyro_bias_z"),
    ],
)
def test_bad_values_raise_naming_the_field(imperfections, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        imperfections.validate()
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        add_humanoid_station(DiagramBuilder(), StationConfig(model="nao_like", imperfections=imperfections))


def test_bad_system_arguments():
    plant = _two_body_plant()
    with pytest.raises(ValueError, match="coulomb"):
        JointFriction(plant, coulomb=-1.0, viscous=0.0)
    with pytest.raises(ValueError, match="smoothing_velocity"):
        JointFriction(plant, coulomb=1.0, viscous=0.0, smoothing_velocity=math.nan)
    with pytest.raises(ValueError, match="random_walk"):
        RandomWalkBias(3, -1.0)
    with pytest.raises(ValueError, match="position_step"):
        JointEncoders(plant, position_step=-1e-3)
    with pytest.raises(ValueError, match="imperfections must be Imperfections"):
        add_humanoid_station(DiagramBuilder(), StationConfig(model="nao_like", imperfections={"seed": 1}))
