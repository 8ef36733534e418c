"""World process shell: ground truth, the simulation clock and the lockstep barrier.

``auv-swarm world --scenario NAME --router ENDPOINT`` drives ``WorldService``
over zenoh. Each tick it waits (bounded by ``run.tick_timeout_s`` of wall time)
for the channel's ``ChannelDone`` and every live AUV's ``Command``. Liveliness
tokens tell who is alive: an AUV whose token disappears is declared dead at
once; one that misses the timeout is treated as hung and no longer waited for
until it answers again, so a dead or frozen process cannot stall the others.
``--speed X`` paces the clock at X times real time for demos (default:
lockstep as fast as the processes go).
"""

from __future__ import annotations

import argparse
import queue
import signal
import sys
import threading
import time

from contract import wire
from contract.shell import add_common_args, handle_info_flags, scenario_from_args, secret
from world.service import WorldService


class Liveness:
    """Who holds a liveliness token right now (updated from zenoh threads)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self.changed = threading.Event()

    def update(self, key: str, alive: bool) -> None:
        with self._lock:
            (self._alive.add if alive else self._alive.discard)(key)
        self.changed.set()

    def __contains__(self, key: str) -> bool:
        with self._lock:
            return key in self._alive


def main(argv: list[str] | None = None) -> int:
    """``auv-swarm world``: run the mission clock until the scenario's duration."""
    parser = argparse.ArgumentParser(prog="auv-swarm world", description=__doc__)
    add_common_args(parser)
    parser.add_argument("--speed", type=float, default=0.0, help="pace at X times real time (0 = lockstep, fastest)")
    parser.add_argument("--wait-s", type=float, default=60.0, help="wall seconds to wait for all processes at start")
    parser.add_argument(
        "--wait-for",
        default="",
        help="also wait at start for these components' liveliness, comma-separated (e.g. recorder,orchestrator)",
    )
    args = parser.parse_args(argv)
    if handle_info_flags(args, "world", sections=("run", "target", "agents", "sensor")):
        return 0
    if args.speed < 0:
        print(f"error: --speed must be >= 0, got {args.speed}", file=sys.stderr)
        return 2
    scenario = scenario_from_args(args)

    from contract.zbus import ZenohBus, password_for

    service = WorldService(scenario)
    timeout = scenario.run.tick_timeout_s
    inbound: queue.Queue[object] = queue.Queue()
    live = Liveness()
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    decode_errors = 0

    def on_bytes(_key: str, data: bytes) -> None:
        nonlocal decode_errors
        try:
            inbound.put(wire.decode(data))
        except wire.DecodeError as exc:
            decode_errors += 1
            print(f"world: dropped malformed message: {exc}", file=sys.stderr, flush=True)

    with ZenohBus(args.router, user="world", password=password_for("world", secret())) as bus:
        bus.subscribe(wire.all_commands(), on_bytes)
        bus.subscribe(wire.channel_done(), on_bytes)
        bus.subscribe_liveliness(wire.all_liveliness(), live.update)
        bus.declare_liveliness(wire.liveliness_component("world"))
        channel_key = wire.liveliness_component("channel")
        extra = [wire.liveliness_component(name.strip()) for name in args.wait_for.split(",") if name.strip()]
        expected = [wire.liveliness(a) for a in service.alive] + [channel_key, *extra]
        deadline = time.monotonic() + args.wait_s
        while not all(k in live for k in expected):
            if time.monotonic() > deadline or stop.is_set():
                missing = [k for k in expected if k not in live]
                print(f"world: gave up waiting for {missing}", file=sys.stderr, flush=True)
                return 1
            live.changed.wait(0.1)
            live.changed.clear()
        print(f"world: all {len(expected)} processes up, starting {scenario.name}", flush=True)

        def publish(key: str, msg: object) -> None:
            bus.publish(key, wire.encode(msg))

        publish(wire.world_events(), wire.WorldEvent(t_s=0.0, source="world", kind="start", auv=-1, text=scenario.name))
        hung: set[int] = set()
        commands: dict[int, wire.Command] = {}
        done_by_tick: dict[int, wire.ChannelDone] = {}
        wall0 = time.monotonic()

        def drain(block_s: float) -> None:
            try:
                msg = inbound.get(timeout=block_s)
            except queue.Empty:
                return
            while True:
                if isinstance(msg, wire.Command) and msg.auv in service.model.states:
                    if msg.tick == service.tick:
                        commands[msg.auv] = msg
                    hung.discard(msg.auv)
                elif isinstance(msg, wire.ChannelDone):
                    done_by_tick[msg.tick] = msg
                try:
                    msg = inbound.get_nowait()
                except queue.Empty:
                    return

        while not service.finished and not stop.is_set():
            tick = service.tick
            publish(wire.channel_tick(), service.channel_tick())
            t_end = time.monotonic() + timeout
            while tick not in done_by_tick and channel_key in live and time.monotonic() < t_end and not stop.is_set():
                drain(0.05)
            done = done_by_tick.pop(tick, None)
            if done is None:
                print(f"world: no channel answer for tick {tick}; no deliveries this tick", file=sys.stderr, flush=True)
            publish(wire.clock(), service.clock())
            publish(wire.truth(), service.truth())
            inputs = service.agent_inputs(done)
            for a, inp in inputs.items():
                publish(wire.sensor(a), inp.sensor)
                publish(wire.nav(a), inp.nav)
            t_end = time.monotonic() + timeout
            while not stop.is_set():
                for a in service.alive:
                    if wire.liveliness(a) not in live:
                        event = service.declare_dead(a, f"AUV {a} lost its liveliness token at tick {tick}")
                        publish(wire.world_events(), event)
                waiting = [a for a in service.alive if a not in commands and a not in hung]
                if not waiting:
                    break
                if time.monotonic() >= t_end:
                    hung.update(waiting)
                    print(
                        f"world: tick {tick}: no command from {waiting}; treated as hung", file=sys.stderr, flush=True
                    )
                    break
                drain(0.05)
            for event in service.apply(commands):
                publish(wire.world_events(), event)
            commands = {a: c for a, c in commands.items() if c.tick == service.tick}
            if args.speed > 0:
                lag = service.model.time_s / args.speed - (time.monotonic() - wall0)
                if lag > 0:
                    stop.wait(lag)
        end = wire.WorldEvent(t_s=service.model.time_s, source="world", kind="end", auv=-1, text="mission complete")
        publish(wire.world_events(), end)
        print(f"world: finished at t = {service.model.time_s:g} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
