"""``apps.time_test_suite`` (``make time-tests``): the pytest summary it reads and its
refusals. Running the suite itself belongs to the command, not to a test of the suite."""

from __future__ import annotations

import pytest

from apps import time_test_suite


def test_pytest_counts_reads_the_last_summary_line():
    summary = "....s.\n[100%]\n= 3 failed, 904 passed, 2 skipped, 1 error in 291.04s (0:04:51) =\n"
    assert time_test_suite.pytest_counts(summary) == {"failed": 3, "passed": 904, "skipped": 2, "error": 1}
    assert time_test_suite.pytest_counts("904 passed in 12.3s\n") == {"passed": 904}
    assert time_test_suite.pytest_counts("no tests ran\n") == {}


@pytest.mark.parametrize("argv", [["--workers", "0"], ["--results", "a/b"]])
def test_bad_arguments_are_refused(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        time_test_suite.main(argv)
    assert exit_info.value.code == 2
    assert "error" in capsys.readouterr().err
