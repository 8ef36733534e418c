"""Fixtures for integration tests: real processes over zenoh on loopback, stopped by pid.

Every process is spawned in its own process group through ``orchestrator.procs``;
at teardown each is stopped and the test asserts that no process of the group is
left. Waits are on events (a line in a log, a received message) with timeouts.
"""

from __future__ import annotations

import os
import secrets
import shutil
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from auv_swarm.bus import credentials, zbus
from auv_swarm.contract import wire
from auv_swarm.orchestrator.mission import procs
from tests.integration import installs

REPO_ROOT = Path(__file__).resolve().parents[2]


@dataclass
class RouterProc:
    """A running router process and the endpoint it listens on."""

    endpoint: str
    proc: subprocess.Popen


class Inbox:
    """Thread-safe collector of (key, payload) deliveries, with waits on a condition."""

    def __init__(self) -> None:
        self.items: list[tuple[str, object]] = []
        self._cond = threading.Condition()

    def __call__(self, key: str, payload: object) -> None:
        with self._cond:
            self.items.append((key, payload))
            self._cond.notify_all()

    def wait_for(self, predicate: Callable[[list[tuple[str, object]]], bool], timeout: float = 10.0) -> bool:
        """Wait until ``predicate(items)`` holds; False after ``timeout`` s."""
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self.items), timeout=timeout)

    def payloads(self, key: str | None = None) -> list[object]:
        """Payloads received so far, optionally only those on ``key``."""
        with self._cond:
            return [p for k, p in self.items if key is None or k == key]


def liveliness_changes(bus: zbus.ZenohBus, history: bool = True) -> Inbox:
    """An Inbox of every liveliness change ``bus`` sees, as (key, alive); with ``history`` the tokens alive now too."""
    changes = Inbox()
    bus.subscribe_liveliness(wire.all_liveliness(), changes, history=history)
    return changes


def until(predicate: Callable[[], bool], timeout: float = 10.0, poll_s: float = 0.02) -> bool:
    """Poll ``predicate`` until it holds; False after ``timeout`` s (wall clock)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return predicate()


def publish_until(
    bus: zbus.ZenohBus, key: str, payload: bytes, done: Callable[[], bool], timeout: float = 10.0
) -> bool:
    """Publish ``payload`` on ``key`` every 50 ms until ``done()`` (routes take a moment to settle after a connect)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        bus.publish(key, payload)
        if until(done, timeout=0.05, poll_s=0.005):
            return True
    return done()


def flush(sender: zbus.ZenohBus, observer_inbox: Inbox, key: str, tag: bytes) -> None:
    """Publish ``tag`` on an allowed ``key`` of ``sender`` and wait until the observer holds it: a causal flush
    (the router has handled, and dropped, whatever forbidden thing ``sender`` did before on that link)."""
    assert publish_until(sender, key, tag, lambda: tag in observer_inbox.payloads(key)), f"flush {tag!r} never arrived"


@pytest.fixture
def run_secret(tmp_path: Path) -> str:
    """A fresh random secret for this test; every user's password is derived from it and written to
    ``tmp_path/creds/<user>.password``, the router's table to ``tmp_path/creds/users.txt``."""
    value = secrets.token_hex(16)
    folder = tmp_path / "creds"
    folder.mkdir()
    table = credentials.derive(value)
    for user, password in table.items():
        (folder / f"{user}.password").write_text(password + "\n", encoding="utf-8")
    (folder / "users.txt").write_text(credentials.users_text(table), encoding="utf-8")
    return value


@pytest.fixture
def spawner(tmp_path: Path, run_secret: str) -> Iterator[Callable[..., subprocess.Popen]]:
    """``spawner(argv, name)`` starts a process (log in tmp_path); all are stopped and checked gone at teardown.

    A process named after a user (``router``, ``world``, ``channel``, ``auv0``, ...) gets its own
    credentials file through ``AUVSWARM_USERS_FILE`` / ``AUVSWARM_PASSWORD_FILE``.
    """
    started: list[subprocess.Popen] = []

    path = os.pathsep.join(p for p in (str(REPO_ROOT), os.environ.get("PYTHONPATH", "")) if p)
    folder = tmp_path / "creds"

    def spawn(argv: list[str], name: str, env: dict[str, str] | None = None) -> subprocess.Popen:
        log_path = tmp_path / f"{name}-{len(started)}.log"
        own: dict[str, str] = {}
        if name == "router":
            own[credentials.USERS_FILE_ENV] = str(folder / "users.txt")
        elif (folder / f"{name}.password").exists():
            own[credentials.PASSWORD_FILE_ENV] = str(folder / f"{name}.password")
        full_env = {"PYTHONPATH": path, **own, **(env or {})}
        proc = procs.spawn(argv, name, env=full_env, log_path=log_path, cwd=REPO_ROOT)
        started.append(proc)
        return proc

    yield spawn
    for proc in reversed(started):
        procs.stop(proc, timeout=5.0)
    for proc in started:
        assert not procs.pid_alive(proc.pid), f"{proc.name} (pid {proc.pid}) still alive"
        assert not procs.group_alive(proc.pid), f"a process of {proc.name}'s group {proc.pid} is still alive"


@pytest.fixture
def start_router(spawner: Callable[..., subprocess.Popen], run_secret: str) -> Callable[..., RouterProc]:
    """``start_router(acl=True, agents=4, port=None)``: a router process on a loopback port, once it listens."""

    def start(acl: bool = True, agents: int = 4, port: int | None = None) -> RouterProc:
        endpoint = f"tcp/127.0.0.1:{port or procs.free_port()}"
        argv = procs.python_argv("auv_swarm", "router", "--listen", endpoint, "--agents", str(agents))
        if not acl:
            argv.append("--no-acl")
        proc = spawner(argv, "router")
        procs.wait_for_line(proc, r"router listening on", timeout=15.0)
        return RouterProc(endpoint, proc)

    return start


@pytest.fixture
def connect(run_secret: str) -> Iterator[Callable[..., zbus.ZenohBus]]:
    """``connect(endpoint, user, password=None, timeout_ms=2000)``: a ZenohBus client (default: the run's
    credentials for ``user``); closed at teardown."""
    buses: list[zbus.ZenohBus] = []

    def open_bus(endpoint: str, user: str, password: str | None = None, timeout_ms: int = 2000) -> zbus.ZenohBus:
        pw = zbus.password_for(user, run_secret) if password is None else password
        bus = zbus.ZenohBus(endpoint, user, pw, connect_timeout_ms=timeout_ms)
        buses.append(bus)
        return bus

    yield open_bus
    for bus in buses:
        bus.close()


def docker_reason(*tools: str) -> str | None:
    """Why a container test cannot run here (docker, ``tools`` such as docker-compose, the daemon), or None."""
    for tool in ("docker", *tools):
        if shutil.which(tool) is None:
            return f"{tool} is not installed"
    if subprocess.run(["docker", "info"], capture_output=True, timeout=60).returncode != 0:
        return "the docker daemon does not answer (docker info failed)"
    return None


def built_base_image(reason: str | None) -> str:
    """The tag docker/base-image.sh prints (it builds the image or reuses it); skips, printing ``reason``, if set."""
    if reason is not None:
        print(f"skipped: {reason}")
        pytest.skip(reason)
    base = subprocess.run([str(REPO_ROOT / "docker" / "base-image.sh")], capture_output=True, text=True, timeout=900)
    assert base.returncode == 0, base.stderr[-3000:]
    return base.stdout.strip().splitlines()[-1]


@pytest.fixture(scope="session")
def fault_plugins(tmp_path_factory) -> dict[str, str]:
    """The test-only plug-in package ``tests/plugins/faults`` (planners ``fault-raise`` and ``fault-die``, estimator
    ``fault-raise``), installed once per run; the environment entries a process needs to see it."""
    return installs.plugin_package("faults", tmp_path_factory.mktemp("fault-plugins"))


@pytest.fixture(scope="session")
def installed(tmp_path_factory) -> dict:
    """The wheel of ``git archive HEAD`` in a fresh virtual environment (:func:`installs.wheel_venv`), once per run."""
    return installs.wheel_venv(tmp_path_factory.mktemp("wheel"))
