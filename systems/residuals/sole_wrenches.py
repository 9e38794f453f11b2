"""Eq. (10) on a robot without foot F/T sensors: the soles' wrenches estimated from the
residuals and subtracted from them, for a controller that needs the joint effort of a push
(the joint admittance of eq. 14; ``diagrams.residuals.push_and_comply``).

With F/T sensors, eq. (10) subtracts the soles' measured wrenches and the residuals hold the
push alone. Without them (or with FSRs, which measure a sole's normal force and centre of
pressure but not its shear and yaw moment) the residuals [r_ext; r_int] hold the soles'
unknown wrench components w as well, through their columns U (``UnknownWrenches``):

    [r_ext; r_int] = Ubar w + T_L w_L + noise

with w_L the contact's wrench on one link L (its map T_L, ``wrench_maps``). Every few
updates the link is chosen whose free wrench, fitted with the soles', leaves the smallest
misfit, among the links that a sole's wrench cannot mimic: a link of a stance leg can (its
free wrench and the sole's differ only by joints the sole's columns already span; their
joint columns have rank below 6 + k), so a push there is not separable from the ground's
reaction, and the leg links are never chosen on a robot without foot sensing. Each update
then fits w with that link's wrench and outputs the residual minus the soles' share,
r - Ubar_r w (the internal residual, eq. 11, or the classical one, eq. 7): eq. (10) with the
soles' wrenches estimated.

Ubar are the columns through the residuals' own first-order filter (as in
``ContactDetector``): the residuals see J(q(t))^T w through it, and the columns at the
current posture would lag by J-dot^T w / K, with w the robot's weight far more than a push's
effect once the robot moves. The link's map is taken at the current posture (its wrench, a
push, is small).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, JacobianWrtVariable
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from systems.common.checks import eval_finite_input, positive_number, resolve_body
from systems.residuals.contact_estimation import (
    UnknownWrenches,
    _SensedConfiguration,
    first_order_filter,
    wrench_maps,
    wrench_maps_of_samples,
)

#: The residuals ``SoleWrenchCompensation`` compensates.
COMPENSATED_RESIDUALS = ("internal", "classical")
#: A link is a candidate when its free wrench's columns, with the soles' projected out, keep
#: this fraction of their largest singular value in every direction: the fit amplifies the
#: residuals' noise by about its inverse. On hrp4_like standing, a stance-leg link's keep
#: 1e-16 (a direction lost: the soles' wrenches mimic it) to 3e-4 (with FSRs, the hip links
#: away from the symmetric posture), the torso's, head's and arms' 2e-2 to 3e-1.
MIN_LINK_CONDITIONING = 3e-3


def _without(Q: np.ndarray, T: np.ndarray) -> np.ndarray:
    """The wrench maps T (B, r, c) without their part in the span of Q's orthonormal columns (r, k)."""
    return T - np.einsum("rk,bkc->brc", Q, np.einsum("rk,brc->bkc", Q, T))


def _least_squares_of_samples(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K, c) the least-squares solutions of K systems A_k x = b_k (A (K, r, c), b (K, r)):
    by QR where A_k has full column rank (its triangular factor's diagonal within 1e-10 of its
    largest), else the minimum-norm solution (pseudo-inverse), as ``lstsq`` gives."""
    Q, R = np.linalg.qr(A)
    diagonal = np.abs(np.diagonal(R, axis1=1, axis2=2))
    full = diagonal.min(axis=1) > 1e-10 * diagonal.max(axis=1)
    x = np.empty((A.shape[0], A.shape[2]))
    if full.any():
        Qb = np.einsum("krc,kr->kc", Q[full], b[full])
        x[full] = np.linalg.solve(R[full], Qb[..., None])[..., 0]
    if not full.all():
        x[~full] = (np.linalg.pinv(A[~full]) @ b[~full, :, None])[..., 0]
    return x


class ReplayedCompensation(NamedTuple):
    """``SoleWrenchCompensation.replay``'s per-update outputs (N updates) and end state.

    Attributes:
        body_index: (N,) the chosen link's body index (-1: none chosen or none usable).
        internal: (N, n) the internal residual minus the soles' share, N m.
        external_wrench_world: (N, 6) the external residual minus the soles' share,
            [moment about the world origin; force], world.
        sole_wrenches_world: (N, 6 m) the soles' fitted wrenches, [moment about the sole
            frame's origin; force] per sole, world (a measured component's share is 0).
        end: the system's discrete state after the last update (to continue from).
    """

    body_index: np.ndarray
    internal: np.ndarray
    external_wrench_world: np.ndarray
    sole_wrenches_world: np.ndarray
    end: np.ndarray


class SoleWrenchCompensation(LeafSystem):
    """The residual without the soles' estimated wrenches (module docstring).

    Inputs:
        ``state`` (nq + nv): the sensed [q; v].
        ``external_wrench_world`` (6): ``ExternalResidual``'s output.
        ``internal_residual`` (n): ``InternalResidual``'s output.
        ``classical_residual`` (nv, ``residual`` "classical" only): ``ClassicalResidual``'s.

    State (discrete): [the chosen link's slot among ``candidate_bodies`` (-1: none yet);
        the filtered columns Ubar (6 + n) x k, row-major; with "classical" also its
        columns' (nv x k)].

    Outputs:
        ``residual`` (n, or nv with "classical"): that residual minus the soles' share.
        ``sole_wrenches_world`` (6 m): the soles' fitted wrenches, [moment about the sole
            frame's origin; force], world (a measured component's share is 0 there).
        ``contact_body_index`` (1): the chosen link's body index (-1 before the first choice).
        ``external_wrench_world`` (6): the external residual (eq. 16) minus the soles' share,
            [moment about the world origin; force], world: the push's wrench.
        ``external_wrench_base`` (6): the same wrench as ``ExternalResidual``'s base output,
            [moment about the base frame F0's origin; force], in F0.

    Args:
        plant: the estimators' finalized floating-base plant.
        unknown_wrench_frames, unknown_wrench_components: the soles and their unknown
            components (``UnknownWrenches``; the estimators' plant's).
        gain: the residuals' K, 1/s (all three the same).
        residual: "internal" or "classical": which residual to compensate.
        candidate_bodies: bodies (names, indices or RigidBody) a contact may be on (default:
            every body with mass); their links' conditioning decides each time.
        period: update period, s (the residuals').
        selection_period: s between two choices of the link (default 0.05).

    Raises:
        ValueError: no unknown wrench frames, an unknown residual kind or body, a gain
            outside (0, 1/period).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        unknown_wrench_frames: Sequence,
        unknown_wrench_components: Sequence | None = None,
        *,
        gain: float,
        residual: str = "internal",
        candidate_bodies: Sequence | None = None,
        period: float = 1e-3,
        selection_period: float = 0.05,
    ):
        super().__init__()
        who = self._who = "SoleWrenchCompensation"
        if residual not in COMPENSATED_RESIDUALS:
            raise ValueError(f"{who}: unknown residual {residual!r}; choose one of {COMPENSATED_RESIDUALS}")
        self._kind = residual
        self._kin = kin = _SensedConfiguration(plant, who)
        self._unknown = UnknownWrenches(plant, unknown_wrench_frames, unknown_wrench_components, who)
        if not self._unknown:
            raise ValueError(f"{who}: needs the soles as unknown_wrench_frames (a robot without foot F/T sensors)")
        self._period = positive_number(period, f"{who}: period")
        selection_period = positive_number(selection_period, f"{who}: selection_period")
        self._factor = float(gain) * self._period
        if not 0.0 < self._factor < 1.0:
            raise ValueError(f"{who}: gain times period must be in (0, 1), got {self._factor}")
        if candidate_bodies is None:
            bodies = [plant.get_body(BodyIndex(i)) for i in range(1, plant.num_bodies())]
            bodies = [b for b in bodies if b.default_mass() > 0.0]
        else:
            bodies = [resolve_body(plant, b, who) for b in candidate_bodies]
        if not bodies:
            raise ValueError(f"{who}: no candidate body")
        self._bodies = tuple(bodies)
        self._slots = {int(b.index()): slot for slot, b in enumerate(self._bodies)}
        nq, nv, n, k = kin.nq, kin.nv, kin.n, self._unknown.size
        self._shape = (6 + n, k)
        self._classical_shape = (nv, k)
        sizes = [1, (6 + n) * k] + ([nv * k] if residual == "classical" else [])
        self._state_port = self.DeclareVectorInputPort("state", nq + nv)
        self._wrench_port = self.DeclareVectorInputPort("external_wrench_world", 6)
        self._internal_port = self.DeclareVectorInputPort("internal_residual", n)
        self._classical_port = (
            self.DeclareVectorInputPort("classical_residual", nv) if residual == "classical" else None
        )
        self._state_index = self.DeclareDiscreteState(np.concatenate(([-1.0], np.zeros(sum(sizes) - 1))))
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._Update)
        self._every = max(1, int(round(selection_period / self._period)))
        out = nv if residual == "classical" else n
        self.DeclareVectorOutputPort("residual", out, self._CalcResidual)
        self.DeclareVectorOutputPort("sole_wrenches_world", 6 * len(self._unknown), self._CalcWrenches)
        self.DeclareVectorOutputPort(
            "contact_body_index", 1, lambda c, o: o.SetFromVector([self._body_index(c)]), {self.xd_ticket()}
        )
        self.DeclareVectorOutputPort("external_wrench_world", 6, self._CalcExternalWorld)
        self.DeclareVectorOutputPort("external_wrench_base", 6, self._CalcExternalBase)

    @property
    def candidate_bodies(self) -> tuple:
        return self._bodies

    # -- the columns ----------------------------------------------------------------------
    def classical_columns(self, q: np.ndarray) -> np.ndarray:
        """(nv, k) the unknown components' generalized forces in the classical residual's
        coordinates (``ClassicalResidual``: [moment about the F0 origin, force, both in F0;
        J_j^T w]) at positions q."""
        kin = self._kin
        kin.set_positions(np.asarray(q, dtype=float))
        X_WF0 = kin.base_pose()
        R, p_F0 = X_WF0[:, :3], X_WF0[:, 3]
        world = kin.plant.world_frame()
        columns = []
        for frame, basis in zip(self._unknown.frames, self._unknown.world_bases(kin.context)):
            B = np.eye(6) if basis is None else basis  # world [m; f] directions
            p_F = frame.CalcPoseInWorld(kin.context).translation()
            m, f = B[:3], B[3:]
            J = kin.plant.CalcJacobianSpatialVelocity(
                kin.context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world
            )
            base = np.vstack((R.T @ (m + np.cross(p_F - p_F0, f, axis=0)), R.T @ f))
            columns.append(np.vstack((base, J[:, 6:].T @ B)))
        return np.concatenate(columns, axis=1)

    def _filtered(self, context: Context) -> tuple[np.ndarray, np.ndarray | None]:
        x = context.get_discrete_state(self._state_index).get_value()
        size = self._shape[0] * self._shape[1]
        stacked = x[1 : 1 + size].reshape(self._shape)
        classical = x[1 + size :].reshape(self._classical_shape) if self._kind == "classical" else None
        return stacked, classical

    def _body_index(self, context: Context) -> float:
        slot = int(context.get_discrete_state(self._state_index).get_value()[0])
        return float(self._bodies[slot].index()) if slot >= 0 else -1.0

    # -- the fit --------------------------------------------------------------------------
    def choose_link(self, q: np.ndarray, rows: np.ndarray, columns: np.ndarray) -> int:
        """The slot of the candidate link whose free wrench, fitted with the soles' wrench
        components (``columns``, (6 + n) x k), leaves the smallest misfit of ``rows`` ([r_ext;
        r_int]) at positions q, among the links a sole's wrench cannot mimic
        (``MIN_LINK_CONDITIONING``); -1 if none can be told from the soles."""
        kin = self._kin
        kin.set_positions(np.asarray(q, dtype=float))
        T = wrench_maps(kin, [b.body_frame() for b in self._bodies])  # (B, 6 + n, 6)
        usable = self._separable(T)
        if not usable.any():
            return -1
        # The fit: with the soles' columns as the residuals see them.
        Q = np.linalg.qr(columns)[0]
        projected = _without(Q, T)
        rest = rows - Q @ (Q.T @ rows)
        x = np.einsum("bcr,r->bc", np.linalg.pinv(projected[usable]), rest)
        misfit = np.linalg.norm(rest - np.einsum("brc,bc->br", projected[usable], x), axis=1)
        return int(np.flatnonzero(usable)[int(np.argmin(misfit))])

    def _separable(self, T: np.ndarray) -> np.ndarray:
        """(B,) which of the links whose wrench maps are ``T`` (B, 6 + n, 6), at the posture
        ``self._kin`` holds, a sole's wrench cannot mimic: the soles' columns at this posture
        (the physics) projected out, they keep ``MIN_LINK_CONDITIONING`` of their largest
        singular value."""
        projected = _without(np.linalg.qr(self._unknown.columns(self._kin))[0], T)
        singular = np.linalg.svd(projected, compute_uv=False)
        return singular[:, -1] > MIN_LINK_CONDITIONING * np.linalg.svd(T, compute_uv=False)[:, 0]

    def given_link(self, q: np.ndarray, body_index: int) -> int | None:
        """The slot of the body ``body_index`` (e.g. a localizer's answer) when it is one of
        the candidates and a sole's wrench cannot mimic it at positions q; else None."""
        slot = self._slots.get(int(body_index))
        if slot is None:
            return None
        self._kin.set_positions(np.asarray(q, dtype=float))
        T = wrench_maps(self._kin, [self._bodies[slot].body_frame()])
        return slot if self._separable(T)[0] else None

    def fit(self, q: np.ndarray, rows: np.ndarray, columns: np.ndarray, slot: int) -> np.ndarray:
        """(k,) the soles' wrench components fitted to ``rows`` with link ``slot``'s free
        wrench (none for -1), ``columns`` the soles' (6 + n) x k."""
        A = columns
        if slot >= 0:
            self._kin.set_positions(np.asarray(q, dtype=float))
            A = np.concatenate((columns, wrench_maps(self._kin, [self._bodies[slot].body_frame()])[0]), axis=1)
        return np.linalg.lstsq(A, rows, rcond=None)[0][: columns.shape[1]]

    def replay(
        self,
        positions: np.ndarray,
        external_wrench_world: np.ndarray,
        internal_residual: np.ndarray,
        start: np.ndarray | None = None,
        first_update: int = 0,
        before: tuple[np.ndarray, np.ndarray] | None = None,
        links: np.ndarray | None = None,
    ) -> ReplayedCompensation:
        """The system's N updates without a Context (``systems.residuals.offline``), as in a
        diagram whose residuals output their discrete state and update at the same times:
        ``external_wrench_world`` and ``internal_residual`` (N rows each) are the residuals
        after each of their updates. Update k (the ``first_update`` + k-th of the system,
        which chooses the link when that count is a multiple of the selection period's
        updates) reads positions[k] and the residuals of update k - 1 (``before``, the pair
        before the first, default zeros); its outputs, read after it, the residuals of
        update k. From ``start`` (the discrete state; default the initial one: no link,
        zero columns). ``links`` (N,), optional: a body index per update (-1: none), e.g.
        the contact localizer's answer; at a selection update a given link that is a
        candidate a sole's wrench cannot mimic (``given_link``) is taken instead of the
        choice by misfit. Computed over all updates at once where the system steps them one
        by one (the columns from Pinocchio's kinematics, ``UnknownWrenches.columns_of_samples``;
        the filter ``first_order_filter``; the fits per run of updates with one link): the
        same numbers to rounding (tests).

        Raises:
            ValueError: arrays of inconsistent sizes or non-finite values (naming them).
        """
        kin, unknown = self._kin, self._unknown
        q = np.asarray(positions, dtype=float)
        r_ext = np.asarray(external_wrench_world, dtype=float)
        r_int = np.asarray(internal_residual, dtype=float)
        N = q.shape[0] if q.ndim == 2 else -1
        for name, array, width in (
            ("positions", q, kin.nq),
            ("external_wrench_world", r_ext, 6),
            ("internal_residual", r_int, kin.n),
        ):
            if array.ndim != 2 or array.shape != (N, width):
                raise ValueError(f"{self._who}.replay: {name} must be (N, {width}) with N = {N}, got {array.shape}")
            if not np.isfinite(array).all():
                raise ValueError(f"{self._who}.replay: {name} holds NaN or inf")
        if self._kind != "internal":
            raise ValueError(f"{self._who}.replay: replays the internal residual's compensation only")
        if links is not None:
            links = np.asarray(links)
            if links.shape != (N,):
                raise ValueError(f"{self._who}.replay: links must be (N,) with N = {N}, got {links.shape}")
        if start is None:
            start = self.CreateDefaultContext().get_discrete_state(self._state_index).get_value()
        start = np.asarray(start, dtype=float)
        slot = int(start[0])
        stacked = start[1:].reshape(self._shape).copy()
        rows = np.concatenate((r_ext, r_int), axis=1)
        first = np.zeros(rows.shape[1]) if before is None else np.concatenate([np.asarray(b, float) for b in before])
        read = np.vstack((first[None], rows[:-1]))  # what each update reads
        k_size, a = unknown.size, self._factor
        if N == 0:
            empty = np.zeros((0, 6 * len(unknown)))
            return ReplayedCompensation(np.zeros(0), r_int.copy(), r_ext.copy(), empty, start.copy())
        # Every sample's columns and world maps at once, then the residuals' first-order filter
        # over them (the system's recursion, term for term).
        columns, world_maps = unknown.columns_of_samples(self._kin.pinocchio, q)
        filtered = first_order_filter(columns, a, stacked)
        # The link: chosen at the selection updates, held in between.
        slots = np.empty(N, dtype=int)
        for k in range(N):
            if (first_update + k) % self._every == 0:
                given = None if links is None or links[k] < 0 else self.given_link(q[k], int(links[k]))
                slot = given if given is not None else self.choose_link(q[k], read[k], filtered[k])
            slots[k] = slot
        # The fits, batched per run of updates with one link: least squares of [filtered
        # columns, the link's wrench map] (minimum norm, as lstsq).
        fitted = np.zeros((N, k_size))
        changes = np.flatnonzero(np.diff(slots)) + 1
        for begin, end in zip(np.concatenate(([0], changes)), np.concatenate((changes, [N]))):
            A = filtered[begin:end]
            slot = int(slots[begin])
            if slot >= 0:
                frames = [self._bodies[slot].body_frame()]
                link = wrench_maps_of_samples(self._kin.pinocchio, frames, q[begin:end])[0][:, 0]
                A = np.concatenate((A, link), axis=2)
            fitted[begin:end] = _least_squares_of_samples(A, rows[begin:end])[:, :k_size]
        shares = (filtered @ fitted[:, :, None])[:, :, 0]
        body = np.array([float(self._bodies[s].index()) if s >= 0 else -1.0 for s in slots])
        return ReplayedCompensation(
            body_index=body,
            internal=r_int - shares[:, 6:],
            external_wrench_world=r_ext - shares[:, :6],
            sole_wrenches_world=(world_maps @ fitted[:, :, None])[:, :, 0],
            end=np.concatenate(([float(slots[-1])], filtered[-1].ravel())),
        )

    def _inputs(self, context: Context) -> tuple[np.ndarray, np.ndarray]:
        x = eval_finite_input(self._who, self._state_port, context)
        rows = np.concatenate(
            (
                eval_finite_input(self._who, self._wrench_port, context),
                eval_finite_input(self._who, self._internal_port, context),
            )
        )
        return x[: self._kin.nq], rows

    def _Update(self, context: Context, discrete_state: DiscreteValues) -> None:
        q, rows = self._inputs(context)
        stacked, classical = self._filtered(context)
        kin = self._kin
        kin.set_positions(q)
        a = self._factor
        stacked = (1.0 - a) * stacked + a * self._unknown.columns(kin)
        parts = [stacked.ravel()]
        if classical is not None:
            parts.append(((1.0 - a) * classical + a * self.classical_columns(q)).ravel())
        slot = int(context.get_discrete_state(self._state_index).get_value()[0])
        if int(round(context.get_time() / self._period)) % self._every == 0:
            slot = self.choose_link(q, rows, stacked)
        discrete_state.get_mutable_vector(self._state_index).SetFromVector(np.concatenate(([float(slot)], *parts)))

    def _solution(self, context: Context) -> np.ndarray:
        q, rows = self._inputs(context)
        stacked, _ = self._filtered(context)
        slot = int(context.get_discrete_state(self._state_index).get_value()[0])
        return self.fit(q, rows, stacked, slot)

    def _CalcResidual(self, context: Context, output: BasicVector) -> None:
        w = self._solution(context)
        stacked, classical = self._filtered(context)
        if self._kind == "classical":
            r = eval_finite_input(self._who, self._classical_port, context)
            output.SetFromVector(r - classical @ w)
        else:
            r = eval_finite_input(self._who, self._internal_port, context)
            output.SetFromVector(r - stacked[6:] @ w)

    def _external_world(self, context: Context) -> np.ndarray:
        """[moment about the world origin; force], world: r_ext minus the soles' share."""
        stacked, _ = self._filtered(context)
        r_ext = eval_finite_input(self._who, self._wrench_port, context)
        return r_ext - stacked[:6] @ self._solution(context)

    def _CalcExternalWorld(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._external_world(context))

    def _CalcExternalBase(self, context: Context, output: BasicVector) -> None:
        wrench = self._external_world(context)
        q, _ = self._inputs(context)
        self._kin.set_positions(q)
        X_WF0 = self._kin.base_pose()
        R, p_F0 = X_WF0[:, :3], X_WF0[:, 3]
        moment_F0 = wrench[:3] - np.cross(p_F0, wrench[3:])
        output.SetFromVector(np.concatenate((R.T @ moment_F0, R.T @ wrench[3:])))

    def _CalcWrenches(self, context: Context, output: BasicVector) -> None:
        q, _ = self._inputs(context)
        self._kin.set_positions(q)
        output.SetFromVector(self._unknown.world_wrenches(self._kin, self._solution(context)).ravel())


__all__ = ["COMPENSATED_RESIDUALS", "MIN_LINK_CONDITIONING", "ReplayedCompensation", "SoleWrenchCompensation"]
