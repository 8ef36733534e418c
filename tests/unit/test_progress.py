"""orchestrator.progress: a redrawn bar on a terminal, plain periodic lines into a log."""

from __future__ import annotations

import io
import time

import pytest

from auv_swarm.orchestrator.mission.progress import Progress


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_on_a_terminal_the_bar_is_redrawn_in_place_and_ends_with_a_newline() -> None:
    out, clock = io.StringIO(), Clock()
    with Progress("mission", 1500.0, "s sim time", stream=out, tty=True, clock=clock, heartbeat=False) as progress:
        for t in (0.0, 750.0, 1500.0):
            clock.t += 1.0
            progress(t, 1500.0)
    text = out.getvalue()
    assert text.count("\r") == 5 and text.endswith("\n") and text.count("\n") == 1
    assert "[############-------------] mission:  50%  750 / 1500 s sim time  2s elapsed, about 2s left" in text
    assert "[#########################] mission: 100%" in text


def test_into_a_log_it_prints_plain_lines_at_start_every_period_and_at_the_end() -> None:
    out, clock = io.StringIO(), Clock()
    progress = Progress(
        "bench planner", 100, "instances", stream=out, tty=False, every_s=10.0, clock=clock, heartbeat=False
    )
    for _k in range(1, 101):
        clock.t += 0.5  # 50 s in all: a line at the start, every 10 s (5), and the last one
        progress.advance()
    progress.close()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    assert lines[0] == "bench planner:   0%  0 / 100 instances  0s elapsed"
    assert lines[1] == "bench planner:  20%  20 / 100 instances  10s elapsed, about 40s left"
    assert lines[-1] == "bench planner: 100%  100 / 100 instances  50s elapsed"
    assert len(lines) == 6, lines  # start, 10-40 s, and the end once: no second line at 100 %
    assert sum(1 for line in lines if ": 100%" in line) == 1


def test_the_last_line_can_name_the_walls_instead_of_the_elapsed_time() -> None:
    out, clock = io.StringIO(), Clock()
    progress = Progress("mission", 1500.0, "s sim time", stream=out, tty=False, clock=clock, heartbeat=False)
    clock.t += 12.0
    progress(1500.0, 1500.0)
    progress.close("mission wall 8.9 s, run wall 11.2 s")
    progress.close("again")  # closed: nothing more
    lines = out.getvalue().splitlines()
    assert lines[-1] == "mission: 100%  1500 / 1500 s sim time  mission wall 8.9 s, run wall 11.2 s"
    assert len(lines) == 2


def test_disabled_progress_prints_nothing_and_a_bad_total_is_refused() -> None:
    out = io.StringIO()
    with Progress("quiet", 10, stream=out, enabled=False) as progress:
        progress.update(5)
    assert out.getvalue() == ""
    with pytest.raises(ValueError, match="total"):
        Progress("bad", float("nan"))


def test_a_long_step_still_gets_its_periodic_line_from_the_heartbeat() -> None:
    out = io.StringIO()
    progress = Progress("table3", 10, "missions", stream=out, tty=False, every_s=0.05)
    try:
        deadline = time.monotonic() + 5.0
        while out.getvalue().count("\n") < 3 and time.monotonic() < deadline:
            time.sleep(0.01)  # no update at all: one long step
    finally:
        progress.close()
    lines = out.getvalue().splitlines()
    assert len(lines) >= 4 and all(line.startswith("table3:   0%  0 / 10 missions") for line in lines), lines
