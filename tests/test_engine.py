"""The study engines (``apps.engine``): the choice from the command line, and the same
results from this process, a process pool and Ray actors."""

from __future__ import annotations

import os

import pytest

from apps.engine import WORKER_ENVIRONMENT, choose_engine, main, open_engine, ray_installed, worker_info


def test_choice_from_the_command_line(monkeypatch):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert choose_engine("auto", 1).kind == "local"
    assert choose_engine("local", 4) == choose_engine("local", 1)  # one worker: this process
    assert choose_engine("pool", 3).workers == 3
    auto = choose_engine("auto", 2)
    assert auto.kind == ("ray" if ray_installed() else "pool") and auto.workers == 2
    assert choose_engine("pool").workers == (os.cpu_count() or 1)
    cluster = choose_engine("auto", None, "10.0.0.1:6379")
    assert (cluster.kind, cluster.workers, cluster.cluster) == ("ray", None, "10.0.0.1:6379")
    monkeypatch.setenv("RAY_ADDRESS", "10.0.0.2:6379")
    assert choose_engine("auto", 2).cluster == "10.0.0.2:6379"
    assert choose_engine("pool", 2).cluster is None  # RAY_ADDRESS is for Ray only
    for bad, match in (
        (lambda: choose_engine("dask"), "engine"),
        (lambda: choose_engine("pool", 0), "workers"),
        (lambda: choose_engine("pool", 2, "10.0.0.1:6379"), "--cluster"),
    ):
        with pytest.raises(ValueError, match=match):
            bad()


@pytest.mark.parametrize("kind", ["local", "pool"])
def test_local_engines_give_every_result_once(kind):
    with open_engine(choose_engine(kind, 2)) as engine:
        results = sorted(engine.imap_unordered(worker_info, range(7)), key=lambda r: r["job"])
        workers = engine.worker_process_ids()
    assert [r["job"] for r in results] == list(range(7))
    assert {r["pid"] for r in results} <= set(workers)
    with open_engine(choose_engine(kind, 2)) as engine:
        ordered = engine.map(worker_info, [5, 3, 9, 1])
    assert [r["job"] for r in ordered] == [5, 3, 9, 1]  # map keeps the jobs' order
    if kind == "pool":
        assert all(r["blas_threads"] == WORKER_ENVIRONMENT["OPENBLAS_NUM_THREADS"] for r in results)
        assert len(workers) == 2 and os.getpid() not in workers
    else:
        assert workers == [os.getpid()]


@pytest.mark.slow
def test_ray_actors_give_every_result_once():
    pytest.importorskip("ray")
    with open_engine(choose_engine("ray", 2)) as engine:
        results = sorted(engine.imap_unordered(worker_info, range(9)), key=lambda r: r["job"])
        workers = engine.worker_process_ids()
    assert [r["job"] for r in results] == list(range(9))
    assert all(r["blas_threads"] == "1" for r in results)  # one BLAS thread per actor
    assert {r["pid"] for r in results} <= set(workers)
    assert len(set(workers)) == 2 and os.getpid() not in workers
    # A job's error reaches the driver as its own type (run_app reports a ValueError in one line).
    with open_engine(choose_engine("ray", 2)) as engine:
        with pytest.raises(ValueError, match="invalid literal"):
            list(engine.imap_unordered(int, ["1", "x", "2", "3"]))


@pytest.mark.parametrize("kind", ["local", "pool"])
def test_a_failing_job_raises_its_error(kind):
    with open_engine(choose_engine(kind, 2)) as engine:
        with pytest.raises(ValueError, match="invalid literal"):
            list(engine.imap_unordered(int, ["1", "x", "2"]))


def test_engine_command_lists_its_workers(capsys):
    assert main(["--engine", "pool", "--workers", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("pool: 2 worker(s)") and 1 <= out.count(" pid ") <= 2  # a fast worker may take all
    assert main(["--engine", "pool", "--cluster", "127.0.0.1:1"]) == 2
