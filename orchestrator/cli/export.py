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
from auv_swarm.results.export import FORMATS, ExportError, export_run

DEFAULT_OUT = "export"
"""The folder under DIR that ``export`` writes into without ``--out``."""


def export(run_dir: Path | str, format: str = "parquet", out: Path | str | None = None) -> list[Path]:
    """Export the run folder (or sweep folder) ``run_dir`` as ``format`` (csv, parquet or mcap) into ``out``
    (default ``run_dir/export``); return the files written (``auv_swarm.export``).

    Raises :class:`~auv_swarm.results.export.ExportError` (a ValueError) for a folder without raw data or a format it
    cannot give, naming what is wrong."""
    run_dir = Path(run_dir)
    target = Path(out) if out is not None else run_dir / DEFAULT_OUT
    if is_store(run_dir):
        try:
            return [export_store(run_dir, format, target)]
        except StoreError as exc:
            raise ExportError(str(exc)) from None
        except sqlite3.Error as exc:
            raise ExportError(f"{run_dir}: the store cannot be read: {exc}") from None
    return export_run(run_dir, format, target)


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
