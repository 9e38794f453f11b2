"""Shared test set-up: the apps write their plots to files (matplotlib's file backend, as
the Makefile sets for ``make``), unless the caller chose a backend."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
