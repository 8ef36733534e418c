"""The results store of a sweep: ``DIR/sweep.sqlite`` (docs/sweeps.md), written by the sweep's client alone.

SQLite in WAL mode (``synchronous = NORMAL``): each mission's row is committed as it finishes, so a client
killed at any moment leaves a store that passes ``PRAGMA integrity_check`` with every finished row. Table
``missions`` has one row per mission, unique on (``scenario_sha256``, ``seed``): the axis columns (named
exactly as their keys), then :data:`FIXED_COLUMNS`. Table ``meta`` records the grid (its hash) and the
auv-swarm version; a store of another grid or version is refused unless it is moved aside
(:func:`open_store` with ``force``). A lock file keeps a second sweep out of a folder in use. At the end
:func:`export_parquet` writes ``missions.parquet``.
"""

from __future__ import annotations

import fcntl
import json
import os
import sqlite3
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

STORE_FILE = "sweep.sqlite"
LOCK_FILE = "sweep.lock"
PARQUET_FILE = "missions.parquet"

METRIC_COLUMNS: tuple[tuple[str, str], ...] = (
    ("n_agents", "INTEGER"),
    ("complete", "INTEGER"),
    ("exit_code", "INTEGER"),
    ("sim_duration_s", "REAL"),
    ("wall_time_s", "REAL"),
    ("ticks", "INTEGER"),
    ("tracking_error_mean_m", "REAL"),
    ("tracking_error_std_m", "REAL"),
    ("tracking_error_samples", "INTEGER"),
    ("tracking_error_p95_m", "REAL"),
    ("tracking_error_steady_mean_m", "REAL"),
    ("no_estimate_fraction", "REAL"),
    ("convergence_error_m", "REAL"),
    ("convergence_hold_s", "REAL"),
    ("convergence_time_s", "REAL"),
    ("under_15m_after_convergence_fraction", "REAL"),
    ("longest_excursion_s", "REAL"),
    ("nees_mean", "REAL"),
    ("nees_in_band_fraction", "REAL"),
    ("nees_samples", "INTEGER"),
    ("fqi", "REAL"),
    ("fqi_degenerate_ticks", "INTEGER"),
    ("plan_count", "INTEGER"),
    ("duplicate_logins", "INTEGER"),
    ("plan_time_median_ms", "REAL"),
    ("plan_time_max_ms", "REAL"),
)
"""The top-level numbers of ``metrics.json`` (docs/results.md), one column each under its own name."""

FIXED_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("seed", "INTEGER NOT NULL", "the mission's run.seed"),
    ("status", "TEXT NOT NULL", "done, or failed (the mission or its plug-in raised, or its worker died 3 times)"),
    ("error", "TEXT", "the message of a failed mission (null when done)"),
    ("scenario_sha256", "TEXT NOT NULL", "SHA-256 of the fully resolved scenario TOML, run.seed written as 0"),
    ("version", "TEXT", "auv-swarm version (package version + git commit where known) of the worker that ran it"),
    ("plugins", "TEXT", "metrics.json's plugins: the mission's plug-in methods, packages and versions (JSON)"),
    *(
        (name, kind, "metrics.json's top-level number of that name (null when the metric is null)")
        for name, kind in METRIC_COLUMNS
    ),
    ("plan_walls_ms", "TEXT", "JSON list of the wall time of every planning instant (ms), in sim-time order"),
    ("wall_s", "REAL", "wall time of the mission on its worker (s)"),
    ("cpu_s", "REAL", "CPU time of the worker process during the mission (s)"),
    ("worker", "TEXT", "the Dask worker's address"),
    ("attempts", "INTEGER NOT NULL", "how many times the mission was started (1 unless a worker died under it)"),
    ("metrics", "TEXT", "the whole metrics.json of the mission (JSON; null when it raised or its worker died)"),
)
"""The store's columns after the axis columns: (name, SQLite type, meaning). docs/sweeps.md's table is made from
this (tools/gendocs.py)."""

FIXED_NAMES = tuple(c[0] for c in FIXED_COLUMNS)


class StoreError(ValueError):
    """The store cannot be used; the message is one line for the user."""


def _quote(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def _axis_type(values: Iterable[Any]) -> str:
    vals = list(values)
    if vals and all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
        return "INTEGER"
    if vals and all(isinstance(v, int | float) and not isinstance(v, bool) for v in vals):
        return "REAL"
    return "TEXT"


def axis_value(value: Any) -> Any:
    """An axis value as its column holds it (numbers as numbers, anything else as TOML-ish text/JSON)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float | str):
        return value
    return json.dumps(value)


class Store:
    """An open ``sweep.sqlite`` with its axis columns; use :func:`open_store`."""

    def __init__(self, folder: Path, axes: dict[str, list[Any]], meta: dict[str, str]) -> None:
        self.folder = Path(folder)
        self.path = self.folder / STORE_FILE
        clash = [a for a in axes if a in FIXED_NAMES]
        if clash:
            raise StoreError(f"axis {clash[0]!r} has the name of one of the store's columns; rename the axis")
        self.axes = list(axes)
        self.db = sqlite3.connect(self.path, isolation_level=None, timeout=10.0)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=NORMAL")
        cols = [f"{_quote(a)} {_axis_type(v)}" for a, v in axes.items()]
        cols += [f"{_quote(n)} {t}" for n, t, _ in FIXED_COLUMNS]
        self.db.execute(f"CREATE TABLE IF NOT EXISTS missions ({', '.join(cols)}, UNIQUE(scenario_sha256, seed))")
        self.db.execute("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
        have = dict(self.db.execute("SELECT key, value FROM meta").fetchall())
        if not have:
            with self.db:
                self.db.execute("BEGIN")
                self.db.executemany("INSERT INTO meta VALUES (?, ?)", sorted(meta.items()))

    def meta(self) -> dict[str, str]:
        return dict(self.db.execute("SELECT key, value FROM meta").fetchall())

    def done(self) -> set[tuple[str, int]]:
        """(scenario_sha256, seed) of the missions already done."""
        return set(self.db.execute("SELECT scenario_sha256, seed FROM missions WHERE status = 'done'").fetchall())

    def put(self, labels: dict[str, Any], row: dict[str, Any]) -> None:
        """Insert or replace the row of one mission (committed at once)."""
        values = {a: axis_value(labels.get(a)) for a in self.axes}
        for name in FIXED_NAMES:
            v = row.get(name)
            if name in ("plan_walls_ms", "metrics", "plugins") and v is not None and not isinstance(v, str):
                v = json.dumps(v)
            elif isinstance(v, bool):
                v = int(v)
            values[name] = v
        names = ", ".join(_quote(n) for n in values)
        marks = ", ".join("?" for _ in values)
        update = ", ".join(f"{_quote(n)} = excluded.{_quote(n)}" for n in values)
        self.db.execute(
            f"INSERT INTO missions ({names}) VALUES ({marks}) ON CONFLICT(scenario_sha256, seed) DO UPDATE SET {update}",
            list(values.values()),
        )

    def rows(self) -> list[dict[str, Any]]:
        """Every row as a dict (``plan_walls_ms`` and ``metrics`` as text)."""
        cur = self.db.execute("SELECT * FROM missions ORDER BY rowid")
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r, strict=True)) for r in cur.fetchall()]

    def close(self) -> None:
        self.db.close()


def read_rows(folder: Path) -> list[dict[str, Any]]:
    """The rows of the store in ``folder`` (read-only)."""
    db = sqlite3.connect(f"file:{Path(folder) / STORE_FILE}?mode=ro", uri=True)
    try:
        cur = db.execute("SELECT * FROM missions ORDER BY rowid")
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r, strict=True)) for r in cur.fetchall()]
    finally:
        db.close()


def read_meta(path: Path) -> dict[str, str]:
    """The meta table of the store file ``path`` (empty if it has none)."""
    db = sqlite3.connect(path)
    try:
        return dict(db.execute("SELECT key, value FROM meta").fetchall())
    except sqlite3.DatabaseError:
        return {}
    finally:
        db.close()


class Lock:
    """``DIR/sweep.lock`` held (flock) while a sweep uses the folder; released by the OS if the client dies."""

    def __init__(self, folder: Path) -> None:
        self.path = Path(folder) / LOCK_FILE
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(self.fd, 64, 0).decode(errors="replace").strip() or "another process"
            os.close(self.fd)
            raise StoreError(f"{folder} is in use by another sweep (pid {holder}); wait for it to end") from None
        os.ftruncate(self.fd, 0)
        os.pwrite(self.fd, str(os.getpid()).encode(), 0)

    def release(self) -> None:
        if self.fd >= 0:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = -1


def open_store(
    folder: Path, axes: dict[str, list[Any]], grid: dict, grid_hash: str, version: str, force: bool
) -> Store:
    """Open (or create) the store of ``folder`` for this grid and version.

    A store of another grid or version raises StoreError (one line) unless ``force``, which moves it aside as
    ``sweep.sqlite.<timestamp>`` and starts a new one.
    """
    path = Path(folder) / STORE_FILE
    if path.exists():
        have = read_meta(path)
        why = None
        if have.get("grid_hash") != grid_hash:
            why = f"another grid (hash {have.get('grid_hash', '?')[:8]}, this one {grid_hash[:8]})"
        elif have.get("version") != version:
            why = f"another auv-swarm version ({have.get('version')}, this one {version})"
        if why is not None:
            if not force:
                raise StoreError(
                    f"{path} holds the missions of {why}; choose another --out, or pass --force to move it aside"
                )
            aside = path.with_name(f"{STORE_FILE}.{time.strftime('%Y%m%dT%H%M%S')}")
            path.rename(aside)
            for suffix in ("-wal", "-shm"):
                extra = path.with_name(STORE_FILE + suffix)
                if extra.exists():
                    extra.rename(aside.with_name(aside.name + suffix))
    meta = {"grid": json.dumps(grid, sort_keys=True), "grid_hash": grid_hash, "version": version}
    meta["created"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    return Store(folder, axes, meta)


def export_parquet(rows: list[dict[str, Any]], path: Path) -> Path:
    """Write ``rows`` (the store's) as a Parquet file (pyarrow), column for column."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = list(rows[0]) if rows else list(FIXED_NAMES)
    table = pa.Table.from_pydict({n: [r.get(n) for r in rows] for n in names})
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    tmp.replace(path)
    return path
