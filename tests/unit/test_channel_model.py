"""Unit tests of the pure acoustic channel model (channel_sim/model.py)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auv_swarm.channel_sim.model import DROP_REASONS, ChannelEvent, ChannelModel, Reception, TdmaSchedule
from auv_swarm.contract.acoustics import snr_db_cfg
from auv_swarm.contract.config import ChannelConfig, ConfigError

ALL = {0, 1, 2}


def cfg(**changes) -> ChannelConfig:
    """A clean link (PDR 1, short range budget) unless a test changes it."""
    base = {"pdr": 1.0, "max_range_m": 1500.0, "slot_s": 14.0, "guard_s": 1.0, "noise_level_db": 40.0}
    return dataclasses.replace(ChannelConfig(), **{**base, **changes})


def model(seed: int = 7, order: tuple[int, ...] = (0, 1, 2), max_frame_bits: int = 960, **changes) -> ChannelModel:
    return ChannelModel(cfg(**changes), order, np.random.default_rng(seed), max_frame_bits)


def outcomes(events: list[ChannelEvent]) -> dict[tuple[int, int], str]:
    """(sender, recipient) -> "delivered" or the drop reason, for per-link events."""
    return {(e.sender, e.recipient): e.reason or e.kind for e in events if e.kind != "sent"}


# --- TDMA schedule -----------------------------------------------------------------------------------------


def test_schedule_owner_window_and_next_start():
    s = TdmaSchedule(14.0, 1.0, (2, 0, 1))
    assert s.frame_s == 42.0
    assert [s.owner(t) for t in (0.0, 13.9, 14.0, 27.99, 28.0, 41.9, 42.0, 56.0)] == [2, 2, 0, 0, 1, 1, 2, 0]
    assert s.slot_window(0, 0.0) == (14.0, 28.0)
    assert s.slot_window(0, 20.0) == (14.0, 28.0)
    assert s.slot_window(0, 28.0) == (56.0, 70.0)
    assert s.next_start(0, 14.0) == 14.0
    assert s.next_start(0, 14.5) == 56.0
    assert s.next_start(2, 1.0) == 42.0


def test_schedule_can_transmit_needs_own_slot_and_room_before_guard():
    s = TdmaSchedule(14.0, 1.0, (0, 1, 2))
    assert s.can_transmit(0, 0.0, 8.0, 1.0)
    assert s.can_transmit(0, 4.0, 8.0, 1.0)  # 4 + 8 + 1 = 13 = slot end - guard
    assert not s.can_transmit(0, 4.5, 8.0, 1.0)
    assert not s.can_transmit(1, 0.0, 1.0, 1.0)
    assert s.can_transmit(1, 14.0, 1.0, 1.0)
    assert s.can_transmit(0, 42.0 * 1000, 8.0, 1.0)


@pytest.mark.parametrize(
    ("slot_s", "guard_s", "order", "word"),
    [(0.0, 0.0, (0,), "slot_s"), (14.0, 14.0, (0,), "guard_s"), (14.0, 1.0, (), "order"), (14.0, 1.0, (0, 0), "order")],
)
def test_schedule_rejects_bad_parameters(slot_s, guard_s, order, word):
    with pytest.raises(ValueError, match=word):
        TdmaSchedule(slot_s, guard_s, order)


# --- start-up checks ---------------------------------------------------------------------------------------


def test_refuses_slot_too_short_with_the_numbers():
    ch = cfg(max_range_m=4000.0)
    with pytest.raises(ConfigError) as err:
        ChannelModel(ch, (0, 1, 2), np.random.default_rng(0), 1800)
    msg = str(err.value)
    assert msg == (
        "channel.slot_s = 14 s cannot hold airtime 15.0 s (1800 bits at 120 bps) + max propagation 2.67 s "
        "(4000 m at 1500 m/s) + guard 1 s = 18.67 s"
    )


def test_accepts_a_slot_that_just_fits_and_aloha_without_slot_check():
    ChannelModel(cfg(max_range_m=4000.0), (0, 1, 2), np.random.default_rng(0), 1240)  # 10.33 + 2.67 + 1 = 14
    ChannelModel(cfg(max_range_m=4000.0, mode="aloha"), (0, 1, 2), np.random.default_rng(0), 1800)


@pytest.mark.parametrize(("bits", "order", "word"), [(0, (0, 1), "max_frame_bits"), (960, (0, 1, 1), "slot_order")])
def test_rejects_bad_constructor_arguments(bits, order, word):
    with pytest.raises(ValueError, match=word):
        ChannelModel(cfg(), order, np.random.default_rng(0), bits)


# --- delivery statistics -----------------------------------------------------------------------------------


def test_delivered_fraction_matches_pdr_at_high_snr():
    m = model(seed=11, pdr=0.65, mode="aloha")
    pos = {0: (0.0, 0.0), 1: (300.0, 0.0), 2: (0.0, 400.0)}
    n_frames = 5000
    delivered = 0
    for k in range(n_frames):
        m.transmit(float(k), 0, k, b"x" * 10, pos, ALL)
        delivered += len(m.deliver_until(float(k) + 0.99)[0])
    links = 2 * n_frames
    assert abs(delivered / links - 0.65) < 0.01
    c = m.counters
    assert c["sent"] == n_frames and c["delivered"] == delivered
    assert c["delivered"] + c["dropped_random_loss"] == links
    assert c["dropped_collision"] == c["dropped_half_duplex"] == c["dropped_low_snr"] == 0


def test_snr_ramp_success_probability_and_statistics():
    snr_1km = snr_db_cfg(1000.0, cfg())
    m = model(seed=3, pdr=0.8, mode="aloha", snr_transition_db=6.0, detection_threshold_db=snr_1km - 3.0)
    dt = m.ch.detection_threshold_db
    assert m.success_probability(dt - 0.1) == 0.0
    assert m.success_probability(dt) == 0.0
    assert m.success_probability(dt + 3.0) == pytest.approx(0.4)
    assert m.success_probability(dt + 6.0) == pytest.approx(0.8)
    assert m.success_probability(dt + 60.0) == pytest.approx(0.8)
    pos = {0: (0.0, 0.0), 1: (1000.0, 0.0), 2: (0.0, 1000.0)}
    for k in range(5000):
        m.transmit(float(k), 0, k, b"x", pos, ALL)
        m.deliver_until(float(k) + 0.99)
    assert abs(m.counters["delivered"] / 10000 - 0.4) < 0.015


def test_low_snr_drops_with_high_noise():
    m = model(noise_level_db=150.0)
    pos = {0: (0.0, 0.0), 1: (1000.0, 0.0), 2: (0.0, 50.0)}
    events = m.transmit(0.0, 0, 1, b"hello", pos, ALL)
    drops = [e for e in events if e.kind == "dropped"]
    assert [(e.recipient, e.reason) for e in drops] == [(1, "low_snr"), (2, "low_snr")]
    assert drops[0].snr_db == pytest.approx(snr_db_cfg(1000.0, m.ch)) and drops[0].snr_db < 10.0
    assert m.deliver_until(1e6) == ([], [])
    assert m.counters["dropped_low_snr"] == 2 and m.counters["delivered"] == 0


# --- latency -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("xy", [(1234.5678, 987.654321), (0.0, 0.0), (1e-3, 3.3e3), (-777.7, 12.3)])
def test_latency_is_airtime_plus_propagation_exactly(xy):
    m = model(mode="aloha")
    pos = {0: (10.1, -20.2), 1: (10.1 + xy[0], -20.2 + xy[1]), 2: (5e3, 5e3)}
    payload = bytes(range(37))
    t0 = 123.456
    sent = m.transmit(t0, 0, 4, payload, pos, ALL)[0]
    assert sent.kind == "sent" and sent.t_s == t0 and sent.recipient == -1 and sent.correlation_id == "0-4"
    receptions, events = m.deliver_until(1e4)
    rx = next(r for r in receptions if r.recipient == 1)
    ev = next(e for e in events if e.recipient == 1)
    range_m = math.hypot(pos[1][0] - pos[0][0], pos[1][1] - pos[0][1])
    expected = 8 * len(payload) / 120.0 + range_m / 1500.0
    assert ev.kind == "delivered" and ev.latency_s == expected
    assert ev.t_s == rx.t_arrival
    assert abs((rx.t_arrival - rx.t_sent) - expected) <= 1e-12
    assert abs((rx.t_first - rx.t_sent) - range_m / 1500.0) <= 1e-12
    assert rx == Reception("0-4", 0, 1, 4, payload, 8 * len(payload), t0, rx.t_first, rx.t_arrival, rx.snr_db)
    assert rx.snr_db == pytest.approx(snr_db_cfg(range_m, m.ch))
    lat = m.latencies
    assert lat["count"] == 2 and lat["mean_s"] > 0.0 and lat["max_s"] >= expected


def test_latency_summary_is_zero_before_any_delivery():
    assert model().latencies == {"count": 0, "mean_s": 0.0, "max_s": 0.0}


# --- oversize and slots ------------------------------------------------------------------------------------


def test_oversize_frame_is_dropped_and_counted():
    m = model(max_frame_bits=800)
    pos = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (0.0, 100.0)}
    events = m.transmit(0.0, 0, 9, b"x" * 101, pos, ALL)
    assert events == [ChannelEvent(0.0, "0-9", "dropped", 0, -1, 808, None, None, "oversize")]
    assert m.transmit(0.0, 0, 10, b"x" * 100, pos, ALL)[0].kind == "sent"
    c = m.counters
    assert c["dropped_oversize"] == 1 and c["sent"] == 1
    assert len(m.deliver_until(100.0)[0]) == 2


def test_out_of_slot_frame_is_deferred_to_the_next_slot():
    m = model()
    pos = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (0.0, 100.0)}
    sent = m.transmit(0.0, 1, 1, b"x" * 120, pos, ALL)[0]  # 960 bits = 8 s; agent 1 owns [14, 28)
    assert sent.kind == "sent" and sent.t_s == 14.0
    late = m.transmit(6.0, 0, 1, b"x" * 120, pos, ALL)[0]  # 6 + 8 + 1 > 14 - 1: next frame's slot at 42
    assert late.t_s == 42.0
    assert m.counters["deferred"] == 2 and m.counters["sent"] == 2
    receptions, _ = m.deliver_until(100.0)
    assert sorted((r.sender, r.t_sent) for r in receptions) == [(0, 42.0), (0, 42.0), (1, 14.0), (1, 14.0)]


def test_out_of_slot_frame_is_rejected_when_configured():
    m = model(out_of_slot="reject")
    pos = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (0.0, 100.0)}
    events = m.transmit(0.0, 1, 5, b"x", pos, ALL)
    assert events == [ChannelEvent(0.0, "1-5", "dropped", 1, -1, 8, None, None, "outside_slot")]
    assert m.counters["dropped_outside_slot"] == 1 and m.counters["sent"] == 0 and m.counters["deferred"] == 0
    assert m.deliver_until(1e3) == ([], [])


def test_busy_modem_sends_frames_back_to_back():
    m = model()
    pos = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (0.0, 100.0)}
    first = m.transmit(0.0, 0, 1, b"x" * 40, pos, ALL)[0]  # 320 bits: 2.67 s
    second = m.transmit(0.0, 0, 2, b"x" * 40, pos, ALL)[0]
    third = m.transmit(10.0, 0, 3, b"x" * 40, pos, ALL)[0]  # 10 + 2.67 + 1 > 14 - 1: deferred
    assert (first.t_s, second.t_s, third.t_s) == (0.0, 320 / 120, 42.0)
    assert m.counters["deferred"] == 1
    _, events = m.deliver_until(100.0)
    assert {e.kind for e in events} == {"delivered"}


def test_queued_airtime_never_exceeds_what_the_next_slot_carries():
    """Slot 14 s, guard 1 s, 1500 m budget (1 s): a slot carries 12 s of airtime, and so does the queue."""
    m = model()
    assert m.backlog_s == pytest.approx(12.0)
    pos = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (0.0, 100.0)}
    kinds = [m.transmit(0.0, 0, seq, b"x" * 40, pos, ALL)[0] for seq in range(1, 7)]  # 2.67 s each
    assert [e.kind for e in kinds] == ["sent"] * 4 + ["dropped"] * 2
    assert kinds[-1] == ChannelEvent(0.0, "0-6", "dropped", 0, -1, 320, None, None, "tx_backlog_full")
    assert m.queued_airtime_s(0, 0.0) == pytest.approx(4 * 320 / 120)
    assert m.queued_airtime_s(0, 2.0) == pytest.approx(4 * 320 / 120 - 2.0)
    c = m.counters
    assert c["sent"] == 4 and c["dropped_tx_backlog_full"] == 2 and m.in_flight == 8
    # another sender's queue is its own; a frame that fits again once the queue has drained is taken
    assert m.transmit(0.0, 1, 1, b"x" * 40, pos, ALL)[0].kind == "sent"
    m.deliver_until(14.0)
    assert [m.transmit(14.0, 0, seq, b"x" * n, pos, ALL)[0].kind for seq, n in ((7, 120), (8, 40))] == ["sent"] * 2
    assert m.transmit(14.0, 0, 9, b"x" * 40, pos, ALL)[0].reason == "tx_backlog_full"  # 8 + 2.67 + 2.67 > 12


def test_aloha_queue_holds_one_slot_of_airtime():
    m = model(mode="aloha")
    assert m.backlog_s == 14.0
    pos = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (0.0, 100.0)}
    events = [m.transmit(0.0, 0, seq, b"x" * 60, pos, ALL)[0] for seq in range(1, 6)]  # 4 s each
    assert [e.kind for e in events] == ["sent"] * 3 + ["dropped"] * 2
    assert [e.t_s for e in events[:3]] == [0.0, 4.0, 8.0]


def test_correct_schedule_never_collides():
    m = model(seed=5, max_range_m=2000.0)
    pos = {0: (0.0, 0.0), 1: (1900.0, 0.0), 2: (900.0, 1500.0)}
    for frame in range(20):
        for i, agent in enumerate((0, 1, 2)):
            t = frame * 42.0 + i * 14.0
            m.deliver_until(t)
            m.transmit(t, agent, frame, b"y" * 120, pos, ALL)
            m.transmit(t, agent, 1000 + frame, b"y" * 10, pos, ALL)
    m.deliver_until(1e5)
    c = m.counters
    assert c["sent"] == 120 and c["delivered"] == 240 and c["deferred"] == 0
    assert all(c[f"dropped_{r}"] == 0 for r in DROP_REASONS)


# --- half-duplex and collisions ----------------------------------------------------------------------------


def test_aloha_half_duplex_and_collision():
    m = model(mode="aloha")
    pos = {0: (0.0, 0.0), 1: (1500.0, 0.0), 2: (750.0, 1000.0)}  # 0-1: 1 s; 0-2 and 1-2: 1250 m
    m.transmit(0.0, 0, 1, b"x" * 30, pos, ALL)  # 2 s airtime
    m.transmit(0.0, 1, 1, b"x" * 30, pos, ALL)
    receptions, events = m.deliver_until(10.0)
    assert receptions == []
    assert outcomes(events) == {(0, 1): "half_duplex", (1, 0): "half_duplex", (0, 2): "collision", (1, 2): "collision"}
    assert all(e.t_s > 0.0 and e.snr_db is not None for e in events)
    assert m.counters["dropped_half_duplex"] == 2 and m.counters["dropped_collision"] == 2


def test_aloha_frames_that_only_touch_do_not_interfere():
    m = model(mode="aloha")
    pos = {0: (0.0, 0.0), 1: (1500.0, 0.0), 2: (750.0, 1000.0)}
    m.transmit(0.0, 0, 1, b"x" * 30, pos, ALL)  # reaches 1 over [1, 3)
    m.transmit(3.0, 1, 1, b"x" * 30, pos, ALL)  # 1 transmits over [3, 5)
    _, events = m.deliver_until(10.0)
    assert set(outcomes(events).values()) == {"delivered"} and len(events) == 4


class FixedDraws:
    """Stands in for the Generator: hands out the given uniform variates in order."""

    def __init__(self, values: list[float]) -> None:
        self.values = list(values)

    def random(self, n: int) -> np.ndarray:
        out, self.values = self.values[:n], self.values[n:]
        return np.array(out)


def test_randomly_lost_frame_still_collides():
    m = ChannelModel(cfg(mode="aloha", pdr=0.65), (0, 1, 2), FixedDraws([0.99, 0.99, 0.0, 0.0]), 960)
    pos = {0: (0.0, 0.0), 1: (1500.0, 0.0), 2: (750.0, 1000.0)}
    first = m.transmit(0.0, 0, 1, b"x" * 30, pos, ALL)  # lost at 1 and 2, but its sound still arrives
    assert outcomes(first) == {(0, 1): "random_loss", (0, 2): "random_loss"}
    m.transmit(0.5, 1, 1, b"x" * 30, pos, ALL)  # at 2 it overlaps the lost frame; at 0 it overlaps 0's own airtime
    _, events = m.deliver_until(10.0)
    assert outcomes(events) == {(1, 0): "half_duplex", (1, 2): "collision"}


def test_broken_schedule_range_beyond_budget_gives_half_duplex_and_collision():
    m = model(slot_s=10.0, max_range_m=1500.0)  # slot budget: 8 s airtime + 1 s propagation + 1 s guard
    pos = {0: (0.0, 0.0), 1: (6000.0, 0.0), 2: (6000.0, 150.0)}  # but 0 is 4 s away from 1 and 2
    m.transmit(0.0, 0, 1, b"x" * 120, pos, ALL)  # reaches 1 and 2 over about [4, 12)
    m.transmit(10.0, 1, 1, b"x" * 120, pos, ALL)  # 1 transmits over [10, 18), reaching 2 over [10.1, 18.1)
    _, events = m.deliver_until(100.0)
    assert outcomes(events) == {(0, 1): "half_duplex", (0, 2): "collision", (1, 2): "collision", (1, 0): "delivered"}


# --- dead recipients ---------------------------------------------------------------------------------------


def test_recipient_dead_at_transmit_and_killed_in_flight():
    m = model()
    pos = {0: (0.0, 0.0), 1: (1500.0, 0.0)}  # 2 is dead: no position needed
    events = m.transmit(0.0, 0, 1, b"x", pos, {0, 1})
    assert outcomes(events) == {(0, 2): "recipient_dead"}
    m.kill(1)  # 0's frame is still in flight to 1
    _, events = m.deliver_until(20.0)
    assert outcomes(events) == {(0, 1): "recipient_dead"}
    assert m.counters["dropped_recipient_dead"] == 2


def test_killed_agent_frames_still_propagate():
    m = model()
    pos = {0: (0.0, 0.0), 1: (1500.0, 0.0), 2: (0.0, 1500.0)}
    m.transmit(14.0, 1, 1, b"x", pos, ALL)
    m.kill(1)
    receptions, _ = m.deliver_until(28.0)
    assert sorted(r.recipient for r in receptions) == [0, 2]
    events = m.transmit(28.0, 2, 1, b"x", pos, {0, 2})
    assert outcomes(events) == {(2, 1): "recipient_dead"}


# --- contract ----------------------------------------------------------------------------------------------


def test_counters_hold_every_reason():
    assert set(model().counters) == {"sent", "delivered", "deferred", *(f"dropped_{r}" for r in DROP_REASONS)}
    assert set(model().counters.values()) == {0}


def test_submission_before_last_delivery_time_is_refused():
    m = model()
    pos = {0: (0.0, 0.0), 1: (100.0, 0.0), 2: (0.0, 100.0)}
    m.deliver_until(14.0)
    with pytest.raises(ValueError, match="t_s must be >= the last deliver_until time"):
        m.transmit(13.0, 0, 1, b"x", pos, ALL)
    with pytest.raises(ValueError, match="t_s"):
        m.deliver_until(13.0)


def test_bad_inputs_raise_without_changing_state():
    m = model()
    with pytest.raises(ValueError, match="positions"):
        m.transmit(0.0, 0, 1, b"x", {0: (0.0, 0.0), 1: (1.0, 0.0)}, ALL)
    with pytest.raises(ValueError, match="positions"):
        m.transmit(0.0, 0, 1, b"x", {0: (0.0, 0.0), 1: (math.nan, 0.0), 2: (1.0, 1.0)}, ALL)
    with pytest.raises(ValueError, match="sender"):
        m.transmit(0.0, 7, 1, b"x", {0: (0.0, 0.0)}, ALL)
    with pytest.raises(ValueError, match="t_s"):
        m.transmit(math.inf, 0, 1, b"x", {0: (0.0, 0.0)}, ALL)
    with pytest.raises(ValueError, match="agent"):
        m.kill(9)
    assert set(m.counters.values()) == {0}
    fresh = model()
    assert m.rng.random() == fresh.rng.random()


def run_random(seed: int, schedule_seed: int) -> tuple[list, list]:
    m = model(seed=seed, pdr=0.65, mode="aloha", max_frame_bits=2000)
    plan = np.random.default_rng(schedule_seed)
    events, receptions = [], []
    pos = {0: (0.0, 0.0), 1: (1200.0, 300.0), 2: (-400.0, 900.0)}
    for k in range(300):
        t = k * 2.0
        r, e = m.deliver_until(t)
        receptions += r
        events += e
        for agent in (0, 1, 2):
            if plan.random() < 0.1:
                payload = plan.integers(0, 256, int(plan.integers(1, 40))).astype(np.uint8).tobytes()
                events += m.transmit(t, agent, k, payload, pos, ALL)
    r, e = m.deliver_until(1e4)
    return receptions + r, events + e


def test_same_seed_same_events():
    a = run_random(21, 5)
    b = run_random(21, 5)
    assert a == b
    assert len(a[0]) > 50
    assert run_random(22, 5)[1] != a[1]


def test_deliveries_are_sorted():
    receptions, events = run_random(4, 9)
    per_call = sorted(receptions, key=lambda r: (r.t_arrival, r.sender, r.recipient, r.seq))
    assert receptions == per_call


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 2), st.floats(0.0, 5.0), st.integers(0, 150)),
        min_size=1,
        max_size=25,
    ),
    st.sampled_from(["tdma", "aloha"]),
    st.sampled_from(["defer", "reject"]),
)
def test_every_link_has_exactly_one_outcome(txs, mode, out_of_slot):
    m = model(seed=1, pdr=0.7, mode=mode, out_of_slot=out_of_slot, max_frame_bits=1000)
    pos = {0: (0.0, 0.0), 1: (1400.0, 0.0), 2: (0.0, 900.0)}
    events: list[ChannelEvent] = []
    t = 0.0
    for seq, (agent, dt, size) in enumerate(txs):
        t += dt
        events += m.deliver_until(t)[1]
        events += m.transmit(t, agent, seq, b"z" * size, pos, ALL)
    events += m.deliver_until(1e6)[1]
    sent = {e.correlation_id for e in events if e.kind == "sent"}
    per_frame_drops = [e for e in events if e.kind == "dropped" and e.recipient == -1]
    assert len(sent) + len(per_frame_drops) == len(txs)
    for cid in sent:
        assert sorted(e.recipient for e in events if e.correlation_id == cid and e.kind != "sent") == sorted(
            {0, 1, 2} - {int(cid.split("-")[0])}
        )
    c = m.counters
    assert c["sent"] == len(sent)
    assert sum(c[f"dropped_{r}"] for r in DROP_REASONS) + c["delivered"] == 2 * len(sent) + len(per_frame_drops)
    assert all(e.reason in DROP_REASONS for e in events if e.kind == "dropped")
    assert all(not (isinstance(v, float) and math.isnan(v)) for e in events for v in (e.latency_s, e.snr_db))
