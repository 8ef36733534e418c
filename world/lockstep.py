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
2. publish the clock, the truth and every live AUV's bearing and navigation;
3. wait until every live AUV has sent its command for tick k, has lost its
   token (declared dead, a ``death`` event) or has missed the timeout (hung: not
   waited for again until it answers);
4. apply the commands, integrate to t_{k+1} and publish the world events.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from contract import wire
from world.service import WorldService


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
        self.tokens: set[str] = set()
        self.hung: set[int] = set()
        self.commands: dict[int, wire.Command] = {}
        self.dones: dict[int, wire.ChannelDone] = {}
        self._channel_key = wire.liveliness_component("channel")
        self._auv_keys = {a: wire.liveliness(a) for a in service.model.ids}
        self._also_keys = [wire.liveliness_component(name) for name in wait_for]

    # inbound (called by the shell's ``wait``) ---------------------------------------------------------------------

    def on_message(self, msg: object) -> None:
        """File a ``Command`` or a ``ChannelDone``; anything else is ignored."""
        if isinstance(msg, wire.Command):
            if msg.auv in self._auv_keys:
                if msg.tick == self.service.tick:
                    self.commands[msg.auv] = msg
                self.hung.discard(msg.auv)
        elif isinstance(msg, wire.ChannelDone):
            self.dones[msg.tick] = msg

    def on_liveliness(self, key: str, alive: bool) -> None:
        """A liveliness token appeared (``alive``) or vanished."""
        (self.tokens.add if alive else self.tokens.discard)(key)

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
        return [self._auv_keys[a] for a in self.service.alive] + [self._channel_key, *central, *self._also_keys]

    def missing_tokens(self) -> list[str]:
        """Expected tokens not held right now."""
        return [k for k in self.expected_tokens() if k not in self.tokens]

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
        if not self._channel_tick(io, tick) or io.stopping():
            return
        done = self.dones.pop(tick, None)
        if done is None:
            io.note(f"no channel answer for tick {tick}; no deliveries this tick")
        io.publish(wire.clock(), service.clock())
        io.publish(wire.truth(), service.truth())
        for a, inp in service.agent_inputs(done).items():
            io.publish(wire.sensor(a), inp.sensor)
            io.publish(wire.nav(a), inp.nav)
        self._reap(io, tick)
        answered = io.wait(lambda: not self._waiting(), self.tick_timeout_s)
        if io.stopping():
            return
        self._reap(io, tick)
        if not answered:
            waiting = self._waiting()
            self.hung.update(waiting)
            io.note(f"tick {tick}: no command from {waiting}; treated as hung")
        for event in service.apply(self.commands):
            io.publish(wire.world_events(), event)
        self.commands = {a: c for a, c in self.commands.items() if c.tick == service.tick}

    def _channel_tick(self, io: LockstepIO, tick: int) -> bool:
        """Phase 1, holding the clock while the channel's token is gone (up to ``grace_s``, then ``lost``)."""
        io.publish(wire.channel_tick(), self.service.channel_tick())
        io.wait(lambda: tick in self.dones or self._channel_key not in self.tokens, self.tick_timeout_s)
        if tick in self.dones or self._channel_key in self.tokens:
            return True
        io.note(f"tick {tick}: the channel's liveliness is gone; holding the clock up to {self.grace_s:g} s")
        if not io.wait(lambda: self._channel_key in self.tokens, self.grace_s):
            if not io.stopping():
                self.lost = "channel_lost"
            return False
        io.note(f"tick {tick}: the channel is back")
        io.publish(wire.channel_tick(), self.service.channel_tick())
        io.wait(lambda: tick in self.dones, self.tick_timeout_s)
        return True

    def end_event(self, abort_reason: str | None = None, text: str = "") -> wire.WorldEvent:
        """The ``end`` event at the current sim time, or the ``abort`` one when ``abort_reason`` is given (its
        text ``"<reason>: <text>"``)."""
        t_s = self.service.model.time_s
        if abort_reason is None:
            return wire.WorldEvent(t_s=t_s, source="world", kind="end", auv=-1, text=text or "mission complete")
        return wire.WorldEvent(t_s=t_s, source="world", kind="abort", auv=-1, text=f"{abort_reason}: {text}")

    def _waiting(self) -> list[int]:
        """Live AUVs the tick still waits for: no command yet, not hung, token held."""
        return [
            a
            for a in self.service.alive
            if a not in self.commands and a not in self.hung and self._auv_keys[a] in self.tokens
        ]

    def _reap(self, io: LockstepIO, tick: int) -> None:
        """Declare dead every live AUV whose token is gone (not while the channel's is gone too: that is the
        router's outage, not the AUVs' death)."""
        if self._channel_key not in self.tokens:
            return
        for a in self.service.alive:
            if self._auv_keys[a] not in self.tokens:
                reason = f"AUV {a} lost its liveliness token at tick {tick}"
                io.publish(wire.world_events(), self.service.declare_dead(a, reason))
