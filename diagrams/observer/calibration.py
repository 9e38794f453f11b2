"""Calibration runs of the Nao experiments: explicit simulations (``diagrams.simulation``)
that an app (or a test) calls before building its diagram, passing the result in. No
diagram builder simulates.

* ``settle_standing_state``: [q; v] of nao_like at rest on the ground in a posture (the
  experiments start from it, without the touch-down transient).
* ``identify_motor_constant``: K_m of eq. (27) (Hawley, Rahem, Suleiman 2019, Sec. 6.4)
  from a simulated static test; ``identified_motor_constants`` is its default run,
  cached per process, as ``build_nao_compliant_arms_diagram(motor_constants=...)`` takes it.

Both are deterministic (no noise) and cached per process (``functools.lru_cache``): a
second call with the same arguments returns the first result without simulating.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence

import numpy as np
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.observer.nao_force_observer import full_posture, nao_model, wide_stance
from diagrams.simulation import simulate
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from diagrams.station.plant_config import default_plant_config
from models import set_standing_state
from systems.common.checks import positive_number
from systems.observer.arm_compliance import NAO_ARM_CHAINS, ArmChain, MotorConstantIdentification, fit_motor_constants
from systems.simulation.disturbances import Push, PushSource, Step
from systems.simulation.pd_gravity import joint_vector_from_names


@functools.lru_cache(maxsize=8)
def _settled_state(duration: float, posture: tuple, plant_config_yaml: str, robot: str) -> tuple[float, ...]:
    plant_config = yaml_load_typed(schema=MultibodyPlantConfig, data=plant_config_yaml)
    builder = DiagramBuilder()
    station = add_humanoid_station(
        builder, StationConfig(model=nao_model(robot), plant_config=plant_config, noise=False)
    )
    plant, humanoid = station.plant, station.humanoid
    # The posture command is the controller's (the robot's model, issue 31); the simulated
    # robot is put in the same posture to start.
    model, model_humanoid = station.estimator.plant, station.estimator.humanoid
    angles = full_posture(model_humanoid, dict(posture))
    hold = builder.AddSystem(ConstantVectorSource(joint_vector_from_names(model, angles)))
    builder.Connect(hold.get_output_port(), station.desired_position)
    diagram = builder.Build()
    plant_context = plant.CreateDefaultContext()
    set_standing_state(plant, plant_context, dataclasses.replace(humanoid, nominal_posture=angles))
    start = functools.partial(station.set_initial_state, state=plant.GetPositionsAndVelocities(plant_context))
    run = simulate(diagram, duration, set_initial_state=start)
    plant_context = plant.GetMyContextFromRoot(run.context)
    return tuple(plant.GetPositionsAndVelocities(plant_context).tolist())


def settle_standing_state(
    posture: dict[str, float] | None = None,
    duration: float = 1.0,
    *,
    plant_config: MultibodyPlantConfig | None = None,
    robot: str = "nao_like",
) -> np.ndarray:
    """[q; v] of ``robot`` (one of ``NAO_ROBOTS``) after standing still for ``duration`` s in ``posture`` (overrides
    of the nominal posture) under position control, without pushes or noise: a state at
    static equilibrium on the ground (contact forces balanced, velocities ~0), so that an
    experiment and its observer start without the touch-down transient. ``plant_config``:
    the experiment's plant (default: the station's). Simulates once per (posture,
    duration, plant config) and process (cached); returns a fresh array.

    Raises:
        ValueError: a non-positive or non-finite duration, an unknown joint in ``posture``.
    """
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be positive, got {duration}")
    config_yaml = yaml_dump_typed(default_plant_config() if plant_config is None else plant_config)
    return np.array(_settled_state(float(duration), tuple(sorted((posture or {}).items())), config_yaml, robot))


def identify_motor_constant(
    loads: Sequence[Sequence[float]] = ((-2.0, 0.0, 0.0), (0.0, 1.5, 0.0), (0.0, 0.0, -2.0)),
    *,
    chains: Sequence[ArmChain] = NAO_ARM_CHAINS,
    load_point: Sequence[float] = (0.02, 0.02, 0.02),
    hold: float = 1.5,
    window: float = 0.5,
) -> MotorConstantIdentification:
    """Identifies K_m of eq. (27) on the simulated nao_like (station, no noise) by a static
    test: it stands in the nominal posture (wide stance, from ``settle_standing_state``)
    while known forces ``loads`` (N, world; each applied to every hand at ``load_point`` in
    the hand body's frame, m) are applied one after the other, each held ``hold`` s; the
    mean sensed state (the station's encoders and base estimate, noise-free: what a
    calibration log of the robot records) over the last ``window`` s of each hold goes to
    ``systems.observer.arm_compliance.fit_motor_constants`` (K_m e = -J^T F at rest, least
    squares per joint) on the robot's model (the station's estimators' plant). The point
    is offset from the gripper origin so that the wrist yaw carries torque too. In this
    simulator K_m recovers the PD's proportional gain K_p (5 N m/rad for the arms, 2 for
    the wrists); on a real Nao it would lump motor, gearbox and servo-loop constants. Simulates ~5 s (~3 s wall).

    Raises:
        ValueError: fewer than one load, a non-finite load, bad durations, unknown chains,
            or a joint that no load moves.
    """
    loads = np.asarray(loads, dtype=float)
    if loads.ndim != 2 or loads.shape[1] != 3 or len(loads) < 1 or not np.all(np.isfinite(loads)):
        raise ValueError("identify_motor_constant: loads must be a list of finite 3-vectors")
    hold = positive_number(hold, "identify_motor_constant: hold")
    window = positive_number(window, "identify_motor_constant: window")
    if window >= hold:
        raise ValueError("identify_motor_constant: window must be shorter than hold")
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model="nao_like", noise=False))
    # The simulated robot (plant and the known loads; the log is of its sensors) and the
    # robot's model (the estimators' plant: the posture command and the fit, issue 31).
    plant, model = station.plant, station.estimator.plant
    for chain in chains:
        if not model.HasBodyNamed(chain.hand_body):
            raise ValueError(f"identify_motor_constant: unknown hand body {chain.hand_body!r}")
    posture = wide_stance()
    q_desired = joint_vector_from_names(model, full_posture(station.estimator.humanoid, posture))
    builder.Connect(builder.AddSystem(ConstantVectorSource(q_desired)).get_output_port(), station.desired_position)
    t0 = 0.2
    pushes = []
    for i, F in enumerate(loads):
        norm = float(np.linalg.norm(F))
        if norm == 0.0:
            continue
        profile = Step(norm, t0 + i * hold, t0 + (i + 1) * hold)
        pushes += [Push(c.hand_body, tuple(load_point), F / norm, profile) for c in chains]
    source = builder.AddSystem(PushSource(plant, pushes))
    builder.Connect(source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), source.GetInputPort("state"))
    logger = LogVectorOutput(station.sensed_state, builder, 0.01)
    diagram = builder.Build()
    start = functools.partial(station.set_initial_state, state=settle_standing_state(posture))
    run = simulate(diagram, t0 + len(loads) * hold, set_initial_state=start)
    log = logger.FindLog(run.context)
    t, X = log.sample_times(), log.data().T
    rest_states = []
    for i in range(len(loads)):
        t_end = t0 + (i + 1) * hold
        inside = (t > t_end - window) & (t < t_end - 0.005)
        rest_states.append(X[inside].mean(axis=0))
    return fit_motor_constants(model, q_desired, np.array(rest_states), loads, chains=chains, load_point=load_point)


@functools.lru_cache(maxsize=1)
def motor_constant_identification() -> MotorConstantIdentification:
    """``identify_motor_constant()`` with its defaults, run once per process (~3 s wall)."""
    return identify_motor_constant()


def identified_motor_constants() -> tuple[tuple[str, float], ...]:
    """K_m of the arm joints, (name, N m/rad) pairs, from ``motor_constant_identification``
    (``dict(...)`` of it is the ``motor_constants`` argument of
    ``build_nao_compliant_arms_diagram``)."""
    return tuple(motor_constant_identification().as_dict().items())


__all__ = [
    "identified_motor_constants",
    "identify_motor_constant",
    "motor_constant_identification",
    "settle_standing_state",
]
