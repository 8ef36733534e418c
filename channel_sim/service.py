"""The channel's lockstep protocol over wire messages: drives :class:`ChannelModel` one world tick at a time.

Pure (no zenoh, no clock): the zenoh node and the in-process runner both use it.

Protocol of tick k (times in s of sim time, positions in m, inertial frame):

1. The world publishes ``ChannelTick(k)`` with the true positions at t_k, the
   alive set, and ``tx_expected[a]``: how many ``ModemTx`` AUV ``a`` published
   at tick k-1 (the count comes back to the world in each agent's ``Command``).
2. :meth:`ChannelService.on_tick` submits those tick-(k-1) transmissions to the
   model at t_{k-1} with the positions of tick k-1 (remembered from the previous
   ``ChannelTick``), in canonical order (sorted by (auv, seq)), then delivers
   every reception whose last bit has arrived by t_k.
3. It returns the ``ModemRx`` (one per delivered reception, stamped tick k), the
   ``PacketEvent`` log, and ``ChannelDone(k)`` with the number of receptions
   delivered to each alive AUV (zeros included): the world forwards that count
   to each agent in ``Nav.rx_expected`` and the agent waits for as many.

The result does not depend on the order in which the transmissions arrived.
"""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.channel_sim.model import ChannelEvent, ChannelModel, Reception
from auv_swarm.contract import rng as rngmod
from auv_swarm.contract.config import Scenario
from auv_swarm.contract.ocean import OceanModel, slot_frame_bits
from auv_swarm.contract.tltable import ocean_for
from auv_swarm.contract.wire import ChannelDone, ChannelTick, ModemRx, ModemTx, PacketEvent

SOURCE = "channel"
SERVICE_COUNTERS = (
    "ticks",
    "tx_received",
    "tx_missing",
    "tx_duplicate",
    "tx_stale",
    "tx_unknown_sender",
    "tx_dead_sender",
    "tick_gaps",
    "tx_expected",
    "tx_lost_restart",
    "tx_undeclared",
)
"""Counters of the protocol layer, next to the model's (see :meth:`ChannelService.counters`).

``tx_undeclared`` counts the frames of a tick beyond the number their sender declared for it (its ``Command``'s
``tx_count``, passed on in ``ChannelTick.tx_expected``): a genuine AUV declares every frame it sends, so the
extra ones come from a second client on its key (or a broken AUV) and are refused before the model (the lowest
``seq`` kept), so they take neither airtime nor random draws from the other AUVs' frames.

``tx_expected`` sums the senders' own counts (``ChannelTick.tx_expected``) over the ticks this service ran;
``tx_lost_restart`` counts the frames a service started mid-mission (a restarted channel process) was told of
on its first tick and never got: the previous process died holding them, or they were sent while no channel
was up (``tx_missing`` counts the frames missing on any other tick)."""


class ChannelService:
    """One channel emulator: a :class:`ChannelModel` (slot order ``scenario.slot_order``) behind the lockstep protocol.

    ``rng`` is the channel's random stream (``contract.rng.stream(seed, "channel")``);
    ``max_frame_bits`` defaults to the slot's budget (:func:`~auv_swarm.contract.ocean.slot_frame_bits`). ``ocean``: the scenario's physical ocean
    (default :func:`contract.tltable.ocean_for`, which reads its TL table); its Gilbert-Elliott draws come from
    the stream ``"channel-burst"``.
    """

    def __init__(
        self,
        scenario: Scenario,
        rng: np.random.Generator,
        max_frame_bits: int | None = None,
        ocean: OceanModel | None = None,
    ) -> None:
        if ocean is None:
            ocean = ocean_for(scenario)
        bits = slot_frame_bits(scenario.channel, scenario.ocean) if max_frame_bits is None else max_frame_bits
        self.scenario = scenario
        self.tick_s = scenario.run.tick_s
        burst = rngmod.stream(scenario.run.seed, "channel-burst") if ocean is not None else None
        self.model = ChannelModel(scenario.channel, scenario.slot_order, rng, bits, ocean, burst)
        self._prev: ChannelTick | None = None
        self._killed: set[int] = set()
        self._counts = dict.fromkeys(SERVICE_COUNTERS, 0)

    @property
    def last_tick(self) -> int | None:
        """The tick of the last processed ``ChannelTick``, None before the first."""
        return None if self._prev is None else self._prev.tick

    def on_tick(self, msg: ChannelTick, txs: list[ModemTx]) -> tuple[list[ModemRx], list[PacketEvent], ChannelDone]:
        """Process ``ChannelTick(k)`` with the transmissions ``txs`` the AUVs published at tick k-1.

        Transmissions of another tick, from an AUV outside the slot order or not alive at
        tick k-1, repeating an (auv, seq) already seen this tick, or beyond the count their sender declared for
        tick k-1 (``msg.tx_expected``; ``tx_undeclared``) are ignored and counted. AUVs missing from
        ``msg.alive`` are killed in the model before delivery, so they receive nothing
        from tick k on; one back in ``msg.alive`` (a restarted AUV) is revived, with its slot. Raises ValueError if ``msg`` is not later than the previous tick.
        """
        prev = self._prev
        if prev is not None and (msg.tick <= prev.tick or msg.t_s < prev.t_s):
            raise ValueError(
                f"ChannelTick.tick must increase (and t_s not decrease): got tick {msg.tick} at {msg.t_s} s "
                f"after tick {prev.tick} at {prev.t_s} s"
            )
        self._counts["ticks"] += 1
        events: list[ChannelEvent] = []
        frames = self._canonical(msg, txs)
        if frames:
            t_prev, positions, alive = self._previous_state(msg)
            for frame in frames:
                if frame.auv not in alive or frame.auv in self._killed:
                    self._counts["tx_dead_sender"] += 1
                    continue
                events.extend(self.model.transmit(t_prev, frame.auv, frame.seq, frame.payload, positions, alive))
        for agent in self.model.agents:
            if agent not in msg.alive and agent not in self._killed:
                self.model.kill(agent)
                self._killed.add(agent)
            elif agent in msg.alive and agent in self._killed:
                self.model.revive(agent)
                self._killed.discard(agent)
        receptions, delivered = self.model.deliver_until(msg.t_s)
        events.extend(delivered)
        self._prev = msg
        rx = [self._modem_rx(msg, r) for r in receptions]
        rx_count = {a: 0 for a in msg.alive}
        for r in receptions:
            if r.recipient in rx_count:
                rx_count[r.recipient] += 1
        done = ChannelDone(tick=msg.tick, rx_count=rx_count, t_s=msg.t_s, source=SOURCE)
        return rx, [self._packet_event(e) for e in events], done

    def counters(self) -> dict[str, int]:
        """The model's counters (sent, delivered, deferred, dropped_<reason>), ``in_flight`` (links on the air now,
        a gauge: see :attr:`ChannelModel.in_flight`) and the protocol's (SERVICE_COUNTERS)."""
        return {**self.model.counters, "in_flight": self.model.in_flight, **self._counts}

    def _canonical(self, msg: ChannelTick, txs: list[ModemTx]) -> list[ModemTx]:
        """The tick-(k-1) transmissions sorted by (auv, seq, payload), without duplicates; counts the rest."""
        if msg.tick == 0:
            self._counts["tx_stale"] += len(txs)
            return []
        self._counts["tx_received"] += len(txs)
        kept: dict[tuple[int, int], ModemTx] = {}
        for tx in sorted(txs, key=lambda m: (m.auv, m.seq, m.payload)):
            if tx.tick != msg.tick - 1:
                self._counts["tx_stale"] += 1
            elif tx.auv not in self.model.agents:
                self._counts["tx_unknown_sender"] += 1
            elif (tx.auv, tx.seq) in kept:
                self._counts["tx_duplicate"] += 1
            else:
                kept[(tx.auv, tx.seq)] = tx
        got: dict[int, int] = {}
        declared: list[ModemTx] = []
        for (auv, _), tx in kept.items():
            got[auv] = got.get(auv, 0) + 1
            if got[auv] <= msg.tx_expected.get(auv, 0):
                declared.append(tx)
            else:
                self._counts["tx_undeclared"] += 1
        self._counts["tx_expected"] += sum(msg.tx_expected.values())
        missing = sum(max(0, n - got.get(a, 0)) for a, n in msg.tx_expected.items())
        self._counts["tx_lost_restart" if self._prev is None else "tx_missing"] += missing
        return declared

    def _previous_state(self, msg: ChannelTick) -> tuple[float, dict[int, tuple[float, float]], set[int]]:
        """(t_{k-1}, positions at k-1, alive at k-1); the current tick's state when tick k-1 was not seen."""
        prev = self._prev
        if prev is not None and prev.tick == msg.tick - 1:
            return prev.t_s, dict(prev.positions), set(prev.alive)
        self._counts["tick_gaps"] += 1
        t_prev = max(msg.t_s - self.tick_s, 0.0 if prev is None else prev.t_s)
        return t_prev, dict(msg.positions), set(msg.alive)

    @staticmethod
    def _modem_rx(msg: ChannelTick, r: Reception) -> ModemRx:
        return ModemRx(
            tick=msg.tick,
            auv=r.recipient,
            sender=r.sender,
            seq=r.seq,
            payload=r.payload,
            t_sent=r.t_sent,
            t_arrival=r.t_arrival,
            snr_db=r.snr_db,
            t_s=msg.t_s,
            source=SOURCE,
        )

    @staticmethod
    def _packet_event(e: ChannelEvent) -> PacketEvent:
        return PacketEvent(
            correlation_id=e.correlation_id,
            kind=e.kind,
            sender=e.sender,
            recipient=e.recipient,
            bits=e.bits,
            latency_s=e.latency_s,
            snr_db=None if e.snr_db is None or not math.isfinite(e.snr_db) else e.snr_db,
            reason=e.reason,
            t_s=max(e.t_s, 0.0),
            source=SOURCE,
        )
