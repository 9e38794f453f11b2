"""apps.engine_scaling: the model of a sweep on N nodes, and the app on a short horizon."""

from __future__ import annotations

import json

import pytest

from apps import engine_scaling


def test_sweep_model_adds_startup_calibration_waves_and_trials():
    # 90 cells on 16 workers: 6 waves of calibrations; 90,000 trials of 2 s over 16 workers.
    m = engine_scaling.sweep_model(2.0, 100.0, 10.0, 1e-3, nodes=8, workers_per_node=2)
    assert (m["workers"], m["trials"]) == (16, 90_000)
    assert m["calibration_phase_s"] == pytest.approx(6 * 100.0)
    assert m["trial_phase_s"] == pytest.approx(90_000 * 2.0 / 16)
    assert m["wall_s"] == pytest.approx(10.0 + 600.0 + 11_250.0)
    assert m["trials_per_s_needed"] == pytest.approx(8.0) and m["driver_keeps_up"]
    # A driver that absorbs fewer trials per second than the workers finish does not keep up.
    slow = engine_scaling.sweep_model(2.0, 100.0, 10.0, 1.0, nodes=64, workers_per_node=2)
    assert slow["trials_per_s_needed"] == pytest.approx(64.0) and not slow["driver_keeps_up"]


@pytest.mark.slow
def test_quick_run_writes_its_results(tmp_path, monkeypatch):
    pytest.importorskip("ray")
    monkeypatch.setenv("HCO_RESULTS_DIR", str(tmp_path / "results"))
    argv = ["--quick", "--trials", "2", "--driver-jobs", "50", "--results", "scaling", "--out", str(tmp_path)]
    assert engine_scaling.main(argv) == 0
    data = json.loads((tmp_path / "results" / "scaling.json").read_text())["data"]
    assert set(data["runs"]) == {"ray_2", "pool_2", "local_1"}
    assert all(run["same_results_as_pool"] for run in data["runs"].values())
    assert data["driver"]["trials_per_s"] > 0 and [m["nodes"] for m in data["model"]] == [1, 8, 64]
