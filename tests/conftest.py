"""Shared test setup: matplotlib draws off screen (the Makefile exports the same for the apps)."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
