"""The one simulation loop of the project: the apps (through ``apps.runner``, which re-exports
it), the calibrations, the contact trials and the logs below them all simulate a diagram
with it.

* ``start_simulation``: a ``Simulator`` of the diagram with its config applied, its initial
  state set and ``Initialize`` called, for a caller that advances it itself (piecewise, or
  after a warm-up).
* ``simulate``: ``start_simulation``, then the diagram advanced to the end, with progress
  printing and a Meshcat recording if asked; returns a ``SimulationRun``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from pydrake.geometry import Meshcat
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator, SimulatorConfig
from pydrake.systems.framework import Context, Diagram


@dataclass
class SimulationRun:
    """A finished simulation: its simulator and root context (the loggers' logs are in it),
    the simulated time, s, and the wall time it took, s."""

    simulator: Simulator
    context: Context
    duration: float
    wall_time_s: float

    @property
    def real_time_factor(self) -> float:
        return self.duration / self.wall_time_s if self.wall_time_s > 0 else math.inf


def start_simulation(
    diagram: Diagram,
    *,
    set_initial_state: Callable[[Context], None] | None = None,
    simulator_config: SimulatorConfig | None = None,
) -> Simulator:
    """A ``Simulator`` of ``diagram`` at time 0, initialized: ``simulator_config`` (if given)
    applied, then ``set_initial_state(root_context)`` (if given), then ``Initialize``. The
    caller advances it (``AdvanceTo``, time in s) and reads its root context
    (``get_context``)."""
    simulator = Simulator(diagram)
    if simulator_config is not None:
        ApplySimulatorConfig(simulator_config, simulator)
    if set_initial_state is not None:
        set_initial_state(simulator.get_mutable_context())
    simulator.Initialize()
    return simulator


def simulate(
    diagram: Diagram,
    duration: float,
    *,
    set_initial_state: Callable[[Context], None] | None = None,
    simulator_config: SimulatorConfig | None = None,
    meshcat: Meshcat | None = None,
    live: bool = True,
    camera: tuple[list[float], list[float]] | None = None,
    label: str | None = None,
    progress_step: float = 0.5,
) -> SimulationRun:
    """Simulates ``diagram`` from time 0 for ``duration`` s (``start_simulation``, then
    ``AdvanceTo(duration)``).

    ``set_initial_state(root_context)`` sets the initial state before ``Initialize``. With
    ``meshcat`` the run is recorded (32 frames per second) for a replay, and shown live too
    when ``live`` (a headless run records without sending each frame to the live view); the
    recording starts before ``Initialize`` and is published at the end (the apps'
    ``save_replay`` writes it). ``camera`` is (camera_in_world, target_in_world), m. With a
    ``label`` the progress is printed every ``progress_step`` simulated seconds, then the
    wall time and the real-time factor.

    Raises:
        ValueError: a ``duration`` that is not positive and finite.
    """
    if not (duration > 0.0 and math.isfinite(duration)):
        raise ValueError(f"the simulated duration must be positive and finite, got {duration}")
    if meshcat is not None:
        meshcat.Delete()
        meshcat.DeleteRecording()

    def set_up(context: Context) -> None:
        if set_initial_state is not None:
            set_initial_state(context)
        if meshcat is not None:
            if camera is not None:
                meshcat.SetCameraPose(camera_in_world=camera[0], target_in_world=camera[1])
            meshcat.StartRecording(frames_per_second=32.0, set_visualizations_while_recording=live)

    simulator = start_simulation(diagram, set_initial_state=set_up, simulator_config=simulator_config)
    context = simulator.get_mutable_context()
    start = time.perf_counter()
    if label is None:
        simulator.AdvanceTo(duration)
    else:
        t = 0.0
        while t < duration - 1e-9:
            t = min(t + progress_step, duration)
            simulator.AdvanceTo(t)
            print(f"\r  {label:9s} {t:5.1f} / {duration:.1f} s simulated", end="", flush=True)
    wall = time.perf_counter() - start
    run = SimulationRun(simulator, context, duration, wall)
    if label is not None:
        print(f"  ({wall:.1f} s wall, real-time factor {run.real_time_factor:.2f})")
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    return run


__all__ = ["SimulationRun", "simulate", "start_simulation"]
