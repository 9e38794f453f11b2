"""Integration tests of diagrams/residuals/contact_localization.py: the detector and localizer in closed loop
with the simulated robot, its sensors and the residuals."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from diagrams.residuals.contact_localization import ContactLocalizationScenario as RealisticScenario
from diagrams.residuals.contact_localization import build_contact_localization_diagram
from diagrams.station.conditions import set_ideal_conditions
from systems.residuals.contact_estimation import VALID


def ContactLocalizationScenario(**fields) -> RealisticScenario:
    """These tests measure the ideal world (the study's ``--ideal``): the scenario with its
    conditions set to ideal."""
    return set_ideal_conditions(RealisticScenario(**fields))


def _simulate(config: ContactLocalizationScenario, t_end: float):
    diagram, handles = build_contact_localization_diagram(config)
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
    handles, context = _simulate(ContactLocalizationScenario(push_body=None, seed=5), 1.5)
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
    _, handles = build_contact_localization_diagram(ContactLocalizationScenario(noise=False))
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
        noise=False, push_start=0.2, push_duration=0.5, push_body=body, push_point=tuple(p_B), push_force=tuple(f_W)
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


def test_rejects_model_without_ft_sensors_and_sole_push():
    with pytest.raises(ValueError, match="F/T"):
        build_contact_localization_diagram(ContactLocalizationScenario(model="nao_like"))
    with pytest.raises(ValueError, match="below an F/T sensor"):
        build_contact_localization_diagram(ContactLocalizationScenario(push_body="r_sole", push_force=(0, 0, -5)))
