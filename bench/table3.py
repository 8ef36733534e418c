"""``auv-swarm bench table3 [--seeds N] [--json]``: the section 3.3 comparison, Monte-Carlo.

Runs the five ``paper-3.3-sim*`` scenarios in process over seeds 1..N (default
10) and reports, per scenario, the tracking error pooled over every live AUV,
tick and seed (mean +/- std, as in the paper's Table 3), the spread of the
per-seed means, the FQI and the planning time, beside the paper's DMPC row.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from contract.config import ConfigError, load_scenario
from contract.shell import plain_description
from orchestrator import outdir
from orchestrator.progress import Progress

PAPER_DMPC = {
    "paper-3.3-sim1": (10.4, 8.0),
    "paper-3.3-sim2": (13.4, 12.6),
    "paper-3.3-sim3": (14.4, 14.2),
    "paper-3.3-sim4": (22.9, 21.5),
    "paper-3.3-sim5": (14.7, 14.9),
}


def one_run(name: str, seed: int) -> dict:
    """Metrics of one in-process mission."""
    from contract.config import load_scenario
    from orchestrator.collect import MessageLog
    from orchestrator.inprocess import run_inprocess
    from orchestrator.results import compute_metrics

    scenario = load_scenario(name).with_overrides(seed=seed)
    log = MessageLog()
    start = time.perf_counter()
    run_inprocess(scenario, [log])
    return compute_metrics(log.to_record(scenario, "inprocess", time.perf_counter() - start))


def pooled(runs: list[dict]) -> tuple[float, float]:
    """Mean and std of the tracking error over all samples of all runs."""
    n = [r["tracking_error_samples"] for r in runs]
    m = [r["tracking_error_mean_m"] for r in runs]
    s = [r["tracking_error_std_m"] for r in runs]
    total = sum(n)
    mean = sum(ni * mi for ni, mi in zip(n, m, strict=True)) / total
    var = sum(ni * (si**2 + (mi - mean) ** 2) for ni, mi, si in zip(n, m, s, strict=True)) / total
    return mean, math.sqrt(var)


def summarise(name: str, runs: list[dict]) -> dict:
    """One Table 3 row from the runs of one scenario."""
    mean, std = pooled(runs)
    per_seed = [r["tracking_error_mean_m"] for r in runs]
    mu = sum(per_seed) / len(per_seed)
    spread = math.sqrt(sum((x - mu) ** 2 for x in per_seed) / len(per_seed))
    fqi = [r["fqi"] for r in runs if r["fqi"] is not None]
    plan_ms = sorted(r["plan_time_median_ms"] for r in runs if r["plan_time_median_ms"] is not None)
    paper = PAPER_DMPC.get(name)
    return {
        "scenario": name,
        "seeds": [r["seed"] for r in runs],
        "tracking_error_mean_m": round(mean, 2),
        "tracking_error_std_m": round(std, 2),
        "per_seed_mean_spread_m": round(spread, 2),
        "per_seed_means_m": [round(x, 2) for x in per_seed],
        "no_estimate_fraction": round(sum(r["no_estimate_fraction"] or 0 for r in runs) / len(runs), 3),
        "fqi": round(sum(fqi) / len(fqi), 3) if fqi else None,
        "plan_time_median_ms": plan_ms[len(plan_ms) // 2] if plan_ms else None,
        "paper_dmpc_m": paper[0] if paper else None,
        "paper_dmpc_std_m": paper[1] if paper else None,
        "at_or_below_paper": (mean <= paper[0]) if paper else None,
    }


def main(argv: list[str]) -> int:
    """Run the batch (in parallel over the machine's cores) and print the table."""
    parser = argparse.ArgumentParser(prog="auv-swarm bench table3", description=plain_description(__doc__))
    parser.add_argument("--seeds", type=int, default=10, help="seeds 1..N per scenario")
    parser.add_argument(
        "--scenarios", nargs="*", default=sorted(PAPER_DMPC), help="scenario names or TOML paths (default: Sim 1-5)"
    )
    parser.add_argument(
        "--workers", type=int, default=os.cpu_count() or 1, help="missions run in parallel (default: the CPU count)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--out", type=Path, default=None, help="also write the JSON to OUT/table3.json")
    parser.add_argument("--force", action="store_true", help="write into --out even if it already holds results")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        print(f"error: --seeds must be >= 1, got {args.seeds}", file=sys.stderr)
        return 2
    if args.workers < 1:
        print(f"error: --workers must be >= 1, got {args.workers}", file=sys.stderr)
        return 2
    try:
        for name in args.scenarios:
            load_scenario(name)
        if args.out is not None:
            outdir.prepare(args.out, force=args.force)
    except (ConfigError, outdir.OutDirError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    jobs = [(name, seed) for name in args.scenarios for seed in range(1, args.seeds + 1)]
    start = time.perf_counter()
    results: list[dict] = [{}] * len(jobs)
    with (
        Progress("bench table3", len(jobs), "missions", enabled=not args.quiet) as progress,
        ProcessPoolExecutor(max_workers=args.workers) as pool,
    ):
        futures = {pool.submit(one_run, name, seed): k for k, (name, seed) in enumerate(jobs)}
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            progress.advance()
    rows = []
    for name in args.scenarios:
        runs = [r for (n, _), r in zip(jobs, results, strict=True) if n == name]
        rows.append(summarise(name, runs))
    out = {"rows": rows, "seeds": args.seeds, "wall_s": round(time.perf_counter() - start, 1)}
    if args.out is not None:
        (args.out / "table3.json").write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"section 3.3, {args.seeds} seeds each, in-process; tracking error pooled over AUVs, ticks and seeds")
    print(f"{'scenario':<16} {'ours (m)':>16} {'seed spread':>12} {'paper DMPC':>14} {'FQI':>6} {'plan ms':>8}")
    for r in rows:
        ours = f"{r['tracking_error_mean_m']:.1f} +/- {r['tracking_error_std_m']:.1f}"
        paper = f"{r['paper_dmpc_m']:.1f} +/- {r['paper_dmpc_std_m']:.1f}" if r["paper_dmpc_m"] else "-"
        print(
            f"{r['scenario']:<16} {ours:>16} {r['per_seed_mean_spread_m']:>12.1f} {paper:>14} "
            f"{r['fqi'] or float('nan'):>6.2f} {r['plan_time_median_ms'] or float('nan'):>8.1f}"
        )
    print(f"wall time {out['wall_s']} s" + (f"; {args.out / 'table3.json'}" if args.out is not None else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
