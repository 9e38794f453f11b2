"""Deprecated home of the apps' shared pieces: they live in ``apps.runner`` now."""

from apps.runner import logged_signals, memory_allocator, replay_meshcat

__all__ = ["logged_signals", "memory_allocator", "replay_meshcat"]
