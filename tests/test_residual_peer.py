"""The three residuals' Pinocchio peer (issue 33, ``systems.residuals.pinocchio_peer``): an
independent check of ``ClassicalResidual``, ``InternalResidual`` and ``ExternalResidual``
(Pinocchio's own kinematics and exact M_dot = C + C^T, no code shared with
``systems.dynamics``), and the benchmark's comparison with it. No timing is asserted."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant

from apps import benchmark, doc_tables
from apps.results import write_results
from models import MODELS_DIR, add_humanoid
from systems.residuals.momentum_residuals import ClassicalResidual, ExternalResidual, InternalResidual, ResidualModel
from systems.residuals.pinocchio_peer import (
    PinocchioResidualPeer,
    PlantCoordinates,
    peer_model_from_plant,
    peer_model_from_urdf,
    plant_joint_parameters,
)

ROBOTS = {"hrp4_like": "hrp4_like", "talos": str(MODELS_DIR / "robots" / "talos.yaml")}
GAINS = (35.0, 20.0, 50.0)  # classical, internal, external: distinct, so a mixed-up gain shows
#: The project's M_dot is a central difference of the mass matrix (relative error ~1e-10,
#: systems.dynamics.floating_base); everything else is exact in both.
TOLERANCE = 1e-8


def _robot(name: str):
    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, ROBOTS[name])
    plant.Finalize()
    return plant, tuple(handles.ft_sensor_frames.values()), handles.description.model_file


def _peer(plant, frames, model_file, *, armature: bool = True):
    joint_armature, damping = plant_joint_parameters(plant)
    if model_file.suffix == ".urdf":  # the user's way: the URDF with a free-flyer root
        model, pin_damping = peer_model_from_urdf(model_file, joint_armature if armature else None, damping)
    else:  # hrp4_like is SDFormat only
        model, pin_damping = peer_model_from_plant(plant, joint_armature if armature else None, damping)
    peer = PinocchioResidualPeer(model, [f.name() for f in frames], pin_damping, GAINS, 1e-3)
    return peer, PlantCoordinates(plant, model)


def _compare(plant, frames, peer, coordinates, steps: int = 12) -> list[float]:
    """Both from their first update on one sequence of random states (changing at every
    update), torques and wrenches: the largest relative difference of the classical,
    internal, external (base) and external (world) residuals."""
    model = ResidualModel(plant)
    bank = [
        ClassicalResidual(plant, GAINS[0], known_wrench_frames=frames, model=model),
        InternalResidual(plant, GAINS[1], known_wrench_frames=frames, model=model),
        ExternalResidual(plant, GAINS[2], known_wrench_frames=frames, model=model),
    ]
    contexts = [system.CreateDefaultContext() for system in bank]
    rng = np.random.default_rng(7)
    n = plant.num_velocities() - 6
    ours, theirs = [[] for _ in range(4)], [[] for _ in range(4)]
    for q, v in benchmark._random_states(plant, steps, seed=5):
        x, tau, wrenches = np.concatenate((q, v)), 20.0 * rng.normal(size=n), 20.0 * rng.normal(size=12)
        for system, context in zip(bank, contexts):
            system.GetInputPort("state").FixValue(context, x)
            system.GetInputPort("known_wrenches").FixValue(context, wrenches)
            if system.HasInputPort("measured_torque"):
                system.GetInputPort("measured_torque").FixValue(context, tau)
            context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
        outputs = (
            bank[0].GetOutputPort("residual").Eval(contexts[0]),
            bank[1].GetOutputPort("residual").Eval(contexts[1]),
            bank[2].GetOutputPort("external_wrench_base").Eval(contexts[2]),
            bank[2].GetOutputPort("external_wrench_world").Eval(contexts[2]),
        )
        q_pin, v_pin = coordinates.state(x)
        step = coordinates.residuals_to_drake(peer.step(q_pin, v_pin, coordinates.joints_to_pin(tau), wrenches))
        for k in range(4):
            ours[k].append(np.array(outputs[k]))
            theirs[k].append(step[k])
    return [benchmark._relative_difference(a, b) for a, b in zip(ours, theirs)]


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_the_peer_agrees_with_the_project_residuals(name):
    plant, frames, model_file = _robot(name)
    assert len(frames) == 2  # the ankle F/T sensors: the known wrenches
    peer, coordinates = _peer(plant, frames, model_file)
    differences = _compare(plant, frames, peer, coordinates)
    assert max(differences) < TOLERANCE, differences


def test_the_comparison_sees_a_model_that_differs_from_the_plant():
    """Control: the peer without the project's reflected rotor inertia (TALOS's URDF alone)
    disagrees far beyond the tolerance."""
    plant, frames, model_file = _robot("talos")
    peer, coordinates = _peer(plant, frames, model_file, armature=False)
    classical, internal, _, _ = _compare(plant, frames, peer, coordinates, steps=4)
    assert classical > 1e4 * TOLERANCE and internal > 1e4 * TOLERANCE


def test_plant_coordinates_round_trip_the_joint_order():
    plant, frames, model_file = _robot("talos")
    _, coordinates = _peer(plant, frames, model_file)
    values = np.arange(plant.num_velocities() - 6, dtype=float)
    assert np.array_equal(coordinates.joints_to_drake(coordinates.joints_to_pin(values)), values)


def test_benchmark_residual_peer_reports_every_field():
    row = benchmark.benchmark_residual_peer("hrp4_like", calls=2, batches=1, steps=4)
    assert row["model"] == "hrp4_like" and row["num_joints"] == 34 and row["known_wrench_frames"] == 2
    assert row["peer_model_source"] == "plant"
    for key in ("calc_mass_matrix_us", "project_bank_us", "peer_us"):
        assert row[key] > 0.0
    assert row["project_over_peer"] == row["project_bank_us"] / row["peer_us"]
    assert row["project_bank_ratio_to_mass_matrix"] == row["project_bank_us"] / row["calc_mass_matrix_us"]
    assert row["agreement_steps"] == 4
    assert row["largest_relative_difference"] < TOLERANCE
    assert row["mass_matrix_relative_difference"] < 1e-9


def _peer_row(model: str, project_us: float) -> dict:
    return {
        "model": model,
        "num_joints": 34,
        "known_wrench_frames": 2,
        "peer_model_source": "plant" if model == "hrp4_like" else "URDF",
        "calc_mass_matrix_us": 20.0,
        "project_bank_us": project_us,
        "peer_us": 100.0,
        "project_bank_ratio_to_mass_matrix": project_us / 20.0,
        "peer_ratio_to_mass_matrix": 5.0,
        "project_over_peer": project_us / 100.0,
        "fused_bank_us": 0.8 * project_us,
        "fused_bank_over_peer": 0.8 * project_us / 100.0,
        "fused_bank_ratio_to_mass_matrix": 0.8 * project_us / 20.0,
        "agreement_steps": 200,
        "classical_relative_difference": 1e-13,
        "internal_relative_difference": 2e-12,
        "external_relative_difference": 1e-13,
        "largest_relative_difference": 2e-12,
        "mass_matrix_relative_difference": 1e-16,
    }


def test_the_peer_table_renders_its_rows_and_floors(tmp_path):
    data = {"floors": benchmark.FLOORS, "residual_peer": [_peer_row("hrp4_like", 250.0), _peer_row("talos", 90.0)]}
    write_results("benchmark", data, command="python -m apps.benchmark", folder=tmp_path)
    body = doc_tables.render("benchmark_residual_peer", tmp_path)
    row = (
        "| hrp4_like | 34 | 2 | 20.0 us | 250 us (12.5x) | 200 us (10.0x) | 100 us (5.0x) | 2.50x, 2.00x "
        "| **not met** |"
    )
    assert row in body
    # TALOS: the fused bank (72 us: 0.72x the peer, 3.6x CalcMassMatrix) meets both floors.
    assert "| talos | 34 | 2 | 20.0 us | 90 us (4.5x) | 72 us (3.6x) | 100 us (5.0x) | 0.90x, 0.72x | met |" in body
    assert "`results/benchmark.json`" in body and "pin.buildModelFromUrdf" in body
    write_results("benchmark", {"floors": benchmark.FLOORS, "residual_peer": []}, command="x", folder=tmp_path)
    assert doc_tables.render("benchmark_residual_peer", tmp_path).startswith("Not measured in this run")
