"""Shared test setup: matplotlib draws off screen (the Makefile exports the same for the apps);
every test fails when Drake logs a deprecation while it runs (the ``drake_deprecations``
fixture; ``DrakeDeprecationWarning`` is an error by ``pyproject.toml``'s ``filterwarnings``),
so each app's smoke test also checks the installed Drake release; the ``hrp4_moved`` fixture."""

import logging
import os

os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402

from models import add_humanoid, set_standing_state  # noqa: E402


class DrakeDeprecationLog(logging.Handler):
    """Keeps every message of Drake's logger (C++ spdlog, forwarded by pydrake) that speaks
    of a deprecation: C++ "DRAKE_DEPRECATED", a deprecated element of a model file."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        text = record.getMessage()
        if "deprecat" in text.lower():
            self.messages.append(text)


_DRAKE_DEPRECATIONS = DrakeDeprecationLog()
_drake_logger = logging.getLogger("drake")
_drake_logger.addHandler(_DRAKE_DEPRECATIONS)
if _drake_logger.getEffectiveLevel() > logging.WARNING:
    _drake_logger.setLevel(logging.WARNING)


@pytest.fixture(autouse=True)
def drake_deprecations():
    """The deprecation messages Drake logs during the test (a list the test may empty); any
    left at its end fail it. Drake logs each C++ message once per process: the first test to
    reach a deprecated feature is the one that fails (``tests/test_no_deprecated_drake.py``
    checks every diagram in a fresh process)."""
    start = len(_DRAKE_DEPRECATIONS.messages)
    new = _DRAKE_DEPRECATIONS.messages
    yield _LogView(new, start)
    assert len(new) == start, f"Drake logged a deprecation during this test: {new[start:]}"


class _LogView:
    """The messages of one test: ``list(view)``; ``view.clear()`` drops them."""

    def __init__(self, messages: list[str], start: int) -> None:
        self._messages, self._start = messages, start

    def __iter__(self):
        return iter(self._messages[self._start :])

    def clear(self) -> None:
        del self._messages[self._start :]


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
