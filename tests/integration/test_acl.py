"""Access control on a real router process: each user may only use its own keys.

Negative checks use causal flushes instead of sleeps: after the forbidden action,
the same client does an allowed action on the same link, and once that one is
seen the router has already processed (and dropped) the forbidden one.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from auv_swarm.bus import zbus
from auv_swarm.contract import wire
from auv_swarm.orchestrator.mission import procs

from .conftest import Inbox, flush, liveliness_changes, publish_until, until

pytestmark = pytest.mark.integration


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
    flush(auv0, channel_in, wire.modem_tx(0), b"flush-0")
    channel.publish(wire.modem_rx(1), b"legit-1")
    assert auv1_in.wait_for(lambda items: (wire.modem_rx(1), b"legit-1") in items, timeout=10.0)

    assert b"forged" not in auv1_in.payloads()
    assert b"forged-tx" not in channel_in.payloads()


def test_auv_cannot_subscribe_to_other_auvs_keys(start_router, connect) -> None:
    """Wildcard or foreign subscriptions of auv0 see nothing but auv0's own traffic (its session matches locally)."""
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
    flush(auv0, world_in, wire.command(0), b"declared")

    auv1.publish(wire.modem_tx(1), b"tx1")
    flush(auv1, channel_in, wire.modem_tx(1), b"tx1-flush")
    channel.publish(wire.modem_rx(1), b"rx1")
    world.publish(wire.nav(1), b"nav1")
    assert publish_until(channel, wire.modem_rx(0), b"rx0", lambda: b"rx0" in own.payloads())

    leaked = [(key, payload) for key, payload in spy.items if wire.parse_auv_id(key) != 0]
    assert leaked == []
    assert not {b"tx1", b"tx1-flush", b"rx1", b"nav1"} & set(spy.payloads())


def test_wrong_password_and_unknown_user_are_refused(start_router, connect, run_secret) -> None:
    router = start_router(agents=2)
    refused = [
        ("auv0", "not-the-password"),
        ("auv7", zbus.password_for("auv7", run_secret)),
        ("auv1", zbus.password_for("auv1", "another-secret")),
    ]
    for user, password in refused:
        with pytest.raises(ConnectionError):
            connect(router.endpoint, user, password=password, timeout_ms=1000)
    with pytest.raises(ConnectionError):
        zbus.ZenohBus(zbus.client_config(router.endpoint, connect_timeout_ms=1000))
    ok = connect(router.endpoint, "auv1")
    assert ok.session.info.routers_zid()


def test_own_liveliness_tokens_come_go_and_reach_a_late_watcher(start_router, connect) -> None:
    # An AUV's token for another id is denied: attack 9, tests/security/test_router_attacks.py.
    router = start_router(agents=2)
    world = connect(router.endpoint, "world")
    changes = liveliness_changes(world)
    auv0 = connect(router.endpoint, "auv0")
    key0 = wire.liveliness_session(0, auv0.session_id)
    token = auv0.declare_liveliness(key0)
    assert changes.wait_for(lambda items: (key0, True) in items, timeout=10.0)
    token.undeclare()
    assert changes.wait_for(lambda items: (key0, False) in items, timeout=10.0)

    auv1 = connect(router.endpoint, "auv1")
    key1 = wire.liveliness_session(1, auv1.session_id)
    auv1.declare_liveliness(key1)
    channel = connect(router.endpoint, "channel")
    channel.declare_liveliness(wire.liveliness_component("channel"))
    assert until(lambda: (key1, True) in changes.items)
    late = liveliness_changes(world)
    assert late.wait_for(lambda items: {(key1, True), (wire.liveliness_component("channel"), True)} <= set(items))


def test_recorder_hears_everything_and_publishes_nothing(start_router, connect) -> None:
    router = start_router(agents=2)
    world = connect(router.endpoint, "world")
    auv0 = connect(router.endpoint, "auv0")
    recorder = connect(router.endpoint, "recorder")
    orchestrator = connect(router.endpoint, "orchestrator")
    heard, orch_in, auv0_in = Inbox(), Inbox(), Inbox()
    recorder.subscribe(f"{wire.PREFIX}/**", heard)
    orchestrator.subscribe(wire.truth(), orch_in)
    orchestrator.subscribe(wire.all_modem_tx(), orch_in)
    auv0.subscribe(wire.clock(), auv0_in)

    # each sample is published until every subscriber that must hear it has (a subscription reaches the
    # router some time after it is declared, so one sample can precede it): counts, not a time window
    assert publish_until(
        world, wire.clock(), b"clk", lambda: b"clk" in auv0_in.payloads() and b"clk" in heard.payloads()
    )
    assert publish_until(auv0, wire.modem_tx(0), b"tx0", lambda: b"tx0" in heard.payloads())
    assert publish_until(world, wire.truth(), b"truth", lambda: b"truth" in orch_in.payloads())

    alive = liveliness_changes(world)
    recorder.publish(wire.clock(), b"recorder-clock")
    orchestrator.publish(wire.clock(), b"orchestrator-clock")
    for name, bus in (("recorder", recorder), ("orchestrator", orchestrator)):
        bus.declare_liveliness(wire.liveliness_component(name))
        assert alive.wait_for(lambda items, n=name: (wire.liveliness_component(n), True) in items)
    assert publish_until(world, wire.clock(), b"clk-2", lambda: b"clk-2" in auv0_in.payloads())
    assert not {b"recorder-clock", b"orchestrator-clock"} & set(auv0_in.payloads())
    assert b"tx0" not in orch_in.payloads()


def test_open_router_deletes_the_password_dictionary(run_secret) -> None:
    endpoint = f"tcp/127.0.0.1:{procs.free_port()}"
    config = zbus.router_config(endpoint, zbus.credentials(run_secret, agents=1), agents=1)
    path = Path(json.loads(config.get_json("transport/auth/usrpwd/dictionary_file")))
    assert path.exists()
    with zbus.open_router(config):
        assert not path.exists()
        with zbus.ZenohBus.connect(endpoint, "auv0", run_secret) as bus:
            assert bus.session.info.routers_zid()


def test_router_cli_picks_a_free_port_and_stops_cleanly(spawner, run_secret) -> None:
    proc = spawner(procs.python_argv("auv_swarm", "router", "--agents", "1"), "router")
    endpoint = procs.wait_for_line(proc, r"router listening on (tcp/127\.0\.0\.1:\d+) \(acl, 1 agents\)").group(1)
    with zbus.ZenohBus.connect(endpoint, "auv0", run_secret) as bus:
        assert bus.session.info.routers_zid()
    assert procs.stop(proc) == 0
    assert "router stopped" in procs.read_log(proc)


def test_router_info_flags(capsys) -> None:
    from auv_swarm.orchestrator.mission import router

    assert router.main(["--example"]) == 0
    assert "auv-swarm router --listen" in capsys.readouterr().out
    assert router.main(["--interface", "--agents", "2"]) == 0
    out = capsys.readouterr().out
    assert "default deny" in out and wire.modem_tx(1) in out and "auv2" not in out
