"""The listen loop that ``auv-swarm run`` (the launcher) and ``auv-swarm collect`` (compose's collector) share.

Both subscribe to the results keys (:data:`RESULT_KEYS`), queue the decoded
messages and read them in one loop that hands each one to their sinks (the
:class:`~auv_swarm.results.collect.MessageLog` first) and tells the
:class:`~auv_swarm.orchestrator.mission.supervise.Supervisor` of every tick and world event. What
each does besides (faults and restarts; the world's liveliness) it does per turn
of :func:`supervised`.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from typing import Protocol

from auv_swarm.contract import wire
from auv_swarm.contract.config import RunConfig
from auv_swarm.orchestrator.mission.supervise import Supervisor

RESULT_KEYS = (
    wire.truth(),
    wire.all_telemetry(),
    wire.channel_events(),
    wire.channel_stats(),
    wire.world_events(),
    wire.all_sensors(),
    wire.all_modem_rx(),
)
"""What the orchestrator listens to, to write the results (the bearings taken and the frames delivered: the bearing
table of record.parquet's companions, docs/results.md)."""

WAIT_S = 0.2
"""Wall seconds one turn waits for a message before it yields without one."""


class Sink(Protocol):
    """Receives what a recorder hears on the bus (truth, sensor, telemetry, channel and world events)."""

    def on_message(self, msg: object) -> None: ...


class Fanout:
    """One sink that hands every message to each of ``sinks`` in turn (anything with ``on_message``)."""

    def __init__(self, sinks: list[Sink]) -> None:
        self.sinks = list(sinks)

    def on_message(self, msg: object) -> None:
        for sink in self.sinks:
            sink.on_message(msg)


def supervisor_for(run: RunConfig) -> Supervisor:
    """The supervisor of a mission of ``run``: a world silent for three tick timeouts plus the grace and 10 s is
    taken as dead."""
    return Supervisor(run.duration_s, silent_limit_s=3 * run.tick_timeout_s + run.grace_s + 10)


def supervised(
    inbound: queue.Queue, sink: Sink, sup: Supervisor, stop: threading.Event
) -> Iterator[tuple[float, object | None]]:
    """Yield ``(now, message or None)`` once a turn until ``sup`` is done or ``stop`` is set (then the run
    counts as interrupted). ``now`` is wall time (``time.monotonic``); a message was handed to ``sink`` and, a
    ``Truth`` or a ``WorldEvent``, given to ``sup`` before it is yielded. A turn waits at most :data:`WAIT_S`."""
    while not sup.done:
        if stop.is_set():
            sup.interrupted()
            return
        try:
            msg = inbound.get(timeout=WAIT_S)
        except queue.Empty:
            msg = None
        now = time.monotonic()
        if msg is not None:
            sink.on_message(msg)
            if isinstance(msg, wire.Truth):
                sup.on_tick(msg.t_s, now)
            elif isinstance(msg, wire.WorldEvent):
                sup.on_event(msg, now)
        yield now, msg
