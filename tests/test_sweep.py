"""The sweep of the contact study (issue 35): its grid, cells, rows and summary, its files
(atomic chunks, resuming, never overwriting), and the same rows bit for bit on every engine."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pyarrow as pa
import pytest
from scipy.stats import beta

from apps import sweep
from diagrams.residuals.contact_study import ContactLocalizationScenario
from diagrams.residuals.contact_sweep import (
    ROW_SCHEMA,
    RUN_COLUMNS,
    SweepCell,
    SweepGrid,
    cell_scenario,
    cell_summary,
    chunk_file,
    chunks,
    grid_as_yaml,
    read_trials,
    sweep_cells,
    trial_row,
    write_chunk,
)
from diagrams.scenarios import load_scenario

#: A tiny ideal-world grid: 2 cells x 4 trials in chunks of 2, short pushes (about 10 s on one core).
TINY = "{world: ideal, robots: [hrp4_like], noise_scales: [0.5, 1.0], trials_per_cell: 4, trials_per_job: 2,"
TINY += " base: {push_start: 0.3}}"


def test_grid_cells_and_scenarios():
    grid = SweepGrid(
        robots=["hrp4_like", "models/robots/talos.yaml"],
        imperfection_seeds=[3, 4],
        mismatch_scales=[0.5, 2.0],
        noise_scales=[1.0, 3.0],
        contacts=[1, 2],
        push_durations=[0.4],
        force_range=[10.0, 20.0],
        trials_per_cell=30,
        seed=11,
        num_seeds=2,
    ).validate()
    cells = sweep_cells(grid)
    assert len(cells) == 2 * 2 * 2 * 2 * 2
    assert len({c.key for c in cells}) == len(cells)  # each cell's files are its own
    assert cells[0].robot == "hrp4_like" and cells[-1].robot == "models/robots/talos.yaml"
    cell = SweepCell("hrp4_like", 4, 2.0, 3.0, 2, 0.4)
    scenario = cell_scenario(grid, cell)
    realistic = ContactLocalizationScenario().station.imperfections.model_mismatch
    station = scenario.station
    assert station.imperfections.seed == 4
    assert station.imperfections.model_mismatch.mass_percent == pytest.approx(2.0 * realistic.mass_percent)
    assert station.imperfections.model_mismatch.inertia_percent == pytest.approx(2.0 * realistic.inertia_percent)
    assert (station.noise_scale, scenario.contacts, scenario.push_duration) == (3.0, 2, 0.4)
    assert (scenario.trials, station.seed, scenario.num_seeds, scenario.force_range) == (30, 11, 2, [10.0, 20.0])
    assert scenario.no_contact_duration == 0 and scenario.slow_motion_duration == 0
    assert station.model_refinement == "calibrate" and station.base_state == "invariant_ekf"
    ideal = cell_scenario(replace(grid, world="ideal"), cell).station
    assert ideal.model_refinement == "none" and ideal.imperfections.is_ideal and ideal.noise_scale == 3.0
    # The grid file round-trips.
    assert grid_as_yaml(load_scenario(SweepGrid, text=grid_as_yaml(grid))) == grid_as_yaml(grid)
    assert [len(c) for c in chunks(list(range(7)), 3)] == [3, 3, 1]


@pytest.mark.parametrize(
    "text, field",
    [
        ("robots: []", "robots"),
        ("noise_scales: [1.0, 1.0]", "noise_scales"),
        ("noise_scales: [-1.0]", "noise_scales"),
        ("contacts: [3]", "contacts"),
        ("push_durations: [0.0]", "push_durations"),
        ("force_range: [10.0, 5.0]", "force_range"),
        ("force_range: [0.0, 5.0]", "force_range"),
        ("trials_per_cell: 0", "trials_per_cell"),
        ("world: moon", "world"),
        ("imperfection_seeds: [-1]", "imperfection_seeds"),
        ("seed: -3", "seed"),
        ("push_durations: [.inf]", "push_durations"),
    ],
)
def test_bad_grids_are_refused_naming_the_field(text, field):
    with pytest.raises(ValueError, match=field):
        load_scenario(SweepGrid, text=text).validate()


def _row(detected=True, right=True, error=0.01, force=0.1) -> dict:
    return {
        "detected": detected,
        "link_among_pushed": right,
        "position_error_m": error,
        "force_error_rel": force if detected else None,
    }


def test_cell_summary_counts_and_intervals():
    rows = [_row(error=0.001 * k) for k in range(1, 17)] + [_row(right=False, error=0.2)]
    rows += [_row(detected=False, right=False, error=None) for _ in range(3)]
    s = cell_summary(rows)
    assert s["trials"] == 20 and s["detection_rate"] == 17 / 20 and s["right_link_rate"] == 16 / 20
    # Clopper-Pearson, from scipy's beta quantiles directly.
    low, high = beta.ppf(0.025, 16, 5), beta.ppf(0.975, 17, 4)
    assert s["right_link_rate_interval"] == pytest.approx([low, high])
    # A trial without a localization is an infinite error: the median is the 10th/11th of 20.
    assert s["median_position_error_m"] == pytest.approx((0.010 + 0.011) / 2)
    assert s["p95_position_error_m"] == math.inf
    assert s["median_force_error_rel"] == pytest.approx(0.1)
    with pytest.raises(ValueError):
        cell_summary([])


def test_rows_match_the_schema_and_chunks_are_written_atomically(tmp_path):
    cell = SweepCell("hrp4_like", 0, 1.0, 1.0, 1, 0.5)
    result = {
        "trial": 3,
        "seed": 7,
        "trial_of_seed": 3,
        "body": "L_ELBOW_P_LINK",
        "geometry": "g",
        "force_world": [3.0, 0.0, 4.0],
        "point_body": [0.0, 0.1, 0.0],
        "contacts": [{"body": "L_ELBOW_P_LINK"}],
        "detected": False,
        "detection_delay_s": None,
        "detector_on_at_push_start": False,
        "false_detections_before_push": 0,
        "status": "no_contact",
        "estimated_body": None,
        "correct_link": False,
        "position_error_m": None,
        "force_error_rel": None,
        "angle_error_deg": None,
        "sole_slip_m": 0.0,
        "sole_slipped": False,
        "simulation_wall_s": 1.0,
        "localizer_update_s": 1e-4,
    }
    row = trial_row(cell, 1, result)
    assert set(row) == set(ROW_SCHEMA.names) and row["force_N"] == 5.0
    folder = tmp_path / "sweep"
    (folder / "trials").mkdir(parents=True)
    path = write_chunk(folder, cell.key, 1, [row])
    assert path == chunk_file(folder, cell.key, 1)
    assert [p.name for p in (folder / "trials").iterdir()] == [path.name]  # no temporary file left
    table = read_trials(folder)
    assert table.num_rows == 1 and table.schema == ROW_SCHEMA
    assert table.to_pylist()[0]["position_error_m"] is None
    assert read_trials(tmp_path / "empty").num_rows == 0


def test_a_sweep_folder_is_never_overwritten(tmp_path, capsys):
    grid = load_scenario(SweepGrid, text=TINY).validate()
    folder = tmp_path / "sweep"
    sweep._prepare_folder(folder, grid_as_yaml(grid), resume=False)
    before = (folder / "grid.yaml").read_bytes()
    with pytest.raises(ValueError, match="--resume"):
        sweep._prepare_folder(folder, grid_as_yaml(grid), resume=False)
    with pytest.raises(ValueError, match="another grid"):
        sweep._prepare_folder(folder, grid_as_yaml(replace(grid, trials_per_cell=5)), resume=True)
    sweep._prepare_folder(folder, grid_as_yaml(grid), resume=True)
    assert (folder / "grid.yaml").read_bytes() == before
    # Through the command line: one line naming the problem, exit 2, the folder unchanged.
    assert sweep.main(["--grid-text", TINY, "--engine", "local", "--out", str(tmp_path), "--no-progress"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert sweep.main(["--out", str(tmp_path)]) == 2
    assert "--grid" in capsys.readouterr().err
    assert sweep.main(["--grid", str(tmp_path / "missing.yaml"), "--out", str(tmp_path)]) == 2
    assert sweep.main(["--grid-text", "contacts: [3]", "--print-grid"]) == 2
    assert sweep.main(["--grid-text", TINY, "--engine", "pool", "--cluster", "127.0.0.1:1", "--out", "x"]) == 2
    assert "--cluster" in capsys.readouterr().err
    (tmp_path / "file").write_text("")
    assert sweep.main(["--grid-text", TINY, "--engine", "local", "--out", str(tmp_path / "file")]) == 2


def _rows(folder: Path) -> pa.Table:
    table = read_trials(folder).drop_columns(list(RUN_COLUMNS))
    return table.sort_by([("cell", "ascending"), ("trial", "ascending")])


def test_tiny_sweep_resumes_what_is_missing(tmp_path, capsys):
    """The tiny grid in this process; then one chunk removed and the sweep resumed: only
    that chunk runs again, and every row is the same bit for bit."""
    args = ["--grid-text", TINY, "--engine", "local", "--no-progress", "--out", str(tmp_path)]
    assert sweep.main(args) == 0
    folder = tmp_path / "sweep"
    first = _rows(folder)
    assert first.num_rows == 8 and set(first["noise_scale"].to_pylist()) == {0.5, 1.0}
    assert sorted(first["trial"].to_pylist()) == [0, 0, 1, 1, 2, 2, 3, 3]
    for name in ("summary.json", "summary.csv", "sweep.png", "grid.yaml"):
        assert (folder / name).is_file()
    cells = json.loads((folder / "summary.json").read_text())["cells"]
    assert [c["robot_mass_kg"] for c in cells] == pytest.approx([39.0, 39.0], abs=0.01)  # hrp4_like's 39 kg
    assert all(c["calibrated_mass_kg"] is None for c in cells)  # the ideal world calibrates nothing
    summary = (folder / "summary.csv").read_text().splitlines()
    assert len(summary) == 3 and summary[0].startswith("cell,robot,")
    files = sorted((folder / "trials").iterdir())
    assert len(files) == 4
    files[1].unlink()
    capsys.readouterr()
    assert sweep.main([*args, "--resume"]) == 0
    out = capsys.readouterr().out
    assert "1 chunk(s) to run (6 trials already done)" in out
    assert _rows(folder).equals(first)
    assert sweep.main([*args, "--resume"]) == 0  # nothing left: the summary again
    assert "0 chunk(s) to run" in capsys.readouterr().out


@pytest.mark.slow
def test_same_rows_on_every_engine(tmp_path):
    """The tiny grid on a pool of 2 processes and on 2 Ray actors gives the rows of one
    worker in this process, bit for bit (but for the wall times and the worker's name)."""
    pytest.importorskip("ray")
    tables = {}
    for engine, workers in (("local", "1"), ("pool", "2"), ("ray", "2")):
        out = tmp_path / engine
        code = sweep.main(
            ["--grid-text", TINY, "--engine", engine, "--workers", workers, "--no-progress", "--out", str(out)]
        )
        assert code == 0
        tables[engine] = _rows(out / "sweep")
    assert tables["local"].num_rows == 8
    assert tables["pool"].equals(tables["local"])
    assert tables["ray"].equals(tables["local"])
    workers = set(read_trials(tmp_path / "ray" / "sweep")["worker"].to_pylist())
    assert len(workers) == 2  # both actors ran chunks
