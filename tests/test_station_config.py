"""The station's settings (``diagrams.station.config.StationConfig``): one nested config in
every experiment scenario, the realistic default world and ``--ideal`` (apps.runner)."""

import dataclasses

import pytest
from pydrake.systems.framework import DiagramBuilder

from apps.runner import experiment_parser, scenario_from_args
from diagrams.locomotion.nao_walk import NaoWalkScenario
from diagrams.residuals.contact_study import ContactLocalizationScenario
from diagrams.residuals.model_refinement import ModelRefinementScenario, refinement_scenario_for
from diagrams.residuals.push_and_comply import PushAndComplyScenario
from diagrams.residuals.residual_comparison import ResidualComparisonScenario
from diagrams.scenarios import load_scenario, scenario_as_dict
from diagrams.station.config import StationConfig, check_model_refinement, replace_station
from diagrams.station.humanoid_station import add_humanoid_station
from systems.simulation.imperfections import Imperfections

ALL = (PushAndComplyScenario, ResidualComparisonScenario, ContactLocalizationScenario)
STATION_FIELDS = {f.name for f in dataclasses.fields(StationConfig)}


@pytest.mark.parametrize("schema", (*ALL, ModelRefinementScenario, NaoWalkScenario))
def test_every_station_scenario_nests_one_station_config_and_repeats_none_of_its_fields(schema):
    fields = {f.name for f in dataclasses.fields(schema)}
    assert "station" in fields and isinstance(schema().station, StationConfig)
    assert not fields & STATION_FIELDS, f"{schema.__name__} repeats {sorted(fields & STATION_FIELDS)}"


@pytest.mark.parametrize("schema", ALL)
def test_the_hrp4_experiments_default_to_the_realistic_world(schema):
    station = schema().station
    assert station.base_state == "invariant_ekf"
    assert station.model_refinement == "calibrate"
    realistic = Imperfections.realistic()
    assert station.imperfections.model_mismatch.mass_percent == realistic.model_mismatch.mass_percent == 5.0
    assert station.imperfections.friction.coulomb_percent == realistic.friction.coulomb_percent > 0.0
    assert not station.is_ideal and StationConfig().is_ideal


def test_in_world_sets_only_the_world_fields():
    custom = StationConfig(model="nao_like", seed=7, noise=False, noise_scale=2.0)
    realistic = custom.in_world("realistic")
    assert (realistic.model, realistic.seed, realistic.noise, realistic.noise_scale) == ("nao_like", 7, False, 2.0)
    assert realistic.base_state == "invariant_ekf" and realistic.model_refinement == "calibrate"
    assert realistic.imperfections == Imperfections.realistic()
    assert (
        scenario_as_dict(realistic.in_world("ideal")) == scenario_as_dict(custom) and custom.in_world("ideal").is_ideal
    )
    with pytest.raises(ValueError, match="world must be one of"):
        custom.in_world("real")
    # realistic(**fields): the world first, then the fields.
    assert StationConfig.realistic(model_refinement="none").model_refinement == "none"


@pytest.mark.parametrize("schema", ALL)
def test_ideal_flag_restores_the_ideal_world_after_the_scenario_file(schema, tmp_path):
    module = {
        PushAndComplyScenario: "push_and_comply",
        ResidualComparisonScenario: "residual_comparison",
        ContactLocalizationScenario: "contact_localization",
    }[schema]
    parser = experiment_parser(f"apps.{module}", None, conditions=True, robot=True)
    scenario_file = tmp_path / "realistic.yaml"
    scenario_file.write_text("station: {base_state: invariant_ekf, seed: 4}\n")
    realistic = scenario_from_args(schema, parser.parse_args(["--scenario", str(scenario_file)]))
    assert not realistic.station.is_ideal and realistic.station.seed == 4
    ideal = scenario_from_args(schema, parser.parse_args(["--scenario", str(scenario_file), "--ideal"]))
    assert ideal.station.is_ideal and ideal.station.seed == 4
    # The apps' shorthand options set the station's fields; --robot its model.
    robot = "models/robots/talos.yaml"
    chosen = scenario_from_args(schema, parser.parse_args(["--robot", robot]), seed=9)
    assert chosen.station.seed == 9 and chosen.station.model == robot
    with pytest.raises(ValueError, match="has no field 'sed'"):
        scenario_from_args(schema, parser.parse_args([]), sed=9)


def test_a_scenario_file_sets_nested_station_fields_and_keeps_the_others():
    scenario = load_scenario(PushAndComplyScenario, text="station: {seed: 3, imperfections: {seed: 2}}")
    assert scenario.station.seed == 3 and scenario.station.imperfections.seed == 2
    assert scenario.station.model == "hrp4_like" and scenario.station.base_state == "invariant_ekf"
    assert scenario.station.imperfections.model_mismatch.mass_percent == 5.0
    again = load_scenario(PushAndComplyScenario, text="\n".join(_yaml_lines(scenario)))
    assert scenario_as_dict(again) == scenario_as_dict(scenario)
    with pytest.raises(ValueError, match="seed"):
        load_scenario(PushAndComplyScenario, text="seed: 3")  # not a field of the scenario any more


def _yaml_lines(scenario) -> list[str]:
    import yaml

    return yaml.safe_dump(scenario_as_dict(scenario)).splitlines()


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"model": ""}, "station.model"),
        ({"seed": -1}, "station.seed"),
        ({"noise_scale": 0.0}, "station.noise_scale"),
        ({"noise_scale": float("nan")}, "station.noise_scale"),
        ({"base_state": "ekf"}, "station.base_state"),
        ({"imperfections": {"seed": 1}}, "station.imperfections"),
        ({"model_refinement": "calibrated"}, "model_refinement must be one of"),
        ({"at_rest_duration": -0.5}, "station.at_rest_duration"),
    ],
)
def test_bad_station_fields_are_refused_by_name_before_anything_is_built(fields, message):
    config = StationConfig(**fields)
    with pytest.raises(ValueError, match=message):
        config.check()
    with pytest.raises(ValueError, match=message):
        add_humanoid_station(DiagramBuilder(), config)
    with pytest.raises(ValueError, match="takes a StationConfig"):
        add_humanoid_station(DiagramBuilder(), "hrp4_like")


def test_replace_station_and_the_calibration_scenario():
    scenario = PushAndComplyScenario()
    trial = replace_station(scenario, seed=5)
    assert trial.station.seed == 5 and scenario.station.seed == 0 and trial.residual_gain == scenario.residual_gain
    calibration = refinement_scenario_for(trial)
    # The same robot and world, another noise draw, and no refinement of its own.
    expected = dataclasses.replace(trial.station, seed=6, model_refinement="none")
    assert scenario_as_dict(calibration.station) == scenario_as_dict(expected)
    assert calibration.internal_gain == scenario.residual_gain


def test_model_refinement_values_are_checked(tmp_path):
    assert check_model_refinement("calibrate") == "calibrate"
    assert check_model_refinement("none") == "none"
    saved = tmp_path / "corrections.npz"
    saved.write_bytes(b"")
    assert check_model_refinement(str(saved)) == str(saved)
    with pytest.raises(ValueError, match="model_refinement must be one of"):
        check_model_refinement("calibrated")


def test_ideal_is_only_offered_where_it_means_something():
    assert "--ideal" not in experiment_parser("apps.standing", None).format_help()
    assert "--ideal" in experiment_parser("apps.push_and_comply", None, conditions=True).format_help()


def test_the_contact_study_checks_the_floors_of_its_world():
    from diagrams.residuals.contact_study import FLOORS, REALISTIC_FLOORS, TWO_CONTACT_FLOORS, floors_for

    assert floors_for(ContactLocalizationScenario()) is REALISTIC_FLOORS
    assert floors_for(ContactLocalizationScenario(station=StationConfig())) is FLOORS
    assert floors_for(ContactLocalizationScenario(contacts=2)) is TWO_CONTACT_FLOORS
    # The realistic floors: issue 12's single-contact floors hold there too ("the default
    # noisy column"); issue 11's for detection, force and false detections (0).
    for key in ("correct_link_rate", "valid_precision", "valid_rate", "more_than_one_contact_rate"):
        assert REALISTIC_FLOORS[key] == FLOORS[key], key
    assert REALISTIC_FLOORS["false_detections"] == ("<=", 0) and REALISTIC_FLOORS["detection_rate"] == (">=", 0.98)
    # Issue 12's ideal-world floors.
    assert FLOORS["correct_link_rate"] == (">=", 0.97) and FLOORS["valid_precision"] == (">=", 0.995)
    assert TWO_CONTACT_FLOORS["both_links_right_rate"] == (">=", 0.80)


@pytest.mark.parametrize("schema", (*ALL, ModelRefinementScenario, NaoWalkScenario, StationConfig))
def test_a_field_the_scenario_does_not_have_cannot_be_set(schema):
    """Scenarios are slotted dataclasses: ``scenario.seed = 3`` on a scenario whose seed is its
    station's is an error, not a new attribute that nothing reads."""
    scenario = schema()
    with pytest.raises(AttributeError):
        scenario.sed = 3
    if schema is not StationConfig:
        with pytest.raises(AttributeError):
            scenario.seed = 3
