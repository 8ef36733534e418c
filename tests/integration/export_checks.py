"""Checks of a run folder's raw data and its three exports, shared by the export tests and the compose test."""

from __future__ import annotations

import collections
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.csv as pcsv
import pyarrow.parquet as pq

from auv_swarm.results.tables import SCHEMA_VERSION, TABLES

RERUN = str(Path(sys.executable).with_name("rerun"))


def read_tables(run_dir: Path) -> dict[str, dict[str, list]]:
    """The four tables of a run folder as Python columns."""
    return {name: pq.read_table(run_dir / f"{name}.parquet").to_pydict() for name in TABLES}


def assert_same_raw_data(a: Path, b: Path) -> None:
    """Two runs of one scenario and seed (any modes) hold the same raw data, NaN for NaN."""
    ta, tb = read_tables(a), read_tables(b)
    for name in TABLES:
        assert list(ta[name]) == list(tb[name]), name
        for col in ta[name]:
            x, y = ta[name][col], tb[name][col]
            assert len(x) == len(y), (name, col, len(x), len(y))
            if x and isinstance(x[0], float):
                assert np.array_equal(np.array(x, dtype=float), np.array(y, dtype=float), equal_nan=True), (name, col)
            else:
                assert x == y, (name, col)


def recomputed_tracking_error(run_dir: Path) -> dict[str, float]:
    """metrics.json's tracking-error figures recomputed from record.parquet and truth.parquet alone."""
    t = read_tables(run_dir)
    rec, truth = t["record"], t["truth"]
    where = {ts: k for k, ts in enumerate(truth["t_s"])}
    errors, live, no_est = [], 0, 0
    for k, ts in enumerate(rec["t_s"]):
        if not rec["alive"][k]:
            continue
        live += 1
        if not rec["estimate_ok"][k]:
            no_est += 1
            continue
        j = where[ts]
        errors.append(
            math.hypot(rec["est_x_m"][k] - truth["source_x_m"][j], rec["est_y_m"][k] - truth["source_y_m"][j])
        )
    e = np.array(errors)
    return {
        "tracking_error_mean_m": float(np.mean(e)),
        "tracking_error_std_m": float(np.std(e)),
        "tracking_error_samples": len(errors),
        "tracking_error_p95_m": float(np.percentile(e, 95)),
        "no_estimate_fraction": no_est / live,
    }


def assert_tracking_error_reproduced(run_dir: Path) -> None:
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    for key, value in recomputed_tracking_error(run_dir).items():
        assert value == (metrics[key] if isinstance(value, int) else _approx(metrics[key])), key


def _approx(v: float):
    import pytest

    return pytest.approx(v, rel=1e-12, abs=1e-12)


def assert_csv_matches(run_dir: Path, out: Path) -> None:
    """The CSV export holds the Parquet tables, column for column, and schema.json names every column."""
    schema = json.loads((out / "schema.json").read_text(encoding="utf-8"))
    assert schema["schema_version"] == SCHEMA_VERSION
    tables = read_tables(run_dir)
    for name, columns in TABLES.items():
        assert [c["name"] for c in schema["tables"][name]] == [c.name for c in columns]
        csv = pcsv.read_csv(out / f"{name}.csv").to_pydict()
        assert list(csv) == list(tables[name]), name
        for col, values in tables[name].items():
            if values and isinstance(values[0], float):
                back = np.array([math.nan if v is None else v for v in csv[col]], dtype=float)  # nan reads as null
                assert np.array_equal(back, np.array(values, dtype=float), equal_nan=True), (name, col)
            elif values and isinstance(values[0], str):
                assert [v or "" for v in csv[col]] == values, (name, col)
            else:
                assert csv[col] == values, (name, col)


def assert_mcap_matches(run_dir: Path, mcap_path: Path) -> None:
    """One /auv/N/pose per live AUV tick, one /events per events.jsonl line, every message valid against its
    channel's schema, log time = sim time; rerun converts the file."""
    import jsonschema
    from mcap.reader import make_reader

    tables = read_tables(run_dir)
    counts: collections.Counter[str] = collections.Counter()
    validators: dict[int, jsonschema.Draft202012Validator] = {}
    with mcap_path.open("rb") as fh:
        reader = make_reader(fh)
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            if schema.id not in validators:
                validators[schema.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
            body = json.loads(message.data)
            validators[schema.id].validate(body)
            if schema.name.startswith("foxglove."):
                stamp = body["timestamp"]
                assert stamp["sec"] * 1_000_000_000 + stamp["nsec"] == message.log_time
            counts[channel.topic] += 1
    rec = tables["record"]
    live = collections.Counter(f"/auv/{a}/pose" for a, ok in zip(rec["auv"], rec["alive"], strict=True) if ok)
    assert {k: v for k, v in counts.items() if k.endswith("/pose")} == dict(live)
    valid = zip(rec["auv"], rec["alive"], rec["estimate_ok"], strict=True)
    estimates = collections.Counter(f"/auv/{a}/estimate" for a, ok, est in valid if ok and est)
    assert {k: v for k, v in counts.items() if k.endswith("/estimate")} == dict(estimates)
    lines = [ln for ln in (run_dir / "events.jsonl").read_text(encoding="utf-8").splitlines() if ln.strip()]
    assert counts["/events"] == len(lines) > 0
    assert counts["/source/truth"] == len(tables["truth"]["t_s"])
    assert counts["/bearings"] == len(tables["bearings"]["t_s"])
    assert counts["/links"] == len(tables["links"]["t_s"])
    done = subprocess.run(
        [
            RERUN,
            "mcap",
            "convert",
            str(mcap_path),
            "-o",
            str(mcap_path.with_suffix(".rrd")),
            "--timeline-type",
            "duration",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "/auv/0/pose" in done.stderr and mcap_path.with_suffix(".rrd").stat().st_size > 1000


def assert_exports(run_dir: Path, out: Path) -> None:
    """``auv-swarm export`` of ``run_dir`` in all three formats into ``out`` (the verb called in this process),
    each checked."""
    from auv_swarm.orchestrator.cli.main import main

    for fmt in ("csv", "parquet", "mcap"):
        assert main(["export", str(run_dir), "--format", fmt, "--out", str(out)]) == 0, fmt
    assert_csv_matches(run_dir, out)
    assert_same_raw_data(run_dir, out)
    assert_mcap_matches(run_dir, out / "record.mcap")
