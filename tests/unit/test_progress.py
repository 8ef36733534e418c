"""orchestrator.progress: a redrawn bar on a terminal, plain periodic lines into a log."""

from __future__ import annotations

import io

import pytest

from orchestrator.progress import Progress


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_on_a_terminal_the_bar_is_redrawn_in_place_and_ends_with_a_newline() -> None:
    out, clock = io.StringIO(), Clock()
    with Progress("mission", 1500.0, "s sim time", stream=out, tty=True, clock=clock) as progress:
        for t in (0.0, 750.0, 1500.0):
            clock.t += 1.0
            progress(t, 1500.0)
    text = out.getvalue()
    assert text.count("\r") == 4 and text.endswith("\n") and text.count("\n") == 1
    assert "[############-------------] mission:  50%  750 / 1500 s sim time  2s elapsed, about 2s left" in text
    assert "[#########################] mission: 100%" in text


def test_into_a_log_it_prints_plain_lines_at_start_every_period_and_at_the_end() -> None:
    out, clock = io.StringIO(), Clock()
    progress = Progress("bench planner", 100, "instances", stream=out, tty=False, every_s=10.0, clock=clock)
    for _k in range(1, 101):
        clock.t += 0.5  # 50 s in all: a line at the start, every 10 s, and the last one
        progress.advance()
    progress.close()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    assert lines[0].startswith("bench planner:   1%  1 / 100 instances  0s elapsed")
    assert lines[-1] == "bench planner: 100%  100 / 100 instances  50s elapsed"
    assert len(lines) == 2 + 4


def test_disabled_progress_prints_nothing_and_a_bad_total_is_refused() -> None:
    out = io.StringIO()
    with Progress("quiet", 10, stream=out, enabled=False) as progress:
        progress.update(5)
    assert out.getvalue() == ""
    with pytest.raises(ValueError, match="total"):
        Progress("bad", float("nan"))
