"""The sweep verb's work: a grid into a resumable store on Dask, then the summary (:func:`execute`).

The verb's argument parsing is :mod:`auv_swarm.orchestrator.cli.sweep`; docs/sweeps.md.
"""

from __future__ import annotations

import contextlib
import sys
from dataclasses import dataclass
from pathlib import Path

from auv_swarm.contract.usage import RUN_FAILED, fail, plural
from auv_swarm.orchestrator.mission import outdir
from auv_swarm.orchestrator.sweep import grid as gridmod
from auv_swarm.orchestrator.sweep.cluster import Scheduler

EXIT_INTERRUPTED = 130


@dataclass
class SweepResult:
    """What :func:`execute` did: the exit code, the folder, the store's rows and the counts."""

    code: int
    folder: Path
    rows: list[dict]
    counts: object | None = None


def execute(
    grid: gridmod.Grid,
    out: Path | None,
    *,
    workers: int | None = None,
    scheduler: Scheduler | None = None,
    dashboard: bool = False,
    force: bool = False,
    quiet: bool = False,
    label: str = "sweep",
    own: tuple[str, ...] = (),
) -> SweepResult:
    """Check the grid, open the store, run the missions not done yet, export and summarise; one line on errors.

    ``scheduler`` (:func:`~auv_swarm.orchestrator.sweep.cluster.scheduler_from_args`) is reached before the
    folder is made: unreachable, nothing is written (exit 1). Used by ``auv-swarm sweep`` and ``auv-swarm bench
    table3``.
    """
    from auv_swarm.orchestrator.sweep import engine as sweep_engine
    from auv_swarm.orchestrator.sweep import store as storemod

    try:
        cells = grid.check()
        storemod.check_axis_names(grid.columns)
    except (gridmod.GridError, storemod.StoreError) as exc:
        return SweepResult(fail(str(exc)), Path("."), [])
    with contextlib.ExitStack() as stack:
        client = None
        if scheduler is not None:
            try:
                client = stack.enter_context(sweep_engine.connect(None, scheduler, dashboard))
            except sweep_engine.EngineError as exc:
                return SweepResult(fail(str(exc), RUN_FAILED), Path("."), [])
        cluster = _Cluster(workers, client, dashboard)
        return _execute(grid, cells, out, cluster, force=force, quiet=quiet, label=label, own=own)


@dataclass
class _Cluster:
    """Where the missions run: a client already connected to a scheduler, or a LocalCluster of ``workers``,
    started once the store is open."""

    workers: int | None
    client: object | None
    dashboard: bool

    @contextlib.contextmanager
    def connect(self):
        from auv_swarm.orchestrator.sweep import engine as sweep_engine

        if self.client is not None:
            yield self.client
            return
        with sweep_engine.connect(self.workers, None, self.dashboard) as client:
            yield client


def _execute(grid, cells, out, cluster: _Cluster, *, force: bool, quiet: bool, label: str, own) -> SweepResult:
    from auv_swarm.orchestrator.mission.progress import SweepProgress
    from auv_swarm.orchestrator.sweep import store as storemod
    from auv_swarm.orchestrator.sweep.version import version

    if grid.skipped and not quiet:
        print(f"{plural(len(grid.skipped), 'invalid grid cell')} skipped (skip_invalid)", file=sys.stderr)
    missions = grid.missions(cells)
    folder = Path(out) if out is not None else grid.default_folder()
    try:
        outdir.prepare(folder, flag="--out", own=(storemod.STORE_FILE, *own), force=False)
    except outdir.OutDirError as exc:
        return SweepResult(fail(str(exc)), folder, [])
    ver = version()
    axes_values = {a.key: list(a.values) for a in grid.axes}
    try:
        lock = storemod.Lock(folder)
    except storemod.StoreError as exc:
        return SweepResult(fail(str(exc)), folder, [])
    try:
        try:
            store = storemod.open_store(folder, axes_values, grid.plain(), grid.hash, ver, force)
        except storemod.StoreError as exc:
            return SweepResult(fail(str(exc)), folder, [])
        try:
            return _run(grid, missions, store, folder, ver, cluster, quiet, label, SweepProgress)
        finally:
            store.close()
    finally:
        lock.release()


def _run(grid, missions, store, folder, ver, cluster: _Cluster, quiet, label, progress_cls) -> SweepResult:
    from auv_swarm.orchestrator.sweep import engine as sweep_engine
    from auv_swarm.orchestrator.sweep import store as storemod
    from auv_swarm.orchestrator.sweep import summary as sweep_summary

    if not quiet:
        print(f"{label}: {plural(len(missions), 'mission')} into {folder}/", file=sys.stderr)
    counts = sweep_engine.Counts()
    code = 0
    try:
        with (
            cluster.connect() as client,
            progress_cls(label, len(missions), enabled=not quiet) as progress,
        ):
            sweep_engine.run(
                missions,
                store,
                ver,
                client,
                count_deaths=cluster.client is not None,
                on_result=lambda c: progress.counts(c.done, c.skipped, c.failed, c.total),
                counts=counts,
            )
    except sweep_engine.Interrupted:
        print(
            f"{label}: interrupted; {counts.done + counts.skipped} of {plural(counts.total, 'mission')} done and kept in "
            f"{folder / storemod.STORE_FILE}; the same command resumes",
            file=sys.stderr,
        )
        return SweepResult(EXIT_INTERRUPTED, folder, store.rows(), counts)
    except sweep_engine.EngineError as exc:
        return SweepResult(fail(str(exc), RUN_FAILED), folder, store.rows(), counts)
    rows = store.rows()
    storemod.export_parquet(rows, folder / storemod.PARQUET_FILE)
    sweep_summary.write(rows, grid.columns, folder, grid.hash)
    if counts.failed:
        for line in counts.failures[:10]:
            print(f"failed: {line}", file=sys.stderr)
        fail(
            f"{counts.failed} of {plural(counts.total, 'mission')} failed (status = failed in "
            f"{folder / storemod.STORE_FILE})",
            RUN_FAILED,
        )
        code = RUN_FAILED
    return SweepResult(code, folder, rows, counts)


def rebuild_summary(folder: Path) -> SweepResult:
    """``auv-swarm sweep --summary DIR``: missions.parquet, summary.json, summary.md and the figures made again from
    ``DIR/sweep.sqlite``, running nothing; one line and exit 2 if DIR holds no sound store."""
    import json

    from auv_swarm.orchestrator.sweep import store as storemod
    from auv_swarm.orchestrator.sweep import summary as sweep_summary

    folder = Path(folder)
    path = folder / storemod.STORE_FILE
    if not path.is_file():
        return SweepResult(fail(f"--summary {folder}: no {storemod.STORE_FILE} there (a sweep's folder?)"), folder, [])
    try:
        meta = storemod.read_meta(path)
        grid = json.loads(meta.get("grid", "{}"))
        axes = [a[0] for a in grid.get("axes", [])]
        rows = storemod.read_rows(folder)
    except (storemod.StoreError, ValueError, TypeError, IndexError) as exc:
        return SweepResult(fail(f"--summary {folder}: {exc}"), folder, [])
    if not rows:
        return SweepResult(fail(f"--summary {folder}: the store holds no mission yet"), folder, [])
    storemod.export_parquet(rows, folder / storemod.PARQUET_FILE)
    sweep_summary.write(rows, axes, folder, meta.get("grid_hash", ""))
    return SweepResult(0, folder, rows)
