"""Residual comparison: Flacco et al. (2016), Secs. II-C, III and V, Figs. 3, 4, 7 and 8.

The humanoid holds its posture (PD + gravity compensation) while a sinusoidal force pushes
its right shoulder. The classical residual (eq. 7, model 8), the internal residual (eq. 11)
and the external residual (eq. 16) run on the simulated sensors only; the push's ground
truth (tau_c,real of eq. 12, the total external wrench) goes to the metrics only.

Run: ``python -m apps.residual_comparison [--model M] [--push-body B] [--duration S]
[--seed N] [--no-noise] [--out DIR]``. Writes to ``DIR/residual_comparison/``:
``fig3_classical.png``, ``fig4_internal.png``, ``fig7_external_base.png``,
``fig8_external_force.png`` and ``metrics.json``, and prints a summary.

Errors are relative RMS errors over the samples after ``--skip`` seconds (default 0.5 s):
sqrt(sum (estimate - truth)^2) / sqrt(sum truth^2), over all joints or per joint. Each is
reported against the raw truth and against the truth passed through the residual's own
first-order filter (time constant 1/K), which removes the filter's designed lag.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402

from diagrams.residuals.residual_comparison import (  # noqa: E402
    ResidualComparisonConfig,
    build_residual_comparison_diagram,
    set_initial_state,
)


def relative_rms_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    """sqrt(sum (estimate - truth)^2) / sqrt(sum truth^2) over every entry (nan if truth is 0)."""
    denominator = float(np.sqrt(np.sum(np.square(truth))))
    if denominator == 0.0:
        return float("nan")
    return float(np.sqrt(np.sum(np.square(estimate - truth))) / denominator)


def first_order_filter(samples: np.ndarray, gain: float, dt: float) -> np.ndarray:
    """The truth as a residual of gain K would see it: y' = K (u - y), y(0) = 0, for the
    columns of ``samples`` taken every ``dt`` seconds (exact for piecewise-constant input)."""
    a = 1.0 - np.exp(-gain * dt)
    out = np.zeros_like(samples)
    y = np.zeros(samples.shape[0])
    for k in range(1, samples.shape[1]):
        y = y + a * (samples[:, k - 1] - y)
        out[:, k] = y
    return out


def _parse(argv):
    parser = argparse.ArgumentParser(
        prog="python -m apps.residual_comparison", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--model", default="hrp4_like", help="hrp4_like, nao_like, or a floating-base SDF/URDF path")
    parser.add_argument("--push-body", default=None, help="pushed body (default: the right shoulder)")
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time, s (default 10)")
    parser.add_argument("--seed", type=int, default=0, help="sensor noise seed")
    parser.add_argument("--no-noise", action="store_true", help="ideal sensors")
    parser.add_argument("--skip", type=float, default=0.5, help="metrics ignore the first SKIP s (default 0.5)")
    parser.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out)")
    args = parser.parse_args(argv)
    if args.duration <= args.skip:
        parser.error("--duration must exceed --skip")
    return args


def run(config: ResidualComparisonConfig, skip: float = 0.5) -> tuple[dict, dict]:
    """Simulates ``config``; returns (metrics, the logged signals)."""
    diagram, handles = build_residual_comparison_diagram(config)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    set_initial_state(diagram, context, handles)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(config.duration)
    wall = time.perf_counter() - start
    logs = {name: logger.FindLog(context) for name, logger in handles.loggers.items()}
    t = logs["internal"].sample_times()
    signals = {name: log.data() for name, log in logs.items()}
    signals["t"] = t
    window = t >= skip
    dt = config.log_period

    truth = signals["tau_c_real"]
    internal, classical = signals["internal"], signals["classical"][6:]
    internal_truth_filtered = first_order_filter(truth, config.internal_gain, dt)
    classical_truth_filtered = first_order_filter(truth, config.classical_gain, dt)
    force_truth = signals["force_world_true"]
    force_estimate = signals["external_world"][3:]
    force_truth_filtered = first_order_filter(force_truth, config.external_gain, dt)
    wrench_base_truth = signals["wrench_base_true"]
    wrench_base_filtered = first_order_filter(wrench_base_truth, config.external_gain, dt)
    names = handles.joint_names

    def per_joint(estimate, reference):
        return {name: relative_rms_error(estimate[k, window], reference[k, window]) for k, name in enumerate(names)}

    before = t < config.push_start  # no push yet: the residuals show only noise
    metrics = {
        "model": config.model,
        "push_body": handles.push_source.pushes[0].body_name,
        "noise": config.noise,
        "sensors": "simulated sensors" if handles.sensors is not None else "true state (no sensor model for this robot)",
        "seed": config.seed,
        "duration_s": config.duration,
        "skip_s": skip,
        "gains_per_s": {"classical": config.classical_gain, "internal": config.internal_gain, "external": config.external_gain},
        "internal_rel_rms_error": relative_rms_error(internal[:, window], truth[:, window]),
        "internal_rel_rms_error_per_joint": per_joint(internal, truth),
        "internal_rel_rms_error_vs_filtered_truth": relative_rms_error(internal[:, window], internal_truth_filtered[:, window]),
        "internal_rel_rms_error_per_joint_vs_filtered_truth": per_joint(internal, internal_truth_filtered),
        "classical_rel_rms_error": relative_rms_error(classical[:, window], truth[:, window]),
        "classical_rel_rms_error_per_joint": per_joint(classical, truth),
        "classical_rel_rms_error_vs_filtered_truth": relative_rms_error(classical[:, window], classical_truth_filtered[:, window]),
        "external_force_rel_rms_error": relative_rms_error(force_estimate[:, window], force_truth[:, window]),
        "external_force_rel_rms_error_vs_filtered_truth": relative_rms_error(
            force_estimate[:, window], force_truth_filtered[:, window]
        ),
        "external_wrench_base_rel_rms_error": relative_rms_error(signals["external_base"][:, window], wrench_base_truth[:, window]),
        "external_wrench_base_rel_rms_error_vs_filtered_truth": relative_rms_error(
            signals["external_base"][:, window], wrench_base_filtered[:, window]
        ),
        "rms_true_joint_effort_Nm": {name: float(np.sqrt(np.mean(truth[k, window] ** 2))) for k, name in enumerate(names)},
        "rms_classical_joint_effort_Nm": {name: float(np.sqrt(np.mean(classical[k, window] ** 2))) for k, name in enumerate(names)},
        "rms_internal_noise_before_push_Nm": {
            name: float(np.sqrt(np.mean(internal[k, before & (t > 0.05)] ** 2))) if np.any(before & (t > 0.05)) else None
            for k, name in enumerate(names)
        },
        "wall_time_s": wall,
        "real_time_factor": config.duration / wall,
    }
    return metrics, {"signals": signals, "names": names, "window": window, "handles": handles}


def _joint_rows(names):
    rows = [("right and left knee pitch", [n for n in names if "KNEE" in n.upper()])]
    rows.append(("chest yaw", [n for n in names if n.upper() in ("CHEST_Y",)]))
    if not rows[1][1]:  # other models: the two joints with the largest true effort go there
        rows[1] = ("", [])
    return rows


def _plot_joints(path: Path, title: str, t, estimate, truth, names, *, base=None, base_truth=None):
    rows = [r for r in _joint_rows(names) if r[1]]
    n_rows = len(rows) + 1 + (1 if base is not None else 0)
    fig, axes = plt.subplots(n_rows, 1, figsize=(8, 2.2 * n_rows), sharex=True)
    axes = np.atleast_1d(axes)
    i = 0
    if base is not None:
        for j, label in enumerate(("m_x", "m_y", "m_z", "f_x", "f_y", "f_z")):
            (line,) = axes[0].plot(t, base[j], label=label)
            axes[0].plot(t, base_truth[j], "--", color=line.get_color())
        axes[0].set_ylabel("virtual joints\n[N m, N]")
        axes[0].legend(ncol=6, fontsize=7)
        i = 1
    for label, joint_names in rows:
        ax = axes[i]
        for name in joint_names:
            k = names.index(name)
            (line,) = ax.plot(t, estimate[k], label=f"{name} estimate")
            ax.plot(t, truth[k], "--", color=line.get_color(), label=f"{name} true")
        ax.set_ylabel(f"{label}\n[N m]")
        ax.legend(fontsize=7)
        i += 1
    axes[-1].plot(t, np.linalg.norm(estimate - truth, axis=0), color="k")
    axes[-1].set_ylabel("error norm\n[N m]")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_wrench(path: Path, title: str, t, estimate, truth, *, moment: bool):
    n_rows = 3 if moment else 2
    fig, axes = plt.subplots(n_rows, 1, figsize=(8, 2.4 * n_rows), sharex=True)
    rows = [(estimate[:3], truth[:3], "torque [N m]", "m"), (estimate[3:], truth[3:], "force [N]", "f")] if moment else [
        (estimate, truth, "force [N]", "f")
    ]
    for ax, (est, tru, label, symbol) in zip(axes, rows):
        for j, axis in enumerate("xyz"):
            (line,) = ax.plot(t, est[j], label=f"{symbol}_{axis} estimate")
            ax.plot(t, tru[j], "--", color=line.get_color(), label=f"{symbol}_{axis} true")
        ax.set_ylabel(label)
        ax.legend(ncol=3, fontsize=7)
    axes[-1].plot(t, np.linalg.norm(estimate[-3:] - truth[-3:], axis=0), color="k")
    axes[-1].set_ylabel("force error norm [N]")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outputs(out_dir: Path, metrics: dict, data: dict) -> None:
    """Writes the four figures and metrics.json to ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    s, names = data["signals"], list(data["names"])
    t = s["t"]
    _plot_joints(
        out_dir / "fig3_classical.png",
        "Classical residual (eq. 7, model 8): estimate (solid) vs true tau_c,real (dashed)",
        t, s["classical"][6:], s["tau_c_real"], names,
        base=s["classical"][:6], base_truth=s["wrench_base_true"],
    )
    _plot_joints(
        out_dir / "fig4_internal.png",
        "Internal residual (eq. 11): estimate (solid) vs true tau_c,real (dashed)",
        t, s["internal"], s["tau_c_real"], names,
    )
    _plot_wrench(
        out_dir / "fig7_external_base.png",
        "External residual (eq. 16) in the base frame: estimate (solid) vs true (dashed)",
        t, s["external_base"], s["wrench_base_true"], moment=True,
    )
    _plot_wrench(
        out_dir / "fig8_external_force.png",
        "External force of the single contact (eq. 19), world: estimate (solid) vs true (dashed)",
        t, s["external_world"][3:], s["force_world_true"], moment=False,
    )
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=True))


def _print_summary(metrics: dict, out_dir: Path) -> None:
    print(
        f"residual comparison on {metrics['model']} ({metrics['sensors']}, noise {'on' if metrics['noise'] else 'off'}),"
        f" after {metrics['skip_s']} s:"
    )
    print(f"{'':44s} {'vs truth':>10s} {'vs filtered truth':>18s}")
    rows = [
        ("internal residual, all joints", "internal_rel_rms_error", "internal_rel_rms_error_vs_filtered_truth"),
        ("classical residual (joint part), all joints", "classical_rel_rms_error", "classical_rel_rms_error_vs_filtered_truth"),
        ("external residual, force (world)", "external_force_rel_rms_error", "external_force_rel_rms_error_vs_filtered_truth"),
        ("external residual, wrench (base frame)", "external_wrench_base_rel_rms_error", "external_wrench_base_rel_rms_error_vs_filtered_truth"),
    ]
    for label, raw, filtered in rows:
        print(f"{label:44s} {100 * metrics[raw]:9.2f}% {100 * metrics[filtered]:17.2f}%")
    per_joint = metrics["internal_rel_rms_error_per_joint"]
    for name in [n for n in per_joint if "KNEE" in n.upper() or n.upper() == "CHEST_Y"]:
        print(
            f"  {name:12s} internal {100 * per_joint[name]:6.2f}%  classical {100 * metrics['classical_rel_rms_error_per_joint'][name]:7.2f}%"
            f"  (true RMS {metrics['rms_true_joint_effort_Nm'][name]:.3f} N m, classical RMS {metrics['rms_classical_joint_effort_Nm'][name]:.3f} N m)"
        )
    print(f"real-time factor {metrics['real_time_factor']:.2f} ({metrics['wall_time_s']:.1f} s wall)")
    print(f"wrote {out_dir}")


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    config = ResidualComparisonConfig(
        model=args.model, push_body=args.push_body, duration=args.duration, seed=args.seed, noise=not args.no_noise
    )
    try:
        metrics, data = run(config, skip=args.skip)
    except ValueError as error:  # bad model, body, or settings: say so, no traceback
        print(f"residual_comparison: error: {error}", file=sys.stderr)
        return 2
    out_dir = args.out / "residual_comparison"
    write_outputs(out_dir, metrics, data)
    _print_summary(metrics, out_dir)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
