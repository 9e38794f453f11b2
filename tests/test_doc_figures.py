"""The documentation's figures (issue 34): each is drawn from committed results files only, each
page shows exactly the figures ``apps.doc_figures`` draws, and no document shows any other image."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest
from PIL import Image

from apps import doc_figures, doc_tables
from apps.results import RESULTS_DIR, load_results, write_results

NAMES = [spec.name for spec in doc_figures.FIGURES]
#: An image in Markdown, MyST or reStructuredText, or raw HTML.
_IMAGE = re.compile(r"!\[[^\]]*\]\(|\{figure\}|\{image\}|<img\b|\.\. (?:figure|image)::", re.I)


@pytest.fixture(scope="module")
def drawn(tmp_path_factory):
    """Every figure drawn from the committed results files into a temporary folder."""
    out = tmp_path_factory.mktemp("figures")
    return {path.stem: path for path in doc_figures.render_all(out)}


def test_every_figure_is_drawn_as_a_valid_image(drawn):
    assert sorted(drawn) == sorted(NAMES) and len(NAMES) == len(set(NAMES))
    for name, path in drawn.items():
        assert path.name == f"{name}.png" and path.stat().st_size > 10_000, name
        with Image.open(path) as image:
            image.verify()
        with Image.open(path) as image:
            assert image.format == "PNG" and image.width >= 600 and image.height >= 300, (name, image.size)
            pixels = np.asarray(image.convert("L"))
        # Not blank: a good part of the picture is drawn (axes, bars, text), not background.
        assert (pixels < 200).mean() > 0.01, f"{name}: almost nothing is drawn"


def test_the_pages_show_exactly_the_figures_drawn_each_once_on_its_page():
    shown = {}
    for path in doc_figures.DOCUMENTS:
        for name in doc_figures.block_names(path.read_text()):
            assert name not in shown, f"figure {name} shown twice ({shown[name]}, {path.name})"
            shown[name] = path
    assert sorted(shown) == sorted(NAMES), (
        f"drawn but shown nowhere: {sorted(set(NAMES) - set(shown))}; "
        f"shown but not drawn: {sorted(set(shown) - set(NAMES))}"
    )
    for spec in doc_figures.FIGURES:
        assert shown[spec.name] == doc_figures.DOCS / spec.page, f"{spec.name} is on {shown[spec.name].name}"


def test_no_document_shows_an_image_outside_a_generated_figure_block():
    """The floor of issue 34: no figure in README or docs that is not drawn from a results
    file. Outside the generated blocks no document has an image; inside, each block shows its
    own figure."""
    for path in doc_figures.DOCUMENTS:
        text = path.read_text()
        outside = doc_figures._BLOCK.sub("", text)
        found = [m.group(0) for m in _IMAGE.finditer(outside)]
        assert not found, f"{path.name}: images not drawn by apps.doc_figures: {found}"
        for match in doc_figures._BLOCK.finditer(text):
            images = re.findall(r"\{figure\} (\S+)", match["body"])
            assert images == [f"_generated/figures/{match['name']}.png"], (path.name, match["name"], images)
            assert len(_IMAGE.findall(match["body"])) == 1


@pytest.mark.parametrize("document", doc_figures.DOCUMENTS, ids=lambda p: p.relative_to(doc_figures.ROOT).as_posix())
def test_every_figure_block_matches_its_results_files(document):
    _, stale = doc_figures.updated(document.read_text())
    assert not stale, f"{document.name}: stale figure blocks {stale}: run `make docs` (python -m apps.doc_figures)"


@pytest.mark.parametrize("name", NAMES)
def test_a_caption_names_each_results_file_and_the_run_that_wrote_it(name):
    body = doc_figures.block(name)
    for source in doc_figures.figure(name).sources:
        payload = load_results(source)
        assert f"`results/{source}.json`" in body and f"`{payload['command']}`" in body
        assert payload["written"] in body


@pytest.mark.parametrize("name", NAMES)
def test_a_figure_reads_only_its_own_results_files(name, tmp_path):
    """From a folder holding only its declared results files, a figure takes the same values
    (and ``draw`` gets nothing but them): it reads nothing else."""
    for source in doc_figures.figure(name).sources:
        shutil.copy(RESULTS_DIR / f"{source}.json", tmp_path / f"{source}.json")
    assert doc_figures.figure_data(name, tmp_path) == doc_figures.figure_data(name)


def test_a_changed_results_file_changes_its_figure(tmp_path, drawn):
    """Control: a value changed in a copy of the results file is the value plotted, and the
    drawn image changes with it."""
    name = "push_and_comply_robots"
    payload = load_results(name)
    payload["data"]["rows"][0]["internal"]["knee_pitch_flexion_deg"] = 42.125
    payload["data"]["rows"][1]["classical"]["upright"] = False
    write_results(name, payload["data"], command=payload["command"], folder=tmp_path)
    values = doc_figures.figure_data(name, tmp_path)
    assert values["internal_knee_deg"][0] == 42.125
    assert values["classical_knee_deg"][1] is None and values["floors_met"][1] is False
    assert values["internal_knee_deg"][2:] == doc_figures.figure_data(name)["internal_knee_deg"][2:]
    changed = doc_figures.render(name, tmp_path / "out", tmp_path)
    assert changed.read_bytes() != drawn[name].read_bytes()
    # Drawn twice from the same file, a figure is the same image (the docs build is reproducible).
    assert doc_figures.render(name, tmp_path / "again", tmp_path).read_bytes() == changed.read_bytes()


def test_the_plotted_values_are_the_results_files_values():
    """A sample of each kind of figure against its file, read here independently."""
    single = load_results("contact_study_single")["data"]
    regions = doc_figures.figure_data("contact_study_regions")
    assert regions["regions"] == [row["region"] for row in single["per_region"]]
    assert regions["right_link_fit_percent"] == [100 * row["fit_correct_link_rate"] for row in single["per_region"]]
    op, value = single["floors"]["median_position_error_m"].split()
    assert regions["floor_position_error_eq22"] == (op, float(value))
    realistic = load_results("residual_comparison_realistic")["data"]
    joints = doc_figures.figure_data("residual_comparison_per_joint")
    assert joints["joints"] == list(realistic["internal_rel_rms_error_per_joint"])
    assert joints["true_effort_Nm"] == list(realistic["rms_true_joint_effort_Nm"].values())
    observer = load_results("nao_force_observer")["data"]
    windows = doc_figures.figure_data("nao_force_observer_windows")["experiments"]
    assert windows[2]["expected_N"] == [w["expected_N"] for w in observer["experiment_3"]["steady_state_windows"]]
    scaling = load_results("engine_scaling")["data"]
    assert doc_figures.figure_data("engine_scaling")["wall_time_s"] == [
        r["wall_time_s"] for r in scaling["runs"].values()
    ]


def test_the_figures_use_the_same_studies_as_the_tables():
    assert [name for name, _ in doc_figures.SENSING_STUDIES] == [name for name, _, _ in doc_tables.SENSING_STUDIES]
    assert [name for name, _ in doc_figures.RESIDUAL_SENSING_RUNS] == [
        name for name, _ in doc_tables.RESIDUAL_SENSING_RUNS
    ]


def test_the_command_line_checks_and_refuses_a_missing_results_folder(tmp_path, capsys):
    assert doc_figures.main(["--check"]) == 0
    assert "up to date" in capsys.readouterr().out
    assert doc_figures.main(["--results", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert "cannot be read" in capsys.readouterr().err
    with pytest.raises(ValueError, match="no figure"):
        doc_figures.figure("nonexistent")
