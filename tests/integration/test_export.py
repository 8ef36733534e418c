"""A run's raw data (record.parquet and companions) in processes mode and in process, its export as CSV, Parquet and
MCAP, and ``compare`` of two runs of different PDR (issue 47)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

import auv_swarm
from auv_swarm.contract.config import KillEvent, load_scenario
from auv_swarm.orchestrator.mission.api import Launch, MissionResult, run_mission
from tests.integration.export_checks import (
    assert_csv_matches,
    assert_exports,
    assert_mcap_matches,
    assert_same_raw_data,
    assert_tracking_error_reproduced,
    read_tables,
)

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, MissionResult]:
    """One short mission (AUV 1 killed at 72 s) in processes mode and in process, and in process at PDR 0.3."""
    root = tmp_path_factory.mktemp("runs")
    base = load_scenario("paper-3.2-challenging").with_overrides(duration_s=120.0, seed=7)
    scenario = dataclasses.replace(base, name="export-test", kills=(KillEvent(agent=1, time_s=72.0),))
    quiet = Launch(recorder=False)
    out = {
        "processes": run_mission(scenario, mode="processes", out=root / "processes", launch=quiet),
        "inprocess": run_mission(scenario, out=root / "inprocess", launch=quiet),
        "pdr": run_mission(scenario.with_keys({"channel.pdr": 0.3}), out=root / "pdr", launch=quiet),
    }
    assert all(r.exit_code == 0 for r in out.values()), {k: r.outcome.line for k, r in out.items()}
    return out


def test_both_modes_write_the_same_raw_data(runs) -> None:
    folder = runs["processes"].out
    assert_same_raw_data(folder, runs["inprocess"].out)
    t = read_tables(folder)
    rec = t["record"]
    assert len(rec["t_s"]) == 3 * len(t["truth"]["t_s"]) == 3 * 61
    dead = [k for k, (a, ts) in enumerate(zip(rec["auv"], rec["t_s"], strict=True)) if a == 1 and ts >= 72.0]
    assert dead and not any(rec["alive"][k] for k in dead) and all(math.isnan(rec["x_m"][k]) for k in dead)
    assert t["truth"]["n_alive"][-1] == 2
    recipients = t["bearings"]["recipient"]
    assert -1 in recipients and any(r >= 0 for r in recipients)
    taken = [k for k, r in enumerate(recipients) if r < 0]
    assert all(t["bearings"]["frame"][k] == "" for k in taken)
    delivered_frames = {f for f, r in zip(t["bearings"]["frame"], recipients, strict=True) if r >= 0}
    link_frames = {f for f, o in zip(t["links"]["frame"], t["links"]["outcome"], strict=True) if o == "delivered"}
    assert delivered_frames <= link_frames
    assert {"sent", "delivered"} <= set(t["links"]["outcome"])


def test_a_processes_run_exports_in_three_formats(runs, tmp_path: Path) -> None:
    assert_exports(runs["processes"].out, tmp_path / "export")


def test_an_inprocess_run_exports_from_python_as_from_its_folder(runs, tmp_path: Path) -> None:
    result = runs["inprocess"]
    written = {fmt: result.export(fmt, tmp_path / "result") for fmt in ("csv", "parquet", "mcap")}
    assert [p.name for p in written["mcap"]] == ["record.mcap"]
    assert {p.name for p in written["csv"]} == {"record.csv", "truth.csv", "bearings.csv", "links.csv", "schema.json"}
    from_folder = auv_swarm.export(result.out, format="mcap", out=tmp_path / "folder")
    assert from_folder[0].read_bytes() == written["mcap"][0].read_bytes()
    assert_csv_matches(result.out, tmp_path / "result")
    assert_same_raw_data(result.out, tmp_path / "result")
    assert_mcap_matches(result.out, tmp_path / "result" / "record.mcap")


@pytest.mark.parametrize("mode", ["processes", "inprocess"])
def test_the_tables_reproduce_the_tracking_error(runs, mode: str) -> None:
    assert_tracking_error_reproduced(runs[mode].out)


def test_compare_two_runs_of_different_pdr(runs, tmp_path: Path, capsys) -> None:
    from auv_swarm.orchestrator.cli.main import main

    a, b = str(runs["inprocess"].out), str(runs["pdr"].out)
    assert main(["compare", a, b, "--out", str(tmp_path / "text")]) == 0
    text = capsys.readouterr().out
    assert main(["compare", a, b, "--out", str(tmp_path / "json"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert "warning" not in text
    pdr = next(line.split() for line in text.splitlines() if line.strip().startswith("channel.pdr "))
    assert pdr == ["channel.pdr", "0.65", "0.3"]
    row = next(line.split() for line in text.splitlines() if line.startswith("channel.delivery_ratio "))
    assert len(row) == 4 and float(row[3]) == pytest.approx(float(row[2]) - float(row[1]))
    assert result["scenario_differences"] == {"channel.pdr": [0.65, 0.3]}
    assert result["metrics"]["seed"] == [7, 7] and result["differences"]["channel.sent"][0] == 0
    assert result["metrics"]["channel.delivery_ratio"][1] < result["metrics"]["channel.delivery_ratio"][0]
    for sub in ("text", "json"):
        assert (tmp_path / sub / "compare.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
