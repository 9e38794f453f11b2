"""A sweep of the contact study over robots, imperfections, noise and pushes, on Ray (issue 35).

The grid (``diagrams.residuals.contact_sweep.SweepGrid``, a YAML file) names robot
descriptions, imperfection draws and model-mismatch magnitudes, sensor noise levels,
contacts per trial, push durations and the force range, and the trials per cell. Each cell
is the contact study (``apps.contact_localization``) of one combination: its realistic world
calibrates the cell's own model first (one job per cell), then its trials run in chunks
from one standing start (one job per chunk), on the workers of ``apps.engine``: Ray actors
on this machine by default, a Ray cluster with ``--cluster ADDRESS``, or a process pool.

Nothing is lost: each chunk's rows are written as one Parquet file as soon as it finishes
(a temporary file renamed into place), and each calibration likewise; ``--resume`` skips
the chunks and calibrations already written (the grid must be the one the folder was
started with). A killed Ray worker is restarted and its job retried; a killed driver loses
the chunks in flight. The same grid gives the same rows bit for bit on any engine and any
number of workers (but for the columns ``RUN_COLUMNS``: wall times and the worker's name).

Run: ``python -m apps.sweep --grid FILE [--grid-text YAML] [--print-grid] [--resume]
[--engine auto|local|pool|ray] [--workers N] [--cluster ADDRESS] [--out DIR] [--results NAME]``.
Writes to ``DIR/sweep/``: ``grid.yaml`` (every field), ``trials/`` (the per-trial Parquet
dataset: one row per trial, every input and every result; read it with
``pyarrow.parquet.read_table``), ``calibrations/`` (each cell's refined model),
``summary.json`` and ``summary.csv`` (per cell: the right-link and detection rates and the
position and force errors, with 95 % intervals, and the calibrated model's total mass
against the robot's), ``runs.json`` (each invocation's engine and times; the summary adds
them up) and ``sweep.png`` (the right-link rate and
the median position error against the mismatch and the noise, one line per robot).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
import tempfile
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyarrow as pa

from apps.engine import add_engine_arguments, engine_from_args, open_engine
from apps.results import app_command, write_results
from apps.runner import DEFAULT_OUT, calibration_cache_folder, json_text, print_written, results_name, run_app
from diagrams.residuals.contact_study import sample_study_trials
from diagrams.residuals.contact_sweep import (
    SUMMARY_KEYS,
    SweepCell,
    SweepGrid,
    calibrate_cell,
    calibrated_mass,
    cell_needs_calibration,
    cell_scenario,
    cell_summary,
    chunks,
    grid_as_yaml,
    read_trials,
    robot_mass,
    run_chunk,
    sweep_cells,
    write_atomically,
    write_chunk,
)
from diagrams.scenarios import load_scenario, scenario_as_yaml
from systems.estimation.base_state_estimator import load_compiled_filter_steps


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m apps.sweep", description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--grid", type=Path, default=None, metavar="FILE", help="the grid (YAML, SweepGrid's fields)")
    parser.add_argument("--grid-text", default=None, metavar="YAML", help="YAML overrides applied after --grid")
    parser.add_argument("--print-grid", action="store_true", help="print the grid (every field) and exit")
    parser.add_argument(
        "--resume", action="store_true", help="go on with the sweep in the output folder (skip what it holds)"
    )
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, metavar="DIR", help="writes DIR/sweep/ (default out/)")
    parser.add_argument(
        "--no-progress", action="store_true", help="no progress bar (a line per finished chunk instead)"
    )
    parser.add_argument(
        "--results", type=results_name, default=None, metavar="NAME", help="also write the summary to results/NAME.json"
    )
    add_engine_arguments(parser)
    return parser.parse_args(argv)


def load_grid(args: argparse.Namespace) -> SweepGrid:
    """The grid of ``--grid`` and ``--grid-text``, validated."""
    return load_scenario(SweepGrid, filename=args.grid, text=args.grid_text).validate()


def _prepare_folder(folder: Path, grid_text: str, resume: bool) -> None:
    """Creates ``folder`` (and its ``trials``, ``calibrations``) or checks that it can be
    resumed: a sweep folder is never overwritten.

    Raises:
        ValueError: the folder holds another sweep (or, without --resume, any sweep), or it
            cannot be written.
    """
    grid_file = folder / "grid.yaml"
    if grid_file.exists():
        if not resume:
            raise ValueError(f"{folder} holds a sweep already: --resume to go on with it, or another --out")
        if grid_file.read_text() != grid_text:
            raise ValueError(f"--resume: {grid_file} is another grid than this one (start a new --out)")
    elif resume and (folder / "trials").is_dir():
        raise ValueError(f"--resume: {folder} has trials but no grid.yaml")
    try:
        for sub in ("trials", "calibrations"):
            (folder / sub).mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=folder, prefix=".write-test.", delete=True)
        probe.close()
    except OSError as error:
        raise ValueError(f"--out: cannot write {folder}: {error.strerror or error}") from None
    if not grid_file.exists():
        write_atomically(grid_file, grid_text.encode())


def _log_run(folder: Path, run: dict) -> list[dict]:
    """Appends ``run`` (one invocation's engine, workers and times) to ``folder/runs.json``
    (atomically) and returns every run of the sweep."""
    path = folder / "runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else []
    runs.append(run)
    write_atomically(path, json_text(runs).encode())
    return runs


class _Progress:
    """Trials done, rate, ETA and the running right-link rate (tqdm; or a line per chunk)."""

    def __init__(self, total: int, done: int, right: int, bar: bool):
        self.total, self.done, self.right = total, done, right
        self.started = time.perf_counter()
        self.at_start = done
        self._bar = None
        if bar:
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, unit="trial", dynamic_ncols=True, file=sys.stderr)
            self._bar.set_postfix_str(self._rate())

    def _rate(self) -> str:
        rate = 100.0 * self.right / self.done if self.done else float("nan")
        return f"right link {rate:.1f} %"

    def add(self, rows: list[dict]) -> None:
        self.done += len(rows)
        self.right += sum(r["detected"] and r["link_among_pushed"] for r in rows)
        if self._bar is not None:
            self._bar.set_postfix_str(self._rate(), refresh=False)
            self._bar.update(len(rows))
        else:
            elapsed = time.perf_counter() - self.started
            speed = (self.done - self.at_start) / elapsed if elapsed > 0 else 0.0
            eta = (self.total - self.done) / speed if speed > 0 else float("inf")
            print(f"{self.done}/{self.total} trials, {speed:.2f} trials/s, ETA {eta:.0f} s, {self._rate()}", flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def run_sweep(grid: SweepGrid, folder: Path, engine, *, progress: bool = True, cache: Path | None = None) -> dict:
    """Runs what ``folder`` lacks of the sweep ``grid`` on ``engine`` (``apps.engine``) and
    returns the timings: wall time of the calibrations and of the trials, s, and the trials
    and chunks run now."""
    cells = sweep_cells(grid)
    scenarios = {cell.key: cell_scenario(grid, cell) for cell in cells}
    texts = {key: scenario_as_yaml(s) for key, s in scenarios.items()}
    cache = cache if cache is not None else folder / "calibration_cache"
    # Calibrations: one job per cell whose world calibrates, unless the folder holds it.
    calibrations: dict[str, bytes | None] = {}
    jobs = []
    for cell in cells:
        path = folder / "calibrations" / f"cell-{cell.key}.npz"
        if not cell_needs_calibration(scenarios[cell.key]):
            calibrations[cell.key] = None
        elif path.is_file():
            calibrations[cell.key] = path.read_bytes()
        else:
            jobs.append((cell.key, texts[cell.key], str(cache)))
    start = time.perf_counter()
    if jobs:
        print(f"calibrating {len(jobs)} cell(s) on {engine.kind} ({engine.workers} worker(s))", flush=True)
    for done, (key, data) in enumerate(engine.imap_unordered(calibrate_cell, jobs), 1):
        write_atomically(folder / "calibrations" / f"cell-{key}.npz", data)
        calibrations[key] = data
        print(f"  {done}/{len(jobs)} calibrations done", flush=True)
    calibration_s = time.perf_counter() - start
    # Trials: one job per chunk not yet written.
    specs_by_draw: dict[tuple, list[dict]] = {}
    jobs, total = [], 0
    finished = read_trials(folder)
    finished_chunks = {(c, k) for c, k in zip(finished["cell"].to_pylist(), finished["chunk"].to_pylist())}
    done_trials = finished.num_rows
    flags = zip(finished["detected"].to_pylist(), finished["link_among_pushed"].to_pylist())
    done_right = sum(detected and right for detected, right in flags)
    for cell in cells:
        scenario = scenarios[cell.key]
        draw = (cell.robot, cell.contacts, grid.trials_per_cell, grid.seed, grid.num_seeds, tuple(grid.force_range))
        if draw not in specs_by_draw:
            specs_by_draw[draw] = sample_study_trials(scenario)
        for k, chunk in enumerate(chunks(specs_by_draw[draw], grid.trials_per_job)):
            total += len(chunk)
            if (cell.key, k) not in finished_chunks:
                fields = {f: getattr(cell, f) for f in SweepCell.__dataclass_fields__}
                jobs.append((fields, k, chunk, texts[cell.key], calibrations[cell.key]))
    print(
        f"{len(cells)} cell(s), {total} trials: {len(jobs)} chunk(s) to run"
        f" ({done_trials} trials already done) on {engine.kind} ({engine.workers} worker(s))",
        flush=True,
    )
    bar = _Progress(total, done_trials, done_right, progress)
    start = time.perf_counter()
    ran = 0
    try:
        for key, chunk, rows in engine.imap_unordered(run_chunk, jobs):
            write_chunk(folder, key, chunk, rows)
            ran += len(rows)
            bar.add(rows)
    finally:
        bar.close()
    return {
        "calibration_wall_s": calibration_s,
        "trials_wall_s": time.perf_counter() - start,
        "trials_run": ran,
        "chunks_run": len(jobs),
    }


def summarize(grid: SweepGrid, table: pa.Table, folder: Path | None = None) -> list[dict]:
    """Per cell (grid order): the cell's values and ``cell_summary`` of its rows; with the
    sweep's ``folder``, the calibrated model's total mass and the robot's, kg (a cell whose
    calibration misreads the weight sees it as a standing external force)."""
    rows = table.to_pylist()
    masses = {robot: robot_mass(robot) for robot in grid.robots} if folder is not None else {}
    by_cell: dict[str, list[dict]] = {}
    for row in rows:
        by_cell.setdefault(row["cell"], []).append(row)
    out = []
    for cell in sweep_cells(grid):
        cell_rows = by_cell.get(cell.key, [])
        entry = cell.as_row()
        entry.update(cell_summary(cell_rows) if cell_rows else {"trials": 0})
        calibration = folder / "calibrations" / f"cell-{cell.key}.npz" if folder is not None else None
        if calibration is not None:
            entry["robot_mass_kg"] = masses[cell.robot]
            entry["calibrated_mass_kg"] = calibrated_mass(calibration.read_bytes()) if calibration.is_file() else None
        out.append(entry)
    return out


def _csv_text(summary: list[dict]) -> str:
    columns = [
        "cell",
        "robot",
        "imperfection_seed",
        "mismatch_scale",
        "noise_scale",
        "contacts",
        "push_duration_s",
        *SUMMARY_KEYS,
        "calibrated_mass_kg",
        "robot_mass_kg",
    ]
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    header = []
    for c in columns:
        header.append(c)
        if c in SUMMARY_KEYS and c != "trials":
            header += [f"{c}_low", f"{c}_high"]
    writer.writerow(header)
    for entry in summary:
        line = []
        for c in columns:
            line.append(entry.get(c))
            if c in SUMMARY_KEYS and c != "trials":
                interval = entry.get(f"{c}_interval") or [None, None]
                line += interval
        writer.writerow(line)
    return buffer.getvalue()


def pooled(table_rows: list[dict], robot: str, axis: str, value: float) -> dict | None:
    """``cell_summary`` of every row of ``robot`` whose ``axis`` is ``value`` (the other
    axes pooled), or None."""
    rows = [r for r in table_rows if r["robot"] == robot and r[axis] == value]
    return cell_summary(rows) if rows else None


def plot_sweep(path: Path, grid: SweepGrid, table: pa.Table) -> None:
    """The right-link rate and the median position error against the mismatch scale and
    the noise scale, one line per robot (the other axes pooled), with 95 % intervals."""
    rows = table.to_pylist()
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    for column, (axis, label) in enumerate(
        (("mismatch_scale", "model mismatch (x realistic)"), ("noise_scale", "sensor noise (x default)"))
    ):
        values = sorted(getattr(grid, f"{axis}s"))
        for robot in grid.robots:
            stats = [pooled(rows, robot, axis, v) for v in values]
            xs = [v for v, s in zip(values, stats) if s]
            kept = [s for s in stats if s]
            if not kept:
                continue
            name = Path(robot).stem
            rate = np.array([100 * s["right_link_rate"] for s in kept])
            rate_ci = 100 * np.array([s["right_link_rate_interval"] for s in kept])
            axes[0, column].errorbar(
                xs, rate, yerr=[rate - rate_ci[:, 0], rate_ci[:, 1] - rate], marker="o", capsize=3, label=name
            )
            error = np.array([100 * s["median_position_error_m"] for s in kept])
            error_ci = np.array([[100 * v for v in s["median_position_error_m_interval"]] for s in kept])
            error_ci = np.where(np.isfinite(error_ci), error_ci, np.nan)
            axes[1, column].errorbar(
                xs,
                error,
                yerr=[np.nan_to_num(error - error_ci[:, 0]), np.nan_to_num(error_ci[:, 1] - error)],
                marker="o",
                capsize=3,
                label=name,
            )
        axes[0, column].set_ylabel("right-link rate [%]")
        axes[1, column].set_ylabel("median position error [cm]")
        axes[1, column].set_xlabel(label)
        axes[0, column].set_title(f"against the {label.split(' (')[0]}")
        for ax in axes[:, column]:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.suptitle(f"Contact study sweep, {grid.world} world: {table.num_rows} trials (95 % intervals)")
    fig.tight_layout()
    sink = io.BytesIO()
    fig.savefig(sink, format="png", dpi=100)
    plt.close(fig)
    write_atomically(path, sink.getvalue())


def _print_summary(summary: list[dict]) -> None:
    print(
        f"{'robot':>14s} {'imp':>3s} {'mism':>5s} {'noise':>5s} {'c':>1s} {'dur':>4s} {'n':>5s}"
        f" {'right link [%] (95 % CI)':>26s} {'median pos. err [cm] (95 % CI)':>32s} {'mass: model/robot [kg]':>23s}"
    )
    for e in summary:
        if not e["trials"]:
            continue
        low, high = e["right_link_rate_interval"]
        mlow, mhigh = e["median_position_error_m_interval"]
        print(
            f"{Path(e['robot']).stem:>14s} {e['imperfection_seed']:3d} {e['mismatch_scale']:5.2f}"
            f" {e['noise_scale']:5.2f} {e['contacts']:1d} {e['push_duration_s']:4.2f} {e['trials']:5d}"
            f" {100 * e['right_link_rate']:8.1f} [{100 * low:5.1f}, {100 * high:5.1f}]"
            f" {100 * e['median_position_error_m']:12.2f} [{100 * mlow:5.2f}, {100 * mhigh:6.2f}]"
            f" {_mass_text(e):>23s}"
        )


def _mass_text(entry: dict) -> str:
    if entry.get("calibrated_mass_kg") is None:
        return "-"
    return f"{entry['calibrated_mass_kg']:.2f}/{entry['robot_mass_kg']:.2f}"


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        if args.grid is None and args.grid_text is None and not args.print_grid:
            raise ValueError("give the grid: --grid FILE (e.g. apps/scenarios/sweep_small.yaml) or --grid-text YAML")
        grid = load_grid(args)
        grid_text = grid_as_yaml(grid)
        if args.print_grid:
            print(grid_text, end="")
            return 0
        choice = engine_from_args(args)
        folder = Path(args.out) / "sweep"
        _prepare_folder(folder, grid_text, args.resume)
        load_compiled_filter_steps()
        start = time.perf_counter()
        with open_engine(choice, initializer=load_compiled_filter_steps) as engine:
            timings = run_sweep(
                grid, folder, engine, progress=not args.no_progress, cache=calibration_cache_folder(args)
            )
            workers = engine.workers
        this_run = {"engine": choice.kind, "workers": workers, "wall_time_s": time.perf_counter() - start, **timings}
        runs = _log_run(folder, this_run)
        table = read_trials(folder)
        summary = summarize(grid, table, folder)
        expected = len(sweep_cells(grid)) * grid.trials_per_cell
        # The figures of the whole sweep: its runs' times added up (a resumed sweep's too).
        report = {
            "grid": grid_text,
            "engine": choice.kind,
            "workers": workers,
            "cluster": choice.cluster,
            "trials": table.num_rows,
            "trials_expected": expected,
            **{key: sum(r[key] for r in runs) for key in ("wall_time_s", "calibration_wall_s", "trials_wall_s")},
            "runs": runs,
            "cells": summary,
        }
        write_atomically(folder / "summary.json", json_text(report).encode())
        write_atomically(folder / "summary.csv", _csv_text(summary).encode())
        plot_sweep(folder / "sweep.png", grid, table)
        _print_summary(summary)
        print(
            f"{table.num_rows} of {expected} trials; this run: {timings['trials_run']} trials in"
            f" {timings['trials_wall_s']:.1f} s, calibrations {timings['calibration_wall_s']:.1f} s,"
            f" on {choice.kind} with {workers} worker(s)"
        )
        print_written(folder)
        if args.results and table.num_rows == expected:
            command = app_command("apps.sweep", argv)
            print(f"wrote {write_results(args.results, report, command=command)}")
        if table.num_rows != expected:
            print(f"sweep: the folder holds {table.num_rows} trials, not {expected}: run again with --resume")
            return 1
        return 0

    return run_app("sweep", body)


if __name__ == "__main__":
    raise SystemExit(main())
