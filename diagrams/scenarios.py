"""One scenario convention for every experiment, after Drake's ``examples/hardware_sim`` and
``manipulation.station``: each diagram builder takes a dataclass of plain fields (SI units)
that nests Drake's own config types where they exist (``MultibodyPlantConfig``,
``SimulatorConfig``), loaded from YAML with ``pydrake.common.yaml.yaml_load_typed``.

A scenario is read in layers: the dataclass's defaults (or a caller's ``defaults``), then a
YAML file, then YAML text (``--scenario FILE`` and ``--scenario-text 'seed: 3'`` in every
app). Keys missing from a layer keep the previous layer's value; an unknown key or a value of
the wrong type is an error that names it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, TypeVar

from pydrake.common.yaml import yaml_dump_typed, yaml_load, yaml_load_typed

Scenario = TypeVar("Scenario")


class ScenarioError(ValueError):
    """A scenario file or text that cannot be read, or a field with a bad value."""


def load_scenario(
    schema: type[Scenario],
    *,
    filename: str | Path | None = None,
    text: str | None = None,
    defaults: Scenario | None = None,
) -> Scenario:
    """``schema``'s defaults (or ``defaults``), overridden by the YAML file ``filename``, then
    by the YAML text ``text`` (either may be None).

    Raises:
        ScenarioError: a missing or unreadable file, malformed YAML, an unknown key or a value
            of the wrong type (the message says which).
    """
    scenario = defaults if defaults is not None else schema()
    if filename is not None:
        path = Path(filename)
        if not path.is_file():
            raise ScenarioError(f"scenario file '{path}' does not exist")
        try:
            scenario = yaml_load_typed(schema=schema, filename=str(path), defaults=scenario)
        except Exception as error:  # Drake's YAML reader raises RuntimeError with details
            raise ScenarioError(f"could not read the scenario file '{path}': {error}") from error
    if text is not None and text.strip():
        try:
            scenario = yaml_load_typed(schema=schema, data=text, defaults=scenario)
        except Exception as error:
            raise ScenarioError(f"could not read the scenario text {text!r}: {error}") from error
    return scenario


#: Fields that, where a scenario has them, must be positive (s).
POSITIVE_FIELDS = ("duration", "log_period", "observer_period")


def check_common_fields(scenario: Any) -> None:
    """The checks every scenario shares: each nested dataclass with a ``check()`` method
    (e.g. ``WalkingParameters``) runs it (YAML loading sets fields without running
    ``__post_init__``), ``seed`` is non-negative and the ``POSITIVE_FIELDS`` it has are
    positive.

    Raises:
        ValueError: a bad value (the message names it).
    """
    for field in dataclasses.fields(scenario):
        value = getattr(scenario, field.name)
        if dataclasses.is_dataclass(value) and callable(getattr(value, "check", None)):
            value.check()
    if getattr(scenario, "seed", 0) < 0:
        raise ValueError(f"seed must be non-negative, got {scenario.seed}")
    for name in POSITIVE_FIELDS:
        if hasattr(scenario, name) and not getattr(scenario, name) > 0:
            raise ValueError(f"{name} must be positive, got {getattr(scenario, name)}")


def scenario_as_dict(scenario: Any) -> dict:
    """The scenario as plain YAML data (nested Drake config types included), e.g. for a
    ``metrics.json``; ``load_scenario(type(s), text=yaml.dump(scenario_as_dict(s)))``
    gives ``s`` back."""
    if not dataclasses.is_dataclass(scenario):
        raise TypeError(f"a scenario is a dataclass, not {type(scenario).__name__}")
    return yaml_load(data=yaml_dump_typed(scenario)) or {}


def scenario_as_yaml(scenario: Any) -> str:
    """The scenario as YAML text (every field, nested Drake configs included)."""
    return yaml_dump_typed(scenario)


__all__ = [
    "POSITIVE_FIELDS",
    "ScenarioError",
    "check_common_fields",
    "load_scenario",
    "scenario_as_dict",
    "scenario_as_yaml",
]
