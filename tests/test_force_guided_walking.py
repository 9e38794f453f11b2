"""Force-guided walking (systems.observer.force_guided_walking): the trigger of eq. G-1 on hand-made
force sequences, the closing-step rule, and the controller alone (no plant simulation) on a
prescribed force: it starts one debounce after the threshold, stops with the step after the
one in progress, and its joint targets stay continuous across the switches."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from diagrams.station.standing import default_gains
from models import add_humanoid, set_standing_state
from systems.locomotion.walking_pattern import Footstep
from systems.observer.force_guided_walking import (
    STANDING,
    STOPPING,
    WALKING,
    ForceGuidedWalkingController,
    ForceTrigger,
    TriggerParameters,
    stop_step,
)


def _run_trigger(trigger: ForceTrigger, times, forces, walking_direction=None):
    """Feeds (t, F) samples; direction follows the events unless ``walking_direction`` is
    forced. Returns [(t, event)]."""
    memory, direction, events = ForceTrigger.initial_memory(), 0, []
    for t, f in zip(times, forces):
        d = direction if walking_direction is None else walking_direction
        memory, event = trigger.update(memory, t, f, d)
        if event:
            events.append((round(t, 6), event))
            direction = event if event in (1, -1) else 0
    return events


def test_trigger_starts_after_the_debounce_and_stops_below_the_threshold():
    trigger = ForceTrigger(TriggerParameters(threshold=2.0, start_debounce=0.1, stop_debounce=0.05))
    t = np.round(np.arange(0.0, 3.0, 0.01), 6)
    f = np.where((t >= 0.5) & (t < 2.0), 3.0, 0.5)
    events = _run_trigger(trigger, t, f)
    # Above from 0.50 s: start at 0.60 s (0.1 s debounce); below from 2.00 s: stop at 2.05 s.
    assert events == [(0.6, 1), (2.05, 2)]


def test_trigger_ignores_short_spikes_and_restarts_the_debounce_on_a_sign_flip():
    trigger = ForceTrigger(TriggerParameters(threshold=2.0, start_debounce=0.1, stop_debounce=0.05))
    t = np.round(np.arange(0.0, 1.0, 0.01), 6)
    f = np.zeros_like(t)
    f[(t >= 0.1) & (t < 0.18)] = 5.0  # 80 ms spike: no start
    f[(t >= 0.3) & (t < 0.35)] = 5.0  # then the sign flips: the debounce restarts at 0.35 s
    f[(t >= 0.35) & (t < 0.9)] = -5.0
    # Start backwards at 0.45 s; the force ends at 0.90 s: stop 0.05 s later.
    assert _run_trigger(trigger, t, f) == [(0.45, -1), (0.95, 2)]


def test_trigger_stops_on_a_reversed_force_and_only_while_walking():
    trigger = ForceTrigger(TriggerParameters(threshold=2.0, start_debounce=0.0, stop_debounce=0.0))
    memory = ForceTrigger.initial_memory()
    memory, event = trigger.update(memory, 0.0, 5.0, 1)  # walking forwards, pulled forwards
    assert event == 0
    memory, event = trigger.update(memory, 0.01, -5.0, 1)  # pushed backwards: stop first
    assert event == 2
    memory, event = trigger.update(ForceTrigger.initial_memory(), 0.0, 0.0, 0)  # standing, no force
    assert event == 0
    with pytest.raises(ValueError, match="finite"):
        trigger.update(memory, 0.0, math.nan, 0)
    with pytest.raises(ValueError, match="direction"):
        trigger.update(memory, 0.0, 1.0, 2)
    with pytest.raises(ValueError, match="threshold"):
        TriggerParameters(threshold=0.0)
    with pytest.raises(ValueError, match="stop_debounce"):
        TriggerParameters(stop_debounce=-0.1)


def test_closing_step_is_the_one_after_the_step_in_progress():
    steps = [
        Footstep(
            side="right",
            start=np.zeros(3),
            end=np.zeros(3),
            support_position=np.zeros(3),
            t_start=0.2 + 0.5 * j,
            t_lift=0.35 + 0.5 * j,
            t_land=0.7 + 0.5 * j,
            swing_height=0.02,
        )
        for j in range(6)
    ]
    assert stop_step(steps, 0.1) == 1  # before the first step: step 1 closes (a step in place)
    assert stop_step(steps, 0.2) == 2  # step 1 has begun
    assert stop_step(steps, 0.69) == 2
    assert stop_step(steps, 1.25) == 4  # step 3 (1.2-1.7 s) in progress


class _ForceSchedule(LeafSystem):
    """F_x(t) = magnitude on [t_on, t_off), else 0, as a (3) vector."""

    def __init__(self, magnitude: float, t_on: float, t_off: float):
        super().__init__()
        self._m, self._on, self._off = magnitude, t_on, t_off
        self.DeclareVectorOutputPort("force", 3, self._Calc)

    def _Calc(self, context, output):
        t = context.get_time()
        output.SetFromVector([self._m if self._on <= t < self._off else 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def controller_run():
    plant = MultibodyPlant(1e-3)
    humanoid = add_humanoid(plant, "nao_like")
    plant.Finalize()
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, humanoid)
    kp, _ = default_gains(plant, humanoid)
    builder = DiagramBuilder()
    dut = builder.AddSystem(
        ForceGuidedWalkingController(
            plant,
            humanoid,
            trigger=TriggerParameters(threshold=2.0, start_debounce=0.1, stop_debounce=0.05),
            initial_positions=plant.GetPositions(context),
            joint_stiffness=kp,
            max_steps=12,
        )
    )
    source = builder.AddSystem(_ForceSchedule(4.0, 1.5, 3.33))
    builder.Connect(source.get_output_port(), dut.GetInputPort("force_estimate"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    ctx = dut.GetMyContextFromRoot(root)
    samples = []
    simulator.Initialize()
    for k in range(1, 701):
        simulator.AdvanceTo(k * 0.01)
        samples.append(
            (
                k * 0.01,
                dut.GetOutputPort("walking_state").Eval(ctx).copy(),
                dut.GetOutputPort("desired_position").Eval(ctx).copy(),
                dut.GetOutputPort("sole_targets").Eval(ctx).copy(),
            )
        )
    return dut, samples


def test_controller_starts_one_debounce_after_the_threshold(controller_run):
    dut, samples = controller_run
    starts = [(t, d) for t, name, d in dut.events if name == "start"]
    assert len(starts) == 1
    t_start, detail = starts[0]
    assert detail["direction"] == 1
    # The force is on from 1.50 s; the 0.1 s debounce and the 10 ms update period.
    assert 1.6 - 1e-9 <= t_start <= 1.61 + 1e-9
    mode_at = {round(t, 2): s for t, s, _, _ in samples}
    assert mode_at[1.5][0] == STANDING and mode_at[1.7][0] == WALKING and mode_at[1.7][1] == 1


def test_controller_finishes_the_step_in_progress_then_closes(controller_run):
    dut, samples = controller_run
    stops = [(t, d) for t, name, d in dut.events if name == "stop"]
    assert len(stops) == 1
    t_stop, detail = stops[0]
    assert 3.38 - 1e-9 <= t_stop <= 3.39 + 1e-9  # below from 3.33 s + 0.05 s debounce
    params = dut.walking_parameters
    t0 = next(t for t, name, _ in dut.events if name == "start")
    elapsed = t_stop - t0
    in_progress = int((elapsed - params.initial_wait) // params.step_duration) + 1
    assert detail["closing_step"] == in_progress + 1
    assert detail["variant"] and detail["com_difference_at_switch_m"] < 0.005
    # After the closing step the soles stand side by side and stay there.
    soles = np.array([s[3] for s in samples])
    times = np.array([s[0] for s in samples])
    last_land = t0 + params.initial_wait + detail["closing_step"] * params.step_duration
    after = times > last_land + 0.05
    assert np.ptp(soles[after], axis=0).max() < 1e-9
    assert abs(soles[after][-1][0] - soles[after][-1][3]) < 1e-9  # same x: the stance is closed
    assert soles[-1][0] > 0.1  # it walked forwards
    mode_at = {round(t, 2): s for t, s, _, _ in samples}
    assert mode_at[round(t_stop + 0.1, 2)][0] == STOPPING and mode_at[7.0][0] == STANDING


def test_joint_targets_are_continuous_across_the_switches(controller_run):
    dut, samples = controller_run
    times = np.array([s[0] for s in samples])
    q = np.array([s[2] for s in samples])
    change = np.abs(np.diff(q, axis=0)).max(axis=1)  # largest joint change per 10 ms
    # The plans' own largest change per 10 ms (walking: the swing legs move fastest).
    own = 0.0
    for plan in dut.plans:
        grid = np.arange(0.0, plan.duration, 0.01)
        values = np.array([plan.sample(plan.q, t) for t in grid])
        own = max(own, float(np.abs(np.diff(values, axis=0)).max()))
    # Crossing from standing to the segment, and the cross-fade of eq. G-2 to the stop
    # variant, add no jump beyond what the plans themselves do.
    assert change.max() <= 1.05 * own
    # The start: the standing hold just before t_0 is the segment's first sample.
    t0 = next(t for t, name, _ in dut.events if name == "start")
    k = int(np.searchsorted(times, t0 - 1e-9)) - 1
    assert times[k] < t0
    np.testing.assert_allclose(q[k], dut.plans[1].q[0], atol=1e-9)


def test_bad_controller_parameters_are_refused():
    plant = MultibodyPlant(1e-3)
    humanoid = add_humanoid(plant, "nao_like")
    plant.Finalize()
    q0 = plant.GetPositions(plant.CreateDefaultContext())
    with pytest.raises(ValueError, match="max_steps"):
        ForceGuidedWalkingController(plant, humanoid, initial_positions=q0, max_steps=1)
    with pytest.raises(ValueError, match="max_lean"):
        ForceGuidedWalkingController(plant, humanoid, initial_positions=q0, max_lean=0.1)


@pytest.mark.slow
def test_app_guided_by_the_hands_starts_and_stops_at_the_threshold(tmp_path):
    """The closed loop (apps.nao_force_guided_walk, defaults, seed 1, ~9 s wall): 3 N pull
    on the hands 1.5-5.5 s, 3 N push 7.5-10.5 s, threshold 1.5 N on the arm joints' estimate
    of the hands' force (eqs. 25-27). Asserted for both episodes: the floors (start <= 0.5 s
    after the applied force crosses the threshold, <= 1 step begun after it drops), the
    direction and extent of the walk, no false start and no fall; and the joint-level
    estimate's accuracy while walking (measured: std 0.03 N, max |error| 0.08 N), far from
    the 1.5 N threshold. Seed 1 was the seed on which the observer-triggered backward stop
    missed the floor (3 steps begun)."""
    import json

    from apps import nao_force_guided_walk

    assert nao_force_guided_walk.main(["--out", str(tmp_path), "--headless", "--no-replay", "--seed", "1"]) == 0
    out = tmp_path / "nao_force_guided_walk"
    m = json.loads((out / "metrics.json").read_text())
    assert m["trigger_source"] == "joint" and m["force_N"] == 3.0
    forward, backward = m["episodes"]
    assert forward["direction"] == 1 and backward["direction"] == -1
    for episode in (forward, backward):
        assert episode["start_latency_s"] <= 0.5
        assert episode["stop_decision_latency_s"] is not None and episode["stop_decision_latency_s"] <= 0.3
        assert episode["steps_begun_after_drop"] <= 1
        assert episode["start_ok"] and episode["stop_ok"]
    assert forward["com_x_displacement_m"] > 0.3  # ~8 steps of 5 cm while pulled
    assert backward["com_x_displacement_m"] < -0.2  # ~6 steps of 5 cm while pushed
    assert m["false_starts_s"] == []
    assert not m["fell"] and m["meets_floors"]
    for case in ("joint_pushed", "joint_no_force"):
        error = m["estimate_errors_while_walking"][case]
        assert error["samples"] > 100 and abs(error["mean_N"]) < 0.2 and error["max_abs_N"] < 0.5
    assert (out / "guided.png").stat().st_size > 20_000


@pytest.mark.slow
def test_app_without_force_does_not_start(tmp_path):
    """``--force 0``: the same 12.7 s with nothing on the hands (seed 2): the robot crouches
    and stands; no start decision (false start) and no fall."""
    import json

    from apps import nao_force_guided_walk

    assert (
        nao_force_guided_walk.main(["--out", str(tmp_path), "--headless", "--no-replay", "--seed", "2", "--force", "0"])
        == 0
    )
    out = tmp_path / "nao_force_guided_walk"
    m = json.loads((out / "metrics.json").read_text())
    assert m["episodes"] == [] and m["false_starts_s"] == []
    assert not [e for e in m["events"] if e[1] == "start"]
    assert not m["fell"] and m["meets_floors"]


def test_app_refuses_an_unknown_trigger_source():
    from diagrams.observer.nao_force_guided_walk import NaoForceGuidedWalkScenario, build_force_guided_diagram

    with pytest.raises(ValueError, match="trigger_source"):
        build_force_guided_diagram(NaoForceGuidedWalkScenario(trigger_source="fsr"))


def test_scenario_file_text_and_unknown_keys(tmp_path, capsys):
    """apps/scenarios/nao_force_guided_walk_default.yaml lists every field at its default
    (the scenario convention, ``tests/scenario_checks.py``); YAML text overrides nested
    fields; an unknown nested key is an error that names it; the app refuses a force below
    the threshold."""
    from scenario_checks import SCENARIOS, check_scenario_convention

    from apps import nao_force_guided_walk
    from diagrams.observer.nao_force_guided_walk import NaoForceGuidedWalkScenario
    from diagrams.scenarios import ScenarioError, load_scenario

    check_scenario_convention(NaoForceGuidedWalkScenario, "nao_force_guided_walk_default.yaml", tmp_path)
    path = SCENARIOS / "nao_force_guided_walk_default.yaml"
    scenario = load_scenario(
        NaoForceGuidedWalkScenario, filename=path, text="trigger: {threshold: 1.0}\nepisodes: [[1.0, 3.0, -1.0]]"
    )
    assert scenario.trigger.threshold == 1.0 and scenario.trigger.stop_debounce == 0.05
    assert scenario.profile().plateaus == ((1.0, 3.0, -3.0),)
    with pytest.raises(ScenarioError, match="treshold"):
        load_scenario(NaoForceGuidedWalkScenario, text="trigger: {treshold: 1.0}")
    assert nao_force_guided_walk.main(["--no-replay", "--force", "1.0"]) == 2
    assert "threshold" in capsys.readouterr().err
