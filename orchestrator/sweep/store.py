"""The results store of a sweep: ``DIR/sweep.sqlite`` (docs/sweeps.md), written by the sweep's client alone.

SQLite in WAL mode (``synchronous = NORMAL``): each mission's row is committed as it finishes, so a client
killed at any moment leaves a store that passes ``PRAGMA integrity_check`` with every finished row. Table
``missions`` has one row per mission, unique on (``scenario_sha256``, ``seed``): the axis columns (named
exactly as their keys), then :data:`FIXED_COLUMNS`. Table ``meta`` records the grid (its hash) and the
auv-swarm version; a store of another grid or version, or a damaged one, is refused unless it is moved aside
with what was made from it (:func:`open_store` with ``force``). A lock file keeps a second sweep out of a folder in use. At the end
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

from auv_swarm.results.metric_info import METRIC_INFO, store_columns

STORE_FILE = "sweep.sqlite"
LOCK_FILE = "sweep.lock"
PARQUET_FILE = "missions.parquet"
SUMMARY_FILES = ("summary.md", "summary.json")
"""What the sweep's summary writes beside its figures (``*.png``); ``--force`` moves them aside with the store."""

METRIC_COLUMNS: tuple[tuple[str, str], ...] = store_columns()
"""The top-level numbers of ``metrics.json`` (docs/results.md), one column each under its own name, from
:data:`~auv_swarm.results.metric_info.METRIC_INFO` (a metric added there is a column here)."""

FIXED_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("seed", "INTEGER NOT NULL", "the mission's run.seed"),
    (
        "status",
        "TEXT NOT NULL",
        "done, or failed (the mission or its plug-in raised, its worker died 3 times, or an AUV was compromised)",
    ),
    ("error", "TEXT", "the message of a failed mission (null when done)"),
    ("scenario_sha256", "TEXT NOT NULL", "SHA-256 of the fully resolved scenario TOML, run.seed written as 0"),
    ("version", "TEXT", "auv-swarm version (package version + git commit where known) of the worker that ran it"),
    ("plugins", "TEXT", "metrics.json's plugins: the mission's plug-in methods, packages and versions (JSON)"),
    *(
        (name, kind, f"metrics.json's {METRIC_INFO[name].axis_label()}: {METRIC_INFO[name].meaning} (null when null)")
        for name, kind in METRIC_COLUMNS
    ),
    ("plan_walls_ms", "TEXT", "JSON list of the wall time of every planning instant (ms), in sim-time order"),
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


def check_axis_names(axes: list[str]) -> None:
    """StoreError if an axis has the name of a store column, or of another axis, in any case: SQLite's column
    names are case-insensitive (an axis ``STATUS`` is the column ``status``)."""
    fixed = {n.lower(): n for n in FIXED_NAMES}
    seen: dict[str, str] = {}
    for a in axes:
        if a.lower() in fixed:
            raise StoreError(
                f"axis {a!r} has the name of the store's column {fixed[a.lower()]!r} (column names ignore case); "
                "rename the axis"
            )
        if a.lower() in seen:
            raise StoreError(f"axes {seen[a.lower()]!r} and {a!r} differ only in case; rename one")
        seen[a.lower()] = a


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
        check_axis_names(list(axes))
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
    """The meta table of the store file ``path``; StoreError (one line naming the file and ``--force``) if the
    file is not a sound SQLite store (damaged, truncated, or another kind of file)."""
    try:
        db = sqlite3.connect(path)
        try:
            check = db.execute("PRAGMA quick_check").fetchone()[0]
            if check != "ok":
                raise sqlite3.DatabaseError(check)
            return dict(db.execute("SELECT key, value FROM meta").fetchall())
        finally:
            db.close()
    except sqlite3.Error as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise StoreError(
            f"{path} is damaged or not a sweep store ({reason}); pass --force to move it aside and start again"
        ) from None


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

    A store of another grid or version, or a damaged one, raises StoreError (one line) unless ``force``, which
    moves it aside with the summary, parquet and figures made from it (:func:`move_aside`) and starts a new one.
    """
    check_axis_names(list(axes))
    path = Path(folder) / STORE_FILE
    if path.exists():
        try:
            why = _other(read_meta(path), grid_hash, version)
        except StoreError:
            if not force:
                raise
            why = "damaged"
        if why is not None and not force:
            raise StoreError(
                f"{path} holds the missions of {why}; choose another --out, or pass --force to move it aside"
            )
        if why is not None:
            move_aside(Path(folder))
    meta = {"grid": json.dumps(grid, sort_keys=True), "grid_hash": grid_hash, "version": version}
    meta["created"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    return Store(folder, axes, meta)


def _other(have: dict[str, str], grid_hash: str, version: str) -> str | None:
    """Why a store with meta ``have`` is not this sweep's (another grid, another version), or None."""
    if have.get("grid_hash") != grid_hash:
        return (
            f"another grid (hash {have.get('grid_hash', '?')[:8]}, this one {grid_hash[:8]}: other axes, seeds or "
            "scenarios, or a scenario file that changed)"
        )
    if have.get("version") != version:
        return f"another auv-swarm version ({have.get('version')}, this one {version})"
    return None


def move_aside(folder: Path) -> Path:
    """Move the store (with its -wal and -shm files), ``missions.parquet``, the summaries and the figures
    (``*.png``) of ``folder`` into ``folder/aside-<timestamp>/``; returns that folder."""
    folder = Path(folder)
    aside = folder / f"aside-{time.strftime('%Y%m%dT%H%M%S')}"
    k = 1
    while aside.exists():
        k += 1
        aside = folder / f"aside-{time.strftime('%Y%m%dT%H%M%S')}-{k}"
    aside.mkdir()
    names = [STORE_FILE, STORE_FILE + "-wal", STORE_FILE + "-shm", PARQUET_FILE, *SUMMARY_FILES]
    for path in [*(folder / n for n in names), *sorted(folder.glob("*.png"))]:
        if path.exists():
            path.rename(aside / path.name)
    return aside


def export_parquet(rows: list[dict[str, Any]], path: Path) -> Path:
    """Write ``rows`` (the store's) as a Parquet file (pyarrow), column for column."""
    import pyarrow.parquet as pq

    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(_table(rows), tmp)
    tmp.replace(path)
    return path


def _table(rows: list[dict[str, Any]]) -> Any:
    """The store's rows as a ``pyarrow.Table``, column for column."""
    import pyarrow as pa

    names = list(rows[0]) if rows else list(FIXED_NAMES)
    return pa.Table.from_pydict({n: [r.get(n) for r in rows] for n in names})


STORE_FORMATS = ("csv", "parquet")
"""What a store exports to (``auv-swarm export SWEEP_DIR``): it has one row per mission and no tracks, so no MCAP."""


def is_store(folder: Path) -> bool:
    """Whether ``folder`` holds a sweep's store."""
    return (Path(folder) / STORE_FILE).is_file()


def export_store(folder: Path, fmt: str, out: Path) -> Path:
    """The store's missions as ``out/missions.csv`` or ``out/missions.parquet`` (every row, every column, as
    :func:`read_rows` gives them); StoreError for another format."""
    if fmt not in STORE_FORMATS:
        raise StoreError(
            f"{folder} is a sweep's store: one row per mission and no tracks, so no {fmt}; "
            f"export it as {' or '.join(STORE_FORMATS)}"
        )
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"missions.{fmt}"
    rows = read_rows(folder)
    if fmt == "parquet":
        return export_parquet(rows, path)
    import pyarrow.csv as pcsv

    tmp = path.with_name(path.name + ".tmp")
    pcsv.write_csv(_table(rows), tmp)
    tmp.replace(path)
    return path
