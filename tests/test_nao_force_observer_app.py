"""apps.nao_force_observer on a short horizon: experiment 3 (the hanging load) at half the
durations, its outputs, and that the estimate tracks eq. (11)'s expected virtual force."""

import json
import re

import numpy as np
import pytest
from scenario_checks import SCENARIOS, check_scenario_convention

from apps import nao_force_observer
from diagrams.observer.nao_force_observer import LOAD_MASS, NaoForceObserverScenario, make_experiment
from diagrams.scenarios import load_scenario
from diagrams.station.config import StationConfig
from systems.simulation.disturbances import SmoothPiecewise
from systems.simulation.visualization import read_static_html


@pytest.fixture(scope="module")
def app_output(tmp_path_factory):
    out = tmp_path_factory.mktemp("nao_force_observer")
    code = nao_force_observer.main(
        ["--out", str(out), "--headless", "--experiment", "3", "--time-scale", "0.5", "--seed", "2"]
    )
    assert code == 0
    return out / "nao_force_observer"


@pytest.mark.slow
def test_app_writes_plot_replay_and_metrics(app_output):
    assert (app_output / "experiment_3.png").stat().st_size > 20_000
    metrics = json.loads((app_output / "metrics.json").read_text())
    assert set(metrics) == {"experiment_3", "summary", "scenario", "memory_allocator", "recordings_step_response"}
    m = metrics["experiment_3"]
    for key in ("rms_error_N", "steady_state_error_N"):
        assert set(m[key]) == {"x", "y", "z"} and all(np.isfinite(v) for v in m[key].values())
    assert m["floors_N"] == {"steady_state": 0.5, "rms": 1.0}
    floors_met = max(m["steady_state_error_N"].values()) <= 0.5 and max(m["rms_error_N"].values()) <= 1.0
    assert m["meets_floors"] is floors_met and metrics["summary"]["seed"] == 2
    assert metrics["scenario"]["station"]["seed"] == 2 and metrics["scenario"]["experiments"] == [3]
    assert m["invalid_samples"] == 0 and m["fsr_saturated_samples"] == 0 and m["base_height_drop_m"] < 0.01


@pytest.mark.slow
def test_estimate_tracks_the_expected_virtual_force(app_output):
    m = json.loads((app_output / "metrics.json").read_text())["experiment_3"]
    quiet, loaded, unloaded = m["steady_state_windows"]  # before, with and after the load
    assert np.abs(quiet["expected_N"]).max() == 0.0
    weight = LOAD_MASS * 9.81
    # Expected (eq. 11): the load's weight, plus the moment of a hand beside and ahead of
    # the CoM where the paper's eq. (24) puts it: [2.22, -4.16, -11.12] N on the real Nao.
    assert abs(loaded["expected_N"][2] + weight) < 1e-9
    np.testing.assert_allclose(loaded["expected_N"][:2], [2.22, -4.16], atol=0.05)
    assert np.abs(unloaded["expected_N"]).max() == 0.0
    assert np.abs(np.subtract(loaded["estimate_N"], loaded["expected_N"])).max() < 0.5, loaded
    # The x/y filters (eq. 21 parameters) ring for ~4 s after the load goes; the halved
    # schedule ends 2.5 s after the ramp (the full one, 5 s after, meets 0.5 N).
    assert np.abs(unloaded["estimate_N"]).max() < 1.0, unloaded
    assert max(m["rms_error_N"].values()) < 1.5  # half-length ramps: a larger transient share


@pytest.mark.slow
def test_experiment_3_hand_is_where_eq_24_puts_it():
    """The paper's stance (nominal) with experiment 3's arm and its load hanging from the
    hand: the simulator's expected virtual force (eq. 11, from the true CoM and the load's
    true point) is eq. (24)'s [2.22, -4.16, -11.12] N: the hand, yielding to the load, is
    6.3 cm ahead of the CoM and 11.8 cm to its right."""
    import functools

    from apps.runner import logged_signals, simulate
    from diagrams.observer.calibration import settle_standing_state
    from diagrams.observer.nao_force_observer import (
        HAND_POINT,
        build_experiment_diagram,
        experiment_posture,
    )
    from systems.simulation.disturbances import Push

    scenario = NaoForceObserverScenario(
        wide_stance=False, station=StationConfig(model="nao_like_recorded", noise=False), experiments=[3]
    )
    experiment = make_experiment(3)
    weight = LOAD_MASS * 9.81
    experiment.pushes = [
        Push(
            HAND_POINT[0],
            np.array(HAND_POINT[1]),
            np.array([0.0, 0.0, -1.0]),
            SmoothPiecewise((0.0, 0.1, 0.6), (0.0, 0.0, weight)),
        )
    ]
    diagram, handles = build_experiment_diagram(scenario, experiment)
    state = settle_standing_state(experiment_posture(scenario, experiment), robot=scenario.station.model)
    run = simulate(diagram, 3.0, set_initial_state=functools.partial(handles.set_initial_state, state=state))
    truth = logged_signals(handles.loggers, run.context, "virtual_force")["truth"][:, -1]
    np.testing.assert_allclose(truth, [2.22, -4.16, -weight], atol=0.05)
    assert experiment_posture(scenario, experiment) == experiment.posture != {}
    assert experiment_posture(scenario, make_experiment(1)) is None


@pytest.mark.slow
def test_replay_is_self_contained_and_animated(app_output):
    html = (app_output / "experiment_3.html").read_text()
    assert re.findall(r"<(?:script|link)[^>]+(?:src|href)\s*=\s*[\"']((?:https?:)?//[^\"']+)", html) == []
    scene = read_static_html(html)
    assert any("applied_forces" in path for path in scene.tracks)
    assert any("estimated_virtual_force" in path for path in scene.tracks)
    assert any("nao_like" in path for path in scene.tracks)


def test_bad_arguments_and_schedules(capsys):
    assert nao_force_observer.main(["--time-scale", "-1", "--no-replay"]) == 2
    assert "time_scale must be positive" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        nao_force_observer.main(["--experiment", "4"])
    with pytest.raises(ValueError, match="unknown experiment"):
        make_experiment(5)
    with pytest.raises(ValueError, match="ramp must be >= 0"):
        make_experiment(2, ramp=-1.0)
    with pytest.raises(ValueError, match="must increase"):
        SmoothPiecewise((1.0, 0.0), (1.0, 2.0))
    # The schedules: steady-state windows lie in plateaus of the applied force; scalar and
    # vector evaluations of a profile agree.
    for number in (1, 2, 3):
        experiment = make_experiment(number)
        for _t0, t1 in experiment.windows:
            times = np.linspace(t1 - 1.0, t1, 50)
            for push in experiment.pushes:
                values = push.profile.value(times)
                assert np.ptp(values) < 1e-12
                assert all(abs(push.profile.value(float(t)) - v) < 1e-12 for t, v in zip(times, values))
        assert experiment.duration < 25.0


def test_scenario_file_text_overrides_and_unknown_keys(tmp_path):
    check_scenario_convention(NaoForceObserverScenario, "nao_force_observer_default.yaml", tmp_path, "load_kg")
    overridden = load_scenario(
        NaoForceObserverScenario,
        filename=SCENARIOS / "nao_force_observer_default.yaml",
        text="experiments: [2]\nramp: 0.1\nstation: {plant_config: {discrete_contact_approximation: lagged}}",
    )
    assert (overridden.experiments, overridden.ramp, overridden.station.seed) == ([2], 0.1, 0)
    assert overridden.station.plant_config.discrete_contact_approximation == "lagged"
    assert overridden.station.plant_config.time_step == 1e-3


def test_scenario_errors_from_the_command_line(tmp_path, capsys):
    assert nao_force_observer.main(["--scenario-text", "load_kg: 2.0", "--no-replay", "--out", str(tmp_path)]) == 2
    assert "nao_force_observer: error:" in capsys.readouterr().err
    assert nao_force_observer.main(["--scenario-text", "experiments: [4]", "--no-replay", "--out", str(tmp_path)]) == 2
    assert "unknown experiment 4" in capsys.readouterr().err


@pytest.mark.slow
def test_experiments_1_and_2_meet_the_papers_floors(tmp_path):
    """Simulated experiments 1 (2 N through the torso at three angles, eq. 23) and 2 (a 1.13 kg
    load pulling the right arm sideways), at the paper's durations: the estimate's error
    against the expected virtual force of eq. (11), which the simulator's applied force
    determines, meets the floors (steady state <= 0.5 N, RMS <= 1.0 N per component)."""
    code = nao_force_observer.main(
        ["--out", str(tmp_path), "--headless", "--no-replay", "--scenario-text", "experiments: [1, 2]", "--seed", "1"]
    )
    assert code == 0
    metrics = json.loads((tmp_path / "nao_force_observer" / "metrics.json").read_text())
    for experiment in ("experiment_1", "experiment_2"):
        m = metrics[experiment]
        assert max(m["steady_state_error_N"].values()) <= 0.5, (experiment, m["steady_state_error_N"])
        assert max(m["rms_error_N"].values()) <= 1.0, (experiment, m["rms_error_N"])
        assert m["meets_floors"] is True and m["invalid_samples"] == 0


@pytest.mark.slow
def test_step_loads_overshoot_like_the_real_robot(tmp_path):
    """The paper's setting (``apps/scenarios/hawley_paper.yaml``: step loads, nominal stance)
    for experiment 1 on the Nao whose standing CoM matches the recordings: steady-state
    error <= 0.5 N per component, and the mean overshoot of the estimate's step responses
    within 10 percentage points of the authors' observer on the real recordings (issue 31's
    floor; measured: 21.8 % against 21.9 %). The recordings' responses come from their own
    ZMP-detected load times, the simulation's from the schedule."""
    code = nao_force_observer.main(
        [
            "--out",
            str(tmp_path),
            "--headless",
            "--no-replay",
            "--scenario",
            str(SCENARIOS / "hawley_paper.yaml"),
            "--experiment",
            "1",
            "--seed",
            "3",
        ]
    )
    assert code == 0
    metrics = json.loads((tmp_path / "nao_force_observer" / "metrics.json").read_text())
    m, real = metrics["experiment_1"], metrics["recordings_step_response"]["summary"]
    assert m["step_loads"] and metrics["scenario"]["ramp"] == 0.0 and metrics["scenario"]["wide_stance"] is False
    assert max(m["steady_state_error_N"].values()) <= 0.5, m["steady_state_error_N"]
    # Four steps (on at 0 deg, turns to 45 and 90 deg, off), each measured on the components
    # that change by >= 1 N: x (0 -> 2 N), z (0 -> 1.41 N), x (1.41 -> 0 N), z (2 -> 0 N).
    assert [(r["component"], r["step_time_s"]) for r in m["step_responses"]] == [
        ("x", 2.0),
        ("z", 6.0),
        ("x", 10.0),
        ("z", 14.0),
    ]
    assert real["steps"] == 8 and 15.0 < real["mean_overshoot_percent"] < 30.0
    assert abs(m["step_response"]["mean_overshoot_percent"] - real["mean_overshoot_percent"]) <= 10.0
    assert m["meets_floors"] is True and not m["fell"] and m["invalid_samples"] == 0
