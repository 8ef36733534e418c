"""Delivery over a real router: a burst towards a slow subscriber is delayed, never dropped.

zenoh drops a put whose outgoing queue is full unless its publisher blocks; ``ZenohBus``
publishers block, so a subscriber that falls behind (a process starved of CPU) still gets
every message, in order.
"""

from __future__ import annotations

import time

import pytest

from auv_core import wire

from .conftest import Inbox, publish_until

pytestmark = pytest.mark.integration

BURST = 2000
PAYLOAD_BYTES = 8192


def test_a_burst_to_a_slow_subscriber_arrives_whole_and_in_order(start_router, connect) -> None:
    router = start_router(agents=1)
    world = connect(router.endpoint, "world")
    recorder = connect(router.endpoint, "recorder")
    inbox = Inbox()
    slow = {"on": False}

    def on_truth(key: str, payload: bytes) -> None:
        if slow["on"]:
            time.sleep(0.002)
        inbox(key, payload)

    recorder.subscribe(wire.truth(), on_truth)
    assert publish_until(world, wire.truth(), b"route", lambda: b"route" in inbox.payloads()), "no route"
    slow["on"] = True
    pad = bytes(PAYLOAD_BYTES - 8)
    for k in range(BURST):
        world.publish(wire.truth(), k.to_bytes(8, "big") + pad)
    assert inbox.wait_for(lambda items: sum(1 for _, p in items if p != b"route") >= BURST, timeout=60.0), (
        f"only {sum(1 for p in inbox.payloads() if p != b'route')} of {BURST} messages arrived"
    )
    got = [int.from_bytes(p[:8], "big") for p in inbox.payloads() if p != b"route"]
    assert got == list(range(BURST))
