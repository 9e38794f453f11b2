"""The documentation's generated tables agree with their results files (issue 31)."""

from __future__ import annotations

import json
import re

import pytest

from apps import doc_tables
from apps.results import RESULTS_DIR, load_results, write_results


@pytest.mark.parametrize("document", doc_tables.DOCUMENTS, ids=lambda p: p.relative_to(doc_tables.ROOT).as_posix())
def test_every_generated_table_matches_its_results_file(document):
    text = document.read_text()
    _, stale = doc_tables.updated(text)
    assert not stale, (
        f"{document.relative_to(doc_tables.ROOT)}: stale tables {stale}: run `make docs` (python -m apps.doc_tables)"
    )


def test_every_results_file_is_quoted_and_every_quoted_table_has_one():
    quoted = {name for path in doc_tables.DOCUMENTS for name in doc_tables.block_names(path.read_text())}
    assert quoted <= set(doc_tables.RENDERERS), (
        f"blocks without a renderer: {sorted(quoted - set(doc_tables.RENDERERS))}"
    )
    files = {path.stem for path in RESULTS_DIR.glob("*.json")}
    read = {source for name in quoted for source in doc_tables.sources(name)}
    # Each file has a table of its own: a table that gathers several files does not count.
    own = {doc_tables.sources(name)[0] for name in quoted if len(doc_tables.sources(name)) == 1}
    assert files <= own, f"results files no document quotes in a table of their own: {sorted(files - own)}"
    assert read <= files, f"tables without a results file: {sorted(read - files)}"


def test_sources_name_renderers_and_each_file_once():
    """SOURCES names only renderers, and a block that reads several files names each once."""
    assert set(doc_tables.SOURCES) <= set(doc_tables.RENDERERS)
    for name, files in doc_tables.SOURCES.items():
        assert files and len(files) == len(set(files)), name


def test_every_block_is_in_one_document_once():
    names = [name for path in doc_tables.DOCUMENTS for name in doc_tables.block_names(path.read_text())]
    assert names, "no generated block found in the documents"
    assert len(names) == len(set(names)), (
        f"blocks quoted more than once: {sorted({n for n in names if names.count(n) > 1})}"
    )


def test_a_changed_figure_makes_its_table_stale(tmp_path):
    """Control: a figure changed in the results file is found, and the rewrite puts it in."""
    name = "push_and_comply_robots"
    payload = load_results(name)
    payload["data"]["rows"][0]["internal"]["knee_pitch_flexion_deg"] = 42.125
    write_results(name, payload["data"], command=payload["command"], folder=tmp_path)
    holders = [path for path in doc_tables.DOCUMENTS if name in doc_tables.block_names(path.read_text())]
    assert len(holders) == 1, f"the block {name} should be in exactly one document, found in {holders}"
    # Only this block: the document's other blocks have no results file in tmp_path.
    block = re.search(rf"<!-- results: {name} -->\n.*?<!-- /results: {name} -->", holders[0].read_text(), re.S)
    text, stale = doc_tables.updated(block.group(0), tmp_path)
    assert stale == [name]
    assert "42.12 deg" in text or "42.13 deg" in text
    assert doc_tables.updated(text, tmp_path)[1] == []


def test_results_files_carry_their_command_and_refuse_unreadable_ones(tmp_path):
    path = write_results("example", {"value": 1.5}, command="python -m apps.x --y", folder=tmp_path)
    payload = json.loads(path.read_text())
    assert payload["command"] == "python -m apps.x --y" and payload["data"] == {"value": 1.5}
    assert payload["drake"] and payload["python"]
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(ValueError, match="broken.json"):
        load_results("broken", tmp_path)
    with pytest.raises(ValueError, match="missing.json"):
        load_results("missing", tmp_path)
    with pytest.raises(ValueError, match="plain file stem"):
        write_results("../escape", {}, command="x", folder=tmp_path)
    with pytest.raises(ValueError, match="no table"):
        doc_tables.render("example", tmp_path)


def _fake_benchmark(**changes) -> dict:
    """A small results file of ``apps.benchmark``, every section measured once."""
    from apps.benchmark import FLOORS

    data = {
        "settings": {"models": ["hrp4_like"], "loop_seconds": 2.0},
        "floors": dict(FLOORS),
        "floating_base": [
            {
                "model": "hrp4_like",
                "num_joints": 34,
                "calc_mass_matrix_us": 20.0,
                "calc_mass_matrix_cached_kinematics_us": 8.0,
                "fast_compute_us": 142.0,
                "reference_compute_us": 4000.0,
                "fast_floating_jacobian_us": 40.0,
                "fast_compute_ratio": 7.1,
                "reference_compute_ratio": 200.0,
                "fast_floating_jacobian_ratio": 2.0,
                "reference_over_fast": 28.2,
            }
        ],
        "residual_update": [
            {
                "model": "hrp4_like",
                "known_wrench_frames": 2,
                "calc_mass_matrix_us": 20.0,
                "three_residuals_update_us": 90.0,
                "three_residuals_update_ratio": 4.5,
            }
        ],
        "force_observer": {"recording": "Force_Y_data", "samples_per_s": 19000.0, "samples": 1678},
        "closed_loop": [
            {
                "loop": "station: plant + sensors + PD",
                "wall_us_per_step": 500.0,
                "cpu_us_per_step": 490.0,
                "real_time_factor": 2.0,
            },
            {
                "loop": "Meshcat recording",
                "wall_us_per_step": 1250.0,
                "cpu_us_per_step": 1200.0,
                "real_time_factor": 0.8,
            },
        ],
        "contact_localizer": [
            {
                "model": "hrp4_like",
                "num_primitives": 35,
                "calc_mass_matrix_us": 20.0,
                "localizer_update_us": 2100.0,
                "localizer_update_ratio": 105.0,
            }
        ],
        "multi_contact_fit": [],
        "log_estimation": [
            {
                "model": "hrp4_like",
                "num_joints": 34,
                "log_seconds": 2.0,
                "log_rate_hz": 1000.0,
                "contact_fraction": 0.75,
                "us_per_sample": 200.0,
                "real_time_factor": 5.0,
                "floor": 5.0,
            }
        ],
        "residual_replay": [],
        "memory_allocator": "tcmalloc",
    }
    data.update(changes)
    return data


def test_the_benchmark_verdicts_are_computed_from_the_measured_figures_and_the_floors():
    """Each verdict follows the figure and the floor in the results file, both ways."""
    data = _fake_benchmark()
    base = "\n".join(doc_tables.RENDERERS["benchmark_floating_base"](data))
    assert "`fast` compute <= 12x one CalcMassMatrix on hrp4_like: met (7.1x;" in base
    assert "`fast` compute <= 60 us on hrp4_like: **not met** (142.0 us)" in base
    assert "17.8x one CalcMassMatrix with cached kinematics" in base  # 142 / 8
    residuals = doc_tables.RENDERERS["benchmark_residual_update"](data)
    assert residuals[0].endswith("| floor <= 100 us |") and residuals[-1].endswith("| met |")
    observer = doc_tables.RENDERERS["benchmark_force_observer"](data)
    assert observer[-1] == "| Force_Y_data | 1678 | 19,000 | 317 | **not met** |"
    loop = doc_tables.RENDERERS["benchmark_closed_loop"](data)
    assert "| 2.00 | yes |" in loop[2] and "| 0.80 | **no** |" in loop[3]
    assert loop[-1] == "Memory allocator of this run: tcmalloc."
    localizer = doc_tables.RENDERERS["benchmark_contact_localizer"](data)
    assert localizer[0].endswith("| floor <= 2 ms |") and localizer[-1].endswith("| **not met** |")
    log = doc_tables.RENDERERS["benchmark_log_estimation"](data)
    assert log[2].endswith("| 5.00 | met |")  # the floor is inclusive
    # 200 us per sample = 10 CalcMassMatrix of 20 us; 5x real time at 1 kHz: 200 us, so 20 us.
    assert "costs 10.0 CalcMassMatrix" in log[-1] and "needs a CalcMassMatrix of 20.0 us or less" in log[-1]
    assert doc_tables.RENDERERS["benchmark_multi_contact_fit"](data)[0].startswith("Not measured in this run")

    # The other way: a slower fast compute misses the ratio floor, a faster one meets the absolute one.
    data["floating_base"][0].update(fast_compute_us=59.0, fast_compute_ratio=12.5)
    base = "\n".join(doc_tables.RENDERERS["benchmark_floating_base"](data))
    assert "12x one CalcMassMatrix on hrp4_like: **not met** (12.5x;" in base
    assert "<= 60 us on hrp4_like: met (59.0 us)" in base
    # A changed floor changes the verdict: the floors come from the file, not the renderer.
    data["floors"]["observer_min_samples_per_s"] = 10000.0
    assert doc_tables.RENDERERS["benchmark_force_observer"](data)[-1].endswith("| met |")


def test_a_block_with_several_results_files_reads_each_and_names_each_command(tmp_path, monkeypatch):
    """SOURCES: one block from several files (the experiments' wall times), with the
    provenance of each, and stale when any of them changes."""
    monkeypatch.setitem(doc_tables.RENDERERS, "gathered", lambda files: [f"{k}: {v['x']}" for k, v in files.items()])
    monkeypatch.setitem(doc_tables.SOURCES, "gathered", ("first", "second"))
    write_results("first", {"x": 1}, command="python -m apps.one", folder=tmp_path)
    write_results("second", {"x": 2}, command="python -m apps.two --y", folder=tmp_path)
    body = doc_tables.render("gathered", tmp_path)
    assert body.startswith("first: 1\nsecond: 2\n\nMeasured by:\n\n- `python -m apps.one` on ")
    assert "`results/first.json`" in body and "- `python -m apps.two --y` on " in body
    block = f"<!-- results: gathered -->\n{body}<!-- /results: gathered -->"
    assert doc_tables.updated(block, tmp_path)[1] == []
    write_results("second", {"x": 3}, command="python -m apps.two --y", folder=tmp_path)
    text, stale = doc_tables.updated(block, tmp_path)
    assert stale == ["gathered"] and "second: 3" in text
    (tmp_path / "first.json").unlink()
    with pytest.raises(ValueError, match="first.json"):
        doc_tables.render("gathered", tmp_path)


def test_the_experiments_table_has_a_row_per_results_file_with_its_wall_time():
    rows = doc_tables.RENDERERS["experiments_wall_time"](
        {name: load_results(name)["data"] for name in doc_tables.sources("experiments_wall_time")}
    )
    assert len(rows) == 2 + len(doc_tables.EXPERIMENT_RUNS)
    for (name, _, _), row in zip(doc_tables.EXPERIMENT_RUNS, rows[2:]):
        assert f"(`{name}`)" in row
        data = load_results(name)["data"]
        if "wall_time_s" in data:
            assert f"{data['wall_time_s']:.1f} s" in row
        if "real_time_factor" in data:
            assert f"{data['real_time_factor']:.2f}" in row
