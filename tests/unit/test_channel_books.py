"""The channel's books over a run (results.channel_books): epochs added up, links lost with a killed channel
process counted as ``channel_restart``, and ``sent * (n - 1) == delivered + link drops + in flight`` across it."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from auv_swarm.channel_sim.model import DROP_REASONS
from auv_swarm.channel_sim.model import FRAME_REASONS as MODEL_FRAME_REASONS
from auv_swarm.channel_sim.service import ChannelService
from auv_swarm.contract.config import scenario_from_dict
from auv_swarm.contract.wire import ChannelTick, ModemTx
from auv_swarm.results.channel_books import FRAME_REASONS, frame_balance, link_balance, run_totals

TICK_S = 2.0
AGENTS = (0, 1, 2, 3)
POSITIONS = {0: (0.0, 0.0), 1: (1500.0, 0.0), 2: (0.0, 1500.0), 3: (1500.0, 1500.0)}


def _service(seed: int) -> ChannelService:
    scenario = scenario_from_dict(
        {"agents": {"count": len(AGENTS)}, "run": {"tick_s": TICK_S}, "channel": {"mode": "aloha", "pdr": 0.6}}
    )
    return ChannelService(scenario, np.random.default_rng(seed))


def _frames(k: int) -> list[ModemTx]:
    """Every AUV sends one 20-byte frame at every even tick: airtime 1.33 s + propagation 1-1.41 s > one tick, so
    the frames submitted at a tick are still on the air when the next tick ends."""
    return [
        ModemTx(tick=k, auv=a, seq=k, payload=bytes([a, k % 256]) * 10, t_s=k * TICK_S, source=f"auv/{a}")
        for a in AGENTS
        if k % 2 == 0
    ]


def _tick(service: ChannelService, k: int, got: list[ModemTx], sent: list[ModemTx]) -> None:
    expected = {a: sum(1 for f in sent if f.auv == a) for a in AGENTS}
    service.on_tick(
        ChannelTick(tick=k, tx_expected=expected, positions=POSITIONS, alive=AGENTS, t_s=k * TICK_S, source="world"),
        got,
    )


def test_run_totals_adds_epochs_and_counts_what_died_with_a_process() -> None:
    old = {"epoch": 5, "sent": 10, "delivered": 12, "dropped_random_loss": 5, "in_flight": 3, "tx_expected": 10}
    new = {
        "epoch": 9,
        "sent": 4,
        "delivered": 6,
        "dropped_random_loss": 2,
        "in_flight": 2,
        "tx_expected": 6,
        "tx_lost_restart": 2,
    }
    totals = run_totals([old, new], n_agents=3)
    # the old process's 3 links on the air, and the 2 frames it held (2 links each), died with it
    assert totals["dropped_channel_restart"] == 3 + 2 * 2
    assert totals["sent"] == 10 + 4 + 2 and totals["in_flight"] == totals["in_flight_at_end"] == 2
    assert totals["delivered"] == 18 and totals["epochs"] == 2 and "epoch" not in totals
    dropped = {"random_loss": 7, "channel_restart": 7}
    assert link_balance(dropped, totals["sent"], totals["delivered"], 2, n_agents=3) == (32, 18 + 14 + 2)
    assert frame_balance(totals) == (16, 16)
    one = run_totals([old], n_agents=3)
    assert one["dropped_channel_restart"] == 0 and one["in_flight_at_end"] == 3
    with pytest.raises(ValueError, match="n_agents"):
        run_totals([old], n_agents=0)


@pytest.mark.parametrize("kill_after", [3, 4, 7])
def test_books_balance_across_a_channel_killed_with_frames_on_the_air_and_in_hand(kill_after: int) -> None:
    """The old service runs ticks 0..kill_after and is dropped (kill -9): the frames on the air, and the frames the
    AUVs sent at tick kill_after (in its hands, never submitted), are lost; a fresh service takes over at the
    next tick, told of those frames, without them."""
    old, new = _service(1), _service(1)
    for k in range(kill_after + 1):
        _tick(old, k, _frames(k - 1), _frames(k - 1))
    epochs = [old.counters()]
    assert old.counters()["in_flight"] > 0 or not _frames(kill_after - 1)
    last = kill_after + 12
    for k in range(kill_after + 1, last + 1):
        sent = _frames(k - 1)
        _tick(new, k, [] if k == kill_after + 1 else sent, sent)
    epochs.append(new.counters())
    totals = run_totals(epochs, n_agents=len(AGENTS))
    lost = epochs[0]["in_flight"] + (len(AGENTS) - 1) * len(_frames(kill_after))
    assert totals["dropped_channel_restart"] == lost
    assert epochs[1]["tx_lost_restart"] == len(_frames(kill_after)) and epochs[1]["tx_missing"] == 0
    dropped = {k[len("dropped_") :]: v for k, v in totals.items() if k.startswith("dropped_")}
    sent_links, accounted = link_balance(dropped, totals["sent"], totals["delivered"], totals["in_flight_at_end"], 4)
    assert sent_links == accounted
    senders, channel = frame_balance(totals)
    assert senders == channel == sum(len(_frames(k)) for k in range(last))


def test_the_channel_publishes_its_counters_before_the_done_of_every_tick_that_moved_a_frame() -> None:
    """So the last counters of a process killed after any ChannelDone stand for every tick the world saw it finish."""
    from auv_swarm.bus.bus import InMemoryBus
    from auv_swarm.channel_sim.node import ChannelNode
    from auv_swarm.contract import wire

    scenario = scenario_from_dict({"agents": {"count": 4}, "run": {"tick_s": TICK_S}, "channel": {"mode": "aloha"}})
    bus = InMemoryBus()
    node = ChannelNode(bus, scenario, seed=3, stats_every=1000)
    order: list[tuple[str, object]] = []
    for key in (wire.channel_stats(), wire.channel_done()):
        bus.subscribe(key, lambda k, p: order.append((k, wire.decode(p))))
    bus.subscribe(wire.all_modem_tx(), node.on_tx)
    bus.subscribe(wire.channel_tick(), node.on_tick_message)
    stop = threading.Event()
    for k in range(10):
        sent = _frames(k - 1)
        for f in sent:
            bus.publish(wire.modem_tx(f.auv), wire.encode(f))
        expected = {a: sum(1 for f in sent if f.auv == a) for a in AGENTS}
        tick = ChannelTick(
            tick=k, tx_expected=expected, positions=POSITIONS, alive=AGENTS, t_s=k * TICK_S, source="world"
        )
        bus.publish(wire.channel_tick(), wire.encode(tick))
        assert node.process_next(stop)
        last_stats = [m for _, m in order if isinstance(m, wire.ChannelStats)][-1:]
        assert isinstance(order[-1][1], wire.ChannelDone) and order[-1][1].tick == k
        if k >= 1:  # every tick from 1 on submits or delivers frames
            assert last_stats and last_stats[0].counters == node.counters(), f"tick {k}: the stats lag its Done"


def test_the_books_know_the_models_per_frame_reasons() -> None:
    assert set(FRAME_REASONS) == set(MODEL_FRAME_REASONS) and set(MODEL_FRAME_REASONS) <= set(DROP_REASONS)
