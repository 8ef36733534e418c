"""Attacks on a router over mutual TLS (issue 45): a certificate is the login, and its name decides what its
holder may do.

A real router process listens on ``tls/127.0.0.1:PORT`` with the swarm's certificates (``auv-swarm credentials
--tls``); clients are :class:`ZenohBus` sessions with their own certificates. Negative checks use causal flushes
(tests/security/test_router_attacks.py): after the forbidden action the attacker does an allowed one on the same
link, and once the observer holds that one the router has already dropped the forbidden one.
"""

from __future__ import annotations

import datetime
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from auv_swarm.bus import credentials, tls, zbus
from auv_swarm.contract import wire
from auv_swarm.orchestrator.mission import procs
from tests.integration.conftest import Inbox, flush, liveliness_changes

pytestmark = pytest.mark.integration


@pytest.fixture
def tls_router(spawner, tmp_path: Path):
    """``(endpoint, folder, proc)``: a router over mutual TLS for 2 AUVs, its certificates in ``folder``."""
    folder = tmp_path / "tls"
    tls.write_zenoh(folder, credentials.users(2), router_hosts=("127.0.0.1",))
    endpoint = f"tls/127.0.0.1:{procs.free_port()}"
    argv = procs.python_argv("auv_swarm", "router", "--listen", endpoint, "--agents", "2", "--tls-dir", str(folder))
    proc = spawner(argv, "tls-router")
    procs.wait_for_line(proc, r"router listening on tls/.* \(mutual TLS, acl, 2 agents\)", timeout=20.0)
    return endpoint, folder, proc


@pytest.fixture
def tls_connect() -> Callable[..., zbus.ZenohBus]:
    """``tls_connect(endpoint, user, folder)``: a client with ``user``'s certificate from ``folder``; closed at
    teardown."""
    buses: list[zbus.ZenohBus] = []

    def open_bus(endpoint: str, user: str, folder: Path) -> zbus.ZenohBus:
        buses.append(zbus.ZenohBus(endpoint, user, tls_dir=folder, connect_timeout_ms=2000))
        return buses[-1]

    yield open_bus
    for bus in buses:
        bus.close()


def _refused(config) -> str:
    with pytest.raises(ConnectionError) as refusal:
        zbus.ZenohBus(config).close()
    return str(refusal.value)


def test_a_client_without_a_swarm_certificate_is_refused(tls_router, tls_connect, tmp_path) -> None:
    endpoint, folder, _ = tls_router
    bare = zbus.client_config(endpoint, "auv0", tls_dir=folder, connect_timeout_ms=1000)
    bare.insert_json5("transport/link/tls", json.dumps({"root_ca_certificate": str(folder / "ca.pem")}))
    assert "authentication failed" in _refused(bare)  # no certificate at all
    stranger = tmp_path / "stranger"  # a certificate named auv0, from a CA of its own
    tls.write_zenoh(stranger, ("auv0",))
    shutil.copy(folder / "ca.pem", stranger / "ca.pem")
    assert "authentication failed" in _refused(
        zbus.client_config(endpoint, "auv0", tls_dir=stranger, connect_timeout_ms=1000)
    )
    stale = tmp_path / "stale"  # the swarm's CA, but a certificate that expired yesterday
    stale.mkdir()
    for name in ("ca.pem", "ca.key"):
        shutil.copy(folder / name, stale / name)
    past = datetime.datetime.now(datetime.UTC) - datetime.timedelta(days=2)
    tls.write_zenoh(stale, ("auv0",), days=1, now=past)
    assert "authentication failed" in _refused(
        zbus.client_config(endpoint, "auv0", tls_dir=stale, connect_timeout_ms=1000)
    )
    password = credentials.password_for("auv0", "whatever")
    assert "authentication failed" in _refused(
        zbus.client_config(endpoint.replace("tls/", "tcp/"), "auv0", password, connect_timeout_ms=1000)
    )  # plain TCP with a password on the TLS port
    misnamed = zbus.client_config(
        endpoint.replace("127.0.0.1", "localhost"), "auv0", tls_dir=folder, connect_timeout_ms=1000
    )
    assert "does not name the host dialled" in _refused(misnamed)  # the client checks the router's name
    assert tls_connect(endpoint, "auv0", folder).session.info.routers_zid()  # the real certificate gets in


def test_auv0s_certificate_cannot_speak_as_auv1(tls_router, tls_connect) -> None:
    endpoint, folder, _ = tls_router
    attacker = tls_connect(endpoint, "auv0", folder)
    world, channel, auv1 = (tls_connect(endpoint, u, folder) for u in ("world", "channel", "auv1"))
    heard = Inbox()
    world.subscribe(wire.all_commands(), heard)
    channel.subscribe(wire.all_modem_tx(), heard)
    auv1.subscribe(wire.modem_rx(1), heard)
    auv1.subscribe(wire.clock(), heard)
    changes = liveliness_changes(world)
    forged = {
        wire.command(1): b"cmd-as-1",
        wire.modem_tx(1): b"tx-as-1",
        wire.modem_rx(1): b"rx-to-1",
        wire.clock(): b"clock",
    }
    for key, payload in forged.items():
        attacker.publish(key, payload)
    own_token, forged_token = wire.liveliness_session(0, "s0"), wire.liveliness_session(1, "s0")
    attacker.declare_liveliness(forged_token)
    attacker.declare_liveliness(own_token)
    for key in (wire.command(0), wire.modem_tx(0)):
        flush(attacker, heard, key, b"own-" + key.encode())  # its own keys: delivered
    assert changes.wait_for(lambda items: (own_token, True) in items, timeout=10.0)
    assert not set(forged.values()) & set(heard.payloads())
    assert [k for k, _ in changes.items if k != own_token] == []
    flush(auv1, heard, wire.command(1), b"the-real-auv1")  # AUV 1's own certificate may


def test_a_second_session_with_one_certificate_shows_in_the_routers_session_list(tls_router, tls_connect) -> None:
    endpoint, folder, proc = tls_router
    tls_connect(endpoint, "auv0", folder)
    tls_connect(endpoint, "auv1", folder)
    tls_connect(endpoint, "auv0", folder)  # a copy of AUV 0's key in use: zenoh accepts the second session
    line = procs.wait_for_line(proc, r"warning: certificate (\S+) holds (\d) sessions", timeout=15.0)
    assert line.groups() == ("auv0", "2")
    assert "certificate auv1" not in procs.read_log(proc)
