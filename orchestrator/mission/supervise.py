"""What the launcher makes of its processes and the world's events: a run that failed says so.

:class:`Supervisor` is told what happens (a process exited, a world event, a tick
of progress, wall time passing) and decides what it means, without touching a
process itself:

- the world, the router or the channel exiting before the world announced the
  end makes the run incomplete (``world_died``, ``router_lost``, ``channel_lost``; a critical
  process that exits while a scheduled restart of the router is under way gave up on the router,
  down longer than ``run.grace_s``: ``router_lost``; the central
  planner of the centralised MPC, whose AUVs cannot move without it, ``central_lost``;
  ``start_failed`` when it happens before the mission started);
- the world's ``abort`` event makes it incomplete with the reason the world gives;
- the recorder exiting is a warning: the recording stops there, the run goes on;
- an AUV exiting without a planned kill is a crash the swarm survives: a
  warning, and the world's ``death`` event records it;
- no new tick for ``STALL_S`` of wall time prints one line saying what the run
  waits for; a world silent for ``silent_limit_s`` is taken as dead;
- a ``duplicate_login`` event (a second client logged in with an AUV's password; the world quarantined that
  AUV) makes a run that otherwise completed incomplete: ``compromised`` (:meth:`Supervisor.final`).

Every decision is one line for the operator (:attr:`Supervisor.lines`), the
first of which names what died and when.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from auv_swarm.contract import wire

STALL_S = 3.0
"""Wall seconds without a new tick before the launcher says what it is waiting for."""

CRITICAL = {"world": "world_died", "router": "router_lost", "channel": "channel_lost", "central": "central_lost"}
"""Processes without which the mission cannot go on, and the incomplete reason their loss gives."""


@dataclass
class Outcome:
    """How a run ended: complete, or not and why (a reason of ``results.record.INCOMPLETE_REASONS``)."""

    complete: bool = True
    reason: str | None = None
    line: str = ""
    events: list[tuple[wire.WorldEvent, float]] = field(default_factory=list)
    """Every world event with the launcher's wall clock (``time.monotonic``) when it arrived."""
    injected: list[dict[str, object]] = field(default_factory=list)
    """Faults the launcher injected: target, action, sim time t_s and wall clock."""

    @property
    def exit_code(self) -> int:
        """0 complete, 130 interrupted, 1 any other incomplete run."""
        if self.complete:
            return 0
        return 130 if self.reason == "interrupted" else 1


@dataclass
class Supervisor:
    """The launcher's judgement of a processes-mode run (see the module docstring)."""

    duration_s: float
    silent_limit_s: float
    t_s: float = 0.0
    started: bool = False
    ended: bool = False
    outcome: Outcome | None = None
    lines: list[str] = field(default_factory=list)
    events: list[tuple[wire.WorldEvent, float]] = field(default_factory=list)
    planned_kills: set[int] = field(default_factory=set)
    dead_auvs: set[int] = field(default_factory=set)
    duplicate_logins: set[int] = field(default_factory=set)
    """AUVs a ``duplicate_login`` event was said for (once each)."""
    recorder_lost: bool = False
    expected_exits: set[str] = field(default_factory=set)
    fault_at: dict[str, float] = field(default_factory=dict)
    """Process name -> sim time of the kill, term or restart injected on it (until the restart is over): its exit
    is said at that time."""
    router_outage: bool = False
    """A scheduled restart of the router is under way: from its kill until a tick after the fresh router is up."""
    _last_tick_wall: float | None = None
    _stall_said: bool = False

    @property
    def done(self) -> bool:
        """True once the world ended the mission or the run failed."""
        return self.ended or self.outcome is not None

    def fail(self, reason: str, line: str) -> None:
        """The run is incomplete for ``reason``; the first failure is the one reported."""
        if self.outcome is None:
            self.outcome = Outcome(False, reason, line)
            self.lines.append(line)

    def on_tick(self, t_s: float, now: float) -> None:
        """A truth message at sim time ``t_s`` arrived at wall time ``now``."""
        self.t_s = max(self.t_s, t_s)
        self._last_tick_wall = now
        if self.router_outage and "router" not in self.expected_exits:
            self.router_outage = False
            self.fault_at.pop("router", None)
        if self._stall_said:
            self._stall_said = False
            self.lines.append(f"the mission moves again at t = {t_s:g} s")

    def on_event(self, ev: wire.WorldEvent, now: float) -> None:
        """A world event."""
        self.events.append((ev, now))
        if ev.kind == "start":
            self.started = True
            self._last_tick_wall = now
        elif ev.kind == "end":
            self.t_s = max(self.t_s, ev.t_s)
            self.ended = True
        elif ev.kind == "abort":
            reason, _, text = ev.text.partition(": ")
            if reason == "channel_lost" and self.router_outage:  # the world lost the channel with the router
                reason, text = "router_lost", f"router down (a scheduled restart) longer than the world waits: {text}"
            self.fail(reason if reason in CRITICAL.values() or reason == "interrupted" else "world_died", text)
        elif ev.kind == "kill" and ev.auv >= 0:
            self.planned_kills.add(ev.auv)
        elif ev.kind == "rejoin":
            if ev.auv in self.dead_auvs or ev.auv in self.planned_kills:
                self.lines.append(f"AUV {ev.auv} rejoined at t = {ev.t_s:g} s; the swarm has it back")
            self.planned_kills.discard(ev.auv)
            self.dead_auvs.discard(ev.auv)
        elif ev.kind == "duplicate_login" and ev.auv not in self.duplicate_logins:
            self.duplicate_logins.add(ev.auv)
            self.lines.append(f"warning: at t = {ev.t_s:g} s {ev.text} (world/events: duplicate_login)")
        elif ev.kind == "death" and ev.auv >= 0 and ev.auv not in self.dead_auvs:
            self.dead_auvs.add(ev.auv)
            self.lines.append(f"warning: AUV {ev.auv} died at t = {ev.t_s:g} s ({ev.text}); the swarm goes on")

    def final(self) -> Outcome:
        """The run's outcome: the first failure, else ``compromised`` when an AUV's login was stolen, else complete."""
        if self.outcome is None and self.duplicate_logins:
            self.outcome = compromised(sorted(self.duplicate_logins))
            self.lines.append(self.outcome.line)
        return self.outcome or Outcome()

    def on_fault(self, name: str, t_s: float) -> None:
        """The launcher injected a scheduled fault on process ``name`` at the tick of sim time ``t_s`` (the world
        holds the clock there until it is confirmed): an exit of ``name`` is said at ``t_s``, not at the last tick
        heard when the exit is noticed."""
        self.fault_at[name] = t_s

    def on_exit(self, name: str, code: int | None) -> None:
        """Process ``name`` ("world", "router", "channel", "central", "recorder", "auv<N>") exited with ``code``;
        the time said is that of the fault injected on it, if one was (:meth:`on_fault`), else the last tick heard."""
        if self.ended or name in self.expected_exits:
            return
        how = f"exit code {code}" if code is None or code >= 0 else f"signal {-code}"
        t_s = self.fault_at.pop(name, self.t_s)
        if name in CRITICAL and self.router_outage and self.started:
            self.fail(
                "router_lost",
                f"router lost at t = {self.fault_at.get('router', t_s):g} s: it was down (a scheduled restart) longer than the {name} "
                f"would wait ({name} {how}); the run is incomplete",
            )
        elif name in CRITICAL:
            when = f"at t = {t_s:g} s" if self.started else "before the mission started"
            reason = CRITICAL[name] if self.started else "start_failed"
            self.fail(reason, f"{name} died {when} ({how}); the run is incomplete")
        elif name == "recorder" and not self.recorder_lost:
            self.recorder_lost = True
            self.lines.append(f"warning: the recorder died at t = {t_s:g} s ({how}); the recording stops there")
        elif name.startswith("auv"):
            auv = int(name[3:])
            if not self.started:
                self.fail("start_failed", f"AUV {auv} exited before the mission started ({how})")
            elif auv not in self.planned_kills:
                self.lines.append(f"AUV {auv} process exited at t = {t_s:g} s ({how})")

    def expect_exit(self, name: str, expected: bool) -> None:
        """A scheduled restart of ``name`` begins (its exit is no failure) or ends (its exit is one again). While
        the router's restart is under way (until a tick after it is back), a critical process that exits gave up
        on the router: the run is ``router_lost``."""
        (self.expected_exits.add if expected else self.expected_exits.discard)(name)
        if not expected and name != "router":  # the router's outage lasts until a tick after it is back
            self.fault_at.pop(name, None)
        if name == "router" and expected:
            self.router_outage = True

    def on_wall(self, now: float) -> None:
        """Wall time ``now`` passes: say so once when the mission stalls, fail when the world is silent too long."""
        if not self.started or self.done or self._last_tick_wall is None:
            return
        quiet = now - self._last_tick_wall
        if quiet > STALL_S and not self._stall_said:
            self._stall_said = True
            self.lines.append(f"no new tick for {STALL_S:g} s at t = {self.t_s:g} s: waiting for the world")
        if quiet > self.silent_limit_s:
            self.fail("world_died", f"the world has been silent for {quiet:.0f} s at t = {self.t_s:g} s")

    def interrupted(self) -> None:
        """Ctrl-C (or SIGTERM) of the launcher."""
        if self.ended and self.outcome is None:
            return
        self.fail("interrupted", f"interrupted at t = {self.t_s:g} s; the results cover the part that ran")


def compromised(auvs: list[int]) -> Outcome:
    """The outcome of a mission in which the world found AUVs ``auvs`` compromised (and quarantined them)."""
    names = ", ".join(map(str, auvs))
    line = (
        f"AUV {names} compromised: a second client logged in with its password (world/events: duplicate_login); "
        "quarantined, the run is incomplete"
    )
    return Outcome(False, "compromised", line)
