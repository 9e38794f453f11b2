"""Model refinement from the residuals (Flacco et al. 2016, Sec. VI, future work): calibrate
the estimators' model of the realistic robot from a slow calibration motion, then measure
the spurious effort it removes.

The realistic robot (``diagrams.station.config``: invariant-EKF base state, IMU noise
and bias walks, encoder quantisation, unmodelled joint friction, motor-torque scale and
offset errors, 5 % mass / 10 % CoM / 10 % inertia mismatch) stands on its F/T feet and
follows a 40 s slow whole-body motion; from that log alone (``CalibrationLog``: sensed state,
motor torques, F/T wrenches) ``identify_model_corrections`` fits the link masses and first
moments (base-parameter regressor), joint friction and motor-torque offset and scale. Then,
without any contact, the external and internal residuals run with the nominal and with the
refined model, standing and during a different slow motion: whatever they report is
spurious. ``--log FILE.npz`` identifies from a recorded log instead (a robot's own; the
layout of ``CalibrationLog.to_npz``) and skips the simulated checks.

Run: ``python -m apps.model_refinement [--scenario FILE] [--scenario-text YAML] [--seed N]
[--calibration-duration S] [--log FILE.npz] [--out DIR]``. Writes to
``DIR/model_refinement/``: ``model_corrections.npz`` (load it with
``ModelCorrections.load``, or give it to any realistic app as ``model_refinement: FILE``),
``calibration_log.npz``, ``spurious_effort.png`` and ``metrics.json``.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

from apps.runner import experiment_parser, output_folder, print_written, run_app, scenario_from_args, write_metrics
from diagrams.residuals.model_refinement import (
    SPURIOUS_FORCE_REDUCTION_FLOOR,
    ModelRefinementScenario,
    build_refinement_diagram,
    calibrate_from_log,
    calibration_log,
    check_spurious_effort,
    reduction,
    run_refinement_diagram,
)
from systems.estimation.model_identification import CalibrationLog


def _parse(argv):
    parser = experiment_parser("apps.model_refinement", __doc__, replay=False, robot=True)
    parser.add_argument("--seed", type=int, default=None, help="sensor noise seed (scenario default 0)")
    parser.add_argument(
        "--calibration-duration", type=float, default=None, help="calibration motion, s (scenario default 40)"
    )
    parser.add_argument(
        "--log", type=Path, default=None, help="identify from this recorded log (.npz) instead of simulating"
    )
    return parser.parse_args(argv)


def _plot(path: Path, traces: dict) -> None:
    fig, axes = plt.subplots(2, 2, figsize=(12, 6), sharex="col")
    for column, case in enumerate(("standing", "slow_motion")):
        for label, color in (("nominal model", "tab:red"), ("refined model", "tab:green")):
            trace = traces[case][label]
            axes[0, column].plot(trace["t"], trace["force_norm"], color=color, lw=0.8, label=label)
            axes[1, column].plot(trace["t"], trace["internal_norm"], color=color, lw=0.8, label=label)
        axes[0, column].set_title(f"no contact, {case.replace('_', ' ')}")
        axes[0, column].set_ylabel("|external force| [N]")
        axes[1, column].set_ylabel("|internal residual| [N m]")
        axes[1, column].set_xlabel("time [s]")
        for ax in axes[:, column]:
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8)
    fig.suptitle("Spurious effort the residuals report without contact (all of it is model error and noise)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    def body() -> int:
        scenario = scenario_from_args(
            ModelRefinementScenario, args, seed=args.seed, calibration_duration=args.calibration_duration
        ).validate()
        out_dir = output_folder(args, "model_refinement")
        diagram, handles = build_refinement_diagram(scenario, scenario.calibration_motion, residuals=False)
        if args.log is not None:
            log = CalibrationLog.from_npz(args.log)
            print(f"model refinement: identifying from {args.log} ({log.time.size} samples)")
        else:
            print(f"model refinement: {scenario.calibration_duration:g} s calibration motion ...", flush=True)
            context = run_refinement_diagram(diagram, handles, scenario.calibration_duration, scenario.simulator_config)
            log = calibration_log(handles, context)
            log.to_npz(out_dir / "calibration_log.npz")
        corrections = calibrate_from_log(scenario, handles, log)
        corrections.save(out_dir / "model_corrections.npz")
        metrics = {"identification": corrections.diagnostics, "log_samples": int(log.time.size)}
        if args.log is None:
            traces, checks = {"standing": {}, "slow_motion": {}}, {}
            for case, motion, duration in (
                ("standing", None, scenario.standing_duration),
                ("slow_motion", scenario.check_motion, scenario.check_duration),
            ):
                print(f"model refinement: checking, {case.replace('_', ' ')} ({duration:g} s, twice) ...", flush=True)
                before, traces[case]["nominal model"] = check_spurious_effort(
                    scenario, motion, duration, None, with_trace=True
                )
                after, traces[case]["refined model"] = check_spurious_effort(
                    scenario, motion, duration, corrections, with_trace=True
                )
                checks[case] = {
                    "nominal_model": before,
                    "refined_model": after,
                    "external_force_reduction": reduction(
                        before["external_force_rms_N"], after["external_force_rms_N"]
                    ),
                    "internal_reduction": reduction(before["internal_rms_Nm"], after["internal_rms_Nm"]),
                }
            metrics.update(checks)
            metrics["floor"] = {"standing external_force_reduction": f">= {SPURIOUS_FORCE_REDUCTION_FLOOR}"}
            metrics["meets_floor"] = checks["standing"]["external_force_reduction"] >= SPURIOUS_FORCE_REDUCTION_FLOOR
            _plot(out_dir / "spurious_effort.png", traces)
            _print_table(checks)
        write_metrics(out_dir, metrics, scenario, args)
        print_written(out_dir)
        return 0

    return run_app("model_refinement", body)


def _print_table(checks: dict) -> None:
    print(f"{'spurious effort without contact':40s} {'nominal':>10s} {'refined':>10s} {'removed':>9s}")
    for case in ("standing", "slow_motion"):
        c = checks[case]
        rows = (
            ("external force RMS [N]", "external_force_rms_N", c["external_force_reduction"]),
            ("internal residual RMS [N m]", "internal_rms_Nm", c["internal_reduction"]),
        )
        for label, key, removed in rows:
            before, after = c["nominal_model"][key], c["refined_model"][key]
            print(f"  {case.replace('_', ' '):12s} {label:27s} {before:10.3f} {after:10.3f} {100 * removed:8.1f}%")
    ok = checks["standing"]["external_force_reduction"] >= SPURIOUS_FORCE_REDUCTION_FLOOR
    print(
        f"floor: the refinement removes >= {100 * SPURIOUS_FORCE_REDUCTION_FLOOR:.0f} % of the standing spurious "
        f"external force: {'ok' if ok else 'MISSED'}"
    )


if __name__ == "__main__":
    raise SystemExit(main())
