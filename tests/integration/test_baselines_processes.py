"""Every section 3.3 method as real processes over zenoh gives the in-process metrics (centralised: its own node)."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

from auv_swarm.contract.config import dump_toml, load_scenario
from auv_swarm.orchestrator.mission.api import run_mission
from auv_swarm.results.metrics import comparable

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("method", ["dec-mpc", "dpso", "centralised"])
def test_short_mission_in_processes_matches_inprocess(tmp_path: Path, method: str) -> None:
    s = load_scenario("paper-3.3-sim2").with_overrides(duration_s=100.0, seed=3)
    s = dataclasses.replace(s, name=f"short-{method}", planner=dataclasses.replace(s.planner, method=method))
    path = tmp_path / "short.toml"
    path.write_text(dump_toml(s), encoding="utf-8")
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "run", "--quiet", "--scenario", str(path), "--out", str(out)],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mode"] == "processes" and metrics["plan_count"] >= 3
    assert (out / "logs" / "central.log").exists() == (method == "centralised")
    if method == "centralised":
        assert metrics["channel"]["sent"] == 0  # the central planner is outside the acoustic channel
    assert comparable(run_mission(s).metrics) == comparable(metrics)
