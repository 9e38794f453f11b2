"""Import layers (issue 13): imports only point down, apps -> diagrams -> systems -> models.

Checked on the source with ``ast`` (every ``import``/``from ... import``, also inside
functions and ``if`` blocks), for every .py file under models/, systems/, diagrams/, apps/:

* models imports none of systems, diagrams, apps;
* systems imports neither diagrams nor apps; systems.common, the lowest of the systems
  sub-packages, imports no other systems sub-package. Sideways imports between the other
  systems sub-packages are allowed (today: dynamics and locomotion -> common; simulation
  -> common, dynamics; residuals -> common, dynamics, simulation; observer -> common,
  locomotion, simulation);
* diagrams imports no apps (diagrams of different worlds may import each other);
* an app imports no other app, except the shared runner ``apps.runner``, the study engine
  ``apps.engine``, plots ``apps.common`` and the results files ``apps.results``.

Relative imports are resolved against the importing module's package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("models", "systems", "diagrams", "apps")
#: The layers each layer must not import (upward imports).
FORBIDDEN = {
    "models": ("systems", "diagrams", "apps"),
    "systems": ("diagrams", "apps"),
    "diagrams": ("apps",),
    "apps": (),
}
SHARED_APP_MODULES = ("apps.common", "apps.engine", "apps.results", "apps.runner")


def module_name(path: Path, root: Path = ROOT) -> str:
    """Dotted module name of a file under ``root`` (``pkg/__init__.py`` -> ``pkg``)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imported_modules(source: str, module: str, *, is_package: bool = False) -> list[tuple[int, str]]:
    """(line, dotted name) of every module ``source`` imports, anywhere in the file. For
    ``from X import y`` both X and X.y are listed (y may be a submodule)."""
    package = module if is_package else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".") if package else []
                if node.level > 1:
                    base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.append((node.lineno, target))
            found += [(node.lineno, f"{target}.{alias.name}") for alias in node.names if alias.name != "*"]
    return found


def _within(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def layer_violations(source: str, module: str, *, is_package: bool = False) -> list[str]:
    """The upward imports of ``module`` (whose text is ``source``) by the rules of the module
    docstring, as readable messages; empty when it keeps to its layer."""
    layer = module.split(".")[0]
    if layer not in FORBIDDEN:
        raise ValueError(f"layer_violations: {module!r} is in none of the layers {LAYERS}")
    out = []
    for line, name in imported_modules(source, module, is_package=is_package):
        for upper in FORBIDDEN[layer]:
            if _within(name, upper):
                out.append(f"{module}:{line}: imports {name} ({layer} must not import {upper})")
        if (
            _within(module, "systems.common")
            and _within(name, "systems")
            and name != "systems"
            and not _within(name, "systems.common")
        ):
            out.append(f"{module}:{line}: imports {name} (systems.common must not import other systems sub-packages)")
        if (
            layer == "apps"
            and _within(name, "apps")
            and name != "apps"
            and not _within(name, module)
            and not any(_within(name, shared) for shared in SHARED_APP_MODULES)
        ):
            out.append(
                f"{module}:{line}: imports {name} (an app must not import another app; move what it "
                "needs down to diagrams/ or systems/)"
            )
    return sorted(set(out))


def _sources() -> list[Path]:
    files = sorted(p for layer in LAYERS for p in (ROOT / layer).rglob("*.py"))
    return [p for p in files if "__pycache__" not in p.parts]


def test_every_layer_has_sources():
    for layer in LAYERS:
        assert any(p.parts[len(ROOT.parts)] == layer for p in _sources()), f"no .py file under {layer}/"
    assert len(_sources()) > 40


def test_no_upward_import():
    violations = []
    for path in _sources():
        violations += layer_violations(path.read_text(), module_name(path), is_package=path.name == "__init__.py")
    assert violations == [], "upward imports:\n" + "\n".join(violations)


@pytest.mark.parametrize(
    "module, source, expected",
    [
        (
            "systems.observer.arm_compliance",
            "def f():\n    from diagrams.station.humanoid_station import add_humanoid_station\n",
            "systems must not import diagrams",
        ),
        ("systems.simulation.cable", "import apps.nao_walk\n", "systems must not import apps"),
        ("models.generate_sdf", "from systems.common import checks\n", "models must not import systems"),
        (
            "diagrams.observer.nao_force_observer",
            "if True:\n    from apps import common\n",
            "diagrams must not import apps",
        ),
        (
            "diagrams.observer.nao_sensing",
            "from ..residuals import contact_localization\nimport apps\n",
            "diagrams must not import apps",
        ),
        (
            "systems.common.checks",
            "from systems.dynamics.base_state import checked_state\n",
            "systems.common must not import other systems sub-packages",
        ),
        (
            "systems.common.checks",
            "from ..dynamics import base_state\n",
            "systems.common must not import other systems sub-packages",
        ),
        (
            "apps.benchmark",
            "from apps.contact_localization import sample_trials\n",
            "an app must not import another app",
        ),
        ("apps.benchmark", "from . import replay_nao_dataset\n", "an app must not import another app"),
    ],
)
def test_the_checker_catches_upward_imports(module, source, expected):
    """Positive control: synthetic sources with an upward import fail the check (so
    ``test_no_upward_import`` cannot pass vacuously)."""
    violations = layer_violations(source, module)
    assert len(violations) >= 1 and all(expected in v for v in violations), violations


@pytest.mark.parametrize(
    "module, source",
    [
        (
            "apps.nao_walk",
            "from apps.common import replay_meshcat\nfrom diagrams.locomotion.nao_walk import walking_floors\n",
        ),
        ("diagrams.observer.nao_walk_pulled", "from diagrams.locomotion.nao_walk import ContactZmp\nimport systems\n"),
        (
            "systems.observer.force_observer",
            "from systems.locomotion.walking_pattern import smoothstep5\nimport models\n",
        ),
        (
            "systems.common.topology",
            "from systems.common.checks import vector3\nfrom pydrake.multibody.plant import MultibodyPlant\n",
        ),
        ("models", "import numpy\n"),
    ],
)
def test_the_checker_accepts_downward_and_sideways_imports(module, source):
    assert layer_violations(source, module, is_package=module == "models") == []


def test_the_checker_refuses_a_module_outside_the_layers():
    with pytest.raises(ValueError, match="tests.test_x.*none of the layers"):
        layer_violations("import os\n", "tests.test_x")
