"""Access control on a real router process: each user may only use its own keys.

Negative checks use causal flushes instead of sleeps: after the forbidden action,
the same client does an allowed action on the same link, and once that one is
seen the router has already processed (and dropped) the forbidden one.
"""

from __future__ import annotations

import pytest

from auv_core import wire, zbus

from .conftest import Inbox, publish_until, until

pytestmark = pytest.mark.integration


def _flush(sender: zbus.ZenohBus, observer_inbox: Inbox, key: str, tag: bytes) -> None:
    """Publish ``tag`` on an allowed ``key`` of ``sender`` and wait until the observer holds it."""
    assert publish_until(sender, key, tag, lambda: tag in observer_inbox.payloads(key)), f"flush {tag!r} never arrived"


def test_allowed_traffic_flows(start_router, connect) -> None:
    router = start_router(agents=2)
    world = connect(router.endpoint, "world")
    channel = connect(router.endpoint, "channel")
    auv0 = connect(router.endpoint, "auv0")
    world_in, channel_in, auv0_in = Inbox(), Inbox(), Inbox()
    world.subscribe(wire.all_commands(), world_in)
    channel.subscribe(wire.all_modem_tx(), channel_in)
    for key in (wire.nav(0), wire.sensor(0), wire.modem_rx(0), wire.clock()):
        auv0.subscribe(key, auv0_in)

    assert publish_until(auv0, wire.command(0), b"cmd", lambda: b"cmd" in world_in.payloads())
    assert publish_until(auv0, wire.modem_tx(0), b"tx", lambda: b"tx" in channel_in.payloads())
    assert publish_until(world, wire.nav(0), b"nav", lambda: b"nav" in auv0_in.payloads(wire.nav(0)))
    assert publish_until(world, wire.clock(), b"clk", lambda: b"clk" in auv0_in.payloads(wire.clock()))
    assert publish_until(channel, wire.modem_rx(0), b"rx", lambda: b"rx" in auv0_in.payloads(wire.modem_rx(0)))


def test_forged_rx_is_denied(start_router, connect) -> None:
    router = start_router(agents=2)
    channel = connect(router.endpoint, "channel")
    auv0 = connect(router.endpoint, "auv0")
    auv1 = connect(router.endpoint, "auv1")
    channel_in, auv1_in = Inbox(), Inbox()
    channel.subscribe(wire.all_modem_tx(), channel_in)
    auv1.subscribe(wire.modem_rx(1), auv1_in)
    assert publish_until(channel, wire.modem_rx(1), b"legit-0", lambda: b"legit-0" in auv1_in.payloads())

    auv0.publish(wire.modem_rx(1), b"forged")
    auv0.publish(wire.modem_tx(1), b"forged-tx")
    _flush(auv0, channel_in, wire.modem_tx(0), b"flush-0")
    channel.publish(wire.modem_rx(1), b"legit-1")
    assert auv1_in.wait_for(lambda items: (wire.modem_rx(1), b"legit-1") in items, timeout=10.0)

    assert b"forged" not in auv1_in.payloads()
    assert b"forged-tx" not in channel_in.payloads()


def test_auv_cannot_subscribe_to_other_auvs_keys(start_router, connect) -> None:
    router = start_router(agents=2)
    world = connect(router.endpoint, "world")
    channel = connect(router.endpoint, "channel")
    auv0 = connect(router.endpoint, "auv0")
    auv1 = connect(router.endpoint, "auv1")
    world_in, channel_in, spy, own = Inbox(), Inbox(), Inbox(), Inbox()
    world.subscribe(wire.all_commands(), world_in)
    channel.subscribe(wire.all_modem_tx(), channel_in)
    for key in (wire.modem_rx(1), wire.modem_tx(1), wire.nav(1), f"{wire.PREFIX}/**", f"{wire.PREFIX}/auv/*/modem/rx"):
        auv0.subscribe(key, spy)
    auv0.subscribe(wire.modem_rx(0), own)
    _flush(auv0, world_in, wire.command(0), b"declared")

    auv1.publish(wire.modem_tx(1), b"tx1")
    _flush(auv1, channel_in, wire.modem_tx(1), b"tx1-flush")
    channel.publish(wire.modem_rx(1), b"rx1")
    world.publish(wire.nav(1), b"nav1")
    assert publish_until(channel, wire.modem_rx(0), b"rx0", lambda: b"rx0" in own.payloads())

    assert spy.payloads() == []


def test_wrong_password_and_unknown_user_are_refused(start_router, connect, run_secret) -> None:
    router = start_router(agents=2)
    with pytest.raises(ConnectionError):
        connect(router.endpoint, "auv0", password="not-the-password")
    with pytest.raises(ConnectionError):
        connect(router.endpoint, "auv7", password=zbus.password_for("auv7", run_secret))
    with pytest.raises(ConnectionError):
        connect(router.endpoint, "auv1", password=zbus.password_for("auv1", "another-secret"))
    with pytest.raises(ConnectionError):
        zbus.ZenohBus(zbus.client_config(router.endpoint, connect_timeout_ms=1000))
    ok = connect(router.endpoint, "auv1")
    assert ok.session.info.routers_zid()


def test_liveliness_tokens_only_on_own_key(start_router, connect) -> None:
    router = start_router(agents=2)
    world = connect(router.endpoint, "world")
    auv0 = connect(router.endpoint, "auv0")
    changes = Inbox()
    world.subscribe_liveliness(wire.all_liveliness(), changes, history=True)
    auv0.declare_liveliness(wire.liveliness(1))
    token = auv0.declare_liveliness(wire.liveliness(0))
    assert changes.wait_for(lambda items: (wire.liveliness(0), True) in items, timeout=10.0)
    token.undeclare()
    assert changes.wait_for(lambda items: (wire.liveliness(0), False) in items, timeout=10.0)
    assert all(key != wire.liveliness(1) for key, _ in changes.items)

    late = Inbox()
    auv1 = connect(router.endpoint, "auv1")
    auv1.declare_liveliness(wire.liveliness(1))
    channel = connect(router.endpoint, "channel")
    channel.declare_liveliness(wire.liveliness_component("channel"))
    assert until(lambda: (wire.liveliness(1), True) in changes.items)
    world.subscribe_liveliness(wire.all_liveliness(), late, history=True)
    assert late.wait_for(
        lambda items: {(wire.liveliness(1), True), (wire.liveliness_component("channel"), True)} <= set(items)
    )
