"""Shared test setup: matplotlib draws off screen (the Makefile exports the same for the apps);
the ``hrp4_moved`` fixture."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402

from models import add_humanoid, set_standing_state  # noqa: E402


@pytest.fixture(scope="module")
def hrp4_moved():
    """(plant, scene_graph, handles, context): hrp4_like standing in a non-trivial posture,
    its arms and torso moved away from the nominal one (seeded), for the localizers' tests."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    handles = add_humanoid(plant, "hrp4_like", scene_graph=scene_graph)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    set_standing_state(plant, context, handles)
    rng = np.random.default_rng(7)
    q = plant.GetPositions(context)
    q[7:] += rng.uniform(-0.2, 0.2, q.size - 7)
    plant.SetPositions(context, q)
    return plant, scene_graph, handles, context
