"""The in-memory bus (key expressions, delivery order, isolation) and the pure parts of the zenoh bus."""

from __future__ import annotations

import json
import os
import stat

import pytest
from hypothesis import given
from hypothesis import strategies as st

from auv_swarm.bus import zbus
from auv_swarm.bus.bus import InMemoryBus, check_key, check_key_expr, key_matches
from auv_swarm.contract import wire


@pytest.mark.parametrize(
    ("expr", "key", "expected"),
    [
        ("a/b", "a/b", True),
        ("a/b", "a/c", False),
        ("a/*", "a/b", True),
        ("a/*", "a/b/c", False),
        ("a/*", "a", False),
        ("a/**", "a", True),
        ("a/**", "a/b/c", True),
        ("**", "x", True),
        ("**/c", "a/b/c", True),
        ("**/c", "c", True),
        ("a/**/c", "a/c", True),
        ("a/**/c", "a/b/d/c", True),
        ("a/**/c", "a/b/d", False),
        ("a/*/c/**", "a/b/c", True),
        ("a/*/*", "a/b", False),
        ("auvswarm/auv/*/modem/tx", "auvswarm/auv/3/modem/tx", True),
        ("auvswarm/auv/*/modem/tx", "auvswarm/auv/3/modem/rx", False),
        ("auvswarm/alive/**", "auvswarm/alive/auv/12", True),
    ],
)
def test_key_matches(expr: str, key: str, expected: bool) -> None:
    assert key_matches(expr, key) is expected


@pytest.mark.parametrize("bad", ["", "/a", "a/", "a//b", "a/b*", "a/***"])
def test_invalid_key_expressions_raise(bad: str) -> None:
    with pytest.raises(ValueError, match="key_expr"):
        check_key_expr(bad)


def test_wildcards_are_not_keys() -> None:
    with pytest.raises(ValueError, match="key may contain no wildcards"):
        check_key("a/*")
    with pytest.raises(ValueError):
        InMemoryBus().publish("a/**", b"")


def _reference(pattern: list[str], key: list[str]) -> bool:
    """Recursive reference matcher (a different algorithm from key_matches' dynamic programme)."""
    if not pattern:
        return not key
    if pattern[0] == "**":
        return _reference(pattern[1:], key) or (bool(key) and _reference(pattern, key[1:]))
    return bool(key) and pattern[0] in ("*", key[0]) and _reference(pattern[1:], key[1:])


@given(
    pattern=st.lists(st.sampled_from(["a", "b", "*", "**"]), min_size=1, max_size=6),
    key=st.lists(st.sampled_from(["a", "b", "c"]), min_size=1, max_size=6),
)
def test_key_matches_agrees_with_a_reference(pattern: list[str], key: list[str]) -> None:
    assert key_matches("/".join(pattern), "/".join(key)) == _reference(pattern, key)


def test_delivery_in_subscription_order_and_only_to_matches() -> None:
    bus = InMemoryBus()
    seen: list[tuple[str, str, bytes]] = []
    bus.subscribe("x/**", lambda k, p: seen.append(("first", k, p)))
    bus.subscribe("x/*/rx", lambda k, p: seen.append(("second", k, p)))
    bus.subscribe("y/*", lambda k, p: seen.append(("other", k, p)))
    bus.subscribe("x/1/rx", lambda k, p: seen.append(("third", k, p)))
    bus.publish("x/1/rx", b"m")
    assert seen == [("first", "x/1/rx", b"m"), ("second", "x/1/rx", b"m"), ("third", "x/1/rx", b"m")]


def test_publications_from_callbacks_are_queued_fifo() -> None:
    bus = InMemoryBus()
    order: list[str] = []

    def relay(key: str, payload: bytes) -> None:
        order.append(f"relay:{payload.decode()}")
        if payload == b"1":
            bus.publish("b", b"2")
            bus.publish("b", b"3")

    bus.subscribe("a", relay)
    bus.subscribe("b", relay)
    bus.subscribe("a", lambda k, p: order.append(f"tail:{p.decode()}"))
    bus.publish("a", b"1")
    assert order == ["relay:1", "tail:1", "relay:2", "relay:3"]


def test_callback_exception_is_counted_and_isolated() -> None:
    bus = InMemoryBus()
    got: list[bytes] = []

    def boom(_key: str, _payload: bytes) -> None:
        raise RuntimeError("subscriber bug")

    bus.subscribe("k", boom)
    bus.subscribe("k", lambda _k, p: got.append(p))
    bus.publish("k", b"1")
    bus.publish("k", b"2")
    assert got == [b"1", b"2"]
    assert bus.callback_errors == 2


def test_undeclare_and_close() -> None:
    bus = InMemoryBus()
    got: list[bytes] = []
    handle = bus.subscribe("k", lambda _k, p: got.append(p))
    bus.publish("k", b"1")
    handle.undeclare()
    bus.publish("k", b"2")
    assert got == [b"1"]
    bus.close()
    with pytest.raises(RuntimeError, match="closed"):
        bus.publish("k", b"3")


def test_liveliness_tokens_and_history() -> None:
    bus = InMemoryBus()
    early: list[tuple[str, bool]] = []
    bus.subscribe_liveliness("alive/**", lambda k, a: early.append((k, a)))
    token = bus.declare_liveliness("alive/auv/1")
    bus.declare_liveliness("alive/world")
    late: list[tuple[str, bool]] = []
    bus.subscribe_liveliness("alive/auv/*", lambda k, a: late.append((k, a)), history=True)
    token.undeclare()
    assert early == [("alive/auv/1", True), ("alive/world", True), ("alive/auv/1", False)]
    assert late == [("alive/auv/1", True), ("alive/auv/1", False)]
    bus.close()
    assert early[-1] == ("alive/world", False)


def test_password_is_hmac_of_the_secret() -> None:
    a = zbus.password_for("auv0", "s1")
    assert len(a) == 32 and int(a, 16) >= 0
    assert a == zbus.password_for("auv0", "s1")
    assert a != zbus.password_for("auv1", "s1")
    assert a != zbus.password_for("auv0", "s2")
    with pytest.raises(ValueError, match="secret"):
        zbus.password_for("auv0", "")


def test_users_and_agent_range() -> None:
    assert zbus.users(2) == ("world", "channel", "recorder", "orchestrator", "central", "auv0", "auv1")
    with pytest.raises(ValueError, match=r"agents must be an integer in \[1, 16\]"):
        zbus.users(17)
    with pytest.raises(ValueError, match=r"auv must be an integer in \[0, 15\]"):
        zbus.agent_user(16)


def _allowed(roles: list[zbus.Role], user: str, action: str, key: str) -> bool:
    role = next(r for r in roles if r.user == user)
    return any(key_matches(expr, key) for expr in getattr(role, action))


def test_acl_table_gives_each_auv_only_its_own_keys() -> None:
    roles = zbus.acl_roles(agents=3)
    for n in range(3):
        user = f"auv{n}"
        for m in range(3):
            own = m == n
            assert _allowed(roles, user, "publish", wire.modem_tx(m)) is own
            assert _allowed(roles, user, "subscribe", wire.modem_rx(m)) is own
            assert _allowed(roles, user, "subscribe", wire.nav(m)) is own
            assert not _allowed(roles, user, "subscribe", wire.modem_tx(m))
            assert not _allowed(roles, user, "publish", wire.modem_rx(m))
        assert _allowed(roles, user, "subscribe", wire.clock())
        assert not _allowed(roles, user, "publish", wire.clock())
    assert _allowed(roles, "channel", "publish", wire.modem_rx(2))
    assert _allowed(roles, "channel", "subscribe", wire.modem_tx(2))
    assert not _allowed(roles, "channel", "publish", wire.modem_tx(2))
    assert not next(r for r in roles if r.user == "recorder").publish
    orchestrator = next(r for r in roles if r.user == "orchestrator")
    assert orchestrator.publish == (wire.faults_injected(),), "the orchestrator puts only its fault confirmations"
    readers = [r.user for r in roles if _allowed(roles, r.user, "subscribe", wire.faults_injected())]
    assert readers == ["world", "recorder"], "the world, and the recorder, which may read everything"
    assert [r.user for r in roles if _allowed(roles, r.user, "publish", wire.faults_injected())] == ["orchestrator"]


def test_acl_table_lets_the_central_planner_read_nav_and_bearings_and_send_each_auv_its_plan() -> None:
    roles = zbus.acl_roles(agents=3)
    for m in range(3):
        assert _allowed(roles, "central", "subscribe", wire.nav(m))
        assert _allowed(roles, "central", "subscribe", wire.sensor(m))
        assert _allowed(roles, "central", "publish", wire.central_plan(m))
        assert not _allowed(roles, "central", "publish", wire.command(m))
        assert not _allowed(roles, "central", "subscribe", wire.modem_rx(m))
        for n in range(3):
            assert _allowed(roles, f"auv{n}", "subscribe", wire.central_plan(m)) is (m == n)
            assert not _allowed(roles, f"auv{n}", "publish", wire.central_plan(m))
    assert _allowed(roles, "central", "subscribe", wire.clock())


def test_access_control_section_is_default_deny_with_one_policy_per_user() -> None:
    section = zbus.access_control(zbus.acl_roles(agents=2))
    assert section["enabled"] is True and section["default_permission"] == "deny"
    assert [s["usernames"] for s in section["subjects"]] == [[u] for u in zbus.users(2)]
    rule_ids = {r["id"] for r in section["rules"]}
    for policy in section["policies"]:
        assert set(policy["rules"]) <= rule_ids
    assert all(r["permission"] == "allow" for r in section["rules"])


def test_router_config_writes_a_private_dictionary_file(tmp_path) -> None:
    creds = zbus.credentials("s", agents=2)
    conf = zbus.router_config("tcp/127.0.0.1:7447", creds, dictionary_file=tmp_path / "users.txt", agents=2)
    path = json.loads(conf.get_json("transport/auth/usrpwd/dictionary_file"))
    text = open(path, encoding="utf-8").read()
    assert text.splitlines() == [f"{u}:{p}" for u, p in creds.items()]
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert json.loads(conf.get_json("mode")) == "router"
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("access_control"))["default_permission"] == "deny"
    with pytest.raises(ValueError, match="acl=True needs credentials"):
        zbus.router_config("tcp/127.0.0.1:7447", {}, acl=True)
    with pytest.raises(ValueError, match="endpoint must look like"):
        zbus.router_config("127.0.0.1:7447", creds)


def test_client_config() -> None:
    conf = zbus.client_config("tcp/127.0.0.1:7447", "auv0", "pw", connect_timeout_ms=500)
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("transport/auth/usrpwd/user")) == "auv0"
    with pytest.raises(ValueError, match="user and password must be given together"):
        zbus.client_config("tcp/127.0.0.1:7447", "auv0")
    with pytest.raises(ValueError, match="connect_timeout_ms"):
        zbus.client_config("tcp/127.0.0.1:7447", connect_timeout_ms=0)


def test_orchestrator_reads_what_the_metrics_and_raw_data_need() -> None:
    roles = zbus.acl_roles(agents=2)
    for key in (wire.truth(), wire.telemetry(1), wire.channel_events(), wire.channel_stats(), wire.world_events()):
        assert _allowed(roles, "orchestrator", "subscribe", key)
    for key in (wire.sensor(1), wire.modem_rx(0)):  # the bearings taken and delivered (bearings.parquet)
        assert _allowed(roles, "orchestrator", "subscribe", key)
    for key in (wire.modem_tx(0), wire.command(0), wire.nav(0), wire.clock()):
        assert not _allowed(roles, "orchestrator", "subscribe", key)
