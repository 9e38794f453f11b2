"""Where the supported Drake releases differ: the one place that knows.

``pyproject.toml`` admits ``drake>=1.51.1,<1.59``. Two releases are tested (docs/installation.md, "Tested
versions"): drake 1.51.1, the last release with wheels for Python 3.11, and drake 1.58.0 on
Python 3.12 and 3.13. Everything else in the project uses API the two share:

* the free-body API under its current names (``SetFreeBodyPose(context, body, X_JpJc)``,
  ``SetFreeBodySpatialVelocity(context, body, V_JpJc)``, ``GetFreeBodyPose``,
  ``GetDefaultFloatingBaseBodyPose``), which both releases have with the same meaning; the
  names 1.51.1 deprecates (``GetUniqueFreeBaseBodyOrThrow``, ``SetDefaultFreeBodyPose``,
  ``HasUniqueFreeBaseBody``, ``SetFreeBodyPoseInWorldFrame`` and the old argument order of
  ``SetFreeBodySpatialVelocity``) are gone in 1.58.0 and are not used;
* ``MultibodyPlantConfig``, whose fields and defaults are the same in both.

What differs is listed here, each with the releases it depends on.
"""

from __future__ import annotations

import importlib.metadata

#: Fields of Drake's configuration structs that not every supported release has. A scenario
#: file written for every release (``apps.write_scenarios``) leaves them out; they keep
#: Drake's default there.
#:
#: * ``SimulatorConfig.publish_every_time_step``: drake 1.51.1 has it (default false; its
#:   ``Simulator.set_publish_every_time_step`` is deprecated, removal 2026-06-01);
#:   drake 1.58.0 has neither.
UNSHARED_CONFIG_FIELDS: dict[str, tuple[str, ...]] = {
    "SimulatorConfig": ("publish_every_time_step",),
}


#: Features drake 1.51.1 deprecates, with the first release that no longer has them (the
#: deprecation test uses them as controls on the releases that still have them).
REMOVED_IN: dict[str, tuple[int, int]] = {
    "TAMSI discrete contact solver": (1, 57),
    "Simulator.set_publish_every_time_step": (1, 58),
}


def drake_version() -> tuple[int, ...] | None:
    """The installed Drake's release as a tuple of ints (e.g. ``(1, 58, 0)``), or None when
    Drake is not an installed distribution (a build from source on ``PYTHONPATH``)."""
    try:
        text = importlib.metadata.version("drake")
    except importlib.metadata.PackageNotFoundError:
        return None
    parts = []
    for piece in text.split("."):
        digits = "".join(c for c in piece if c.isdigit())
        if not digits:
            break
        parts.append(int(digits))
    return tuple(parts)


def still_has(feature: str) -> bool:
    """Whether the installed release still has ``feature`` of ``REMOVED_IN`` (False for an
    unknown release: a build from source)."""
    version = drake_version()
    return version is not None and (1, 51) <= version[:2] < REMOVED_IN[feature]


__all__ = ["REMOVED_IN", "UNSHARED_CONFIG_FIELDS", "drake_version", "still_has"]
