"""Bodies joined by welds are one rigid link for the localizers (issue 14, TALOS): a URDF's
fixed joints (a reduced model's gripper fingers) make several bodies that move as one, and no
joint effort tells a push on one from a push on another. The localizers report a push on
such a body as valid (not "ambiguous" against its welded sibling), and the study scores the
link as right when the estimate is on the same rigid link."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from diagrams.station.plant_config import default_plant_config
from models import add_ground, add_humanoid, point_contact_scene_graph_config, set_standing_state
from systems.common.topology import rigid_link_of_bodies
from systems.residuals.contact_estimation import VALID, ContactLocalizer, _SensedConfiguration
from systems.residuals.multi_contact import MultiContactLocalizer

TALOS = Path(__file__).resolve().parents[1] / "models" / "robots" / "talos.yaml"


@pytest.fixture(scope="module")
def talos():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), point_contact_scene_graph_config(), builder)
    h = add_humanoid(plant, TALOS, scene_graph=scene_graph)
    add_ground(plant)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, h)
    return plant, scene_graph, h, plant.GetPositions(context)


def test_welded_bodies_share_a_rigid_link(talos):
    plant, _, _, _ = talos
    link = rigid_link_of_bodies(plant)
    index = {
        name: int(plant.GetBodyByName(name).index())
        for name in (
            "arm_right_7_link",
            "gripper_right_base_link",
            "gripper_right_fingertip_2_link",
            "gripper_right_motor_double_link",
            "arm_right_6_link",
        )
    }
    assert link[index["gripper_right_fingertip_2_link"]] == link[index["arm_right_7_link"]]
    assert link[index["gripper_right_base_link"]] == link[index["arm_right_7_link"]]
    assert link[index["gripper_right_motor_double_link"]] != link[index["arm_right_7_link"]]  # a revolute joint
    assert link[index["arm_right_6_link"]] != link[index["arm_right_7_link"]]


def _exact_inputs(plant, q, body, p_B, f_W):
    """The ideal residuals of force f_W at point p_B of body: r = J^fb^T f (eq. 12), and the
    external wrench [p x f; f] about the world origin."""
    kin = _SensedConfiguration(plant, "test")
    kin.set_positions(q)
    r = kin.floating_jacobian(body, p_B).T @ f_W
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    p_W = plant.EvalBodyPoseInWorld(context, body).multiply(p_B)
    return np.concatenate((np.cross(p_W, f_W), f_W)), r, p_W


def test_a_push_on_a_welded_gripper_body_is_valid_on_its_rigid_link(talos):
    plant, scene_graph, h, q = talos
    feet = [f.body() for f in h.sole_frames.values()] + [
        plant.GetBodyByName(n) for n in ("leg_left_6_link", "leg_right_6_link")
    ]
    localizer = ContactLocalizer(plant, scene_graph, exclude_bodies=feet)
    body = plant.GetBodyByName("gripper_right_fingertip_2_link")
    # A point on the fingertip's box, pushed into it from the outside (along its -x face).
    inspector = scene_graph.model_inspector()
    (g,) = plant.GetCollisionGeometriesForBody(body)
    box, X_BG = inspector.GetShape(g), inspector.GetPoseInFrame(g)
    p_B = X_BG.multiply([box.width() / 2, 0.0, 0.0])
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    R_WB = plant.EvalBodyPoseInWorld(context, body).rotation().matrix()
    f_W = -15.0 * (R_WB @ X_BG.rotation().matrix()[:, 0])
    wrench, r, p_W = _exact_inputs(plant, q, body, p_B, f_W)
    result = localizer.localize(q, wrench, r)
    assert result.status == VALID
    assert localizer.same_link(result.body_index, int(body.index()))
    assert not localizer.same_link(result.runner_up_body_index, int(body.index()))
    multi = MultiContactLocalizer(plant, scene_graph, exclude_bodies=feet)
    fit = multi.fit_one(q, wrench, r)
    assert multi.same_link(fit.body_indices[0], int(body.index()))
    assert fit.runner_up_body_indices and not multi.same_link(fit.runner_up_body_indices[0], int(body.index()))
