"""Standing diagram: a humanoid on the ground under PD + gravity compensation.

    ConstantVectorSource(q_nominal) ─► PdGravityController ─► MultibodyPlant (+ ground)
                                            ▲ state                │
                                            └──────────────────────┤─► state logger
                                                                   └─► SceneGraph ─► Meshcat (optional)

The plant is discrete (default 1 ms) with Drake's SAP solver and point contact
(``diagrams.station.plant_config.default_plant_config``); the feet touch the ground through
four small spheres each. ``make standing`` measures base drift and foot forces (docs/scenarios-and-worlds.md).

Scenarios are YAML files loaded into ``StandingScenario`` with
``pydrake.common.yaml.yaml_load_typed`` (``diagrams.scenarios``); ``standing_run_metrics``
gives a run's metrics (base drift, foot contact, fall).
"""

# No ``from __future__ import annotations``: yaml_load_typed reads the scenario's field types.

import functools
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, SceneGraph
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from diagrams.station.plant_config import check_plant_config, default_plant_config
from models import (
    MODEL_NAMES,
    HumanoidHandles,
    add_ground,
    add_humanoid,
    is_humanoid,
    point_contact_scene_graph_config,
    robot_description,
    set_standing_state,
)
from systems.common.contact_results import robot_point_contacts
from systems.simulation.contact_monitor import FirstUnexpectedContact
from systems.simulation.pd_gravity import PdGravityController, joint_vector_from_names

#: hrp4_like's PD gains per gain group: (kp [N m/rad], kd [N m s/rad]), the reference that
#: ``default_gains`` scales for a robot whose description gives no gains (the built-in
#: descriptions give theirs: models/hrp4_like.yaml, models/nao_like.yaml).
REFERENCE_GAINS = {
    "legs": (3000.0, 30.0),
    "torso": (1500.0, 20.0),
    "head": (50.0, 1.0),
    "arms": (200.0, 4.0),
    "wrists": (50.0, 1.0),
    "hands": (10.0, 0.2),
}
#: The robot whose gains and experiments the others scale from (``size_ratios``).
REFERENCE_MODEL = "hrp4_like"
#: The explicit 1 kHz PD's damping margin: kd dt / H_ii at most this (H the joint-space
#: inertia's diagonal at the standing posture, rotor inertia included).
KD_STABILITY_MARGIN = 0.3


@dataclass(slots=True)
class StandingScenario:
    """The standing experiment's settings (SI units).

    Attributes:
        models: the humanoids simulated one after the other (``models.MODEL_NAMES``).
        duration: simulated time per model, s.
        settle_time: the base drift is measured after this, s (at most ``duration``).
        state_log_period: period of the state logger, s.
        plant_config: Drake's ``MultibodyPlantConfig`` (default: 1 ms steps, point contact,
            SAP; see ``diagrams.station.plant_config``).
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``); the plant
            is discrete, so only ``target_realtime_rate`` and the publishing matter.
    """

    models: list[str] = field(default_factory=lambda: list(MODEL_NAMES))
    duration: float = 10.0
    settle_time: float = 1.0
    state_log_period: float = 0.01
    plant_config: MultibodyPlantConfig = field(default_factory=default_plant_config)
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)


@dataclass
class StandingHandles:
    """What build_standing_diagram() created.

    Attributes:
        plant: the MultibodyPlant (discrete, SAP, point contact).
        scene_graph: its SceneGraph.
        humanoid: the robot's HumanoidHandles.
        controller: the PdGravityController.
        state_logger: VectorLogSink of the plant state [q; v].
        q_desired: the constant desired joint positions (v[6:] order), rad.
        meshcat_visualizer: the MeshcatVisualizer, or None.
        first_contact: the ``FirstUnexpectedContact`` monitor of every robot collision
            geometry but the feet's contact geometries, or None (the robot has none).
        capped_gains: the joints whose default gains the stability cap lowered, {joint: (kd
            scaled, kd cap)} N m s/rad ({} with given gains).
    """

    plant: MultibodyPlant
    scene_graph: SceneGraph
    humanoid: HumanoidHandles
    controller: PdGravityController
    state_logger: VectorLogSink
    q_desired: np.ndarray
    meshcat_visualizer: MeshcatVisualizer | None = None
    first_contact: FirstUnexpectedContact | None = None
    capped_gains: dict = field(default_factory=dict)


def standing_size(plant: MultibodyPlant, humanoid: HumanoidHandles) -> tuple[float, float]:
    """(mass, kg; centre of mass height standing, m) of the humanoid in its standing state."""
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, humanoid)
    mass = plant.CalcTotalMass(context, [humanoid.model_instance])
    height = plant.CalcCenterOfMassPositionInWorld(context, [humanoid.model_instance])[2]
    return float(mass), float(height)


@functools.cache
def _reference_size() -> tuple[float, float]:
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(default_plant_config(), point_contact_scene_graph_config(), builder)
    humanoid = add_humanoid(plant, REFERENCE_MODEL)
    plant.Finalize()
    return standing_size(plant, humanoid)


def size_ratios(plant: MultibodyPlant, humanoid: HumanoidHandles) -> tuple[float, float]:
    """(m / m_ref, m h / (m_ref h_ref)): the humanoid's mass and gravitational moment (m the
    mass, h the centre of mass height standing) against ``REFERENCE_MODEL``'s, computed the
    same way (exactly 1 on the reference robot itself)."""
    mass, height = standing_size(plant, humanoid)
    reference_mass, reference_height = _reference_size()
    return mass / reference_mass, mass * height / (reference_mass * reference_height)


def default_gains(plant: MultibodyPlant, humanoid: HumanoidHandles) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint default (kp, kd) arrays in v[6:] order for a humanoid (``gains_and_caps``)."""
    kp, kd, _ = gains_and_caps(plant, humanoid)
    return kp, kd


def gains_and_caps(plant: MultibodyPlant, humanoid: HumanoidHandles) -> tuple[np.ndarray, np.ndarray, dict]:
    """Per-joint default (kp, kd) arrays in v[6:] order for a humanoid, and the joints whose
    gains the stability cap lowered: {joint: (kd scaled, kd cap)}, N m s/rad.

    The description's ``gains`` where it gives them (every built-in model gives all).
    Other groups scale hrp4_like's (``REFERENCE_GAINS``) by the robot's gravitational
    moment m g h against hrp4_like's (m the mass, h the centre of mass height standing):
    a stance leg then holds the body with about the same static angle error. kd is then
    capped at ``KD_STABILITY_MARGIN`` H_ii / dt (H the joint-space inertia at the standing
    posture, dt the plant's step), and kp with it in the same ratio, so the explicit PD
    stays stable on a light joint.
    """
    description = humanoid.description
    given = description.gains if description is not None else {}
    table = dict(given)
    missing = [g for g in REFERENCE_GAINS if g not in table]
    inertia = None
    if missing:
        _, scale = size_ratios(plant, humanoid)
        context = plant.CreateDefaultContext()
        set_standing_state(plant, context, humanoid)
        table.update({g: (scale * REFERENCE_GAINS[g][0], scale * REFERENCE_GAINS[g][1]) for g in missing})
        inertia = np.diag(plant.CalcMassMatrix(context))
    kp, kd, capped = {}, {}, {}
    dt = plant.time_step() if plant.time_step() > 0.0 else 1e-3
    for group in ("legs", "torso", "head", "arms", "hands"):
        for j in humanoid.joint_groups[group]:
            key = "wrists" if ("WRIST" in j.upper()) else group
            kp[j], kd[j] = table[key]
            if inertia is not None and key not in given:
                index = plant.GetJointByName(j, humanoid.model_instance).velocity_start()
                limit = KD_STABILITY_MARGIN * inertia[index] / dt
                if kd[j] > limit:
                    capped[j] = (float(kd[j]), float(limit))
                    kp[j], kd[j] = kp[j] * limit / kd[j], limit
    return joint_vector_from_names(plant, kp), joint_vector_from_names(plant, kd), capped


def build_standing_diagram(
    model_name: str,
    *,
    plant_config: MultibodyPlantConfig | None = None,
    meshcat: Meshcat | None = None,
    kp=None,
    kd=None,
    state_log_period: float = 0.01,
) -> tuple[Diagram, StandingHandles]:
    """Builds the standing diagram for one humanoid.

    Args:
        model_name: a built-in model (models.MODEL_NAMES) or a robot description YAML file.
        plant_config: Drake's plant configuration (default ``default_plant_config()``: 1 ms
            steps, point contact, SAP; see ``diagrams.station.plant_config``).
        meshcat: if given, a MeshcatVisualizer is added.
        kp: PD stiffness, N m/rad, scalar or per joint (v[6:] order); default per model
            (``default_gains``).
        kd: PD damping, N m s/rad, scalar or per joint; default per model.
        state_log_period: period of the state logger, s.

    Returns:
        (diagram, StandingHandles).

    Raises:
        ValueError: an unknown model, a plant configuration the station refuses.
    """
    if not is_humanoid(model_name):
        raise ValueError(
            f"unknown humanoid model {model_name!r}: give one of {MODEL_NAMES} or a robot description YAML file"
        )
    config = default_plant_config() if plant_config is None else plant_config
    check_plant_config(config)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(config, point_contact_scene_graph_config(), builder)
    humanoid = add_humanoid(plant, model_name, scene_graph=scene_graph)
    add_ground(plant)
    plant.Finalize()

    kp_default, kd_default, capped = gains_and_caps(plant, humanoid)
    if kp is not None or kd is not None:
        capped = {}
    controller = builder.AddSystem(
        PdGravityController(plant, kp_default if kp is None else kp, kd_default if kd is None else kd)
    )
    controller.set_name("pd_gravity_controller")
    q_desired = joint_vector_from_names(plant, humanoid.nominal_posture)
    source = builder.AddSystem(ConstantVectorSource(q_desired))
    source.set_name("desired_position")
    builder.Connect(source.get_output_port(), controller.GetInputPort("desired_position"))
    builder.Connect(plant.get_state_output_port(), controller.GetInputPort("state"))
    builder.Connect(controller.get_output_port(), plant.get_actuation_input_port())
    logger = LogVectorOutput(plant.get_state_output_port(), builder, state_log_period)
    logger.set_name("state_logger")
    # Every robot collision geometry but the feet's contact geometries: which touched the
    # ground first explains a fall.
    feet = {g for ids in humanoid.fsr_geometries.values() for g in ids}
    inspector = scene_graph.model_inspector()
    watched = {
        g: f"{body}/{inspector.GetName(g).split('::')[-1]}"
        for body, ids in humanoid.collision_geometries.items()
        for g in ids
        if g not in feet
    }
    monitor = None
    if watched:
        monitor = builder.AddSystem(FirstUnexpectedContact(watched, plant.time_step()))
        monitor.set_name("first_unexpected_contact")
        builder.Connect(plant.get_contact_results_output_port(), monitor.get_input_port())
    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    diagram = builder.Build()
    diagram.set_name(f"standing_{model_name}")
    return diagram, StandingHandles(
        plant, scene_graph, humanoid, controller, logger, q_desired, visualizer, monitor, capped
    )


def set_initial_state(diagram: Diagram, context: Context, handles: StandingHandles) -> None:
    """Puts the robot in its nominal posture, both soles on the ground, at rest."""
    plant_context = handles.plant.GetMyMutableContextFromRoot(context)
    set_standing_state(handles.plant, plant_context, handles.humanoid)


# ---------------------------------------------------------------------------------------
# Measurements shared by the standing test and apps.standing.
# ---------------------------------------------------------------------------------------


def foot_sphere_normal_forces(
    plant: MultibodyPlant, plant_context: Context, humanoid: HumanoidHandles
) -> dict[str, np.ndarray]:
    """Ground normal force (N, along the contact normal: world z on flat ground; the
    convention of ``systems.common.contact_results``) on each foot contact sphere, FSR order.

    Reads the plant's contact results (point contact); a sphere without contact reads 0.
    """
    results = plant.get_contact_results_output_port().Eval(plant_context)
    spheres = {g for ids in humanoid.fsr_geometries.values() for g in ids}
    contacts = robot_point_contacts(results, spheres, "foot_sphere_normal_forces")
    return {
        side: contacts.summed({g: i for i, g in enumerate(ids)}, len(ids))
        for side, ids in humanoid.fsr_geometries.items()
    }


@dataclass
class StandingMetrics:
    """Summary of a standing run (see standing_metrics())."""

    base_drift_m: float  # max |p_WB(t) - p_WB(t_settle)| for t >= t_settle, m
    base_drift_rad: float  # max rotation angle of R_WB(t_settle)^T R_WB(t), rad
    sole_tilt_rad: dict  # final angle between each sole's z and world z, rad
    sole_height_m: dict  # final height of each sole frame origin, m
    sphere_forces_N: dict  # final normal force per foot sphere, N
    fell: bool

    @property
    def min_sphere_force_N(self) -> float:
        return float(min(f.min() for f in self.sphere_forces_N.values()))

    @property
    def feet_flat(self) -> bool:
        """Both soles level (< 1 deg), on the ground (< 1 mm) and every foot sphere pressed:
        a Python bool (a NumPy bool is no JSON)."""
        return bool(
            max(self.sole_tilt_rad.values()) < np.radians(1.0)
            and max(abs(h) for h in self.sole_height_m.values()) < 1e-3
            and self.min_sphere_force_N > 0.0
        )


def standing_metrics(handles: StandingHandles, context: Context, settle_time: float = 1.0) -> StandingMetrics:
    """Base drift after ``settle_time`` from the state log, and the final foot contact."""
    plant = handles.plant
    plant_context = plant.GetMyContextFromRoot(context)
    log = handles.state_logger.FindLog(context)
    t, x = log.sample_times(), log.data()
    base = handles.humanoid.base_body
    q_start = base.floating_positions_start()
    keep = t >= settle_time - 1e-9
    quats = x[q_start : q_start + 4, keep]
    pos = x[q_start + 4 : q_start + 7, keep]
    drift_m, drift_rad = 0.0, 0.0
    if pos.shape[1] > 0:
        drift_m = float(np.max(np.linalg.norm(pos - pos[:, :1], axis=0)))
        q0 = quats[:, 0] / np.linalg.norm(quats[:, 0])
        dots = np.abs(q0 @ (quats / np.linalg.norm(quats, axis=0)))
        drift_rad = float(np.max(2.0 * np.arccos(np.clip(dots, -1.0, 1.0))))
    tilt, height = {}, {}
    for side, frame in handles.humanoid.sole_frames.items():
        X = frame.CalcPoseInWorld(plant_context)
        tilt[side] = float(np.arccos(np.clip(X.rotation().matrix()[2, 2], -1.0, 1.0)))
        height[side] = float(X.translation()[2])
    forces = foot_sphere_normal_forces(plant, plant_context, handles.humanoid)
    z_base = plant.EvalBodyPoseInWorld(plant_context, base).translation()[2]
    z_base0 = x[q_start + 6, 0] if x.shape[1] else z_base
    fell = bool(z_base < 0.7 * z_base0 or drift_m > 0.10 or drift_rad > np.radians(20))
    return StandingMetrics(drift_m, drift_rad, tilt, height, forces, fell)


def check_standing_scenario(scenario: StandingScenario) -> None:
    """Checks what ``diagrams.scenarios.check_finite_and_signs`` does not, before anything is
    simulated: ``models`` is a non-empty list whose every entry is a readable robot (a built-in
    name or a description file, ``models.robot_description``).

    Raises:
        ValueError: the first bad field, named (a bad robot: its description's error).
    """
    models = scenario.models
    if not isinstance(models, list) or not all(isinstance(name, str) for name in models):
        raise ValueError(f"models must be a list of robot names or description files, got {models!r}")
    if not models:
        raise ValueError("the scenario's models list is empty: nothing to simulate")
    for name in models:
        robot_description(name)


def standing_run_metrics(
    scenario: StandingScenario, handles: StandingHandles, context: Context, wall_time_s: float
) -> dict:
    """The metrics of one finished run of ``scenario`` (``context``: the simulator's root
    context, ``wall_time_s``: the wall time it took) as plain data: base drift after the
    settle time (cm, deg), the final foot contact (sole tilt, deg; sole height, mm; sphere
    forces, N), feet flat, fell, and the real-time factor."""
    duration = scenario.duration
    metrics = standing_metrics(handles, context, settle_time=min(scenario.settle_time, duration))
    return dict(
        model=handles.humanoid.name,
        duration_s=duration,
        wall_s=wall_time_s,
        real_time_factor=duration / wall_time_s,
        base_drift_cm=100.0 * metrics.base_drift_m,
        base_drift_deg=float(np.degrees(metrics.base_drift_rad)),
        min_sphere_force_N=metrics.min_sphere_force_N,
        sole_tilt_deg={k: float(np.degrees(v)) for k, v in metrics.sole_tilt_rad.items()},
        sole_height_mm={k: 1000.0 * v for k, v in metrics.sole_height_m.items()},
        sphere_forces_N={k: v.tolist() for k, v in metrics.sphere_forces_N.items()},
        feet_flat=metrics.feet_flat,
        fell=metrics.fell,
        first_unexpected_contact=first_unexpected_contact(handles, context),
        stability_capped_gains={j: {"kd_scaled": a, "kd_cap": b} for j, (a, b) in handles.capped_gains.items()},
    )


def first_unexpected_contact(handles: StandingHandles, context: Context) -> str | None:
    """Which robot geometry other than the feet's contact geometries touched the ground
    first, when and how deep (``FirstUnexpectedContact.describe``), or None."""
    monitor = handles.first_contact
    if monitor is None:
        return None
    return monitor.describe(monitor.get_output_port().Eval(monitor.GetMyContextFromRoot(context)))


__all__ = [
    "REFERENCE_GAINS",
    "StandingHandles",
    "StandingMetrics",
    "StandingScenario",
    "build_standing_diagram",
    "check_standing_scenario",
    "default_gains",
    "first_unexpected_contact",
    "foot_sphere_normal_forces",
    "gains_and_caps",
    "set_initial_state",
    "standing_metrics",
    "standing_run_metrics",
]
