"""The contact study (Flacco et al. 2016, Secs. V-VI, Fig. 9): a standing humanoid pushed at
random points, its contacts detected, localized and their forces estimated from the residuals
alone; ``apps.contact_localization`` is its command line.

The Monte Carlo study samples random contacts (``sample_trials``), runs one diagram per trial
and one without contact, and computes its metrics (``trial_result``, ``no_contact_result``,
``contact_localization_metrics``). By default (``estimation: offline``) the residuals, the
detector and the localizer run on a record of their inputs after each simulation
(``estimate_run``), as they would have in the loop.

Modules, each importing only those above it:

* ``scenario``: ``ContactLocalizationScenario``, the floors (``floors_for``) and the runs the
  study is made of (``trial_scenario``, ``run_schedule``, ``no_contact_scenario``,
  ``slow_motion_scenario``);
* ``builder``: the diagram (``build_contact_localization_diagram``) and its handles;
* ``sampling``: the random contacts (``sample_trials``, ``sample_study_trials``) and the body
  regions (``body_regions``);
* ``offline``: the estimators on the recorded inputs (``estimator_log``, ``estimate_run``,
  ``offline_trial``), the one-or-two-contact fit's whitening (``averaged_input_covariances``,
  ``load_model_error``, ``cross_fitting_folds``, ``multi_contact_localizer``) and the
  localizer's update timing;
* ``metrics``: one trial's results (``trial_result``, ``multi_contact_result``), a run
  without contact's (``no_contact_result``) and the study's totals
  (``contact_localization_metrics``);
* ``trials``: the trials and the runs without contact as a worker runs them (``run_trials``,
  ``run_no_contact``, ``localize_multi_contact``);
* ``study``: the study's phases on an engine (``run_study``, ``run_job``).

The intervals are ``diagrams.residuals.study_statistics``'s (shared with the sweep).
"""

from diagrams.residuals.contact_study.builder import (
    ESTIMATE_RGBA,
    TRUE_RGBA,
    ContactLocalizationHandles,
    build_contact_localization_diagram,
)
from diagrams.residuals.contact_study.metrics import (
    contact_localization_metrics,
    multi_contact_result,
    no_contact_result,
    trial_result,
)
from diagrams.residuals.contact_study.offline import (
    AVERAGED_NOISE_RUN_S,
    AVERAGED_NOISE_STARTUP_S,
    MIN_LOAD_CALIBRATION_TRIALS,
    EstimatorLog,
    OfflineTrial,
    averaged_input_covariances,
    cross_fitting_folds,
    estimate_run,
    estimator_log,
    load_model_error,
    multi_contact_localizer,
    offline_trial,
    time_localizer_advance,
    time_localizer_update,
)
from diagrams.residuals.contact_study.sampling import (
    REGIONS,
    body_regions,
    sample_study_trials,
    sample_trials,
)
from diagrams.residuals.contact_study.scenario import (
    ESTIMATIONS,
    FLOORS,
    FSR_FEET_FLOORS,
    MAX_ANGLE_DEG,
    MAX_FORCE,
    MIN_FORCE,
    NO_FOOT_FT_FLOORS,
    REALISTIC_FLOORS,
    STACKED_FIT_FLOORS,
    TWO_CONTACT_FLOORS,
    ContactLocalizationScenario,
    check_force_range,
    floors_for,
    has_fsr_feet,
    lacks_foot_ft_sensors,
    no_contact_scenario,
    run_schedule,
    scenario_push,
    slow_motion_scenario,
    trial_scenario,
)
from diagrams.residuals.contact_study.study import (
    JOB_KINDS,
    StudyRun,
    calibrate_study_model,
    first_pass_job_count,
    first_pass_jobs,
    multi_contact_jobs,
    run_job,
    run_jobs,
    run_study,
    study_metrics,
)
from diagrams.residuals.contact_study.trials import (
    MULTI_CONTACT_TRIALS_PER_JOB,
    SOLE_SLIP_RESTART,
    TRIALS_PER_JOB,
    estimate_more,
    localize_multi_contact,
    run_no_contact,
    run_trials,
    sole_slip,
)

__all__ = [
    "STACKED_FIT_FLOORS",
    "FLOORS",
    "REALISTIC_FLOORS",
    "TWO_CONTACT_FLOORS",
    "NO_FOOT_FT_FLOORS",
    "FSR_FEET_FLOORS",
    "lacks_foot_ft_sensors",
    "has_fsr_feet",
    "floors_for",
    "MIN_FORCE",
    "MAX_FORCE",
    "MAX_ANGLE_DEG",
    "ContactLocalizationScenario",
    "ESTIMATIONS",
    "scenario_push",
    "check_force_range",
    "trial_scenario",
    "run_schedule",
    "no_contact_scenario",
    "slow_motion_scenario",
    "TRUE_RGBA",
    "ESTIMATE_RGBA",
    "ContactLocalizationHandles",
    "build_contact_localization_diagram",
    "REGIONS",
    "body_regions",
    "sample_trials",
    "sample_study_trials",
    "AVERAGED_NOISE_RUN_S",
    "AVERAGED_NOISE_STARTUP_S",
    "averaged_input_covariances",
    "multi_contact_localizer",
    "MIN_LOAD_CALIBRATION_TRIALS",
    "load_model_error",
    "cross_fitting_folds",
    "time_localizer_update",
    "time_localizer_advance",
    "EstimatorLog",
    "estimator_log",
    "estimate_run",
    "OfflineTrial",
    "offline_trial",
    "trial_result",
    "multi_contact_result",
    "no_contact_result",
    "contact_localization_metrics",
    "TRIALS_PER_JOB",
    "MULTI_CONTACT_TRIALS_PER_JOB",
    "SOLE_SLIP_RESTART",
    "sole_slip",
    "run_trials",
    "estimate_more",
    "localize_multi_contact",
    "run_no_contact",
    "JOB_KINDS",
    "run_job",
    "run_jobs",
    "calibrate_study_model",
    "first_pass_jobs",
    "first_pass_job_count",
    "multi_contact_jobs",
    "study_metrics",
    "StudyRun",
    "run_study",
]
