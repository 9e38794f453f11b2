"""Integration tests of the contact study (diagrams/residuals/contact_study/): the detector and localizer in closed loop
with the simulated robot, its sensors and the residuals."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from diagrams.residuals.contact_study import ContactLocalizationScenario as RealisticScenario
from diagrams.residuals.contact_study import build_contact_localization_diagram
from diagrams.station.config import StationConfig
from systems.residuals.contact_estimation import ALL_WRENCH_COMPONENTS, SOLE_SHEAR_AND_YAW, VALID


def ContactLocalizationScenario(**fields) -> RealisticScenario:
    """These tests measure the ideal world (the study's ``--ideal``): the scenario with its
    conditions set to ideal."""
    station = fields.pop("station", StationConfig())
    return RealisticScenario(station=station.in_world("ideal"), **fields)


def _simulate(config: ContactLocalizationScenario, t_end: float):
    diagram, handles = build_contact_localization_diagram(config, online=True)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.station.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(t_end)
    return handles, context


def test_no_contact_statistics_match_predicted_noise():
    """Without contact, with sensor noise, the detector's Mahalanobis statistics have the
    chi-square means (3 and n dof) that the covariances predicted from the sensor noise
    imply, and nothing is detected."""
    handles, context = _simulate(
        ContactLocalizationScenario(station=StationConfig.realistic(seed=5), push_body=None), 1.5
    )
    log = handles.loggers["test_statistics"].FindLog(context)
    t, stats = log.sample_times(), log.data()
    window = t > 0.2
    n = handles.plant.num_velocities() - 6
    assert np.mean(stats[0, window]) == pytest.approx(3.0, rel=0.25)
    assert np.mean(stats[1, window]) == pytest.approx(n, rel=0.25)
    assert not handles.loggers["contact_detected"].FindLog(context).data().any()


def test_push_detected_and_localized_without_noise():
    """A 12 N push on the chest's front face, ideal sensors: detected within 7 ms, the
    right link, the point within 1 mm, the force within 0.5 %."""
    body = "CHEST_Y_LINK"
    _, handles = build_contact_localization_diagram(
        ContactLocalizationScenario(station=StationConfig.realistic(noise=False))
    )
    localizer = handles.localizer
    geo = localizer.geometry
    plant = handles.plant
    g = int(np.flatnonzero(geo.body_indices == int(plant.GetBodyByName(body).index()))[0])
    # A point on the box's front face (+x), off-centre, and a force along its inward normal tilted by 30 deg.
    p_G, n_G = geo.params[g] * np.array([1.0, 0.3, -0.2]), np.array([1.0, 0.0, 0.0])
    X_BG = geo.X_BG[g]
    p_B = X_BG[:, :3] @ p_G + X_BG[:, 3]
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, handles.station.initial_state)
    R_WB = plant.EvalBodyPoseInWorld(context, plant.GetBodyByName(body)).rotation().matrix()
    n_W = R_WB @ X_BG[:, :3] @ n_G
    tangent = np.cross(n_W, [0.0, 0.0, 1.0])
    tangent /= np.linalg.norm(tangent)
    f_W = 12.0 * (-np.cos(np.radians(30)) * n_W + np.sin(np.radians(30)) * tangent)
    config = ContactLocalizationScenario(
        station=StationConfig.realistic(noise=False),
        push_start=0.2,
        push_duration=0.5,
        push_body=body,
        push_point=tuple(p_B),
        push_force=tuple(f_W),
    )
    handles, root = _simulate(config, 0.7)
    detection = handles.detector.GetOutputPort("detection_time").Eval(handles.detector.GetMyContextFromRoot(root))[0]
    # The external test alone fires once 12 N (1 - (1 - K T)^k) exceeds its threshold, about
    # 6.7 sigma = 1.9 N: k = 5 updates at K T = 0.035, plus one update of delay.
    assert 0.2 < detection <= 0.207
    estimate = handles.localizer.estimate(handles.localizer.GetMyContextFromRoot(root))
    true_point = handles.push_source.GetOutputPort("point_world").Eval(handles.push_source.GetMyContextFromRoot(root))
    assert estimate.status == VALID
    assert estimate.body_index == int(plant.GetBodyByName(body).index())
    # The robot sways ~3.5 mm under the push while the localizer averages over 0.4 s; the
    # estimate is the mean contact point over that window, the truth the final one.
    assert np.linalg.norm(estimate.point_W - true_point) < 3e-3
    assert np.linalg.norm(estimate.force_W - f_W) < 5e-3 * 12.0


def test_feet_without_ft_sensors_are_unknowns_and_feet_are_never_pushed():
    """A robot without foot F/T sensors gets its soles as the estimators' unknown wrench
    frames, its whole feet excluded: whole wrenches without sensing (hrp4_like_no_ft), the
    shear and yaw moment with FSRs (nao_like), whose normal forces and centres of pressure
    are then known wrenches at the soles. A push on a foot is refused either way (it is part
    of the ground's wrench, or below an F/T sensor)."""
    soles = ["l_sole_frame", "r_sole_frame"]
    _, handles = build_contact_localization_diagram(
        ContactLocalizationScenario(station=StationConfig.realistic(model="nao_like"))
    )
    assert [f.name() for f in handles.station.estimator.unknown_wrench_frames] == soles
    assert handles.station.estimator.unknown_wrench_components == (SOLE_SHEAR_AND_YAW, SOLE_SHEAR_AND_YAW)
    assert [f.name() for f in handles.detector.unknown_wrench_frames] == soles
    assert [f.name() for f in handles.localizer.unknown_wrench_frames] == soles
    assert [f.name() for f in handles.station.known_wrench_frames] == soles
    assert handles.station.known_wrenches.size() == 12
    _, handles = build_contact_localization_diagram(
        ContactLocalizationScenario(station=StationConfig.realistic(model="models/robots/hrp4_like_no_ft.yaml"))
    )
    assert [f.name() for f in handles.detector.unknown_wrench_frames] == soles
    assert handles.station.estimator.unknown_wrench_components == (ALL_WRENCH_COMPONENTS, ALL_WRENCH_COMPONENTS)
    assert not handles.station.known_wrench_frames
    with pytest.raises(ValueError, match="part of a foot"):
        build_contact_localization_diagram(ContactLocalizationScenario(push_body="r_sole", push_force=(0, 0, -5)))
    with pytest.raises(ValueError, match="part of a foot"):
        build_contact_localization_diagram(
            ContactLocalizationScenario(
                station=StationConfig.realistic(model="models/robots/hrp4_like_no_ft.yaml"),
                push_body="R_ANKLE_R_LINK",
                push_force=(0, 0, -5),
            )
        )


def test_study_trials_split_over_seeds_and_match_each_seeds_own_draw():
    """``sample_study_trials``: 7 trials over 3 seeds go 3 / 2 / 2, numbered 0..6 across the
    seeds, each exactly the trial its seed's ``sample_trials`` draws."""
    from diagrams.residuals.contact_study import sample_study_trials, sample_trials

    specs = sample_study_trials(
        ContactLocalizationScenario(station=StationConfig.realistic(seed=40), trials=7, num_seeds=3)
    )
    assert [s["trial"] for s in specs] == list(range(7))
    assert [s["seed"] for s in specs] == [40, 40, 40, 41, 41, 42, 42]
    for spec in specs:
        own = sample_trials("hrp4_like", 3, spec["seed"])[spec["trial_of_seed"]]
        assert spec["body"] == own["body"] and spec["noise_seed"] == own["noise_seed"]
        np.testing.assert_array_equal(spec["force_world"], own["force_world"])
    assert len({s["noise_seed"] for s in specs}) == 7


def test_study_first_pass_jobs_their_count_and_their_results_by_kind():
    """The study's first pass (``contact_study.study``): the runs without contact first, the
    trials in chunks of ``TRIALS_PER_JOB`` (at least ``trials_per_run``), counted by
    ``first_pass_job_count`` (with two contacts the fits' noise too); ``run_jobs`` joins the
    trials' results in trial order whatever order the engine returns them in; ``run_job``
    refuses a kind it does not run (the app's replays)."""
    from diagrams.residuals.contact_study import (
        TRIALS_PER_JOB,
        first_pass_job_count,
        first_pass_jobs,
        run_job,
        run_jobs,
    )

    scenario = RealisticScenario(trials=2 * TRIALS_PER_JOB + 1, contacts=2, multi_contact=False, slow_motion_duration=0)
    specs = [{"trial": i} for i in range(scenario.trials)]
    count = first_pass_job_count(scenario, replay_jobs=2)
    scenario.multi_contact = True  # as run_study sets it for two contacts
    jobs = first_pass_jobs(scenario, specs, "yaml")
    assert [kind for kind, *_ in jobs] == ["no_contact", "covariances", "trials", "trials", "trials"]
    assert count == len(jobs) + 2
    assert [t for kind, chunk, _, _ in jobs if kind == "trials" for t in chunk] == specs
    scenario.trials_per_run = 2 * TRIALS_PER_JOB
    assert [len(chunk) for kind, chunk, _, _ in first_pass_jobs(scenario, specs, "yaml") if kind == "trials"] == [
        2 * TRIALS_PER_JOB,
        1,
    ]

    class Reversed:  # an engine that returns the jobs' results last first
        kind, workers = "reversed", 1

        def imap_unordered(self, function, jobs):
            return reversed([function(job) for job in jobs])

    def fake(job):
        kind, chunk, _, _ = job
        return kind, [{"trial": t["trial"]} for t in chunk] if kind == "trials" else kind

    seen = []
    outputs = run_jobs(jobs, Reversed(), fake, progress=lambda done, total: seen.append((done, total)))
    assert [r["trial"] for r in outputs["trials"]] == list(range(scenario.trials))
    assert outputs["no_contact"] == "no_contact" and outputs["covariances"] == "covariances"
    assert seen == [(k, len(jobs)) for k in range(1, len(jobs) + 1)]
    with pytest.raises(ValueError, match="no job of kind 'replay'"):
        run_job(("replay", {}, "yaml", None))


@pytest.mark.slow
def test_trials_run_one_after_another_each_detected_and_localized_in_its_window():
    """Three pushes in one run (``run_schedule``, 0.4 s apart): each trial's window holds its
    own detection (none carried over from the previous push, no false detection in the
    gap), its localization, and the true point of its own push; the study's runner
    (``diagrams.residuals.contact_study.trials.run_trials``) reads the same results from the same run."""
    from diagrams.residuals.contact_study import run_schedule, run_trials, sample_trials, trial_result

    scenario = ContactLocalizationScenario(push_start=0.3, push_duration=0.3, trial_gap=0.4, trials_per_run=3)
    specs = sample_trials("hrp4_like", 3, seed=0)  # an elbow, a shoulder and a hand link
    pushes, windows, push_indices = run_schedule(scenario, specs)
    assert push_indices == [[0], [1], [2]]
    np.testing.assert_allclose(windows, [(0.0, 0.3, 0.6), (0.6, 1.0, 1.3), (1.3, 1.7, 2.0)], atol=1e-12)
    diagram, handles = build_contact_localization_diagram(scenario, pushes=pushes, online=True)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.station.set_initial_state(context)
    simulator.Initialize()
    results = []
    for k, (spec, window) in enumerate(zip(specs, windows)):
        simulator.AdvanceTo(window[2])
        result = trial_result(scenario, spec, handles, context, 0.0, push_indices=push_indices[k], window=window)
        results.append(result)
        assert result["detected"] and not result["detector_on_at_push_start"], k
        assert result["false_detections_before_push"] == 0
        assert 0.0 <= result["detection_delay_s"] < 0.02
        assert result["correct_link"] and result["position_error_m"] < 0.01, (k, result["estimated_body"])
        assert result["force_error_rel"] < 0.05
        body = handles.plant.GetBodyByName(spec["body"])
        X_WB = handles.plant.EvalBodyPoseInWorld(handles.plant.GetMyContextFromRoot(context), body)
        np.testing.assert_allclose(result["true_point_world"], X_WB @ np.array(spec["point_body"]), atol=1e-12)
    from_runner = run_trials([dict(s) for s in specs], scenario)
    assert [r["estimated_body"] for r in from_runner] == [r["estimated_body"] for r in results]
    for a, b in zip(from_runner, results):
        assert a["position_error_m"] == pytest.approx(b["position_error_m"], abs=1e-12)
        assert a["sole_slip_m"] < 0.002


def test_trials_from_one_shared_standing_start_match_the_trials_run_alone():
    """``shared_standing_start`` (the study's default): the standing start simulated once,
    its state restored before each push. Without sensor noise the restored start is the
    start each trial would have simulated on its own, so every trial's detection,
    localization and force are those of the same trial run alone (from its own standing
    start) up to round-off, whatever the trials before it did; with noise the pushes see
    noise of their own (they come one after another in time)."""
    from diagrams.residuals.contact_study import run_trials, sample_trials

    shared = ContactLocalizationScenario(
        station=StationConfig.realistic(noise=False), push_start=0.3, push_duration=0.3, multi_contact=False
    )
    assert shared.shared_standing_start and shared.trials_per_run == 1
    specs = sample_trials("hrp4_like", 3, seed=0)
    together = run_trials([dict(s) for s in specs], shared)
    alone = [run_trials([dict(s)], shared)[0] for s in specs]
    for a, b in zip(together, alone):
        assert a["detected"] and not a["detector_on_at_push_start"] and a["false_detections_before_push"] == 0
        assert a["estimated_body"] == b["estimated_body"] and a["correct_link"]
        assert (a["detection_delay_s"] is None) == (b["detection_delay_s"] is None)
        if b["detection_delay_s"] is not None:
            assert a["detection_delay_s"] == pytest.approx(b["detection_delay_s"], abs=1e-9)
        np.testing.assert_allclose(a["estimated_point_world"], b["estimated_point_world"], atol=1e-9)
        np.testing.assert_allclose(a["estimated_force_world"], b["estimated_force_world"], atol=1e-7)
        np.testing.assert_allclose(a["true_point_world"], b["true_point_world"], atol=1e-12)
        assert a["sole_slip_m"] < 0.002 and not a["run_restarted_after"]


@pytest.mark.parametrize(
    "world",
    ["ideal", pytest.param("ekf", marks=pytest.mark.slow), pytest.param("uncalibrated", marks=pytest.mark.slow)],
)
def test_offline_estimation_of_the_trials_equals_the_estimators_in_the_loop(world):
    """The study's default ``estimation: offline`` (the robot, its sensors and base-state
    estimator simulated, the residuals, detector and localizer run on the recorded inputs
    afterwards) reports what the same estimators report running in the diagram, trial by
    trial, with sensor noise, on trials from the shared standing start: detection, its
    delay and the false detections, the status, link, point, force and score of the
    final localization and the averaged inputs it used. Worlds: ideal; the invariant EKF
    in the loop (its base state feeds the PD's gravity); and the realistic world without
    its calibration (to keep the test short), whose detector is already on at the end of
    the standing start, so that every restored trial starts with it on."""
    from dataclasses import replace

    from diagrams.residuals.contact_study import run_trials, sample_trials
    from systems.simulation.imperfections import Imperfections

    scenario = RealisticScenario(
        station=StationConfig.realistic(model_refinement="none"), push_start=0.3, push_duration=0.4, multi_contact=False
    )
    if world == "ideal":
        scenario.station = scenario.station.in_world("ideal")
    elif world == "ekf":
        scenario.station.imperfections = Imperfections()
    assert scenario.estimation == "offline" and scenario.shared_standing_start
    specs = sample_trials("hrp4_like", 3, seed=4)
    offline = run_trials([dict(s) for s in specs], scenario)
    online = run_trials([dict(s) for s in specs], replace(scenario, estimation="online"))
    if world == "uncalibrated":  # not vacuous: the flag carried into the restored trials
        assert all(r["detector_on_at_push_start"] and not r["detected"] for r in online)
    else:  # not vacuous: pushes detected and links localized
        assert sum(r["detected"] for r in online) >= 2 and any(r["status"] == VALID for r in online)
    for a, b in zip(offline, online):
        for key in ("detected", "detector_on_at_push_start", "false_detections_before_push", "status"):
            assert a[key] == b[key], key
        assert a["estimated_body"] == b["estimated_body"] and a["correct_link"] == b["correct_link"]
        assert (a["detection_delay_s"] is None) == (b["detection_delay_s"] is None)
        if b["detection_delay_s"] is not None:
            assert a["detection_delay_s"] == pytest.approx(b["detection_delay_s"], abs=1e-9)
        np.testing.assert_allclose(a["estimated_point_world"], b["estimated_point_world"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(a["estimated_force_world"], b["estimated_force_world"], rtol=0, atol=1e-8)
        assert (a["score"] is None) == (b["score"] is None)
        if b["score"] is not None:
            assert a["score"] == pytest.approx(b["score"], rel=1e-6, abs=1e-12)
        for name in ("q", "external_wrench_world", "residual"):
            x, y = a["localizer_inputs"][name], b["localizer_inputs"][name]
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-9 * max(1.0, np.abs(y).max()))


def test_two_contact_tables_count_both_links():
    """With two contacts per trial the per-link table counts each pushed link as found when
    the answer has two contacts and names it, the per-seed table counts trials with both
    links right, and the confusion list names the true pair and what was found."""
    from diagrams.residuals.contact_study.metrics import _intervals_and_tables

    def trial(seed, true, found):
        return {
            "seed": seed,
            "body": true[0],
            "correct_link": False,  # the single-contact localizer's: not used with two contacts
            "estimated_body": None,
            "status_reason": "n/a",
            "contacts": [{"body": b} for b in true],
            "contacts_estimated": len(found),
            "estimated_contact_body_names": list(found),
            "contact_links_right": sorted(found) == sorted(true),
            "contact_position_errors_m": [0.001, 0.002] if sorted(found) == sorted(true) else [np.inf, np.inf],
        }

    results = [
        trial(1, ("A", "B"), ("B", "A")),
        trial(1, ("A", "C"), ("A", "D")),
        trial(2, ("C", "B"), ("C",)),
    ]
    tables = _intervals_and_tables(results, results, [], [0.0] * 3, [])
    per_link = {row["group"]: (row["successes"], row["trials"]) for row in tables["per_link"]}
    assert per_link == {"A": (2, 2), "B": (1, 2), "C": (0, 2)}
    per_seed = {row["group"]: (row["successes"], row["trials"]) for row in tables["per_seed"]}
    assert per_seed == {"1": (1, 2), "2": (0, 1)}
    assert tables["confusion"] == [
        {"true": "A + C", "estimated": "A + D", "count": 1},
        {"true": "B + C", "estimated": "C (one contact)", "count": 1},
    ]
    assert tables["intervals"]["both_links_right_rate"][0] < 1 / 3 < tables["intervals"]["both_links_right_rate"][1]


def test_study_trials_on_a_robot_without_foot_ft_sensors():
    """hrp4_like with its F/T sensors ignored (``sensing: none``), the ideal world with
    sensor noise, pushes on an arm and on the torso: each detected, found on its link
    within 1 cm with its force within 5 % by the eq. (22) localizer (per link, the ground's
    wrenches unknowns) and by the stacked fit, whose sole normal forces are within 5 % of
    the robot's weight of the simulator's; a push on a stance shank is never claimed."""
    from diagrams.residuals.contact_study import body_regions, multi_contact_result, run_trials, sample_trials
    from systems.residuals.multi_contact import MultiContactLocalizer

    robot = "models/robots/hrp4_like_no_ft.yaml"
    scenario = ContactLocalizationScenario(
        station=StationConfig.realistic(model=robot, seed=9), no_contact_duration=0.0, slow_motion_duration=0.0
    )
    specs = sample_trials(robot, 40, 9)
    chosen = [next(s for s in specs if s["region"] == r) for r in ("arms", "torso")]
    chosen.append(next(s for s in specs if s["body"] in ("L_KNEE_P_LINK", "R_KNEE_P_LINK")))
    results = run_trials(chosen, scenario)
    _, handles = build_contact_localization_diagram(scenario)
    estimator = handles.station.estimator
    assert body_regions(estimator.plant, estimator.humanoid)["R_KNEE_P_LINK"] == "legs"
    fit = MultiContactLocalizer(
        estimator.plant,
        estimator.scene_graph,
        exclude_bodies=estimator.excluded_bodies,
        unknown_wrench_frames=estimator.unknown_wrench_frames,
    )
    for spec, result in zip(chosen, results):
        assert result["detected"], spec["body"]
        inputs = result["localizer_inputs"]
        stacked = multi_contact_result(
            fit,
            inputs["q"],
            inputs["external_wrench_world"],
            inputs["residual"],
            [spec["body_index"]],
            np.asarray(result["true_points_world"]),
            np.array([spec["force_world"]]),
        )
        if spec["region"] == "legs":
            assert result["status"] != VALID and not stacked["fit_valid"], spec["body"]
            continue
        assert result["correct_link"] and result["position_error_m"] < 0.01, spec["body"]
        assert result["force_error_rel"] < 0.05
        assert stacked["fit_correct_link"] and stacked["fit_position_error_m"] < 0.01
        error = np.subtract(stacked["foot_normal_forces_N"], result["true_foot_normal_forces_N"])
        assert np.max(np.abs(error)) < 0.05 * result["robot_weight_N"]


def test_floors_follow_the_robots_foot_sensing():
    """Issue 36's per-region floors for a robot without foot F/T sensors, in either world
    (without the sole force floor where FSRs measure the forces); the F/T robot keeps the
    study's own."""
    from diagrams.residuals.contact_study import (
        FLOORS,
        FSR_FEET_FLOORS,
        NO_FOOT_FT_FLOORS,
        REALISTIC_FLOORS,
        floors_for,
        lacks_foot_ft_sensors,
    )

    assert lacks_foot_ft_sensors("models/robots/hrp4_like_no_ft.yaml") and lacks_foot_ft_sensors("nao_like")
    assert not lacks_foot_ft_sensors("hrp4_like") and not lacks_foot_ft_sensors("models/robots/talos.yaml")
    assert (
        floors_for(
            ContactLocalizationScenario(station=StationConfig.realistic(model="models/robots/hrp4_like_no_ft.yaml"))
        )
        is NO_FOOT_FT_FLOORS
    )
    assert floors_for(RealisticScenario(station=StationConfig.realistic(model="nao_like"))) is FSR_FEET_FLOORS
    assert "foot_normal_force_rms_error_valid_of_weight" not in FSR_FEET_FLOORS
    assert FSR_FEET_FLOORS.items() < NO_FOOT_FT_FLOORS.items()
    assert floors_for(ContactLocalizationScenario()) is FLOORS
    assert floors_for(RealisticScenario()) is REALISTIC_FLOORS


def test_metrics_per_region_and_sole_forces_count_what_they_say():
    """Hand-made trials: the per-region table's rates and medians, the flat keys the floors
    read, and the sole normal force RMS (over the detected trials, of the weight)."""
    from diagrams.residuals.contact_study import NO_FOOT_FT_FLOORS, contact_localization_metrics

    def trial(k, region, detected, right, position, feet=None):
        r = {
            "trial": k,
            "body": f"{region}_{k}",
            "region": region,
            "detected": detected,
            "detection_delay_s": 0.001 if detected else None,
            "false_detections_before_push": 0,
            "status": 0 if right else 4,
            "status_reason": "valid" if right else "ambiguous",
            "estimated_body": f"{region}_{k}" if right else "waist",
            "correct_link": right,
            "position_error_m": position,
            "force_error_rel": 0.01 if detected else None,
            "angle_error_deg": 1.0 if detected else None,
            "localizer_update_s": 1e-3,
            "fit_correct_link": right,
            "fit_valid": right,
            "fit_position_error_m": position,
        }
        if feet is not None:
            r.update(foot_normal_forces_N=feet[0], true_foot_normal_forces_N=feet[1], robot_weight_N=400.0)
        return r

    results = [
        trial(0, "arms", True, True, 0.002, ([200.0, 200.0], [203.0, 197.0])),
        trial(1, "arms", True, True, 0.004, ([210.0, 190.0], [206.0, 194.0])),
        trial(2, "legs", True, False, 0.3, ([150.0, 250.0], [100.0, 300.0])),
        trial(3, "legs", False, False, None, ([0.0, 0.0], [200.0, 200.0])),  # undetected: not counted
        trial(4, "torso", True, True, 0.001),
    ]
    m = contact_localization_metrics(results, None, None, NO_FOOT_FT_FLOORS)
    rows = {row["region"]: row for row in m["per_region"]}
    assert [row["region"] for row in m["per_region"]] == ["arms", "torso", "legs"]
    assert rows["arms"]["correct_link_rate"] == 1.0 and rows["arms"]["median_position_error_m"] == pytest.approx(0.003)
    assert rows["legs"]["detection_rate"] == 0.5 and rows["legs"]["correct_link_rate"] == 0.0
    assert rows["legs"]["median_position_error_m"] == float("inf")
    assert m["correct_link_rate_legs"] == 0.0 and m["fit_correct_link_rate_torso"] == 1.0
    rms = np.sqrt(np.mean(np.square([-3.0, 3.0, 4.0, -4.0, 50.0, -50.0])))
    assert m["foot_normal_force_rms_error_N"] == pytest.approx(rms)
    assert m["foot_normal_force_rms_error_of_weight"] == pytest.approx(rms / 400.0)
    # Over the eq. (22) localizer's valid results only (not the leg push's): the arms' two.
    assert m["foot_normal_force_rms_error_valid_N"] == pytest.approx(np.sqrt(np.mean(np.square([3.0, 3.0, 4.0, 4.0]))))
    assert rows["legs"]["foot_normal_force_rms_error_of_weight"] == pytest.approx(50.0 / 400.0)
    assert "foot_normal_force_rms_error_of_weight" not in rows["torso"]
    assert m["meets_floors"]["correct_link_rate_legs"] is False and m["meets_floors"]["correct_link_rate_arms"]
    assert m["meets_floors"]["foot_normal_force_rms_error_valid_of_weight"]
