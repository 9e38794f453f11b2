"""Experiment 4 of Hawley et al. (2019), Sec. 6.3 (Figs. 9-11), in simulation: nao_like walks
forward, a cable tied to its waist tightens over a pulley, lifts a 0.3 kg mass and pulls the
robot backwards by ~3 N at ~5 deg from the x axis; the Kalman force observer (WALKING
preset, eq. 22) estimates the pull from the FSRs, IMU and encoders. Issue 7, item 2.

Floors (issue 7): walking >= 20 steps and >= 1 m forward at a mean speed >= 0.08 m/s
without falling WITH the pull (definitions: ``apps.nao_walk``); while the mass hangs and the
robot walks steadily (from 1 s after the load leaves the ground to the last planned
touch-down), the mean estimated F_x within 0.5 N of the true pull (the cable force's x
component, mean over the same samples) and the RMS error (sample by sample) <= 1.5 N. The
virtual force of eq. 11 (what the LIP observer estimates by construction) is reported too.

Run: ``python -m apps.nao_walk_pulled [--scenario FILE] [--scenario-text YAML] [--steps N]
[--seed S] [--no-noise] [--no-pull] [--tighten-distance D] [--out DIR] [--headless]
[--no-replay]``: the scenario is ``diagrams.observer.nao_walk_pulled.NaoWalkPulledScenario``
(``apps/scenarios/nao_walk_pulled_default.yaml`` lists every field); the shorthand options
override its fields (``--steps`` without ``--tighten-distance`` scales the cable's
``tighten_distance`` by the number of steps, keeping its share of the walk). Writes to
``DIR/nao_walk_pulled/`` (default ``out/nao_walk_pulled/``): ``metrics.json`` (walking and
observer metrics, floors), ``force_xy.png`` / ``force_z.png`` (Fig. 10 a/b: estimated F_x,
F_y, F_z vs the pull and the virtual force), ``normal_force.png`` (Fig. 11: f_n^o),
``load.png`` (tension and load height), ``walk_time.png`` (ZMP/CoM, foot forces, tilt/yaw)
and ``walk_pulled.html`` (self-contained Meshcat replay: the robot, the cable force in red,
the estimate in blue).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
from pydrake.geometry import Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform

from apps.common import plot_walking_time
from apps.runner import (
    experiment_parser,
    output_folder,
    print_written,
    replace_fields,
    replay_meshcat,
    run_app,
    save_replay,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.observer.nao_walk_pulled import (
    NaoWalkPulledScenario,
    build_nao_walk_pulled_diagram,
    nao_walk_pulled_metrics,
)
from systems.locomotion.walking_pattern import WalkingParameters


def run_scenario(scenario: NaoWalkPulledScenario, meshcat: Meshcat | None = None, *, live: bool = True) -> dict:
    """Builds the diagram, runs the whole pattern; returns the handles and the metrics
    (``nao_walk_pulled_metrics``, with their signals)."""
    diagram, handles = build_nao_walk_pulled_diagram(scenario, meshcat=meshcat)

    def set_initial_state(root_context) -> None:
        handles.set_initial_state(root_context)
        if meshcat is not None and handles.cable is not None:  # the pulley (drawn once)
            meshcat.SetObject("pulley", Sphere(0.02), Rgba(0.2, 0.2, 0.2, 1.0))
            meshcat.SetTransform("pulley", RigidTransform(handles.cable.pulley))

    run = simulate(
        diagram,
        handles.controller.duration,
        set_initial_state=set_initial_state,
        simulator_config=scenario.simulator_config,
        meshcat=meshcat,
        live=live,
        camera=([0.2, -1.6, 0.7], [0.2, 0.0, 0.2]),
    )
    return {"handles": handles, **nao_walk_pulled_metrics(scenario, handles, run.context, run.wall_time_s)}


def _shade(ax, o: dict) -> None:
    s = o["signals"]
    window = o["window_mask"]
    if window.any():
        t = s["t"]
        ax.axvspan(t[window][0], t[window][-1], color="tab:green", alpha=0.07, lw=0)


def plot_forces(out: Path, run: dict) -> None:
    """Fig. 10 (a) F_x, F_y and (b) F_z: estimate vs the cable pull and eq. 11's virtual force."""
    o = run["observer"]
    s = o["signals"]
    t = s["t"]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for i, (ax, axis) in enumerate(zip(axes, "xy")):
        ax.plot(t, s["estimate"][:, i], color="tab:blue", lw=0.8, label=f"estimated $F_{axis}$")
        ax.plot(t, s["pull"][:, i], "--", color="tab:green", lw=1.2, label=f"cable pull $F_{axis}$ (truth)")
        ax.plot(t, s["virtual_truth"][:, i], ":", color="k", lw=0.8, label="virtual force (eq. 11)")
        ax.set_ylabel(f"$F_{axis}$ [N]")
        ax.grid(True, alpha=0.3)
        _shade(ax, o)
    axes[0].legend(fontsize=7, ncol=3)
    axes[0].set_title("Exp. 4: walking while pulled (shaded: evaluation window, load hanging)", fontsize=10)
    axes[1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(out / "force_xy.png", dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(t, s["estimate"][:, 2], color="tab:blue", lw=0.8, label="estimated $F_z$")
    ax.plot(t, s["pull"][:, 2], "--", color="tab:green", lw=1.2, label="cable pull $F_z$ (truth)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("$F_z$ [N]")
    ax.grid(True, alpha=0.3)
    _shade(ax, o)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "force_z.png", dpi=110)
    plt.close(fig)


def plot_normal_force(out: Path, run: dict) -> None:
    """Fig. 11: f_n^o = -(sum of the 8 FSR readings)."""
    o = run["observer"]
    s = o["signals"]
    mass = run["handles"].parameters.mass
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(s["t"], s["normal_force"], color="tab:purple", lw=0.8, label="$f_n^o$ (FSRs)")
    ax.axhline(-mass * 9.81, color="k", ls="--", lw=0.8, label="$-M g$")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("normal force [N]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "normal_force.png", dpi=110)
    plt.close(fig)


def plot_load(out: Path, run: dict) -> None:
    s = run["observer"]["signals"]
    if "tension" not in s:
        return
    fig, axes = plt.subplots(2, 1, figsize=(10, 4.5), sharex=True)
    axes[0].plot(s["t"], s["tension"], color="tab:red", lw=0.8)
    axes[0].set_ylabel("tension [N]")
    axes[1].plot(s["t"], s["load_height"], color="tab:brown", lw=0.8)
    axes[1].set_ylabel("load height [m]")
    axes[1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "load.png", dpi=110)
    plt.close(fig)


def _parse(argv):
    parser = experiment_parser("apps.nao_walk_pulled", __doc__)
    parser.add_argument("--steps", type=int, default=None, help="number of steps (walking.num_steps, default 22)")
    parser.add_argument("--seed", type=int, default=None, help="noise seed (default 0)")
    parser.add_argument("--no-noise", action="store_true", help="ideal sensors (default: the sensors' noise on)")
    parser.add_argument("--no-pull", action="store_true", help="walk without the cable (observer bias while walking)")
    parser.add_argument(
        "--tighten-distance",
        type=float,
        default=None,
        help="torso travel before the line is taut, m (cable.tighten_distance; default: the "
        "scenario's, scaled to --steps)",
    )
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        scenario = scenario_from_args(
            NaoWalkPulledScenario,
            args,
            seed=args.seed,
            noise=False if args.no_noise else None,
            pull=False if args.no_pull else None,
        )
        tighten = args.tighten_distance
        if tighten is None and args.steps is not None:  # keep the cable's share of the walk before the line is taut
            tighten = scenario.cable.tighten_distance * (args.steps - 1) / (WalkingParameters().num_steps - 1)
        scenario.walking = replace_fields(scenario.walking, num_steps=args.steps)
        scenario.cable = replace_fields(scenario.cable, tighten_distance=tighten)
        scenario.check()
        out = output_folder(args, "nao_walk_pulled")
        meshcat = replay_meshcat(not args.no_replay, args.headless)
        params, pull = scenario.walking, scenario.pull
        print(
            f"walking {params.num_steps} steps of {params.step_length} m ({params.duration:.1f} s simulated)"
            f"{' pulled by a 0.3 kg load over a pulley' if pull else ' without the cable'} ...",
            flush=True,
        )
        run = run_scenario(scenario, meshcat, live=not args.headless)
        save_replay(meshcat, out / "walk_pulled.html")
        plot_forces(out, run)
        plot_normal_force(out, run)
        plot_load(out, run)
        plot_walking_time(out / "walk_time.png", {"metrics": run["walking"]})
        summary = {k: v for k, v in run.items() if k != "handles"}
        w = summary["walking"] = {k: v for k, v in run["walking"].items() if k != "signals"}
        o = summary["observer"] = {k: v for k, v in run["observer"].items() if k not in ("signals", "window_mask")}
        write_metrics(out, summary, scenario, args)
        checks = summary["floors"]
        print(
            f"  walk: {w['steps_detected']}/{w['steps_planned']} steps, {w['distance_m']:.3f} m, mean speed "
            f"{w['mean_speed_mps']:.3f} m/s, {'upright' if w['upright'] else 'FELL'} (max tilt "
            f"{w['max_base_tilt_deg']:.1f} deg, max |yaw| {w['max_abs_yaw_deg']:.1f} deg)"
        )
        if pull and o.get("window_samples", 0):
            print(
                f"  load lifted at {o['measured_lift_time_s']:.2f} s (up to {o['max_load_height_m']:.3f} m); window "
                f"{o['window_s'][0]:.2f}-{o['window_s'][1]:.2f} s: pull F_x {o['true_pull_x_mean_N']:.3f} N "
                f"(virtual {o['true_virtual_x_mean_N']:.3f} N), estimated {o['estimated_x_mean_N']:.3f} N "
                f"(mean error {o['mean_error_x_N']:+.3f} N, RMS {o['rms_error_x_N']:.3f} N); F_y "
                f"{o['true_pull_y_mean_N']:.3f} vs {o['estimated_y_mean_N']:.3f} N; F_z {o['true_pull_z_mean_N']:.3f} "
                f"vs {o['estimated_z_mean_N']:.3f} N"
            )
        print(
            f"  {summary['wall_time_s']:.1f} s wall (real-time factor {summary['real_time_factor']:.2f}); floors "
            f"{'met' if summary['meets_floors'] else 'MISSED: ' + ', '.join(k for k, v in checks.items() if not v)}"
        )
        print_written(out)
        return 0

    return run_app("nao_walk_pulled", body)


if __name__ == "__main__":
    raise SystemExit(main())
