"""No estimator sees the simulated robot (issue 31): each realistic diagram of the residual
experiments is checked by reference and by behaviour (``tests/truth_isolation.py``): an
absurd inertia on the simulated robot's right elbow (30 times its mass and inertia, its centre
of mass 5 cm away) changes no output and no update of any system outside the simulation side,
given the same inputs and state."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from truth_isolation import (
    absurd_simulated_inertias,
    differing_estimators,
    estimator_side,
    references_to_plant,
)

from diagrams.station.config import StationConfig
from diagrams.station.estimator_plant import build_estimator_plant
from systems.estimation.model_identification import ModelCorrections
from systems.simulation.imperfections import Imperfections, ModelMismatch, perturbed_spatial_inertias

LINK = "R_ELBOW_P_LINK"
#: Simulated time before the check, s: the estimators' inputs and states are then nonzero.
ADVANCE = 0.03


def _refined_model() -> ModelCorrections:
    """A stand-in refined model of hrp4_like (the realistic world's mismatch of another seed,
    nonzero torque corrections), so that the diagrams build their torque correction too."""
    estimator = build_estimator_plant("hrp4_like")
    inertias = perturbed_spatial_inertias(estimator.plant, ModelMismatch(5.0, 5.0, 5.0), seed=99)
    n = estimator.topology.num_joints
    return ModelCorrections(inertias, np.full(n, 0.2), np.full(n, 0.05), 0.1, np.full(n, 0.1), np.full(n, 0.01))


def _simulated(diagram, handles_station, duration: float = ADVANCE):
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    handles_station.set_initial_state(context)
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    return context


def _push_and_comply(residual_kind: str):
    from diagrams.residuals.push_and_comply import PushAndComplyScenario, build_push_and_comply_diagram

    scenario = PushAndComplyScenario(tare_duration=0.0, push_start=0.0, push_peak_time=0.5, push_end=1.0, duration=1.0)
    diagram, handles = build_push_and_comply_diagram(scenario, residual_kind, model_corrections=_refined_model())
    return diagram, _simulated(diagram, handles.station)


def _residual_comparison():
    from diagrams.residuals.residual_comparison import ResidualComparisonScenario, build_residual_comparison_diagram

    scenario = ResidualComparisonScenario(push_start=0.0)
    diagram, handles = build_residual_comparison_diagram(scenario, model_corrections=_refined_model())
    return diagram, _simulated(diagram, handles.station)


def _contact_localization():
    from diagrams.residuals.contact_study import ContactLocalizationScenario, build_contact_localization_diagram

    scenario = ContactLocalizationScenario(
        push_body=LINK, push_point=(0.0, -0.05, -0.1), push_force=(0.0, 15.0, 0.0), push_start=0.0
    )
    diagram, handles = build_contact_localization_diagram(scenario, model_corrections=_refined_model(), online=True)
    return diagram, _simulated(diagram, handles.station, 0.15)


def _model_refinement():
    from diagrams.residuals.model_refinement import ModelRefinementScenario, build_refinement_diagram

    diagram, handles = build_refinement_diagram(ModelRefinementScenario(), None, _refined_model())
    return diagram, _simulated(diagram, handles.station)


BUILDS = {
    "push_and_comply_internal": lambda: _push_and_comply("internal"),
    "push_and_comply_classical": lambda: _push_and_comply("classical"),
    "residual_comparison": _residual_comparison,
    "contact_localization": _contact_localization,
    "model_refinement": _model_refinement,
}


def _plant(diagram):
    return diagram.GetSubsystemByName("plant")


@pytest.mark.parametrize("name", sorted(BUILDS))
def test_no_estimator_holds_the_simulated_plant(name):
    diagram, _ = BUILDS[name]()
    plant = _plant(diagram)
    checked = estimator_side(diagram)
    assert any(type(s).__name__ == "PdGravityController" for s in checked)
    leaks = {s.get_name(): references_to_plant(s, plant) for s in checked}
    assert not {k: v for k, v in leaks.items() if v}, leaks


@pytest.mark.parametrize("name", sorted(BUILDS))
def test_an_absurd_simulated_inertia_changes_no_estimator_output(name, monkeypatch):
    differing, compared = differing_estimators(BUILDS[name], monkeypatch, LINK, _plant)
    assert compared >= 5
    assert not differing, differing


def test_the_checks_catch_estimators_built_on_the_simulated_plant(monkeypatch):
    """Control: with the station's estimators' plant replaced by a view of the simulated one
    (the leak issue 31 removed), both checks name the residual and the admittance."""
    from diagrams.residuals import push_and_comply
    from systems.residuals.momentum_residuals import ResidualModel

    real_station = push_and_comply.add_humanoid_station

    def leaky_station(builder, config, model_corrections=None):
        station = real_station(builder, config, model_corrections=model_corrections)
        station.estimator = dataclasses.replace(
            station.estimator,
            plant=station.plant,
            scene_graph=station.scene_graph,
            humanoid=station.humanoid,
            topology=station.topology,
            ft_frames=tuple(station.sensors.ft_frames),
        )
        station.known_wrench_frames = station.estimator.ft_frames
        station.dynamics_model = ResidualModel(station.plant)
        return station

    monkeypatch.setattr(push_and_comply, "add_humanoid_station", leaky_station)
    diagram, _ = _push_and_comply("internal")
    plant = _plant(diagram)
    leaks = [s.get_name() for s in estimator_side(diagram) if references_to_plant(s, plant)]
    assert "internal_residual" in leaks and "joint_admittance_controller" in leaks, leaks
    differing, _ = differing_estimators(lambda: _push_and_comply("internal"), monkeypatch, LINK, _plant)
    assert any(d.startswith("internal_residual") for d in differing), differing


def test_the_absurd_inertia_reaches_the_simulated_plant_only(monkeypatch):
    from truth_isolation import absurd_inertia

    from diagrams.residuals.push_and_comply import PushAndComplyScenario, build_push_and_comply_diagram

    nominal = build_estimator_plant("hrp4_like").plant.GetBodyByName(LINK).default_spatial_inertia()
    absurd = absurd_inertia(nominal)
    with absurd_simulated_inertias(monkeypatch, {LINK: absurd}):
        _, handles = build_push_and_comply_diagram(
            PushAndComplyScenario(station=StationConfig.realistic(imperfections=Imperfections())), "internal"
        )
    simulated = handles.station.plant.GetBodyByName(LINK).default_spatial_inertia()
    estimated = handles.station.estimator.plant.GetBodyByName(LINK).default_spatial_inertia()
    np.testing.assert_allclose(simulated.CopyToFullMatrix6(), absurd.CopyToFullMatrix6(), rtol=1e-12)
    np.testing.assert_allclose(estimated.CopyToFullMatrix6(), nominal.CopyToFullMatrix6(), rtol=1e-12)
