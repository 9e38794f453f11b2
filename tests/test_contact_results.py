"""systems.common.contact_results: one convention for the normal force on the robot."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from diagrams.station.standing import build_standing_diagram, set_initial_state
from systems.common.contact_results import robot_point_contacts


def test_normal_force_on_flat_ground_is_the_world_z_force_on_the_robot_to_the_bit():
    diagram, handles = build_standing_diagram("nao_like")  # 1 ms steps, SAP, point contact
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_initial_state(diagram, context, handles)
    simulator.AdvanceTo(0.5)
    plant = handles.plant
    plant_context = plant.GetMyContextFromRoot(context)
    results = plant.get_contact_results_output_port().Eval(plant_context)
    robot = {g for ids in handles.humanoid.collision_geometries.values() for g in ids}
    contacts = robot_point_contacts(results, robot)
    assert len(contacts.geometries) == results.num_point_pair_contacts() > 0
    for i in range(results.num_point_pair_contacts()):  # the world-z reading, by hand
        info = results.point_pair_contact_info(i)
        pair = info.point_pair()
        f_z_on_robot = info.contact_force()[2] if pair.id_B in robot else -info.contact_force()[2]
        assert contacts.normal_forces[i] == f_z_on_robot
        np.testing.assert_array_equal(contacts.points[i], info.contact_point())
    assert np.all(contacts.normal_forces > 0.0)  # compressive
    weight = plant.CalcTotalMass(plant_context) * 9.81
    assert contacts.normal_forces.sum() == pytest.approx(weight, rel=0.05)
    # Per-slot sums, and a geometry set without contact reads nothing.
    slots = {g: 0 for g in handles.humanoid.fsr_geometries["left"]}
    assert contacts.summed(slots, 1)[0] > 0.0
    assert robot_point_contacts(results, set()).normal_forces.shape == (0,)
    assert robot_point_contacts(results, set()).points.shape == (0, 3)
