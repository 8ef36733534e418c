"""``auv-swarm drill``: the whole catalogue once on a short mission, then one test per drill on its report entry."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from auv_swarm.orchestrator.cli.drill import NAMES
from auv_swarm.results.channel_books import FRAME_REASONS

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
ERROR_CHECKS = {"survivors_under_threshold"}
"""Checks on tracking error: a 240 s mission is too short for the team to converge first."""


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("drill")
    done = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "drill", "--duration", "240", "--fault-at", "0.5"]
        + ["--out", str(out), "--json"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    result = json.loads(done.stdout.strip().splitlines()[-1])
    passed = all(d["passed"] for d in result["drills"])
    assert done.returncode == (0 if passed else 1), done.stderr[-2000:]
    on_disk = json.loads((out / "drill-report.json").read_text())
    assert on_disk == json.loads(json.dumps(result))
    assert (out / "drill-report.md").read_text().startswith("# Drill report")
    result["out"] = out
    return result


@pytest.mark.parametrize("name", NAMES)
def test_drill(report: dict, name: str) -> None:
    entry = next(d for d in report["drills"] if d["name"] == name)
    failed = [k for k, ok in entry["checks"].items() if not ok and k not in ERROR_CHECKS]
    assert failed == [], entry
    assert entry["processes_left"] == 0 and entry["results_readable"] is True
    if name != "kill-launcher":
        assert (report["out"] / f"{name}.png").stat().st_size > 1000
    if name == "kill-auv":
        assert 0 <= entry["detection_ms"] <= 1000.0
    if name == "restart-auv":
        assert entry["rejoin_to_frame_frames"] <= 3.0 and entry["rejoin_to_in_plans_frames"] <= 3.0
    if name == "stop-auv":
        assert entry["hung_intervals_s"]["2"]
    if name in ("restart-channel", "restart-router"):
        assert entry["agents_lost"] == [] and entry["complete"] is True
    if name == "restart-channel":
        # every link the AUVs sent across the restart is delivered, lost under one reason (channel_restart for
        # what died with the killed process) or still on its way at the end: sent*(n-1) = delivered + lost + in flight
        books, lost = entry["channel_books"], entry["frames_lost_by_reason"]
        link_lost = sum(v for k, v in lost.items() if k not in FRAME_REASONS)
        assert "channel_restart" in lost and books["balanced"] is True
        assert books["sent_links"] == books["delivered"] + link_lost + books["in_flight_at_end"]
        assert books["frames_senders"] == books["frames_channel"]
    if name == "kill-world":
        assert entry["complete"] is False and entry["exit_code"] == 1 and entry["incomplete_reason"] == "world_died"


def test_drill_usage_errors_exit_2() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "drill", "--only", "no-such-drill"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and "invalid choice" in done.stderr
