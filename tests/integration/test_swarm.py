"""The swarm as real processes over zenoh: a short mission, determinism, a kill drill."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from auv_swarm.contract.config import KillEvent, dump_toml, load_scenario
from auv_swarm.orchestrator.mission.api import run_mission
from auv_swarm.results.metrics import comparable
from tests.processes import cmdline, processes_with, session

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]


def short_scenario(tmp_path: Path, duration_s: float = 140.0, kill_at_s: float | None = 84.0) -> Path:
    """paper-3.2-challenging cut short, with AUV 1 killed early; written as a user TOML."""
    s = load_scenario("paper-3.2-challenging").with_overrides(duration_s=duration_s, seed=7)
    kills = (KillEvent(agent=1, time_s=kill_at_s),) if kill_at_s is not None else ()
    s = dataclasses.replace(s, name="short-test", kills=kills)
    path = tmp_path / "short.toml"
    path.write_text(dump_toml(s), encoding="utf-8")
    return path


def run_cli(args: list[str], timeout: float = 180.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "auv_swarm", "run", "--quiet", *args],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_multiprocess_mission_writes_results_and_matches_inprocess(tmp_path: Path) -> None:
    scenario_path = short_scenario(tmp_path)
    out_a, out_b = tmp_path / "a", tmp_path / "b"
    first = run_cli(["--scenario", str(scenario_path), "--out", str(out_a)])
    assert first.returncode == 0, first.stderr[-2000:]
    assert processes_with(str(tmp_path)) == [], "orphan processes left behind"

    metrics = json.loads((out_a / "metrics.json").read_text())
    assert metrics["mode"] == "processes"
    assert metrics["scenario"] == "short-test" and metrics["seed"] == 7
    assert metrics["sim_duration_s"] == pytest.approx(140.0)
    assert set(metrics["agents"]) == {"0", "1", "2"}
    assert metrics["agents"]["1"]["alive_until_s"] == pytest.approx(84.0)
    assert metrics["agents"]["0"]["alive_until_s"] is None
    assert all(metrics["agents"][a]["plans"] >= 1 for a in ("0", "2"))
    assert metrics["channel"]["sent"] >= 6
    assert metrics["channel"]["delivered"] >= 1
    assert metrics["tracking_error_mean_m"] is not None and metrics["tracking_error_mean_m"] > 0
    for name in ("events.jsonl", "trajectories.png", "tracking_error.png", "costs.png", "recording.rrd"):
        assert (out_a / name).stat().st_size > 1000, name
    kinds = {json.loads(line)["kind"] for line in (out_a / "events.jsonl").read_text().splitlines()}
    assert {"plan", "kill", "packet_sent", "packet_delivered"} <= kinds
    assert "tracking error" in first.stdout

    second = run_cli(["--scenario", str(scenario_path), "--out", str(out_b)])
    assert second.returncode == 0, second.stderr[-2000:]
    again = json.loads((out_b / "metrics.json").read_text())
    assert comparable(again) == comparable(metrics)

    scenario = load_scenario(str(scenario_path))
    inprocess = run_mission(scenario).metrics
    assert comparable(inprocess) == comparable(metrics)


def test_navigation_error_gives_the_same_metrics_in_processes_and_in_process(tmp_path: Path) -> None:
    """Dead reckoning with a compass bias and a fix (docs/navigation.md): the AUVs measure, plan, share and steer
    from where they believe they are, the same in both modes."""
    s = load_scenario(str(short_scenario(tmp_path, duration_s=100.0, kill_at_s=None)))
    keys = {
        "navigation.drift_fraction": 0.05,
        "navigation.heading_bias_deg": 3.0,
        "navigation.fix_period_s": 60.0,
        "navigation.fix_sigma_m": 8.0,
    }
    path = tmp_path / "nav.toml"
    path.write_text(dump_toml(s.with_keys(keys)), encoding="utf-8")
    done = run_cli(["--scenario", str(path), "--out", str(tmp_path / "nav")])
    assert done.returncode == 0, done.stderr[-2000:]
    assert processes_with(str(tmp_path)) == [], "orphan processes left behind"
    metrics = json.loads((tmp_path / "nav" / "metrics.json").read_text())
    assert metrics["nav_error_max_m"] > metrics["nav_error_mean_m"] > 0.0
    assert comparable(run_mission(load_scenario(str(path))).metrics) == comparable(metrics)


def test_kill_drill_swarm_survives_sigkill_of_an_auv(tmp_path: Path) -> None:
    scenario_path = short_scenario(tmp_path, duration_s=200.0, kill_at_s=None)
    out = tmp_path / "drill"
    argv = [sys.executable, "-m", "auv_swarm", "run", "--quiet", "--scenario", str(scenario_path), "--out", str(out)]
    with session(argv) as proc:
        world_log = out / "logs" / "world.log"
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (world_log.exists() and "starting" in world_log.read_text()):
            time.sleep(0.1)
        victims = [p for p in processes_with(str(out)) if "--id 2" in cmdline(p)]
        assert len(victims) == 1, victims
        os.kill(victims[0], signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["sim_duration_s"] == pytest.approx(200.0)
    assert metrics["agents"]["2"]["alive_until_s"] is not None
    assert metrics["agents"]["0"]["alive_until_s"] is None
    assert processes_with(str(tmp_path)) == []


def test_bench_swarm_runs_both_modes_and_finds_identical_metrics() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "bench", "swarm", "--duration", "30", "--repeat", "2", "--json"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["metrics_identical"] is True
    assert result["repeat"] == 2 and len(result["processes_walls_s"]) == len(result["inprocess_walls_s"]) == 2
    assert result["processes_wall_s"] > 0.0 and result["inprocess_wall_s"] > 0.0
    ratio = result["processes_wall_s"] / result["inprocess_wall_s"]
    assert result["speedup_inprocess"] == pytest.approx(ratio, rel=0.01)
    assert result["inprocess_with_startup_wall_s"] > result["inprocess_wall_s"]
    whole_ratio = result["processes_wall_s"] / result["inprocess_with_startup_wall_s"]
    assert result["speedup_inprocess_with_startup"] == pytest.approx(whole_ratio, rel=0.01)
    bad = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "bench", "swarm", "--repeat", "0"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and "--repeat must be >= 1" in bad.stderr
