"""Attacks on the router's key-level rules, by a client holding AUV 0's own, legitimate credentials.

Each test fails if the attack succeeds. Negative checks use causal flushes, not sleeps:
after the forbidden action the attacker (or the victim's publisher) does an allowed one
on the same link, and once the observer holds that one the router has already handled,
and dropped, the forbidden one.
"""

from __future__ import annotations

import pytest

from auv_swarm.bus import credentials, zbus
from auv_swarm.contract import wire
from auv_swarm.orchestrator.mission import procs
from tests.integration.conftest import Inbox, flush, liveliness_changes, publish_until, until

pytestmark = pytest.mark.integration


def test_auv_cannot_publish_on_another_auvs_or_a_components_keys(start_router, connect) -> None:
    router = start_router(agents=3)
    attacker = connect(router.endpoint, "auv0")
    world, channel, orchestrator, auv1 = (
        connect(router.endpoint, u) for u in ("world", "channel", "orchestrator", "auv1")
    )
    heard = Inbox()
    world.subscribe(wire.all_commands(), heard)
    world.subscribe(wire.channel_done(), heard)
    channel.subscribe(wire.all_modem_tx(), heard)
    orchestrator.subscribe(wire.all_telemetry(), heard)
    orchestrator.subscribe(wire.truth(), heard)
    auv1.subscribe(wire.modem_rx(1), heard)
    auv1.subscribe(wire.nav(1), heard)
    auv1.subscribe(wire.clock(), heard)
    forged = {
        wire.command(1): b"cmd-as-1",
        wire.modem_tx(1): b"tx-as-1",
        wire.telemetry(1): b"tm-as-1",
        wire.modem_rx(1): b"rx-to-1",
        wire.nav(1): b"nav-to-1",
        wire.clock(): b"clock",
        wire.truth(): b"truth",
        wire.channel_done(): b"done",
    }
    for key, payload in forged.items():
        attacker.publish(key, payload)
    for key in (wire.command(0), wire.modem_tx(0), wire.telemetry(0)):
        flush(attacker, heard, key, b"flush-" + key.encode())
    assert not set(forged.values()) & set(heard.payloads())


def test_only_the_orchestrator_can_confirm_a_fault_to_the_world(start_router, connect) -> None:
    """The world holds the clock at a fault's tick until ``orchestrator/faults`` confirms it: an AUV or the channel
    that put a confirmation would move the clock past a fault that never happened (the recorder puts nothing at
    all: tests/integration/test_acl.py)."""
    router = start_router(agents=1)
    world, orchestrator = connect(router.endpoint, "world"), connect(router.endpoint, "orchestrator")
    heard = Inbox()
    world.subscribe(wire.faults_injected(), heard)
    world.subscribe(wire.command(0), heard)
    world.subscribe(wire.channel_done(), heard)
    auv0, channel = connect(router.endpoint, "auv0"), connect(router.endpoint, "channel")
    for name, bus in (("auv0", auv0), ("channel", channel)):
        bus.publish(wire.faults_injected(), f"confirm-by-{name}".encode())
    flush(auv0, heard, wire.command(0), b"flush-auv0")
    flush(channel, heard, wire.channel_done(), b"flush-channel")
    assert publish_until(orchestrator, wire.faults_injected(), b"confirm", lambda: b"confirm" in heard.payloads())
    forged = {p for p in heard.payloads(wire.faults_injected()) if p != b"confirm"}
    assert forged == set(), forged


def test_auv_cannot_read_truth_or_another_auvs_inbox(start_router, connect) -> None:
    router = start_router(agents=3)
    attacker = connect(router.endpoint, "auv0")
    world, channel, orchestrator, auv1 = (
        connect(router.endpoint, u) for u in ("world", "channel", "orchestrator", "auv1")
    )
    spy, own, truth_in, inbox1 = Inbox(), Inbox(), Inbox(), Inbox()
    for key in (wire.truth(), wire.modem_rx(1), wire.nav(1), wire.sensor(1), wire.all_telemetry(), f"{wire.PREFIX}/**"):
        attacker.subscribe(key, spy)
    attacker.subscribe(wire.modem_rx(0), own)
    orchestrator.subscribe(wire.truth(), truth_in)
    auv1.subscribe(wire.modem_rx(1), inbox1)
    auv1.subscribe(wire.nav(1), inbox1)
    assert publish_until(world, wire.truth(), b"truth", lambda: b"truth" in truth_in.payloads())
    assert publish_until(channel, wire.modem_rx(1), b"rx1", lambda: b"rx1" in inbox1.payloads())
    assert publish_until(world, wire.nav(1), b"nav1", lambda: b"nav1" in inbox1.payloads())
    assert publish_until(auv1, wire.telemetry(1), b"tm1", lambda: True)
    assert publish_until(channel, wire.modem_rx(0), b"rx0", lambda: b"rx0" in own.payloads())
    leaked = [(k, p) for k, p in spy.items if wire.parse_auv_id(k) != 0]
    assert leaked == [], leaked


def test_auv_cannot_hold_a_liveliness_token_for_another_id(start_router, connect) -> None:
    router = start_router(agents=3)
    attacker = connect(router.endpoint, "auv0")
    changes = liveliness_changes(connect(router.endpoint, "world"))
    own = wire.liveliness_session(0, attacker.session_id)
    others = (wire.liveliness_session(1, attacker.session_id), wire.liveliness(1), wire.liveliness(0))
    for key in (*others, f"{own}/deeper", wire.liveliness_component("world")):
        attacker.declare_liveliness(key)
    attacker.declare_liveliness(own)
    assert changes.wait_for(lambda items: (own, True) in items, timeout=10.0)
    spoofed = [k for k, _ in changes.items if k != own]
    assert spoofed == [], "an AUV holds only tokens of its own id, one per session"


def _refused(proc, pattern: str) -> str:
    proc.wait(timeout=60.0)
    text = procs.read_log(proc)
    assert proc.returncode == 2, text
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == 1 and pattern in lines[0] and "Traceback" not in text, text
    return lines[0]


@pytest.mark.parametrize(
    ("argv", "user"),
    [
        (["channel"], "channel"),
        (["world"], "world"),
        (["agent", "--id", "0"], "auv0"),
    ],
)
def test_a_process_without_credentials_refuses_to_start(spawner, argv, user) -> None:
    proc = spawner(procs.python_argv("auv_swarm", *argv, "--router", "tcp/127.0.0.1:1"), f"bare-{user}")
    line = _refused(proc, f"no credentials for user {user}")
    assert "--password-file" in line and credentials.PASSWORD_FILE_ENV in line


def test_a_router_without_a_user_table_refuses_to_start(spawner) -> None:
    proc = spawner(procs.python_argv("auv_swarm", "router", "--agents", "2"), "bare-router")
    _refused(proc, "no user table")


def test_insecure_dev_warns_on_every_start(spawner) -> None:
    endpoint = f"tcp/127.0.0.1:{procs.free_port()}"
    router = spawner(procs.python_argv("auv_swarm", "router", "--listen", endpoint, "--insecure-dev"), "dev-router")
    procs.wait_for_line(router, "router listening", timeout=20.0)
    assert "warning: --insecure-dev" in procs.read_log(router)
    dev = credentials.password_for("auv0", credentials.DEV_SECRET)
    with zbus.ZenohBus(endpoint, "auv0", dev) as bus:
        assert bus.session.info.routers_zid()


def test_refused_login_says_authentication_failed_and_a_dead_router_says_unreachable(start_router, spawner) -> None:
    router = start_router(agents=2)
    with pytest.raises(ConnectionError, match="authentication failed"):
        zbus.ZenohBus(router.endpoint, "auv0", "not-the-password", connect_timeout_ms=1000)
    with pytest.raises(ConnectionError, match="router unreachable"):
        zbus.ZenohBus(f"tcp/127.0.0.1:{procs.free_port()}", "auv0", "whatever", connect_timeout_ms=500)
    proc = spawner(
        procs.python_argv("auv_swarm", "channel", "--router", router.endpoint),
        "wrong-channel",
        env={credentials.PASSWORD_FILE_ENV: "/dev/null"},
    )
    proc.wait(timeout=60.0)
    assert proc.returncode == 2 and "must be one non-empty line" in procs.read_log(proc)


def test_another_auvs_password_file_does_not_log_in_as_this_auv(start_router, spawner, tmp_path) -> None:
    router = start_router(agents=2)
    proc = spawner(
        procs.python_argv("auv_swarm", "channel", "--router", router.endpoint),
        "channel-with-auv0-password",
        env={credentials.PASSWORD_FILE_ENV: str(tmp_path / "creds" / "auv0.password")},
    )
    proc.wait(timeout=60.0)
    text = procs.read_log(proc)
    assert proc.returncode == 1 and "authentication failed" in text and "Traceback" not in text, text
    assert until(lambda: router.proc.poll() is None)
