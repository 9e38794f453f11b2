"""The scenario convention (diagrams.scenarios) and the apps' shared runner (apps.runner), on
small scenarios and a trivial diagram."""

import dataclasses
import json

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, ZeroOrderHold

from apps.runner import (
    experiment_parser,
    finish_outputs,
    logged_signals,
    output_folder,
    run_app,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.scenarios import ScenarioError, load_scenario, scenario_as_dict, scenario_as_yaml


@dataclasses.dataclass
class _Scenario:
    seed: int = 0
    gains: dict[str, float] = dataclasses.field(default_factory=lambda: {"legs": 1.0, "arms": 2.0})
    point: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 1.0])
    plant_config: MultibodyPlantConfig = dataclasses.field(
        default_factory=lambda: MultibodyPlantConfig(time_step=1e-3, contact_model="point")
    )
    simulator_config: SimulatorConfig = dataclasses.field(default_factory=SimulatorConfig)


def test_a_scenario_is_read_in_layers_defaults_file_then_text(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("seed: 4\ngains: {arms: 5.0}\nplant_config: {time_step: 0.002}\n")
    scenario = load_scenario(
        _Scenario, filename=path, text="seed: 7\nplant_config: {discrete_contact_approximation: lagged}"
    )
    assert scenario.seed == 7  # the text wins over the file
    assert scenario.gains == {"legs": 1.0, "arms": 5.0}  # a map merges with its defaults
    assert scenario.point == [0.0, 0.0, 1.0]
    assert scenario.plant_config.time_step == 0.002  # nested Drake config: from the file
    assert scenario.plant_config.discrete_contact_approximation == "lagged"  # ... and the text
    assert scenario.plant_config.contact_model == "point"  # ... the rest kept


def test_bad_scenarios_are_errors_that_name_the_problem(tmp_path):
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(_Scenario, filename=tmp_path / "missing.yaml")
    with pytest.raises(ScenarioError, match="sed"):
        load_scenario(_Scenario, text="sed: 3")
    bad = tmp_path / "bad.yaml"
    bad.write_text("seed: [1, 2]\n")
    with pytest.raises(ScenarioError, match="bad.yaml"):
        load_scenario(_Scenario, filename=bad)
    assert issubclass(ScenarioError, ValueError)


def test_scenario_round_trips_through_yaml():
    scenario = load_scenario(_Scenario, text="seed: 3\npoint: [1.0, 2.0, 3.0]")
    data = scenario_as_dict(scenario)
    assert data["seed"] == 3 and data["point"] == [1.0, 2.0, 3.0] and data["plant_config"]["time_step"] == 1e-3
    again = load_scenario(_Scenario, text=scenario_as_yaml(scenario))
    assert scenario_as_dict(again) == data
    with pytest.raises(TypeError, match="dataclass"):
        scenario_as_dict({"seed": 3})


def test_shorthand_options_override_fields_unless_none(tmp_path):
    parser = experiment_parser("apps.example", "An example.\n\nMore.")
    args = parser.parse_args(["--scenario-text", "seed: 2", "--out", str(tmp_path), "--no-replay"])
    assert scenario_from_args(_Scenario, args, seed=None).seed == 2
    assert scenario_from_args(_Scenario, args, seed=9).seed == 9
    with pytest.raises(ScenarioError, match="no field 'speed'"):
        scenario_from_args(_Scenario, args, speed=1.0)
    folder = output_folder(args, "example")
    assert folder == tmp_path / "example" and folder.is_dir()
    finish_outputs(True)  # what run_app does at the end of a run


def test_run_app_turns_value_errors_into_a_message_and_exit_code_2(capsys):
    def body():
        raise ValueError("the robot has no floating base")

    assert run_app("example", body) == 2
    assert "example: error: the robot has no floating base" in capsys.readouterr().err
    assert run_app("example", lambda: None) == 0


def test_simulate_runs_the_diagram_for_the_duration_and_the_logs_are_read_back(tmp_path):
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource([1.0, 2.0]))
    logger = LogVectorOutput(source.get_output_port(), builder, 0.1)
    diagram = builder.Build()
    run = simulate(diagram, 1.0, simulator_config=SimulatorConfig(), label="trivial")
    assert run.context.get_time() == pytest.approx(1.0) and run.wall_time_s > 0.0 and run.real_time_factor > 0.0
    signals = logged_signals({"source": logger}, run.context, "source")
    np.testing.assert_array_equal(signals["source"][:, -1], [1.0, 2.0])
    assert signals["t"][-1] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="duration must be positive"):
        simulate(diagram, 0.0)

    path = write_metrics(tmp_path, {"value": 1.5}, _Scenario())
    written = json.loads(path.read_text())
    assert (
        written["value"] == 1.5
        and written["scenario"]["seed"] == 0
        and written["memory_allocator"]
        in (
            "tcmalloc",
            "system",
        )
    )


def test_start_simulation_sets_the_initial_state_before_initialize_and_apps_share_the_loop():
    """``diagrams.simulation.start_simulation``: the config applied, the initial state set, then
    ``Initialize`` (a logger's sample at t = 0 sees that state); ``apps.runner`` re-exports
    the loop below the apps."""
    import apps.runner
    import diagrams.simulation

    assert apps.runner.simulate is diagrams.simulation.simulate
    assert apps.runner.SimulationRun is diagrams.simulation.SimulationRun
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource([1.0, 2.0]))
    hold = builder.AddSystem(ZeroOrderHold(0.1, 2))
    builder.Connect(source.get_output_port(), hold.get_input_port())
    logger = LogVectorOutput(hold.get_output_port(), builder, 0.1)
    diagram = builder.Build()

    def set_initial_state(context):
        hold.GetMyMutableContextFromRoot(context).SetDiscreteState([5.0, 6.0])

    config = SimulatorConfig(target_realtime_rate=3.0)
    simulator = diagrams.simulation.start_simulation(
        diagram, set_initial_state=set_initial_state, simulator_config=config
    )
    assert simulator.get_target_realtime_rate() == 3.0 and simulator.get_context().get_time() == 0.0
    np.testing.assert_array_equal(logger.FindLog(simulator.get_context()).data()[:, 0], [5.0, 6.0])


def test_results_option_writes_the_metrics_with_the_command_that_ran(tmp_path, monkeypatch):
    """``--results NAME``: write_metrics also writes results/NAME.json (here redirected with
    HCO_RESULTS_DIR) with the app's command line, without the per-trial list."""
    import json

    from apps.runner import experiment_parser, write_metrics

    monkeypatch.setenv("HCO_RESULTS_DIR", str(tmp_path / "results"))
    args = experiment_parser("apps.example", "An example.").parse_args(["--results", "example", "--out", str(tmp_path)])
    assert args.command == "python -m apps.example --results example --out " + str(tmp_path)
    write_metrics(tmp_path, {"rate": np.float64(0.5), "per_trial": [1, 2]}, None, args)
    payload = json.loads((tmp_path / "results" / "example.json").read_text())
    assert payload["command"] == args.command and payload["data"]["rate"] == 0.5
    assert "per_trial" not in payload["data"]
    assert json.loads((tmp_path / "metrics.json").read_text())["per_trial"] == [1, 2]
    without = experiment_parser("apps.example", "An example.").parse_args(["--out", str(tmp_path / "b")])
    write_metrics(tmp_path / "b", {"rate": 1.0}, None, without)
    assert sorted(p.name for p in (tmp_path / "results").iterdir()) == ["example.json"]
