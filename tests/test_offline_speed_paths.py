"""The fast paths of the offline estimation (``estimate_from_log``) equal their references to
rounding: the stacked dynamics terms the per-sample ones, the detector's replay its
per-sample ``advance``, ``replay_contact_estimation`` every system stepped sample by sample
with its own ``advance`` (the residuals, the detector and the localizer, with the
one-update delay of the diagram) on a short log of a push, and the localizer's culled
geometric queries the queries of every primitive."""

from __future__ import annotations

import numpy as np
import pytest

from diagrams.residuals.log_estimation import (
    LogEstimationSettings,
    build_estimator_plant,
    build_offline_estimators,
    log_inputs,
    make_detector,
    make_localizer,
    simulate_push_log,
)
from systems.residuals.contact_estimation import VALID, ContactDetector
from systems.residuals.offline import replay_contact_estimation


@pytest.fixture(scope="module")
def robot():
    return build_estimator_plant("hrp4_like")


@pytest.fixture(scope="module")
def short_log(robot):
    """hrp4_like standing 0.8 s, pushed from 0.5 s to the end: the replay's inputs."""
    log, _ = simulate_push_log("hrp4_like", duration=0.8, push_end=1.0)
    return log_inputs(robot, log)


@pytest.mark.parametrize("dynamics", ["fast", "pinocchio"])
def test_stacked_dynamics_terms_equal_the_per_sample_ones(robot, short_log, dynamics):
    """``mass_matrix_terms_of_samples`` (the C++ calls of all samples in one loop, the rest
    stacked) equals ``mass_matrix_terms`` sample by sample, a sample with still joints
    included (M_F0 depends on the joint positions only: M_dot = 0, "fast" skipping the
    central difference, "pinocchio" to rounding)."""
    settings = LogEstimationSettings(dynamics=dynamics)
    model, _, _ = build_offline_estimators(robot, settings, short_log.period)
    dynamics = model.dynamics._impl
    nq = robot.plant.num_positions()
    x = short_log.state[[0, 1, 300, 650, 799]].copy()
    x[0, nq + 6 :] = 0.0
    M, M_dot, bias, R_WB, v0, J = dynamics.mass_matrix_terms_of_samples(x[:, :nq], x[:, nq:], robot.ft_frames)
    assert J.shape == (5, len(robot.ft_frames), 6, robot.plant.num_velocities())
    still = np.abs(M_dot[0]).max()
    assert (still == 0.0 if dynamics == "fast" else still < 1e-12) and np.abs(M_dot[1:]).max() > 1e-3
    for k in range(len(x)):
        expected = dynamics.mass_matrix_terms(x[k, :nq], x[k, nq:])
        for got, want in zip((M[k], M_dot[k], bias[k], R_WB[k], v0[k]), expected):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * max(np.abs(want).max(), 1.0))


def test_detector_replay_equals_stepping_its_updates(robot):
    """``ContactDetector.replay`` (the threshold tests of all updates at once) equals
    ``advance`` stepped update by update: the flags, and the state after the last update,
    through the start-up, a switch on after two updates above, releases and a brief dip."""
    detector = ContactDetector(
        robot.plant, known_wrench_frames=robot.ft_frames, on_samples=2, startup_time=0.05, period=1e-3
    )
    on, off = detector.thresholds["on"], detector.thresholds["off"]
    N = 400
    times = np.arange(N) * 1e-3
    statistics = np.tile(0.1 * np.array(off), (N, 1))
    statistics[20:30] = 2.0 * np.array(on)  # during the start-up: ignored
    statistics[100:101, 0] = 2.0 * on[0]  # one update above: not enough
    statistics[150:250, 1] = 2.0 * on[1]  # on, on the internal test
    statistics[250:262, 1] = 0.5 * (on[1] + off[1])  # between the thresholds: held
    statistics[300:305, 0] = 2.0 * on[0]
    statistics[305:310, 0] = 0.5 * off[0]  # 5 ms below: not yet released (20 ms)
    statistics[310:320, 0] = 2.0 * on[0]
    start = detector.CreateDefaultContext().get_discrete_state_vector().CopyToVector()
    state, stepped, states = start, np.empty(N, dtype=bool), []
    for k in range(N):
        state = detector.advance(state, tuple(statistics[k].tolist()), float(times[k]))
        stepped[k] = state[0] > 0.5
        states.append(state)
    flags, end = detector.replay(start, statistics, times)
    np.testing.assert_array_equal(flags, stepped)
    assert end == states[-1]
    # Not vacuous: on at the second update above (151), held between the thresholds and
    # through the 5 ms dip, released 20 ms after falling below the off thresholds.
    assert np.flatnonzero(np.diff(stepped.astype(int))).tolist() == [150, 280, 300, 338]
    # From the middle of a contact, as a replay that goes on from where one left off.
    rest, end = detector.replay(states[199], statistics[200:], times[200:])
    np.testing.assert_array_equal(rest, stepped[200:])
    assert end == states[-1]
    flags, end = detector.replay(states[199], statistics[:0], times[:0])
    assert flags.shape == (0,) and end == list(states[199])


def test_contact_estimation_replay_equals_each_system_stepped(robot, short_log):
    """``replay_contact_estimation`` (stacked residuals, the detector's replay, the
    localizer's replay) equals each system's own ``advance`` stepped sample by sample, the
    detector and the localizer reading the residuals (and the flag) of the update before."""
    settings = LogEstimationSettings()
    period = short_log.period
    _, internal, external = build_offline_estimators(robot, settings, period)
    detector = make_detector(robot, settings, period)
    localizer = make_localizer(robot, settings, period)
    state, torque, wrenches = short_log.state, short_log.joint_torque, short_log.known_wrenches
    replayed = replay_contact_estimation(internal, external, lambda *_: detector, localizer, state, torque, wrenches)

    N, n = state.shape[0], torque.shape[1]
    internal_residual, external_wrench = np.empty((N, n)), np.empty((N, 6))
    detected, localization = np.empty(N, dtype=bool), np.empty((N, 14))
    integrals = [None, None]
    detector_state = detector.CreateDefaultContext().get_discrete_state_vector().CopyToVector()
    localizer_state = localizer.initial_state()
    late = (np.zeros(n), np.zeros(6), False)  # the residuals and the flag of update k - 1
    for k in range(N):
        t = k * period
        integrals[0], internal_residual[k], _ = internal.advance(state[k], torque[k], wrenches[k], integrals[0])
        integrals[1], residual, terms = external.advance(state[k], None, wrenches[k], integrals[1])
        external_wrench[k] = external.world_wrench(terms, state[k], residual)
        detector_state = detector.advance(detector_state, detector.statistics(late[1], late[0]), t)
        localizer_state = localizer.advance(localizer_state, t, state[k], late[1], late[0], late[2])
        detected[k], localization[k] = detector_state[0] > 0.5, localizer_state[3]
        late = (internal_residual[k], external_wrench[k], bool(detected[k]))

    for got, want in ((replayed.internal, internal_residual), (replayed.external_wrench_world, external_wrench)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-11 * np.abs(want).max())
    np.testing.assert_array_equal(replayed.contact_detected, detected)
    np.testing.assert_array_equal(replayed.localization["status"], localization[:, 0])
    np.testing.assert_array_equal(replayed.localization["body_index"], localization[:, 1])
    np.testing.assert_allclose(replayed.localization["point_world"], localization[:, 2:5], rtol=0, atol=1e-9)
    np.testing.assert_allclose(replayed.localization["force_world"], localization[:, 5:8], rtol=0, atol=1e-9)
    assert detected[550:].all() and (localization[650:, 0] == VALID).all()  # not vacuous


def test_offline_dynamics_choice_changes_only_rounding(robot, short_log):
    """The offline default "pinocchio" (M_dot = C + C^T exactly) and the online systems'
    "fast" (M_dot by central difference) give the same estimation of the short push's log
    to the difference's rounding: residuals to 1e-9 of their size, the same detection and
    localizations; an unknown implementation is refused by name."""
    period = short_log.period
    out = {}
    for dynamics in ("fast", "pinocchio"):
        settings = LogEstimationSettings(dynamics=dynamics)
        _, internal, external = build_offline_estimators(robot, settings, period)
        assert internal.model.dynamics.implementation == dynamics
        out[dynamics] = replay_contact_estimation(
            internal,
            external,
            lambda *_, s=settings: make_detector(robot, s, period),
            make_localizer(robot, settings, period),
            short_log.state,
            short_log.joint_torque,
            short_log.known_wrenches,
        )
    fast, pinocchio = out["fast"], out["pinocchio"]
    for got, want in (
        (pinocchio.internal, fast.internal),
        (pinocchio.external_wrench_world, fast.external_wrench_world),
    ):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
        assert np.abs(got - want).max() > 0.0  # two computations of M_dot, not one
    np.testing.assert_array_equal(pinocchio.contact_detected, fast.contact_detected)
    np.testing.assert_array_equal(pinocchio.localization["body_index"], fast.localization["body_index"])
    np.testing.assert_allclose(pinocchio.localization["point_world"], fast.localization["point_world"], atol=1e-9)
    assert fast.contact_detected[550:].all()
    with pytest.raises(ValueError, match="dynamics must be one of"):
        LogEstimationSettings(dynamics="reference")


def test_localizer_bounding_sphere_culling_changes_no_result(robot):
    """``ContactLocalizer.localize`` skips the primitives whose bounding sphere the line of
    action misses (or that holds no candidate point): on random lines of action near the
    robot, at the standing pose and at moved ones, every result (status, link, point,
    scores, runner-up, candidates) equals that of querying every primitive (the culling
    disabled by infinite bounding radii)."""
    culled = make_localizer(robot, LogEstimationSettings(), 1e-3)
    every = make_localizer(robot, LogEstimationSettings(), 1e-3)
    every._bounding_radius2 = np.full_like(every._bounding_radius2, np.inf)
    plant = robot.plant
    nq, n = plant.num_positions(), plant.num_velocities() - 6
    rng = np.random.default_rng(3)
    statuses = set()
    for trial in range(300):
        q = robot.standing_state[:nq].copy()
        if trial % 3:
            q[7:] += 0.3 * rng.normal(size=nq - 7)
        point = rng.normal(size=3) * [0.2, 0.3, 0.4] + [0.0, 0.0, 0.8]
        force = rng.normal(size=3)
        force *= rng.uniform(0.5, 40.0) / np.linalg.norm(force)
        wrench = np.concatenate((np.cross(point, force), force))
        residual = rng.normal(size=n)
        a, b = culled.localize(q, wrench, residual), every.localize(q, wrench, residual)
        assert (a.status, a.body_index, a.runner_up_body_index) == (b.status, b.body_index, b.runner_up_body_index)
        np.testing.assert_array_equal(a.point_W, b.point_W)
        np.testing.assert_array_equal(a.runner_up_point_W, b.runner_up_point_W)
        assert (a.score, a.runner_up_score) == (b.score, b.runner_up_score)
        assert len(a.candidates) == len(b.candidates)
        for (body_a, point_a, score_a, l_a), (body_b, point_b, score_b, l_b) in zip(a.candidates, b.candidates):
            assert (body_a, score_a, l_a) == (body_b, score_b, l_b)
            np.testing.assert_array_equal(point_a, point_b)
        statuses.add(a.status)
    assert VALID in statuses and len(statuses) >= 3  # not vacuous: hits, misses, ambiguities


@pytest.mark.parametrize("dynamics", ["fast", "pinocchio"])
def test_a_stacked_replay_leaves_no_stale_kinematics_in_the_shared_model(robot, short_log, dynamics):
    """The stacked replay moves the dynamics' own context (``fast``) or kinematics
    (``pinocchio``) through the log's samples: a model that had evaluated a state before
    gives that state's known-wrench forces afterwards, not the last sample's."""
    from systems.residuals.momentum_residuals import ResidualModel
    from systems.residuals.offline import replay_residuals

    x0, w = short_log.state[300], short_log.known_wrenches[300]
    model = ResidualModel(robot.plant, dynamics)
    model.state_rates(x0)  # the state evaluated, its Jacobians not yet
    replay_residuals(
        robot.plant,
        model,
        robot.ft_frames,
        short_log.state[600:],
        short_log.joint_torque[600:],
        short_log.known_wrenches[600:],
        internal_gain=35.0,
        external_gain=35.0,
        period=short_log.period,
        stacked=True,
    )
    got = np.concatenate(model.known_wrench_forces(model.state_rates(x0), robot.ft_frames, w))
    fresh = ResidualModel(robot.plant, dynamics)
    want = np.concatenate(fresh.known_wrench_forces(fresh.state_rates(x0), robot.ft_frames, w))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
