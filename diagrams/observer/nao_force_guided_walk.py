"""Force-guided walking (Hawley et al. 2019, Sec. 6.5, Fig. 15) in simulation: the diagram
and its metrics (the experiment ``make nao-force-guided-walk``, ``apps.nao_force_guided_walk``,
whose docstring discusses the trigger sources and the measurements).

    PushSource (both hands, GuidanceProfile) ─► MultibodyPlant (nao_like, station) ◄─ PdGravityController
                                                  │ contact results, sensed state, IMU       ▲ desired_position
    nao_sensing pipeline (F0) ─► LipForceObserverSystem ─► ObserverHandForce ─┐           │
    JointTorqueFromPositionError (eq. 27) ─► ArmExternalForceEstimator ───────┼─► CompliantArmBlender (eq. 28)
                                                                              ▼
              force_estimate ("joint" | "observer" | "blend") ─► ForceGuidedWalkingController

Every estimate reads sensor outputs and the controller's own commands only; the applied
force reaches the loggers only. The controller and every estimator are built from the robot's
model (the station's estimators' plant, ``station.estimator``), never from the simulated
plant; ``ContactZmp`` (true contact forces) feeds the loggers and the metrics only.
"""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, MatrixGain

from diagrams.locomotion.nao_walk import detect_steps
from diagrams.observer.nao_sensing import add_observer_pipeline, nao_observer_parameters
from diagrams.scenarios import check_common_fields
from diagrams.station.config import StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from diagrams.station.standing import default_gains
from systems.locomotion.contact_zmp import ContactZmp
from systems.locomotion.walking_pattern import WalkingParameters
from systems.observer.arm_compliance import (
    NAO_ARM_CHAINS,
    ArmExternalForceEstimator,
    CompliantArmBlender,
    JointTorqueFromPositionError,
    ObserverHandForce,
)
from systems.observer.force_guided_walking import GUIDED_WALKING, ForceGuidedWalkingController, TriggerParameters
from systems.observer.force_observer import STANDING, WALKING
from systems.observer.hand_guidance import GuidanceProfile, ScaledProfile
from systems.simulation.disturbances import Push, PushSource

#: Floors of issue 7 (force-guided walking).
MAX_START_LATENCY = 0.5  # s
MAX_STEPS_AFTER_DROP = 1
#: Inputs of the trigger (module docstring): the joint-level hand force (default), the
#: Kalman observer's estimate, or eq. 28's blend of the two.
TRIGGER_SOURCES = ("joint", "observer", "blend")
DEFAULT_TRIGGER_SOURCE = "joint"
#: Low-pass of the joint-level estimate, s (``ArmExternalForceEstimator``'s default).
JOINT_FILTER_TIME_CONSTANT = 0.1
#: Samples closer than this to an edge of the applied force are left out of the estimates'
#: error statistics while walking, s.
EDGE_MARGIN = 0.4
#: The hands' bodies of nao_like and the grip point (body origin).
HAND_BODIES = ("l_gripper", "r_gripper")


@dataclass(slots=True)
class NaoForceGuidedWalkScenario:
    """The force-guided walk's settings (SI units; ``diagrams.scenarios``). Defaults: the
    app's. The force is 3 N, not 4 N: the ZMP shift it causes grows with it (z_c F / (m g),
    ``systems.observer.force_guided_walking``), and 4 N pushing backwards for 3 s while the
    robot walked backwards broke its gait up (measured when this was chosen; see the git
    history of BENCHMARKS.md).

    Attributes:
        force: total guidance force on the hands, N (0: no force, the false-start check).
        episodes: the guidance episodes [t_on, t_off, sign of the force] (s, s, +1 forwards /
            -1 backwards); each a plateau of ``force`` with ``ramp`` s edges
            (``systems.observer.hand_guidance.GuidanceProfile``).
        ramp: the plateaus' edges, s.
        duration: simulated time, s.
        trigger_source: the trigger's input, one of ``TRIGGER_SOURCES`` (module docstring).
        trigger: the trigger of eq. G-1 (threshold on the estimated F_x, N; debounces, s).
        preset: the observer's covariances, "walking" (eq. 22) or "standing" (eq. 21). The
            paper does not give them for Sec. 6.5; its walking preset lags ~0.5 s behind a
            force step, too slow for the start floor; eq. 21 with a 10x larger force-rate
            variance follows within ~0.2 s (only with the "observer" and "blend" sources).
        force_rate_variance: sigma^2 of the force's second derivative (eq. 17), (N/s^2)^2
            (the paper's presets: 1e3).
        walking: the walking segments' parameters (``GUIDED_WALKING``).
        max_steps: steps of one walking segment at most.
        max_lean: bound of eq. G-3's ZMP offset change, m (0, the default, disables the lean;
            ``systems.observer.force_guided_walking``).
        station: the robot (``nao_like``, the walking controller's) and its world
            (``diagrams.station.config``): the sensor noise, its seed, Drake's plant
            configuration.
        log_period: period of every logger, s.
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``).
    """

    station: StationConfig = dataclasses.field(default_factory=lambda: StationConfig(model="nao_like"))
    force: float = 3.0
    episodes: list[list[float]] = dataclasses.field(default_factory=lambda: [[1.5, 5.5, 1.0], [7.5, 10.5, -1.0]])
    ramp: float = 0.2
    duration: float = 12.7
    trigger_source: str = DEFAULT_TRIGGER_SOURCE
    trigger: TriggerParameters = dataclasses.field(default_factory=lambda: TriggerParameters(threshold=1.5))
    preset: str = "standing"
    force_rate_variance: float = 1e4
    walking: WalkingParameters = dataclasses.field(default_factory=lambda: dataclasses.replace(GUIDED_WALKING))
    max_steps: int = 20
    max_lean: float = 0.0
    log_period: float = 0.005
    simulator_config: SimulatorConfig = dataclasses.field(default_factory=SimulatorConfig)

    def check(self) -> None:
        """Raises ValueError on a bad value (the message names it)."""
        check_common_fields(self)
        if self.station.model != "nao_like":
            raise ValueError(f"station.model must be nao_like (the walking controller's), got {self.station.model!r}")
        if not (self.force > self.trigger.threshold or self.force == 0.0):
            raise ValueError(
                f"force ({self.force} N) must exceed the trigger's threshold ({self.trigger.threshold} N), or be 0"
            )
        if self.preset not in ("walking", "standing"):
            raise ValueError(f"preset must be 'walking' or 'standing', got {self.preset!r}")
        if self.trigger_source not in TRIGGER_SOURCES:
            raise ValueError(f"trigger_source must be one of {TRIGGER_SOURCES}, got {self.trigger_source!r}")
        if any(len(episode) != 3 for episode in self.episodes):
            raise ValueError(f"each episode is [t_on, t_off, sign], got {self.episodes}")

    def profile(self) -> GuidanceProfile:
        """The applied force on the hands (total F_x): ``force`` on every episode; none
        with ``force`` 0."""
        if self.force == 0.0:
            return GuidanceProfile(plateaus=(), ramp=self.ramp)
        return GuidanceProfile(
            plateaus=tuple((t_on, t_off, sign * self.force) for t_on, t_off, sign in self.episodes), ramp=self.ramp
        )


def build_force_guided_diagram(
    scenario: NaoForceGuidedWalkScenario | None = None,
    *,
    meshcat: Meshcat | None = None,
    motor_constants: dict | None = None,
) -> tuple[Diagram, dict]:
    """Station + hand pushes (``scenario.profile()``: the total F_x, half per hand) + observer
    pipeline (``diagrams.observer.nao_sensing``, in ``diagrams.observer.nao_walk_pulled``'s
    fixed stance frame F0) + joint-level hand force estimate (eqs. 25-27) +
    ``ForceGuidedWalkingController`` fed by ``scenario.trigger_source``: "joint" (the hands'
    total force from eqs. 25-27, i.e. eq. 28 with K1 = 0), "observer" (the Kalman observer's
    virtual F_x) or "blend" (eq. 28). All three are logged. ``motor_constants``: {arm joint:
    K_m} of eq. 27 (default: the PD's K_p).

    Returns the diagram and a dict of handles: ``station``, ``controller``, ``loggers``
    (VectorLogSinks every ``log_period`` s, read by ``guided_metrics``), ``parameters`` (the
    observer's), ``push_source``.

    Raises:
        ValueError: a bad scenario (``NaoForceGuidedWalkScenario.check``), e.g. an unknown
            ``preset`` or ``trigger_source``.
    """
    scenario = scenario if scenario is not None else NaoForceGuidedWalkScenario()
    scenario.check()
    profile, trigger, preset, trigger_source = (
        scenario.profile(),
        scenario.trigger,
        scenario.preset,
        scenario.trigger_source,
    )
    noise, seed, walking, max_steps, log_period = (
        scenario.station.noise,
        scenario.station.seed,
        scenario.walking,
        scenario.max_steps,
        scenario.log_period,
    )
    force_rate_variance = scenario.force_rate_variance
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, scenario.station)
    # The simulated robot (plant, pushes, contact forces for the metrics) and the robot's own
    # model (the estimators' plant: gains, the controller and every estimator, issue 31).
    plant, humanoid = station.plant, station.humanoid
    model, model_humanoid = station.estimator.plant, station.estimator.humanoid
    kp, kd = default_gains(model, model_humanoid)
    q0 = station.estimator.standing_state[: model.num_positions()]  # the plan starts standing (as the robot does)
    controller = builder.AddSystem(
        ForceGuidedWalkingController(
            model,
            model_humanoid,
            walking,
            trigger,
            initial_positions=q0,
            joint_stiffness=kp,
            max_steps=max_steps,
            max_lean=scenario.max_lean,
        )
    )
    controller.set_name("force_guided_walking_controller")
    builder.Connect(controller.GetOutputPort("desired_position"), station.desired_position)
    pushes = [Push(body, np.zeros(3), np.array([1.0, 0.0, 0.0]), ScaledProfile(profile, 0.5)) for body in HAND_BODIES]
    push_source = builder.AddSystem(PushSource(plant, pushes))
    push_source.set_name("hand_pushes")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))
    contact_zmp = builder.AddSystem(ContactZmp(plant, humanoid))
    builder.Connect(plant.get_contact_results_output_port(), contact_zmp.GetInputPort("contact_results"))

    context0 = model.CreateDefaultContext()
    model.SetPositions(context0, q0)
    origin = model_humanoid.sole_frames["right"].CalcPoseInWorld(context0).translation()
    base = nao_observer_parameters(model, model_humanoid.model_instance)
    chosen = WALKING if preset == "walking" else STANDING
    parameters = dataclasses.replace(chosen, mass=base.mass, gravity=base.gravity, period=base.period)
    if force_rate_variance is not None:
        parameters = dataclasses.replace(parameters, force_rate_variance=float(force_rate_variance))
    pipeline = add_observer_pipeline(builder, station, origin_W=origin, noise=noise, seed=seed, parameters=parameters)
    fsr, observer = pipeline.fsr_array, pipeline.observer

    # Joint-level estimate of the hands' force (Sec. 6.4, eqs. 25-27) from the arm joints'
    # position errors against the walking controller's own (constant) arm targets; K_m of
    # eq. 27 = the PD's K_p, what ``diagrams.observer.calibration.identify_motor_constant``
    # identifies on this simulator (4.96-5.00 N m/rad shoulders and elbows, 2.00 wrists).
    names = [n for c in NAO_ARM_CHAINS for n in c.joint_names]
    kp_by_name = dict(zip(station.estimator.joint_names, kp.tolist()))
    kd_by_name = dict(zip(station.estimator.joint_names, kd.tolist()))
    km = {n: kp_by_name[n] for n in names} if motor_constants is None else dict(motor_constants)
    joint_torque = builder.AddSystem(JointTorqueFromPositionError(model, km, NAO_ARM_CHAINS))
    joint_torque.set_name("joint_torque_from_position_error")
    builder.Connect(controller.GetOutputPort("desired_position"), joint_torque.GetInputPort("desired_position"))
    builder.Connect(station.sensed_state, joint_torque.GetInputPort("state"))
    estimator = builder.AddSystem(
        ArmExternalForceEstimator(
            model,
            NAO_ARM_CHAINS,
            damping=[kd_by_name[n] for n in names],
            filter_time_constant=JOINT_FILTER_TIME_CONSTANT,
        )
    )
    estimator.set_name("arm_external_force_estimator")
    builder.Connect(joint_torque.GetOutputPort("motor_torque"), estimator.GetInputPort("motor_torque"))
    builder.Connect(station.sensed_state, estimator.GetInputPort("state"))
    total = builder.AddSystem(MatrixGain(np.hstack([np.eye(3)] * len(NAO_ARM_CHAINS))))  # sum over the hands
    total.set_name("total_hand_force")
    builder.Connect(estimator.GetOutputPort("hand_forces"), total.get_input_port())
    # Eq. 28's blend (K1 = K_a / 8) of the observer's estimate read as a force on the hands
    # (eq. 11 inverted; the ground is the world's z = 0 plane) and the joint-level estimate.
    hand_force = builder.AddSystem(
        ObserverHandForce(model, model.world_frame(), NAO_ARM_CHAINS, model_instances=[model_humanoid.model_instance])
    )
    builder.Connect(observer.GetOutputPort("virtual_force"), hand_force.GetInputPort("virtual_force"))
    builder.Connect(station.sensed_state, hand_force.GetInputPort("state"))
    blender = builder.AddSystem(CompliantArmBlender(3 * len(NAO_ARM_CHAINS)))
    builder.Connect(hand_force.GetOutputPort("hand_forces"), blender.GetInputPort("observer_force"))
    builder.Connect(estimator.GetOutputPort("hand_forces"), blender.GetInputPort("joint_force"))
    builder.Connect(fsr.GetOutputPort("fsr_forces"), blender.GetInputPort("fsr_forces"))
    blended_total = builder.AddSystem(MatrixGain(np.hstack([np.eye(3)] * len(NAO_ARM_CHAINS))))
    builder.Connect(blender.GetOutputPort("blended_force"), blended_total.get_input_port())
    source_port = {
        "observer": observer.GetOutputPort("virtual_force"),
        "joint": total.get_output_port(),
        "blend": blended_total.get_output_port(),
    }[trigger_source]
    builder.Connect(source_port, controller.GetInputPort("force_estimate"))

    loggers = {
        "state": LogVectorOutput(plant.get_state_output_port(), builder, log_period),
        "foot_normal_forces": LogVectorOutput(contact_zmp.GetOutputPort("foot_normal_forces"), builder, log_period),
        "walking_state": LogVectorOutput(controller.GetOutputPort("walking_state"), builder, log_period),
        "estimate": LogVectorOutput(observer.GetOutputPort("virtual_force"), builder, log_period),
        "joint_estimate": LogVectorOutput(total.get_output_port(), builder, log_period),
        "blended_estimate": LogVectorOutput(blended_total.get_output_port(), builder, log_period),
        "applied": LogVectorOutput(push_source.GetOutputPort("force_world"), builder, log_period),
        "com_reference": LogVectorOutput(controller.GetOutputPort("com_reference"), builder, log_period),
    }
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(
            builder, station.scene_graph, meshcat, MeshcatVisualizerParams(publish_period=1.0 / 32.0)
        )
    diagram = builder.Build()
    diagram.set_name("nao_force_guided_walk")
    return diagram, {
        "station": station,
        "controller": controller,
        "loggers": loggers,
        "parameters": parameters,
        "push_source": push_source,
    }


def guided_metrics(handles: dict, context, profile: GuidanceProfile, trigger: TriggerParameters) -> dict:
    """Start/stop timing against the applied force's threshold crossings (definitions in
    ``apps.nao_force_guided_walk``'s docstring), the estimates' errors while walking, and
    falls, from the loggers of ``build_force_guided_diagram`` in the simulated ``context``."""
    station, controller = handles["station"], handles["controller"]
    plant, humanoid = station.plant, station.humanoid
    logs = {k: v.FindLog(context) for k, v in handles["loggers"].items()}
    t = logs["state"].sample_times()
    x = logs["state"].data()
    feet = logs["foot_normal_forces"].data()
    steps = detect_steps(t, feet)
    lift_offs = np.array([s[1] for s in steps])
    touch_downs = np.array([s[2] for s in steps])
    params = controller.walking_parameters
    ds = params.double_support_time
    starts = [(te, d) for te, name, d in controller.events if name == "start"]
    stops = [(te, d) for te, name, d in controller.events if name == "stop"]
    pc = plant.CreateDefaultContext()
    com = np.empty((t.size, 3))
    tilt = np.empty(t.size)
    yaw = np.empty(t.size)
    nq = plant.num_positions()
    for k in range(t.size):
        plant.SetPositions(pc, x[:nq, k])
        com[k] = plant.CalcCenterOfMassPositionInWorld(pc, [humanoid.model_instance])
        R = plant.EvalBodyPoseInWorld(pc, humanoid.base_body).rotation().matrix()
        tilt[k] = math.degrees(math.acos(min(1.0, max(-1.0, R[2, 2]))))
        yaw[k] = math.degrees(math.atan2(R[1, 0], R[0, 0]))
    episodes = []
    crossings = profile.crossings(trigger.threshold)
    windows = [
        (t_on, next((c[0] for c in crossings[i + 1 :] if c[1] == "off"), math.inf))
        for i, (t_on, kind, _) in enumerate(crossings)
        if kind == "on"
    ]
    # A false start: a start decision outside every episode's window [t_on, t_off + 0.5 s).
    false_starts = [te for te, _ in starts if not any(a <= te < b + 0.5 for a, b in windows)]
    for i, (t_on, kind, sign) in enumerate(crossings):
        if kind != "on":
            continue
        t_off = next((c[0] for c in crossings[i + 1 :] if c[1] == "off"), math.inf)
        e = {"direction": sign, "force_on_s": t_on, "force_off_s": t_off}
        start = next(((te, d) for te, d in starts if t_on <= te < t_off + 0.5), None)
        e["start_decision_s"] = start[0] if start else None
        e["start_latency_s"] = (start[0] - t_on) if start else None
        first_lift = lift_offs[lift_offs > t_on]
        e["first_lift_off_latency_s"] = float(first_lift[0] - t_on) if first_lift.size else None
        stop = next(((te, d) for te, d in stops if te >= t_off), None)
        e["stop_decision_s"] = stop[0] if stop else None
        e["stop_decision_latency_s"] = (stop[0] - t_off) if stop else None
        e["closing_step"] = stop[1].get("closing_step") if stop else None
        e["com_difference_at_switch_m"] = stop[1].get("com_difference_at_switch_m") if stop else None
        nxt = next((c[0] for c in crossings[i + 1 :] if c[1] == "on"), math.inf)
        after = (lift_offs > t_off) & (lift_offs < nxt)
        e["lift_offs_after_drop"] = int(after.sum())
        e["steps_begun_after_drop"] = int(((lift_offs > t_off + ds) & (lift_offs < nxt)).sum())
        last_td = touch_downs[(touch_downs > t_off) & (touch_downs < nxt)]
        e["last_touch_down_after_drop_s"] = float(last_td.max() - t_off) if last_td.size else 0.0
        during = (lift_offs >= t_on) & (lift_offs < min(t_off + 2.0, nxt))
        e["steps_during"] = int(during.sum())
        k0, k1 = np.searchsorted(t, t_on), min(np.searchsorted(t, min(nxt, t[-1])), t.size - 1)
        e["com_x_displacement_m"] = float(com[k1, 0] - com[k0, 0])
        e["moved_in_force_direction"] = bool(
            np.sign(e["com_x_displacement_m"]) == sign and abs(e["com_x_displacement_m"]) > 0.02
        )
        e["start_ok"] = bool(start is not None and start[0] - t_on <= MAX_START_LATENCY)
        e["stop_ok"] = bool(e["steps_begun_after_drop"] <= MAX_STEPS_AFTER_DROP and stop is not None)
        episodes.append(e)
    fell = bool(tilt.max() > 30.0 or x[6].min() < 0.7 * x[6, 0])
    # The estimates' errors against the applied F_x while the robot walks (mode != standing),
    # away from the force's edges (>= EDGE_MARGIN s: the joint-level low-pass and the
    # observer settle), split into pushed / no force.
    applied_x = logs["applied"].data()[0] + logs["applied"].data()[3]
    walking = logs["walking_state"].data()[0] > 0.5
    edges = np.array(
        [e for t_on, t_off, _ in profile.plateaus for e in (t_on, t_on + profile.ramp, t_off, t_off + profile.ramp)]
    )
    far = np.ones(t.size, bool) if edges.size == 0 else np.abs(t[:, None] - edges[None, :]).min(axis=1) >= EDGE_MARGIN
    estimate_errors = {}
    for name, log in (("joint", "joint_estimate"), ("observer", "estimate"), ("blend", "blended_estimate")):
        error = logs[log].data()[0] - applied_x
        for case, mask in (
            ("pushed", walking & far & (np.abs(applied_x) > 1e-6)),
            ("no_force", walking & far & (np.abs(applied_x) <= 1e-6)),
        ):
            e = error[mask]
            estimate_errors[f"{name}_{case}"] = (
                {
                    "samples": int(e.size),
                    "mean_N": float(e.mean()),
                    "std_N": float(e.std()),
                    "max_abs_N": float(np.abs(e).max()),
                }
                if e.size
                else {"samples": 0}
            )
    return {
        "episodes": episodes,
        "false_starts_s": false_starts,
        "estimate_errors_while_walking": estimate_errors,
        "steps_detected": len(steps),
        "fell": fell,
        "max_base_tilt_deg": float(tilt.max()),
        "max_abs_yaw_deg": float(np.abs(yaw).max()),
        "events": [(te, n, d) for te, n, d in controller.events],
        "segments_built": len(controller.plans) - 1,
        "signals": {
            "t": t,
            "com": com,
            "feet": feet.T,
            "estimate": logs["estimate"].data().T,
            "joint_estimate": logs["joint_estimate"].data().T,
            "blended_estimate": logs["blended_estimate"].data().T,
            "applied": logs["applied"].data().T,
            "walking_state": logs["walking_state"].data().T,
            "tilt": tilt,
        },
    }


def force_guided_walk_metrics(scenario: NaoForceGuidedWalkScenario, handles: dict, context, wall_time_s: float) -> dict:
    """The app's metrics: ``guided_metrics`` (with its ``signals``), the wall and simulated
    time, the floors per episode (start within 0.5 s, stop within one step, moved in the
    force's direction), no false start, no fall, and the scenario's threshold, force,
    trigger source, preset, noise, seed and walking parameters."""
    m = guided_metrics(handles, context, scenario.profile(), scenario.trigger)
    m["wall_time_s"] = wall_time_s
    m["simulated_s"] = context.get_time()
    checks = {}
    for i, e in enumerate(m["episodes"]):
        checks[f"episode{i}_start_within_0.5s"] = e["start_ok"]
        checks[f"episode{i}_stop_within_one_step"] = e["stop_ok"]
        checks[f"episode{i}_moved_in_force_direction"] = e["moved_in_force_direction"]
    checks["no_false_start"] = not m["false_starts_s"]
    checks["no_fall"] = not m["fell"]
    m.update(
        floors=checks,
        meets_floors=all(checks.values()),
        threshold_N=scenario.trigger.threshold,
        force_N=scenario.force,
        trigger_source=scenario.trigger_source,
        preset=scenario.preset,
        noise=scenario.station.noise,
        seed=scenario.station.seed,
        walking_parameters=dataclasses.asdict(scenario.walking),
    )
    return m


__all__ = [
    "DEFAULT_TRIGGER_SOURCE",
    "EDGE_MARGIN",
    "HAND_BODIES",
    "JOINT_FILTER_TIME_CONSTANT",
    "MAX_START_LATENCY",
    "MAX_STEPS_AFTER_DROP",
    "NaoForceGuidedWalkScenario",
    "TRIGGER_SOURCES",
    "build_force_guided_diagram",
    "force_guided_walk_metrics",
    "guided_metrics",
]
