"""The one runner every app uses: its command line (``--scenario FILE``, ``--scenario-text
YAML``, ``--out DIR``, ``--headless``, ``--no-replay``), the scenario loading, the simulation
with progress and Meshcat recording (``simulate`` and ``SimulationRun``, re-exported from
``diagrams.simulation``, the loop the calibrations and trials below the apps use too), the
replay files, ``metrics.json``, and the errors.

An app is then what is particular to its experiment: its scenario type and diagram (in
``diagrams/``), its metrics (next to the diagram), its plots and its printed table.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import Context

from diagrams.scenarios import (
    ScenarioError,
    check_finite_and_signs,
    load_scenario,
    one_line,
    scenario_as_dict,
    scenario_file_text,
)
from diagrams.simulation import SimulationRun, simulate
from diagrams.station.config import StationConfig
from models import robot_description

#: The folder every app writes into, as ``DIR/<experiment>/`` (``--out DIR``).
DEFAULT_OUT = Path("out")


def memory_allocator() -> str:
    """ "tcmalloc" when the process runs with tcmalloc preloaded (``make`` does it when the
    library is installed: Drake's SAP solver then takes less time per step), else "system"."""
    return "tcmalloc" if "tcmalloc" in os.environ.get("LD_PRELOAD", "") else "system"


def experiment_parser(
    module: str, doc: str | None, *, replay: bool = True, conditions: bool = False, robot: bool = False
) -> argparse.ArgumentParser:
    """The arguments every app shares; the app adds its own. ``module`` is the app's module
    name (``apps.<experiment>``), ``doc`` its docstring (the first paragraph is the
    description). With ``conditions`` (the experiments whose default is the realistic
    world, ``diagrams.station.config``) the app also takes ``--ideal``; with ``robot``
    (the experiments on any humanoid) ``--robot FILE.yaml``, a robot description
    (``models.description``) that replaces the scenario's model."""
    parser = _AppParser(module, prog=f"python -m {module}", description=(doc or "").split("\n\n")[0])
    parser.add_argument(
        "--scenario",
        type=Path,
        default=None,
        metavar="FILE",
        help="YAML scenario file (apps/scenarios/); missing keys keep their defaults",
    )
    parser.add_argument(
        "--scenario-text",
        default=None,
        metavar="YAML",
        help="YAML overrides applied after --scenario, e.g. --scenario-text 'station: {seed: 3}'",
    )
    parser.add_argument(
        "--print-scenario",
        action="store_true",
        help="print the scenario this command would run (YAML, every field, after --scenario, --scenario-text "
        "and the other options) and exit: a file to start from",
    )
    add_out_argument(parser)
    parser.add_argument(
        "--results",
        type=results_name,
        default=None,
        metavar="NAME",
        help="also write the metrics to results/NAME.json, with this command (the file the docs' tables are "
        "generated from: python -m apps.doc_tables)",
    )
    parser.add_argument("--headless", action="store_true", help="no live Meshcat URL (the replays are still written)")
    if replay:
        parser.add_argument("--no-replay", action="store_true", help="skip the Meshcat replays (faster)")
    if robot:
        parser.add_argument(
            "--robot",
            default=None,
            metavar="FILE.yaml",
            help="the robot: a robot description YAML beside its URDF/SDF (docs/robots.md, 'Bring your own robot'), "
            "or a built-in name (hrp4_like, nao_like); default: the scenario's model",
        )
    if conditions:
        parser.add_argument(
            "--ideal",
            action="store_true",
            help="the ideal world: true base state plus white noise, no imperfections, no model refinement "
            "(default: realistic; applied after --scenario and --scenario-text)",
        )
    return parser


class _AppParser(argparse.ArgumentParser):
    """An app's parser: the parsed arguments also hold ``command``, the command line that
    ran the app (``apps.results.app_command``: what a results file records)."""

    def __init__(self, module: str, **kwargs):
        super().__init__(**kwargs)
        self.module = module

    def parse_args(self, args=None, namespace=None):
        from apps.results import app_command

        parsed = super().parse_args(args, namespace)
        parsed.command = app_command(self.module, None if args is None else list(args))
        return parsed


def _number(text: str, kind: type, lowest: float, inclusive: bool) -> int | float:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected {'an integer' if kind is int else 'a number'}, got {text!r}"
        ) from None
    if not math.isfinite(value) or value < lowest or (value == lowest and not inclusive):
        raise argparse.ArgumentTypeError(f"must be finite and {'>=' if inclusive else '>'} {lowest:g}, got {text}")
    return value


def positive_int(text: str) -> int:
    """An option's type: an integer > 0 (``argparse`` names the option in its error)."""
    return _number(text, int, 0, False)


def non_negative_int(text: str) -> int:
    """An option's type: an integer >= 0."""
    return _number(text, int, 0, True)


def positive_float(text: str) -> float:
    """An option's type: a finite number > 0."""
    return _number(text, float, 0.0, False)


def non_negative_float(text: str) -> float:
    """An option's type: a finite number >= 0."""
    return _number(text, float, 0.0, True)


def writable_folder(text: str) -> Path:
    """``--out``'s type: the folder ``text``, created if missing, into which a file can be
    written; checked when the command line is read, before any simulation.

    Raises:
        argparse.ArgumentTypeError: a file, or a folder that cannot be created or written
            (the reason named).
    """
    folder = Path(text)
    problem = _unwritable(folder)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return folder


def results_name(text: str) -> str:
    """``--results``'s type: a plain file stem whose results file
    (``apps.results.results_path``) can be written; checked before any simulation.

    Raises:
        argparse.ArgumentTypeError: a name with a folder in it, or a results folder that is
            a file or cannot be written.
    """
    from apps.results import results_path

    try:
        path = results_path(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    problem = _unwritable(path.parent)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def _unwritable(folder: Path) -> str | None:
    """Why ``folder`` (created if missing) cannot take a file, or None when a file was
    written into it."""
    if folder.exists() and not folder.is_dir():
        return f"'{folder}' is a file, not a folder"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        return f"cannot write into '{folder}': {error.strerror or error}"
    return None


def add_out_argument(parser: argparse.ArgumentParser, folder: str = "<experiment>") -> None:
    """``--out OUT`` (default ``out``): the app writes into ``OUT/<folder>/``
    (``output_folder``); also for the apps without a scenario. A folder that cannot be
    written is refused when the command line is read (``writable_folder``)."""
    parser.add_argument(
        "--out",
        type=writable_folder,
        default=str(DEFAULT_OUT),
        help=f"output folder; the app writes into OUT/{folder}/ (default {DEFAULT_OUT})",
    )


def scenario_from_args(schema: type, args: argparse.Namespace, defaults: Any = None, **overrides: Any) -> Any:
    """The scenario of ``--scenario`` and ``--scenario-text`` over ``defaults`` (or
    ``schema()``); with ``--ideal``, its ``station`` in the ideal world
    (``StationConfig.in_world``); then each keyword in ``overrides`` whose value is not None
    replaces that field, or else its ``station``'s (an app's shorthand options such as
    ``--seed``); ``--robot`` replaces its station's ``model`` (or its ``models`` list), after
    the description is read and checked. With
    ``--print-scenario`` it prints the result as a scenario file and exits (``SystemExit(0)``).

    Raises:
        ScenarioError: see ``diagrams.scenarios.load_scenario``; an override of an unknown field.
        ValueError: a ``--robot`` that is no readable description (naming the field); a number
            that is not finite, a negative duration, time or seed, or a period that is not
            positive (``diagrams.scenarios.check_finite_and_signs``).
    """
    robot = getattr(args, "robot", None)
    if robot is not None:
        robot_description(robot)  # a bad file fails here, naming its field, before anything is built
        if "models" in {f.name for f in dataclasses.fields(schema)}:
            overrides = {**overrides, "models": [robot]}
        else:
            overrides = {**overrides, "model": robot}
    scenario = load_scenario(schema, filename=args.scenario, text=args.scenario_text, defaults=defaults)
    station = getattr(scenario, "station", None)
    if getattr(args, "ideal", False):
        if not isinstance(station, StationConfig):
            raise ScenarioError(f"{schema.__name__} has no station to put in the ideal world")
        scenario.station = station = station.in_world("ideal")
    for name, value in overrides.items():
        if value is None:
            continue
        if hasattr(scenario, name):
            setattr(scenario, name, value)
        elif isinstance(station, StationConfig) and hasattr(station, name):
            setattr(station, name, value)
        else:
            raise ScenarioError(f"{schema.__name__} has no field '{name}'")
    check_finite_and_signs(scenario)
    if getattr(args, "print_scenario", False):
        header = f"A scenario of {schema.__module__}.{schema.__qualname__} (SI units)."
        print(scenario_file_text(scenario, header), end="")
        raise SystemExit(0)
    return scenario


def replace_fields(config: Any, **overrides: Any) -> Any:
    """A copy of the dataclass ``config`` (e.g. a scenario's nested ``walking``) with each
    keyword in ``overrides`` whose value is not None replacing that field (an app's
    shorthand options); ``dataclasses.replace`` runs the type's own checks again.

    Raises:
        ScenarioError: an override of an unknown field.
    """
    for name in overrides:
        if not hasattr(config, name):
            raise ScenarioError(f"{type(config).__name__} has no field '{name}'")
    return dataclasses.replace(config, **{name: value for name, value in overrides.items() if value is not None})


#: The output folders of the run under way: (folder, the previous output moved aside or None).
_RUN_OUTPUTS: list[tuple[Path, Path | None]] = []

#: Where the apps keep the model calibrations they reuse (``OUT/<CALIBRATION_CACHE>/``): not
#: an app's output folder, which a run replaces whole.
CALIBRATION_CACHE = "calibration_cache"


def output_folder(args: argparse.Namespace, experiment: str) -> Path:
    """``OUT/<experiment>/``, created empty for this run. An earlier output there is moved
    aside and comes back unchanged when the run fails (``run_app``: an error, exit code 2,
    or an interruption); on success it is deleted, so the folder holds this run's files only.

    Raises:
        ValueError: it exists as a file, or cannot be created (the reason named).
    """
    folder = Path(args.out) / experiment
    if any(folder == pending for pending, _ in _RUN_OUTPUTS):
        return folder
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"the output folder '{folder}' is a file")
    previous = None
    try:
        if folder.exists():
            previous = folder.with_name(f".{folder.name}.previous-{os.getpid()}")
            if previous.exists():
                shutil.rmtree(previous)
            folder.rename(previous)
        folder.mkdir(parents=True)
    except OSError as error:
        if previous is not None and previous.exists() and not folder.exists():
            previous.rename(folder)
        raise ValueError(f"cannot create the output folder '{folder}': {error.strerror or error}") from None
    _RUN_OUTPUTS.append((folder, previous))
    return folder


def calibration_cache_folder(args: argparse.Namespace) -> Path:
    """``OUT/calibration_cache/``: where ``diagrams.residuals.model_refinement.refined_model``
    keeps the calibrations the realistic apps reuse; created, and checked to take a file
    before anything is calibrated.

    Raises:
        ValueError: it is a file, or cannot be created or written (the reason named).
    """
    folder = Path(args.out) / CALIBRATION_CACHE
    problem = _unwritable(folder)
    if problem is not None:
        raise ValueError(f"the calibration cache: {problem}")
    return folder


def finish_outputs(success: bool) -> None:
    """Ends the run's output folders: kept (the earlier outputs deleted) on ``success``, else
    removed with the earlier outputs put back as they were. ``run_app`` calls it."""
    while _RUN_OUTPUTS:
        folder, previous = _RUN_OUTPUTS.pop()
        if success:
            if previous is not None:
                shutil.rmtree(previous, ignore_errors=True)
            continue
        shutil.rmtree(folder, ignore_errors=True)
        if previous is not None and previous.exists():
            previous.rename(folder)


def replay_meshcat(enabled: bool, headless: bool) -> Meshcat | None:
    """A Meshcat for recording the replays (None when replays are off); prints its live URL
    unless ``headless``."""
    if not enabled:
        return None
    meshcat = Meshcat()
    if not headless:
        print(f"Meshcat (live view): {meshcat.web_url()}")
    return meshcat


def logged_signals(loggers: dict, context: Context, time_from: str) -> dict:
    """{name: (size, samples) array} of every logger's log in ``context``, plus ``"t"``, the
    sample times of the logger ``time_from`` (all loggers of one rate share them)."""
    logs = {name: logger.FindLog(context) for name, logger in loggers.items()}
    signals = {name: log.data() for name, log in logs.items()}
    signals["t"] = logs[time_from].sample_times()
    return signals


def save_replay(meshcat: Meshcat | None, path: Path) -> Path | None:
    """Writes the published recording of ``meshcat`` as a self-contained HTML file."""
    if meshcat is None:
        return None
    path.write_text(meshcat.StaticHtml())
    return path


def _json_value(value: Any) -> Any:
    """``json.dumps``'s ``default``: a NumPy scalar as its Python value (a NumPy bool stays a
    bool), an array as a list, a path as text; anything else float() accepts as a float."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{type(value).__name__} is not JSON serializable: {value!r}") from None


def json_text(data: Any) -> str:
    """``data`` as indented JSON text (NumPy values included; NaN and infinities as JSON's
    extension, ``NaN``/``Infinity``), ending with a newline."""
    return json.dumps(data, indent=2, allow_nan=True, default=_json_value) + "\n"


def write_metrics(folder: Path, metrics: dict, scenario: Any = None, args: argparse.Namespace | None = None) -> Path:
    """``folder/metrics.json``: ``metrics``, plus the scenario (every field) and the memory
    allocator the run used; with ``args.results`` (``--results NAME``) the same payload but
    its ``per_trial`` list also goes to ``results/NAME.json`` with the command
    (``apps.results.write_results``)."""
    payload = dict(metrics)
    if scenario is not None:
        payload["scenario"] = scenario_as_dict(scenario)
    payload.setdefault("memory_allocator", memory_allocator())
    path = folder / "metrics.json"
    path.write_text(json_text(payload))
    if args is not None and getattr(args, "results", None):
        from apps.results import write_results

        # Per-trial lists (the contact study's ``per_trial``) stay in metrics.json only.
        summary = {k: v for k, v in payload.items() if k != "per_trial"}
        written = write_results(args.results, json.loads(json_text(summary)), command=args.command)
        print(f"results file: {written}")
    return path


def print_written(folder: Path) -> None:
    print(f"wrote {folder}: " + ", ".join(sorted(p.name for p in folder.iterdir())))


def run_app(name: str, body: Callable[[], int | None]) -> int:
    """Runs an app's ``body``; a ``ValueError`` (bad scenario, bad option, bad input data) or
    an ``OSError`` (a file that cannot be read or written) becomes ``<name>: error:
    <message>`` on stderr (one line, ``diagrams.scenarios.one_line``) and exit code 2, never a
    traceback. The run's output folders (``output_folder``) are kept when ``body`` returns 0
    or 1 (it ran and reports, e.g. a robot that fell); after an error or an interruption
    they are removed and the earlier outputs put back unchanged."""
    try:
        code = int(body() or 0)
    except ValueError as error:
        finish_outputs(False)
        print(f"\n{name}: error: {one_line(error)}", file=sys.stderr)
        return 2
    except OSError as error:
        finish_outputs(False)
        where = f" '{error.filename}'" if error.filename else ""
        print(f"\n{name}: error: {one_line(error.strerror or error)}{where}", file=sys.stderr)
        return 2
    except BaseException:
        finish_outputs(False)
        raise
    finish_outputs(code in (0, 1))
    return code


__all__ = [
    "CALIBRATION_CACHE",
    "DEFAULT_OUT",
    "ScenarioError",
    "SimulationRun",
    "add_out_argument",
    "calibration_cache_folder",
    "writable_folder",
    "experiment_parser",
    "finish_outputs",
    "json_text",
    "logged_signals",
    "memory_allocator",
    "non_negative_float",
    "non_negative_int",
    "output_folder",
    "positive_float",
    "positive_int",
    "print_written",
    "replace_fields",
    "replay_meshcat",
    "results_name",
    "run_app",
    "save_replay",
    "scenario_from_args",
    "simulate",
    "write_metrics",
]
