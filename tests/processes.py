"""Processes for the integration and security tests: started in their own session, found by command line,
never left behind."""

from __future__ import annotations

import os
import signal
import subprocess
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from auv_swarm.orchestrator.mission.procs import PROCESS_MODULES

REPO_ROOT = Path(__file__).resolve().parents[1]


def cmdline(pid: int) -> str:
    """The command line of ``pid`` with its arguments space-separated ("" once the process is gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def role_line(pid: int) -> str:
    """The command line of ``pid`` with each swarm module written as its role (``-m world``, ``-m agent --id 2``)."""
    text = cmdline(pid) + " "
    for role, module in PROCESS_MODULES.items():
        text = text.replace(f" -m {module} ", f" -m {role} ")
    return text


def processes_with(marker: str) -> list[int]:
    """PIDs of live processes (this one excepted) whose command line mentions ``marker``."""
    return [
        int(entry.name)
        for entry in Path("/proc").iterdir()
        if entry.name.isdigit() and int(entry.name) != os.getpid() and marker in cmdline(int(entry.name))
    ]


def start(argv: Sequence[str], env: dict[str, str] | None = None, cwd: Path = REPO_ROOT) -> subprocess.Popen:
    """``argv`` in a session (and process group) of its own, stdout and stderr on text pipes; ``env`` None: ours."""
    return subprocess.Popen(
        list(argv), cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )


def kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL the process group of ``proc`` (from :func:`start`) if ``proc`` still runs, and reap it."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


@contextmanager
def session(
    argv: Sequence[str], env: dict[str, str] | None = None, cwd: Path = REPO_ROOT
) -> Iterator[subprocess.Popen]:
    """:func:`start` ``argv``; on leaving the block, :func:`kill_group` it (a failed check leaves no process)."""
    proc = start(argv, env, cwd)
    try:
        yield proc
    finally:
        kill_group(proc)
