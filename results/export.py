"""A run's raw data out of its folder, or out of a run record: CSV, Parquet or MCAP (``auv-swarm export``).

The tables are those of :mod:`.tables` (``record.parquet``, ``truth.parquet``, ``bearings.parquet``,
``links.parquet``, written with every run); CSV adds ``schema.json`` (schema version, the run, every column's type,
unit, frame and meaning), MCAP is :func:`.foxglove.write_mcap` (``record.mcap``). A folder written before the raw
data existed, or by a newer schema, is an :class:`ExportError` (one line; the CLI's exit 2).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from auv_swarm.results.record import RunRecord
from auv_swarm.results.report import event_lines
from auv_swarm.results.tables import SCHEMA_VERSION, TABLES, build_tables, run_meta, to_arrow

FORMATS = ("csv", "parquet", "mcap")
"""What :func:`export_run` writes."""

MCAP_FILE = "record.mcap"
SCHEMA_FILE = "schema.json"
EVENTS_FILE = "events.jsonl"
MCAP_EXTRA = "pip install 'auv-swarm[mcap]'"


class ExportError(ValueError):
    """A run folder that cannot be exported, or a format that cannot be written here (one line)."""


def read_tables(run_dir: Path) -> tuple[dict[str, Any], dict[str, str]]:
    """The run folder's tables (``pyarrow.Table`` by name) and the run's metadata (scenario, seed, mode).

    Raises :class:`ExportError` when ``record.parquet`` or a companion is missing or of a newer schema version."""
    import pyarrow
    import pyarrow.parquet as pq

    run_dir = Path(run_dir)
    if not (run_dir / "record.parquet").is_file():
        why = "no such folder" if not run_dir.is_dir() else "no record.parquet"
        raise ExportError(
            f"{run_dir}: {why} (a run folder holds its raw data since issue 47; run the mission again to export it)"
        )
    tables, meta = {}, {}
    for name in TABLES:
        path = run_dir / f"{name}.parquet"
        if not path.is_file():
            raise ExportError(f"{run_dir}: record.parquet without its companion {path.name}")
        try:
            table = pq.read_table(path)
        except pyarrow.ArrowException as exc:  # truncated or not Parquet at all
            raise ExportError(f"{path}: not a readable Parquet table ({str(exc).splitlines()[0]})") from None
        raw = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()}
        version = int(raw.get("auv_swarm.schema_version", "0"))
        if version > SCHEMA_VERSION:
            raise ExportError(
                f"{path}: raw data schema version {version}, newer than this auv-swarm's {SCHEMA_VERSION}: upgrade"
            )
        meta = {k.removeprefix("auv_swarm."): v for k, v in raw.items() if k in _META_KEYS}
        tables[name] = table
    return tables, meta


_META_KEYS = ("auv_swarm.scenario", "auv_swarm.seed", "auv_swarm.mode")


DEFAULT_OUT = "export"
"""The folder under the run folder that :func:`export` writes into without ``out``."""


def export(run_dir: Path | str, format: str = "parquet", out: Path | str | None = None) -> list[Path]:
    """Export the run folder ``run_dir`` as ``format`` (csv, parquet or mcap) into ``out`` (default
    ``run_dir/export``); return the files written (``auv_swarm.export``; a sweep's store: ``auv-swarm export``).

    Raises :class:`ExportError` (a ValueError) for a folder without raw data or a format it cannot give, naming what
    is wrong."""
    run_dir = Path(run_dir)
    return export_run(run_dir, format, Path(out) if out is not None else run_dir / DEFAULT_OUT)


def export_run(run_dir: Path, fmt: str, out: Path) -> list[Path]:
    """Export the run folder ``run_dir`` as ``fmt`` (one of :data:`FORMATS`) into the folder ``out``; the files
    written."""
    _check_format(fmt)
    tables, meta = read_tables(run_dir)
    events_path = Path(run_dir) / EVENTS_FILE
    events = events_path.read_text(encoding="utf-8").splitlines() if events_path.is_file() else []
    events = [e for e in events if e.strip()]
    if fmt == "mcap":  # the only format that carries the events: each line becomes a message
        for number, line in enumerate(events, start=1):
            try:
                json.loads(line)
            except json.JSONDecodeError as exc:
                raise ExportError(f"{events_path}:{number}: not a JSON line ({exc.msg})") from None
    return write_export(tables, events, meta, fmt, out)


def export_record(rec: RunRecord, fmt: str, out: Path) -> list[Path]:
    """Export a run record (``MissionResult.record``) as ``fmt`` into the folder ``out``, exactly as the folder that
    ``write_results`` makes of it would export; the files written."""
    _check_format(fmt)
    meta = run_meta(rec)
    tables = {name: to_arrow(name, cols, meta) for name, cols in build_tables(rec).items()}
    return write_export(tables, event_lines(rec), {k: str(v) for k, v in meta.items()}, fmt, out)


def _check_format(fmt: str) -> None:
    if fmt not in FORMATS:
        raise ExportError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "mcap":
        try:
            import mcap  # noqa: F401
        except ImportError:
            raise ExportError(f"MCAP export needs the mcap package: {MCAP_EXTRA}") from None


def write_export(
    tables: Mapping[str, Any], events: Sequence[str], meta: Mapping[str, str], fmt: str, out: Path
) -> list[Path]:
    """Write ``tables`` (``pyarrow.Table`` by name) as ``fmt`` into the folder ``out`` (created); the files written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if fmt == "mcap":
        from auv_swarm.results.foxglove import write_mcap

        columns = {name: table.to_pydict() for name, table in tables.items()}
        return [write_mcap(out / MCAP_FILE, columns, events, meta)]
    written = []
    for name, table in tables.items():
        written.append(_write_table(table, out / f"{name}.{fmt}", fmt))
    if fmt == "csv":
        path = out / SCHEMA_FILE
        path.write_text(json.dumps(schema_description(meta), indent=2) + "\n", encoding="utf-8")
        written.append(path)
    return written


def _write_table(table: Any, path: Path, fmt: str) -> Path:
    """One table as CSV (header row, NaN as ``nan``, booleans as ``true``/``false``) or Parquet, moved into place."""
    tmp = path.with_name(path.name + ".tmp")
    if fmt == "csv":
        import pyarrow.csv as pcsv

        pcsv.write_csv(table, tmp)
    else:
        import pyarrow.parquet as pq

        pq.write_table(table, tmp)
    tmp.replace(path)
    return path


def schema_description(meta: Mapping[str, str]) -> dict[str, Any]:
    """``schema.json``: the schema version, the run, and every table's columns (name, type, unit, frame, meaning)."""
    return {
        "schema_version": SCHEMA_VERSION,
        "run": dict(meta),
        "tables": {name: [asdict(c) for c in columns] for name, columns in TABLES.items()},
    }
