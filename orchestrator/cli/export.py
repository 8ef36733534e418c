"""``auv-swarm export DIR --format csv|parquet|mcap [--out OUT]``: a run's raw data, or a sweep's store, as files.

A run folder (``record.parquet`` and its companions, written with every run) exports its four tables as CSV (with
``schema.json``) or Parquet, or the whole run as one MCAP file (``record.mcap``: Foxglove, other MCAP readers,
``rerun mcap convert``). A sweep's folder (``sweep.sqlite``) exports its missions as ``missions.csv`` or
``missions.parquet``; MCAP is refused (a store has no tracks). ``--out`` defaults to ``DIR/export``. A folder
without the raw data (an older run), a store asked for MCAP, or MCAP without the ``mcap`` package: one line, exit 2.
docs/results.md describes every column and topic.
"""

from __future__ import annotations

import argparse
import sqlite3
from pathlib import Path

from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.sweep.store import StoreError, export_store, is_store
from auv_swarm.results.export import DEFAULT_OUT, FORMATS, ExportError
from auv_swarm.results.export import export as export_run_folder


def export(folder: Path, format: str, out: Path | None) -> list[Path]:
    """Export a run folder (:func:`auv_swarm.results.export.export`) or a sweep's folder (its missions)."""
    if not is_store(folder):
        return export_run_folder(folder, format, out)
    try:
        return [export_store(folder, format, out if out is not None else folder / DEFAULT_OUT)]
    except StoreError as exc:
        raise ExportError(str(exc)) from None
    except sqlite3.Error as exc:
        raise ExportError(f"{folder}: the store cannot be read: {exc}") from None


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm export``."""
    parser = argparse.ArgumentParser(prog="auv-swarm export", description=plain_description(__doc__))
    parser.add_argument(
        "dir", type=Path, metavar="DIR", help="a run's results folder, or a sweep's folder (sweep.sqlite)"
    )
    parser.add_argument("--format", required=True, choices=FORMATS, help="csv, parquet or mcap (runs only)")
    parser.add_argument("--out", type=Path, default=None, help=f"folder to write into (default DIR/{DEFAULT_OUT})")
    args = parser.parse_args(argv)
    try:
        written = export(args.dir, args.format, args.out)
    except (ExportError, OSError) as exc:
        return fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    folder = written[0].parent if written else args.out
    print(f"wrote {', '.join(p.name for p in written)} to {folder}")
    return 0
