"""Recorder process shell: listen on the bus and log the mission to rerun.

``auv-swarm recorder --scenario S --router ENDPOINT --out DIR [--viewer] [--rerun-url URL]``
subscribes (as zenoh user ``recorder``) to the truth, every AUV's telemetry and
bearing, the channel's packet events and counters, and the world events, and
feeds them to :class:`recorder.core.RerunRecorder`, which writes
``DIR/recording.rrd``. Messages are decoded on the main thread in arrival order;
a message that does not decode is counted and reported, never fatal. The
recording is flushed to disk every ``--flush-s`` seconds of wall time, so a kill -9
loses at most that much. The process prints ``recorder ready`` once subscribed,
and exits on SIGTERM/SIGINT or shortly after the world's "end" event.
"""

from __future__ import annotations

import argparse
import queue
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from auv_swarm.bus.identity import OBSERVER_AHEAD_TICKS, Gate
from auv_swarm.bus.lifeline import Lifeline, parent_from_env
from auv_swarm.bus.shell import add_common_args, connect, handle_info_flags, scenario_from_args
from auv_swarm.contract import wire
from auv_swarm.contract.usage import fail, plain_description

if TYPE_CHECKING:
    from auv_swarm.bus.zbus import ZenohBus
    from auv_swarm.recorder.core import RerunRecorder

DRAIN_S = 1.0
"""After the world's "end" event, keep logging until the bus has been quiet this long (wall s)."""
DRAIN_MAX_S = 5.0


def subscriptions(prefix: str = wire.PREFIX) -> list[str]:
    """The key expressions the recorder listens to."""
    return [
        wire.truth(prefix),
        wire.all_telemetry(prefix),
        wire.all_sensors(prefix),
        wire.channel_events(prefix),
        wire.channel_stats(prefix),
        wire.world_events(prefix),
    ]


def interface_text() -> str:
    """What the recorder subscribes to and what it writes (for ``--interface``)."""
    lines = [
        "recorder publishes: nothing (writes DIR/recording.rrd, streams to a rerun viewer)",
        "recorder subscribes:",
    ]
    lines += [f"  {key}" for key in subscriptions()]
    lines.append(f"recorder liveliness token: {wire.liveliness_component('recorder')}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``auv-swarm recorder``: record a mission until the world ends it or a signal stops the process."""
    parser = argparse.ArgumentParser(prog="auv-swarm recorder", description=plain_description(__doc__))
    add_common_args(parser)
    parser.add_argument("--out", type=Path, default=None, help="results folder; the recording is OUT/recording.rrd")
    parser.add_argument("--viewer", action="store_true", help="also spawn a local rerun viewer and stream to it")
    parser.add_argument("--rerun-url", default=None, help="also stream to the viewer at rerun+http://HOST:PORT/proxy")
    parser.add_argument(
        "--web-viewer",
        default=None,
        metavar="HOST:PORT",
        help="also stream to the web viewer's gRPC proxy at HOST:PORT when HOST resolves (compose's viewer profile)",
    )
    parser.add_argument("--flush-s", type=float, default=1.0, help="wall seconds between flushes of the .rrd file")
    args = parser.parse_args(argv)
    if args.interface:
        print(interface_text())
        return 0
    if handle_info_flags(args, "recorder", sections=("run", "agents", "channel", "planner")):
        return 0
    if args.out is None:
        return fail("--out DIR is required (the recording is written to DIR/recording.rrd)")
    if not args.flush_s > 0:
        return fail(f"--flush-s must be > 0 s, got {args.flush_s}")
    scenario = scenario_from_args(args)

    from auv_swarm.bus.zbus import shutdown_event
    from auv_swarm.recorder.core import RerunRecorder
    from auv_swarm.recorder.options import RecorderOptions

    stop = shutdown_event()
    url = args.rerun_url
    if args.web_viewer is not None and url is None:
        url = web_viewer_url(args.web_viewer, stop)
    try:
        options = RecorderOptions(spawn_viewer=args.viewer, url=url)
        recorder = RerunRecorder(scenario, args.out / "recording.rrd", options)
    except ValueError as exc:
        return fail(str(exc))
    with recorder:
        lifeline = Lifeline(scenario.run.grace_s, parent_from_env())
        with connect(args, "recorder") as bus:
            lifeline.attach(bus, stop, "recorder", follow_end=False)
            dropped = record(bus, recorder, stop, args.flush_s, on_end=lifeline.note_end)
    print(
        f"recorder stopped: {recorder.received} messages logged, {dropped} dropped (undecodable, forged or replayed), "
        f"{recorder.malformed} rejected; {recorder.rows_logged} rows in {recorder.chunks_sent['file']} chunks to "
        f"{recorder.rrd_path}, {recorder.chunks_sent['live']} chunks to the live viewer",
        flush=True,
    )
    return lifeline.shell_exit_code(stop)


def web_viewer_url(host_port: str, stop: threading.Event, wait_s: float = 30.0) -> str | None:
    """The proxy url of the web viewer at ``HOST:PORT`` once it listens; None when HOST does not resolve.

    Under compose the ``viewer`` service exists only with its profile: its name resolves
    only then, and the recorder waits up to ``wait_s`` for it to listen.
    """
    import socket

    host, _, port = host_port.rpartition(":")
    if not host or not port.isdigit():
        print(f"error: --web-viewer must be HOST:PORT, got {host_port!r}", file=sys.stderr)
        raise SystemExit(2)
    try:
        socket.getaddrinfo(host, int(port))
    except OSError:
        return None
    deadline = time.monotonic() + wait_s
    while not stop.is_set() and time.monotonic() < deadline:
        try:
            with socket.create_connection((host, int(port)), timeout=1.0):
                return f"rerun+http://{host}:{port}/proxy"
        except OSError:
            time.sleep(0.5)
    print(f"recorder: the web viewer at {host_port} did not answer within {wait_s:g} s", file=sys.stderr, flush=True)
    return None


def record(
    bus: ZenohBus,
    recorder: RerunRecorder,
    stop: threading.Event,
    flush_s: float,
    on_end: Callable[[], None] | None = None,
) -> int:
    """Subscribe, print ``recorder ready``, then feed ``recorder`` until ``stop`` or the drain after the world's end
    (``on_end`` is called when the end arrives).

    Samples are queued by the zenoh threads and decoded here, in arrival order, through the
    identity and replay check of ``bus.identity.Gate``. Returns how many samples it dropped.
    """
    inbound: queue.Queue[tuple[str, bytes]] = queue.Queue()
    for key in subscriptions():
        bus.subscribe(key, lambda k, data: inbound.put((k, data)))
    bus.declare_liveliness(wire.liveliness_component("recorder"))
    print(f"recorder ready: recording {recorder.scenario.name} to {recorder.rrd_path}", flush=True)
    gate = Gate("recorder")
    newest_truth = 0
    next_flush = time.monotonic() + flush_s
    ended_at: float | None = None
    last_message = time.monotonic()
    while not stop.is_set():
        now = time.monotonic()
        if ended_at is not None and (now - last_message > DRAIN_S or now - ended_at > DRAIN_MAX_S):
            break
        if now >= next_flush:
            recorder.flush()
            next_flush = now + flush_s
        try:
            key, data = inbound.get(timeout=0.1)
        except queue.Empty:
            continue
        last_message = time.monotonic()
        msg = gate.receive(key, data, max_tick=newest_truth + OBSERVER_AHEAD_TICKS)
        if msg is None:
            continue
        if isinstance(msg, wire.Truth):
            newest_truth = max(newest_truth, msg.tick)
        recorder.on_message(msg)
        if isinstance(msg, wire.WorldEvent) and msg.kind in ("end", "abort") and ended_at is None:
            ended_at = time.monotonic()
            if on_end is not None:
                on_end()
    return gate.dropped()


if __name__ == "__main__":
    sys.exit(main())
