"""``auv-swarm bench manoeuvre [--seeds N] [--json]``: manoeuvring sources, adaptive vs fixed-window estimator.

Runs every ``manoeuvre-*`` built-in scenario in process over seeds 1..N (default 10), once with each
estimator method (default: ``adaptive-window`` and ``wls-cv``), in parallel over ``--workers``
processes, and prints per scenario and method: the tracking error pooled over every live AUV, tick
and seed (mean and p95, as ``tracking_error_mean_m``), the fraction of samples under 15 m after
convergence, the position NEES (mean, and fraction inside the 95 % chi-square band), and the
estimator's time per call. Targets (issue 18): mean <= 15 m and p95 <= 40 m with the default method.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

TARGET_MEAN_M = 15.0
TARGET_P95_M = 40.0
METHODS = ("adaptive-window", "wls-cv")


def one_run(name: str, seed: int, method: str) -> dict[str, Any]:
    """One in-process mission: its metrics, its pooled error samples and the estimator's time per call."""
    from agent import core
    from contract.config import load_scenario
    from orchestrator.collect import MessageLog
    from orchestrator.inprocess import run_inprocess
    from orchestrator.results import compute_metrics, tracking_errors

    scenario = load_scenario(name).with_overrides(seed=seed)
    scenario = scenario.replace(estimator=dataclasses.replace(scenario.estimator, method=method))
    calls: list[float] = []
    make = core.make_estimator

    def timed_make(cfg: Any, sigma: float) -> Any:
        est = make(cfg, sigma)
        update = est.update

        def timed(bearings: Any, t_s: float) -> Any:
            start = time.perf_counter()
            out = update(bearings, t_s)
            calls.append(time.perf_counter() - start)
            return out

        est.update = timed
        return est

    core.make_estimator = timed_make
    try:
        log = MessageLog()
        start = time.perf_counter()
        run_inprocess(scenario, [log])
        rec = log.to_record(scenario, "inprocess", time.perf_counter() - start)
    finally:
        core.make_estimator = make
    metrics = compute_metrics(rec)
    errors = np.concatenate(list(tracking_errors(rec).values()))
    return {
        "metrics": metrics,
        "errors": errors[np.isfinite(errors)].tolist(),
        "estimator_ms": [1e3 * c for c in calls],
    }


def _pool(runs: list[dict[str, Any]]) -> dict[str, Any]:
    errors = np.concatenate([np.asarray(r["errors"]) for r in runs])
    ms = np.concatenate([np.asarray(r["estimator_ms"]) for r in runs])
    m = [r["metrics"] for r in runs]

    def mean_of(key: str) -> float | None:
        vals = [x[key] for x in m if x.get(key) is not None]
        return float(np.mean(vals)) if vals else None

    nees_w = [(x["nees_mean"], x["nees_in_band_fraction"], x["nees_samples"]) for x in m if x.get("nees_samples")]
    total = sum(w for _, _, w in nees_w)
    return {
        "runs": len(runs),
        "tracking_error_mean_m": float(np.mean(errors)) if errors.size else None,
        "tracking_error_p95_m": float(np.percentile(errors, 95)) if errors.size else None,
        "per_seed_means_m": [x["tracking_error_mean_m"] for x in m],
        "under_15m_after_convergence_fraction": mean_of("under_15m_after_convergence_fraction"),
        "converged_runs": sum(1 for x in m if x.get("convergence_time_s") is not None),
        "longest_excursion_s": max((x["longest_excursion_s"] for x in m if x.get("longest_excursion_s")), default=None),
        "track_lost": sum(a.get("track_lost") or 0 for x in m for a in x["agents"].values()),
        "nees_mean": sum(n * w for n, _, w in nees_w) / total if total else None,
        "nees_in_band_fraction": sum(f * w for _, f, w in nees_w) / total if total else None,
        "estimator_ms_median": float(np.median(ms)) if ms.size else None,
    }


def run(seeds: int, scenarios: list[str], methods: tuple[str, ...], workers: int) -> dict[str, Any]:
    """Every (scenario, method, seed) mission, pooled per (scenario, method)."""
    jobs = [(s, seed, m) for s in scenarios for m in methods for seed in range(1, seeds + 1)]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(one_run, *zip(*jobs, strict=True)))
    table: dict[str, dict[str, Any]] = {}
    for s in scenarios:
        table[s] = {}
        for m in methods:
            table[s][m] = _pool([r for (js, _, jm), r in zip(jobs, results, strict=True) if js == s and jm == m])
    return {"seeds": seeds, "methods": list(methods), "scenarios": table, "wall_s": time.perf_counter() - start}


def _fmt(v: Any, spec: str) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def _pct(fraction: float | None, width: int) -> str:
    return f"{'-' if fraction is None else format(100 * fraction, '.0f') + '%':>{width}}"


def _table(result: dict[str, Any]) -> str:
    width = max(20, 2 + max((len(s) for s in result["scenarios"]), default=0))
    lines = [
        f"bench manoeuvre: seeds 1..{result['seeds']}, in process; error pooled over live AUVs, ticks and seeds; "
        f"targets mean <= {TARGET_MEAN_M:g} m, p95 <= {TARGET_P95_M:g} m",
        "",
        f"{'scenario':<{width}}{'estimator':<17}{'mean m':>8}{'p95 m':>8}{'<15m':>7}{'conv':>6}{'lost':>6}"
        f"{'NEES':>8}{'in band':>9}{'ms/call':>9}",
    ]
    for s, by_method in result["scenarios"].items():
        for m, r in by_method.items():
            under = r["under_15m_after_convergence_fraction"]
            band = r["nees_in_band_fraction"]
            lines.append(
                f"{s:<{width}}{m:<17}{_fmt(r['tracking_error_mean_m'], '8.1f')}{_fmt(r['tracking_error_p95_m'], '8.1f')}"
                f"{_pct(under, 7)}"
                f"{r['converged_runs']:>3}/{r['runs']:<2}{r['track_lost']:>6}"
                f"{_fmt(r['nees_mean'], '8.1f'):>8}{_pct(band, 9)}"
                f"{_fmt(r['estimator_ms_median'], '9.3f')}"
            )
    lines += [
        "",
        "<15m: fraction of samples under 15 m after convergence (mean over converged runs); conv: runs that "
        "converged; lost: AUV track losses (> 50 m for > 60 s); NEES: position NEES (2 = consistent), in band: "
        "inside [0.05, 7.38]",
        f"wall {result['wall_s']:.0f} s",
    ]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """``auv-swarm bench manoeuvre [--seeds N] [--scenarios ...] [--methods ...] [--workers W] [--json]``."""
    from contract.config import ESTIMATOR_METHODS, ConfigError, builtin_scenarios, load_scenario
    from contract.shell import plain_description
    from contract.usage import fail

    parser = argparse.ArgumentParser(prog="auv-swarm bench manoeuvre", description=plain_description(__doc__))
    parser.add_argument("--seeds", type=int, default=10, help="seeds 1..N per scenario and method (default 10)")
    parser.add_argument(
        "--scenarios",
        nargs="*",
        default=[s for s in builtin_scenarios() if s.startswith("manoeuvre")],
        help="scenario names or TOML paths (default: the built-in manoeuvre scenarios)",
    )
    parser.add_argument("--methods", nargs="*", default=list(METHODS), help="estimator methods to compare")
    parser.add_argument(
        "--workers", type=int, default=min(2, os.cpu_count() or 1), help="missions run in parallel (default: up to 2)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    if args.workers < 1:
        parser.error(f"--workers must be >= 1, got {args.workers}")
    unknown = [m for m in args.methods if m not in ESTIMATOR_METHODS]
    if unknown:
        parser.error(f"--methods must be among {', '.join(ESTIMATOR_METHODS)}, got {', '.join(unknown)}")
    for s in args.scenarios:
        try:
            load_scenario(s)
        except ConfigError as exc:
            return fail(f"--scenarios: {exc}")
    result = run(args.seeds, args.scenarios, tuple(args.methods), args.workers)
    print(json.dumps(result) if args.json else _table(result))
    return 0
