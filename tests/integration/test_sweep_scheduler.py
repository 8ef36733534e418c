"""``auv-swarm sweep --scheduler``: a real ``dask scheduler`` and ``dask worker`` processes on free loopback ports.

A worker SIGKILLed by pid mid-sweep: its mission runs again and every row equals an undisturbed run's; a worker
of another auv-swarm version stops the sweep (exit 1 naming both), and so does a worker that lacks a plug-in method
the sweep picks (before any mission). Every process is stopped by pid."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from auv_swarm.contract.config import load_scenario
from auv_swarm.orchestrator.mission import procs
from auv_swarm.orchestrator.mission.api import run_mission
from auv_swarm.orchestrator.sweep import store as st
from auv_swarm.orchestrator.sweep.version import FAKE_VERSION_ENV, version
from auv_swarm.results.metrics import comparable
from tests.integration.test_sweep import done_rows

pytestmark = pytest.mark.integration

SCENARIO = "paper-3.3-sim2"


@contextmanager
def cluster(logs: Path, workers: int, env: dict[str, str] | None = None) -> Iterator[tuple[str, list]]:
    """A loopback scheduler and ``workers`` nanny-supervised workers (one thread each); yields (address, workers)."""
    port = procs.free_port()
    address = f"tcp://127.0.0.1:{port}"
    started = []
    try:
        sched = procs.spawn(
            procs.python_argv(
                "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"
            ),
            "scheduler",
            log_path=logs / "scheduler.log",
        )
        started.append(sched)
        procs.wait_for_line(sched, r"Scheduler at:", timeout=60)
        for k in range(workers):
            w = procs.spawn(
                procs.python_argv(
                    "distributed.cli.dask_worker",
                    address,
                    "--nthreads",
                    "1",
                    "--nworkers",
                    "1",
                    "--host",
                    "127.0.0.1",
                    "--no-dashboard",
                ),
                f"worker{k}",
                env=env,
                log_path=logs / f"worker{k}.log",
            )
            started.append(w)
        for w in started[1:]:
            procs.wait_for_line(w, r"Registered to:", timeout=60)
        yield address, started[1:]
    finally:
        for p in reversed(started):
            procs.stop(p)
        assert not any(procs.group_alive(p.pid) for p in started)


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def test_a_worker_killed_mid_sweep_changes_no_row(tmp_path: Path) -> None:
    out = tmp_path / "s"
    with cluster(tmp_path, 2) as (address, workers):
        client = procs.spawn(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                SCENARIO,
                "planner.method=dmpc,dec-mpc",
                "--seeds",
                "1-4",
                "--scheduler",
                address,
                "--out",
                str(out),
            ],
            "sweep",
            log_path=tmp_path / "sweep.log",
        )
        try:
            deadline = time.monotonic() + 120
            while done_rows(out) < 1:
                assert client.poll() is None and time.monotonic() < deadline, procs.read_log(client)
                time.sleep(0.05)
            victims = _children(workers[0].pid)
            assert victims, "the nanny has no worker process"
            os.kill(victims[0], signal.SIGKILL)
            assert client.wait(timeout=180) == 0, procs.read_log(client)
        finally:
            procs.stop(client)
    log = procs.read_log(client)
    assert "error:" not in log and "failed:" not in log and "Traceback" not in log
    rows = st.read_rows(out)
    assert len(rows) == 8 and {r["status"] for r in rows} == {"done"}
    assert len({r["worker"] for r in rows}) >= 2
    for r in rows:
        s = load_scenario(SCENARIO).with_keys({"planner.method": r["planner.method"], "run.seed": r["seed"]})
        expected = json.loads(json.dumps(run_mission(s).metrics))
        assert comparable(json.loads(r["metrics"])) == comparable(expected), (r["planner.method"], r["seed"])


def test_a_worker_of_another_version_stops_the_sweep(tmp_path: Path) -> None:
    out = tmp_path / "v"
    with cluster(tmp_path, 1, env={FAKE_VERSION_ENV: "9.9.9-fake"}) as (address, _workers):
        done = subprocess.run(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                SCENARIO,
                "--seeds",
                "2",
                "--duration",
                "20",
                "--scheduler",
                address,
                "--out",
                str(out),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            env={k: v for k, v in os.environ.items() if k != FAKE_VERSION_ENV},
        )
    assert done.returncode == 1
    err = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert len(err) == 1 and "9.9.9-fake" in err[0] and version() in err[0], done.stderr
    assert "Traceback" not in done.stderr


def test_an_unreachable_scheduler_is_one_line(tmp_path: Path) -> None:
    port = procs.free_port()
    done = subprocess.run(
        [
            *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
            SCENARIO,
            "--seeds",
            "1",
            "--duration",
            "20",
            "--scheduler",
            f"tcp://127.0.0.1:{port}",
            "--out",
            str(tmp_path / "u"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1].startswith("error: cannot reach the Dask scheduler at tcp://127.0.0.1:")
    assert "Traceback" not in done.stderr


def test_the_client_gives_up_a_mission_whose_worker_keeps_dying(tmp_path: Path, fault_plugins: dict[str, str]) -> None:
    out = tmp_path / "d"
    with cluster(tmp_path, 2, env=fault_plugins) as (address, _workers):
        done = subprocess.run(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                SCENARIO,
                "planner.method=fault-die",  # the installed plug-in kills its worker in the missions of seed 2
                "--seeds",
                "3",
                "--duration",
                "20",
                "--scheduler",
                address,
                "--out",
                str(out),
            ],
            capture_output=True,
            text=True,
            timeout=240,
            env={**os.environ, **fault_plugins},
        )
    assert done.returncode == 1, done.stderr
    assert "error: 1 of 3 missions failed" in done.stderr and "Traceback" not in done.stderr
    rows = {r["seed"]: r for r in st.read_rows(out)}
    assert rows[2]["status"] == "failed" and "its worker died" in rows[2]["error"]
    assert rows[1]["status"] == rows[3]["status"] == "done"


def test_a_sweep_refuses_up_front_a_plugin_a_worker_lacks(tmp_path: Path, fault_plugins: dict[str, str]) -> None:
    """The client has the plug-in package installed, the cluster's workers do not: one line naming a worker, exit 1,
    no mission run."""
    out = tmp_path / "l"
    with cluster(tmp_path, 1) as (address, workers):
        done = subprocess.run(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                SCENARIO,
                "planner.method=dmpc,fault-raise",
                "--seeds",
                "1",
                "--scheduler",
                address,
                "--out",
                str(out),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            env={**os.environ, **fault_plugins},
        )
    assert done.returncode == 1, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("error: worker tcp://127.0.0.1:") and "cannot run this sweep" in last, done.stderr
    assert "planner.method 'fault-raise' is not known here" in last and "Traceback" not in done.stderr
    assert st.read_rows(out) == []
