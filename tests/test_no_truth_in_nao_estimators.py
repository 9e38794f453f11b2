"""No estimator, observer or controller of the Nao diagrams sees the simulated robot (issue 31):
each Nao diagram builder is checked by reference and by behaviour (``tests/truth_isolation.py``):
an absurd inertia on the simulated robot's right forearm (30 times its mass and inertia, its
centre of mass 5 cm away) changes no output and no update of any system outside the
simulation side (the Kalman force observer and its measurements, the arm compliance and the
hand-force estimates, the walking controllers), given the same inputs and state."""

from __future__ import annotations

import dataclasses

import pytest
from pydrake.systems.analysis import Simulator
from truth_isolation import differing_estimators, estimator_side, references_to_plant

from systems.observer.arm_compliance import NAO_ARM_CHAINS
from systems.simulation.disturbances import Push, Step

LINK = "RForeArm"
#: Simulated time before the check, s: the estimators' inputs and states are then nonzero
#: (three observer samples at 60 Hz, several compliance-controller updates at 100 Hz).
ADVANCE = 0.05
#: K_m of eq. 27 (N m/rad): the PD's K_p, what the calibration identifies (not run here).
MOTOR_CONSTANTS = {n: (2.0 if "Wrist" in n else 5.0) for c in NAO_ARM_CHAINS for n in c.joint_names}
#: The Kalman force observer and its measurements (``diagrams.observer.nao_sensing``).
OBSERVER = {"CenterOfPressure", "SupportFootCom", "ImuComAcceleration", "LipForceObserverSystem"}
#: The hand-force estimates of Sec. 6.4 (``systems.observer.arm_compliance``).
ARM_ESTIMATES = {"JointTorqueFromPositionError", "ArmExternalForceEstimator", "ObserverHandForce"}


def _simulated(diagram, set_initial_state, duration: float = ADVANCE):
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    return context


def _force_observer():
    from diagrams.observer.nao_force_observer import Experiment, NaoForceObserverScenario, build_experiment_diagram

    # Experiment 1's setup (the wide stance, a force through the torso), on from the start.
    push = Push("torso", (0.05, 0.0, -0.05), (1.0, 0.0, 0.0), Step(2.0, 0.0))
    experiment = Experiment(1, "a push through the torso", [push], duration=ADVANCE)
    diagram, handles = build_experiment_diagram(NaoForceObserverScenario(experiments=[1]), experiment)
    return diagram, _simulated(diagram, handles.set_initial_state)


def _compliant_arms():
    from diagrams.observer.nao_compliant_arms import build_nao_compliant_arms_diagram, hand_pushes, lean_posture

    diagram, handles = build_nao_compliant_arms_diagram(
        hand_pushes(Step(1.5, 0.0)),
        posture_knots=((0.02, lean_posture(-0.1)),),
        motor_constants=MOTOR_CONSTANTS,
    )
    return diagram, _simulated(diagram, handles.set_initial_state)


def _walk_pulled():
    from diagrams.observer.nao_walk_pulled import NaoWalkPulledScenario, build_nao_walk_pulled_diagram

    diagram, handles = build_nao_walk_pulled_diagram(NaoWalkPulledScenario())
    return diagram, _simulated(diagram, handles.set_initial_state)


def _force_guided_walk():
    from diagrams.observer.nao_force_guided_walk import NaoForceGuidedWalkScenario, build_force_guided_diagram

    # "blend": the observer's, the joint-level and the blended estimates all built.
    diagram, handles = build_force_guided_diagram(NaoForceGuidedWalkScenario(trigger_source="blend"))
    return diagram, _simulated(diagram, handles["station"].set_initial_state)


def _nao_walk(base_state: str = "truth_plus_noise"):
    from diagrams.locomotion.nao_walk import NaoWalkScenario, build_nao_walk_diagram
    from diagrams.station.config import StationConfig
    from systems.locomotion.walking_pattern import WalkingParameters

    scenario = NaoWalkScenario(
        station=StationConfig(model="nao_like", noise=True, base_state=base_state),
        walking=WalkingParameters(num_steps=4),
    )
    diagram, handles = build_nao_walk_diagram(scenario)
    return diagram, _simulated(diagram, handles.set_initial_state)


#: name: (build, the estimator-side classes the diagram must hold, else the check is void).
BUILDS = {
    "force_observer": (_force_observer, OBSERVER),
    "compliant_arms": (_compliant_arms, OBSERVER | ARM_ESTIMATES | {"HandComplianceController"}),
    "walk_pulled": (_walk_pulled, OBSERVER | {"NaoWalkingController"}),
    "force_guided_walk": (_force_guided_walk, OBSERVER | ARM_ESTIMATES | {"ForceGuidedWalkingController"}),
    "nao_walk": (_nao_walk, {"NaoWalkingController"}),
    "nao_walk_invariant_ekf": (
        lambda: _nao_walk("invariant_ekf"),
        {"NaoWalkingController", "InvariantEkfBaseStateEstimator", "FootContactFromFsr"},
    ),
}


def _plant(diagram):
    return diagram.GetSubsystemByName("plant")


@pytest.mark.parametrize("name", sorted(BUILDS))
def test_no_nao_estimator_holds_the_simulated_plant(name):
    build, expected = BUILDS[name]
    diagram, _ = build()
    plant = _plant(diagram)
    checked = estimator_side(diagram)
    classes = {type(s).__name__ for s in checked}
    assert expected | {"PdGravityController"} <= classes, sorted(expected - classes)
    leaks = {s.get_name(): references_to_plant(s, plant) for s in checked}
    assert not {k: v for k, v in leaks.items() if v}, leaks


@pytest.mark.parametrize("name", sorted(BUILDS))
def test_an_absurd_simulated_inertia_changes_no_nao_estimator_output(name, monkeypatch):
    build, expected = BUILDS[name]
    differing, compared = differing_estimators(build, monkeypatch, LINK, _plant)
    assert compared >= len(expected) + 1
    assert not differing, differing


def test_the_checks_catch_nao_estimators_built_on_the_simulated_plant(monkeypatch):
    """Control: with the station's estimators' plant replaced by the simulated one for the
    diagram's own systems (what issue 31 removed), both checks name the arm compliance and
    the hand-force estimates."""
    from diagrams.observer import nao_compliant_arms

    real_station = nao_compliant_arms.add_humanoid_station

    def leaky_station(*args, **kwargs):
        station = real_station(*args, **kwargs)
        station.estimator = dataclasses.replace(
            station.estimator, plant=station.plant, humanoid=station.humanoid, topology=station.topology
        )
        return station

    monkeypatch.setattr(nao_compliant_arms, "add_humanoid_station", leaky_station)
    diagram, _ = _compliant_arms()
    plant = _plant(diagram)
    leaks = [s.get_name() for s in estimator_side(diagram) if references_to_plant(s, plant)]
    assert "hand_compliance_controller" in leaks and "arm_external_force_estimator" in leaks, leaks
    differing, _ = differing_estimators(_compliant_arms, monkeypatch, LINK, _plant)
    assert any(d.startswith("arm_external_force_estimator") for d in differing), differing
