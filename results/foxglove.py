"""A run as an MCAP file for Foxglove, rerun and other MCAP readers (``auv-swarm export --format mcap``).

Every channel is JSON-encoded and carries the JSON Schema it names (MCAP schema encoding ``jsonschema``): the
Foxglove message types ``foxglove.PoseInFrame`` and ``foxglove.Log`` (their documented fields), and one schema per
raw-data table made from its declared columns (:data:`auv_swarm.results.tables.TABLES`). Log time and publish time
are sim time in nanoseconds. The ``mcap`` package is an extra (``pip install 'auv-swarm[mcap]'``), imported here
only. Topics (docs/results.md):

- ``/auv/N/pose`` (``foxglove.PoseInFrame``): AUV N's true pose, one per tick it is alive;
- ``/auv/N/estimate`` (``foxglove.PoseInFrame``): AUV N's estimate of the source, at every tick it has one
  (orientation: the estimated velocity's direction);
- ``/auv/N/state`` (``auv_swarm.AuvState``): AUV N's row of ``record.parquet``, one per tick it is alive;
- ``/source/truth`` (``foxglove.PoseInFrame``) and ``/source/state`` (``auv_swarm.SourceState``): the truth per tick;
- ``/bearings`` (``auv_swarm.Bearing``), ``/links`` (``auv_swarm.Link``): the rows of those tables;
- ``/events`` (``foxglove.Log``): one message per line of events.jsonl (``message`` the line, ``name`` its kind).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from auv_swarm.results.tables import SCHEMA_VERSION, TABLES, Column

FRAME_ID = "local"
"""The frame_id of every pose: the world's 2-D inertial frame (z = 0), metres."""

ROW_SCHEMAS = {
    "record": "auv_swarm.AuvState",
    "truth": "auv_swarm.SourceState",
    "bearings": "auv_swarm.Bearing",
    "links": "auv_swarm.Link",
}
"""The name of each table's row schema."""

WARNING_EVENTS = ("kill", "death", "hung", "abort", "duplicate_login", "packet_dropped")
"""Event kinds logged at level WARNING (3) on /events; every other kind at INFO (2)."""

_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
    "required": ["sec", "nsec"],
}
_XYZ = {k: {"type": "number"} for k in "xyz"}

POSE_IN_FRAME = {
    "title": "foxglove.PoseInFrame",
    "description": "A timestamped pose for an object or reference frame in 3D space",
    "type": "object",
    "properties": {
        "timestamp": {**_TIME, "description": "Timestamp of pose"},
        "frame_id": {"type": "string", "description": "Frame of reference for pose position and orientation"},
        "pose": {
            "title": "foxglove.Pose",
            "type": "object",
            "properties": {
                "position": {
                    "title": "foxglove.Vector3",
                    "type": "object",
                    "properties": _XYZ,
                    "required": list("xyz"),
                },
                "orientation": {
                    "title": "foxglove.Quaternion",
                    "type": "object",
                    "properties": {**_XYZ, "w": {"type": "number"}},
                    "required": list("xyzw"),
                },
            },
            "required": ["position", "orientation"],
        },
    },
    "required": ["timestamp", "frame_id", "pose"],
}
"""foxglove.PoseInFrame's documented fields as a JSON Schema."""

LOG = {
    "title": "foxglove.Log",
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": {**_TIME, "description": "Timestamp of log message"},
        "level": {"type": "integer", "enum": [0, 1, 2, 3, 4, 5], "description": "0 unknown .. 2 info, 3 warning .. 5"},
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
    "required": ["timestamp", "level", "message", "name", "file", "line"],
}
"""foxglove.Log's documented fields as a JSON Schema."""

_JSON_TYPES = {"float": ["number", "null"], "int": "integer", "bool": "boolean", "str": "string"}


def row_schema(table: str) -> dict[str, Any]:
    """The JSON Schema of one row of ``table``: every declared column (a float may be null: NaN or infinite)."""
    columns: Sequence[Column] = TABLES[table]

    def describe(c: Column) -> str:
        extra = "; ".join(x for x in (c.unit, c.frame) if x)
        return f"{c.meaning} ({extra})" if extra else c.meaning

    return {
        "title": ROW_SCHEMAS[table],
        "description": f"one row of {table}.parquet (auv-swarm raw data, schema version {SCHEMA_VERSION})",
        "type": "object",
        "properties": {c.name: {"type": _JSON_TYPES[c.kind], "description": describe(c)} for c in columns},
        "required": [c.name for c in columns],
        "additionalProperties": False,
    }


def schemas() -> dict[str, dict[str, Any]]:
    """Every schema the file carries, by name."""
    return {
        "foxglove.PoseInFrame": POSE_IN_FRAME,
        "foxglove.Log": LOG,
        **{ROW_SCHEMAS[t]: row_schema(t) for t in TABLES},
    }


def sim_ns(t_s: float) -> int:
    """Sim time (s) as integer nanoseconds."""
    return int(round(float(t_s) * 1e9))


def _stamp(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def pose(ns: int, x: float, y: float, yaw_rad: float) -> dict[str, Any]:
    """A foxglove.PoseInFrame at (x, y, 0) in :data:`FRAME_ID`, turned ``yaw_rad`` about +z (0 when not finite)."""
    half = 0.5 * yaw_rad if math.isfinite(yaw_rad) else 0.0
    return {
        "timestamp": _stamp(ns),
        "frame_id": FRAME_ID,
        "pose": {
            "position": {"x": float(x), "y": float(y), "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)},
        },
    }


def _clean(row: Mapping[str, Any]) -> dict[str, Any]:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}


def _rows(columns: Mapping[str, Sequence[Any]]) -> Iterable[dict[str, Any]]:
    names = list(columns)
    for values in zip(*(columns[n] for n in names), strict=True):
        yield dict(zip(names, values, strict=True))


def messages(tables: Mapping[str, Mapping[str, Sequence[Any]]], events: Sequence[str]) -> list[tuple[str, int, dict]]:
    """Every message of the file as (topic, log time ns, JSON object), in sim-time order (ties: as generated).

    ``tables`` maps each table name to its columns (name -> values, Python scalars); ``events`` are the lines of
    events.jsonl."""
    out: list[tuple[str, int, dict]] = []
    for row in _rows(tables["record"]):
        if not row["alive"]:
            continue
        ns, auv = sim_ns(row["t_s"]), row["auv"]
        out.append((f"/auv/{auv}/pose", ns, pose(ns, row["x_m"], row["y_m"], row["heading_rad"])))
        if row["estimate_ok"]:
            yaw = math.atan2(row["est_vy_mps"], row["est_vx_mps"])
            out.append((f"/auv/{auv}/estimate", ns, pose(ns, row["est_x_m"], row["est_y_m"], yaw)))
        out.append((f"/auv/{auv}/state", ns, _clean(row)))
    for row in _rows(tables["truth"]):
        ns = sim_ns(row["t_s"])
        yaw = math.atan2(row["source_vy_mps"], row["source_vx_mps"])
        out.append(("/source/truth", ns, pose(ns, row["source_x_m"], row["source_y_m"], yaw)))
        out.append(("/source/state", ns, _clean(row)))
    for row in _rows(tables["bearings"]):
        out.append(("/bearings", sim_ns(row["t_s"] if row["recipient"] < 0 else row["t_delivered_s"]), _clean(row)))
    for row in _rows(tables["links"]):
        out.append(("/links", sim_ns(row["t_s"]), _clean(row)))
    for number, line in enumerate(events, start=1):
        event = json.loads(line)
        ns = sim_ns(event.get("t_s", 0.0))
        kind = str(event.get("kind", ""))
        level = 3 if kind in WARNING_EVENTS else 2
        log = {"timestamp": _stamp(ns), "level": level, "message": line, "name": kind, "file": "events.jsonl"}
        out.append(("/events", ns, {**log, "line": number}))
    order = sorted(range(len(out)), key=lambda k: (out[k][1], k))
    return [out[k] for k in order]


def topic_schema(topic: str) -> str:
    """The schema name of ``topic``."""
    if topic.endswith(("/pose", "/estimate")) or topic == "/source/truth":
        return "foxglove.PoseInFrame"
    if topic == "/events":
        return "foxglove.Log"
    if topic.endswith("/state"):
        return ROW_SCHEMAS["truth" if topic.startswith("/source/") else "record"]
    return ROW_SCHEMAS[topic.strip("/")]


def write_mcap(
    path: Path,
    tables: Mapping[str, Mapping[str, Sequence[Any]]],
    events: Sequence[str],
    meta: Mapping[str, Any],
) -> Path:
    """Write the MCAP file ``path`` from the tables' columns, the events.jsonl lines and the run's ``meta``
    (scenario, seed, mode: an MCAP metadata record ``auv_swarm`` with the schema version). Raises ImportError
    without the ``mcap`` package."""
    from mcap.writer import Writer

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("wb") as fh:
        writer = Writer(fh)
        writer.start(profile="", library=f"auv-swarm (raw data schema {SCHEMA_VERSION})")
        schema_ids = {
            name: writer.register_schema(name, "jsonschema", json.dumps(schema).encode())
            for name, schema in schemas().items()
        }
        channels: dict[str, int] = {}
        sequence: dict[str, int] = {}
        for topic, ns, body in messages(tables, events):
            if topic not in channels:
                channels[topic] = writer.register_channel(topic, "json", schema_ids[topic_schema(topic)])
                sequence[topic] = 0
            data = json.dumps(body, allow_nan=False, separators=(",", ":")).encode()
            writer.add_message(channels[topic], ns, data, ns, sequence[topic])
            sequence[topic] += 1
        writer.add_metadata(
            "auv_swarm", {"schema_version": str(SCHEMA_VERSION), **{k: str(v) for k, v in meta.items()}}
        )
        writer.finish()
    tmp.replace(path)
    return path
