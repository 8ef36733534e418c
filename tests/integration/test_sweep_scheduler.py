"""``auv-swarm sweep --scheduler``: a real ``dask scheduler`` and ``dask worker`` processes on free loopback ports,
started as docs/sweeps.md's recipe starts them: mutual TLS with the files of ``auv-swarm credentials --dask DIR``.

The cluster listens on loopback only and answers a client holding DIR's certificate, refuses one without it; a
worker SIGKILLed by pid mid-sweep: its mission runs again and every row equals the LocalCluster's for the same
grid; a worker of another auv-swarm version stops the sweep (exit 1 naming both; over plain TCP with
``--insecure-scheduler``, which warns), and so does a worker that lacks a plug-in method the sweep picks (before
any mission); an unreachable scheduler is one line. Every process is stopped by pid."""

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

from auv_swarm.bus import credentials, tls
from auv_swarm.orchestrator.cli import sweep as sweep_verb
from auv_swarm.orchestrator.mission import procs
from auv_swarm.orchestrator.sweep import store as st
from auv_swarm.orchestrator.sweep.version import FAKE_VERSION_ENV, version
from auv_swarm.results.metrics import comparable
from tests import listeners
from tests.integration.test_sweep import done_rows

pytestmark = pytest.mark.integration

SCENARIO = "paper-3.3-sim2"


def _tls_flags(tls_dir: Path | None, role: str) -> list[str]:
    """Dask's own TLS flags for ``role``'s files in ``tls_dir`` (docs/sweeps.md); none for plain TCP."""
    if tls_dir is None:
        return []
    return [
        *("--tls-ca-file", str(tls_dir / "ca.pem")),
        *("--tls-cert", str(tls_dir / f"{role}.pem"), "--tls-key", str(tls_dir / f"{role}.key")),
    ]


@contextmanager
def cluster(
    logs: Path, workers: int, env: dict[str, str] | None = None, tls_dir: Path | None = None
) -> Iterator[tuple[str, list]]:
    """A loopback scheduler and ``workers`` nanny-supervised workers (one thread each), by docs/sweeps.md's recipe:
    TLS with ``tls_dir``'s files (None: plain TCP), every listener on 127.0.0.1; yields (address, processes): the
    scheduler, then the workers."""
    port = procs.free_port()
    scheme = "tcp" if tls_dir is None else "tls"
    address = f"{scheme}://127.0.0.1:{port}"
    started = []
    try:
        sched = procs.spawn(
            procs.python_argv(
                "distributed.cli.dask_scheduler",
                *("--host", "127.0.0.1", "--port", str(port), "--protocol", scheme),
                *("--no-dashboard", "--dashboard-address", "127.0.0.1:0"),
                *_tls_flags(tls_dir, "scheduler"),
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
                    *("--nthreads", "1", "--nworkers", "1", "--host", "127.0.0.1"),
                    *("--no-dashboard", "--dashboard-address", "127.0.0.1:0"),
                    *_tls_flags(tls_dir, "worker"),
                ),
                f"worker{k}",
                env=env,
                log_path=logs / f"worker{k}.log",
            )
            started.append(w)
        for w in started[1:]:
            procs.wait_for_line(w, r"Registered to:", timeout=60)
        yield address, started
    finally:
        for p in reversed(started):
            procs.stop(p)
        assert not any(procs.group_alive(p.pid) for p in started)


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _check_listeners(processes: list, tls_dir: Path, other: Path) -> None:
    """The cluster's listeners are on loopback; its scheduler, nannies and workers answer ``tls_dir``'s client and
    refuse plain TCP, TLS without a certificate and another CA's client (the control of test_sweep_tls.py)."""
    found = [x for p in processes for x in listeners.listeners(p.pid)]
    assert found and [x for x in found if x.host != "127.0.0.1"] == [], found
    dask = [f"tls://{x.host}:{x.port}" for x in found if listeners.http_status(x.host, x.port) is None]
    assert len(dask) == 1 + 2 * (len(processes) - 1), found  # the scheduler, each worker and its nanny
    assert len(found) == len(dask) + len(processes), found  # and an HTTP server each, on loopback
    mine = listeners.client_context(tls_dir / "client.pem", tls_dir / "client.key", tls_dir / "ca.pem")
    theirs = listeners.client_context(other / "client.pem", other / "client.key")
    attempts = [(a, mine) for a in dask] + [(a.replace("tls://", "tcp://"), None) for a in dask]
    attempts += [(a, listeners.client_context()) for a in dask] + [(a, theirs) for a in dask]
    answers = listeners.dask_identity(attempts)
    n = len(dask)
    assert all(x.startswith("answered") for x in answers[:n]), answers[:n]
    assert {x.split(": ")[1] for x in answers[:n]} == {"'Scheduler'", "'Nanny'", "'Worker'"}, answers[:n]
    assert all(x.startswith("refused") for x in answers[n:]), answers[n:]


def test_a_worker_killed_mid_sweep_on_a_tls_cluster_changes_no_row(tmp_path: Path) -> None:
    tls_dir, other = tmp_path / "tls", tmp_path / "other"
    assert credentials.main(["--dask", str(tls_dir)]) == 0
    tls.write_dask(other)
    out = tmp_path / "s"
    grid = ["planner.method=dmpc,dec-mpc", "--seeds", "1-4"]
    with cluster(tmp_path, 2, tls_dir=tls_dir) as (address, processes):
        _check_listeners(processes, tls_dir, other)
        client = procs.spawn(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                *(SCENARIO, *grid, "--scheduler", address, "--tls-dir", str(tls_dir), "--out", str(out)),
            ],
            "sweep",
            log_path=tmp_path / "sweep.log",
        )
        try:
            deadline = time.monotonic() + 120
            while done_rows(out) < 1:
                assert client.poll() is None and time.monotonic() < deadline, procs.read_log(client)
                time.sleep(0.05)
            victims = _children(processes[1].pid)
            assert victims, "the nanny has no worker process"
            os.kill(victims[0], signal.SIGKILL)
            assert client.wait(timeout=180) == 0, procs.read_log(client)
        finally:
            procs.stop(client)
    log = procs.read_log(client)
    assert "error:" not in log and "failed:" not in log and "Traceback" not in log
    rows = st.read_rows(out)
    assert len(rows) == 8 and {r["status"] for r in rows} == {"done"}
    assert len({r["worker"] for r in rows}) >= 2 and all(r["worker"].startswith("tls://127.0.0.1:") for r in rows)
    local = sweep_verb.main([SCENARIO, *grid, "--workers", "2", "--out", str(tmp_path / "local"), "--quiet"])
    assert local == 0
    expected = {(r["planner.method"], r["seed"]): r for r in st.read_rows(tmp_path / "local")}
    for r in rows:
        twin = expected[(r["planner.method"], r["seed"])]
        assert comparable(json.loads(r["metrics"])) == comparable(json.loads(twin["metrics"])), (
            r["planner.method"],
            r["seed"],
        )


def test_a_worker_of_another_version_stops_the_sweep_on_an_insecure_cluster(tmp_path: Path) -> None:
    out = tmp_path / "v"
    with cluster(tmp_path, 1, env={FAKE_VERSION_ENV: "9.9.9-fake"}) as (address, _processes):
        assert address.startswith("tcp://")
        done = subprocess.run(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                *(SCENARIO, "--seeds", "2", "--duration", "20"),
                *("--scheduler", address, "--insecure-scheduler", "--out", str(out)),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            env={k: v for k, v in os.environ.items() if k != FAKE_VERSION_ENV},
        )
    assert done.returncode == 1
    err = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert len(err) == 1 and "9.9.9-fake" in err[0] and version() in err[0], done.stderr
    warnings = [line for line in done.stderr.splitlines() if line.startswith("warning: --insecure-scheduler")]
    assert len(warnings) == 1 and "anyone who can reach" in warnings[0], done.stderr
    assert "Traceback" not in done.stderr


def test_an_unreachable_scheduler_is_one_line_before_the_folder_is_made(tmp_path: Path) -> None:
    port = procs.free_port()
    tls.write_dask(tmp_path / "tls")
    done = subprocess.run(
        [
            *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
            *(SCENARIO, "--seeds", "1", "--duration", "20", "--out", str(tmp_path / "u")),
            *("--scheduler", f"tls://127.0.0.1:{port}", "--tls-dir", str(tmp_path / "tls")),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [done.stderr.strip()], done.stderr  # one line
    assert done.stderr.startswith("error: cannot reach the Dask scheduler at tls://127.0.0.1:")
    assert not (tmp_path / "u").exists()


def test_the_client_gives_up_a_mission_whose_worker_keeps_dying(tmp_path: Path, fault_plugins: dict[str, str]) -> None:
    out = tmp_path / "d"
    tls.write_dask(tmp_path / "tls")
    with cluster(tmp_path, 2, env=fault_plugins, tls_dir=tmp_path / "tls") as (address, _processes):
        done = subprocess.run(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                SCENARIO,
                "planner.method=fault-die",  # the installed plug-in kills its worker in the missions of seed 2
                *("--seeds", "3", "--duration", "20", "--out", str(out)),
                *("--scheduler", address, "--tls-dir", str(tmp_path / "tls")),
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
    tls.write_dask(tmp_path / "tls")
    with cluster(tmp_path, 1, tls_dir=tmp_path / "tls") as (address, _processes):
        done = subprocess.run(
            [
                *procs.python_argv("auv_swarm.orchestrator.cli.sweep"),
                *(SCENARIO, "planner.method=dmpc,fault-raise", "--seeds", "1", "--out", str(out)),
                *("--scheduler", address, "--tls-dir", str(tmp_path / "tls")),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            env={**os.environ, **fault_plugins},
        )
    assert done.returncode == 1, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("error: worker tls://127.0.0.1:") and "cannot run this sweep" in last, done.stderr
    assert "planner.method 'fault-raise' is not known here" in last and "Traceback" not in done.stderr
    assert st.read_rows(out) == []
