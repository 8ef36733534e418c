"""``auv-swarm bench table3 [--methods M,...] [--seeds A-B|N] [--out DIR] [--json]``: the paper's Table 3, Monte-Carlo.

Runs the five ``paper-3.3-sim*`` scenarios with every method (``planner.method``: dmpc,
dec-mpc, dpso, centralised) in process over seeds 1..N (default 10), in parallel over the
cores, and reports per scenario and method: the tracking error pooled over every live AUV,
tick and seed (mean +/- std, as the paper's Table 3), the mean of the per-seed means and
their spread (population std), the optimisation time per plan (wall, median and 95th
percentile; a centralised plan is the whole team's joint plan), the FQI (our definition,
docs/results.md), and the paper's row beside it. ``--out`` writes table3.md, table3.json
and table3.png (grouped bars with the pooled std as error bars, the paper's means as markers).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

from auv_swarm.contract.config import PLANNER_METHODS, ConfigError, load_scenario
from auv_swarm.contract.usage import SEEDS_HELP, fail, parse_seeds, plain_description, seeds_text

SCENARIOS = ("paper-3.3-sim1", "paper-3.3-sim2", "paper-3.3-sim3", "paper-3.3-sim4", "paper-3.3-sim5")

PAPER = {
    # (scenario, method): (error mean m, error std m, optimisation time s or None, FQI of the paper or None)
    ("paper-3.3-sim1", "centralised"): (7.8, 5.9, None, None),
    ("paper-3.3-sim1", "dec-mpc"): (11.6, 9.3, 16.0, 10.5),
    ("paper-3.3-sim1", "dpso"): (10.5, 7.2, 7.2, 10.2),
    ("paper-3.3-sim1", "dmpc"): (10.4, 8.0, 8.4, 8.5),
    ("paper-3.3-sim2", "centralised"): (13.2, 10.6, None, None),
    ("paper-3.3-sim2", "dec-mpc"): (25.0, 22.1, 27.7, 13.3),
    ("paper-3.3-sim2", "dpso"): (33.7, 24.3, 10.7, 16.7),
    ("paper-3.3-sim2", "dmpc"): (13.4, 12.6, 13.2, 11.4),
    ("paper-3.3-sim3", "centralised"): (13.2, 10.6, None, None),
    ("paper-3.3-sim3", "dec-mpc"): (28.3, 31.2, 30.3, 8.9),
    ("paper-3.3-sim3", "dpso"): (41.9, 39.3, 11.6, 20.6),
    ("paper-3.3-sim3", "dmpc"): (14.4, 14.2, 6.68, 8.4),
    ("paper-3.3-sim4", "centralised"): (15.0, 13.5, None, None),
    ("paper-3.3-sim4", "dec-mpc"): (24.1, 22.6, 31.4, 12.6),
    ("paper-3.3-sim4", "dpso"): (59.2, 53.0, 13.9, 19.3),
    ("paper-3.3-sim4", "dmpc"): (22.9, 21.5, 9.7, 9.5),
    ("paper-3.3-sim5", "centralised"): (10.5, 5.0, None, None),
    ("paper-3.3-sim5", "dec-mpc"): (20.5, 17.7, 24.7, 27.3),
    ("paper-3.3-sim5", "dpso"): (37.9, 32.3, 13.7, 43.0),
    ("paper-3.3-sim5", "dmpc"): (14.7, 14.9, 8.5, 25.5),
}
"""The paper's Table 3 (section 3.3), method names ours."""


def one_run(name: str, method: str, seed: int) -> dict:
    """Metrics of one in-process mission, with every plan's wall time (ms; one per planning instant)."""
    from auv_swarm.contract.config import load_scenario
    from auv_swarm.orchestrator.mission.api import run_mission

    scenario = load_scenario(name).with_overrides(seed=seed).with_keys({"planner.method": method})
    cpu0 = time.process_time()
    result = run_mission(scenario)
    cpu_s = time.process_time() - cpu0
    record, metrics = result.record, dict(result.metrics)
    instants: dict[float, float] = {}
    for series in record.agents.values():
        for t_s, wall in zip(series.plan_times_s, series.plan_wall_ms, strict=True):
            instants.setdefault(t_s, wall)
    metrics["plan_walls_ms"] = [instants[t] for t in sorted(instants)]
    metrics["method"] = method
    metrics["cpu_s"] = cpu_s
    return metrics


def pooled(runs: list[dict]) -> tuple[float, float]:
    """Mean and std of the tracking error over all samples of all runs."""
    n = [r["tracking_error_samples"] for r in runs]
    m = [r["tracking_error_mean_m"] for r in runs]
    s = [r["tracking_error_std_m"] for r in runs]
    total = sum(n)
    mean = sum(ni * mi for ni, mi in zip(n, m, strict=True)) / total
    var = sum(ni * (si**2 + (mi - mean) ** 2) for ni, mi, si in zip(n, m, s, strict=True)) / total
    return mean, math.sqrt(var)


def percentile(values: list[float], q: float) -> float | None:
    """The q-th percentile (0..100) by linear interpolation between order statistics; None if empty."""
    if not values:
        return None
    v = sorted(values)
    pos = (len(v) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (pos - lo)


def summarise(name: str, method: str, runs: list[dict]) -> dict:
    """One Table 3 row from the runs of one scenario and method."""
    mean, std = pooled(runs)
    per_seed = [r["tracking_error_mean_m"] for r in runs]
    mu = sum(per_seed) / len(per_seed)
    spread = math.sqrt(sum((x - mu) ** 2 for x in per_seed) / len(per_seed))
    fqi = [r["fqi"] for r in runs if r["fqi"] is not None]
    walls = [w for r in runs for w in r["plan_walls_ms"]]
    paper = PAPER.get((name, method))
    med, p95 = percentile(walls, 50.0), percentile(walls, 95.0)
    return {
        "scenario": name,
        "method": method,
        "seeds": len(runs),
        "error_mean_m": round(mean, 2),
        "error_std_m": round(std, 2),
        "seed_means_mean_m": round(mu, 2),
        "seed_means_spread_m": round(spread, 2),
        "seed_means_m": [round(x, 2) for x in per_seed],
        "opt_time_median_ms": None if med is None else round(med, 1),
        "opt_time_p95_ms": None if p95 is None else round(p95, 1),
        "plans": len(walls),
        "fqi": round(sum(fqi) / len(fqi), 3) if fqi else None,
        "no_estimate_fraction": round(sum(r["no_estimate_fraction"] or 0 for r in runs) / len(runs), 3),
        "mission_cpu_s": round(sum(r["cpu_s"] for r in runs) / len(runs), 2),
        "paper_error_mean_m": paper[0] if paper else None,
        "paper_error_std_m": paper[1] if paper else None,
        "paper_opt_time_s": paper[2] if paper else None,
        "paper_fqi": paper[3] if paper else None,
    }


def targets(rows: list[dict]) -> dict:
    """The issue's targets: DMPC below dec-MPC and DPSO per scenario; DMPC/centralised ratio against the paper's."""
    by = {(r["scenario"], r["method"]): r for r in rows}
    scen = sorted({r["scenario"] for r in rows})
    out: dict = {"dmpc_below_baselines": {}, "dmpc_over_centralised": {}}
    for s in scen:
        d = by.get((s, "dmpc"))
        if d is None:
            continue
        others = [by[(s, m)]["error_mean_m"] for m in ("dec-mpc", "dpso") if (s, m) in by]
        if others:
            out["dmpc_below_baselines"][s] = all(d["error_mean_m"] < o for o in others)
        c = by.get((s, "centralised"))
        if c is not None and c["error_mean_m"] > 0:
            paper = PAPER[(s, "dmpc")][0] / PAPER[(s, "centralised")][0]
            ours = d["error_mean_m"] / c["error_mean_m"]
            out["dmpc_over_centralised"][s] = {
                "ours": round(ours, 2),
                "paper": round(paper, 2),
                "at_or_below": ours <= paper,
            }
    return out


def markdown(out: dict) -> str:
    """table3.md: our rows beside the paper's, row for row."""
    lines = [
        f"# Table 3, measured: {out['seeds']} seeds per scenario and method, in process, 1500 s missions",
        "",
        "Tracking error pooled over every live AUV, tick and seed (mean ± std); seed means: mean ± spread "
        "(population std) of the per-seed means; optimisation time per plan, wall (a centralised plan is the "
        "team's joint plan); FQI ours (1 = optimal geometry, docs/results.md), the paper's is defined otherwise.",
        "",
        "| scenario | method | error (m) | seed means (m) | opt. time median / p95 (ms) | FQI | paper error (m) "
        "| paper opt. time (s) | paper FQI |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in out["rows"]:
        paper_err = f"{r['paper_error_mean_m']} ± {r['paper_error_std_m']}" if r["paper_error_mean_m"] else "-"
        lines.append(
            f"| {r['scenario']} | {r['method']} | {r['error_mean_m']:.1f} ± {r['error_std_m']:.1f} "
            f"| {r['seed_means_mean_m']:.1f} ± {r['seed_means_spread_m']:.1f} "
            f"| {_num(r['opt_time_median_ms'])} / {_num(r['opt_time_p95_ms'])} | {_num(r['fqi'], '.2f')} "
            f"| {paper_err} | {_num(r['paper_opt_time_s'], 'g')} | {_num(r['paper_fqi'], 'g')} |"
        )
    t = out.get("targets", {})
    if t.get("dmpc_below_baselines"):
        hits = sum(t["dmpc_below_baselines"].values())
        lines += ["", f"DMPC mean below dec-MPC's and DPSO's: {hits} of {len(t['dmpc_below_baselines'])} scenarios."]
    if t.get("dmpc_over_centralised"):
        ratios = t["dmpc_over_centralised"]
        hits = sum(v["at_or_below"] for v in ratios.values())
        text = ", ".join(f"{s[-4:]} {v['ours']} (paper {v['paper']})" for s, v in ratios.items())
        lines.append(f"DMPC / centralised error ratio at or below the paper's: {hits} of {len(ratios)} ({text}).")
    lines += [
        "",
        f"Wall time of the sweep: {out['wall_s']} s on {out['workers']} workers; the missions' CPU time "
        f"{out['cpu_s']} s (the sweep's wall on idle cores is about CPU / workers).",
    ]
    return "\n".join(lines) + "\n"


def _num(v: float | None, spec: str = ".1f") -> str:
    return "-" if v is None else format(v, spec)


def figure(out: dict, path: Path) -> None:
    """Grouped bars (mean ± pooled std) per scenario and method, the paper's means as markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = out["rows"]
    scen = list(dict.fromkeys(r["scenario"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    by = {(r["scenario"], r["method"]): r for r in rows}
    width = 0.8 / max(1, len(methods))
    fig, ax = plt.subplots(figsize=(10, 4.5), constrained_layout=True)
    for k, m in enumerate(methods):
        xs = [i + (k - (len(methods) - 1) / 2) * width for i in range(len(scen))]
        ys = [by[(s, m)]["error_mean_m"] if (s, m) in by else math.nan for s in scen]
        es = [by[(s, m)]["error_std_m"] if (s, m) in by else 0.0 for s in scen]
        bars = ax.bar(xs, ys, width, yerr=es, capsize=2, label=f"{m} (ours)")
        paper = [PAPER.get((s, m), (math.nan,))[0] for s in scen]
        ax.plot(xs, paper, "D", color=bars.patches[0].get_facecolor(), markeredgecolor="black", markersize=6)
    ax.plot([], [], "D", color="white", markeredgecolor="black", label="paper's mean (marker)")
    ax.set_xticks(range(len(scen)), [s.replace("paper-3.3-", "") for s in scen])
    ax.set_ylabel("tracking error (m)")
    ax.set_title(f"Table 3: tracking error per scenario and method ({out['seeds']} seeds, bars: pooled mean ± std)")
    ax.legend(ncols=3, fontsize=8)
    ax.set_ylim(bottom=0)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def rows_from_store(store_rows: list[dict], scenarios: list[str], methods: list[str]) -> list[dict]:
    """Table 3's rows from the sweep store's rows (one per scenario, method and seed)."""
    by: dict[tuple[str, str], list[dict]] = {}
    for r in store_rows:
        run = dict(r, plan_walls_ms=json.loads(r["plan_walls_ms"] or "[]"))
        by.setdefault((r["scenario"], r["planner.method"]), []).append(run)
    out = []
    for s in scenarios:
        for m in methods:
            runs = sorted(by.get((s, m), []), key=lambda r: r["seed"])
            out.append(summarise(s, m, runs))
    return out


def main(argv: list[str]) -> int:
    """Run the grid as a sweep (the engine and store of ``auv-swarm sweep``), print the table, write the files."""
    from auv_swarm.orchestrator.sweep import cluster
    from auv_swarm.orchestrator.sweep import grid as gridmod
    from auv_swarm.orchestrator.sweep.execute import execute
    from auv_swarm.orchestrator.sweep.store import STORE_FILE

    parser = argparse.ArgumentParser(prog="auv-swarm bench table3", description=plain_description(__doc__))
    parser.add_argument(
        "--methods", default=",".join(PLANNER_METHODS), help="comma-separated planner.method names (default: all)"
    )
    parser.add_argument("--seeds", default="10", help=f"{SEEDS_HELP}, per scenario and method (default 10)")
    parser.add_argument(
        "--scenarios", nargs="*", default=list(SCENARIOS), help="scenario names or TOML paths (default: Sim 1-5)"
    )
    parser.add_argument(
        "--workers", type=int, default=None, help="LocalCluster worker processes (default: the CPU count)"
    )
    cluster.add_scheduler_args(parser)
    parser.add_argument(
        "--out", type=Path, default=None, help="the sweep folder (default sweeps/multi-<hash>/): store and table3.*"
    )
    parser.add_argument("--force", action="store_true", help="move a store of another grid or version aside")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in PLANNER_METHODS]
    if bad or not methods:
        return fail(f"--methods must name some of {', '.join(PLANNER_METHODS)}, got {args.methods!r}")
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        return fail(str(exc))
    if args.workers is not None and args.workers < 1:
        return fail(f"--workers must be >= 1, got {args.workers}")
    try:
        scheduler = cluster.scheduler_from_args(args)
    except cluster.ClusterError as exc:
        return fail(str(exc))
    try:
        for name in args.scenarios:
            load_scenario(name)
    except ConfigError as exc:
        return fail(str(exc))
    grid = gridmod.Grid(
        [],
        [gridmod.Axis(gridmod.SCENARIO_AXIS, tuple(args.scenarios)), gridmod.Axis("planner.method", tuple(methods))],
        seeds,
    )
    folder = args.out if args.out is not None else grid.default_folder()
    own = ("table3.json",) if args.force or (folder / STORE_FILE).exists() else ()
    start = time.perf_counter()
    result = execute(
        grid,
        folder,
        workers=args.workers,
        scheduler=scheduler,
        force=args.force,
        quiet=args.quiet,
        label="bench table3",
        own=own,
    )
    if result.code != 0:
        return result.code
    rows = rows_from_store(result.rows, args.scenarios, methods)
    out = {
        "rows": rows,
        "seeds": len(seeds),
        "seed_range": seeds_text(seeds),
        "methods": methods,
        "workers": args.workers or (os.cpu_count() or 1) if args.scheduler is None else args.scheduler,
        "wall_s": round(time.perf_counter() - start, 1),
        "cpu_s": round(sum(r["cpu_s"] or 0.0 for r in result.rows), 1),
        "sweep": str(folder),
    }
    out["targets"] = targets(rows)
    (folder / "table3.json").write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    (folder / "table3.md").write_text(markdown(out), encoding="utf-8")
    figure(out, folder / "table3.png")
    if args.json:
        print(json.dumps(out))
    else:
        print(markdown(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
