"""Scheduled faults of the channel, router, world and recorder (processes mode only).

At the first truth at or after ``at_s`` of sim time the launcher signals the process:
``kill`` (SIGKILL) and ``term`` (SIGTERM) are what they say, and the supervisor judges
the run as for any death; ``stop`` is SIGSTOP, then SIGCONT ``duration_s`` wall seconds
later; ``restart`` is SIGKILL, then a fresh process of the same role ``down_s`` wall
seconds later (the supervisor expects that exit). The world holds the clock while the
channel is gone, up to ``run.grace_s``, so a channel or router back by then leaves the
run complete. AUV faults are the world's business (``world.service``), not this module's.
"""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Callable

from auv_swarm.contract.config import Fault


class ComponentFaults:
    """The launcher's schedule of non-AUV faults; ``procs`` is the launcher's live table of processes."""

    def __init__(
        self,
        faults: tuple[Fault, ...],
        procs: dict[str, subprocess.Popen],
        respawn: Callable[[str], None],
        expect_exit: Callable[[str, bool], None],
        say: Callable[[str], None],
        external: tuple[Fault, ...] = (),
    ) -> None:
        """``external``: AUV faults the launcher injects unannounced to the world (drills: kill -9 or SIGSTOP
        from outside, so that detection is really measured); an AUV's process is ``auv<N>``."""
        self.pending = sorted((f for f in faults if f.auv is None), key=lambda f: f.at_s)
        self.pending = sorted(self.pending + list(external), key=lambda f: f.at_s)
        self.procs = procs
        self.respawn = respawn
        self.expect_exit = expect_exit
        self.say = say
        self.later: list[tuple[float, str, str]] = []
        self.injected: list[dict[str, object]] = []

    def on_time(self, t_s: float, now: float) -> None:
        """Sim time ``t_s`` reached at wall time ``now``: inject every fault due."""
        while self.pending and self.pending[0].at_s <= t_s + 1e-9:
            fault = self.pending.pop(0)
            name = fault.target if fault.auv is None else f"auv{fault.auv}"
            proc = self.procs.get(name)
            if proc is None or proc.poll() is not None:
                self.say(f"warning: fault on {fault.target} at t = {t_s:g} s skipped: no such process running")
                continue
            self.injected.append({"target": fault.target, "action": fault.action, "t_s": t_s, "wall": now})
            self.say(f"fault: {fault.action} {fault.target} at t = {t_s:g} s")
            if fault.action == "kill":
                proc.send_signal(signal.SIGKILL)
            elif fault.action == "term":
                proc.send_signal(signal.SIGTERM)
            elif fault.action == "stop":
                proc.send_signal(signal.SIGSTOP)
                self.later.append((now + fault.duration_s, "cont", name))
            else:
                self.expect_exit(name, True)
                proc.send_signal(signal.SIGKILL)
                proc.wait(timeout=10.0)
                self.later.append((now + fault.down_s, "respawn", name))

    def on_wall(self, now: float) -> None:
        """Wall time ``now``: resume stopped processes and start restarted ones when due."""
        for item in sorted(self.later):
            due, what, target = item
            if due > now:
                continue
            self.later.remove(item)
            if what == "cont":
                self.procs[target].send_signal(signal.SIGCONT)
                self.say(f"fault: {target} continues")
            else:
                self.respawn(target)
                self.expect_exit(target, False)
                self.say(f"fault: {target} restarted")

    def resume_all(self) -> None:
        """SIGCONT whatever is still stopped (so that it can be stopped for good)."""
        for _due, what, target in self.later:
            if what == "cont" and self.procs[target].poll() is None:
                self.procs[target].send_signal(signal.SIGCONT)
        self.later.clear()
