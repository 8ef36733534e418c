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

Rows are buffered per entity and sent with ``send_columns`` every ``flush_every``
ticks, or sooner once the oldest buffered row has waited ``flush_after_s`` of wall
time (so a live viewer of a paced or slow run stays current, and a kill -9 loses at
most that much), on :meth:`flush` and on :meth:`close`. :meth:`close` then merges the
file's small chunks (``compact``), so the same data gives about the same file size
however the run was paced. The file sink never blocks. A live
viewer (``spawn_viewer`` or ``url``) gets a second recording stream with the same
recording id, connected from a background thread after a TCP probe, so a missing
viewer costs the mission nothing.
"""

from __future__ import annotations

import functools
import logging
import math
import re
import socket
import subprocess
import threading
import time
import uuid
from collections import defaultdict, deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from contract import wire
from contract.config import Scenario, dump_toml
from recorder.viewer import TIMELINE, compact, viewer_binary

log = logging.getLogger(__name__)

APP_ID = "auv-swarm"
DEFAULT_VIEWER_PORT = 9876
DEFAULT_FLUSH_EVERY = 250
DEFAULT_FLUSH_AFTER_S = 0.5
TRAIL_PERIOD_S = 10.0
"""Spacing of the trail points (s of sim time); a trail row is logged each time a point is added."""
ELLIPSE_CONFIDENCE = 0.95
ELLIPSE_POINTS = 48
HEADING_ARROW_M = 80.0
VIEWER_START_S = 15.0
"""Wall time a spawned viewer gets to start listening (s)."""
HISTORY_TICKS = 256
"""Truths (and measured bearings) kept for late telemetry: zenoh orders nothing across publishers."""
PENDING_TICKS = HISTORY_TICKS
"""Telemetry waits for the Truth of its tick until telemetry of this many ticks is waiting (early telemetry)."""
_MAX_WARNINGS = 10

_AUV_COLOURS = np.array(
    [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (148, 103, 189),
        (23, 190, 207),
        (227, 119, 194),
        (188, 189, 34),
        (140, 86, 75),
    ],
    dtype=np.uint8,
)
_TARGET_COLOUR = (214, 39, 40, 255)
_DEAD_COLOUR = (120, 120, 120, 255)
_REASON_COLOURS = {
    "random_loss": (200, 200, 200, 200),
    "low_snr": (255, 80, 80, 220),
    "outside_slot": (255, 200, 0, 220),
    "oversize": (255, 0, 255, 220),
    "collision": (255, 140, 0, 220),
    "half_duplex": (0, 200, 255, 220),
    "recipient_dead": (120, 120, 120, 220),
}
_OTHER_REASON_COLOUR = (255, 255, 255, 220)
_EVENT_LEVELS = {
    "start": "INFO",
    "end": "INFO",
    "abort": "ERROR",
    "rejoin": "INFO",
    "kill": "WARN",
    "death": "ERROR",
    "hung": "WARN",
    "resume": "INFO",
}
_SEGMENT_BAD = re.compile(r"[^A-Za-z0-9_.-]")


def auv_colour(auv: int, alpha: int = 255) -> tuple[int, int, int, int]:
    """The display colour (RGBA, 0-255) of AUV ``auv``."""
    r, g, b = (int(c) for c in _AUV_COLOURS[auv % len(_AUV_COLOURS)])
    return (r, g, b, alpha)


def snr_colour(snr_db: float | None, threshold_db: float, span_db: float) -> tuple[int, ...]:
    """RGBA of a delivered packet: red at ``threshold_db`` (DT), yellow half-way, green at DT + ``span_db`` and above."""
    if not span_db > 0.0:
        raise ValueError(f"span_db must be > 0 dB, got {span_db!r}")
    if snr_db is None or not math.isfinite(snr_db):
        return (160, 160, 160, 230)
    s = min(1.0, max(0.0, (snr_db - threshold_db) / span_db))
    r = 255 if s < 0.5 else int(round(255 * 2 * (1.0 - s)))
    g = int(round(255 * 2 * s)) if s < 0.5 else 255
    return (r, g, 40, 230)


def covariance_ellipse(
    center: Sequence[float], cov: Any, confidence: float = ELLIPSE_CONFIDENCE, n_points: int = ELLIPSE_POINTS
) -> np.ndarray:
    """Closed polyline (n_points + 1, 2) of the ``confidence`` region of a 2-D Gaussian (m).

    ``cov`` is the 2x2 position block of the estimate covariance P (eq. 15, m^2),
    symmetrised; negative eigenvalues (round-off) count as zero. The scale is the
    chi-square quantile with 2 degrees of freedom, sqrt(-2 ln(1 - confidence)).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 3:
        raise ValueError(f"n_points must be an integer >= 3, got {n_points!r}")
    c = np.asarray(cov, dtype=float)
    mu = np.asarray(center, dtype=float)
    if c.shape != (2, 2) or mu.shape != (2,):
        raise ValueError(f"cov must be 2x2 and center of length 2, got shapes {c.shape} and {mu.shape}")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(mu))):
        raise ValueError("cov and center must be finite")
    scale = float(np.max(np.abs(c))) or 1.0
    a, b, d = c[0, 0] / scale, 0.5 * (c[0, 1] + c[1, 0]) / scale, c[1, 1] / scale
    mid, half = 0.5 * (a + d), math.hypot(0.5 * (a - d), b)
    k = math.sqrt(-2.0 * math.log1p(-confidence) * scale)
    major, minor = k * math.sqrt(max(mid + half, 0.0)), k * math.sqrt(max(mid - half, 0.0))
    theta = 0.5 * math.atan2(2.0 * b, a - d)
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    axes = np.array([[major * cos_t, -minor * sin_t], [major * sin_t, minor * cos_t]])
    return mu + (axes @ _unit_circle(n_points)).T


@functools.cache
def _unit_circle(n_points: int) -> np.ndarray:
    """(2, n_points + 1) cos/sin of n_points + 1 angles from 0 to 2 pi (closed)."""
    angles = np.linspace(0.0, 2.0 * math.pi, n_points + 1)
    return np.stack([np.cos(angles), np.sin(angles)])


def circle(center: Sequence[float], radius_m: float, n_points: int = 64) -> np.ndarray:
    """Closed polyline (n_points + 1, 2) of the circle of ``radius_m`` (m) around ``center`` (m)."""
    if not (math.isfinite(radius_m) and radius_m >= 0.0):
        raise ValueError(f"radius_m must be a finite number >= 0 m, got {radius_m!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 3:
        raise ValueError(f"n_points must be an integer >= 3, got {n_points!r}")
    return np.asarray(center, dtype=float) + radius_m * _unit_circle(n_points).T


def _segment(name: str) -> str:
    """``name`` as one entity-path segment (characters other than letters, digits, _ . - become _)."""
    return _SEGMENT_BAD.sub("_", name) or "_"


def _counter_entity(name: str) -> str:
    """Packet counters (sent, delivered, deferred, dropped_<reason>) under plots/channel, the rest under channel_other."""
    packet = name in ("sent", "delivered", "deferred") or name.startswith("dropped_")
    return f"plots/{'channel' if packet else 'channel_other'}/{_segment(name)}"


class _Rows:
    """One entity's rows awaiting ``send_columns``: sim times (s) and the instances of each component per row."""

    def __init__(self, archetype: Any) -> None:
        self.archetype = archetype
        self.times: list[float] = []
        self.lengths: list[int] = []
        self.components: dict[str, list[Any]] = {}

    def add(self, t_s: float, **components: Sequence[Any]) -> None:
        lengths = {len(v) for v in components.values()}
        if len(lengths) != 1:
            raise ValueError(f"components of one row must have equal lengths, got {sorted(lengths)}")
        if not self.components:
            self.components = {k: [] for k in components}
        elif set(components) != set(self.components):
            raise ValueError(f"every row must give the components {sorted(self.components)}, got {sorted(components)}")
        self.times.append(float(t_s))
        self.lengths.append(lengths.pop())
        for k, v in components.items():
            self.components[k].extend(v)

    def columns(self) -> Any:
        data: dict[str, Any] = {}
        for k, v in self.components.items():
            if k in ("positions", "origins", "vectors"):
                data[k] = np.asarray(v, dtype=np.float32).reshape(-1, 2)
            elif k == "colors":
                data[k] = np.asarray(v, dtype=np.uint8).reshape(-1, 4)
            elif k in ("radii", "draw_order"):
                data[k] = np.asarray(v, dtype=np.float32)
            elif k == "strips":
                strips = [np.asarray(s, dtype=np.float32).reshape(-1, 2) for s in v]
                uniform = strips and all(len(s) == len(strips[0]) for s in strips)
                data[k] = np.stack(strips) if uniform else strips
            else:
                data[k] = list(v)
        return self.archetype.columns(**data).partition(self.lengths)

    def clear(self) -> None:
        self.times.clear()
        self.lengths.clear()
        for v in self.components.values():
            v.clear()


class _Trail:
    """Past positions (m) spaced ``period_s`` apart in sim time."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.points: list[tuple[float, float]] = []
        self.last_t = -math.inf

    def update(self, t_s: float, xy: tuple[float, float]) -> list[tuple[float, float]] | None:
        """Append ``xy`` if ``period_s`` has passed since the last point and return the trail, else None."""
        if t_s - self.last_t < self.period_s - 1e-9:
            return None
        self.points.append(xy)
        self.last_t = t_s
        return list(self.points)


TRACKING_ERROR_RANGE_M = 100.0
"""Upper end of the tracking-error plot's initial y range (m): the 15 m bound and the 50 m track-lost level in view."""


def blueprint(scenario: Scenario) -> rrb.Blueprint:
    """The viewer layout: the 2-D map on the left, the plots and the event log in a grid on the right."""
    mission = rrb.TimeRange(
        start=rrb.TimeRangeBoundary.absolute(seconds=0.0),
        end=rrb.TimeRangeBoundary.absolute(seconds=scenario.run.duration_s),
    )

    def plot(name: str, origin: str, axis_y: rrb.ScalarAxis | None = None) -> rrb.TimeSeriesView:
        return rrb.TimeSeriesView(
            name=name,
            origin=origin,
            plot_legend=rrb.PlotLegend(visible=True),
            axis_x=rrb.TimeAxis(view_range=mission),
            axis_y=axis_y,
        )

    plots = [
        # a fixed 0-100 m y range (zoomable): one early spike of hundreds of metres no longer flattens the rest
        plot("tracking error (m)", "plots/tracking_error", rrb.ScalarAxis(range=(0.0, TRACKING_ERROR_RANGE_M))),
        plot("Fiedler value lambda_2 (eq. 37)", "plots/fiedler"),
        plot("cost: geometry (eq. 34)", "plots/cost/geometry"),
        plot("cost: distance (eq. 36)", "plots/cost/distance"),
        plot("cost: connectivity (eq. 37)", "plots/cost/connectivity"),
        plot("planning time (ms, wall clock)", "plots/plan_ms"),
        plot("channel counters (cumulative)", "plots/channel"),
        rrb.TextLogView(name="events", origin="events"),
    ]
    title = f"map: {scenario.name} (m, x east, y north)"
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name=title, origin="/", contents=["world/**"]),
            rrb.Grid(*plots, grid_columns=2),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=TIMELINE, play_state="following", state="collapsed"),
        collapse_panels=True,
    )


def _viewer_reachable(url: str, timeout_s: float) -> bool:
    """True if a TCP connection to the host and port of a rerun gRPC ``url`` succeeds within ``timeout_s``."""
    parsed = urlparse(url)
    host = parsed.hostname or "127.0.0.1"
    port = parsed.port or (443 if parsed.scheme.endswith("https") else DEFAULT_VIEWER_PORT)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def check_url(url: str) -> str:
    """Validate a rerun gRPC url (``rerun+http://HOST:PORT/proxy``); ValueError names the allowed form."""
    parsed = urlparse(str(url))
    if parsed.scheme not in ("rerun", "rerun+http", "rerun+https") or not parsed.hostname or parsed.path != "/proxy":
        raise ValueError(f"rerun url must look like rerun+http://HOST:PORT/proxy, got {url!r}")
    return str(url)


class RerunRecorder:
    """Sink of wire messages that logs the mission to ``rrd_path`` and, optionally, to a live viewer.

    ``on_message`` never raises: anything unexpected or malformed (an unknown
    message type, an AUV id outside the scenario, a non-finite number) is counted
    in ``malformed`` and logged. ``busy_s`` is the wall time spent inside the
    recorder (s). ``live_state`` is "off", "connecting", "connected" or
    "unreachable"; ``viewer`` is the viewer process it spawned, if any. Feed it
    from one thread.
    """

    def __init__(
        self,
        scenario: Scenario,
        rrd_path: Path,
        *,
        spawn_viewer: bool = False,
        url: str | None = None,
        flush_every: int = DEFAULT_FLUSH_EVERY,
        flush_after_s: float = DEFAULT_FLUSH_AFTER_S,
        viewer_port: int = DEFAULT_VIEWER_PORT,
        connect_timeout_s: float = 2.0,
        compact_at_close: bool = True,
    ) -> None:
        if isinstance(flush_every, bool) or not isinstance(flush_every, int) or flush_every < 1:
            raise ValueError(f"flush_every must be an integer >= 1 (ticks), got {flush_every!r}")
        if isinstance(flush_after_s, bool) or not isinstance(flush_after_s, (int, float)) or not flush_after_s >= 0:
            raise ValueError(f"flush_after_s must be a number >= 0 (s of wall time), got {flush_after_s!r}")
        if isinstance(viewer_port, bool) or not isinstance(viewer_port, int) or not 1 <= viewer_port <= 65535:
            raise ValueError(f"viewer_port must be an integer in [1, 65535], got {viewer_port!r}")
        if not connect_timeout_s > 0:
            raise ValueError(f"connect_timeout_s must be > 0 s, got {connect_timeout_s!r}")
        if url is not None:
            check_url(url)
        started = time.perf_counter()
        self.scenario = scenario
        self.rrd_path = Path(rrd_path)
        self.rrd_path.parent.mkdir(parents=True, exist_ok=True)
        self.flush_every = flush_every
        self.flush_after_s = float(flush_after_s)
        self.compact_at_close = compact_at_close
        self.malformed = 0
        self.received = 0
        self.busy_s = 0.0
        self.live_state = "off"
        self.viewer: subprocess.Popen | None = None
        self._n = scenario.agents.count
        self._closed = False
        self._lock = threading.Lock()
        self._rows: dict[str, _Rows] = {}
        self._scalars: dict[str, tuple[list[float], list[float]]] = defaultdict(lambda: ([], []))
        self._truths: dict[int, wire.Truth] = {}
        self._last_truth: wire.Truth | None = None
        self._pending: dict[int, list[wire.Telemetry]] = defaultdict(list)
        self._bearings: dict[tuple[int, int], float] = {}
        self._packets: deque[wire.PacketEvent] = deque()
        self._channel_counts: dict[str, int] = {}
        self._trails: dict[str, _Trail] = defaultdict(lambda: _Trail(TRAIL_PERIOD_S))
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
        self._live: rr.RecordingStream | None = None
        self._live_thread: threading.Thread | None = None
        if spawn_viewer or url is not None:
            self._live = rr.RecordingStream(APP_ID, recording_id=recording_id)
            self.live_state = "connecting"
            self._live_thread = threading.Thread(
                target=self._connect_live,
                args=(spawn_viewer, url, viewer_port, connect_timeout_s),
                name="rerun-live-connect",
                daemon=True,
            )
        for stream in self._streams():
            self._send_static(stream)
        if self._live_thread is not None:
            self._live_thread.start()
        self.busy_s += time.perf_counter() - started

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
            self._send_rows()
        finally:
            with self._lock:
                self._closed = True
                live, connected = self._live, self.live_state == "connected"
            self._rec.flush()
            self._rec.disconnect()
            if live is not None and connected:
                self._release_live(live)
            if self.compact_at_close:
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
        target = _finite(m.target, "Truth.target", 4)
        agents = {}
        for a, pose in m.agents.items():
            agents[self._auv(a, "Truth.agents")] = _finite(pose, f"Truth.agents[{a}]", 3)
        alive = {self._auv(a, "Truth.alive") for a in m.alive}
        t = float(m.t_s)
        self._truths[m.tick] = m
        if len(self._truths) > 2 * HISTORY_TICKS:
            self._truths = {k: v for k, v in self._truths.items() if k >= m.tick - HISTORY_TICKS}
            self._bearings = {k: v for k, v in self._bearings.items() if k[1] >= m.tick - HISTORY_TICKS}
        self._last_truth = m

        txy = (target[0], target[1])
        self._row(rr.Points2D, "world/target/truth", t, positions=[txy], colors=[_TARGET_COLOUR], radii=[-6.0])
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
        for a, (x, y, theta) in sorted(agents.items()):
            colour = auv_colour(a) if a in alive else _DEAD_COLOUR
            base = f"world/auv/{a}"
            label = f"AUV {a}" if a in alive else f"AUV {a} (dead)"
            self._row(
                rr.Points2D, f"{base}/truth", t, positions=[(x, y)], colors=[colour], radii=[-5.0], labels=[label]
            )
            vec = (HEADING_ARROW_M * math.cos(theta), HEADING_ARROW_M * math.sin(theta))
            self._row(rr.Arrows2D, f"{base}/heading", t, origins=[(x, y)], vectors=[vec], colors=[colour], radii=[-1.5])
            strip = self._trails[base].update(t, (x, y))
            if strip is not None:
                self._row(
                    rr.LineStrips2D, f"{base}/trail", t, strips=[strip], colors=[(*colour[:3], 140)], radii=[-1.0]
                )
        for a in sorted(set(agents) - alive - self._cleared):
            self._cleared.add(a)
            self._row(rr.Points2D, f"world/auv/{a}/estimate", t, positions=[], colors=[], radii=[])
            for tail in ("estimate/covariance", "bearing", "plan"):
                self._row(rr.LineStrips2D, f"world/auv/{a}/{tail}", t, strips=[], colors=[], radii=[])
        self._cleared &= set(agents) - alive
        self._log_packets(t, agents)
        for name, value in sorted(self._channel_counts.items()):
            self._scalar(_counter_entity(name), t, value)
        for tick in sorted(k for k in self._pending if k <= m.tick):
            for tm in self._pending.pop(tick):
                self._log_telemetry(tm, self._truths.get(tick))
        self._ticks_unflushed += 1
        now = time.monotonic()
        if self._unflushed_since is None:
            self._unflushed_since = now
        if self._ticks_unflushed >= self.flush_every or now - self._unflushed_since >= self.flush_after_s:
            self._send_rows()

    def _on_telemetry(self, m: wire.Telemetry) -> None:
        self._auv(m.auv, "Telemetry.auv")
        _finite(m.xi, "Telemetry.xi", 4)
        _finite(m.P, "Telemetry.P", 16)
        for i, wp in enumerate(m.waypoints):
            _finite(wp, f"Telemetry.waypoints[{i}]", 2)
        _finite([m.cost, m.plan_wall_ms, m.fiedler, *m.terms.values()], "Telemetry cost, terms, plan_wall_ms, fiedler")
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
                self._scalar(_counter_entity(name), float(m.t_s), value)

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
            self._send_rows()

    def _on_sensor(self, m: wire.Sensor) -> None:
        self._auv(m.auv, "Sensor.auv")
        if m.bearing_rad is not None:
            self._bearings[(m.auv, m.tick)] = _finite([m.bearing_rad], "Sensor.bearing_rad", 1)[0]

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
        if pose is not None:
            origin = (pose[0], pose[1])
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
            start = [(pose[0], pose[1])] if pose is not None else []
            strip = [*start, *m.waypoints]
            self._row(rr.LineStrips2D, f"{base}/plan", t, strips=[strip], colors=[colour], radii=[-2.0])
        if m.estimate_ok and truth is not None:
            err = math.hypot(m.xi[0] - truth.target[0], m.xi[1] - truth.target[1])
            self._scalar(f"plots/tracking_error/auv{a}", t, err)
        if m.planned:
            for term, value in sorted(m.terms.items()):
                self._scalar(f"plots/cost/{_segment(term)}/auv{a}", t, value)
            self._scalar(f"plots/cost/total/auv{a}", t, m.cost)
            self._scalar(f"plots/fiedler/auv{a}", t, m.fiedler)
            self._scalar(f"plots/plan_ms/auv{a}", t, m.plan_wall_ms)

    def _log_packets(self, t: float, agents: dict[int, tuple[float, float, float]]) -> None:
        """The packets of the last slot, drawn between the current true positions."""
        window = self.scenario.channel.slot_s
        while self._packets and self._packets[0].t_s <= t - window:
            self._packets.popleft()
        threshold, span = self._snr_scale
        delivered: list[Any] = []
        delivered_colours: list[tuple[int, ...]] = []
        dropped: list[Any] = []
        dropped_colours: list[tuple[int, ...]] = []
        dropped_labels: list[str] = []
        frames: list[tuple[float, float]] = []
        frame_colours: list[tuple[int, ...]] = []
        frame_labels: list[str] = []
        for p in self._packets:
            if p.t_s > t or p.sender not in agents:
                continue
            src = agents[p.sender][:2]
            reason = p.reason or "unknown"
            if p.recipient == -1:
                if p.kind == "dropped":
                    frames.append(src)
                    frame_colours.append(_REASON_COLOURS.get(reason, _OTHER_REASON_COLOUR))
                    frame_labels.append(reason)
                continue
            if p.recipient not in agents:
                continue
            strip = [src, agents[p.recipient][:2]]
            if p.kind == "delivered":
                delivered.append(strip)
                delivered_colours.append(snr_colour(p.snr_db, threshold, span))
            else:
                dropped.append(strip)
                dropped_colours.append(_REASON_COLOURS.get(reason, _OTHER_REASON_COLOUR))
                dropped_labels.append(reason)
        self._row(
            rr.LineStrips2D,
            "world/packets/delivered",
            t,
            strips=delivered,
            colors=delivered_colours,
            radii=[-1.5] * len(delivered),
        )
        self._row(
            rr.LineStrips2D,
            "world/packets/dropped",
            t,
            strips=dropped,
            colors=dropped_colours,
            labels=dropped_labels,
            radii=[-1.0] * len(dropped),
        )
        self._row(
            rr.Points2D,
            "world/packets/dropped_frames",
            t,
            positions=frames,
            colors=frame_colours,
            labels=frame_labels,
            radii=[-8.0] * len(frames),
        )

    def _row(self, archetype: Any, entity: str, t_s: float, **components: Sequence[Any]) -> None:
        rows = self._rows.get(entity)
        if rows is None:
            rows = self._rows[entity] = _Rows(archetype)
        rows.add(t_s, **components)

    def _scalar(self, entity: str, t_s: float, value: float) -> None:
        if entity not in self._styled:
            self._styled.add(entity)
            match = re.search(r"/auv(\d+)$", entity)
            if match is not None:
                a = int(match.group(1))
                for stream in self._streams():
                    stream.log(entity, rr.SeriesLines(colors=[auv_colour(a)], names=[f"AUV {a}"]), static=True)
        times, values = self._scalars[entity]
        times.append(float(t_s))
        values.append(float(value))

    def _send_rows(self) -> None:
        """Send every buffered row with one ``send_columns`` per entity and stream."""
        self._ticks_unflushed = 0
        self._unflushed_since = None
        batches = []
        for entity, rows in self._rows.items():
            if rows.times:
                batches.append((entity, list(rows.times), rows.columns()))
                rows.clear()
        for entity, (times, values) in self._scalars.items():
            if times:
                batches.append((entity, list(times), rr.Scalars.columns(scalars=np.asarray(values, dtype=float))))
                times.clear()
                values.clear()
        for stream in self._streams():
            for entity, times, columns in batches:
                stream.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=_nanos(times))], columns=columns)

    def _send_static(self, stream: rr.RecordingStream) -> None:
        stream.send_recording_name(f"{self.scenario.name} (seed {self.scenario.run.seed})")
        stream.send_blueprint(blueprint(self.scenario), make_active=True, make_default=True)
        stream.log("world", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        stream.log("scenario", rr.TextDocument(dump_toml(self.scenario), media_type="text/plain"), static=True)

    def _streams(self) -> list[rr.RecordingStream]:
        with self._lock:
            live = self._live if self.live_state in ("connecting", "connected") else None
        return [self._rec] if live is None else [self._rec, live]

    def _auv(self, auv: int, where: str) -> int:
        if isinstance(auv, bool) or not isinstance(auv, int) or not 0 <= auv < self._n:
            raise ValueError(f"{where} must be an AUV id in [0, {self._n - 1}], got {auv!r}")
        return auv

    def _reject(self, why: str) -> None:
        self.malformed += 1
        if self.malformed <= _MAX_WARNINGS or self.malformed % 1000 == 0:
            log.warning("recorder: ignored message #%d: %s", self.malformed, why)

    # Live viewer --------------------------------------------------------------------------------------------------

    def _connect_live(self, spawn_viewer: bool, url: str | None, port: int, timeout_s: float) -> None:
        """Background thread: spawn a viewer if asked, probe the urls, and attach gRPC sinks to the reachable ones."""
        urls = []
        if spawn_viewer:
            local = f"rerun+http://127.0.0.1:{port}/proxy"
            urls.append(local)
            if not _viewer_reachable(local, 0.2):
                self._spawn_viewer(port)
        if url is not None:
            urls.append(url)
        reachable = [u for u in urls if _viewer_reachable(u, timeout_s)]
        with self._lock:
            if self._closed or self._live is None:
                return
            if not reachable:
                self.live_state = "unreachable"
                self._live = None
                log.warning("recorder: no rerun viewer at %s; recording to %s only", ", ".join(urls), self.rrd_path)
                return
            self._live.set_sinks(*(rr.GrpcSink(u) for u in reachable))
            self.live_state = "connected"

    def _spawn_viewer(self, port: int) -> None:
        """Start the viewer binary (detached, so it outlives the run) and wait until it listens on ``port``.

        ``rr.spawn`` is not used: it holds the GIL while it waits for the viewer,
        which would stall the mission. The viewer's output goes to viewer.log beside
        the recording.
        """
        log_path = self.rrd_path.parent / "viewer.log"
        try:
            with open(log_path, "ab") as out:
                self.viewer = subprocess.Popen(
                    [viewer_binary(), "--port", str(port), "--hide-welcome-screen", "--expect-data-soon"],
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
        except OSError as exc:
            log.warning("recorder: could not start the rerun viewer: %s", exc)
            return
        deadline = time.monotonic() + VIEWER_START_S
        while time.monotonic() < deadline and not self._closed:
            if self.viewer.poll() is not None:
                log.warning("recorder: the rerun viewer exited with %s; see %s", self.viewer.returncode, log_path)
                return
            if _viewer_reachable(f"rerun+http://127.0.0.1:{port}/proxy", 0.2):
                return
            time.sleep(0.1)

    @staticmethod
    def _release_live(live: rr.RecordingStream) -> None:
        """Flush the live stream briefly and disconnect it off the caller's thread (a vanished viewer can take 5 s)."""

        def release() -> None:
            try:
                live.flush(timeout_sec=2.0)
            except RuntimeError as exc:
                log.warning("recorder: live viewer did not take the last data: %s", exc)
            live.disconnect()

        worker = threading.Thread(target=release, name="rerun-live-release", daemon=True)
        worker.start()
        worker.join(timeout=3.0)


def _nanos(times_s: Sequence[float]) -> np.ndarray:
    """Sim times (s) as a timedelta64[ns] array, rounded to the nearest ns like ``set_time`` does."""
    return np.round(np.asarray(times_s, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")


def _finite(values: Sequence[float], where: str, n: int | None = None) -> tuple[float, ...]:
    """``values`` as floats, or ValueError naming ``where`` if the count is not ``n`` or one is not finite."""
    out = tuple(map(float, values))
    if n is not None and len(out) != n:
        raise ValueError(f"{where} must have {n} values, got {len(out)}")
    if not all(map(math.isfinite, out)):
        raise ValueError(f"{where} must be finite, got {out!r}")
    return out


def overhead(scenario: Scenario, out_dir: Path, repeats: int = 1) -> dict[str, float]:
    """Wall time of an in-process run without and with a :class:`RerunRecorder` sink (best of ``repeats``).

    Returns ``without_s``, ``with_s``, ``ratio`` (with / without), ``recorder_busy_s``
    (wall time spent inside the recorder) and ``rrd_bytes``. The recording goes to
    ``out_dir/recording.rrd``.
    """
    from orchestrator.inprocess import run_inprocess

    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    without, with_rec, busy = math.inf, math.inf, math.inf
    path = Path(out_dir) / "recording.rrd"
    for _ in range(repeats):
        start = time.perf_counter()
        run_inprocess(scenario, [])
        without = min(without, time.perf_counter() - start)
        start = time.perf_counter()
        with RerunRecorder(scenario, path) as recorder:
            run_inprocess(scenario, [recorder])
        with_rec = min(with_rec, time.perf_counter() - start)
        busy = min(busy, recorder.busy_s)
    return {
        "without_s": without,
        "with_s": with_rec,
        "ratio": with_rec / without,
        "recorder_busy_s": busy,
        "rrd_bytes": float(path.stat().st_size),
    }
