"""``auv-swarm run --tls``: the one-host swarm over mutual TLS, certificates made for the run (issue 45)."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import pytest

from auv_swarm.contract.config import load_scenario
from auv_swarm.orchestrator.mission.api import run_mission
from auv_swarm.results.metrics import comparable
from tests.integration.test_swarm import run_cli, short_scenario

pytestmark = pytest.mark.integration


def _tls_folders() -> set[Path]:
    return set(Path(tempfile.gettempdir()).glob("auvswarm-tls-*"))


def test_run_tls_equals_the_plain_run_and_leaves_no_certificate_behind(tmp_path: Path) -> None:
    scenario = short_scenario(tmp_path, duration_s=30.0, kill_at_s=None)
    before = _tls_folders()
    done = run_cli(["--tls", "--scenario", str(scenario), "--out", str(tmp_path / "run")])
    assert done.returncode == 0, done.stderr[-2000:]
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert comparable(metrics) == comparable(run_mission(load_scenario(str(scenario))).metrics)
    router_log = (tmp_path / "run" / "logs" / "router.log").read_text()
    assert "listening on tls/127.0.0.1:" in router_log and "(mutual TLS, acl, 3 agents)" in router_log
    assert "ready on tls/127.0.0.1:" in (tmp_path / "run" / "logs" / "auv0.log").read_text()
    assert _tls_folders() <= before  # the run's certificates went with it
