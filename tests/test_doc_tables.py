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
    files = {path.stem for path in RESULTS_DIR.glob("*.json")}
    assert files <= quoted, f"results files no document quotes: {sorted(files - quoted)}"
    assert quoted <= files, f"tables without a results file: {sorted(quoted - files)}"
    assert quoted <= set(doc_tables.RENDERERS)


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
