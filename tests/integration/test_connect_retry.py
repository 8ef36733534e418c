"""Clients retry an unreachable router until a deadline, and tell a refused login from an unreachable router."""

from __future__ import annotations

import threading
import time

import pytest

from auv_swarm.bus import zbus
from auv_swarm.orchestrator.mission import procs

pytestmark = pytest.mark.integration


def test_refused_login_is_reported_as_such_at_once(start_router, monkeypatch) -> None:
    router = start_router(agents=3)
    monkeypatch.setenv(zbus.RETRY_ENV, "30")
    started = time.monotonic()
    with pytest.raises(ConnectionError, match="authentication failed: the router at .* refused user auv0"):
        zbus.ZenohBus(router.endpoint, "auv0", "not-the-password", connect_timeout_ms=1000)
    assert time.monotonic() - started < 10.0, "a refused login must not be retried until the deadline"


def test_unreachable_router_is_retried_until_the_deadline(monkeypatch, run_secret) -> None:
    endpoint = f"tcp/127.0.0.1:{procs.free_port()}"
    monkeypatch.setenv(zbus.RETRY_ENV, "2")
    started = time.monotonic()
    with pytest.raises(ConnectionError, match=r"router unreachable at .*\(retried for 2 s\)"):
        zbus.ZenohBus.connect(endpoint, "auv0", run_secret, connect_timeout_ms=300)
    assert time.monotonic() - started >= 2.0


def test_a_client_started_before_the_router_connects_once_it_is_up(spawner, monkeypatch, run_secret) -> None:
    port = procs.free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    monkeypatch.setenv(zbus.RETRY_ENV, "30")
    result: dict[str, object] = {}

    def client() -> None:
        try:
            with zbus.ZenohBus.connect(endpoint, "auv0", run_secret, connect_timeout_ms=500):
                result["ok"] = True
        except ConnectionError as exc:
            result["error"] = exc

    thread = threading.Thread(target=client)
    thread.start()
    time.sleep(1.5)
    router = spawner(procs.python_argv("auv_swarm", "router", "--listen", endpoint, "--agents", "3"), "router")
    procs.wait_for_line(router, r"router listening on", timeout=15.0)
    thread.join(timeout=40.0)
    assert result == {"ok": True}


def test_bad_retry_setting_is_one_clear_error(monkeypatch) -> None:
    monkeypatch.setenv(zbus.RETRY_ENV, "soon")
    with pytest.raises(ValueError, match="AUVSWARM_CONNECT_RETRY_S must be a number"):
        zbus.retry_seconds()
