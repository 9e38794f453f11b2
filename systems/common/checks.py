"""Checks of the values arriving on a system's input ports.

Every system of this package refuses NaN or inf on its inputs with a ValueError that names
the system, the port and the entries, instead of passing a silent wrong number on.
"""

from __future__ import annotations

import math

import numpy as np


def check_finite_input(system_name: str, port_name: str, value: np.ndarray) -> None:
    """Raises ValueError naming the system, port and indices if ``value`` has NaN/inf.

    One dot product per call (this runs in every system at every step); the indices are
    looked up only when the sum is not finite (an overflowing sum of finite values passes).
    """
    if _is_finite_vector(value):
        return
    flat = np.asarray(value, dtype=float).reshape(-1)
    if not math.isfinite(float(flat @ flat)):
        bad = np.flatnonzero(~np.isfinite(flat))
        if bad.size:
            raise ValueError(f"{system_name}: input '{port_name}' has NaN or inf at indices {bad.tolist()}")


def eval_finite_input(system_name: str, port, context) -> np.ndarray:
    """``port.Eval(context)``, checked by ``check_finite_input`` (the port's name is looked up
    only when the fast test fails)."""
    value = port.Eval(context)
    if not _is_finite_vector(value):
        check_finite_input(system_name, port.get_name(), value)
    return value


def _is_finite_vector(value) -> bool:
    """The common case, a vector port's value: a finite 1-D array, tested with no conversion
    or copy (one dot product; an overflowing sum of finite values goes to the full check)."""
    return type(value) is np.ndarray and value.ndim == 1 and math.isfinite(value.dot(value))


def positive_number(value, name: str, *, allow_zero: bool = False) -> float:
    """``value`` as a float, checked: finite and > 0 (>= 0 with ``allow_zero``).

    Raises:
        ValueError: naming ``name`` (e.g. "PulleyLoad: stiffness"): not a number, NaN/inf,
            negative, or zero when not allowed.
    """
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or x < 0.0 or (x == 0.0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be {kind} and finite, got {value!r}")
    return x


def vector3(value, name: str) -> np.ndarray:
    """``value`` as a new (3,) float array of finite numbers.

    Raises:
        ValueError: naming ``name``: not 3 real numbers, or NaN/inf among them.
    """
    try:
        x = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 real numbers, got {value!r}") from None
    if x.shape != (3,) or not np.isfinite(x).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return x
