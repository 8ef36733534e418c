"""Live state in the rerun viewer and the run's ``recording.rrd``: the only module that imports rerun.

:class:`RerunRecorder` is a sink of decoded wire messages (``on_message``): Truth,
Telemetry, PacketEvent, ChannelStats, WorldEvent, and Sensor when the caller has
them. It logs on the ``sim_time`` timeline (seconds of simulated time):

- ``world/target/truth``, ``world/target/trail``, ``world/target/d_star`` (a
  translucent disc of radius d* around the target, eq. 36);
- ``world/auv/{id}/truth`` (grey once dead, when its estimate, bearing and plan are
  cleared), ``.../heading``, ``.../trail``,
  ``.../estimate`` (eq. 14), ``.../estimate/covariance`` (95 % ellipse of the
  position block of P, eq. 15), ``.../plan`` (the planned waypoints over the
  horizon, eq. 39), ``.../bearing`` (the measured bearing, eq. 4, when Sensor
  messages are fed, else the line toward the AUV's own estimate);
- ``world/packets/delivered`` (sender to recipient, coloured by SNR, eq. 22: red
  at the detection threshold DT, green at rho_M of eq. 26), ``world/packets/dropped``
  (links, coloured and labelled by reason) and ``world/packets/dropped_frames``
  (frames dropped at the sender), each showing the packets of the last TDMA slot
  between the vehicles' current true positions;
- ``world/auv/{id}/believed`` (+ ``/offset`` to the truth; the bearing and plan start there) and
  ``plots/nav_error/auv{id}`` (m), under imperfect navigation only (docs/navigation.md);
- ``plots/tracking_error/auv{id}`` (m, from Truth and Telemetry of the same tick),
  ``plots/cost/{term}/auv{id}`` and ``plots/cost/total/auv{id}`` (eq. 38, at each
  planning step), ``plots/fiedler/auv{id}`` (eq. 37), ``plots/plan_ms/auv{id}``
  (wall-clock ms), ``plots/channel/{counter}`` (cumulative sent, delivered,
  deferred, dropped_<reason>: counted from the packet events and reset to the
  channel's own ChannelStats whenever one arrives) and
  ``plots/channel_other/{counter}`` (the channel's other counters);
- ``events`` (rr.TextLog: start, end, kill, death, rejoin);
- ``scenario`` (static: the scenario as TOML).

Positions are metres in the inertial frame (x east, y north). Rerun's 2-D view has
y down, so a static transform on ``world`` flips y for display only: the values in
the recording are the world's own coordinates.

Rows are buffered per entity and sent to the file with ``send_columns`` every
``flush_every`` ticks, or sooner once the oldest buffered row has waited
``flush_after_s`` of wall time (a kill -9 loses at most that much), on :meth:`flush`
and on :meth:`close`. A live viewer gets the same rows on its own cadence, every
``live_flush_s`` of wall time (and at the end): each send is one chunk per entity,
and the web viewer's proxy keeps every chunk for a page opened later, which loads
them one by one (issue 28 item 6: a 1500 s run at ``--speed 5`` sent thousands of
chunks, and a page opened after it had 1210 of 1500 s after 120 s). The channel
counters are logged when they change (with the previous value at the tick before, so
the plotted steps keep their shape) and at the end, not at every tick. :meth:`close` then merges the
file's small chunks (``compact``), so the same data gives about the same file size
however the run was paced. The file sink never blocks. A live viewer (``spawn_viewer`` or ``url`` of
:class:`~auv_swarm.recorder.options.RecorderOptions`) gets a second recording stream with the same recording
id (:class:`~auv_swarm.recorder.live.LiveViewer`), connected from a background thread after a TCP probe, so a
missing viewer costs the mission nothing.
"""

from __future__ import annotations

import logging
import math
import re
import subprocess
import time
import uuid
from collections import defaultdict, deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from auv_swarm.contract import wire
from auv_swarm.contract.config import Scenario, dump_toml
from auv_swarm.recorder.live import LiveViewer, Scalars, scalar_buffers
from auv_swarm.recorder.options import RecorderOptions
from auv_swarm.recorder.rows import Rows, Trail, finite, nanos
from auv_swarm.recorder.style import (
    DEAD_COLOUR,
    OTHER_REASON_COLOUR,
    REASON_COLOURS,
    TARGET_COLOUR,
    auv_colour,
    blueprint,
    counter_entity,
    covariance_ellipse,
    segment,
    snr_colour,
)
from auv_swarm.recorder.viewer import TIMELINE, compact, release_live

log = logging.getLogger(__name__)

APP_ID = "auv-swarm"
TRAIL_PERIOD_S = 10.0
"""Spacing of the trail points (s of sim time); a trail row is logged each time a point is added."""
HEADING_ARROW_M = 80.0
HISTORY_TICKS = 256
"""Truths (and measured bearings) kept for late telemetry: zenoh orders nothing across publishers."""
PENDING_TICKS = HISTORY_TICKS
"""Telemetry waits for the Truth of its tick until telemetry of this many ticks is waiting (early telemetry)."""
_MAX_WARNINGS = 10

_EVENT_LEVELS = {
    "start": "INFO",
    "end": "INFO",
    "abort": "ERROR",
    "rejoin": "INFO",
    "kill": "WARN",
    "death": "ERROR",
    "hung": "WARN",
    "resume": "INFO",
    "duplicate_login": "WARN",
}


_PACKET_LAYERS = (
    ("delivered", rr.LineStrips2D, "strips", -1.5, False),
    ("dropped", rr.LineStrips2D, "strips", -1.0, True),
    ("dropped_frames", rr.Points2D, "positions", -8.0, True),
)
"""The packet layers under ``world/packets``: entity, rerun archetype, its geometry component, line or point
radius (negative: screen pixels) and whether each item is labelled with its drop reason."""


def _draw(
    layer: tuple[list[Any], list[tuple[int, ...]], list[str]], item: Any, colour: tuple[int, ...], label: str
) -> None:
    items, colours, labels = layer
    items.append(item)
    colours.append(colour)
    labels.append(label)


class RerunRecorder:
    """Sink of wire messages that logs the mission to ``rrd_path`` and, optionally, to a live viewer.

    ``on_message`` never raises: anything unexpected or malformed (an unknown
    message type, an AUV id outside the scenario, a non-finite number) is counted
    in ``malformed`` and logged. ``busy_s`` is the wall time spent inside the
    recorder (s). ``options`` (:class:`RecorderOptions`, defaults when None) say
    how often rows are sent and whether a live viewer gets them; ``live`` is that
    viewer (:class:`LiveViewer`, ``live_state`` its state, ``viewer`` the process it
    spawned, if any). Feed it from one thread.
    """

    def __init__(self, scenario: Scenario, rrd_path: Path, options: RecorderOptions | None = None) -> None:
        started = time.perf_counter()
        self.scenario = scenario
        self.options = options = RecorderOptions() if options is None else options
        self.rrd_path = Path(rrd_path)
        self.rrd_path.parent.mkdir(parents=True, exist_ok=True)
        self.chunks_sent = {"file": 0, "live": 0}
        self.rows_logged = 0
        self.malformed = 0
        self.received = 0
        self.busy_s = 0.0
        self._n = scenario.agents.count
        self._closed = False
        self._rows: dict[str, Rows] = {}
        self._scalars: Scalars = scalar_buffers()
        # per channel counter: (time, value) last logged, and the time it was last seen
        self._counter_logged: dict[str, tuple[float, int]] = {}
        self._counter_seen: dict[str, float] = {}
        self._truths: dict[int, wire.Truth] = {}
        self._last_truth: wire.Truth | None = None
        self._pending: dict[int, list[wire.Telemetry]] = defaultdict(list)
        self._bearings: dict[tuple[int, int], float] = {}
        self._packets: deque[wire.PacketEvent] = deque()
        self._channel_counts: dict[str, int] = {}
        self._trails: dict[str, Trail] = defaultdict(lambda: Trail(TRAIL_PERIOD_S))
        self._ticks_unflushed = 0
        self._unflushed_since: float | None = None
        self._styled: set[str] = set()
        self._cleared: set[int] = set()
        ch = scenario.channel
        rho_max = ch.snr_max_db or ch.source_level_db - ch.noise_level_db + ch.directivity_index_db
        self._snr_scale = (ch.detection_threshold_db, max(1.0, rho_max - ch.detection_threshold_db))
        self._handlers: dict[type, Callable[[Any], None]] = {
            wire.Truth: self._on_truth,
            wire.Telemetry: self._on_telemetry,
            wire.PacketEvent: self._on_packet,
            wire.ChannelStats: self._on_stats,
            wire.WorldEvent: self._on_world_event,
            wire.Sensor: self._on_sensor,
        }
        recording_id = str(uuid.uuid4())
        self._rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
        self._rec.set_sinks(rr.FileSink(str(self.rrd_path)))
        self.live = LiveViewer(options, APP_ID, recording_id, self.rrd_path)
        for stream in self._streams():
            self._send_static(stream)
        self.live.start()
        self.busy_s += time.perf_counter() - started

    @property
    def live_state(self) -> str:
        """The live viewer's state: "off", "connecting", "connected" or "unreachable"."""
        return self.live.state

    @property
    def viewer(self) -> subprocess.Popen | None:
        """The viewer process the live viewer spawned, if any."""
        return self.live.viewer

    # The sink interface -------------------------------------------------------------------------------------------

    def on_message(self, msg: object) -> None:
        """Log one decoded wire message; anything unexpected or malformed is counted in ``malformed``."""
        started = time.perf_counter()
        try:
            handler = self._handlers.get(type(msg))
            if self._closed or handler is None:
                why = "recorder is closed" if self._closed else f"unexpected message type {type(msg).__name__}"
                self._reject(why)
                return
            try:
                handler(msg)
                self.received += 1
            except Exception as exc:
                self._reject(f"{type(msg).__name__}: {exc}")
        finally:
            self.busy_s += time.perf_counter() - started

    def flush(self) -> None:
        """Send every buffered row to the sinks and flush the file (the data so far survives a kill -9)."""
        started = time.perf_counter()
        try:
            if not self._closed:
                self._send_rows()
                self._rec.flush()
        finally:
            self.busy_s += time.perf_counter() - started

    def close(self) -> None:
        """Send what is buffered, finish the .rrd file and let go of the live viewer (idempotent, never blocks long)."""
        if self._closed:
            return
        started = time.perf_counter()
        try:
            for tick in sorted(self._pending):
                for m in self._pending[tick]:
                    self._log_telemetry(m, self._truths.get(tick))
            self._pending.clear()
            self._close_counters()
            self._send_rows(live_now=True)
        finally:
            self._closed = True
            live = self.live.close()
            self._rec.flush()
            self._rec.disconnect()
            if live is not None:
                release_live(live)
            if self.options.compact_at_close:
                try:
                    compact(self.rrd_path)
                except RuntimeError as exc:
                    log.warning("recorder: %s; the recording stays as written", exc)
            self.busy_s += time.perf_counter() - started

    def __enter__(self) -> RerunRecorder:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # Message handlers ---------------------------------------------------------------------------------------------

    def _on_truth(self, m: wire.Truth) -> None:
        """One tick's truth: the target and the AUVs, the dead ones cleared, the last slot's packets, the channel
        counters, the telemetry that waited for this tick; then the rows are sent if due."""
        target = finite(m.target, "Truth.target", 4)
        agents = {}
        for a, pose in m.agents.items():
            agents[self._auv(a, "Truth.agents")] = finite(pose, f"Truth.agents[{a}]", 3)
        alive = {self._auv(a, "Truth.alive") for a in m.alive}
        t = float(m.t_s)
        self._remember(m)
        self._log_target(t, (target[0], target[1]))
        for a, pose in sorted(agents.items()):
            self._log_auv(t, a, pose, a in alive)
        self._clear_dead(t, set(agents) - alive)
        self._log_packets(t, agents)
        for name, value in sorted(self._channel_counts.items()):
            self._counter(name, t, value)
        for tick in sorted(k for k in self._pending if k <= m.tick):
            for tm in self._pending.pop(tick):
                self._log_telemetry(tm, self._truths.get(tick))
        self._tick_logged()

    def _remember(self, m: wire.Truth) -> None:
        """Keep the truth for late telemetry; forget truths and bearings older than HISTORY_TICKS now and then."""
        self._truths[m.tick] = m
        if len(self._truths) > 2 * HISTORY_TICKS:
            self._truths = {k: v for k, v in self._truths.items() if k >= m.tick - HISTORY_TICKS}
            self._bearings = {k: v for k, v in self._bearings.items() if k[1] >= m.tick - HISTORY_TICKS}
        self._last_truth = m

    def _log_target(self, t: float, txy: tuple[float, float]) -> None:
        """The true target, its trail and the disc of radius d* around it (eq. 36)."""
        self._row(rr.Points2D, "world/target/truth", t, positions=[txy], colors=[TARGET_COLOUR], radii=[-6.0])
        trail = self._trails["target"].update(t, txy)
        if trail is not None:
            self._row(
                rr.LineStrips2D, "world/target/trail", t, strips=[trail], colors=[(214, 39, 40, 160)], radii=[-1.0]
            )
        d_star = self.scenario.planner.d_star_m
        self._row(
            rr.Points2D,
            "world/target/d_star",
            t,
            positions=[txy],
            colors=[(214, 39, 40, 28)],
            radii=[d_star],
            draw_order=[-10.0],
        )

    def _log_auv(self, t: float, a: int, pose: tuple[float, float, float], alive: bool) -> None:
        """AUV ``a``'s true position (labelled, grey once dead), heading arrow and trail."""
        x, y, theta = pose
        colour = auv_colour(a) if alive else DEAD_COLOUR
        base = f"world/auv/{a}"
        label = f"AUV {a}" if alive else f"AUV {a} (dead)"
        self._row(rr.Points2D, f"{base}/truth", t, positions=[(x, y)], colors=[colour], radii=[-5.0], labels=[label])
        vec = (HEADING_ARROW_M * math.cos(theta), HEADING_ARROW_M * math.sin(theta))
        self._row(rr.Arrows2D, f"{base}/heading", t, origins=[(x, y)], vectors=[vec], colors=[colour], radii=[-1.5])
        strip = self._trails[base].update(t, (x, y))
        if strip is not None:
            self._row(rr.LineStrips2D, f"{base}/trail", t, strips=[strip], colors=[(*colour[:3], 140)], radii=[-1.0])

    def _clear_dead(self, t: float, dead: set[int]) -> None:
        """Clear the estimate, covariance, bearing and plan of each AUV once, when it is first seen dead."""
        for a in sorted(dead - self._cleared):
            self._cleared.add(a)
            self._row(rr.Points2D, f"world/auv/{a}/estimate", t, positions=[], colors=[], radii=[])
            for tail in ("estimate/covariance", "bearing", "plan"):
                self._row(rr.LineStrips2D, f"world/auv/{a}/{tail}", t, strips=[], colors=[], radii=[])
        self._cleared &= dead

    def _tick_logged(self) -> None:
        """Send the rows after ``flush_every`` ticks, or once the oldest has waited ``flush_after_s`` (wall time)."""
        self._ticks_unflushed += 1
        now = time.monotonic()
        if self._unflushed_since is None:
            self._unflushed_since = now
        waited = now - self._unflushed_since
        if self._ticks_unflushed >= self.options.flush_every or waited >= self.options.flush_after_s:
            self._send_rows()

    def _on_telemetry(self, m: wire.Telemetry) -> None:
        self._auv(m.auv, "Telemetry.auv")
        finite(m.xi, "Telemetry.xi", 4)
        finite(m.nav, "Telemetry.nav", 3)
        finite(m.P, "Telemetry.P", 16)
        for i, wp in enumerate(m.waypoints):
            finite(wp, f"Telemetry.waypoints[{i}]", 2)
        finite([m.cost, m.plan_wall_ms, m.fiedler, *m.terms.values()], "Telemetry cost, terms, plan_wall_ms, fiedler")
        last = self._last_truth
        truth = self._truths.get(m.tick)
        if truth is None and (last is None or m.tick > last.tick):
            self._pending[m.tick].append(m)
            while len(self._pending) > PENDING_TICKS:
                oldest = min(self._pending)
                for tm in self._pending.pop(oldest):
                    self._log_telemetry(tm, None)
            return
        self._log_telemetry(m, truth)

    def _on_packet(self, m: wire.PacketEvent) -> None:
        self._auv(m.sender, "PacketEvent.sender")
        if m.recipient != -1:
            self._auv(m.recipient, "PacketEvent.recipient")
        if m.kind not in ("sent", "delivered", "dropped"):
            raise ValueError(f"PacketEvent.kind must be sent, delivered or dropped, got {m.kind!r}")
        name = f"dropped_{m.reason}" if m.kind == "dropped" else m.kind
        self._channel_counts[name] = self._channel_counts.get(name, 0) + 1
        if m.kind != "sent":
            self._packets.append(m)

    def _on_stats(self, m: wire.ChannelStats) -> None:
        counters = {str(k): int(v) for k, v in m.counters.items()}
        self._channel_counts.update(counters)
        for name, value in sorted(counters.items()):
            if name != "epoch":  # the channel process's start time, not a count
                self._counter(name, float(m.t_s), value)

    def _on_world_event(self, m: wire.WorldEvent) -> None:
        if m.kind not in _EVENT_LEVELS:
            raise ValueError(f"WorldEvent.kind must be one of {', '.join(_EVENT_LEVELS)}, got {m.kind!r}")
        if m.auv != -1:
            self._auv(m.auv, "WorldEvent.auv")
        who = f" (AUV {m.auv})" if m.auv >= 0 else ""
        text = f"{m.kind}{who}: {m.text}"
        for stream in self._streams():
            stream.set_time(TIMELINE, duration=float(m.t_s))
            stream.log("events", rr.TextLog(text, level=_EVENT_LEVELS[m.kind]))
        if m.kind in ("end", "abort"):
            self._close_counters()
            self._send_rows(live_now=True)

    def _on_sensor(self, m: wire.Sensor) -> None:
        self._auv(m.auv, "Sensor.auv")
        if m.bearing_rad is not None:
            self._bearings[(m.auv, m.tick)] = finite([m.bearing_rad], "Sensor.bearing_rad", 1)[0]

    # Logging helpers ----------------------------------------------------------------------------------------------

    def _log_telemetry(self, m: wire.Telemetry, truth: wire.Truth | None) -> None:
        """Estimate, covariance, plan, bearing line and plots of one AUV at one tick; ``truth`` of the same tick."""
        a, t = m.auv, float(m.t_s)
        base = f"world/auv/{a}"
        colour = auv_colour(a)
        pose = truth.agents.get(a) if truth is not None else None
        est = (m.xi[0], m.xi[1])
        if m.estimate_ok:
            cov = np.asarray(m.P, dtype=float).reshape(4, 4)[:2, :2]
            ellipse = covariance_ellipse(est, cov)
            self._row(rr.Points2D, f"{base}/estimate", t, positions=[est], colors=[colour], radii=[-3.5])
            self._row(
                rr.LineStrips2D, f"{base}/estimate/covariance", t, strips=[ellipse], colors=[colour], radii=[-1.0]
            )
        else:
            self._row(rr.Points2D, f"{base}/estimate", t, positions=[], colors=[], radii=[])
            self._row(rr.LineStrips2D, f"{base}/estimate/covariance", t, strips=[], colors=[], radii=[])
        bearing_strips: list[Any] = []
        origin = (m.nav[0], m.nav[1])  # the AUV measures and plans from where it believes it is
        if pose is not None:
            self._log_believed(m, pose)
            measured = self._bearings.get((a, m.tick))
            if measured is not None:
                length = math.hypot(est[0] - origin[0], est[1] - origin[1]) if m.estimate_ok else 0.0
                length = length if length > 1.0 else self.scenario.planner.d_star_m
                end = (origin[0] + length * math.cos(measured), origin[1] + length * math.sin(measured))
                bearing_strips = [[origin, end]]
            elif m.estimate_ok:
                bearing_strips = [[origin, est]]
        self._row(
            rr.LineStrips2D,
            f"{base}/bearing",
            t,
            strips=bearing_strips,
            colors=[(*colour[:3], 110)] * len(bearing_strips),
            radii=[-0.75] * len(bearing_strips),
        )
        if m.waypoints:
            start = [origin] if pose is not None else []
            strip = [*start, *m.waypoints]
            self._row(rr.LineStrips2D, f"{base}/plan", t, strips=[strip], colors=[colour], radii=[-2.0])
        if m.estimate_ok and truth is not None:
            err = math.hypot(m.xi[0] - truth.target[0], m.xi[1] - truth.target[1])
            self._scalar(f"plots/tracking_error/auv{a}", t, err)
        if m.planned:
            for term, value in sorted(m.terms.items()):
                self._scalar(f"plots/cost/{segment(term)}/auv{a}", t, value)
            self._scalar(f"plots/cost/total/auv{a}", t, m.cost)
            self._scalar(f"plots/fiedler/auv{a}", t, m.fiedler)
            self._scalar(f"plots/plan_ms/auv{a}", t, m.plan_wall_ms)

    def _log_believed(self, m: wire.Telemetry, pose: tuple[float, float, float]) -> None:
        """Where the AUV believes it is, beside its truth (imperfect navigation only)."""
        if not self.scenario.navigation.perfect:
            a, t, colour = m.auv, float(m.t_s), auv_colour(m.auv)
            believed, true = (m.nav[0], m.nav[1]), (pose[0], pose[1])
            base = f"world/auv/{a}/believed"
            self._row(rr.Points2D, base, t, positions=[believed], colors=[(*colour[:3], 150)], radii=[-4.0])
            self._row(rr.LineStrips2D, f"{base}/offset", t, strips=[[true, believed]], colors=[colour], radii=[-0.75])
            self._scalar(f"plots/nav_error/auv{a}", t, math.hypot(believed[0] - true[0], believed[1] - true[1]))

    def _log_packets(self, t: float, agents: dict[int, tuple[float, float, float]]) -> None:
        """The packets of the last slot, drawn between the current true positions."""
        window = self.scenario.channel.slot_s
        while self._packets and self._packets[0].t_s <= t - window:
            self._packets.popleft()
        threshold, span = self._snr_scale
        drawn: dict[str, tuple[list[Any], list[tuple[int, ...]], list[str]]] = {
            name: ([], [], []) for name, *_ in _PACKET_LAYERS
        }
        for p in self._packets:
            if p.t_s > t or p.sender not in agents:
                continue
            src = agents[p.sender][:2]
            reason = p.reason or "unknown"
            if p.recipient == -1:
                if p.kind == "dropped":
                    _draw(drawn["dropped_frames"], src, REASON_COLOURS.get(reason, OTHER_REASON_COLOUR), reason)
                continue
            if p.recipient not in agents:
                continue
            strip = [src, agents[p.recipient][:2]]
            if p.kind == "delivered":
                _draw(drawn["delivered"], strip, snr_colour(p.snr_db, threshold, span), reason)
            else:
                _draw(drawn["dropped"], strip, REASON_COLOURS.get(reason, OTHER_REASON_COLOUR), reason)
        for name, archetype, geometry, radius, labelled in _PACKET_LAYERS:
            items, colours, labels = drawn[name]
            components = {geometry: items, "colors": colours, "radii": [radius] * len(items)}
            if labelled:
                components["labels"] = labels
            self._row(archetype, f"world/packets/{name}", t, **components)

    def _row(self, archetype: Any, entity: str, t_s: float, **components: Sequence[Any]) -> None:
        self.rows_logged += 1
        for buffers in (self._rows, self.live.rows):
            if buffers is not None:
                rows = buffers.get(entity)
                if rows is None:
                    rows = buffers[entity] = Rows(archetype)
                rows.add(t_s, **components)

    def _counter(self, name: str, t_s: float, value: int) -> None:
        """A channel counter seen at ``t_s``: logged when it changes, preceded by its old value at the last
        time it was seen, so the plot keeps the step; :meth:`_close_counters` logs the final values."""
        last = self._counter_logged.get(name)
        seen = self._counter_seen.get(name)
        self._counter_seen[name] = t_s if seen is None else max(seen, t_s)
        if last is not None and last[1] == value:
            return
        if last is not None and seen is not None and last[0] < seen < t_s:
            self._scalar(counter_entity(name), seen, last[1])
        self._scalar(counter_entity(name), t_s, value)
        self._counter_logged[name] = (t_s, value)

    def _close_counters(self) -> None:
        """Log every counter's value at the last time it was seen (the plots reach the end)."""
        for name, (t_logged, value) in sorted(self._counter_logged.items()):
            seen = self._counter_seen.get(name, t_logged)
            if seen > t_logged:
                self._scalar(counter_entity(name), seen, value)
                self._counter_logged[name] = (seen, value)

    def _scalar(self, entity: str, t_s: float, value: float) -> None:
        if entity not in self._styled:
            self._styled.add(entity)
            match = re.search(r"/auv(\d+)$", entity)
            if match is not None:
                a = int(match.group(1))
                for stream in self._streams():
                    stream.log(entity, rr.SeriesLines(colors=[auv_colour(a)], names=[f"AUV {a}"]), static=True)
        self.rows_logged += 1
        for buffers in (self._scalars, self.live.scalars):
            if buffers is not None:
                times, values = buffers[entity]
                times.append(float(t_s))
                values.append(float(value))

    def _send_rows(self, live_now: bool = False) -> None:
        """Send the file's buffered rows, and the live viewer's once ``live_flush_s`` has passed since its last
        send (or ``live_now``): one ``send_columns`` per entity."""
        self._ticks_unflushed = 0
        self._unflushed_since = None
        self._send(self._rec, self._rows, self._scalars, "file")
        due = self.live.take_due(live_now)
        if due is not None:
            self._send(*due, "live")

    def _send(
        self,
        stream: rr.RecordingStream,
        rows_by_entity: dict[str, Rows],
        scalars: Scalars,
        which: str,
    ) -> None:
        for entity, rows in rows_by_entity.items():
            if rows.times:
                self._send_columns(stream, entity, rows.times, rows.columns(), which)
                rows.clear()
        for entity, (times, values) in scalars.items():
            if times:
                columns = rr.Scalars.columns(scalars=np.asarray(values, dtype=float))
                self._send_columns(stream, entity, times, columns, which)
                times.clear()
                values.clear()

    def _send_columns(
        self, stream: rr.RecordingStream, entity: str, times: list[float], columns: Any, which: str
    ) -> None:
        stream.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=nanos(times))], columns=columns)
        self.chunks_sent[which] += 1

    def _send_static(self, stream: rr.RecordingStream) -> None:
        stream.send_recording_name(f"{self.scenario.name} (seed {self.scenario.run.seed})")
        stream.send_blueprint(blueprint(self.scenario), make_active=True, make_default=True)
        stream.log("world", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        stream.log("scenario", rr.TextDocument(dump_toml(self.scenario), media_type="text/plain"), static=True)

    def _streams(self) -> list[rr.RecordingStream]:
        live = self.live.stream()
        return [self._rec] if live is None else [self._rec, live]

    def _auv(self, auv: int, where: str) -> int:
        if isinstance(auv, bool) or not isinstance(auv, int) or not 0 <= auv < self._n:
            raise ValueError(f"{where} must be an AUV id in [0, {self._n - 1}], got {auv!r}")
        return auv

    def _reject(self, why: str) -> None:
        self.malformed += 1
        if self.malformed <= _MAX_WARNINGS or self.malformed % 1000 == 0:
            log.warning("recorder: ignored message #%d: %s", self.malformed, why)
