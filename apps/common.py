"""Small pieces shared by the apps."""

from __future__ import annotations

from pydrake.geometry import Meshcat


def replay_meshcat(enabled: bool, headless: bool) -> Meshcat | None:
    """A Meshcat for recording the apps' replays (None when replays are off); prints its live
    URL unless ``headless``."""
    if not enabled:
        return None
    meshcat = Meshcat()
    if not headless:
        print(f"Meshcat (live view): {meshcat.web_url()}")
    return meshcat
