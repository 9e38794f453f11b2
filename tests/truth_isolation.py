"""Checks that no estimator of a diagram sees the simulated robot (issue 31).

Two independent checks, for any diagram built on a ``HumanoidStation``:

* **By reference** (``references_to_plant``): no leaf system outside the simulation side
  (``SIMULATION_SIDE``: the plant, SceneGraph, sensors, disturbances, ground truth,
  visualization) holds the simulated plant, directly or through a frame, body or joint of it,
  in its attributes (searched recursively through objects, dataclasses and containers).
* **By behaviour** (``differing_estimators``): the diagram is built twice, once with the
  simulated robot's description as it is and once with an absurd inertia on one of its links
  (``absurd_simulated_inertias``: the simulated plant only; the estimators' plant is parsed
  from the unchanged description). Every leaf system outside the simulation side is given the
  same inputs and state in both and must compute bit for bit the same outputs and updates: a
  system that read any value of the simulated plant's parameters would differ.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Iterator

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import SpatialInertia
from pydrake.systems.framework import Context, Diagram, LeafSystem

#: Leaf systems that may see the simulated robot: the simulator, its sensors (which read
#: the true state and contacts, and add their errors), the disturbances, the ground truth and
#: the visualization. Class names.
SIMULATION_SIDE = frozenset(
    {
        # the simulator
        "MultibodyPlant",
        "SceneGraph",
        "JointFriction",
        # sensors (systems.simulation.sensors, systems.observer.fsr_sensing)
        "JointEncoders",
        "MotorTorqueSensor",
        "FootForceTorqueSensors",
        "Accelerometer",
        "Gyroscope",
        "RandomWalkBias",
        "BaseStateEstimator",
        "SensedStateAssembler",
        "FsrArray",
        # disturbances and their ground truth
        "PushSource",
        # the cable of the Nao's pulled walk (systems.simulation.cable): physics on the true
        # state, its force into the plant and its ground truth to the loggers
        "PulleyLoad",
        # Drake's merger of the disturbances' applied forces into the plant's input (its
        # output, a list of forces, also has no value comparison)
        "ExternallyAppliedSpatialForceMultiplexer",
        "VirtualForceTruth",
        "CableVirtualForceTruth",
        "ContactZmp",
        # visualization
        "MeshcatVisualizer",
        "ContactVisualizer",
        "JointEffortOverlay",
        "ForceArrows",
    }
)


def absurd_inertia(M: SpatialInertia) -> SpatialInertia:
    """A physically valid but absurd spatial inertia in place of ``M`` (about the link
    origin): 30 times the mass and the rotational inertia about the centre of mass, the
    centre of mass 5 cm away."""
    mass, com = M.get_mass(), M.get_com()
    central = M.CalcRotationalInertia().ShiftToCenterOfMass(mass, com)
    return SpatialInertia.MakeFromCentralInertia(30.0 * mass, com + np.array([0.03, -0.04, 0.0]), central * 30.0)


@contextlib.contextmanager
def absurd_simulated_inertias(monkeypatch, links: dict[str, SpatialInertia]) -> Iterator[None]:
    """While active, every station parses its *simulated* robot with ``links`` ({link name:
    M_BBo_B}) in place of the description's inertias; the estimators' plant
    (``diagrams.station.estimator_plant``) still parses the description as it is."""
    from diagrams.station import humanoid_station
    from models import add_humanoid

    def simulated_humanoid(plant, name, **kwargs):
        return add_humanoid(plant, name, link_inertias=links, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(humanoid_station, "add_humanoid", simulated_humanoid)
        yield


def leaf_systems(diagram: Diagram) -> list:
    """Every leaf system of ``diagram``, depth first."""
    out = []
    for system in diagram.GetSystems():
        if isinstance(system, Diagram):
            out += leaf_systems(system)
        else:
            out.append(system)
    return out


def estimator_side(diagram: Diagram) -> list:
    """The leaf systems outside ``SIMULATION_SIDE``."""
    return [s for s in leaf_systems(diagram) if type(s).__name__ not in SIMULATION_SIDE]


def references_to_plant(obj, plant: MultibodyPlant, path: str = "", depth: int = 8, seen=None) -> list[str]:
    """Attribute paths from ``obj`` to ``plant`` or to a multibody element of it."""
    seen = set() if seen is None else seen
    if obj is None or isinstance(obj, (str, bytes, int, float, bool, complex, np.ndarray, np.generic)):
        return []
    if id(obj) in seen or depth < 0:
        return []
    seen.add(id(obj))
    if obj is plant:
        return [path or "<self>"]
    parent = getattr(obj, "GetParentPlant", None)
    if callable(parent) and not isinstance(obj, type):
        try:
            if parent() is plant:
                return [path]
        except Exception:  # an element of no plant
            pass
    found = []
    if isinstance(obj, dict):
        for key, value in obj.items():
            found += references_to_plant(key, plant, f"{path}[{key!r}]", depth - 1, seen)
            found += references_to_plant(value, plant, f"{path}[{key!r}]", depth - 1, seen)
        return found
    if isinstance(obj, (list, tuple, set, frozenset)):
        for k, value in enumerate(obj):
            found += references_to_plant(value, plant, f"{path}[{k}]", depth - 1, seen)
        return found
    attributes = getattr(obj, "__dict__", None)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        attributes = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if isinstance(attributes, dict):
        for name, value in attributes.items():
            if name.startswith("_pydrake_internal"):  # pydrake's keep-alive links to the diagram
                continue
            found += references_to_plant(value, plant, f"{path}.{name}", depth - 1, seen)
    return found


def _values(port, context):
    value = port.Eval(context)
    return np.asarray(value) if isinstance(value, np.ndarray) else value


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    try:
        return bool(a == b) or repr(a) == repr(b)
    except Exception:
        return repr(a) == repr(b)


def system_results(system: LeafSystem, inputs: list, source: Context) -> dict:
    """The outputs and the periodic discrete update of ``system`` in a fresh context with
    ``inputs`` fixed and the state of ``source`` (a context of an identical system)."""
    context = system.CreateDefaultContext()
    context.SetTime(source.get_time())
    for k in range(context.num_discrete_state_groups()):
        context.get_mutable_discrete_state(k).SetFrom(source.get_discrete_state(k))
    for k in range(context.num_abstract_states()):
        context.get_mutable_abstract_state(k).SetFrom(source.get_abstract_state(k))
    if context.num_continuous_states():
        context.get_mutable_continuous_state_vector().SetFromVector(source.get_continuous_state_vector().CopyToVector())
    for k, value in enumerate(inputs):
        if value is not None:
            system.get_input_port(k).FixValue(context, value)
    results = {}
    for k in range(system.num_output_ports()):
        port = system.get_output_port(k)
        results[f"output {port.get_name()}"] = _values(port, context)
    if context.num_discrete_state_groups():
        try:
            update = system.EvalUniquePeriodicDiscreteUpdate(context)
            results["discrete update"] = np.concatenate(
                [update.get_vector(k).CopyToVector() for k in range(update.num_groups())]
            )
        except RuntimeError:  # no unique periodic update
            pass
    return results


def differing_estimators(
    build: Callable[[], tuple[Diagram, Context]],
    monkeypatch,
    link: str,
    simulated_plant: Callable[[Diagram], MultibodyPlant],
) -> tuple[list[str], int]:
    """Builds the diagram twice with ``build`` (returns the diagram and a root context at a
    state worth checking), the second time with an absurd inertia on the simulated robot's
    ``link``; gives every estimator-side system of the second diagram the first one's inputs
    and state, and returns (the systems, with the result, that computed anything differently;
    the number of systems compared)."""
    diagram_a, context_a = build()
    plant_a = simulated_plant(diagram_a)
    M = plant_a.GetBodyByName(link).default_spatial_inertia()
    with absurd_simulated_inertias(monkeypatch, {link: absurd_inertia(M)}):
        diagram_b, _ = build()
    plant_b = simulated_plant(diagram_b)
    assert not np.allclose(
        plant_b.GetBodyByName(link).default_spatial_inertia().CopyToFullMatrix6(), M.CopyToFullMatrix6()
    ), "the absurd inertia did not reach the simulated plant: the check would be void"
    systems_a, systems_b = estimator_side(diagram_a), estimator_side(diagram_b)
    assert [type(s) for s in systems_a] == [type(s) for s in systems_b], "the two builds differ in structure"
    differing, compared = [], 0
    for system_a, system_b in zip(systems_a, systems_b):
        source = system_a.GetMyContextFromRoot(context_a)
        inputs = []
        for k in range(system_a.num_input_ports()):
            port = system_a.get_input_port(k)
            inputs.append(port.Eval(source) if port.HasValue(source) else None)
        results_a = system_results(system_a, inputs, source)
        results_b = system_results(system_b, inputs, source)
        compared += 1
        for key, value in results_a.items():
            if not _same(value, results_b[key]):
                differing.append(f"{system_a.get_name()} ({type(system_a).__name__}): {key}")
    return differing, compared
