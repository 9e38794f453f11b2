"""Nao-like robot walking straight on flat ground under joint position control.

    NaoWalkingController ─ desired_position ─► PdGravityController ─► MultibodyPlant (nao_like,
     │ zmp/com references, sole targets,        (station, 1 kHz)        flat ground, SAP 1 ms)
     │ planned contact                                                     │ contact results, state
     ▼                                                                     ▼
    loggers ◄──────────────────────────────────────────────  ContactZmp (ZMP from contact forces)

The walking controller plays a precomputed open-loop pattern (ZMP preview control,
``systems.locomotion.walking_pattern``), planned on the robot's model (the station's
estimators' plant, ``station.estimator``, never the simulated plant); the station's PD +
gravity compensation tracks it, reading the (optionally noisy) sensed state. The measured
ZMP is computed from the true contact forces (ground truth for the metrics; no estimator
reads it).
"""

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from diagrams.scenarios import check_common_fields
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import HumanoidStation, add_humanoid_station
from diagrams.station.standing import default_gains
from systems.estimation.ekf_settings import STILL_MIN_DURATION
from systems.locomotion.contact_zmp import MIN_NORMAL_FORCE, ContactZmp
from systems.locomotion.walking_pattern import NaoWalkingController, WalkingParameters
from systems.simulation.disturbances import Push, PushSource


@dataclass
class NaoWalkHandles:
    """What ``build_nao_walk_diagram`` created.

    Attributes:
        station: the humanoid station (plant, sensors, PD + gravity controller).
        controller: the NaoWalkingController (its ``pattern`` and ``trajectory`` hold the
            plan).
        contact_zmp: the ContactZmp.
        push_source: the PushSource of the external forces, or None.
        loggers: VectorLogSinks: ``state`` (true [q; v]), ``zmp`` (measured), ``normal_force``,
            ``foot_normal_forces``, ``zmp_reference``, ``com_reference``, ``sole_targets``,
            ``planned_contact``, ``desired_position``, ``sensed_state`` (the station's [q; v]).
        meshcat_visualizer: the MeshcatVisualizer, or None.
    """

    station: HumanoidStation
    controller: NaoWalkingController
    contact_zmp: ContactZmp
    loggers: dict[str, VectorLogSink]
    push_source: PushSource | None = None
    meshcat_visualizer: MeshcatVisualizer | None = None

    def set_initial_state(self, root_context: Context) -> None:
        """Standing state in the nominal posture (the pattern's t = 0 posture)."""
        self.station.set_initial_state(root_context)


def add_walking_loggers(
    builder: DiagramBuilder,
    plant: MultibodyPlant,
    controller: NaoWalkingController,
    contact_zmp: ContactZmp,
    log_period: float,
) -> dict[str, VectorLogSink]:
    """Loggers of a walking diagram, every ``log_period`` s: the plant's ``state``, the
    contact ZMP's ``zmp``, ``foot_normal_forces`` and ``normal_force``, and the controller's
    ``zmp_reference``, ``com_reference``, ``sole_targets``, ``planned_contact`` and
    ``desired_position`` (what ``walking_metrics`` reads)."""
    loggers = {"state": LogVectorOutput(plant.get_state_output_port(), builder, log_period)}
    for name in ("zmp", "foot_normal_forces", "normal_force"):
        loggers[name] = LogVectorOutput(contact_zmp.GetOutputPort(name), builder, log_period)
    for name in ("zmp_reference", "com_reference", "sole_targets", "planned_contact", "desired_position"):
        loggers[name] = LogVectorOutput(controller.GetOutputPort(name), builder, log_period)
    for name, logger in loggers.items():
        logger.set_name(f"log_{name}")
    return loggers


@dataclass(slots=True)
class NaoWalkScenario:
    """The walking experiment's settings (SI units; ``diagrams.scenarios``). Defaults: the
    issue-7 walk (22 steps of 5 cm, 0.5 s each).

    Attributes:
        walking: the walking pattern (``systems.locomotion.walking_pattern.WalkingParameters``).
        zmp_correction_passes: passes of Kajita 2003's multibody ZMP correction
            (``systems.locomotion.walking_pattern.correct_for_multibody_zmp``; 0 = cart-table
            CoM only).
        stiffness_compensation: add the static joint deflection under the planned ground
            reaction to the targets (``systems.locomotion.walking_pattern.stiffness_compensation``,
            with the station's PD gains ``diagrams.station.standing.default_gains``).
        velocity_lead: with ``stiffness_compensation``, also lead the targets by
            K_p^-1 K_d q_dot_ref (eq. W-3), since the PD damps towards zero velocity. Off by
            default (measured not to help when this was chosen; see the git history of
            BENCHMARKS.md).
        station: the robot (``nao_like``, the walking controller's) and its world
            (``diagrams.station.config``; default: noise-free sensors, the ideal world). The
            PD reads the sensed state; its ``base_state`` "invariant_ekf" (the contact-aided
            invariant EKF, foot contact from the FSRs) is not read by the open-loop walking
            controller: the EKF's walking drift is measured on it
            (``tests/test_station_base_state.py``, which prints it with ``pytest -s``). Its
            ``at_rest_duration`` is ``standing_start``'s (none below ``STILL_MIN_DURATION``).
        log_period: period of every logger, s.
        standing_start: s the robot stands in the pattern's first posture before walking
            (``NaoWalkingController.start_delay``; default 0).
        log_sensors: also log what a robot's own log holds, every ``log_period``: the IMU's
            ``gyro`` and ``accel`` and the soles' ``fsr_forces`` (the station's noise; an
            ``FsrArray`` of its own, seed 16 ``station.seed`` + 7) (``diagrams.locomotion.walking_log``).
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``).
    """

    station: StationConfig = dataclasses.field(default_factory=lambda: StationConfig(model="nao_like", noise=False))
    walking: WalkingParameters = dataclasses.field(default_factory=WalkingParameters)
    zmp_correction_passes: int = 1
    stiffness_compensation: bool = True
    velocity_lead: bool = False
    log_period: float = 0.005
    standing_start: float = 0.0
    log_sensors: bool = False
    simulator_config: SimulatorConfig = dataclasses.field(default_factory=SimulatorConfig)

    def check(self) -> None:
        """Raises ValueError on a bad value (the message names it)."""
        check_common_fields(self)
        if self.station.model != "nao_like":
            raise ValueError(f"station.model must be nao_like (the walking controller's), got {self.station.model!r}")
        if self.zmp_correction_passes < 0:
            raise ValueError(f"zmp_correction_passes must be >= 0, got {self.zmp_correction_passes}")
        if not self.standing_start >= 0.0:
            raise ValueError(f"standing_start must be >= 0 s, got {self.standing_start}")


def build_nao_walk_diagram(
    scenario: NaoWalkScenario | None = None,
    *,
    pushes: Sequence[Push] = (),
    meshcat: Meshcat | None = None,
) -> tuple[Diagram, NaoWalkHandles]:
    """Builds the diagram of the module docstring for ``scenario`` (default
    ``NaoWalkScenario()``).

    Args:
        pushes: external forces on the robot (``systems.simulation.disturbances.Push``), e.g. a pull
            on the waist; none by default (then no PushSource is added).
        meshcat: if given, a MeshcatVisualizer (32 Hz) is added.

    Raises:
        ValueError: bad parameters (see ``NaoWalkScenario.check``, ``WalkingParameters`` and
            ``NaoWalkingController``).
    """
    scenario = scenario if scenario is not None else NaoWalkScenario()
    scenario.check()
    parameters, log_period = scenario.walking, scenario.log_period
    stiffness_compensation, velocity_lead = scenario.stiffness_compensation, scenario.velocity_lead
    zmp_correction_passes = scenario.zmp_correction_passes
    builder = DiagramBuilder()
    at_rest_duration = STILL_MIN_DURATION if scenario.standing_start >= STILL_MIN_DURATION else None
    station = add_humanoid_station(builder, dataclasses.replace(scenario.station, at_rest_duration=at_rest_duration))
    # The simulated robot (plant, pushes, contact ZMP for the metrics) and the robot's own
    # model (the estimators' plant: the gains and the walking plan, issue 31).
    plant, humanoid = station.plant, station.humanoid
    model, model_humanoid = station.estimator.plant, station.estimator.humanoid
    kp, kd = default_gains(model, model_humanoid)
    controller = builder.AddSystem(
        NaoWalkingController(
            model,
            model_humanoid,
            parameters,
            initial_positions=station.estimator.standing_state[: model.num_positions()],
            joint_stiffness=kp if stiffness_compensation else None,
            joint_damping=kd if (stiffness_compensation and velocity_lead) else None,
            zmp_correction_passes=zmp_correction_passes,
            start_delay=scenario.standing_start,
        )
    )
    controller.set_name("nao_walking_controller")
    builder.Connect(controller.GetOutputPort("desired_position"), station.desired_position)
    push_source = None
    if pushes:
        push_source = builder.AddSystem(PushSource(plant, list(pushes)))
        push_source.set_name("push_source")
        builder.Connect(
            push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port()
        )
        builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))
    contact_zmp = builder.AddSystem(ContactZmp(plant, humanoid))
    contact_zmp.set_name("contact_zmp")
    builder.Connect(plant.get_contact_results_output_port(), contact_zmp.GetInputPort("contact_results"))

    loggers = add_walking_loggers(builder, plant, controller, contact_zmp, log_period)
    loggers["sensed_state"] = LogVectorOutput(station.sensed_state, builder, log_period)
    loggers["sensed_state"].set_name("log_sensed_state")
    if scenario.log_sensors:
        from systems.observer.fsr_sensing import FSR_NOISE_STD, FsrArray
        from systems.simulation.sensors import SEEDS_PER_CALL

        imu = station.sensors.imu
        loggers["gyro"] = LogVectorOutput(imu.angular_velocity, builder, log_period)
        loggers["accel"] = LogVectorOutput(imu.linear_acceleration, builder, log_period)
        fsr = builder.AddSystem(
            FsrArray(
                plant,
                humanoid,
                noise_std=FSR_NOISE_STD if scenario.station.noise else 0.0,
                seed=SEEDS_PER_CALL * scenario.station.seed + 7,
            )
        )
        fsr.set_name("log_fsr_array")
        builder.Connect(plant.get_contact_results_output_port(), fsr.GetInputPort("contact_results"))
        loggers["fsr_forces"] = LogVectorOutput(fsr.GetOutputPort("fsr_forces"), builder, log_period)

    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.scene_graph, meshcat, MeshcatVisualizerParams(publish_period=1.0 / 32.0)
        )
    diagram = builder.Build()
    diagram.set_name("nao_walk")
    return diagram, NaoWalkHandles(
        station=station,
        controller=controller,
        contact_zmp=contact_zmp,
        loggers=loggers,
        push_source=push_source,
        meshcat_visualizer=visualizer,
    )


# ---------------------------------------------------------------------------------------
# Metrics of a walking run (shared by apps.nao_walk and the tests).
# ---------------------------------------------------------------------------------------

#: A foot counts as lifted below LIFT_FORCE and as landed above LAND_FORCE (N; hysteresis).
LIFT_FORCE = 0.5
LAND_FORCE = 5.0
#: A lift-off counts as a step only if the foot stays off the ground at least this long, s
#: (a swing phase; excludes touch-down bounces of a few ms and the zero contact forces
#: that the discrete plant reports before its first step).
MIN_AIR_TIME = 0.05
#: Fall criteria: base tilt above FALL_TILT_DEG or base height below FALL_HEIGHT_RATIO of
#: its initial value.
FALL_TILT_DEG = 30.0
FALL_HEIGHT_RATIO = 0.7
#: A planned sole within this height of the ground (m) counts as a planned support foot in
#: the ZMP metric: the swing profile (S-1) keeps the sole below 1 mm for the first and last
#: ~10 % of the swing, where joint compliance decides whether it touches.
PLANNED_CONTACT_HEIGHT = 1e-3
#: A foot carrying more than this share of the total normal force counts as loaded.
LOADED_SHARE = 0.05


def signed_distance_to_polygon(points_xy: np.ndarray, point: np.ndarray) -> float:
    """Signed distance (m) from ``point`` to the convex hull of ``points_xy`` (m, 2):
    negative outside, positive inside (the margin to the nearest edge)."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points_xy)
    # equations: n . x + b <= 0 inside, |n| = 1.
    return float(-np.max(hull.equations[:, :2] @ point + hull.equations[:, 2]))


def detect_steps(t: np.ndarray, forces: np.ndarray) -> list[tuple[int, float, float]]:
    """Swing phases in the foot normal forces (2, K): (foot index, lift-off time, touch-down
    time) for every touch-down (> LAND_FORCE) after a lift-off (< LIFT_FORCE) at least
    MIN_AIR_TIME earlier."""
    steps = []
    for i, f in enumerate(np.asarray(forces)):
        lifted, t_lift = False, 0.0
        for k, value in enumerate(f):
            if not lifted and value < LIFT_FORCE:
                lifted, t_lift = True, t[k]
            elif lifted and value > LAND_FORCE:
                lifted = False
                if t[k] - t_lift >= MIN_AIR_TIME:
                    steps.append((i, float(t_lift), float(t[k])))
    return sorted(steps, key=lambda s: s[2])


def walking_metrics(handles: NaoWalkHandles, root_context: Context) -> dict:
    """Summary of a run from the loggers (ground truth).

    Returns a dict with: ``distance_m`` (CoM x at the end minus at t = 0),
    ``walking_distance_m`` / ``mean_speed_mps`` (CoM x displacement from the first step's
    start to one step after the last touch-down, over that time), ``steps_planned``,
    ``steps_detected`` (swing phases in the foot normal forces, ``detect_steps``),
    ``upright`` / ``fell``, ``max_base_tilt_deg``, ``min_base_height_m``,
    ``zmp_in_support_fraction`` (fraction of samples with ground contact where the
    measured ZMP lies inside the convex hull of the contact spheres of the feet the PLAN
    has on the ground (planned sole below PLANNED_CONTACT_HEIGHT), at their actual poses),
    ``zmp_margin_p05_m`` / ``zmp_margin_min_m`` (5th percentile / min signed distance of
    the ZMP to that polygon's edges), ``zmp_loaded_margin_*`` (the same for the polygon of
    the feet actually carrying > LOADED_SHARE of the load: ~0 means a foot tipping on an
    edge), ``zmp_tracking_rms_m`` (measured vs reference ZMP), ``max_abs_yaw_deg``,
    ``lateral_drift_m``, ``max_footprint_error_m`` (landed sole vs planned footprint, world:
    the open-loop drift accumulates), ``max_stride_error_m`` (each swing's displacement vs
    the planned one), timing.
    """
    plant = handles.station.plant
    humanoid = handles.station.humanoid
    controller = handles.controller
    params = controller.parameters
    logs = {name: logger.FindLog(root_context) for name, logger in handles.loggers.items()}
    t = logs["state"].sample_times()
    x = logs["state"].data()
    nq = plant.num_positions()
    context = plant.CreateDefaultContext()
    base = humanoid.base_body
    instances = [humanoid.model_instance]
    com = np.empty((t.size, 3))
    tilt = np.empty(t.size)
    yaw = np.empty(t.size)
    base_z = np.empty(t.size)
    fsr_world = {side: np.empty((t.size, 4, 2)) for side in ("left", "right")}
    for k in range(t.size):
        plant.SetPositions(context, x[:nq, k])
        com[k] = plant.CalcCenterOfMassPositionInWorld(context, instances)
        X_WB = plant.EvalBodyPoseInWorld(context, base)
        R = X_WB.rotation().matrix()
        tilt[k] = np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0)))
        yaw[k] = np.degrees(np.arctan2(R[1, 0], R[0, 0]))
        base_z[k] = X_WB.translation()[2]
        for side in ("left", "right"):
            X_WS = humanoid.sole_frames[side].CalcPoseInWorld(context)
            xyz = np.column_stack([humanoid.fsr_positions[side], np.zeros(4)])
            fsr_world[side][k] = (X_WS.rotation().matrix() @ xyz.T).T[:, :2] + X_WS.translation()[:2]

    zmp = logs["zmp"].data().T
    zmp_ref = logs["zmp_reference"].data().T
    normal = logs["normal_force"].data()[0]
    planned = logs["planned_contact"].data().T > 0.5
    sole_z = logs["sole_targets"].data()[[2, 5]].T
    planned_support = planned | (sole_z < PLANNED_CONTACT_HEIGHT)
    feet = logs["foot_normal_forces"].data()
    # Contact results are sampled: the first samples read zero before the plant's first step.
    valid = (normal >= MIN_NORMAL_FORCE) & np.isfinite(zmp).all(axis=1)
    margins = np.full(t.size, np.nan)
    loaded_margins = np.full(t.size, np.nan)
    loaded = feet.T > LOADED_SHARE * np.maximum(normal, 1e-9)[:, None]
    for k in np.flatnonzero(valid):
        corners = np.vstack([fsr_world[side][k] for i, side in enumerate(("left", "right")) if planned_support[k, i]])
        margins[k] = signed_distance_to_polygon(corners, zmp[k])
        # No loaded foot (another body carries the robot): the polygon of both feet.
        feet_k = [side for i, side in enumerate(("left", "right")) if loaded[k, i]] or ["left", "right"]
        corners = np.vstack([fsr_world[side][k] for side in feet_k])
        loaded_margins[k] = signed_distance_to_polygon(corners, zmp[k])
    started = t > 2.0 * plant.time_step()
    in_support = margins[valid & started] >= 0.0
    walk0, walk1 = params.walk_start, min(params.walk_end + params.step_duration, t[-1])
    k0 = min(int(np.searchsorted(t, walk0)), t.size - 1)  # (a run may stop early)
    k1 = max(min(int(np.searchsorted(t, walk1)), t.size) - 1, k0)
    walking_distance = float(com[k1, 0] - com[k0, 0])
    fell = bool(tilt.max() > FALL_TILT_DEG or base_z.min() < FALL_HEIGHT_RATIO * base_z[0])
    steps = controller.pattern.steps
    # Footprints: sole position at the end of each step's double support after landing.
    # Stride errors: the foot's displacement over its swing (from before lift-off to after
    # touch-down) minus the planned one (open loop: absolute footprint errors accumulate).
    footprint_errors, stride_errors = [], []
    for step in steps:
        if step.t_land + 0.5 * params.double_support_time > t[-1]:
            continue  # not landed within the run
        sole = humanoid.sole_frames[step.side]
        k = int(np.searchsorted(t, step.t_land + 0.5 * params.double_support_time))
        plant.SetPositions(context, x[:nq, k])
        p = sole.CalcPoseInWorld(context).translation()
        plant.SetPositions(context, x[:nq, int(np.searchsorted(t, step.t_start))])
        p_before = sole.CalcPoseInWorld(context).translation()
        footprint_errors.append(float(np.linalg.norm(p[:2] - step.end[:2])))
        stride_errors.append(float(np.linalg.norm((p - p_before)[:2] - (step.end - step.start)[:2])))
    after = t >= walk0
    return {
        "duration_s": float(t[-1]),
        "distance_m": float(com[-1, 0] - com[0, 0]),
        "base_distance_m": float(x[4, -1] - x[4, 0]),
        "walking_time_s": float(t[k1] - t[k0]),
        "walking_distance_m": walking_distance,
        "mean_speed_mps": walking_distance / float(t[k1] - t[k0]) if k1 > k0 else 0.0,
        "steps_planned": len(steps),
        "steps_detected": len(detect_steps(t, feet)),
        "fell": fell,
        "upright": not fell,
        "max_base_tilt_deg": float(tilt.max()),
        "min_base_height_m": float(base_z.min()),
        "initial_base_height_m": float(base_z[0]),
        "max_abs_yaw_deg": float(np.abs(yaw).max()),
        "final_yaw_deg": float(yaw[-1]),
        "lateral_drift_m": float(com[-1, 1] - com[0, 1]),
        "final_com_error_m": float(np.linalg.norm(com[-1, :2] - logs["com_reference"].data()[:2, -1])),
        "zmp_samples": int(np.sum(valid & started)),
        "zmp_in_support_fraction": float(in_support.mean()) if in_support.size else 0.0,
        "zmp_margin_p05_m": float(np.nanpercentile(margins[valid & started], 5)) if in_support.size else float("nan"),
        "zmp_margin_min_m": float(np.nanmin(margins[valid & started])) if in_support.size else float("nan"),
        "zmp_loaded_margin_p05_m": float(np.nanpercentile(loaded_margins[valid & started], 5))
        if in_support.size
        else float("nan"),
        "zmp_loaded_margin_min_m": float(np.nanmin(loaded_margins[valid & started]))
        if in_support.size
        else float("nan"),
        "zmp_tracking_rms_m": (
            float(np.sqrt(np.mean(np.sum((zmp[valid & after] - zmp_ref[valid & after]) ** 2, axis=1))))
            if np.any(valid & after)
            else float("nan")
        ),
        "samples_without_contact": int(np.sum(~valid & started)),
        "max_footprint_error_m": float(max(footprint_errors)) if footprint_errors else 0.0,
        "max_stride_error_m": float(max(stride_errors)) if stride_errors else 0.0,
        "max_com_model_error_m": float(controller.trajectory.com_error.max()),
        "signals": {
            "t": t,
            "com": com,
            "tilt_deg": tilt,
            "yaw_deg": yaw,
            "zmp": zmp,
            "zmp_reference": zmp_ref,
            "zmp_margin": margins,
            "com_reference": logs["com_reference"].data().T,
            "foot_normal_forces": feet.T,
            "planned_contact": planned,
            "planned_support": planned_support,
            "fsr_world": fsr_world,
        },
    }


#: Floors of issue 7 (walking; ``walking_floors``).
MIN_STEPS = 20
MIN_DISTANCE = 1.0  # m
MIN_SPEED = 0.08  # m/s


def walking_floors(metrics: dict) -> dict:
    """The issue's walking floors on ``walking_metrics``' result, each True/False: >= 20 steps,
    >= 1 m, >= 0.08 m/s mean speed, no fall."""
    return {
        "steps_ge_20": metrics["steps_detected"] >= MIN_STEPS,
        "distance_ge_1m": metrics["distance_m"] >= MIN_DISTANCE,
        "mean_speed_ge_0.08": metrics["mean_speed_mps"] >= MIN_SPEED,
        "no_fall": not metrics["fell"],
    }


def nao_walk_metrics(
    scenario: NaoWalkScenario, handles: NaoWalkHandles, root_context: Context, wall_time_s: float
) -> dict:
    """The app's metrics: ``walking_metrics`` (with its ``signals``), the floors
    (``walking_floors``, ``meets_floors``), the wall time and real-time factor, and the
    scenario's walking parameters, ZMP correction passes, noise and seed."""
    m = walking_metrics(handles, root_context)
    checks = walking_floors(m)
    params = scenario.walking
    m.update(
        {
            "floors": checks,
            "meets_floors": all(checks.values()),
            "wall_time_s": wall_time_s,
            "real_time_factor": m["duration_s"] / wall_time_s,
            "parameters": dataclasses.asdict(params),
            "zmp_correction_passes": scenario.zmp_correction_passes,
            "noise": scenario.station.noise,
            "seed": scenario.station.seed,
        }
    )
    return m


__all__ = [
    "walking_floors",
    "detect_steps",
    "NaoWalkHandles",
    "NaoWalkScenario",
    "add_walking_loggers",
    "build_nao_walk_diagram",
    "nao_walk_metrics",
    "signed_distance_to_polygon",
    "walking_metrics",
]
