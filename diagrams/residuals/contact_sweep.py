"""A sweep of the contact study (Flacco et al. 2016, Secs. V-VI) over robots, model mismatch,
sensor noise and pushes (issue 35): the grid, its cells, one table row per trial, and the
summary per cell with 95 % intervals. ``apps.sweep`` runs it on any engine.

A cell is one combination of the grid's axes: a robot description, an imperfection draw
(``Imperfections.seed``: which links are heavier, which sensors are off), a model-mismatch
magnitude (a factor on the base scenario's mass, CoM and inertia percentages), a sensor noise
level (``noise_scale``: a factor on every noise std), contacts per trial and a push
duration. Each cell is a ``ContactLocalizationScenario`` (the grid's ``base`` with these
fields set) with ``trials_per_cell`` random contacts drawn from the grid's seeds: the same
pushes in every cell of one robot (common random numbers, so that a difference between two
noise levels is the noise's, not the draw's). The cell's realistic world calibrates its own
model (``model_refinement: calibrate``), with its own sensors.

The trials of a cell are run in chunks of ``trials_per_job`` from one standing start
(``diagrams.residuals.contact_study.trials.run_trials``); a trial's result depends on its chunk
(the noise of the start is the chunk's), never on the engine or the number of workers.
"""

import dataclasses
import hashlib
import io
import itertools
import math
import os
import socket
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from diagrams.residuals.contact_study import (
    MAX_FORCE,
    MIN_FORCE,
    ContactLocalizationScenario,
    check_force_range,
    run_trials,
)
from diagrams.residuals.model_refinement import calibration_file, refined_model
from diagrams.residuals.study_statistics import (
    CONFIDENCE_LEVEL,
    percentile_with_inf,
    proportion_interval,
    quantile_interval,
)
from diagrams.scenarios import check_finite_and_signs, load_scenario, scenario_as_yaml

#: ``SweepGrid.world`` values.
WORLDS = ("realistic", "ideal")


@dataclass
class SweepGrid:
    """The sweep's axes and its fixed settings. SI units.

    Attributes:
        robots: robot descriptions (``hrp4_like``, or a description file such as
            ``models/robots/talos.yaml``), each with foot F/T sensors.
        imperfection_seeds: the imperfection draws (``Imperfections.seed``).
        mismatch_scales: factors on the base scenario's model mismatch (mass, CoM and
            inertia percentages; 1: the realistic 5 %, 10 %, 10 %).
        noise_scales: factors on every sensor noise std (1: the defaults).
        contacts: contacts per trial, each 1 or 2.
        push_durations: push durations, s.
        force_range: the push magnitudes are drawn uniformly in [min, max], N.
        trials_per_cell: random contacts per cell.
        trials_per_job: trials a worker simulates from one standing start (a chunk; the
            unit of work, of progress and of resuming).
        seed: the first seed the trials are drawn from (also the sensor noise's).
        num_seeds: the trials of a cell come from seeds seed ... seed + num_seeds - 1.
        world: "realistic" (the EKF's base state, the imperfections, a calibrated model) or
            "ideal" (``StationConfig.in_world``: no imperfection, no calibration; the
            imperfection axes then change nothing but the cell's name).
        base: the contact study's scenario every cell starts from (its model, trials,
            seeds, contacts, push duration, force range and noise scale are the cell's;
            its runs without contact are not run).
    """

    robots: list[str] = field(default_factory=lambda: ["hrp4_like"])
    imperfection_seeds: list[int] = field(default_factory=lambda: [0])
    mismatch_scales: list[float] = field(default_factory=lambda: [1.0])
    noise_scales: list[float] = field(default_factory=lambda: [1.0])
    contacts: list[int] = field(default_factory=lambda: [1])
    push_durations: list[float] = field(default_factory=lambda: [0.5])
    force_range: list[float] = field(default_factory=lambda: [MIN_FORCE, MAX_FORCE])
    trials_per_cell: int = 50
    trials_per_job: int = 10
    seed: int = 7000
    num_seeds: int = 1
    world: str = "realistic"
    base: ContactLocalizationScenario = field(default_factory=ContactLocalizationScenario)

    def validate(self) -> "SweepGrid":
        """Returns self; raises ValueError naming the field for an empty axis, a repeated
        value, a negative scale or seed, contacts other than 1 or 2, a non-positive push
        duration, a bad force range, trials < 1 or an unknown world."""
        check_finite_and_signs(self)
        for name in ("robots", "imperfection_seeds", "mismatch_scales", "noise_scales", "contacts", "push_durations"):
            values = getattr(self, name)
            if not values:
                raise ValueError(f"grid.{name} must name at least one value")
            if len(set(values)) != len(values):
                raise ValueError(f"grid.{name} repeats a value: {values}")
        for value in self.imperfection_seeds:
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"grid.imperfection_seeds must hold non-negative integers, got {value!r}")
        for name in ("mismatch_scales", "noise_scales"):
            for value in getattr(self, name):
                if not value >= 0.0:
                    raise ValueError(f"grid.{name} must hold numbers >= 0, got {value!r}")
        for value in self.contacts:
            if value not in (1, 2):
                raise ValueError(f"grid.contacts must hold 1 or 2, got {value!r}")
        for value in self.push_durations:
            if not value > 0.0:
                raise ValueError(f"grid.push_durations must hold durations > 0 s, got {value!r}")
        try:
            check_force_range(self.force_range)
        except ValueError as error:
            raise ValueError(f"grid.{error}") from None
        for name in ("trials_per_cell", "trials_per_job", "num_seeds"):
            if getattr(self, name) < 1:
                raise ValueError(f"grid.{name} must be >= 1, got {getattr(self, name)}")
        if self.trials_per_cell < self.num_seeds:
            raise ValueError(f"grid.trials_per_cell ({self.trials_per_cell}) must be >= num_seeds ({self.num_seeds})")
        if self.world not in WORLDS:
            raise ValueError(f"grid.world must be one of {WORLDS}, got {self.world!r}")
        return self


@dataclass(frozen=True)
class SweepCell:
    """One combination of the grid's axes (``SweepGrid``); ``key``: its name in the files."""

    robot: str
    imperfection_seed: int
    mismatch_scale: float
    noise_scale: float
    contacts: int
    push_duration: float

    @property
    def key(self) -> str:
        """A short, stable name: a hash of the cell's values."""
        text = repr(dataclasses.astuple(self))
        return hashlib.sha1(text.encode()).hexdigest()[:12]

    def as_row(self) -> dict:
        return {
            "cell": self.key,
            "robot": self.robot,
            "imperfection_seed": self.imperfection_seed,
            "mismatch_scale": self.mismatch_scale,
            "noise_scale": self.noise_scale,
            "contacts": self.contacts,
            "push_duration_s": self.push_duration,
        }


def sweep_cells(grid: SweepGrid) -> list[SweepCell]:
    """Every cell of the grid, robots outermost (the order of the tables)."""
    axes = (
        grid.robots,
        grid.imperfection_seeds,
        grid.mismatch_scales,
        grid.noise_scales,
        grid.contacts,
        grid.push_durations,
    )
    return [
        SweepCell(robot, int(seed), float(mismatch), float(noise), int(contacts), float(duration))
        for robot, seed, mismatch, noise, contacts, duration in itertools.product(*axes)
    ]


def cell_scenario(grid: SweepGrid, cell: SweepCell) -> ContactLocalizationScenario:
    """The contact study of one cell (module docstring)."""
    base = grid.base
    mismatch = base.station.imperfections.model_mismatch
    imperfections = dataclasses.replace(
        base.station.imperfections,
        seed=cell.imperfection_seed,
        model_mismatch=dataclasses.replace(
            mismatch,
            mass_percent=mismatch.mass_percent * cell.mismatch_scale,
            com_percent=mismatch.com_percent * cell.mismatch_scale,
            inertia_percent=mismatch.inertia_percent * cell.mismatch_scale,
        ),
    )
    station = dataclasses.replace(
        base.station, model=cell.robot, seed=grid.seed, noise_scale=cell.noise_scale, imperfections=imperfections
    )
    scenario = dataclasses.replace(
        base,
        station=station.in_world("ideal") if grid.world == "ideal" else station,
        trials=grid.trials_per_cell,
        num_seeds=grid.num_seeds,
        contacts=cell.contacts,
        multi_contact=False,
        push_duration=cell.push_duration,
        force_range=list(grid.force_range),
        no_contact_duration=0.0,
        slow_motion_duration=0.0,
        trials_per_run=1,
    )
    return scenario


def cell_needs_calibration(scenario: ContactLocalizationScenario) -> bool:
    """The cell's world calibrates its model (``model_refinement: calibrate``)."""
    return scenario.station.model_refinement == "calibrate"


def chunks(specs: Sequence[dict], size: int) -> list[list[dict]]:
    """The trial specs in chunks of ``size`` (the last one shorter)."""
    return [list(specs[i : i + size]) for i in range(0, len(specs), size)]


#: The per-trial table's columns that measure time or name where a trial ran: they differ
#: between runs of the same trials; every other column is the same bit for bit.
RUN_COLUMNS = ("simulation_wall_s", "localizer_update_s", "worker")


def trial_row(cell: SweepCell, chunk: int, result: dict) -> dict:
    """One row of the per-trial table: the cell's values, the trial's push and its results
    (``trial_result``), flat (vectors as lists, absent values None)."""
    contacts = result.get("contacts", [result])
    force = np.asarray(result["force_world"], dtype=float)
    row = {
        **cell.as_row(),
        "chunk": int(chunk),
        "trial": int(result["trial"]),
        "seed": int(result["seed"]),
        "trial_of_seed": int(result["trial_of_seed"]),
        "body": result["body"],
        "bodies": [c["body"] for c in contacts],
        "geometry": result["geometry"],
        "force_N": float(np.linalg.norm(force)),
        "force_world": [float(f) for f in force],
        "point_body": [float(p) for p in result["point_body"]],
        "detected": bool(result["detected"]),
        "detection_delay_s": _optional(result["detection_delay_s"]),
        "detector_on_at_push_start": bool(result["detector_on_at_push_start"]),
        "false_detections_before_push": int(result["false_detections_before_push"]),
        "status": str(result["status"]),
        "estimated_body": result["estimated_body"],
        "correct_link": bool(result["correct_link"]),
        # The localized link is the pushed one (``same_link``: or welded to it), or one of two.
        "link_among_pushed": bool(result["correct_link"]) or result["estimated_body"] in {c["body"] for c in contacts},
        "position_error_m": _optional(result["position_error_m"]),
        "force_error_rel": _optional(result["force_error_rel"]),
        "angle_error_deg": _optional(result["angle_error_deg"]),
        "sole_slip_m": float(result["sole_slip_m"]),
        "sole_slipped": bool(result["sole_slipped"]),
        "simulation_wall_s": float(result["simulation_wall_s"]),
        "localizer_update_s": float(result["localizer_update_s"]),
        "worker": str(result.get("worker", "")),
    }
    return row


def _optional(value) -> float | None:
    return None if value is None else float(value)


#: Per cell, the summary's figures (with 95 % intervals where a rate or a quantile).
SUMMARY_KEYS = (
    "trials",
    "detection_rate",
    "right_link_rate",
    "median_position_error_m",
    "p95_position_error_m",
    "median_force_error_rel",
)


def cell_summary(rows: Iterable[dict], level: float = CONFIDENCE_LEVEL) -> dict:
    """The figures of one cell's trial rows: ``trials``, ``detection_rate`` and
    ``right_link_rate`` (the localized link is a pushed one; an undetected trial counts as
    wrong) with Clopper-Pearson intervals, the median and 95th percentile of the position
    error (m; a trial without a localization counts as an infinite error) and the median
    relative force error of the detected trials, with order-statistics intervals."""
    rows = list(rows)
    n = len(rows)
    if n == 0:
        raise ValueError("cell_summary needs at least one trial")
    detected = sum(r["detected"] for r in rows)
    right = sum(r["detected"] and r["link_among_pushed"] for r in rows)
    errors = [math.inf if r["position_error_m"] is None else r["position_error_m"] for r in rows]
    forces = [r["force_error_rel"] for r in rows if r["force_error_rel"] is not None]
    out = {
        "trials": n,
        "detection_rate": detected / n,
        "detection_rate_interval": list(proportion_interval(detected, n, level)),
        "right_link_rate": right / n,
        "right_link_rate_interval": list(proportion_interval(right, n, level)),
        "median_position_error_m": percentile_with_inf(errors, 50),
        "median_position_error_m_interval": list(quantile_interval(errors, 0.5, level)),
        "p95_position_error_m": percentile_with_inf(errors, 95),
        "p95_position_error_m_interval": list(quantile_interval(errors, 0.95, level)),
        "median_force_error_rel": float(np.median(forces)) if forces else None,
        "median_force_error_rel_interval": list(quantile_interval(forces, 0.5, level)) if forces else None,
    }
    return out


def grid_as_yaml(grid: SweepGrid) -> str:
    """The grid as YAML text (every field: the file ``apps.sweep`` writes and resumes from)."""
    return scenario_as_yaml(grid)


# ---------------------------------------------------------------------------------------
# The sweep's files: one Parquet file per finished chunk.
# ---------------------------------------------------------------------------------------


#: The per-trial table's schema (``trial_row``): fixed, so that every chunk's file has the
#: same types whatever values it happens to hold (a chunk without a localization included).
ROW_SCHEMA = pa.schema(
    [
        ("cell", pa.string()),
        ("robot", pa.string()),
        ("imperfection_seed", pa.int64()),
        ("mismatch_scale", pa.float64()),
        ("noise_scale", pa.float64()),
        ("contacts", pa.int64()),
        ("push_duration_s", pa.float64()),
        ("chunk", pa.int64()),
        ("trial", pa.int64()),
        ("seed", pa.int64()),
        ("trial_of_seed", pa.int64()),
        ("body", pa.string()),
        ("bodies", pa.list_(pa.string())),
        ("geometry", pa.string()),
        ("force_N", pa.float64()),
        ("force_world", pa.list_(pa.float64())),
        ("point_body", pa.list_(pa.float64())),
        ("detected", pa.bool_()),
        ("detection_delay_s", pa.float64()),
        ("detector_on_at_push_start", pa.bool_()),
        ("false_detections_before_push", pa.int64()),
        ("status", pa.string()),
        ("estimated_body", pa.string()),
        ("correct_link", pa.bool_()),
        ("link_among_pushed", pa.bool_()),
        ("position_error_m", pa.float64()),
        ("force_error_rel", pa.float64()),
        ("angle_error_deg", pa.float64()),
        ("sole_slip_m", pa.float64()),
        ("sole_slipped", pa.bool_()),
        ("simulation_wall_s", pa.float64()),
        ("localizer_update_s", pa.float64()),
        ("worker", pa.string()),
    ]
)


def write_atomically(path: Path, data: bytes) -> None:
    """Writes ``data`` to ``path`` through a temporary file in the same folder."""
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as file:
            file.write(data)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def chunk_file(folder: Path, cell_key: str, chunk: int) -> Path:
    """The Parquet file of one finished chunk."""
    return folder / "trials" / f"cell-{cell_key}_chunk-{chunk:05d}.parquet"


def write_chunk(folder: Path, cell_key: str, chunk: int, rows: list[dict]) -> Path:
    """Writes a chunk's rows (atomically) and returns the file."""
    sink = io.BytesIO()
    pq.write_table(pa.Table.from_pylist(rows, schema=ROW_SCHEMA), sink)
    path = chunk_file(folder, cell_key, chunk)
    write_atomically(path, sink.getvalue())
    return path


def read_trials(folder: Path) -> pa.Table:
    """Every finished chunk's rows in ``folder/trials`` (sorted by cell order of the files,
    then trial)."""
    files = sorted((folder / "trials").glob("cell-*_chunk-*.parquet"))
    if not files:
        return ROW_SCHEMA.empty_table()
    return pa.concat_tables([pq.read_table(f, schema=ROW_SCHEMA) for f in files])


# ---------------------------------------------------------------------------------------
# The jobs a worker runs (``apps.engine``): plain data in, plain data out.
# ---------------------------------------------------------------------------------------


def calibrate_cell(job: tuple[str, str, str]) -> tuple[str, bytes]:
    """Worker: the refined model of one cell (``refined_model``, cached in the worker's
    ``cache_folder``). ``job``: (cell key, the cell's scenario as YAML, cache folder).
    Returns the key and the corrections file's bytes (the driver keeps them and sends them
    with the cell's trials, so a worker on another machine needs no shared disk)."""
    key, scenario_yaml, cache_folder = job
    scenario = load_scenario(ContactLocalizationScenario, text=scenario_yaml)
    path = calibration_file(scenario, Path(cache_folder))
    refined_model(scenario, Path(cache_folder))
    return key, path.read_bytes()


def run_chunk(job: tuple[dict, int, list[dict], str, bytes | None]) -> tuple[str, int, list[dict]]:
    """Worker: one chunk of a cell's trials (``run_trials``). ``job``: (the cell's
    ``SweepCell`` fields, the chunk's index, its trial specs, the cell's scenario as YAML,
    its calibration's bytes or None). Returns the cell's key, the chunk and its rows
    (``trial_row``)."""
    cell_fields, chunk, specs, scenario_yaml, calibration = job
    cell = SweepCell(**cell_fields)
    scenario = load_scenario(ContactLocalizationScenario, text=scenario_yaml)
    if calibration is not None:
        scenario.station.model_refinement = str(_calibration_path(calibration))
    worker = f"{socket.gethostname()}:{os.getpid()}"
    results = run_trials([dict(s) for s in specs], scenario)
    return cell.key, chunk, [trial_row(cell, chunk, {**r, "worker": worker}) for r in results]


def calibrated_mass(data: bytes) -> float:
    """The total mass of a calibration's refined model (the bytes ``calibrate_cell``
    returns), kg: against the robot's (``robot_mass``), a calibration that misreads the
    robot's weight shows as a standing external force of (difference) x g."""
    from systems.estimation.model_identification import ModelCorrections

    corrections = ModelCorrections.load(_calibration_path(data))
    return float(sum(M.get_mass() for M in corrections.spatial_inertias.values()))


def robot_mass(model: str) -> float:
    """The total mass of the robot ``model`` as its description gives it (the simulated
    robot of the realistic world, before the estimators' mismatch), kg."""
    from pydrake.multibody.plant import MultibodyPlant

    from models import add_humanoid

    plant = MultibodyPlant(time_step=1e-3)
    handles = add_humanoid(plant, model)
    plant.Finalize()
    return float(plant.CalcTotalMass(plant.CreateDefaultContext(), [handles.model_instance]))


def _calibration_path(data: bytes) -> Path:
    """A file in this machine's temporary folder holding ``data`` (named by its hash,
    written atomically once)."""
    folder = Path(tempfile.gettempdir()) / "hco-sweep-calibrations"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{hashlib.sha1(data).hexdigest()}.npz"
    if not path.is_file():
        write_atomically(path, data)
    return path
