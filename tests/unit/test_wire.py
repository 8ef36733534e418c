"""The wire contract: round trips, hostile input, schema checks and key expressions."""

from __future__ import annotations

import dataclasses
import math
import random

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from auv_swarm.contract import wire
from auv_swarm.contract.params import MAX_HORIZON
from auv_swarm.contract.wire import (
    MESSAGE_TYPES,
    CentralPlan,
    ChannelDone,
    ChannelStats,
    ChannelTick,
    Clock,
    Command,
    DecodeError,
    FaultsInjected,
    ModemRx,
    ModemTx,
    Nav,
    PacketEvent,
    Sensor,
    Telemetry,
    Truth,
    WorldEvent,
    decode,
    encode,
)

ids = st.integers(0, 255)
ticks = st.integers(0, 2**63 - 1)
counts = st.integers(0, 2**63 - 1)
times = st.floats(0.0, 1e9, allow_nan=False, allow_infinity=False)
reals = st.floats(allow_nan=False, allow_infinity=False)
nonneg = st.floats(0.0, 1e12, allow_nan=False, allow_infinity=False)
alive = st.lists(ids, unique=True, max_size=20).map(tuple)
common = {"t_s": times, "source": st.text(max_size=64)}
estimate_and_plan = {  # the fields of Telemetry and of CentralPlan (the same, in another order)
    "tick": ticks,
    "auv": ids,
    "estimate_ok": st.booleans(),
    "estimate_reason": st.text(max_size=256),
    "xi": st.tuples(reals, reals, reals, reals),
    "P": st.lists(reals, min_size=16, max_size=16).map(tuple),
    "plan": st.lists(st.tuples(reals, reals), max_size=MAX_HORIZON).map(tuple),
    "waypoints": st.lists(st.tuples(reals, reals), max_size=MAX_HORIZON).map(tuple),
    "cost": reals,
    "terms": st.dictionaries(st.text(max_size=64), reals, max_size=32),
    "plan_wall_ms": nonneg,
    "n_measurements": counts,
    "planned": st.booleans(),
    "fiedler": reals,
}

STRATEGIES = {
    Clock: st.builds(Clock, tick=ticks, alive=alive, **common),
    Nav: st.builds(
        Nav, tick=ticks, auv=ids, x=reals, y=reals, theta=reals, u=reals, r=reals, rx_expected=counts, **common
    ),
    Sensor: st.builds(Sensor, tick=ticks, auv=ids, bearing_rad=st.none() | reals, **common),
    Command: st.builds(Command, tick=ticks, auv=ids, u=reals, r=reals, tx_count=counts, **common),
    ModemTx: st.builds(ModemTx, tick=ticks, auv=ids, seq=counts, payload=st.binary(max_size=300), **common),
    ModemRx: st.builds(
        ModemRx,
        tick=ticks,
        auv=ids,
        sender=ids,
        seq=counts,
        payload=st.binary(max_size=300),
        t_sent=times,
        t_arrival=times,
        snr_db=reals,
        **common,
    ),
    ChannelTick: st.builds(
        ChannelTick,
        tick=ticks,
        tx_expected=st.dictionaries(ids, counts, max_size=8),
        positions=st.dictionaries(ids, st.tuples(reals, reals), max_size=8),
        alive=alive,
        **common,
    ),
    ChannelDone: st.builds(ChannelDone, tick=ticks, rx_count=st.dictionaries(ids, counts, max_size=8), **common),
    Truth: st.builds(
        Truth,
        tick=ticks,
        target=st.tuples(reals, reals, reals, reals),
        agents=st.dictionaries(ids, st.tuples(reals, reals, reals), max_size=8),
        alive=alive,
        **common,
    ),
    Telemetry: st.builds(Telemetry, **estimate_and_plan, nav=st.tuples(reals, reals, reals), **common),
    CentralPlan: st.builds(CentralPlan, **estimate_and_plan, **common),
    ChannelStats: st.builds(
        ChannelStats, counters=st.dictionaries(st.text(max_size=64), counts, max_size=20), **common
    ),
    PacketEvent: st.builds(
        PacketEvent,
        correlation_id=st.text(max_size=128),
        kind=st.sampled_from(["sent", "delivered", "dropped"]),
        sender=ids,
        recipient=st.integers(-1, 255),
        bits=counts,
        latency_s=st.none() | nonneg,
        snr_db=st.none() | reals,
        reason=st.none() | st.text(max_size=256),
        **common,
    ),
    WorldEvent: st.builds(
        WorldEvent,
        kind=st.sampled_from(["start", "end", "kill", "rejoin", "death"]),
        auv=st.integers(-1, 255),
        text=st.text(max_size=1024),
        **common,
    ),
    FaultsInjected: st.builds(
        FaultsInjected, tick=ticks, faults=st.lists(st.text(max_size=128), max_size=64).map(tuple), **common
    ),
}
any_message = st.one_of(*STRATEGIES.values())


def _nav(**changes: object) -> Nav:
    base = Nav(tick=3, auv=1, x=10.0, y=-5.0, theta=0.5, u=1.5, r=0.01, rx_expected=2, t_s=6.0, source="world")
    return dataclasses.replace(base, **changes)


def _raw(msg: wire.Message) -> list:
    return msgpack.unpackb(encode(msg), raw=False, strict_map_key=False)


def _pack(raw: list) -> bytes:
    return msgpack.packb(raw, use_bin_type=True)


def test_every_message_type_has_a_strategy() -> None:
    assert set(STRATEGIES) == set(MESSAGE_TYPES)


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_round_trip_every_message_type(cls: type, data: st.DataObject) -> None:
    msg = data.draw(STRATEGIES[cls])
    blob = encode(msg)
    assert decode(blob) == msg
    assert decode(blob, expected=cls) == msg
    assert decode(blob).version == wire.SCHEMA_VERSION


def _random_bytes(rng: random.Random) -> bytes:
    n = rng.choice([0, 1, 2, 3, 5, 8, 16, 40, 120, 600])
    return rng.randbytes(rng.randint(0, n))


def _assert_only_decode_error(blob: bytes, expected: type | None) -> None:
    try:
        msg = decode(blob, expected)
    except DecodeError:
        return
    assert isinstance(msg, wire.Message)
    assert expected is None or type(msg) is expected
    assert decode(encode(msg)) == msg


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1))
def test_10000_random_byte_strings_raise_only_decode_error(seed: int) -> None:
    """100 examples x 100 random byte strings = 10,000 inputs, each to decode() with and without expected."""
    rng = random.Random(seed)
    for _ in range(100):
        blob = _random_bytes(rng)
        _assert_only_decode_error(blob, None)
        _assert_only_decode_error(blob, rng.choice(MESSAGE_TYPES))


JUNK = [
    None,
    True,
    False,
    0,
    -1,
    256,
    2**64 - 1,
    -(2**63),
    1.5,
    math.nan,
    math.inf,
    -math.inf,
    1e308,
    "",
    "x" * 300,
    b"",
    b"\x00" * 10,
    [],
    [1, 2],
    {},
    {1: 2},
    {"a": [1]},
    [[1, 2, 3]],
    [None] * 16,
]


def _mutate_raw(raw: list, rng: random.Random) -> bytes:
    """A structural mutation of a decoded message array: field swap, type change, drop or add a field."""
    raw = list(raw)
    op = rng.randrange(6)
    i = rng.randrange(2, len(raw)) if rng.random() < 0.8 else rng.randrange(len(raw))
    if op == 0:
        j = rng.randrange(len(raw))
        raw[i], raw[j] = raw[j], raw[i]
    elif op == 1:
        raw[i] = rng.choice(JUNK)
    elif op == 2:
        del raw[i]
    elif op == 3:
        raw.insert(i, rng.choice(JUNK))
    elif op == 4 and isinstance(raw[i], list) and raw[i]:
        inner = list(raw[i])
        inner[rng.randrange(len(inner))] = rng.choice(JUNK)
        raw[i] = inner
    elif op == 4 and isinstance(raw[i], dict) and raw[i]:
        inner = dict(raw[i])
        key = rng.choice(list(inner))
        inner[key if rng.random() < 0.5 else rng.choice([-1, 300, "k", 1.5])] = rng.choice(JUNK)
        raw[i] = inner
    else:
        raw[rng.choice([0, 1])] = rng.choice([0, 2, 99, -1, True, "1", 1.0])
    return _pack(raw)


def _mutate_bytes(blob: bytes, rng: random.Random) -> bytes:
    """A byte-level mutation: bit flips, truncation, insertion, deletion or appended garbage."""
    data = bytearray(blob)
    op = rng.randrange(5)
    if op == 0 and data:
        for _ in range(rng.randint(1, 3)):
            k = rng.randrange(len(data))
            data[k] ^= 1 << rng.randrange(8)
    elif op == 1:
        del data[rng.randrange(len(data) + 1) :]
    elif op == 2:
        k = rng.randrange(len(data) + 1)
        data[k:k] = rng.randbytes(rng.randint(1, 4))
    elif op == 3 and data:
        k = rng.randrange(len(data))
        del data[k : k + rng.randint(1, 4)]
    else:
        data += rng.randbytes(rng.randint(1, 8))
    return bytes(data)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=any_message, seed=st.integers(0, 2**32 - 1))
def test_10000_mutated_messages_raise_only_decode_error(msg: wire.Message, seed: int) -> None:
    """200 examples x 50 mutations (bit flips, truncation, field swaps, type changes) = 10,000 inputs."""
    rng = random.Random(seed)
    blob = encode(msg)
    raw = _raw(msg)
    for k in range(50):
        mutated = _mutate_bytes(blob, rng) if k % 2 else _mutate_raw(raw, rng)
        _assert_only_decode_error(mutated, None)
        _assert_only_decode_error(mutated, rng.choice([type(msg), *MESSAGE_TYPES]))


def test_hostile_sizes_raise_decode_error() -> None:
    for blob in (
        b"\x91" * 100_000,
        b"\xdd\xff\xff\xff\xff",
        b"\xdb\xff\xff\xff\xff",
        b"\xc6\xff\xff\xff\xff",
        b"\x81\x90\x01",
        b"\xd6\xff\x00\x00\x00\x00",
        b"\x00" * (wire.MAX_MESSAGE_BYTES + 1),
    ):
        with pytest.raises(DecodeError):
            decode(blob)
    for not_bytes in ("text", None, 12, [1, 2]):
        with pytest.raises(DecodeError, match="bytes"):
            decode(not_bytes)  # type: ignore[arg-type]


def test_expected_type_mismatch_names_both_types() -> None:
    blob = encode(_nav())
    assert decode(blob, expected=Nav) == _nav()
    with pytest.raises(DecodeError, match="expected Clock, got Nav"):
        decode(blob, expected=Clock)
    with pytest.raises(DecodeError, match="expected must be a message type"):
        decode(blob, expected=int)  # type: ignore[arg-type]
    with pytest.raises(DecodeError, match="expected must be a message type"):
        decode(blob, expected=[Nav])  # type: ignore[arg-type]


def test_wrong_version_is_rejected_both_ways() -> None:
    raw = _raw(_nav())
    for version in (0, 2, True, "1", 1.0):
        raw[1] = version
        with pytest.raises(DecodeError, match="Nav.version"):
            decode(_pack(raw))
    with pytest.raises(ValueError, match="Nav.version must be 1"):
        encode(_nav(version=2))


def test_unknown_tag_and_wrong_field_count() -> None:
    raw = _raw(_nav())
    with pytest.raises(DecodeError, match="unknown message tag"):
        decode(_pack([999, *raw[1:]]))
    with pytest.raises(DecodeError, match="unknown message tag"):
        decode(_pack([True, *raw[1:]]))
    with pytest.raises(DecodeError, match="Nav must have 10 fields, got 9"):
        decode(_pack(raw[:-1]))
    with pytest.raises(DecodeError, match="array"):
        decode(_pack({"tag": 2}))


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("auv", 256, "Nav.auv must be an integer in \\[0, 255\\]"),
        ("auv", True, "Nav.auv must be an integer"),
        ("tick", -1, "Nav.tick"),
        ("rx_expected", -3, "Nav.rx_expected"),
        ("x", math.nan, "Nav.x must be a finite number"),
        ("y", math.inf, "Nav.y must be a finite number"),
        ("theta", "0.5", "Nav.theta"),
        ("t_s", -0.5, "Nav.t_s must be a finite number in \\[0.0, inf\\]"),
        ("source", "s" * 65, "Nav.source must be a string of at most 64"),
        ("source", b"world", "Nav.source"),
    ],
)
def test_field_violations_name_type_and_field(field: str, value: object, match: str) -> None:
    raw = _raw(_nav())
    names = ["t_s", "source", *(f.name for f in dataclasses.fields(Nav) if f.name not in ("t_s", "source", "version"))]
    raw[2 + names.index(field)] = value
    with pytest.raises(DecodeError, match=match):
        decode(_pack(raw))
    with pytest.raises(ValueError, match=match):
        encode(_nav(**{field: value}))


def test_nested_and_container_violations() -> None:
    tick = ChannelTick(tick=1, tx_expected={0: 1}, positions={0: (1.0, 2.0)}, alive=(0, 1), t_s=2.0, source="world")
    assert decode(encode(tick)) == tick
    bad = [
        ({"alive": (0, 0)}, "ChannelTick.alive must not repeat"),
        ({"tx_expected": {300: 1}}, "ChannelTick.tx_expected key"),
        ({"tx_expected": {"0": 1}}, "ChannelTick.tx_expected key"),
        ({"positions": {0: (1.0,)}}, "ChannelTick.positions\\[0\\] must be an array of exactly 2"),
        ({"positions": {0: (1.0, math.nan)}}, "ChannelTick.positions\\[0\\]\\[1\\]"),
    ]
    for change, match in bad:
        with pytest.raises(ValueError, match=match):
            encode(dataclasses.replace(tick, **change))
    with pytest.raises(ValueError, match="ModemTx.payload must be bytes of length at most 65536"):
        encode(ModemTx(tick=0, auv=0, seq=0, payload=b"\x00" * 65537, t_s=0.0, source="auv/0"))
    with pytest.raises(ValueError, match="PacketEvent.kind must be one of sent, delivered, dropped"):
        encode(PacketEvent("c", "lost", 0, 1, 8, None, None, None, t_s=0.0, source="channel"))
    with pytest.raises(ValueError, match="msg must be one of"):
        encode("not a message")  # type: ignore[arg-type]


def test_encode_accepts_numpy_values_and_canonicalises() -> None:
    msg = Telemetry(
        tick=np.int64(4),
        auv=2,
        estimate_ok=np.bool_(True),
        estimate_reason="ok",
        xi=np.array([1.0, 2.0, 0.5, -0.5]),
        P=np.eye(4).ravel(),
        plan=np.array([[0.1, 1.0], [0.0, 2.0]]),
        waypoints=[[1, 2]],
        cost=np.float64(1.25),
        terms={"geometry": 0.5},
        plan_wall_ms=3,
        n_measurements=12,
        planned=True,
        fiedler=0.2,
        nav=np.array([3.0, 4.0, 0.5]),
        t_s=8.0,
        source="auv/2",
    )
    out = decode(encode(msg), expected=Telemetry)
    assert out.tick == 4 and type(out.tick) is int
    assert out.xi == (1.0, 2.0, 0.5, -0.5)
    assert out.P == tuple(np.eye(4).ravel().tolist())
    assert out.plan == ((0.1, 1.0), (0.0, 2.0))
    assert out.waypoints == ((1.0, 2.0),) and type(out.waypoints[0][0]) is float
    assert out.plan_wall_ms == 3.0 and out.estimate_ok is True


def test_integer_keys_survive_and_bytes_stay_bytes() -> None:
    rx = ModemRx(5, 2, 0, 7, b"\x01\x02", 9.5, 10.8, 23.5, t_s=10.0, source="channel")
    assert decode(encode(rx)).payload == b"\x01\x02"
    done = decode(encode(ChannelDone(tick=5, rx_count={0: 1, 2: 3}, t_s=10.0, source="channel")))
    assert done.rx_count == {0: 1, 2: 3}
    assert all(type(k) is int for k in done.rx_count)


def test_key_functions_layout() -> None:
    assert wire.modem_tx(3) == "auvswarm/auv/3/modem/tx"
    assert wire.modem_rx(3) == "auvswarm/auv/3/modem/rx"
    assert wire.sensor(3) == "auvswarm/auv/3/sensor"
    assert wire.nav(3) == "auvswarm/auv/3/nav"
    assert wire.command(3) == "auvswarm/auv/3/cmd"
    assert wire.telemetry(3) == "auvswarm/auv/3/telemetry"
    assert wire.liveliness(3) == "auvswarm/alive/auv/3"
    assert wire.liveliness_component("world") == "auvswarm/alive/world"
    assert wire.clock() == "auvswarm/world/clock"
    assert wire.truth() == "auvswarm/world/truth"
    assert wire.world_events() == "auvswarm/world/events"
    assert wire.channel_tick() == "auvswarm/channel/tick"
    assert wire.channel_done() == "auvswarm/channel/done"
    assert wire.channel_stats() == "auvswarm/channel/stats"
    assert wire.channel_events() == "auvswarm/channel/events"
    assert wire.all_modem_tx() == "auvswarm/auv/*/modem/tx"
    assert wire.all_modem_rx() == "auvswarm/auv/*/modem/rx"
    assert wire.all_commands() == "auvswarm/auv/*/cmd"
    assert wire.all_telemetry() == "auvswarm/auv/*/telemetry"
    assert wire.all_sensors() == "auvswarm/auv/*/sensor"
    assert wire.all_sensors(prefix="lab") == "lab/auv/*/sensor"
    assert wire.all_liveliness() == "auvswarm/alive/**"
    assert wire.nav(np.int64(4)) == "auvswarm/auv/4/nav"
    assert wire.liveliness(np.uint8(4)) == "auvswarm/alive/auv/4"
    assert wire.nav(0, prefix="lab/run-7") == "lab/run-7/auv/0/nav"
    assert wire.clock(prefix="x") == "x/world/clock"


@pytest.mark.parametrize("bad", [-1, 256, True, 1.0, "3"])
def test_key_functions_reject_bad_ids(bad: object) -> None:
    for fn in (wire.modem_tx, wire.modem_rx, wire.sensor, wire.nav, wire.command, wire.telemetry, wire.liveliness):
        with pytest.raises(ValueError, match="auv must be an integer in \\[0, 255\\]"):
            fn(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", ["", "a/*", "a/**/b", "/a", "a/", "a b", "a$"])
def test_key_functions_reject_bad_prefixes_and_names(bad: str) -> None:
    with pytest.raises(ValueError, match="prefix"):
        wire.clock(prefix=bad)
    with pytest.raises(ValueError, match="name"):
        wire.liveliness_component(bad)


def test_parse_auv_id() -> None:
    for auv in (0, 7, 255):
        for fn in (wire.modem_tx, wire.modem_rx, wire.sensor, wire.nav, wire.command, wire.telemetry, wire.liveliness):
            assert wire.parse_auv_id(fn(auv)) == auv
            assert wire.parse_auv_id(fn(auv, prefix="auv/lab")) == auv
    for key in (
        "auvswarm/world/clock",
        "auvswarm/auv/03/nav",
        "auvswarm/auv/256/nav",
        "auvswarm/auv/-1/nav",
        "auvswarm/auv/*/cmd",
        "auvswarm/auv",
        "",
        "auvswarm/auv/1e2/nav",
        "auvswarm/alive/world",
    ):
        assert wire.parse_auv_id(key) is None


def test_key_table_covers_every_key_and_message() -> None:
    patterns = {row.key for row in wire.KEY_TABLE}
    concrete = [wire.modem_tx, wire.modem_rx, wire.sensor, wire.nav, wire.command, wire.telemetry]
    for fn in concrete:
        assert fn(9).replace("/9", "/{id}") in patterns
    assert wire.liveliness_session(9, "ab12").replace("/9/ab12", "/{id}/{session}") in patterns
    for fn in (
        wire.clock,
        wire.truth,
        wire.world_events,
        wire.channel_tick,
        wire.channel_done,
        wire.channel_stats,
        wire.channel_events,
        wire.faults_injected,
    ):
        assert fn() in patterns
    assert wire.liveliness_component("world").replace("/world", "/{component}") in patterns
    messages = {row.message for row in wire.KEY_TABLE}
    assert {cls.__name__ for cls in MESSAGE_TYPES} <= messages
    assert all(len(row) == 4 for row in wire.KEY_TABLE)
    assert wire.key_table("lab")[0].key.startswith("lab/")


def test_interface_rows_and_formatting() -> None:
    channel = wire.interface_rows("channel")
    assert {r.message for r in channel} >= {"ModemTx", "ModemRx", "ChannelTick", "ChannelDone", "PacketEvent"}
    assert "Telemetry" not in {r.message for r in channel}
    md = wire.format_key_table(markdown=True).splitlines()
    assert md[0] == "| key | publisher | subscribers | message |"
    assert len(md) == 2 + len(wire.KEY_TABLE)
    text = wire.format_key_table(channel)
    assert text.splitlines()[0].split() == ["key", "publisher", "subscribers", "message"]
    assert "auvswarm/auv/{id}/modem/tx" in text


def test_one_rule_for_a_session_id_in_tokens_and_attachments() -> None:
    """Tokens (keys) and attachments (bus/zbus.session_of) take a session id by one rule: a zenoh id in hex."""
    from auv_swarm.contract import keys

    zid = "0123456789abcdef0123456789ABCDEF"
    assert keys.is_session_id(zid) and keys.parse_liveliness(wire.liveliness_session(2, zid)) == (2, zid)
    for bad in ("", "a-b", "a.b", "a_b", "é", "a" * (keys.MAX_SESSION_ID_CHARS + 1), None, 7):
        assert not keys.is_session_id(bad)
        if isinstance(bad, str) and bad:
            assert keys.parse_liveliness(f"{wire.liveliness(2)}/{bad}") is None
            with pytest.raises(ValueError, match="session must be"):
                wire.liveliness_session(2, bad)
