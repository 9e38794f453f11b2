"""apps.model_refinement on a short horizon: calibration, checks, files; identification from
a saved log; bad input."""

import json

import pytest
from scenario_checks import check_scenario_convention

from apps import model_refinement
from diagrams.residuals.model_refinement import ModelRefinementScenario

SHORT = (
    "{calibration_duration: 8.0, standing_duration: 3.0, check_duration: 3.0, skip: 1.0, "
    "station: {base_state: truth_plus_noise}, calibration_motion: {seed: 1, min_frequency: 0.2, max_frequency: 0.5, "
    "ramp_time: 1.0}}"
)


@pytest.mark.slow
def test_app_calibrates_checks_and_reuses_its_log(tmp_path, capsys):
    assert model_refinement.main(["--scenario-text", SHORT, "--out", str(tmp_path)]) == 0
    out = tmp_path / "model_refinement"
    for name in ("model_corrections.npz", "calibration_log.npz", "spurious_effort.png", "metrics.json"):
        assert (out / name).stat().st_size > 1000, name
    metrics = json.loads((out / "metrics.json").read_text())
    standing = metrics["standing"]
    # The mismatch's spurious force is there, and the refined model removes most of it.
    assert standing["nominal_model"]["external_force_rms_N"] > 2.0
    assert standing["external_force_reduction"] > 0.5
    assert metrics["scenario"]["station"]["imperfections"]["model_mismatch"]["mass_percent"] == 5.0
    assert "removed" in capsys.readouterr().out
    # The same identification from the saved log (a robot's own log), without the checks.
    again = tmp_path / "again"
    log = out / "calibration_log.npz"
    assert model_refinement.main(["--scenario-text", SHORT, "--log", str(log), "--out", str(again)]) == 0
    metrics_again = json.loads((again / "model_refinement" / "metrics.json").read_text())
    assert "standing" not in metrics_again
    assert metrics_again["identification"]["rank"] == metrics["identification"]["rank"]


def test_app_reports_bad_input(tmp_path, capsys):
    assert model_refinement.main(["--log", str(tmp_path / "missing.npz"), "--out", str(tmp_path)]) == 2
    assert "missing.npz" in capsys.readouterr().err
    assert model_refinement.main(["--scenario-text", "calibration_duration: -1", "--out", str(tmp_path)]) == 2
    assert "calibration_duration" in capsys.readouterr().err


def test_scenario_convention(tmp_path):
    check_scenario_convention(ModelRefinementScenario, "model_refinement_default.yaml", tmp_path)
