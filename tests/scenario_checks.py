"""Checks every app's scenario type passes: the scenario convention of ``diagrams.scenarios``."""

from pathlib import Path

import pytest

from diagrams.scenarios import load_scenario, scenario_as_dict

#: The apps' scenario files.
SCENARIOS = Path(__file__).resolve().parent.parent / "apps" / "scenarios"


def check_scenario_convention(
    schema: type, default_file: str, tmp_path: Path, unknown_key: str = "no_such_field"
) -> None:
    """``apps/scenarios/<default_file>`` loads equal to ``schema()`` (every field, compared
    through YAML: Drake's config types have no ==); a missing file, an unknown key (in a file
    or in the text) and a value of the wrong type are ValueErrors that say which."""
    default = scenario_as_dict(schema())
    assert scenario_as_dict(load_scenario(schema)) == default
    assert scenario_as_dict(load_scenario(schema, filename=SCENARIOS / default_file)) == default
    with pytest.raises(ValueError, match="does not exist"):
        load_scenario(schema, filename=tmp_path / "missing.yaml")
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text(f"{unknown_key}: 3\n")
    with pytest.raises(ValueError, match=unknown_key):
        load_scenario(schema, filename=unknown)
    with pytest.raises(ValueError, match=unknown_key):
        load_scenario(schema, text=f"{unknown_key}: 3")
    with pytest.raises(ValueError, match="could not read the scenario text"):
        load_scenario(schema, text="duration: [1, 2]")
