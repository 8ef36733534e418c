"""The world's tick loop, as one object both run modes drive (see ``world.service`` for one tick's work).

:class:`Lockstep` holds what the loop knows between ticks: the commands and
``ChannelDone`` received so far, who holds a liveliness token, which AUVs are
hung. It never reads a clock, never sleeps and never touches a network: a
:class:`LockstepIO` does the waiting and the publishing. Its ``wait(until,
timeout_s)`` hands inbound messages to :meth:`Lockstep.on_message` and
liveliness changes to :meth:`Lockstep.on_liveliness` until ``until()`` holds or
``timeout_s`` has passed, however that shell measures time:

- ``world.node`` (processes): a queue filled by zenoh threads, wall-clock
  timeouts of ``run.tick_timeout_s``, liveliness tokens from zenoh;
- ``orchestrator.inprocess`` (one process): a synchronous in-memory bus, so
  every answer is in before ``wait`` is called and no time passes.

One tick k (:meth:`Lockstep.step`):

1. publish ``ChannelTick(k)``; wait for ``ChannelDone(k)`` while the channel holds
   its token (a missing answer means no deliveries this tick). While the channel's
   token is gone the clock is held, up to ``run.grace_s``: a channel back by then
   gets ``ChannelTick(k)`` again, one that is not is lost (``lost``), and the run
   ends incomplete;
2. publish the clock and the truth; on the first tick at or after a fault the launcher injects
   (``WorldService(hold_at=...)``: the channel, router, world or recorder, or a drill's
   unannounced kill), hold the clock here until the launcher's ``FaultsInjected`` for this tick
   arrives (up to ``FAULT_WAIT_S``), so the fault lands on that tick however slowly the launcher
   reads the truth (after a router fault, also until every token is back, up to ``run.grace_s``);
   then publish every live AUV's bearing and navigation;
3. wait until every live AUV has sent its command for tick k, has lost its
   token (declared dead, a ``death`` event) or has missed the timeout (hung: not
   waited for again until it answers);
4. apply the commands, integrate to t_{k+1} and publish the world events.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from auv_swarm.contract import wire
from auv_swarm.contract.params import agent_user
from auv_swarm.world.service import WorldService
from auv_swarm.world.sessions import Sessions

REJOIN_WAIT_S = 60.0
"""Longest the world holds the clock for a restarted AUV to come back (wall s)."""
FAULT_WAIT_S = 60.0
"""Longest the world holds the clock at a fault's tick for the launcher's confirmation (wall s); a router
restart's ``down_s`` falls inside it."""


class LockstepIO(Protocol):
    """How a shell moves the lockstep's messages and measures its waits."""

    def publish(self, key: str, msg: wire.Message) -> None:
        """Send ``msg`` on ``key``."""

    def wait(self, until: Callable[[], bool], timeout_s: float) -> bool:
        """Deliver inbound messages to the lockstep until ``until()`` holds, ``timeout_s`` passed or the shell is
        stopping; return ``until()``."""

    def stopping(self) -> bool:
        """True once the shell was asked to stop (a signal)."""

    def note(self, text: str) -> None:
        """A diagnostic line for the operator (the log)."""


class Lockstep:
    """The world's side of the tick protocol over a :class:`WorldService` (see the module docstring)."""

    def __init__(
        self,
        service: WorldService,
        tick_timeout_s: float,
        grace_s: float | None = None,
        wait_for: tuple[str, ...] = (),
    ) -> None:
        """``wait_for``: components (e.g. ``recorder``) whose liveliness tokens must also be up before the start."""
        if not tick_timeout_s > 0:
            raise ValueError(f"tick_timeout_s must be > 0 s, got {tick_timeout_s!r}")
        self.service = service
        self.tick_timeout_s = tick_timeout_s
        self.grace_s = service.scenario.run.grace_s if grace_s is None else grace_s
        self.lost: str | None = None
        self.rejoin_wait_s = REJOIN_WAIT_S
        self.crashed: set[int] = set()
        self._old_gone: set[int] = set()
        self._resuming: set[int] = set()
        self.resumed: list[int] = []
        self._after_outage = False
        self.tokens: set[str] = set()
        self.hung: set[int] = set()
        self.commands: dict[int, wire.Command] = {}
        self.dones: dict[int, wire.ChannelDone] = {}
        self.fault_wait_s = FAULT_WAIT_S
        self.confirmed: dict[int, tuple[str, ...]] = {}
        """Tick -> the faults the launcher confirmed injecting there (``FaultsInjected``)."""
        self._holding = False
        self._gone_in_hold: set[str] = set()
        self.sessions = Sessions(service.model.ids)
        """Which bus session speaks for each AUV, and the AUVs found compromised (``world.sessions``)."""
        self._channel_key = wire.liveliness_component("channel")
        self._auv_keys = {a: wire.liveliness(a) for a in service.model.ids}
        self._also_keys = [wire.liveliness_component(name) for name in wait_for]

    # inbound (called by the shell's ``wait``) ---------------------------------------------------------------------

    def on_message(self, msg: object) -> None:
        """File a ``Command``, a ``ChannelDone`` or a ``FaultsInjected``; anything else is ignored."""
        if isinstance(msg, wire.Command):
            if msg.auv in self._auv_keys:
                if msg.tick == self.service.tick:
                    self.commands[msg.auv] = msg
                if msg.auv in self.hung:
                    self.hung.discard(msg.auv)
                    self.resumed.append(msg.auv)
        elif isinstance(msg, wire.ChannelDone):
            self.dones[msg.tick] = msg
        elif isinstance(msg, wire.FaultsInjected):
            self.confirmed[msg.tick] = msg.faults

    def on_duplicate(self, _key: str, msg: object) -> None:
        """A second, different ``Command`` of one tick on an AUV's key (``bus.identity``: ``duplicate_login``):
        the AUV is compromised (reported and quarantined before the tick's commands are applied)."""
        if isinstance(msg, wire.Command) and msg.auv in self._auv_keys:
            self.sessions.report(msg.auv, f"two different commands of tick {msg.tick} on AUV {msg.auv}'s key")

    def on_sender(self, auv: int, session: str | None, what: str) -> bool:
        """A ``what`` (command, frame, telemetry) on AUV ``auv``'s key came from bus session ``session``: True
        when it may be used (``world.sessions``: the bound session's; another's is evidence of a second login)."""
        if not self.sessions.known(auv):
            return False
        return self.sessions.on_message(auv, session, what, dead=auv not in self.service.alive)

    def on_liveliness(self, key: str, alive: bool) -> None:
        """A liveliness token appeared (``alive``) or vanished; an AUV's whose bound session's token went is
        gone (whatever other session holds a token of its name)."""
        (self.tokens.add if alive else self.tokens.discard)(key)
        if not alive and self._holding:
            self._gone_in_hold.add(key)
        parsed = wire.parse_liveliness(key)
        if parsed is None or not self.sessions.known(parsed[0]):
            return
        auv, session = parsed
        held = self.sessions.holds(auv)
        self.sessions.on_token(auv, session, alive, dead=auv not in self.service.alive)
        if held and not self.sessions.holds(auv):
            self._old_gone.add(auv)

    # the loop -----------------------------------------------------------------------------------------------------

    @property
    def finished(self) -> bool:
        """True once the mission's last tick has run."""
        return self.service.finished

    def expected_tokens(self) -> list[str]:
        """The tokens that must be up before the mission starts: every live AUV's, the channel's (and the central
        planner's under the centralised method, whose AUVs wait for its plans) and ``wait_for``'s."""
        central = (
            [wire.liveliness_component("central")] if self.service.scenario.planner.method == "centralised" else []
        )
        return [self._auv_token(a) for a in self.service.alive] + [self._channel_key, *central, *self._also_keys]

    def missing_tokens(self) -> list[str]:
        """Expected tokens not held right now (an AUV's: its bound session's)."""
        auvs = [self._auv_token(a) for a in self.service.alive if not self.sessions.holds(a)]
        return auvs + [k for k in self.expected_tokens()[len(self.service.alive) :] if k not in self.tokens]

    def _auv_token(self, auv: int) -> str:
        """The token key of AUV ``auv``'s bound session (its plain key on a bus without sessions, or unbound)."""
        session = self.sessions.bound.get(auv)
        return self._auv_keys[auv] if session is None else wire.liveliness_session(auv, session)

    def start(self, io: LockstepIO, wait_s: float) -> list[str]:
        """Wait up to ``wait_s`` for every expected token; publish the ``start`` event. Returns the missing tokens
        (empty when the mission started)."""
        io.wait(lambda: not self.missing_tokens(), wait_s)
        missing = self.missing_tokens()
        if not missing:
            name = self.service.scenario.name
            io.publish(wire.world_events(), wire.WorldEvent(t_s=0.0, source="world", kind="start", auv=-1, text=name))
        return missing

    def step(self, io: LockstepIO) -> None:
        """Run one tick (see the module docstring); returns early, before integrating, if the shell is stopping
        or the channel is lost (``lost`` says so)."""
        service = self.service
        tick = service.tick
        self._rejoin(io)
        self._quarantine(io)
        if not self._channel_tick(io, tick) or io.stopping():
            return
        done = self.dones.pop(tick, None)
        if done is None:
            io.note(f"no channel answer for tick {tick}; no deliveries this tick")
        io.publish(wire.clock(), service.clock())
        io.publish(wire.truth(), service.truth())
        if service.hold_due():
            self._hold(io, tick)
            if io.stopping():
                return
        for a, inp in service.agent_inputs(done).items():
            io.publish(wire.sensor(a), inp.sensor)
            io.publish(wire.nav(a), inp.nav)
        self._reap(io, tick)
        if self._resuming:  # a stopped process catches up on the ticks it slept through: hold the clock for it
            io.wait(lambda: not (self._resuming & set(self._waiting())), self.rejoin_wait_s)
            self._resuming.clear()
        answered = io.wait(lambda: not self._waiting(), self.tick_timeout_s)
        if io.stopping():
            return
        self._reap(io, tick)
        if not answered:
            waiting = self._waiting()
            self.hung.update(waiting)
            io.note(f"tick {tick}: no command from {waiting}; treated as hung")
            for a in waiting:
                text = f"AUV {a} sent no command for tick {tick} within {self.tick_timeout_s:g} s"
                io.publish(wire.world_events(), self._event("hung", a, text))
        for a in self.resumed:
            io.publish(wire.world_events(), self._event("resume", a, f"AUV {a} answers again"))
        self.resumed.clear()
        self._quarantine(io)
        for event in service.apply(self.commands):
            if event.kind == "kill":
                self._old_gone.discard(event.auv)  # a restart waits for this process's token to go first
            io.publish(wire.world_events(), event)
        self.commands = {a: c for a, c in self.commands.items() if c.tick == service.tick}

    def _rejoin(self, io: LockstepIO) -> None:
        """Re-admit the restarted AUVs due now, holding the clock (up to ``rejoin_wait_s``) until the killed
        process's token has gone and the fresh process's is up, so a restart lands on the same tick however
        long the launcher takes to act and the process to start. An AUV that died
        unscheduled and whose token is back (restarted by hand or by ``--restart on-failure``) is re-admitted
        at once (not deterministic: it depends on when the process came back)."""
        for a in sorted(self.crashed):
            if self.sessions.holds(a):
                self.crashed.discard(a)
                self.hung.discard(a)
                io.publish(wire.world_events(), self.service.rejoin(a))
        for a in self.service.resumes_due():
            self.hung.discard(a)
            self._resuming.add(a)
            io.publish(wire.world_events(), self.service.resume(a))
        for a in self.service.rejoins_due():
            if io.wait(lambda a=a: a in self._old_gone and self.sessions.holds(a), self.rejoin_wait_s):
                self.hung.discard(a)
                io.publish(wire.world_events(), self.service.rejoin(a))
            elif not io.stopping():
                reason = f"AUV {a} did not come back within {self.rejoin_wait_s:g} s of its restart"
                io.note(reason)
                io.publish(wire.world_events(), self.service.give_up_rejoin(a, reason))

    def _hold(self, io: LockstepIO, tick: int) -> None:
        """Hold the clock at ``tick`` (its truth out, its navigation not yet) until the launcher confirms the faults
        it injects there (up to ``fault_wait_s``). When every token held at the start of the hold went meanwhile,
        the router was down (a router fault takes every session's link with it, and its confirmation can only
        come through the fresh router): wait up to ``grace_s`` for them all to come back before any AUV is sent
        this tick. A single process's fault (the channel, an AUV) is not waited for: its tick goes on without
        it, so what it misses does not depend on how fast it comes back."""
        held = set(self.expected_tokens()) & self.tokens
        self._holding, self._gone_in_hold = True, set()
        try:
            if not io.wait(lambda: tick in self.confirmed, self.fault_wait_s):
                if not io.stopping():
                    io.note(f"tick {tick}: no confirmation of the faults due within {self.fault_wait_s:g} s; going on")
                return
            faults = ", ".join(self.confirmed[tick]) or "none could be injected"
            io.note(f"tick {tick}: the launcher injected its faults ({faults})")
            if held and held <= self._gone_in_hold:
                io.note(f"tick {tick}: every process's token went with the router; waiting up to {self.grace_s:g} s")
                io.wait(lambda: held <= self.tokens, self.grace_s)
        finally:
            self._holding = False
            self.confirmed = {k: v for k, v in self.confirmed.items() if k > tick}

    def _channel_tick(self, io: LockstepIO, tick: int) -> bool:
        """Phase 1, holding the clock while the channel's token is gone (up to ``grace_s``, then ``lost``)."""
        io.publish(wire.channel_tick(), self._channel_tick_message())
        io.wait(lambda: tick in self.dones or self._channel_key not in self.tokens, self.tick_timeout_s)
        if tick in self.dones or self._channel_key in self.tokens:
            return True
        io.note(f"tick {tick}: the channel's liveliness is gone; holding the clock up to {self.grace_s:g} s")
        if not io.wait(lambda: self._channel_key in self.tokens, self.grace_s):
            if not io.stopping():
                self.lost = "channel_lost"
            return False
        io.note(f"tick {tick}: the channel is back")
        self._after_outage = True
        io.publish(wire.channel_tick(), self._channel_tick_message())
        io.wait(lambda: tick in self.dones, self.tick_timeout_s)
        return True

    def end_event(self, abort_reason: str | None = None, text: str = "") -> wire.WorldEvent:
        """The ``end`` event at the current sim time, or the ``abort`` one when ``abort_reason`` is given (its
        text ``"<reason>: <text>"``)."""
        t_s = self.service.model.time_s
        if abort_reason is None:
            return wire.WorldEvent(t_s=t_s, source="world", kind="end", auv=-1, text=text or "mission complete")
        return wire.WorldEvent(t_s=t_s, source="world", kind="abort", auv=-1, text=f"{abort_reason}: {text}")

    def _channel_tick_message(self) -> wire.ChannelTick:
        """Phase 1's message: the service's, with the session each AUV's frames must come from."""
        refused = tuple(sorted(self.sessions.compromised))
        return self.service.channel_tick(self.sessions.channel_sessions(), refused)

    def _quarantine(self, io: LockstepIO) -> None:
        """Report every AUV found compromised since the last call (a ``duplicate_login`` event) and quarantine it:
        dead where it is (a ``death`` event), its commands, frames and telemetry refused for the rest of the
        mission, never restarted."""
        for a in self.sessions.detected:
            why = self.sessions.compromised[a]
            text = f"{why}: a second client is logged in as {agent_user(a)}; AUV {a} is quarantined"
            io.note(text)
            io.publish(wire.world_events(), self._event("duplicate_login", a, text))
            io.publish(wire.world_events(), self.service.quarantine(a, f"compromised: {why}"))
            self.crashed.discard(a)
            self.hung.discard(a)
            self.commands.pop(a, None)
        self.sessions.detected.clear()

    def _event(self, kind: str, auv: int, text: str) -> wire.WorldEvent:
        return wire.WorldEvent(t_s=self.service.model.time_s, source="world", kind=kind, auv=auv, text=text)

    def _waiting(self) -> list[int]:
        """Live AUVs the tick still waits for: no command yet, not hung, not found compromised, token held."""
        return [
            a
            for a in self.service.alive
            if a not in self.commands
            and a not in self.sessions.compromised
            and a not in self.hung
            and a not in self.service.stopped
            and self.sessions.holds(a)
        ]

    def _reap(self, io: LockstepIO, tick: int) -> None:
        """Declare dead every live AUV whose token is gone (not while the channel's is gone too: that is the
        router's outage, not the AUVs' death; right after such an outage the AUVs get ``grace_s`` to declare
        their tokens again)."""
        if self._channel_key not in self.tokens:
            return
        if self._after_outage:
            self._after_outage = False
            io.wait(lambda: all(self.sessions.holds(a) for a in self.service.alive), self.grace_s)
        for a in self.service.alive:
            if not self.sessions.holds(a):
                reason = f"AUV {a} lost its liveliness token at tick {tick}"
                io.publish(wire.world_events(), self.service.declare_dead(a, reason))
                self.crashed.add(a)
