"""The Nao-like robot walks straight on flat ground: ZMP preview control (Kajita 2003) on the
cart-table model, swing-foot trajectories and analytic leg IK give joint targets that the
station's joint PD tracks (position control, as on Nao). Issue 7, item 1.

Floors (issue 7): >= 20 steps and >= 1 m forward at a mean speed >= 0.08 m/s without falling.
Definitions (``diagrams.locomotion.nao_walk.walking_metrics``): distance = CoM x displacement over the
run; mean speed = CoM x displacement from the first step's start to one step after the last
touch-down, divided by that time; steps = touch-downs after lift-offs in the contact forces;
fall = base tilt > 30 deg or base height < 70 % of its initial value; ZMP in support = the
ZMP from the contact forces inside the convex hull of the contact spheres of the feet that
the plan has on the ground (at their actual poses).

Run: ``python -m apps.nao_walk [--scenario FILE] [--scenario-text YAML] [--steps N]
[--step-length L] [--step-duration T] [--double-support-ratio R] [--swing-height H]
[--com-height Z] [--zmp-correction-passes K] [--noise] [--seed S] [--out DIR] [--headless]
[--no-replay]``: the scenario is ``diagrams.locomotion.nao_walk.NaoWalkScenario``
(``apps/scenarios/nao_walk_default.yaml`` lists every field); the shorthand options override
its fields. Writes to ``DIR/nao_walk/`` (default ``out/nao_walk/``): ``metrics.json``,
``walk_top.png`` (top view: footprints, ZMP, CoM), ``walk_time.png`` (x / y of ZMP and CoM vs
their references, foot normal forces, base tilt) and ``walk.html`` (self-contained Meshcat
replay).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

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
from diagrams.locomotion.nao_walk import NaoWalkScenario, build_nao_walk_diagram, nao_walk_metrics


def run_scenario(scenario: NaoWalkScenario, meshcat=None, *, live: bool = True) -> dict:
    """Builds the walking diagram, runs the whole pattern; returns the handles and the
    metrics (``nao_walk_metrics``, with their signals)."""
    diagram, handles = build_nao_walk_diagram(scenario, meshcat=meshcat)
    run = simulate(
        diagram,
        handles.controller.duration,
        set_initial_state=handles.set_initial_state,
        simulator_config=scenario.simulator_config,
        meshcat=meshcat,
        live=live,
        camera=([0.6, -1.2, 0.6], [0.4, 0.0, 0.2]),
    )
    return {"handles": handles, "metrics": nao_walk_metrics(scenario, handles, run.context, run.wall_time_s)}


def plot_top(path: Path, run: dict) -> None:
    """Top view: planned footprints (grey), the support polygons, ZMP (measured, reference),
    CoM (reference, actual)."""
    s = run["metrics"]["signals"]
    controller = run["handles"].controller
    humanoid = run["handles"].station.humanoid
    fig, ax = plt.subplots(figsize=(12, 4.2))
    fsr = {side: humanoid.fsr_positions[side] for side in ("left", "right")}
    order = [0, 1, 3, 2, 0]  # front_left, front_right, rear_right, rear_left
    prints = [
        (side, p)
        for side, p in (("left", controller.pattern.soles["left"][0]), ("right", controller.pattern.soles["right"][0]))
    ]
    prints += [(step.side, step.end) for step in controller.pattern.steps]
    for side, p in prints:
        corners = fsr[side][order] + p[:2]
        ax.plot(corners[:, 0], corners[:, 1], color="0.6", lw=0.8)
    ax.plot(s["zmp"][:, 0], s["zmp"][:, 1], color="tab:red", lw=0.6, alpha=0.8, label="ZMP (contact forces)")
    ax.plot(s["zmp_reference"][:, 0], s["zmp_reference"][:, 1], "--", color="k", lw=0.8, label="ZMP reference")
    ax.plot(s["com_reference"][:, 0], s["com_reference"][:, 1], color="tab:green", lw=1.2, label="CoM reference")
    ax.plot(s["com"][:, 0], s["com"][:, 1], ":", color="tab:blue", lw=1.5, label="CoM (simulated)")
    ax.set_aspect("equal")
    ax.set_ylim(-0.16, 0.12)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7, loc="lower left", ncol=4)
    ax.set_title("nao_like walking: footprints (FSR polygons), ZMP and CoM", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _parse(argv):
    parser = experiment_parser("apps.nao_walk", __doc__)
    parser.add_argument("--steps", type=int, default=None, help="number of steps (walking.num_steps)")
    parser.add_argument("--step-length", type=float, default=None, help="m (walking.step_length)")
    parser.add_argument("--step-duration", type=float, default=None, help="s (walking.step_duration)")
    parser.add_argument("--double-support-ratio", type=float, default=None, help="(walking.double_support_ratio)")
    parser.add_argument("--swing-height", type=float, default=None, help="m (walking.swing_height)")
    parser.add_argument("--com-height", type=float, default=None, help="m (walking.com_height)")
    parser.add_argument(
        "--zmp-correction-passes",
        type=int,
        default=None,
        help="passes of the multibody ZMP correction (Kajita 2003; 0 = cart-table only; default 1)",
    )
    parser.add_argument("--noise", action="store_true", help="sensor noise on (the PD reads the noisy sensed state)")
    parser.add_argument("--seed", type=int, default=None, help="noise seed (default 0)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        scenario = scenario_from_args(
            NaoWalkScenario,
            args,
            zmp_correction_passes=args.zmp_correction_passes,
            noise=True if args.noise else None,
            seed=args.seed,
        )
        scenario.walking = replace_fields(
            scenario.walking,
            num_steps=args.steps,
            step_length=args.step_length,
            step_duration=args.step_duration,
            double_support_ratio=args.double_support_ratio,
            swing_height=args.swing_height,
            com_height=args.com_height,
        )
        scenario.check()
        out = output_folder(args, "nao_walk")
        meshcat = replay_meshcat(not args.no_replay, args.headless)
        params = scenario.walking
        print(
            f"walking {params.num_steps} steps of {params.step_length} m, {params.step_duration} s each "
            f"({params.duration:.1f} s simulated) ...",
            flush=True,
        )
        run = run_scenario(scenario, meshcat, live=not args.headless)
        m = run["metrics"]
        save_replay(meshcat, out / "walk.html")
        plot_top(out / "walk_top.png", run)
        plot_walking_time(out / "walk_time.png", run)
        write_metrics(out, {k: v for k, v in m.items() if k != "signals"}, scenario, args)
        checks = m["floors"]
        print(
            f"  distance {m['distance_m']:.3f} m, mean speed {m['mean_speed_mps']:.3f} m/s, steps "
            f"{m['steps_detected']}/{m['steps_planned']}, {'upright' if m['upright'] else 'FELL'} (max tilt "
            f"{m['max_base_tilt_deg']:.1f} deg), ZMP in support {100 * m['zmp_in_support_fraction']:.1f} % "
            f"(5th-percentile margin {1000 * m['zmp_margin_p05_m']:.1f} mm; in the loaded feet's polygon "
            f"{1000 * m['zmp_loaded_margin_p05_m']:.1f} mm)"
        )
        print(
            f"  {m['wall_time_s']:.1f} s wall (real-time factor {m['real_time_factor']:.2f}); floors "
            f"{'met' if m['meets_floors'] else 'MISSED: ' + ', '.join(k for k, v in checks.items() if not v)}"
        )
        print_written(out)
        return 0

    return run_app("nao_walk", body)


if __name__ == "__main__":
    raise SystemExit(main())
