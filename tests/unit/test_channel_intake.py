"""The channel's intake (issue 44): which frames it holds never depends on the order they came in, only the bound
session's frames are taken, a quarantined AUV's none, and frames declared and never sent cost the wait once."""

from __future__ import annotations

import random

from auv_swarm.contract import wire
from auv_swarm.contract.wire import ModemTx, encode
from tests.unit.test_channel_service import _Node, _tick, _tx

FLOOD_SEQ0 = 1_000_000_000


def _flood(k: int, n: int = 60) -> list[ModemTx]:
    return [_tx(1, FLOOD_SEQ0 + i, k=k, nbytes=8) for i in range(n)]


def _on_air(frames: list[ModemTx], sessions: dict[int, str] | None = None, via: dict[int, str] | None = None):
    """Frames of tick 1 handed to a node in the given order (each from session ``via[seq]``; the world bound the
    AUVs to ``sessions``): the frames the node handed the channel model at tick 2 (sender, seq), and its counters."""
    n = _Node()
    handed: list[tuple[int, int]] = []
    on_tick = n.node.service.on_tick

    def spy(msg: wire.ChannelTick, txs: list[ModemTx]):
        handed.extend((tx.auv, tx.seq) for tx in txs)
        return on_tick(msg, txs)

    n.node.service.on_tick = spy
    n.tick(_tick(0))
    n.tick(wire.ChannelTick(**{**_tick(1, {}).__dict__, "sessions": sessions or {}}))
    handed.clear()
    for tx in frames:
        n.node.accept_tx(wire.modem_tx(tx.auv), tx, (via or {}).get(tx.seq))
    n.tick(wire.ChannelTick(**{**_tick(2, {0: 1, 1: 1}).__dict__, "sessions": sessions or {}}))
    return sorted(handed), n.node.counters()


def test_a_flood_before_or_after_the_frame_keeps_the_same_frames() -> None:
    own = [_tx(0, 1, k=1), _tx(1, 7, k=1)]
    after, c_after = _on_air(own + _flood(1))
    before, c_before = _on_air(_flood(1) + own)
    shuffled = own + _flood(1)
    random.Random(3).shuffle(shuffled)
    mixed, _ = _on_air(shuffled)
    assert after == before == mixed and after[:2] == [(0, 1), (1, 7)]
    assert c_before["tx_queue_full"] == c_after["tx_queue_full"] == 60 + 1 - 16
    assert c_before["tx_undeclared"] == c_after["tx_undeclared"] == 15 - c_after["tx_over_budget"]
    assert c_before["sent"] == c_after["sent"] == 2, "what each AUV declared, AUV 1's own frame among them"


def test_only_the_bound_session_s_frames_are_taken() -> None:
    real, impostor = "aa11", "bb22"
    frames = [_tx(1, 3, k=1, nbytes=150), _tx(1, 2, k=1), _tx(0, 1, k=1)]
    handed, c = _on_air(frames, sessions={1: real}, via={3: impostor, 2: real})
    assert handed == [(0, 1), (1, 2)]
    assert c["tx_foreign_session"] == 1 and c["sent"] == 2


def test_a_quarantined_auv_s_frames_are_refused_at_intake_and_at_its_tick() -> None:
    n = _Node()
    n.tick(_tick(0))
    n.bus.publish(wire.modem_tx(1), encode(_tx(1, 1, k=0)))
    n.tick(wire.ChannelTick(**{**_tick(1, {1: 1}).__dict__, "refused": (1,)}))
    n.bus.publish(wire.modem_tx(1), encode(_tx(1, 2, k=1)))
    n.tick(wire.ChannelTick(**{**_tick(2, {}).__dict__, "refused": (1,)}))
    c = n.node.counters()
    assert c["tx_quarantined"] == 2 and c["sent"] == 0 and c["tick_timeouts"] == 0


def test_frames_declared_and_never_sent_cost_the_wait_once() -> None:
    n = _Node(tick_timeout_s=0.2)
    n.tick(_tick(0))
    for k in range(1, 8):
        n.bus.publish(wire.modem_tx(0), encode(_tx(0, k, k=k - 1)))
        n.tick(_tick(k, {0: 1, 1: 16}))
    c = n.node.counters()
    assert c["tick_timeouts"] == 1, c
    assert c["sent"] == 7 and c["tx_missing"] == 7 * 16
