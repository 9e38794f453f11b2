"""Plots shared by several apps: ``plot_walking_time`` (nao_walk, nao_walk_pulled). The apps'
runner is ``apps.runner``."""

from __future__ import annotations

from pathlib import Path


def plot_walking_time(path: Path, run: dict) -> None:
    """x and y of ZMP / CoM vs references, foot normal forces with the planned contact, base
    tilt, from ``run["metrics"]["signals"]`` (``diagrams.locomotion.nao_walk.walking_metrics``;
    the nao-walk and nao-walk-pulled apps)."""
    import matplotlib.pyplot as plt

    s = run["metrics"]["signals"]
    t = s["t"]
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True)
    for i, axis in enumerate("xy"):
        ax = axes[i]
        ax.plot(t, s["zmp"][:, i], color="tab:red", lw=0.6, label="ZMP")
        ax.plot(t, s["zmp_reference"][:, i], "--", color="k", lw=0.8, label="ZMP ref")
        ax.plot(t, s["com_reference"][:, i], color="tab:green", lw=1.2, label="CoM ref")
        ax.plot(t, s["com"][:, i], ":", color="tab:blue", lw=1.5, label="CoM")
        ax.set_ylabel(f"{axis} [m]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7, ncol=4)
    ax = axes[2]
    for i, (side, color) in enumerate((("left", "tab:blue"), ("right", "tab:orange"))):
        ax.plot(t, s["foot_normal_forces"][:, i], color=color, lw=0.8, label=f"{side} foot")
        ax.fill_between(t, 0, 60 * s["planned_contact"][:, i], color=color, alpha=0.08, step="mid")
    ax.set_ylabel("normal force [N]")
    ax.legend(fontsize=7)
    ax.grid(True, alpha=0.3)
    axes[3].plot(t, s["tilt_deg"], color="k", lw=0.8, label="base tilt")
    axes[3].plot(t, s["yaw_deg"], color="tab:purple", lw=0.8, label="base yaw")
    axes[3].set_ylabel("angle [deg]")
    axes[3].set_xlabel("time [s] (shaded: planned contact)")
    axes[3].legend(fontsize=7)
    axes[3].grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["plot_walking_time"]
