"""The default scenario files are written from the dataclasses (``apps.write_scenarios``) and
load on the installed Drake release: the files in the repository are what the command writes,
every ``*_default.yaml`` is one of them, and a Drake config field that not every supported
release has is left out (``models.drake_compat``)."""

# No ``from __future__ import annotations``: Drake's YAML writer reads the test dataclasses' field types.
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

import diagrams.scenarios as scenarios
from apps.write_scenarios import DEFAULT_SCENARIOS, SCENARIO_FOLDER, default_file_text, write_default_scenarios
from diagrams.scenarios import attribute_docs, load_scenario, scenario_as_dict, scenario_file_text


def test_committed_files_are_what_the_command_writes():
    differ = []
    assert write_default_scenarios(check=True, report=differ.append) == [], differ


def test_every_default_file_is_written_by_the_command():
    assert sorted(p.name for p in SCENARIO_FOLDER.glob("*_default.yaml")) == sorted(DEFAULT_SCENARIOS)


@pytest.mark.parametrize("name", sorted(DEFAULT_SCENARIOS))
def test_default_file_loads_equal_to_the_dataclass(name):
    schema = DEFAULT_SCENARIOS[name]
    loaded = load_scenario(schema, filename=SCENARIO_FOLDER / name)
    assert scenario_as_dict(loaded) == scenario_as_dict(schema())


def test_check_reports_a_stale_file_and_the_command_rewrites_it(tmp_path: Path):
    name = "standing_default.yaml"
    (tmp_path / name).write_text(default_file_text(name).replace("duration: 10.0", "duration: 11.0"))
    reported = []
    assert name in write_default_scenarios(tmp_path, check=True, report=reported.append)
    assert any(name in line for line in reported)
    assert "duration: 11.0" in (tmp_path / name).read_text()  # --check writes nothing
    write_default_scenarios(tmp_path, report=lambda _: None)
    assert (tmp_path / name).read_text() == default_file_text(name)


@dataclass
class _Config:
    kept: float = 1.0
    only_in_some_releases: bool = False


@dataclass
class _Scenario:
    """A scenario for the test.

    Attributes:
        speed, seed: the speed, m/s, and the seed; a long description that goes on to a
            second line.
        config: a config of which one field only some releases have.
    """

    speed: float = 2.0
    seed: int = 0
    config: _Config = field(default_factory=_Config)


def test_attribute_docs_reads_joint_entries_and_continuations():
    docs = attribute_docs(_Scenario)
    assert docs["speed"] == docs["seed"]
    assert docs["speed"].startswith("speed, seed: the speed") and docs["speed"].endswith("a second line.")
    assert docs["config"] == "config: a config of which one field only some releases have."


def test_unshared_config_fields_are_left_out_and_a_set_one_is_refused(monkeypatch):
    monkeypatch.setattr(scenarios, "UNSHARED_CONFIG_FIELDS", {"_Config": ("only_in_some_releases",)})
    text = scenario_file_text(_Scenario(), "header")
    data = yaml.safe_load(text)
    assert data == {"speed": 2.0, "seed": 0, "config": {"kept": 1.0}}
    assert text.count("# speed, seed:") == 1  # one comment for the joint entry
    with pytest.raises(ValueError, match="only_in_some_releases"):
        scenario_file_text(_Scenario(config=_Config(only_in_some_releases=True)), "header")
