"""Headless Chromium for the tests that open a page in a real browser (the Meshcat replay, the
documentation site): where it is, a skip marker for machines without it, and one launch
procedure with its retries."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest


def chromium() -> str | None:
    """The Chromium executable, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


#: Skips a test where Chromium is not installed, except in CI (``CI`` set), where it must be.
requires_chromium = pytest.mark.skipif(
    chromium() is None and not os.environ.get("CI"),
    reason="Debian's chromium is not installed (make test-slow installs it when run as root; CI always has it)",
)

#: Offline, headless, no profile sync or updates; a virtual-time budget shorter than a
#: recorded animation (with a budget past an animation's end, headless Chromium 156 waited
#: forever in 4 of 6 launches, measured; with 1 s it finished in 4-20 s in 16 of 16).
FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--disable-dev-shm-usage",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--disable-sync",
    "--virtual-time-budget=1000",
)


def run_chromium(args: list[str], url: str, tmp_path: Path, name: str, succeeded: Callable[[str], bool]) -> str:
    """Opens ``url`` in headless Chromium with ``FLAGS`` and ``args``, up to three times until
    ``succeeded(stdout)``; each attempt gets a fresh profile and 90 s (a hung browser is
    killed), and its stderr is kept for the report. Returns the successful attempt's stdout.

    Raises:
        AssertionError: no attempt succeeded (the last one's stderr tail in the message).
    """
    executable = chromium()
    assert executable, "chromium must be installed in CI (.ci/run runs make test-slow, which installs it)"
    log_tail = ""
    for attempt in range(3):
        command = [executable, *FLAGS, *args, f"--user-data-dir={tmp_path / f'profile-{name}{attempt}'}", url]
        log = tmp_path / f"chromium-{name}{attempt}.log"
        with log.open("w") as stderr:
            process = subprocess.Popen(
                command, stdout=subprocess.PIPE, stderr=stderr, text=True, start_new_session=True
            )
            try:
                output, _ = process.communicate(timeout=90)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                output, _ = process.communicate()
        if succeeded(output):
            return output
        log_tail = "\n".join(log.read_text(errors="replace").splitlines()[-15:])
    raise AssertionError(f"chromium did not open {url} in 3 attempts; last stderr lines:\n{log_tail}")
