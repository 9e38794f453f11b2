"""The contact study's estimators run offline, and what its one-or-two-contact fit is whitened
with. A diagram built with ``online=False`` records the estimators' inputs at every update
(``estimator_log``); the residuals, the detector and the localizer then run on that record
(``estimate_run``: their own update code, the residuals stacked over the samples,
``systems.residuals.offline``). They report the same as in the loop, to rounding
(``tests/test_contact_localization.py``), for a fraction of the cost of Python systems
stepped at 1 kHz. ``offline_trial`` reads one trial from the replayed segments.

The ``MultiContactLocalizer`` of the study (``multi_contact_localizer``) whitens with the
averaged inputs' noise (``averaged_input_covariances``) and the model error under load
measured on pushes of known force (``load_model_error``), cross-fitted
(``cross_fitting_folds``). ``time_localizer_update`` and ``time_localizer_advance`` time one
localizer update, online and offline.
"""

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import Context

from diagrams.residuals.contact_study.builder import ContactLocalizationHandles, build_contact_localization_diagram
from diagrams.residuals.contact_study.scenario import ContactLocalizationScenario
from diagrams.simulation import simulate
from diagrams.station.config import replace_station
from systems.estimation.model_identification import ModelCorrections
from systems.residuals.contact_estimation import (
    ContactLocalizer,
    LocalizationResult,
    UnknownWrenches,
    _SensedConfiguration,
)
from systems.residuals.multi_contact import MultiContactLocalizer
from systems.residuals.offline import ReplayedEstimation, ReplayState, replay_contact_estimation

#: The averaged-input noise calibration's run without contact: its length and the start-up
#: it leaves out, s.
AVERAGED_NOISE_RUN_S, AVERAGED_NOISE_STARTUP_S = 3.0, 0.5


def averaged_input_covariances(
    scenario: ContactLocalizationScenario, model_corrections: ModelCorrections | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The noise of the localizer's averaged inputs without contact, for the multi-contact
    fit's chi-square tests: (external wrench 6 x 6 ([moment about the world origin; force],
    N m, N), internal residual n x n). Measured on a 3 s run without contact (its own noise
    seed; the first 0.5 s left out) as mu mu^T + Sigma 2 / (K T): the residuals' mean mu
    (model error: averaging does not remove it) plus their sample covariance Sigma scaled
    to the variance of a mean over T = push_duration - settle_time (a first-order residual
    of gain K, driven by white noise, has var(mean over T) = Sigma 2 / (K T) for T >> 1/K).
    On a robot without foot F/T sensors the residuals carry the ground's wrenches, which
    are unknowns of the fit, not model error: mu is the mean after each sample's
    least-squares ground wrenches (at the run's mean posture) are taken out (Sigma stays
    the raw residuals', whose sway of the ground wrenches the fit's projection removes).
    """
    seed = (scenario.station.seed * 100003 + 99971) % (2**31 - 1)
    calibration = dataclasses.replace(replace_station(scenario, seed=seed), push_body=None, motion=None)
    diagram, handles = build_contact_localization_diagram(
        calibration, model_corrections=model_corrections, online=False
    )
    simulate(diagram, AVERAGED_NOISE_RUN_S, set_initial_state=handles.station.set_initial_state)
    inputs = estimator_log(handles)
    replay = estimate_run(handles, inputs)
    keep = inputs.log_times >= AVERAGED_NOISE_STARTUP_S
    raw = np.concatenate((replay.external_wrench_world, replay.internal), axis=1)[keep]
    unexplained = raw
    estimator = handles.station.estimator
    if estimator.unknown_wrench_frames:
        kin = _SensedConfiguration(estimator.plant, "averaged_input_covariances")
        q = inputs.state[keep, : kin.nq].mean(axis=0)
        q[:4] /= np.linalg.norm(q[:4])
        kin.set_positions(q)
        unknown = UnknownWrenches(
            estimator.plant,
            estimator.unknown_wrench_frames,
            estimator.unknown_wrench_components,
            "averaged_input_covariances",
        )
        U = unknown.columns(kin)
        unexplained = raw - (U @ np.linalg.lstsq(U, raw.T, rcond=None)[0]).T
    blocks = []
    for rows, gain in ((slice(0, 6), scenario.external_gain), (slice(6, None), scenario.internal_gain)):
        x = raw[:, rows].T
        mean = unexplained[:, rows].mean(axis=0)
        averaging = max(scenario.push_duration - scenario.settle_time, scenario.period)
        blocks.append(np.outer(mean, mean) + np.cov(x) * min(1.0, 2.0 / (gain * averaging)))
    return blocks[0], blocks[1]


def multi_contact_localizer(
    handles: ContactLocalizationHandles,
    covariances: tuple[np.ndarray, np.ndarray],
    load_covariances: tuple[np.ndarray, np.ndarray] | None = None,
) -> MultiContactLocalizer:
    """The study's one-or-two-contact localizer on the estimators' plant of ``handles`` (keep
    them alive with it), the soles excluded, with the averaged inputs' ``covariances``
    (``averaged_input_covariances``) and, if given, the model error under load
    (``load_model_error``). On a robot without foot F/T sensors the soles' ground wrenches
    are its unknowns, and the load model is left out: it scales with the external
    residual's force, there the robot's weight as much as the push."""
    estimator = handles.station.estimator
    unknown = estimator.unknown_wrench_frames
    load_ext, load_int = (None, None) if load_covariances is None or unknown else load_covariances
    return MultiContactLocalizer(
        estimator.plant,
        estimator.scene_graph,
        exclude_bodies=handles.excluded_bodies,
        covariance_external=covariances[0],
        covariance_internal=covariances[1],
        load_covariance_external=load_ext,
        load_covariance_internal=load_int,
        unknown_wrench_frames=unknown,
        unknown_wrench_components=estimator.unknown_wrench_components,
    )


#: The fewest detected pushes of known force ``load_model_error`` measures the model error
#: on (fewer: the multi-contact fit whitens with the sensor noise alone).
MIN_LOAD_CALIBRATION_TRIALS = 20


def load_model_error(plant: MultibodyPlant, trials: Sequence[dict]) -> tuple[np.ndarray, np.ndarray]:
    """The residuals' error under load, per N^2 of the total external force, measured on
    pushes of known points and forces (the study's trials: each with its
    ``localizer_inputs`` and its ``contacts``): for trial k, e_k = b_k - sum_c A_c f_c, b_k
    the averaged [external wrench; internal residual] its localization used and A_c f_c
    what the true contact c predicts at the averaged q (eq. 20: [p_c x f_c; f_c] and
    J^fb_c^T f_c). Returns (sum_k e_ext e_ext^T, sum_k e_int e_int^T) / sum_k |F_k|^2, F_k
    the trial's total force: the ``load_covariance_external`` and ``_internal`` of
    ``MultiContactLocalizer``. The model error of a refined model under load (friction,
    inertial and torque-scale errors; the base-state estimator's errors) grows with the
    load; e_k also holds the averaged sensor noise, which makes the figure an upper bound.

    Raises:
        ValueError: no trial, or a trial without its inputs or contacts.
    """
    if not trials:
        raise ValueError("load_model_error needs at least one push of known force")
    kin = _SensedConfiguration(plant, "load_model_error")
    n = plant.num_velocities() - 6
    sum_ext, sum_int, load = np.zeros((6, 6)), np.zeros((n, n)), 0.0
    for trial in trials:
        try:
            inputs, contacts = trial["localizer_inputs"], trial.get("contacts", [trial])
            q = np.asarray(inputs["q"], dtype=float)
            wrench = np.asarray(inputs["external_wrench_world"], dtype=float)
            residual = np.asarray(inputs["residual"], dtype=float)
        except KeyError as missing:
            raise ValueError(f"load_model_error: trial {trial.get('trial')!r} has no {missing}") from None
        kin.set_positions(q)
        predicted_ext, predicted_int, total = np.zeros(6), np.zeros(n), np.zeros(3)
        for contact in contacts:
            body = plant.get_body(BodyIndex(int(contact["body_index"])))
            p_B = np.asarray(contact["point_body"], dtype=float)
            X_WB = kin.body_pose(body)
            p_W = X_WB[:, :3] @ p_B + X_WB[:, 3]
            f_W = np.asarray(contact["force_world"], dtype=float)
            predicted_ext += np.concatenate((np.cross(p_W, f_W), f_W))
            predicted_int += kin.floating_jacobian(body, p_B).T @ f_W
            total += f_W
        e_ext, e_int = wrench - predicted_ext, residual - predicted_int
        sum_ext += np.outer(e_ext, e_ext)
        sum_int += np.outer(e_int, e_int)
        load += float(total @ total)
    if not load > 0.0:
        raise ValueError("load_model_error: the pushes' total force is zero")
    return sum_ext / load, sum_int / load


def cross_fitting_folds(trials: Sequence[dict]) -> list[list[int]]:
    """The folds of the study's cross-fitting: the indices of ``trials`` per seed (with two
    or more seeds), else the even and the odd trials. Each fold's multi-contact fit uses the
    model error measured on the other folds (``load_model_error``), never on its own trials."""
    seeds = sorted({trial.get("seed", 0) for trial in trials})
    if len(seeds) >= 2:
        return [[i for i, trial in enumerate(trials) if trial.get("seed", 0) == seed] for seed in seeds]
    return [list(range(0, len(trials), 2)), list(range(1, len(trials), 2))]


def time_localizer_update(handles: ContactLocalizationHandles, context: Context, repeats: int = 20) -> float:
    """Median wall time [s] of one ContactLocalizer update with the trial's final inputs,
    each call at a slightly different q (so that no pose or mass matrix is reused)."""
    localizer = handles.localizer
    lc = localizer.GetMyContextFromRoot(context)
    x = np.array(localizer.GetInputPort("state").Eval(lc))
    probe = localizer.CreateDefaultContext()
    state_value = localizer.GetInputPort("state").FixValue(probe, x)
    for name in ("external_wrench_world", "residual", "contact_detected"):
        localizer.GetInputPort(name).FixValue(probe, np.array(localizer.GetInputPort(name).Eval(lc)))
    localizer.GetInputPort("contact_detected").FixValue(probe, [1.0])

    def update(x2: np.ndarray) -> None:
        state_value.GetMutableData().set_value(x2)
        localizer.EvalUniquePeriodicDiscreteUpdate(probe)

    return _median_update_time(update, x, handles.plant.num_positions(), repeats)


def time_localizer_advance(
    localizer: ContactLocalizer, x: np.ndarray, w: np.ndarray, r: np.ndarray, repeats: int = 20
) -> float:
    """``time_localizer_update`` without a diagram (offline estimation): the median wall
    time [s] of one update (``advance``, the code of the periodic update) from a new
    context's state with contact detected, at the inputs x, w, r."""
    start = localizer.initial_state()

    def update(x2: np.ndarray) -> None:
        localizer.advance(start, 0.0, x2, w, r, True)

    nq = len(x) - (len(r) + 6)  # x = [q; v], v = 6 base + n joint velocities
    return _median_update_time(update, np.array(x), nq, repeats)


def _median_update_time(update, x: np.ndarray, nq: int, repeats: int) -> float:
    rng = np.random.default_rng(0)
    samples = []
    for _ in range(repeats):
        x2 = x.copy()
        x2[7:nq] += 1e-6 * rng.normal(size=nq - 7)
        start = time.perf_counter()
        update(x2)
        samples.append(time.perf_counter() - start)
    return float(np.median(samples))


@dataclass
class EstimatorLog:
    """The estimators' inputs at every update of a run built with ``online=False``, in the
    order the updates ran: their times (N,), s, the times the online systems' outputs of
    each update would be logged (the next update's), and per update the sensed state
    [q; v], the motor torque the internal residual reads and the F/T wrenches in world.
    On a robot without foot F/T sensors also the simulator's normal force on each foot
    contact sphere (``FSR_NAMES`` order, N): ground truth for the metrics, which no
    estimator reads ((N, 0) otherwise)."""

    update_times: np.ndarray
    log_times: np.ndarray
    state: np.ndarray
    torque: np.ndarray
    wrenches: np.ndarray
    true_fsr_forces: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def estimator_log(handles: ContactLocalizationHandles) -> EstimatorLog:
    """The ``EstimatorLog`` of a run so far (its ``recorder``'s records)."""
    recorder = handles.recorder
    if recorder is None:
        raise ValueError("estimator_log: the estimators ran in the diagram (online): nothing was recorded")
    times = recorder.times
    period = handles.internal.period
    return EstimatorLog(
        update_times=times,
        log_times=np.append(times[1:], times[-1] + period) if times.size else times,
        state=recorder.values("state"),
        torque=recorder.values("torque"),
        wrenches=recorder.values("wrenches") if "wrenches" in recorder.names else np.zeros((times.size, 0)),
        true_fsr_forces=recorder.values("true_fsr_forces")
        if "true_fsr_forces" in recorder.names
        else np.zeros((times.size, 0)),
    )


def estimate_run(
    handles: ContactLocalizationHandles, log: EstimatorLog, start: ReplayState | None = None
) -> ReplayedEstimation:
    """The handles' residuals, detector and localizer run on the updates of ``log``
    (``replay_contact_estimation``), going on from ``start`` (the ``end`` of the updates
    before them; None: the run's first updates). The localizer's result is its
    state after the last update (what the study reads at a trial's end: ``end``)."""
    return replay_contact_estimation(
        handles.internal,
        handles.external,
        lambda *_: handles.detector,
        handles.localizer,
        log.state,
        log.torque,
        log.wrenches,
        start=start,
        times=log.update_times,
        localize_end_only=True,
    )


@dataclass
class OfflineTrial:
    """One trial's estimation from the log (``estimate_run``), as ``trial_result`` reads
    it: per logged update (log times, the window's updates and, for a run's first trial,
    the standing start's before them) the detector's flag and the time its detection began,
    the localization at the end, the inputs it was computed from ((q, wrench, residual),
    ``ContactLocalizer.localization_inputs``), and the last sensed state, external wrench
    and internal residual (the localizer's update time is measured at them)."""

    log_times: np.ndarray
    detected: np.ndarray
    detection_time: np.ndarray
    estimate: LocalizationResult
    localization_inputs: tuple[np.ndarray, np.ndarray, np.ndarray]
    last_inputs: tuple[np.ndarray, np.ndarray, np.ndarray]
    true_fsr_forces: np.ndarray | None = None


def offline_trial(
    handles: ContactLocalizationHandles,
    segments: Sequence[tuple[EstimatorLog, ReplayedEstimation]],
    detected_before: bool,
) -> OfflineTrial:
    """The ``OfflineTrial`` of one trial's replayed segments ``(log, replay)``
    (``estimate_run``), in time order, the last one ending at the trial's end;
    ``detected_before``: the detector's flag before the first of them."""
    times = np.concatenate([log.log_times for log, _ in segments])
    update_times = np.concatenate([log.update_times for log, _ in segments])
    detected = np.concatenate([replay.contact_detected for _, replay in segments])
    # The detector's detection_time output: the time of the update at which it last switched on.
    rising = np.flatnonzero(np.diff(np.concatenate(([detected_before], detected)).astype(np.int8)) > 0)
    since = np.full(detected.size, -1)
    since[rising] = rising
    since = np.maximum.accumulate(since)
    detection_time = np.where(since >= 0, update_times[np.maximum(since, 0)], 0.0)
    log, last = segments[-1]
    localizer = handles.localizer
    end = last.end.localizer
    truth = None
    forces = np.concatenate([log.true_fsr_forces for log, _ in segments])
    if forces.size:
        # The truth over the window the localizer's means average (else the last update).
        start = localizer.averaging_start(end[0])
        inside = update_times >= start if start is not None else np.zeros(update_times.size, dtype=bool)
        truth = forces[inside].mean(axis=0) if inside.any() else forces[-1]
    return OfflineTrial(
        log_times=times,
        detected=detected.astype(float),
        detection_time=detection_time,
        estimate=localizer.unpack(end[3]),
        localization_inputs=localizer.split_localized(end[2]),
        last_inputs=(log.state[-1], last.external_wrench_world[-1], last.internal[-1]),
        true_fsr_forces=truth,
    )
