"""The walking diagram (diagrams.locomotion.nao_walk) in simulation: a short walk, the ZMP from
contact forces, the step detector, and apps.nao_walk's full floor run (22 steps, ~7 s wall)."""

import json

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from scenario_checks import SCENARIOS, check_scenario_convention

from apps import nao_walk
from diagrams.locomotion.nao_walk import (
    NaoWalkScenario,
    build_nao_walk_diagram,
    detect_steps,
    signed_distance_to_polygon,
    walking_metrics,
)
from diagrams.scenarios import ScenarioError, load_scenario
from systems.locomotion.walking_pattern import WalkingParameters


@pytest.fixture(scope="module")
def short_walk():
    params = WalkingParameters(num_steps=6, final_wait=0.5)
    diagram, handles = build_nao_walk_diagram(NaoWalkScenario(walking=params))
    simulator = Simulator(diagram)
    handles.set_initial_state(simulator.get_mutable_context())
    simulator.Initialize()
    simulator.AdvanceTo(handles.controller.duration)
    return handles, walking_metrics(handles, simulator.get_context())


def test_short_walk_stays_upright_and_moves_forward(short_walk):
    handles, m = short_walk
    planned = handles.controller.pattern.steps[-1].end[0] - handles.controller.pattern.soles["left"][0][0]
    assert planned == pytest.approx(0.25)
    assert m["upright"] and m["max_base_tilt_deg"] < 8.0
    assert m["steps_detected"] == 6
    assert m["distance_m"] == pytest.approx(planned, abs=0.03)  # the CoM ends over the final feet
    assert abs(m["lateral_drift_m"]) < 0.03 and m["max_abs_yaw_deg"] < 5.0
    assert m["max_footprint_error_m"] < 0.03 and m["max_stride_error_m"] < 0.015
    assert m["zmp_in_support_fraction"] >= 0.98
    assert m["samples_without_contact"] == 0


def test_detected_steps_follow_the_plan(short_walk):
    handles, m = short_walk
    s = m["signals"]
    steps = detect_steps(s["t"], s["foot_normal_forces"].T)
    plan = handles.controller.pattern.steps
    assert len(steps) == len(plan)
    for (foot, t_lift, t_land), step in zip(steps, plan):
        assert foot == (0 if step.side == "left" else 1)
        assert abs(t_lift - step.t_lift) < 0.06 and abs(t_land - step.t_land) < 0.06


def test_contact_zmp_matches_weight_and_standing_cop(short_walk):
    handles, m = short_walk
    s = m["signals"]
    t = s["t"]
    mass = handles.station.plant.CalcTotalMass(handles.station.plant.CreateDefaultContext())
    standing = (t > 0.2) & (t < 0.6)
    total = s["foot_normal_forces"][standing].sum(axis=1)
    assert np.abs(total - mass * 9.81).max() < 0.05 * mass * 9.81
    # Standing still, the ZMP is under the CoM.
    np.testing.assert_allclose(s["zmp"][standing][-1], s["com"][standing][-1, :2], atol=3e-3)


def test_signed_distance_to_polygon():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    assert signed_distance_to_polygon(square, np.array([0.5, 0.5])) == pytest.approx(0.5)
    assert signed_distance_to_polygon(square, np.array([0.9, 0.5])) == pytest.approx(0.1)
    assert signed_distance_to_polygon(square, np.array([1.2, 0.5])) == pytest.approx(-0.2)


@pytest.mark.slow
def test_app_full_walk_meets_the_floors(tmp_path):
    assert nao_walk.main(["--out", str(tmp_path), "--headless", "--no-replay"]) == 0
    out = tmp_path / "nao_walk"
    m = json.loads((out / "metrics.json").read_text())
    assert m["meets_floors"] and all(m["floors"].values())
    assert m["steps_detected"] >= 20 and m["distance_m"] >= 1.0 and m["mean_speed_mps"] >= 0.08 and not m["fell"]
    assert m["zmp_in_support_fraction"] >= 0.98
    for name in ("walk_top.png", "walk_time.png"):
        assert (out / name).stat().st_size > 20_000


def test_app_rejects_bad_parameters(tmp_path, capsys):
    assert nao_walk.main(["--out", str(tmp_path), "--step-duration", "-0.5", "--no-replay"]) == 2
    assert "step_duration" in capsys.readouterr().err
    assert nao_walk.main(["--out", str(tmp_path), "--step-length", "0.3", "--no-replay"]) == 2


def test_contact_zmp_moves_by_the_static_moment_of_a_pull():
    """Standing (before the first step) with a 3 N pull backwards at the waist, 5 deg up: the
    ZMP from the contact forces satisfies the static moment balance about y,
    p_x = (m g c_x + P_z F_x - P_x F_z) / (m g - F_z), with the simulated CoM c and the
    force's point P (the pull moves it ~15 mm backwards)."""
    from systems.simulation.disturbances import Push, Step

    angle = np.radians(5.0)
    direction = np.array([-np.cos(angle), 0.0, np.sin(angle)])
    push = Push("torso", [0.0, 0.0, -0.05], direction, Step(3.0, 0.1))
    params = WalkingParameters(num_steps=1, initial_wait=3.0)  # still: lowered by 1.5 s, first step at 3 s
    diagram, handles = build_nao_walk_diagram(NaoWalkScenario(walking=params), pushes=[push])
    simulator = Simulator(diagram)
    handles.set_initial_state(simulator.get_mutable_context())
    simulator.Initialize()
    simulator.AdvanceTo(1.9)
    m = walking_metrics(handles, simulator.get_context())
    s = m["signals"]
    k = np.searchsorted(s["t"], 1.85)
    plant = handles.station.plant
    context = plant.GetMyContextFromRoot(simulator.get_context())
    X_WT = plant.EvalBodyPoseInWorld(context, handles.station.humanoid.base_body)
    P = X_WT.multiply(np.array([0.0, 0.0, -0.05]))
    F = 3.0 * direction
    weight = plant.CalcTotalMass(context) * 9.81
    c = s["com"][k]
    expected = (weight * c[0] + P[2] * F[0] - P[0] * F[2]) / (weight - F[2])
    print(f"ZMP x {s['zmp'][k, 0]:.5f} m, static balance {expected:.5f} m, CoM x {c[0]:.5f} m")
    assert s["zmp"][k, 0] == pytest.approx(expected, abs=1e-3)
    assert expected - c[0] < -0.012  # the pull moved the ZMP behind the CoM
    assert s["foot_normal_forces"][k].sum() == pytest.approx(weight - F[2], rel=0.02)


def test_app_writes_a_meshcat_replay(tmp_path):
    assert nao_walk.main(["--out", str(tmp_path), "--headless", "--steps", "1"]) == 0
    out = tmp_path / "nao_walk"
    html = (out / "walk.html").read_text()
    assert len(html) > 100_000 and "meshcat" in html.lower()
    m = json.loads((out / "metrics.json").read_text())
    assert m["steps_detected"] == 1 and not m["fell"] and not m["meets_floors"]


def test_scenario_file_text_and_unknown_keys(tmp_path):
    """apps/scenarios/nao_walk_default.yaml lists every field at its default (the scenario
    convention, ``tests/scenario_checks.py``); YAML text overrides nested fields; an unknown
    nested key is an error that names it."""
    check_scenario_convention(NaoWalkScenario, "nao_walk_default.yaml", tmp_path)
    scenario = load_scenario(
        NaoWalkScenario,
        filename=SCENARIOS / "nao_walk_default.yaml",
        text="station: {seed: 3, plant_config: {time_step: 0.002}}\nwalking: {num_steps: 4}",
    )
    assert scenario.station.seed == 3 and scenario.walking.num_steps == 4
    assert scenario.station.plant_config.time_step == 0.002
    assert scenario.walking.step_length == WalkingParameters().step_length
    with pytest.raises(ScenarioError, match="walk_speed"):
        load_scenario(NaoWalkScenario, text="walking: {walk_speed: 1.0}")


def test_app_rejects_a_bad_scenario(tmp_path, capsys):
    assert nao_walk.main(["--out", str(tmp_path), "--no-replay", "--scenario-text", "walking: {com_height: 0.5}"]) == 2
    assert "com_height" in capsys.readouterr().err
