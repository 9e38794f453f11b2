"""Every app that runs on a humanoid takes ``--robot FILE.yaml`` (issue 14): each runs, on a
short horizon, on TALOS (models/robots/talos.yaml, from example-robot-data), a robot the
project was not built on, with no code change; a robot without what an app needs, or a bad
description, is a clear error (exit 2), never a traceback."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from apps import (
    contact_localization,
    estimate_from_log,
    model_refinement,
    push_and_comply,
    residual_comparison,
    standing,
)

ROOT = Path(__file__).resolve().parents[1]
TALOS = str(ROOT / "models" / "robots" / "talos.yaml")
NAO = str(ROOT / "models" / "nao_like.yaml")


def test_standing_on_talos(tmp_path):
    assert standing.main(["--robot", TALOS, "--duration", "0.6", "--no-meshcat", "--out", str(tmp_path)]) == 0
    row = json.loads((tmp_path / "standing" / "talos.json").read_text())
    assert row["fell"] is False and row["feet_flat"] is True


@pytest.mark.slow
def test_push_and_comply_on_talos(tmp_path):
    text = "{duration: 1.0, tare_duration: 0.2, push_start: 0.3, push_peak_time: 0.6, push_end: 0.9}"
    args = ["--robot", TALOS, "--ideal", "--headless", "--scenario-text", text, "--out", str(tmp_path)]
    assert push_and_comply.main(args) == 0
    metrics = json.loads((tmp_path / "push_and_comply" / "metrics.json").read_text())
    assert metrics["scenario"]["station"]["model"] == TALOS
    # The knees found by role (each six-joint leg's fourth joint), not by an HRP-4 name.
    assert set(metrics["internal"]["knee_pitch_flexion_per_knee_deg"]) == {"leg_left_4_joint", "leg_right_4_joint"}


@pytest.mark.slow
def test_residual_comparison_on_talos(tmp_path):
    args = ["--robot", TALOS, "--ideal", "--duration", "1.5", "--seed", "2", "--out", str(tmp_path)]
    assert residual_comparison.main(args) == 0
    metrics = json.loads((tmp_path / "residual_comparison" / "metrics.json").read_text())
    # Physics: the internal residual follows the push's true joint effort on this robot too.
    assert metrics["internal_rel_rms_error"] < 0.2


@pytest.mark.slow
def test_contact_study_on_talos(tmp_path):
    args = ["--robot", TALOS, "--ideal", "--trials", "2", "--workers", "1", "--replays", "0", "--headless"]
    args += ["--push-start", "0.2", "--contact-duration", "0.4", "--no-contact-duration", "0.3"]
    args += ["--slow-motion-duration", "0.3", "--seed", "5", "--out", str(tmp_path)]
    assert contact_localization.main(args) == 0
    metrics = json.loads((tmp_path / "contact_localization" / "metrics.json").read_text())
    assert metrics["trials"] == 2 and metrics["detection_rate"] == 1.0


@pytest.mark.slow
def test_model_refinement_on_talos_says_which_joints_a_short_calibration_leaves_undetermined(tmp_path, capsys):
    # The full run (its default calibration motion) is too long for a test; a 3 s motion
    # does not excite every joint of this robot, and the app says which, instead of a
    # silent wrong model.
    text = (
        "{calibration_duration: 3.0, standing_duration: 1.5, check_duration: 1.5, skip: 0.5, "
        "station: {base_state: truth_plus_noise}, "
        "calibration_motion: {seed: 1, min_frequency: 0.3, max_frequency: 0.6, "
        "ramp_time: 0.5}}"
    )
    assert model_refinement.main(["--robot", TALOS, "--scenario-text", text, "--out", str(tmp_path)]) == 2
    assert "the log does not determine the torque scale of joints ['" in capsys.readouterr().err


def test_estimate_from_log_on_a_robot_with_fsrs(tmp_path, capsys):
    """nao_like's demo log (FSR readings, no F/T wrench: a table format, FSRs have no ROS
    message) is estimated with its soles' shear and yaw as unknowns: the push is found on
    its link, as the simulation's own estimators found it, and its force, net of the soles'
    estimated wrenches, within 3 % over the whole contact. The demo's push stands within
    what this light robot withstands (the study's force scaled by its mass): its feet carry
    its weight less the push's lift throughout (the study's 11 N tipped it over)."""
    log = tmp_path / "demo.csv"
    args = ["--robot", NAO, "--write-demo-log", str(log), "--headless", "--out", str(tmp_path), "--no-replay"]
    assert estimate_from_log.main(args) == 0
    printed = capsys.readouterr().out
    found = re.search(r"a push of [0-9.]+ N \[(\S+), (\S+), (\S+)\] on (\S+) from", printed)
    push, pushed = np.array([float(found.group(i)) for i in (1, 2, 3)]), found.group(4)
    metrics = json.loads((tmp_path / "estimate_from_log" / "metrics.json").read_text())
    assert metrics["estimated_sole_wrenches"] == ["l_sole_frame", "r_sole_frame"]
    assert [c["link"] for c in metrics["contacts"]] == [pushed]
    estimated = np.array(metrics["contacts"][0]["mean_force_world_N"])
    assert np.linalg.norm(estimated - push) < 0.03 * np.linalg.norm(push)
    assert not metrics["not_estimated"]
    table = np.genfromtxt(log, delimiter=",", names=True)
    fsr = np.column_stack([table[name] for name in table.dtype.names if name.startswith("fsr_")])
    weight = fsr[100:400].sum(axis=1).mean()  # standing before the push
    assert fsr[400:].sum(axis=1).min() > weight - push[2] - 0.1 * weight


@pytest.mark.parametrize(
    ("app", "extra"),
    [(standing, ["--no-meshcat"]), (push_and_comply, ["--ideal"]), (residual_comparison, ["--ideal"])],
)
def test_a_bad_robot_description_is_an_error_that_names_the_field(tmp_path, capsys, app, extra):
    raw = yaml.safe_load(Path(TALOS).read_text())
    raw["feet"]["left"]["sensing"] = "sonar"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(raw))
    # The description is copied away from its folder: its package:// model still resolves.
    code = app.main(["--robot", str(bad), *extra, "--out", str(tmp_path)])
    assert code == 2
    assert "feet.left.sensing: must be one of" in capsys.readouterr().err


@pytest.mark.slow
def test_estimate_from_log_on_talos_recovers_a_known_push(tmp_path, capsys):
    """The offline pipeline on a robot the project never shipped: a demo log of TALOS under a
    random contact of the contact study, written as MCAP, read back and estimated."""
    from diagrams.residuals.log_estimation import demo_push

    log = tmp_path / "talos_push.mcap"
    args = ["--robot", TALOS, "--write-demo-log", str(log), "--headless", "--no-replay", "--out", str(tmp_path)]
    assert estimate_from_log.main(args) == 0
    metrics = json.loads((tmp_path / "estimate_from_log" / "metrics.json").read_text())
    body, _, force = demo_push(TALOS)
    (contact,) = metrics["contacts"]
    assert contact["link"] == body
    error = np.linalg.norm(np.subtract(contact["mean_force_world_N"], force)) / np.linalg.norm(force)
    assert error < 0.05
