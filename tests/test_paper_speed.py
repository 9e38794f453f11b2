"""apps.paper_speed: the classical residual computed as the paper did (explicit C(q, q_dot) on
the virtual-joint model of eq. 8) is right, so that its timing is the paper's comparison."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

from apps import paper_speed


@pytest.fixture(scope="module")
def virtual():
    return paper_speed.virtual_joint_plant("nao_like")


def test_the_explicit_coriolis_matrix_is_the_christoffel_factorization(virtual):
    """C q_dot = c (Drake's bias term) and H_dot = C + C^T (a central difference of
    CalcMassMatrix along q_dot): the two properties eq. (7) needs."""
    plant, _ = virtual
    n = plant.num_positions()
    rng = np.random.default_rng(3)
    q, v = rng.uniform(-0.5, 0.5, n), rng.normal(size=n)
    C = paper_speed.ExplicitCoriolisClassicalResidual(plant, 35.0, 1e-3).coriolis_matrix(q, v)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    plant.SetVelocities(context, v)
    np.testing.assert_allclose(C @ v, plant.CalcBiasTerm(context), atol=1e-10)
    h = 1e-6

    def mass_matrix(positions):
        plant.SetPositions(context, positions)
        return plant.CalcMassMatrix(context)

    H_dot = (mass_matrix(q + h * v) - mass_matrix(q - h * v)) / (2 * h)
    np.testing.assert_allclose(C + C.T, H_dot, atol=1e-6 * np.abs(H_dot).max())


def test_the_explicit_classical_residual_recovers_an_applied_generalized_force(virtual):
    """Physics: the robot floats (gravity on, no ground, no motor torque) while a constant
    generalized force acts on a virtual joint and two robot joints; simulated by Drake's
    error-controlled integrator, the residual of the sampled motion (the joints' viscous
    damping known, as eq. 7's tau_mu) converges to that force."""
    plant, _ = virtual
    n = plant.num_velocities()
    applied = np.zeros(n)
    applied[[1, 9, 20]] = [3.0, 0.4, -0.25]
    builder = DiagramBuilder()
    simulated = builder.AddSystem(paper_speed.virtual_joint_plant("nao_like")[0])
    source = builder.AddSystem(ConstantVectorSource(applied))
    builder.Connect(source.get_output_port(), simulated.get_applied_generalized_force_input_port())
    builder.Connect(
        builder.AddSystem(ConstantVectorSource(np.zeros(simulated.num_actuated_dofs()))).get_output_port(),
        simulated.get_actuation_input_port(),
    )
    period = 5e-4
    logger = builder.AddSystem(VectorLogSink(2 * n, period))
    builder.Connect(simulated.get_state_output_port(), logger.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.get_mutable_integrator().set_target_accuracy(1e-9)
    simulator.AdvanceTo(0.15)
    states = logger.FindLog(simulator.get_context()).data().T
    damping = np.zeros(n)
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.num_velocities() == 1:
            damping[joint.velocity_start()] = joint.default_damping()
    residual = paper_speed.ExplicitCoriolisClassicalResidual(plant, 60.0, period)
    for x in states:
        r = residual.update(x[:n], x[n:], -damping * x[n:])
    np.testing.assert_allclose(r, applied, atol=0.002 * np.abs(applied).max())


def test_the_benchmark_times_all_four_and_writes_its_results(tmp_path):
    code = paper_speed.main(["--calls", "2", "--batches", "1", "--results-folder", str(tmp_path)])
    assert code == 0
    import json

    data = json.loads((tmp_path / "paper_speed.json").read_text())["data"]
    for key in ("classical_explicit_coriolis_ms", "internal_reference_ms", "internal_fast_ms", "classical_project_ms"):
        assert data[key] > 0.0
    assert data["paper_ratio"] == pytest.approx(15.9)
