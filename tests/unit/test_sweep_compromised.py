"""A sweep's row of a mission in which an AUV was found compromised is ``failed``, with the reason (issue 44)."""

from __future__ import annotations

from types import SimpleNamespace

from auv_swarm.contract.config import Scenario, dump_toml
from auv_swarm.orchestrator.mission import api
from auv_swarm.orchestrator.sweep.worker import run_one


def _row(monkeypatch, stolen: list[int]) -> dict:
    metrics = {
        "complete": not stolen,
        "incomplete_reason": "compromised" if stolen else None,
        "exit_code": 1 if stolen else 0,
        "compromised_auvs": stolen,
        "tracking_error_mean_m": 12.5,
    }
    result = SimpleNamespace(metrics=metrics, record=SimpleNamespace(agents={}))
    monkeypatch.setattr(api, "run_mission", lambda scenario, mode: result)
    return run_one(dump_toml(Scenario()), {})


def test_a_compromised_mission_is_a_failed_row_that_keeps_its_metrics(monkeypatch) -> None:
    row = _row(monkeypatch, [1])
    assert row["status"] == "failed" and row["error"].startswith("compromised: AUV 1")
    assert row["metrics"]["compromised_auvs"] == [1] and row["tracking_error_mean_m"] == 12.5


def test_a_clean_mission_is_done(monkeypatch) -> None:
    row = _row(monkeypatch, [])
    assert row["status"] == "done" and row["error"] is None
