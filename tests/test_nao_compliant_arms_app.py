"""apps.nao_compliant_arms, scenario b (push on both hands while leaning, feet partly off the
ground): outputs, the floor (hand displacement within 10 % of F / k against the true force
and the estimate) and that the blend of eq. (28) is really exercised (K1 < 1)."""

import json
import re

import numpy as np
import pytest
from scenario_checks import SCENARIOS, check_scenario_convention

from apps import nao_compliant_arms
from diagrams.observer.nao_compliant_arms import DEFAULT_FORCE, NaoCompliantArmsScenario, make_scenario
from diagrams.scenarios import load_scenario
from systems.simulation.visualization import read_static_html


@pytest.fixture(scope="module")
def app_output(tmp_path_factory):
    out = tmp_path_factory.mktemp("nao_compliant_arms")
    assert nao_compliant_arms.main(["--out", str(out), "--headless", "--case", "b", "--seed", "3"]) == 0
    return out / "nao_compliant_arms"


@pytest.mark.slow
def test_outputs_and_floor(app_output):
    assert (app_output / "scenario_b.png").stat().st_size > 20_000
    metrics = json.loads((app_output / "metrics.json").read_text())
    assert set(metrics) == {"scenario_b", "summary", "scenario", "memory_allocator"}
    m = metrics["scenario_b"]
    assert m["floor_relative_error"] == 0.10 and metrics["summary"]["seed"] == 3
    assert metrics["scenario"]["station"]["seed"] == 3 and metrics["scenario"]["cases"] == ["b"]
    for side in ("left", "right"):
        hand = m["hands"][side]
        # The applied force per hand is -1.5 N along the torso's x (the torso barely tilts).
        assert abs(hand["F_true_x_N"] + DEFAULT_FORCE) < 0.01 * DEFAULT_FORCE
        assert hand["relative_error_vs_true"] <= 0.10 and hand["relative_error_vs_estimate"] <= 0.10, hand
        assert abs(hand["displacement_m"] - hand["F_true_over_k_m"]) <= 0.10 * abs(hand["F_true_over_k_m"])
        joint = hand["estimate_errors_x"]["joint_force"]
        assert abs(joint["steady_state_mean_error_N"]) < 0.05 and joint["hold_rms_error_N"] < 0.1
    assert m["meets_floor"] is True
    # Eq. (28) at work: some FSRs lost contact, so the joint-level estimate has weight.
    assert 0.0 < m["k1_steady_mean"] < 1.0
    assert m["fsr_saturated_samples"] == 0 and m["base_height_drop_m"] < 0.01
    assert all(np.isfinite(v) for v in metrics["summary"]["motor_constants_N_m_per_rad"].values())


@pytest.mark.slow
def test_replay_is_self_contained_and_animated(app_output):
    html = (app_output / "scenario_b.html").read_text()
    assert re.findall(r"<(?:script|link)[^>]+(?:src|href)\s*=\s*[\"']((?:https?:)?//[^\"']+)", html) == []
    scene = read_static_html(html)
    assert any("applied_forces" in path for path in scene.tracks)
    assert any("estimated_hand_forces" in path for path in scene.tracks)
    assert any("nao_like" in path for path in scene.tracks)


def test_bad_arguments(capsys):
    assert nao_compliant_arms.main(["--force", "-1", "--no-replay"]) == 2
    assert "force must be in" in capsys.readouterr().err
    assert nao_compliant_arms.main(["--seed", "-2", "--no-replay"]) == 2
    with pytest.raises(SystemExit):
        nao_compliant_arms.main(["--case", "c"])
    with pytest.raises(ValueError, match="unknown scenario"):
        make_scenario("c")


def test_scenario_file_text_overrides_and_unknown_keys(tmp_path, capsys):
    check_scenario_convention(NaoCompliantArmsScenario, "nao_compliant_arms_default.yaml", tmp_path, "push_force")
    overridden = load_scenario(
        NaoCompliantArmsScenario,
        filename=SCENARIOS / "nao_compliant_arms_default.yaml",
        text="cases: [b]\nlean: -0.2\nstation: {plant_config: {discrete_contact_approximation: lagged}}",
    )
    assert (overridden.cases, overridden.lean, overridden.force) == (["b"], -0.2, DEFAULT_FORCE)
    assert overridden.station.plant_config.discrete_contact_approximation == "lagged"
    assert nao_compliant_arms.main(["--scenario-text", "push_force: 2.0", "--no-replay", "--out", str(tmp_path)]) == 2
    assert "nao_compliant_arms: error:" in capsys.readouterr().err
