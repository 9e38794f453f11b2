"""Force-guided walking (Hawley et al. 2019, Sec. 6.5, Fig. 15) in simulation: a "human" pulls
both hands of nao_like forwards, lets go, then pushes them backwards; an estimate of the
force on the hands drives ``ForceGuidedWalkingController``, which walks in its direction while
|F_x| exceeds the threshold and stops when it falls below. Issue 7, item 4.

The trigger's input (``--trigger-source``):

* ``joint`` (default): the hands' total force from the arm joints (Sec. 6.4, eqs. 25-27:
  tau_m = K_m (q_d - q) against the walking controller's arm targets, minus the arm rows of
  the floating-base inverse dynamics, through (J^T)^+; ``systems.observer.arm_compliance``), i.e.
  eq. 28's blend with K1 = 0. Sec. 6.5 is the interaction of Sec. 6.4 (a human holding the
  hands); eq. 28 gives the joint-level estimate the weight of the FSRs that lose contact,
  and a walking robot unloads one foot's four FSRs in every single support. This estimate
  has no Kalman filter lag (only a 0.1 s low-pass) and does not depend on the feet's
  contact: measured (seed 1) while walking, its error against the applied force has mean
  0.000 N and std 0.03 N (pushed, steady) / 0.02 N (no force, closing steps); standing,
  std 0.002 N (simulation: the model is exact and the encoders' noise is 2e-5 rad).
* ``observer``: the Kalman observer's virtual F_x (eq. 11; ``--preset``, eq. 21 with a 10x
  force-rate variance by default). While walking it errs by ~2 N RMS and lags: walking
  backwards it stayed beyond the threshold up to 0.66 s after the push ended (3 steps begun
  after the drop, 4 N, seed 1), and at 3 N it dips below the threshold mid-walk.
* ``blend``: eq. 28 as in ``diagrams.observer.nao_compliant_arms`` (K1 = K_a / 8, FSRs above 1 N; the
  observer's estimate read as a force on the hands by ``ObserverHandForce``). With both
  feet down (double support, standing, the closing step's end) K1 = 1: the observer alone,
  with its errors; measured (seed 1) it misses the stop floor too (3 N: 2 steps begun after
  the forward drop; 4 N: the backward stop is never decided in time, 3 steps begun).

Floors (issue 7): the robot starts within 0.5 s of the (applied) force crossing the
threshold, and stops within one step after it drops. Definitions here: start latency = the
controller's start decision (the segment's t_0, when the CoM starts its first weight shift)
minus the time the applied F_x (sum over both hands) crosses the threshold; the first
lift-off's latency is reported too. Stop: "steps begun after the drop" = detected lift-offs
later than t_drop + the double-support time (a lift-off before that belongs to the step in
progress at t_drop); the floor is <= 1 (the closing step); the time from the drop to the last
touch-down is reported. Also checked: no false start (a start decision outside every
episode's window [force on, force off + 0.5 s)); ``--force 0`` runs the same 12.7 s without
any force (the false-start check alone).

Measured (2 cores, ~9 s wall for 12.7 s simulated; episode = forwards / backwards):

    settings                                    start latency   steps begun after drop   false starts
    default (joint, 3 N, 1.5 N), seeds 0-4      0.18 / 0.18 s   1 / 1 (stop decided      0
      and --no-noise                                            +0.13 s after the drop)
    --force 0, seeds 0-4 and --no-noise         -               -                        0
    --trigger-source observer, 3 N, seed 1      0.32 / 0.32 s   forwards stopped 0.7 s   0
                                                                before the drop / 2
    observer, 4 N (the former default)          0.28 / 0.28 s   1 / 3 (seed 1, no noise) 0
                                                                1 / 1 (seeds 0, 2)
    joint, 4 N, seed 0                          0.17 / 0.17 s   1 / 6: the backward gait 0
                                                                breaks up (yaw 40 deg)
    blend (eq. 28), 3 N, seed 1                 0.27 / 0.26 s   2 / 1                    0
    blend (eq. 28), 4 N, seed 1                 0.25 / 0.23 s   1 / 3                    0

Walking backwards while pushed backwards with 4 N is beyond the walking controller: once
the trigger keeps it walking for the whole 3 s push (6 steps), the steps degrade into
short hops with both feet off the ground (seed 0: 17 lift-offs, yaw 40 deg); the observer
trigger hid this by stopping early. Hence the 3 N default (ZMP shift ~1.3 cm).

Run: ``python -m apps.nao_force_guided_walk [--force N] [--threshold N] [--trigger-source
joint|observer|blend] [--preset walking|standing] [--force-rate-variance V] [--start-debounce S]
[--stop-debounce S] [--seed S] [--no-noise] [--out DIR] [--headless] [--no-replay]``. Writes to
DIR (default ``out/nao_force_guided_walk``): ``metrics.json``, ``guided.png`` (applied and
estimated F_x (both estimates) with the threshold, walking state, CoM x, foot forces) and
``guided.html`` (Meshcat replay).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402
from pydrake.systems.primitives import LogVectorOutput, MatrixGain  # noqa: E402

from apps.common import replay_meshcat  # noqa: E402
from diagrams.station.humanoid_station import add_humanoid_station  # noqa: E402
from diagrams.observer.nao_force_observer import add_observer_pipeline, nao_observer_parameters  # noqa: E402
from diagrams.locomotion.nao_walk import detect_steps  # noqa: E402
from systems.locomotion.contact_zmp import ContactZmp  # noqa: E402
from diagrams.station.standing import default_gains  # noqa: E402
from systems.observer.arm_compliance import (NAO_ARM_CHAINS, ArmExternalForceEstimator, CompliantArmBlender,  # noqa: E402
                                    JointTorqueFromPositionError, ObserverHandForce)
from systems.simulation.disturbances import Push, PushSource  # noqa: E402
from systems.observer.force_guided_walking import GUIDED_WALKING, ForceGuidedWalkingController, TriggerParameters  # noqa: E402
from systems.observer.force_observer import STANDING, WALKING  # noqa: E402
from systems.common.smoothing import smoothstep5  # noqa: E402
from systems.locomotion.walking_pattern import WalkingParameters  # noqa: E402

#: Floors of issue 7 (force-guided walking).
MAX_START_LATENCY = 0.5  # s
MAX_STEPS_AFTER_DROP = 1
#: App defaults (measured, see the module docstring's table). 3 N on the hands moves the ZMP
#: ~1.3 cm; 4 N pushing backwards for 3 s while the robot walks backwards breaks its gait up.
#: The observer's settings (only with ``--trigger-source observer``): the paper does not give
#: them for Sec. 6.5; its walking preset (eq. 22) lags ~0.5 s behind a force step, too slow
#: for the start floor; eq. 21 with a 10x larger force-rate variance follows within ~0.2 s.
DEFAULT_FORCE = 3.0
DEFAULT_THRESHOLD = 1.5
DEFAULT_PRESET = "standing"
DEFAULT_FORCE_RATE_VARIANCE = 1e4
#: Inputs of the trigger (module docstring): the joint-level hand force (default), the
#: Kalman observer's estimate, or eq. 28's blend of the two.
TRIGGER_SOURCES = ("joint", "observer", "blend")
DEFAULT_TRIGGER_SOURCE = "joint"
#: Low-pass of the joint-level estimate, s (``ArmExternalForceEstimator``'s default).
JOINT_FILTER_TIME_CONSTANT = 0.1
#: The guidance episodes (t_on, t_off, sign of the force) and the simulated time, s.
EPISODES = ((1.5, 5.5, 1.0), (7.5, 10.5, -1.0))
DURATION = 12.7
#: Samples closer than this to an edge of the applied force are left out of the estimates'
#: error statistics while walking, s.
EDGE_MARGIN = 0.4
#: The hands' bodies of nao_like and the grip point (body origin).
HAND_BODIES = ("l_gripper", "r_gripper")


@dataclass(frozen=True)
class GuidanceProfile:
    """Total force along x on the hands, N: a sequence of plateaus (t_on, t_off, magnitude)
    with ``ramp`` s 5th-order smoothstep edges (rising from t_on, falling from t_off),
    zero elsewhere; per hand, half of it."""

    plateaus: tuple = ((1.5, 5.5, 5.0), (7.5, 10.5, -5.0))
    ramp: float = 0.2

    def __post_init__(self):
        if not (math.isfinite(self.ramp) and self.ramp > 0):
            raise ValueError(f"ramp must be positive, got {self.ramp}")
        last = -math.inf
        for t_on, t_off, magnitude in self.plateaus:
            if not (math.isfinite(t_on) and math.isfinite(t_off) and math.isfinite(magnitude)):
                raise ValueError("plateaus must hold finite numbers")
            if not (t_on >= last and t_off >= t_on + self.ramp):
                raise ValueError(f"plateau ({t_on}, {t_off}) must start after the previous one ends and last >= ramp")
            last = t_off + self.ramp

    def value(self, t):
        t_arr = np.asarray(t, dtype=float)
        out = np.zeros_like(t_arr)
        for t_on, t_off, magnitude in self.plateaus:
            up = smoothstep5((t_arr - t_on) / self.ramp)
            down = 1.0 - smoothstep5((t_arr - t_off) / self.ramp)
            out = out + magnitude * np.minimum(up, down)
        return float(out) if np.ndim(t) == 0 else out

    def crossings(self, threshold: float) -> list[tuple[float, str, int]]:
        """(time, "on"/"off", sign) where |total| crosses ``threshold`` (1 ms grid)."""
        t = np.arange(0.0, self.end + 1.0, 1e-3)
        v = self.value(t)
        above = np.abs(v) > threshold
        out = []
        for k in np.flatnonzero(above[1:] != above[:-1]) + 1:
            out.append((float(t[k]), "on" if above[k] else "off", int(np.sign(v[k] if above[k] else v[k - 1]))))
        return out

    @property
    def end(self) -> float:
        return max((t_off + self.ramp for _, t_off, _ in self.plateaus), default=0.0)


class _HalfProfile:
    """Half of a profile (one hand)."""

    def __init__(self, profile: GuidanceProfile):
        self._profile = profile

    def value(self, t):
        return 0.5 * self._profile.value(t)


def build_force_guided_diagram(profile: GuidanceProfile, trigger: TriggerParameters, *, preset: str = "walking",
                               force_rate_variance: float | None = None,
                               noise: bool = True, seed: int = 0, walking: WalkingParameters | None = None,
                               max_steps: int = 20, log_period: float = 0.005, meshcat: Meshcat | None = None,
                               trigger_source: str = DEFAULT_TRIGGER_SOURCE, motor_constants: dict | None = None):
    """Station + hand pushes + observer pipeline (``diagrams.observer.nao_walk_pulled``'s fixed stance
    frame F0) + joint-level hand force estimate (eqs. 25-27) + ``ForceGuidedWalkingController``
    fed by ``trigger_source``: "joint" (the hands' total force from eqs. 25-27, i.e. eq. 28
    with K1 = 0) or "observer" (the Kalman observer's virtual F_x). Both are logged.
    ``motor_constants``: {arm joint: K_m} of eq. 27 (default: the PD's K_p)."""
    if preset not in ("walking", "standing"):
        raise ValueError(f"preset must be 'walking' or 'standing', got {preset!r}")
    if trigger_source not in TRIGGER_SOURCES:
        raise ValueError(f"trigger_source must be one of {TRIGGER_SOURCES}, got {trigger_source!r}")
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, "nao_like", noise=noise, seed=seed)
    plant, humanoid = station.plant, station.humanoid
    kp, _ = default_gains(plant, humanoid)
    q0 = station.initial_state[: plant.num_positions()]
    controller = builder.AddSystem(ForceGuidedWalkingController(
        plant, humanoid, walking, trigger, initial_positions=q0, joint_stiffness=kp, max_steps=max_steps))
    controller.set_name("force_guided_walking_controller")
    builder.Connect(controller.GetOutputPort("desired_position"), station.desired_position)
    pushes = [Push(body, np.zeros(3), np.array([1.0, 0.0, 0.0]), _HalfProfile(profile)) for body in HAND_BODIES]
    push_source = builder.AddSystem(PushSource(plant, pushes))
    push_source.set_name("hand_pushes")
    builder.Connect(push_source.GetOutputPort("applied_spatial_forces"), plant.get_applied_spatial_force_input_port())
    builder.Connect(plant.get_state_output_port(), push_source.GetInputPort("state"))
    contact_zmp = builder.AddSystem(ContactZmp(plant, humanoid))
    builder.Connect(plant.get_contact_results_output_port(), contact_zmp.GetInputPort("contact_results"))

    context0 = plant.CreateDefaultContext()
    plant.SetPositions(context0, q0)
    origin = humanoid.sole_frames["right"].CalcPoseInWorld(context0).translation()
    base = nao_observer_parameters(plant, humanoid.model_instance)
    chosen = WALKING if preset == "walking" else STANDING
    parameters = dataclasses.replace(chosen, mass=base.mass, gravity=base.gravity, period=base.period)
    if force_rate_variance is not None:
        parameters = dataclasses.replace(parameters, force_rate_variance=float(force_rate_variance))
    pipeline = add_observer_pipeline(builder, station, origin_W=origin, noise=noise, seed=seed, parameters=parameters)
    fsr, observer = pipeline.fsr_array, pipeline.observer

    # Joint-level estimate of the hands' force (Sec. 6.4, eqs. 25-27) from the arm joints'
    # position errors against the walking controller's own (constant) arm targets; K_m of
    # eq. 27 = the PD's K_p, what ``systems.observer.arm_compliance.identify_motor_constant``
    # identifies on this simulator (4.96-5.00 N m/rad shoulders and elbows, 2.00 wrists).
    names = [n for c in NAO_ARM_CHAINS for n in c.joint_names]
    _, kd = default_gains(plant, humanoid)
    kp_by_name = dict(zip(station.joint_names, kp.tolist()))
    kd_by_name = dict(zip(station.joint_names, kd.tolist()))
    km = {n: kp_by_name[n] for n in names} if motor_constants is None else dict(motor_constants)
    joint_torque = builder.AddSystem(JointTorqueFromPositionError(plant, km, NAO_ARM_CHAINS))
    joint_torque.set_name("joint_torque_from_position_error")
    builder.Connect(controller.GetOutputPort("desired_position"), joint_torque.GetInputPort("desired_position"))
    builder.Connect(station.sensed_state, joint_torque.GetInputPort("state"))
    estimator = builder.AddSystem(ArmExternalForceEstimator(
        plant, NAO_ARM_CHAINS, damping=[kd_by_name[n] for n in names], filter_time_constant=JOINT_FILTER_TIME_CONSTANT))
    estimator.set_name("arm_external_force_estimator")
    builder.Connect(joint_torque.GetOutputPort("motor_torque"), estimator.GetInputPort("motor_torque"))
    builder.Connect(station.sensed_state, estimator.GetInputPort("state"))
    total = builder.AddSystem(MatrixGain(np.hstack([np.eye(3)] * len(NAO_ARM_CHAINS))))  # sum over the hands
    total.set_name("total_hand_force")
    builder.Connect(estimator.GetOutputPort("hand_forces"), total.get_input_port())
    # Eq. 28's blend (K1 = K_a / 8) of the observer's estimate read as a force on the hands
    # (eq. 11 inverted; the ground is the world's z = 0 plane) and the joint-level estimate.
    hand_force = builder.AddSystem(ObserverHandForce(plant, plant.world_frame(), NAO_ARM_CHAINS,
                                                     model_instances=[humanoid.model_instance]))
    builder.Connect(observer.GetOutputPort("virtual_force"), hand_force.GetInputPort("virtual_force"))
    builder.Connect(station.sensed_state, hand_force.GetInputPort("state"))
    blender = builder.AddSystem(CompliantArmBlender(3 * len(NAO_ARM_CHAINS)))
    builder.Connect(hand_force.GetOutputPort("hand_forces"), blender.GetInputPort("observer_force"))
    builder.Connect(estimator.GetOutputPort("hand_forces"), blender.GetInputPort("joint_force"))
    builder.Connect(fsr.GetOutputPort("fsr_forces"), blender.GetInputPort("fsr_forces"))
    blended_total = builder.AddSystem(MatrixGain(np.hstack([np.eye(3)] * len(NAO_ARM_CHAINS))))
    builder.Connect(blender.GetOutputPort("blended_force"), blended_total.get_input_port())
    source_port = {"observer": observer.GetOutputPort("virtual_force"), "joint": total.get_output_port(),
                   "blend": blended_total.get_output_port()}[trigger_source]
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
        MeshcatVisualizer.AddToBuilder(builder, station.scene_graph, meshcat,
                                       MeshcatVisualizerParams(publish_period=1.0 / 32.0))
    diagram = builder.Build()
    diagram.set_name("nao_force_guided_walk")
    return diagram, {"station": station, "controller": controller, "loggers": loggers, "parameters": parameters,
                     "push_source": push_source}


def guided_metrics(handles: dict, context, profile: GuidanceProfile, trigger: TriggerParameters) -> dict:
    """Start/stop timing against the applied force's threshold crossings (module docstring)."""
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
    windows = [(t_on, next((c[0] for c in crossings[i + 1:] if c[1] == "off"), math.inf))
               for i, (t_on, kind, _) in enumerate(crossings) if kind == "on"]
    # A false start: a start decision outside every episode's window [t_on, t_off + 0.5 s).
    false_starts = [te for te, _ in starts if not any(a <= te < b + 0.5 for a, b in windows)]
    for i, (t_on, kind, sign) in enumerate(crossings):
        if kind != "on":
            continue
        t_off = next((c[0] for c in crossings[i + 1:] if c[1] == "off"), math.inf)
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
        nxt = next((c[0] for c in crossings[i + 1:] if c[1] == "on"), math.inf)
        after = (lift_offs > t_off) & (lift_offs < nxt)
        e["lift_offs_after_drop"] = int(after.sum())
        e["steps_begun_after_drop"] = int(((lift_offs > t_off + ds) & (lift_offs < nxt)).sum())
        last_td = touch_downs[(touch_downs > t_off) & (touch_downs < nxt)]
        e["last_touch_down_after_drop_s"] = float(last_td.max() - t_off) if last_td.size else 0.0
        during = (lift_offs >= t_on) & (lift_offs < min(t_off + 2.0, nxt))
        e["steps_during"] = int(during.sum())
        k0, k1 = np.searchsorted(t, t_on), min(np.searchsorted(t, min(nxt, t[-1])), t.size - 1)
        e["com_x_displacement_m"] = float(com[k1, 0] - com[k0, 0])
        e["moved_in_force_direction"] = bool(np.sign(e["com_x_displacement_m"]) == sign and
                                             abs(e["com_x_displacement_m"]) > 0.02)
        e["start_ok"] = bool(start is not None and start[0] - t_on <= MAX_START_LATENCY)
        e["stop_ok"] = bool(e["steps_begun_after_drop"] <= MAX_STEPS_AFTER_DROP and stop is not None)
        episodes.append(e)
    fell = bool(tilt.max() > 30.0 or x[6].min() < 0.7 * x[6, 0])
    # The estimates' errors against the applied F_x while the robot walks (mode != standing),
    # away from the force's edges (>= EDGE_MARGIN s: the joint-level low-pass and the
    # observer settle), split into pushed / no force.
    applied_x = logs["applied"].data()[0] + logs["applied"].data()[3]
    walking = logs["walking_state"].data()[0] > 0.5
    edges = np.array([e for t_on, t_off, _ in profile.plateaus for e in (t_on, t_on + profile.ramp, t_off,
                                                                         t_off + profile.ramp)])
    far = np.ones(t.size, bool) if edges.size == 0 else np.abs(t[:, None] - edges[None, :]).min(axis=1) >= EDGE_MARGIN
    estimate_errors = {}
    for name, log in (("joint", "joint_estimate"), ("observer", "estimate"), ("blend", "blended_estimate")):
        error = logs[log].data()[0] - applied_x
        for case, mask in (("pushed", walking & far & (np.abs(applied_x) > 1e-6)),
                           ("no_force", walking & far & (np.abs(applied_x) <= 1e-6))):
            e = error[mask]
            estimate_errors[f"{name}_{case}"] = ({"samples": int(e.size), "mean_N": float(e.mean()),
                                                  "std_N": float(e.std()), "max_abs_N": float(np.abs(e).max())}
                                                 if e.size else {"samples": 0})
    return {"episodes": episodes, "false_starts_s": false_starts, "estimate_errors_while_walking": estimate_errors,
            "steps_detected": len(steps), "fell": fell, "max_base_tilt_deg": float(tilt.max()),
            "max_abs_yaw_deg": float(np.abs(yaw).max()), "events": [(te, n, d) for te, n, d in controller.events],
            "segments_built": len(controller.plans) - 1,
            "signals": {"t": t, "com": com, "feet": feet.T, "estimate": logs["estimate"].data().T,
                        "joint_estimate": logs["joint_estimate"].data().T,
                        "blended_estimate": logs["blended_estimate"].data().T,
                        "applied": logs["applied"].data().T, "walking_state": logs["walking_state"].data().T,
                        "tilt": tilt}}


def plot(path: Path, m: dict, threshold: float) -> None:
    s = m["signals"]
    t = s["t"]
    applied_x = s["applied"][:, 0] + s["applied"][:, 3]
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True)
    ax = axes[0]
    ax.plot(t, applied_x, "--", color="tab:green", label="applied $F_x$ (both hands)")
    ax.plot(t, s["estimate"][:, 0], color="tab:blue", lw=0.8, alpha=0.6, label="estimated $F_x$ (observer, eq. 11)")
    ax.plot(t, s["joint_estimate"][:, 0], color="tab:orange", lw=0.8, label="estimated $F_x$ (arm joints, eqs. 25-27)")
    for sgn in (1, -1):
        ax.axhline(sgn * threshold, color="tab:red", ls=":", lw=0.8)
    ax.set_ylabel("$F_x$ [N]")
    ax.legend(fontsize=7)
    axes[1].plot(t, s["walking_state"][:, 0], color="k", lw=0.8, label="mode (0 stand, 1 walk, 2 stop)")
    axes[1].plot(t, s["walking_state"][:, 1], color="tab:purple", lw=0.8, label="direction")
    axes[1].legend(fontsize=7)
    axes[2].plot(t, s["com"][:, 0], color="tab:blue")
    axes[2].set_ylabel("CoM x [m]")
    for i, side in enumerate(("left", "right")):
        axes[3].plot(t, s["feet"][:, i], lw=0.7, label=f"{side} foot")
    axes[3].set_ylabel("normal force [N]")
    axes[3].set_xlabel("time [s]")
    axes[3].legend(fontsize=7)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(profile: GuidanceProfile, trigger: TriggerParameters, *, preset: str = "walking",
        force_rate_variance: float | None = None, noise: bool = True,
        seed: int = 0, duration: float | None = None, meshcat: Meshcat | None = None,
        trigger_source: str = DEFAULT_TRIGGER_SOURCE) -> dict:
    diagram, handles = build_force_guided_diagram(profile, trigger, preset=preset,
                                                  force_rate_variance=force_rate_variance, noise=noise, seed=seed,
                                                  meshcat=meshcat, trigger_source=trigger_source)
    simulator = Simulator(diagram)
    handles["station"].set_initial_state(simulator.get_mutable_context())
    if meshcat is not None:
        meshcat.SetCameraPose(camera_in_world=[0.3, -1.4, 0.6], target_in_world=[0.2, 0.0, 0.2])
        meshcat.StartRecording(frames_per_second=32.0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(duration if duration is not None else profile.end + 2.0)
    wall = time.perf_counter() - start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    m = guided_metrics(handles, simulator.get_context(), profile, trigger)
    m["wall_time_s"] = wall
    m["simulated_s"] = simulator.get_context().get_time()
    return m


def _parse(argv):
    parser = argparse.ArgumentParser(prog="python -m apps.nao_force_guided_walk", description=__doc__.split("\n\n")[0])
    parser.add_argument("--force", type=float, default=DEFAULT_FORCE,
                        help=f"total guidance force on the hands, N (default {DEFAULT_FORCE}; 0: no force, the "
                             "false-start check)")
    parser.add_argument("--trigger-source", choices=TRIGGER_SOURCES, default=DEFAULT_TRIGGER_SOURCE,
                        help="the trigger's input: the arm joints' hand force estimate (eqs. 25-27), the "
                             "observer's, or eq. 28's blend of the two with K1 = K_a / 8 "
                             f"(default {DEFAULT_TRIGGER_SOURCE})")
    parser.add_argument("--threshold", type=float, default=DEFAULT_THRESHOLD,
                        help=f"threshold on the estimated F_x, N (default {DEFAULT_THRESHOLD})")
    parser.add_argument("--preset", choices=("walking", "standing"), default=DEFAULT_PRESET,
                        help=f"observer covariances: eq. 22 (walking) or eq. 21 (standing; default {DEFAULT_PRESET})")
    parser.add_argument("--force-rate-variance", type=float, default=DEFAULT_FORCE_RATE_VARIANCE,
                        help="sigma^2 of the force's second derivative (eq. 17), (N/s^2)^2 "
                             f"(default {DEFAULT_FORCE_RATE_VARIANCE:g}; the paper's presets: 1e3)")
    parser.add_argument("--start-debounce", type=float, default=TriggerParameters().start_debounce, help="s")
    parser.add_argument("--stop-debounce", type=float, default=TriggerParameters().stop_debounce, help="s")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-noise", action="store_true")
    parser.add_argument("--out", type=Path, default=Path("out") / "nao_force_guided_walk")
    parser.add_argument("--headless", action="store_true")
    parser.add_argument("--no-replay", action="store_true")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    try:
        if args.seed < 0:
            raise ValueError(f"--seed must be non-negative, got {args.seed}")
        if not (args.force > args.threshold or args.force == 0.0):
            raise ValueError(f"--force ({args.force} N) must exceed --threshold ({args.threshold} N), or be 0")
        trigger = TriggerParameters(threshold=args.threshold, start_debounce=args.start_debounce,
                                    stop_debounce=args.stop_debounce)
        profile = GuidanceProfile(plateaus=tuple((t_on, t_off, sign * args.force) for t_on, t_off, sign in EPISODES)
                                  if args.force > 0 else ())
    except ValueError as error:
        print(f"nao_force_guided_walk: error: {error}", file=sys.stderr)
        return 2
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    meshcat = replay_meshcat(not args.no_replay, args.headless)
    source = {"joint": "the arm joints' hand force estimate",
              "observer": f"the observer's estimate ({args.preset} preset)",
              "blend": f"eq. 28's blend of the observer ({args.preset} preset) and the arm joints"}[args.trigger_source]
    print(f"guiding nao_like by the hands: {args.force} N forwards 1.5-5.5 s, backwards 7.5-10.5 s; threshold "
          f"{args.threshold} N on {source} ...", flush=True)
    m = run(profile, trigger, preset=args.preset, force_rate_variance=args.force_rate_variance, noise=not args.no_noise,
            seed=args.seed, meshcat=meshcat, trigger_source=args.trigger_source, duration=DURATION)
    if meshcat is not None:
        (out / "guided.html").write_text(meshcat.StaticHtml())
    plot(out / "guided.png", m, args.threshold)
    checks = {}
    for i, e in enumerate(m["episodes"]):
        checks[f"episode{i}_start_within_0.5s"] = e["start_ok"]
        checks[f"episode{i}_stop_within_one_step"] = e["stop_ok"]
        checks[f"episode{i}_moved_in_force_direction"] = e["moved_in_force_direction"]
    checks["no_false_start"] = not m["false_starts_s"]
    checks["no_fall"] = not m["fell"]
    summary = {k: v for k, v in m.items() if k != "signals"}
    summary.update(floors=checks, meets_floors=all(checks.values()), threshold_N=args.threshold, force_N=args.force,
                   trigger_source=args.trigger_source, preset=args.preset, noise=not args.no_noise, seed=args.seed,
                   walking_parameters=dataclasses.asdict(GUIDED_WALKING))
    (out / "metrics.json").write_text(json.dumps(summary, indent=2, default=float))
    def seconds(value) -> str:
        return "never" if value is None else f"{value:.3f} s"

    for i, e in enumerate(m["episodes"]):
        print(f"  episode {i} ({'forwards' if e['direction'] > 0 else 'backwards'}): start latency "
              f"{seconds(e['start_latency_s'])} (first lift-off {seconds(e['first_lift_off_latency_s'])}), "
              f"{e['steps_during']} steps, CoM x {e['com_x_displacement_m']:+.3f} m; after the drop: stop decided "
              f"+{seconds(e['stop_decision_latency_s'])}, "
              f"steps begun {e['steps_begun_after_drop']} (lift-offs {e['lift_offs_after_drop']}), last touch-down "
              f"+{e['last_touch_down_after_drop_s']:.2f} s")
    print(f"  false starts (no force on): {len(m['false_starts_s'])}")
    for name, err in m["estimate_errors_while_walking"].items():
        if err["samples"]:
            print(f"  F_x error while walking, {name}: mean {err['mean_N']:+.3f} N, std {err['std_N']:.3f} N, max "
                  f"|e| {err['max_abs_N']:.2f} N ({err['samples']} samples)")
    print(f"  {'upright' if not m['fell'] else 'FELL'} (max tilt {m['max_base_tilt_deg']:.1f} deg, max |yaw| "
          f"{m['max_abs_yaw_deg']:.1f} deg); {m['wall_time_s']:.1f} s wall for {m['simulated_s']:.1f} s; floors "
          f"{'met' if summary['meets_floors'] else 'MISSED: ' + ', '.join(k for k, v in checks.items() if not v)}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
