"""Start, watch and stop the swarm's OS processes (used by the orchestrator and the integration tests).

Every process is started in its own process group with its output in a log
file, and stopped by its pid: SIGTERM to the group, then SIGKILL after a timeout.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from auv_swarm.bus.credentials import CREDENTIAL_ENV
from auv_swarm.bus.lifeline import PARENT_ENV, process_exists


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def python_argv(module: str, *args: str) -> list[str]:
    """``[python, -P, -m, module, *args]`` with the running interpreter.

    ``-P`` keeps the current folder off the child's ``sys.path``, so the child imports ``auv_swarm`` as this
    process did (the installed package, or an editable install's finder), never a copy in the folder it was
    started from; nothing is added to ``PYTHONPATH``.
    """
    return [sys.executable, "-P", "-m", module, *args]


PROCESS_MODULES = {
    "router": "auv_swarm.orchestrator.mission.router",
    "world": "auv_swarm.world",
    "channel": "auv_swarm.channel_sim",
    "agent": "auv_swarm.agent",
    "central": "auv_swarm.central",
    "recorder": "auv_swarm.recorder",
}
"""The module each of the swarm's processes runs as (``python -m MODULE``); the same options as its verb."""


def process_argv(role: str, *args: str) -> list[str]:
    """The command line of the swarm process ``role`` (a key of :data:`PROCESS_MODULES`) with ``args``."""
    return python_argv(PROCESS_MODULES[role], *args)


def spawn(
    argv: list[str],
    name: str,
    env: dict[str, str] | None = None,
    log_path: Path | None = None,
    cwd: Path | None = None,
    secret: str | None = None,
) -> subprocess.Popen:
    """Start ``argv`` in a new session (its own process group), stdout and stderr to ``log_path``.

    ``env`` entries are added to the current environment, less the variables that name
    or hold credentials (``bus.credentials.CREDENTIAL_ENV``) unless ``env`` sets them.
    ``secret`` (this child's own password or user table) is written to the child's stdin,
    a pipe closed at once, which the child reads at start (``--password-fd 0``): it never
    appears in the environment, the command line or a file. Without ``log_path`` the
    output goes to a temporary file. The log path is kept on the returned object
    as ``proc.log_path`` and the name as ``proc.name``.
    """
    if not argv:
        raise ValueError("argv must name a program, got an empty list")
    if log_path is None:
        fd, tmp = tempfile.mkstemp(prefix=f"auvswarm-{name}-", suffix=".log")
        os.close(fd)
        log_path = Path(tmp)
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    inherited = {k: v for k, v in os.environ.items() if k not in CREDENTIAL_ENV}
    full_env = {**inherited, "PYTHONUNBUFFERED": "1", **(env or {})}
    with open(log_path, "ab") as out:
        proc = subprocess.Popen(
            argv,
            stdin=subprocess.DEVNULL if secret is None else subprocess.PIPE,
            stdout=out,
            stderr=subprocess.STDOUT,
            env=full_env,
            cwd=cwd,
            start_new_session=True,
        )
    if secret is not None:
        hand_over(proc, secret)
    proc.log_path = log_path  # type: ignore[attr-defined]
    proc.name = name  # type: ignore[attr-defined]
    return proc


def hand_over(proc: subprocess.Popen, secret: str) -> None:
    """Write ``secret`` and a newline to ``proc``'s stdin pipe and close it (a child that died early is ignored)."""
    try:
        proc.stdin.write(secret.encode() + b"\n")
        proc.stdin.close()
    except (BrokenPipeError, OSError):
        pass


def pid_alive(pid: int) -> bool:
    """True if a process with ``pid`` exists and is not a zombie."""
    if pid <= 0:
        raise ValueError(f"pid must be > 0, got {pid}")
    return process_exists(pid)


def group_alive(pgid: int) -> bool:
    """True if any process of process group ``pgid`` is still running (zombies excluded)."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text(encoding="ascii", errors="replace").rsplit(")", 1)[1].split()
        except (FileNotFoundError, ProcessLookupError, IndexError):
            continue
        if int(fields[2]) == pgid and fields[0] not in ("Z", "X"):
            return True
    return False


def children_of(launcher: int) -> list[int]:
    """Live processes (zombies excluded) carrying ``AUVSWARM_PARENT_PID=<launcher>``: the children of the
    launcher ``launcher``, found even after it is gone (they outlive a killed launcher for a moment)."""
    mark = f"{PARENT_ENV}={launcher}".encode()
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if mark not in (entry / "environ").read_bytes().split(b"\0"):
                continue
            if (entry / "stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X"):
                pids.append(int(entry.name))
        except OSError:
            continue
    return pids


def _signal_group(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass


def stop(proc: subprocess.Popen, timeout: float = 5.0) -> int | None:
    """SIGTERM the process group of ``proc``, wait up to ``timeout`` s, then SIGKILL it; returns the exit code.

    The process group is the one ``spawn`` created (its id is ``proc.pid``). Any
    other member of the group still running after the leader exited is killed too.
    """
    if timeout < 0:
        raise ValueError(f"timeout must be >= 0 s, got {timeout}")
    if proc.poll() is None:
        _signal_group(proc, signal.SIGTERM)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _signal_group(proc, signal.SIGKILL)
            proc.wait(timeout=5.0)
    deadline = time.monotonic() + timeout
    while group_alive(proc.pid):
        if time.monotonic() > deadline:
            _signal_group(proc, signal.SIGKILL)
            break
        time.sleep(0.02)
    return proc.returncode


def kill(proc: subprocess.Popen) -> int | None:
    """SIGKILL the process group of ``proc`` at once (a crash drill); returns the exit code."""
    _signal_group(proc, signal.SIGKILL)
    proc.wait(timeout=5.0)
    return proc.returncode


def read_log(source: Path | subprocess.Popen) -> str:
    """The text written so far to a log file, or to a spawned process's log."""
    path = Path(getattr(source, "log_path", source))
    try:
        return path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return ""


def wait_for_line(
    source: Path | subprocess.Popen, pattern: str, timeout: float = 10.0, poll_s: float = 0.02
) -> re.Match[str]:
    """Wait until a line of the log matches the regular expression ``pattern``; returns the match.

    ``source`` is a log path or a process from :func:`spawn`. Raises TimeoutError
    after ``timeout`` s (wall clock), and at once if the process exited without
    printing the line; the message quotes the log's tail.
    """
    if timeout <= 0:
        raise ValueError(f"timeout must be > 0 s, got {timeout}")
    regex = re.compile(pattern)
    proc = source if isinstance(source, subprocess.Popen) else None
    deadline = time.monotonic() + timeout
    while True:
        text = read_log(source)
        for line in text.splitlines():
            match = regex.search(line)
            if match:
                return match
        if proc is not None and proc.poll() is not None:
            raise TimeoutError(
                f"{getattr(proc, 'name', proc.pid)} exited with {proc.returncode} before printing {pattern!r}; "
                f"log tail:\n{_tail(text)}"
            )
        if time.monotonic() > deadline:
            raise TimeoutError(f"no line matching {pattern!r} within {timeout} s; log tail:\n{_tail(text)}")
        time.sleep(poll_s)


def _tail(text: str, lines: int = 20) -> str:
    return "\n".join(text.splitlines()[-lines:])
