"""Progress of a long command on stderr: one helper for every verb that runs longer than a few seconds.

On a terminal it is a bar redrawn in place (``\\r``). When stderr is not a terminal
(a log file, a pipe, CI) it is a plain line when the work starts, one every
``every_s`` seconds of wall time and one when it ends, so a redirected log gets
readable lines and no carriage returns. A background thread keeps the lines (and
the bar's elapsed time) coming while one long step runs.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable
from typing import TextIO

from auv_swarm.contract.usage import plural

BAR_WIDTH = 25
TTY_REDRAW_S = 0.1
"""Shortest wall time between two redraws of the bar (s), unless the percentage changed."""
PLAIN_EVERY_S = 10.0
"""Wall time between two plain progress lines when stderr is not a terminal (s)."""


class Progress:
    """Report ``done`` out of ``total`` units of work, labelled ``label``.

    Call :meth:`update` (or the object itself, ``progress(done, total)``, the
    callback shape the mission loops use) as work is done, and :meth:`close` (or
    use it as a context manager) at the end. ``enabled`` False prints nothing.
    ``tty`` None asks the stream; ``clock`` is a monotonic wall clock in s;
    ``heartbeat`` redraws from a background thread when no update came for a while.
    """

    def __init__(
        self,
        label: str,
        total: float,
        unit: str = "",
        *,
        enabled: bool = True,
        stream: TextIO | None = None,
        every_s: float = PLAIN_EVERY_S,
        tty: bool | None = None,
        clock: Callable[[], float] = time.monotonic,
        heartbeat: bool = True,
    ) -> None:
        if not (math.isfinite(total) and total >= 0):
            raise ValueError(f"total must be a finite number >= 0, got {total!r}")
        if not every_s > 0:
            raise ValueError(f"every_s must be > 0 s, got {every_s!r}")
        self.label = label
        self.total = float(total)
        self.unit = unit
        self.enabled = enabled
        self.stream = stream if stream is not None else sys.stderr
        self.every_s = float(every_s)
        self.tty = _isatty(self.stream) if tty is None else tty
        self.clock = clock
        self.done = 0.0
        self.closed = False
        self._start = clock()
        self._last_draw = -math.inf
        self._last_pct = -1
        self._started_line = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None
        self._draw(force=True)
        if enabled and heartbeat:
            self._ticker = threading.Thread(target=self._beat, name="progress", daemon=True)
            self._ticker.start()

    def __call__(self, done: float, total: float | None = None) -> None:
        self.update(done, total)

    def update(self, done: float, total: float | None = None) -> None:
        """Set the work done so far (and the total, if it changed); redraw if due."""
        if total is not None and math.isfinite(total) and total >= 0:
            self.total = float(total)
        self.done = float(done)
        self._draw(force=False)

    def _draw(self, force: bool) -> None:
        with self._lock:
            if not self.enabled or self.closed:
                return
            now = self.clock()
            pct = self.percent()
            if self.tty:
                if force or pct != self._last_pct or now - self._last_draw >= TTY_REDRAW_S:
                    self._write("\r" + self.line(now) + "\x1b[K")
                    self._last_pct, self._last_draw = pct, now
            elif not self._started_line or (now - self._last_draw >= self.every_s and not self._finished()):
                self._write(self.line(now) + "\n")
                self._started_line, self._last_draw = True, now

    def _finished(self) -> bool:
        """All the work is done: into a log only :meth:`close` prints the last line (never two at 100 %)."""
        return self.total > 0 and self.done >= self.total

    def _beat(self) -> None:
        """Background thread: redraw about once a second on a terminal, every ``every_s`` into a log."""
        period = 1.0 if self.tty else self.every_s
        while not self._stop.wait(period):
            self._draw(force=self.tty)

    def clear(self) -> None:
        """End the bar's line on a terminal, so that the next message starts on a line of its own.

        The bar is drawn again on the next update; into a log nothing is needed (every line ends).
        """
        with self._lock:
            if self.enabled and self.tty and not self.closed and self._last_draw > -math.inf:
                self._write("\n")
                self._last_draw, self._last_pct = -math.inf, -1

    def advance(self, amount: float = 1.0) -> None:
        """Add ``amount`` units to the work done."""
        self.update(self.done + amount)

    def close(self, final: str | None = None) -> None:
        """Print the final state once (the bar's line ends; a last plain line); ``final``, if given, replaces the
        elapsed time at its end (``mission wall 8.9 s, run wall 11.2 s``)."""
        self._stop.set()
        if self._ticker is not None and self._ticker is not threading.current_thread():
            self._ticker.join(timeout=5.0)
        with self._lock:
            if self.closed:
                return
            if self.enabled:
                now = self.clock()
                text = self.line(now)
                if final is not None:
                    elapsed = f"  {_duration(now - self._start)} elapsed"
                    text = text.split(elapsed)[0] + f"  {final}"
                self._write(("\r" + text + "\x1b[K\n") if self.tty else text + "\n")
            self.closed = True

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def percent(self) -> int:
        """Whole percent done (100 when the total is 0)."""
        return int(100 * min(1.0, self.done / self.total)) if self.total > 0 else 100

    def line(self, now: float) -> str:
        """The progress text at wall time ``now``: label, bar (terminal only), percent, counts, elapsed, ETA."""
        pct = self.percent()
        elapsed = now - self._start
        counts = f"{_num(self.done)} / {_num(self.total)}{' ' + self.unit if self.unit else ''}"
        text = f"{self.label}: {pct:3d}%  {counts}  {_duration(elapsed)} elapsed"
        if 0 < self.done < self.total and elapsed > 0:
            text += f", about {_duration(elapsed * (self.total - self.done) / self.done)} left"
        if self.tty:
            filled = pct * BAR_WIDTH // 100
            text = f"[{'#' * filled}{'-' * (BAR_WIDTH - filled)}] {text}"
        return text

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):
            self.enabled = False


def _isatty(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def _num(x: float) -> str:
    return f"{x:.0f}" if abs(x - round(x)) < 1e-9 or abs(x) >= 100 else f"{x:.1f}"


def _duration(seconds: float) -> str:
    s = int(round(max(0.0, seconds)))
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


class SweepProgress(Progress):
    """A sweep's progress: missions done / skipped (done before) / failed out of the total, missions per minute
    and the time left (the rate counts only missions run by this command)."""

    def __init__(self, label: str, total: int, **kwargs: object) -> None:
        self.skipped = 0
        self.failed = 0
        self.ran = 0
        super().__init__(label, total, "missions", **kwargs)  # type: ignore[arg-type]

    def counts(self, done: int, skipped: int, failed: int, total: int | None = None) -> None:
        """Set the counts (``done`` counts missions finished by this command, failed ones included)."""
        self.skipped, self.failed, self.ran = skipped, failed, done + failed
        self.update(skipped + done + failed, total)

    def line(self, now: float) -> str:
        elapsed = now - self._start
        done = int(self.done) - self.skipped - self.failed
        text = (
            f"{self.label}: {self.percent():3d}%  {done} done, {self.skipped} skipped, {self.failed} failed "
            f"/ {plural(int(self.total), 'mission')}  {_duration(elapsed)} elapsed"
        )
        if self.ran and elapsed > 0:
            rate = self.ran / elapsed
            text += f", {60 * rate:.1f} missions/min"
            left = self.total - self.done
            if left > 0:
                text += f", about {_duration(left / rate)} left"
        if self.tty:
            filled = self.percent() * BAR_WIDTH // 100
            text = f"[{'#' * filled}{'-' * (BAR_WIDTH - filled)}] {text}"
        return text
