"""The recorder's options: one validated frozen value (no rerun here, so a shell can check them cheaply)."""

from __future__ import annotations

from dataclasses import dataclass

from auv_swarm.recorder.viewer import DEFAULT_VIEWER_PORT, check_url

DEFAULT_FLUSH_EVERY = 250
DEFAULT_FLUSH_AFTER_S = 0.5
DEFAULT_LIVE_FLUSH_S = 2.0
"""Wall seconds between sends to a live viewer (its latency grows by at most this much)."""


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass(frozen=True)
class RecorderOptions:
    """How a :class:`~auv_swarm.recorder.core.RerunRecorder` sends what it logs.

    - ``spawn_viewer``: start a native rerun viewer on ``viewer_port`` and stream to it;
      ``url``: stream to a viewer at ``rerun+http://HOST:PORT/proxy`` (either makes a live viewer);
    - ``flush_every`` (ticks) and ``flush_after_s`` (s of wall time): the file's rows are sent every
      ``flush_every`` ticks, or once the oldest buffered row has waited ``flush_after_s``;
    - ``live_flush_s`` (s of wall time): the live viewer's rows are sent on this cadence;
    - ``connect_timeout_s`` (s): how long a viewer url is probed before it counts as unreachable;
    - ``compact_at_close``: merge the file's small chunks when the recorder closes.

    A bad value is a ValueError of one line naming the option and its allowed range.
    """

    spawn_viewer: bool = False
    url: str | None = None
    flush_every: int = DEFAULT_FLUSH_EVERY
    flush_after_s: float = DEFAULT_FLUSH_AFTER_S
    live_flush_s: float = DEFAULT_LIVE_FLUSH_S
    viewer_port: int = DEFAULT_VIEWER_PORT
    connect_timeout_s: float = 2.0
    compact_at_close: bool = True

    def __post_init__(self) -> None:
        if not _is_int(self.flush_every) or self.flush_every < 1:
            raise ValueError(f"flush_every must be an integer >= 1 (ticks), got {self.flush_every!r}")
        for name in ("flush_after_s", "live_flush_s"):
            value = getattr(self, name)
            if not _is_number(value) or not value >= 0:
                raise ValueError(f"{name} must be a number >= 0 (s of wall time), got {value!r}")
            object.__setattr__(self, name, float(value))
        if not _is_int(self.viewer_port) or not 1 <= self.viewer_port <= 65535:
            raise ValueError(f"viewer_port must be an integer in [1, 65535], got {self.viewer_port!r}")
        if not _is_number(self.connect_timeout_s) or not self.connect_timeout_s > 0:
            raise ValueError(f"connect_timeout_s must be > 0 s, got {self.connect_timeout_s!r}")
        if self.url is not None:
            check_url(self.url)

    @property
    def live(self) -> bool:
        """Whether a live viewer is asked for (spawned or at a url)."""
        return self.spawn_viewer or self.url is not None
