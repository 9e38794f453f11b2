"""Bad inputs to the apps are refused with one line that names them, before anything is
simulated, and leave an earlier output untouched (issue 34's list): an output folder that is
a file or cannot be written, non-finite durations, negative durations and periods, an empty
or partly unknown models list, counts of zero; a run whose metrics hold NumPy values (a
robot that fell) writes them; a run that fails late, or is interrupted, puts the earlier
output back byte for byte, and one that succeeds replaces it whole."""

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from apps import benchmark, contact_localization, push_and_comply, residual_comparison, standing
from apps.runner import (
    json_text,
    non_negative_float,
    output_folder,
    positive_int,
    run_app,
    simulate,
    writable_folder,
)


def _refused(main, argv: list[str], capsys) -> str:
    """The one-line error of an app refusing ``argv``: exit code 2 from the runner or from
    argparse, no traceback; returns stderr."""
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse: "error: argument --out: ..."
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and "error:" in err
    return err


@pytest.fixture
def previous_output(tmp_path: Path) -> Path:
    """An earlier run's standing/metrics.json in ``tmp_path``."""
    folder = tmp_path / "standing"
    folder.mkdir()
    (folder / "metrics.json").write_text('{"previous": true}\n')
    return folder / "metrics.json"


def test_out_that_is_a_file_or_cannot_be_written_is_refused_before_simulating(tmp_path, capsys):
    afile = tmp_path / "a_file"
    afile.write_text("x")
    assert "is a file, not a folder" in _refused(standing.main, ["--out", str(afile), "--no-replay"], capsys)
    assert "cannot write into" in _refused(standing.main, ["--out", "/proc/no_such/out", "--no-replay"], capsys)
    assert "cannot write into" in _refused(benchmark.main, ["--out", "/proc/no_such/out"], capsys)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "standing").write_text("a file where the app's folder goes")
    err = _refused(standing.main, ["--out", str(tmp_path / "out"), "--no-replay", "--duration", "0.01"], capsys)
    assert "is a file" in err
    assert writable_folder(str(tmp_path / "new" / "folder")).is_dir()


@pytest.mark.parametrize(
    ("main", "argv", "message"),
    [
        (standing.main, ["--duration", "inf"], "duration must be finite"),
        (standing.main, ["--scenario-text", "duration: .inf"], "duration must be finite"),
        (standing.main, ["--scenario-text", "state_log_period: -1"], "state_log_period must be positive"),
        (standing.main, ["--scenario-text", "models: []"], "models list is empty"),
        (standing.main, ["--scenario-text", "models: [hrp4_like, no_such_robot]"], "no_such_robot"),
        (residual_comparison.main, ["--duration", "inf"], "duration must be finite"),
        (push_and_comply.main, ["--scenario-text", "duration: .inf"], "duration must be finite"),
        (push_and_comply.main, ["--scenario-text", "push_end: .nan"], "push_end must be finite"),
        (contact_localization.main, ["--no-contact-duration", "-5"], "--no-contact-duration: must be finite and >= 0"),
        (contact_localization.main, ["--scenario-text", "slow_motion_duration: -1"], "slow_motion_duration must be"),
        (contact_localization.main, ["--workers", "0"], "--workers: must be finite and > 0"),
        (benchmark.main, ["--calls", "0"], "--calls: must be finite and > 0"),
        (benchmark.main, ["--log-seconds", "nan"], "--log-seconds: must be finite"),
    ],
)
def test_bad_values_are_refused_naming_them_and_leave_the_earlier_output(
    main, argv, message, tmp_path, previous_output, capsys
):
    err = _refused(main, [*argv, "--out", str(tmp_path)], capsys)
    assert message in err, err
    assert previous_output.read_text() == '{"previous": true}\n'
    assert sorted(p.name for p in previous_output.parent.iterdir()) == ["metrics.json"]


def test_option_types_name_the_rule():
    assert positive_int("3") == 3 and non_negative_float("0") == 0.0
    for bad in ("0", "-1", "x", "1.5"):
        with pytest.raises(Exception, match="must be|expected"):
            positive_int(bad)
    for bad in ("inf", "nan", "-0.1"):
        with pytest.raises(Exception, match="must be finite"):
            non_negative_float(bad)


def test_metrics_with_numpy_values_are_written_as_json(tmp_path):
    """What a standing run of a robot that fell returns (NumPy bools among the metrics)."""
    row = {"fell": np.bool_(True), "feet_flat": np.bool_(False), "drift": np.float64(1.5), "n": np.int64(3)}
    row["trace"] = np.array([1.0, math.nan])
    data = json.loads(json_text(row))
    assert data == {"fell": True, "feet_flat": False, "drift": 1.5, "n": 3, "trace": [1.0, data["trace"][1]]}
    assert data["fell"] is True and math.isnan(data["trace"][1])
    with pytest.raises(TypeError, match="object is not JSON serializable"):
        json_text({"x": object()})


def test_os_errors_and_non_finite_durations_are_one_line_errors(capsys):
    def unwritable():
        raise PermissionError(13, "Permission denied", "/read-only/metrics.json")

    assert run_app("example", unwritable) == 2
    assert "example: error: Permission denied '/read-only/metrics.json'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="positive and finite"):
        simulate(None, math.inf)


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("failure", [ValueError("bad input found late"), OSError(28, "No space left on device")])
def test_a_run_that_fails_leaves_the_earlier_output_byte_identical(tmp_path, failure, capsys):
    args = argparse.Namespace(out=tmp_path)
    earlier = tmp_path / "example"
    earlier.mkdir()
    (earlier / "metrics.json").write_text('{"earlier": 1}')
    (earlier / "plot.png").write_bytes(b"\x89PNG earlier")
    before = _snapshot(tmp_path)

    def body():
        folder = output_folder(args, "example")
        assert not (folder / "metrics.json").exists()  # a run starts from an empty folder
        (folder / "metrics.json").write_text('{"half": "written"}')
        raise failure

    assert run_app("example", body) == 2
    assert "example: error:" in capsys.readouterr().err
    assert _snapshot(tmp_path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["example"]  # nothing left aside


def test_an_interrupted_run_puts_the_earlier_output_back(tmp_path):
    args = argparse.Namespace(out=tmp_path)
    (tmp_path / "example").mkdir()
    (tmp_path / "example" / "metrics.json").write_text("earlier")

    def body():
        (output_folder(args, "example") / "metrics.json").write_text("partial")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_app("example", body)
    assert (tmp_path / "example" / "metrics.json").read_text() == "earlier"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["example"]


@pytest.mark.parametrize("code", [0, 1])
def test_a_run_that_reports_replaces_the_earlier_output_whole(tmp_path, code):
    """Exit 0, or 1 (it ran and reports a failure, e.g. a robot that fell): the folder holds
    this run's files only."""
    args = argparse.Namespace(out=tmp_path)
    (tmp_path / "example").mkdir()
    (tmp_path / "example" / "stale.json").write_text("from an earlier run")

    def body():
        (output_folder(args, "example") / "metrics.json").write_text("new")
        return code

    assert run_app("example", body) == code
    assert _snapshot(tmp_path) == {"example/metrics.json": b"new"}


@pytest.mark.parametrize(
    ("main", "schema_path", "argv", "field", "value"),
    [
        (standing.main, "diagrams.station.standing.StandingScenario", ["--duration", "3"], "duration", 3.0),
        (
            push_and_comply.main,
            "diagrams.residuals.push_and_comply.PushAndComplyScenario",
            ["--scenario-text", "push_peak_force: 5.0", "--seed", "4"],
            "push_peak_force",
            5.0,
        ),
    ],
)
def test_print_scenario_writes_the_scenario_the_command_would_run(main, schema_path, argv, field, value, capsys):
    """``--print-scenario`` prints every field after the scenario options and exits 0,
    without simulating: the text loads back into the same scenario."""
    import importlib

    from diagrams.scenarios import load_scenario, scenario_as_dict

    module, _, name = schema_path.rpartition(".")
    schema = getattr(importlib.import_module(module), name)
    with pytest.raises(SystemExit) as stop:
        main(["--print-scenario", *argv])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    scenario = load_scenario(schema, text=text)
    assert getattr(scenario, field) == value
    assert scenario_as_dict(scenario) != scenario_as_dict(schema())  # the options are in it
    assert text.startswith(f"# A scenario of {schema_path}")
