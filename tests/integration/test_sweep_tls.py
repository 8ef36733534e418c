"""``auv-swarm sweep`` on its LocalCluster admits only holders of the sweep's certificates (issue 42).

During a real sweep (2 workers): every listener of the sweep's processes is on 127.0.0.1 (read from /proc, and
``ss -ltn`` shows none of them on a wildcard address); its scheduler, both nannies and both workers refuse a
Dask client over plain TCP, over TLS without a certificate, and over TLS with a certificate of another CA; the
HTTP servers Dask starts beside them serve no route. That the same probe is answered when it holds the right
certificate is shown on a cluster by hand (test_sweep_scheduler.py)."""

from __future__ import annotations

import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from auv_swarm.bus import tls
from auv_swarm.orchestrator.mission import procs
from tests import listeners
from tests.integration.test_sweep import spawn_sweep, wait_rows

pytestmark = pytest.mark.integration

DASK_LISTENERS = 5
"""With 2 workers: the scheduler and the 2 nannies (in the client's process), the 2 workers."""
HTTP_LISTENERS = 3
"""The HTTP servers Dask always starts: the scheduler's and each worker's."""


def _wildcard_in_ss(ports: set[int]) -> list[str]:
    """The lines of ``ss -ltn`` that show one of ``ports`` on a wildcard address (``ss`` missing: skipped)."""
    if shutil.which("ss") is None:
        return []
    out = subprocess.run(["ss", "-Hltn"], capture_output=True, text=True, timeout=10).stdout.splitlines()
    found = []
    for line in out:
        local = line.split()[3]
        host, _, port = local.rpartition(":")
        if int(port) in ports and host in ("0.0.0.0", "[::]", "*", "[::ffff:0.0.0.0]"):
            found.append(line)
    return found


def test_the_local_cluster_refuses_a_client_without_the_sweeps_certificates(tmp_path: Path) -> None:
    other = tmp_path / "other-ca"
    tls.write_dask(other)  # a well-formed cluster's certificates, of another CA
    out = tmp_path / "s"
    sweep = spawn_sweep(out, "paper-3.2-challenging", "--seeds", "1-100", "--duration", "300", "--workers", "2")
    try:
        wait_rows(out, 1, sweep)  # the cluster is up and runs missions
        found = listeners.listeners(sweep.pid)
        assert [x for x in found if x.host != "127.0.0.1"] == [], found
        assert _wildcard_in_ss({x.port for x in found}) == []
        http = [x for x in found if listeners.http_status(x.host, x.port) is not None]
        assert len(http) == HTTP_LISTENERS, found
        for x in http:  # no route: no worker list, logs or call stacks
            for path in ("/health", "/info/main/workers.html", "/json/identity.json", "/metrics"):
                assert listeners.http_status(x.host, x.port, path) == 404, (x, path)
        dask = [f"{x.host}:{x.port}" for x in found if x not in http]
        assert len(dask) == DASK_LISTENERS, found
        contexts = {
            "plain TCP": None,
            "TLS, no certificate": listeners.client_context(),
            "TLS, another CA's client": listeners.client_context(other / "client.pem", other / "client.key"),
            "TLS, another CA's worker": listeners.client_context(other / "worker.pem", other / "worker.key"),
        }
        attempts = [
            (how, f"{'tcp' if ctx is None else 'tls'}://{a}", ctx) for how, ctx in contexts.items() for a in dask
        ]
        t0 = time.monotonic()
        answers = listeners.dask_identity([(address, ctx) for _how, address, ctx in attempts])
        print(f"{len(attempts)} attempts in {time.monotonic() - t0:.1f} s")
        refused = [f"{how} {address}: {answer}" for (how, address, _ctx), answer in zip(attempts, answers, strict=True)]
        assert all(": refused" in line for line in refused), refused
        assert sweep.poll() is None, procs.read_log(sweep)
        sweep.send_signal(signal.SIGINT)
        assert sweep.wait(timeout=60) == 130, procs.read_log(sweep)
    finally:
        procs.stop(sweep)
    deadline = time.monotonic() + 15
    while procs.group_alive(sweep.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not procs.group_alive(sweep.pid)
