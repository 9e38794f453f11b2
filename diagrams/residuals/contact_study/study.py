"""The contact study's phases (Flacco et al. 2016, Secs. V-VI), as ``apps.contact_localization``
runs them (``run_study``): the model's calibration, once; a first pass of jobs (the runs
without contact, the averaged inputs' noise, the trials in chunks of ``TRIALS_PER_JOB``); the
one-or-two-contact fits of all trials, cross-fitted (``multi_contact_jobs``); and the study's
metrics (``study_metrics``).

The jobs are plain data (the scenario travels as YAML: Drake's config types do not pickle),
run by the module-level ``run_job``, so that any engine runs them and the results do not
depend on it. The engine is a parameter: ``apps.engine``'s, or anything with its
``imap_unordered(function, jobs)``, ``kind`` and ``workers`` (this module is below the apps).
The command line, the Meshcat replays and the files are the app's.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from diagrams.residuals.contact_study.builder import build_contact_localization_diagram
from diagrams.residuals.contact_study.metrics import contact_localization_metrics
from diagrams.residuals.contact_study.offline import (
    MIN_LOAD_CALIBRATION_TRIALS,
    averaged_input_covariances,
    cross_fitting_folds,
    load_model_error,
)
from diagrams.residuals.contact_study.sampling import sample_study_trials
from diagrams.residuals.contact_study.scenario import MAX_ANGLE_DEG, ContactLocalizationScenario, floors_for
from diagrams.residuals.contact_study.trials import (
    MULTI_CONTACT_TRIALS_PER_JOB,
    TRIALS_PER_JOB,
    localize_multi_contact,
    run_no_contact,
    run_trials,
)
from diagrams.residuals.model_refinement import calibration_file, refined_model
from diagrams.scenarios import load_scenario, scenario_as_yaml

#: The kinds of ``run_job``'s jobs; ``run_study`` also hands its ``replay`` jobs to the
#: caller's job function.
JOB_KINDS = ("trials", "multi_contact", "covariances", "no_contact", "slow_motion")


def run_job(job: tuple) -> tuple[str, object]:
    """Runs one job of the study, ``(kind, spec, scenario_yaml, extra)``: ``"trials"`` (the
    trial specs ``spec``, ``run_trials``), ``"multi_contact"`` (finished trials, with
    ``extra`` their (noise, load) covariances, ``localize_multi_contact``), ``"covariances"``
    (``averaged_input_covariances``), ``"no_contact"`` or ``"slow_motion"`` (``run_no_contact``).
    Returns (kind, result).

    Raises:
        ValueError: another kind.
    """
    # The scenario travels as YAML: Drake's config types do not pickle.
    # extra: the (noise, load) covariances of a "multi_contact" job.
    kind, spec, scenario_yaml, extra = job
    if kind not in JOB_KINDS:
        raise ValueError(f"run_job: no job of kind {kind!r} (one of {JOB_KINDS})")
    scenario = load_scenario(ContactLocalizationScenario, text=scenario_yaml)
    if kind == "trials":
        return kind, run_trials(spec, scenario)
    if kind == "multi_contact":
        return kind, localize_multi_contact(spec, scenario, *extra)
    if kind == "covariances":
        return kind, averaged_input_covariances(scenario, refined_model(scenario))
    return kind, run_no_contact(scenario, kind)


def run_jobs(
    jobs: list,
    engine,
    function: Callable[[tuple], tuple[str, object]] = run_job,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Runs the jobs on ``engine`` (its ``imap_unordered``) with ``function``; returns their
    results by kind: the "trials" and "multi_contact" jobs' lists joined, in trial order, the
    "replay" jobs' files, and the others' ("no_contact", "slow_motion", "covariances").
    ``progress(done, total)`` is called after each job."""
    outputs_by_kind: dict = {}
    for done, (kind, value) in enumerate(engine.imap_unordered(function, jobs), 1):
        if kind in ("trials", "multi_contact", "replay"):
            outputs_by_kind.setdefault(kind, []).extend(value)
        else:
            outputs_by_kind[kind] = value
        if progress is not None:
            progress(done, len(jobs))
    for kind in ("trials", "multi_contact"):
        outputs_by_kind.get(kind, []).sort(key=lambda r: r["trial"])
    return outputs_by_kind


def calibrate_study_model(scenario: ContactLocalizationScenario, cache_folder: Path) -> None:
    """With ``model_refinement: calibrate``, calibrates the study's model once, into
    ``cache_folder``, and sets the scenario's ``model_refinement`` to the saved file (the
    workers read it); otherwise does nothing."""
    if scenario.station.model_refinement == "calibrate":
        # Calibrated once, here; the workers read the saved corrections. The file is named
        # before the calibration, as refined_model names it (its key hashes the code: an
        # edit of the sources during a long calibration must not change the name read back).
        saved = calibration_file(scenario, cache_folder)
        refined_model(scenario, cache_folder)
        scenario.station.model_refinement = str(saved)


def first_pass_jobs(scenario: ContactLocalizationScenario, specs: list[dict], scenario_yaml: str) -> list[tuple]:
    """The jobs of the study's first pass, the longest first: the runs without contact
    (those of a positive duration), the averaged inputs' noise (with ``multi_contact``, for
    the fits after the trials), and the trials ``specs`` in chunks of ``TRIALS_PER_JOB`` (at
    least ``trials_per_run``)."""
    jobs = []
    if scenario.no_contact_duration > 0:  # the longest jobs first
        jobs.append(("no_contact", None, scenario_yaml, None))
    if scenario.slow_motion_duration > 0:
        jobs.append(("slow_motion", None, scenario_yaml, None))
    if scenario.multi_contact:  # the noise of the averaged inputs, for the fits after the trials
        jobs.append(("covariances", None, scenario_yaml, None))
    size = max(scenario.trials_per_run, TRIALS_PER_JOB)
    jobs += [("trials", specs[i : i + size], scenario_yaml, None) for i in range(0, len(specs), size)]
    return jobs


def first_pass_job_count(scenario: ContactLocalizationScenario, replay_jobs: int = 0) -> int:
    """The number of jobs of the study's first pass (``first_pass_jobs``, before its
    ``multi_contact`` is set for two contacts), plus ``replay_jobs``."""
    size = max(scenario.trials_per_run, TRIALS_PER_JOB)
    multi_contact = scenario.multi_contact or scenario.contacts == 2
    return (
        (scenario.no_contact_duration > 0)
        + (scenario.slow_motion_duration > 0)
        + bool(multi_contact)
        + replay_jobs
        + math.ceil(scenario.trials / size)
    )


def multi_contact_jobs(
    results: list[dict],
    plant: MultibodyPlant,
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


def study_metrics(
    scenario: ContactLocalizationScenario, results: list[dict], runs: dict, engine_kind: str, workers: int
) -> dict:
    """The study's metrics (``contact_localization_metrics`` against ``floors_for`` the
    scenario) from its trials' ``results`` and its runs without contact (``runs``: the
    "no_contact" and "slow_motion" results, where run), with the study's settings and the
    engine it ran on; ``wall_time_s`` is left None for the caller."""
    metrics = contact_localization_metrics(
        results, runs.get("no_contact"), runs.get("slow_motion"), floors_for(scenario)
    )
    metrics.update(
        {
            "model": scenario.station.model,
            "seed": scenario.station.seed,
            "seeds": list(range(scenario.station.seed, scenario.station.seed + scenario.num_seeds)),
            "trials_per_run": scenario.trials_per_run,
            "contacts": scenario.contacts,
            "trials_with_a_sole_slip": sum(r["sole_slipped"] for r in results),
            "noise": scenario.station.noise,
            "engine": engine_kind,
            "workers": workers,
            "push_start_s": scenario.push_start,
            "contact_duration_s": scenario.push_duration,
            "force_range_N": list(scenario.force_range),
            "max_angle_from_normal_deg": MAX_ANGLE_DEG,
            "wall_time_s": None,
            "no_contact_run": runs.get("no_contact"),
            "slow_motion_run": runs.get("slow_motion"),
        }
    )
    return metrics


@dataclass
class StudyRun:
    """What ``run_study`` returns: the study's trial ``specs`` (``sample_study_trials``), its
    ``metrics`` (``study_metrics``; per-trial results not yet in them), the trials' ``results``
    (each with its ``localizer_inputs``), the "replay" jobs' outputs (``replays``) and the
    wall time of each phase (``phases``, s)."""

    specs: list[dict]
    metrics: dict
    results: list[dict]
    replays: list
    phases: dict


def run_study(
    scenario: ContactLocalizationScenario,
    engine,
    *,
    calibration_folder: Callable[[], Path],
    start: float,
    replay_jobs: Callable[[list[dict], str], list[tuple]] | None = None,
    function: Callable[[tuple], tuple[str, object]] = run_job,
    progress: Callable[[int, int], None] | None = None,
) -> StudyRun:
    """Runs the study of ``scenario`` on ``engine`` (module docstring): calibrates its model
    (with ``model_refinement: calibrate``) into the folder ``calibration_folder()`` returns,
    called only then (``calibrate_study_model``; the scenario then names the saved file, and
    its ``multi_contact`` is set for two contacts), runs the first pass, then the
    cross-fitted one-or-two-contact fits, and assembles the metrics. ``start``: the study's
    start time (s, ``time.perf_counter``), from which the calibration phase is timed.
    ``replay_jobs(specs, scenario_yaml)``: jobs run at the end of the first pass by
    ``function`` (which runs the others as ``run_job`` does); ``progress`` as in
    ``run_jobs``, per pass."""
    specs = sample_study_trials(scenario)
    if scenario.station.model_refinement == "calibrate":
        calibrate_study_model(scenario, calibration_folder())
    phases = {"calibration": time.perf_counter() - start}  # wall time of each phase, s
    scenario_yaml = scenario_as_yaml(scenario)
    scenario.multi_contact = scenario.multi_contact or scenario.contacts == 2
    jobs = first_pass_jobs(scenario, specs, scenario_yaml)
    if replay_jobs is not None:
        jobs += replay_jobs(specs, scenario_yaml)
    mark = time.perf_counter()
    runs = run_jobs(jobs, engine, function, progress)
    phases["simulations"] = time.perf_counter() - mark
    results = runs.pop("trials")
    replays = runs.pop("replay", [])
    mark = time.perf_counter()
    if scenario.multi_contact:
        # After all trials: each seed's trials whitened with the model error under
        # load measured on the other seeds' (cross-fitting).
        _, handles = build_contact_localization_diagram(scenario, model_corrections=refined_model(scenario))
        covariances = runs.pop("covariances")
        multi_jobs = multi_contact_jobs(results, handles.station.estimator.plant, scenario_yaml, covariances)
        by_trial = {m.pop("trial"): m for m in run_jobs(multi_jobs, engine, function, progress)["multi_contact"]}
        for r in results:
            r.update(by_trial[r["trial"]])
    phases["one_or_two_contact_fits"] = time.perf_counter() - mark
    metrics = study_metrics(scenario, results, runs, engine.kind, engine.workers)
    return StudyRun(specs=specs, metrics=metrics, results=results, replays=replays, phases=phases)
