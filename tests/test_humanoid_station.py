"""The humanoid station: one sensor reading per step, shared by the PD and the estimators."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

import systems.simulation.sensors as sensors_module
from diagrams.residuals.residual_comparison import (
    ResidualComparisonScenario,
    build_residual_comparison_diagram,
    set_initial_state,
)
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station


def _station_diagram(noise: bool):
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model="hrp4_like", noise=noise))
    hold = builder.AddSystem(ConstantVectorSource(station.q_hold))
    builder.Connect(hold.get_output_port(), station.desired_position)
    return builder.Build(), station


def test_pd_reads_the_state_at_the_start_of_each_step():
    """Without noise the held sample is exactly the plant's state when each step begins."""
    diagram, station = _station_diagram(noise=False)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.Initialize()
    plant_context = station.plant.GetMyContextFromRoot(context)
    hold_context = station.sensed_state_hold.GetMyContextFromRoot(context)
    for k in range(1, 6):
        simulator.AdvanceTo(k * 1e-3)
        held = station.sensed_state_hold.get_output_port().Eval(hold_context)
        np.testing.assert_array_equal(held, station.plant.GetPositionsAndVelocities(plant_context))


def test_sensor_chain_runs_once_per_step_with_three_residuals(monkeypatch):
    calls = []
    original = sensors_module.SensedStateAssembler._CalcState

    def counting(self, context, output):
        calls.append(context.get_time())
        original(self, context, output)

    monkeypatch.setattr(sensors_module.SensedStateAssembler, "_CalcState", counting)
    diagram, handles = build_residual_comparison_diagram(
        ResidualComparisonScenario(station=StationConfig(), duration=0.02)
    )
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_initial_state(diagram, context, handles)
    simulator.Initialize()
    simulator.AdvanceTo(0.005)
    calls.clear()
    simulator.AdvanceTo(0.015)
    # Ten steps: the PD reads the hold, the three residuals share one cached evaluation
    # (without the hold the PD's read before each plant step made it twenty).
    assert len(calls) == 10, calls


def test_pd_refuses_a_hold_that_was_never_set():
    diagram, station = _station_diagram(noise=True)
    simulator = Simulator(diagram)
    station.plant.SetPositionsAndVelocities(
        station.plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()), station.initial_state
    )  # the plant alone: the held sample stays zero
    with pytest.raises(ValueError, match="quaternion of norm 0.*set_initial_state"):
        simulator.AdvanceTo(0.002)


def test_set_initial_state_checks_the_state():
    diagram, station = _station_diagram(noise=False)
    context = diagram.CreateDefaultContext()
    with pytest.raises(ValueError, match="finite numbers"):
        station.set_initial_state(context, np.zeros(3))
    bad = station.initial_state.copy()
    bad[10] = np.nan
    with pytest.raises(ValueError, match="finite numbers"):
        station.set_initial_state(context, bad)
    crouched = station.initial_state.copy()
    crouched[-1] = 0.1
    station.set_initial_state(context, crouched)
    np.testing.assert_array_equal(
        station.sensed_state_hold.get_output_port().Eval(station.sensed_state_hold.GetMyContextFromRoot(context)),
        crouched,
    )
