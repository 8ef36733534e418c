"""Delivery over a real router: a burst towards a slow subscriber is delayed, never dropped.

zenoh drops a put whose outgoing queue is full unless its publisher blocks; ``ZenohBus``
publishers block, so a subscriber that falls behind (a process starved of CPU) still gets
every message, in order.
"""

from __future__ import annotations

import threading
import time

import pytest

from auv_swarm.contract import wire

from .conftest import Inbox, publish_until

pytestmark = pytest.mark.integration

BURST = 2000
PAYLOAD_BYTES = 8192


def test_a_burst_to_a_slow_subscriber_arrives_whole_and_in_order(start_router, connect) -> None:
    router = start_router(agents=1)
    world = connect(router.endpoint, "world")
    recorder = connect(router.endpoint, "recorder")
    inbox = Inbox()
    slow = threading.Event()

    def on_truth(key: str, payload: bytes) -> None:
        if slow.is_set():
            time.sleep(0.002)
        inbox(key, payload)

    recorder.subscribe(wire.truth(), on_truth)
    assert publish_until(world, wire.truth(), b"route", lambda: b"route" in inbox.payloads()), "no route"
    slow.set()
    pad = bytes(PAYLOAD_BYTES - 8)
    for k in range(BURST):
        world.publish(wire.truth(), k.to_bytes(8, "big") + pad)

    def burst() -> list[bytes]:
        return [p for p in inbox.payloads() if p != b"route"]

    assert inbox.wait_for(lambda _items: len(burst()) >= BURST, timeout=60.0), f"only {len(burst())} of {BURST} arrived"
    assert [int.from_bytes(p[:8], "big") for p in burst()] == list(range(BURST))
