"""The authors' real-Nao recordings (Hawley, Rahem and Suleiman 2019) in their published
format, and the Kalman force observer run on them (``replay``).

A recording is a folder of ``CoM_Pos.mat`` (``Xc_Yc_Zc``, N x 3, m), ``Acc.mat`` (``acc``,
N x 3, m/s^2), ``ZMP.mat`` (``ZMP``, N x 2, m) and ``total_force.mat`` (``total_force``,
N x 2, raw FSR sums of each foot). The FSR scale is calibrated as in the authors'
implementation: f_n^o = -(sum of both feet) scaled once so that the first sample equals M g.

The two published recordings ship in ``data/hawley2019-nao/``; ``published_dataset_dir()``
finds them there or, when the environment variable ``HCO_SHARED_DIR`` is set, in
``$HCO_SHARED_DIR/datasets/hawley2019-nao``. Used by ``apps.replay_nao_dataset``,
``apps.benchmark`` and the tests. A missing or unreadable folder or file is a
``DatasetError`` that names the path.
"""

from __future__ import annotations

import os
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
BUNDLED_DATASET_DIR = Path(__file__).resolve().parents[2] / "data" / "hawley2019-nao"


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
        hint = (
            f"point {DATA_DIR_VARIABLE} at a folder holding datasets/hawley2019-nao/,"
            f" or unset it to use {BUNDLED_DATASET_DIR}"
        )
    else:
        directory = BUNDLED_DATASET_DIR
        origin = "the recordings shipped with the repository"
        hint = (
            f"restore data/hawley2019-nao from the repository,"
            f" or set {DATA_DIR_VARIABLE} (see apps/replay_nao_dataset.py)"
        )
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


__all__ = [
    "BUNDLED_DATASET_DIR",
    "DATASET_FILES",
    "DATA_DIR_VARIABLE",
    "DatasetError",
    "EXPECTED",
    "RECORDINGS",
    "load_recording",
    "published_dataset_dir",
    "replay",
]
