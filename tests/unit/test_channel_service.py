"""ChannelService: the lockstep tick protocol around the channel model."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auv_swarm.bus.bus import InMemoryBus
from auv_swarm.channel_sim.node import ChannelNode
from auv_swarm.channel_sim.service import SERVICE_COUNTERS, ChannelService
from auv_swarm.contract import wire
from auv_swarm.contract.config import scenario_from_dict
from auv_swarm.contract.ocean import slot_frame_bits
from auv_swarm.contract.payload import slot_budget_bits
from auv_swarm.contract.wire import ChannelTick, ModemTx, decode, encode

TICK_S = 2.0
C = 1500.0
POSITIONS = {0: (0.0, 0.0), 1: (1500.0, 0.0), 2: (0.0, 1500.0)}


def _scenario(pdr: float = 1.0, agents: int = 3, **channel: object):
    return scenario_from_dict(
        {"agents": {"count": agents}, "run": {"tick_s": TICK_S}, "channel": {"pdr": pdr, **channel}}
    )


def _tick(k: int, tx_expected: dict[int, int] | None = None, alive=(0, 1, 2), positions=None) -> ChannelTick:
    return ChannelTick(
        tick=k,
        tx_expected=tx_expected or {},
        positions=positions or {a: POSITIONS[a] for a in alive},
        alive=tuple(alive),
        t_s=k * TICK_S,
        source="world",
    )


def _tx(auv: int, seq: int, k: int, nbytes: int = 20) -> ModemTx:
    return ModemTx(
        tick=k, auv=auv, seq=seq, payload=bytes([auv, seq % 256]) * (nbytes // 2), t_s=k * TICK_S, source=f"auv/{auv}"
    )


def _run(service: ChannelService, schedule: dict[int, list[ModemTx]], ticks: int):
    out = []
    for k in range(ticks):
        txs = schedule.get(k - 1, [])
        expected = {a: sum(1 for t in txs if t.auv == a) for a in (0, 1, 2)}
        out.append(service.on_tick(_tick(k, expected), list(txs)))
    return out


def test_default_frame_budget_is_the_slot_budget() -> None:
    s = _scenario()
    assert slot_frame_bits(s.channel, s.ocean) == slot_budget_bits(120.0, 14.0, 1.0, 4000.0, 1500.0) == 1240
    assert ChannelService(s, np.random.default_rng(1)).model.max_frame_bits == 1240


def test_tx_of_previous_tick_is_delivered_with_airtime_plus_propagation() -> None:
    service = ChannelService(_scenario(), np.random.default_rng(1))
    tx = _tx(0, 0, k=1, nbytes=20)
    out = _run(service, {1: [tx]}, ticks=4)
    airtime = 160 / 120.0
    # sent at t_1 = 2 s; last bit at 2 + 1.333 + 1.0 = 4.333 s to AUVs 1 and 2 (both 1500 m away)
    assert [len(rx) for rx, _, _ in out] == [0, 0, 0, 2]
    rx, events, done = out[3]
    assert {r.auv for r in rx} == {1, 2}
    for r in rx:
        assert r.sender == 0 and r.seq == 0 and r.payload == tx.payload and r.tick == 3
        assert r.t_sent == 2.0
        assert math.isclose(r.t_arrival - r.t_sent, airtime + 1500.0 / C, abs_tol=1e-12)
        assert decode(encode(r)) == r
    assert done.tick == 3 and done.rx_count == {0: 0, 1: 1, 2: 1}
    assert [e.kind for e in out[2][1]] == ["sent"]
    assert sorted(e.kind for e in events) == ["delivered", "delivered"]
    assert all(math.isclose(e.latency_s, airtime + 1.0, abs_tol=1e-12) for e in events)
    assert out[0][2].rx_count == {0: 0, 1: 0, 2: 0}


def _frames(k: int) -> list[ModemTx]:
    return [_tx(a, s, k) for a in (0, 1, 2) for s in range(2)]


@settings(max_examples=25, deadline=None)
@given(perm_seed=st.integers(0, 2**32 - 1), seed=st.integers(0, 2**32 - 1))
def test_output_does_not_depend_on_arrival_order(perm_seed: int, seed: int) -> None:
    schedule = {k: _frames(k) for k in range(1, 12, 3)}
    shuffled = {
        k: [v[i] for i in np.random.default_rng(perm_seed + k).permutation(len(v))] for k, v in schedule.items()
    }
    a = _run(ChannelService(_scenario(pdr=0.65), np.random.default_rng(seed)), schedule, ticks=30)
    b = _run(ChannelService(_scenario(pdr=0.65), np.random.default_rng(seed)), shuffled, ticks=30)
    assert a == b
    assert sum(len(rx) for rx, _, _ in a) > 0


def test_counts_missing_duplicate_stale_unknown_and_dead() -> None:
    service = ChannelService(_scenario(), np.random.default_rng(3))
    service.on_tick(_tick(0), [_tx(0, 9, k=0)])
    txs = [_tx(0, 0, k=0), _tx(0, 0, k=0), _tx(1, 0, k=3)]
    service.on_tick(_tick(1, {0: 1, 1: 1, 2: 2}), txs)
    counts = service.counters()
    assert counts["tx_stale"] == 2  # tick-0 frames sent with ChannelTick(0), and a tick-3 frame at tick 1
    assert counts["tx_duplicate"] == 1
    assert counts["tx_missing"] == 3  # auv1 expected 1 (its frame was stale), auv2 expected 2
    assert counts["sent"] == 1 and counts["ticks"] == 2
    assert set(SERVICE_COUNTERS) <= set(counts)
    assert {"delivered", "deferred", "dropped_random_loss"} <= set(counts)

    service.on_tick(_tick(2, {2: 1}, alive=(0, 1)), [_tx(2, 0, k=1)])
    service.on_tick(_tick(3, {2: 1}, alive=(0, 1)), [_tx(2, 1, k=2)])
    assert service.counters()["tx_dead_sender"] == 1


def test_frames_beyond_the_declared_count_are_refused_before_the_model() -> None:
    """A second client on AUV 0's key adds frames its Command never declared: the lowest seqs declared are kept,
    the rest counted ``tx_undeclared``, and the run is the run without them (same deliveries, same draws)."""
    schedule = {k: _frames(k) for k in range(1, 12, 3)}
    extra = {k: [*frames, *(_tx(0, 100 + i, k) for i in range(5))] for k, frames in schedule.items()}
    plain = ChannelService(_scenario(pdr=0.65), np.random.default_rng(4))
    flooded = ChannelService(_scenario(pdr=0.65), np.random.default_rng(4))
    a = _run(plain, schedule, ticks=30)
    b = []
    for k in range(30):  # declared as in the plain run: two frames per AUV and tick
        expected = {x: sum(1 for t in schedule.get(k - 1, []) if t.auv == x) for x in (0, 1, 2)}
        b.append(flooded.on_tick(_tick(k, expected), list(extra.get(k - 1, []))))
    assert a == b
    assert flooded.counters()["tx_undeclared"] == 5 * len(schedule) and plain.counters()["tx_undeclared"] == 0


def test_unknown_sender_is_counted() -> None:
    service = ChannelService(_scenario(agents=2), np.random.default_rng(0))
    service.on_tick(_tick(0, alive=(0, 1)), [])
    service.on_tick(_tick(1, {2: 1}, alive=(0, 1)), [_tx(2, 0, k=0)])
    assert service.counters()["tx_unknown_sender"] == 1


def test_dead_recipient_gets_nothing_and_is_not_counted_in_done() -> None:
    service = ChannelService(_scenario(), np.random.default_rng(5))
    _run(service, {}, ticks=2)
    rx, _, _ = service.on_tick(_tick(2, {0: 1}), [_tx(0, 0, k=1)])
    assert rx == []
    rx, events, done = service.on_tick(_tick(3, {}, alive=(0, 1)), [])
    assert [r.auv for r in rx] == [1]
    assert done.rx_count == {0: 0, 1: 1}
    assert [(e.recipient, e.reason) for e in events if e.kind == "dropped"] == [(2, "recipient_dead")]


def test_positions_of_the_previous_tick_are_used() -> None:
    service = ChannelService(_scenario(), np.random.default_rng(2))
    service.on_tick(_tick(0), [])
    service.on_tick(_tick(1), [])
    moved = {0: (0.0, 0.0), 1: (3000.0, 0.0), 2: (0.0, 3000.0)}
    service.on_tick(_tick(2, {0: 1}, positions=moved), [_tx(0, 0, k=1)])
    rx, _, _ = service.on_tick(_tick(3, positions=moved), [])
    assert len(rx) == 2
    assert all(math.isclose(r.t_arrival - r.t_sent, 160 / 120 + 1.0, abs_tol=1e-12) for r in rx)


def test_tick_must_increase() -> None:
    service = ChannelService(_scenario(), np.random.default_rng(0))
    service.on_tick(_tick(4), [])
    with pytest.raises(ValueError, match="ChannelTick.tick must increase"):
        service.on_tick(_tick(4), [])
    assert service.last_tick == 4


def test_pdr_sets_the_delivered_fraction() -> None:
    service = ChannelService(_scenario(pdr=0.65, mode="aloha"), np.random.default_rng(11))
    delivered = sent_links = 0
    for k in range(1, 2001):
        rx, _, _ = service.on_tick(_tick(k, {0: 1} if k > 1 else {}), [_tx(0, k, k=k - 1, nbytes=2)])
        delivered += len(rx)
    sent_links = 2 * service.counters()["sent"]
    assert abs(delivered / sent_links - 0.65) < 0.03


class _Node:
    """A ChannelNode on an InMemoryBus, with everything it publishes collected."""

    def __init__(self, tick_timeout_s: float = 0.2) -> None:
        scenario = scenario_from_dict(
            {
                "agents": {"count": 3},
                "run": {"tick_s": TICK_S, "tick_timeout_s": tick_timeout_s, "seed": 4},
                "channel": {"pdr": 1.0},
            }
        )
        self.bus = InMemoryBus()
        self.node = ChannelNode(self.bus, scenario, seed=4, stats_every=1)
        self.out: list[tuple[str, object]] = []
        self.bus.subscribe(wire.all_modem_tx(), self.node.on_tx)
        self.bus.subscribe(wire.channel_tick(), self.node.on_tick_message)
        self.bus.subscribe(wire.channel_done(), lambda k, p: self.out.append((k, decode(p))))
        self.bus.subscribe(wire.all_modem_rx(), lambda k, p: self.out.append((k, decode(p))))
        self.stop = threading.Event()

    def tick(self, msg: ChannelTick) -> wire.ChannelDone:
        self.bus.publish(wire.channel_tick(), encode(msg))
        assert self.node.process_next(self.stop)
        return [m for _, m in self.out if isinstance(m, wire.ChannelDone)][-1]


def test_node_runs_ticks_and_survives_malformed_input() -> None:
    n = _Node()
    n.tick(_tick(0))
    n.bus.publish(wire.modem_tx(0), b"\x93garbage")
    n.bus.publish(wire.modem_tx(0), encode(_tick(3)))
    n.bus.publish(wire.modem_tx(1), encode(_tx(0, 0, k=0)))
    n.bus.publish(wire.modem_tx(0), encode(_tx(0, 1, k=0)))
    n.tick(_tick(1, {0: 1}))
    done = n.tick(_tick(2))
    counts = n.node.counters()
    assert counts["decode_errors"] == 2 and counts["tx_forged_source"] == 1
    assert counts["sent"] == 1 and counts["tick_timeouts"] == 0
    assert done.rx_count == {0: 0, 1: 1, 2: 1}
    assert sorted(k for k, m in n.out if isinstance(m, wire.ModemRx)) == [wire.modem_rx(1), wire.modem_rx(2)]
    assert n.bus.callback_errors == 0


def test_node_waits_bounded_for_missing_frames_and_ignores_late_ones() -> None:
    n = _Node(tick_timeout_s=0.2)
    n.tick(_tick(0))
    done = n.tick(_tick(1, {0: 1}))
    assert done.tick == 1 and n.node.counters()["tick_timeouts"] == 1
    n.bus.publish(wire.modem_tx(0), encode(_tx(0, 0, k=0)))
    assert n.node.counters()["tx_late"] == 1


def test_node_repeats_done_for_a_repeated_tick_and_restarts_on_an_older_one() -> None:
    n = _Node()
    first = n.tick(_tick(0))
    n.tick(_tick(1))
    again = n.tick(_tick(1))
    assert again.tick == 1 and n.node.counters()["tick_repeats"] == 1
    restarted = n.tick(_tick(0))
    assert restarted == first
    assert n.node.counters()["world_restarts"] == 1


def test_node_intake_is_bounded_and_refuses_replays_and_future_frames() -> None:
    n = _Node()
    n.tick(_tick(0))
    n.tick(_tick(1))
    budget_bytes = n.node.service.model.max_frame_bits // 8
    n.bus.publish(wire.modem_tx(0), encode(_tx(0, 1, k=1, nbytes=budget_bytes)))
    n.bus.publish(wire.modem_tx(0), encode(_tx(0, 2, k=1, nbytes=2)))
    n.bus.publish(wire.modem_tx(0), b"\x00" * (n.node.max_tx_bytes + 1))
    n.bus.publish(wire.modem_tx(1), encode(_tx(1, 1, k=2)))
    n.bus.publish(wire.modem_tx(1), encode(_tx(1, 1, k=1)))
    n.bus.publish(wire.modem_tx(1), encode(_tx(1, 1, k=1)))
    for seq in range(2, 40):
        n.bus.publish(wire.modem_tx(2), encode(_tx(2, seq, k=1, nbytes=0)))
    c = n.node.counters()
    assert c["tx_over_budget"] == 1 and c["decode_errors"] == 0, "the oversize message, before it is decoded"
    assert c["tx_future"] == 1 and c["tx_repeated"] == 1
    assert c["tx_queue_full"] == 38 - 16
    n.tick(_tick(2, {0: 1, 1: 1, 2: 16}))
    c = n.node.counters()
    assert c["tx_over_budget"] == 2, "AUV 0's second frame of the tick no longer fits the slot budget"
    assert c["tx_received"] == 1 + 1 + 16
    n.tick(_tick(0))
    n.bus.publish(wire.modem_tx(1), encode(_tx(1, 1, k=0)))
    assert n.node.counters()["tx_repeated"] == 1, "after a world restart, tick 0 is not a repeat"
