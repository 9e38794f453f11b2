"""One scenario convention for every experiment, after Drake's ``examples/hardware_sim`` and
``manipulation.station``: each diagram builder takes a dataclass of plain fields (SI units)
that nests Drake's own config types where they exist (``MultibodyPlantConfig``,
``SimulatorConfig``), loaded from YAML with ``pydrake.common.yaml.yaml_load_typed``.

A scenario is read in layers: the dataclass's defaults (or a caller's ``defaults``), then a
YAML file, then YAML text (``--scenario FILE`` and ``--scenario-text 'station: {seed: 3}'`` in every
app). Keys missing from a layer keep the previous layer's value; an unknown key or a value of
the wrong type is an error that names it.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import textwrap
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydrake.common.yaml import yaml_dump_typed, yaml_load, yaml_load_typed

from models.drake_compat import UNSHARED_CONFIG_FIELDS

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
            raise ScenarioError(f"could not read the scenario file '{path}': {one_line(error)}") from error
        _check_lists(schema, _yaml_data(path.read_text()), f"scenario file '{path}': ")
    if text is not None and text.strip():
        try:
            scenario = yaml_load_typed(schema=schema, data=text, defaults=scenario)
        except Exception as error:
            raise ScenarioError(f"could not read the scenario text {text!r}: {one_line(error)}") from error
        _check_lists(schema, _yaml_data(text), f"scenario text {text!r}: ")
    return scenario


def _yaml_data(text: str) -> Any:
    """``text`` read by PyYAML (None where PyYAML cannot read what Drake's reader could)."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return None


def _check_lists(schema: type, data: Any, where: str, path: str = "") -> None:
    """Drake's YAML reader turns a string given for a list field into a list of its letters
    (``models: hrp4_like``) and a mapping into a list of its keys: refused here, from the
    YAML ``data`` of ``schema`` (nested dataclasses included).

    Raises:
        ScenarioError: a list field given something else than a list, named.
    """
    if not (dataclasses.is_dataclass(schema) and isinstance(data, dict)):
        return
    try:
        hints = typing.get_type_hints(schema)
    except Exception:  # an annotation that does not resolve at run time: Drake's reader judged it
        return
    for field in dataclasses.fields(schema):
        if field.name not in data:
            continue
        value, name = data[field.name], f"{path}{field.name}"
        hint = hints[field.name]
        union = typing.get_origin(hint) in (typing.Union, types.UnionType)
        kinds = [t for t in typing.get_args(hint) if t is not type(None)] if union else [hint]
        if value is not None and not isinstance(value, list) and all(typing.get_origin(t) is list for t in kinds):
            raise ScenarioError(f"{where}{name} must be a list, got {value!r}")
        for kind in kinds:
            _check_lists(kind, value, where, f"{name}.")


def one_line(error: BaseException | str) -> str:
    """An error's message on one line: its lines stripped and joined by spaces, without the
    caret lines that point into an echoed source line (a YAML parser's message spans five)."""
    lines = (line.strip() for line in str(error).splitlines())
    return " ".join(line for line in lines if line and set(line) != {"^"})


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


#: A field whose name ends in one of these is a time in a run, s: >= 0 (``check_finite_and_signs``).
TIME_SUFFIXES = ("_time", "_start", "_end")


def check_finite_and_signs(scenario: Any) -> None:
    """The checks every scenario gets when it is read (``apps.runner.scenario_from_args``):
    every number, nested ones included, is finite (a duration of ``inf`` would simulate for
    ever); a field whose name ends in ``duration`` or in one of ``TIME_SUFFIXES`` (a time
    in the run, e.g. ``push_start``, ``settle_time``) is >= 0, one that ends in ``period``
    is > 0, and a ``seed`` (or ``*_seed``) is >= 0 (None where a field allows it).

    Raises:
        ValueError: a bad value, named by its dotted field path.
    """

    def walk(value: Any, path: str) -> None:
        if isinstance(value, dict):
            for key, item in value.items():
                walk(item, f"{path}.{key}" if path else str(key))
        elif isinstance(value, list):
            for i, item in enumerate(value):
                walk(item, f"{path}[{i}]")
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            name = path.rsplit(".", 1)[-1]
            if not math.isfinite(value):
                raise ValueError(f"{path} must be finite, got {value}")
            if (name.endswith("duration") or name.endswith(TIME_SUFFIXES)) and value < 0:
                raise ValueError(f"{path} must be >= 0 s, got {value}")
            if (name == "seed" or name.endswith("_seed")) and value < 0:
                raise ValueError(f"{path} must be a non-negative integer, got {value}")
            if name.endswith("period") and value <= 0:
                raise ValueError(f"{path} must be positive, got {value}")

    walk(scenario_as_dict(scenario), "")


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


def attribute_docs(schema: type) -> dict[str, str]:
    """The entries of the "Attributes:" section of ``schema``'s docstring by field name, each
    as written (``"a, b: text"`` for both ``a`` and ``b``; continuation lines joined)."""
    lines = inspect.cleandoc(schema.__doc__ or "").splitlines()
    if "Attributes:" not in lines:
        return {}
    entries: list[tuple[list[str], str]] = []
    for line in lines[lines.index("Attributes:") + 1 :]:
        if line.strip() and not line.startswith(" "):
            break  # the next section
        if line.startswith("    ") and not line.startswith("     ") and ":" in line:
            names = [name.strip() for name in line.partition(":")[0].split(",")]
            entries.append((names, line.strip()))
        elif entries and line.strip():
            entries[-1] = (entries[-1][0], f"{entries[-1][1]} {line.strip()}")
    return {name: text for names, text in entries for name in names}


def _shared_config_fields(value: Any, data: Any) -> Any:
    """``data`` (the YAML data of ``value``) without the fields of Drake's config structs that
    not every supported Drake release has (``models.drake_compat``), recursively through
    dataclasses.

    Raises:
        ValueError: such a field away from Drake's default (a file that holds it would not load
            on every supported release).
    """
    unshared = UNSHARED_CONFIG_FIELDS.get(type(value).__name__, ())
    if unshared and isinstance(data, dict):
        default = yaml_load(data=yaml_dump_typed(type(value)()))
        for name in unshared:
            if name in data and data[name] != default.get(name):
                raise ValueError(
                    f"{type(value).__name__}.{name} = {data[name]!r} is not Drake's default, and not every "
                    "supported Drake release has this field (models/drake_compat.py)"
                )
            data.pop(name, None)
    if dataclasses.is_dataclass(value) and isinstance(data, dict):
        for field in dataclasses.fields(value):
            if field.name in data:
                data[field.name] = _shared_config_fields(getattr(value, field.name), data[field.name])
    return data


class _ScenarioDumper(yaml.SafeDumper):
    """Block style, but a list of scalars on one line (``push_point: [0.0, 0.0, 0.0]``)."""


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flat = all(not isinstance(item, (list, dict)) for item in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flat)


_ScenarioDumper.add_representer(list, _represent_list)


def _comment(text: str) -> str:
    return textwrap.fill(text, 100, initial_indent="# ", subsequent_indent="# ", break_on_hyphens=False)


def scenario_file_text(scenario: Any, header: str) -> str:
    """A scenario file of ``scenario``: ``header`` as comment lines, then every field (nested
    Drake configs included, less the fields only some supported Drake releases have), each
    below its entry of the docstring's "Attributes:" section. The apps' default files are
    written with it (``python -m apps.write_scenarios``)."""
    data = _shared_config_fields(scenario, scenario_as_dict(scenario))
    docs = attribute_docs(type(scenario))
    parts = [_comment(paragraph) for paragraph in header.strip().split("\n\n")]
    described: set[str] = set()
    for name, value in data.items():
        if name in docs and docs[name] not in described:
            described.add(docs[name])
            parts.append(_comment(docs[name]))
        parts.append(yaml.dump({name: value}, Dumper=_ScenarioDumper, sort_keys=False, width=100).rstrip())
    return "\n".join(parts) + "\n"


__all__ = [
    "POSITIVE_FIELDS",
    "ScenarioError",
    "TIME_SUFFIXES",
    "attribute_docs",
    "check_common_fields",
    "check_finite_and_signs",
    "load_scenario",
    "one_line",
    "scenario_as_dict",
    "scenario_as_yaml",
    "scenario_file_text",
]
