"""AUV process shell: binds one ``AgentCore`` to zenoh (``python -m agent --id I``).

It subscribes to its own navigation, sensor and modem rx, runs the core once
it holds everything the world announced for a tick (navigation, bearing and
``rx_expected`` modem frames), then publishes its modem frames, telemetry and,
last, its command, which tells the world this AUV is done with the tick.
A message that does not decode is counted and dropped; it never stops the AUV.
"""

from __future__ import annotations

import argparse
import functools
import sys
from dataclasses import dataclass, field

from auv_swarm.agent.core import AgentCore
from auv_swarm.bus.identity import Gate
from auv_swarm.bus.shell import add_common_args, handle_info_flags, scenario_from_args, serve
from auv_swarm.contract import wire
from auv_swarm.contract.methods import METHOD_ERROR, MethodError
from auv_swarm.contract.usage import RUN_FAILED, fail, plain_description


@dataclass
class TickInbox:
    """Messages of one tick, as they arrive."""

    nav: wire.Nav | None = None
    sensor: wire.Sensor | None = None
    rx: list[wire.ModemRx] = field(default_factory=list)
    central: wire.CentralPlan | None = None
    needs_central: bool = False

    def complete(self) -> bool:
        if self.needs_central and self.central is None:
            return False
        return self.nav is not None and self.sensor is not None and len(self.rx) >= self.nav.rx_expected


class AgentNode:
    """The shell: decode, buffer by tick, run the core, publish."""

    def __init__(self, core: AgentCore) -> None:
        self.core = core
        self.inbox: dict[int, TickInbox] = {}
        self.next_tick = 0
        self.gate = Gate(f"auv {core.auv}")
        auv = core.auv
        self._keys = (wire.modem_tx(auv), wire.telemetry(auv), wire.command(auv))
        self.centralised = core.method == "centralised"

    def accept(self, msg: object) -> None:
        """File a decoded message under its tick (stale or foreign messages are ignored)."""
        tick = getattr(msg, "tick", -1)
        if getattr(msg, "auv", None) != self.core.auv or tick < self.next_tick:
            return
        box = self.inbox.get(tick)
        if box is None:
            box = self.inbox[tick] = TickInbox(needs_central=self.centralised)
        if isinstance(msg, wire.Nav):
            box.nav = msg
        elif isinstance(msg, wire.Sensor):
            box.sensor = msg
        elif isinstance(msg, wire.ModemRx):
            box.rx.append(msg)
        elif isinstance(msg, wire.CentralPlan):
            box.central = msg

    def ready(self) -> list[tuple[int, TickInbox]]:
        """Complete ticks in order; a newer complete tick supersedes older incomplete ones."""
        done = []
        for tick in sorted(self.inbox):
            box = self.inbox[tick]
            if box.complete():
                done.append((tick, box))
        if done:
            last = done[-1][0]
            for tick in [t for t in self.inbox if t <= last]:
                del self.inbox[tick]
            self.next_tick = last + 1
        return done

    def on_message(self, key: str, msg: wire.Message) -> list[tuple[str, wire.Message]]:
        """File one decoded message that arrived on ``key``, run every tick now complete; return what to publish.

        A message whose body does not match its key (``bus.identity``) is counted and dropped.
        Modem frames first, then telemetry, then the command (which tells the world the AUV
        is done with the tick).
        """
        if not self.gate.admit(key, msg):
            return []
        return self._run(msg)

    def _run(self, msg: wire.Message) -> list[tuple[str, wire.Message]]:
        self.accept(msg)
        out: list[tuple[str, wire.Message]] = []
        tx_key, telemetry_key, command_key = self._keys
        for _tick, box in self.ready():
            result = self.core.on_tick(box.nav, box.sensor, box.rx, box.central)
            out.extend((tx_key, tx) for tx in result.tx)
            out.append((telemetry_key, result.telemetry))
            out.append((command_key, result.command))
        return out

    def on_bytes(self, key: str, data: bytes) -> list[tuple[str, bytes]]:
        """:meth:`on_message` for an encoded message; one that does not decode is counted, never raised."""
        msg = self.gate.receive(key, data)
        if msg is None:
            return []
        return [(out_key, wire.encode(out)) for out_key, out in self._run(msg)]

    def subscriptions(self) -> list[str]:
        """The keys this AUV listens to: its navigation, its sensor, its modem rx (and its central plan if centralised)."""
        auv = self.core.auv
        keys = [wire.nav(auv), wire.sensor(auv), wire.modem_rx(auv)]
        return keys + [wire.central_plan(auv)] if self.centralised else keys


def left_alive_set(auv: int, clock_bytes: bytes, was_alive: bool) -> bool | None:
    """Whether ``auv`` is in the Clock's alive set; None when it was alive and is no longer (it was killed).

    An AUV the world killed exits, so its process (and its container) stops as the metrics
    say; one that starts outside the alive set (a restart) waits to be re-admitted.
    A Clock that does not decode counts as no news.
    """
    try:
        clock = wire.decode(clock_bytes)
    except wire.DecodeError:
        return was_alive
    if not isinstance(clock, wire.Clock):
        return was_alive
    alive = auv in clock.alive
    return None if was_alive and not alive else alive


def main(argv: list[str] | None = None) -> int:
    """``auv-swarm agent --id I --scenario NAME --router ENDPOINT``."""
    parser = argparse.ArgumentParser(prog="auv-swarm agent", description=plain_description(__doc__))
    parser.add_argument("--id", type=int, default=0, help="this AUV's id (0-based)")
    add_common_args(parser)
    args = parser.parse_args(argv)
    if handle_info_flags(args, "agent", sections=("agents", "sensor", "estimator", "planner")):
        return 0
    scenario = scenario_from_args(args)
    if not 0 <= args.id < scenario.agents.count:
        return fail(f"--id must be in [0, {scenario.agents.count - 1}], got {args.id}")

    was_alive = False

    def on_clock(data: bytes) -> int | None:
        """Exit (code 0) once the world no longer counts this AUV alive (a scheduled kill)."""
        nonlocal was_alive
        alive = left_alive_set(args.id, data, was_alive)
        if alive is None:
            print(f"auv {args.id}: the world no longer counts me alive (a scheduled kill); exiting", flush=True)
            return 0
        was_alive = alive
        return None

    try:
        node = AgentNode(AgentCore(args.id, scenario))
        token = functools.partial(wire.liveliness_session, args.id)  # one token per session: a second login shows
        return serve(
            args, f"auv{args.id}", f"auv {args.id}", token, scenario.run.grace_s, node, {wire.clock(): on_clock}
        )
    except MethodError as exc:  # a plug-in method raised: the launcher reads this line (a failed mission)
        return fail(f"{METHOD_ERROR}: {exc}", RUN_FAILED)


if __name__ == "__main__":
    sys.exit(main())
