"""The station's ``base_state`` option: the contact-aided invariant EKF
(``systems.estimation.base_state_estimator``) as the source of the sensed base state, against
the plant's truth, in the residual comparison, and the default left bit-identical."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from diagrams.residuals.residual_comparison import (
    ResidualComparisonScenario,
    build_residual_comparison_diagram,
    residual_comparison_metrics,
)
from diagrams.station.config import BASE_STATE_SOURCES, StationConfig
from diagrams.station.humanoid_station import add_humanoid_station
from systems.dynamics.base_state import quaternion_to_rotation
from systems.simulation.imperfections import Imperfections

DT = 1e-3


def _standing(
    duration: float, *, model: str = "hrp4_like", log_contact: bool = False, **station_kwargs
) -> tuple[dict, object]:
    """The ``model`` station (default hrp4_like) holding its posture for ``duration`` s: the
    sensed and true states logged every step (and the estimator's contact flags)."""
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model=model, **station_kwargs))
    hold = builder.AddSystem(ConstantVectorSource(station.q_hold))
    builder.Connect(hold.get_output_port(), station.desired_position)
    logs = {
        "sensed": LogVectorOutput(station.sensed_state, builder, DT),
        "true": LogVectorOutput(station.plant.get_state_output_port(), builder, DT),
        "torque": LogVectorOutput(station.measured_torque, builder, DT),
    }
    if log_contact:
        logs["contact"] = LogVectorOutput(station.foot_contact.GetOutputPort("foot_contact"), builder, DT)
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    return {k: log.FindLog(context).data() for k, log in logs.items()}, station


def _base_errors(station, sensed: np.ndarray, true: np.ndarray) -> dict:
    """The sensed base state against the true one, per logged sample: ``tilt`` and ``yaw``
    (deg, of the orientation error), the linear ``velocity_rms`` (m/s) and the final
    ``position_error`` (3, m)."""
    q0 = station.topology.free_joint.position_start()
    v0 = station.plant.num_positions() + station.topology.free_joint.velocity_start()
    tilt, yaw = [], []
    for k in range(sensed.shape[1]):
        E = quaternion_to_rotation(sensed[q0 : q0 + 4, k]) @ quaternion_to_rotation(true[q0 : q0 + 4, k]).T
        tilt.append(math.degrees(math.acos(min(1.0, max(-1.0, E[2, 2])))))
        yaw.append(math.degrees(math.atan2(E[1, 0] - E[0, 1], E[0, 0] + E[1, 1])))
    dv = sensed[v0 + 3 : v0 + 6] - true[v0 + 3 : v0 + 6]
    return {
        "tilt": np.array(tilt),
        "yaw": np.array(yaw),
        "velocity_rms": float(np.sqrt(np.mean(np.sum(dv**2, axis=0)))),
        "position_error": sensed[q0 + 4 : q0 + 7, -1] - true[q0 + 4 : q0 + 7, -1],
    }


def test_invariant_ekf_sensed_base_state_meets_the_floors_standing():
    """2.5 s standing with the noisy sensors: tilt <= 0.5 deg, base linear velocity RMS <=
    0.02 m/s (the issue's floors), the sensed base part against the plant's true state."""
    data, station = _standing(2.5, base_state="invariant_ekf")
    assert station.sensors.base_estimator is None and station.base_state_estimator is not None
    sensed, true = data["sensed"], data["true"]
    errors = _base_errors(station, sensed, true)
    tilt, velocity_rms = errors["tilt"], errors["velocity_rms"]
    position_error = float(np.linalg.norm(errors["position_error"]))
    print(f"\ninvariant_ekf standing 2.5 s: max tilt {max(tilt):.4f} deg, base velocity RMS {velocity_rms:.5f} m/s")
    assert np.isfinite(sensed).all()
    assert max(tilt) <= 0.5
    assert velocity_rms <= 0.02
    assert position_error <= 0.01


def test_set_initial_state_starts_the_estimator_at_that_state():
    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model="hrp4_like", base_state="invariant_ekf"))
    builder.Connect(builder.AddSystem(ConstantVectorSource(station.q_hold)).get_output_port(), station.desired_position)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    moved = station.initial_state.copy()
    q0 = station.topology.free_joint.position_start()
    moved[q0 + 4 : q0 + 7] += [0.3, -0.2, 0.01]
    station.set_initial_state(context, moved)
    estimator = station.base_state_estimator
    pose = estimator.GetOutputPort("base_pose").Eval(estimator.GetMyContextFromRoot(context))
    np.testing.assert_allclose(pose, moved[q0 : q0 + 7], atol=1e-12)


@pytest.mark.slow
def test_residual_comparison_with_the_invariant_ekf_stays_finite():
    """A short residual comparison (2 s, the push from 0.5 s) with each base-state source;
    the internal residual's relative error is printed for both (``pytest -s``)."""
    errors = {}
    for base_state in BASE_STATE_SOURCES:
        scenario = ResidualComparisonScenario(
            station=StationConfig.realistic(base_state=base_state, imperfections=Imperfections()), duration=2.0
        )
        diagram, handles = build_residual_comparison_diagram(scenario)
        simulator = Simulator(diagram)
        context = simulator.get_mutable_context()
        handles.station.set_initial_state(context)
        simulator.Initialize()
        simulator.AdvanceTo(scenario.duration)
        logs = {k: log.FindLog(context) for k, log in handles.loggers.items()}
        signals = {k: log.data() for k, log in logs.items()}
        signals["t"] = logs["internal"].sample_times()
        assert np.isfinite(signals["internal"]).all()
        metrics = residual_comparison_metrics(scenario, handles, signals, 1.0)
        errors[base_state] = metrics["internal_rel_rms_error"]
    print("\ninternal residual relative RMS error over 0.5-2 s:", {k: round(v, 4) for k, v in errors.items()})
    assert all(math.isfinite(e) for e in errors.values())
    # The internal residual is insensitive to the base estimate's small errors.
    assert errors["invariant_ekf"] < 2.0 * errors["truth_plus_noise"] + 0.05


def test_unknown_base_state_names_the_choices():
    with pytest.raises(ValueError, match="truth_plus_noise.*invariant_ekf"):
        add_humanoid_station(DiagramBuilder(), StationConfig(model="hrp4_like", base_state="ekf"))


def test_invariant_ekf_without_foot_force_sensing_flags_contact_from_the_estimated_sole_wrenches():
    """hrp4_like without foot F/T sensors or FSRs (``models/robots/hrp4_like_no_ft.yaml``),
    realistic sensors: the EKF's contact flags come from the soles' wrenches estimated from
    the station's own residuals (``foot_contact_from_estimated_wrenches``); both feet are in
    contact from the first steps, and the sensed base state meets the F/T robot's floors of
    ``test_invariant_ekf_sensed_base_state_meets_the_floors_standing``."""
    data, station = _standing(
        2.5,
        model="models/robots/hrp4_like_no_ft.yaml",
        log_contact=True,
        base_state="invariant_ekf",
        imperfections=Imperfections.realistic(),
    )
    assert station.foot_contact.get_name() == "foot_contact_from_estimated_wrenches"
    assert np.all(data["contact"][:, 10:] == 1.0)
    errors = _base_errors(station, data["sensed"], data["true"])
    assert np.isfinite(data["sensed"]).all()
    assert max(errors["tilt"]) <= 0.5
    assert errors["velocity_rms"] <= 0.02
    assert float(np.linalg.norm(errors["position_error"])) <= 0.01


def test_default_base_state_is_bit_identical():
    implicit, _ = _standing(0.2)
    explicit, station = _standing(0.2, base_state="truth_plus_noise")
    assert station.base_state_estimator is None and station.sensors.base_estimator is not None
    for key in implicit:
        np.testing.assert_array_equal(implicit[key], explicit[key])


@pytest.mark.slow
def test_nao_like_invariant_ekf_with_fsr_contact_meets_the_floors_standing():
    """nao_like (no F/T sensors) with base_state "invariant_ekf": its contact flags come from
    its four FSRs per foot (an FsrArray and FootContactFromFsr: on above 10 % of its weight,
    5.1 N, off below 5 %, 2.5 N).
    20 s standing with the noisy sensors: tilt <= 0.5 deg, base linear velocity RMS <= 0.02
    m/s (the issue's floors), both feet flagged in contact after the first step. The IMU is
    the station's default (no bias walk: the bias-free filter). Measured (``pytest -s``):
    max tilt 0.009°, velocity RMS 1.4 mm/s, yaw error 0.006°, position error 1.3 mm after
    20 s (0.020°, 0.04 mm from the generic initial covariance); ~36 s of wall time."""
    from systems.estimation.base_state_estimator import FootContactFromFsr

    duration = 20.0
    data, station = _standing(duration, model="nao_like", base_state="invariant_ekf", log_contact=True)
    assert isinstance(station.foot_contact, FootContactFromFsr)
    assert station.foot_contact.threshold == pytest.approx(0.10 * 5.19 * 9.81, rel=0.02)
    assert station.foot_contact.off_threshold == pytest.approx(0.05 * 5.19 * 9.81, rel=0.02)
    sensed, true = data["sensed"], data["true"]
    errors = _base_errors(station, sensed, true)
    tilt, yaw, velocity_rms = errors["tilt"], errors["yaw"], errors["velocity_rms"]
    position_error = float(np.linalg.norm(errors["position_error"]))
    print(
        f"\nnao_like invariant_ekf (FSR contact) standing {duration:.0f} s: max tilt {max(tilt):.4f} deg, base "
        f"velocity RMS {velocity_rms:.5f} m/s, final yaw error {yaw[-1]:.4f} deg, position error "
        f"{1e3 * position_error:.2f} mm, contact flags min over t >= 0.01 s {data['contact'][:, 10:].min(axis=1)}"
    )
    assert np.isfinite(sensed).all()
    assert data["contact"][:, 10:].min() == 1.0
    assert max(tilt) <= 0.5
    assert velocity_rms <= 0.02
    assert position_error <= 0.01


@pytest.mark.slow
def test_invariant_ekf_walking_drift_on_nao_like_with_the_realistic_imu():
    """The EKF while nao_like walks (the issue-7 walk, 12 s: about 1.1 m, 20 steps of
    single and double support, FSR contact flags), with the realistic IMU (BMI088 noise,
    EuRoC bias walks): tilt <= 0.5 deg and base linear velocity RMS <= 0.02 m/s (the
    issue's floors, here while walking), and the unobservable yaw and position drift within
    0.5 deg and 2 cm over the walk, all against the plant's true state. The realistic gyro
    has a 0.35 deg/s turn-on bias about the vertical: the robot stands 1 s before it walks,
    and the station's filter measures that bias over its first 0.5 s (without the still
    start the yaw drifted 4.2 deg over the walk)."""
    from diagrams.locomotion.nao_walk import NaoWalkScenario, build_nao_walk_diagram

    scenario = NaoWalkScenario(
        station=StationConfig(
            model="nao_like",
            noise=True,
            base_state="invariant_ekf",
            imperfections=Imperfections(imu=Imperfections.realistic().imu),
        ),
        standing_start=1.0,
    )
    diagram, handles = build_nao_walk_diagram(scenario)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(13.0)
    station = handles.station
    assert station.base_state_estimator is not None and station.base_state_estimator.estimates_imu_bias
    assert station.base_state_estimator.at_rest_duration == pytest.approx(0.5)
    sensed = handles.loggers["sensed_state"].FindLog(context).data()
    true = handles.loggers["state"].FindLog(context).data()
    errors = _base_errors(station, sensed, true)
    tilt, yaw, velocity_rms = errors["tilt"], errors["yaw"], errors["velocity_rms"]
    q0 = station.topology.free_joint.position_start()
    walked = float(np.linalg.norm(true[q0 + 4 : q0 + 6, -1] - true[q0 + 4 : q0 + 6, 0]))
    horizontal = float(np.linalg.norm(errors["position_error"][:2]))
    vertical = float(abs(errors["position_error"][2]))
    print(
        f"\nnao_like standing 1 s then walking 12 s ({walked:.2f} m), realistic IMU: max tilt {max(tilt):.3f} deg, "
        f"velocity RMS {1e3 * velocity_rms:.1f} mm/s, final yaw error {yaw[-1]:.3f} deg, position error horizontal "
        f"{1e3 * horizontal:.1f} mm, vertical {1e3 * vertical:.1f} mm"
    )
    assert walked > 1.0  # the walk happened
    assert np.isfinite(sensed).all()
    assert max(tilt) <= 0.5
    assert velocity_rms <= 0.02
    assert abs(yaw[-1]) <= 0.5 and horizontal <= 0.02 and vertical <= 0.02
