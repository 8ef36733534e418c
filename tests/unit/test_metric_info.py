"""METRIC_INFO is the one table of metrics.json's names: every name has an entry, every entry is a name, and the
store's columns and docs/results.md follow it."""

from __future__ import annotations

import pytest

from auv_swarm.orchestrator.sweep.store import FIXED_NAMES, METRIC_COLUMNS
from auv_swarm.results import metrics as metrics_module
from auv_swarm.results.metric_info import KINDS, METRIC_INFO, Metric, metric_name, metric_names, store_columns
from auv_swarm.results.metrics import compute_metrics
from tests.unit.test_results import synthetic_record


@pytest.fixture(scope="module")
def metrics() -> dict:
    rec = synthetic_record()  # an AUV lost (after_first_kill), channel drops by reason, plans
    rec.run_wall_time_s = 14.0
    return compute_metrics(rec)


def test_every_name_of_metrics_json_has_an_entry(metrics: dict) -> None:
    missing = sorted(metric_names(metrics) - set(METRIC_INFO))
    assert not missing, f"metrics.json names without a METRIC_INFO entry (add one line each): {missing}"


def test_every_entry_is_a_name_of_metrics_json(metrics: dict) -> None:
    assert sorted(set(METRIC_INFO) - metric_names(metrics)) == []
    assert list(metrics) == [n for n in METRIC_INFO if "." not in n]  # the table lists them in the file's order


def test_a_metric_without_an_entry_is_caught(metrics: dict) -> None:
    assert "a_new_metric_m" in metric_names({**metrics, "a_new_metric_m": 1.0}) - set(METRIC_INFO)
    assert metric_name(("agents", "7", "plans")) == "agents.<id>.plans"
    assert metric_name(("channel", "dropped", "collision")) == "channel.dropped.<reason>"


def test_kinds_units_and_fractions(metrics: dict) -> None:
    assert all(m.kind in KINDS and m.label for m in METRIC_INFO.values())
    for name, m in METRIC_INFO.items():
        value = metrics.get(name) if "." not in name else None
        if m.kind == "fraction" and value is not None:
            assert 0.0 <= value <= 1.0, name
        if m.kind in ("real", "count") and value is not None:
            assert isinstance(value, int | float) and not isinstance(value, bool), name
    assert METRIC_INFO["tracking_error_mean_m"].axis_label() == "mean tracking error (m)"
    with pytest.raises(ValueError, match="kind must be one of"):
        Metric("x", "", "percent", "")
    assert metrics_module.METRIC_INFO is METRIC_INFO


def test_the_store_has_a_column_per_top_level_number(metrics: dict) -> None:
    numbers = [
        k
        for k, v in metrics.items()
        if k != "seed" and (isinstance(v, int | float) or v is None) and METRIC_INFO[k].kind not in ("text",)
    ]
    assert [name for name, _ in METRIC_COLUMNS] == [name for name, _ in store_columns()] == numbers
    assert "run_wall_time_s" in FIXED_NAMES and "wall_s" not in FIXED_NAMES
    assert dict(METRIC_COLUMNS)["complete"] == "INTEGER" and dict(METRIC_COLUMNS)["fqi"] == "REAL"
