"""Step response of a force estimate: overshoot and settling time, the figures by which
Hawley et al.'s observer (2019, Figs. 6-8) is compared on the real Nao and in simulation.

A step is a change of the applied load at a known time t_s (in simulation, the schedule; on
a recording, the moment the measured ZMP moves: ``load_steps_from_zmp``). For one force
component, with F_0 the estimate's settled level before the step and F_1 after it (means
over the last ``settled_window`` seconds before the step and before the window's end):

* overshoot = max over the window of sign(F_1 - F_0) (F(t) - F_1) / |F_1 - F_0|, in percent
  (0 when the estimate never passes F_1);
* settling time = the time from t_s until the estimate stays within
  ``band`` |F_1 - F_0| of F_1 to the window's end, s (NaN if it never does).

Both are measured against the estimate's own settled levels, not the true force, so that a
steady-state bias is not counted as overshoot and the same definition applies to a real
recording, which has no true force.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

#: Default settling band, a fraction of the step's size.
SETTLING_BAND = 0.1
#: Default length of the windows over which the settled levels are averaged, s.
SETTLED_WINDOW = 1.0
#: Steps smaller than this (N) are not measured (noise would dominate).
MIN_STEP = 1.0


@dataclass(frozen=True)
class StepResponse:
    """One component's response to one step (module docstring).

    Attributes:
        component: "x", "y" or "z".
        step_time_s: t_s, s.
        before_N, after_N: F_0 and F_1, N.
        peak_N: the estimate's extreme value in the step's direction, N.
        overshoot_percent: %; settling_time_s: s (NaN: never settled in the window).
    """

    component: str
    step_time_s: float
    before_N: float
    after_N: float
    peak_N: float
    overshoot_percent: float
    settling_time_s: float

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(self).items()}


def step_responses(
    t: np.ndarray,
    estimate: np.ndarray,
    step_times: list[float],
    end_times: list[float],
    *,
    components: tuple[str, ...] = ("x", "y", "z"),
    band: float = SETTLING_BAND,
    settled_window: float = SETTLED_WINDOW,
    min_step: float = MIN_STEP,
) -> list[StepResponse]:
    """The responses of every component of ``estimate`` ((N, k) samples at times ``t``, s)
    to the steps at ``step_times``, each observed until the matching ``end_times`` entry
    (the next change of the load, or the record's end). Components whose settled level
    changes by less than ``min_step`` N are skipped.

    Raises:
        ValueError: mismatched shapes, a step without ``settled_window`` seconds of data
            before it or after it, or a non-positive band.
    """
    t = np.asarray(t, dtype=float)
    estimate = np.asarray(estimate, dtype=float).reshape(len(t), -1)
    if estimate.shape[1] != len(components):
        raise ValueError(f"estimate has {estimate.shape[1]} columns for {len(components)} components")
    if len(step_times) != len(end_times):
        raise ValueError("step_times and end_times must have the same length")
    if not band > 0:
        raise ValueError(f"band must be positive, got {band}")
    out = []
    previous_end = t[0]
    for t_s, t_end in zip(step_times, end_times, strict=True):
        before_rows = (t >= max(previous_end, t_s - settled_window)) & (t < t_s)
        window = (t >= t_s) & (t <= t_end)
        after_rows = window & (t > t_end - settled_window)
        if t_s - settled_window < t[0] or t_end - t_s < 2 * settled_window or not before_rows.any():
            raise ValueError(f"the step at {t_s:.3f} s needs {settled_window} s of data before it and twice after it")
        previous_end = t_s
        for k, component in enumerate(components):
            before = float(estimate[before_rows, k].mean())
            after = float(estimate[after_rows, k].mean())
            change = after - before
            if abs(change) < min_step:
                continue
            values, times = estimate[window, k], t[window]
            excursion = np.sign(change) * (values - after)
            peak = int(np.argmax(excursion))
            outside = np.flatnonzero(np.abs(values - after) > band * abs(change))
            if outside.size == 0:
                settling = 0.0
            elif outside[-1] == len(values) - 1:
                settling = math.nan
            else:
                settling = float(times[outside[-1] + 1] - t_s)
            out.append(
                StepResponse(
                    component,
                    float(t_s),
                    before,
                    after,
                    float(values[peak]),
                    float(max(0.0, excursion[peak]) / abs(change) * 100.0),
                    settling,
                )
            )
    return out


def load_steps_from_zmp(
    t: np.ndarray, zmp: np.ndarray, *, quiet_time: float = 1.0, margin: float = 0.5
) -> tuple[list[float], list[float]]:
    """The times a load went on and came off in a standing recording, from its measured ZMP
    ((N, 2), m): the ZMP moves at once when a load acts (eq. 10), whereas the estimate lags.
    The ZMP's displacement from its mean over the first ``quiet_time`` seconds is taken;
    the load is on while it exceeds half its largest value. Returns (step times, end times)
    for ``step_responses``: the first crossing up and the last crossing down. A hand puts a
    load on or takes it off within about a second (the ZMP of ``Force_Z_data`` moves for
    ~1.5 s), so the window of the first ends ``margin`` s before the second; the second's
    ends at the record's end.

    Raises:
        ValueError: no load found (the ZMP never moves more than 1 cm), or a load still on
            at the end.
    """
    t = np.asarray(t, dtype=float)
    zmp = np.asarray(zmp, dtype=float)
    rest = zmp[t < t[0] + quiet_time].mean(axis=0)
    shift = np.linalg.norm(zmp - rest, axis=1)
    if shift.max() < 0.01:
        raise ValueError(f"no load found: the ZMP moves at most {shift.max() * 100:.2f} cm")
    loaded = np.flatnonzero(shift > 0.5 * shift.max())
    on, off = loaded[0], loaded[-1] + 1
    if off >= len(t):
        raise ValueError("the load is still on at the end of the recording")
    return [float(t[on]), float(t[off])], [float(t[off] - margin), float(t[-1])]


def summary(responses: list[StepResponse]) -> dict:
    """Mean and largest overshoot (%) and settling time (s) over ``responses`` (settling
    times that never settled count as NaN in the mean: reported as None)."""
    if not responses:
        return {"steps": 0}
    overshoot = np.array([r.overshoot_percent for r in responses])
    settling = np.array([r.settling_time_s for r in responses])

    def finite(x):
        return None if not np.isfinite(x) else float(x)

    return {
        "steps": len(responses),
        "mean_overshoot_percent": float(overshoot.mean()),
        "max_overshoot_percent": float(overshoot.max()),
        "mean_settling_time_s": finite(settling.mean()),
        "max_settling_time_s": finite(settling.max()),
    }


__all__ = [
    "MIN_STEP",
    "SETTLED_WINDOW",
    "SETTLING_BAND",
    "StepResponse",
    "load_steps_from_zmp",
    "step_responses",
    "summary",
]
