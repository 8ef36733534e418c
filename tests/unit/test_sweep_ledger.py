"""The sweep engine's bookkeeping (:class:`~auv_swarm.orchestrator.sweep.engine.Ledger`): one death rule, whoever
sees the death, without a cluster (the engine over real Dask workers is tests/integration/test_sweep*.py)."""

from __future__ import annotations

from auv_swarm.contract.config import load_scenario
from auv_swarm.orchestrator.sweep.engine import MAX_DEATHS, Ledger
from auv_swarm.orchestrator.sweep.grid import Cell, Mission


def _mission(seed: int = 1) -> Mission:
    return Mission(Cell("paper-3.3-sim2", {}, load_scenario("paper-3.3-sim2")), seed)


def _launch(ledger: Ledger, m: Mission) -> tuple[str, object]:
    key, fut = ledger.next_attempt(m), object()
    ledger.started(key, fut, m)
    return key, fut


def test_a_death_counts_once_whoever_sees_it_and_the_third_gives_the_mission_up() -> None:
    ledger, m = Ledger(count_deaths=True), _mission()
    key, _fut = _launch(ledger, m)
    assert key == f"mission-{m.cell.sha256[:16]}-s1-a1"
    assert ledger.departed({"w1": [key]}, {"w1"}) == [], "seen on w1"
    assert ledger.departed({"w2": [key]}, {"w2"}) == [], "w1 left under it: death 1, rescheduled on w2"
    assert ledger.ended(key) is m, "then the cluster lost the future"
    assert ledger.died(m) is False, "death 2, by the same rule: the client submits it again"
    key2, fut2 = _launch(ledger, m)
    assert key2.endswith("-s1-a2") and ledger.attempts[m.key] == 2
    assert ledger.departed({"w3": [key2]}, {"w3"}) == []
    assert ledger.departed({}, set()) == [(fut2, m)], "w3 left under it: death 3, given up"
    assert ledger.deaths[m.key] == MAX_DEATHS == 3
    assert ledger.failed_row(m) == {"status": "failed", "error": "its worker died 3 times", "attempts": 3}
    assert ledger.ended(key2) is None, "its cancelled future comes back: the row is written already"
    assert ledger.futures() == [] and ledger.departed({}, set()) == []


def test_a_mission_is_given_up_at_the_third_death_seen_as_lost_futures() -> None:
    ledger, m = Ledger(count_deaths=False), _mission()
    verdicts = []
    for _ in range(MAX_DEATHS):
        key, _fut = _launch(ledger, m)
        assert ledger.ended(key) is m
        verdicts.append(ledger.died(m))
    assert verdicts == [False, False, True]
    assert ledger.failed_row(m)["error"] == "its worker died 3 times"


def test_on_a_local_cluster_the_scheduler_gives_up_and_the_client_only_counts() -> None:
    ledger, m, other = Ledger(count_deaths=False), _mission(1), _mission(2)
    key, _fut = _launch(ledger, m)
    other_key, other_fut = _launch(ledger, other)
    for worker in ("w1", "w2", "w3", "w4"):
        assert ledger.departed({worker: [key]}, {worker}) == []
    assert ledger.deaths == {m.key: 3}, "three departures seen, none given up: KilledWorker will come"
    assert ledger.failed_row(other)["error"] == "its worker died 3 times", "a KilledWorker the client never saw"
    assert ledger.failed_row(other, "RuntimeError: boom") == {
        "status": "failed",
        "error": "RuntimeError: boom",
        "attempts": MAX_DEATHS,
    }
    assert ledger.futures() == [_fut, other_fut] and other_key.endswith("-s2-a1")
