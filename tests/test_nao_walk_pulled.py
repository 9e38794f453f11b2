"""Experiment 4 (diagrams.observer.nao_walk_pulled): the fixed-frame measurements and the cable's
virtual-force truth against hand-computed values, and the app's pulled walk (22 steps, the line
taut after 0.55 m, ~10-15 s wall) whose walk and observer estimate must meet the issue's
floors.

Why not a shorter walk for the observer floor: with the WALKING preset (eq. 22) the estimate
needs ~1.5-2 s to converge after the load lifts (the F_x plot); on a 12-step walk with the
line taut after 0.1 m the window (1 s after the lift to the last touch-down, 3.6 s) is
dominated by that transient and the mean error is 0.68 N (measured, seed 0), above the
0.5 N floor; on the app's walk (4.5 s window) it is 0.42-0.43 N (seeds 0-2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from scenario_checks import SCENARIOS, check_scenario_convention

from diagrams.locomotion.nao_walk import walking_metrics
from diagrams.observer.nao_walk_pulled import (
    CableSetup,
    NaoWalkPulledScenario,
    build_nao_walk_pulled_diagram,
    observer_metrics,
)
from diagrams.scenarios import ScenarioError, load_scenario
from diagrams.station.config import StationConfig
from models import add_humanoid, set_standing_state
from systems.locomotion.walking_pattern import WalkingParameters
from systems.observer.fsr_sensing import CenterOfPressure, SupportFootCom
from systems.simulation.ground_truth import CableVirtualForceTruth

G = 9.81


@pytest.fixture(scope="module")
def nao():
    plant = MultibodyPlant(1e-3)
    handles = add_humanoid(plant, "nao_like")
    plant.Finalize()
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    return plant, handles, context


def test_fixed_frame_measurements_match_kinematics(nao):
    """CenterOfPressure and SupportFootCom with a fixed world origin (the walking frame F0)."""
    plant, handles, context = nao
    x = plant.GetPositionsAndVelocities(context)
    origin = np.array([0.1, -0.2, 0.0])
    cop = CenterOfPressure(plant, handles, origin_W=origin)
    com_system = SupportFootCom(plant, handles, origin_W=origin)
    cop_ctx, com_ctx = cop.CreateDefaultContext(), com_system.CreateDefaultContext()
    cop.GetInputPort("state").FixValue(cop_ctx, x)
    com_system.GetInputPort("state").FixValue(com_ctx, x)
    forces = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
    cop.GetInputPort("fsr_forces").FixValue(cop_ctx, forces)
    com = plant.CalcCenterOfMassPositionInWorld(context, [handles.model_instance])
    np.testing.assert_allclose(com_system.GetOutputPort("com_position").Eval(com_ctx), com - origin, atol=1e-12)
    assert cop.GetOutputPort("normal_force").Eval(cop_ctx)[0] == pytest.approx(-forces.sum())
    # CoP: the force-weighted FSR positions (the soles are level: sole frame + FSR offsets).
    points = []
    for side in ("left", "right"):
        X = handles.sole_frames[side].CalcPoseInWorld(context)
        points += [X.multiply(np.array([px, py, 0.0])) - origin for px, py in handles.fsr_positions[side]]
    np.testing.assert_allclose(
        cop.GetOutputPort("zmp").Eval(cop_ctx), forces @ np.array(points)[:, :2] / forces.sum(), atol=1e-12
    )
    cop.GetInputPort("fsr_forces").FixValue(cop_ctx, np.zeros(8))
    np.testing.assert_array_equal(cop.GetOutputPort("zmp").Eval(cop_ctx), np.zeros(2))
    with pytest.raises(ValueError, match="origin_W"):
        CenterOfPressure(plant, handles, origin_W=[0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="origin_W"):
        SupportFootCom(plant, handles, origin_W=[0.0, 0.0])


def test_cable_virtual_force_follows_eq_11(nao):
    plant, handles, context = nao
    x = plant.GetPositionsAndVelocities(context)
    com = plant.CalcCenterOfMassPositionInWorld(context, [handles.model_instance])
    dut = CableVirtualForceTruth(plant, handles, ground_height=0.0)
    ctx = dut.CreateDefaultContext()
    dut.GetInputPort("state").FixValue(ctx, x)
    force = np.array([-2.9, -0.25, 0.3])
    dut.GetInputPort("force_world").FixValue(ctx, force)
    # At the CoM: no moment, the virtual force is the force.
    dut.GetInputPort("point_world").FixValue(ctx, com)
    np.testing.assert_allclose(dut.GetOutputPort("virtual_force").Eval(ctx), force, atol=1e-12)
    # 5 cm above the CoM: F_x counts (z_c + 0.05) / z_c times (tau_y = 0.05 F_x), F_y too.
    dut.GetInputPort("point_world").FixValue(ctx, com + [0.0, 0.0, 0.05])
    scale = (com[2] + 0.05) / com[2]
    np.testing.assert_allclose(
        dut.GetOutputPort("virtual_force").Eval(ctx), [force[0] * scale, force[1] * scale, force[2]], atol=1e-12
    )


def test_bad_cable_setups_are_refused():
    with pytest.raises(ValueError, match="pulley_height"):
        CableSetup(pulley_height=0.0)
    with pytest.raises(ValueError, match="lateral_angle_deg"):
        CableSetup(lateral_angle_deg=60.0)
    # A low pulley: the load would be lifted into it.
    with pytest.raises(ValueError, match="into the pulley"):
        build_nao_walk_pulled_diagram(
            NaoWalkPulledScenario(
                walking=WalkingParameters(num_steps=12),
                cable=CableSetup(pulley_height=0.3, tighten_distance=0.05),
                station=StationConfig(model="nao_like", noise=False),
            )
        )
    with pytest.raises(ValueError, match="never tightens"):
        build_nao_walk_pulled_diagram(
            NaoWalkPulledScenario(
                walking=WalkingParameters(num_steps=4),
                cable=CableSetup(tighten_distance=0.5),
                station=StationConfig(model="nao_like", noise=False),
            )
        )


@pytest.fixture(scope="module")
def pulled_walk():
    """The app's configuration (defaults), sensor noise on, seed 0, no replay."""
    diagram, handles = build_nao_walk_pulled_diagram(
        NaoWalkPulledScenario(
            walking=WalkingParameters(), cable=CableSetup(), station=StationConfig(model="nao_like", noise=True, seed=0)
        )
    )
    simulator = Simulator(diagram)  # Build() refused any algebraic loop
    handles.set_initial_state(simulator.get_mutable_context())
    simulator.Initialize()
    simulator.AdvanceTo(handles.controller.duration)
    context = simulator.get_context()
    return handles, walking_metrics(handles, context), observer_metrics(handles, context)


@pytest.mark.slow
def test_pulled_walk_lifts_the_load_and_meets_the_walking_floors(pulled_walk):
    handles, w, o = pulled_walk
    assert w["upright"] and w["steps_detected"] >= 20
    assert w["distance_m"] >= 1.0 and w["mean_speed_mps"] >= 0.08
    # The line is taut once the torso has walked ~0.55 m (planned ~6.9 s; the simulated
    # robot runs slightly ahead of its plan) and the load rises by what the robot walks after.
    assert handles.planned_tighten_time - 1.0 < o["measured_lift_time_s"] < handles.planned_tighten_time + 0.5
    assert 0.3 < o["max_load_height_m"] < handles.setup.pulley_height
    s = o["signals"]
    hanging = o["window_mask"]
    assert np.mean(s["tension"][hanging]) == pytest.approx(0.3 * G, rel=0.05)
    # The pull: ~3 N backwards, ~5 deg to the side (the pulley is on -y).
    angle = math.degrees(math.atan2(-o["true_pull_y_mean_N"], -o["true_pull_x_mean_N"]))
    assert -o["true_pull_x_mean_N"] == pytest.approx(2.9, abs=0.1) and 2.0 < angle < 6.0


@pytest.mark.slow
def test_observer_meets_the_exp4_floors(pulled_walk):
    _, _, o = pulled_walk
    assert o["window_samples"] > 240  # > 4 s of walking with the load hanging
    assert abs(o["mean_error_x_N"]) <= 0.5
    assert o["rms_error_x_N"] <= 1.5
    # Before the line is taut the walking robot's estimate is ~0 (no false pull).
    assert abs(o["estimated_x_mean_before_pull_N"]) < 0.3


def test_scenario_file_text_and_unknown_keys(tmp_path):
    """apps/scenarios/nao_walk_pulled_default.yaml lists every field at its default (the
    scenario convention, ``tests/scenario_checks.py``); YAML text overrides nested fields; an
    unknown nested key is an error that names it; a loaded bad value is refused by the
    builder."""
    check_scenario_convention(NaoWalkPulledScenario, "nao_walk_pulled_default.yaml", tmp_path)
    path = SCENARIOS / "nao_walk_pulled_default.yaml"
    scenario = load_scenario(NaoWalkPulledScenario, filename=path, text="pull: false\ncable: {stiffness: 1500.0}")
    assert not scenario.pull and scenario.cable.stiffness == 1500.0 and scenario.cable.pulley_height == 0.65
    with pytest.raises(ScenarioError, match="pulley_hieght"):
        load_scenario(NaoWalkPulledScenario, text="cable: {pulley_hieght: 1.0}")
    with pytest.raises(ValueError, match="lateral_angle_deg"):
        build_nao_walk_pulled_diagram(load_scenario(NaoWalkPulledScenario, text="cable: {lateral_angle_deg: 60.0}"))


def test_app_short_walk_without_pull(tmp_path):
    """The app on a short walk without the cable writes OUT/nao_walk_pulled/."""
    import json

    from apps import nao_walk_pulled

    assert (
        nao_walk_pulled.main(
            ["--out", str(tmp_path), "--headless", "--no-replay", "--steps", "2", "--no-pull", "--no-noise"]
        )
        == 0
    )
    m = json.loads((tmp_path / "nao_walk_pulled" / "metrics.json").read_text())
    assert m["walking"]["steps_planned"] == 2 and m["cable"] is None and m["scenario"]["pull"] is False
