"""A run's raw data as four tables (``record.parquet`` and its companions), every column declared once.

:data:`TABLES` declares each table's columns with their type, unit, frame and meaning; docs/results.md's column
table is generated from it (tools/gendocs.py) and :func:`build_tables` checks that what it builds has exactly these
columns, so a new field is one :class:`Column` line here plus the line that fills it. Positions are metres in the
local frame (the world's 2-D inertial frame), headings and bearings rad from +x counter-clockwise, times seconds of
sim time. :data:`SCHEMA_VERSION` is written into every file (Parquet key-value metadata ``auv_swarm.schema_version``;
``schema.json`` beside CSV files): bump it when a column changes meaning or goes away, not when one is added.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from auv_swarm.results.metrics import alive_counts
from auv_swarm.results.record import COV_TERMS, RunRecord

SCHEMA_VERSION = 1
"""Version of the tables' layout (docs/results.md, "Raw data")."""

LOCAL = "local x/y"
"""The frame of every position and velocity: the world's 2-D inertial frame (docs/world.md), metres."""

_NUMPY = {"float": float, "int": np.int64, "bool": bool, "str": object}


@dataclass(frozen=True)
class Column:
    """One column: ``name``, ``kind`` (float, int, bool or str), ``unit`` ("" when none), ``frame`` ("" when none),
    ``meaning``."""

    name: str
    kind: str
    unit: str
    frame: str
    meaning: str


def _cov(a: str, b: str) -> Column:
    unit = {0: "m^2", 1: "m^2/s", 2: "m^2/s^2"}[(a in ("vx", "vy")) + (b in ("vx", "vy"))]
    meaning = f"entry ({a}, {b}) of the covariance the AUV reports (eq. 15 plus the model-error term)"
    return Column(f"P_{a}{b}", "float", unit, LOCAL, meaning)


RECORD = (
    Column("t_s", "float", "s", "", "sim time of the tick"),
    Column("auv", "int", "", "", "AUV id"),
    Column("alive", "bool", "", "", "the AUV is alive at this tick (its other columns are NaN when not)"),
    Column("x_m", "float", "m", LOCAL, "true position, x"),
    Column("y_m", "float", "m", LOCAL, "true position, y"),
    Column("heading_rad", "float", "rad", "from +x, counter-clockwise", "true heading"),
    Column("believed_x_m", "float", "m", LOCAL, "the position the AUV believes it has (its navigation), x"),
    Column(
        "believed_y_m", "float", "m", LOCAL, "the position the AUV believes it has, y (= y_m under perfect navigation)"
    ),
    Column("estimate_ok", "bool", "", "", "the AUV has a valid estimate of the source (else est_* and P_* are NaN)"),
    Column("est_x_m", "float", "m", LOCAL, "the AUV's estimate of the source position, x (xi of eq. 14)"),
    Column("est_y_m", "float", "m", LOCAL, "the AUV's estimate of the source position, y"),
    Column("est_vx_mps", "float", "m/s", LOCAL, "the AUV's estimate of the source velocity, x"),
    Column("est_vy_mps", "float", "m/s", LOCAL, "the AUV's estimate of the source velocity, y"),
    *(_cov(a, b) for a, b in COV_TERMS),
)
"""``record.parquet``: one row per tick and AUV (every AUV of the team at every tick)."""

TRUTH = (
    Column("t_s", "float", "s", "", "sim time of the tick"),
    Column("source_x_m", "float", "m", LOCAL, "true source position, x"),
    Column("source_y_m", "float", "m", LOCAL, "true source position, y"),
    Column("source_vx_mps", "float", "m/s", LOCAL, "true source velocity, x"),
    Column("source_vy_mps", "float", "m/s", LOCAL, "true source velocity, y"),
    Column("n_alive", "int", "", "", "live AUVs at this tick"),
    Column(
        "geometry_cost",
        "float",
        "",
        "",
        "1/sigma_min(Phi) of the true geometry (eqs. 34-35); NaN below 2 live AUVs, inf if parallel",
    ),
)
"""``truth.parquet``: one row per tick."""

BEARINGS = (
    Column("t_s", "float", "s", "", "sim time the bearing was taken"),
    Column("auv", "int", "", "", "the AUV that took it"),
    Column("bearing_rad", "float", "rad", "from +x, counter-clockwise", "the bearing of the source (eq. 2)"),
    Column("sensor_x_m", "float", "m", LOCAL, "where it was taken, x"),
    Column("sensor_y_m", "float", "m", LOCAL, "where it was taken, y"),
    Column("recipient", "int", "", "", "-1: as taken; else the AUV it was delivered to"),
    Column("t_delivered_s", "float", "s", "", "sim time the frame carrying it arrived (NaN as taken)"),
    Column("frame", "str", "", "", "the frame that carried it (links' frame; empty as taken)"),
)
"""``bearings.parquet``: every bearing as taken (the world's, true sensor position) and as each recipient got it
(from the acoustic payload: 0.1 s, 1 m and 0.1 deg steps)."""

LINKS = (
    Column("t_s", "float", "s", "", "sim time: first bit leaves (sent), last bit arrives (delivered), or the drop"),
    Column("frame", "str", "", "", "the frame's id, sender-seq"),
    Column("sender", "int", "", "", "the AUV that sent it"),
    Column("recipient", "int", "", "", "the AUV it went to; -1 for the frame itself (sent, per-frame drops)"),
    Column("outcome", "str", "", "", "sent, delivered or dropped"),
    Column("reason", "str", "", "", "why it was dropped (channel.md's drop reasons; empty otherwise)"),
    Column("bits", "int", "bit", "", "the frame's length"),
    Column("latency_s", "float", "s", "", "airtime plus propagation of a delivered frame (NaN otherwise)"),
    Column("snr_db", "float", "dB", "", "the link's SNR (eq. 22), where the channel reports one (NaN otherwise)"),
)
"""``links.parquet``: the channel's log, one row per frame sent and per link delivered or dropped."""

TABLES: dict[str, tuple[Column, ...]] = {"record": RECORD, "truth": TRUTH, "bearings": BEARINGS, "links": LINKS}
"""Every table, by the stem of its file (``record.parquet``, ``truth.parquet``, ...)."""


def build_tables(rec: RunRecord) -> dict[str, dict[str, np.ndarray]]:
    """The four tables of ``rec`` as columns (name -> 1-D array), in the order and with the names of :data:`TABLES`.

    Rows in a canonical order (record: tick then AUV; bearings: as taken first, then by delivery; links: by time),
    so the same run gives the same tables whichever order the messages came in."""
    built = {"record": _record(rec), "truth": _truth(rec), "bearings": _bearings(rec), "links": _links(rec)}
    for name, columns in TABLES.items():
        have, want = list(built[name]), [c.name for c in columns]
        if have != want:
            raise AssertionError(f"table {name!r} built with columns {have}, declared {want}")
    return built


def _record(rec: RunRecord) -> dict[str, np.ndarray]:
    ids = sorted(rec.agents)
    if not ids:
        return {c.name: np.empty(0, dtype=_NUMPY[c.kind]) for c in RECORD}
    n_t, n_a = len(rec.times), len(ids)

    def stack(attr: str) -> np.ndarray:
        """(T * n_a, ...): rows tick-major, AUV-minor."""
        arr = np.stack([getattr(rec.agents[i], attr) for i in ids], axis=1)
        return arr.reshape(n_t * n_a, *arr.shape[2:])

    pos, est, vel, cov = stack("position"), stack("estimate"), stack("velocity"), stack("covariance")
    believed = stack("believed")
    out = {
        "t_s": np.repeat(rec.times, n_a),
        "auv": np.tile(np.asarray(ids, dtype=np.int64), n_t),
        "alive": stack("alive").astype(bool),
        "x_m": pos[:, 0],
        "y_m": pos[:, 1],
        "heading_rad": stack("heading"),
        "believed_x_m": believed[:, 0],
        "believed_y_m": believed[:, 1],
        "estimate_ok": stack("estimate_ok").astype(bool),
        "est_x_m": est[:, 0],
        "est_y_m": est[:, 1],
        "est_vx_mps": vel[:, 0],
        "est_vy_mps": vel[:, 1],
    }
    for k, (a, b) in enumerate(COV_TERMS):
        out[f"P_{a}{b}"] = cov[:, k]
    return out


def _truth(rec: RunRecord) -> dict[str, np.ndarray]:
    target = rec.target.reshape(-1, 4)
    return {
        "t_s": np.asarray(rec.times, dtype=float),
        "source_x_m": target[:, 0],
        "source_y_m": target[:, 1],
        "source_vx_mps": target[:, 2],
        "source_vy_mps": target[:, 3],
        "n_alive": alive_counts(rec).astype(np.int64),
        "geometry_cost": np.asarray(rec.geometry_cost, dtype=float),
    }


def _bearings(rec: RunRecord) -> dict[str, np.ndarray]:
    rows = sorted(
        rec.bearings,
        key=lambda b: (
            b.recipient >= 0,
            b.t_delivered_s if b.recipient >= 0 else 0.0,
            b.recipient,
            b.auv,
            b.t_s,
            b.frame,
        ),
    )
    return {
        "t_s": np.array([b.t_s for b in rows], dtype=float),
        "auv": np.array([b.auv for b in rows], dtype=np.int64),
        "bearing_rad": np.array([b.bearing_rad for b in rows], dtype=float),
        "sensor_x_m": np.array([b.sensor_xy[0] for b in rows], dtype=float),
        "sensor_y_m": np.array([b.sensor_xy[1] for b in rows], dtype=float),
        "recipient": np.array([b.recipient for b in rows], dtype=np.int64),
        "t_delivered_s": np.array([b.t_delivered_s for b in rows], dtype=float),
        "frame": np.array([b.frame for b in rows], dtype=object),
    }


def _links(rec: RunRecord) -> dict[str, np.ndarray]:
    rows = [e for e in rec.events if str(e.get("kind", "")).startswith("packet_")]
    rows.sort(key=lambda e: (e["t_s"], str(e.get("correlation_id", "")), e["kind"], int(e.get("recipient", -1))))

    def num(e: Mapping[str, Any], key: str) -> float:
        v = e.get(key)
        return math.nan if v is None else float(v)

    return {
        "t_s": np.array([e["t_s"] for e in rows], dtype=float),
        "frame": np.array([str(e.get("correlation_id", "")) for e in rows], dtype=object),
        "sender": np.array([int(e.get("sender", -1)) for e in rows], dtype=np.int64),
        "recipient": np.array([int(e.get("recipient", -1)) for e in rows], dtype=np.int64),
        "outcome": np.array([e["kind"].removeprefix("packet_") for e in rows], dtype=object),
        "reason": np.array([e.get("reason") or "" for e in rows], dtype=object),
        "bits": np.array([int(e.get("bits", 0)) for e in rows], dtype=np.int64),
        "latency_s": np.array([num(e, "latency_s") for e in rows], dtype=float),
        "snr_db": np.array([num(e, "snr_db") for e in rows], dtype=float),
    }


# ---------------------------------------------------------------------------- Parquet


def file_metadata(rec_meta: Mapping[str, Any], table: str) -> dict[bytes, bytes]:
    """The key-value metadata of one Parquet file: schema version, table name, the run's scenario, seed, mode."""
    meta = {"schema_version": SCHEMA_VERSION, "table": table, **rec_meta}
    return {f"auv_swarm.{k}".encode(): str(v).encode() for k, v in meta.items()}


def run_meta(rec: RunRecord) -> dict[str, Any]:
    """What identifies the run in every file: scenario name, seed and mode."""
    return {"scenario": rec.scenario.name, "seed": rec.scenario.run.seed, "mode": rec.mode}


_ARROW = {"float": "float64", "int": "int64", "bool": "bool_", "str": "string"}


def to_arrow(name: str, columns: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> Any:
    """One built table as a ``pyarrow.Table``: each field typed as declared, its unit, frame and meaning in the
    field's metadata, :func:`file_metadata` in the schema's."""
    import pyarrow as pa

    fields = [
        pa.field(
            c.name,
            getattr(pa, _ARROW[c.kind])(),
            metadata={"unit": c.unit, "frame": c.frame, "meaning": c.meaning},
        )
        for c in TABLES[name]
    ]
    schema = pa.schema(fields, metadata=file_metadata(meta, name))
    arrays = [
        pa.array(columns[f.name].tolist() if f.type == pa.string() else columns[f.name], type=f.type) for f in fields
    ]
    return pa.Table.from_arrays(arrays, schema=schema)


def write_tables(rec: RunRecord, out_dir: Path) -> list[Path]:
    """Write ``record.parquet``, ``truth.parquet``, ``bearings.parquet`` and ``links.parquet`` into ``out_dir``
    (each written to a temporary name, then moved into place); return their paths."""
    import pyarrow.parquet as pq

    meta = run_meta(rec)
    paths = []
    for name, columns in build_tables(rec).items():
        path = Path(out_dir) / f"{name}.parquet"
        tmp = path.with_name(path.name + ".tmp")
        pq.write_table(to_arrow(name, columns, meta), tmp)
        tmp.replace(path)
        paths.append(path)
    return paths


def columns_table() -> str:
    """docs/results.md's table of every column (tools/gendocs.py, block ``record-columns``)."""
    lines = ["| file | column | type | unit | frame | meaning |", "|---|---|---|---|---|---|"]
    for name, columns in TABLES.items():
        for c in columns:
            cells = (f"`{name}.parquet`", f"`{c.name}`", c.kind, c.unit or "-", c.frame or "-", c.meaning)
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
