"""The contact study's trials (Flacco et al. 2016, Secs. V-VI), as a worker runs them: a
chunk of random contacts simulated from one standing start, the runs without contact, and the
one-or-two-contact localization of finished trials. Every function takes plain data (trial
specs from ``sample_trials``, a ``ContactLocalizationScenario``) and returns plain dicts, so
that any engine (``apps.engine``: this process, a process pool, Ray actors) can run them and
the same inputs give the same results bit for bit wherever they run.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from diagrams.residuals.contact_study.builder import build_contact_localization_diagram
from diagrams.residuals.contact_study.metrics import multi_contact_result, no_contact_result, trial_result
from diagrams.residuals.contact_study.offline import estimate_run, estimator_log, multi_contact_localizer, offline_trial
from diagrams.residuals.contact_study.scenario import (
    ContactLocalizationScenario,
    no_contact_scenario,
    run_schedule,
    slow_motion_scenario,
    trial_scenario,
)
from diagrams.residuals.model_refinement import refined_model
from diagrams.simulation import simulate, start_simulation

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
        # ``start_simulation``, not ``simulate``: the run advances window by window from a cloned standing start.
        simulator = start_simulation(
            diagram, set_initial_state=handles.station.set_initial_state, simulator_config=scenario.simulator_config
        )
        context = simulator.get_mutable_context()
        plant_context = handles.plant.GetMyContextFromRoot(context)
        soles = handles.station.humanoid.sole_frames
        start = {name: frame.CalcPoseInWorld(plant_context) for name, frame in soles.items()}
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
                segments, resume = estimate_more(handles, segments, resume)
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
                segments, resume = estimate_more(handles, segments, resume)
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


def estimate_more(handles, segments: list, resume) -> tuple:
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


def run_no_contact(scenario: ContactLocalizationScenario, kind: str = "no_contact") -> dict:
    """A run without contact, standing for ``no_contact_duration`` s (``kind`` "no_contact",
    ``no_contact_scenario``) or in slow motion for ``slow_motion_duration`` s ("slow_motion",
    ``slow_motion_scenario``): its false detections.

    Raises:
        ValueError: a run's duration that is not positive and finite (``simulate``).
    """
    run_scenario = no_contact_scenario(scenario) if kind == "no_contact" else slow_motion_scenario(scenario)
    diagram, handles = build_contact_localization_diagram(run_scenario, model_corrections=refined_model(scenario))
    run = simulate(
        diagram,
        run_scenario.no_contact_duration,
        set_initial_state=handles.station.set_initial_state,
        simulator_config=run_scenario.simulator_config,
    )
    return no_contact_result(run_scenario, handles, run.context)
