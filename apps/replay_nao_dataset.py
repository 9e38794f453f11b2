"""Runs the Kalman force observer (Hawley et al. 2019) on a real Nao recording.

Run: ``python -m apps.replay_nao_dataset DIR [--out OUT] [--preset standing|walking]
[--no-calibration]``. DIR holds a recording in the published format of the authors' dataset:
``CoM_Pos.mat`` (``Xc_Yc_Zc``, N x 3, m), ``Acc.mat`` (``acc``, N x 3, m/s^2), ``ZMP.mat``
(``ZMP``, N x 2, m) and ``total_force.mat`` (``total_force``, N x 2, raw FSR sums of each
foot). Writes into ``OUT/replay_nao_dataset/<recording>/`` (OUT default ``out``,
<recording> the name of DIR): ``estimates.csv`` (header ``t,Fx,Fy,Fz``, one row per sample,
t = k T with k from 1) and ``estimates.png`` (the estimate, and the paper's expected virtual
force when the recording is one of the paper's two).

The FSR scale is calibrated as in the authors' implementation: f_n^o = -(sum of both feet)
scaled once so that the first sample equals M g (no external force then).

The authors' two published recordings ship with the repository in ``data/hawley2019-nao/``
(``Force_Y_data``, ``Force_Z_data``; GPL-2.0 data, see that folder's README), e.g.
``python -m apps.replay_nao_dataset data/hawley2019-nao/Force_Y_data`` (writes
``out/replay_nao_dataset/Force_Y_data/``).
DIR may be any folder of your own recordings in the same format. The loading, checks and
replay are ``systems.observer.nao_dataset``'s; the tests and ``apps.benchmark`` find the
published recordings with its ``published_dataset_dir()``: the
repository's ``data/hawley2019-nao`` by default, or, when the environment variable
``HCO_SHARED_DIR`` is set, ``$HCO_SHARED_DIR/datasets/hawley2019-nao`` (a folder holding
``Force_Y_data/`` and ``Force_Z_data/``: to run them on your own copy of the recordings).
A missing or unreadable folder is an error that names the path.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from apps.runner import add_out_argument, output_folder, print_written, run_app
from systems.observer.force_observer import STANDING
from systems.observer.nao_dataset import EXPECTED, RECORDINGS, replay

EXPERIMENT = "replay_nao_dataset"


def write_outputs(out_dir: Path, forces: np.ndarray, period: float, name: str) -> None:
    """``estimates.csv`` and ``estimates.png`` of the recording ``name`` in ``out_dir``."""
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
        prog=f"python -m apps.{EXPERIMENT}",
        description=__doc__.split("\n\n")[0],
        epilog=f"The authors' published recordings: {', '.join(f'data/hawley2019-nao/{n}' for n in RECORDINGS)} "
        "(in the repository; GPL-2.0 data, see data/hawley2019-nao/README.md).",
    )
    parser.add_argument(
        "directory", type=Path, help="folder of one recording (CoM_Pos.mat, Acc.mat, ZMP.mat, total_force.mat)"
    )
    add_out_argument(parser, f"{EXPERIMENT}/<recording>")
    parser.add_argument("--preset", choices=("standing", "walking"), default="standing", help="eq. (21) or eq. (22)")
    parser.add_argument("--no-calibration", action="store_true", help="use -sum(total_force) as f_n without scaling")
    args = parser.parse_args(argv)

    def body() -> int:
        # A DatasetError (a ValueError) names the missing or malformed file: exit code 2.
        forces = replay(args.directory, walking=args.preset == "walking", calibrate=not args.no_calibration)
        name = args.directory.resolve().name
        out_dir = output_folder(args, f"{EXPERIMENT}/{name}")
        write_outputs(out_dir, forces, STANDING.period, name)
        print(f"{len(forces)} samples")
        print_written(out_dir)
        return 0

    return run_app(EXPERIMENT, body)


if __name__ == "__main__":
    raise SystemExit(main())
