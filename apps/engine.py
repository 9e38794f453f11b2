"""Where a study's jobs run: this process, a pool of local processes, or Ray (issue 35).

A study hands an engine a module-level function and a list of picklable jobs (trial specs,
a scenario as YAML text, arrays); the engine yields each job's result as it finishes. Drake
diagrams do not pickle, so a job carries parameters only and the worker builds what it
needs; each worker is a long-lived process (a Ray actor, or a pool process) whose
``initializer`` ran once (e.g. loading the compiled EKF steps) and whose module-level caches
(trial specs, refined models) last across its jobs.

Engines (``--engine``):

* ``local``: the jobs one after another in this process (``--workers 1``).
* ``pool``: ``concurrent.futures.ProcessPoolExecutor`` over spawned processes on this
  machine. A worker that dies fails the study with ``BrokenProcessPool`` (no retry).
* ``ray``: one Ray actor per worker (``num_cpus=1`` each). Without ``--cluster`` Ray starts
  on this machine (``ray.init(num_cpus=workers)``); with ``--cluster ADDRESS`` (or
  ``RAY_ADDRESS``) it joins that cluster and uses one actor per CPU of the cluster (or
  ``--workers``). A killed worker process is restarted by Ray and its job retried
  (``max_restarts``/``max_task_retries``); the driver hands each job's result on once.
  Every node must have the project installed as this machine has (``make install`` in a
  checkout at the same path, or the same image): the jobs name the project's functions,
  not their code, and the workers import them from the driver's checkout path. A cluster
  started by ``ray start`` authenticates its drivers with a token (Ray's default): run the
  driver with ``RAY_AUTH_MODE=token`` on a machine that holds the token.
* ``auto`` (default): ``local`` with one worker; else ``ray`` if Ray is installed, else
  ``pool``.

The workers run with one BLAS/OpenMP thread each (``WORKER_ENVIRONMENT``): a study's
parallelism is its workers, and a job's floating-point results must not depend on how many
threads a library chose, so that the same jobs give the same results bit for bit on any
engine and any number of workers (``tests/test_engine.py``).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import sys
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The engines of ``--engine``.
ENGINES = ("auto", "local", "pool", "ray")

#: Set in every worker process (and for the pool's children while it starts them).
WORKER_ENVIRONMENT = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def ray_installed() -> bool:
    """True when the ``ray`` package can be imported (``make install`` installs it)."""
    return importlib.util.find_spec("ray") is not None


def add_engine_arguments(parser: argparse.ArgumentParser, default_workers: int | None = None) -> None:
    """``--engine``, ``--workers`` and ``--cluster``: how a study runs its jobs."""
    from apps.runner import positive_int

    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="auto",
        help="where the jobs run: auto (default: local for one worker, else ray if installed, else pool), "
        "local (this process), pool (local processes), ray",
    )
    parser.add_argument(
        "--workers",
        type=positive_int,
        default=default_workers,
        help="parallel workers (default: every core here; with --cluster, every CPU of the cluster)",
    )
    parser.add_argument(
        "--cluster",
        default=None,
        metavar="ADDRESS",
        help="the address of a running Ray cluster (host:port of `ray start --head`), or RAY_ADDRESS; "
        "implies --engine ray",
    )


@dataclass(frozen=True)
class EngineChoice:
    """What ``--engine/--workers/--cluster`` resolved to: ``kind`` (local, pool, ray),
    ``workers`` (None: Ray decides from the cluster's CPUs) and the Ray ``cluster`` address."""

    kind: str
    workers: int | None
    cluster: str | None = None


def choose_engine(engine: str = "auto", workers: int | None = None, cluster: str | None = None) -> EngineChoice:
    """Resolves the command line's choice (``add_engine_arguments``).

    Raises:
        ValueError: an unknown engine, fewer than one worker, ``--cluster`` with an engine
            other than ray or auto, or Ray asked for but not installed.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    cluster = cluster or (os.environ.get("RAY_ADDRESS") if engine in ("auto", "ray") else None) or None
    if cluster is not None:
        if engine not in ("auto", "ray"):
            raise ValueError(f"--cluster runs on Ray: it cannot be used with --engine {engine}")
        engine = "ray"
    if engine == "auto":
        count = workers if workers is not None else (os.cpu_count() or 1)
        engine = "local" if count == 1 else "ray" if ray_installed() else "pool"
    if engine == "ray" and not ray_installed():
        raise ValueError("--engine ray needs the ray package: `make install` installs it (pip install 'ray>=2.40')")
    if engine != "ray" or cluster is None:
        workers = workers if workers is not None else (os.cpu_count() or 1)
    if engine == "local":
        workers = 1
    return EngineChoice(engine, workers, cluster)


def engine_from_args(args: argparse.Namespace) -> EngineChoice:
    """``choose_engine`` of the parsed ``add_engine_arguments``."""
    return choose_engine(args.engine, args.workers, args.cluster)


class Engine:
    """Runs jobs on the chosen engine; a context manager (``open_engine``)."""

    def __init__(self, choice: EngineChoice, initializer: Callable[[], None] | None = None):
        self.choice = choice
        self.initializer = initializer
        self.workers = choice.workers or 1
        self._stack = contextlib.ExitStack()
        self._pool: ProcessPoolExecutor | None = None
        self._actors: list = []
        self._ray = None

    @property
    def kind(self) -> str:
        return self.choice.kind

    def __enter__(self) -> Engine:
        try:
            if self.kind == "local":
                if self.initializer is not None:
                    self.initializer()
            elif self.kind == "pool":
                self._start_pool()
            else:
                self._start_ray()
        except BaseException:
            self._stack.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self._stack.close()

    def _start_pool(self) -> None:
        import multiprocessing

        saved = {key: os.environ.get(key) for key in WORKER_ENVIRONMENT}
        os.environ.update(WORKER_ENVIRONMENT)  # inherited by the spawned children
        self._stack.callback(_restore_environment, saved)
        self._pool = ProcessPoolExecutor(
            self.workers, mp_context=multiprocessing.get_context("spawn"), initializer=self.initializer
        )
        self._stack.callback(self._pool.shutdown, wait=True, cancel_futures=True)

    def _start_ray(self) -> None:
        import ray

        self._ray = ray
        if not ray.is_initialized():
            options: dict[str, Any] = {
                "include_dashboard": False,
                "log_to_driver": True,
                "configure_logging": True,
                "logging_level": "warning",
                "runtime_env": {"env_vars": _ray_worker_environment()},
            }
            if self.choice.cluster is None:
                # A new instance on this machine, even where `ray start` left one running
                # (Ray would connect to it): a cluster is used only when asked for.
                options.update(address="local", num_cpus=self.workers)
            else:
                options["address"] = self.choice.cluster
            try:
                ray.init(**options)
            except ConnectionError as error:
                hint = (
                    ""
                    if os.environ.get("RAY_AUTH_MODE")
                    else " (a cluster with token authentication: RAY_AUTH_MODE=token)"
                )
                raise ValueError(f"cannot reach the Ray cluster at {self.choice.cluster}{hint}: {error}") from None
            self._stack.callback(ray.shutdown)
        if self.choice.workers is None:
            self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=-1)(_Worker)
        self._actors = [actor.remote(self.initializer) for _ in range(self.workers)]

    def imap_unordered(self, function: Callable[[Any], Any], jobs: Iterable[Any]) -> Iterator[Any]:
        """``function(job)`` of every job, as the jobs finish (in any order). ``function``
        must be importable by name (a module-level function), the jobs picklable."""
        jobs = list(jobs)
        if self.kind == "local":
            for job in jobs:
                yield function(job)
        elif self.kind == "pool":
            pending = {self._pool.submit(function, job) for job in jobs}
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    yield future.result()
        else:
            yield from self._ray_imap(function, jobs)

    def map(self, function: Callable[[Any], Any], jobs: Iterable[Any]) -> list[Any]:
        """``function(job)`` of every job, in the jobs' order (run as ``imap_unordered``)."""
        jobs = list(jobs)
        results: list[Any] = [None] * len(jobs)
        for index, result in self.imap_unordered(_call_indexed, [(function, i, job) for i, job in enumerate(jobs)]):
            results[index] = result
        return results

    def _ray_imap(self, function, jobs: list) -> Iterator[Any]:
        ray = self._ray
        queue = list(reversed(jobs))
        idle = list(self._actors)
        running: dict = {}  # object ref -> actor
        try:
            while queue or running:
                while idle and queue:  # one job in flight per actor: the others wait here
                    actor = idle.pop()
                    running[actor.run.remote(function, queue.pop())] = actor
                done, _ = ray.wait(list(running), num_returns=1)
                for ref in done:
                    idle.append(running.pop(ref))
                    yield ray.get(ref)
        finally:
            for ref in running:  # the driver stops early (an error, Ctrl-C): drop the rest
                try:
                    ray.cancel(ref)
                except Exception:  # noqa: BLE001 (a failed cancel must not hide the first error)
                    pass

    def worker_process_ids(self) -> list[int]:
        """The process ids of the workers (Ray: the actors'; pool: its processes; local:
        this one)."""
        if self.kind == "local":
            return [os.getpid()]
        if self.kind == "pool":
            return sorted(self._pool._processes)  # noqa: SLF001 (no public accessor)
        return sorted(self._ray.get([a.pid.remote() for a in self._actors]))


class _Worker:
    """A Ray actor: a worker process that ran ``initializer`` once and runs jobs."""

    def __init__(self, initializer: Callable[[], None] | None):
        os.environ.update(WORKER_ENVIRONMENT)
        if initializer is not None:
            initializer()

    def run(self, function: Callable[[Any], Any], job: Any) -> Any:
        return function(job)

    def pid(self) -> int:
        return os.getpid()


def _ray_worker_environment() -> dict[str, str]:
    """The Ray workers' environment: ``WORKER_ENVIRONMENT`` and the project's root on
    ``PYTHONPATH`` (the project runs from its checkout, ``pyproject.toml``: a worker on any
    node imports it from the same path)."""
    root = str(Path(__file__).resolve().parents[1])
    path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)
    return {**WORKER_ENVIRONMENT, "PYTHONPATH": path}


def _call_indexed(job: tuple[Callable[[Any], Any], int, Any]) -> tuple[int, Any]:
    """(index, function(job)) of an indexed job (``Engine.map``)."""
    function, index, payload = job
    return index, function(payload)


def worker_info(job: int) -> dict:
    """A job that tells where it ran: ``job`` back, the worker's host name and process id
    and its BLAS threads (``WORKER_ENVIRONMENT``); ``python -m apps.engine`` runs it on
    every worker to check a cluster."""
    import socket

    return {
        "job": job,
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m apps.engine [--engine E] [--workers N] [--cluster ADDRESS]``: starts the
    engine, runs ``worker_info`` on it (four jobs per worker) and prints its workers."""
    parser = argparse.ArgumentParser(prog="python -m apps.engine", description=main.__doc__)
    add_engine_arguments(parser)
    args = parser.parse_args(argv)
    try:
        choice = engine_from_args(args)
    except ValueError as error:
        print(f"engine: error: {error}", file=sys.stderr)
        return 2
    with open_engine(choice) as engine:
        infos = list(engine.imap_unordered(worker_info, range(4 * engine.workers)))
    print(f"{choice.kind}: {engine.workers} worker(s)")
    for host, pid in sorted({(i["host"], i["pid"]) for i in infos}):
        print(f"  {host} pid {pid}: {sum(i['pid'] == pid for i in infos)} job(s)")
    return 0


def _restore_environment(saved: dict[str, str | None]) -> None:
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


def open_engine(choice: EngineChoice, initializer: Callable[[], None] | None = None) -> Engine:
    """The engine ``choice`` (``choose_engine``), to be used as a context manager: its
    workers are started on entry (each running ``initializer`` once) and stopped on exit."""
    return Engine(choice, initializer)


if __name__ == "__main__":
    raise SystemExit(main())
