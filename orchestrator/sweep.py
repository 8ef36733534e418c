"""``auv-swarm sweep [SCENARIO] [KEY=V1,V2,...]... [--seeds A-B | --seeds N] [--duration S] [--out DIR]
[--workers N] [--scheduler ADDRESS] [--dashboard] [--force] [--json]``: a grid of missions on Dask.

SCENARIO is a built-in name, a scenario TOML path, or a sweep file (a TOML file with a [sweep] table). Each
KEY=V1,V2,... is an axis over a dotted scenario key (values read as TOML scalars, else strings);
scenario=NAME,... sweeps base scenarios. Every cell is checked before the first mission. Rows go to
DIR/sweep.sqlite as missions finish (default DIR: sweeps/<base>-<8 hex of the grid's hash>/); the same
command resumes. At the end: missions.parquet, summary.json, summary.md and figures. docs/sweeps.md.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from auv_swarm.contract.shell import plain_description
from auv_swarm.contract.usage import BAD_INPUT, RUN_FAILED, fail
from auv_swarm.orchestrator import grid as gridmod
from auv_swarm.orchestrator import outdir

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
    scheduler: str | None = None,
    dashboard: bool = False,
    force: bool = False,
    quiet: bool = False,
    label: str = "sweep",
    own: tuple[str, ...] = (),
) -> SweepResult:
    """Check the grid, open the store, run the missions not done yet, export and summarise; one line on errors.

    Used by ``auv-swarm sweep`` and ``auv-swarm bench table3``.
    """
    from auv_swarm.orchestrator.progress import SweepProgress
    from auv_swarm.orchestrator.version import version
    from auv_swarm.results import store as storemod

    try:
        cells = grid.check()
    except gridmod.GridError as exc:
        return SweepResult(fail(str(exc)), Path("."), [])
    if grid.skipped and not quiet:
        print(f"{len(grid.skipped)} invalid grid cells skipped (skip_invalid)", file=sys.stderr)
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
            return _run(grid, missions, store, folder, ver, workers, scheduler, dashboard, quiet, label, SweepProgress)
        finally:
            store.close()
    finally:
        lock.release()


def _run(grid, missions, store, folder, ver, workers, scheduler, dashboard, quiet, label, progress_cls) -> SweepResult:
    from auv_swarm.orchestrator import sweep_engine
    from auv_swarm.results import store as storemod
    from auv_swarm.results import sweep_summary

    if not quiet:
        print(f"{label}: {len(missions)} missions into {folder}/", file=sys.stderr)
    counts = sweep_engine.Counts()
    code = 0
    try:
        with (
            sweep_engine.connect(workers, scheduler, dashboard) as client,
            progress_cls(label, len(missions), enabled=not quiet) as progress,
        ):
            sweep_engine.run(
                missions,
                store,
                ver,
                client,
                count_deaths=scheduler is not None,
                on_result=lambda c: progress.counts(c.done, c.skipped, c.failed, c.total),
                counts=counts,
            )
    except sweep_engine.Interrupted:
        print(
            f"{label}: interrupted; {counts.done + counts.skipped} of {counts.total} missions done and kept in "
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
            f"{counts.failed} of {counts.total} missions failed (status = failed in {folder / storemod.STORE_FILE})",
            RUN_FAILED,
        )
        code = RUN_FAILED
    return SweepResult(code, folder, rows, counts)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="auv-swarm sweep", description=plain_description(__doc__))
    parser.add_argument(
        "items",
        nargs="*",
        metavar="[SCENARIO] [KEY=V1,V2,...]",
        help="a scenario name, scenario TOML or sweep file, then axes KEY=V1,V2,... (scenario=A,B for base scenarios)",
    )
    parser.add_argument("--seeds", default=None, help="A-B (inclusive) or N (seeds 1..N); default 10")
    parser.add_argument("--duration", type=float, default=None, help="mission length (s of sim time) for every cell")
    parser.add_argument("--out", type=Path, default=None, help="results folder (default sweeps/<base>-<hash>/)")
    parser.add_argument("--workers", type=int, default=None, help="LocalCluster worker processes (default: cores)")
    parser.add_argument(
        "--scheduler", default=None, metavar="ADDRESS", help="an existing Dask scheduler (tcp://HOST:PORT)"
    )
    parser.add_argument("--dashboard", action="store_true", help="serve the Dask dashboard (needs the dashboard extra)")
    parser.add_argument("--force", action="store_true", help="move a store of another grid or version aside")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    parser.add_argument("--json", action="store_true", help="print summary.json on stdout")
    return parser


def grid_from_args(items: list[str], seeds: str | None, duration: float | None) -> gridmod.Grid:
    """The grid of the verb's positional items (GridError on bad input)."""
    scenario = None
    axes = [i for i in items if "=" in i]
    plain = [i for i in items if "=" not in i]
    if len(plain) > 1:
        raise gridmod.GridError(f"{plain[1]!r}: expected KEY=V1,V2,... (one SCENARIO at most, then axes)")
    if plain:
        scenario = plain[0]
        if gridmod.is_sweep_file(scenario):
            if axes:
                raise gridmod.GridError(f"{scenario} is a sweep file: put the axes in its [sweep.axes] table")
            return gridmod.from_file(scenario, seeds, duration)
    return gridmod.from_command_line(scenario, axes, seeds, duration)


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.workers is not None and args.workers < 1:
        return fail(f"--workers must be >= 1, got {args.workers}")
    if args.workers is not None and args.scheduler is not None:
        return fail("--workers sizes the LocalCluster; with --scheduler the cluster's workers are used")
    try:
        grid = grid_from_args(args.items, args.seeds, args.duration)
    except gridmod.GridError as exc:
        return fail(str(exc), BAD_INPUT)
    result = execute(
        grid,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        dashboard=args.dashboard,
        force=args.force,
        quiet=args.quiet,
    )
    if result.code in (0, RUN_FAILED) and result.rows:
        summary_path = result.folder / "summary.json"
        if args.json and summary_path.exists():
            print(summary_path.read_text(encoding="utf-8").strip())
        elif not args.quiet and summary_path.exists():
            print((result.folder / "summary.md").read_text(encoding="utf-8"))
    return result.code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
