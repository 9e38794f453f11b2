"""Integration test of the residual-estimation diagram and smoke test of its app."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scenario_checks import SCENARIOS, check_scenario_convention

from apps import residual_comparison
from apps.residual_comparison import run_once
from diagrams.residuals.residual_comparison import (
    ResidualComparisonScenario,
    check_metrics_window,
    first_order_filter,
    relative_rms_error,
)
from diagrams.scenarios import load_scenario
from diagrams.station.config import StationConfig


def test_scenario_files_load_into_the_dataclass(tmp_path):
    check_scenario_convention(ResidualComparisonScenario, "residual_comparison_default.yaml", tmp_path, "push_strength")
    default_file = load_scenario(ResidualComparisonScenario, filename=SCENARIOS / "residual_comparison_default.yaml")
    assert default_file.push_body is None and default_file.push_amplitude == 40.0
    overridden = load_scenario(
        ResidualComparisonScenario,
        filename=SCENARIOS / "residual_comparison_default.yaml",
        text="skip: 1.0\npush_direction: [0, 0, -1]\n"
        "station: {seed: 7, plant_config: {discrete_contact_approximation: lagged}}",
    )
    assert (overridden.station.seed, overridden.skip, overridden.push_direction) == (7, 1.0, [0.0, 0.0, -1.0])
    assert overridden.station.plant_config.discrete_contact_approximation == "lagged"
    assert overridden.station.plant_config.time_step == 1e-3
    assert overridden.duration == 10.0  # other keys keep the defaults
    with pytest.raises(ValueError, match="skip < duration"):
        check_metrics_window(ResidualComparisonScenario(duration=1.0, skip=1.0))


def test_relative_rms_error_and_first_order_filter():
    truth = np.array([[1.0, 2.0, -2.0]])
    assert relative_rms_error(truth * 1.1, truth) == pytest.approx(0.1)
    assert np.isnan(relative_rms_error(truth, np.zeros_like(truth)))
    # A step through y' = K (u - y): 1 - exp(-K t) at the samples (exact for held input).
    K, dt = 20.0, 0.01
    y = first_order_filter(np.ones((1, 50)), K, dt)
    t = np.arange(50) * dt
    np.testing.assert_allclose(y[0], 1.0 - np.exp(-K * t), rtol=1e-12, atol=1e-15)


@pytest.fixture(scope="module")
def short_noise_free_run():
    """3 s of the paper's experiment with ideal sensors (the push starts at 0.5 s)."""
    scenario = ResidualComparisonScenario(station=StationConfig(noise=False), duration=3.0, skip=0.5)
    run = run_once(scenario)
    return scenario, run["metrics"], run


def test_internal_and_external_residuals_track_the_truth(short_noise_free_run):
    config, metrics, _ = short_noise_free_run
    # Against the truth seen through each residual's own first-order filter (its design).
    assert metrics["internal_rel_rms_error_vs_filtered_truth"] < 0.01
    assert metrics["external_force_rel_rms_error_vs_filtered_truth"] < 0.01
    assert metrics["external_wrench_base_rel_rms_error_vs_filtered_truth"] < 0.01
    for joint in ("R_KNEE_P", "L_KNEE_P", "CHEST_Y"):
        assert metrics["internal_rel_rms_error_per_joint_vs_filtered_truth"][joint] < 0.03, joint


def test_classical_residual_cannot_see_the_legs(short_noise_free_run):
    """The paper's negative result (Sec. II-C, Fig. 3): the push loads the knees, the
    classical residual's knee entries stay ~0, and its joint part is far from the truth."""
    _, metrics, data = short_noise_free_run
    assert metrics["classical_rel_rms_error"] > 0.3
    for knee in ("R_KNEE_P", "L_KNEE_P"):
        true_rms = metrics["rms_true_joint_effort_Nm"][knee]
        assert true_rms > 0.05
        assert metrics["rms_classical_joint_effort_Nm"][knee] < 0.05 * true_rms


@pytest.mark.parametrize("robot", ["hrp4_like_no_ft.yaml", "hrp4_like_fsr.yaml"])
def test_residuals_net_of_the_soles_track_the_truth_without_foot_ft_sensors(robot):
    """Without foot F/T sensors the raw residuals hold the robot's weight (hundreds of N on
    the knees); net of the soles' wrenches fitted with the push's link (SoleWrenchCompensation)
    they track the push's own effort as the F/T robot's do, knees included, and the classical
    residual still cannot see the legs."""
    scenario = ResidualComparisonScenario(
        station=StationConfig(model=f"models/robots/{robot}", noise=False), duration=3.0, skip=0.5
    )
    run = run_once(scenario)
    metrics = run["metrics"]
    assert set(run["handles"].sole_compensations) == {"internal", "classical"}
    assert metrics["internal_rel_rms_error_vs_filtered_truth"] < 0.01
    assert metrics["external_force_rel_rms_error_vs_filtered_truth"] < 0.01
    assert metrics["external_wrench_base_rel_rms_error_vs_filtered_truth"] < 0.01
    for joint in ("R_KNEE_P", "L_KNEE_P", "CHEST_Y"):
        assert metrics["internal_rel_rms_error_per_joint_vs_filtered_truth"][joint] < 0.03, joint
    assert metrics["classical_rel_rms_error"] > 0.3
    for knee in ("R_KNEE_P", "L_KNEE_P"):
        assert metrics["rms_classical_joint_effort_Nm"][knee] < 0.05 * metrics["rms_true_joint_effort_Nm"][knee]
    with pytest.raises(ValueError, match="must be equal"):
        run_once(dataclasses.replace(scenario, classical_gain=20.0))


def test_robot_stands_still_while_pushed(short_noise_free_run):
    _, _, data = short_noise_free_run
    x = data["signals"]["state"]
    assert np.ptp(x[6]) < 0.01  # base height moves less than 1 cm
    assert np.ptp(x[4]) < 0.02 and np.ptp(x[5]) < 0.02


def test_app_writes_figures_and_metrics(tmp_path, capsys):
    assert residual_comparison.main(["--duration", "1.2", "--out", str(tmp_path), "--seed", "3", "--ideal"]) == 0
    out = tmp_path / "residual_comparison"
    for name in ("fig3_classical.png", "fig4_internal.png", "fig7_external_base.png", "fig8_external_force.png"):
        assert (out / name).stat().st_size > 10_000, name
    metrics = json.loads((out / "metrics.json").read_text())
    for key in (
        "internal_rel_rms_error",
        "internal_rel_rms_error_per_joint",
        "classical_rel_rms_error",
        "external_force_rel_rms_error",
    ):
        assert key in metrics
    assert set(metrics["internal_rel_rms_error_per_joint"]) >= {"R_KNEE_P", "L_KNEE_P", "CHEST_Y"}
    assert metrics["noise"] is True and metrics["seed"] == 3
    assert "internal residual" in capsys.readouterr().out
    assert metrics["scenario"]["station"]["seed"] == 3 and metrics["scenario"]["duration"] == 1.2


def test_app_reads_scenario_file_and_text_and_reports_errors(tmp_path, capsys):
    scenario = tmp_path / "short.yaml"
    scenario.write_text("duration: 1.0\nskip: 0.2\nstation: {seed: 5, noise: false}\n")
    args = [
        "--scenario",
        str(scenario),
        "--scenario-text",
        "station: {seed: 6}",
        "--skip",
        "0.3",
        "--ideal",
        "--out",
        str(tmp_path),
    ]
    assert residual_comparison.main(args) == 0
    metrics = json.loads((tmp_path / "residual_comparison" / "metrics.json").read_text())
    assert (metrics["duration_s"], metrics["seed"], metrics["noise"], metrics["skip_s"]) == (1.0, 6, False, 0.3)
    capsys.readouterr()
    assert residual_comparison.main(["--scenario-text", "push_strength: 3", "--out", str(tmp_path)]) == 2
    assert "push_strength" in capsys.readouterr().err
    assert residual_comparison.main(["--duration", "0.4", "--out", str(tmp_path)]) == 2  # skip 0.5 >= duration
    assert "skip < duration" in capsys.readouterr().err


def test_app_reports_bad_model_and_body(tmp_path, capsys):
    assert residual_comparison.main(["--model", str(tmp_path / "missing.sdf"), "--out", str(tmp_path)]) == 2
    assert "neither one of" in capsys.readouterr().err
    assert residual_comparison.main(["--push-body", "no_such_link", "--duration", "1", "--out", str(tmp_path)]) == 2
    assert "no_such_link" in capsys.readouterr().err
