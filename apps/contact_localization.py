"""Contact localization Monte Carlo study: Flacco et al. (2016), Secs. V-VI, Fig. 9.

By default the study runs in the realistic world (``diagrams.station.config``: the
base state from the invariant EKF, realistic imperfections, the model refined once from a
calibration motion before the trials); ``--ideal`` runs it in the ideal world.

The humanoid (``hrp4_like``) stands holding its posture with noisy sensors; in each trial a
constant force of 5-40 N, within 60 deg of the inward surface normal, pushes a random point
of the outer collision surface of a random link (upper body and legs; the soles, below the
F/T sensors, are excluded) for 0.5 s. The trials (1000 by default) are drawn from several
seeds (5 by default: seed, seed + 1, ...). The internal and external residuals, the
ContactDetector and the ContactLocalizer see only the sensors; by default they run after
each trial's simulation on the inputs it recorded at each update (``estimation: offline``),
as they would have in the loop. ``--contacts 2`` pushes two links at once. Every trial
also goes through the one-or-two-contact MultiContactLocalizer, after all trials
(cross-fitted: each seed's trials with the model error under load measured on the other
seeds' trials, whose pushes are known, ``diagrams.residuals.contact_study.multi_contact_jobs``).
Per trial the app records
detection and its delay, the localized link and point and the force at the end of the push
(the localizer averages its inputs from 0.1 s after detection and localizes at 100 Hz),
and the computation time of one localizer update. Each trial starts from the standing
start (``--trials-per-run N`` runs N trials one after another instead, 0.4 s apart). Two
runs without contact count false detections: 60 s standing, and 60 s of slow whole-body
motion (``diagrams.station.motions``, a motion the calibration never saw).

Run: ``python -m apps.contact_localization [--scenario FILE] [--scenario-text YAML]
[--trials N] [--contacts 1|2] [--seed S] [--num-seeds K] [--trials-per-run N] [--model M] [--push-start S]
[--contact-duration S] [--no-contact-duration S] [--slow-motion-duration S] [--no-noise]
[--ideal] [--out DIR] [--headless] [--engine E] [--workers W] [--cluster ADDRESS] [--replays R]``.
The scenario is a ``ContactLocalizationScenario``; ``--trials``, ``--contacts``, ``--seed``,
``--num-seeds``, ``--trials-per-run``, ``--model``, ``--push-start``,
``--contact-duration`` (``push_duration``), ``--no-contact-duration``,
``--slow-motion-duration`` and ``--no-noise`` override its fields, ``--ideal`` its world;
``--engine``, ``--workers``, ``--cluster`` and ``--replays`` are how it runs: the jobs (chunks of
``TRIALS_PER_JOB`` trials, the runs without contact, the replays) go to the workers of
``apps.engine`` (Ray actors on this machine by default, or on a Ray cluster with
``--cluster``; a process pool with ``--engine pool``); the results do not depend on the
engine or the number of workers.
Writes to ``DIR/contact_localization/``: ``metrics.json`` (totals, floors, per-trial
results, per-link and per-seed tables, the scenario, the wall time by phase),
``localizer_inputs.npz`` (per trial the averaged q, external wrench and internal residual
the final localization used: ``ContactLocalizer.localize`` replays it),
``position_errors.png`` (histogram), and
``replay_trial_<i>.html`` (Meshcat replays of the first R trials: green arrow = true force
ending at the true contact point, red arrow = the localizer's estimate, shown while valid).

The study (its scenario, diagram, trials, offline estimation, metrics, and its phases on the
engine, ``run_study``) is ``diagrams.residuals.contact_study``; this app holds its command line,
its Meshcat replays and the files it writes.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from apps.engine import add_engine_arguments, engine_from_args, open_engine
from apps.runner import (
    calibration_cache_folder,
    experiment_parser,
    non_negative_float,
    non_negative_int,
    output_folder,
    positive_float,
    positive_int,
    print_written,
    replay_meshcat,
    run_app,
    save_replay,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.residuals.contact_study import (
    ContactLocalizationScenario,
    build_contact_localization_diagram,
    first_pass_job_count,
    run_job,
    run_schedule,
    run_study,
    trial_scenario,
)
from diagrams.residuals.model_refinement import refined_model
from diagrams.scenarios import load_scenario
from systems.estimation.base_state_estimator import load_compiled_filter_steps

#: The replays go on 0.3 s after the push, to show its release.
REPLAY_AFTER_PUSH_S = 0.3


# ---------------------------------------------------------------------------------------
# The replays (worker process, or here).
# ---------------------------------------------------------------------------------------


def record_replay(spec: dict, scenario: ContactLocalizationScenario, meshcat, *, live: bool = True) -> None:
    """Records the trial ``spec`` in ``meshcat``, its push and its release."""
    trial = trial_scenario(scenario, spec)
    pushes, _, _ = run_schedule(scenario, [spec])
    diagram, handles = build_contact_localization_diagram(
        trial, meshcat, model_corrections=refined_model(scenario), pushes=pushes, online=True
    )
    simulate(
        diagram,
        trial.push_start + trial.push_duration + REPLAY_AFTER_PUSH_S,
        set_initial_state=handles.station.set_initial_state,
        simulator_config=trial.simulator_config,
        meshcat=meshcat,
        live=live,
        camera=([1.6, -1.6, 1.2], [0.0, 0.0, 0.7]),
    )


def save_trial_replay(spec: dict, scenario: ContactLocalizationScenario, out_dir: Path) -> Path:
    """Records the trial ``spec`` (``record_replay``, not live) in a Meshcat of its own and
    writes it to ``out_dir/replay_trial_<i>.html``: a headless run's replays, recorded in
    the worker processes beside the trials."""
    meshcat = replay_meshcat(True, headless=True)
    record_replay(spec, scenario, meshcat, live=False)
    return save_replay(meshcat, Path(out_dir) / f"replay_trial_{spec['trial']}.html")


def _job(job: tuple) -> tuple[str, object]:
    """A job of the study (``run_job``), or a headless replay: ``("replay", spec,
    scenario_yaml, folder)`` (``save_trial_replay``)."""
    kind, spec, scenario_yaml, extra = job
    if kind == "replay":
        scenario = load_scenario(ContactLocalizationScenario, text=scenario_yaml)
        return kind, [str(save_trial_replay(spec, scenario, extra))]
    return run_job(job)


# ---------------------------------------------------------------------------------------
# Outputs.
# ---------------------------------------------------------------------------------------


def plot_position_errors(path: Path, results: list[dict]) -> None:
    errors = np.array([r["position_error_m"] for r in results if r["position_error_m"] is not None]) * 100.0
    fig, ax = plt.subplots(figsize=(7, 4))
    if errors.size:
        ax.hist(np.minimum(errors, 20.0), bins=np.linspace(0.0, 20.0, 41), color="tab:blue", edgecolor="k")
        ax.axvline(np.median(errors), color="tab:green", label=f"median {np.median(errors):.2f} cm")
        ax.axvline(
            np.percentile(errors, 95), color="tab:orange", label=f"95th percentile {np.percentile(errors, 95):.2f} cm"
        )
    ax.axvline(2.0, color="tab:green", ls="--", label="floor: median 2 cm")
    ax.axvline(5.0, color="tab:orange", ls="--", label="floor: p95 5 cm")
    missing = sum(r["position_error_m"] is None for r in results)
    ax.set_xlabel("position error [cm] (clipped at 20)")
    ax.set_ylabel("trials")
    ax.set_title(f"Contact localization, {len(results)} trials ({missing} without a localization)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _parse(argv):
    parser = experiment_parser("apps.contact_localization", __doc__, replay=False, conditions=True, robot=True)
    parser.add_argument("--trials", type=positive_int, default=None, help="number of trials (scenario default 1000)")
    parser.add_argument(
        "--contacts", type=int, choices=(1, 2), default=None, help="contacts per trial (default 1; 2: two links)"
    )
    parser.add_argument(
        "--seed", type=non_negative_int, default=None, help="first seed of the trials and of the sensor noise"
    )
    parser.add_argument(
        "--num-seeds", type=positive_int, default=None, help="seeds the trials are drawn from (default 5)"
    )
    parser.add_argument(
        "--trials-per-run",
        type=positive_int,
        default=None,
        help="trials simulated one after another in one run (default 1: each from the standing start)",
    )
    parser.add_argument(
        "--model", default=None, help="the humanoid (hrp4_like, or a robot description; --robot is the same)"
    )
    add_engine_arguments(parser)
    parser.add_argument(
        "--replays", type=non_negative_int, default=3, help="Meshcat replays of the first N trials (default 3)"
    )
    parser.add_argument(
        "--push-start", type=non_negative_float, default=None, help="contact onset, s (scenario default 0.5)"
    )
    parser.add_argument(
        "--contact-duration",
        type=positive_float,
        default=None,
        help="contact duration, s (the scenario's push_duration, default 0.5)",
    )
    parser.add_argument(
        "--no-contact-duration",
        type=non_negative_float,
        default=None,
        help="length of the standing run without contact for false detections, s (scenario default 60; 0 skips)",
    )
    parser.add_argument(
        "--slow-motion-duration",
        type=non_negative_float,
        default=None,
        help="length of the slow whole-body motion run without contact, s (scenario default 60; 0 skips)",
    )
    parser.add_argument("--no-noise", action="store_true", help="ideal sensors")
    args = parser.parse_args(argv)
    if (
        (args.workers is not None and args.workers < 1)
        or args.replays < 0
        or (args.trials is not None and args.trials < 1)
        or (args.num_seeds is not None and args.num_seeds < 1)
        or (args.trials_per_run is not None and args.trials_per_run < 1)
        or (args.contact_duration is not None and args.contact_duration <= 0)
        or (args.push_start is not None and args.push_start < 0)
    ):
        parser.error(
            "--trials, --num-seeds, --trials-per-run and --workers must be >= 1, --replays >= 0,"
            " --contact-duration > 0, --push-start >= 0"
        )
    return args


def _progress(done: int, total: int) -> None:
    print(f"\r{done}/{total} jobs done", end="", flush=True)
    if done == total:
        print()


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        scenario = scenario_from_args(
            ContactLocalizationScenario,
            args,
            trials=args.trials,
            seed=args.seed,
            num_seeds=args.num_seeds,
            trials_per_run=args.trials_per_run,
            contacts=args.contacts,
            model=args.model,
            push_start=args.push_start,
            push_duration=args.contact_duration,
            no_contact_duration=args.no_contact_duration,
            slow_motion_duration=args.slow_motion_duration,
            noise=False if args.no_noise else None,
        )
        if scenario.trials < 1:
            raise ValueError(f"the study needs at least one trial, got trials: {scenario.trials}")
        out_dir = output_folder(args, "contact_localization")
        if scenario.contacts not in (1, 2):
            raise ValueError(f"contacts must be 1 or 2, got contacts: {scenario.contacts}")
        start = time.perf_counter()
        # The compiled filter steps, here first: compiled if numba's cache lacks them (~35 s;
        # `make install` compiles them, or a fresh clone's first study would spend that in
        # its calibration), then only loaded by the workers.
        load_compiled_filter_steps()
        # One set of workers for both passes, started first: they import and load the
        # compiled filter while the model is calibrated.
        choice = engine_from_args(args)
        if choice.kind == "pool":  # no more processes than jobs
            headless_replays = min(args.replays, scenario.trials) if args.headless else 0
            workers = min(choice.workers, first_pass_job_count(scenario, headless_replays))
            choice = dataclasses.replace(choice, workers=workers)
        with open_engine(choice, initializer=load_compiled_filter_steps) as engine:
            return _study(scenario, args, out_dir, start, engine)

    return run_app("contact_localization", body)


def _study(scenario: ContactLocalizationScenario, args, out_dir: Path, start: float, engine) -> int:
    """The study of ``main``, run on ``engine`` (``apps.engine``; ``run_study``), from its
    start time ``start`` (s, ``time.perf_counter``); then its live replays and its files."""

    def replay_jobs(specs: list[dict], scenario_yaml: str) -> list[tuple]:
        # Headless, the replays are recorded in the workers too, last (short jobs: they fill
        # the pool's tail); live, here after the study.
        return [("replay", spec, scenario_yaml, out_dir) for spec in specs[: args.replays]] if args.headless else []

    study = run_study(
        scenario,
        engine,
        calibration_folder=functools.partial(calibration_cache_folder, args),
        start=start,
        replay_jobs=replay_jobs,
        function=_job,
        progress=_progress,
    )
    metrics, results, phases = study.metrics, study.results, study.phases
    live_replays = [] if args.headless else study.specs[: args.replays]
    mark = time.perf_counter()
    meshcat = replay_meshcat(bool(live_replays), args.headless)
    for spec in live_replays:
        record_replay(spec, scenario, meshcat)
        save_replay(meshcat, out_dir / f"replay_trial_{spec['trial']}.html")
    phases["live_replays"] = time.perf_counter() - mark
    metrics["wall_time_s"] = time.perf_counter() - start
    metrics["phase_wall_s"] = phases
    inputs = [r.pop("localizer_inputs") for r in results]
    metrics["per_trial"] = results
    write_metrics(out_dir, metrics, scenario, args)
    np.savez_compressed(
        out_dir / "localizer_inputs.npz",
        trial=np.array([r["trial"] for r in results]),
        **{name: np.array([i[name] for i in inputs]) for name in inputs[0]},
    )
    plot_position_errors(out_dir / "position_errors.png", results)
    _print_summary(metrics)
    print_written(out_dir)
    return 0


def _print_summary(metrics: dict) -> None:
    print(
        f"contact localization on {metrics['model']}, {metrics['trials']} trials of {metrics['contacts']} contact(s)"
        f" (seeds {metrics['seeds']}),"
        f" noise {'on' if metrics['noise'] else 'off'}:"
    )
    intervals = metrics.get("intervals", {})
    level = 100 * metrics.get("interval_level", 0.95)
    for key, floor_text in metrics["floors"].items():
        op, floor = floor_text.split()
        value = metrics.get(key)
        ok = metrics["meets_floors"].get(key)
        text = "n/a" if value is None else f"{value:.4g}"
        ci = f"[{intervals[key][0]:.4g}, {intervals[key][1]:.4g}]" if key in intervals else ""
        verdict = "ok" if ok else "MISSED" if ok is not None else "not measured"
        print(f"  {key:32s} {text:>10s} {ci:>20s}   floor {op} {floor:<6}  {verdict}")
    extra = (
        "valid_rate",
        "valid_precision",
        "more_than_one_contact_rate",
        "p_value_one_below_0.05_rate",
        "two_contact_fit_links_right_rate",
        "p95_contact_position_error_m",
        "p95_contact_force_error_rel",
        "foot_normal_force_rms_error_of_weight",
    )
    for key in (k for k in extra if k not in metrics["floors"]):
        if metrics.get(key) is not None:
            ci = f"[{intervals[key][0]:.4g}, {intervals[key][1]:.4g}]" if key in intervals else ""
            print(f"  {key:32s} {metrics[key]:>10.4g} {ci:>20s}")
    print(f"  ({level:.0f} % intervals: Clopper-Pearson for rates, order statistics for quantiles)")
    print(f"  status counts: {metrics['status_counts']}")
    two = metrics.get("contacts") == 2
    seeds_title = "both-links-right rate per seed:" if two else "eq. (22) localizer's right-link rate per seed:"
    for title, rows in (
        (seeds_title, metrics.get("per_seed", [])),
        ("stacked fit's right-link rate per seed:", metrics.get("fit_per_seed", [])),
    ):
        if len(rows) > 1:
            print(f"  {title}")
            for row in rows:
                low, high = row["interval"]
                counts = f"{row['successes']:4d} / {row['trials']:<4d} {100 * row['rate']:5.1f} %"
                print(f"    seed {row['group']:>8s} {counts}  [{100 * low:.1f}, {100 * high:.1f}]")
    if metrics.get("per_region") and not two:
        print(
            "  per body region: trials, detection, right link (eq. 22 / stacked fit), median position error"
            " (, sole normal force RMS error of the weight):"
        )
        for row in metrics["per_region"]:
            fit = row.get("fit_correct_link_rate")
            fit_text = "" if fit is None else f" / {100 * fit:5.1f} %"
            sole = row.get("foot_normal_force_rms_error_of_weight")
            sole_text = "" if sole is None else f"  {100 * sole:.1f} %"
            print(
                f"    {row['region']:6s} {row['trials']:5d}  {100 * row['detection_rate']:5.1f} %"
                f"  {100 * row['correct_link_rate']:5.1f} %{fit_text}  {100 * row['median_position_error_m']:.2f} cm"
                f"{sole_text}"
            )
    worst = [row for row in metrics.get("per_link", []) if row["rate"] < 1.0]
    if worst:
        what = "found (two contacts, this link among them)" if two else "eq. (22) localizer's right-link"
        print(f"  {what} rate per pushed link, below 100 % (all links: metrics.json 'per_link'):")
        for row in worst:
            print(f"    {row['group']:20s} {row['successes']:4d} / {row['trials']:<4d} {100 * row['rate']:5.1f} %")
    if metrics.get("confusion"):
        whose = "misses (true links" if two else "eq. (22) localizer's misses (true link"
        print(f"  {whose} -> estimated or status: count):")
        for row in metrics["confusion"]:
            print(f"    {row['true']} -> {row['estimated']}: {row['count']}")
    phases = ", ".join(f"{name.replace('_', ' ')} {t:.0f} s" for name, t in metrics.get("phase_wall_s", {}).items())
    print(f"wall time {metrics['wall_time_s']:.1f} s ({phases})")


if __name__ == "__main__":
    raise SystemExit(main())
