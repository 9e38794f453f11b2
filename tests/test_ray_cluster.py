"""A sweep on a real Ray cluster (issue 35): a head node and a second worker node started on
this machine with ``ray start`` on loopback ports, one CPU each. One worker process is killed
in the middle of a sweep: every trial still completes exactly once, with the rows of a
one-worker run in this process. Then the driver is killed in the middle of a sweep and
``--resume`` finishes it, with the same rows again."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyarrow as pa
import pytest

from apps import sweep
from diagrams.residuals.contact_sweep import RUN_COLUMNS, read_trials

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
#: 2 cells x 6 trials, one trial per chunk: 12 jobs of about 2 s each.
GRID = "{world: ideal, robots: [hrp4_like], noise_scales: [0.5, 1.0], trials_per_cell: 6, trials_per_job: 1,"
GRID += " base: {push_start: 0.3}}"


#: ``ray start`` turns Ray's token authentication on; its drivers need this to send the token.
AUTH = {"RAY_AUTH_MODE": "token"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ray_command() -> str:
    ray = Path(sys.executable).with_name("ray")
    return str(ray) if ray.exists() else shutil.which("ray")


@pytest.fixture(scope="module")
def ray_cluster():
    """The address of a 2-node local cluster (1 CPU each); its processes are killed after."""
    pytest.importorskip("ray")
    ray = _ray_command()
    temp = Path(tempfile.mkdtemp(prefix="rt", dir="/tmp"))  # short: Ray's socket paths have a length limit
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_USAGE_STATS_ENABLED": "0", **AUTH}
    common = ["--num-cpus=1", "--node-ip-address=127.0.0.1", "--disable-usage-stats"]
    nodes = []
    try:
        head = [ray, "start", "--head", f"--port={port}", "--include-dashboard=false", f"--temp-dir={temp}", *common]
        nodes.append(subprocess.Popen([*head, "--block"], env=env, cwd=ROOT, start_new_session=True))
        address = f"127.0.0.1:{port}"
        _wait_for_cpus(address, 1, env)
        worker = [ray, "start", f"--address={address}", *common, "--block"]
        nodes.append(subprocess.Popen(worker, env=env, cwd=ROOT, start_new_session=True))
        _wait_for_cpus(address, 2, env)
        yield address
    finally:
        for node in nodes:
            try:
                os.killpg(node.pid, signal.SIGTERM)
                node.wait(timeout=20)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                with_group = getattr(node, "pid", None)
                if with_group:
                    try:
                        os.killpg(with_group, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
        # The cluster's processes that left the nodes' process groups (e.g. workers).
        subprocess.run(["pkill", "-9", "-f", str(temp)], check=False)
        shutil.rmtree(temp, ignore_errors=True)


def _wait_for_cpus(address: str, cpus: int, env: dict, timeout: float = 90.0) -> None:
    code = (
        "import ray, sys; ray.init(address=sys.argv[1], logging_level='error');"
        "print(int(ray.cluster_resources().get('CPU', 0)))"
    )
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        run = subprocess.run([sys.executable, "-c", code, address], env=env, capture_output=True, text=True)
        if run.returncode == 0 and run.stdout.strip().splitlines()[-1:] == [str(cpus)]:
            return
        time.sleep(2.0)
    raise RuntimeError(f"the Ray cluster at {address} did not reach {cpus} CPUs: {run.stderr[-2000:]}")


def _sweep(out: Path, *extra: str) -> subprocess.Popen:
    command = [sys.executable, "-m", "apps.sweep", "--grid-text", GRID, "--no-progress", "--out", str(out), *extra]
    env = {**os.environ, **AUTH}
    return subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _wait_for_chunks(folder: Path, count: int, process: subprocess.Popen, timeout: float = 300.0) -> list[Path]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        files = sorted((folder / "trials").glob("*.parquet")) if (folder / "trials").is_dir() else []
        if len(files) >= count:
            return files
        if process.poll() is not None:
            raise RuntimeError(f"the sweep ended early: {process.stdout.read()[-3000:]}")
        time.sleep(0.2)
    raise RuntimeError(f"no {count} chunks written in {timeout} s")


def _rows(folder: Path) -> pa.Table:
    table = read_trials(folder).drop_columns(list(RUN_COLUMNS))
    return table.sort_by([("cell", "ascending"), ("trial", "ascending")])


@pytest.fixture(scope="module")
def one_worker_rows(tmp_path_factory) -> pa.Table:
    out = tmp_path_factory.mktemp("one_worker")
    assert sweep.main(["--grid-text", GRID, "--engine", "local", "--no-progress", "--out", str(out)]) == 0
    return _rows(out / "sweep")


def _exactly_once(folder: Path) -> None:
    table = read_trials(folder)
    keys = list(zip(table["cell"].to_pylist(), table["trial"].to_pylist()))
    assert len(keys) == 12 and len(set(keys)) == 12


def test_a_killed_worker_loses_no_trial(ray_cluster, one_worker_rows, tmp_path):
    process = _sweep(tmp_path, "--cluster", ray_cluster)
    first = _wait_for_chunks(tmp_path / "sweep", 1, process)
    victim = int(pa.parquet.read_table(first[0])["worker"][0].as_py().rsplit(":", 1)[1])
    os.kill(victim, signal.SIGKILL)  # an actor of the cluster, most likely in its next chunk
    output, _ = process.communicate(timeout=600)
    assert process.returncode == 0, output[-3000:]
    assert "on ray with 2 worker(s)" in output
    _exactly_once(tmp_path / "sweep")
    assert _rows(tmp_path / "sweep").equals(one_worker_rows)
    workers = set(read_trials(tmp_path / "sweep")["worker"].to_pylist())
    assert f"{socket.gethostname()}:{victim}" in workers and len(workers) >= 3  # the killed actor came back anew


def test_a_killed_driver_is_resumed(ray_cluster, one_worker_rows, tmp_path):
    process = _sweep(tmp_path, "--cluster", ray_cluster)
    _wait_for_chunks(tmp_path / "sweep", 3, process)
    process.kill()
    process.wait()
    done = len(list((tmp_path / "sweep" / "trials").glob("*.parquet")))
    assert 3 <= done < 12
    assert not list((tmp_path / "sweep" / "trials").glob("*.tmp"))  # nothing half-written is kept as a chunk
    resumed = _sweep(tmp_path, "--cluster", ray_cluster, "--resume")
    output, _ = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, output[-3000:]
    assert f"({done} trials already done)" in output
    _exactly_once(tmp_path / "sweep")
    assert _rows(tmp_path / "sweep").equals(one_worker_rows)
