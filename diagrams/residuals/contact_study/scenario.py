"""The contact study's scenario (Flacco et al. 2016, Secs. V-VI): ``ContactLocalizationScenario``,
the floors its totals are judged against (``floors_for``), and the runs it is made of: one
trial's push (``scenario_push``, ``trial_scenario``), several trials one after another in one run
(``run_schedule``), and the runs without contact (``no_contact_scenario``,
``slow_motion_scenario``).

Scenarios are YAML files loaded into ``ContactLocalizationScenario`` with
``pydrake.common.yaml.yaml_load_typed`` (``diagrams.scenarios``).
"""

# No ``from __future__ import annotations``: yaml_load_typed reads the scenario's field types.

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.analysis import SimulatorConfig

from diagrams.station.config import StationConfig, replace_station
from diagrams.station.motions import SlowMotion
from models import is_humanoid, robot_description
from systems.simulation.disturbances import Push, Step

#: Issue 12's single-contact floors on the stacked fit (``MultiContactLocalizer`` as a
#: single-contact localizer, once per push on the averaged inputs: ``multi_contact_result``).
STACKED_FIT_FLOORS = {
    "fit_correct_link_rate": (">=", 0.97),
    "fit_valid_precision": (">=", 0.995),
    "fit_valid_rate": (">=", 0.90),
    "fit_median_position_error_m": ("<=", 0.01),
    "fit_p95_position_error_m": ("<=", 0.03),
}

#: The floors on the study's totals in the ideal world: (comparison, value). Issue 5's,
#: raised by issue 12 (right link, position, valid precision and coverage, and "more than
#: one contact" on single contacts).
FLOORS = {
    "detection_rate": (">=", 0.99),
    "median_detection_delay_s": ("<=", 0.020),
    "false_detections": ("<=", 0),
    "correct_link_rate": (">=", 0.97),
    "median_position_error_m": ("<=", 0.01),
    "p95_position_error_m": ("<=", 0.03),
    "median_force_error_rel": ("<=", 0.05),
    "median_angle_error_deg": ("<=", 5.0),
    "valid_precision": (">=", 0.995),
    "valid_rate": (">=", 0.90),
    "more_than_one_contact_rate": ("<=", 0.02),
    "median_localizer_update_ms": ("<=", 2.0),
    **STACKED_FIT_FLOORS,
}

#: The floors for the realistic world, after model refinement: issue 11's (detection,
#: false detections, force), raised by issue 12's single-contact floors, which hold for
#: "the default noisy column" too (right link, position, valid precision and coverage,
#: "more than one contact", update time).
REALISTIC_FLOORS = {
    "detection_rate": (">=", 0.98),
    "false_detections": ("<=", 0),
    "correct_link_rate": (">=", 0.97),
    "median_position_error_m": ("<=", 0.01),
    "p95_position_error_m": ("<=", 0.03),
    "median_force_error_rel": ("<=", 0.10),
    "valid_precision": (">=", 0.995),
    "valid_rate": (">=", 0.90),
    "more_than_one_contact_rate": ("<=", 0.02),
    "median_localizer_update_ms": ("<=", 2.0),
    **STACKED_FIT_FLOORS,
}

#: Issue 12's floors for two simultaneous contacts (``contacts`` 2), in both worlds.
TWO_CONTACT_FLOORS = {
    "detection_rate": (">=", 0.99),
    "false_detections": ("<=", 0),
    "both_links_right_rate": (">=", 0.80),
    "median_contact_position_error_m": ("<=", 0.03),
    "median_contact_force_error_rel": ("<=", 0.10),
    "more_than_one_contact_rate": (">=", 0.90),
}


#: Issue 36's floors for one contact on a robot without foot F/T sensors (the ground's
#: wrenches unknowns of the estimators), per body region (``REGIONS``), in both worlds.
NO_FOOT_FT_FLOORS = {
    "detection_rate": (">=", 0.99),
    "false_detections": ("<=", 0),
    "correct_link_rate_arms": (">=", 0.90),
    "correct_link_rate_torso": (">=", 0.90),
    "correct_link_rate_legs": (">=", 0.70),
    "fit_correct_link_rate_arms": (">=", 0.90),
    "fit_correct_link_rate_torso": (">=", 0.90),
    "fit_correct_link_rate_legs": (">=", 0.70),
    "median_position_error_m": ("<=", 0.02),
    "fit_median_position_error_m": ("<=", 0.02),
    "foot_normal_force_rms_error_valid_of_weight": ("<=", 0.05),
}

#: ``NO_FOOT_FT_FLOORS`` for a robot whose feet have FSRs: their normal forces are measured,
#: not estimated, so the sole force floor has nothing to judge.
FSR_FEET_FLOORS = {k: v for k, v in NO_FOOT_FT_FLOORS.items() if not k.startswith("foot_normal_force")}


def lacks_foot_ft_sensors(model: str) -> bool:
    """Whether the humanoid ``model`` (a built-in name or a robot description) has a foot
    without an F/T sensor (False for anything else)."""
    if not is_humanoid(model):
        return False
    return any(foot.sensing != "force_torque" for foot in robot_description(model).feet.values())


def has_fsr_feet(model: str) -> bool:
    """Whether the humanoid ``model`` has a foot with FSRs (``sensing: fsr``): their normal
    forces are measurements, not estimates of the study (False for anything else)."""
    if not is_humanoid(model):
        return False
    return any(foot.sensing == "fsr" for foot in robot_description(model).feet.values())


def floors_for(scenario: "ContactLocalizationScenario") -> dict:
    """``TWO_CONTACT_FLOORS`` for two contacts; ``NO_FOOT_FT_FLOORS`` on a robot without
    foot F/T sensors (``FSR_FEET_FLOORS`` where FSRs measure the sole forces); else ``FLOORS``
    in the ideal world, ``REALISTIC_FLOORS`` otherwise (any imperfection, the EKF base state
    or a refined model)."""
    if scenario.contacts == 2:
        return TWO_CONTACT_FLOORS
    if lacks_foot_ft_sensors(scenario.station.model):
        return FSR_FEET_FLOORS if has_fsr_feet(scenario.station.model) else NO_FOOT_FT_FLOORS
    return FLOORS if scenario.station.is_ideal else REALISTIC_FLOORS


#: The random contacts of the localization study (``sample_trials``): force magnitude, N,
#: and the largest angle between the force and the surface's inward normal, deg.
MIN_FORCE, MAX_FORCE, MAX_ANGLE_DEG = 5.0, 40.0, 60.0


@dataclass(slots=True)
class ContactLocalizationScenario:
    """The contact study, and one run of its diagram. SI units.

    Attributes:
        station: the robot (``hrp4_like``, or any humanoid description: its feet with F/T
            sensors, FSRs or no sensing) and its world (``diagrams.station.config``):
            realistic by default, ideal with ``--ideal``. Its ``seed`` is the sensor noise
            seed of one run; the study's first seed, from which it samples the trials and
            derives each run's noise seed.
        push_body: the pushed link, or None for a run without contact (the study sets each
            trial's push_body, push_point, push_force and seed from ``sample_trials``).
        push_point: the contact point in the link's body frame, m.
        push_force: the (constant) force in world, N.
        push_start: s; the force is on for push_start <= t < push_start + push_duration
            (the study: the first trial of each run).
        push_duration: s (the study's contact duration).
        trial_gap: the study's pause between two trials of one run, s (with
            ``trials_per_run`` > 1).
        trials_per_run: the study's trials simulated one after another in one run
            (``run_schedule``), ``trial_gap`` apart, the robot and the residuals coming
            back to rest in between; 1 (default): each trial from the standing start, as
            in the paper. Runs of several trials test a robot that has been pushed
            before (when this was measured its feet slipped, and the realistic world's
            detector did not always release within the gap; see the git history of
            BENCHMARKS.md).
        shared_standing_start: with ``trials_per_run`` 1, the study simulates the standing
            start (the first ``push_start`` seconds) once per job of trials and restores its
            state before each trial's push (``diagrams.residuals.contact_study.trials.run_trials``): the
            same start as simulating it for each trial, at a third less simulated time per
            trial (1 s pushes). The trials' pushes then follow one another in time, so each
            push sees sensor noise of its own; what the trials of one job share is the
            noise of the start. False: each trial simulates its own standing start.
        num_seeds: the study samples its trials from the seeds s, s + 1, ...,
            s + num_seeds - 1 (s: ``station.seed``) (``trials`` split evenly; a figure that holds on one seed
            only is not a result).
        trials: the study's number of random contacts (over all its seeds).
        contacts: contacts per trial: 1, or 2 (two links pushed at once; ``sample_trials``).
        force_range: the pushes' magnitudes are drawn uniformly in [min, max], N.
        multi_contact: the study also localizes each trial's averaged inputs with the
            one-or-two-contact ``MultiContactLocalizer`` (``multi_contact_result``; always
            with ``contacts`` 2): how often it says "more than one contact". Its tests
            whiten with the averaged sensor noise (``averaged_input_covariances``) and the
            model error under load measured on the other seeds' trials, whose contacts
            are known (``load_model_error``, ``cross_fitting_folds``).
        no_contact_duration: the study's run without contact, standing (false detections),
            s; 0 skips it.
        slow_motion_duration: the study's run without contact during ``slow_motion`` (false
            detections while the whole body moves slowly), s; 0 skips it.
        slow_motion: that run's motion (``diagrams.station.motions``; a different seed from
            the calibration motion's).
        motion: the posture motion of one run (None: holding the standing posture; the
            study sets it for its slow-motion run).
        internal_gain, external_gain: residual gains K, 1/s.
        period: residual/detector/localizer period, s.
        settle_time: the localizer's wait after detection before averaging, s.
        localization_period: s between two localizations while in contact (the localizer
            averages its inputs every ``period`` all the same; None: every update).
        detector_release_probability: the detector's p_off (``ContactDetector``'s
            release_probability): it switches off when both test statistics stay below
            their chi-square (1 - p_off)-quantiles for 20 ms.
        detector_startup_time: the detector stays off for this long after the start, s (the
            residuals' and the base-state estimator's start-up; a push that starts earlier is
            detected only from then on).
        log_period: period of the loggers (detector outputs, residuals), s; the localizer's
            outputs are logged every ``localization_period`` (its rate of estimates).
        estimation: where the residuals, the detector and the localizer run: "offline"
            (the study's default) simulates the robot, its sensors and its base-state
            estimator with the estimators' inputs logged at every update, and runs the
            estimators on that log afterwards (``systems.residuals.offline``, their own
            update code, stacked over the samples); "online" runs them in the diagram. They
            do not act on the robot here (no admittance), so both give the same results to
            rounding (``tests/test_contact_localization.py``); offline costs a fraction
            of the per-step time of Python systems in the loop. The Meshcat replays run
            online (they draw the estimate as it comes).
        simulator_config: Drake's ``SimulatorConfig`` (``ApplySimulatorConfig``); the plant
            is discrete, so only ``target_realtime_rate`` and the publishing matter.
    """

    station: StationConfig = field(default_factory=StationConfig.realistic)
    push_body: str | None = None
    push_point: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    push_force: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    push_start: float = 0.5
    push_duration: float = 0.5
    trial_gap: float = 0.4
    trials_per_run: int = 1
    shared_standing_start: bool = True
    num_seeds: int = 5
    trials: int = 1000
    contacts: int = 1
    force_range: list[float] = field(default_factory=lambda: [MIN_FORCE, MAX_FORCE])
    multi_contact: bool = True
    no_contact_duration: float = 60.0
    slow_motion_duration: float = 60.0
    slow_motion: SlowMotion = field(default_factory=lambda: SlowMotion(seed=3, amplitude_scale=0.5))
    motion: SlowMotion | None = None
    internal_gain: float = 35.0
    external_gain: float = 35.0
    period: float = 1e-3
    settle_time: float = 0.1
    localization_period: float | None = 0.01
    detector_release_probability: float = 1e-2
    detector_startup_time: float = 0.1
    log_period: float = 1e-3
    estimation: str = "offline"
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)


#: ``ContactLocalizationScenario.estimation`` values.
ESTIMATIONS = ("offline", "online")


def scenario_push(scenario: ContactLocalizationScenario) -> Push:
    """The push of a one-push ``scenario`` (its push_body, push_point, push_force,
    push_start and push_duration).

    Raises:
        ValueError: a zero force.
    """
    force = np.asarray(scenario.push_force, dtype=float)
    magnitude = float(np.linalg.norm(force))
    if magnitude == 0.0:
        raise ValueError("push_force must be non-zero (use push_body=None for no contact)")
    return Push(
        scenario.push_body,
        np.asarray(scenario.push_point, dtype=float),
        force / magnitude,
        Step(magnitude, scenario.push_start, scenario.push_start + scenario.push_duration),
    )


def check_force_range(force_range: Sequence[float]) -> tuple[float, float]:
    """(min, max) of a push magnitude range, N.

    Raises:
        ValueError: not two finite numbers with 0 < min <= max.
    """
    try:
        low, high = (float(f) for f in force_range)
    except (TypeError, ValueError):
        raise ValueError(f"force_range must be [min, max] in N, got {force_range!r}") from None
    if not (math.isfinite(high) and 0.0 < low <= high):
        raise ValueError(f"force_range must be [min, max] with 0 < min <= max, finite, got {list(force_range)!r}")
    return low, high


def trial_scenario(scenario: ContactLocalizationScenario, spec: dict) -> ContactLocalizationScenario:
    """The run of the trial ``spec`` (``sample_trials``) alone: ``scenario`` with its push and
    noise seed."""
    return dataclasses.replace(
        replace_station(scenario, seed=spec["noise_seed"]),
        push_body=spec["body"],
        push_point=list(spec["point_body"]),
        push_force=list(spec["force_world"]),
    )


def run_schedule(
    scenario: ContactLocalizationScenario, specs: Sequence[dict]
) -> tuple[list[Push], list[tuple], list[list[int]]]:
    """The trials ``specs`` one after another in one run: trial k pushes (each of its
    contacts) from push_start + k (push_duration + trial_gap) for push_duration. Returns
    the pushes, each trial's window (previous trial's end or 0, push start, push end, s)
    and the indices of each trial's pushes in the push list."""
    pushes, windows, indices = [], [], []
    previous_end = 0.0
    for k, spec in enumerate(specs):
        start = scenario.push_start + k * (scenario.push_duration + scenario.trial_gap)
        one = dataclasses.replace(scenario, push_start=start)
        indices.append([])
        for contact in spec.get("contacts", [spec]):
            indices[-1].append(len(pushes))
            pushes.append(scenario_push(trial_scenario(one, {**contact, "noise_seed": spec["noise_seed"]})))
        windows.append((previous_end, start, start + scenario.push_duration))
        previous_end = start + scenario.push_duration
    return pushes, windows, indices


def no_contact_scenario(scenario: ContactLocalizationScenario) -> ContactLocalizationScenario:
    """The study's run without contact, standing: no push, its own noise seed (derived from
    the study's)."""
    seed = (scenario.station.seed * 100003 + 99991) % (2**31 - 1)
    return dataclasses.replace(replace_station(scenario, seed=seed), push_body=None, motion=None)


def slow_motion_scenario(scenario: ContactLocalizationScenario) -> ContactLocalizationScenario:
    """The study's run without contact during its slow whole-body motion (``slow_motion``,
    ``slow_motion_duration``): no push, its own noise seed."""
    seed = (scenario.station.seed * 100003 + 99989) % (2**31 - 1)
    return dataclasses.replace(
        replace_station(scenario, seed=seed),
        push_body=None,
        motion=scenario.slow_motion,
        no_contact_duration=scenario.slow_motion_duration,
    )
