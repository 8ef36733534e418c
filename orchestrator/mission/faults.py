"""Scheduled faults of the channel, router, world and recorder (processes mode only).

Each fault lands on a tick fixed by the scenario, however slowly the launcher reads the bus: the
world is told the faults' times (``auv-swarm world --hold-at``), publishes the truth of the first
tick at or after each and holds the clock there; the launcher, on that truth, signals the process
and confirms on ``orchestrator/faults`` (a :class:`~auv_swarm.contract.wire.FaultsInjected` for
that tick, which only the orchestrator may put), and the world goes on. ``kill`` (SIGKILL) and
``term`` (SIGTERM) are what they say, confirmed once the process is gone, and the supervisor
judges the run as for any death, naming the injection tick; ``stop`` is SIGSTOP, then SIGCONT
``duration_s`` wall seconds later; ``restart`` is SIGKILL, then a fresh process of the same role
``down_s`` wall seconds later (the supervisor expects that exit). The confirmation is sent again
until the world's next truth shows it arrived (a restarted router drops what was sent while it was
down). The world holds the clock while the channel is gone, up to ``run.grace_s``, so a channel or
router back by then leaves the run complete. AUV faults are the world's business
(``world.service``), not this module's, except a drill's unannounced ones (``external``).
"""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Callable

from auv_swarm.contract import wire
from auv_swarm.contract.config import Fault
from auv_swarm.orchestrator.mission.supervise import Supervisor

EXIT_WAIT_S = 10.0
"""Longest the launcher waits for a killed or terminated process to be gone before it confirms the fault (wall s)."""


class ComponentFaults:
    """The launcher's schedule of non-AUV faults; ``procs`` is the launcher's live table of processes,
    ``confirm`` publishes a :class:`~auv_swarm.contract.wire.FaultsInjected` to the world."""

    def __init__(
        self,
        faults: tuple[Fault, ...],
        procs: dict[str, subprocess.Popen],
        respawn: Callable[[str], None],
        sup: Supervisor,
        confirm: Callable[[wire.FaultsInjected], None],
        external: tuple[Fault, ...] = (),
    ) -> None:
        """``external``: AUV faults the launcher injects unannounced to the world (drills: kill -9 or SIGSTOP
        from outside, so that detection is really measured); an AUV's process is ``auv<N>``."""
        self.pending = sorted([*(f for f in faults if f.auv is None), *external], key=lambda f: f.at_s)
        self.procs = procs
        self.respawn = respawn
        self.sup = sup
        self.confirm = confirm
        self.later: list[tuple[float, str, str]] = []
        self.injected: list[dict[str, object]] = []
        self.unconfirmed: wire.FaultsInjected | None = None
        """The last confirmation sent, until a truth of a later tick shows the world got it."""

    def hold_at(self) -> tuple[float, ...]:
        """The sim times the world must hold the clock at (``auv-swarm world --hold-at``)."""
        return tuple(f.at_s for f in self.pending)

    def on_truth(self, truth: wire.Truth, now: float) -> None:
        """The world's truth of a tick arrived at wall time ``now``: inject every fault due and confirm them."""
        if self.unconfirmed is not None and truth.tick > self.unconfirmed.tick:
            self.unconfirmed = None
        done: list[str] = []
        due = False
        while self.pending and self.pending[0].at_s <= truth.t_s + 1e-9:
            due = True
            fault = self.pending.pop(0)
            if self.inject(fault, truth.t_s, now):
                done.append(f"{fault.action} {fault.target}")
        if due:
            self.unconfirmed = wire.FaultsInjected(
                t_s=truth.t_s, source="orchestrator", tick=truth.tick, faults=tuple(done)
            )
            self.confirm(self.unconfirmed)

    def inject(self, fault: Fault, t_s: float, now: float) -> bool:
        """Signal ``fault``'s process at sim time ``t_s``; False when it is not running (a warning)."""
        name = fault.target if fault.auv is None else f"auv{fault.auv}"
        proc = self.procs.get(name)
        if proc is None or proc.poll() is not None:
            self.sup.lines.append(f"warning: fault on {fault.target} at t = {t_s:g} s skipped: no such process running")
            return False
        self.injected.append({"target": fault.target, "action": fault.action, "t_s": t_s, "wall": now})
        self.sup.lines.append(f"fault: {fault.action} {fault.target} at t = {t_s:g} s")
        if fault.action != "stop":
            self.sup.on_fault(name, t_s)
        if fault.action in ("kill", "term"):
            proc.send_signal(signal.SIGKILL if fault.action == "kill" else signal.SIGTERM)
            try:
                proc.wait(timeout=EXIT_WAIT_S)
            except subprocess.TimeoutExpired:
                self.sup.lines.append(f"warning: {name} still runs {EXIT_WAIT_S:g} s after its {fault.action}")
        elif fault.action == "stop":
            proc.send_signal(signal.SIGSTOP)
            self.later.append((now + fault.duration_s, "cont", name))
        else:
            self.sup.expect_exit(name, True)
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=EXIT_WAIT_S)
            self.later.append((now + fault.down_s, "respawn", name))
        return True

    def on_wall(self, now: float) -> None:
        """Wall time ``now``: confirm again what the world may not have got, resume stopped processes and start
        restarted ones when due."""
        if self.unconfirmed is not None:
            self.confirm(self.unconfirmed)
        for item in sorted(self.later):
            due, what, target = item
            if due > now:
                continue
            self.later.remove(item)
            if what == "cont":
                self.procs[target].send_signal(signal.SIGCONT)
                self.sup.lines.append(f"fault: {target} continues")
            else:
                self.respawn(target)
                self.sup.expect_exit(target, False)
                self.sup.lines.append(f"fault: {target} restarted")

    def resume_all(self) -> None:
        """SIGCONT whatever is still stopped (so that it can be stopped for good)."""
        for _due, what, target in self.later:
            if what == "cont" and self.procs[target].poll() is None:
                self.procs[target].send_signal(signal.SIGCONT)
        self.later.clear()
