"""Checks every app's scenario file gets: its default file is the dataclass's defaults, YAML
text overrides it, and an unknown key is an error that names it."""

from pathlib import Path

import pytest

from diagrams.scenarios import load_scenario, scenario_as_dict


def check_default_file_and_overrides(schema: type, default_file: Path, text: str, unknown_key: str):
    """Asserts that ``default_file`` loads equal to ``schema()`` (every field, nested Drake
    configs included: they have no ==) and that ``unknown_key`` is refused by name; returns
    ``default_file`` overridden by ``text``, for the caller's own assertions."""
    assert scenario_as_dict(load_scenario(schema, filename=default_file)) == scenario_as_dict(schema())
    with pytest.raises(ValueError, match=unknown_key):
        load_scenario(schema, text=f"{unknown_key}: 2.0")
    return load_scenario(schema, filename=default_file, text=text)
