"""The raw data tables (results/tables.py), their export and ``compare`` on synthetic runs: bearings taken and
delivered from bus messages, refusals (an older folder, a newer schema, MCAP of a store or without the package), the
base-scenario warning (issue 47)."""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from auv_swarm.contract import wire
from auv_swarm.contract.config import Scenario, dump_toml
from auv_swarm.contract.payload import AcousticPayload, encode_payload
from auv_swarm.orchestrator.cli.main import main
from auv_swarm.orchestrator.sweep import store as st
from auv_swarm.results.collect import MessageLog
from auv_swarm.results.compare import compare
from auv_swarm.results.export import ExportError, export_record, export_run
from auv_swarm.results.metrics import compute_metrics
from auv_swarm.results.record import COV_TERMS, AgentTick, RunRecord
from auv_swarm.results.report import event_lines
from auv_swarm.results.tables import TABLES, build_tables, columns_table, write_tables

SCENARIO = Scenario()


def test_every_table_has_its_declared_columns_and_the_docs_list_them() -> None:
    rec = RunRecord.new(Scenario(name="empty"), "inprocess", [0, 1])
    built = build_tables(rec)
    assert {n: list(c) for n, c in built.items()} == {n: [c.name for c in cols] for n, cols in TABLES.items()}
    assert all(len(v) == 0 for cols in built.values() for v in cols.values())
    docs = (Path(__file__).resolve().parents[2] / "docs" / "results.md").read_text(encoding="utf-8")
    assert columns_table() in docs
    assert [c.name for c in TABLES["record"] if c.name.startswith("P_")] == [f"P_{a}{b}" for a, b in COV_TERMS]


def _truth(tick: int, t_s: float) -> wire.Truth:
    agents = {0: (10.0, 20.0, 0.5), 1: (-30.0, 40.0, 1.0)}
    return wire.Truth(tick=tick, target=(100.0, 50.0, 1.0, 0.0), agents=agents, alive=(0, 1), t_s=t_s, source="world")


def _telemetry(tick: int, t_s: float, auv: int) -> wire.Telemetry:
    ok = auv == 0
    P = tuple(float(k) for k in range(16)) if ok else (0.0,) * 16
    return wire.Telemetry(
        tick=tick, auv=auv, estimate_ok=ok, estimate_reason="" if ok else "too few bearings",
        xi=(101.0, 52.0, 0.9, 0.1) if ok else (0.0,) * 4, P=P, plan=(), waypoints=(), cost=0.0, terms={},
        plan_wall_ms=0.0, n_measurements=3, planned=False, fiedler=0.0, nav=(0.0, 0.0, 0.0), t_s=t_s,
        source=f"auv{auv}",
    )  # fmt: skip


def _log() -> MessageLog:
    """Two ticks of two AUVs: AUV 0 has an estimate, AUV 1 none; AUV 0 takes a bearing at each tick and its frame
    (both bearings) reaches AUV 1, and a second frame with a payload of another sender is left out."""
    log = MessageLog()
    for tick, t_s in ((0, 0.0), (1, 2.0)):
        log.on_message(_truth(tick, t_s))
        for auv in (0, 1):
            log.on_message(_telemetry(tick, t_s, auv))
        log.on_message(wire.Sensor(tick=tick, auv=0, bearing_rad=0.25 + tick, t_s=t_s, source="world"))
        log.on_message(wire.Sensor(tick=tick, auv=1, bearing_rad=None, t_s=t_s, source="world"))
    bearings = ((0.0, 10.0, 20.0, 0.25), (2.0, 10.0, 20.0, 1.25))
    n_headings = SCENARIO.planner.n_headings
    for seq, sender in ((0, 0), (1, 1)):
        payload = AcousticPayload(0, 2.0, 10.0, 20.0, 0.5, 1.0, (), 0, bearings)
        data, dropped = encode_payload(payload, 4000, n_headings)
        assert dropped == 0
        rx = wire.ModemRx(tick=1, auv=1, sender=sender, seq=seq, payload=data, t_sent=2.0, t_arrival=2.5,
                          snr_db=20.0, t_s=2.0, source="channel")  # fmt: skip
        log.on_message(rx)
    return log


def test_the_record_holds_the_full_estimate_and_every_bearing_taken_and_delivered() -> None:
    scenario = dataclasses.replace(SCENARIO, agents=dataclasses.replace(SCENARIO.agents, count=2))
    t = build_tables(_log().to_record(scenario, "inprocess", 0.0))
    rec = t["record"]
    assert list(rec["auv"]) == [0, 1, 0, 1] and list(rec["t_s"]) == [0.0, 0.0, 2.0, 2.0]
    assert list(rec["estimate_ok"]) == [True, False, True, False]
    assert rec["est_vx_mps"][0] == 0.9 and rec["est_vy_mps"][0] == 0.1
    assert [rec[f"P_{a}{b}"][0] for a, b in COV_TERMS] == [0, 1, 2, 3, 5, 6, 7, 10, 11, 15]
    assert math.isnan(rec["P_xx"][1]) and math.isnan(rec["est_x_m"][1])
    b = t["bearings"]
    assert list(b["recipient"]) == [-1, -1, 1, 1] and list(b["auv"]) == [0, 0, 0, 0]
    assert list(b["frame"]) == ["", "", "0-0", "0-0"]
    assert list(b["t_s"]) == [0.0, 2.0, 0.0, 2.0] and list(b["t_delivered_s"][2:]) == [2.5, 2.5]
    assert np.allclose(b["bearing_rad"], [0.25, 1.25, 0.25, 1.25], atol=math.radians(0.05) + 1e-12)
    assert list(b["sensor_x_m"]) == [10.0, 10.0, 10.0, 10.0]
    assert list(t["truth"]["n_alive"]) == [2, 2]


def _run(tmp_path: Path, name: str = "synthetic", pdr: float = 0.65) -> tuple[Path, RunRecord]:
    """A synthetic run's folder (what write_results writes but the figures, and scenario.toml) and its record: two AUVs whose
    estimate is 3 m off the truth from the sixth tick on."""
    scenario = dataclasses.replace(SCENARIO, name=name, channel=dataclasses.replace(SCENARIO.channel, pdr=pdr))
    rec = RunRecord.new(scenario, "inprocess", [0, 1])
    for k in range(40):
        est = (100.0 + k, 3.0) if k >= 5 else None
        ticks = {i: AgentTick((10.0 * i, 0.0), 0.1, est, velocity=(1.0, 0.0)) for i in (0, 1)}
        rec.append_tick(2.0 * k, (100.0 + k, 0.0, 0.5, 0.0), ticks)
    rec.add_packet({"t_s": 3.0, "kind": "sent", "correlation_id": "0-0", "sender": 0, "recipient": -1, "bits": 900})
    folder = tmp_path / f"{name}-{pdr}"
    folder.mkdir()
    (folder / "metrics.json").write_text(json.dumps(compute_metrics(rec)), encoding="utf-8")
    (folder / "events.jsonl").write_text("".join(line + "\n" for line in event_lines(rec)), encoding="utf-8")
    (folder / "scenario.toml").write_text(dump_toml(scenario), encoding="utf-8")
    write_tables(rec, folder)  # write_results' files but the figures
    return folder, rec


def _run_folder(tmp_path: Path, name: str = "synthetic", pdr: float = 0.65) -> Path:
    return _run(tmp_path, name, pdr)[0]


def test_an_older_run_folder_is_one_line_and_exit_2(tmp_path: Path, capsys) -> None:
    folder = _run_folder(tmp_path)
    (folder / "record.parquet").unlink()
    for argv in (["export", str(folder), "--format", "csv"], ["compare", str(folder), str(folder)]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "no record.parquet" in err and err.startswith("error: ")
    assert main(["export", str(tmp_path / "nowhere"), "--format", "parquet"]) == 2
    assert "no such folder" in capsys.readouterr().err


def test_a_damaged_table_or_events_line_is_one_line_and_exit_2(tmp_path: Path, capsys) -> None:
    folder = _run_folder(tmp_path)
    events = (folder / "events.jsonl").read_text(encoding="utf-8")
    (folder / "events.jsonl").write_text(events + '{"kind": "cut off\n', encoding="utf-8")
    assert main(["export", str(folder), "--format", "mcap"]) == 2
    err = capsys.readouterr().err.strip()
    n = len(events.splitlines()) + 1
    assert len(err.splitlines()) == 1 and f"events.jsonl:{n}: not a JSON line" in err, err
    data = (folder / "links.parquet").read_bytes()
    (folder / "links.parquet").write_bytes(data[: len(data) // 2])  # a copy cut short
    for argv in (["export", str(folder), "--format", "csv"], ["compare", str(folder), str(folder)]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "links.parquet: not a readable Parquet table" in err, err


def test_a_newer_schema_is_refused(tmp_path: Path) -> None:
    folder = _run_folder(tmp_path)
    table = pq.read_table(folder / "truth.parquet")
    meta = {**table.schema.metadata, b"auv_swarm.schema_version": b"99"}
    pq.write_table(table.replace_schema_metadata(meta), folder / "truth.parquet")
    with pytest.raises(ExportError, match="schema version 99"):
        export_run(folder, "csv", tmp_path / "out")


def test_mcap_without_the_package_names_the_extra(tmp_path: Path, monkeypatch, capsys) -> None:
    folder = _run_folder(tmp_path)
    monkeypatch.setitem(sys.modules, "mcap", None)
    assert main(["export", str(folder), "--format", "mcap"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pip install 'auv-swarm[mcap]'" in err
    assert not (folder / "export" / "record.mcap").exists()


def test_a_sweep_store_exports_to_csv_and_parquet_and_refuses_mcap(tmp_path: Path, capsys) -> None:
    store = st.open_store(tmp_path, {"channel.pdr": [0.5, 0.9]}, {"axes": ["channel.pdr"]}, "hash", "v", False)
    for seed, pdr in ((1, 0.5), (2, 0.9)):
        store.put({"channel.pdr": pdr}, {"seed": seed, "status": "done", "scenario_sha256": f"s{seed}", "attempts": 1})
    rows = store.rows()
    store.close()
    assert main(["export", str(tmp_path), "--format", "parquet"]) == 0
    assert pq.read_table(tmp_path / "export" / "missions.parquet").to_pylist() == rows
    assert main(["export", str(tmp_path), "--format", "csv", "--out", str(tmp_path / "csv")]) == 0
    header = (tmp_path / "csv" / "missions.csv").read_text().splitlines()[0]
    assert header.split(",")[:3] == ['"channel.pdr"', '"seed"', '"status"']
    capsys.readouterr()
    assert main(["export", str(tmp_path), "--format", "mcap"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no tracks" in err


def test_export_record_equals_the_export_of_its_folder(tmp_path: Path) -> None:
    folder, rec = _run(tmp_path)
    for fmt in ("parquet", "csv", "mcap"):
        of_folder = export_run(folder, fmt, tmp_path / f"folder-{fmt}")
        of_record = export_record(rec, fmt, tmp_path / f"record-{fmt}")
        assert [p.name for p in of_folder] == [p.name for p in of_record]
        assert all(a.read_bytes() == b.read_bytes() for a, b in zip(of_folder, of_record, strict=True)), fmt
        if fmt == "parquet":
            assert all((folder / p.name).read_bytes() == p.read_bytes() for p in of_folder)
    schema = json.loads((tmp_path / "record-csv" / "schema.json").read_text())
    assert schema["run"] == {"scenario": "synthetic", "seed": "1", "mode": "inprocess"}
    with pytest.raises(ExportError, match="format must be one of"):
        export_record(rec, "xlsx", tmp_path / "c")


def test_compare_lists_the_differing_keys_and_warns_of_another_base_scenario(tmp_path: Path) -> None:
    a, b, c = _run_folder(tmp_path), _run_folder(tmp_path, pdr=0.3), _run_folder(tmp_path, name="other")
    same = compare([a, b], out=tmp_path / "fig")
    assert same.warning is None and same.scenario_differences == {"channel.pdr": [0.65, 0.3]}
    assert same.metrics["tracking_error_mean_m"] == [3.0, 3.0] and same.differences["tracking_error_mean_m"] == [0, 0]
    assert (tmp_path / "fig" / "compare.png").stat().st_size > 1000
    other = compare([a, c], out=tmp_path / "fig")
    assert other.warning is not None and "different base scenarios" in other.warning
    assert other.text().splitlines()[0] == other.warning and other.scenario_differences["name"] == [
        "synthetic",
        "other",
    ]
    with pytest.raises(ExportError, match="at least two"):
        compare([a], out=tmp_path)


def test_compares_team_error_is_the_metrics_team_error_of_the_record(tmp_path: Path) -> None:
    """compare.png's curve, rebuilt from the run folder's tables, is metrics.team_error of the run's own record."""
    from auv_swarm.results.compare import load_run
    from auv_swarm.results.metrics import team_error, tracking_errors

    folder, rec = _run(tmp_path, "synthetic", 0.65)
    run = load_run(folder)
    np.testing.assert_allclose(run.team_error_m, team_error(tracking_errors(rec), len(rec.times)), rtol=1e-12)
    assert np.array_equal(run.times_s, rec.times)
