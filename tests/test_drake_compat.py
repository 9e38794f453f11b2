"""What the project assumes of the installed Drake release (``models.drake_compat``): it is one
that ``pyproject.toml`` admits, the free-body API the project calls means the same on every
supported release, and the suite's guard against deprecated Drake features works."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from packaging.specifiers import SpecifierSet
from packaging.version import Version
from pydrake.common.deprecation import DrakeDeprecationWarning, deprecated_callable
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from models import add_humanoid
from models.drake_compat import drake_version

ROOT = Path(__file__).resolve().parents[1]


def test_installed_drake_is_in_the_project_range():
    dependencies = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (spec,) = [d for d in dependencies if d.startswith("drake")]
    version = drake_version()
    assert version is not None and len(version) >= 2
    assert Version(".".join(map(str, version))) in SpecifierSet(spec.removeprefix("drake"))


@pytest.mark.parametrize("model", ["hrp4_like", "nao_like"])
def test_free_body_api_sets_the_base_pose_and_velocity_in_world(model):
    """``SetFreeBodyPose(context, body, X)`` and ``SetFreeBodySpatialVelocity(context, body, V)``
    (the names and argument order both releases share) set the floating base's pose and
    spatial velocity in world, as the project's code assumes."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    handles = add_humanoid(plant, model)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    base = handles.base_body
    assert base.is_floating_base_body()
    X_WB = RigidTransform(RollPitchYaw(0.2, -0.3, 0.4), [0.1, -0.2, 0.9])
    V_WB = SpatialVelocity([0.3, -0.1, 0.2], [0.5, 0.4, -0.6])
    plant.SetFreeBodyPose(context, base, X_WB)
    plant.SetFreeBodySpatialVelocity(context, base, V_WB)
    np.testing.assert_allclose(plant.EvalBodyPoseInWorld(context, base).GetAsMatrix4(), X_WB.GetAsMatrix4(), atol=1e-14)
    np.testing.assert_allclose(plant.GetFreeBodyPose(context, base).GetAsMatrix4(), X_WB.GetAsMatrix4(), atol=1e-14)
    V = plant.EvalBodySpatialVelocityInWorld(context, base)
    np.testing.assert_allclose(V.get_coeffs(), V_WB.get_coeffs(), atol=1e-14)


def test_a_logged_deprecation_reaches_the_suite_guard(drake_deprecations):
    """The guard of ``tests/conftest.py`` sees a deprecation Drake logs in the test process (a
    model file with a deprecated SDFormat element), so that it cannot pass silently."""
    plant = MultibodyPlant(1e-3)
    model = "<sdf version='1.9'><model name='m'><link name='l'/></model><_drake_deprecation_unit_test_element/></sdf>"
    Parser(plant).AddModelsFromString(model, "sdf")
    assert any("_drake_deprecation_unit_test_element" in m for m in drake_deprecations)
    drake_deprecations.clear()


def test_a_deprecated_binding_fails_a_test():
    """``DrakeDeprecationWarning`` is an error in the suite (``pyproject.toml``)."""
    with pytest.raises(DrakeDeprecationWarning, match="use something else"):
        deprecated_callable("use something else", date="2038-01-19")(lambda: None)()
