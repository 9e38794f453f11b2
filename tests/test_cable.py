"""PulleyLoad: the cable-and-mass pull of Hawley et al. Experiment 4, checked against statics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.multibody.plant import ExternallyAppliedSpatialForceMultiplexer, MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from models import add_humanoid, set_standing_state
from systems.simulation.cable import PulleyLoad

G = 9.81


@pytest.fixture(scope="module")
def nao():
    plant = MultibodyPlant(1e-3)
    handles = add_humanoid(plant, "nao_like")
    plant.Finalize()
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    return plant, plant.GetPositionsAndVelocities(context)


def _attachment(plant, x, p_BA):
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, x)
    return plant.EvalBodyPoseInWorld(context, plant.GetBodyByName("torso")).multiply(p_BA)


def _run_alone(load: PulleyLoad, x: np.ndarray, seconds: float):
    context = load.CreateDefaultContext()
    load.GetInputPort("state").FixValue(context, x)
    simulator = Simulator(load, context)
    simulator.Initialize()
    simulator.AdvanceTo(seconds)
    out = {
        name: load.GetOutputPort(name).Eval(context).copy()
        for name in ("force_world", "point_world", "tension", "load_height")
    }
    return out


def test_slack_cable_pulls_nothing_and_the_load_stays_down(nao):
    plant, x = nao
    p_BA = np.array([-0.05, 0.0, -0.06])
    A = _attachment(plant, x, p_BA)
    pulley = A + np.array([-0.5, 0.0, 0.0])
    load = PulleyLoad(plant, "torso", p_BA, pulley, cable_length=0.5 + pulley[2] + 0.05)
    out = _run_alone(load, x, 0.5)
    assert out["tension"][0] == 0.0 and out["load_height"][0] == 0.0
    np.testing.assert_array_equal(out["force_world"], np.zeros(3))
    np.testing.assert_allclose(out["point_world"], A, atol=1e-12)


def _walk_away(load: PulleyLoad, plant, x: np.ndarray, distance: float, walk_time: float, seconds: float):
    """Runs the load alone while the robot's base moves forward (+x) by ``distance`` m over
    ``walk_time`` s (smoothly), then stands; returns the outputs at ``seconds`` and the last state."""
    context = load.CreateDefaultContext()
    port = load.GetInputPort("state").FixValue(context, x)
    simulator = Simulator(load, context)
    simulator.Initialize()
    moved = x.copy()
    for i in range(1, round(seconds / 1e-3) + 1):
        s = min(i * 1e-3 / walk_time, 1.0)
        moved[4] = x[4] + distance * (3 * s * s - 2 * s * s * s)
        port.GetMutableData().set_value(moved)
        simulator.AdvanceTo(i * 1e-3)
    out = {
        name: load.GetOutputPort(name).Eval(context).copy()
        for name in ("force_world", "point_world", "tension", "load_height")
    }
    return out, moved


def test_walking_away_lifts_the_load_to_its_static_equilibrium(nao):
    """The line tightens as the robot moves away, the load lifts, and hanging at rest
    T = m0 g while the line's stretch m0 g / k sets its height."""
    plant, x = nao
    p_BA = np.array([-0.05, 0.0, -0.06])
    A = _attachment(plant, x, p_BA)
    alpha = math.radians(5.0)
    pulley = A + 0.5 * np.array([-math.cos(alpha), -math.sin(alpha), 0.0])
    L0 = float(np.linalg.norm(pulley - A)) + pulley[2] + 0.01  # 1 cm of slack at the start
    m0, k = 0.3, 2000.0
    load = PulleyLoad(plant, "torso", p_BA, pulley, load_mass=m0, cable_length=L0, stiffness=k, damping=5.0)
    out, moved = _walk_away(load, plant, x, distance=0.05, walk_time=1.0, seconds=3.0)
    A_end = _attachment(plant, moved, p_BA)
    d = float(np.linalg.norm(pulley - A_end))
    assert out["tension"][0] == pytest.approx(m0 * G, rel=1e-4)
    assert out["load_height"][0] == pytest.approx(d + pulley[2] - L0 - m0 * G / k, abs=1e-5)
    assert out["load_height"][0] > 0.035  # about 4 cm of the 5 cm walked
    u = (pulley - A_end) / d
    np.testing.assert_allclose(out["force_world"], m0 * G * u, rtol=1e-4, atol=1e-6)
    # The paper's setup: about 3 N backwards, about 5 deg from the x axis.
    assert np.linalg.norm(out["force_world"]) == pytest.approx(2.94, abs=0.01)
    angle = math.degrees(math.atan2(-out["force_world"][1], -out["force_world"][0]))
    assert angle == pytest.approx(
        math.degrees(math.atan2(0.5 * math.sin(alpha), 0.5 * math.cos(alpha) + 0.05)), abs=1e-3
    )


def test_undamped_hanging_load_oscillates_at_the_line_frequency(nao):
    """Without damping a hanging load released 1 mm above its equilibrium bobs on the line
    at sqrt(k / m0), the line staying taut (1 mm < the static stretch m0 g / k = 1.5 mm)."""
    plant, x = nao
    p_BA = np.zeros(3)
    A = _attachment(plant, x, p_BA)
    pulley = A + np.array([-0.4, 0.0, 0.0])
    m0, k = 0.3, 2000.0
    L0 = 0.4 + pulley[2] - 0.02
    load = PulleyLoad(plant, "torso", p_BA, pulley, load_mass=m0, cable_length=L0, stiffness=k, damping=0.0)
    context = load.CreateDefaultContext()
    load.GetInputPort("state").FixValue(context, x)
    simulator = Simulator(load, context)
    simulator.Initialize()
    equilibrium = 0.02 - m0 * G / k
    context.SetDiscreteState(0, [equilibrium + 0.001, 0.0])  # group 0: the load [z0, z0dot]
    heights = []
    for i in range(1, 601):
        simulator.AdvanceTo(i * 1e-3)
        heights.append(load.GetOutputPort("load_height").Eval(context)[0])
    heights = np.array(heights)
    assert heights.min() > equilibrium - 0.0011 and heights.max() < equilibrium + 0.0011
    crossings = np.flatnonzero((heights[:-1] < equilibrium) & (heights[1:] >= equilibrium))
    measured_period = np.diff(crossings).mean() * 1e-3
    assert measured_period == pytest.approx(2 * math.pi * math.sqrt(m0 / k), rel=0.03)


def test_bad_parameters_are_refused(nao):
    plant, _ = nao
    kwargs = dict(cable_length=1.0)
    with pytest.raises(ValueError, match="no body named 'pelvis'"):
        PulleyLoad(plant, "pelvis", np.zeros(3), [-1, 0, 0.3], **kwargs)
    with pytest.raises(ValueError, match="p_BA must be 3 finite"):
        PulleyLoad(plant, "torso", [0, np.nan, 0], [-1, 0, 0.3], **kwargs)
    with pytest.raises(ValueError, match="load_mass must be positive"):
        PulleyLoad(plant, "torso", np.zeros(3), [-1, 0, 0.3], load_mass=0.0, **kwargs)
    with pytest.raises(ValueError, match="resolve the line's vibration"):
        PulleyLoad(plant, "torso", np.zeros(3), [-1, 0, 0.3], stiffness=1e7, **kwargs)
    with pytest.raises(ValueError, match="above the ground"):
        PulleyLoad(plant, "torso", np.zeros(3), [-1, 0, 0.0], **kwargs)
    load = PulleyLoad(plant, "torso", np.zeros(3), [-1, 0, 0.3], **kwargs)
    context = load.CreateDefaultContext()
    bad = np.zeros(plant.num_positions() + plant.num_velocities())
    bad[3] = np.nan
    load.GetInputPort("state").FixValue(context, bad)
    with pytest.raises(ValueError, match="PulleyLoad: input 'state' has NaN"):
        Simulator(load, context).Initialize()


def test_pulls_a_standing_robot_in_a_diagram():
    """Wired with the plant (through a force multiplexer): no algebraic loop, the load is
    lifted and hangs at m0 g while the position-controlled robot stands."""
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model="nao_like", noise=False))
    plant = station.plant
    builder.Connect(builder.AddSystem(ConstantVectorSource(station.q_hold)).get_output_port(), station.desired_position)
    x0 = station.initial_state
    p_BA = np.array([-0.05, 0.0, -0.06])
    A = _attachment(plant, x0, p_BA)
    pulley = A + np.array([-0.5, 0.0, 0.0])
    load = builder.AddSystem(PulleyLoad(plant, "torso", p_BA, pulley, cable_length=0.5 + pulley[2] - 0.03))
    mux = builder.AddSystem(ExternallyAppliedSpatialForceMultiplexer(1))
    builder.Connect(load.GetOutputPort("applied_spatial_forces"), mux.get_input_port(0))
    builder.Connect(mux.get_output_port(), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), load.GetInputPort("state"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(1.5)
    load_context = load.GetMyContextFromRoot(context)
    assert load.GetOutputPort("load_height").Eval(load_context)[0] > 0.01
    assert load.GetOutputPort("tension").Eval(load_context)[0] == pytest.approx(0.3 * G, rel=0.05)
    base_height = plant.GetPositions(plant.GetMyContextFromRoot(context))[6]
    assert base_height == pytest.approx(x0[6], abs=0.01)  # still standing
