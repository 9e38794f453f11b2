"""Push and comply as the paper ran it, each of the project's changes one at a time, and on
several robots (issue 31). Writes the results files docs/push-and-comply.md's tables are generated from.

``--study ablation``: Flacco et al. (2016) Sec. IV as published, then the project's changes
added one at a time, with both residuals, in the ideal and the realistic world:

1. *paper*: 5 N on each shoulder, eq. (14) as printed (q_d = q + K_a r T, ``integrate_from:
   measured``), no closed-chain projection, no centre-of-mass hold, no dead band;
2. *+ 20 N*: the project's push (the paper's 5 N is within the realistic residual's noise);
3. *+ posture integration*: q_d integrates K_a r from the desired posture (the PD keeps its
   stiffness);
4. *+ closed-chain projection*: leg rates that keep both soles still;
5. *+ CoM hold*: rates that also keep the estimators' centre of mass over the feet;
6. *+ dead band*: the admittance ignores residuals within its dead band (0.02 N m, and 2
   standard deviations of the calibrated residual noise in the realistic world);
7. *+ residual tare*: the residual's offset at rest, averaged over the first 2 s while the
   robot stands untouched, is removed (``ResidualTare``);
8. *+ residual gain 5/s*: the residual's bandwidth K from the contact detector's 35/s (the
   rows above; the paper gives none) down to the push's band (eq. 14 integrates r; the
   noise above the band only widens the dead band): the project's default
   (``apps/scenarios/push_and_comply_default.yaml``).

``--study robots``: the project's default in the realistic world on robots drawn with several
imperfection seeds (model mismatch, friction, sensor errors; each its own calibration) and on
TALOS and Romeo (``models/robots/talos.yaml``, ``romeo.yaml``).

``--study sensing``: the project's default on robots whose feet have F/T sensors, FSRs or
no sensing (issue 36; ``SENSING_ROBOTS``): the soles' unknown wrenches estimated and removed
from the residual (``SoleWrenchCompensation``) where no F/T sensor measures them, in both
worlds (the realistic world's base-state EKF flags contact from the F/T sensors, the FSRs,
or without either from the soles' wrenches estimated from the residuals).

Run: ``python -m apps.push_and_comply_study --study ablation|robots|sensing [--worlds ideal realistic]
[--engine E] [--workers N] [--cluster ADDRESS] [--duration S] [--results-folder DIR] [--out DIR]``
(the runs go to the workers of ``apps.engine``: Ray actors here by default). Writes
``results/push_and_comply_<study>.json`` (``--results-folder``: elsewhere) and prints the
table; the calibrations are cached in ``DIR/calibration_cache/`` as the other apps do.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from apps.engine import add_engine_arguments, engine_from_args, open_engine
from apps.results import app_command, write_results
from apps.runner import (
    add_out_argument,
    calibration_cache_folder,
    logged_signals,
    positive_float,
    run_app,
    simulate,
    writable_folder,
)
from diagrams.scenarios import scenario_as_yaml

#: The ablation's rows: (label, the fields each adds to the previous row's scenario).
ABLATION_STEPS = (
    (
        "paper (5 N, eq. 14 as printed)",
        {
            "push_peak_force": 5.0,
            "integrate_from": "measured",
            "closed_chain_projection": False,
            "hold_center_of_mass": False,
            "dead_band": 0.0,
            "dead_band_sigmas": 0.0,
            "tare_duration": 0.0,
            "residual_gain": 35.0,
        },
    ),
    ("+ 20 N", {"push_peak_force": 20.0}),
    ("+ posture integration", {"integrate_from": "desired"}),
    ("+ closed-chain projection", {"closed_chain_projection": True}),
    ("+ CoM hold", {"hold_center_of_mass": True}),
    ("+ dead band", {"dead_band": 0.02, "dead_band_sigmas": 2.0}),
    ("+ residual tare", {"tare_duration": 2.0}),
    ("+ residual gain 5/s (the project's default)", {"residual_gain": 5.0}),
)

#: The robots of ``--study robots``: (label, model, imperfections seed, sensor seed).
ROBOTS = (
    ("hrp4_like robot 0", "hrp4_like", 0, 0),
    ("hrp4_like robot 3", "hrp4_like", 3, 4),
    ("hrp4_like robot 7", "hrp4_like", 7, 8),
    ("hrp4_like robot 11", "hrp4_like", 11, 12),
    ("hrp4_like robot 19", "hrp4_like", 19, 20),
    ("hrp4_like robot 23", "hrp4_like", 23, 5),
    ("TALOS robot 0", "models/robots/talos.yaml", 0, 0),
    ("Romeo robot 0", "models/robots/romeo.yaml", 0, 0),
)

#: The robots of ``--study sensing``: (label, model, world).
SENSING_ROBOTS = (
    ("hrp4_like, foot F/T sensors", "hrp4_like", "ideal"),
    ("hrp4_like, FSRs", "models/robots/hrp4_like_fsr.yaml", "ideal"),
    ("hrp4_like, no foot sensing", "models/robots/hrp4_like_no_ft.yaml", "ideal"),
    ("TALOS, no foot sensing", "models/robots/talos_no_ft.yaml", "ideal"),
    ("hrp4_like, foot F/T sensors", "hrp4_like", "realistic"),
    ("hrp4_like, FSRs", "models/robots/hrp4_like_fsr.yaml", "realistic"),
    ("hrp4_like, no foot sensing", "models/robots/hrp4_like_no_ft.yaml", "realistic"),
)

#: The metrics each row keeps (``push_and_comply_metrics``' keys).
KEPT_METRICS = (
    "push_peak_force_N",
    "knee_pitch_flexion_deg",
    "knee_dead_band_N_m",
    "knee_push_effort_N_m",
    "joints_moved_over_1deg",
    "com_height_drop_m",
    "com_horizontal_travel_m",
    "pelvis_height_drop_m",
    "max_foot_slip_m",
    "max_base_tilt_deg",
    "upright",
    "real_time_factor",
)


#: The worlds of the ablation.
WORLDS = ("ideal", "realistic")


def ablation_scenarios(duration: float | None = None, worlds: tuple[str, ...] = WORLDS) -> list[dict]:
    """The ablation's rows in ``worlds``: dicts with ``label``, ``world`` and ``scenario``."""
    from diagrams.residuals.push_and_comply import PushAndComplyScenario

    rows = []
    for world in worlds:
        fields: dict = {}
        for label, changes in ABLATION_STEPS:
            fields.update(changes)
            scenario = dataclasses.replace(PushAndComplyScenario(), **fields)
            scenario.station = scenario.station.in_world(world)
            rows.append({"label": label, "world": world, "scenario": _shortened(scenario, duration)})
    return rows


def robot_scenarios(duration: float | None = None) -> list[dict]:
    """The robots' rows: dicts with ``label``, ``world`` and ``scenario``."""
    from diagrams.residuals.push_and_comply import PushAndComplyScenario

    rows = []
    for label, model, robot_seed, sensor_seed in ROBOTS:
        default = PushAndComplyScenario()
        imperfections = dataclasses.replace(default.station.imperfections, seed=robot_seed)
        station = dataclasses.replace(default.station, model=model, seed=sensor_seed, imperfections=imperfections)
        scenario = dataclasses.replace(default, station=station)
        rows.append({"label": label, "world": "realistic", "scenario": _shortened(scenario, duration)})
    return rows


def sensing_scenarios(duration: float | None = None) -> list[dict]:
    """The foot-sensing rows (``SENSING_ROBOTS``): dicts with ``label``, ``world`` and
    ``scenario``."""
    from diagrams.residuals.push_and_comply import PushAndComplyScenario

    rows = []
    for label, model, world in SENSING_ROBOTS:
        scenario = PushAndComplyScenario()
        scenario.station = dataclasses.replace(scenario.station, model=model).in_world(world)
        rows.append({"label": label, "world": world, "scenario": _shortened(scenario, duration)})
    return rows


def _shortened(scenario, duration: float | None):
    """The scenario with its push's times scaled to ``duration`` s (None: as it is)."""
    if duration is None:
        return scenario
    scale = duration / scenario.duration
    return dataclasses.replace(
        scenario,
        duration=duration,
        push_start=scenario.push_start * scale,
        push_peak_time=scenario.push_peak_time * scale,
        push_end=scenario.push_end * scale,
        tare_duration=scenario.tare_duration * scale,
    )


def _calibrate(job: tuple[str, str]) -> str:
    """Worker: calibrates (or finds in the cache) the refined model of one scenario."""
    from diagrams.residuals.model_refinement import refined_model
    from diagrams.residuals.push_and_comply import load_scenario

    scenario_yaml, cache = job
    refined_model(load_scenario(text=scenario_yaml), Path(cache))
    return scenario_yaml


def _run(job: tuple[str, str, str]) -> dict:
    """Worker: one closed loop (scenario YAML, residual kind, calibration cache folder); its
    kept metrics."""
    from diagrams.residuals.model_refinement import refined_model
    from diagrams.residuals.push_and_comply import (
        build_push_and_comply_diagram,
        load_scenario,
        push_and_comply_metrics,
    )

    scenario_yaml, kind, cache = job
    scenario = load_scenario(text=scenario_yaml)
    corrections = refined_model(scenario, Path(cache))
    diagram, handles = build_push_and_comply_diagram(scenario, kind, model_corrections=corrections)
    run = simulate(
        diagram,
        scenario.duration,
        set_initial_state=handles.station.set_initial_state,
        simulator_config=scenario.simulator_config,
    )
    signals = logged_signals(handles.loggers, run.context, "state")
    metrics = push_and_comply_metrics(scenario, handles, signals, run.wall_time_s)
    return {key: metrics[key] for key in KEPT_METRICS}


def run_study(rows: list[dict], cache: Path, engine) -> list[dict]:
    """Runs every row with both residuals; returns the rows with their ``internal`` and
    ``classical`` metrics (the scenario replaced by its YAML text), on ``engine``
    (``apps.engine``)."""
    texts = [scenario_as_yaml(row["scenario"]) for row in rows]
    calibrations = sorted({t for t, row in zip(texts, rows) if row["world"] == "realistic"})
    jobs = [(t, kind, str(cache)) for t in texts for kind in ("internal", "classical")]
    # One calibration per robot first (rows of the same robot share it through the cache).
    by_robot = {}
    for text in calibrations:
        by_robot.setdefault(_calibration_key(text), text)
    engine.map(_calibrate, [(text, str(cache)) for text in by_robot.values()])
    results = engine.map(_run, jobs)
    out = []
    for k, (row, text) in enumerate(zip(rows, texts)):
        out.append(
            {
                "label": row["label"],
                "world": row["world"],
                "model": row["scenario"].station.model,
                "robot_seed": row["scenario"].station.imperfections.seed,
                "sensor_seed": row["scenario"].station.seed,
                "internal": results[2 * k],
                "classical": results[2 * k + 1],
                "scenario": text,
            }
        )
    return out


def _calibration_key(text: str) -> str:
    from diagrams.residuals.model_refinement import calibration_file
    from diagrams.residuals.push_and_comply import load_scenario

    return calibration_file(load_scenario(text=text), Path(".")).name


def print_table(rows: list[dict]) -> None:
    """One line per row: knee flexion of both runs, the internal run's CoM height drop and
    horizontal travel, and whether each run stayed upright."""
    print(f"{'world':10s} {'row':38s} {'knee int.':>9s} {'knee cl.':>9s} {'CoM drop/travel':>16s}  upright")
    for row in rows:
        i, c = row["internal"], row["classical"]
        knees = f"{i['knee_pitch_flexion_deg']:9.2f} {c['knee_pitch_flexion_deg']:9.2f}"
        com = f"{100 * i['com_height_drop_m']:6.2f}/{100 * i['com_horizontal_travel_m']:.2f} cm"
        upright = f"{'yes' if i['upright'] else 'NO'}/{'yes' if c['upright'] else 'NO'}"
        print(f"{row['world']:10s} {row['label']:38s} {knees} {com:>16s}  {upright}")


def _parse(argv):
    parser = argparse.ArgumentParser(
        prog="python -m apps.push_and_comply_study",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--study", choices=("ablation", "robots", "sensing"), required=True)
    parser.add_argument("--worlds", nargs="+", choices=WORLDS, default=list(WORLDS), help="the ablation's worlds")
    add_engine_arguments(parser)
    parser.add_argument(
        "--duration",
        type=positive_float,
        default=None,
        help="shorten every run to S s (push times scaled); a smoke test",
    )
    parser.add_argument(
        "--results-folder",
        type=writable_folder,
        default=None,
        help="write the results file there instead of results/",
    )
    add_out_argument(parser, "push_and_comply_study")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        if args.study == "ablation":
            rows = ablation_scenarios(args.duration, tuple(args.worlds))
        elif args.study == "sensing":
            rows = sensing_scenarios(args.duration)
        else:
            rows = robot_scenarios(args.duration)
        start = time.perf_counter()
        with open_engine(engine_from_args(args)) as engine:
            done = run_study(rows, calibration_cache_folder(args), engine)
            workers = engine.workers
        print_table(done)
        data = {"rows": done, "wall_time_s": time.perf_counter() - start, "workers": workers}
        command = app_command("apps.push_and_comply_study", argv)
        path = write_results(f"push_and_comply_{args.study}", data, command=command, folder=args.results_folder)
        print(f"wrote {path}")
        return 0

    return run_app("push_and_comply_study", body)


if __name__ == "__main__":
    raise SystemExit(main())
