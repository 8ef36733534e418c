"""Network namespaces for tests: hosts of their own on one machine, joined by veth links (needs root and iproute2).

:class:`Hosts` makes one infrastructure namespace and one namespace per AUV, each AUV joined to the
infrastructure by a veth pair of its own (``10.45.<n>.2`` on the AUV's side, ``10.45.<n>.1`` on the
infrastructure's), starts processes inside them and removes everything it made on :meth:`Hosts.close`,
also after a failure: its processes by pid, then any process left in its namespaces, then the namespaces
(which takes their links with them). Nothing is made in the namespace the test runs in.
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import subprocess
from pathlib import Path

from auv_swarm.orchestrator.mission import procs


def unavailable() -> str | None:
    """Why namespaces cannot be made here (not root, no ``ip``, or the kernel refuses), or None."""
    if os.geteuid() != 0:
        return "network namespaces need root (CI runs as root)"
    if shutil.which("ip") is None:
        return "no ip command (iproute2)"
    probe = f"auvswarm-probe-{secrets.token_hex(3)}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True, timeout=30)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True, timeout=30)
    return None


def ip(*args: str) -> None:
    """Run ``ip ARGS``; RuntimeError with its stderr if it fails."""
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {done.stderr.strip()}")


def infra_address(n: int) -> str:
    """The infrastructure's address on AUV ``n``'s link."""
    return f"10.45.{n}.1"


class Hosts:
    """An infrastructure namespace and one per AUV, with veth links between them (see the module docstring)."""

    def __init__(self, agents: int, logs: Path) -> None:
        self.token = secrets.token_hex(3)
        self.infra = f"auvswarm-{self.token}-infra"
        self.auvs = [f"auvswarm-{self.token}-auv{n}" for n in range(agents)]
        self.logs = logs
        self.made: list[str] = []
        self.started: list[subprocess.Popen] = []
        try:
            self._add(self.infra)
            for n, ns in enumerate(self.auvs):
                self._add(ns)
                ip("-n", self.infra, "link", "add", f"i{n}", "type", "veth", "peer", "name", f"a{n}", "netns", ns)
                ip("-n", self.infra, "addr", "add", f"{infra_address(n)}/24", "dev", f"i{n}")
                ip("-n", ns, "addr", "add", f"10.45.{n}.2/24", "dev", f"a{n}")
                ip("-n", self.infra, "link", "set", f"i{n}", "up")
                ip("-n", ns, "link", "set", f"a{n}", "up")
        except Exception:
            self.close()
            raise

    def _add(self, ns: str) -> None:
        ip("netns", "add", ns)
        self.made.append(ns)
        ip("-n", ns, "link", "set", "lo", "up")

    def spawn(self, ns: str, argv: list[str], name: str) -> subprocess.Popen:
        """Start ``argv`` inside namespace ``ns`` (its own process group, output in ``logs/NAME.log``)."""
        proc = procs.spawn(["ip", "netns", "exec", ns, *argv], name, log_path=self.logs / f"{name}.log")
        self.started.append(proc)
        return proc

    def cut(self, n: int, up: bool = False) -> None:
        """Take AUV ``n``'s link down (``up``: bring it back); its processes and sessions live on."""
        ip("-n", self.infra, "link", "set", f"i{n}", "up" if up else "down")

    def remove(self, n: int) -> None:
        """AUV ``n``'s host vanishes: its link goes first (no goodbye reaches the router), then its processes
        (SIGKILL) and its namespace."""
        ip("-n", self.infra, "link", "del", f"i{n}")
        self._kill_inside(self.auvs[n])
        ip("netns", "del", self.auvs[n])
        self.made.remove(self.auvs[n])

    def _kill_inside(self, ns: str) -> None:
        listed = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True, timeout=30)
        for pid in (int(p) for p in listed.stdout.split() if p.isdigit()):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def close(self) -> None:
        """Stop every process started here, then whatever is left inside the namespaces, then the namespaces."""
        for proc in reversed(self.started):
            procs.stop(proc, timeout=5.0)
        for ns in list(self.made):
            self._kill_inside(ns)
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)
            self.made.remove(ns)

    def left(self) -> list[str]:
        """This object's namespaces that still exist (empty after :meth:`close`)."""
        listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=30).stdout
        return [line.split()[0] for line in listed.splitlines() if self.token in line]
