"""``auv-swarm channel`` / ``python -m channel_sim``: the acoustic channel emulator process.

A thin zenoh shell around :class:`channel_sim.service.ChannelService`: it buffers
every AUV's ``ModemTx`` by tick, and on ``ChannelTick(k)`` waits (at most half of
``run.tick_timeout_s`` of wall clock) until it holds the ``tx_expected`` frames of
tick k-1, runs the tick, and publishes the ``ModemRx`` to each recipient, the
``PacketEvent`` log and ``ChannelDone(k)``. Malformed messages are counted and
logged, never fatal. A repeated ``ChannelTick(k)`` (a world retrying) gets the same
``ChannelDone(k)`` again; an older tick means the world restarted its mission and
the channel starts afresh.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import threading
import time
from collections import defaultdict, deque

from auv_swarm.bus import shell
from auv_swarm.bus.bus import Bus
from auv_swarm.bus.identity import Gate
from auv_swarm.bus.lifeline import Lifeline, parent_from_env
from auv_swarm.channel_sim.model import DROP_REASONS
from auv_swarm.channel_sim.service import SOURCE, ChannelService
from auv_swarm.contract import rng, wire
from auv_swarm.contract.config import Scenario
from auv_swarm.contract.usage import plain_description
from auv_swarm.contract.wire import ChannelDone, ChannelStats, ChannelTick, DecodeError, ModemTx

log = logging.getLogger("channel")

NODE_COUNTERS = (
    "decode_errors",
    "tx_late",
    "tx_over_budget",
    "tx_queue_full",
    "tx_repeated",
    "tx_foreign_session",
    "tx_quarantined",
    "tick_timeouts",
    "tick_repeats",
    "world_restarts",
)
"""Counters of the process shell, published with the service's in ChannelStats (and the intake gate's
drops by reason as ``tx_<reason>``, see ``bus.identity.REASONS``)."""

MAX_TICKS_AHEAD = 0
"""A frame may be stamped at most this many ticks after the last processed one: an AUV answers tick k,
which the channel has processed by then, with frames of tick k, so a genuine frame is never ahead.
Later ones are rejected (``tx_future``) before they could make the sender's next frames look replayed."""

MAX_QUEUED_PER_AUV = 16
"""Frames held per AUV while they wait for their tick (an AUV sends one per slot): the lowest ``seq`` are kept,
whatever order they came in, and the others are ``tx_queue_full``."""

FRAME_OVERHEAD_BYTES = 256
"""Bytes a ModemTx may hold besides its payload; a larger message is rejected before it is decoded."""

LEDGER_COUNTERS = (
    "sent",
    "delivered",
    "in_flight",
    "tx_expected",
    "tx_lost_restart",
    *(f"dropped_{r}" for r in DROP_REASONS),
)
"""The counters a frame's fate moves. A tick that moved any of them publishes ChannelStats before its
ChannelDone (besides every ``stats_every`` ticks), so the last stats of a channel process that is killed
stand for every tick the world saw it finish: the run's books (``results.channel_books``) then know
which frames died with it."""

TX_WAIT_FRACTION = 0.5
"""The channel waits at most this fraction of ``run.tick_timeout_s`` for missing frames, so that its
answer still reaches a world that waits the full timeout for ``ChannelDone``."""


class ChannelNode:
    """The channel process's state: tx buffer by tick, pending ticks, and the service.

    Bus callbacks only decode and buffer (:meth:`on_tx`, :meth:`on_tick_message`);
    :meth:`process_next` runs on the main thread and does the waiting. With
    ``encoded=False`` (the in-process swarm) the bus carries decoded messages both
    ways: :meth:`accept_tx` and :meth:`accept_tick` are the callbacks, and what the
    node publishes is the message object itself.
    """

    def __init__(
        self, bus: Bus, scenario: Scenario, seed: int, stats_every: int = 10, encoded: bool = True, epoch: int = 0
    ) -> None:
        if stats_every < 1:
            raise ValueError(f"stats_every must be >= 1 tick, got {stats_every}")
        self.bus = bus
        self.encoded = encoded
        self.scenario = scenario
        self.seed = seed
        self.stats_every = stats_every
        self.timeout_s = TX_WAIT_FRACTION * scenario.run.tick_timeout_s
        self.service = ChannelService(scenario, rng.stream(seed, "channel"))
        self.counts = dict.fromkeys(NODE_COUNTERS, 0)
        self.epoch = epoch
        self.gate = Gate("channel", log=log.warning)
        self.max_tx_bytes = math.ceil(self.service.model.max_frame_bits / 8) + FRAME_OVERHEAD_BYTES
        self._cond = threading.Condition()
        self._txs: dict[int, dict[tuple[int, int], tuple[ModemTx, str | None]]] = defaultdict(dict)
        self._sessions: dict[int, str] = {}
        self._refused: frozenset[int] = frozenset()
        self._late: set[int] = set()
        """AUVs whose declared frames did not come within the wait once: not waited for again until they do."""
        self._ticks: deque[ChannelTick] = deque()
        self._t_s = 0.0
        self._last_done: ChannelDone | None = None
        self._ledger: tuple[int, ...] = ()

    def on_tx(self, key: str, payload: bytes, session: str | None = None) -> None:
        """Bus callback for ``<prefix>/auv/*/modem/tx`` (``session``: the sender's bus session, if the bus has
        them): decode and buffer by tick.

        A message that could not hold a frame of the slot budget is rejected before it is decoded
        (over zenoh, before it is even copied: ``max_bytes`` of ``ZenohBus.subscribe``).
        """
        if len(payload) > self.max_tx_bytes:
            self._reject(key, "tx_over_budget", f"{len(payload)} bytes")
            return
        try:
            msg = wire.decode(payload, ModemTx)
        except DecodeError as exc:
            self._count_bad(key, exc)
            return
        self.accept_tx(key, msg, session)

    def accept_tx(self, key: str, msg: ModemTx, session: str | None = None) -> None:
        """Buffer a decoded ``ModemTx`` published on ``key`` (from bus session ``session``) under its tick.

        Dropped and counted: a frame the intake gate refuses (identity from the key), one whose tick was
        already processed (``tx_late``) or lies more than :data:`MAX_TICKS_AHEAD` ticks ahead (``tx_future``),
        one of a quarantined AUV (``tx_quarantined``) or of another session than the one the world bound the
        AUV to (``tx_foreign_session``, see ``wire.ChannelTick``), a second one of an (AUV, seq) held
        (``tx_repeated``), and one beyond the :data:`MAX_QUEUED_PER_AUV` lowest ``seq`` of that AUV
        (``tx_queue_full``). What the channel holds is thus bounded per AUV, and which frames it holds does not
        depend on the order they came in: a frame that arrives first cannot take another's place.
        """
        if not self.gate.admit(key, msg, max_tick=(self.service.last_tick or 0) + MAX_TICKS_AHEAD, track=False):
            return
        with self._cond:
            reason = self._intake(msg, session)
            if reason is None:
                self._cond.notify_all()
        if reason is not None:
            self._reject(key, reason, f"frame of tick {msg.tick}, seq {msg.seq}, {8 * len(msg.payload)} bits")

    def _intake(self, msg: ModemTx, session: str | None) -> str | None:
        """Hold ``msg`` (lock held); the reason it is refused, or None."""
        last = self.service.last_tick
        if last is not None and msg.tick < last:
            return "tx_late"
        if msg.auv in self._refused:
            return "tx_quarantined"
        bound = self._sessions.get(msg.auv)
        if bound is not None and session != bound:
            return "tx_foreign_session"
        held = self._txs[msg.tick]
        if (msg.auv, msg.seq) in held:
            return "tx_repeated"
        mine = [seq for auv, seq in held if auv == msg.auv]
        if len(mine) >= MAX_QUEUED_PER_AUV:
            highest = max(mine)
            if msg.seq > highest:
                return "tx_queue_full"
            del held[(msg.auv, highest)]
            self.counts["tx_queue_full"] += 1
        held[(msg.auv, msg.seq)] = (msg, session)
        return None

    def _reject(self, key: str, reason: str, detail: str) -> None:
        with self._cond:
            self.counts[reason] += 1
            n = self.counts[reason]
        if n == 1 or n % 1000 == 0:
            log.warning("%s on %s (%s); %d so far", reason, key, detail, n)

    def _pop_tick(self, tick: int, msg: ChannelTick) -> list[ModemTx]:
        """Take the frames held for ``tick`` out of the buffer (lock held): by (AUV, seq), those of the session
        ``msg`` names for their AUV and not of a refused one, as many as fit the slot budget (``tx_over_budget``)."""
        bits: dict[int, int] = defaultdict(int)
        out = []
        for (auv, _seq), (tx, session) in sorted(self._txs.pop(tick, {}).items()):
            bound = msg.sessions.get(auv)
            if auv in msg.refused:
                self.counts["tx_quarantined"] += 1
            elif bound is not None and session != bound:
                self.counts["tx_foreign_session"] += 1
            elif bits[auv] + 8 * len(tx.payload) > self.service.model.max_frame_bits:
                self.counts["tx_over_budget"] += 1
            else:
                bits[auv] += 8 * len(tx.payload)
                out.append(tx)
        return out

    def on_tick_message(self, key: str, payload: bytes) -> None:
        """Bus callback for ``<prefix>/channel/tick``: decode and queue."""
        try:
            msg = wire.decode(payload, ChannelTick)
        except DecodeError as exc:
            self._count_bad(key, exc)
            return
        self.accept_tick(key, msg)

    def accept_tick(self, _key: str, msg: ChannelTick) -> None:
        """Queue a decoded ``ChannelTick`` (its sessions and refused AUVs apply to the frames that come next)."""
        with self._cond:
            self._sessions = dict(msg.sessions)
            self._refused = frozenset(msg.refused)
            self._ticks.append(msg)
            self._cond.notify_all()

    def _count_bad(self, key: str, exc: DecodeError) -> None:
        with self._cond:
            self.counts["decode_errors"] += 1
            n = self.counts["decode_errors"]
        if n <= 10 or n % 100 == 0:
            log.warning("malformed message on %s dropped (%d so far): %s", key, n, exc)

    def _missing(self, msg: ChannelTick) -> list[int]:
        """AUVs waited for whose declared frames of tick k-1 are not all held yet."""
        held: dict[int, int] = defaultdict(int)
        for auv, _seq in self._txs.get(msg.tick - 1, {}):
            held[auv] += 1
        return [a for a, n in msg.tx_expected.items() if held[a] < n and a not in self._late]

    def process_next(self, stop: threading.Event, poll_s: float = 0.1) -> bool:
        """Wait for the next ChannelTick (until ``stop``), gather its frames, run it and publish; True if one ran."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._ticks or stop.is_set(), timeout=poll_s) or not self._ticks:
                return False
            msg = self._ticks.popleft()
            repeat = msg.tick == self.service.last_tick
            deadline = time.monotonic() + self.timeout_s
            while not repeat and self._missing(msg) and not stop.is_set():
                left = deadline - time.monotonic()
                if left <= 0.0:
                    self._timed_out(msg)
                    break
                self._cond.wait(timeout=min(left, poll_s))
            txs = [] if repeat else self._pop_tick(msg.tick - 1, msg)
            for tick in [t for t in self._txs if t < msg.tick - 1]:
                self.counts["tx_late"] += len(self._txs.pop(tick))
            got = defaultdict(int)
            for tx in txs:
                got[tx.auv] += 1
            self._late -= {a for a in self._late if got[a] >= msg.tx_expected.get(a, 0)}
        self._run_tick(msg, txs)
        return True

    def _timed_out(self, msg: ChannelTick) -> None:
        """The wait for tick k-1's declared frames ran out (lock held): the AUVs still missing some are not waited
        for again until a tick brings all they declared, so frames declared and never sent (a stall) cost the
        wait once."""
        missing = self._missing(msg)
        self.counts["tick_timeouts"] += 1
        self._late.update(missing)
        log.warning(
            "tick %d: proceeding without all expected frames of tick %d (AUV %s; not waited for again until they "
            "send what they declare)",
            msg.tick,
            msg.tick - 1,
            ", ".join(map(str, missing)),
        )

    def _run_tick(self, msg: ChannelTick, txs: list[ModemTx]) -> None:
        last = self.service.last_tick
        if last is not None and msg.tick == last and self._last_done is not None:
            self.counts["tick_repeats"] += 1
            log.info("ChannelTick %d repeated: ChannelDone published again", msg.tick)
            self._publish(wire.channel_done(), self._last_done)
            return
        if last is not None and msg.tick < last:
            self.counts["world_restarts"] += 1
            log.warning("ChannelTick %d after tick %d: the world restarted, the channel starts afresh", msg.tick, last)
            self.service = ChannelService(self.scenario, rng.stream(self.seed, "channel"))
            self.gate.forget()
            with self._cond:
                self.counts["tx_late"] += sum(len(frames) for frames in self._txs.values())
                self._txs.clear()
                self._late.clear()
        refused_before = self.service.model.counters["dropped_tx_backlog_full"]
        rx, events, done = self.service.on_tick(msg, txs)
        refused = self.service.model.counters["dropped_tx_backlog_full"]
        if refused // 1000 > refused_before // 1000 or (refused and not refused_before):
            senders = sorted({e.sender for e in events if e.reason == "tx_backlog_full"})
            log.warning(
                "tx_backlog_full: tick %d refused frames of AUV %s (queued airtime at its limit of %.2f s); %d so far",
                msg.tick - 1,
                ", ".join(map(str, senders)),
                self.service.model.backlog_s,
                refused,
            )
        for m in rx:
            self._publish(wire.modem_rx(m.auv), m)
        for e in events:
            self._publish(wire.channel_events(), e)
        self._t_s = msg.t_s
        counters = self.service.counters()
        ledger = tuple(counters[k] for k in LEDGER_COUNTERS)
        if counters["ticks"] % self.stats_every == 0 or ledger != self._ledger:
            self.publish_stats()
        self._publish(wire.channel_done(), done)
        self._last_done = done

    def counters(self) -> dict[str, int]:
        """Service counters plus the shell's (NODE_COUNTERS), the gate's and ``epoch``, the process's start (µs
        since the Unix epoch; 0 in process): counters restart with a restarted channel, so run totals sum the last
        stats of every epoch."""
        gate = {f"tx_{reason}": n for reason, n in self.gate.counts.items() if reason != "decode_error"}
        with self._cond:
            return {**self.service.counters(), **self.counts, **gate, "epoch": self.epoch}

    def publish_stats(self) -> None:
        """Publish the counters as ChannelStats on ``<prefix>/channel/stats``."""
        counters = self.counters()
        self._ledger = tuple(counters[k] for k in LEDGER_COUNTERS)
        stats = ChannelStats(counters=counters, t_s=self._t_s, source=SOURCE)
        self._publish(wire.channel_stats(), stats)

    def _publish(self, key: str, msg: wire.Message) -> None:
        self.bus.publish(key, wire.encode(msg) if self.encoded else msg)


def run(scenario: Scenario, args: argparse.Namespace, stats_every: int = 10) -> int:
    """Serve as the channel on the zenoh router at ``args.router`` until the mission ends (see
    ``bus.lifeline``) or SIGTERM/SIGINT."""
    from auv_swarm.bus import zbus

    stop = zbus.shutdown_event()
    router = args.router
    lifeline = Lifeline(scenario.run.grace_s, parent_from_env())
    with shell.connect(args, "channel") as bus:
        node = ChannelNode(bus, scenario, scenario.run.seed, stats_every, epoch=time.time_ns() // 1000)
        bus.subscribe(wire.all_modem_tx(), node.on_tx, max_bytes=node.max_tx_bytes, sender=True)
        bus.subscribe(wire.channel_tick(), node.on_tick_message)
        lifeline.attach(bus, stop, "channel")
        bus.declare_liveliness(wire.liveliness_component("channel"))
        print(f"channel ready on {router} (scenario {scenario.name}, seed {scenario.run.seed})", flush=True)
        while not stop.is_set():
            node.process_next(stop)
        node.publish_stats()
        print(f"channel stopped: {node.counters()}", flush=True)
    return lifeline.shell_exit_code(stop)


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm channel``."""
    parser = argparse.ArgumentParser(prog="auv-swarm channel", description=plain_description(__doc__))
    shell.add_common_args(parser)
    parser.add_argument("--stats-every", type=int, default=10, help="publish ChannelStats every N ticks (and at exit)")
    args = parser.parse_args(argv)
    if shell.handle_info_flags(args, "channel", sections=("channel", "run")):
        return 0
    if args.stats_every < 1:
        parser.error(f"--stats-every must be >= 1, got {args.stats_every}")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s channel %(levelname)s %(message)s", stream=sys.stderr)
    return run(shell.scenario_from_args(args), args, args.stats_every)


if __name__ == "__main__":
    sys.exit(main())
