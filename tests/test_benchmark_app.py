"""Smoke test of `python -m apps.benchmark` (the timings themselves are never asserted)."""

import json
import shlex

from apps import benchmark, doc_tables
from apps.results import RESULTS_DIR_VARIABLE, load_results


def test_benchmark_runs_and_reports_every_figure(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(RESULTS_DIR_VARIABLE, str(tmp_path / "results"))  # never the committed file
    argv = ["--model", "nao_like", "--calls", "3", "--batches", "1", "--loop-seconds", "0.08", "--out", str(tmp_path)]
    assert benchmark.main([*argv, "--results", "benchmark"]) == 0
    results = json.loads((tmp_path / "benchmark" / "metrics.json").read_text())
    rows = results["floating_base"]
    assert [r["model"] for r in rows] == ["nao_like"]
    row = rows[0]
    assert row["num_joints"] == 26
    for key in ("calc_mass_matrix_us", "fast_compute_us", "reference_compute_us", "fast_floating_jacobian_us"):
        assert row[key] > 0.0
    assert row["fast_compute_ratio"] == row["fast_compute_us"] / row["calc_mass_matrix_us"]
    (residual,) = results["residual_update"]
    assert residual["model"] == "nao_like" and residual["three_residuals_update_us"] > 0.0
    loops = results["closed_loop"]
    assert [r["loop"] for r in loops] == [
        "station: plant + sensors + PD",
        "push-and-comply, internal residual",
        "Meshcat recording",
    ]
    assert all(r["wall_us_per_step"] > 0 and r["cpu_us_per_step"] > 0 for r in loops)
    assert "nao_like" in capsys.readouterr().out

    # The results file: the same figures, the floors they are checked against, the command.
    payload = load_results("benchmark", tmp_path / "results")
    assert payload["command"] == shlex.join(["python", "-m", "apps.benchmark", *argv, "--results", "benchmark"])
    assert payload["data"]["floors"] == benchmark.FLOORS
    assert payload["data"]["floating_base"] == results["floating_base"]
    assert payload["data"]["settings"]["models"] == ["nao_like"]
    # Every table of BENCHMARKS.md renders from it; what this run skipped says so.
    for name in [n for n, files in doc_tables.SOURCES.items() if files == ("benchmark",)]:
        body = doc_tables.render(name, tmp_path / "results")
        assert "`results/benchmark.json`" in body
    assert doc_tables.render("benchmark_log_estimation", tmp_path / "results").startswith("Not measured in this run")


def test_without_results_the_benchmark_writes_no_results_file(tmp_path, monkeypatch):
    monkeypatch.setenv(RESULTS_DIR_VARIABLE, str(tmp_path / "results"))
    argv = ["--model", "nao_like", "--calls", "1", "--batches", "1", "--loop-seconds", "0", "--out", str(tmp_path)]
    assert benchmark.main(argv) == 0
    assert (tmp_path / "benchmark" / "metrics.json").is_file()
    assert not (tmp_path / "results").exists()


def test_benchmark_stops_with_a_clear_error_when_the_nao_recording_is_missing(tmp_path, monkeypatch, capsys):
    """The observer's figure is never silently skipped: a missing recording is an error
    naming the path, reported before the timings start."""
    monkeypatch.setenv("HCO_SHARED_DIR", str(tmp_path))
    assert benchmark.main(["--model", "nao_like", "--loop-seconds", "0"]) == 2
    err = capsys.readouterr().err
    assert "benchmark: error:" in err and str(tmp_path / "datasets" / "hawley2019-nao") in err


def test_a_closed_loop_shorter_than_its_warm_up_is_refused_before_any_timing(capsys):
    assert benchmark.main(["--model", "nao_like", "--loop-seconds", "0.03"]) == 2
    assert "--loop-seconds must be 0 (skip) or exceed the closed loop's 0.05 s warm-up" in capsys.readouterr().err


def test_residual_replay_benchmark_times_both_paths_on_one_log():
    """The calibration replay's timing (``benchmark_residual_replay``): both paths on the same
    short log, and they agree (to the mass matrix's central difference)."""
    row = benchmark.benchmark_residual_replay(0.3, repeats=1)
    assert row["samples"] == 300
    assert row["per_sample_us"] > 0.0 and row["stacked_us"] > 0.0
    assert row["speedup"] == row["per_sample_us"] / row["stacked_us"]
    assert row["largest_difference"] < 1e-6


def test_benchmark_times_the_pinocchio_peer_beside_the_residual_bank(tmp_path, monkeypatch):
    """Issue 33: on hrp4_like the three residuals' bank is timed beside its Pinocchio peer in
    the same run, the ratio and their agreement go to the results file, and its table renders."""
    monkeypatch.setenv(RESULTS_DIR_VARIABLE, str(tmp_path / "results"))
    argv = ["--model", "hrp4_like", "--calls", "2", "--batches", "1", "--loop-seconds", "0", "--log-seconds", "0"]
    argv += ["--fit-pairs", "0", "--peer-steps", "3", "--out", str(tmp_path), "--results", "benchmark"]
    assert benchmark.main(argv) == 0
    results = json.loads((tmp_path / "benchmark" / "metrics.json").read_text())
    (row,) = results["residual_peer"]
    assert row["model"] == "hrp4_like" and row["agreement_steps"] == 3 and results["settings"]["peer_steps"] == 3
    assert row["project_over_peer"] == row["project_bank_us"] / row["peer_us"] > 0.0
    assert row["largest_relative_difference"] < 1e-8
    assert results["floors"]["residual_bank_max_ratio_to_peer"] == 1.0
    body = doc_tables.render("benchmark_residual_peer", tmp_path / "results")
    assert body.startswith("| model | DoF (joints) |") and "| hrp4_like | 34 | 2 |" in body
