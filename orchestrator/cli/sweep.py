"""``auv-swarm sweep [SCENARIO | --scenario SCENARIO] [KEY=V1,V2,...]... [--seeds A-B | --seeds N] [--duration S]
[--out DIR] [--workers N] [--scheduler tls://HOST:PORT --tls-dir DIR] [--insecure-scheduler] [--dashboard]
[--force] [--json]``: a grid of missions on Dask; ``auv-swarm sweep --summary DIR``: a sweep's summary made
again from its store.

SCENARIO is a built-in name, a scenario TOML path, or a sweep file (a TOML file with a [sweep] table). Each
KEY=V1,V2,... is an axis over a dotted scenario key (values read as TOML scalars, else strings);
scenario=NAME,... sweeps base scenarios. Every cell is checked before the first mission. Rows go to
DIR/sweep.sqlite as missions finish (default DIR: sweeps/<base>-<8 hex of the grid's hash>/); the same
command resumes. At the end: missions.parquet, summary.json, summary.md and figures. Every Dask link is mutual
TLS: the LocalCluster's with certificates made for the sweep, an existing cluster's with those of --tls-dir
(auv-swarm credentials --dask DIR); a tcp:// scheduler only with --insecure-scheduler. docs/sweeps.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from auv_swarm.contract.usage import BAD_INPUT, RUN_FAILED, SEEDS_HELP, fail, plain_description
from auv_swarm.orchestrator.sweep import cluster
from auv_swarm.orchestrator.sweep import grid as gridmod
from auv_swarm.orchestrator.sweep.execute import execute, rebuild_summary


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="auv-swarm sweep", description=plain_description(__doc__))
    parser.add_argument(
        "items",
        nargs="*",
        metavar="[SCENARIO] [KEY=V1,V2,...]",
        help="a scenario name, scenario TOML or sweep file, then axes KEY=V1,V2,... (scenario=A,B for base scenarios)",
    )
    parser.add_argument(
        "--scenario", default=None, metavar="SCENARIO", help="the scenario, as the positional SCENARIO (either one)"
    )
    parser.add_argument("--seeds", default=None, help=f"{SEEDS_HELP}; default 10")
    parser.add_argument("--duration", type=float, default=None, help="mission length (s of sim time) for every cell")
    parser.add_argument("--out", type=Path, default=None, help="results folder (default sweeps/<base>-<hash>/)")
    parser.add_argument("--workers", type=int, default=None, help="LocalCluster worker processes (default: cores)")
    cluster.add_scheduler_args(parser)
    parser.add_argument("--dashboard", action="store_true", help="serve the Dask dashboard (needs the dashboard extra)")
    parser.add_argument("--force", action="store_true", help="move a store of another grid or version aside")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    parser.add_argument("--json", action="store_true", help="print summary.json on stdout")
    parser.add_argument(
        "--summary",
        type=Path,
        default=None,
        metavar="DIR",
        help="make DIR's summary, parquet and figures again from its sweep.sqlite, running nothing",
    )
    return parser


def grid_from_args(
    items: list[str], seeds: str | None, duration: float | None, option: str | None = None
) -> gridmod.Grid:
    """The grid of the verb's positional items and ``--scenario`` (GridError on bad input)."""
    axes = [i for i in items if "=" in i]
    plain = [i for i in items if "=" not in i]
    if len(plain) > 1:
        raise gridmod.GridError(f"{plain[1]!r}: expected KEY=V1,V2,... (one SCENARIO at most, then axes)")
    if option is not None and plain and plain[0] != option:
        raise gridmod.GridError(f"two scenarios given: {plain[0]!r} and --scenario {option!r}; give one")
    scenario = option if option is not None else (plain[0] if plain else None)
    if scenario is not None:
        if gridmod.is_sweep_file(scenario):
            if axes:
                raise gridmod.GridError(f"{scenario} is a sweep file: put the axes in its [sweep.axes] table")
            return gridmod.from_file(scenario, seeds, duration)
    return gridmod.from_command_line(scenario, axes, seeds, duration)


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.summary is not None:
        return summary_main(args)
    if args.workers is not None and args.workers < 1:
        return fail(f"--workers must be >= 1, got {args.workers}")
    if args.workers is not None and args.scheduler is not None:
        return fail("--workers sizes the LocalCluster; with --scheduler the cluster's workers are used")
    try:
        scheduler = cluster.scheduler_from_args(args)
    except cluster.ClusterError as exc:
        return fail(str(exc), BAD_INPUT)
    try:
        grid = grid_from_args(args.items, args.seeds, args.duration, args.scenario)
    except gridmod.GridError as exc:
        return fail(str(exc), BAD_INPUT)
    return _show(
        execute(
            grid,
            args.out,
            workers=args.workers,
            scheduler=scheduler,
            dashboard=args.dashboard,
            force=args.force,
            quiet=args.quiet,
        ),
        args,
    )


def summary_main(args: argparse.Namespace) -> int:
    """``--summary DIR``: nothing else of a sweep may be given; the summary made again and shown."""
    others = [
        flag
        for flag, given in (
            ("SCENARIO or axes", args.items),
            ("--scenario", args.scenario),
            ("--seeds", args.seeds),
            ("--duration", args.duration is not None),
            ("--out", args.out),
            ("--workers", args.workers is not None),
            ("--scheduler", args.scheduler),
            ("--tls-dir", args.tls_dir),
            ("--insecure-scheduler", args.insecure_scheduler),
            ("--force", args.force),
        )
        if given
    ]
    if others:
        return fail(f"--summary DIR runs nothing: leave out {', '.join(others)}")
    return _show(rebuild_summary(args.summary), args)


def _show(result, args: argparse.Namespace) -> int:
    """Print summary.md (or summary.json with --json) of a sweep that produced one; the exit code."""
    if result.code in (0, RUN_FAILED) and result.rows:
        summary_path = result.folder / "summary.json"
        if args.json and summary_path.exists():
            print(summary_path.read_text(encoding="utf-8").strip())
        elif not args.quiet and summary_path.exists():
            print((result.folder / "summary.md").read_text(encoding="utf-8"))
    return result.code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
