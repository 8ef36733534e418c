"""Fuzzing every decoder behind the consumers' counters: wire messages (``Gate.receive``) and the acoustic
payload (``AgentCore`` ingesting a delivered frame).

Nothing may crash, and every rejection must be a counted DecodeError: the number of inputs the
decoder rejects equals the counter the consumer keeps. The default run uses hypothesis; the
``slow`` run feeds at least 10^5 inputs per decoder (random bytes and mutations of valid ones).
"""

from __future__ import annotations

import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from auv_swarm.agent.core import AgentCore
from auv_swarm.bus.identity import Gate
from auv_swarm.contract import wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.contract.payload import decode_payload, encode_payload
from tests.unit.test_payload import payloads
from tests.unit.test_wire import _mutate_bytes, _mutate_raw, _raw, any_message

SLOW_INPUTS = 100_000
SCENARIO = load_scenario("paper-3.2-challenging")
N_HEADINGS = SCENARIO.planner.n_headings


class WireTarget:
    """wire.decode as the world hears it: through a Gate, on a key that fits the message."""

    def __init__(self) -> None:
        self.gate = Gate("fuzz", log=lambda _line: None)
        self.inputs = self.rejected = 0

    def feed(self, key: str, data: bytes) -> None:
        self.inputs += 1
        try:
            wire.decode(data)
        except wire.DecodeError:
            self.rejected += 1
        self.gate.receive(key, data)

    def check(self) -> None:
        assert self.gate.counts["decode_error"] == self.rejected


class PayloadTarget:
    """decode_payload as an AUV meets it: inside a ModemRx the channel delivered."""

    def __init__(self) -> None:
        self.core = AgentCore(2, SCENARIO)
        self.inputs = self.rejected = 0

    def feed(self, data: bytes) -> None:
        self.inputs += 1
        try:
            p = decode_payload(data, N_HEADINGS)
        except wire.DecodeError:
            self.rejected += 1
            p = None
        sender = p.sender if p is not None and p.sender in (0, 1) else 0
        rx = wire.ModemRx(
            t_s=1e6, source="channel", tick=1, auv=2, sender=sender, seq=1, payload=data,
            t_sent=0.0, t_arrival=0.0, snr_db=20.0,
        )  # fmt: skip
        self.core._ingest([rx], 1e6)

    def check(self) -> None:
        assert self.core.stats.payload_decode_errors == self.rejected


def _key_for(msg: wire.Message) -> str:
    return wire.nav(msg.auv) if isinstance(msg, wire.Nav) else wire.command(0)


def _wire_inputs(msg: wire.Message, rng: random.Random, n: int):
    blob, raw = wire.encode(msg), _raw(msg)
    for k in range(n):
        if k % 3 == 0:
            yield rng.randbytes(rng.choice([0, 1, 2, 5, 16, 64, 300]))
        else:
            yield _mutate_bytes(blob, rng) if k % 3 == 1 else _mutate_raw(raw, rng)


def _payload_inputs(blob: bytes, rng: random.Random, n: int):
    """Every fourth input random bytes of a telling length, the others ``blob`` mutated as the wire tests do
    (bit flips, truncation, insertion, deletion, appended garbage)."""
    for k in range(n):
        yield rng.randbytes(rng.choice([0, 1, 15, 16, 40, 155, 2000])) if k % 4 == 0 else _mutate_bytes(blob, rng)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=any_message, seed=st.integers(0, 2**32 - 1))
def test_wire_decoder_rejections_are_all_counted(msg: wire.Message, seed: int) -> None:
    target = WireTarget()
    for data in _wire_inputs(msg, random.Random(seed), 60):
        target.feed(_key_for(msg), data)
    target.check()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), seed=st.integers(0, 2**32 - 1))
def test_payload_decoder_rejections_are_all_counted(data: st.DataObject, seed: int) -> None:
    blob, _ = encode_payload(data.draw(payloads(N_HEADINGS)), 1 << 16, N_HEADINGS)
    target = PayloadTarget()
    for item in _payload_inputs(blob, random.Random(seed), 40):
        target.feed(item)
    target.check()


def _samples(strategy: st.SearchStrategy, n: int) -> list:
    found: list = []

    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(strategy)
    def collect(value: object) -> None:
        found.append(value)

    collect()
    return found


@pytest.mark.slow
def test_wire_decoder_survives_100k_inputs() -> None:
    samples = _samples(any_message, 100)
    per = -(-SLOW_INPUTS // len(samples))
    target, rng = WireTarget(), random.Random(1)
    for msg in samples:
        for data in _wire_inputs(msg, rng, per):
            target.feed(_key_for(msg), data)
    assert target.inputs >= SLOW_INPUTS
    target.check()
    print(f"wire: {target.inputs} inputs, {target.rejected} rejected and counted, 0 crashes")


@pytest.mark.slow
def test_payload_decoder_survives_100k_inputs() -> None:
    samples = _samples(payloads(N_HEADINGS), 100)
    per = -(-SLOW_INPUTS // len(samples))
    target, rng = PayloadTarget(), random.Random(2)
    for p in samples:
        blob, _ = encode_payload(p, 1 << 16, N_HEADINGS)
        for data in _payload_inputs(blob, rng, per):
            target.feed(data)
    assert target.inputs >= SLOW_INPUTS
    target.check()
    print(f"acoustic payload: {target.inputs} inputs, {target.rejected} rejected and counted, 0 crashes")


def test_a_plan_longer_than_the_horizon_cap_is_a_decode_error() -> None:
    """The 4-bit plan-length field holds up to 15, the decoder accepts up to MAX_PLAN_LENGTH (found by fuzzing)."""
    from auv_swarm.contract.payload import FIXED_HEADER_BITS, MAX_PLAN_LENGTH, AcousticPayload

    p = AcousticPayload(sender=1, t_s=1.0, x=0.0, y=0.0, theta=0.0, u_e=1.0, plan=(), round=0, bearings=())
    blob = bytearray(encode_payload(p, 1 << 16, N_HEADINGS)[0])
    target = PayloadTarget()
    for h in range(MAX_PLAN_LENGTH + 1, 16):
        forged = bytearray(blob)
        bit = FIXED_HEADER_BITS - 4 - 8  # the 4-bit plan-length field
        for i in range(4):
            byte, off = divmod(bit + i, 8)
            value = (h >> (3 - i)) & 1
            forged[byte] = (forged[byte] & ~(0x80 >> off)) | (value << (7 - off))
        target.feed(bytes(forged))
    assert target.rejected == 15 - MAX_PLAN_LENGTH
    target.check()
