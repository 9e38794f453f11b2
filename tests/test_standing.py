"""Integration test: each humanoid stands 10 s under PD + gravity compensation.

Discrete plant, 1 ms steps, SAP, point contact (diagrams.station.standing). After the first
second of settling the base must move less than 1 cm and 1 degree, and at the end both
soles must be flat on the ground with all four spheres of each foot loaded.
"""

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import Simulator

from diagrams.station.standing import (
    build_standing_diagram,
    first_unexpected_contact,
    set_initial_state,
    standing_metrics,
)
from models import MODEL_NAMES

DURATION = 10.0  # s
SETTLE = 1.0  # s


@pytest.mark.parametrize("model_name", MODEL_NAMES)
def test_stands_still_with_feet_flat(model_name):
    plant_config = MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap", contact_model="point")
    diagram, handles = build_standing_diagram(model_name, plant_config=plant_config)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_initial_state(diagram, context, handles)
    simulator.Initialize()
    simulator.AdvanceTo(DURATION)
    assert context.get_time() == pytest.approx(DURATION)

    m = standing_metrics(handles, context, settle_time=SETTLE)
    assert not m.fell
    assert m.base_drift_m < 0.01, f"base moved {100 * m.base_drift_m:.3f} cm after {SETTLE} s"
    assert m.base_drift_rad < np.radians(1.0), f"base turned {np.degrees(m.base_drift_rad):.3f} deg after {SETTLE} s"
    for side in ("left", "right"):
        assert m.sole_tilt_rad[side] < np.radians(1.0), side
        # Point-contact penetration under load stays well below 1 mm.
        assert -1e-3 < m.sole_height_m[side] <= 0.0, side
        assert np.all(m.sphere_forces_N[side] > 0.0), (side, m.sphere_forces_N[side])
    assert m.feet_flat

    # The spheres carry the robot's weight (total normal force = m g at rest).
    plant = handles.plant
    weight = plant.CalcTotalMass(plant.GetMyContextFromRoot(context)) * 9.81
    total = sum(f.sum() for f in m.sphere_forces_N.values())
    assert total == pytest.approx(weight, rel=0.01)

    # The logger recorded the whole run, and the joints hold the nominal posture.
    log = handles.state_logger.FindLog(context)
    assert log.sample_times()[-1] == pytest.approx(DURATION, abs=0.011)
    q_joints = np.array(
        [
            plant.GetJointByName(j, handles.humanoid.model_instance).get_angle(plant.GetMyContextFromRoot(context))
            for j in handles.humanoid.nominal_posture
        ]
    )
    q_nominal = np.array(list(handles.humanoid.nominal_posture.values()))
    assert np.max(np.abs(q_joints - q_nominal)) < np.radians(3.0)
    # Nothing but the feet's contact geometries touched the ground.
    assert first_unexpected_contact(handles, context) is None


def test_metrics_detect_a_fall():
    """Without position feedback the robot collapses; the metrics must say so."""
    diagram, handles = build_standing_diagram("hrp4_like", kp=0.0, kd=1.0)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_initial_state(diagram, context, handles)
    simulator.Initialize()
    simulator.AdvanceTo(2.0)
    m = standing_metrics(handles, context, settle_time=SETTLE)
    assert m.fell
    assert not m.feet_flat or m.base_drift_m > 0.01
    # The fall is explained: the collapsing robot put another part of it on the ground.
    first = first_unexpected_contact(handles, context)
    assert first is not None and "touched the ground first, at" in first
    time = float(first.split(" at ")[1].split(" s")[0])
    assert 0.0 < time < 2.0
