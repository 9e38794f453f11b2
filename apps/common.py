"""Small pieces shared by the apps."""

from __future__ import annotations

import os

from pydrake.geometry import Meshcat


def memory_allocator() -> str:
    """"tcmalloc" when the process runs with tcmalloc preloaded (``make`` does it when the
    library is installed: Drake's SAP solver then takes less time per step), else "system"."""
    return "tcmalloc" if "tcmalloc" in os.environ.get("LD_PRELOAD", "") else "system"


def replay_meshcat(enabled: bool, headless: bool) -> Meshcat | None:
    """A Meshcat for recording the apps' replays (None when replays are off); prints its live
    URL unless ``headless``."""
    if not enabled:
        return None
    meshcat = Meshcat()
    if not headless:
        print(f"Meshcat (live view): {meshcat.web_url()}")
    return meshcat


def logged_signals(loggers: dict, context, time_from: str) -> dict:
    """{name: (size, samples) array} of every logger's log in ``context``, plus ``"t"``, the
    sample times of the logger ``time_from`` (all loggers of one rate share them)."""
    logs = {name: logger.FindLog(context) for name, logger in loggers.items()}
    signals = {name: log.data() for name, log in logs.items()}
    signals["t"] = logs[time_from].sample_times()
    return signals
