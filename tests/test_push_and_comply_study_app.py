"""apps.push_and_comply_study: the paper's setting, the project's changes one at a time, and
the robots (issue 31)."""

from __future__ import annotations

import dataclasses
import json

import pytest

from apps import push_and_comply_study
from diagrams.residuals import push_and_comply
from diagrams.residuals.push_and_comply import PushAndComplyScenario
from diagrams.scenarios import scenario_as_dict


def test_the_ablation_goes_from_the_paper_to_the_default_one_change_at_a_time():
    rows = push_and_comply_study.ablation_scenarios()
    for world in push_and_comply_study.WORLDS:
        chain = [r["scenario"] for r in rows if r["world"] == world]
        assert len(chain) == len(push_and_comply_study.ABLATION_STEPS)
        paper = chain[0]
        assert paper.push_peak_force == 5.0 and paper.integrate_from == "measured"
        assert not paper.closed_chain_projection and not paper.hold_center_of_mass and paper.dead_band == 0.0
        for before, after, (_, changes) in zip(chain, chain[1:], push_and_comply_study.ABLATION_STEPS[1:]):
            a, b = scenario_as_dict(before), scenario_as_dict(after)
            assert {name for name in a if a[name] != b[name]} == set(changes)
        default = PushAndComplyScenario()
        default.station = default.station.in_world(world)
        assert scenario_as_dict(chain[-1]) == scenario_as_dict(default)


def test_the_robots_are_the_default_scenario_on_other_robots():
    rows = push_and_comply_study.robot_scenarios()
    assert any("talos" in r["scenario"].station.model for r in rows)
    seeds = [r["scenario"].station.imperfections.seed for r in rows if r["scenario"].station.model == "hrp4_like"]
    assert len(set(seeds)) == len(seeds) >= 6
    default = PushAndComplyScenario()
    for row in rows:
        s = row["scenario"]
        imperfections = dataclasses.replace(default.station.imperfections, seed=s.station.imperfections.seed)
        station = dataclasses.replace(
            default.station, model=s.station.model, seed=s.station.seed, imperfections=imperfections
        )
        expected = dataclasses.replace(default, station=station)
        assert scenario_as_dict(s) == scenario_as_dict(expected)
        assert row["world"] == "realistic"


def test_the_sensing_rows_are_the_default_on_each_foot_sensing_in_the_worlds_it_supports():
    """Issue 36: the default scenario on robots with foot F/T sensors, FSRs and none, in
    both worlds."""
    from models import robot_description

    rows = push_and_comply_study.sensing_scenarios()
    sensing = {
        (next(iter({f.sensing for f in robot_description(r["scenario"].station.model).feet.values()})), r["world"])
        for r in rows
    }
    assert {(f, w) for f in ("force_torque", "fsr", "none") for w in ("ideal", "realistic")} <= sensing
    default = PushAndComplyScenario()
    for row in rows:
        station = dataclasses.replace(default.station, model=row["scenario"].station.model)
        expected = dataclasses.replace(default, station=station.in_world(row["world"]))
        assert scenario_as_dict(row["scenario"]) == scenario_as_dict(expected)


@pytest.mark.slow
def test_app_writes_the_ablation_results_file(tmp_path):
    """Short horizon, ideal world: every row runs with both residuals. With eq. (14) as
    printed (q_d = q + K_a r T) the PD holds no stiffness and the robot sinks under its own
    weight (the scenario's docstring); integrating from the desired posture it stands."""
    code = push_and_comply_study.main(
        [
            "--study",
            "ablation",
            "--worlds",
            "ideal",
            "--duration",
            "0.4",
            "--workers",
            "2",
            "--out",
            str(tmp_path),
            "--results-folder",
            str(tmp_path / "results"),
        ]
    )
    assert code == 0
    payload = json.loads((tmp_path / "results" / "push_and_comply_ablation.json").read_text())
    assert payload["command"].startswith("python -m apps.push_and_comply_study --study ablation")
    rows = payload["data"]["rows"]
    assert [r["label"] for r in rows] == [label for label, _ in push_and_comply_study.ABLATION_STEPS]
    for row in rows:
        for kind in ("internal", "classical"):
            assert set(row[kind]) == set(push_and_comply_study.KEPT_METRICS)
    paper, integrated = rows[1], rows[2]  # 20 N: eq. (14) as printed, then integrated from q_d
    assert paper["internal"]["com_height_drop_m"] > 5 * integrated["internal"]["com_height_drop_m"]
    assert paper["internal"]["knee_pitch_flexion_deg"] > 3.0 > integrated["internal"]["knee_pitch_flexion_deg"]


def test_robot_floors_need_both_runs_upright_the_internal_knees_bent_and_the_classical_ones_not():
    floor = push_and_comply.FLOOR_INTERNAL_KNEE_DEG
    internal = {"upright": True, "knee_pitch_flexion_deg": floor}
    classical = {"upright": True, "knee_pitch_flexion_deg": 0.02}
    assert push_and_comply.meets_robot_floors(internal, classical)
    assert not push_and_comply.meets_robot_floors({**internal, "knee_pitch_flexion_deg": floor - 0.01}, classical)
    assert not push_and_comply.meets_robot_floors({**internal, "upright": False}, classical)
    assert not push_and_comply.meets_robot_floors(internal, {**classical, "upright": False})
    bent = {**classical, "knee_pitch_flexion_deg": push_and_comply.FLOOR_CLASSICAL_KNEE_DEG}
    assert not push_and_comply.meets_robot_floors(internal, bent)
