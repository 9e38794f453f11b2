"""Speed of the floating-base decomposition (Flacco et al. eq. 9, Algorithms 1-2, eq. 13).

Run: ``make benchmark`` (= ``python -m apps.benchmark --results benchmark``; the figures also
go to ``OUT/benchmark/metrics.json``, ``--out OUT``, default ``out``). ``--results NAME``
writes them, with the floors they are checked against and the command, to
``results/NAME.json`` (``apps.results``), from which BENCHMARKS.md's tables and verdicts are
generated (``make docs``). For each humanoid model it prints the microseconds per call of

* one ``CalcMassMatrix`` after a new state (``SetPositions`` + ``CalcMassMatrix``): the unit,
  since every estimator step sees a new state; for reference, also one ``CalcMassMatrix``
  on an unchanged context (kinematics cached: the C++ composite-body pass alone);
* ``FloatingBaseDynamics.compute`` with the ``fast`` and ``reference`` implementations (the
  whole decomposition: H, F, I0c, C^, p^, their derivatives, H_fb, H_fb_dot, C_fb);
* ``floating_jacobian`` of a point (fast);

each as a ratio to the ``CalcMassMatrix`` unit measured in the same run, so that the ratios
hold on a noisy machine. Each figure is the median over several batches at random states.

The three residuals (classical, internal, external; one shared model) are timed per update,
and, on ``hrp4_like`` and TALOS (``--model all``), beside their obvious peer (issue 33): the
same residuals as a plain loop on Pinocchio's C++ kernels
(``systems.residuals.pinocchio_peer``), with the ratio project / peer and the largest
relative difference of their outputs over ``--peer-steps`` updates of one input sequence.

It also times the push-and-comply closed loop (``hrp4_like``, 1 ms steps, the scenario's
contact solver, its first ``--loop-seconds`` with the push moved to start at once): the
station alone (plant with contact, sensors, PD + gravity; constant posture), the whole internal-residual loop, and
the same with Meshcat recording its replay: microseconds of wall and CPU time per step and
the real-time factor; the Kalman force observer's throughput on a real Nao recording (the
authors' ``Force_Y_data``, shipped in ``data/hawley2019-nao``; ``HCO_SHARED_DIR`` moves it, see
``systems.observer.nao_dataset``: a missing recording stops the run with an error naming the
path); one update of the contact localizer (Flacco et al. Sec. VI) on ``hrp4_like``; the
one-or-two-contact fit (``MultiContactLocalizer.fit_one`` and ``fit_two``, ``--fit-pairs``
two-contact trials' exact inputs at the standing pose); and the
offline estimation from a 1 kHz ``hrp4_like`` log (``--log-seconds``, issue 14: residuals,
force, detector and localizer on one core), as its real-time factor; and, on the same log,
the calibration's replay of the three residuals (``replay_residuals`` with the classical
one, as ``calibrate_from_log`` runs it): sample by sample and stacked.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from apps.results import app_command, write_results
from apps.runner import (
    add_out_argument,
    memory_allocator,
    non_negative_float,
    non_negative_int,
    output_folder,
    positive_float,
    positive_int,
    print_written,
    run_app,
    write_metrics,
)
from diagrams.station.humanoid_station import ONLINE_DYNAMICS
from models import MODEL_NAMES, MODELS_DIR, add_humanoid
from systems.dynamics.floating_base import FloatingBaseDynamics
from systems.residuals.momentum_residuals import (
    ClassicalResidual,
    ExternalResidual,
    InternalResidual,
    ResidualBank,
    ResidualModel,
)

EXPERIMENT = "benchmark"

#: The issues' floors the figures are checked against: written into the results file beside
#: the measurements, so that BENCHMARKS.md's verdicts are computed from both (apps.doc_tables).
FLOORS = {
    # The foundation issue: FloatingBaseDynamics.compute ("fast") per call.
    "fast_compute_max_ratio": 12.0,  # x one CalcMassMatrix at a new state, measured in the same run
    "fast_compute_max_us": 60.0,  # on the model below
    "fast_compute_floor_model": "hrp4_like",
    # The residual estimators' issue: classical + internal + external, one update.
    "three_residuals_update_max_us": 100.0,
    # Issue 33: the three residuals' bank against the same residuals as a plain loop on
    # Pinocchio (benchmark_residual_peer), per update; goal 0.5x the peer.
    "residual_bank_max_ratio_to_peer": 1.0,
    "residual_bank_max_ratio_to_mass_matrix": 6.0,  # x one CalcMassMatrix at a new state, same run
    # The Kalman force observer's throughput on a real recording.
    "observer_min_samples_per_s": 20000.0,
    # The contact localizer (Flacco et al. Sec. VI): one update.
    "localizer_update_max_us": 2000.0,
    # Issue 14: offline estimation from a 1 kHz log, one core.
    "log_estimation_min_real_time_factor": 5.0,
    # Issue 33's speed floors that BENCHMARKS.md's "Speed" table judges (apps.doc_tables):
    # the offline estimation, the main job's closed loop (2 cores), the contact studies'
    # wall time on 2 workers (results/contact_study_*.json; make test's: time_test_suite).
    "log_estimation_speed_min_real_time_factor": 20.0,
    "closed_loop_min_real_time_factor": 1.0,
    "contact_study_single_max_s": 300.0,
    "contact_study_two_max_s": 480.0,
}


def _median_microseconds(call: Callable[[int], object], calls: int, batches: int) -> float:
    """Median over ``batches`` of the mean time of ``calls`` calls of ``call(i)`` [us]."""
    call(0)  # warm up
    samples = []
    for _ in range(batches):
        start = time.perf_counter()
        for i in range(calls):
            call(i)
        samples.append((time.perf_counter() - start) / calls * 1e6)
    return statistics.median(samples)


def _interleaved_median_microseconds(
    calls_by_name: dict[str, Callable[[int], object]], calls: int, batches: int
) -> dict[str, float]:
    """``_median_microseconds`` of several functions, their batches interleaved (one batch of
    each in turn), so that a change of the machine's load during the run falls on all."""
    samples: dict[str, list[float]] = {name: [] for name in calls_by_name}
    for call in calls_by_name.values():
        call(0)  # warm up
    for _ in range(batches):
        for name, call in calls_by_name.items():
            start = time.perf_counter()
            for i in range(calls):
                call(i)
            samples[name].append((time.perf_counter() - start) / calls * 1e6)
    return {name: statistics.median(values) for name, values in samples.items()}


def _random_states(plant: MultibodyPlant, count: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    context = plant.CreateDefaultContext()
    q0 = plant.GetPositions(context)
    states = []
    for _ in range(count):
        q = q0.copy()
        quaternion = rng.normal(size=4)
        q[:4] = quaternion / np.linalg.norm(quaternion)
        q[4:7] = rng.uniform(-1, 1, 3)
        q[7:] = rng.uniform(-0.5, 0.5, plant.num_positions() - 7)
        states.append((q, rng.normal(size=plant.num_velocities())))
    return states


def benchmark_model(name: str, *, calls: int = 300, batches: int = 7, reference_calls: int = 10) -> dict:
    """Timings [us] and ratios to one CalcMassMatrix for one humanoid model."""
    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, name)
    plant.Finalize()
    states = _random_states(plant, 16, seed=0)
    context = plant.CreateDefaultContext()
    fast = FloatingBaseDynamics(plant, "fast")
    reference = FloatingBaseDynamics(plant, "reference")
    hand_frame = handles.shoulder_bodies["right"].body_frame()
    point = np.array([0.0, 0.0, 0.05])

    def mass_matrix(i: int):
        plant.SetPositions(context, states[i % 16][0])
        return plant.CalcMassMatrix(context)

    def fast_compute(i: int):
        return fast.compute(*states[i % 16])

    def reference_compute(i: int):
        return reference.compute(*states[i % 16])

    def fast_jacobian(i: int):
        return fast.floating_jacobian(states[i % 16][0], hand_frame, point)

    def mass_matrix_cached(i: int):
        return plant.CalcMassMatrix(context)

    unit = _median_microseconds(mass_matrix, calls, batches)
    results = {
        "model": name,
        "num_joints": fast.num_joints,
        "calc_mass_matrix_us": unit,
        "calc_mass_matrix_cached_kinematics_us": _median_microseconds(mass_matrix_cached, calls, batches),
        "fast_compute_us": _median_microseconds(fast_compute, calls, batches),
        "reference_compute_us": _median_microseconds(reference_compute, reference_calls, batches),
        "fast_floating_jacobian_us": _median_microseconds(fast_jacobian, calls, batches),
    }
    for key in ("fast_compute", "reference_compute", "fast_floating_jacobian"):
        results[key + "_ratio"] = results[key + "_us"] / unit
    results["reference_over_fast"] = results["reference_compute_us"] / results["fast_compute_us"]
    return results


def _project_residual_bank(plant: MultibodyPlant, frames, torque: np.ndarray, wrenches: np.ndarray, x0: np.ndarray):
    """The project's classical, internal and external residuals sharing one ResidualModel
    (gain 35 1/s, 1 ms), each with a context whose torque and wrench inputs are fixed; returns
    (residuals, contexts, the fixed state input values). The model's dynamics are the
    stations' (``ONLINE_DYNAMICS``)."""
    model = ResidualModel(plant, ONLINE_DYNAMICS)
    residuals = [
        ClassicalResidual(plant, 35.0, known_wrench_frames=frames, model=model),
        InternalResidual(plant, 35.0, known_wrench_frames=frames, model=model),
        ExternalResidual(plant, 35.0, known_wrench_frames=frames, model=model),
    ]
    contexts = []
    for residual in residuals:  # the same sensor signals feed all three, as in a diagram
        context = residual.CreateDefaultContext()
        if residual.HasInputPort("measured_torque"):
            residual.GetInputPort("measured_torque").FixValue(context, torque)
        if frames:
            residual.GetInputPort("known_wrenches").FixValue(context, wrenches)
        contexts.append(context)
    fixed = [residual.GetInputPort("state").FixValue(context, x0) for residual, context in zip(residuals, contexts)]
    return residuals, contexts, fixed


def benchmark_residual_update(name: str, *, calls: int = 200, batches: int = 7) -> dict:
    """One update of the classical, internal and external residuals (sharing one
    ResidualModel, with the humanoid's F/T sensors as known wrenches) at a new state [us]."""
    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, name)
    plant.Finalize()
    states = _random_states(plant, 16, seed=1)
    n = plant.num_velocities() - 6
    frames = tuple(handles.ft_sensor_frames.values())
    rng = np.random.default_rng(2)
    torque, wrenches = rng.normal(size=n), rng.normal(size=6 * len(frames))
    residuals, contexts, fixed = _project_residual_bank(plant, frames, torque, wrenches, np.concatenate(states[0]))
    full_states = [np.concatenate(s) for s in states]

    def update_all(i: int):
        x = full_states[i % 16]
        for residual, context, value in zip(residuals, contexts, fixed):
            value.GetMutableData().set_value(x)
            residual.EvalUniquePeriodicDiscreteUpdate(context)

    context = plant.CreateDefaultContext()

    def mass_matrix(i: int):
        plant.SetPositions(context, states[i % 16][0])
        return plant.CalcMassMatrix(context)

    unit = _median_microseconds(mass_matrix, calls, batches)
    update = _median_microseconds(update_all, calls, batches)
    return {
        "model": name,
        "known_wrench_frames": len(frames),
        "calc_mass_matrix_us": unit,
        "three_residuals_update_us": update,
        "three_residuals_update_ratio": update / unit,
    }


#: The robots of the residual bank's comparison with its Pinocchio peer: the built-in model and
#: the public URDF robot, both with two ankle F/T sensors (name, add_humanoid's argument).
PEER_ROBOTS = (("hrp4_like", "hrp4_like"), ("talos", str(MODELS_DIR / "robots" / "talos.yaml")))


def _relative_difference(ours: list[np.ndarray], peer: list[np.ndarray]) -> float:
    """max_k |ours_k - peer_k|_inf / max_k |peer_k|_inf over a sequence of residuals (the
    absolute difference when the peer's are all zero: a single, first update)."""
    scale = max(float(np.abs(p).max()) for p in peer)
    difference = max(float(np.abs(a - b).max()) for a, b in zip(ours, peer))
    return difference / scale if scale > 0.0 else difference


def benchmark_residual_peer(robot: str, *, calls: int = 150, batches: int = 7, steps: int = 200) -> dict:
    """The project's three residuals against the obvious peer (issue 33): the same residuals
    as a plain loop on Pinocchio (``systems.residuals.pinocchio_peer``), on ``robot`` (a
    built-in name or a description YAML) with its F/T sensors as known wrenches.

    Timed exactly as ``benchmark_residual_update`` (the same 16 random states, changing at
    every call, the same torques and wrenches; their batches interleaved with those of the
    unit, ``_interleaved_median_microseconds``), after one update (both take their
    steady-state branch): the project's bank (three Drake systems sharing one ResidualModel),
    the fused ``ResidualBank`` (the same three in one system) and the peer's ``step`` (its
    inputs in Pinocchio's coordinates, converted beforehand as a Pinocchio user's sensors
    would give them), with one CalcMassMatrix at a new state as
    the unit. Then ``steps`` updates of both on one sequence of random states, torques and
    wrenches, from the first update: the largest relative difference of each residual
    (max over the steps of the largest entry's difference / the largest entry of the peer's
    residual over the steps), and of the joint-space mass matrix at a state (the peer's model
    against the plant's: armature, inertias)."""
    from systems.residuals.pinocchio_peer import (
        PinocchioResidualPeer,
        PlantCoordinates,
        peer_model_from_plant,
        peer_model_from_urdf,
        plant_joint_parameters,
    )

    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, robot)
    plant.Finalize()
    frames = tuple(handles.ft_sensor_frames.values())
    armature, damping = plant_joint_parameters(plant)
    urdf = handles.description.model_file if handles.description is not None else None
    if urdf is not None and urdf.suffix.lower() == ".urdf":
        pin_model, pin_damping = peer_model_from_urdf(urdf, armature, damping)
        source = "URDF"
    else:
        pin_model, pin_damping = peer_model_from_plant(plant, armature, damping)
        source = "plant"
    coordinates = PlantCoordinates(plant, pin_model)

    def make_peer():
        return PinocchioResidualPeer(pin_model, [f.name() for f in frames], pin_damping, (35.0, 35.0, 35.0), 1e-3)

    # Timing: benchmark_residual_update's states and inputs.
    states = _random_states(plant, 16, seed=1)
    n = plant.num_velocities() - 6
    rng = np.random.default_rng(2)
    torque, wrenches = rng.normal(size=n), rng.normal(size=6 * len(frames))
    full_states = [np.concatenate(s) for s in states]
    residuals, contexts, fixed = _project_residual_bank(plant, frames, torque, wrenches, full_states[-1])
    for residual, context in zip(residuals, contexts):
        context.SetDiscreteState(residual.EvalUniquePeriodicDiscreteUpdate(context))

    def update_all(i: int):
        x = full_states[i % 16]
        for residual, context, value in zip(residuals, contexts, fixed):
            value.GetMutableData().set_value(x)
            residual.EvalUniquePeriodicDiscreteUpdate(context)

    peer = make_peer()
    pin_states = [coordinates.state(x) for x in full_states]
    pin_torque = coordinates.joints_to_pin(torque)
    peer.step(*pin_states[-1], pin_torque, wrenches)

    def peer_step(i: int):
        q, v = pin_states[i % 16]
        return peer.step(q, v, pin_torque, wrenches)

    plant_context = plant.CreateDefaultContext()

    def mass_matrix(i: int):
        plant.SetPositions(plant_context, states[i % 16][0])
        return plant.CalcMassMatrix(plant_context)

    bank = ResidualBank(plant, 35.0, known_wrench_frames=frames, implementation=ONLINE_DYNAMICS)
    bank_context = bank.CreateDefaultContext()
    bank.GetInputPort("measured_torque").FixValue(bank_context, torque)
    if frames:
        bank.GetInputPort("known_wrenches").FixValue(bank_context, wrenches)
    bank_state = bank.GetInputPort("state").FixValue(bank_context, full_states[-1])
    bank_context.SetDiscreteState(bank.EvalUniquePeriodicDiscreteUpdate(bank_context))

    def update_bank(i: int):
        bank_state.GetMutableData().set_value(full_states[i % 16])
        bank.EvalUniquePeriodicDiscreteUpdate(bank_context)

    timings = _interleaved_median_microseconds(
        {"unit": mass_matrix, "project": update_all, "fused": update_bank, "peer": peer_step}, calls, batches
    )
    unit, project, peer_us = timings["unit"], timings["project"], timings["peer"]

    # Agreement: both from their first update on one sequence of inputs.
    rng = np.random.default_rng(3)
    sequence = _random_states(plant, steps, seed=4)
    residuals, contexts, fixed = _project_residual_bank(plant, frames, torque, wrenches, full_states[0])
    torque_ports = [r.GetInputPort("measured_torque") if r.HasInputPort("measured_torque") else None for r in residuals]
    peer = make_peer()
    ours: dict[str, list] = {"classical": [], "internal": [], "external": [], "external_world": []}
    theirs: dict[str, list] = {key: [] for key in ours}
    for q, v in sequence:
        x = np.concatenate((q, v))
        tau, w = 20.0 * rng.normal(size=n), 20.0 * rng.normal(size=6 * len(frames))
        for residual, context, port in zip(residuals, contexts, torque_ports):
            residual.GetInputPort("state").FixValue(context, x)
            if port is not None:
                port.FixValue(context, tau)
            if frames:
                residual.GetInputPort("known_wrenches").FixValue(context, w)
            context.SetDiscreteState(residual.EvalUniquePeriodicDiscreteUpdate(context))
        ours["classical"].append(residuals[0].GetOutputPort("residual").Eval(contexts[0]).copy())
        ours["internal"].append(residuals[1].GetOutputPort("residual").Eval(contexts[1]).copy())
        ours["external"].append(residuals[2].GetOutputPort("external_wrench_base").Eval(contexts[2]).copy())
        ours["external_world"].append(residuals[2].GetOutputPort("external_wrench_world").Eval(contexts[2]).copy())
        step = coordinates.residuals_to_drake(peer.step(*coordinates.state(x), coordinates.joints_to_pin(tau), w))
        for key, value in zip(theirs, step):
            theirs[key].append(value)
    difference = {key: _relative_difference(ours[key], theirs[key]) for key in ours}

    # The peer's model against the plant's: the joint-space inertia H (armature included).
    q_pin, _ = coordinates.state(full_states[0])
    import pinocchio as pin

    H_pin = pin.crba(pin_model, pin_model.createData(), q_pin)[6:, 6:]
    plant.SetPositions(plant_context, states[0][0])
    H_drake = plant.CalcMassMatrix(plant_context)[6:, 6:]
    order = np.empty(n, dtype=int)
    order[coordinates.joint_drake] = coordinates.joint_pin
    H_pin = H_pin[np.ix_(order, order)]  # Drake's joint order
    return {
        "model": robot if robot in MODEL_NAMES else handles.name,
        "num_joints": n,
        "known_wrench_frames": len(frames),
        "peer_model_source": source,
        "project_dynamics": ONLINE_DYNAMICS,
        "calc_mass_matrix_us": unit,
        "project_bank_us": project,
        "fused_bank_us": timings["fused"],
        "fused_bank_over_peer": timings["fused"] / peer_us,
        "fused_bank_ratio_to_mass_matrix": timings["fused"] / unit,
        "peer_us": peer_us,
        "project_bank_ratio_to_mass_matrix": project / unit,
        "peer_ratio_to_mass_matrix": peer_us / unit,
        "project_over_peer": project / peer_us,
        "agreement_steps": steps,
        "classical_relative_difference": difference["classical"],
        "internal_relative_difference": difference["internal"],
        "external_relative_difference": max(difference["external"], difference["external_world"]),
        "largest_relative_difference": max(difference.values()),
        "mass_matrix_relative_difference": float(np.abs(H_pin - H_drake).max() / np.abs(H_drake).max()),
    }


def benchmark_force_observer(batches: int = 5, dataset_dir: Path | None = None) -> dict:
    """Samples per second of the Kalman force observer core on a real Nao recording (the
    authors' Force_Y_data, shipped in data/hawley2019-nao; ``dataset_dir`` defaults to
    ``systems.observer.nao_dataset.published_dataset_dir()``).

    Raises:
        systems.observer.nao_dataset.DatasetError: the recording is missing or unreadable.
    """
    from systems.observer.force_observer import calibrated_normal_force, estimate_virtual_forces
    from systems.observer.nao_dataset import load_recording, published_dataset_dir

    dataset = (published_dataset_dir() if dataset_dir is None else Path(dataset_dir)) / "Force_Y_data"
    data = load_recording(dataset)
    normal_force = calibrated_normal_force(data["total_force"].sum(axis=1))
    samples = []
    for _ in range(batches):
        start = time.perf_counter()
        estimate_virtual_forces(data["Xc_Yc_Zc"], data["acc"], data["ZMP"], normal_force)
        samples.append(len(normal_force) / (time.perf_counter() - start))
    return {"recording": dataset.name, "samples_per_s": statistics.median(samples), "samples": len(normal_force)}


#: The closed loop's timed seconds are split into this many segments (``benchmark_closed_loop``).
CLOSED_LOOP_SEGMENTS = 5


def benchmark_closed_loop(seconds: float = 2.0) -> list[dict]:
    """Wall and CPU (this thread) time per 1 ms step of the push-and-comply loop and parts: the
    station alone (the ideal station: sensors with noise, PD + gravity, constant posture), and
    the scenario's closed loop (its default world's estimators: the invariant EKF and the
    realistic imperfections, with the nominal model: no calibration is run) without and with
    Meshcat recording. Each is simulated for ``seconds`` (> 0.05 s): 0.05 s of warm-up, then
    ``CLOSED_LOOP_SEGMENTS`` timed segments, of which the median is reported."""
    if not seconds > 0.05:
        raise ValueError(f"the closed loop's --loop-seconds must exceed its 0.05 s warm-up, got {seconds}")
    from pydrake.geometry import Meshcat
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource

    from diagrams.residuals.push_and_comply import PushAndComplyScenario, build_push_and_comply_diagram
    from diagrams.simulation import start_simulation
    from diagrams.station.config import StationConfig
    from diagrams.station.humanoid_station import add_humanoid_station

    scenario = PushAndComplyScenario(
        duration=seconds, tare_duration=0.0, push_start=0.0, push_peak_time=0.6 * seconds, push_end=seconds
    )

    def station_only():
        builder = DiagramBuilder()
        ideal = StationConfig(model=scenario.station.model, plant_config=scenario.station.plant_config)
        station = add_humanoid_station(builder, ideal)
        posture = builder.AddSystem(ConstantVectorSource(station.q_hold))
        builder.Connect(posture.get_output_port(), station.desired_position)
        return builder.Build(), station, None

    def loop(meshcat):
        def build():
            diagram, handles = build_push_and_comply_diagram(scenario, "internal", meshcat)
            return diagram, handles.station, meshcat

        return build

    rows = []
    meshcat = Meshcat()
    for label, build in (
        ("station: plant + sensors + PD", station_only),
        ("push-and-comply, internal residual", loop(None)),
        ("  + Meshcat recording", loop(meshcat)),
    ):
        diagram, station, recorder = build()
        if recorder is not None:
            recorder.StartRecording(frames_per_second=32.0)
        # ``start_simulation``, not ``simulate``: only the steps after the warm-up are timed.
        simulator = start_simulation(diagram, set_initial_state=station.set_initial_state)
        simulator.AdvanceTo(0.05)  # warm-up: caches, first contact
        # The timed part in CLOSED_LOOP_SEGMENTS equal segments; the median segment's time
        # (a transient hiccup of a shared machine then moves the figure by no more than it
        # moves one segment).
        ends = np.linspace(0.05, seconds, CLOSED_LOOP_SEGMENTS + 1)[1:]
        walls, cpus = [], []
        for end in ends:
            wall, cpu = time.perf_counter(), time.thread_time()
            simulator.AdvanceTo(end)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.thread_time() - cpu)
        if recorder is not None:
            recorder.StopRecording()
            recorder.DeleteRecording()
            recorder.Delete()
        segment = (seconds - 0.05) / CLOSED_LOOP_SEGMENTS
        wall, cpu = float(np.median(walls)), float(np.median(cpus))
        steps = segment / 1e-3
        rows.append(
            {
                "loop": label.strip(" +"),
                "wall_us_per_step": wall / steps * 1e6,
                "cpu_us_per_step": cpu / steps * 1e6,
                "real_time_factor": segment / wall,
                "segments": CLOSED_LOOP_SEGMENTS,
            }
        )
        rows[-1]["label"] = label
    return rows


def benchmark_contact_localizer(model: str = "hrp4_like", *, calls: int = 100, batches: int = 7, seed: int = 0) -> dict:
    """One full ContactLocalizer update (line of action, all primitives, buried-point test,
    scores) at a new sensed state, for the lines of 16 random contacts of the study, in us
    and as a ratio to one CalcMassMatrix after a new state measured in the same run (the
    unit of ``apps.benchmark``). For ``make benchmark``; the issue's floor is 2 ms."""
    from diagrams.residuals.contact_study import (
        ContactLocalizationScenario,
        build_contact_localization_diagram,
        sample_trials,
    )
    from diagrams.station.config import StationConfig

    _, handles = build_contact_localization_diagram(
        ContactLocalizationScenario(station=StationConfig.realistic(model=model, noise=False))
    )
    plant, localizer = handles.plant, handles.localizer
    x0 = handles.station.initial_state
    nq = plant.num_positions()
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, x0)
    dynamics = FloatingBaseDynamics(plant)
    inputs = []
    for spec in sample_trials(model, 16, seed):
        body = plant.GetBodyByName(spec["body"])
        f = np.asarray(spec["force_world"])
        p_W = plant.EvalBodyPoseInWorld(context, body).multiply(np.asarray(spec["point_body"]))
        tau = dynamics.floating_jacobian(x0[:nq], body.body_frame(), np.asarray(spec["point_body"])).T @ f
        inputs.append((np.concatenate((np.cross(p_W, f), f)), tau))
    probe = localizer.CreateDefaultContext()
    state = localizer.GetInputPort("state").FixValue(probe, x0)
    wrench = localizer.GetInputPort("external_wrench_world").FixValue(probe, inputs[0][0])
    residual = localizer.GetInputPort("residual").FixValue(probe, inputs[0][1])
    localizer.GetInputPort("contact_detected").FixValue(probe, [1.0])
    rng = np.random.default_rng(seed)
    states = []
    for _ in range(16):
        x = x0.copy()
        x[7:nq] += 1e-6 * rng.normal(size=nq - 7)  # a new q: no pose or mass matrix reused
        states.append(x)

    def update(i: int):
        state.GetMutableData().set_value(states[i % 16])
        wrench.GetMutableData().set_value(inputs[i % 16][0])
        residual.GetMutableData().set_value(inputs[i % 16][1])
        return localizer.EvalUniquePeriodicDiscreteUpdate(probe)

    def mass_matrix(i: int):
        plant.SetPositions(context, states[i % 16][:nq])
        return plant.CalcMassMatrix(context)

    unit = _median_microseconds(mass_matrix, calls, batches)
    update_us = _median_microseconds(update, calls, batches)
    return {
        "model": model,
        "num_primitives": len(localizer.geometry),
        "calc_mass_matrix_us": unit,
        "localizer_update_us": update_us,
        "localizer_update_ratio": update_us / unit,
    }


def benchmark_multi_contact_fit(model: str = "hrp4_like", *, pairs: int = 10, seed: int = 51) -> dict:
    """``MultiContactLocalizer.fit_one`` and ``fit_two`` (the study's one-or-two-contact fit)
    on the exact inputs of ``pairs`` two-contact trials of the study (``sample_trials``), at
    the standing pose after its precomputation (a steady posture), in ms: medians, the
    slowest ``fit_two``, and one ``fit_one`` at a new pose (its precomputation included)."""
    from diagrams.residuals.contact_study import (
        ContactLocalizationScenario,
        build_contact_localization_diagram,
        sample_trials,
    )
    from diagrams.station.config import StationConfig
    from systems.residuals.multi_contact import MultiContactLocalizer

    _, handles = build_contact_localization_diagram(
        ContactLocalizationScenario(station=StationConfig.realistic(model=model, noise=False))
    )
    plant = handles.plant
    x0 = handles.station.initial_state
    nq = plant.num_positions()
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, x0)
    dynamics = FloatingBaseDynamics(plant)
    localizer = MultiContactLocalizer(plant, handles.scene_graph, exclude_bodies=handles.excluded_bodies)
    inputs = []
    for spec in sample_trials(model, pairs, seed, contacts=2):
        wrench, tau = np.zeros(6), np.zeros(plant.num_velocities() - 6)
        for contact in spec["contacts"]:
            body = plant.GetBodyByName(contact["body"])
            f, p_B = np.asarray(contact["force_world"]), np.asarray(contact["point_body"])
            p_W = plant.EvalBodyPoseInWorld(context, body).multiply(p_B)
            wrench += np.concatenate((np.cross(p_W, f), f))
            tau += dynamics.floating_jacobian(x0[:nq], body.body_frame(), p_B).T @ f
        inputs.append((wrench, tau))
    q = x0[:nq]
    localizer.fit_two(q, *inputs[0])  # the pose's precomputation
    one, two = [], []
    for wrench, tau in inputs:
        start = time.perf_counter()
        localizer.fit_one(q, wrench, tau)
        one.append(time.perf_counter() - start)
        start = time.perf_counter()
        localizer.fit_two(q, wrench, tau)
        two.append(time.perf_counter() - start)
    moved = q.copy()
    moved[7:] += 1e-6 * np.random.default_rng(seed).normal(size=nq - 7)
    start = time.perf_counter()
    localizer.fit_one(moved, *inputs[0])
    new_pose = time.perf_counter() - start
    return {
        "model": model,
        "pairs": pairs,
        "fit_one_median_ms": 1e3 * float(np.median(one)),
        "fit_two_median_ms": 1e3 * float(np.median(two)),
        "fit_two_max_ms": 1e3 * float(np.max(two)),
        "fit_one_new_pose_ms": 1e3 * new_pose,
    }


#: The BLAS libraries' thread counts a one-core measurement runs with (a second BLAS thread
#: would borrow another core, or wait for it when it is busy: stalls of a few ms).
ONE_THREAD_BLAS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def benchmark_log_estimation(seconds: float = 2.0, *, repeats: int = 3, push_seconds: float | None = None) -> dict:
    """Offline estimation from a log (issue 14's floor: >= 5x real time on a 1 kHz log of a
    30+ DoF robot, one core): ``hrp4_like`` (34 joints) simulated standing for ``seconds``
    under a constant 28 N push from 0.5 s, to the end (contact for most of the log: the
    localizer's worst case), its 1 kHz log estimated offline (residuals, force, detector,
    localizer; ``LogEstimationSettings``' defaults) on one core: in a process of its own
    started with one BLAS thread (``ONE_THREAD_BLAS``) and pinned to one CPU while timing;
    with ``push_seconds``, a push of that long. The best of ``repeats`` estimations of the
    same robot model: wall and CPU time, and the real-time factor (log duration / wall
    time)."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    saved = {name: os.environ.get(name) for name in ONE_THREAD_BLAS}
    os.environ.update(ONE_THREAD_BLAS)  # inherited by the process spawned below
    try:
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            return pool.submit(_log_estimation_on_one_core, seconds, repeats, push_seconds).result()
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _log_estimation_on_one_core(seconds: float, repeats: int, push_seconds: float | None) -> dict:
    """``benchmark_log_estimation``'s measurement, in the process it spawns."""
    import os

    from diagrams.residuals.log_estimation import (
        LogEstimationSettings,
        build_estimator_plant,
        estimate_from_log,
        simulate_push_log,
    )

    push_end = seconds + 1.0 if push_seconds is None else 0.5 + push_seconds
    log, _ = simulate_push_log("hrp4_like", duration=seconds, push_end=push_end)
    robot = build_estimator_plant("hrp4_like")
    affinity = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    if affinity:
        os.sched_setaffinity(0, {min(affinity)})
    try:
        timings = []
        for _ in range(repeats):
            cpu, wall = time.process_time(), time.perf_counter()
            estimates = estimate_from_log(robot, log)
            timings.append((time.perf_counter() - wall, time.process_time() - cpu))
    finally:
        if affinity:
            os.sched_setaffinity(0, affinity)
    wall, cpu = min(timings)
    duration = log.num_samples * estimates.period
    return {
        "model": "hrp4_like",
        "num_joints": len(log.joint_names),
        "log_seconds": duration,
        "log_rate_hz": 1.0 / estimates.period,
        "contact_fraction": float(estimates.contact_detected.mean()),
        "dynamics": LogEstimationSettings().dynamics,
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
        "wall_s": wall,
        "cpu_s": cpu,
        "us_per_sample": 1e6 * wall / log.num_samples,
        "real_time_factor": duration / wall,
        "floor": FLOORS["log_estimation_min_real_time_factor"],
    }


def benchmark_residual_replay(seconds: float = 2.0, *, repeats: int = 3) -> dict:
    """The three residuals (internal, external, classical; one shared model) replayed on the
    1 kHz log of ``benchmark_log_estimation``'s push (``hrp4_like``, ``seconds`` long), as
    ``calibrate_from_log`` replays a calibration log: each system's own update sample by
    sample (``stacked`` False) and the whole log stacked; the best of ``repeats``, in
    microseconds per sample, and the largest difference between the two, N m."""
    from diagrams.residuals.log_estimation import build_estimator_plant, log_inputs, simulate_push_log
    from systems.residuals.offline import replay_residuals

    log, _ = simulate_push_log("hrp4_like", duration=seconds, push_end=seconds + 1.0)
    robot = build_estimator_plant("hrp4_like")
    inputs = log_inputs(robot, log)
    model = ResidualModel(robot.plant)
    replayed, us = {}, {}
    for stacked in (False, True):
        best = math.inf
        for _ in range(repeats):
            start = time.perf_counter()
            replayed[stacked] = replay_residuals(
                robot.plant,
                model,
                robot.ft_frames,
                inputs.state,
                inputs.joint_torque,
                inputs.known_wrenches,
                internal_gain=35.0,
                external_gain=35.0,
                period=inputs.period,
                classical_gain=35.0,
                stacked=stacked,
            )
            best = min(best, time.perf_counter() - start)
        us[stacked] = 1e6 * best / inputs.state.shape[0]
    difference = max(
        float(np.abs(np.asarray(a) - np.asarray(b)).max()) for a, b in zip(replayed[False], replayed[True])
    )
    return {
        "model": "hrp4_like",
        "samples": int(inputs.state.shape[0]),
        "per_sample_us": us[False],
        "stacked_us": us[True],
        "speedup": us[False] / us[True],
        "largest_difference": difference,
    }


def _table_header(title: str, header: str, *, blank_line: bool = True) -> None:
    """Prints a table's title, its column header and a rule."""
    if blank_line:
        print()
    print(title)
    print(header)
    print("-" * len(header))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog=f"python -m apps.{EXPERIMENT}", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", choices=(*MODEL_NAMES, "all"), default="all")
    parser.add_argument("--calls", type=positive_int, default=300, help="calls per batch (fast paths)")
    parser.add_argument("--batches", type=positive_int, default=7, help="batches; the median is reported")
    parser.add_argument(
        "--loop-seconds",
        type=non_negative_float,
        default=2.0,
        help="simulated seconds per closed-loop timing: 0.05 s of warm-up, then the median of "
        f"{CLOSED_LOOP_SEGMENTS} timed segments (0 skips them)",
    )
    parser.add_argument(
        "--log-seconds",
        type=non_negative_float,
        default=2.0,
        help="seconds of the simulated hrp4_like log estimated offline (0 skips it)",
    )
    parser.add_argument(
        "--log-push-seconds",
        type=positive_float,
        default=None,
        help="the push's duration in that log, from 0.5 s (default: to the end, the localizer's worst case)",
    )
    parser.add_argument(
        "--peer-steps",
        type=non_negative_int,
        default=200,
        help="updates on which the three residuals are compared with their Pinocchio peer, timed beside it "
        "on hrp4_like and (with --model all) TALOS (0 skips the comparison)",
    )
    parser.add_argument(
        "--fit-pairs",
        type=non_negative_int,
        default=10,
        help="two-contact trials the one-or-two-contact fit is timed on (0 skips it)",
    )
    add_out_argument(parser)
    parser.add_argument(
        "--results",
        default=None,
        metavar="NAME",
        help="also write the figures and their floors to results/NAME.json, with this command (the file "
        "BENCHMARKS.md's tables are generated from: python -m apps.doc_tables)",
    )
    args = parser.parse_args(argv)
    args.command = app_command(f"apps.{EXPERIMENT}", argv)
    return run_app(EXPERIMENT, lambda: _run(args))


def _run(args: argparse.Namespace) -> int:
    from systems.observer.nao_dataset import published_dataset_dir

    if 0.0 < args.loop_seconds <= 0.05:
        raise ValueError(
            f"--loop-seconds must be 0 (skip) or exceed the closed loop's 0.05 s warm-up, got {args.loop_seconds}"
        )
    # Before the long timings: a missing recording is an error (DatasetError, a ValueError,
    # naming the path), not a skipped figure.
    dataset_dir = published_dataset_dir()

    names = MODEL_NAMES if args.model == "all" else (args.model,)
    peer_robots = [
        robot for name, robot in PEER_ROBOTS if name in names or (name not in MODEL_NAMES and args.model == "all")
    ]
    if args.peer_steps > 0 and peer_robots:
        try:  # also before the long timings: the peer needs Pinocchio (the test extra)
            import systems.residuals.pinocchio_peer  # noqa: F401
        except ImportError as error:
            raise ValueError(
                f"the residuals' Pinocchio peer needs Pinocchio ({error}): pip install pin, or --peer-steps 0"
            ) from error
    rows = [benchmark_model(name, calls=args.calls, batches=args.batches) for name in names]
    _table_header(
        "Floating-base decomposition, us per call (x one CalcMassMatrix in the same run)",
        f"{'model':<10} {'n':>3} {'CalcMassMatrix':>15} {'(cached kin.)':>14} {'fast compute':>20} "
        f"{'reference compute':>22} {'fast J^fb':>18} {'ref/fast':>9}",
        blank_line=False,
    )
    for r in rows:
        print(
            f"{r['model']:<10} {r['num_joints']:>3} {r['calc_mass_matrix_us']:>12.1f} us"
            f" {r['calc_mass_matrix_cached_kinematics_us']:>11.1f} us"
            f" {r['fast_compute_us']:>9.1f} us ({r['fast_compute_ratio']:>5.1f}x)"
            f" {r['reference_compute_us']:>11.0f} us ({r['reference_compute_ratio']:>5.0f}x)"
            f" {r['fast_floating_jacobian_us']:>7.1f} us ({r['fast_floating_jacobian_ratio']:>4.1f}x)"
            f" {r['reference_over_fast']:>8.0f}x"
        )
    residual_rows = [
        benchmark_residual_update(name, calls=max(args.calls // 2, 1), batches=args.batches) for name in names
    ]
    _table_header(
        "Residual update: classical + internal + external, one shared model, at a new state (us per update)",
        f"{'model':<10} {'F/T frames':>10} {'CalcMassMatrix':>15} {'three residuals':>22}",
    )
    for r in residual_rows:
        print(
            f"{r['model']:<10} {r['known_wrench_frames']:>10} {r['calc_mass_matrix_us']:>12.1f} us"
            f" {r['three_residuals_update_us']:>11.1f} us ({r['three_residuals_update_ratio']:>5.1f}x)"
        )
    peer_rows = [
        benchmark_residual_peer(robot, calls=max(args.calls // 2, 1), batches=args.batches, steps=args.peer_steps)
        for robot in (peer_robots if args.peer_steps > 0 else ())
    ]
    if peer_rows:
        _table_header(
            "The three residuals: the project's, as three systems and as the fused ResidualBank (the floor's), "
            "against the same residuals as a plain loop on Pinocchio (us per update, x one CalcMassMatrix)",
            f"{'model':<10} {'n':>3} {'CalcMassMatrix':>15} {'three systems':>21} {'fused bank':>21}"
            f" {'Pinocchio peer':>21} {'fused/peer':>11} {'three/peer':>11} {'largest rel. difference':>24}",
        )
        for r in peer_rows:
            print(
                f"{r['model']:<10} {r['num_joints']:>3} {r['calc_mass_matrix_us']:>12.1f} us"
                f" {r['project_bank_us']:>9.1f} us ({r['project_bank_ratio_to_mass_matrix']:>5.1f}x)"
                f" {r['fused_bank_us']:>9.1f} us ({r['fused_bank_ratio_to_mass_matrix']:>5.1f}x)"
                f" {r['peer_us']:>9.1f} us ({r['peer_ratio_to_mass_matrix']:>5.1f}x)"
                f" {r['fused_bank_over_peer']:>10.2f}x {r['project_over_peer']:>10.2f}x"
                f" {r['largest_relative_difference']:>24.1e}"
            )
    observer = benchmark_force_observer(batches=args.batches, dataset_dir=dataset_dir)
    print()
    print(
        f"Kalman force observer (Hawley et al.), real Nao recording of {observer['samples']} samples: "
        f"{observer['samples_per_s']:.0f} samples/s (floor {FLOORS['observer_min_samples_per_s']:.0f}; "
        "60 Hz real time needs 60)"
    )
    loop_rows = []
    if args.loop_seconds > 0:
        loop_rows = benchmark_closed_loop(args.loop_seconds)
        _table_header(
            f"Push-and-comply closed loop on hrp4_like, {args.loop_seconds:g} s simulated, 1 ms steps",
            f"{'loop':<36} {'wall/step':>11} {'CPU/step':>11} {'real-time factor':>17}",
        )
        for r in loop_rows:
            print(
                f"{r.pop('label'):<36} {r['wall_us_per_step']:>8.0f} us {r['cpu_us_per_step']:>8.0f} us"
                f" {r['real_time_factor']:>17.2f}"
            )
    localizer_rows = [
        benchmark_contact_localizer(name, calls=max(args.calls // 3, 1), batches=args.batches)
        for name in names
        if name == "hrp4_like"  # the contact study needs the foot F/T sensors
    ]
    if localizer_rows:
        _table_header(
            "Contact localizer (Sec. VI: line of action, every collision primitive, scores): one update at a new state",
            f"{'model':<10} {'primitives':>10} {'CalcMassMatrix':>15} {'one update':>22} {'floor':>8}",
        )
        for r in localizer_rows:
            print(
                f"{r['model']:<10} {r['num_primitives']:>10} {r['calc_mass_matrix_us']:>12.1f} us"
                f" {r['localizer_update_us']:>11.1f} us ({r['localizer_update_ratio']:>5.1f}x)"
                f" {FLOORS['localizer_update_max_us']:>5.0f} us"
            )
    fit_rows = [
        benchmark_multi_contact_fit(name, pairs=args.fit_pairs)
        for name in names
        if name == "hrp4_like" and args.fit_pairs > 0
    ]
    if fit_rows and args.fit_pairs > 0:
        _table_header(
            f"One-or-two-contact fit (MultiContactLocalizer), {args.fit_pairs} two-contact trials' exact inputs, "
            "at the standing pose",
            f"{'model':<10} {'fit_one':>10} {'fit_two':>10} {'fit_two max':>12} {'fit_one, new pose':>18}",
        )
        for r in fit_rows:
            print(
                f"{r['model']:<10} {r['fit_one_median_ms']:>7.1f} ms {r['fit_two_median_ms']:>7.1f} ms"
                f" {r['fit_two_max_ms']:>9.1f} ms {r['fit_one_new_pose_ms']:>15.1f} ms"
            )
    log_rows = []
    if "hrp4_like" in names and args.log_seconds > 0:  # F/T feet: the whole offline pipeline
        log_rows = [benchmark_log_estimation(args.log_seconds, push_seconds=args.log_push_seconds)]
        _table_header(
            "Offline estimation from a 1 kHz log (residuals, force, detector, localizer), one core",
            f"{'model':<10} {'joints':>6} {'log':>7} {'in contact':>10} {'per sample':>11} {'real-time factor':>17}"
            f" {'floor':>6}",
        )
        for r in log_rows:
            print(
                f"{r['model']:<10} {r['num_joints']:>6} {r['log_seconds']:>5.1f} s"
                f" {100 * r['contact_fraction']:>8.0f} % {r['us_per_sample']:>8.0f} us"
                f" {r['real_time_factor']:>17.2f} {r['floor']:>6.1f}"
            )
    replay_rows = []
    if "hrp4_like" in names and args.log_seconds > 0:
        replay_rows = [benchmark_residual_replay(args.log_seconds)]
        _table_header(
            "Calibration's residual replay (internal, external, classical) on the same log, one process",
            f"{'model':<10} {'samples':>7} {'sample by sample':>17} {'stacked':>10} {'speed-up':>9}"
            f" {'largest difference':>19}",
        )
        for r in replay_rows:
            print(
                f"{r['model']:<10} {r['samples']:>7} {r['per_sample_us']:>14.0f} us {r['stacked_us']:>7.0f} us"
                f" {r['speedup']:>8.1f}x {r['largest_difference']:>14.1e} N m"
            )
    out_dir = output_folder(args, EXPERIMENT)
    figures = {
        "settings": {
            "models": list(names),
            "calls": args.calls,
            "batches": args.batches,
            "loop_seconds": args.loop_seconds,
            "log_seconds": args.log_seconds,
            "log_push_seconds": args.log_push_seconds,
            "fit_pairs": args.fit_pairs,
            "peer_steps": args.peer_steps,
        },
        "floors": FLOORS,
        "log_estimation": log_rows,
        "residual_replay": replay_rows,
        "floating_base": rows,
        "residual_update": residual_rows,
        "residual_peer": peer_rows,
        "force_observer": observer,
        "closed_loop": loop_rows,
        "contact_localizer": localizer_rows,
        "multi_contact_fit": fit_rows,
        "memory_allocator": memory_allocator(),
    }
    write_metrics(out_dir, figures)
    print(f"\nmemory allocator: {figures['memory_allocator']}")
    if args.results:
        print(f"results file: {write_results(args.results, figures, command=args.command)}")
    print_written(out_dir)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
