"""The documentation's figures (issue 34): each figure of ``FIGURES`` is drawn with matplotlib
from committed results files only (``results/<name>.json``, read by ``apps.results``, as the
generated tables are), into ``docs/_generated/figures/<NAME>.png`` (generated, not tracked).

A page shows a figure in its block between ``<!-- figure: NAME -->`` and ``<!-- /figure: NAME -->``:
a MyST ``{figure}`` directive whose caption says what the figure shows and names each results
file it is drawn from and the command that wrote it (date, Python, Drake), regenerated here as
``apps.doc_tables`` regenerates the tables. No number in a figure is typed: the plotted values
are those ``figure_data`` takes from the files, the floors those the files record (the
push-and-comply floors: ``diagrams.residuals.push_and_comply``, as the tables give them).

Run: ``python -m apps.doc_figures`` (``make docs``, before Sphinx) draws every figure and
rewrites the stale blocks; ``--out DIR`` draws into DIR and ``--results DIR`` reads the
results files from DIR (neither rewrites a page); ``--check`` only reports the stale blocks
(exit 1), as ``tests/test_doc_figures.py`` does.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from apps.results import generated_block_pattern, load_results, provenance, regenerated_blocks, stale_documents

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
#: Where ``make docs`` draws the figures; the pages' blocks point there.
FIGURES_DIR = DOCS / "_generated" / "figures"
#: The documents that may show a figure (each only in a generated block).
DOCUMENTS = (ROOT / "README.md", ROOT / "BENCHMARKS.md", *sorted(DOCS.glob("*.md")))
#: The resolution of every figure (the apps' plots use the same).
DPI = 110

_BLOCK = generated_block_pattern("figure")


@dataclass(frozen=True)
class Figure:
    """One figure: its file ``<name>.png``, the page that shows it, the results files it is
    drawn from, what its caption says it shows, its alt text, the function that takes the
    plotted values from the files ({file name: its ``data``} -> plain values) and the one that
    draws them on a matplotlib figure."""

    name: str
    page: str
    sources: tuple[str, ...]
    caption: str
    alt: str
    extract: Callable[[dict[str, dict]], dict]
    draw: Callable[[dict, object], None]
    size: tuple[float, float] = (10.0, 4.8)


# ---------------------------------------------------------------------------------------------
# Shared pieces


def _floor(text: str | None) -> tuple[str, float] | None:
    """A results file's floor (">= 0.95") as (operator, value); None without one."""
    if not text:
        return None
    op, value = text.split()
    return op, float(value)


def _percent(value: float | None) -> float | None:
    return None if value is None else 100.0 * value


def _bar_labels(ax, bars, values, fmt: str, missing: str | list[str] = "n/a", **kwargs) -> None:
    """Each bar's value at its end (``fmt``), or ``missing`` (one text, or one per bar) where
    the value is missing (its bar drawn with no length)."""
    missing = [missing] * len(values) if isinstance(missing, str) else missing
    labels = [text if v is None else fmt.format(v) for v, text in zip(values, missing)]
    ax.bar_label(bars, labels=labels, fontsize=7, **kwargs)


def _lengths(values: list) -> list[float]:
    """Bar lengths: a missing value (None) gets none, and its label says why."""
    return [0.0 if v is None else v for v in values]


def _points(values: list) -> list[float]:
    """Plotted points: a missing value (None) is not drawn."""
    return [np.nan if v is None else v for v in values]


def _legend_below(fig, ax, ncol: int) -> None:
    """The legend of ``ax``'s artists under the figure, off the data."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize=8)


# ---------------------------------------------------------------------------------------------
# The contact study (docs/contact-study.md)


def _contact_regions_data(sources: dict[str, dict]) -> dict:
    data = sources["contact_study_single"]
    rows = data["per_region"]
    floors = data.get("floors", {})
    return {
        "regions": [row["region"] for row in rows],
        "trials": [row["trials"] for row in rows],
        "right_link_eq22_percent": [_percent(row["correct_link_rate"]) for row in rows],
        "right_link_fit_percent": [_percent(row.get("fit_correct_link_rate")) for row in rows],
        "position_error_eq22_mm": [1000.0 * row["median_position_error_m"] for row in rows],
        "position_error_fit_mm": [
            None if row.get("fit_median_position_error_m") is None else 1000.0 * row["fit_median_position_error_m"]
            for row in rows
        ],
        "floor_right_link_eq22": _floor(floors.get("correct_link_rate")),
        "floor_right_link_fit": _floor(floors.get("fit_correct_link_rate")),
        "floor_position_error_eq22": _floor(floors.get("median_position_error_m")),
        "floor_position_error_fit": _floor(floors.get("fit_median_position_error_m")),
    }


def _draw_contact_regions(d: dict, fig) -> None:
    rate_ax, error_ax = fig.subplots(1, 2)
    x = np.arange(len(d["regions"]))
    width = 0.38
    ticks = [f"{region}\n({trials} trials)" for region, trials in zip(d["regions"], d["trials"])]
    for ax, keys, unit, title in (
        (rate_ax, ("right_link_eq22_percent", "right_link_fit_percent"), "%", "right link"),
        (error_ax, ("position_error_eq22_mm", "position_error_fit_mm"), "mm", "median position error"),
    ):
        for offset, key, label, color in (
            (-width / 2, keys[0], "eq. (22) localizer", "C0"),
            (width / 2, keys[1], "stacked fit", "C2"),
        ):
            values = d[key]
            bars = ax.bar(x + offset, _lengths(values), width, label=label, color=color)
            _bar_labels(ax, bars, values, "{:.1f}")
        ax.set_xticks(x, ticks)
        ax.set_ylabel(f"{title} ({unit})")
        ax.set_title(title + " per body region")
    for ax, floors, scale in (
        (rate_ax, ("floor_right_link_eq22", "floor_right_link_fit"), 100.0),
        (error_ax, ("floor_position_error_eq22", "floor_position_error_fit"), 1000.0),
    ):
        shown = {d[key] for key in floors if d[key] is not None}
        for op, value in sorted(shown):
            unit = "%" if ax is rate_ax else "mm"
            label = f"floor on all trials: {op} {scale * value:g} {unit}"
            ax.axhline(scale * value, color="k", ls="--", lw=1, label=label)
    rate_ax.set_ylim(0, 110)
    error_ax.set_ylim(0, 1.25 * max(v for v in error_ax.get_ylim()))
    rate_ax.legend(loc="lower left", fontsize=8)
    error_ax.legend(loc="upper left", fontsize=8)


# ---------------------------------------------------------------------------------------------
# Push and comply (docs/push-and-comply.md, docs/robots.md)


def _knee_rows(rows: list[dict], label: Callable[[dict], str], floors: bool) -> dict:
    from diagrams.residuals.push_and_comply import meets_robot_floors

    def knee(metrics: dict) -> float | None:
        return metrics["knee_pitch_flexion_deg"] if metrics["upright"] else None

    return {
        "labels": [label(row) for row in rows],
        "internal_knee_deg": [knee(row["internal"]) for row in rows],
        "classical_knee_deg": [knee(row["classical"]) for row in rows],
        "floors_met": [meets_robot_floors(row["internal"], row["classical"]) for row in rows] if floors else None,
    }


def _draw_knees(ax, d: dict, *, floors: bool) -> None:
    """Horizontal bars: the knee flexion of the internal and the classical run of each row;
    "fell" where the run did not stay upright; the floors as vertical lines. No legend (the
    caller puts one under the figure)."""
    from diagrams.residuals.push_and_comply import FLOOR_CLASSICAL_KNEE_DEG, FLOOR_INTERNAL_KNEE_DEG

    y = np.arange(len(d["labels"]))
    height = 0.38
    for offset, key, label, color in (
        (-height / 2, "internal_knee_deg", "internal residual", "C0"),
        (height / 2, "classical_knee_deg", "classical residual", "C1"),
    ):
        values = d[key]
        bars = ax.barh(y + offset, _lengths(values), height, label=label, color=color)
        _bar_labels(ax, bars, values, "{:.2f}", missing="fell", padding=2)
    labels = d["labels"]
    if floors and d.get("floors_met") is not None:
        labels = [text + ("" if met else "\n(floors not met)") for text, met in zip(labels, d["floors_met"])]
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("knee flexion, the smaller knee (deg)")
    if floors:
        label = f"floor: internal run >= {FLOOR_INTERNAL_KNEE_DEG:g} deg"
        ax.axvline(FLOOR_INTERNAL_KNEE_DEG, color="C0", ls="--", lw=1, label=label)
        label = f"floor: classical run < {FLOOR_CLASSICAL_KNEE_DEG:g} deg"
        ax.axvline(FLOOR_CLASSICAL_KNEE_DEG, color="C1", ls=":", lw=1.2, label=label)
    ax.set_xlim(0, 1.15 * ax.get_xlim()[1])


def _ablation_data(sources: dict[str, dict]) -> dict:
    rows = sources["push_and_comply_ablation"]["rows"]
    worlds = list(dict.fromkeys(row["world"] for row in rows))
    return {
        "worlds": worlds,
        "per_world": [
            _knee_rows([row for row in rows if row["world"] == world], lambda row: row["label"], floors=False)
            for world in worlds
        ],
    }


def _draw_ablation(d: dict, fig) -> None:
    axes = np.atleast_1d(fig.subplots(1, len(d["worlds"]), sharex=True))
    for ax, world, rows in zip(axes, d["worlds"], d["per_world"]):
        _draw_knees(ax, rows, floors=False)
        ax.set_title(f"{world} world")
    for ax in axes[1:]:
        if ax.get_yticklabels() and [t.get_text() for t in ax.get_yticklabels()] == [
            t.get_text() for t in axes[0].get_yticklabels()
        ]:
            ax.tick_params(labelleft=False)
    _legend_below(fig, axes[0], ncol=2)


def _robots_data(sources: dict[str, dict]) -> dict:
    rows = sources["push_and_comply_robots"]["rows"]
    return _knee_rows(rows, lambda row: f"{row['label']} ({row['robot_seed']} / {row['sensor_seed']})", floors=True)


def _sensing_knees_data(sources: dict[str, dict]) -> dict:
    rows = sources["push_and_comply_sensing"]["rows"]
    return _knee_rows(rows, lambda row: f"{row['label']}, {row['world']} world", floors=True)


def _draw_robot_knees(d: dict, fig) -> None:
    ax = fig.subplots()
    _draw_knees(ax, d, floors=True)
    _legend_below(fig, ax, ncol=2)


# ---------------------------------------------------------------------------------------------
# The residual comparison (docs/residuals.md)

#: The residual comparison per foot sensing (hrp4_like, realistic world): (results file, label),
#: the runs of ``apps.doc_tables.RESIDUAL_SENSING_RUNS``.
RESIDUAL_SENSING_RUNS = (
    ("residual_comparison_realistic", "foot F/T sensors"),
    ("residual_comparison_realistic_fsr", "FSRs"),
    ("residual_comparison_realistic_no_ft", "no foot sensing"),
)


def _residual_joints_data(sources: dict[str, dict]) -> dict:
    data = sources["residual_comparison_realistic"]
    joints = list(data["internal_rel_rms_error_per_joint"])
    return {
        "joints": joints,
        "true_effort_Nm": [data["rms_true_joint_effort_Nm"][j] for j in joints],
        "classical_effort_Nm": [data["rms_classical_joint_effort_Nm"][j] for j in joints],
        "internal_noise_Nm": [data["rms_internal_noise_before_push_Nm"][j] for j in joints],
        "internal_percent": [100.0 * data["internal_rel_rms_error_per_joint"][j] for j in joints],
        "classical_percent": [100.0 * data["classical_rel_rms_error_per_joint"][j] for j in joints],
        "skip_s": data["skip_s"],
    }


def _draw_residual_joints(d: dict, fig) -> None:
    effort_ax, error_ax = fig.subplots(2, 1, sharex=True)
    x = np.arange(len(d["joints"]))
    effort_ax.semilogy(x, d["true_effort_Nm"], "o", color="k", ms=4, label="true effort of the push (eq. 12)")
    effort_ax.semilogy(x, d["classical_effort_Nm"], "s", color="C1", ms=4, label="classical residual, joint part")
    label = "internal residual's noise at rest (before the push)"
    effort_ax.semilogy(x, _points(d["internal_noise_Nm"]), "_", color="C0", ms=9, mew=1.5, label=label)
    effort_ax.set_ylabel("RMS (N m)")
    effort_ax.set_title(
        "per joint: the push's effort, what the classical residual sees, the internal one's noise", pad=24
    )
    effort_ax.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, frameon=False)
    error_ax.semilogy(x, d["internal_percent"], "o", color="C0", ms=4, label="internal residual")
    error_ax.semilogy(x, d["classical_percent"], "s", color="C1", ms=4, label="classical residual (joint part)")
    error_ax.set_ylabel(f"relative RMS error\nafter {d['skip_s']:g} s (%)")
    error_ax.set_title("per joint: relative RMS error against the true effort", pad=24)
    error_ax.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2, frameon=False)
    error_ax.set_xticks(x, d["joints"], rotation=90, fontsize=7)
    for ax in (effort_ax, error_ax):
        ax.grid(True, which="major", axis="y", alpha=0.3)


def _residual_sensing_data(sources: dict[str, dict]) -> dict:
    joints = list(sources[RESIDUAL_SENSING_RUNS[0][0]]["internal_rel_rms_error_per_joint"])
    return {
        "joints": joints,
        "runs": [label for _, label in RESIDUAL_SENSING_RUNS],
        "internal_percent": [
            [100.0 * sources[name]["internal_rel_rms_error_per_joint"][j] for j in joints]
            for name, _ in RESIDUAL_SENSING_RUNS
        ],
    }


def _draw_residual_sensing(d: dict, fig) -> None:
    ax = fig.subplots()
    x = np.arange(len(d["joints"]))
    for k, (label, values, marker) in enumerate(zip(d["runs"], d["internal_percent"], ("o", "^", "s"))):
        ax.semilogy(x + 0.2 * (k - 1), values, marker, ms=4, color=f"C{k}", label=label, ls="none")
    ax.set_xticks(x, d["joints"], rotation=90, fontsize=7)
    ax.set_ylabel("internal residual: relative RMS error (%)")
    ax.set_title("internal residual per joint against the true effort, by foot sensing (realistic world)", pad=24)
    ax.grid(True, which="major", axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, frameon=False)


# ---------------------------------------------------------------------------------------------
# The Nao force observer (docs/nao-force-observer.md)

#: The three settings of ``make hawley-settings``: (results file, label).
HAWLEY_SETTINGS = (
    ("nao_force_observer_paper", "the paper's setting (steps)"),
    ("nao_force_observer_steps_wide", "steps, wider stance"),
    ("nao_force_observer", "the project's default (ramps)"),
)
_COMPONENTS = ("x", "y", "z")


def _experiments(data: dict) -> list[str]:
    return sorted(key for key in data if key.startswith("experiment_"))


def _nao_windows_data(sources: dict[str, dict]) -> dict:
    data = sources["nao_force_observer"]
    experiments = []
    for key in _experiments(data):
        m = data[key]
        windows = m.get("steady_state_windows", [])
        experiments.append(
            {
                "title": m["title"],
                "fell": m.get("fell", False),
                "windows_s": [w["window_s"] for w in windows],
                "expected_N": [w["expected_N"] for w in windows],
                "estimate_N": [w["estimate_N"] for w in windows],
                "error_N": [w["error_N"] for w in windows],
                "floor_steady_state_N": m.get("floors_N", {}).get("steady_state"),
            }
        )
    return {"experiments": experiments}


def _draw_nao_windows(d: dict, fig) -> None:
    experiments = d["experiments"]
    axes = fig.subplots(2, len(experiments), squeeze=False, sharex="col")
    for column, e in enumerate(experiments):
        top, bottom = axes[0, column], axes[1, column]
        x = np.arange(len(e["windows_s"]))
        for k, component in enumerate(_COMPONENTS):
            offset = 0.22 * (k - 1)
            expected = [v[k] for v in e["expected_N"]]
            estimate = [v[k] for v in e["estimate_N"]]
            error = [v[k] for v in e["error_N"]]
            top.plot(x + offset, expected, "o", mfc="none", color=f"C{k}", ms=7, label=f"expected {component}")
            top.plot(x + offset, estimate, "x", color=f"C{k}", ms=6, label=f"estimate {component}")
            bottom.bar(x + offset, error, 0.2, color=f"C{k}", label=component)
        floor = e["floor_steady_state_N"]
        if floor is not None:
            bottom.axhspan(-floor, floor, color="0.9", zorder=0, label=f"floor: |error| <= {floor:g} N")
            largest = max((abs(v) for window in e["error_N"] for v in window), default=0.0)
            bottom.set_ylim(-max(1.3 * floor, 1.1 * largest), max(1.3 * floor, 1.1 * largest))
        top.set_title(e["title"].replace(": ", ":\n", 1) + (" (fell)" if e["fell"] else ""), fontsize=9)
        top.axhline(0.0, color="0.6", lw=0.5)
        bottom.axhline(0.0, color="0.6", lw=0.5)
        bottom.set_xticks(x, [f"{a:g}-{b:g} s" for a, b in e["windows_s"]], fontsize=8, rotation=30)
        bottom.set_xlabel("steady-state window")
    axes[0, 0].set_ylabel("virtual force (N)")
    axes[1, 0].set_ylabel("estimate - expected (N)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    floors = [(h, text) for h, text in zip(*axes[1, 0].get_legend_handles_labels()) if text.startswith("floor")]
    handles += [h for h, _ in floors[:1]]
    labels += [text for _, text in floors[:1]]
    fig.legend(handles, labels, loc="outside lower center", ncol=7, fontsize=8)


def _nao_settings_data(sources: dict[str, dict]) -> dict:
    experiments = _experiments(sources[HAWLEY_SETTINGS[-1][0]])
    settings = []
    for name, label in HAWLEY_SETTINGS:
        data = sources[name]
        overshoot, settling = [], []
        for key in experiments:
            m = data.get(key, {})
            step = m.get("step_response", {}) if not m.get("fell") else {}
            overshoot.append(step.get("mean_overshoot_percent") if step.get("steps") else None)
            settling.append(step.get("mean_settling_time_s") if step.get("steps") else None)
        settings.append(
            {
                "label": label,
                "fell": [bool(data.get(key, {}).get("fell")) for key in experiments],
                "overshoot_percent": overshoot,
                "settling_s": settling,
            }
        )
    real = sources[HAWLEY_SETTINGS[-1][0]].get("recordings_step_response", {}).get("summary", {})
    return {
        "experiments": [f"experiment {key.split('_')[1]}" for key in experiments],
        "settings": settings,
        "recordings_overshoot_percent": real.get("mean_overshoot_percent"),
        "recordings_settling_s": real.get("mean_settling_time_s"),
    }


def _draw_nao_settings(d: dict, fig) -> None:
    overshoot_ax, settling_ax = fig.subplots(1, 2)
    x = np.arange(len(d["experiments"]))
    width = 0.8 / len(d["settings"])
    for k, setting in enumerate(d["settings"]):
        offset = width * (k - (len(d["settings"]) - 1) / 2)
        for ax, key, fmt in ((overshoot_ax, "overshoot_percent", "{:.1f}"), (settling_ax, "settling_s", "{:.2f}")):
            values = setting[key]
            bars = ax.bar(x + offset, _lengths(values), width, color=f"C{k}", label=setting["label"])
            missing = ["fell" if fell else "not settled" for fell in setting["fell"]]
            _bar_labels(ax, bars, values, fmt, missing=missing, rotation=90, padding=2)
    for ax, key, unit in (
        (overshoot_ax, "recordings_overshoot_percent", "%"),
        (settling_ax, "recordings_settling_s", "s"),
    ):
        if d[key] is not None:
            ax.axhline(
                d[key], color="k", ls="--", lw=1, label=f"real recordings, authors' observer ({d[key]:.2f} {unit})"
            )
        ax.set_xticks(x, d["experiments"])
        ax.set_ylim(0, 1.35 * ax.get_ylim()[1])
    overshoot_ax.set_ylabel("mean overshoot past the settled level (%)")
    overshoot_ax.set_title("overshoot of the estimate")
    settling_ax.set_ylabel("mean time to stay within 10 % of the change (s)")
    settling_ax.set_title("settling time of the estimate")
    overshoot_ax.legend(fontsize=7, loc="upper left")
    settling_ax.legend(fontsize=7, loc="upper left")


# ---------------------------------------------------------------------------------------------
# Foot sensing (docs/robots.md)

#: The contact study per foot sensing: (results file, label), the studies of
#: ``apps.doc_tables.SENSING_STUDIES``.
SENSING_STUDIES = (
    ("contact_study_sensing_ft", "hrp4_like, F/T, ideal"),
    ("contact_study_sensing_fsr", "hrp4_like, FSR, ideal"),
    ("contact_study_sensing_fsr_realistic", "hrp4_like, FSR, realistic"),
    ("contact_study_sensing_none", "hrp4_like, none, ideal"),
    ("contact_study_sensing_none_realistic", "hrp4_like, none, realistic"),
    ("contact_study_sensing_none_talos", "TALOS, none, ideal"),
)


def _sensing_regions_data(sources: dict[str, dict]) -> dict:
    regions = [row["region"] for row in sources[SENSING_STUDIES[0][0]]["per_region"]]
    studies = []
    for name, label in SENSING_STUDIES:
        data = sources[name]
        rows = {row["region"]: row for row in data["per_region"]}
        floors = data.get("floors", {})
        studies.append(
            {
                "label": label,
                "eq22_percent": [_percent(rows[r]["correct_link_rate"]) for r in regions],
                "fit_percent": [_percent(rows[r].get("fit_correct_link_rate")) for r in regions],
                "eq22_floor": [_floor(floors.get(f"correct_link_rate_{r}")) for r in regions],
                "fit_floor": [_floor(floors.get(f"fit_correct_link_rate_{r}")) for r in regions],
            }
        )
    return {"regions": regions, "studies": studies}


def _draw_sensing_regions(d: dict, fig) -> None:
    axes = fig.subplots(1, 2, sharey=True)
    x = np.arange(len(d["regions"]))
    n = len(d["studies"])
    width = 0.8 / n
    for ax, key, title in ((axes[0], "eq22", "eq. (22) localizer"), (axes[1], "fit", "stacked fit")):
        floor_drawn = False
        for k, study in enumerate(d["studies"]):
            offset = width * (k - (n - 1) / 2)
            values = study[f"{key}_percent"]
            bars = ax.bar(x + offset, _lengths(values), width, color=f"C{k}", label=study["label"])
            _bar_labels(ax, bars, values, "{:.0f}", padding=1)
            for i, floor in enumerate(study[f"{key}_floor"]):
                if floor is not None:
                    ends = [x[i] + offset - width / 2, x[i] + offset + width / 2]
                    label = None if floor_drawn else "the study's floor for the region"
                    ax.plot(ends, [100 * floor[1]] * 2, color="k", lw=1.5, label=label)
                    floor_drawn = True
        ax.set_xticks(x, d["regions"])
        ax.set_title(f"right link, {title}")
        ax.set_ylim(0, 112)
    axes[0].set_ylabel("right link, per body region (%)")
    _legend_below(fig, axes[0], ncol=4)


# ---------------------------------------------------------------------------------------------
# Sweeps (docs/sweeps.md)


def _robot_name(robot: str) -> str:
    return Path(robot).stem if robot.endswith((".yaml", ".yml")) else robot


def _sweep_data(sources: dict[str, dict]) -> dict:
    cells = sources["sweep_small"]["cells"]
    return {
        "robots": [_robot_name(cell["robot"]) for cell in cells],
        "labels": [f"draw {cell['imperfection_seed']}\nnoise x{cell['noise_scale']:g}" for cell in cells],
        "right_link_percent": [100.0 * cell["right_link_rate"] for cell in cells],
        "right_link_interval_percent": [[100.0 * v for v in cell["right_link_rate_interval"]] for cell in cells],
        "position_error_cm": [100.0 * cell["median_position_error_m"] for cell in cells],
        "position_error_interval_cm": [[100.0 * v for v in cell["median_position_error_m_interval"]] for cell in cells],
        "trials": [cell["trials"] for cell in cells],
    }


def _draw_sweep(d: dict, fig) -> None:
    rate_ax, error_ax = fig.subplots(2, 1, sharex=True)
    x = np.arange(len(d["labels"]))
    robots = list(dict.fromkeys(d["robots"]))
    for ax, key, interval_key, unit in (
        (rate_ax, "right_link_percent", "right_link_interval_percent", "right link (%)"),
        (error_ax, "position_error_cm", "position_error_interval_cm", "median position error (cm)"),
    ):
        values, interval = np.array(d[key]), np.array(d[interval_key])
        for k, robot in enumerate(robots):
            mine = np.array([r == robot for r in d["robots"]])
            below, above = values[mine] - interval[mine, 0], interval[mine, 1] - values[mine]
            ax.errorbar(x[mine], values[mine], yerr=[below, above], fmt="o", color=f"C{k}", capsize=3, label=robot)
        ax.set_ylabel(unit)
        ax.grid(True, axis="y", alpha=0.3)
    rate_ax.set_title(f"each cell of the grid ({d['trials'][0]} trials each): value and 95 % interval")
    rate_ax.legend(fontsize=8, loc="lower left")
    error_ax.set_xticks(x, d["labels"], fontsize=7)


def _engine_scaling_data(sources: dict[str, dict]) -> dict:
    data = sources["engine_scaling"]
    runs = list(data["runs"].values())
    return {
        "runs": [f"{run['engine']}, {run['workers']} worker{'s' if run['workers'] > 1 else ''}" for run in runs],
        "wall_time_s": [run["wall_time_s"] for run in runs],
        "simulations_s": [run.get("phase_wall_s", {}).get("simulations") for run in runs],
        "trials": data["trials"],
        "model_nodes": [row["nodes"] for row in data["model"]],
        "model_wall_h": [row["wall_s"] / 3600.0 for row in data["model"]],
        "model_calibration_h": [row["calibration_phase_s"] / 3600.0 for row in data["model"]],
        "model_trials_h": [row["trial_phase_s"] / 3600.0 for row in data["model"]],
        "model_trials": data["model"][0]["trials"] if data["model"] else None,
    }


def _draw_engine_scaling(d: dict, fig) -> None:
    runs_ax, model_ax = fig.subplots(1, 2)
    x = np.arange(len(d["runs"]))
    bars = runs_ax.bar(x - 0.2, d["wall_time_s"], 0.4, color="C0", label="wall time")
    _bar_labels(runs_ax, bars, d["wall_time_s"], "{:.0f} s")
    bars = runs_ax.bar(x + 0.2, _lengths(d["simulations_s"]), 0.4, color="C2", label="of which the simulations")
    _bar_labels(runs_ax, bars, d["simulations_s"], "{:.0f} s")
    runs_ax.set_xticks(x, d["runs"])
    runs_ax.set_ylabel("time (s)")
    runs_ax.set_title(f"the same {d['trials']}-trial contact study, measured")
    runs_ax.set_ylim(0, 1.15 * runs_ax.get_ylim()[1])
    runs_ax.legend(fontsize=8, loc="upper left")
    model_ax.loglog(d["model_nodes"], d["model_wall_h"], "o-", color="k", label="wall time")
    model_ax.loglog(d["model_nodes"], d["model_trials_h"], "s--", color="C2", label="the trials")
    model_ax.loglog(d["model_nodes"], d["model_calibration_h"], "^:", color="C1", label="the calibrations")
    model_ax.set_xticks(d["model_nodes"], [str(n) for n in d["model_nodes"]])
    model_ax.minorticks_off()
    model_ax.set_xlabel("nodes of this machine's size")
    model_ax.set_ylabel("time (h)")
    model_ax.set_title(f"the model: a sweep of {d['model_trials']} trials")
    model_ax.grid(True, which="major", alpha=0.3)
    model_ax.legend(fontsize=8)


# ---------------------------------------------------------------------------------------------

#: Every figure of the documentation, in the order of the pages.
FIGURES: tuple[Figure, ...] = (
    Figure(
        "contact_study_regions",
        "contact-study.md",
        ("contact_study_single",),
        "The single-contact study per body region: the share of pushes put on the right link and the median "
        "position error, with the eq. (22) localizer and the stacked fit; dashed, the study's floors, which "
        "apply to all trials together.",
        "Bar charts of the right-link rate and the median position error per body region",
        _contact_regions_data,
        _draw_contact_regions,
    ),
    Figure(
        "push_and_comply_ablation",
        "push-and-comply.md",
        ("push_and_comply_ablation",),
        "Knee flexion of the internal and the classical run in the paper's setting and with each of the "
        'project\'s changes added, in both worlds; "fell": the run did not stay upright.',
        "Bar charts of the knee flexion per setting, ideal and realistic world",
        _ablation_data,
        _draw_ablation,
        (11.0, 5.2),
    ),
    Figure(
        "push_and_comply_robots",
        "push-and-comply.md",
        ("push_and_comply_robots",),
        "Knee flexion of the internal and the classical run on each robot, with issue 31's floors.",
        "Bar chart of the knee flexion per robot, internal and classical residual",
        _robots_data,
        _draw_robot_knees,
        (9.0, 5.6),
    ),
    Figure(
        "residual_comparison_per_joint",
        "residuals.md",
        ("residual_comparison_realistic",),
        "The realistic-world run per joint: above, the push's true effort, the classical residual's joint part "
        "and the internal residual's noise at rest (RMS); below, each residual's relative RMS error against "
        "the true effort (log scales).",
        "Per-joint RMS efforts and relative errors of the internal and the classical residual",
        _residual_joints_data,
        _draw_residual_joints,
        (11.0, 7.0),
    ),
    Figure(
        "residual_comparison_sensing",
        "residuals.md",
        tuple(name for name, _ in RESIDUAL_SENSING_RUNS),
        "The internal residual's relative RMS error per joint against the true effort, with foot F/T sensors, "
        "FSRs and no foot sensing (log scale).",
        "Per-joint relative error of the internal residual for three kinds of foot sensing",
        _residual_sensing_data,
        _draw_residual_sensing,
        (11.0, 4.8),
    ),
    Figure(
        "nao_force_observer_windows",
        "nao-force-observer.md",
        ("nao_force_observer",),
        "The project's default setting: the observer's estimate against the expected virtual force in each "
        "steady-state window, per component (above), and their difference with the steady-state floor (below).",
        "Expected and estimated virtual force per steady-state window, and their difference",
        _nao_windows_data,
        _draw_nao_windows,
        (11.0, 6.4),
    ),
    Figure(
        "nao_force_observer_settings",
        "nao-force-observer.md",
        tuple(name for name, _ in HAWLEY_SETTINGS),
        "The estimate's mean overshoot and settling time in each experiment, in the three settings of "
        "`make hawley-settings`, against the authors' observer on their real recordings (dashed).",
        "Bar charts of the overshoot and settling time per experiment and setting",
        _nao_settings_data,
        _draw_nao_settings,
        (11.0, 5.0),
    ),
    Figure(
        "contact_study_sensing",
        "robots.md",
        tuple(name for name, _ in SENSING_STUDIES),
        "The contact study per foot sensing: the share of pushes put on the right link per body region, with "
        "the eq. (22) localizer and the stacked fit; black ticks, each study's floor for the region where its "
        "results file has one.",
        "Bar charts of the right-link rate per body region for each foot sensing",
        _sensing_regions_data,
        _draw_sensing_regions,
        (11.0, 5.0),
    ),
    Figure(
        "push_and_comply_sensing",
        "robots.md",
        ("push_and_comply_sensing",),
        "Knee flexion of the internal and the classical run per robot, foot sensing and world, with the floors "
        "of issues 31 and 36.",
        "Bar chart of the knee flexion per robot and foot sensing",
        _sensing_knees_data,
        _draw_robot_knees,
        (9.0, 5.2),
    ),
    Figure(
        "sweep_small",
        "sweeps.md",
        ("sweep_small",),
        "Each cell of the small grid: the right-link rate and the median position error with their 95 % "
        "intervals, per robot, imperfection draw and noise level.",
        "Right-link rate and median position error with intervals per grid cell",
        _sweep_data,
        _draw_sweep,
        (10.0, 6.0),
    ),
    Figure(
        "engine_scaling",
        "sweeps.md",
        ("engine_scaling",),
        "Left, the same study's wall time on each engine and the part its simulations took; right, the "
        "modelled wall time of the issue-sized sweep on N nodes and its two phases (log scales).",
        "Measured wall time per engine and modelled wall time against the number of nodes",
        _engine_scaling_data,
        _draw_engine_scaling,
    ),
)
_BY_NAME = {figure.name: figure for figure in FIGURES}


def figure(name: str) -> Figure:
    """The figure ``name``.

    Raises:
        ValueError: no figure has that name.
    """
    if name not in _BY_NAME:
        raise ValueError(f"no figure is drawn under the name {name!r}; known: {sorted(_BY_NAME)}")
    return _BY_NAME[name]


def _payloads(name: str, folder: Path | None) -> dict[str, dict]:
    return {source: load_results(source, folder) for source in figure(name).sources}


def figure_data(name: str, folder: Path | None = None) -> dict:
    """The values the figure ``name`` plots, taken from its results files (in ``folder``;
    default: ``apps.results``'s)."""
    return figure(name).extract({source: payload["data"] for source, payload in _payloads(name, folder).items()})


def render(name: str, out_dir: Path = FIGURES_DIR, folder: Path | None = None) -> Path:
    """Draws the figure ``name`` from its results files into ``out_dir/<name>.png``."""
    from matplotlib.figure import Figure as MatplotlibFigure

    spec = figure(name)
    values = figure_data(name, folder)
    fig = MatplotlibFigure(figsize=spec.size, layout="constrained")
    spec.draw(values, fig)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{name}.png"
    temporary = path.with_suffix(".tmp.png")
    fig.savefig(temporary, dpi=DPI, metadata={"Software": None})
    temporary.replace(path)
    return path


def render_all(out_dir: Path = FIGURES_DIR, folder: Path | None = None) -> list[Path]:
    """Draws every figure of ``FIGURES`` into ``out_dir``."""
    return [render(spec.name, out_dir, folder) for spec in FIGURES]


def block(name: str, folder: Path | None = None) -> str:
    """The body of the page's block ``name``: the MyST figure, its caption naming the results
    files and the commands that wrote them."""
    spec = figure(name)
    payloads = _payloads(name, folder)
    lines = [
        f"```{{figure}} {FIGURES_DIR.relative_to(DOCS).as_posix()}/{name}.png",
        f":alt: {spec.alt}",
        ":width: 100%",
        "",
    ]
    if len(payloads) == 1:
        ((source, payload),) = payloads.items()
        lines.append(f"{spec.caption} {provenance('Drawn from a results file measured by', source, payload)}.")
    else:
        lines += [f"{spec.caption} Drawn from results files measured by:", ""]
        lines += [provenance("-", source, payload) for source, payload in payloads.items()]
    return "\n".join(lines + ["```"]) + "\n"


def updated(text: str, folder: Path | None = None) -> tuple[str, list[str]]:
    """``text`` with every figure block regenerated, and the names of the blocks that changed."""
    return regenerated_blocks(_BLOCK, text, lambda name: block(name, folder))


def block_names(text: str) -> list[str]:
    """The names of the figure blocks in ``text``."""
    return [m["name"] for m in _BLOCK.finditer(text)]


def main(argv: list[str] | None = None) -> int:
    """Draws every figure and rewrites the stale blocks (or with ``--check`` reports them);
    exit 2 with a one-line message when a results file is missing or unreadable."""
    from apps.runner import run_app

    parser = argparse.ArgumentParser(prog="python -m apps.doc_figures", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help=f"draw the figures into OUT (default {FIGURES_DIR.relative_to(ROOT)})")
    parser.add_argument("--results", type=Path, help="read the results files from RESULTS (default results/)")
    parser.add_argument("--check", action="store_true", help="report stale figure blocks (exit 1), draw nothing")
    args = parser.parse_args(argv)

    def body() -> int:
        stale, rewritten = stale_documents(DOCUMENTS, lambda text: updated(text, args.results), ROOT)
        if args.check:
            print("\n".join(f"stale: {s}" for s in stale) if stale else "every figure block is up to date")
            return 1 if stale else 0
        paths = render_all(args.out or FIGURES_DIR, args.results)
        print(f"{len(paths)} figures drawn into {paths[0].parent}")
        if args.out is None and args.results is None:
            for path, text in rewritten.items():
                path.write_text(text)
            print("\n".join(f"rewritten: {s}" for s in stale) if stale else "every figure block is up to date")
        return 0

    return run_app("doc_figures", body)


if __name__ == "__main__":
    raise SystemExit(main())
