"""The documentation's generated tables (issue 31): each block of README.md, BENCHMARKS.md or a
page of docs/ between ``<!-- results: NAME -->`` and ``<!-- /results: NAME -->`` is the table ``RENDERERS[NAME]``
makes from ``results/<NAME>.json`` (``apps.results``), followed by the command that wrote it.

Run: ``python -m apps.doc_tables`` (``make docs``) rewrites the blocks; ``--check`` only reports
the stale ones (exit 1), as ``tests/test_doc_tables.py`` does.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable
from pathlib import Path

from apps.results import load_results

ROOT = Path(__file__).resolve().parent.parent
#: The documents whose blocks are generated.
DOCUMENTS = (ROOT / "README.md", ROOT / "BENCHMARKS.md", *sorted((ROOT / "docs").glob("*.md")))

_BLOCK = re.compile(r"(<!-- results: (?P<name>[\w.-]+) -->\n)(?P<body>.*?)(<!-- /results: (?P=name) -->)", re.S)


def _deg(value) -> str:
    return "n/a" if value is None else f"{value:.2f} deg"


def _knee(metrics: dict) -> str:
    """The knee flexion of a run that stayed upright; "fell" otherwise (the flexion of a
    robot on the floor says nothing)."""
    return _deg(metrics["knee_pitch_flexion_deg"]) if metrics["upright"] else "fell"


def _yes(value: bool) -> str:
    return "yes" if value else "**no**"


def _push_and_comply_ablation(data: dict) -> list[str]:
    lines = [
        "| world | setting | internal: knee flexion | CoM drop / horizontal travel | upright "
        "| classical: knee flexion | upright |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in data["rows"]:
        i, c = row["internal"], row["classical"]
        lines.append(
            f"| {row['world']} | {row['label']} | {_knee(i)} "
            f"| {100 * i['com_height_drop_m']:.2f} / {100 * i['com_horizontal_travel_m']:.2f} cm "
            f"| {_yes(i['upright'])} | {_knee(c)} | {_yes(c['upright'])} |"
        )
    return lines


def _push_and_comply_robots(data: dict) -> list[str]:
    lines = [
        "| robot (imperfections / sensor seed) | internal: knee flexion | CoM drop | base tilt | upright "
        "| classical: knee flexion | upright | push per shoulder |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in data["rows"]:
        i, c = row["internal"], row["classical"]
        lines.append(
            f"| {row['label']} ({row['robot_seed']} / {row['sensor_seed']}) | {_knee(i)} "
            f"| {100 * i['com_height_drop_m']:.1f} cm | {i['max_base_tilt_deg']:.1f} deg | {_yes(i['upright'])} "
            f"| {_knee(c)} | {_yes(c['upright'])} | {i['push_peak_force_N']:.1f} N |"
        )
    return lines


def _with_interval(metrics: dict, key: str, scale: float, unit: str) -> str:
    """``metrics[key]`` times ``scale`` with its 95 % interval (``metrics["intervals"]``)."""
    value = metrics.get(key)
    if value is None:
        return "n/a"
    interval = metrics.get("intervals", {}).get(key)
    text = f"{scale * value:.1f} {unit}"
    return text + (f" [{scale * interval[0]:.1f}, {scale * interval[1]:.1f}]" if interval else "")


#: The contact study's quoted metrics: (label, key, scale, unit, which studies: 1 or 2 contacts).
CONTACT_STUDY_ROWS = (
    ("detection", "detection_rate", 100.0, "%", (1, 2)),
    ("right link, eq. (22) localizer", "correct_link_rate", 100.0, "%", (1,)),
    ("valid precision, eq. (22) localizer", "valid_precision", 100.0, "%", (1,)),
    ("median position error, eq. (22) localizer", "median_position_error_m", 1000.0, "mm", (1,)),
    ("right link, stacked fit", "fit_correct_link_rate", 100.0, "%", (1,)),
    ("valid precision, stacked fit", "fit_valid_precision", 100.0, "%", (1,)),
    ("median position error, stacked fit", "fit_median_position_error_m", 1000.0, "mm", (1,)),
    ("p95 position error, stacked fit", "fit_p95_position_error_m", 1000.0, "mm", (1,)),
    ('says "more than one contact"', "more_than_one_contact_rate", 100.0, "%", (1, 2)),
    ("both links right", "both_links_right_rate", 100.0, "%", (2,)),
    ("median contact position error", "median_contact_position_error_m", 1000.0, "mm", (2,)),
)


def _floor(text: str | None, scale: float, unit: str) -> str:
    """A metrics file's floor (">= 0.95") in the row's unit (">= 95 %")."""
    if not text:
        return ""
    op, value = text.split()
    return f"{op} {scale * float(value):g} {unit}"


def _contact_study(data: dict) -> list[str]:
    scenario = data.get("scenario", {})
    contacts = scenario.get("contacts", 1)
    seeds = f"{scenario.get('seed')}-{scenario.get('seed', 0) + scenario.get('num_seeds', 1) - 1}"
    lines = [
        f"{data.get('trials')} trials, {'two links pushed at once' if contacts == 2 else 'one contact'} each, "
        f"seeds {seeds}, {'ideal' if scenario.get('model_refinement') == 'none' else 'realistic'} world; "
        f"false detections: {data.get('false_detections')}",
        "",
        "| metric | value [95 % interval] | floor | met |",
        "| --- | --- | --- | --- |",
    ]
    floors, met = data.get("floors", {}), data.get("meets_floors", {})
    for label, key, scale, unit, studies in CONTACT_STUDY_ROWS:
        if contacts not in studies or data.get(key) is None:
            continue
        checked = met.get(key)
        lines.append(
            f"| {label} | {_with_interval(data, key, scale, unit)} | {_floor(floors.get(key), scale, unit)} | "
            f"{'' if checked is None else ('yes' if checked else '**no**')} |"
        )
    return lines


def _paper_speed(data: dict) -> list[str]:
    return [
        f"| one residual update, {data['model']} ({data['num_joints']} joints) | measured | the paper (HRP-4) |",
        "| --- | --- | --- |",
        f"| classical residual, explicit C(q, q_dot) (the paper's way, O(n^2)) "
        f"| {data['classical_explicit_coriolis_ms']:.2f} ms | {data['paper_classical_ms']:.1f} ms |",
        f"| internal residual, recursive Algorithms 1-2 in Python (O(n)) "
        f"| {data['internal_reference_ms']:.2f} ms | {data['paper_internal_ms']:.1f} ms |",
        f"| internal residual, Drake's C++ (the default) | {data['internal_fast_ms']:.3f} ms | |",
        f"| classical residual, the project's (no explicit C) | {data['classical_project_ms']:.3f} ms | |",
        f"| classical (explicit C) / internal, recursive | "
        f"{data['ratio_classical_explicit_over_internal_reference']:.1f}x | {data['paper_ratio']:.1f}x |",
        f"| classical (explicit C) / internal, Drake's C++ | "
        f"{data['ratio_classical_explicit_over_internal_fast']:.1f}x | |",
    ]


def _residual_comparison(data: dict) -> list[str]:
    scenario = data.get("scenario", {})
    world = "ideal" if scenario.get("model_refinement") == "none" else "realistic"
    rows = (
        ("internal residual vs tau_c,real, all joints", "internal_rel_rms_error"),
        ("classical residual (joint part) vs tau_c,real", "classical_rel_rms_error"),
        ("external residual force vs the applied force", "external_force_rel_rms_error"),
    )
    lines = [
        f"| relative RMS error after {data['skip_s']:g} s, {world} world, seed {data['seed']} | raw "
        "| vs the truth through the residual's filter |",
        "| --- | --- | --- |",
    ]
    for label, key in rows:
        lines.append(f"| {label} | {100 * data[key]:.2f} % | {100 * data[key + '_vs_filtered_truth']:.2f} % |")
    return lines


def _nao_force_observer(data: dict) -> list[str]:
    components = ("x", "y", "z")
    lines = [
        "| | "
        + " | ".join(f"RMS {c}" for c in components)
        + " | "
        + " | ".join(f"steady {c}" for c in components)
        + " | overshoot | settling | floors met |",
        "| --- " * 10 + "|",
    ]

    def response(summary: dict) -> str:
        if not summary.get("steps"):
            return "- | -"
        settling = summary.get("mean_settling_time_s")
        settled = "not settled" if settling is None else f"{settling:.2f} s"
        return f"{summary['mean_overshoot_percent']:.1f} % | {settled}"

    for key in sorted(k for k in data if k.startswith("experiment_")):
        m = data[key]
        if m.get("fell"):
            lines.append(f"| experiment {key.split('_')[1]} | fell | | | | | | | | no |")
            continue
        rms = " | ".join(f"{m['rms_error_N'][c]:.3f} N" for c in components)
        steady = " | ".join(f"{m['steady_state_error_N'][c]:.3f} N" for c in components)
        step = response(m["step_response"]) if "step_response" in m else "- | -"
        lines.append(f"| experiment {key.split('_')[1]} | {rms} | {steady} | {step} | {_yes(m['meets_floors'])} |")
    if "recordings_step_response" in data:
        real = data["recordings_step_response"]["summary"]
        lines.append(f"| real recordings (authors' observer) | | | | | | | {response(real)} | |")
    return lines


#: NAME -> the table's lines from the results file's ``data``.
RENDERERS: dict[str, Callable[[dict], list[str]]] = {
    "push_and_comply_ablation": _push_and_comply_ablation,
    "push_and_comply_robots": _push_and_comply_robots,
    "paper_speed": _paper_speed,
    "residual_comparison_realistic": _residual_comparison,
    "residual_comparison_ideal": _residual_comparison,
    "contact_study_single": _contact_study,
    "contact_study_two": _contact_study,
    "nao_force_observer": _nao_force_observer,
    "nao_force_observer_paper": _nao_force_observer,
    "nao_force_observer_steps_wide": _nao_force_observer,
}


def _release(drake) -> str:
    """Drake's release as written by ``write_results`` ("1.58.0"; a list in older files)."""
    return ".".join(map(str, drake)) if isinstance(drake, list) else str(drake)


def render(name: str, folder: Path | None = None) -> str:
    """The block body of ``name``: its table, then the command and date of its results file.

    Raises:
        ValueError: no renderer for ``name``, or its results file cannot be read.
    """
    if name not in RENDERERS:
        raise ValueError(f"no table is generated under the name {name!r}; known: {sorted(RENDERERS)}")
    payload = load_results(name, folder)
    lines = RENDERERS[name](payload["data"])
    lines += [
        "",
        f"Measured by `{payload['command']}` on {payload['written']} (Python {payload['python']}, "
        f"Drake {_release(payload['drake'])}; `results/{name}.json`).",
    ]
    return "\n".join(lines) + "\n"


def updated(text: str, folder: Path | None = None) -> tuple[str, list[str]]:
    """``text`` with every block regenerated, and the names of the blocks that changed."""
    changed = []

    def replace(match: re.Match) -> str:
        body = render(match["name"], folder)
        if body != match["body"]:
            changed.append(match["name"])
        return match.group(1) + body + match.group(4)

    return _BLOCK.sub(replace, text), changed


def block_names(text: str) -> list[str]:
    """The names of the generated blocks in ``text``."""
    return [m["name"] for m in _BLOCK.finditer(text)]


def main(argv: list[str] | None = None) -> int:
    """Rewrites (or with ``--check`` reports) the stale blocks; exit 2 with a one-line
    message when a results file is missing or unreadable, before any document is written."""
    from apps.runner import run_app

    parser = argparse.ArgumentParser(prog="python -m apps.doc_tables", description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="report stale blocks (exit 1), change nothing")
    args = parser.parse_args(argv)

    def body() -> int:
        stale, rewritten = [], {}
        for path in DOCUMENTS:
            text, changed = updated(path.read_text())
            stale += [f"{path.relative_to(ROOT)}: {name}" for name in changed]
            if changed:
                rewritten[path] = text
        if not args.check:
            for path, text in rewritten.items():
                path.write_text(text)
        verb = "stale" if args.check else "rewritten"
        print("\n".join(f"{verb}: {s}" for s in stale) if stale else "every generated table is up to date")
        return 1 if (stale and args.check) else 0

    return run_app("doc_tables", body)


if __name__ == "__main__":
    raise SystemExit(main())
