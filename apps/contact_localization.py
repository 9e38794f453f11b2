"""Contact localization Monte Carlo study: Flacco et al. (2016), Secs. V-VI, Fig. 9.

By default the study runs in the realistic world (``diagrams.station.conditions``: the
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
seeds' trials, whose pushes are known, ``multi_contact_jobs``).
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
[--ideal] [--out DIR] [--headless] [--workers W] [--replays R]``.
The scenario is a ``ContactLocalizationScenario``; ``--trials``, ``--contacts``, ``--seed``,
``--num-seeds``, ``--trials-per-run``, ``--model``, ``--push-start``,
``--contact-duration`` (``push_duration``), ``--no-contact-duration``,
``--slow-motion-duration`` and ``--no-noise`` override its fields, ``--ideal`` its world;
``--workers`` and ``--replays`` are how it runs. Trials run in parallel processes ('spawn').
Writes to ``DIR/contact_localization/``: ``metrics.json`` (totals, floors, per-trial
results, per-link and per-seed tables, the scenario, the wall time by phase),
``localizer_inputs.npz`` (per trial the averaged q, external wrench and internal residual
the final localization used: ``ContactLocalizer.localize`` replays it),
``position_errors.png`` (histogram), and
``replay_trial_<i>.html`` (Meshcat replays of the first R trials: green arrow = true force
ending at the true contact point, red arrow = the localizer's estimate, shown while valid).

The metrics are defined in ``diagrams.residuals.contact_localization``.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import os
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

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
from diagrams.residuals.contact_localization import (
    MAX_ANGLE_DEG,
    MAX_FORCE,
    MIN_FORCE,
    MIN_LOAD_CALIBRATION_TRIALS,
    ContactLocalizationScenario,
    averaged_input_covariances,
    build_contact_localization_diagram,
    contact_localization_metrics,
    cross_fitting_folds,
    estimate_run,
    estimator_log,
    floors_for,
    load_model_error,
    multi_contact_localizer,
    multi_contact_result,
    no_contact_result,
    no_contact_scenario,
    offline_trial,
    run_schedule,
    sample_study_trials,
    slow_motion_scenario,
    trial_result,
    trial_scenario,
)
from diagrams.residuals.model_refinement import calibration_file, refined_model
from diagrams.scenarios import load_scenario, scenario_as_yaml
from systems.estimation.base_state_estimator import load_compiled_filter_steps

#: The replays go on 0.3 s after the push, to show its release.
REPLAY_AFTER_PUSH_S = 0.3


# ---------------------------------------------------------------------------------------
# One trial (worker process).
# ---------------------------------------------------------------------------------------


#: Trials a worker process runs per job (at least one run of ``trials_per_run``).
TRIALS_PER_JOB = 25
#: Trials per job of the one-or-two-contact localization (after the simulations).
MULTI_CONTACT_TRIALS_PER_JOB = 25

#: A run is restarted from the standing start after a trial that moved a sole from where it
#: stood by more than these (m, rad): the base-state estimator takes a foot in contact as
#: still, so the next trials would measure a robot that slipped, not one standing.
SOLE_SLIP_RESTART = (0.002, math.radians(0.2))


def sole_slip(plant, plant_context, sole_frames: dict, start: dict) -> tuple[float, float]:
    """The largest displacement (m) and rotation (rad) of the soles from their poses ``start``
    (frame name -> RigidTransform)."""
    moved, turned = 0.0, 0.0
    for name, frame in sole_frames.items():
        X = start[name].InvertAndCompose(frame.CalcPoseInWorld(plant_context))
        moved = max(moved, float(np.linalg.norm(X.translation())))
        turned = max(turned, float(abs(X.rotation().ToAngleAxis().angle())))
    return moved, turned


def run_trials(specs: list[dict], scenario: ContactLocalizationScenario) -> list[dict]:
    """Simulates the trials ``specs`` (``sample_trials``) of ``scenario`` and returns their
    results (``trial_result``, with the soles' slip since the standing start), each read at
    the end of its push (the one-or-two-contact localization comes after all trials,
    ``localize_multi_contact``).

    How the trials are run:

    * ``trials_per_run`` 1 with ``shared_standing_start`` (the default): the standing start
      is simulated once and its state saved at ``push_start``; the trials then push one
      after another, each from that state, restored before its push (time goes on, so each
      push sees sensor noise of its own).
    * ``trials_per_run`` 1 otherwise: each trial simulates its own standing start.
    * ``trials_per_run`` N > 1: N trials one after another in each run, the robot not reset
      in between (``run_schedule``); a trial after which a sole has slipped
      (``SOLE_SLIP_RESTART``) ends its run, and the next trials start a new one.
    """
    results = []
    model_corrections = refined_model(scenario)
    shared_start = scenario.trials_per_run == 1 and scenario.shared_standing_start
    per_run = len(specs) if shared_start else scenario.trials_per_run
    schedule = dataclasses.replace(scenario, trial_gap=0.0) if shared_start else scenario
    remaining = list(specs)
    while remaining:
        run_specs = remaining[:per_run]
        run_scenario = trial_scenario(scenario, run_specs[0])  # the run's noise seed
        pushes, windows, push_indices = run_schedule(schedule, run_specs)
        diagram, handles = build_contact_localization_diagram(
            run_scenario, model_corrections=model_corrections, pushes=pushes
        )
        simulator = Simulator(diagram)
        ApplySimulatorConfig(scenario.simulator_config, simulator)
        context = simulator.get_mutable_context()
        handles.station.set_initial_state(context)
        plant_context = handles.plant.GetMyContextFromRoot(context)
        soles = handles.station.humanoid.sole_frames
        start = {name: frame.CalcPoseInWorld(plant_context) for name, frame in soles.items()}
        simulator.Initialize()
        standing = None
        # Offline estimation (``handles.online`` False): the run's replayed segments so far
        # and the estimators' state after them.
        segments, resume, standing_end = [], None, None
        detected_at_start = False  # the detector's flag at the standing start's end
        if shared_start:
            simulator.AdvanceTo(scenario.push_start)
            standing = context.Clone()
            if handles.online:
                detector_context = handles.detector.GetMyContextFromRoot(standing)
                detected_at_start = handles.detector.GetOutputPort("contact_detected").Eval(detector_context)[0] > 0.5
            else:
                segments, resume = _estimate_more(handles, segments, resume)
                standing_end = resume
                detected_at_start = standing_end.detected
        done = len(run_specs)
        for k, (spec, window, indices) in enumerate(zip(run_specs, windows, push_indices)):
            restored = shared_start and k > 0
            if restored:
                context.SetStateAndParametersFrom(standing)  # the standing start; the time goes on
                window = (window[1], window[1], window[2])
                segments, resume = [], standing_end
            wall_start = time.perf_counter()
            simulator.AdvanceTo(window[2])
            offline = None
            if not handles.online:
                segments, resume = _estimate_more(handles, segments, resume)
                offline = offline_trial(handles, segments, restored and detected_at_start)
            result = trial_result(
                scenario,
                spec,
                handles,
                context,
                time.perf_counter() - wall_start,
                push_indices=indices,
                window=window,
                restored_at_start=restored,
                detected_at_start=bool(detected_at_start),
                offline=offline,
            )
            moved, turned = sole_slip(handles.plant, plant_context, soles, start)
            result["sole_slip_m"], result["sole_slip_deg"] = moved, math.degrees(turned)
            result["sole_slipped"] = moved > SOLE_SLIP_RESTART[0] or turned > SOLE_SLIP_RESTART[1]
            result["run_restarted_after"] = result["sole_slipped"] and not shared_start
            results.append(result)
            if result["run_restarted_after"]:
                done = k + 1
                break
        remaining = remaining[done:]
    return results


def _estimate_more(handles, segments: list, resume) -> tuple:
    """Runs the offline estimators (``estimate_run``) on the updates recorded since the
    last call (the records are then cleared), from the state ``resume`` the last replay
    ended in. Returns ``segments`` with this one appended (its ``EstimatorLog`` and
    replay) and its end state."""
    log = estimator_log(handles)
    if not log.update_times.size:
        return segments, resume
    handles.recorder.clear()
    replay = estimate_run(handles, log, resume)
    return [*segments, (log, replay)], replay.end


def localize_multi_contact(
    trials: list[dict],
    scenario: ContactLocalizationScenario,
    covariances: tuple[np.ndarray, np.ndarray],
    load_covariances: tuple[np.ndarray, np.ndarray] | None,
) -> list[dict]:
    """The one-or-two-contact localization (``multi_contact_result``) of the ``trials``'
    averaged inputs (``localizer_inputs``) against their true contacts, whitened with the
    averaged inputs' noise ``covariances`` and the model error under load
    ``load_covariances`` (measured on other trials, ``load_model_error``; None: none).
    Returns one dict per trial, with its ``trial``."""
    # The diagram owns the plant the localizer reads: both live until the end.
    diagram, handles = build_contact_localization_diagram(scenario, model_corrections=refined_model(scenario))
    localizer = multi_contact_localizer(handles, covariances, load_covariances)
    out = []
    for trial in trials:
        contacts = trial.get("contacts", [trial])
        inputs = trial["localizer_inputs"]
        result = multi_contact_result(
            localizer,
            inputs["q"],
            inputs["external_wrench_world"],
            inputs["residual"],
            [c["body_index"] for c in contacts],
            np.asarray(trial["true_points_world"]),
            np.array([c["force_world"] for c in contacts]),
        )
        out.append({"trial": trial["trial"], **result})
    return out


def multi_contact_jobs(
    results: list[dict],
    plant,
    scenario_yaml: str,
    covariances: tuple[np.ndarray, np.ndarray],
    chunk: int = MULTI_CONTACT_TRIALS_PER_JOB,
) -> list[tuple]:
    """The jobs of the one-or-two-contact localization of the study's ``results``,
    cross-fitted (``cross_fitting_folds``): each fold's trials whitened with the model
    error under load measured on the detected trials of the other folds
    (``load_model_error``; none with fewer than ``MIN_LOAD_CALIBRATION_TRIALS``)."""
    jobs = []
    fields = ("trial", "contacts", "localizer_inputs", "true_points_world", "body_index", "force_world")
    for fold in cross_fitting_folds(results):
        inside = set(fold)
        known = [r for i, r in enumerate(results) if i not in inside and r["detected"]]
        load = load_model_error(plant, known) if len(known) >= MIN_LOAD_CALIBRATION_TRIALS else None
        trials = [{k: results[i][k] for k in fields if k in results[i]} for i in fold]
        for j in range(0, len(trials), chunk):
            jobs.append(("multi_contact", trials[j : j + chunk], scenario_yaml, (covariances, load)))
    return jobs


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


def run_no_contact(scenario: ContactLocalizationScenario, kind: str = "no_contact") -> dict:
    """A run without contact, standing (``kind`` "no_contact", ``no_contact_scenario``) or
    in slow motion ("slow_motion", ``slow_motion_scenario``): its false detections."""
    run_scenario = no_contact_scenario(scenario) if kind == "no_contact" else slow_motion_scenario(scenario)
    diagram, handles = build_contact_localization_diagram(run_scenario, model_corrections=refined_model(scenario))
    run = simulate(
        diagram,
        run_scenario.no_contact_duration,
        set_initial_state=handles.station.set_initial_state,
        simulator_config=run_scenario.simulator_config,
    )
    return no_contact_result(run_scenario, handles, run.context)


def save_trial_replay(spec: dict, scenario: ContactLocalizationScenario, out_dir: Path) -> Path:
    """Records the trial ``spec`` (``record_replay``, not live) in a Meshcat of its own and
    writes it to ``out_dir/replay_trial_<i>.html``: a headless run's replays, recorded in
    the worker processes beside the trials."""
    meshcat = replay_meshcat(True, headless=True)
    record_replay(spec, scenario, meshcat, live=False)
    return save_replay(meshcat, Path(out_dir) / f"replay_trial_{spec['trial']}.html")


def _job(job: tuple) -> tuple[str, object]:
    # The scenario travels as YAML: Drake's config types do not pickle.
    # extra: the (noise, load) covariances of a "multi_contact" job, the folder of a "replay".
    kind, spec, scenario_yaml, extra = job
    scenario = load_scenario(ContactLocalizationScenario, text=scenario_yaml)
    if kind == "trials":
        return kind, run_trials(spec, scenario)
    if kind == "multi_contact":
        return kind, localize_multi_contact(spec, scenario, *extra)
    if kind == "replay":
        return kind, [str(save_trial_replay(spec, scenario, extra))]
    if kind == "covariances":
        return kind, averaged_input_covariances(scenario, refined_model(scenario))
    return kind, run_no_contact(scenario, kind)


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
    parser.add_argument("--model", default=None, help="humanoid with foot F/T sensors (hrp4_like)")
    parser.add_argument(
        "--workers", type=positive_int, default=os.cpu_count() or 1, help="parallel processes (default: all cores)"
    )
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
        args.workers < 1
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


def _run_jobs(jobs: list, pool) -> dict:
    """Runs the jobs (in ``pool``, a process pool, or here when None); returns their results
    by kind: the "trials" and "multi_contact" jobs' lists joined, in trial order, the
    "replay" jobs' files, and the others' ("no_contact", "slow_motion", "covariances")."""
    outputs_by_kind: dict = {}
    outputs = map(_job, jobs) if pool is None else pool.imap_unordered(_job, jobs)
    for done, (kind, value) in enumerate(outputs, 1):
        if kind in ("trials", "multi_contact", "replay"):
            outputs_by_kind.setdefault(kind, []).extend(value)
        else:
            outputs_by_kind[kind] = value
        print(f"\r{done}/{len(jobs)} jobs done", end="", flush=True)
    print()
    for kind in ("trials", "multi_contact"):
        outputs_by_kind.get(kind, []).sort(key=lambda r: r["trial"])
    return outputs_by_kind


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
        # One pool of spawned processes for both passes (one process: here), started first:
        # the workers import and load the compiled filter while the model is calibrated.
        pool = None
        if args.workers > 1:
            pool = multiprocessing.get_context("spawn").Pool(
                min(args.workers, _job_count(scenario, args)), initializer=load_compiled_filter_steps
            )
        try:
            return _study(scenario, args, out_dir, start, pool)
        except BaseException:
            if pool is not None:
                pool.terminate()  # a job failed (or Ctrl-C): do not wait for the others
            raise

    return run_app("contact_localization", body)


def _job_count(scenario: ContactLocalizationScenario, args) -> int:
    """The number of jobs of the study's first pass (``_study``)."""
    size = max(scenario.trials_per_run, TRIALS_PER_JOB)
    multi_contact = scenario.multi_contact or scenario.contacts == 2
    return (
        (scenario.no_contact_duration > 0)
        + (scenario.slow_motion_duration > 0)
        + bool(multi_contact)
        + (min(args.replays, scenario.trials) if args.headless else 0)
        + math.ceil(scenario.trials / size)
    )


def _study(scenario: ContactLocalizationScenario, args, out_dir: Path, start: float, pool) -> int:
    """The study of ``main``, run in ``pool`` (None: in this process), from its start time
    ``start`` (s, ``time.perf_counter``)."""
    specs = sample_study_trials(scenario)
    if scenario.model_refinement == "calibrate":
        # Calibrated once, here; the workers read the saved corrections. The file is named
        # before the calibration, as refined_model names it (its key hashes the code: an
        # edit of the sources during a long calibration must not change the name read back).
        saved = calibration_file(scenario, calibration_cache_folder(args))
        refined_model(scenario, calibration_cache_folder(args))
        scenario.model_refinement = str(saved)
    phases = {"calibration": time.perf_counter() - start}  # wall time of each phase, s
    scenario_yaml = scenario_as_yaml(scenario)
    scenario.multi_contact = scenario.multi_contact or scenario.contacts == 2
    jobs = []
    if scenario.no_contact_duration > 0:  # the longest jobs first
        jobs.append(("no_contact", None, scenario_yaml, None))
    if scenario.slow_motion_duration > 0:
        jobs.append(("slow_motion", None, scenario_yaml, None))
    if scenario.multi_contact:  # the noise of the averaged inputs, for the fits after the trials
        jobs.append(("covariances", None, scenario_yaml, None))
    size = max(scenario.trials_per_run, TRIALS_PER_JOB)
    jobs += [("trials", specs[i : i + size], scenario_yaml, None) for i in range(0, len(specs), size)]
    # Headless, the replays are recorded in the workers too, last (short jobs: they fill
    # the pool's tail); live, here after the study.
    live_replays = [] if args.headless else specs[: args.replays]
    if args.headless:
        jobs += [("replay", spec, scenario_yaml, out_dir) for spec in specs[: args.replays]]
    mark = time.perf_counter()
    no_contact = _run_jobs(jobs, pool)
    phases["simulations"] = time.perf_counter() - mark
    results = no_contact.pop("trials")
    no_contact.pop("replay", None)  # the files are written
    mark = time.perf_counter()
    if scenario.multi_contact:
        # After all trials: each seed's trials whitened with the model error under
        # load measured on the other seeds' (cross-fitting).
        _, handles = build_contact_localization_diagram(scenario, model_corrections=refined_model(scenario))
        covariances = no_contact.pop("covariances")
        multi_jobs = multi_contact_jobs(results, handles.station.estimator.plant, scenario_yaml, covariances)
        by_trial = {m.pop("trial"): m for m in _run_jobs(multi_jobs, pool)["multi_contact"]}
        for r in results:
            r.update(by_trial[r["trial"]])
    phases["one_or_two_contact_fits"] = time.perf_counter() - mark
    if pool is not None:
        pool.close()
        pool.join()
    metrics = contact_localization_metrics(
        results, no_contact.get("no_contact"), no_contact.get("slow_motion"), floors_for(scenario)
    )
    metrics.update(
        {
            "model": scenario.model,
            "seed": scenario.seed,
            "seeds": list(range(scenario.seed, scenario.seed + scenario.num_seeds)),
            "trials_per_run": scenario.trials_per_run,
            "contacts": scenario.contacts,
            "trials_with_a_sole_slip": sum(r["sole_slipped"] for r in results),
            "noise": scenario.noise,
            "workers": args.workers,
            "push_start_s": scenario.push_start,
            "contact_duration_s": scenario.push_duration,
            "force_range_N": [MIN_FORCE, MAX_FORCE],
            "max_angle_from_normal_deg": MAX_ANGLE_DEG,
            "wall_time_s": None,
            "no_contact_run": no_contact.get("no_contact"),
            "slow_motion_run": no_contact.get("slow_motion"),
        }
    )

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
