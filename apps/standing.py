"""Standing simulation of the humanoids under PD + gravity compensation.

Usage::

    python -m apps.standing [--scenario FILE] [--scenario-text YAML]
                         [--model hrp4_like|nao_like|all | --robot FILE.yaml] [--duration 10]
                         [--no-meshcat | --no-replay] [--headless] [--out DIR]

For each model of the scenario (``StandingScenario``; ``--model``, ``--robot`` and ``--duration`` override
its ``models`` and ``duration``): simulates ``duration`` seconds (1 ms discrete steps, SAP,
point contact), prints a table (base drift after the first second of settling, smallest foot
sphere normal force, feet flat, real-time factor), writes ``DIR/standing/<model>.json``,
``DIR/standing/metrics.json`` (every model and the scenario) and, with Meshcat on, a
self-contained replay ``DIR/standing/<model>.html``. Exits with status 1 if a robot falls.
"""

from __future__ import annotations

import sys

import numpy as np

from apps.runner import (
    experiment_parser,
    json_text,
    output_folder,
    replay_meshcat,
    run_app,
    save_replay,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.station.standing import (
    KD_STABILITY_MARGIN,
    StandingScenario,
    build_standing_diagram,
    check_standing_scenario,
    set_initial_state,
    standing_run_metrics,
)
from models import MODEL_NAMES, set_standing_state


def _parse(argv):
    parser = experiment_parser("apps.standing", __doc__, robot=True)
    parser.add_argument(
        "--model",
        choices=(*MODEL_NAMES, "all"),
        default=None,
        help="which humanoid to simulate (overrides the scenario's models, default: all)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        help="simulated time per model, s (overrides the scenario's, default: 10)",
    )
    parser.add_argument(
        "--no-meshcat",
        dest="no_replay",
        action="store_true",
        help="the same as --no-replay: no Meshcat (no live view, no HTML replay)",
    )
    args = parser.parse_args(argv)
    if args.duration is not None and args.duration <= 0:
        parser.error("--duration must be positive")
    return args


def run_model(scenario: StandingScenario, name: str, meshcat, *, live: bool = True) -> dict:
    """Simulates one model standing; returns its metrics (``standing_run_metrics``)."""
    diagram, handles = build_standing_diagram(
        name, plant_config=scenario.plant_config, meshcat=meshcat, state_log_period=scenario.state_log_period
    )
    # A three-quarter view framing the robot (Meshcat's default camera is far away): its
    # height taken as twice its centre of mass's, standing.
    plant = handles.plant
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles.humanoid)
    height = 2.0 * plant.CalcCenterOfMassPositionInWorld(context, [handles.humanoid.model_instance])[2]
    run = simulate(
        diagram,
        scenario.duration,
        set_initial_state=lambda context: set_initial_state(diagram, context, handles),
        simulator_config=scenario.simulator_config,
        meshcat=meshcat,
        live=live,
        camera=(np.array([1.1, -1.1, 0.8]) * height, np.array([0.0, 0.0, 0.5 * height])),
    )
    return standing_run_metrics(scenario, handles, run.context, run.wall_time_s)


def main(argv=None) -> int:
    """Runs the app; returns the process exit status (1 if a robot fell, 2 on an error)."""
    args = _parse(argv)

    def body() -> int:
        models = None if args.model is None else (list(MODEL_NAMES) if args.model == "all" else [args.model])
        scenario = scenario_from_args(StandingScenario, args, models=models, duration=args.duration)
        check_standing_scenario(scenario)  # every model read and checked before the first is simulated
        print("standing simulation of the humanoids (PD + gravity compensation)")
        out_dir = output_folder(args, "standing")
        meshcat = replay_meshcat(not args.no_replay, args.headless)

        rows = []
        for name in scenario.models:
            print(f"simulating {name} for {scenario.duration:g} s ...", flush=True)
            row = run_model(scenario, name, meshcat, live=not args.headless)
            (out_dir / f"{row['model']}.json").write_text(json_text(row))
            html = save_replay(meshcat, out_dir / f"{row['model']}.html")
            if html is not None:
                row["replay"] = str(html)
            rows.append(row)
        write_metrics(out_dir, {row["model"]: row for row in rows}, scenario, args)

        header = (
            f"{'model':<10} {'drift cm':>9} {'drift deg':>9} {'min F N':>8} {'feet flat':>9} {'RTF':>6} {'fell':>5}"
        )
        print(
            f"\nbase drift measured after the first {scenario.settle_time:g} s; "
            "min F = smallest foot-sphere normal force at the end"
        )
        print(header)
        print("-" * len(header))
        for r in rows:
            print(
                f"{r['model']:<10} {r['base_drift_cm']:9.3f} {r['base_drift_deg']:9.3f} "
                f"{r['min_sphere_force_N']:8.2f} {str(r['feet_flat']):>9} "
                f"{r['real_time_factor']:6.2f} {str(r['fell']):>5}"
            )
        for r in rows:
            if "replay" in r:
                print(f"replay: {r['replay']}")
        fell = [r["model"] for r in rows if r["fell"]]
        for r in rows:
            if not r["fell"] and r["feet_flat"]:
                continue
            # Why: which part touched the ground besides the feet, and gains the cap lowered.
            if r["first_unexpected_contact"] is not None:
                print(f"{r['model']}: {r['first_unexpected_contact']}")
            if r["stability_capped_gains"]:
                joints = ", ".join(
                    f"{j} (kd {g['kd_scaled']:.3g} -> {g['kd_cap']:.3g})"
                    for j, g in r["stability_capped_gains"].items()
                )
                print(
                    f"{r['model']}: the PD's stability cap (kd dt <= {KD_STABILITY_MARGIN} H_ii) lowered the gains of "
                    f"{joints}: give the description a rotor inertia for them (actuators.rotor_inertia) or gains"
                )
        if fell:
            print(f"FELL: {', '.join(fell)}", file=sys.stderr)
            return 1
        return 0

    return run_app("standing", body)


if __name__ == "__main__":
    sys.exit(main())
