"""The documentation's generated tables (issue 31): each block of README.md, BENCHMARKS.md or a
page of docs/ between ``<!-- results: NAME -->`` and ``<!-- /results: NAME -->`` is the table ``RENDERERS[NAME]``
makes from ``results/<NAME>.json`` (``apps.results``), followed by the command that wrote it. A
block may read another file or several (``SOURCES``): BENCHMARKS.md's tables each read part of
``results/benchmark.json``, and its table of wall times and real-time factors reads the files of
every experiment that records them.

Run: ``python -m apps.doc_tables`` (``make docs``) rewrites the blocks; ``--check`` only reports
the stale ones (exit 1), as ``tests/test_doc_tables.py`` does.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from apps.results import generated_block_pattern, load_results, provenance, regenerated_blocks, stale_documents

ROOT = Path(__file__).resolve().parent.parent
#: The documents whose blocks are generated.
DOCUMENTS = (ROOT / "README.md", ROOT / "BENCHMARKS.md", *sorted((ROOT / "docs").glob("*.md")))

_BLOCK = generated_block_pattern("results")


def _deg(value) -> str:
    return "n/a" if value is None else f"{value:.2f} deg"


def _knee(metrics: dict) -> str:
    """The knee flexion of a run that stayed upright; "fell" otherwise (the flexion of a
    robot on the floor says nothing)."""
    return _deg(metrics["knee_pitch_flexion_deg"]) if metrics["upright"] else "fell"


def _yes(value: bool) -> str:
    return "yes" if value else "**no**"


def _push_and_comply_ablation(data: dict) -> list[str]:
    lines = [
        "| world | setting | internal: knee flexion | CoM drop / horizontal travel | upright "
        "| classical: knee flexion | upright |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in data["rows"]:
        i, c = row["internal"], row["classical"]
        lines.append(
            f"| {row['world']} | {row['label']} | {_knee(i)} "
            f"| {100 * i['com_height_drop_m']:.2f} / {100 * i['com_horizontal_travel_m']:.2f} cm "
            f"| {_yes(i['upright'])} | {_knee(c)} | {_yes(c['upright'])} |"
        )
    return lines


def _push_and_comply_robots(data: dict) -> list[str]:
    from diagrams.residuals.push_and_comply import meets_robot_floors

    lines = [
        "| robot (imperfections / sensor seed) | internal: knee flexion | CoM drop | base tilt | upright "
        "| classical: knee flexion | upright | push per shoulder | knee: the push's effort / the dead band "
        "| floors met |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in data["rows"]:
        i, c = row["internal"], row["classical"]
        lines.append(
            f"| {row['label']} ({row['robot_seed']} / {row['sensor_seed']}) | {_knee(i)} "
            f"| {100 * i['com_height_drop_m']:.1f} cm | {i['max_base_tilt_deg']:.1f} deg | {_yes(i['upright'])} "
            f"| {_knee(c)} | {_yes(c['upright'])} | {i['push_peak_force_N']:.1f} N | {_knee_effort_and_band(i)} "
            f"| {_yes(meets_robot_floors(i, c))} |"
        )
    return lines + ["", _robot_floors_note("issue 31"), _KNEE_COLUMN_NOTE]


def _knee_effort_and_band(metrics: dict) -> str:
    """The push's peak true effort at the knees and the admittance's dead band there, N m."""
    effort, band = metrics.get("knee_push_effort_N_m"), metrics.get("knee_dead_band_N_m")
    return f"{max(effort.values()):.2f} / {max(band.values()):.2f} N m" if effort and band else "n/a"


_KNEE_COLUMN_NOTE = (
    "The knee column: the push's peak true joint effort at the knees (eq. 12) and the internal run's "
    "admittance dead band there (2 standard deviations of the calibrated residual noise, at least the "
    "scenario's own; a soft threshold, it takes that much of the knees' residual)."
)


def _push_and_comply_sensing(data: dict) -> list[str]:
    """Issue 36's push-and-comply rows: robots by foot sensing, in each world."""
    from diagrams.residuals.push_and_comply import meets_robot_floors

    lines = [
        "| robot, foot sensing | world | internal: knee flexion | CoM drop | upright | classical: knee flexion "
        "| upright | push per shoulder | knee: the push's effort / the dead band | floors met |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in data["rows"]:
        i, c = row["internal"], row["classical"]
        lines.append(
            f"| {row['label']} | {row['world']} | {_knee(i)} | {100 * i['com_height_drop_m']:.1f} cm "
            f"| {_yes(i['upright'])} | {_knee(c)} | {_yes(c['upright'])} | {i['push_peak_force_N']:.1f} N "
            f"| {_knee_effort_and_band(i)} | {_yes(meets_robot_floors(i, c))} |"
        )
    return lines + ["", _robot_floors_note("issues 31 and 36"), _KNEE_COLUMN_NOTE]


def _robot_floors_note(issues: str) -> str:
    """The push-and-comply floors of a robot (``meets_robot_floors``), under ``issues``."""
    from diagrams.residuals.push_and_comply import FLOOR_CLASSICAL_KNEE_DEG, FLOOR_INTERNAL_KNEE_DEG

    return (
        f"Floors ({issues}): the internal run upright with both knees bent >= {FLOOR_INTERNAL_KNEE_DEG:g} deg, "
        f"the classical run upright with its knees bent < {FLOOR_CLASSICAL_KNEE_DEG:g} deg."
    )


def _with_interval(metrics: dict, key: str, scale: float, unit: str) -> str:
    """``metrics[key]`` times ``scale`` with its 95 % interval (``metrics["intervals"]``)."""
    value = metrics.get(key)
    if value is None:
        return "n/a"
    interval = metrics.get("intervals", {}).get(key)
    text = f"{scale * value:.1f} {unit}"
    return text + (f" [{scale * interval[0]:.1f}, {scale * interval[1]:.1f}]" if interval else "")


#: The contact study's quoted metrics: (label, key, scale, unit, which studies: 1 or 2 contacts).
CONTACT_STUDY_ROWS = (
    ("detection", "detection_rate", 100.0, "%", (1, 2)),
    ("right link, eq. (22) localizer", "correct_link_rate", 100.0, "%", (1,)),
    ("valid precision, eq. (22) localizer", "valid_precision", 100.0, "%", (1,)),
    ("median position error, eq. (22) localizer", "median_position_error_m", 1000.0, "mm", (1,)),
    ("right link, stacked fit", "fit_correct_link_rate", 100.0, "%", (1,)),
    ("valid precision, stacked fit", "fit_valid_precision", 100.0, "%", (1,)),
    ("median position error, stacked fit", "fit_median_position_error_m", 1000.0, "mm", (1,)),
    ("p95 position error, stacked fit", "fit_p95_position_error_m", 1000.0, "mm", (1,)),
    ('says "more than one contact"', "more_than_one_contact_rate", 100.0, "%", (1, 2)),
    ("both links right", "both_links_right_rate", 100.0, "%", (2,)),
    ("median contact position error", "median_contact_position_error_m", 1000.0, "mm", (2,)),
)


def _floor(text: str | None, scale: float, unit: str) -> str:
    """A metrics file's floor (">= 0.95") in the row's unit (">= 95 %")."""
    if not text:
        return ""
    op, value = text.split()
    return f"{op} {scale * float(value):g} {unit}"


def _station(scenario: dict) -> dict:
    """A results file's station settings (model, seed, world): its scenario's ``station``, or
    the scenario itself in a file written before scenarios nested them."""
    return scenario.get("station", scenario)


def _contact_study(data: dict) -> list[str]:
    scenario = data.get("scenario", {})
    station = _station(scenario)
    contacts = scenario.get("contacts", 1)
    seeds = f"{station.get('seed')}-{station.get('seed', 0) + scenario.get('num_seeds', 1) - 1}"
    lines = [
        f"{data.get('trials')} trials, {'two links pushed at once' if contacts == 2 else 'one contact'} each, "
        f"seeds {seeds}, {'ideal' if station.get('model_refinement') == 'none' else 'realistic'} world; "
        f"false detections: {data.get('false_detections')}",
        "",
        "| metric | value [95 % interval] | floor | met |",
        "| --- | --- | --- | --- |",
    ]
    floors, met = data.get("floors", {}), data.get("meets_floors", {})
    for label, key, scale, unit, studies in CONTACT_STUDY_ROWS:
        if contacts not in studies or data.get(key) is None:
            continue
        checked = met.get(key)
        lines.append(
            f"| {label} | {_with_interval(data, key, scale, unit)} | {_floor(floors.get(key), scale, unit)} | "
            f"{'' if checked is None else ('yes' if checked else '**no**')} |"
        )
    return lines


def _paper_speed(data: dict) -> list[str]:
    return [
        f"| one residual update, {data['model']} ({data['num_joints']} joints) | measured | the paper (HRP-4) |",
        "| --- | --- | --- |",
        f"| classical residual, explicit C(q, q_dot) (the paper's way, O(n^2)) "
        f"| {data['classical_explicit_coriolis_ms']:.2f} ms | {data['paper_classical_ms']:.1f} ms |",
        f"| internal residual, recursive Algorithms 1-2 in Python (O(n)) "
        f"| {data['internal_reference_ms']:.2f} ms | {data['paper_internal_ms']:.1f} ms |",
        f"| internal residual, Drake's C++ (the default) | {data['internal_fast_ms']:.3f} ms | |",
        f"| classical residual, the project's (no explicit C) | {data['classical_project_ms']:.3f} ms | |",
        f"| classical (explicit C) / internal, recursive | "
        f"{data['ratio_classical_explicit_over_internal_reference']:.1f}x | {data['paper_ratio']:.1f}x |",
        f"| classical (explicit C) / internal, Drake's C++ | "
        f"{data['ratio_classical_explicit_over_internal_fast']:.1f}x | |",
    ]


def _residual_comparison(data: dict) -> list[str]:
    world = "ideal" if _station(data.get("scenario", {})).get("model_refinement") == "none" else "realistic"
    rows = (
        ("internal residual vs tau_c,real, all joints", "internal_rel_rms_error"),
        ("classical residual (joint part) vs tau_c,real", "classical_rel_rms_error"),
        ("external residual force vs the applied force", "external_force_rel_rms_error"),
    )
    robot = "" if data.get("model", "hrp4_like") == "hrp4_like" else f"`{data['model']}`, "
    lines = [
        f"| relative RMS error after {data['skip_s']:g} s, {robot}{world} world, seed {data['seed']} | raw "
        "| vs the truth through the residual's filter |",
        "| --- | --- | --- |",
    ]
    for label, key in rows:
        lines.append(f"| {label} | {100 * data[key]:.2f} % | {100 * data[key + '_vs_filtered_truth']:.2f} % |")
    return lines


#: The residual comparison per foot sensing on hrp4_like, realistic world: (results file, label).
RESIDUAL_SENSING_RUNS = (
    ("residual_comparison_realistic", "F/T (measured soles' wrenches)"),
    ("residual_comparison_realistic_fsr", "FSRs (soles' shear and yaw estimated)"),
    ("residual_comparison_realistic_no_ft", "none (soles' wrenches estimated)"),
)


def _residual_comparison_sensing(runs: dict) -> list[str]:
    lines = [
        "| foot sensing | internal residual, all joints | knees (right / left) | external force "
        "| classical (joint part) |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name, label in RESIDUAL_SENSING_RUNS:
        data = runs[name]
        knees = data["internal_rel_rms_error_per_joint"]
        lines.append(
            f"| {label} | {100 * data['internal_rel_rms_error']:.1f} % | {100 * knees['R_KNEE_P']:.1f} / "
            f"{100 * knees['L_KNEE_P']:.1f} % | {100 * data['external_force_rel_rms_error']:.1f} % | "
            f"{100 * data['classical_rel_rms_error']:.0f} % |"
        )
    return lines


def _nao_force_observer(data: dict) -> list[str]:
    components = ("x", "y", "z")
    lines = [
        "| | "
        + " | ".join(f"RMS {c}" for c in components)
        + " | "
        + " | ".join(f"steady {c}" for c in components)
        + " | overshoot | settling | floors met |",
        "| --- " * 10 + "|",
    ]

    def response(summary: dict) -> str:
        if not summary.get("steps"):
            return "- | -"
        settling = summary.get("mean_settling_time_s")
        settled = "not settled" if settling is None else f"{settling:.2f} s"
        return f"{summary['mean_overshoot_percent']:.1f} % | {settled}"

    for key in sorted(k for k in data if k.startswith("experiment_")):
        m = data[key]
        if m.get("fell"):
            lines.append(f"| experiment {key.split('_')[1]} | fell | | | | | | | | no |")
            continue
        rms = " | ".join(f"{m['rms_error_N'][c]:.3f} N" for c in components)
        steady = " | ".join(f"{m['steady_state_error_N'][c]:.3f} N" for c in components)
        step = response(m["step_response"]) if "step_response" in m else "- | -"
        lines.append(f"| experiment {key.split('_')[1]} | {rms} | {steady} | {step} | {_yes(m['meets_floors'])} |")
    if "recordings_step_response" in data:
        real = data["recordings_step_response"]["summary"]
        lines.append(f"| real recordings (authors' observer) | | | | | | | {response(real)} | |")
    return lines


def _met(ok: bool) -> str:
    return "met" if ok else "**not met**"


def _ratio(value: float) -> str:
    return f"{value:.1f}x" if value < 100 else f"{value:.0f}x"


def _not_measured(what: str, option: str) -> list[str]:
    return [f"Not measured in this run ({what}: {option})."]


def _benchmark_floating_base(data: dict) -> list[str]:
    floors, rows = data["floors"], data["floating_base"]
    lines = [
        "| model | joints | CalcMassMatrix, new state (the unit) | CalcMassMatrix, cached kinematics "
        "| `fast` compute | `reference` compute | `fast` J^fb (a point) | reference / fast |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['num_joints']} | {r['calc_mass_matrix_us']:.1f} us "
            f"| {r['calc_mass_matrix_cached_kinematics_us']:.1f} us "
            f"| {r['fast_compute_us']:.1f} us ({_ratio(r['fast_compute_ratio'])}) "
            f"| {r['reference_compute_us']:.0f} us ({_ratio(r['reference_compute_ratio'])}) "
            f"| {r['fast_floating_jacobian_us']:.1f} us ({_ratio(r['fast_floating_jacobian_ratio'])}) "
            f"| {_ratio(r['reference_over_fast'])} |"
        )
    lines += ["", "Floors of the foundation issue:", ""]
    ratio = floors["fast_compute_max_ratio"]
    for r in rows:
        cached = r["fast_compute_us"] / r["calc_mass_matrix_cached_kinematics_us"]
        lines.append(
            f"- `fast` compute <= {ratio:g}x one CalcMassMatrix on {r['model']}: "
            f"{_met(r['fast_compute_ratio'] <= ratio)} ({_ratio(r['fast_compute_ratio'])}; "
            f"{_ratio(cached)} one CalcMassMatrix with cached kinematics)"
        )
    model, limit = floors["fast_compute_floor_model"], floors["fast_compute_max_us"]
    measured = [r for r in rows if r["model"] == model]
    lines.append(
        f"- `fast` compute <= {limit:g} us on {model}: "
        + (
            f"{_met(measured[0]['fast_compute_us'] <= limit)} ({measured[0]['fast_compute_us']:.1f} us)"
            if measured
            else f"not measured in this run (`--model {model}` or `all`)"
        )
    )
    return lines


def _benchmark_residual_update(data: dict) -> list[str]:
    limit = data["floors"]["three_residuals_update_max_us"]
    lines = [
        "| model | F/T sensors (known wrenches) | CalcMassMatrix | three residuals, one update "
        f"| floor <= {limit:g} us |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in data["residual_update"]:
        lines.append(
            f"| {r['model']} | {r['known_wrench_frames']} | {r['calc_mass_matrix_us']:.1f} us "
            f"| {r['three_residuals_update_us']:.1f} us ({_ratio(r['three_residuals_update_ratio'])}) "
            f"| {_met(r['three_residuals_update_us'] <= limit)} |"
        )
    return lines


_PEER_SOURCES = {
    "URDF": "from its URDF (`pin.buildModelFromUrdf`, free-flyer root)",
    "plant": "rebuilt from the Drake plant's joints and inertias (its model is SDFormat only)",
}


def _benchmark_residual_peer(data: dict) -> list[str]:
    rows = data.get("residual_peer", [])
    if not rows:
        return _not_measured("the Pinocchio peer", "`--peer-steps 0`, or neither hrp4_like nor `--model all`")
    floors = data["floors"]
    to_peer, to_unit = floors["residual_bank_max_ratio_to_peer"], floors["residual_bank_max_ratio_to_mass_matrix"]
    lines = [
        "| model | DoF (joints) | known wrench frames | CalcMassMatrix | project bank, three systems "
        "(x CalcMassMatrix) | fused `ResidualBank` | Pinocchio peer | project / peer (three, fused) "
        f"| floors met by the fused bank (<= {to_peer:g}x the peer, <= {to_unit:g}x CalcMassMatrix) "
        "| largest difference |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        fused = r.get("fused_bank_us")
        best_ratio = r["project_over_peer"] if fused is None else min(r["project_over_peer"], r["fused_bank_over_peer"])
        best_unit = r["project_bank_ratio_to_mass_matrix"]
        if fused is not None:
            best_unit = min(best_unit, r["fused_bank_ratio_to_mass_matrix"])
        met = best_ratio <= to_peer and best_unit <= to_unit
        fused_cell = "n/a" if fused is None else f"{fused:.0f} us ({_ratio(r['fused_bank_ratio_to_mass_matrix'])})"
        fused_ratio = "" if fused is None else f", {r['fused_bank_over_peer']:.2f}x"
        lines.append(
            f"| {r['model']} | {r['num_joints']} | {r['known_wrench_frames']} | {r['calc_mass_matrix_us']:.1f} us "
            f"| {r['project_bank_us']:.0f} us ({_ratio(r['project_bank_ratio_to_mass_matrix'])}) | {fused_cell} "
            f"| {r['peer_us']:.0f} us ({_ratio(r['peer_ratio_to_mass_matrix'])}) "
            f"| {r['project_over_peer']:.2f}x{fused_ratio} | {_met(met)} "
            f"| {100 * r['largest_relative_difference']:.2g} % |"
        )
    lines += [
        "",
        "Largest difference: of the classical, internal and external residuals over "
        + ", ".join(
            f"{r['agreement_steps']} updates on {r['model']} ({100 * r['classical_relative_difference']:.2g} %, "
            f"{100 * r['internal_relative_difference']:.2g} %, {100 * r['external_relative_difference']:.2g} %)"
            for r in rows
        )
        + ", relative to the peer's largest entry. The peer's model: "
        + "; ".join(f"{r['model']} {_PEER_SOURCES.get(r['peer_model_source'], r['peer_model_source'])}" for r in rows)
        + ", with the plant's reflected rotor inertia as `model.armature` and its joint damping.",
    ]
    dynamics = {r.get("project_dynamics", "fast") for r in rows}
    lines[-1] += (
        " The project's residuals run on the stations' dynamics: "
        + " and ".join(f"`{d}` ({_DYNAMICS.get(d, d)})" for d in sorted(dynamics))
        + "."
    )
    return lines


#: How each ``FloatingBaseDynamics`` implementation computes the model, for the benchmark tables.
_DYNAMICS = {
    "fast": "Drake's kernels, M-dot by a central difference of two more mass matrices",
    "pinocchio": "Pinocchio's `crba` and `computeCoriolisMatrix` on a model built from the Drake plant",
}


def _benchmark_force_observer(data: dict) -> list[str]:
    r, floor = data["force_observer"], data["floors"]["observer_min_samples_per_s"]
    return [
        f"| recording | samples | samples per second | times real time (60 Hz) | floor >= {floor:,.0f} samples/s |",
        "| --- | --- | --- | --- | --- |",
        f"| {r['recording']} | {r['samples']} | {r['samples_per_s']:,.0f} | {r['samples_per_s'] / 60.0:,.0f} "
        f"| {_met(r['samples_per_s'] >= floor)} |",
    ]


def _benchmark_closed_loop(data: dict) -> list[str]:
    rows, seconds = data["closed_loop"], data["settings"]["loop_seconds"]
    if not rows:
        return _not_measured("the closed loop", "`--loop-seconds 0`")
    lines = [
        f"| loop (hrp4_like, {seconds:g} s simulated, 1 ms steps) | wall per step | CPU per step "
        "| real-time factor | faster than real time |",
        "| --- | --- | --- | --- | --- |",
    ]
    labels = {"Meshcat recording": "the same, with Meshcat recording the replay"}
    for r in rows:
        lines.append(
            f"| {labels.get(r['loop'], r['loop'])} | {r['wall_us_per_step']:.0f} us | {r['cpu_us_per_step']:.0f} us "
            f"| {r['real_time_factor']:.2f} | {_yes(r['real_time_factor'] >= 1.0)} |"
        )
    return [*lines, "", f"Memory allocator of this run: {data.get('memory_allocator', 'not recorded')}."]


def _benchmark_contact_localizer(data: dict) -> list[str]:
    rows, limit = data["contact_localizer"], data["floors"]["localizer_update_max_us"]
    if not rows:
        return _not_measured("the contact localizer", "it runs with `--model hrp4_like` or `all`")
    lines = [
        f"| model | collision primitives | CalcMassMatrix | one update | floor <= {limit / 1000:g} ms |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['num_primitives']} | {r['calc_mass_matrix_us']:.1f} us "
            f"| {r['localizer_update_us']:.0f} us ({_ratio(r['localizer_update_ratio'])}) "
            f"| {_met(r['localizer_update_us'] <= limit)} |"
        )
    return lines


def _benchmark_multi_contact_fit(data: dict) -> list[str]:
    rows = data["multi_contact_fit"]
    if not rows:
        return _not_measured("the one-or-two-contact fit", "`--fit-pairs 0`, or a model other than hrp4_like")
    lines = [
        "| model | two-contact trials | `fit_one`, median | `fit_two`, median | `fit_two`, slowest "
        "| `fit_one` at a new pose |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['pairs']} | {r['fit_one_median_ms']:.1f} ms | {r['fit_two_median_ms']:.1f} ms "
            f"| {r['fit_two_max_ms']:.1f} ms | {r['fit_one_new_pose_ms']:.1f} ms |"
        )
    return lines


def _benchmark_log_estimation(data: dict) -> list[str]:
    rows, floor = data["log_estimation"], data["floors"]["log_estimation_min_real_time_factor"]
    if not rows:
        return _not_measured("the offline estimation", "`--log-seconds 0`, or a model other than hrp4_like")
    lines = [
        "| model | joints | dynamics | log | in contact | per sample | real-time factor "
        f"| floor >= {floor:g}x real time |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['num_joints']} | `{r.get('dynamics', 'fast')}` "
            f"| {r['log_seconds']:.1f} s at {r['log_rate_hz']:.0f} Hz "
            f"| {100 * r['contact_fraction']:.0f} % | {r['us_per_sample']:.0f} us | {r['real_time_factor']:.2f} "
            f"| {_met(r['real_time_factor'] >= floor)} |"
        )
    units = {r["model"]: r["calc_mass_matrix_us"] for r in data["floating_base"]}
    for r in rows:
        if r["model"] in units:
            lines += [
                "",
                f"A log sample costs {r['us_per_sample'] / units[r['model']]:.1f} CalcMassMatrix at a new state "
                f"of the same run ({units[r['model']]:.1f} us), so {floor:g}x real time at "
                f"{r['log_rate_hz']:.0f} Hz needs a CalcMassMatrix of "
                f"{units[r['model']] * 1e6 / (floor * r['log_rate_hz'] * r['us_per_sample']):.1f} us or less "
                "on this machine.",
            ]
    return lines


def _base_state_from_log(data: dict) -> list[str]:
    floors = data["floors"]
    lines = [
        f"| seed | estimator | tilt RMS (<= {floors['tilt_rms_deg']:g} deg) "
        f"| yaw error after 12 s (<= {floors['yaw_error_deg']:g} deg) "
        f"| horizontal drift (<= {floors['drift_percent']:g} % of the distance) "
        f"| velocity RMS walking (<= {floors['velocity_rms_m_s']:g} m/s) |",
        "| --- | --- | --- | --- | --- | --- |",
    ]

    def row(seed, label: str, errors: dict) -> str:
        met = errors["floors_met"]
        cells = {
            "tilt_rms_deg": f"{errors['tilt_rms_deg']:.2f} deg",
            "yaw_error_deg": f"{errors['yaw_error_deg']:+.2f} deg",
            "drift_percent": f"{100 * errors['horizontal_drift_m']:.1f} cm = {errors['drift_percent']:.1f} %",
            "velocity_rms_m_s": f"{errors['velocity_rms_m_s']:.3f} m/s",
        }
        marked = [text if met[name] else f"**{text}**" for name, text in cells.items()]
        return f"| {seed} | {label} | " + " | ".join(marked) + " |"

    for r in data["rows"]:
        lines.append(row(r["seed"], "`apps.estimate_from_log` (the default EKF)", r["front_door"]))
        lines += [row(r["seed"], a["label"], a["errors"]) for a in r["ablations"]]
    settings, first = data["settings"], data["rows"][0]
    lines += [
        "",
        f"The log: {data['robot']} standing {settings['standing_start']:g} s then walking {settings['walking']:g} s "
        f"({first['front_door']['displacement_m']:.2f} m for seed {first['seed']}), {first['log']['samples']} samples "
        f"at {settings['rate_hz']:g} Hz (steps {1e3 * first['log']['step_range_s'][0]:.1f}-"
        f"{1e3 * first['log']['step_range_s'][1]:.1f} ms), {first['log']['channels']}; gyro turn-on bias "
        f"{[round(b, 2) for b in settings['gyro_bias_deg_s']]} deg/s. Bold: a floor missed. "
        + ("Every floor met by the default on every seed." if data["all_floors_met"] else "A floor is missed."),
    ]
    return lines


def _base_state_from_log_readme(data: dict) -> list[str]:
    """The README's short form of ``_base_state_from_log``: the front door's rows only."""
    full = _base_state_from_log(data)
    rows = [line for line in full[2:] if "`apps.estimate_from_log`" in line]
    ablations = {
        a["label"]: max(abs(r["ablations"][i]["errors"]["yaw_error_deg"]) for r in data["rows"])
        for i, a in enumerate(data["rows"][0]["ablations"])
    }
    worst = "; ".join(f"{label}, {value:.1f} deg" for label, value in ablations.items())
    return (
        full[:2]
        + rows
        + [
            "",
            f"The ablations' worst yaw errors: {worst}. Every figure: "
            "[docs/robots.md](docs/robots.md#the-base-state-against-a-truth-make-base-state-from-log).",
        ]
    )


def _benchmark_residual_replay(data: dict) -> list[str]:
    rows = data["residual_replay"]
    if not rows:
        return _not_measured("the residual replay", "`--log-seconds 0`, or a model other than hrp4_like")
    lines = [
        "| model | samples | sample by sample | stacked | speed-up | largest difference |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['samples']} | {r['per_sample_us']:.0f} us | {r['stacked_us']:.0f} us "
            f"| {r['speedup']:.1f}x | {r['largest_difference']:.1e} N m |"
        )
    return lines


def _seconds(value) -> str:
    return "n/a" if value is None else f"{value:.1f} s"


def _factor_range(values: list) -> str:
    values = [v for v in values if v is not None]
    if not values:
        return "n/a"
    low, high = min(values), max(values)
    return f"{low:.2f}" if f"{low:.2f}" == f"{high:.2f}" else f"{low:.2f}-{high:.2f}"


def _run_row(label: str, name: str, data: dict) -> str:
    """A single simulation's row: ``duration_s``, ``wall_time_s``, ``real_time_factor``."""
    return (
        f"| {label} (`{name}`) | {_seconds(data.get('duration_s'))} | {_seconds(data.get('wall_time_s'))} "
        f"| {_factor_range([data.get('real_time_factor')])} |"
    )


def _experiments_row(label: str, name: str, data: dict) -> str:
    """Several simulations in one process (``experiment_<k>``): their sums, and the range of
    their real-time factors."""
    runs = [data[k] for k in sorted(data) if k.startswith("experiment_")]
    simulated = sum(r.get("duration_s", 0.0) for r in runs)
    wall = sum(r.get("wall_time_s", 0.0) for r in runs)
    return (
        f"| {label} (`{name}`): {len(runs)} experiments | {simulated:.1f} s | {wall:.1f} s "
        f"| {_factor_range([r.get('real_time_factor') for r in runs])} per experiment |"
    )


def _study_row(label: str, name: str, data: dict) -> str:
    """A study run in parallel processes: its wall time on its workers; the real-time factor
    of each of its simulations when it records them."""
    rows = data.get("rows", [])
    factors = [row[kind].get("real_time_factor") for row in rows for kind in ("internal", "classical") if kind in row]
    runs = f"{len(factors)} runs" if rows else f"{data.get('trials')} trials"
    phases = data.get("phase_wall_s")
    wall = _seconds(data.get("wall_time_s"))
    if phases:
        named = {k: k.replace("one_or_two_contact", "one-or-two-contact").replace("_", " ") for k in phases}
        wall += " (" + ", ".join(f"{named[k]}: {v:.0f} s" for k, v in phases.items() if v >= 0.5) + ")"
    factor = f"{_factor_range(factors)} per run" if factors else "not recorded"
    return f"| {label} (`{name}`): {runs} on {data.get('workers')} workers | - | {wall} | {factor} |"


#: The experiments whose results files record their wall time: (results file, label, row).
EXPERIMENT_RUNS = (
    ("residual_comparison_realistic", "`make residual-comparison`, realistic world", _run_row),
    ("residual_comparison_ideal", "`make residual-comparison ARGS=--ideal`", _run_row),
    ("nao_force_observer_paper", "`make hawley-settings`, the paper's setting", _experiments_row),
    ("nao_force_observer_steps_wide", "`make hawley-settings`, steps in the wider stance", _experiments_row),
    ("nao_force_observer", "`make nao-force-observer`, the default setting", _experiments_row),
    ("push_and_comply_ablation", "`make paper-settings`", _study_row),
    ("push_and_comply_robots", "`make robots`", _study_row),
    ("contact_study_single", "`make contact`, one contact", _study_row),
    ("contact_study_two", "`make contact ARGS='--contacts 2'`", _study_row),
)


def _experiments_wall_time(sources: dict[str, dict]) -> list[str]:
    lines = [
        "| experiment (results file) | simulated | wall time | real-time factor |",
        "| --- | --- | --- | --- |",
    ]
    for name, label, row in EXPERIMENT_RUNS:
        lines.append(row(label, name, sources[name]))
    return lines


def _test_suite(data: dict) -> list[str]:
    counts = ", ".join(f"{v} {k}" for k, v in data["counts"].items())
    return [
        f"| workers | ruff | pytest | `make test` | tests | floor <= {data['floor_s'] / 60:g} min |",
        "| --- | --- | --- | --- | --- | --- |",
        f"| {data['workers']} | {data['ruff_s']:.1f} s | {data['pytest_s']:.1f} s | {data['wall_s'] / 60:.1f} min "
        f"| {counts} | {_met(data['wall_s'] <= data['floor_s'])} |",
    ]


def _speed(sources: dict[str, dict]) -> list[str]:
    """Issue 33's speed floors, each judged from the results file that measures it."""
    bench, floors = sources["benchmark"], sources["benchmark"]["floors"]
    lines = ["| what (issue 33) | measured | floor | verdict | command |", "| --- | --- | --- | --- | --- |"]

    def row(what: str, measured: str, floor: str, ok: bool | None, command: str) -> None:
        verdict = "not measured" if ok is None else _met(ok)
        lines.append(f"| {what} | {measured} | {floor} | {verdict} | `{command}` |")

    for r in bench["residual_peer"]:
        row(
            f"three residuals in one `ResidualBank` update, {r['model']} ({r['num_joints']} joints), "
            "x the Pinocchio plain-loop peer",
            f"{r['fused_bank_over_peer']:.2f}x",  # two decimals: the floor is 1x
            f"<= {_ratio(floors['residual_bank_max_ratio_to_peer'])}",
            r["fused_bank_over_peer"] <= floors["residual_bank_max_ratio_to_peer"],
            "make benchmark",
        )
        row(
            f"the same, x one CalcMassMatrix at a new state, {r['model']}",
            _ratio(r["fused_bank_ratio_to_mass_matrix"]),
            f"<= {_ratio(floors['residual_bank_max_ratio_to_mass_matrix'])}",
            r["fused_bank_ratio_to_mass_matrix"] <= floors["residual_bank_max_ratio_to_mass_matrix"],
            "make benchmark",
        )
    for r in bench["log_estimation"]:
        floor = floors["log_estimation_speed_min_real_time_factor"]
        row(
            f"offline estimation of a {r['log_rate_hz']:.0f} Hz log, {r['num_joints']} joints, one core "
            f"(`{r.get('dynamics', 'fast')}` dynamics)",
            f"{r['real_time_factor']:.1f}x real time",
            f">= {floor:g}x",
            r["real_time_factor"] >= floor,
            "make benchmark",
        )
    loop = [r for r in bench["closed_loop"] if r["loop"].startswith("push-and-comply")]
    for r in loop:
        floor = floors["closed_loop_min_real_time_factor"]
        row(
            "the main job's closed loop (push-and-comply, internal residual, realistic estimators)",
            f"real-time factor {r['real_time_factor']:.2f}",
            f">= {floor:g}",
            r["real_time_factor"] >= floor,
            "make benchmark",
        )
    for name, label, command in (
        ("contact_study_single", "contact study, single contacts", "make contact"),
        ("contact_study_two", "contact study, two contacts", "make contact ARGS='--contacts 2'"),
    ):
        data, floor = sources[name], floors[f"{name}_max_s"]
        row(
            f"{label}: {data.get('trials')} realistic trials on {data.get('workers', 2)} workers",
            f"{data['wall_time_s'] / 60:.1f} min",
            f"<= {floor / 60:g} min",
            data["wall_time_s"] <= floor,
            command,
        )
    suite = sources["test_suite"]
    row(
        f"`make test` (ruff and {suite['counts'].get('passed', 0)} tests on {suite['workers']} workers)",
        f"{suite['wall_s'] / 60:.1f} min",
        f"<= {suite['floor_s'] / 60:g} min",
        suite["wall_s"] <= suite["floor_s"],
        "make time-tests",
    )
    return lines


def _readme_speed(data: dict) -> list[str]:
    """One sentence for the README's first screen: the main job's real-time factor."""
    floor = data["floors"]["closed_loop_min_real_time_factor"]
    loops = {r["loop"]: r["real_time_factor"] for r in data["closed_loop"]}
    main = next((v for k, v in loops.items() if k.startswith("push-and-comply")), None)
    if main is None:
        return _not_measured("the closed loop", "`--loop-seconds 0`")
    station = next((v for k, v in loops.items() if k.startswith("station")), None)
    verdict = "meets" if main >= floor else "is below"
    sentence = (
        f"Speed: the main job's closed loop runs at real-time factor {main:.2f}, which {verdict} the goal of {floor:g}"
    )
    if station is not None:
        sentence += f" (the simulated robot and its sensors alone: {station:.2f})"
    if data["log_estimation"]:
        factor = data["log_estimation"][0]["real_time_factor"]
        sentence += f"; the offline estimation from a log runs at {factor:.1f}x real time on one core"
    return [sentence + ' ([BENCHMARKS.md](BENCHMARKS.md), "Speed").']


def _interval_text(entry: dict, key: str, scale: float, digits: int) -> str:
    value, interval = entry.get(key), entry.get(f"{key}_interval")
    if value is None:
        return "n/a"
    text = f"{scale * value:.{digits}f}"
    if interval:
        low, high = (scale * v if v is not None and abs(v) != float("inf") else None for v in interval)
        text += f" [{'-' if low is None else f'{low:.{digits}f}'}, {'-' if high is None else f'{high:.{digits}f}'}]"
    return text


def _sweep(data: dict) -> list[str]:
    lines = [
        f"{data['trials']} trials on {data['engine']} with {data['workers']} workers: calibrations "
        f"{data['calibration_wall_s'] / 60:.1f} min, trials {data['trials_wall_s'] / 60:.1f} min, "
        f"{data['wall_time_s'] / 60:.1f} min in all.",
        "",
        "| robot | imperfection draw | noise (x default) | trials | detected % | right link % [95 % interval] "
        "| median position error, cm [95 % interval] | median force error % | calibrated / robot mass, kg |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for e in data["cells"]:
        if not e.get("trials"):
            continue
        force = e.get("median_force_error_rel")
        lines.append(
            f"| {Path(e['robot']).stem} | {e['imperfection_seed']} | {e['noise_scale']:g} | {e['trials']} "
            f"| {100 * e['detection_rate']:.0f} | {_interval_text(e, 'right_link_rate', 100, 0)} "
            f"| {_interval_text(e, 'median_position_error_m', 100, 2)} "
            f"| {'n/a' if force is None else f'{100 * force:.0f}'} | {_masses(e)} |"
        )
    return lines


def _masses(entry: dict) -> str:
    if entry.get("calibrated_mass_kg") is None:
        return "n/a"
    return f"{entry['calibrated_mass_kg']:.2f} / {entry['robot_mass_kg']:.2f}"


def _engine_scaling(data: dict) -> list[str]:
    lines = [
        f"The same {data['trials']}-trial contact study (seed {data['seed']}, realistic world, its runs without "
        f"contact and its one-or-two-contact fits), on a {data['cpu_count']}-core machine:",
        "",
        "| engine | workers | wall time | simulations | same per-trial results as the pool |",
        "| --- | --- | --- | --- | --- |",
    ]
    for run in data["runs"].values():
        lines.append(
            f"| {run['engine']} | {run['workers']} | {run['wall_time_s']:.0f} s "
            f"| {run['phase_wall_s']['simulations']:.0f} s | {_yes(run['same_results_as_pool'])} |"
        )
    d = data["driver"]
    lines += [
        "",
        f"Ray / pool wall time: {data['ray_over_pool']:.3f} (floor <= 1.10: "
        f"{'met' if data['ray_within_10_percent_of_pool'] else '**not met**'}); two workers against one: "
        f"{data['speedup_2_workers']:.2f}x.",
        "",
        f"The driver: Ray's round trip of an empty job {1e3 * d['ray_round_trip_s']:.2f} ms, a chunk's Parquet file "
        f"({d['trials_per_job']} trials) {1e3 * d['chunk_write_s']:.2f} ms: one driver absorbs about "
        f"{d['trials_per_s']:.0f} trials/s.",
        "",
        f"The model (per trial {data['trial_s_one_worker']:.2f} s, per calibration "
        f"{(data['calibration_s_one_worker'] or 0) / 60:.1f} min, one worker; {data['model_workers_per_node']} workers "
        f"per node) for {data['sweep']['cells']} cells x {data['sweep']['trials_per_cell']} trials:",
        "",
        "| nodes | workers | calibrations | trials | wall time | trials/s the driver must absorb |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for m in data["model"]:
        lines.append(
            f"| {m['nodes']} | {m['workers']} | {m['calibration_phase_s'] / 60:.0f} min "
            f"| {m['trial_phase_s'] / 3600:.2f} h | {m['wall_s'] / 3600:.2f} h | {m['trials_per_s_needed']:.1f} |"
        )
    return lines


#: The sensing comparison's studies: (results file, robot, foot sensing).
SENSING_STUDIES = (
    ("contact_study_sensing_ft", "hrp4_like", "F/T"),
    ("contact_study_sensing_fsr", "hrp4_like", "FSR"),
    ("contact_study_sensing_fsr_realistic", "hrp4_like, realistic world", "FSR"),
    ("contact_study_sensing_none", "hrp4_like", "none"),
    ("contact_study_sensing_none_realistic", "hrp4_like, realistic world", "none"),
    ("contact_study_sensing_none_talos", "TALOS", "none"),
)


def _sensing_comparison(sources: dict[str, dict]) -> list[str]:
    """Issue 36's table: single-contact studies with the feet's F/T sensors, with FSRs (the
    soles' normal forces and centres of pressure measured, their shear and yaw moment
    unknowns) and with none (the ground's wrenches unknowns), per body region."""
    lines = [
        "| robot | foot sensing | region | trials | detected | right link, eq. (22) / stacked fit "
        "| median position error, eq. (22) / fit | sole normal force error (RMS, of the weight) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, robot, sensing in SENSING_STUDIES:
        data = sources[name]
        for row in data["per_region"]:
            fit = row.get("fit_correct_link_rate")
            fit_position = row.get("fit_median_position_error_m")
            sole = row.get("foot_normal_force_rms_error_of_weight")
            lines.append(
                f"| {robot} | {sensing} | {row['region']} | {row['trials']} | {100 * row['detection_rate']:.1f} % "
                f"| {100 * row['correct_link_rate']:.1f} / {'n/a' if fit is None else f'{100 * fit:.1f}'} % "
                f"| {100 * row['median_position_error_m']:.2f} / "
                f"{'n/a' if fit_position is None else f'{100 * fit_position:.2f}'} cm "
                f"| {f'measured ({sensing})' if sole is None else f'{100 * sole:.1f} %'} |"
            )
    lines.append("")
    for name, robot, sensing in SENSING_STUDIES:
        data = sources[name]
        text = (
            f"- {robot}, {sensing}: {data['trials']} trials (seeds {data['seeds'][0]}-{data['seeds'][-1]}), false "
            f"detections {data['false_detections']} in {data['no_contact_run_s']:g} s standing and "
            f"{data['slow_motion_run_s']:g} s of slow whole-body motion; valid results "
            f"{100 * data['valid_rate']:.1f} %, of which right {100 * data['valid_precision']:.1f} %"
        )
        valid = data.get("foot_normal_force_rms_error_valid_of_weight")
        if valid is not None:
            text += f"; sole normal force RMS error over the valid ones {100 * valid:.2f} % of the weight"
        lines.append(text + f"; wall time {data['wall_time_s'] / 60:.1f} min.")
    return lines


def _floors_table(data: dict) -> list[str]:
    """A study's floors as its results file judges them: metric, value, floor, met."""
    units = (("_of_weight", 100.0, "% of the weight"), ("_rate", 100.0, "%"), ("precision", 100.0, "%"))
    units += (("_rel", 100.0, "%"), ("_m", 100.0, "cm"), ("_ms", 1.0, "ms"), ("_s", 1000.0, "ms"))
    units += (("_deg", 1.0, "deg"),)

    def unit_of(key: str) -> tuple[float, str]:
        for part, scale, unit in units:
            if key.endswith(part) or (part in ("_rate", "precision") and part in key):
                return scale, unit
        return 1.0, ""

    lines = [
        f"{data.get('model')}: {data.get('trials')} trials, {data.get('contacts', 1)} contact(s) each",
        "",
        "| metric | value | floor | met |",
        "| --- | --- | --- | --- |",
    ]
    met = data.get("meets_floors", {})
    for key, text in data.get("floors", {}).items():
        scale, unit = unit_of(key)
        value = data.get(key)
        shown = "n/a" if value is None else f"{scale * value:.4g} {unit}".strip()
        op, floor = text.split()
        checked = met.get(key)
        lines.append(
            f"| {key} | {shown} | {f'{op} {scale * float(floor):g} {unit}'.strip()} | "
            f"{'not judged' if checked is None else ('yes' if checked else '**no**')} |"
        )
    return lines


#: NAME -> the table's lines from the results file's ``data`` (or, for a block with several
#: ``SOURCES``, from {results file name: its ``data``}).
RENDERERS: dict[str, Callable[[dict], list[str]]] = {
    "push_and_comply_ablation": _push_and_comply_ablation,
    "push_and_comply_robots": _push_and_comply_robots,
    "push_and_comply_sensing": _push_and_comply_sensing,
    "paper_speed": _paper_speed,
    "residual_comparison_realistic": _residual_comparison,
    "residual_comparison_ideal": _residual_comparison,
    "residual_comparison_sensing": _residual_comparison_sensing,
    "residual_comparison_realistic_no_ft": _residual_comparison,
    "residual_comparison_realistic_fsr": _residual_comparison,
    "contact_study_single": _contact_study,
    "contact_study_two": _contact_study,
    "nao_force_observer": _nao_force_observer,
    "nao_force_observer_paper": _nao_force_observer,
    "nao_force_observer_steps_wide": _nao_force_observer,
    "benchmark_floating_base": _benchmark_floating_base,
    "benchmark_residual_update": _benchmark_residual_update,
    "benchmark_residual_peer": _benchmark_residual_peer,
    "benchmark_force_observer": _benchmark_force_observer,
    "benchmark_closed_loop": _benchmark_closed_loop,
    "benchmark_contact_localizer": _benchmark_contact_localizer,
    "benchmark_multi_contact_fit": _benchmark_multi_contact_fit,
    "benchmark_log_estimation": _benchmark_log_estimation,
    "benchmark_residual_replay": _benchmark_residual_replay,
    "base_state_from_log": _base_state_from_log,
    "base_state_from_log_readme": _base_state_from_log_readme,
    "experiments_wall_time": _experiments_wall_time,
    "speed": _speed,
    "readme_speed": _readme_speed,
    "test_suite": _test_suite,
    "sweep_small": _sweep,
    "engine_scaling": _engine_scaling,
    "sensing_comparison": _sensing_comparison,
    **{name: _floors_table for name, _, _ in SENSING_STUDIES},
}

#: The results files of the blocks that do not read ``results/<NAME>.json``: one file (the
#: renderer gets its ``data``) or several (the renderer gets {file name: its ``data``}).
SOURCES: dict[str, tuple[str, ...]] = {
    **{name: ("benchmark",) for name in RENDERERS if name.startswith("benchmark_")},
    "experiments_wall_time": tuple(name for name, _, _ in EXPERIMENT_RUNS),
    "base_state_from_log_readme": ("base_state_from_log",),
    "speed": ("benchmark", "contact_study_single", "contact_study_two", "test_suite"),
    "readme_speed": ("benchmark",),
    "sensing_comparison": tuple(name for name, _, _ in SENSING_STUDIES),
    "residual_comparison_sensing": tuple(name for name, _ in RESIDUAL_SENSING_RUNS),
}


def sources(name: str) -> tuple[str, ...]:
    """The results files the block ``name`` is generated from."""
    return SOURCES.get(name, (name,))


def render(name: str, folder: Path | None = None) -> str:
    """The block body of ``name``: its table, then the command and date of its results file.

    Raises:
        ValueError: no renderer for ``name``, or its results file cannot be read.
    """
    if name not in RENDERERS:
        raise ValueError(f"no table is generated under the name {name!r}; known: {sorted(RENDERERS)}")
    payloads = {source: load_results(source, folder) for source in sources(name)}
    if len(payloads) == 1:
        ((source, payload),) = payloads.items()
        lines = RENDERERS[name](payload["data"])
        lines += ["", provenance("Measured by", source, payload) + "."]
    else:
        lines = RENDERERS[name]({source: payload["data"] for source, payload in payloads.items()})
        lines += ["", "Measured by:", ""]
        lines += [provenance("-", source, payload) for source, payload in payloads.items()]
    return "\n".join(lines) + "\n"


def updated(text: str, folder: Path | None = None) -> tuple[str, list[str]]:
    """``text`` with every block regenerated, and the names of the blocks that changed."""
    return regenerated_blocks(_BLOCK, text, lambda name: render(name, folder))


def block_names(text: str) -> list[str]:
    """The names of the generated blocks in ``text``."""
    return [m["name"] for m in _BLOCK.finditer(text)]


def main(argv: list[str] | None = None) -> int:
    """Rewrites (or with ``--check`` reports) the stale blocks; exit 2 with a one-line
    message when a results file is missing or unreadable, before any document is written."""
    from apps.runner import run_app

    parser = argparse.ArgumentParser(prog="python -m apps.doc_tables", description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="report stale blocks (exit 1), change nothing")
    args = parser.parse_args(argv)

    def body() -> int:
        stale, rewritten = stale_documents(DOCUMENTS, updated, ROOT)
        if not args.check:
            for path, text in rewritten.items():
                path.write_text(text)
        verb = "stale" if args.check else "rewritten"
        print("\n".join(f"{verb}: {s}" for s in stale) if stale else "every generated table is up to date")
        return 1 if (stale and args.check) else 0

    return run_app("doc_tables", body)


if __name__ == "__main__":
    raise SystemExit(main())
