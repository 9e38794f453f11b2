"""Tests of ResidualBank (systems/residuals/momentum_residuals.py): the classical, internal and
external residuals (Flacco et al. 2016, eqs. 7, 11, 16) in one system give, bit for bit, what
the three separate systems give, and refuse the same bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable, RevoluteJoint, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from models import add_humanoid
from systems.residuals.momentum_residuals import (
    ClassicalResidual,
    ExternalResidual,
    InternalResidual,
    ResidualBank,
    ResidualModel,
)

OUTPUTS = ("classical_residual", "internal_residual", "external_wrench_base", "external_wrench_world")


@pytest.fixture(scope="module")
def humanoid():
    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    return plant, tuple(handles.ft_sensor_frames.values())


def _random_state(plant, rng) -> np.ndarray:
    x = plant.GetPositionsAndVelocities(plant.CreateDefaultContext())
    nq = plant.num_positions()
    quaternion = rng.normal(size=4)
    x[:4] = quaternion / np.linalg.norm(quaternion)
    x[4:7] = rng.normal(size=3)
    x[7:nq] += 0.3 * rng.normal(size=nq - 7)
    x[nq:] = rng.normal(size=plant.num_velocities())
    return x


def _separate(plant, frames, gains, damping):
    model = ResidualModel(plant)
    return (
        ClassicalResidual(plant, gains[0], known_wrench_frames=frames, joint_damping=damping, model=model),
        InternalResidual(plant, gains[1], known_wrench_frames=frames, joint_damping=damping, model=model),
        ExternalResidual(plant, gains[2], known_wrench_frames=frames, model=model),
    )


@pytest.mark.parametrize("with_frames", [True, False])
def test_bank_equals_the_three_systems(humanoid, with_frames):
    """Random states, torques and wrenches (and a repeated state, which the model's cache
    serves): the bank's four outputs equal the three systems' at every update, bitwise."""
    plant, frames = humanoid
    frames = frames if with_frames else ()
    nv, n = plant.num_velocities(), plant.num_velocities() - 6
    rng = np.random.default_rng(11)
    gains = (rng.uniform(5.0, 60.0, nv), rng.uniform(5.0, 60.0, n), rng.uniform(5.0, 60.0, 6))
    damping = rng.uniform(0.0, 2.0, n)
    bank = ResidualBank(plant, gains, known_wrench_frames=frames, joint_damping=damping)
    systems = _separate(plant, frames, gains, damping)
    assert [bank.get_output_port(i).get_name() for i in range(bank.num_output_ports())] == list(OUTPUTS)
    bank_context = bank.CreateDefaultContext()
    contexts = [system.CreateDefaultContext() for system in systems]
    x = _random_state(plant, rng)
    for step in range(30):
        if step != 7:  # step 7 repeats step 6's state
            x = _random_state(plant, rng)
        torque, wrenches = 20.0 * rng.normal(size=n), 20.0 * rng.normal(size=6 * len(frames))
        for system, context in [(bank, bank_context), *zip(systems, contexts)]:
            system.GetInputPort("state").FixValue(context, x)
            if system.HasInputPort("measured_torque"):
                system.GetInputPort("measured_torque").FixValue(context, torque)
            system.GetInputPort("known_wrenches").FixValue(context, wrenches)
            context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
        expected = (
            systems[0].GetOutputPort("residual").Eval(contexts[0]),
            systems[1].GetOutputPort("residual").Eval(contexts[1]),
            systems[2].GetOutputPort("external_wrench_base").Eval(contexts[2]),
            systems[2].GetOutputPort("external_wrench_world").Eval(contexts[2]),
        )
        for name, value in zip(OUTPUTS, expected):
            np.testing.assert_array_equal(bank.GetOutputPort(name).Eval(bank_context), value, err_msg=name)
        if step == 0:
            assert not np.any(bank.GetOutputPort("classical_residual").Eval(bank_context))  # r_0 = 0
    assert np.abs(bank.GetOutputPort("internal_residual").Eval(bank_context)).max() > 1.0


def test_bank_in_a_simulated_diagram_matches_the_systems(humanoid):
    """In a diagram run by a Simulator (its discrete-update semantics), fed one falling
    robot's state: the bank and the three systems log the same numbers."""
    _, frames_template = humanoid
    builder = DiagramBuilder()
    plant = builder.AddSystem(MultibodyPlant(time_step=1e-3))
    handles = add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    frames = tuple(handles.ft_sensor_frames.values())
    assert len(frames) == len(frames_template)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(3)
    torque = builder.AddSystem(ConstantVectorSource(rng.normal(size=n)))
    wrenches = builder.AddSystem(ConstantVectorSource(rng.normal(size=6 * len(frames))))
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(plant.num_actuators()))).get_output_port(),
        plant.get_actuation_input_port(),
    )
    bank = builder.AddSystem(ResidualBank(plant, 35.0, known_wrench_frames=frames))
    systems = [builder.AddSystem(s) for s in _separate(plant, frames, (35.0, 35.0, 35.0), None)]
    for system in (bank, *systems):
        builder.Connect(plant.get_state_output_port(), system.GetInputPort("state"))
        if system.HasInputPort("measured_torque"):
            builder.Connect(torque.get_output_port(), system.GetInputPort("measured_torque"))
        builder.Connect(wrenches.get_output_port(), system.GetInputPort("known_wrenches"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetVelocities(plant_context, rng.normal(size=plant.num_velocities()))
    simulator.AdvanceTo(0.02)
    pairs = (
        ("classical_residual", systems[0], "residual"),
        ("internal_residual", systems[1], "residual"),
        ("external_wrench_base", systems[2], "external_wrench_base"),
        ("external_wrench_world", systems[2], "external_wrench_world"),
    )
    for name, system, port in pairs:
        value = bank.GetOutputPort(name).Eval(bank.GetMyContextFromRoot(context))
        np.testing.assert_array_equal(value, system.GetOutputPort(port).Eval(system.GetMyContextFromRoot(context)))
        assert np.abs(value).max() > 0.0, name


@pytest.mark.parametrize(("port", "index"), [("state", 5), ("measured_torque", 1), ("known_wrenches", 3)])
def test_bank_refuses_non_finite_inputs_naming_the_port(humanoid, port, index):
    plant, frames = humanoid
    bank = ResidualBank(plant, 35.0, known_wrench_frames=frames)
    context = bank.CreateDefaultContext()
    values = {
        "state": plant.GetPositionsAndVelocities(plant.CreateDefaultContext()),
        "measured_torque": np.zeros(plant.num_velocities() - 6),
        "known_wrenches": np.zeros(6 * len(frames)),
    }
    values[port][index] = np.inf if port == "state" else np.nan
    for name, value in values.items():
        bank.GetInputPort(name).FixValue(context, value)
    with pytest.raises(ValueError, match=f"ResidualBank: input '{port}' has NaN or inf at indices \\[{index}\\]"):
        bank.EvalUniquePeriodicDiscreteUpdate(context)


def test_bank_refuses_bad_ports_sizes_and_parameters(humanoid):
    plant, frames = humanoid
    bank = ResidualBank(plant, 35.0, known_wrench_frames=frames)
    context = bank.CreateDefaultContext()
    with pytest.raises(RuntimeError):
        bank.GetInputPort("residual")
    with pytest.raises((RuntimeError, ValueError)):
        bank.GetInputPort("known_wrenches").FixValue(context, np.zeros(6 * len(frames) + 1))
        bank.EvalUniquePeriodicDiscreteUpdate(context)
    with pytest.raises(ValueError, match="ResidualBank: .*K T < 1"):
        ResidualBank(plant, 2000.0)
    with pytest.raises(ValueError, match="ResidualBank: InternalResidual: gain must be a scalar or have"):
        ResidualBank(plant, (35.0, np.ones(3), 35.0))
    with pytest.raises(ValueError, match="ResidualBank: known wrench frame 'nowhere'"):
        ResidualBank(plant, 35.0, known_wrench_frames=["nowhere"])
    with pytest.raises(ValueError, match="ResidualBank: .*joint_damping"):
        ResidualBank(plant, 35.0, joint_damping=-1.0)
    fixed = MultibodyPlant(1e-3)
    body = fixed.AddRigidBody("b", SpatialInertia.SolidBoxWithMass(1, 1, 1, 1))
    fixed.WeldFrames(fixed.world_frame(), body.body_frame())
    fixed.Finalize()
    with pytest.raises(ValueError, match="ResidualBank: the plant has no floating base"):
        ResidualBank(fixed, 10.0)
    with pytest.raises(ValueError, match="ResidualBank: .*another plant"):
        ResidualBank(plant, 10.0, model=ResidualModel(_other_humanoid()))


def _other_humanoid():
    plant = MultibodyPlant(time_step=0.0)
    add_humanoid(plant, "hrp4_like")
    plant.Finalize()
    return plant


def test_fixed_base_classical_residual_takes_known_wrenches():
    """Eq. (7) on a fixed-base arm with an F/T frame: a known wrench w counts as the measured
    joint torque J^T w (it used to raise a TypeError)."""
    plant = MultibodyPlant(0.0)
    a = plant.AddRigidBody("a", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.4))
    b = plant.AddRigidBody("b", SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.4))
    plant.AddJoint(RevoluteJoint("j0", plant.world_frame(), a.body_frame(), [0, 1, 0]))
    plant.AddJoint(RevoluteJoint("j1", a.body_frame(), b.body_frame(), [1, 0, 0]))
    plant.Finalize()
    with_frame = ClassicalResidual(plant, 20.0, known_wrench_frames=[b.body_frame()], joint_damping=0.0)
    without = ClassicalResidual(plant, 20.0, joint_damping=0.0)
    contexts = (with_frame.CreateDefaultContext(), without.CreateDefaultContext())
    plant_context = plant.CreateDefaultContext()
    world = plant.world_frame()
    rng = np.random.default_rng(4)
    for _ in range(10):
        x, torque, wrench = rng.normal(size=4), rng.normal(size=2), rng.normal(size=6)
        plant.SetPositionsAndVelocities(plant_context, x)
        J = plant.CalcJacobianSpatialVelocity(
            plant_context, JacobianWrtVariable.kV, b.body_frame(), np.zeros(3), world, world
        )
        for system, context, tau, w in (
            (with_frame, contexts[0], torque, wrench),
            (without, contexts[1], torque + J.T @ wrench, np.zeros(0)),
        ):
            system.GetInputPort("state").FixValue(context, x)
            system.GetInputPort("measured_torque").FixValue(context, tau)
            system.GetInputPort("known_wrenches").FixValue(context, w)
            context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
        r_with = with_frame.GetOutputPort("residual").Eval(contexts[0])
        r_without = without.GetOutputPort("residual").Eval(contexts[1])
        np.testing.assert_allclose(r_with, r_without, rtol=1e-12, atol=1e-12 * np.abs(r_without).max())
    assert np.abs(r_with).max() > 0.0


@pytest.mark.parametrize("implementation", ["pinocchio", "reference"])
def test_known_wrench_forces_without_a_drake_f0_context(humanoid, implementation):
    """Models whose dynamics keep no Drake F0 context: the "pinocchio" one gives its own F0
    Jacobians, unless a gravity call (a PD sharing the model) has moved its kinematics since
    the state's evaluation; both give the "fast" model's known-wrench forces to 1e-12."""
    plant, frames = humanoid
    rng = np.random.default_rng(8)
    x, other = _random_state(plant, rng), _random_state(plant, rng)
    wrenches = 20.0 * rng.normal(size=6 * len(frames))
    fast = ResidualModel(plant, "fast")
    expected = np.concatenate(fast.known_wrench_forces(fast.evaluate(x), frames, wrenches))
    for gravity_between in (False, True):
        model = ResidualModel(plant, implementation)
        terms = model.evaluate(x)
        if gravity_between:
            model.gravity_joint_torques(other)
        value = np.concatenate(model.known_wrench_forces(terms, frames, wrenches))
        np.testing.assert_allclose(value, expected, rtol=0.0, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("implementation", ["fast", "pinocchio", "reference"])
def test_state_rates_equal_the_eliminated_matrices(humanoid, implementation):
    """``ResidualModel.state_rates`` (eq. 9 and 13 applied to vectors, G never formed) gives
    the momenta and model rates of the matrices ``evaluate`` forms (H_fb, H_fb_dot, C_fb,
    the blocks of M_F0) times the velocities, and ``eliminated_base_wrench`` G^T w, to
    rounding; the same known-wrench forces from either; a massless model is refused."""
    plant, frames = humanoid
    rng = np.random.default_rng(12)
    model = ResidualModel(plant, implementation)
    for _ in range(3):
        x = _random_state(plant, rng)
        rates = model.state_rates(x)
        t = model.evaluate(x)
        qdot, v0 = x[plant.num_positions() + 6 :], t.v0
        classical = (
            np.concatenate((t.I0c @ v0 + t.F @ qdot, t.F.T @ v0 + t.H @ qdot)),
            np.concatenate((t.I0c_dot @ v0 + t.F_dot @ qdot - t.p_hat, t.F_dot.T @ v0 + t.H_dot @ qdot - t.C_hat)),
        )
        internal = (t.H_fb @ qdot, t.H_fb_dot @ qdot - t.C_fb)
        for got, want in zip((*rates.classical, *rates.internal, *rates.base), (*classical, *internal, *classical)):
            want = want[: got.size]
            np.testing.assert_allclose(got, want, rtol=0.0, atol=1e-11 * np.abs(want).max())
        w = 30.0 * rng.normal(size=6)
        np.testing.assert_allclose(model.eliminated_base_wrench(rates, w), t.I0c_inv_F.T @ w, rtol=0.0, atol=1e-11)
        wrenches = 20.0 * rng.normal(size=6 * len(frames))
        from_rates = np.concatenate(model.known_wrench_forces(rates, frames, wrenches))
        other = ResidualModel(plant, implementation)  # its own cache
        from_terms = np.concatenate(other.known_wrench_forces(other.evaluate(x), frames, wrenches))
        np.testing.assert_allclose(from_rates, from_terms, rtol=0.0, atol=1e-12 * np.abs(from_terms).max())
    if implementation == "fast":
        massless = ResidualModel(plant, implementation)
        massless.dynamics.mass_matrix_terms = lambda q, v: (
            (np.zeros((plant.num_velocities(),) * 2),) * 2
            + (
                np.zeros(plant.num_velocities()),
                np.eye(3),
                np.zeros(6),
            )
        )
        with pytest.raises(ValueError, match="I0c is not positive definite"):
            massless.state_rates(_random_state(plant, rng))
