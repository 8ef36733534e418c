"""Every process ends with its mission: the world's ``end``, the world's death, or the launcher's death.

A process shell (router, channel, AUV, recorder) holds a :class:`Lifeline`. It
stops the shell, through the shell's stop event, when

- the world announces the end of the mission (a ``WorldEvent`` of kind ``end``);
- the world's liveliness token has been gone longer than ``run.grace_s`` of wall
  time after it was seen (the world died, or the router is gone for good);
- the process that launched it (``AUVSWARM_PARENT_PID``, set by ``auv-swarm run``)
  no longer exists, so a SIGKILL of the launcher leaves no orphan.

A shell started by hand (no ``AUVSWARM_PARENT_PID``) ends on the first two. The
decision (:meth:`Lifeline.check`) is pure: wall time is passed in.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from typing import Any

from auv_swarm.bus.identity import Gate
from auv_swarm.contract import wire

PARENT_ENV = "AUVSWARM_PARENT_PID"
"""Environment variable naming the launcher's pid; a child stops when that process is gone."""
POLL_S = 0.2
"""Wall seconds between two looks at the parent and the world's token."""


def parent_from_env() -> int | None:
    """The launcher's pid from ``AUVSWARM_PARENT_PID``, or None (started by hand, or a bad value)."""
    text = os.environ.get(PARENT_ENV, "")
    return int(text) if text.isdigit() and int(text) > 1 else None


def process_exists(pid: int) -> bool:
    """True if a process ``pid`` exists and is not a zombie."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (FileNotFoundError, IndexError):
        return True


class Lifeline:
    """Why a shell should stop now, if it should (see the module docstring)."""

    def __init__(self, grace_s: float, parent_pid: int | None = None) -> None:
        if not grace_s > 0:
            raise ValueError(f"grace_s must be > 0 s, got {grace_s!r}")
        self.grace_s = grace_s
        self.parent_pid = parent_pid
        self.ended = False
        self.aborted = False
        self.world_seen = False
        self.world_gone_since: float | None = None
        self.reason: str | None = None
        self.end_noted = False
        self._world_key = wire.liveliness_component("world")

    def note_end(self) -> None:
        """A shell that handles the end itself (``attach(follow_end=False)``) saw it: the world leaving
        afterwards is expected, not a reason to stop (it would turn a lingering shell's exit into a failure)."""
        self.end_noted = True

    def on_world_event(self, msg: object) -> None:
        """A decoded world event: ``end`` or ``abort`` ends the mission (``abort``: an incomplete one)."""
        if isinstance(msg, wire.WorldEvent) and msg.kind in ("end", "abort"):
            self.ended = True
            self.aborted = msg.kind == "abort"

    def on_liveliness(self, key: str, alive: bool, now: float) -> None:
        """A liveliness change at wall time ``now`` (only the world's token matters)."""
        if key != self._world_key:
            return
        if alive:
            self.world_seen = True
            self.world_gone_since = None
        elif self.world_seen and self.world_gone_since is None:
            self.world_gone_since = now

    def check(self, now: float, parent_alive: bool = True) -> str | None:
        """The reason to stop at wall time ``now`` (None: keep going); remembered in ``reason``."""
        if self.reason is None:
            if self.ended:
                self.reason = "the world " + (
                    "aborted the mission" if self.aborted else "announced the end of the mission"
                )
            elif not parent_alive:
                self.reason = f"the launcher (pid {self.parent_pid}) is gone"
            elif (
                not self.end_noted and self.world_gone_since is not None and now - self.world_gone_since > self.grace_s
            ):
                self.reason = f"the world's liveliness has been gone for more than {self.grace_s:g} s"
        return self.reason

    @property
    def exit_code(self) -> int:
        """0 when the mission ended (or nothing happened), 1 when it was aborted or the world or launcher lost."""
        return 0 if self.reason is None or (self.ended and not self.aborted) else 1

    def shell_exit_code(self, stop: threading.Event) -> int:
        """A shell's exit code: 130 when Ctrl-C (SIGINT) stopped it, else :attr:`exit_code` (SIGTERM, the
        supervisor's way to stop a process, is not a failure)."""
        return 130 if getattr(stop, "signum", None) == signal.SIGINT else self.exit_code

    def attach(self, bus: Any, stop: threading.Event, name: str, follow_end: bool = True) -> None:
        """Watch ``bus`` (world events, the world's token) and the parent on a daemon thread; set ``stop`` and
        print one line naming the reason when it is time to go. ``follow_end`` False: the shell handles the
        ``end`` event itself (the recorder drains the bus first)."""

        gate = Gate(name)

        def on_event(key: str, data: bytes) -> None:
            msg = gate.receive(key, data)
            if msg is not None:
                self.on_world_event(msg)

        if follow_end:
            bus.subscribe(wire.world_events(), on_event)
        bus.subscribe_liveliness(
            self._world_key, lambda key, alive: self.on_liveliness(key, alive, time.monotonic()), history=True
        )

        def watch() -> None:
            while not stop.is_set():
                parent_alive = self.parent_pid is None or process_exists(self.parent_pid)
                reason = self.check(time.monotonic(), parent_alive)
                if reason is not None:
                    print(f"{name}: stopping: {reason}", flush=True)
                    stop.set()
                    return
                stop.wait(POLL_S)

        threading.Thread(target=watch, name=f"{name}-lifeline", daemon=True).start()
