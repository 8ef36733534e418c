"""Scheduled faults and the restart policy over real processes (issue 13): a restarted AUV rejoins, and a
scheduled restart gives the same metrics as in process. Channel and router restarts are the drills' tests
(tests/integration/test_drill.py)."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from auv_swarm.contract.config import Fault, dump_toml, load_scenario
from auv_swarm.orchestrator.mission.api import run_mission
from auv_swarm.results.metrics import comparable
from tests.integration.test_lifecycle import Run

pytestmark = pytest.mark.integration


def _scenario(tmp_path: Path, duration_s: float, faults: tuple[Fault, ...]) -> Path:
    s = load_scenario("paper-3.2-challenging").with_overrides(duration_s=duration_s, seed=5)
    s = s.replace(name="fault-test", kills=(), faults=faults)
    path = tmp_path / "faults.toml"
    path.write_text(dump_toml(s), encoding="utf-8")
    return path


def test_a_scheduled_auv_restart_rejoins_on_its_tick_as_in_process(tmp_path: Path) -> None:
    path = _scenario(tmp_path, 300.0, (Fault(at_s=150.0, target="auv:1", action="restart", down_s=30.0),))
    run = Run(tmp_path, "--scenario", str(path))
    assert run.finish(timeout=180) == 0, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["agents"]["1"]["alive_intervals_s"] == [[0.0, 150.0], [180.0, 300.0]]
    assert metrics["agents"]["1"]["alive_until_s"] is None and metrics["complete"] is True
    events = [json.loads(x) for x in (run.out / "events.jsonl").read_text().splitlines()]
    assert [(e["kind"], e["t_s"]) for e in events if e["kind"] in ("kill", "rejoin")] == [
        ("kill", 150.0),
        ("rejoin", 180.0),
    ]
    assert any(e["kind"] == "plan" and e["agent"] == 1 and e["t_s"] > 180.0 for e in events)
    scenario = load_scenario(str(path))
    assert comparable(run_mission(scenario).metrics) == comparable(metrics)
    assert run.left() == []


def test_restart_on_failure_brings_a_crashed_auv_back(tmp_path: Path) -> None:
    with Run(tmp_path, "--duration", "600", "--speed", "30", "--restart", "on-failure:0.5") as run:
        run.wait_started()
        time.sleep(1.0)
        os.kill(run.child("--id 2"), signal.SIGKILL)
        code = run.finish()
    assert code == 0, run.stderr[-2000:]
    assert "restarting auv2 (--restart on-failure)" in run.stderr
    metrics = run.metrics()
    intervals = metrics["agents"]["2"]["alive_intervals_s"]
    assert len(intervals) == 2 and intervals[1][1] == pytest.approx(600.0), intervals
    events = [json.loads(x) for x in (run.out / "events.jsonl").read_text().splitlines()]
    assert [e["kind"] for e in events if e["kind"] in ("death", "rejoin")] == ["death", "rejoin"]
    assert run.left() == []


def test_a_killed_channel_is_channel_lost_at_the_faults_tick(tmp_path: Path) -> None:
    """The world holds the clock at a fault's tick until the launcher confirms it (``orchestrator/faults``): the
    recorder's kill at 61 s lands on the next tick (62 s), the channel's at 100 s on 100 s, however busy the
    machine, and the lines name those ticks."""
    faults = (Fault(at_s=61.0, target="recorder", action="kill"), Fault(at_s=100.0, target="channel", action="kill"))
    run = Run(tmp_path, "--scenario", str(_scenario(tmp_path, 300.0, faults)))
    assert run.finish(timeout=180) == 1, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["complete"] is False and metrics["incomplete_reason"] == "channel_lost"
    assert metrics["sim_duration_s"] == 100.0, "no tick after the channel's kill"
    lines = run.stderr.splitlines()
    for line in (
        "fault: kill recorder at t = 62 s",
        "warning: the recorder died at t = 62 s (signal 9); the recording stops there",
        "fault: kill channel at t = 100 s",
        "channel died at t = 100 s (signal 9); the run is incomplete",
    ):
        assert line in lines, run.stderr[-2000:]
    world_log = (run.out / "logs" / "world.log").read_text()
    assert "world: tick 31: the launcher injected its faults (kill recorder)" in world_log
    assert "world: tick 50: the launcher injected its faults (kill channel)" in world_log
    assert run.left() == []


def test_a_scheduled_auv_stop_is_hung_then_resumes_as_in_process(tmp_path: Path) -> None:
    path = _scenario(tmp_path, 300.0, (Fault(at_s=150.0, target="auv:2", action="stop", duration_s=40.0),))
    run = Run(tmp_path, "--scenario", str(path))
    assert run.finish(timeout=180) == 0, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["agents"]["2"]["hung_intervals_s"] == [[150.0, 190.0]]
    assert metrics["agents"]["2"]["alive_intervals_s"] == [[0.0, 300.0]], "a stopped AUV is not lost"
    scenario = load_scenario(str(path))
    assert comparable(run_mission(scenario).metrics) == comparable(metrics)
    assert run.left() == []
