"""Experiment 4 of Hawley, Rahem and Suleiman (2019), Sec. 6.3 (Figs. 9-11), in simulation:
``nao_like`` walks forward while a cable tied to the back of its torso tightens over a
pulley, lifts a 0.3 kg mass lying on the ground and pulls the robot backwards by ~3 N; the
Kalman force observer (WALKING preset, eq. 22) estimates the pull from the FSRs, the IMU and
the encoders.

    NaoWalkingController ─ desired_position ─► PdGravityController ─► MultibodyPlant ◄─┐
     (open-loop pattern, systems.locomotion.walking_pattern)  (station, 1 kHz)     │ state      │ cable force
                                                                        ▼            │
                                            PulleyLoad (truth: force_world, point_world)
                                                 │ force, point
                                                 ▼
    CableVirtualForceTruth (eq. 11, ground plane z = 0 of the stance frame) ─► loggers
    FsrArray ─► CenterOfPressure ─► zmp, normal_force ┐
    sensed state ─► SupportFootCom ─► com_position   ├─► LipForceObserverSystem
    IMU ─► ImuComAcceleration ─────────────► com_acceleration┘    (WALKING, T = 1/60 s)

Frame convention while walking (``origin_W`` of ``CenterOfPressure`` and ``SupportFootCom``):
the observer's CoM position and ZMP are both expressed in ONE frame F0, world-aligned (x forward, z up), fixed for the
whole run, with its origin at the right sole frame's origin at t = 0 (on the ground). The
support foot changes every step, so a frame at the current support foot would make the
Kalman state x_c jump by a step length at every support switch; F0 does not move, and
z_c = CoM height above the ground, p = CoP on the ground plane z = 0 of F0, as the LIP/ZMP
model (eqs. 2-13) needs. Positions come from forward kinematics of the SENSED state
(encoders + the base estimate of ``systems.simulation.sensors``, which is the truth plus noise: a
stand-in for the leg odometry a real Nao would use to carry F0 from footprint to footprint;
without slipping the two agree).

The observer never reads the cable: only the sensors; it and the walking controller are
built from the robot's model (the station's estimators' plant, ``station.estimator``), never
from the simulated plant. The ground truth reaches only the loggers:
``PulleyLoad.force_world`` (the pull at the waist, the paper's "expected force" in Fig. 10)
and its virtual force at the CoM (eq. 11, ``CableVirtualForceTruth``).

Cable geometry (``CableSetup``): the line is tied to the back of the torso at the height of
the walking CoM (so the pull moves the LIP almost as a force at the CoM: eq. 11 adds only
tau_y / z_c ~ 0), runs backwards to a pulley ``pulley_distance`` behind the attachment,
``pulley_height`` above the ground and ``lateral_angle_deg`` to the side (the paper's
alpha ~ 5 deg), then down to the mass on the ground. The slack is chosen from the plan so
that the line tightens after the torso has walked ``tighten_distance``. The load hangs
below the pulley, so it can rise at most ``pulley_height``: the pulley is higher than the
waist (0.55 m vs 0.26 m; the line rises ~7 deg at the start, ~5 deg at the end) and the
line tightens late enough that the load stays ``min_clearance`` below it
(checked at construction from the plan).

No feed-forward lean for the expected pull (tried, measured worse, removed; see the git
history of BENCHMARKS.md).
"""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams
from pydrake.multibody.plant import ExternallyAppliedSpatialForceMultiplexer
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.locomotion.nao_walk import NaoWalkHandles, add_walking_loggers, walking_floors, walking_metrics
from diagrams.observer.nao_sensing import (
    OBSERVER_PERIOD,
    ObserverPipeline,
    add_observer_pipeline,
    add_virtual_force_arrows,
    nao_observer_parameters,
)
from diagrams.scenarios import check_common_fields
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from diagrams.station.standing import default_gains
from systems.locomotion.contact_zmp import ContactZmp
from systems.locomotion.walking_pattern import NaoWalkingController, WalkingParameters
from systems.observer.force_observer import WALKING, LipForceObserverSystem, LipObserverParameters
from systems.observer.fsr_sensing import FsrArray, ImuComAcceleration
from systems.simulation.cable import PulleyLoad
from systems.simulation.ground_truth import CableVirtualForceTruth
from systems.simulation.visualization import add_force_arrows

#: The paper's lifted mass, kg (m0 ~ 300 g).
LOAD_MASS = 0.3


@dataclass
class CableSetup:
    """Geometry of the cable of Experiment 4 (SI units, world frame, x forward). A plain
    dataclass, so that a scenario can nest it; ``check()`` repeats ``__post_init__``'s
    checks on loaded values.

    Attributes:
        load_mass: m0, kg.
        attachment_back: distance of the attachment point behind the torso origin, m
            (the torso's back).
        pulley_distance: horizontal distance from the attachment (at t = 0) back to the
            pulley, m.
        pulley_height: height of the pulley above the ground, m.
        lateral_angle_deg: angle between the line (at t = 0, seen from above) and the -x
            axis, deg (the paper's alpha ~ 5 deg); the pulley is on the -y side.
        tighten_distance: forward distance the torso walks (according to the plan) before
            the line is taut, m (sets the slack).
        stiffness: the line's stiffness, N/m; damping: N s/m.
        min_clearance: the planned highest load position must stay this far below the
            pulley, m.
    """

    load_mass: float = LOAD_MASS
    attachment_back: float = 0.05
    pulley_distance: float = 3.0
    pulley_height: float = 0.65
    lateral_angle_deg: float = 5.0
    tighten_distance: float = 0.55
    stiffness: float = 2000.0
    damping: float = 5.0
    min_clearance: float = 0.08

    def __post_init__(self):
        self.check()

    def check(self) -> None:
        """Raises ValueError on a bad value (the message names it)."""
        for name in ("load_mass", "pulley_distance", "pulley_height", "stiffness"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"CableSetup.{name} must be positive, got {value}")
        for name in ("attachment_back", "tighten_distance", "damping", "min_clearance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"CableSetup.{name} must be non-negative, got {value}")
        if not (0.0 <= self.lateral_angle_deg < 45.0):
            raise ValueError(f"CableSetup.lateral_angle_deg must be in [0, 45), got {self.lateral_angle_deg}")


@dataclass
class NaoWalkPulledHandles(NaoWalkHandles):
    """``NaoWalkHandles`` (usable by ``diagrams.locomotion.nao_walk.walking_metrics``) plus the
    pull and the observer.

    Attributes (besides the walking ones):
        cable: the PulleyLoad; setup: its CableSetup; slack_length: its natural length, m.

        planned_tighten_time / planned_lift_time: when the plan makes the line taut / the
            load start rising (quasi-static, from the planned torso motion), s.

        frame_origin: p_WF0, m.

        pipeline (``diagrams.observer.nao_sensing.ObserverPipeline``, F at ``frame_origin``),
            fsr_array, imu_com_acceleration, observer: its parts; truth: the ground truth.

        parameters: the observer's parameters (eq. 22 with the model's mass, T = 1/60 s).

        observer_loggers: loggers at the observer period: ``virtual_force``, ``valid``,
            ``truth`` (eq. 11), ``cable_force``, ``tension``, ``load_height``, ``zmp``
            (FSR CoP in F0), ``normal_force`` (f_n^o), ``com_position`` (sensed, F0),
            ``com_acceleration``, ``fsr_forces`` (read), ``true_fsr_forces``.
    """

    cable: PulleyLoad | None = None
    setup: CableSetup | None = None
    slack_length: float = 0.0
    planned_tighten_time: float = float("nan")
    planned_lift_time: float = float("nan")
    frame_origin: np.ndarray | None = None
    pipeline: ObserverPipeline | None = None
    fsr_array: FsrArray | None = None
    imu_com_acceleration: ImuComAcceleration | None = None
    observer: LipForceObserverSystem | None = None
    truth: CableVirtualForceTruth | None = None
    parameters: LipObserverParameters | None = None
    observer_loggers: dict | None = None


@dataclass(slots=True)
class NaoWalkPulledScenario:
    """Experiment 4's settings (SI units; ``diagrams.scenarios``). Defaults: the issue-7 walk
    (22 steps of 5 cm) with the default cable, sensor noise on.

    Attributes:
        walking: the walking pattern (``systems.locomotion.walking_pattern.WalkingParameters``).
        cable: the cable geometry (``CableSetup``).
        pull: False leaves the cable out (the walk alone, same pipeline: the observer's
            estimate then measures its own bias while walking).
        station: the robot (``nao_like``, the walking controller's) and its world
            (``diagrams.station.config``): the sensor noise (station sensors and FSRs,
            ``systems.simulation.sensors`` defaults), its seed, Drake's plant configuration.
        observer_period: T, s.
        log_period: period of the walking loggers, s.
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``).
    """

    station: StationConfig = dataclasses.field(default_factory=lambda: StationConfig(model="nao_like"))
    walking: WalkingParameters = dataclasses.field(default_factory=WalkingParameters)
    cable: CableSetup = dataclasses.field(default_factory=CableSetup)
    pull: bool = True
    observer_period: float = OBSERVER_PERIOD
    log_period: float = 0.005
    simulator_config: SimulatorConfig = dataclasses.field(default_factory=SimulatorConfig)

    def check(self) -> None:
        """Raises ValueError on a bad value (the message names it)."""
        check_common_fields(self)
        if self.station.model != "nao_like":
            raise ValueError(f"station.model must be nao_like (the walking controller's), got {self.station.model!r}")


def build_nao_walk_pulled_diagram(
    scenario: NaoWalkPulledScenario | None = None,
    *,
    meshcat: Meshcat | None = None,
) -> tuple[Diagram, NaoWalkPulledHandles]:
    """Builds the diagram of the module docstring for ``scenario`` (default
    ``NaoWalkPulledScenario()``).

    Args:
        meshcat: if given, a MeshcatVisualizer, the cable (red arrow of the pull) and the
            estimated virtual force (blue arrow at the CoM) at 32 Hz.

    Raises:
        ValueError: bad parameters; a cable geometry that would lift the load into the
            pulley during the planned walk, or never tighten it.
    """
    scenario = scenario if scenario is not None else NaoWalkPulledScenario()
    scenario.check()
    parameters, setup, pull = scenario.walking, scenario.cable, scenario.pull
    noise, seed, observer_period, log_period = (
        scenario.station.noise,
        scenario.station.seed,
        scenario.observer_period,
        scenario.log_period,
    )
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, scenario.station)
    # The simulated robot (plant, cable, ground truth) and the robot's own model (the
    # estimators' plant: the gains, the walking plan and every estimator, issue 31).
    plant, humanoid = station.plant, station.humanoid
    estimator = station.estimator
    model, model_humanoid = estimator.plant, estimator.humanoid
    kp, kd = default_gains(model, model_humanoid)
    q0 = estimator.standing_state[: model.num_positions()]  # the plan starts standing (as the robot does)

    # The plan first: it fixes the attachment height and the cable's slack.
    controller = NaoWalkingController(model, model_humanoid, parameters, initial_positions=q0, joint_stiffness=kp)
    torso = controller.trajectory.torso_position  # (K, 3) planned torso origin, world
    t_plan = controller.pattern.t
    walk_k = int(np.searchsorted(t_plan, parameters.walk_start))
    dz = float(controller.pattern.com[walk_k, 2] - torso[walk_k, 2])  # CoM height relative to the torso origin
    p_BA = np.array([-setup.attachment_back, 0.0, dz])
    A_plan = torso + p_BA  # the torso stays level with heading 0 in the plan
    alpha = math.radians(setup.lateral_angle_deg)
    pulley = np.array(
        [
            A_plan[0, 0] - setup.pulley_distance * math.cos(alpha),
            A_plan[0, 1] - setup.pulley_distance * math.sin(alpha),
            setup.pulley_height,
        ]
    )
    reach = np.linalg.norm(A_plan - pulley, axis=1)  # |A - P| along the plan
    d_tight = float(np.interp(A_plan[0, 0] + setup.tighten_distance, A_plan[:, 0], reach))
    # Natural length: taut (stretch 0) when the load is on the ground and |A - P| = d_tight.
    cable_length = d_tight + setup.pulley_height
    stretch_hang = setup.load_mass * parameters.gravity / setup.stiffness
    lift = reach - d_tight - stretch_hang  # planned load height (quasi-static), m
    if reach.max() <= d_tight:
        raise ValueError(
            "CableSetup: the line never tightens during the planned walk "
            f"(tighten_distance {setup.tighten_distance} m >= the planned torso travel)"
        )
    if lift.max() > setup.pulley_height - setup.min_clearance:
        raise ValueError(
            f"CableSetup: the load would rise {lift.max():.3f} m, into the pulley at "
            f"{setup.pulley_height} m: raise the pulley or tighten later"
        )
    planned_tighten = float(t_plan[np.argmax(reach >= d_tight)])
    planned_lift = float(t_plan[np.argmax(lift > 0)])

    builder.AddSystem(controller)
    controller.set_name("nao_walking_controller")
    builder.Connect(controller.GetOutputPort("desired_position"), station.desired_position)

    cable = None
    if pull:
        cable = builder.AddSystem(
            PulleyLoad(
                plant,
                humanoid.base_body.name(),
                p_BA,
                pulley,
                load_mass=setup.load_mass,
                cable_length=cable_length,
                stiffness=setup.stiffness,
                damping=setup.damping,
                gravity=parameters.gravity,
            )
        )
        cable.set_name("pulley_load")
        builder.Connect(plant.get_state_output_port(), cable.GetInputPort("state"))
        mux = builder.AddSystem(ExternallyAppliedSpatialForceMultiplexer(1))
        mux.set_name("applied_force_mux")
        builder.Connect(cable.GetOutputPort("applied_spatial_forces"), mux.get_input_port(0))
        builder.Connect(mux.get_output_port(), plant.get_applied_spatial_force_input_port())

    contact_zmp = builder.AddSystem(ContactZmp(plant, humanoid))
    contact_zmp.set_name("contact_zmp")
    builder.Connect(plant.get_contact_results_output_port(), contact_zmp.GetInputPort("contact_results"))

    # Observer pipeline: sensors only.
    context0 = model.CreateDefaultContext()
    model.SetPositions(context0, q0)
    origin = model_humanoid.sole_frames["right"].CalcPoseInWorld(context0).translation()
    standing = nao_observer_parameters(model, model_humanoid.model_instance, period=observer_period)
    obs_params = dataclasses.replace(WALKING, mass=standing.mass, gravity=standing.gravity, period=standing.period)
    pipeline = add_observer_pipeline(builder, station, origin_W=origin, noise=noise, seed=seed, parameters=obs_params)
    fsr, acc, observer = pipeline.fsr_array, pipeline.imu_com_acceleration, pipeline.observer

    truth = builder.AddSystem(CableVirtualForceTruth(plant, humanoid, ground_height=float(origin[2])))
    truth.set_name("cable_virtual_force_truth")
    builder.Connect(plant.get_state_output_port(), truth.GetInputPort("state"))
    if cable is not None:
        builder.Connect(cable.GetOutputPort("force_world"), truth.GetInputPort("force_world"))
        builder.Connect(cable.GetOutputPort("point_world"), truth.GetInputPort("point_world"))
    else:
        zero = builder.AddSystem(ConstantVectorSource(np.zeros(3)))
        builder.Connect(zero.get_output_port(), truth.GetInputPort("force_world"))
        builder.Connect(zero.get_output_port(), truth.GetInputPort("point_world"))

    loggers = add_walking_loggers(builder, plant, controller, contact_zmp, log_period)
    T = obs_params.period
    observer_loggers = {
        "virtual_force": LogVectorOutput(observer.GetOutputPort("virtual_force"), builder, T),
        "valid": LogVectorOutput(observer.GetOutputPort("valid"), builder, T),
        "truth": LogVectorOutput(truth.GetOutputPort("virtual_force"), builder, T),
        "zmp": LogVectorOutput(pipeline.center_of_pressure.GetOutputPort("zmp"), builder, T),
        "normal_force": LogVectorOutput(pipeline.center_of_pressure.GetOutputPort("normal_force"), builder, T),
        "com_position": LogVectorOutput(pipeline.support_foot_com.GetOutputPort("com_position"), builder, T),
        "com_acceleration": LogVectorOutput(acc.GetOutputPort("com_acceleration"), builder, T),
        "fsr_forces": LogVectorOutput(fsr.GetOutputPort("fsr_forces"), builder, T),
        "true_fsr_forces": LogVectorOutput(fsr.GetOutputPort("true_fsr_forces"), builder, T),
    }
    if cable is not None:
        for name in ("force_world", "tension", "load_height"):
            observer_loggers["cable_" + name if name == "force_world" else name] = LogVectorOutput(
                cable.GetOutputPort(name), builder, T
            )
    for name, logger in observer_loggers.items():
        logger.set_name(f"log_observer_{name}")

    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.scene_graph, meshcat, MeshcatVisualizerParams(publish_period=1.0 / 32.0)
        )
        if cable is not None:
            add_force_arrows(
                builder,
                meshcat,
                cable.GetOutputPort("force_world"),
                cable.GetOutputPort("point_world"),
                name="cable_force_arrow",
                path="cable_force",
                newtons_per_meter=20.0,
            )
        add_virtual_force_arrows(builder, meshcat, observer, truth, newtons_per_meter=20.0)

    diagram = builder.Build()
    diagram.set_name("nao_walk_pulled")
    return diagram, NaoWalkPulledHandles(
        station=station,
        controller=controller,
        contact_zmp=contact_zmp,
        loggers=loggers,
        meshcat_visualizer=visualizer,
        cable=cable,
        setup=setup,
        slack_length=cable_length,
        planned_tighten_time=planned_tighten,
        planned_lift_time=planned_lift,
        frame_origin=origin,
        pipeline=pipeline,
        fsr_array=fsr,
        imu_com_acceleration=acc,
        observer=observer,
        truth=truth,
        parameters=obs_params,
        observer_loggers=observer_loggers,
    )


def observer_metrics(handles: NaoWalkPulledHandles, root_context: Context, *, settle_time: float = 1.0) -> dict:
    """Exp. 4 metrics from the observer loggers (ground truth only here).

    The evaluation window ("the mass hangs and the robot walks steadily"): from
    ``settle_time`` after the load leaves the ground (measured, ``load_height`` > 1 mm) to the
    planned last touch-down (``walk_end``), restricted to samples where the load hangs.
    The estimate of sample k is logged at t_{k+1} (observer timing, ``diagrams.observer.nao_force_observer``):
    it is compared with the truth logged one sample earlier.

    Returns:
        dict with ``window_s`` [t0, t1], ``window_samples``, ``true_pull_x_mean_N`` (cable
        force, mean over the window), ``true_virtual_x_mean_N`` (eq. 11), the estimate's
        ``estimated_x_mean_N``, ``mean_error_x_N`` (estimate - cable pull), ``rms_error_x_N``
        (sample by sample vs the cable pull), the same vs the virtual force, y and z
        components, ``estimated_x_mean_before_pull_N`` (walking, line slack: the bias), and
        ``signals``.
    """
    logs = {name: lg.FindLog(root_context) for name, lg in handles.observer_loggers.items()}
    t = logs["virtual_force"].sample_times()
    est = logs["virtual_force"].data().T
    truth = logs["truth"].data().T
    # Align: estimate at t_{k+1} is for the inputs at t_k.
    est_k = np.vstack([est[1:], est[-1:]])
    out: dict = {}
    params = handles.controller.parameters
    walk_end = params.walk_end
    cable = logs.get("cable_force_world")
    pull = cable.data().T if cable is not None else np.zeros_like(truth)
    signals = {
        "t": t,
        "estimate": est_k,
        "virtual_truth": truth,
        "pull": pull,
        "normal_force": logs["normal_force"].data()[0],
        "valid": logs["valid"].data()[0],
    }
    if "load_height" in logs:
        height = logs["load_height"].data()[0]
        tension = logs["tension"].data()[0]
        signals.update(load_height=height, tension=tension)
        lifted = height > 1e-3
        t_lift = float(t[np.argmax(lifted)]) if lifted.any() else float("nan")
        out["measured_lift_time_s"] = t_lift
        out["max_load_height_m"] = float(height.max())
        window = lifted & (t >= t_lift + settle_time) & (t <= walk_end)
    else:
        window = (t >= params.walk_start + settle_time) & (t <= walk_end)
    before = (
        (t >= params.walk_start + settle_time)
        & (t < handles.planned_tighten_time)
        & (np.linalg.norm(pull, axis=1) == 0)
    )
    k = np.flatnonzero(window)
    out["window_s"] = [float(t[k[0]]), float(t[k[-1]])] if k.size else [float("nan")] * 2
    out["window_samples"] = int(k.size)
    if k.size:
        for i, axis in enumerate("xyz"):
            out[f"true_pull_{axis}_mean_N"] = float(pull[k, i].mean())
            out[f"true_virtual_{axis}_mean_N"] = float(truth[k, i].mean())
            out[f"estimated_{axis}_mean_N"] = float(est_k[k, i].mean())
            out[f"mean_error_{axis}_N"] = float(est_k[k, i].mean() - pull[k, i].mean())
            out[f"rms_error_{axis}_N"] = float(np.sqrt(np.mean((est_k[k, i] - pull[k, i]) ** 2)))
            out[f"rms_error_{axis}_vs_virtual_N"] = float(np.sqrt(np.mean((est_k[k, i] - truth[k, i]) ** 2)))
        out["estimated_x_std_N"] = float(est_k[k, 0].std())
        out["valid_fraction_in_window"] = float(signals["valid"][k].mean())
    if before.any():
        out["estimated_x_mean_before_pull_N"] = float(est_k[before, 0].mean())
        out["estimated_x_rms_before_pull_N"] = float(np.sqrt(np.mean(est_k[before, 0] ** 2)))
    fsr = logs["fsr_forces"].data()
    true_fsr = logs["true_fsr_forces"].data()
    if k.size:
        # What the FSRs miss in the window (saturation at 25 N, noise clipped at 0), N.
        out["fsr_missing_force_mean_N"] = float((true_fsr[:, k].sum(axis=0) - fsr[:, k].sum(axis=0)).mean())
        out["fsr_saturated_fraction"] = float(np.mean(np.any(true_fsr[:, k] > handles.fsr_array.saturation, axis=0)))
    out["normal_force_range_N"] = [
        float(np.percentile(signals["normal_force"][t > 0.1], 1)),
        float(np.percentile(signals["normal_force"][t > 0.1], 99)),
    ]
    out["signals"] = signals
    out["window_mask"] = window
    return out


#: Floors of issue 7, Exp. 4.
MAX_MEAN_ERROR_X = 0.5  # N
MAX_RMS_ERROR_X = 1.5  # N


def pulled_floors(walking: dict, observer: dict, pull: bool = True) -> dict:
    """The issue's floors on ``walking_metrics`` and ``observer_metrics``, each True/False
    (the Exp. 4 ones only with the pull)."""
    checks = {k + "_with_pull" if pull else k: v for k, v in walking_floors(walking).items()}
    if pull:
        ok = observer.get("window_samples", 0) > 0
        checks["mean_Fx_error_le_0.5N"] = bool(ok and abs(observer["mean_error_x_N"]) <= MAX_MEAN_ERROR_X)
        checks["rms_Fx_error_le_1.5N"] = bool(ok and observer["rms_error_x_N"] <= MAX_RMS_ERROR_X)
    return checks


def nao_walk_pulled_metrics(
    scenario: NaoWalkPulledScenario, handles: NaoWalkPulledHandles, root_context: Context, wall_time_s: float
) -> dict:
    """The app's metrics: ``walking`` (``walking_metrics``) and ``observer``
    (``observer_metrics``), both with their signals, the floors (``pulled_floors``), the
    cable as built, the observer's parameters, the frame, noise, seed, the wall time and
    real-time factor, and the walking parameters."""
    h = handles
    w = walking_metrics(h, root_context)
    o = observer_metrics(h, root_context)
    checks = pulled_floors(w, o, scenario.pull)
    return {
        "walking": w,
        "observer": o,
        "floors": checks,
        "meets_floors": all(checks.values()),
        "cable": (
            {
                "pulley_world_m": h.cable.pulley.tolist(),
                "natural_length_m": h.slack_length,
                "planned_tighten_time_s": h.planned_tighten_time,
                "planned_lift_time_s": h.planned_lift_time,
                **dataclasses.asdict(h.setup),
            }
            if h.cable is not None
            else None
        ),
        "observer_parameters": {
            "mass": h.parameters.mass,
            "period": h.parameters.period,
            "jerk_variance": h.parameters.jerk_variance,
            "force_rate_variance": h.parameters.force_rate_variance,
            "R_z": h.parameters.R_z,
            "R_xy": h.parameters.R_xy,
            "preset": "WALKING (eq. 22)",
        },
        "frame": "F0: world-aligned, origin at the right sole at t = 0 (fixed for the run)",
        "noise": scenario.station.noise,
        "seed": scenario.station.seed,
        "wall_time_s": wall_time_s,
        "real_time_factor": w["duration_s"] / wall_time_s,
        "walking_parameters": dataclasses.asdict(scenario.walking),
    }


__all__ = [
    "CableSetup",
    "LOAD_MASS",
    "MAX_MEAN_ERROR_X",
    "MAX_RMS_ERROR_X",
    "NaoWalkPulledHandles",
    "NaoWalkPulledScenario",
    "build_nao_walk_pulled_diagram",
    "nao_walk_pulled_metrics",
    "observer_metrics",
    "pulled_floors",
]
