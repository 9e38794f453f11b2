"""The contact study's results and metrics (Flacco et al. 2016, Secs. V-VI): one trial's
(``trial_result``), its one-or-two-contact localization (``multi_contact_result``), a run
without contact's (``no_contact_result``), and the study's totals against its floors
(``contact_localization_metrics``), with 95 % intervals (``study_statistics``).

Metric definitions: ``detection_rate`` = trials whose contact was detected during the push
(a detection before the push counts as a false detection, not as this trial's);
``correct_link_rate`` and the position errors are over ALL trials (a trial without a
localization counts as a wrong link and an infinite position error); force errors are over
the detected trials: |f_hat - f| / |f| and the angle between f_hat and f.
"""

import math
from collections.abc import Sequence

import numpy as np
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import Context

from diagrams.residuals.contact_study.builder import ContactLocalizationHandles
from diagrams.residuals.contact_study.offline import (
    OfflineTrial,
    estimate_run,
    estimator_log,
    time_localizer_advance,
    time_localizer_update,
)
from diagrams.residuals.contact_study.sampling import REGIONS
from diagrams.residuals.contact_study.scenario import FLOORS, ContactLocalizationScenario
from diagrams.residuals.study_statistics import (
    CONFIDENCE_LEVEL,
    percentile_with_inf,
    proportion_interval,
    quantile_interval,
    rate_table,
)
from diagrams.station.standing import foot_sphere_normal_forces
from systems.observer.fsr_sensing import FSR_SIDES
from systems.residuals.contact_estimation import VALID
from systems.residuals.multi_contact import MultiContactLocalizer


def trial_result(
    scenario: ContactLocalizationScenario,
    spec: dict,
    handles: ContactLocalizationHandles,
    context: Context,
    wall_time_s: float,
    *,
    push_indices: Sequence[int] = (0,),
    window: tuple[float, float, float] | None = None,
    restored_at_start: bool = False,
    detected_at_start: bool = False,
    offline: OfflineTrial | None = None,
) -> dict:
    """The results of the trial ``spec`` at the end of its push, from the simulator's root
    ``context``: detection and its delay, the localized link and point, the force errors,
    and the localizer's update time (module docstring); ``wall_time_s``: the simulation's
    wall time. The trial is the pushes ``push_indices`` of the run (one per contact; the
    single-contact localizer's figures are for the first), in ``window`` (previous
    trial's end, push start, push end; default: the scenario's one push,
    ``trial_scenario``): a detection in the window before the push is a false detection,
    and a detector still on at the push's start (a contact that never ended) leaves the
    push undetected. ``localizer_inputs`` holds the (averaged) q, external wrench and
    internal residual of the final localization, as arrays
    (``ContactLocalizer.localization_inputs``: the study's localizations can be replayed
    offline; the study's one-or-two-contact localization, ``multi_contact_result``, runs on
    them after all trials). ``restored_at_start``: the run's state was
    restored to its standing start at the window's start (``shared_standing_start``), so
    the detector's flag there is the saved start's, ``detected_at_start``, whatever the
    log's last sample before it says. ``offline``:
    the trial's estimation from the log (``online=False`` diagrams), read instead of the
    online estimators' loggers and state."""
    if window is None:
        window = (0.0, scenario.push_start, scenario.push_start + scenario.push_duration)
    previous_end, push_start, t_end = window
    if offline is None:
        estimate = handles.localizer.estimate(handles.localizer.GetMyContextFromRoot(context))
        log = handles.loggers["contact_detected"].FindLog(context)
        t, detected = log.sample_times(), log.data()[0]
        times = handles.loggers["detection_time"].FindLog(context).data()[0]
    else:
        estimate = offline.estimate
        t, detected, times = offline.log_times, offline.detected, offline.detection_time
    pc = handles.push_source.GetMyContextFromRoot(context)
    points = np.array(handles.push_source.GetOutputPort("point_world").Eval(pc)).reshape(-1, 3)
    true_points = points[list(push_indices)]
    true_point = true_points[0]
    f_true = np.asarray(spec["force_world"])

    before = t <= previous_end
    if restored_at_start:
        state_before = 1.0 if detected_at_start else 0.0
    else:
        state_before = detected[before][-1] if before.any() else 0.0
    inside = ~before & (t <= t_end)
    t, detected, times = t[inside], detected[inside], times[inside]
    rising = np.flatnonzero(np.diff(np.concatenate(([state_before], detected))) > 0.5)
    false_before = int(np.sum(t[rising] < push_start))
    at_start = t < push_start
    on_at_start = bool(detected[at_start][-1] > 0.5) if at_start.any() else state_before > 0.5
    during = (t >= push_start) & (detected > 0.5)
    result = {
        **spec,
        "detected": bool(during.any()) and not on_at_start,
        "detector_on_at_push_start": on_at_start,
        "false_detections_before_push": false_before,
        "detection_delay_s": None,
        "status": estimate.status,
        "status_reason": estimate.reason,
        "estimated_body_index": estimate.body_index,
        "estimated_body": handles.plant.get_body(BodyIndex(estimate.body_index)).name()
        if estimate.body_index >= 0
        else None,
        "correct_link": handles.localizer.same_link(estimate.body_index, spec["body_index"]),
        "position_error_m": None,
        "force_error_rel": None,
        "angle_error_deg": None,
        "score": estimate.score if math.isfinite(estimate.score) else None,
        "runner_up_score": estimate.runner_up_score if math.isfinite(estimate.runner_up_score) else None,
        "true_point_world": true_point.tolist(),
        "estimated_point_world": estimate.point_W.tolist(),
        "estimated_force_world": estimate.force_W.tolist(),
        "simulation_wall_s": wall_time_s,
    }
    if result["detected"]:
        first = np.flatnonzero(during)[0]
        result["detection_delay_s"] = float(times[first] - push_start)
        f_hat = estimate.force_W
        result["force_error_rel"] = float(np.linalg.norm(f_hat - f_true) / np.linalg.norm(f_true))
        cos = float(f_hat @ f_true / max(np.linalg.norm(f_hat) * np.linalg.norm(f_true), 1e-300))
        result["angle_error_deg"] = math.degrees(math.acos(min(1.0, max(-1.0, cos))))
    if estimate.body_index >= 0:
        result["position_error_m"] = float(np.linalg.norm(estimate.point_W - true_point))
    if offline is None:
        result["localizer_update_s"] = time_localizer_update(handles, context)
        q, wrench, residual = handles.localizer.localization_inputs(handles.localizer.GetMyContextFromRoot(context))
    else:
        result["localizer_update_s"] = time_localizer_advance(handles.localizer, *offline.last_inputs)
        q, wrench, residual = offline.localization_inputs
    result["localizer_inputs"] = {"q": q, "external_wrench_world": wrench, "residual": residual}
    result["true_points_world"] = true_points.tolist()
    if handles.station.estimator.unknown_wrench_frames and not handles.station.estimator.fsr_sides:
        # The ground's normal force on each sole without F/T sensors or FSRs (sides sorted,
        # as the estimators' unknown wrench frames): what the fits estimate (FSRs measure it). Averaged over the
        # window the localizer's means average when the estimators ran offline, else at
        # the push's end.
        plant, humanoid = handles.plant, handles.station.humanoid
        plant_context = plant.GetMyContextFromRoot(context)
        sides = [s for s in sorted(humanoid.sole_frames) if s not in humanoid.ft_sensor_joints]
        if offline is not None and offline.true_fsr_forces is not None:
            per_sphere = offline.true_fsr_forces.reshape(len(FSR_SIDES), -1)
            forces = {side: per_sphere[FSR_SIDES.index(side)] for side in sides}
        else:
            forces = foot_sphere_normal_forces(plant, plant_context, humanoid)
        result["true_foot_normal_forces_N"] = [float(np.sum(forces[s])) for s in sides]
        result["robot_weight_N"] = float(
            plant.CalcTotalMass(plant_context) * -plant.gravity_field().gravity_vector()[2]
        )
    return result


def _not_localized(contacts: int) -> dict:
    """``multi_contact_result`` of a trial without inputs to localize: no contact found."""
    out = {
        "contacts_estimated": 0,
        "p_value_one": None,
        "estimated_contact_bodies": [],
        "estimated_contact_body_names": [],
    }
    if contacts == 1:
        out.update(fit_correct_link=False, fit_valid=False, fit_position_error_m=None)
    else:
        out.update(
            contact_position_errors_m=[math.inf, math.inf],
            contact_force_errors_rel=[math.inf, math.inf],
            two_contact_fit_links_right=False,
            contact_links_right=False,
        )
    return out


def multi_contact_result(
    multi_contact: MultiContactLocalizer,
    q: np.ndarray,
    wrench_W: np.ndarray,
    residual: np.ndarray,
    true_bodies: Sequence[int],
    true_points_W: np.ndarray,
    true_forces_W: np.ndarray,
) -> dict:
    """One trial's one-or-two-contact localization (``MultiContactLocalizer.localize`` on
    the localizer's averaged inputs) against its true contacts: ``contacts_estimated`` (0,
    1 or 2), ``p_value_one`` (the single-contact fit's chi-square p-value); for one true
    contact, the stacked fit as a single-contact localizer: ``fit_correct_link`` (one
    contact reported, on the true link), ``fit_valid`` (``MultiContactResult.valid``) and
    ``fit_position_error_m`` (None unless one contact is reported); and, for two true
    contacts, ``contact_links_right`` (two contacts reported, on the two true
    links) and the position and force errors of the two-contact fit's contacts matched to
    the true ones (the pairing with the smaller total position error)."""
    if not np.any(q):  # the trial was never localized (no detection): its inputs are zeros
        return _not_localized(len(true_bodies))
    estimate = multi_contact.localize(q, wrench_W, residual, max_contacts=2)
    out = {
        "contacts_estimated": int(estimate.num_contacts),
        "p_value_one": None if math.isnan(estimate.p_value_one) else float(estimate.p_value_one),
        "estimated_contact_bodies": [int(b) for b in estimate.body_indices],
        "estimated_contact_body_names": [multi_contact.body_name(b) for b in estimate.body_indices],
    }
    if estimate.one is not None and estimate.one.unknown_wrenches.size and not multi_contact.partly_known_wrenches:
        # The ground's normal force on each sole of the single-contact fit (world z; FSRs
        # measure it where the soles' wrenches are partly known).
        out["foot_normal_forces_N"] = [float(w[5]) for w in estimate.one.unknown_wrenches]
    if len(true_bodies) == 1:
        one = estimate.num_contacts == 1
        out["fit_correct_link"] = bool(one and multi_contact.same_link(estimate.body_indices[0], true_bodies[0]))
        out["fit_valid"] = bool(estimate.valid)
        out["fit_position_error_m"] = float(np.linalg.norm(estimate.points_W[0] - true_points_W[0])) if one else None
    if len(true_bodies) == 2:
        two = estimate.two if estimate.two is not None else multi_contact.fit_two(q, wrench_W, residual)
        if len(two.body_indices) == 2:
            pairs = [(0, 1), (1, 0)]
            errors = [
                [float(np.linalg.norm(two.points_W[e] - true_points_W[t])) for t, e in enumerate(order)]
                for order in pairs
            ]
            best = int(np.argmin([sum(e) for e in errors]))
            order = pairs[best]
            out["contact_position_errors_m"] = errors[best]
            out["contact_force_errors_rel"] = [
                float(np.linalg.norm(two.forces_W[e] - true_forces_W[t]) / np.linalg.norm(true_forces_W[t]))
                for t, e in enumerate(order)
            ]
            out["two_contact_fit_links_right"] = all(two.body_indices[e] == true_bodies[t] for t, e in enumerate(order))
        else:
            out["contact_position_errors_m"] = [math.inf, math.inf]
            out["contact_force_errors_rel"] = [math.inf, math.inf]
            out["two_contact_fit_links_right"] = False
        out["contact_links_right"] = estimate.num_contacts == 2 and sorted(estimate.body_indices) == sorted(true_bodies)
    return out


def no_contact_result(
    scenario: ContactLocalizationScenario, handles: ContactLocalizationHandles, context: Context
) -> dict:
    """The run without contact (``no_contact_scenario``) of ``scenario.no_contact_duration`` s:
    the number of OFF->ON switches of the detector, and the largest test statistics over
    their thresholds after the detector's start-up time (before it the detector ignores
    them: the residuals and the base-state estimator start). A run built with
    ``online=False`` runs its estimators on its log here (``estimate_run``)."""
    if handles.online:
        log = handles.loggers["contact_detected"].FindLog(context)
        detected = log.data()[0]
        stats_log = handles.loggers["test_statistics"].FindLog(context)
        stats = stats_log.data()[:, stats_log.sample_times() >= handles.detector.startup_time]
    else:
        inputs = estimator_log(handles)
        replay = estimate_run(handles, inputs)
        detected = replay.contact_detected.astype(float)
        stats = replay.test_statistics[inputs.log_times >= handles.detector.startup_time].T
    on = handles.detector.thresholds["on"]
    return {
        "duration_s": scenario.no_contact_duration,
        "motion": "standing" if scenario.motion is None else "slow whole-body motion",
        "noise_seed": scenario.station.seed,
        "false_detections": int(np.sum(np.diff(np.concatenate(([0.0], detected))) > 0.5)),
        "max_statistic_over_threshold": [float(stats[0].max() / on[0]), float(stats[1].max() / on[1])],
    }


def _multi_contact_metrics(results: list[dict]) -> dict:
    """The one-or-two-contact localization's totals (``multi_contact_result``), where the
    trials went through it: ``more_than_one_contact_rate`` (trials it said 2 contacts),
    and for two-contact trials ``both_links_right_rate``, the two-contact fit's own
    ``two_contact_fit_links_right_rate`` and its per-contact position and force errors
    (median, p95; over all contacts of all trials)."""
    checked = [r for r in results if "contacts_estimated" in r]
    if not checked:
        return {}
    out = {
        "multi_contact_trials": len(checked),
        "more_than_one_contact_rate": float(np.mean([r["contacts_estimated"] == 2 for r in checked])),
        "p_value_one_below_0.05_rate": float(
            np.mean([r["p_value_one"] is not None and r["p_value_one"] < 0.05 for r in checked])
        ),
    }
    single = [r for r in checked if "fit_correct_link" in r]
    if single:
        valid = [r for r in single if r["fit_valid"]]
        positions = np.array(
            [math.inf if r["fit_position_error_m"] is None else r["fit_position_error_m"] for r in single]
        )
        out.update(
            {
                "fit_correct_link_rate": float(np.mean([r["fit_correct_link"] for r in single])),
                "fit_valid_rate": len(valid) / len(single),
                "fit_valid_precision": float(np.mean([r["fit_correct_link"] for r in valid])) if valid else None,
                "fit_median_position_error_m": percentile_with_inf(positions, 50),
                "fit_p95_position_error_m": percentile_with_inf(positions, 95),
            }
        )
    two = [r for r in checked if "contact_links_right" in r]
    if two:
        positions = np.concatenate([r["contact_position_errors_m"] for r in two])
        forces = np.concatenate([r["contact_force_errors_rel"] for r in two])
        out.update(
            {
                "both_links_right_rate": float(np.mean([r["contact_links_right"] for r in two])),
                "two_contact_fit_links_right_rate": float(np.mean([r["two_contact_fit_links_right"] for r in two])),
                "median_contact_position_error_m": float(np.median(positions)),
                "p95_contact_position_error_m": percentile_with_inf(positions, 95),
                "median_contact_force_error_rel": float(np.median(forces)),
                "p95_contact_force_error_rel": percentile_with_inf(forces, 95),
            }
        )
    return out


def _intervals_and_tables(results: list[dict], detected: list, valid: list, positions, forces) -> dict:
    """The study's 95 % intervals (``study_statistics``: Clopper-Pearson for the rates,
    order statistics for the quantiles), its per-link table of the right-link rate, and the
    confusion list of its misses (true link -> estimated link or status, with counts)."""
    n = len(results)
    if n == 0:
        return {"intervals": {}, "per_link": [], "confusion": []}
    intervals = {
        "detection_rate": proportion_interval(len(detected), n),
        "correct_link_rate": proportion_interval(sum(r["correct_link"] for r in results), n),
        "valid_rate": proportion_interval(len(valid), n),
        "median_position_error_m": quantile_interval(positions, 0.5),
        "p95_position_error_m": quantile_interval(positions, 0.95),
    }
    if valid:
        intervals["valid_precision"] = proportion_interval(sum(r["correct_link"] for r in valid), len(valid))
    checked = [r for r in results if "contacts_estimated" in r]
    if checked:
        intervals["more_than_one_contact_rate"] = proportion_interval(
            sum(r["contacts_estimated"] == 2 for r in checked), len(checked)
        )
    single = [r for r in checked if "fit_correct_link" in r]
    if single:
        valid = [r for r in single if r["fit_valid"]]
        intervals["fit_correct_link_rate"] = proportion_interval(
            sum(r["fit_correct_link"] for r in single), len(single)
        )
        intervals["fit_valid_rate"] = proportion_interval(len(valid), len(single))
        if valid:
            intervals["fit_valid_precision"] = proportion_interval(
                sum(r["fit_correct_link"] for r in valid), len(valid)
            )
        fit_positions = [math.inf if r["fit_position_error_m"] is None else r["fit_position_error_m"] for r in single]
        intervals["fit_median_position_error_m"] = quantile_interval(fit_positions, 0.5)
        intervals["fit_p95_position_error_m"] = quantile_interval(fit_positions, 0.95)
    two = [r for r in checked if "contact_links_right" in r]
    if two:
        intervals["both_links_right_rate"] = proportion_interval(sum(r["contact_links_right"] for r in two), len(two))
        positions = np.concatenate([r["contact_position_errors_m"] for r in two])
        intervals["median_contact_position_error_m"] = quantile_interval(positions, 0.5)
    if forces:
        intervals["median_force_error_rel"] = quantile_interval(forces, 0.5)
    confusion: dict[tuple[str, str], int] = {}
    if two and len(two) == n:
        # Two contacts per trial: a trial is right when both links are; a pushed link is
        # found when the answer has two contacts and names it.
        for r in results:
            if not r["contact_links_right"]:
                found = r.get("estimated_contact_body_names", [])
                shown = " + ".join(sorted(found)) if found else "no contact"
                if len(found) == 1:
                    shown += " (one contact)"
                key = (" + ".join(sorted(c["body"] for c in r["contacts"])), shown)
                confusion[key] = confusion.get(key, 0) + 1
        pushed = [
            {
                "body": c["body"],
                "found": r["contacts_estimated"] == 2 and c["body"] in r["estimated_contact_body_names"],
            }
            for r in results
            for c in r["contacts"]
        ]
        per_link = rate_table(pushed, lambda p: p["body"], lambda p: p["found"])
        per_seed = rate_table(results, lambda r: str(r.get("seed", "")), lambda r: r["contact_links_right"])
    else:
        for r in results:
            if not r["correct_link"]:
                key = (r["body"], r["estimated_body"] or f"none ({r['status_reason']})")
                confusion[key] = confusion.get(key, 0) + 1
        per_link = rate_table(results, lambda r: r["body"], lambda r: r["correct_link"])
        per_seed = rate_table(results, lambda r: str(r.get("seed", "")), lambda r: r["correct_link"])
    fit_tables = {}
    if single and len(single) == n:  # the stacked fit as the single-contact localizer
        fit_tables = {
            "fit_per_link": rate_table(single, lambda r: r["body"], lambda r: r["fit_correct_link"]),
            "fit_per_seed": rate_table(single, lambda r: str(r.get("seed", "")), lambda r: r["fit_correct_link"]),
        }
    return {
        "intervals": {k: [float(a), float(b)] for k, (a, b) in intervals.items()},
        "interval_level": CONFIDENCE_LEVEL,
        **fit_tables,
        "per_link": per_link,
        "per_seed": per_seed,
        "confusion": [
            {"true": t, "estimated": e, "count": c}
            for (t, e), c in sorted(confusion.items(), key=lambda item: (-item[1], item[0]))
        ],
    }


def _region_table(results: list[dict]) -> list[dict]:
    """Per body region (``REGIONS``, of the first contact): trials, detection rate, the
    eq. (22) localizer's right-link rate and median position error (inf counted for a
    trial without localization), and the stacked fit's where it ran."""
    table = []
    for region in REGIONS:
        rows = [r for r in results if r.get("region") == region]
        if not rows:
            continue
        positions = [math.inf if r["position_error_m"] is None else r["position_error_m"] for r in rows]
        entry = {
            "region": region,
            "trials": len(rows),
            "detection_rate": float(np.mean([r["detected"] for r in rows])),
            "correct_link_rate": float(np.mean([r["correct_link"] for r in rows])),
            "median_position_error_m": float(np.median(positions)),
        }
        sole_forces = _sole_force_rms(rows)
        if sole_forces is not None:
            entry["foot_normal_force_rms_error_of_weight"] = sole_forces[1]
        fits = [r for r in rows if "fit_correct_link" in r]
        if fits:
            entry["fit_correct_link_rate"] = float(np.mean([r["fit_correct_link"] for r in fits]))
            entry["fit_median_position_error_m"] = float(
                np.median([math.inf if r["fit_position_error_m"] is None else r["fit_position_error_m"] for r in fits])
            )
        table.append(entry)
    return table


def _sole_force_rms(results: list[dict]) -> tuple[float, float] | None:
    """(RMS error N, the same of the robot's weight) of the stacked fit's ground normal
    force per sole against the simulator's, over the detected ``results`` that have both
    (None when none has)."""
    errors, weights = [], []
    for r in results:
        if r["detected"] and "foot_normal_forces_N" in r and "true_foot_normal_forces_N" in r:
            errors.extend(np.subtract(r["foot_normal_forces_N"], r["true_foot_normal_forces_N"]).tolist())
            weights.append(r["robot_weight_N"])
    if not errors:
        return None
    rms = float(np.sqrt(np.mean(np.square(errors))))
    return rms, rms / float(np.mean(weights))


def _foot_force_metrics(results: list[dict]) -> dict:
    """Without foot F/T sensors: the sole normal force RMS error (``_sole_force_rms``) over
    the detected trials, and over those whose eq. (22) localization is VALID: the
    localizer's claim that the residuals tell the contact from the ground's wrenches. A
    push on a stance leg is not told from them, and its fit may trade the push for the
    ground's wrench (errors of kilonewtons); the eq. (22) localizer's per-link rivals do
    not call one valid, while the stacked fit's own ``valid`` sometimes does (its
    runner-up comes from the refitted links only). {} without such trials."""
    every = _sole_force_rms(results)
    if every is None:
        return {}
    out = {"foot_normal_force_rms_error_N": every[0], "foot_normal_force_rms_error_of_weight": every[1]}
    valid = _sole_force_rms([r for r in results if r["status"] == VALID])
    if valid is not None:
        out["foot_normal_force_rms_error_valid_N"] = valid[0]
        out["foot_normal_force_rms_error_valid_of_weight"] = valid[1]
    return out


def contact_localization_metrics(
    results: list[dict], no_contact: dict | None, slow_motion: dict | None = None, floors: dict | None = None
) -> dict:
    """The study's totals (module docstring) from its trials' ``trial_result``s and the
    ``no_contact_result`` of its standing run and of its slow-motion run (None: skipped),
    and whether each meets its floor (``floors``, default ``FLOORS``; see ``floors_for``;
    None: not measured). ``false_detections`` counts all three; its floor is judged only
    with a standing run without contact (``no_contact`` of a positive duration): the
    trials' quiet starts alone do not make it met."""
    floors = FLOORS if floors is None else floors
    n = len(results)
    detected = [r for r in results if r["detected"]]
    delays = [r["detection_delay_s"] for r in detected]
    positions = np.array([r["position_error_m"] if r["position_error_m"] is not None else np.inf for r in results])
    forces = [r["force_error_rel"] for r in detected]
    angles = [r["angle_error_deg"] for r in detected]
    updates = np.array([r["localizer_update_s"] for r in results]) * 1e3

    def median(values):
        return float(np.median(values)) if len(values) else None

    metrics = {
        "trials": n,
        "detection_rate": len(detected) / n if n else None,
        "median_detection_delay_s": median(delays),
        "p95_detection_delay_s": float(np.percentile(delays, 95)) if delays else None,
        "false_detections": (no_contact["false_detections"] if no_contact else 0)
        + (slow_motion["false_detections"] if slow_motion else 0)
        + sum(r["false_detections_before_push"] for r in results),
        "false_detections_no_contact_run": no_contact["false_detections"] if no_contact else None,
        "no_contact_run_s": no_contact["duration_s"] if no_contact else None,
        "false_detections_slow_motion_run": slow_motion["false_detections"] if slow_motion else None,
        "slow_motion_run_s": slow_motion["duration_s"] if slow_motion else None,
        "false_detections_before_push_in_trials": sum(r["false_detections_before_push"] for r in results),
        "correct_link_rate": float(np.mean([r["correct_link"] for r in results])) if n else None,
        "valid_rate": float(np.mean([r["status"] == 0 for r in results])) if n else None,
        "ambiguous_rate": float(np.mean([r["status"] == 4 for r in results])) if n else None,
        "median_position_error_m": float(np.median(positions)) if n else None,
        "p95_position_error_m": percentile_with_inf(positions, 95) if n else None,
        "median_position_error_correct_link_m": median([r["position_error_m"] for r in results if r["correct_link"]]),
        "median_force_error_rel": median(forces),
        "p95_force_error_rel": float(np.percentile(forces, 95)) if forces else None,
        "median_angle_error_deg": median(angles),
        "p95_angle_error_deg": float(np.percentile(angles, 95)) if angles else None,
        "median_localizer_update_ms": float(np.median(updates)) if n else None,
        "max_localizer_update_ms": float(np.max(updates)) if n else None,
        "status_counts": {
            reason: sum(r["status_reason"] == reason for r in results)
            for reason in sorted({r["status_reason"] for r in results})
        },
        "wrong_links": [
            {"trial": r["trial"], "true": r["body"], "estimated": r["estimated_body"], "status": r["status_reason"]}
            for r in results
            if not r["correct_link"]
        ],
    }
    valid = [r for r in results if r["status"] == 0]
    metrics["valid_precision"] = float(np.mean([r["correct_link"] for r in valid])) if valid else None
    metrics["per_region"] = _region_table(results)
    for row in metrics["per_region"]:  # flat, for the floors
        for key in ("correct_link_rate", "fit_correct_link_rate"):
            if key in row:
                metrics[f"{key}_{row['region']}"] = row[key]
    metrics.update(_foot_force_metrics(results))
    metrics.update(_multi_contact_metrics(results))
    metrics.update(_intervals_and_tables(results, detected, valid, positions, forces))
    checks = {}
    for key, (op, floor) in floors.items():
        value = metrics.get(key)
        checks[key] = None if value is None else bool(value >= floor if op == ">=" else value <= floor)
    if "false_detections" in checks and not (no_contact and no_contact["duration_s"] > 0):
        checks["false_detections"] = None  # no standing run without contact: the floor is not judged
    metrics["floors"] = {k: f"{op} {v}" for k, (op, v) in floors.items()}
    metrics["meets_floors"] = checks
    return metrics
