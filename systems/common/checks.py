"""Checks of the values given to the systems: input ports, parameters, plants, bodies.

Every system of this package refuses NaN or inf on its inputs with a ValueError that names
the system, the port and the entries, instead of passing a silent wrong number on; its
constructor refuses bad parameters with a ValueError that names the system and parameter.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, RigidBody


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


def per_joint(
    value,
    joints: int | Sequence[str],
    name: str,
    *,
    who: str | None = None,
    allow_inf: bool = False,
    sign: str | None = None,
    entry: str = "joint",
) -> np.ndarray:
    """``value`` as a new (n,) float array, one entry per joint (or per ``entry``).

    Args:
        value: a scalar (the same for every joint), n values in joint order, or (with
            ``joints`` given as names) a {joint name: value} mapping covering every joint.
        joints: n, or the n joint names.
        name: the parameter's name, for the messages (e.g. "kp").
        who: the system's name, prefixed to the messages ("who: name ...").
        allow_inf: accept +-inf (e.g. "no bound"); NaN is always refused.
        sign: None (any sign), "non-negative" or "positive".
        entry: what an entry is, for the messages ("joint": "at joint indices [1]").

    Raises:
        ValueError: naming ``who`` and ``name``: not numbers, wrong shape, a joint missing
            from the mapping, NaN (or inf), or an entry of the wrong sign (with its indices).
    """
    prefix = f"{who}: {name}" if who else name
    names = None if isinstance(joints, (int, np.integer)) else tuple(joints)
    n = int(joints) if names is None else len(names)
    if isinstance(value, Mapping):
        if names is None:
            raise ValueError(f"{prefix} must be a scalar or {n} values, not a mapping (no joint names known)")
        missing = [j for j in names if j not in value]
        if missing:
            raise ValueError(f"{prefix} has no value for {missing}")
        value = [value[j] for j in names]
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{prefix} must be a number or an array of {n} numbers, got {value!r}") from err
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    elif arr.shape != (n,):
        raise ValueError(f"{prefix} must be a scalar or have shape ({n},), got shape {arr.shape}")
    else:
        arr = arr.copy()
    bad = np.flatnonzero(np.isnan(arr) if allow_inf else ~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{prefix} has non-finite entries at indices {bad.tolist()}; {name} must be finite")
    if sign is not None:
        if sign not in ("non-negative", "positive"):
            raise ValueError(f"per_joint: sign must be None, 'non-negative' or 'positive', got {sign!r}")
        wrong = np.flatnonzero(arr < 0.0 if sign == "non-negative" else arr <= 0.0)
        if wrong.size:
            what = "negative" if sign == "non-negative" else "not positive"
            raise ValueError(
                f"{prefix} must be {sign}; {what} at {entry} indices {wrong.tolist()}: {arr[wrong].tolist()}"
            )
    return arr


def check_plant(plant, who: str) -> MultibodyPlant:
    """``plant``, checked to be a finalized MultibodyPlant.

    Raises:
        ValueError: naming ``who``: not a MultibodyPlant, or not finalized.
    """
    if not isinstance(plant, MultibodyPlant):
        raise ValueError(f"{who}: plant must be a MultibodyPlant, got {type(plant).__name__}")
    if not plant.is_finalized():
        raise ValueError(f"{who}: the MultibodyPlant must be finalized")
    return plant


def resolve_body(
    plant: MultibodyPlant, body, who: str, *, model_instance: str | None = None, allow_world: bool = False
) -> RigidBody:
    """The plant's body given as a RigidBody, a name (in ``model_instance`` if given) or an index.

    Raises:
        ValueError: naming ``who``: a body of another plant, an unknown or ambiguous name,
            an unknown model instance, an index out of range, another type, or the world
            body unless ``allow_world``.
    """
    if isinstance(body, RigidBody):
        if int(body.index()) >= plant.num_bodies() or plant.get_body(body.index()).name() != body.name():
            raise ValueError(f"{who}: body '{body.name()}' does not belong to this plant")
        resolved = plant.get_body(body.index())
    elif isinstance(body, str):
        if model_instance is not None:
            if not plant.HasModelInstanceNamed(model_instance):
                raise ValueError(f"{who}: no model instance named {model_instance!r} in the plant")
            instance = plant.GetModelInstanceByName(model_instance)
            if not plant.HasBodyNamed(body, instance):
                raise ValueError(f"{who}: unknown body {body!r} in model instance {model_instance!r}")
            resolved = plant.GetBodyByName(body, instance)
        else:
            if not plant.HasBodyNamed(body):
                raise ValueError(f"{who}: unknown body {body!r}")
            try:
                resolved = plant.GetBodyByName(body)
            except RuntimeError as error:  # the name exists in several model instances
                raise ValueError(
                    f"{who}: the body name {body!r} is ambiguous ({error}); give its model instance"
                ) from None
    elif isinstance(body, (int, np.integer, BodyIndex)):
        index = int(body)
        if not 0 <= index < plant.num_bodies():
            raise ValueError(f"{who}: body index {index} out of range [0, {plant.num_bodies()})")
        resolved = plant.get_body(BodyIndex(index))
    else:
        raise ValueError(f"{who}: a body must be a RigidBody, a name or an index, got {type(body).__name__}")
    if not allow_world and resolved.index() == plant.world_body().index():
        raise ValueError(f"{who}: the world body cannot carry a contact of the robot")
    return resolved
