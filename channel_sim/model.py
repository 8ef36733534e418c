"""Pure acoustic channel model: TDMA slots, airtime, propagation, delivery draws (eqs. 22-24).

The medium between the AUVs. Every frame a modem submits goes through a short chain
of yes/no checks (after MOOS-IvP's uFldNodeComms), and every frame that does not
reach a recipient is counted under exactly one reason of :data:`DROP_REASONS`.

Units and frames: times in seconds of simulated time, positions in metres in the
inertial frame, bit rate in bit/s, levels in dB. Time and the random generator are
passed in; the module has no clock, no I/O and no global random state.

Timeline of one frame from ``sender`` (docs/channel.md, "Airtime, propagation and latency"):

- ``t_start``: the first bit leaves the transducer (the submit time, or later if the
  modem is still busy with an earlier frame or the frame is deferred to the next slot);
- ``t_first = t_start + range / c``: the first bit reaches a recipient;
- ``t_arrival = t_start + bits / bit_rate + range / c``: the last bit reaches it, so the
  latency is exactly the airtime plus the propagation delay.

Checks, in order: oversize, transmit backlog and slot (per frame, at submit time); recipient dead,
SNR below the detection threshold DT (eqs. 22-24), random loss (per link, at submit
time); recipient killed since, half-duplex, collision (per link, at delivery time).

Under ``ocean.model = "physical"`` (an ``OceanModel`` given) the link SNR comes from the ocean's TL and noise,
the frame decodes with the modem's packet-error curve for its length (a failure is ``low_snr``), ``channel.pdr``
is an extra random loss (``random_loss``), an optional Gilbert-Elliott chain per link adds ``burst_loss`` on its
own random stream, and the propagation delay is range over the profile's mean sound speed (docs/ocean.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from auv_swarm.contract.acoustics import snr_db_cfg
from auv_swarm.contract.config import ChannelConfig, ConfigError
from auv_swarm.contract.modem import GilbertElliott
from auv_swarm.contract.ocean import OceanModel

DROP_REASONS = (
    "random_loss",
    "low_snr",
    "outside_slot",
    "oversize",
    "tx_backlog_full",
    "collision",
    "half_duplex",
    "recipient_dead",
    "burst_loss",
)
"""Every reason a frame can fail to reach a recipient; each has a ``dropped_<reason>`` counter."""

FRAME_REASONS = ("oversize", "tx_backlog_full", "outside_slot")
"""The reasons decided per frame at submit time (the frame never goes on the air); the others count links."""

TIME_EPS_S = 1e-9
"""Tolerance of the slot-boundary comparisons (s): absorbs float rounding of sums of slot lengths."""


@dataclass(frozen=True)
class Reception:
    """One frame delivered to one recipient.

    ``t_sent``: first bit leaves the sender (s); ``t_first``: first bit arrives (s);
    ``t_arrival``: last bit arrives (s); ``snr_db``: link SNR of eq. (22) (dB).
    """

    correlation_id: str
    sender: int
    recipient: int
    seq: int
    payload: bytes
    bits: int
    t_sent: float
    t_first: float
    t_arrival: float
    snr_db: float


@dataclass(frozen=True)
class ChannelEvent:
    """One line of the channel's event log.

    ``kind`` is "sent" (one per frame put on the medium, ``recipient`` = -1, ``t_s`` = first bit
    leaves), "delivered" (``t_s`` = last bit arrives, with ``latency_s`` and ``snr_db``) or
    "dropped" (``reason`` from :data:`DROP_REASONS`; ``recipient`` = -1 for per-frame drops).
    """

    t_s: float
    correlation_id: str
    kind: str
    sender: int
    recipient: int
    bits: int
    latency_s: float | None
    snr_db: float | None
    reason: str | None


def _check_slot_order(order: tuple[int, ...], name: str) -> tuple[int, ...]:
    order = tuple(order)
    if not order:
        raise ValueError(f"{name} must hold at least one AUV id, got ()")
    if any(isinstance(a, bool) or not isinstance(a, (int, np.integer)) or a < 0 for a in order):
        raise ValueError(f"{name} must hold AUV ids (integers >= 0), got {list(order)}")
    if len(set(order)) != len(order):
        raise ValueError(f"{name} must not repeat an AUV id, got {list(order)}")
    return tuple(int(a) for a in order)


class TdmaSchedule:
    """Time-division schedule: agent ``order[i]`` owns ``[m*F + i*slot_s, m*F + (i+1)*slot_s)`` for every frame m.

    ``F = n * slot_s`` is the frame length (s); the last ``guard_s`` of each slot must stay
    silent at every recipient (the paper's T_s and T_f = n T_s, section 2.5).
    """

    def __init__(self, slot_s: float, guard_s: float, order: tuple[int, ...]) -> None:
        if not (math.isfinite(slot_s) and slot_s > 0.0):
            raise ValueError(f"slot_s must be in (0, inf) s, got {slot_s!r}")
        if not (math.isfinite(guard_s) and 0.0 <= guard_s < slot_s):
            raise ValueError(f"guard_s must be in [0, slot_s = {slot_s:g}) s, got {guard_s!r}")
        self.slot_s = float(slot_s)
        self.guard_s = float(guard_s)
        self.order = _check_slot_order(order, "order")
        self.frame_s = len(self.order) * self.slot_s
        self._index = {a: i for i, a in enumerate(self.order)}

    def _offset(self, agent: int) -> float:
        if agent not in self._index:
            raise ValueError(f"agent must be one of the slot order {list(self.order)}, got {agent!r}")
        return self._index[agent] * self.slot_s

    def owner(self, t: float) -> int:
        """The agent whose slot contains time ``t`` (s)."""
        k = math.floor((t + TIME_EPS_S) / self.slot_s)
        return self.order[k % len(self.order)]

    def slot_window(self, agent: int, t: float) -> tuple[float, float]:
        """(start, end) in s of ``agent``'s slot containing ``t``, or of its next slot if ``t`` is outside its own."""
        offset = self._offset(agent)
        m = math.floor((t - offset + TIME_EPS_S) / self.frame_s)
        start = m * self.frame_s + offset
        if t >= start + self.slot_s - TIME_EPS_S:
            start += self.frame_s
        return start, start + self.slot_s

    def next_start(self, agent: int, t: float) -> float:
        """Earliest start (s) of one of ``agent``'s slots at or after ``t``."""
        offset = self._offset(agent)
        m = math.ceil((t - offset - TIME_EPS_S) / self.frame_s)
        return m * self.frame_s + offset

    def can_transmit(self, agent: int, t: float, airtime_s: float, max_prop_s: float) -> bool:
        """True when ``t`` lies in ``agent``'s slot and the frame's last bit reaches the farthest
        recipient (``airtime_s + max_prop_s`` later) before the slot's guard time begins."""
        start, end = self.slot_window(agent, t)
        return t >= start - TIME_EPS_S and t + airtime_s + max_prop_s <= end - self.guard_s + TIME_EPS_S


@dataclass(slots=True)
class _Link:
    """A frame on its way from ``sender`` to one ``recipient`` (internal)."""

    correlation_id: str
    sender: int
    recipient: int
    seq: int
    payload: bytes
    bits: int
    t_start: float
    t_first: float
    t_arrival: float
    latency_s: float
    snr_db: float


def _fmt(x: float) -> str:
    """Two decimals, trailing zeros trimmed to one: 15.0, 2.67, 18.67."""
    text = f"{x:.2f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


class ChannelModel:
    """The acoustic medium shared by the AUVs listed in ``slot_order``.

    Use: ``transmit`` frames at non-decreasing times, call ``deliver_until(t)`` to collect what has
    fully arrived by ``t``. Invariant: a frame is never submitted before the last ``deliver_until``
    time, so a reception that ended by then cannot be disturbed by a later frame (checked: an
    earlier submission raises ValueError).
    """

    def __init__(
        self,
        ch: ChannelConfig,
        slot_order: tuple[int, ...],
        rng: np.random.Generator,
        max_frame_bits: int,
        ocean: OceanModel | None = None,
        burst_rng: np.random.Generator | None = None,
    ) -> None:
        """``ocean``: the physical ocean (None: eqs. 22-24 of the paper); ``burst_rng``: the Gilbert-Elliott
        stream, needed when ``ocean.burst_p_good_bad`` > 0."""
        if isinstance(max_frame_bits, bool) or not isinstance(max_frame_bits, (int, np.integer)) or max_frame_bits < 1:
            raise ValueError(f"max_frame_bits must be an integer in [1, inf), got {max_frame_bits!r}")
        self.ch = ch
        self.rng = rng
        self.max_frame_bits = int(max_frame_bits)
        self.agents = tuple(sorted(_check_slot_order(slot_order, "slot_order")))
        self.ocean = ocean
        self.link = None if ocean is None else ocean.link
        slot_speed = ch.sound_speed_mps if ocean is None else ocean.min_sound_speed_mps
        self.max_propagation_s = ch.max_range_m / slot_speed
        self._bursts: dict[tuple[int, int], GilbertElliott] | None = None
        if ocean is not None and ocean.config.burst_p_good_bad > 0.0:
            if burst_rng is None:
                raise ValueError("burst_rng must be a numpy Generator when ocean.burst_p_good_bad > 0")
            oc = ocean.config
            self.burst_rng = burst_rng
            self._bursts = {
                (a, b): GilbertElliott(oc.burst_p_good_bad, oc.burst_p_bad_good, oc.burst_loss)
                for a in self.agents
                for b in self.agents
                if a != b
            }
        self.schedule: TdmaSchedule | None = None
        if ch.mode == "tdma":
            need = self.airtime_s(self.max_frame_bits) + self.max_propagation_s + ch.guard_s
            if ch.slot_s < need - TIME_EPS_S:
                raise ConfigError(
                    f"channel.slot_s = {ch.slot_s:g} s cannot hold airtime {_fmt(self.airtime_s(self.max_frame_bits))} s "
                    f"({self.max_frame_bits} bits at {ch.bit_rate_bps:g} bps) + max propagation "
                    f"{_fmt(self.max_propagation_s)} s ({ch.max_range_m:g} m at {slot_speed:g} m/s) "
                    f"+ guard {ch.guard_s:g} s = {_fmt(need)} s"
                )
            self.schedule = TdmaSchedule(ch.slot_s, ch.guard_s, tuple(slot_order))
        self.backlog_s = self._backlog_capacity_s()
        self._dead: set[int] = set()
        self._busy_until: dict[int, float] = {}
        self._transmissions: list[tuple[int, float, float]] = []
        self._interferers: list[_Link] = []
        self._pending: list[_Link] = []
        self._last_delivery = -math.inf
        self._counters = {"sent": 0, "delivered": 0, "deferred": 0, **{f"dropped_{r}": 0 for r in DROP_REASONS}}
        self._latency_sum = 0.0
        self._latency_max = 0.0

    def airtime_s(self, bits: int) -> float:
        """Time (s) to push ``bits`` through the modem: bits / bit rate."""
        return bits / self.ch.bit_rate_bps

    def _backlog_capacity_s(self) -> float:
        """The most airtime (s) one sender may have queued: what its next slot can carry under TDMA
        (``slot_s - guard_s - max_range_m / sound_speed_mps``, the slot budget), one slot (``slot_s``) under ALOHA;
        never less than one largest frame's airtime, so a frame of the allowed size always fits an empty queue."""
        ch = self.ch
        slot = ch.slot_s - ch.guard_s - self.max_propagation_s if ch.mode == "tdma" else ch.slot_s
        return max(slot, self.airtime_s(self.max_frame_bits))

    def queued_airtime_s(self, sender: int, t_s: float) -> float:
        """Airtime (s) ``sender``'s modem still owes after ``t_s``: frames accepted and not yet fully on the air
        (the rest of the one on the air, and every deferred one)."""
        return sum(end - max(start, t_s) for agent, start, end in self._transmissions if agent == sender and end > t_s)

    def success_probability(self, snr_db: float) -> float:
        """Probability that a frame heard at ``snr_db`` (eq. 22) is decoded.

        0 below DT; with ``snr_transition_db`` = W > 0 it is pdr * min(1, (snr - DT) / W) above DT,
        otherwise pdr (the Bernoulli packet delivery ratio).
        """
        ch = self.ch
        margin = snr_db - ch.detection_threshold_db
        if margin < 0.0:
            return 0.0
        if ch.snr_transition_db > 0.0:
            return ch.pdr * min(1.0, margin / ch.snr_transition_db)
        return ch.pdr

    def _drop(self, t_s: float, cid: str, sender: int, recipient: int, bits: int, reason: str, snr: float | None):
        self._counters[f"dropped_{reason}"] += 1
        return ChannelEvent(t_s, cid, "dropped", sender, recipient, bits, None, snr, reason)

    def transmit(
        self,
        t_s: float,
        sender: int,
        seq: int,
        payload: bytes,
        positions: dict[int, tuple[float, float]],
        alive: set[int],
    ) -> list[ChannelEvent]:
        """Submit one frame at sim time ``t_s`` (s); returns the events decided now.

        ``positions``: agent id -> (x, y) in metres at ``t_s`` (needed for the sender and every live
        recipient); ``alive``: the live agent ids (agents passed to :meth:`kill` count as dead too).
        The correlation id is ``f"{sender}-{seq}"``. One uniform variate is drawn per other agent on
        every call, whatever happens to the frame, so random streams stay aligned across runs.
        """
        if not math.isfinite(t_s):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        if t_s < self._last_delivery:
            raise ValueError(
                f"t_s must be >= the last deliver_until time {self._last_delivery!r} s "
                f"(a reception already delivered cannot be disturbed), got {t_s!r}"
            )
        if sender not in self.agents:
            raise ValueError(f"sender must be one of {list(self.agents)}, got {sender!r}")
        dead = self._dead | (set(self.agents) - set(alive))
        recipients = [a for a in self.agents if a != sender]
        sx, sy = self._position(positions, sender, "sender")
        live_xy = {a: self._position(positions, a, "recipient") for a in recipients if a not in dead}
        draws = self.rng.random(len(recipients))
        bursts = self.burst_rng.random((len(recipients), 2)) if self._bursts is not None else None
        payload = bytes(payload)
        bits = 8 * len(payload)
        cid = f"{sender}-{seq}"
        if bits > self.max_frame_bits:
            return [self._drop(t_s, cid, sender, -1, bits, "oversize", None)]
        airtime = self.airtime_s(bits)
        if self.queued_airtime_s(sender, t_s) + airtime > self.backlog_s + TIME_EPS_S:
            return [self._drop(t_s, cid, sender, -1, bits, "tx_backlog_full", None)]
        t_start = max(t_s, self._busy_until.get(sender, -math.inf))
        if self.schedule is not None and not self.schedule.can_transmit(
            sender, t_start, airtime, self.max_propagation_s
        ):
            if self.ch.out_of_slot == "reject":
                return [self._drop(t_s, cid, sender, -1, bits, "outside_slot", None)]
            t_start = self.schedule.next_start(sender, t_start)
            self._counters["deferred"] += 1
        self._busy_until[sender] = t_start + airtime
        self._transmissions.append((sender, t_start, t_start + airtime))
        self._counters["sent"] += 1
        events = [ChannelEvent(t_start, cid, "sent", sender, -1, bits, None, None, None)]
        for k, (recipient, u) in enumerate(zip(recipients, draws, strict=True)):
            if recipient in dead:
                events.append(self._drop(t_start, cid, sender, recipient, bits, "recipient_dead", None))
                continue
            rx, ry = live_xy[recipient]
            range_m = math.hypot(rx - sx, ry - sy)
            link = self._link(cid, sender, recipient, seq, payload, bits, t_start, airtime, range_m)
            reason = self._loss(link, float(u), None if bursts is None else bursts[k])
            if reason != "low_snr" or (self.link is not None and link.snr_db >= self.link.threshold_db):
                self._interferers.append(link)
            if reason is not None:
                events.append(self._drop(t_start, cid, sender, recipient, bits, reason, link.snr_db))
                continue
            self._pending.append(link)
        return events

    def _link(
        self,
        cid: str,
        sender: int,
        recipient: int,
        seq: int,
        payload: bytes,
        bits: int,
        t_start: float,
        airtime: float,
        range_m: float,
    ) -> _Link:
        """The frame on its way to one recipient: SNR (eq. 22) and timing from the range (m)."""
        if self.link is None:
            propagation = range_m / self.ch.sound_speed_mps
            snr = float(snr_db_cfg(range_m, self.ch))
        else:
            propagation = self.link.delay_s(range_m)
            snr = float(self.link.snr_db(range_m))
        latency = airtime + propagation
        return _Link(
            correlation_id=cid,
            sender=sender,
            recipient=recipient,
            seq=seq,
            payload=payload,
            bits=bits,
            t_start=t_start,
            t_first=t_start + propagation,
            t_arrival=t_start + latency,
            latency_s=latency,
            snr_db=snr,
        )

    def _loss(self, link: _Link, u: float, burst: np.ndarray | None) -> str | None:
        """Why the link is lost at submit time (a drop reason), or None. Paper: below DT, then the Bernoulli
        draw against :meth:`success_probability`. Physical: one draw split as modem failure (``low_snr``, the
        packet-error curve for the frame's bits) then ``channel.pdr`` (``random_loss``), then the link's
        Gilbert-Elliott state (``burst_loss``)."""
        if self.link is None:
            if link.snr_db < self.ch.detection_threshold_db:
                return "low_snr"
            return "random_loss" if u >= self.success_probability(link.snr_db) else None
        p_modem = self.link.delivery(link.snr_db, link.bits)
        if u >= p_modem:
            return "low_snr"
        if u >= p_modem * self.ch.pdr:
            return "random_loss"
        if burst is not None and self._bursts[(link.sender, link.recipient)].step(float(burst[0]), float(burst[1])):
            return "burst_loss"
        return None

    @staticmethod
    def _position(positions: dict[int, tuple[float, float]], agent: int, role: str) -> tuple[float, float]:
        if agent not in positions:
            raise ValueError(f"positions must hold the {role} {agent}, got ids {sorted(positions)}")
        x, y = (float(v) for v in positions[agent])
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"positions[{agent}] must be finite (m), got {positions[agent]!r}")
        return x, y

    def _fate(self, link: _Link) -> str | None:
        """Delivery-time checks: recipient killed, half-duplex, collision; None = delivered."""
        if link.recipient in self._dead:
            return "recipient_dead"
        for agent, start, end in self._transmissions:
            if agent == link.recipient and start < link.t_arrival and end > link.t_first:
                return "half_duplex"
        for other in self._interferers:
            if (
                other is not link
                and other.recipient == link.recipient
                and other.t_first < link.t_arrival
                and other.t_arrival > link.t_first
            ):
                return "collision"
        return None

    def deliver_until(self, t_s: float) -> tuple[list[Reception], list[ChannelEvent]]:
        """Resolve every pending reception whose last bit arrives by ``t_s`` (s).

        Returns the receptions and their "delivered"/"dropped" events (stamped ``t_arrival``),
        sorted by (t_arrival, sender, recipient, seq).
        """
        if not math.isfinite(t_s):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        if t_s < self._last_delivery:
            raise ValueError(f"t_s must be >= the last deliver_until time {self._last_delivery!r} s, got {t_s!r}")
        self._last_delivery = t_s
        due = sorted(
            (lk for lk in self._pending if lk.t_arrival <= t_s),
            key=lambda lk: (lk.t_arrival, lk.sender, lk.recipient, lk.seq),
        )
        receptions: list[Reception] = []
        events: list[ChannelEvent] = []
        for lk in due:
            reason = self._fate(lk)
            if reason is not None:
                events.append(
                    self._drop(lk.t_arrival, lk.correlation_id, lk.sender, lk.recipient, lk.bits, reason, lk.snr_db)
                )
                continue
            receptions.append(
                Reception(
                    correlation_id=lk.correlation_id,
                    sender=lk.sender,
                    recipient=lk.recipient,
                    seq=lk.seq,
                    payload=lk.payload,
                    bits=lk.bits,
                    t_sent=lk.t_start,
                    t_first=lk.t_first,
                    t_arrival=lk.t_arrival,
                    snr_db=lk.snr_db,
                )
            )
            events.append(
                ChannelEvent(
                    lk.t_arrival,
                    lk.correlation_id,
                    "delivered",
                    lk.sender,
                    lk.recipient,
                    lk.bits,
                    lk.latency_s,
                    lk.snr_db,
                    None,
                )
            )
            self._counters["delivered"] += 1
            self._latency_sum += lk.latency_s
            self._latency_max = max(self._latency_max, lk.latency_s)
        self._pending = [lk for lk in self._pending if lk.t_arrival > t_s]
        self._prune(t_s)
        return receptions, events

    def _prune(self, t_s: float) -> None:
        """Forget transmissions and interferers that can overlap neither a pending nor a future reception."""
        horizon = min([t_s, *(lk.t_first for lk in self._pending)])
        self._transmissions = [tx for tx in self._transmissions if tx[2] > horizon]
        self._interferers = [lk for lk in self._interferers if lk.t_arrival > horizon]

    def kill(self, agent: int) -> None:
        """Mark ``agent`` dead: receptions still pending to it are dropped "recipient_dead" at delivery.

        Frames it already put on the medium still propagate. Call after ``deliver_until`` of the kill time.
        """
        if agent not in self.agents:
            raise ValueError(f"agent must be one of {list(self.agents)}, got {agent!r}")
        self._dead.add(agent)

    def revive(self, agent: int) -> None:
        """``agent`` is back (a restarted AUV): frames reach it again from now on."""
        if agent not in self.agents:
            raise ValueError(f"agent must be one of {list(self.agents)}, got {agent!r}")
        self._dead.discard(agent)

    @property
    def counters(self) -> dict[str, int]:
        """Counts: "sent" frames, "deferred" frames, "delivered" links and "dropped_<reason>" for every reason.

        Per-frame reasons (:data:`FRAME_REASONS`) count frames; the others count (frame, recipient) links.
        """
        return dict(self._counters)

    @property
    def in_flight(self) -> int:
        """Links (frame, recipient) on the air: sent, not yet delivered nor dropped. ``sent * (n - 1)`` equals
        ``delivered`` plus the link drops plus this, at every instant."""
        return len(self._pending)

    @property
    def latencies(self) -> dict[str, float]:
        """Latency summary of delivered links: "count", "mean_s" and "max_s" (s; 0.0 when none delivered)."""
        n = self._counters["delivered"]
        return {"count": n, "mean_s": self._latency_sum / n if n else 0.0, "max_s": self._latency_max}
