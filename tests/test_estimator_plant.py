"""The estimators' own plant (diagrams.station.estimator_plant) and the inertias written into
a model's text (models.with_link_inertias): issue 31."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, SpatialInertia, UnitInertia
from pydrake.systems.framework import DiagramBuilder

from diagrams.station.config import StationConfig
from diagrams.station.estimator_plant import build_estimator_plant
from diagrams.station.humanoid_station import add_humanoid_station
from models import add_humanoid, with_link_inertias
from systems.simulation.imperfections import Imperfections, ModelMismatch, perturbed_spatial_inertias

TALOS = "models/robots/talos.yaml"


def _inertia(mass: float, com, radius: float = 0.05) -> SpatialInertia:
    return SpatialInertia(mass, np.asarray(com, float), UnitInertia.SolidSphere(radius).ShiftFromCenterOfMass(com))


@pytest.mark.parametrize(
    "robot, link", [("hrp4_like", "R_ELBOW_P_LINK"), ("nao_like", "RForeArm"), (TALOS, "arm_right_4_link")]
)
def test_written_inertias_become_the_plants_defaults(robot, link):
    """SDFormat (the built-ins) and URDF (TALOS): the parsed link has exactly the given
    mass, centre of mass and rotational inertia; the other links keep the file's."""
    wanted = _inertia(2.5, [0.01, -0.02, 0.03])
    plant = MultibodyPlant(time_step=0.0)
    add_humanoid(plant, robot, link_inertias={link: wanted})
    plant.Finalize()
    nominal = MultibodyPlant(time_step=0.0)
    add_humanoid(nominal, robot)
    nominal.Finalize()
    np.testing.assert_allclose(
        plant.GetBodyByName(link).default_spatial_inertia().CopyToFullMatrix6(), wanted.CopyToFullMatrix6(), atol=1e-14
    )
    for i in range(1, plant.num_bodies()):
        body = plant.get_body(BodyIndex(i))
        if body.name() != link:
            np.testing.assert_array_equal(
                body.default_spatial_inertia().CopyToFullMatrix6(),
                nominal.GetBodyByName(body.name()).default_spatial_inertia().CopyToFullMatrix6(),
            )


def test_bad_written_inertias_are_refused_by_name():
    with pytest.raises(ValueError, match="no link named 'NOT_A_LINK'"):
        add_humanoid(MultibodyPlant(time_step=0.0), "hrp4_like", link_inertias={"NOT_A_LINK": _inertia(1.0, [0, 0, 0])})
    with pytest.raises(ValueError, match="physically valid"):
        with_link_inertias("<robot><link name='a'/></robot>", "urdf", {"a": "not an inertia"})
    with pytest.raises(ValueError, match="not XML"):
        with_link_inertias("<robot", "urdf", {"a": _inertia(1.0, [0, 0, 0])})


def test_the_station_gives_the_estimators_their_own_plant_with_the_mismatch():
    """Realistic world: the estimators' plant is another plant, whose default inertias are
    the model mismatch's; the simulated plant keeps the description's."""
    builder = DiagramBuilder()
    imperfections = Imperfections.realistic()
    station = add_humanoid_station(builder, StationConfig(model="hrp4_like", imperfections=imperfections))
    estimator = station.estimator
    assert estimator.plant is not station.plant and estimator.scene_graph is not station.scene_graph
    nominal = build_estimator_plant("hrp4_like")
    expected = perturbed_spatial_inertias(nominal.plant, imperfections.model_mismatch, imperfections.seed)
    assert set(expected) == set(station.estimator_inertias)
    for index, M in expected.items():
        body = BodyIndex(index)
        np.testing.assert_allclose(
            estimator.plant.get_body(body).default_spatial_inertia().CopyToFullMatrix6(),
            M.CopyToFullMatrix6(),
            atol=1e-14,
        )
        np.testing.assert_array_equal(
            station.plant.get_body(body).default_spatial_inertia().CopyToFullMatrix6(),
            nominal.plant.get_body(body).default_spatial_inertia().CopyToFullMatrix6(),
        )
    assert ModelMismatch() != imperfections.model_mismatch
    # The estimators' frames are their plant's; the station's F/T frames are those.
    assert all(frame.GetParentPlant() is estimator.plant for frame in station.known_wrench_frames)
    assert station.dynamics_model.plant is estimator.plant


def test_a_model_file_gets_its_own_estimators_plant(tmp_path):
    """A floating-base model file (no description): parsed again, gravity off as the
    station simulates it."""
    from models import model_file

    builder = DiagramBuilder()
    station = add_humanoid_station(builder, StationConfig(model=str(model_file("nao_like"))))
    assert station.humanoid is None and station.estimator.humanoid is None
    assert station.estimator.plant is not station.plant
    np.testing.assert_array_equal(station.estimator.plant.gravity_field().gravity_vector(), np.zeros(3))
    np.testing.assert_array_equal(station.estimator.standing_state, station.initial_state)
