"""Collect what a recorder hears on the bus and turn it into a ``RunRecord``.

Messages may arrive in any order (zenoh orders nothing across publishers), so
everything is keyed by tick and sorted before the record is built: the same
messages give the same record whichever order they came in.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Callable

from auv_swarm.contract import wire
from auv_swarm.contract.config import Scenario
from auv_swarm.contract.payload import decode_payload
from auv_swarm.results.channel_books import run_totals
from auv_swarm.results.record import COV_INDEX, AgentTick, Bearing, RunRecord


class MessageLog:
    """A sink for bus messages (``on_message``), kept until the run ends."""

    def __init__(self) -> None:
        self.truth: dict[int, wire.Truth] = {}
        self.telemetry: dict[tuple[int, int], wire.Telemetry] = {}
        self.packets: list[wire.PacketEvent] = []
        self.world_events: list[wire.WorldEvent] = []
        self.sensors: dict[tuple[int, int], wire.Sensor] = {}
        self.frames: dict[tuple[int, int, int, int], wire.ModemRx] = {}
        self.stats: wire.ChannelStats | None = None
        self.epochs: dict[int, wire.ChannelStats] = {}
        self.malformed = 0

    def on_message(self, msg: object) -> None:
        """File one decoded message."""
        if isinstance(msg, wire.Truth):
            self.truth[msg.tick] = msg
        elif isinstance(msg, wire.Telemetry):
            self.telemetry[(msg.tick, msg.auv)] = msg
        elif isinstance(msg, wire.PacketEvent):
            self.packets.append(msg)
        elif isinstance(msg, wire.WorldEvent):
            self.world_events.append(msg)
        elif isinstance(msg, wire.Sensor):
            self.sensors[(msg.tick, msg.auv)] = msg
        elif isinstance(msg, wire.ModemRx):
            self.frames[(msg.tick, msg.auv, msg.sender, msg.seq)] = msg
        elif isinstance(msg, wire.ChannelStats):
            epoch = msg.counters.get("epoch", 0)
            last = self.epochs.get(epoch)
            if last is None or msg.t_s >= last.t_s:
                self.epochs[epoch] = msg
            if self.stats is None or msg.t_s >= self.stats.t_s:
                self.stats = msg

    def channel_totals(self, n_agents: int) -> dict[str, int] | None:
        """The channel's counters over the run (``results.channel_books.run_totals``): the last stats of every
        channel process (epoch, in the order they started) added up, the links that died with a killed process
        lost as ``channel_restart``; ``epochs`` counts the processes. None if no stats came."""
        if not self.epochs:
            return None
        return run_totals([self.epochs[e].counters for e in sorted(self.epochs)], n_agents)

    def missing_telemetry(self) -> int:
        """How many (tick, live AUV) pairs still lack telemetry."""
        return sum(1 for k, tr in self.truth.items() for a in tr.alive if (k, a) not in self.telemetry)

    def wait_complete(
        self, inbound: queue.Queue, scenario: Scenario, timeout: float, file: Callable[[object], None] | None = None
    ) -> None:
        """Drain ``inbound`` until every live AUV's telemetry and the final channel stats are in (or timeout).

        ``file`` files each message (default this log's ``on_message``; a fan-out that includes this log)."""
        file = file or self.on_message
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                file(inbound.get(timeout=0.1))
                continue
            except queue.Empty:
                pass
            if self.final_stats() and self.missing_telemetry() == 0:
                return

    def final_stats(self) -> bool:
        """True once channel stats as recent as the last truth are in (the channel publishes its final
        counters when it stops, after the mission's last tick; periodic ones may be older)."""
        last = max((tr.t_s for tr in self.truth.values()), default=0.0)
        return self.stats is not None and self.stats.t_s >= last

    def to_record(self, scenario: Scenario, mode: str, wall_time_s: float) -> RunRecord:
        """Build the run record, tick by tick, in a canonical order."""
        rec = RunRecord.new(scenario, mode, range(scenario.agents.count))
        for tick in sorted(self.truth):
            tr = self.truth[tick]
            agents = {}
            for a in tr.alive:
                x, y, theta = tr.agents[a]
                tm = self.telemetry.get((tick, a))
                ok = tm is not None and tm.estimate_ok
                agents[a] = AgentTick(
                    position=(x, y),
                    heading=theta,
                    estimate=(tm.xi[0], tm.xi[1]) if ok else None,
                    estimate_cov=(tm.P[0], tm.P[1], tm.P[5]) if ok else None,
                    velocity=(tm.xi[2], tm.xi[3]) if ok else None,
                    covariance=tuple(tm.P[k] for k in COV_INDEX) if ok else None,
                    believed=(tm.nav[0], tm.nav[1]) if tm is not None else None,
                )
            rec.append_tick(tr.t_s, tr.target, agents)
        self._add_bearings(rec, scenario.planner.n_headings)
        for (_tick, auv), tm in sorted(self.telemetry.items()):
            if tm.planned:
                rec.add_plan(auv, tm.t_s, tm.plan_wall_ms, tm.terms)
        for ev in sorted(self.world_events, key=lambda e: (e.t_s, e.kind, e.auv)):
            if ev.kind in ("kill", "death") and 0 <= ev.auv < scenario.agents.count:
                rec.mark_killed(ev.auv, ev.t_s, ev.kind, None if ev.kind == "kill" else ev.text)
            elif ev.kind == "rejoin" and 0 <= ev.auv < scenario.agents.count:
                rec.mark_rejoined(ev.auv, ev.t_s)
            elif ev.kind in ("hung", "resume") and 0 <= ev.auv < scenario.agents.count:
                rec.mark_hung(ev.auv, ev.t_s, ev.kind == "hung", ev.text)
            elif ev.kind not in ("kill", "death"):
                rec.add_event(ev.t_s, ev.kind, agent=ev.auv, text=ev.text)
        for ev in sorted(self.packets, key=lambda e: (e.t_s, e.correlation_id, e.kind, e.recipient)):
            rec.add_packet(
                {
                    "t_s": ev.t_s,
                    "kind": ev.kind,
                    "correlation_id": ev.correlation_id,
                    "sender": ev.sender,
                    "recipient": ev.recipient,
                    "bits": ev.bits,
                    "latency_s": ev.latency_s,
                    "snr_db": ev.snr_db,
                    "reason": ev.reason,
                }
            )
        rec.finish(wall_time_s, self.channel_totals(scenario.agents.count))
        return rec

    def _add_bearings(self, rec: RunRecord, n_headings: int) -> None:
        """The bearings taken (``Sensor``, at the AUV's true position of that tick) and those delivered
        (decoded from each ``ModemRx`` payload; one whose sender field disagrees with the channel's, or that does
        not decode, carries none that the recipient would use, and is left out)."""
        for (tick, auv), sensor in sorted(self.sensors.items()):
            truth = self.truth.get(tick)
            if sensor.bearing_rad is None or truth is None or auv not in truth.agents:
                continue
            x, y, _theta = truth.agents[auv]
            rec.add_bearing(Bearing(sensor.t_s, auv, sensor.bearing_rad, (x, y)))
        for (_tick, recipient, sender, seq), rx in sorted(self.frames.items()):
            try:
                payload = decode_payload(rx.payload, n_headings)
            except (wire.DecodeError, ValueError):
                continue
            if payload.sender != sender:
                continue
            for t_s, sx, sy, value in payload.bearings:
                rec.add_bearing(Bearing(t_s, sender, value, (sx, sy), recipient, rx.t_arrival, f"{sender}-{seq}"))
