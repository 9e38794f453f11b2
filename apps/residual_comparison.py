"""Residual comparison: Flacco et al. (2016), Secs. II-C, III and V, Figs. 3, 4, 7 and 8.

The humanoid holds its posture (PD + gravity compensation) while a sinusoidal force pushes
its right shoulder. The classical residual (eq. 7, model 8), the internal residual (eq. 11)
and the external residual (eq. 16) run on the simulated sensors only; the push's ground
truth (tau_c,real of eq. 12, the total external wrench) goes to the metrics only.

Run: ``python -m apps.residual_comparison [--scenario FILE] [--scenario-text YAML]
[--model M] [--push-body B] [--duration S] [--seed N] [--no-noise] [--skip S] [--out DIR]``
(the shorthand options override the scenario's fields of the same name; ``--no-noise`` sets
``noise: false``). Writes to ``DIR/residual_comparison/``: ``fig3_classical.png``,
``fig4_internal.png``, ``fig7_external_base.png``, ``fig8_external_force.png`` and
``metrics.json``, and prints a summary.

Errors are relative RMS errors over the samples after the scenario's ``skip`` seconds
(default 0.5 s): sqrt(sum (estimate - truth)^2) / sqrt(sum truth^2), over all joints or per
joint. Each is reported against the raw truth and against the truth passed through the
residual's own first-order filter (time constant 1/K), which removes the filter's designed
lag (``diagrams.residuals.residual_comparison.residual_comparison_metrics``).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from apps.runner import (
    calibration_cache_folder,
    experiment_parser,
    logged_signals,
    output_folder,
    print_written,
    run_app,
    scenario_from_args,
    simulate,
    write_metrics,
)
from diagrams.residuals.model_refinement import refined_model
from diagrams.residuals.residual_comparison import (
    ResidualComparisonScenario,
    build_residual_comparison_diagram,
    check_metrics_window,
    residual_comparison_metrics,
)
from systems.estimation.model_identification import ModelCorrections


def _parse(argv):
    parser = experiment_parser("apps.residual_comparison", __doc__, replay=False, conditions=True, robot=True)
    parser.add_argument("--model", default=None, help="hrp4_like, nao_like, or a floating-base SDF/URDF path")
    parser.add_argument("--push-body", default=None, help="pushed body (default: the right shoulder)")
    parser.add_argument("--duration", type=float, default=None, help="simulated time, s (scenario default 10)")
    parser.add_argument("--seed", type=int, default=None, help="sensor noise seed (scenario default 0)")
    parser.add_argument("--no-noise", action="store_true", help="ideal sensors")
    parser.add_argument(
        "--skip", type=float, default=None, help="metrics ignore the first SKIP s (scenario default 0.5)"
    )
    return parser.parse_args(argv)


def run_once(
    scenario: ResidualComparisonScenario, meshcat=None, *, model_corrections: ModelCorrections | None = None
) -> dict:
    """Simulates ``scenario`` (with the refined model ``model_corrections``, if given): its
    logged signals, handles, wall time and metrics."""
    check_metrics_window(scenario)  # before the simulation, not after it
    diagram, handles = build_residual_comparison_diagram(scenario, meshcat, model_corrections=model_corrections)
    run = simulate(
        diagram,
        scenario.duration,
        set_initial_state=handles.station.set_initial_state,
        simulator_config=scenario.simulator_config,
        meshcat=meshcat,
    )
    signals = logged_signals(handles.loggers, run.context, "internal")
    metrics = residual_comparison_metrics(scenario, handles, signals, run.wall_time_s)
    return {"signals": signals, "handles": handles, "wall": run.wall_time_s, "metrics": metrics}


def _joint_rows(names, knees=None):
    knees = [n for n in names if "KNEE" in n.upper()] if knees is None else list(knees)
    rows = [("right and left knee pitch", knees)]
    rows.append(("chest yaw", [n for n in names if n.upper() in ("CHEST_Y",)]))
    if not rows[1][1]:  # other models: the two joints with the largest true effort go there
        rows[1] = ("", [])
    return rows


def _plot_joints(path: Path, title: str, t, estimate, truth, names, *, knees=None, base=None, base_truth=None):
    rows = [r for r in _joint_rows(names, knees) if r[1]]
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
    rows = (
        [(estimate[:3], truth[:3], "torque [N m]", "m"), (estimate[3:], truth[3:], "force [N]", "f")]
        if moment
        else [(estimate, truth, "force [N]", "f")]
    )
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


def _plot(out_dir: Path, run: dict) -> None:
    """Writes the four figures to ``out_dir``."""
    s, names = run["signals"], list(run["handles"].joint_names)
    humanoid = run["handles"].station.humanoid
    knees = None if humanoid is None else humanoid.joint_groups["knees"]  # None: found by name
    t = s["t"]
    _plot_joints(
        out_dir / "fig3_classical.png",
        "Classical residual (eq. 7, model 8): estimate (solid) vs true tau_c,real (dashed)",
        t,
        s["classical"][6:],
        s["tau_c_real"],
        names,
        knees=knees,
        base=s["classical"][:6],
        base_truth=s["wrench_base_true"],
    )
    _plot_joints(
        out_dir / "fig4_internal.png",
        "Internal residual (eq. 11): estimate (solid) vs true tau_c,real (dashed)",
        t,
        s["internal"],
        s["tau_c_real"],
        names,
        knees=knees,
    )
    _plot_wrench(
        out_dir / "fig7_external_base.png",
        "External residual (eq. 16) in the base frame: estimate (solid) vs true (dashed)",
        t,
        s["external_base"],
        s["wrench_base_true"],
        moment=True,
    )
    _plot_wrench(
        out_dir / "fig8_external_force.png",
        "External force of the single contact (eq. 19), world: estimate (solid) vs true (dashed)",
        t,
        s["external_world"][3:],
        s["force_world_true"],
        moment=False,
    )


def _print_summary(metrics: dict) -> None:
    print(
        f"residual comparison on {metrics['model']} ({metrics['sensors']},"
        f" noise {'on' if metrics['noise'] else 'off'}),"
        f" after {metrics['skip_s']} s:"
    )
    print(f"{'':44s} {'vs truth':>10s} {'vs filtered truth':>18s}")
    rows = [
        ("internal residual, all joints", "internal_rel_rms_error", "internal_rel_rms_error_vs_filtered_truth"),
        (
            "classical residual (joint part), all joints",
            "classical_rel_rms_error",
            "classical_rel_rms_error_vs_filtered_truth",
        ),
        (
            "external residual, force (world)",
            "external_force_rel_rms_error",
            "external_force_rel_rms_error_vs_filtered_truth",
        ),
        (
            "external residual, wrench (base frame)",
            "external_wrench_base_rel_rms_error",
            "external_wrench_base_rel_rms_error_vs_filtered_truth",
        ),
    ]
    for label, raw, filtered in rows:
        print(f"{label:44s} {100 * metrics[raw]:9.2f}% {100 * metrics[filtered]:17.2f}%")
    per_joint = metrics["internal_rel_rms_error_per_joint"]
    for name in [n for n in per_joint if "KNEE" in n.upper() or n.upper() == "CHEST_Y"]:
        print(
            f"  {name:12s} internal {100 * per_joint[name]:6.2f}%"
            f"  classical {100 * metrics['classical_rel_rms_error_per_joint'][name]:7.2f}%"
            f"  (true RMS {metrics['rms_true_joint_effort_Nm'][name]:.3f} N m,"
            f" classical RMS {metrics['rms_classical_joint_effort_Nm'][name]:.3f} N m)"
        )
    print(f"real-time factor {metrics['real_time_factor']:.2f} ({metrics['wall_time_s']:.1f} s wall)")


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        scenario = scenario_from_args(
            ResidualComparisonScenario,
            args,
            model=args.model,
            push_body=args.push_body,
            duration=args.duration,
            seed=args.seed,
            noise=False if args.no_noise else None,
            skip=args.skip,
        )
        check_metrics_window(scenario)
        build_residual_comparison_diagram(scenario)  # a bad model, body or setting fails here, before calibrating
        out_dir = output_folder(args, "residual_comparison")
        corrections = refined_model(scenario, calibration_cache_folder(args))
        # A bad model, body or setting: a ValueError, reported by run_app.
        run = run_once(scenario, model_corrections=corrections)
        _plot(out_dir, run)
        write_metrics(out_dir, run["metrics"], scenario, args)
        _print_summary(run["metrics"])
        print_written(out_dir)
        return 0

    return run_app("residual_comparison", body)


if __name__ == "__main__":
    raise SystemExit(main())
