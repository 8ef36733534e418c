"""The live viewer's side of a recording: its own stream, its own row buffers, its background connection."""

from __future__ import annotations

import logging
import subprocess
import threading
import time
from collections import defaultdict
from pathlib import Path

import rerun as rr

from auv_swarm.recorder.options import RecorderOptions
from auv_swarm.recorder.rows import Rows
from auv_swarm.recorder.viewer import spawn_live_viewer, viewer_reachable

log = logging.getLogger(__name__)

Scalars = dict[str, tuple[list[float], list[float]]]
"""Buffered scalar rows by entity: (times s, values)."""


def scalar_buffers() -> Scalars:
    """Empty scalar buffers that grow an entity's (times, values) on first use."""
    return defaultdict(lambda: ([], []))


class LiveViewer:
    """A second recording stream with the recording's id, connected from a background thread.

    ``state`` is "off" (none asked for), "connecting", "connected" or "unreachable"; ``viewer`` is
    the viewer process it spawned, if any. ``rows``/``scalars`` are its own buffers (None unless
    connecting or connected), sent every ``live_flush_s`` of wall time by :meth:`take_due`. The
    connection spawns a viewer if asked, probes the urls and attaches gRPC sinks to the reachable
    ones after a TCP probe, so a missing viewer costs the mission nothing.
    """

    def __init__(self, options: RecorderOptions, app_id: str, recording_id: str, rrd_path: Path) -> None:
        self.options = options
        self.rrd_path = rrd_path
        self.state = "off"
        self.viewer: subprocess.Popen | None = None
        self.rows: dict[str, Rows] | None = None
        self.scalars: Scalars | None = None
        self.sent_at = time.monotonic()
        self._stream: rr.RecordingStream | None = None
        self._closed = False
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        if options.live:
            self._stream = rr.RecordingStream(app_id, recording_id=recording_id)
            self.rows, self.scalars = {}, scalar_buffers()
            self.state = "connecting"
            self._thread = threading.Thread(target=self._connect, name="rerun-live-connect", daemon=True)

    def start(self) -> None:
        """Start connecting in the background (after the static data is logged to :meth:`stream`)."""
        if self._thread is not None:
            self._thread.start()

    def stream(self) -> rr.RecordingStream | None:
        """The live stream while it is connecting or connected, else None."""
        with self._lock:
            return self._stream if self.state in ("connecting", "connected") else None

    def take_due(self, now_too: bool) -> tuple[rr.RecordingStream, dict[str, Rows], Scalars] | None:
        """(stream, rows, scalars) to send when ``live_flush_s`` has passed since the last send (or ``now_too``),
        else None; the send time is taken as now."""
        live = self.stream()
        now = time.monotonic()
        rows, scalars = self.rows, self.scalars
        if live is None or rows is None or scalars is None:
            return None
        if not (now_too or now - self.sent_at >= self.options.live_flush_s):
            return None
        self.sent_at = now
        return live, rows, scalars

    def close(self) -> rr.RecordingStream | None:
        """Stop connecting; the stream to release if it was connected."""
        with self._lock:
            self._closed = True
            return self._stream if self.state == "connected" else None

    def _connect(self) -> None:
        """Background thread: spawn a viewer if asked, probe the urls, and attach gRPC sinks to the reachable ones."""
        urls = []
        if self.options.spawn_viewer:
            port = self.options.viewer_port
            local = f"rerun+http://127.0.0.1:{port}/proxy"
            urls.append(local)
            if not viewer_reachable(local, 0.2):
                self.viewer = spawn_live_viewer(port, self.rrd_path.parent / "viewer.log", lambda: self._closed)
        if self.options.url is not None:
            urls.append(self.options.url)
        reachable = [u for u in urls if viewer_reachable(u, self.options.connect_timeout_s)]
        with self._lock:
            if self._closed or self._stream is None:
                return
            if not reachable:
                self.state = "unreachable"
                self._stream = None
                self.rows = self.scalars = None
                log.warning("recorder: no rerun viewer at %s; recording to %s only", ", ".join(urls), self.rrd_path)
                return
            self._stream.set_sinks(*(rr.GrpcSink(u) for u in reachable))
            self.state = "connected"
