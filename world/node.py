"""World process shell: ground truth, the simulation clock and the lockstep barrier.

``auv-swarm world --scenario NAME --router ENDPOINT`` drives
:class:`world.lockstep.Lockstep` over zenoh: zenoh threads queue commands,
``ChannelDone`` and liveliness changes, and :class:`ZenohIO` hands them to the
lockstep on the main thread, waiting at most ``run.tick_timeout_s`` of wall
time per phase. ``--speed X`` paces the clock at X times real time for demos
(default: lockstep as fast as the processes go).
"""

from __future__ import annotations

import argparse
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable

from auv_swarm.bus.identity import Gate
from auv_swarm.bus.lifeline import Lifeline, parent_from_env
from auv_swarm.bus.shell import add_common_args, connect, handle_info_flags, scenario_from_args
from auv_swarm.contract import wire
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.world.lockstep import Lockstep
from auv_swarm.world.service import WorldService

POLL_S = 0.05
"""Longest the shell blocks on its queue before looking at the stop flag again (wall s)."""


_WHAT = {"cmd": "command", "modem/tx": "frame", "telemetry": "telemetry message"}
"""What the world calls a message on each key an AUV publishes (the tail of ``<prefix>/auv/<id>/...``)."""


class ZenohIO:
    """:class:`world.lockstep.LockstepIO` over a zenoh bus: wall-clock waits on a queue the zenoh threads fill."""

    def __init__(self, bus: object, lockstep: Lockstep, stop: threading.Event) -> None:
        self.bus = bus
        self.lockstep = lockstep
        self.stop = stop
        self.inbound: queue.Queue[tuple[str, object]] = queue.Queue()
        self.gate = Gate("world", on_duplicate=lambda key, msg: self.lockstep.on_duplicate(key, msg))

    def on_bytes(self, key: str, data: bytes) -> None:
        """Zenoh callback for ``ChannelDone`` and ``FaultsInjected``: decode, check against the key
        (``bus.identity``: a forged message is counted and dropped) and queue."""
        msg = self.gate.receive(key, data, max_tick=self.lockstep.service.tick)
        if msg is not None:
            self.inbound.put(("msg", msg))

    def on_auv(self, key: str, data: object, session: str | None) -> None:
        """Zenoh callback for what the AUVs publish (commands, frames, telemetry) with the sender's session: queued
        for the main thread, which checks the session (``world.sessions``) and files the commands."""
        self.inbound.put(("auv", (key, data, session)))

    def _from_auv(self, key: str, data: object, session: str | None) -> None:
        """One message of an AUV: its session checked, then a command decoded and checked against the key
        (``bus.identity``: a forged, replayed or future one is counted and dropped; a second different one
        of one tick is a duplicate login) and filed. Frames and telemetry are only looked at for their session
        (their bytes are not even copied out of zenoh)."""
        auv = wire.parse_auv_id(key)
        what = _WHAT.get(key.partition(f"/auv/{auv}/")[2])
        if auv is None or what is None or not self.lockstep.on_sender(auv, session, what):
            return
        if what == "command":
            msg = self.gate.receive(key, data, max_tick=self.lockstep.service.tick)
            if msg is not None:
                self.lockstep.on_message(msg)

    def on_liveliness(self, key: str, alive: bool) -> None:
        """Zenoh callback for liveliness tokens: queue the change."""
        self.inbound.put(("live", (key, alive)))

    def publish(self, key: str, msg: wire.Message) -> None:
        self.bus.publish(key, wire.encode(msg))

    def wait(self, until: Callable[[], bool], timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while not until():
            left = end - time.monotonic()
            if left <= 0 or self.stop.is_set():
                return False
            self._drain(min(POLL_S, left))
        return True

    def stopping(self) -> bool:
        return self.stop.is_set()

    def note(self, text: str) -> None:
        print(f"world: {text}", file=sys.stderr, flush=True)

    def _drain(self, block_s: float) -> None:
        try:
            item = self.inbound.get(timeout=block_s)
        except queue.Empty:
            return
        while True:
            kind, value = item
            if kind == "msg":
                self.lockstep.on_message(value)
            elif kind == "auv":
                self._from_auv(*value)
            else:
                self.lockstep.on_liveliness(*value)
            try:
                item = self.inbound.get_nowait()
            except queue.Empty:
                return


def run(lockstep: Lockstep, bus: object, stop: threading.Event, speed: float, wait_s: float) -> int:
    """Bring the mission up on ``bus``, tick it to the end and announce it; an ``abort`` instead when the channel
    is lost or ``stop`` is set (a signal, or the launcher gone). Returns the exit code: 0 complete, 1 aborted."""
    io = ZenohIO(bus, lockstep, stop)
    Lifeline(lockstep.service.scenario.run.grace_s, parent_from_env()).attach(bus, stop, "world", follow_end=False)
    bus.subscribe(wire.all_commands(), io.on_auv, sender=True)
    bus.subscribe(wire.all_modem_tx(), io.on_auv, max_bytes=0, sender=True)
    bus.subscribe(wire.all_telemetry(), io.on_auv, max_bytes=0, sender=True)
    bus.subscribe(wire.channel_done(), io.on_bytes)
    bus.subscribe(wire.faults_injected(), io.on_bytes)
    bus.subscribe_liveliness(wire.all_liveliness(), io.on_liveliness)
    bus.declare_liveliness(wire.liveliness_component("world"))
    missing = lockstep.start(io, wait_s)
    if missing:
        io.note(f"gave up waiting for {missing}")
        return 1
    scenario = lockstep.service.scenario
    print(f"world: all {len(lockstep.expected_tokens())} processes up, starting {scenario.name}", flush=True)
    wall0 = time.monotonic()
    while not lockstep.finished and not stop.is_set() and lockstep.lost is None:
        lockstep.step(io)
        if speed > 0:
            lag = lockstep.service.model.time_s / speed - (time.monotonic() - wall0)
            if lag > 0:
                stop.wait(lag)
    t_s = lockstep.service.model.time_s
    if lockstep.finished:
        io.publish(wire.world_events(), lockstep.end_event())
        print(f"world: finished at t = {t_s:g} s", flush=True)
        return 0
    if lockstep.lost is not None:
        text = f"the channel's liveliness was gone for more than {lockstep.grace_s:g} s at t = {t_s:g} s"
        event = lockstep.end_event(lockstep.lost, text)
    else:
        event = lockstep.end_event("interrupted", f"the world was stopped at t = {t_s:g} s")
    io.publish(wire.world_events(), event)
    print(f"world: mission aborted: {event.text}", file=sys.stderr, flush=True)
    return 130 if getattr(stop, "signum", None) == signal.SIGINT else 1


def parse_times(text: str) -> tuple[float, ...]:
    """``--hold-at``: comma-separated sim times (s), each finite and >= 0; ValueError naming the bad one."""
    times = []
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        try:
            value = float(item)
        except ValueError:
            raise ValueError(f"must be sim times in s separated by commas, got {item!r}") from None
        if not 0.0 <= value < float("inf"):
            raise ValueError(f"a sim time must be finite and >= 0 s, got {item!r}")
        times.append(value)
    return tuple(times)


def main(argv: list[str] | None = None) -> int:
    """``auv-swarm world``: run the mission clock until the scenario's duration."""
    parser = argparse.ArgumentParser(prog="auv-swarm world", description=plain_description(__doc__))
    add_common_args(parser)
    parser.add_argument("--speed", type=float, default=0.0, help="pace at X times real time (0 = lockstep, fastest)")
    parser.add_argument("--wait-s", type=float, default=60.0, help="wall seconds to wait for all processes at start")
    parser.add_argument(
        "--wait-for",
        default="",
        help="also wait at start for these components' liveliness, comma-separated (e.g. recorder,orchestrator)",
    )
    parser.add_argument(
        "--hold-at",
        default="",
        help="sim times (s), comma-separated, of faults the launcher injects: the world holds the clock at the first "
        "tick at or after each until the launcher confirms (auv-swarm run sets it)",
    )
    args = parser.parse_args(argv)
    if handle_info_flags(args, "world", sections=("run", "target", "agents", "sensor")):
        return 0
    if args.speed < 0:
        return fail(f"--speed must be >= 0, got {args.speed}")
    try:
        hold_at = parse_times(args.hold_at)
    except ValueError as exc:
        return fail(f"--hold-at: {exc}")
    scenario = scenario_from_args(args)

    from auv_swarm.bus.zbus import shutdown_event

    stop = shutdown_event()
    try:
        service = WorldService(scenario, hold_at=hold_at)
    except ValueError as exc:
        return fail(f"the world rejects scenario {scenario.name!r}: {exc}")
    also = tuple(name.strip() for name in args.wait_for.split(",") if name.strip())
    lockstep = Lockstep(service, scenario.run.tick_timeout_s, wait_for=also)
    with connect(args, "world") as bus:
        return run(lockstep, bus, stop, args.speed, args.wait_s)


if __name__ == "__main__":
    sys.exit(main())
