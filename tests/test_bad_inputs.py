"""Bad inputs to the apps are refused with one line that names them, before anything is
simulated, and leave an earlier output untouched (issue 34's list): an output folder, a
calibration cache or a results file that cannot be written, non-finite durations, negative
durations, times, seeds and periods, an empty, partly unknown or single-name models list, a
bad push schedule (before the calibration), a link of non-physical mass, counts of zero; a
robot that falls is reported (exit 1, its table and metrics.json); the false-detection floor
is not met with nothing measured; a run that fails late, or is interrupted, puts the earlier
output back byte for byte, and one that succeeds replaces it whole."""

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import models
from apps import benchmark, contact_localization, push_and_comply, residual_comparison, standing
from apps.runner import (
    calibration_cache_folder,
    json_text,
    non_negative_float,
    output_folder,
    positive_int,
    run_app,
    simulate,
    writable_folder,
)
from diagrams.residuals import model_refinement
from diagrams.residuals.contact_study import FLOORS, contact_localization_metrics
from diagrams.residuals.push_and_comply import PushAndComplyScenario
from diagrams.station.standing import StandingMetrics


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
        (standing.main, ["--scenario-text", "models: hrp4_like"], "models must be a list, got 'hrp4_like'"),
        (standing.main, ["--scenario-text", "settle_time: -1"], "settle_time must be >= 0 s"),
        (standing.main, ["--scenario-text", "plant_config: {time_step: .nan}"], "time_step must be finite"),
        (residual_comparison.main, ["--duration", "inf"], "duration must be finite"),
        (push_and_comply.main, ["--scenario-text", "duration: .inf"], "duration must be finite"),
        (push_and_comply.main, ["--scenario-text", "push_end: .nan"], "push_end must be finite"),
        (push_and_comply.main, ["--scenario-text", "push_start: -1"], "push_start must be >= 0 s"),
        (push_and_comply.main, ["--scenario-text", "station: {seed: -1}"], "seed must be a non-negative integer"),
        (contact_localization.main, ["--scenario-text", "station: {seed: -1}"], "seed must be a non-negative integer"),
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


def _description(tmp_path: Path, builtin: str, edit, name: str = "robot") -> Path:
    """A description file in ``tmp_path``: the built-in robot ``builtin``'s, renamed ``name``
    and changed by ``edit(raw)``."""
    raw = yaml.safe_load(models.description_file(builtin).read_text())
    raw["model"], raw["name"] = str(models.model_file(builtin)), name
    edit(raw)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def test_a_robot_that_falls_is_reported_with_exit_1_its_table_and_metrics(tmp_path, capsys):
    """Nao with leg and torso gains 80 times too weak falls within a second: the run exits 1,
    prints its table, and writes metrics.json with plain JSON values (issue 34: the NumPy
    bool of ``feet_flat`` crashed the report)."""
    weak = {"legs": [0.5, 0.005], "torso": [0.5, 0.005]}
    robot = _description(tmp_path, "nao_like", lambda raw: raw["gains"].update(weak), "nao_weak")
    (tmp_path / "out" / "standing").mkdir(parents=True)
    (tmp_path / "out" / "standing" / "metrics.json").write_text('{"previous": true}\n')
    argv = ["--robot", str(robot), "--duration", "1", "--scenario-text", "settle_time: 0"]
    code = standing.main([*argv, "--no-replay", "--out", str(tmp_path / "out")])
    out, err = capsys.readouterr()
    assert code == 1, err
    assert "Traceback" not in err and "FELL: nao_weak" in err
    assert "nao_weak" in out.split("fell", 1)[1]  # the table's row
    metrics = json.loads((tmp_path / "out" / "standing" / "metrics.json").read_text())
    assert metrics["nao_weak"]["fell"] is True and metrics["nao_weak"]["feet_flat"] is False
    assert json.loads((tmp_path / "out" / "standing" / "nao_weak.json").read_text())["fell"] is True


def test_standing_metrics_are_plain_python_values():
    metrics = StandingMetrics(
        0.2, 0.5, {"left": 0.4, "right": 0.0}, {"left": 0.1, "right": 0.0}, {"left": np.zeros(4)}, True
    )
    assert type(metrics.feet_flat) is bool and metrics.feet_flat is False
    assert type(metrics.min_sphere_force_N) is float


def test_an_out_folder_that_refuses_files_is_found_before_simulating(tmp_path, monkeypatch, capsys):
    """A read-only folder (simulated: root writes anywhere) is refused when the command line
    is read, with the reason."""

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr("apps.runner.tempfile.TemporaryFile", refused)
    err = _refused(standing.main, ["--out", str(tmp_path), "--no-replay"], capsys)
    assert f"cannot write into '{tmp_path}': Permission denied" in err


def test_a_calibration_cache_that_cannot_be_written_is_refused_before_calibrating(
    tmp_path, previous_output, monkeypatch, capsys
):
    def no_calibration(scenario):
        raise AssertionError("calibrated before the cache folder was checked")

    monkeypatch.setattr(model_refinement, "calibrate_model", no_calibration)
    (tmp_path / "calibration_cache").write_text("a file where the cache goes")
    with pytest.raises(ValueError, match="the calibration cache: '.*calibration_cache' is a file, not a folder"):
        calibration_cache_folder(argparse.Namespace(out=tmp_path))
    err = _refused(push_and_comply.main, ["--out", str(tmp_path)], capsys)
    assert "is a file, not a folder" in err and len(err.strip().splitlines()) == 1
    assert previous_output.read_text() == '{"previous": true}\n'
    with pytest.raises(ValueError, match="the calibration cache '.*calibration_cache' is a file, not a folder"):
        model_refinement.refined_model(PushAndComplyScenario(), tmp_path / "calibration_cache")
    with pytest.raises(ValueError, match="cannot write into the calibration cache '.*inner': Not a directory"):
        model_refinement.refined_model(PushAndComplyScenario(), tmp_path / "calibration_cache" / "inner")


def test_a_bad_push_schedule_is_refused_before_calibrating(tmp_path, previous_output, monkeypatch, capsys):
    def no_calibration(scenario):
        raise AssertionError("calibrated before the scenario was checked")

    monkeypatch.setattr(model_refinement, "calibrate_model", no_calibration)
    err = _refused(push_and_comply.main, ["--scenario-text", "push_end: 4", "--out", str(tmp_path)], capsys)
    assert "push_start < push_peak_time < push_end" in err
    assert previous_output.read_text() == '{"previous": true}\n'


def test_errors_are_one_line(tmp_path, capsys):
    """A YAML parser's message spans five lines (the echoed text and a caret): one here."""
    err = _refused(standing.main, ["--scenario-text", "[", "--out", str(tmp_path)], capsys)
    assert err.strip().splitlines() == [err.strip()]
    assert "could not read the scenario text '['" in err and "expected the node content" in err


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("<mass>nan</mass>", "mass > 0"),
        ("<mass>0</mass>", "mass > 0"),
        ("<mass>-2</mass>", "mass > 0"),
    ],
)
def test_a_robot_with_a_non_physical_link_mass_is_refused_naming_the_link(tmp_path, edit, message, capsys):
    """What the loader refuses (tests/test_robot_description.py has every case) reaches an
    app's user as one line naming the link."""
    text = models.model_file("hrp4_like").read_text()
    start = text.index("<mass>0.05</mass>", text.index('<link name="L_HAND_J1_LINK">'))
    model = tmp_path / "robot.sdf"
    model.write_text(text[:start] + edit + text[start + len("<mass>0.05</mass>") :])
    robot = _description(tmp_path, "hrp4_like", lambda raw: raw.update(model=str(model)))
    err = _refused(standing.main, ["--robot", str(robot), "--no-replay", "--out", str(tmp_path)], capsys)
    assert "link 'L_HAND_J1_LINK' has a non-physical inertia" in err and message in err
    assert len(err.strip().splitlines()) == 1


def test_the_false_detection_floor_is_not_met_without_a_run_without_contact():
    """A zero ``no_contact_duration`` skips the standing run without contact: no false
    detection was looked for there, so its floor is not judged (None), not met."""
    assert contact_localization_metrics([], None, None, FLOORS)["meets_floors"]["false_detections"] is None
    skipped = {"duration_s": 0.0, "false_detections": 0}
    assert contact_localization_metrics([], skipped, None, FLOORS)["meets_floors"]["false_detections"] is None
    run = {"duration_s": 60.0, "false_detections": 0}
    assert contact_localization_metrics([], run, None, FLOORS)["meets_floors"]["false_detections"] is True
    run["false_detections"] = 2
    assert contact_localization_metrics([], run, None, FLOORS)["meets_floors"]["false_detections"] is False


def test_a_results_file_that_cannot_be_written_is_refused_before_simulating(tmp_path, monkeypatch, capsys):
    err = _refused(standing.main, ["--results", "../elsewhere", "--out", str(tmp_path)], capsys)
    assert "argument --results: a results name is a plain file stem" in err
    (tmp_path / "a_file").write_text("x")
    monkeypatch.setenv("HCO_RESULTS_DIR", str(tmp_path / "a_file"))
    err = _refused(standing.main, ["--results", "standing", "--out", str(tmp_path)], capsys)
    assert "argument --results: '" in err and "a_file' is a file, not a folder" in err
