"""Smoke test of `python -m apps.standing`."""

import json

import pytest
from pydrake.multibody.plant import MultibodyPlantConfig
from scenario_checks import SCENARIOS, check_scenario_convention

from apps import standing as stand
from diagrams.scenarios import load_scenario
from diagrams.station.standing import StandingScenario, build_standing_diagram


def test_stand_app_runs_and_reports(tmp_path, capsys):
    status = stand.main(["--model", "all", "--duration", "1", "--no-meshcat", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0
    assert "standing simulation of the humanoids" in out
    for name in ("hrp4_like", "nao_like"):
        assert name in out
        row = json.loads((tmp_path / "standing" / f"{name}.json").read_text())
        assert row["fell"] is False
        assert row["feet_flat"] is True
        assert row["min_sphere_force_N"] > 0.0
        assert row["real_time_factor"] > 0.0
        assert not (tmp_path / "standing" / f"{name}.html").exists()  # no Meshcat, no replay


def test_stand_app_rejects_bad_arguments(tmp_path):
    with pytest.raises(SystemExit):
        stand.main(["--model", "atlas", "--no-meshcat", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        stand.main(["--duration", "-1", "--no-meshcat", "--out", str(tmp_path)])


def test_scenario_files_load_into_the_dataclass(tmp_path):
    check_scenario_convention(StandingScenario, "standing_default.yaml", tmp_path, "model")
    scenario = load_scenario(
        StandingScenario,
        filename=SCENARIOS / "standing_default.yaml",
        text="models: [nao_like]\nplant_config: {discrete_contact_approximation: lagged}",
    )
    assert scenario.models == ["nao_like"] and scenario.duration == 10.0  # other keys keep the defaults
    assert scenario.plant_config.discrete_contact_approximation == "lagged"
    with pytest.raises(ValueError, match="deprecated the TAMSI solver"):
        build_standing_diagram(
            "nao_like",
            plant_config=MultibodyPlantConfig(
                time_step=1e-3, contact_model="point", discrete_contact_approximation="tamsi"
            ),
        )


def test_stand_app_reads_scenario_file_and_text(tmp_path, capsys):
    scenario = tmp_path / "short.yaml"
    scenario.write_text("models: [hrp4_like]\nduration: 0.3\n")
    args = [
        "--scenario",
        str(scenario),
        "--scenario-text",
        "models: [nao_like]",
        "--no-meshcat",
        "--out",
        str(tmp_path),
    ]
    assert stand.main(args) == 0
    assert not (tmp_path / "standing" / "hrp4_like.json").exists()
    row = json.loads((tmp_path / "standing" / "nao_like.json").read_text())
    assert row["duration_s"] == 0.3 and row["fell"] is False
    metrics = json.loads((tmp_path / "standing" / "metrics.json").read_text())
    assert metrics["scenario"]["models"] == ["nao_like"] and metrics["nao_like"]["duration_s"] == 0.3
    # The shorthand options override the scenario's fields.
    assert stand.main([*args, "--model", "hrp4_like", "--duration", "0.2"]) == 0
    assert json.loads((tmp_path / "standing" / "hrp4_like.json").read_text())["duration_s"] == 0.2
    capsys.readouterr()
    assert stand.main(["--scenario-text", "model: nao_like", "--no-meshcat", "--out", str(tmp_path)]) == 2
    assert "model" in capsys.readouterr().err
    assert stand.main(["--scenario-text", "models: [atlas]", "--no-meshcat", "--out", str(tmp_path)]) == 2
    assert "atlas" in capsys.readouterr().err


def test_stand_app_writes_a_replay(tmp_path):
    assert stand.main(["--model", "nao_like", "--duration", "0.3", "--headless", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "standing" / "nao_like.html").stat().st_size > 10_000
