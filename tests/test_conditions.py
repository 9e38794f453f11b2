"""The realistic default world and ``--ideal`` (diagrams.station.conditions, apps.runner)."""

import pytest

from apps.runner import experiment_parser, scenario_from_args
from diagrams.residuals.contact_localization import ContactLocalizationScenario
from diagrams.residuals.push_and_comply import PushAndComplyScenario
from diagrams.residuals.residual_comparison import ResidualComparisonScenario
from diagrams.station.conditions import check_model_refinement, is_ideal, set_ideal_conditions
from diagrams.station.standing import StandingScenario
from systems.simulation.imperfections import Imperfections

ALL = (PushAndComplyScenario, ResidualComparisonScenario, ContactLocalizationScenario)


@pytest.mark.parametrize("schema", ALL)
def test_the_hrp4_experiments_default_to_the_realistic_world(schema):
    scenario = schema()
    assert scenario.base_state == "invariant_ekf"
    assert scenario.model_refinement == "calibrate"
    realistic = Imperfections.realistic()
    assert scenario.imperfections.model_mismatch.mass_percent == realistic.model_mismatch.mass_percent == 5.0
    assert scenario.imperfections.friction.coulomb_percent == realistic.friction.coulomb_percent > 0.0
    assert not is_ideal(scenario)


@pytest.mark.parametrize("schema", ALL)
def test_ideal_flag_restores_the_ideal_world_after_the_scenario_file(schema, tmp_path):
    module = {
        PushAndComplyScenario: "push_and_comply",
        ResidualComparisonScenario: "residual_comparison",
        ContactLocalizationScenario: "contact_localization",
    }[schema]
    parser = experiment_parser(f"apps.{module}", None, conditions=True)
    scenario_file = tmp_path / "realistic.yaml"
    scenario_file.write_text("base_state: invariant_ekf\nseed: 4\n")
    realistic = scenario_from_args(schema, parser.parse_args(["--scenario", str(scenario_file)]))
    assert not is_ideal(realistic) and realistic.seed == 4
    ideal = scenario_from_args(schema, parser.parse_args(["--scenario", str(scenario_file), "--ideal"]))
    assert is_ideal(ideal) and ideal.seed == 4
    assert ideal.base_state == "truth_plus_noise" and ideal.imperfections.is_ideal and ideal.model_refinement == "none"


def test_ideal_is_only_offered_where_it_means_something():
    assert "--ideal" not in experiment_parser("apps.standing", None).format_help()
    assert "--ideal" in experiment_parser("apps.push_and_comply", None, conditions=True).format_help()
    # A scenario without condition fields is left alone.
    standing = StandingScenario()
    assert set_ideal_conditions(standing) is standing and is_ideal(standing)


def test_model_refinement_values_are_checked(tmp_path):
    assert check_model_refinement("calibrate") == "calibrate"
    assert check_model_refinement("none") == "none"
    saved = tmp_path / "corrections.npz"
    saved.write_bytes(b"")
    assert check_model_refinement(str(saved)) == str(saved)
    with pytest.raises(ValueError, match="model_refinement must be one of"):
        check_model_refinement("calibrated")


def test_the_contact_study_checks_the_floors_of_its_world():
    from diagrams.residuals.contact_localization import FLOORS, REALISTIC_FLOORS, TWO_CONTACT_FLOORS, floors_for

    assert floors_for(ContactLocalizationScenario()) is REALISTIC_FLOORS
    assert floors_for(set_ideal_conditions(ContactLocalizationScenario())) is FLOORS
    assert floors_for(ContactLocalizationScenario(contacts=2)) is TWO_CONTACT_FLOORS
    # The realistic floors: issue 12's single-contact floors hold there too ("the default
    # noisy column"); issue 11's for detection, force and false detections (0).
    for key in ("correct_link_rate", "valid_precision", "valid_rate", "more_than_one_contact_rate"):
        assert REALISTIC_FLOORS[key] == FLOORS[key], key
    assert REALISTIC_FLOORS["false_detections"] == ("<=", 0) and REALISTIC_FLOORS["detection_rate"] == (">=", 0.98)
    # Issue 12's ideal-world floors.
    assert FLOORS["correct_link_rate"] == (">=", 0.97) and FLOORS["valid_precision"] == (">=", 0.995)
    assert TWO_CONTACT_FLOORS["both_links_right_rate"] == (">=", 0.80)
