"""The compact acoustic payload: quantisation bounds, budget, drop priority, hostile bytes."""

from __future__ import annotations

import dataclasses
import math
import random

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from auv_swarm.contract.payload import (
    MAX_PLAN_LENGTH,
    AcousticPayload,
    bearing_bits,
    decode_payload,
    encode_payload,
    header_bits,
    max_bearings,
    slot_budget_bits,
)
from auv_swarm.contract.wire import DecodeError

PAPER_BUDGET = 1240
BIG_BUDGET = 1 << 16
EPS = 1e-9


def _angle_error_deg(a: float, b: float) -> float:
    return abs(math.degrees(math.remainder(a - b, math.tau)))


def _payload(n_bearings: int = 0, **changes: object) -> AcousticPayload:
    bearings = tuple((200.0 - 2.0 * k, 1000.0 + 3.0 * k, -2000.0 - k, 0.1 * k) for k in range(n_bearings))
    base = AcousticPayload(
        sender=2,
        t_s=200.0,
        x=1000.3,
        y=-2000.2,
        theta=1.2,
        u_e=1.37,
        plan=((4, 1), (8, 2), (0, 0), (3, 1), (5, 2)),
        round=17,
        bearings=tuple(reversed(bearings)),
    )
    return dataclasses.replace(base, **changes)


@st.composite
def payloads(draw: st.DrawFn, n_headings: int, max_n: int = 40) -> AcousticPayload:
    t_s = draw(st.floats(0.0, 13_421_772.0))
    x = draw(st.floats(-65_535.0, 65_534.0))
    y = draw(st.floats(-65_535.0, 65_534.0))
    horizon = draw(st.integers(0, MAX_PLAN_LENGTH))
    plan = tuple(draw(st.tuples(st.integers(0, n_headings - 1), st.integers(0, 2))) for _ in range(horizon))
    bearings = []
    for _ in range(draw(st.integers(0, max_n))):
        age = draw(st.floats(0.0, min(102.0, t_s)))
        dx, dy = draw(st.floats(-255.0, 254.0)), draw(st.floats(-255.0, 254.0))
        bearings.append((max(0.0, t_s - age), x + dx, y + dy, draw(st.floats(-10.0, 10.0))))
    return AcousticPayload(
        sender=draw(st.integers(0, 255)),
        t_s=t_s,
        x=x,
        y=y,
        theta=draw(st.floats(-100.0, 100.0)),
        u_e=draw(st.floats(0.0, 10.23)),
        plan=plan,
        round=draw(st.integers(0, 255)),
        bearings=tuple(bearings),
    )


def test_paper_budget_arithmetic() -> None:
    assert slot_budget_bits(120.0, 14.0, 1.0, 4000.0, 1500.0) == PAPER_BUDGET
    assert slot_budget_bits(120.0, 6.0, 1.0, 4000.0, 1500.0) == 280
    assert slot_budget_bits(100.0, 10.0, 0.0, 0.0, 1500.0) == 1000
    assert bearing_bits() == 40
    assert header_bits(5, 9) == 150
    assert max_bearings(PAPER_BUDGET, 5, 9) == 27
    assert max_bearings(280, 4, 7) == 3


@pytest.mark.parametrize(
    ("n_headings", "per_step"), [(1, 3), (2, 4), (3, 5), (7, 6), (8, 6), (9, 7), (64, 9), (256, 11)]
)
def test_header_bits_per_plan_step(n_headings: int, per_step: int) -> None:
    assert header_bits(3, n_headings) - header_bits(0, n_headings) == 3 * per_step


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((0.0, 14.0, 1.0, 4000.0, 1500.0), "bit_rate_bps"),
        ((120.0, math.nan, 1.0, 4000.0, 1500.0), "slot_s"),
        ((120.0, 14.0, -1.0, 4000.0, 1500.0), "guard_s"),
        ((120.0, 14.0, 1.0, -1.0, 1500.0), "max_range_m"),
        ((120.0, 14.0, 1.0, 4000.0, 0.0), "sound_speed_mps"),
        ((120.0, 3.0, 1.0, 4000.0, 1500.0), "slot_s must be >= guard_s"),
    ],
)
def test_slot_budget_rejects_bad_parameters(args: tuple[float, ...], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        slot_budget_bits(*args)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), n_headings=st.sampled_from([1, 2, 7, 9, 21, 64]))
def test_round_trip_error_bounds(data: st.DataObject, n_headings: int) -> None:
    p = data.draw(payloads(n_headings))
    blob, dropped = encode_payload(p, BIG_BUDGET, n_headings)
    assert dropped == 0
    q = decode_payload(blob, n_headings)
    assert (q.sender, q.round, q.plan) == (p.sender, p.round, p.plan)
    assert abs(q.t_s - p.t_s) <= 0.05 + EPS
    assert abs(q.x - p.x) <= 0.5 + EPS and abs(q.y - p.y) <= 0.5 + EPS
    assert _angle_error_deg(q.theta, p.theta) <= 0.05 + EPS
    assert -math.pi < q.theta <= math.pi
    assert abs(q.u_e - p.u_e) <= 0.005 + EPS
    assert len(q.bearings) == len(p.bearings)
    for (t, sx, sy, b), (t0, sx0, sy0, b0) in zip(q.bearings, p.bearings, strict=True):
        assert abs(t - t0) <= 0.05 + EPS
        assert abs(sx - sx0) <= 0.5 + EPS and abs(sy - sy0) <= 0.5 + EPS
        assert _angle_error_deg(b, b0) <= 0.05 + EPS
        assert -math.pi < b <= math.pi
    assert encode_payload(q, BIG_BUDGET, n_headings) == (blob, 0)


def test_priority_keeps_newest_bearings_in_their_order() -> None:
    p = _payload(30)
    blob, dropped = encode_payload(p, PAPER_BUDGET, 9)
    q = decode_payload(blob, 9)
    assert dropped == 3 and len(q.bearings) == 27
    assert [round(b[0], 1) for b in q.bearings] == [round(b[0], 1) for b in p.bearings if b[0] > 200.0 - 2.0 * 27]
    shuffled = list(p.bearings)
    random.Random(4).shuffle(shuffled)
    q2 = decode_payload(encode_payload(dataclasses.replace(p, bearings=tuple(shuffled)), PAPER_BUDGET, 9)[0], 9)
    assert sorted(b[0] for b in q2.bearings) == sorted(b[0] for b in q.bearings)
    assert [b[0] for b in q2.bearings] == [round(b[0], 1) for b in shuffled if b[0] > 200.0 - 2.0 * 27]


def test_unrepresentable_bearings_are_dropped_and_counted() -> None:
    p = _payload(
        0,
        bearings=(
            (90.0, 1000.0, -2000.0, 0.1),
            (199.0, 1300.0, -2000.0, 0.2),
            (199.0, 1000.0, -1700.0, 0.3),
            (199.0, 1000.0, -2000.0, 0.4),
        ),
    )
    blob, dropped = encode_payload(p, BIG_BUDGET, 9)
    q = decode_payload(blob, 9)
    assert dropped == 3
    assert q.bearings == ((199.0, 1000.0, -2000.0, pytest.approx(0.4, abs=1e-3)),)


def test_bearing_count_is_capped_at_255() -> None:
    bearings = tuple((200.0 - 0.1 * k, 1000.0, -2000.0, 0.0) for k in range(300))
    blob, dropped = encode_payload(_payload(0, bearings=bearings), BIG_BUDGET, 9)
    assert dropped == 45 and len(decode_payload(blob, 9).bearings) == 255


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), budget=st.integers(152, 3000))
def test_budget_is_never_exceeded(data: st.DataObject, budget: int) -> None:
    p = data.draw(payloads(9, max_n=80))
    padded_header = 8 * math.ceil(header_bits(len(p.plan), 9) / 8)
    if padded_header > budget:
        with pytest.raises(ValueError, match="budget_bits"):
            encode_payload(p, budget, 9)
        return
    blob, dropped = encode_payload(p, budget, 9)
    kept = decode_payload(blob, 9).bearings
    assert 8 * len(blob) <= budget
    assert dropped + len(kept) == len(p.bearings)
    if dropped:
        assert len(kept) == max_bearings(budget, len(p.plan), 9)


def test_header_over_budget_raises_naming_budget_bits() -> None:
    with pytest.raises(ValueError, match="budget_bits must be >= 152"):
        encode_payload(_payload(), 144, 9)
    with pytest.raises(ValueError, match="budget_bits"):
        encode_payload(_payload(), -8, 9)
    blob, dropped = encode_payload(_payload(3), 152, 9)
    assert (len(blob), dropped) == (19, 3)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"sender": 256}, "sender must be an integer in \\[0, 255\\]"),
        ({"sender": True}, "sender"),
        ({"round": -1}, "round must be an integer in \\[0, 255\\]"),
        ({"t_s": -1.0}, "t_s must be in \\[0, 13421772.7\\] s"),
        ({"t_s": 2e7}, "t_s must be in"),
        ({"t_s": math.nan}, "t_s must be a finite number"),
        ({"x": 70_000.0}, "x must be in \\[-65536, 65535\\] m"),
        ({"y": -1e308}, "y must be in"),
        ({"theta": math.inf}, "theta must be a finite number"),
        ({"u_e": 10.5}, "u_e must be in \\[0, 10.23\\] m/s"),
        ({"u_e": -0.1}, "u_e must be in"),
        ({"plan": ((9, 0),)}, "plan\\[0\\] dheading_index must be an integer in \\[0, 8\\]"),
        ({"plan": ((0, 8),)}, "plan\\[0\\] speed_index must be an integer in \\[0, 7\\]"),
        ({"plan": ((0, 1, 2),)}, "plan\\[0\\] must be a"),
        ({"plan": ((0, 0),) * (MAX_PLAN_LENGTH + 1)}, f"plan must be a tuple of at most {MAX_PLAN_LENGTH}"),
        ({"bearings": ((201.0, 1000.0, -2000.0, 0.0),)}, "bearings\\[0\\] t_s must be in"),
        ({"bearings": ((1e308, 1000.0, -2000.0, 0.0),)}, "bearings\\[0\\] t_s must be in"),
        ({"bearings": ((199.0, math.nan, -2000.0, 0.0),)}, "bearings\\[0\\]\\[1\\] must be a finite number"),
        ({"bearings": ((199.0, 1000.0),)}, "bearings\\[0\\] must be"),
    ],
)
def test_invalid_fields_raise_value_error_naming_them(changes: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        encode_payload(_payload(**changes), PAPER_BUDGET, 9)


@pytest.mark.parametrize("n_headings", [0, 257, True, 9.0])
def test_invalid_n_headings(n_headings: object) -> None:
    with pytest.raises(ValueError, match="n_headings must be an integer in \\[1, 256\\]"):
        encode_payload(_payload(), PAPER_BUDGET, n_headings)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n_headings"):
        decode_payload(b"\x00" * 20, n_headings)  # type: ignore[arg-type]


def _check_decoder(blob: bytes, n_headings: int) -> None:
    """Only DecodeError may escape; anything accepted is a canonical encoding."""
    try:
        q = decode_payload(blob, n_headings)
    except DecodeError:
        return
    assert encode_payload(q, BIG_BUDGET, n_headings) == (blob, 0)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1))
def test_5000_random_byte_strings_raise_only_decode_error(seed: int) -> None:
    """50 examples x 100 random byte strings = 5,000 inputs (lengths chosen around real payload sizes)."""
    rng = random.Random(seed)
    for _ in range(100):
        n_headings = rng.choice([1, 7, 9, 64])
        length = rng.choice([0, 1, 14, 15, 16, 19, 40, 124, 155, 2000])
        blob = rng.randbytes(length)
        if blob and rng.random() < 0.5:
            blob = bytes([0x10 | (blob[0] & 0x0F)]) + blob[1:]
        _check_decoder(blob, n_headings)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), seed=st.integers(0, 2**32 - 1))
def test_5000_mutated_payloads_raise_only_decode_error(data: st.DataObject, seed: int) -> None:
    """100 examples x 50 mutations (bit flips, truncation, extension, byte swaps) = 5,000 inputs."""
    p = data.draw(payloads(9))
    blob, _ = encode_payload(p, BIG_BUDGET, 9)
    rng = random.Random(seed)
    for _ in range(50):
        mutated = bytearray(blob)
        op = rng.randrange(4)
        if op == 0:
            for _ in range(rng.randint(1, 3)):
                k = rng.randrange(len(mutated))
                mutated[k] ^= 1 << rng.randrange(8)
        elif op == 1:
            del mutated[rng.randrange(len(mutated)) :]
        elif op == 2:
            mutated += rng.randbytes(rng.randint(1, 6))
        else:
            i, j = rng.randrange(len(mutated)), rng.randrange(len(mutated))
            mutated[i], mutated[j] = mutated[j], mutated[i]
        _check_decoder(bytes(mutated), 9)
        _check_decoder(bytes(mutated), rng.choice([1, 7, 64]))


def test_specific_malformations() -> None:
    blob, _ = encode_payload(_payload(2), PAPER_BUDGET, 9)
    with pytest.raises(DecodeError, match="version must be 2"):
        decode_payload(bytes([blob[0] ^ 0x30]) + blob[1:], 9)
    with pytest.raises(DecodeError, match="length must be"):
        decode_payload(blob[:-1], 9)
    with pytest.raises(DecodeError, match="shorter than"):
        decode_payload(blob[:5], 9)
    with pytest.raises(DecodeError, match="padding bits must be zero"):
        decode_payload(blob[:-1] + bytes([blob[-1] | 1]), 9)
    with pytest.raises(DecodeError, match="data must be bytes"):
        decode_payload("text", 9)  # type: ignore[arg-type]
    with pytest.raises(DecodeError, match="plan\\[.\\] must index"):
        decode_payload(encode_payload(_payload(2, plan=((15, 1),)), PAPER_BUDGET, 16)[0], 9)


def test_naive_msgpack_of_21_bearings_does_not_fit_the_paper_budget_but_ours_does() -> None:
    """Paper slot: 120 bps x (14 s - 1 s guard - 4 km / 1500 m/s) = 1240 bits; 21 bearings = T_f / T_m = 42 s / 2 s."""
    p = _payload(21)
    naive = msgpack.packb(
        [p.sender, p.t_s, p.x, p.y, p.theta, p.u_e, [list(s) for s in p.plan], p.round, [list(b) for b in p.bearings]],
        use_single_float=False,
    )
    assert 8 * len(naive) > PAPER_BUDGET
    blob, dropped = encode_payload(p, PAPER_BUDGET, 9)
    assert dropped == 0
    assert 8 * len(blob) <= PAPER_BUDGET
    assert len(blob) == math.ceil((header_bits(5, 9) + 21 * bearing_bits()) / 8) == 124
