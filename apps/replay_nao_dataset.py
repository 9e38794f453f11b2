"""Runs the Kalman force observer (Hawley et al. 2019) on a real Nao recording.

Run: ``python -m apps.replay_nao_dataset DIR --out OUTDIR [--preset standing|walking]
[--no-calibration]``. DIR holds a recording in the published format of the authors' dataset:
``CoM_Pos.mat`` (``Xc_Yc_Zc``, N x 3, m), ``Acc.mat`` (``acc``, N x 3, m/s^2), ``ZMP.mat``
(``ZMP``, N x 2, m) and ``total_force.mat`` (``total_force``, N x 2, raw FSR sums of each
foot). Writes ``OUTDIR/estimates.csv`` (header ``t,Fx,Fy,Fz``, one row per sample,
t = k T with k from 1) and ``OUTDIR/estimates.png`` (the estimate, and the paper's expected
virtual force when the recording is one of the paper's two).

The FSR scale is calibrated as in the authors' implementation: f_n^o = -(sum of both feet)
scaled once so that the first sample equals M g (no external force then).

The authors' two published recordings ship with the repository in ``data/hawley2019-nao/``
(``Force_Y_data``, ``Force_Z_data``; GPL-2.0 data, see that folder's README), e.g.
``python -m apps.replay_nao_dataset data/hawley2019-nao/Force_Y_data --out out/nao_Y``.
DIR may be any folder of your own recordings in the same format. The tests and
``apps.benchmark`` find the published recordings with ``published_dataset_dir()``: the
repository's ``data/hawley2019-nao`` by default, or, when the environment variable
``HCO_SHARED_DIR`` is set, ``$HCO_SHARED_DIR/datasets/hawley2019-nao`` (a folder holding
``Force_Y_data/`` and ``Force_Z_data/``: to run them on your own copy of the recordings).
A missing or unreadable folder is an error that names the path.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import scipy.io

from systems.observer.force_observer import STANDING, WALKING, calibrated_normal_force, estimate_virtual_forces

#: Files and variables of the published format, with their number of columns.
DATASET_FILES = {
    "CoM_Pos.mat": ("Xc_Yc_Zc", 3),
    "Acc.mat": ("acc", 3),
    "ZMP.mat": ("ZMP", 2),
    "total_force.mat": ("total_force", 2),
}
#: The paper's expected virtual forces while loaded (eq. 24; dataset README), N.
EXPECTED = {"Force_Y_data": (0.0, -10.96, 0.0), "Force_Z_data": (2.22, -4.16, -11.12)}


#: The published recordings' folders (``published_dataset_dir()`` must hold both).
RECORDINGS = ("Force_Y_data", "Force_Z_data")
#: Environment variable that moves ``published_dataset_dir()`` to
#: ``$HCO_SHARED_DIR/datasets/hawley2019-nao`` (a folder of your own).
DATA_DIR_VARIABLE = "HCO_SHARED_DIR"
#: The recordings shipped with the repository (GPL-2.0 data, see its README.md).
BUNDLED_DATASET_DIR = Path(__file__).resolve().parents[1] / "data" / "hawley2019-nao"


class DatasetError(ValueError):
    """A recording that cannot be used: the message names the file, variable or rows."""


def published_dataset_dir() -> Path:
    """The folder holding the authors' recordings ``Force_Y_data`` and ``Force_Z_data``:
    ``$HCO_SHARED_DIR/datasets/hawley2019-nao`` when that variable is set (non-empty), else
    ``data/hawley2019-nao`` in the repository (shipped with it).

    Raises:
        DatasetError: the folder, or one of the two recordings' folders in it, is missing
            or unreadable (the message names the path and where it came from).
    """
    root = os.environ.get(DATA_DIR_VARIABLE)
    if root:
        directory = Path(root) / "datasets" / "hawley2019-nao"
        origin = f"set by the environment variable {DATA_DIR_VARIABLE}={root!r}"
        hint = f"point {DATA_DIR_VARIABLE} at a folder holding datasets/hawley2019-nao/, or unset it to use {BUNDLED_DATASET_DIR}"
    else:
        directory = BUNDLED_DATASET_DIR
        origin = "the recordings shipped with the repository"
        hint = f"restore data/hawley2019-nao from the repository, or set {DATA_DIR_VARIABLE} (see apps/replay_nao_dataset.py)"
    for folder in (directory, *(directory / name for name in RECORDINGS)):
        if not folder.is_dir():
            raise DatasetError(f"Nao recordings not found: '{folder}' is not a folder ({origin}); {hint}")
        if not os.access(folder, os.R_OK | os.X_OK):
            raise DatasetError(f"Nao recordings not readable: cannot read the folder '{folder}' ({origin})")
    return directory


def load_recording(directory: Path) -> dict[str, np.ndarray]:
    """Reads and checks a recording. Returns {variable name: (N, columns) array}.

    Raises:
        DatasetError: a missing or unreadable file, a missing variable, a wrong shape,
            mismatched lengths, or rows with NaN or inf (the message lists them).
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise DatasetError(f"'{directory}' is not a folder")
    if not os.access(directory, os.R_OK | os.X_OK):
        raise DatasetError(f"cannot read the folder '{directory}'")
    data = {}
    for file_name, (variable, columns) in DATASET_FILES.items():
        path = directory / file_name
        if not path.is_file():
            raise DatasetError(f"missing file '{path}'")
        try:
            content = scipy.io.loadmat(str(path))
        except Exception as error:  # scipy raises several types for corrupt files
            raise DatasetError(f"cannot read '{path}': {error}") from error
        if variable not in content:
            found = sorted(k for k in content if not k.startswith("__"))
            raise DatasetError(f"'{path}' has no variable '{variable}' (found: {', '.join(found) or 'none'})")
        array = np.asarray(content[variable], dtype=float)
        if array.ndim != 2 or array.shape[1] != columns:
            raise DatasetError(f"'{path}': variable '{variable}' has shape {array.shape}; expected N x {columns}")
        bad = np.flatnonzero(~np.all(np.isfinite(array), axis=1))
        if bad.size:
            shown = ", ".join(str(i + 1) for i in bad[:10]) + (" ..." if bad.size > 10 else "")
            raise DatasetError(f"'{path}': variable '{variable}' has NaN or inf in rows {shown} (1-based)")
        data[variable] = array
    lengths = {name: len(array) for name, array in data.items()}
    if len(set(lengths.values())) != 1:
        raise DatasetError(f"the recordings have different lengths: {lengths}")
    if lengths["total_force"] == 0:
        raise DatasetError("the recording is empty")
    return data


def replay(directory: Path, *, walking: bool = False, calibrate: bool = True) -> np.ndarray:
    """The observer's (N, 3) virtual force estimates on the recording in ``directory``."""
    data = load_recording(directory)
    parameters = WALKING if walking else STANDING
    total = data["total_force"].sum(axis=1)
    normal_force = calibrated_normal_force(total, parameters.mass, parameters.gravity) if calibrate else -total
    forces, _ = estimate_virtual_forces(data["Xc_Yc_Zc"], data["acc"], data["ZMP"], normal_force, parameters)
    return forces


def write_outputs(out_dir: Path, forces: np.ndarray, period: float, name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    t = period * np.arange(1, len(forces) + 1)
    np.savetxt(out_dir / "estimates.csv", np.column_stack((t, forces)), delimiter=",", header="t,Fx,Fy,Fz", comments="")
    fig, ax = plt.subplots(figsize=(8, 4))
    for j, axis in enumerate("xyz"):
        (line,) = ax.plot(t, forces[:, j], label=f"F_{axis} estimate")
        if name in EXPECTED:
            ax.axhline(EXPECTED[name][j], ls="--", color=line.get_color(), label=f"F_{axis} expected (paper, loaded)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("virtual force [N]")
    ax.set_title(f"Kalman force observer on the real Nao recording '{name}'")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out_dir / "estimates.png", dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m apps.replay_nao_dataset", description=__doc__.split("\n\n")[0],
        epilog=f"The authors' published recordings: {', '.join(f'data/hawley2019-nao/{n}' for n in RECORDINGS)} "
        "(in the repository; GPL-2.0 data, see data/hawley2019-nao/README.md).")
    parser.add_argument("directory", type=Path, help="folder of one recording (CoM_Pos.mat, Acc.mat, ZMP.mat, total_force.mat)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--preset", choices=("standing", "walking"), default="standing", help="eq. (21) or eq. (22)")
    parser.add_argument("--no-calibration", action="store_true", help="use -sum(total_force) as f_n without scaling")
    args = parser.parse_args(argv)
    try:
        forces = replay(args.directory, walking=args.preset == "walking", calibrate=not args.no_calibration)
    except DatasetError as error:
        print(f"replay_nao_dataset: error: {error}", file=sys.stderr)
        return 2
    write_outputs(args.out, forces, STANDING.period, args.directory.resolve().name)
    print(f"{len(forces)} samples; wrote {args.out / 'estimates.csv'} and {args.out / 'estimates.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
