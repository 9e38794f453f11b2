"""Smoke test of apps/contact_localization.py: two short trials in two spawned processes,
a short run without contact and one Meshcat replay."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scenario_checks import SCENARIOS, check_scenario_convention

from apps import contact_localization
from diagrams.residuals.contact_study import (
    ContactLocalizationScenario,
    build_contact_localization_diagram,
    no_contact_scenario,
    sample_trials,
    trial_scenario,
)
from diagrams.scenarios import load_scenario
from systems.simulation.visualization import read_static_html


@pytest.mark.slow
def test_app_smoke(tmp_path):
    code = contact_localization.main(
        [
            "--trials",
            "2",
            "--workers",
            "2",
            "--replays",
            "1",
            "--headless",
            "--push-start",
            "0.2",
            "--contact-duration",
            "0.4",
            "--no-contact-duration",
            "0.5",
            "--slow-motion-duration",
            "0.5",
            "--seed",
            "3",
            "--ideal",
            "--out",
            str(tmp_path),
        ]
    )
    assert code == 0
    out = tmp_path / "contact_localization"
    metrics = json.loads((out / "metrics.json").read_text())
    for key in (
        "detection_rate",
        "median_detection_delay_s",
        "false_detections",
        "correct_link_rate",
        "median_position_error_m",
        "p95_position_error_m",
        "median_force_error_rel",
        "median_angle_error_deg",
        "trials",
    ):
        assert key in metrics
    assert metrics["trials"] == 2 and len(metrics["per_trial"]) == 2
    assert metrics["no_contact_run"]["duration_s"] == 0.5 and metrics["slow_motion_run"]["duration_s"] == 0.5
    assert metrics["slow_motion_run"]["motion"] == "slow whole-body motion"
    # Physics, not bookkeeping: the contacts are found (noise on, 0.2 s of averaging).
    assert metrics["detection_rate"] == 1.0
    assert metrics["correct_link_rate"] == 1.0
    assert metrics["median_position_error_m"] < 0.02
    assert metrics["median_force_error_rel"] < 0.05
    assert (out / "position_errors.png").stat().st_size > 10_000
    # Each single contact also went through the one-or-two-contact fit, which found one.
    assert metrics["multi_contact_trials"] == 2 and metrics["more_than_one_contact_rate"] == 0.0
    assert all(trial["contacts_estimated"] == 1 for trial in metrics["per_trial"])
    # The 95 % intervals bracket their figures, and the per-link table counts every trial.
    low, high = metrics["intervals"]["correct_link_rate"]
    assert low <= metrics["correct_link_rate"] <= high == 1.0
    assert sum(row["trials"] for row in metrics["per_link"]) == 2 and metrics["confusion"] == []
    # The stacked fit's own tables count its right links.
    fit_right = sum(trial["fit_correct_link"] for trial in metrics["per_trial"])
    assert sum(row["successes"] for row in metrics["fit_per_seed"]) == fit_right
    assert sum(row["trials"] for row in metrics["fit_per_link"]) == 2
    # The wall time split by phase (headless: the replays are recorded in the workers).
    phases = metrics["phase_wall_s"]
    assert set(phases) == {"calibration", "simulations", "one_or_two_contact_fits", "live_replays"}
    assert all(t >= 0.0 for t in phases.values()) and sum(phases.values()) <= metrics["wall_time_s"]
    assert phases["simulations"] > phases["live_replays"]
    # The recorded localizer inputs replay to the study's own results.
    inputs = np.load(out / "localizer_inputs.npz")
    assert list(inputs["trial"]) == [0, 1]
    scenario = load_scenario(ContactLocalizationScenario, text="{}")
    scenario.station = scenario.station.in_world("ideal")
    _, handles = build_contact_localization_diagram(scenario)
    for k, trial in enumerate(metrics["per_trial"]):
        replay = handles.localizer.localize(inputs["q"][k], inputs["external_wrench_world"][k], inputs["residual"][k])
        assert replay.body_index == trial["estimated_body_index"] and replay.status == trial["status"]
        np.testing.assert_allclose(replay.point_W, trial["estimated_point_world"], atol=1e-12)
    # The replay animates the true and the estimated force arrows.
    scene = read_static_html((out / "replay_trial_0.html").read_text())
    for path in ("/drake/true_force/0", "/drake/estimated_force/0"):
        assert path in scene.tracks, sorted(scene.tracks)[:10]
        visible = [value for _, value in scene.tracks[path].get("visible", [])]
        assert True in visible, path  # shown during the push


@pytest.mark.slow
def test_app_two_contacts(tmp_path):
    """``--contacts 2``: two links pushed at once in each trial (ideal world, noise on); the
    one-or-two-contact fit says two contacts and finds both, and the replay shows both
    true forces."""
    code = contact_localization.main(
        ["--contacts", "2", "--trials", "2", "--num-seeds", "1", "--seed", "50", "--workers", "1", "--replays", "1"]
        + ["--push-start", "0.2", "--contact-duration", "0.4", "--no-contact-duration", "0"]
        + ["--slow-motion-duration", "0", "--headless", "--ideal", "--out", str(tmp_path)]
    )
    assert code == 0
    out = tmp_path / "contact_localization"
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["contacts"] == 2
    assert set(metrics["floors"]) >= {"both_links_right_rate", "more_than_one_contact_rate"}
    assert metrics["detection_rate"] == 1.0 and metrics["more_than_one_contact_rate"] == 1.0
    for trial in metrics["per_trial"]:
        assert len(trial["contacts"]) == 2 and trial["contacts"][0]["body"] != trial["contacts"][1]["body"]
        assert len(trial["true_points_world"]) == 2
    assert metrics["both_links_right_rate"] == 1.0  # seed 50's first two: a wrist and an ankle, a wrist and a hand
    assert metrics["median_contact_position_error_m"] < 0.01 and metrics["median_contact_force_error_rel"] < 0.05
    # The tables count two-contact outcomes: a row per pushed link (found), per seed (both
    # links right), no misses.
    pushed = sorted(c["body"] for trial in metrics["per_trial"] for c in trial["contacts"])
    assert sorted(row["group"] for row in metrics["per_link"] for _ in range(row["trials"])) == pushed
    assert all(row["rate"] == 1.0 for row in metrics["per_link"])
    assert metrics["per_seed"] == [
        {"group": "50", "trials": 2, "successes": 2, "rate": 1.0, "interval": metrics["per_seed"][0]["interval"]}
    ]
    assert metrics["confusion"] == [] and "fit_per_seed" not in metrics
    for trial in metrics["per_trial"]:
        assert sorted(trial["estimated_contact_body_names"]) == sorted(c["body"] for c in trial["contacts"])
    scene = read_static_html((out / "replay_trial_0.html").read_text())
    assert {"/drake/true_force/0", "/drake/true_force/1"} <= set(scene.tracks)


def test_sampled_contacts_are_on_the_outer_surface_and_within_the_cone():
    specs = sample_trials("hrp4_like", 5, seed=0)
    assert len({s["body"] for s in specs}) > 1
    for s in specs:
        f = np.asarray(s["force_world"])
        assert 5.0 <= np.linalg.norm(f) <= 40.0
        assert s["body"] not in ("l_sole", "r_sole")


def test_scenario_files_load_into_the_dataclass(tmp_path):
    check_scenario_convention(ContactLocalizationScenario, "contact_localization_default.yaml", tmp_path, "workers")
    scenario = load_scenario(
        ContactLocalizationScenario,
        filename=SCENARIOS / "contact_localization_default.yaml",
        text="trials: 40\nno_contact_duration: 0\nstation: {plant_config: {discrete_contact_approximation: lagged}}",
    )
    assert (scenario.trials, scenario.no_contact_duration, scenario.station.seed) == (
        40,
        0.0,
        0,
    )  # others keep the defaults
    assert scenario.station.plant_config.discrete_contact_approximation == "lagged"
    # One trial's run: the study's settings with the trial's push and noise seed.
    spec = {"body": "CHEST_Y_LINK", "point_body": [0.1, 0.0, 0.2], "force_world": [-20.0, 0.0, 0.0], "noise_seed": 17}
    trial = trial_scenario(scenario, spec)
    assert (trial.push_body, trial.push_point, trial.push_force, trial.station.seed) == (
        "CHEST_Y_LINK",
        [0.1, 0.0, 0.2],
        [-20.0, 0.0, 0.0],
        17,
    )
    assert trial.station.plant_config.discrete_contact_approximation == "lagged" and scenario.push_body is None
    quiet = no_contact_scenario(scenario)
    assert quiet.push_body is None and quiet.station.seed == 99991


def test_app_reads_scenario_text_and_reports_errors(tmp_path, capsys):
    code = contact_localization.main(
        [
            "--scenario-text",
            "trials: 1\npush_start: 0.15\npush_duration: 0.3\nno_contact_duration: 0\nslow_motion_duration: 0\n"
            "station: {seed: 2}",
            "--ideal",
            "--workers",
            "1",
            "--replays",
            "0",
            "--headless",
            "--out",
            str(tmp_path),
        ]
    )
    assert code == 0
    metrics = json.loads((tmp_path / "contact_localization" / "metrics.json").read_text())
    assert metrics["trials"] == 1 and metrics["no_contact_run"] is None and metrics["seed"] == 2
    assert (metrics["push_start_s"], metrics["contact_duration_s"]) == (0.15, 0.3)
    assert metrics["scenario"]["trials"] == 1
    capsys.readouterr()
    assert contact_localization.main(["--scenario-text", "workers: 2", "--out", str(tmp_path)]) == 2
    assert "workers" in capsys.readouterr().err
    assert contact_localization.main(["--scenario-text", "trials: 0", "--out", str(tmp_path)]) == 2
    assert "at least one trial" in capsys.readouterr().err


@pytest.mark.slow
def test_app_calibrates_once_in_the_realistic_world(tmp_path, monkeypatch):
    """The default (realistic) study calibrates the robot's model once, saves it, and every
    run reads the saved file (here the calibration is replaced by the estimators' own model
    with no friction or torque corrections, to keep the test short: the plumbing is under
    test, the calibration in test_model_refinement.py)."""
    from diagrams.residuals import model_refinement
    from systems.estimation.model_identification import ModelCorrections

    calls = []

    def fake_calibration(scenario):
        _, handles = model_refinement.build_refinement_diagram(scenario, None)
        n = handles.station.topology.num_joints
        inertias = handles.station.estimator_inertias
        zeros = np.zeros(n)
        calls.append(scenario)
        return ModelCorrections(inertias, zeros, zeros, 0.1, zeros, zeros), None

    monkeypatch.setattr(model_refinement, "calibrate_model", fake_calibration)
    code = contact_localization.main(
        [
            "--trials",
            "1",
            "--workers",
            "1",
            "--replays",
            "0",
            "--push-start",
            "0.2",
            "--contact-duration",
            "0.3",
            "--no-contact-duration",
            "0",
            "--slow-motion-duration",
            "0",
            "--out",
            str(tmp_path),
        ]
    )
    assert code == 0 and len(calls) == 1
    metrics = json.loads((tmp_path / "contact_localization" / "metrics.json").read_text())
    station = metrics["scenario"]["station"]
    assert station["base_state"] == "invariant_ekf" and station["imperfections"]["model_mismatch"]["mass_percent"] == 5
    saved = Path(station["model_refinement"])
    assert saved.is_file() and saved.parent == tmp_path / "calibration_cache"
    assert metrics["trials"] == 1


def test_multi_contact_jobs_cross_fit_the_load_model_error_by_seed(hrp4_moved):
    """``multi_contact_jobs``: every trial is localized once, in chunks; each seed's trials
    get the model error under load measured on the OTHER seeds' detected trials
    (``load_model_error``), never on their own, and none when fewer than
    ``MIN_LOAD_CALIBRATION_TRIALS`` such trials are known."""
    from diagrams.residuals.contact_study import MIN_LOAD_CALIBRATION_TRIALS, load_model_error, multi_contact_jobs

    plant, _, _, context = hrp4_moved
    q = plant.GetPositions(context)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(3)
    body = plant.GetBodyByName("R_ELBOW_P_LINK")

    def trial(k: int, seed: int, detected: bool = True) -> dict:
        contact = {"body_index": int(body.index()), "point_body": [0.0, 0.0, -0.1], "force_world": [10.0, 0.0, 0.0]}
        inputs = {"q": q, "external_wrench_world": rng.normal(size=6), "residual": rng.normal(size=n)}
        return {
            "trial": k,
            "seed": seed,
            "detected": detected,
            "contacts": [contact],
            **contact,
            "localizer_inputs": inputs,
            "true_points_world": [[0.0, 0.0, 0.0]],
        }

    few = MIN_LOAD_CALIBRATION_TRIALS - 1
    results = [trial(k, 0) for k in range(25)] + [trial(25 + k, 1, detected=k > 0) for k in range(few + 1)]
    covariances = (np.eye(6), np.eye(n))
    jobs = multi_contact_jobs(results, plant, "yaml", covariances, chunk=10)
    assert all(kind == "multi_contact" and len(trials) <= 10 for kind, trials, _, _ in jobs)
    assert sorted(t["trial"] for _, trials, _, _ in jobs for t in trials) == list(range(len(results)))
    for _, trials, text, (given, load) in jobs:
        assert text == "yaml" and given is covariances
        seed = results[trials[0]["trial"]]["seed"]
        assert all(results[t["trial"]]["seed"] == seed for t in trials)
        if seed == 0:  # the other seed has only `few` detected trials
            assert load is None
        else:
            expected = load_model_error(plant, results[:25])
            np.testing.assert_array_equal(load[0], expected[0])
            np.testing.assert_array_equal(load[1], expected[1])
