"""Integration test of the residual-estimation diagram and smoke test of its app."""

from __future__ import annotations

import json

import numpy as np
import pytest

from apps import residual_comparison
from apps.residual_comparison import first_order_filter, relative_rms_error, run
from diagrams.residuals.residual_comparison import ResidualComparisonConfig


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
    config = ResidualComparisonConfig(duration=3.0, noise=False)
    return config, *run(config, skip=0.5)


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


def test_robot_stands_still_while_pushed(short_noise_free_run):
    _, _, data = short_noise_free_run
    x = data["signals"]["state"]
    assert np.ptp(x[6]) < 0.01  # base height moves less than 1 cm
    assert np.ptp(x[4]) < 0.02 and np.ptp(x[5]) < 0.02


def test_app_writes_figures_and_metrics(tmp_path, capsys):
    assert residual_comparison.main(["--duration", "1.2", "--out", str(tmp_path), "--seed", "3"]) == 0
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


def test_app_reports_bad_model_and_body(tmp_path, capsys):
    assert residual_comparison.main(["--model", str(tmp_path / "missing.sdf"), "--out", str(tmp_path)]) == 2
    assert "neither one of" in capsys.readouterr().err
    assert residual_comparison.main(["--push-body", "no_such_link", "--duration", "1", "--out", str(tmp_path)]) == 2
    assert "no_such_link" in capsys.readouterr().err
