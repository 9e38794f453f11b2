"""Compliant arms on the simulated Nao-like robot (Hawley, Rahem, Suleiman 2019, Sec. 6.4,
eqs. 25-29, Figs. 12-14).

Both hands are pushed backwards (-x) by the same force, put on with a 2 s quintic ramp,
held, and released; the arms yield as x_h = x_h^0 + F_x / k (eq. 29, k = 50 N/m), with F_x
the blend (eq. 28) of the Kalman observer (read as a force on the hands) and the joint-level
estimate from the arm's position errors (eqs. 25-27, K_m identified in simulation first).

* scenario a: standing (wide stance), all 8 FSRs loaded: K1 = 1, the observer drives eq. 29;
* scenario b: the robot first leans sideways (t = 0.5-2.5 s, both hip rolls -0.1 rad, ankle
  rolls +0.1 rad; ``--lean``): the soft ankles let both feet roll onto their -y edges, 2 of
  the 8 FSRs read below 1 N (K1 = 0.75), and 4 once the push also moves the CoP backwards
  (K1 = K_a / K_t = 0.5): the joint-level estimate takes half the weight. With ``--lean -0.2``
  one FSR saturates (25 N) and the observer's estimate degrades (the paper's "unreliable
  data from the FSR"); ``--saturation-guard`` (an extension of eq. 28) then sets K1 = 0.

Measured quantity: each hand's displacement along the torso's x axis, from the TRUE plant
state (torso-frame kinematics), relative to its mean over the second before the push. Its
mean over the last second of the hold is compared with F_true / k (the applied force in the
torso frame) and with F_est / k (the mean blended estimate that the controller used).

Floor (issue 7): hand displacement within 10 % of F / k in steady state, against the true
force and against the estimate.

Run: ``python -m apps.nao_compliant_arms [--out DIR] [--headless] [--seed N]
[--scenario a|b|all] [--force N] [--lean RAD] [--no-replay] [--saturation-guard]
[--no-deflection-compensation]``.
Writes to DIR (default ``out/nao_compliant_arms``): ``scenario_<s>.png`` (Fig. 14 style), ``scenario_<s>.html``
(Meshcat replay: red = applied forces, blue = blended estimate), ``metrics.json``.
"""

from __future__ import annotations

import argparse
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
from pydrake.geometry import Meshcat  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402

from apps.common import logged_signals, replay_meshcat  # noqa: E402
from systems.simulation.disturbances import SmoothPiecewise  # noqa: E402
from diagrams.observer.nao_compliant_arms import (  # noqa: E402
    build_nao_compliant_arms_diagram,
    hand_pushes,
    lean_posture,
)
from diagrams.observer.calibration import identified_motor_constants, settle_standing_state  # noqa: E402
from diagrams.observer.nao_force_observer import wide_stance  # noqa: E402
from systems.observer.arm_compliance import DEFAULT_STIFFNESS, NAO_ARM_CHAINS  # noqa: E402

#: Push per hand, N (along -x: towards the robot), and the schedule, s.
DEFAULT_FORCE = 1.5
PUSH_ON, PUSH_FULL, PUSH_OFF, PUSH_GONE, DURATION = 3.0, 5.0, 11.0, 13.0, 14.0
#: Steady-state window (last second of the hold) and the baseline window before the push.
STEADY_WINDOW = (PUSH_OFF - 1.0, PUSH_OFF)
BASELINE_WINDOW = (PUSH_ON - 1.0, PUSH_ON)
#: Scenario b's lean: knots (s) and hip-roll angle (rad).
LEAN_START, LEAN_END, LEAN_ANGLE = 0.5, 2.5, -0.1
#: Floor: relative error of the steady-state hand displacement vs F / k.
DISPLACEMENT_FLOOR = 0.10
SIDES = tuple(c.side for c in NAO_ARM_CHAINS)


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    force: float
    lean: float | None

    def pushes(self):
        profile = SmoothPiecewise((0.0, PUSH_ON, PUSH_FULL, PUSH_OFF, PUSH_GONE),
                                  (0.0, 0.0, self.force, self.force, 0.0))
        return hand_pushes(profile, direction=(-1.0, 0.0, 0.0))

    def posture_knots(self):
        if self.lean is None:
            return ()
        return ((LEAN_START, wide_stance()), (LEAN_END, lean_posture(self.lean)))


def make_scenario(name: str, force: float = DEFAULT_FORCE, lean: float = LEAN_ANGLE) -> Scenario:
    """Scenario ``name`` ("a" or "b") with ``force`` N per hand; ``lean`` is b's hip-roll
    lean, rad (``diagrams.observer.nao_compliant_arms.lean_posture``)."""
    if name not in ("a", "b"):
        raise ValueError(f"unknown scenario {name!r}; choose a or b")
    if not (math.isfinite(force) and 0.0 < force <= 4.0):
        raise ValueError(f"force must be in (0, 4] N per hand (arm effort limits), got {force}")
    if not (math.isfinite(lean) and abs(lean) <= 0.3):
        raise ValueError(f"lean must be within +-0.3 rad (joint limits), got {lean}")
    if name == "a":
        return Scenario("a", f"a: {force:g} N per hand along -x, standing (all FSRs loaded)", force, None)
    return Scenario("b", f"b: {force:g} N per hand along -x while leaning {lean:g} rad (feet partly off)", force, lean)


def simulate(scenario: Scenario, *, seed: int = 0, meshcat: Meshcat | None = None, noise: bool = True,
             compensate_deflection: bool = True, saturation_guard: bool = False) -> dict:
    """Runs a scenario from the settled wide stance; returns logs, handles and wall time.
    (The FSRs read zero at t = 0, before the plant's first step: K1 is 0 at that sample.)"""
    if meshcat is not None:
        meshcat.Delete()
        meshcat.DeleteRecording()
    diagram, handles = build_nao_compliant_arms_diagram(
        scenario.pushes(), posture_knots=scenario.posture_knots(), noise=noise, seed=seed,
        motor_constants=dict(identified_motor_constants()), compensate_deflection=compensate_deflection,
        saturation_guard=saturation_guard,
        meshcat=meshcat)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.set_initial_state(context, settle_standing_state(wide_stance()))
    if meshcat is not None:
        meshcat.SetCameraPose(camera_in_world=[0.8, -0.8, 0.5], target_in_world=[0.0, 0.0, 0.25])
        meshcat.StartRecording(frames_per_second=32.0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(DURATION)
    wall = time.perf_counter() - start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    signals = logged_signals(handles.loggers, context, "state")
    return {"signals": signals, "handles": handles, "wall": wall}


def true_hand_kinematics(run: dict) -> tuple[np.ndarray, np.ndarray]:
    """From the TRUE state log: (samples, 3 per hand) hand positions in the torso frame B, m,
    and (samples, 3, 3) R_WB."""
    handles = run["handles"]
    plant = handles.station.plant
    base = handles.station.humanoid.base_body.body_frame()
    frames = [plant.GetBodyByName(c.hand_body).body_frame() for c in NAO_ARM_CHAINS]
    points = [np.asarray(c.p_HP, float) for c in NAO_ARM_CHAINS]
    ctx = plant.CreateDefaultContext()
    X = run["signals"]["state"].T
    nq = plant.num_positions()
    p = np.empty((len(X), 3 * len(frames)))
    R = np.empty((len(X), 3, 3))
    for i, x in enumerate(X):
        plant.SetPositions(ctx, x[:nq])
        for j, (frame, point) in enumerate(zip(frames, points)):
            p[i, 3 * j: 3 * j + 3] = plant.CalcPointsPositions(ctx, frame, point, base).reshape(-1)
        R[i] = base.CalcRotationMatrixInWorld(ctx).matrix()
    return p, R


def _to_base(forces_W: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(samples, 3 per hand) world forces -> torso frame, with R (samples, 3, 3) = R_WB."""
    F = forces_W.reshape(len(forces_W), -1, 3)
    return np.einsum("nji,nkj->nki", R, F).reshape(len(forces_W), -1)


def scenario_metrics(scenario: Scenario, run: dict, stiffness: float = DEFAULT_STIFFNESS) -> dict:
    s = run["signals"]
    t = s["t"]
    p, R = true_hand_kinematics(run)
    base = (t >= BASELINE_WINDOW[0]) & (t < BASELINE_WINDOW[1])
    steady = (t >= STEADY_WINDOW[0]) & (t < STEADY_WINDOW[1])
    hold = (t >= PUSH_FULL) & (t < PUSH_OFF)
    dx = p - p[base].mean(axis=0)
    F_true = _to_base(s["force_world"].T, R)
    estimates = {name: _to_base(s[name].T, R) for name in ("observer_force", "joint_force", "blended_force")}
    hands = {}
    worst_true, worst_est = 0.0, 0.0
    for j, side in enumerate(SIDES):
        x = 3 * j
        disp = float(dx[steady, x].mean())
        f_true = float(F_true[steady, x].mean())
        f_est = float(estimates["blended_force"][steady, x].mean())
        rel_true = abs(disp - f_true / stiffness) / abs(f_true / stiffness)
        rel_est = abs(disp - f_est / stiffness) / abs(f_est / stiffness)
        worst_true, worst_est = max(worst_true, rel_true), max(worst_est, rel_est)
        errors = {}
        for name, F in estimates.items():
            e = F[:, x] - F_true[:, x]
            errors[name] = {"steady_state_mean_error_N": float(e[steady].mean()),
                            "hold_rms_error_N": float(np.sqrt(np.mean(e[hold] ** 2)))}
        hands[side] = {
            "displacement_m": disp,
            "F_true_x_N": f_true,
            "F_est_x_N": f_est,
            "F_true_over_k_m": f_true / stiffness,
            "F_est_over_k_m": f_est / stiffness,
            "relative_error_vs_true": rel_true,
            "relative_error_vs_estimate": rel_est,
            "estimate_errors_x": errors,
        }
    k1 = s["k1"][0]
    fsr = s["fsr_forces"]
    handles = run["handles"]
    x = s["state"]
    z_base = x[handles.station.humanoid.base_body.floating_positions_start() + 6]
    return {
        "title": scenario.title,
        "force_per_hand_N": scenario.force,
        "stiffness_N_per_m": stiffness,
        "steady_window_s": list(STEADY_WINDOW),
        "hands": hands,
        "worst_relative_error_vs_true": worst_true,
        "worst_relative_error_vs_estimate": worst_est,
        "floor_relative_error": DISPLACEMENT_FLOOR,
        "meets_floor": bool(worst_true <= DISPLACEMENT_FLOOR and worst_est <= DISPLACEMENT_FLOOR),
        "k1_steady_mean": float(k1[steady].mean()),
        "k1_min_after_first_step": float(k1[t >= 0.05].min()),
        "k1_before_push_mean": float(k1[base].mean()),
        "fsr_steady_mean_N": fsr[:, steady].mean(axis=1).tolist(),
        "fsr_saturated_samples": int(np.sum(np.any(fsr >= handles.fsr_array.saturation - 1e-9, axis=0))),
        "base_height_drop_m": float(z_base[0] - z_base.min()),
        "wall_time_s": run["wall"],
        "real_time_factor": DURATION / run["wall"],
        "_series": {"t": t, "dx": dx, "F_true": F_true, **estimates, "k1": k1},
    }


def plot_scenario(path: Path, scenario: Scenario, metrics: dict) -> None:
    """Fig. 14 style: hand displacement with F/k, the estimated forces, and K1."""
    d = metrics["_series"]
    t, k = d["t"], metrics["stiffness_N_per_m"]
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.3]})
    colors = {"left": "tab:blue", "right": "tab:orange"}
    for j, side in enumerate(SIDES):
        x = 3 * j
        axes[0].plot(t, 100 * d["dx"][:, x], color=colors[side], lw=2.6 if side == "left" else 1.2,
                     alpha=0.6 if side == "left" else 1.0, label=f"{side} hand displacement (true)")
    axes[0].plot(t, 100 * d["F_true"][:, 0] / k, "--", color="tab:green", lw=1.5, label="F_true / k")
    axes[0].plot(t, 100 * d["blended_force"][:, 0] / k, ":", color="k", lw=1.3, label="F_est / k (left)")
    axes[0].set_ylabel("x_h - x_h^0 [cm]")
    axes[0].legend(fontsize=8, loc="lower left")
    axes[0].set_title(scenario.title, fontsize=10)
    axes[1].plot(t, d["F_true"][:, 0], "--", color="tab:green", lw=1.5, label="true (per hand)")
    axes[1].plot(t, d["observer_force"][:, 0], color="tab:purple", lw=2.4, alpha=0.6,
                 label="observer (eq. 11 inverted)")
    axes[1].plot(t, d["joint_force"][:, 0], color="tab:red", lw=1.0, label="joint level (eqs. 25-27)")
    axes[1].plot(t, d["blended_force"][:, 0], color="k", lw=1.3, label="blended (eq. 28)")
    axes[1].set_ylabel("F_x, left hand [N]")
    axes[1].legend(fontsize=8, loc="lower left")
    axes[2].plot(t, d["k1"], color="tab:gray")
    axes[2].set_ylim(-0.05, 1.05)
    axes[2].set_ylabel("K1")
    axes[2].set_xlabel("time [s] (grey: steady-state window)")
    for ax in axes:
        ax.axvspan(*STEADY_WINDOW, color="0.92", zorder=0)
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _parse(argv):
    parser = argparse.ArgumentParser(prog="python -m apps.nao_compliant_arms", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out") / "nao_compliant_arms",
                        help="output folder (default out/nao_compliant_arms)")
    parser.add_argument("--headless", action="store_true", help="no live Meshcat URL (the replays are still written)")
    parser.add_argument("--seed", type=int, default=0, help="sensor noise seed (default 0)")
    parser.add_argument("--scenario", choices=("a", "b", "all"), default="all", help="which scenario (default all)")
    parser.add_argument("--force", type=float, default=DEFAULT_FORCE,
                        help=f"push per hand, N (default {DEFAULT_FORCE:g})")
    parser.add_argument("--lean", type=float, default=LEAN_ANGLE,
                        help=f"scenario b's hip-roll lean, rad (default {LEAN_ANGLE:g}; -0.2 saturates an FSR)")
    parser.add_argument("--no-replay", action="store_true", help="skip the Meshcat replays (faster)")
    parser.add_argument("--saturation-guard", action="store_true",
                        help="extension of eq. 28: K1 = 0 while an FSR saturates (25 N)")
    parser.add_argument("--no-deflection-compensation", action="store_true",
                        help="ablation: command eq. 29's IK solution without the K_m^-1 J^T F offset")
    return parser.parse_args(argv)


def _print_table(metrics: dict) -> None:
    print(f"{'scenario':<12}{'hand':<7}{'dx [cm]':>9}{'Ftrue/k':>9}{'Fest/k':>9}{'err true':>10}{'err est':>9}"
          f"{'K1':>6}{'floor':>8}{'RTF':>6}")
    for key, m in metrics.items():
        for side, h in m["hands"].items():
            print(f"{key:<12}{side:<7}{100 * h['displacement_m']:>9.3f}{100 * h['F_true_over_k_m']:>9.3f}"
                  f"{100 * h['F_est_over_k_m']:>9.3f}{100 * h['relative_error_vs_true']:>9.1f}%"
                  f"{100 * h['relative_error_vs_estimate']:>8.1f}%{m['k1_steady_mean']:>6.2f}"
                  f"{'met' if m['meets_floor'] else 'MISSED':>8}{m['real_time_factor']:>6.2f}")
    print(f"floor: steady-state hand displacement within {100 * DISPLACEMENT_FLOOR:g} % of F/k "
          "(against the true force and against the estimate)")


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    names = ("a", "b") if args.scenario == "all" else (args.scenario,)
    try:
        if args.seed < 0:
            raise ValueError(f"--seed must be a non-negative integer, got {args.seed}")
        scenarios = [make_scenario(n, args.force, args.lean) for n in names]
    except ValueError as error:
        print(f"nao_compliant_arms: error: {error}", file=sys.stderr)
        return 2
    out_dir = args.out
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    km = dict(identified_motor_constants())
    print(f"K_m identified (static loads on the hands, {time.perf_counter() - start:.1f} s): "
          + ", ".join(f"{n} {v:.3f}" for n, v in km.items()) + " N m/rad")
    meshcat = replay_meshcat(not args.no_replay, args.headless)
    metrics = {}
    for scenario in scenarios:
        print(f"scenario {scenario.title}: {DURATION:g} s simulated ...", flush=True)
        run = simulate(scenario, seed=args.seed, meshcat=meshcat,
                       compensate_deflection=not args.no_deflection_compensation,
                       saturation_guard=args.saturation_guard)
        key = f"scenario_{scenario.name}"
        if meshcat is not None:
            (out_dir / f"{key}.html").write_text(meshcat.StaticHtml())
        m = scenario_metrics(scenario, run)
        plot_scenario(out_dir / f"{key}.png", scenario, m)
        m.pop("_series")
        metrics[key] = m
    summary = {
        "all_floors_met": all(m["meets_floor"] for m in metrics.values()),
        "seed": args.seed,
        "motor_constants_N_m_per_rad": km,
        "controller": "eq. 29 with k = 50 N/m, damped least-squares arm IK, "
                      + ("no deflection compensation (ablation)" if args.no_deflection_compensation
                         else "deflection compensation K_m^-1 J^T F"),
        "deflection_compensation": not args.no_deflection_compensation,
        "blend": "eq. 28, K1 = K_a / 8, FSR in contact above 1 N",
        "lean_rad": args.lean,
        "saturation_guard": args.saturation_guard,
    }
    (out_dir / "metrics.json").write_text(json.dumps({**metrics, "summary": summary}, indent=2))
    _print_table(metrics)
    print(f"wrote {out_dir}: " + ", ".join(sorted(p.name for p in out_dir.iterdir())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
