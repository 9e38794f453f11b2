"""The paper's speed claim, reproduced (Flacco et al. 2016, Sec. III; issue 31).

The paper computes the classical residual (eq. 7) with the factorized Coriolis matrix
C(q, q_dot) built by "n instances of the Newton-Euler" method (O(n^2)) and reports, for HRP-4,
0.0795 s per classical residual against 0.005 s for the internal residual (eq. 11) from its
O(n) Algorithms 1-2: "almost 16 times faster". This benchmark times one update of each on
``hrp4_like`` (34 joints) at new states, in one run:

* **classical, explicit C** (as the paper), on the virtual-joint model of eq. (8)
  (``virtual_joint_plant``: the floating base replaced by three prismatic and three revolute
  joints, so that q_dot = v and the Christoffel factorization exists): M(q)
  (``CalcMassMatrix``), tau_g(q), and C(q, q_dot) column by column, C e_k = (c(q, q_dot + e_k)
  - c(q, q_dot - e_k)) / 4 with c = C q_dot Drake's bias term (``CalcBiasTerm``, one
  recursive Newton-Euler pass each: 2 nv passes, O(n^2)); then eq. (7)'s update with
  C^T q_dot. C q_dot = c and H_dot = C + C^T hold (tests/test_paper_speed.py).
* **internal, reference**: ``InternalResidual`` on the recursive Algorithms 1-2 in Python
  (``systems.dynamics.floating_base_reference``, O(n)).
* **internal, fast**: ``InternalResidual`` on Drake's C++ (the project's default).
* **classical, the project's**: ``ClassicalResidual`` (eq. 7 with Drake's bias term and a
  central difference of M for H_dot: no explicit C).

Run: ``python -m apps.paper_speed [--calls N] [--batches N] [--results-folder DIR]``
(``make paper-speed``). Writes ``results/paper_speed.json`` and prints the table. Timings
depend on the machine; the ratios are what the paper's claim is about.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from apps.results import app_command, write_results
from apps.runner import positive_int, run_app
from models import add_humanoid
from systems.residuals.momentum_residuals import ClassicalResidual, InternalResidual, ResidualModel

#: The paper's figures for HRP-4: seconds per residual.
PAPER_CLASSICAL_S, PAPER_INTERNAL_S = 0.0795, 0.005


#: The virtual joints of eq. (8), world to base: translations along x, y, z, then rotations
#: about z, y, x (yaw, pitch, roll).
VIRTUAL_JOINTS = (
    ("x", "prismatic"),
    ("y", "prismatic"),
    ("z", "prismatic"),
    ("z", "revolute"),
    ("y", "revolute"),
    ("x", "revolute"),
)


def virtual_joint_plant(model: str = "hrp4_like") -> tuple[MultibodyPlant, object]:
    """The robot with eq. (8)'s six virtual joints (``VIRTUAL_JOINTS``, massless bodies
    between them) in place of its free joint: coordinates [x, y, z, yaw, pitch, roll, joints],
    q_dot = v. Returns the finalized plant and the robot's handles."""
    from pydrake.multibody.tree import PrismaticJoint, RevoluteJoint, SpatialInertia

    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, model)
    parent = plant.world_body()
    axes = {"x": [1.0, 0.0, 0.0], "y": [0.0, 1.0, 0.0], "z": [0.0, 0.0, 1.0]}
    for k, (axis, kind) in enumerate(VIRTUAL_JOINTS):
        last = k == len(VIRTUAL_JOINTS) - 1
        child = (
            handles.base_body
            if last
            else plant.AddRigidBody(f"virtual_{k}", handles.model_instance, SpatialInertia.Zero())
        )
        joint_type = PrismaticJoint if kind == "prismatic" else RevoluteJoint
        plant.AddJoint(joint_type(f"virtual_{kind}_{axis}_{k}", parent.body_frame(), child.body_frame(), axes[axis]))
        parent = child
    plant.Finalize()
    return plant, handles


class ExplicitCoriolisClassicalResidual:
    """The classical residual (eq. 7) computed as the paper did: H(q), g(q) and the explicit
    Coriolis matrix C(q, q_dot) (Christoffel factorization, from 2 nv bias-term passes),
    r_{k+1} = K (H v - p_0 - sum_k (tau + C^T v - g + r) T), on a plant whose velocities are
    its coordinates' derivatives (``virtual_joint_plant``). A benchmark's reference, not a
    Drake system."""

    def __init__(self, plant: MultibodyPlant, gain: float, period: float):
        self.plant, self.gain, self.period = plant, gain, period
        self.context = plant.CreateDefaultContext()
        nv = plant.num_velocities()
        self.basis = np.eye(nv)
        self.integral = np.zeros(nv)
        self.residual = np.zeros(nv)
        self.initial_momentum = None

    def coriolis_matrix(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """C(q, v), nv x nv: column k is (c(q, v + e_k) - c(q, v - e_k)) / 4."""
        plant, context = self.plant, self.context
        plant.SetPositions(context, q)
        columns = []
        for e in self.basis:
            plant.SetVelocities(context, v + e)
            plus = plant.CalcBiasTerm(context)
            plant.SetVelocities(context, v - e)
            columns.append(0.25 * (plus - plant.CalcBiasTerm(context)))
        return np.column_stack(columns)

    def update(self, q: np.ndarray, v: np.ndarray, generalized_force: np.ndarray) -> np.ndarray:
        """One period: the residual after the sensed (q, v) and the known generalized force
        (motor torques on the joints, zeros on the base), nv entries."""
        C = self.coriolis_matrix(q, v)
        plant, context = self.plant, self.context
        plant.SetVelocities(context, v)
        momentum = plant.CalcMassMatrix(context) @ v
        gravity = -plant.CalcGravityGeneralizedForces(context)  # g(q) of M v_dot + c + g = tau
        if self.initial_momentum is None:
            self.initial_momentum = momentum
        self.integral += (generalized_force + C.T @ v - gravity + self.residual) * self.period
        self.residual = self.gain * (momentum - self.initial_momentum - self.integral)
        return self.residual


def _median_ms(call: Callable[[int], object], calls: int, batches: int) -> float:
    """Median over ``batches`` of the mean time of ``calls`` calls of ``call(i)``, ms; i runs
    on across batches (each call at another state than the one before: no cached terms)."""
    call(-1)  # warm up
    samples, i = [], 0
    for _ in range(batches):
        start = time.perf_counter()
        for _ in range(calls):
            call(i)
            i += 1
        samples.append((time.perf_counter() - start) / calls * 1e3)
    return statistics.median(samples)


def _states(plant: MultibodyPlant, count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    q0 = plant.GetPositions(plant.CreateDefaultContext())
    out = []
    for _ in range(count):
        q = q0.copy()
        quaternion = rng.normal(size=4)
        q[:4] = quaternion / np.linalg.norm(quaternion)
        q[7:] = rng.uniform(-0.5, 0.5, plant.num_positions() - 7)
        out.append(np.concatenate([q, rng.normal(size=plant.num_velocities())]))
    return out


def benchmark_paper_speed(model: str = "hrp4_like", *, calls: int = 20, batches: int = 5) -> dict:
    """Milliseconds per update of the four residuals of the module docstring at new states
    (medians of ``batches`` batches of ``calls`` updates), and the ratios."""
    plant = MultibodyPlant(time_step=0.0)
    handles = add_humanoid(plant, model)
    plant.Finalize()
    nv = plant.num_velocities()
    states = _states(plant, 16, seed=7)
    torque = np.random.default_rng(8).normal(size=nv - 6)
    frames = tuple(handles.ft_sensor_frames[s] for s in sorted(handles.ft_sensor_frames))
    wrenches = np.random.default_rng(9).normal(size=6 * len(frames))

    def system_update(system) -> Callable[[int], object]:
        context = system.CreateDefaultContext()
        system.GetInputPort("measured_torque").FixValue(context, torque)
        if frames:
            system.GetInputPort("known_wrenches").FixValue(context, wrenches)
        state = system.GetInputPort("state").FixValue(context, states[0])

        def update(i: int):
            state.GetMutableData().set_value(states[i % 16])
            return system.EvalUniquePeriodicDiscreteUpdate(context)

        return update

    virtual, _ = virtual_joint_plant(model)
    explicit = ExplicitCoriolisClassicalResidual(virtual, 35.0, 1e-3)
    rng = np.random.default_rng(10)
    virtual_states = [rng.uniform(-0.5, 0.5, 2 * virtual.num_positions()) for _ in range(16)]
    generalized = np.concatenate([np.zeros(6), torque])
    n = virtual.num_positions()
    rows = {
        "classical_explicit_coriolis_ms": _median_ms(
            lambda i: explicit.update(virtual_states[i % 16][:n], virtual_states[i % 16][n:], generalized),
            calls,
            batches,
        ),
        "internal_reference_ms": _median_ms(
            system_update(InternalResidual(plant, 35.0, 1e-3, frames, model=ResidualModel(plant, "reference"))),
            max(calls // 4, 1),
            batches,
        ),
        "internal_fast_ms": _median_ms(
            system_update(InternalResidual(plant, 35.0, 1e-3, frames, model=ResidualModel(plant))), 10 * calls, batches
        ),
        "classical_project_ms": _median_ms(
            system_update(ClassicalResidual(plant, 35.0, 1e-3, frames, model=ResidualModel(plant))),
            10 * calls,
            batches,
        ),
    }
    classical = rows["classical_explicit_coriolis_ms"]
    return {
        "model": model,
        "num_joints": nv - 6,
        **rows,
        "ratio_classical_explicit_over_internal_reference": classical / rows["internal_reference_ms"],
        "ratio_classical_explicit_over_internal_fast": classical / rows["internal_fast_ms"],
        "paper_classical_ms": 1e3 * PAPER_CLASSICAL_S,
        "paper_internal_ms": 1e3 * PAPER_INTERNAL_S,
        "paper_ratio": PAPER_CLASSICAL_S / PAPER_INTERNAL_S,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m apps.paper_speed", description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=positive_int, default=20, help="explicit-C updates per batch")
    parser.add_argument("--batches", type=positive_int, default=5, help="batches; the median is reported")
    parser.add_argument("--results-folder", type=Path, default=None, help="write results/paper_speed.json there")
    args = parser.parse_args(argv)

    def body() -> int:
        r = benchmark_paper_speed(calls=args.calls, batches=args.batches)
        print(f"one residual update on {r['model']} ({r['num_joints']} joints), ms (the paper: HRP-4)")
        print(f"  classical, explicit C (the paper's way)  {r['classical_explicit_coriolis_ms']:9.3f}   (paper 79.5)")
        print(f"  internal, recursive Algorithms 1-2       {r['internal_reference_ms']:9.3f}   (paper 5.0)")
        print(f"  internal, Drake C++ (the default)        {r['internal_fast_ms']:9.3f}")
        print(f"  classical, the project's (no explicit C) {r['classical_project_ms']:9.3f}")
        reference, fast = (
            r["ratio_classical_explicit_over_internal_reference"],
            r["ratio_classical_explicit_over_internal_fast"],
        )
        print(f"  classical explicit / internal recursive: {reference:.1f}x (paper {r['paper_ratio']:.1f}x)")
        print(f"  classical explicit / internal fast: {fast:.1f}x")
        path = write_results(
            "paper_speed", r, command=app_command("apps.paper_speed", argv), folder=args.results_folder
        )
        print(f"wrote {path}")
        return 0

    return run_app("paper_speed", body)


if __name__ == "__main__":
    raise SystemExit(main())
