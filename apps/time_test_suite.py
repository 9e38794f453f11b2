"""Wall time of the default test suite, as ``make test`` runs it (issue 33's floor: <= 4 min on
2 cores).

Run: ``make time-tests`` (= ``python -m apps.time_test_suite --results test_suite``). It runs
``make test``'s two steps in processes of their own, as the Makefile does: ruff (check and
format check), then ``pytest -q -n WORKERS --dist loadfile -m "not slow"`` (``--workers``,
default 2: the floor's two cores), and prints each step's wall time, the whole, and the
pytest summary (passed, failed, skipped). ``--results NAME`` writes them to
``results/NAME.json`` with the floor, from which BENCHMARKS.md's "Speed" table is generated
(``make docs``). A suite that fails is reported (exit 1): its time is not a measurement of
the suite. Timings depend on what else runs on the machine: run it on an idle one.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from pathlib import Path

from apps.results import app_command, write_results
from apps.runner import positive_int, results_name, run_app

ROOT = Path(__file__).resolve().parent.parent
#: Issue 33's floor for ``make test``, s.
FLOOR_S = 240.0


def _timed(command: list[str]) -> tuple[float, subprocess.CompletedProcess]:
    start = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    return time.perf_counter() - start, done


def pytest_counts(summary: str) -> dict[str, int]:
    """{outcome: count} of pytest's last summary line (``12 passed, 2 skipped in 3.4s``)."""
    lines = [line for line in summary.strip().splitlines() if " in " in line and re.search(r"\d+ \w+", line)]
    if not lines:
        return {}
    return {
        word: int(count)
        for count, word in re.findall(r"(\d+) (passed|failed|skipped|errors?|xfailed|xpassed)", lines[-1])
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m apps.time_test_suite", description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=positive_int, default=2, help="pytest-xdist processes (default 2)")
    parser.add_argument("--results", type=results_name, default=None, metavar="NAME", help="write results/NAME.json")
    args = parser.parse_args(argv)

    def body() -> int:
        python = sys.executable
        steps = {
            "ruff": [[python, "-m", "ruff", "check", "."], [python, "-m", "ruff", "format", "--check", "."]],
            "pytest": [[python, "-m", "pytest", "-q", "-n", str(args.workers), "--dist", "loadfile", "-m", "not slow"]],
        }
        wall, summary, ok = {}, "", True
        for step, commands in steps.items():
            wall[step] = 0.0
            for command in commands:
                seconds, done = _timed(command)
                wall[step] += seconds
                ok = ok and done.returncode == 0
                if step == "pytest":
                    summary = done.stdout
                print(f"{' '.join(command[1:])}: {seconds:.1f} s (exit {done.returncode})")
        total = sum(wall.values())
        counts = pytest_counts(summary)
        print(f"make test's steps: {total:.1f} s on {args.workers} workers ({counts}); floor {FLOOR_S:.0f} s")
        if not ok:
            print(summary[-3000:])
            print("the suite failed: its time is not reported as a measurement", file=sys.stderr)
            return 1
        if args.results:
            data = {
                "workers": args.workers,
                "ruff_s": wall["ruff"],
                "pytest_s": wall["pytest"],
                "wall_s": total,
                "counts": counts,
                "floor_s": FLOOR_S,
            }
            print(f"wrote {write_results(args.results, data, command=app_command('apps.time_test_suite', argv))}")
        return 0

    return run_app("time_test_suite", body)


if __name__ == "__main__":
    raise SystemExit(main())
