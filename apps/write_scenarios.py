"""Writes every app's default scenario file, ``apps/scenarios/<app>_default.yaml``, from its
scenario dataclass: every field at its default, each below its docstring entry. The files
are written, never edited by hand, so they hold exactly the fields of the dataclasses and
of the Drake configs every supported Drake release shares (``models.drake_compat``).

    python -m apps.write_scenarios           # (re)write the files
    python -m apps.write_scenarios --check   # exit 1, naming them, if a file differs

``make scenarios`` runs the first; ``tests/test_write_scenarios.py`` the check.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from diagrams.locomotion.nao_walk import NaoWalkScenario
from diagrams.observer.nao_compliant_arms import NaoCompliantArmsScenario
from diagrams.observer.nao_force_guided_walk import NaoForceGuidedWalkScenario
from diagrams.observer.nao_force_observer import NaoForceObserverScenario
from diagrams.observer.nao_walk_pulled import NaoWalkPulledScenario
from diagrams.residuals.contact_study import ContactLocalizationScenario
from diagrams.residuals.model_refinement import ModelRefinementScenario
from diagrams.residuals.push_and_comply import PushAndComplyScenario
from diagrams.residuals.residual_comparison import ResidualComparisonScenario
from diagrams.scenarios import scenario_file_text
from diagrams.station.standing import StandingScenario

#: The folder of the scenario files.
SCENARIO_FOLDER = Path(__file__).resolve().parent / "scenarios"

#: Each app's default file: its name and scenario type (the app reads it with ``--scenario``).
DEFAULT_SCENARIOS: dict[str, type] = {
    "standing_default.yaml": StandingScenario,
    "residual_comparison_default.yaml": ResidualComparisonScenario,
    "push_and_comply_default.yaml": PushAndComplyScenario,
    "contact_localization_default.yaml": ContactLocalizationScenario,
    "model_refinement_default.yaml": ModelRefinementScenario,
    "nao_force_observer_default.yaml": NaoForceObserverScenario,
    "nao_walk_default.yaml": NaoWalkScenario,
    "nao_walk_pulled_default.yaml": NaoWalkPulledScenario,
    "nao_force_guided_walk_default.yaml": NaoForceGuidedWalkScenario,
    "nao_compliant_arms_default.yaml": NaoCompliantArmsScenario,
}


def default_file_text(name: str, schema: type | None = None) -> str:
    """The text of the default scenario file ``name`` (of ``DEFAULT_SCENARIOS``)."""
    schema = schema or DEFAULT_SCENARIOS[name]
    header = (
        f"The default scenario of apps.{name.removesuffix('_default.yaml')}: every field of "
        f"{schema.__module__}.{schema.__qualname__} at its default (SI units). Written by "
        "`python -m apps.write_scenarios`; do not edit: copy it, keep the fields you change "
        "and pass it with --scenario FILE (missing fields keep their defaults).\n\n"
        "Drake's configs (plant_config: MultibodyPlantConfig, simulator_config: SimulatorConfig) "
        "list the fields every supported Drake release has."
    )
    return scenario_file_text(schema(), header)


def write_default_scenarios(
    folder: Path = SCENARIO_FOLDER, *, check: bool = False, report: Callable[[str], None] = print
) -> list[str]:
    """Writes (or with ``check`` only compares) every file of ``DEFAULT_SCENARIOS`` in
    ``folder``; returns the names of the files that were missing or differed."""
    changed = []
    for name in DEFAULT_SCENARIOS:
        path = folder / name
        text = default_file_text(name)
        if path.is_file() and path.read_text() == text:
            continue
        changed.append(name)
        if check:
            report(f"{path} differs from its scenario dataclass: run `python -m apps.write_scenarios`")
        else:
            path.write_text(text)
            report(f"wrote {path}")
    return changed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m apps.write_scenarios", description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a file differs")
    args = parser.parse_args(argv)
    changed = write_default_scenarios(check=args.check)
    if not changed:
        print(f"the {len(DEFAULT_SCENARIOS)} default scenario files are up to date")
    return 1 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
