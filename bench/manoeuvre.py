"""``auv-swarm bench manoeuvre [--seeds A-B|N] [--reference] [--json]``: manoeuvring sources, adaptive vs fixed-window estimator.

Runs every ``manoeuvre-*`` built-in scenario in process over seeds 1..N (default 10), once with each
estimator method (default: ``adaptive-window`` and ``wls-cv``), in parallel over ``--workers``
processes, and prints per scenario and method: the tracking error pooled over every live AUV, tick
and seed (mean and p95, as ``tracking_error_mean_m``), the fraction of samples under 15 m after
convergence, the position NEES (mean, and fraction inside the 95 % chi-square band), and the
estimator's time per call. Targets (issue 18): mean <= 15 m and p95 <= 40 m with the default method.

``--reference`` also replays the first method's missions through a yardstick (bench/reference_filter.py):
Stone Soup's constant-velocity UKF started at the true state, fed each AUV's bearings as its estimator got
them ("delivered") or every AUV's bearings at once ("central"), with the best process noise of a grid.
"""

from __future__ import annotations

import argparse
import bisect
import dataclasses
import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from auv_swarm.contract.usage import seeds_text

TARGET_MEAN_M = 15.0
TARGET_P95_M = 40.0
METHODS = ("adaptive-window", "wls-cv")
REFERENCE_QS = (3e-4, 1e-3, 3e-3, 1e-2)  # m^2/s^3, the process noise grid of --reference
REFERENCE_P0 = np.diag([50.0**2, 50.0**2, 0.5**2, 0.5**2])  # the reference starts at the truth, this uncertain


def reference_errors(
    rec: Any, histories: list[list[tuple[float, list[Any]]]], qs: tuple[float, ...], sigma_m_rad: float
) -> dict[str, dict[str, list[float]]]:
    """The reference UKF's errors (m) on the samples pooled for the mission's own estimates, per ``q``.

    ``delivered``: one filter per AUV estimator, fed the bearings that estimator was given, when it was
    given them (its own at once, the others' as the channel delivered them). ``central``: one filter fed
    every AUV's own bearings at once, lossless: the centralised filter of issue 18.
    """
    from auv_swarm.bench.reference_filter import ReferenceUKF
    from auv_swarm.results.metrics import tracking_errors

    errors = tracking_errors(rec)
    tick_s = float(rec.times[1] - rec.times[0]) if len(rec.times) > 1 else 1.0
    truth = rec.target

    def index(t_s: float) -> int:
        return int(round(t_s / tick_s))

    owned = []  # (auv, calls) per estimator instance; an AUV's own bearing is the one taken at the call's time
    for calls in histories:
        own = {b.source for t_s, bearings in calls for b in bearings if b.t_s == t_s}
        if len(own) == 1 and calls:
            owned.append((own.pop(), calls))
    samples = sorted(
        (index(t_s), auv) for auv, calls in owned for t_s, _ in calls if np.isfinite(errors[auv][index(t_s)])
    )
    own_bearings = sorted(
        {
            (b.t_s, b.source): b for auv, calls in owned for _, bearings in calls for b in bearings if b.source == auv
        }.values(),
        key=lambda b: (b.t_s, b.source),
    )
    out: dict[str, dict[str, list[float]]] = {}
    for q in qs:
        delivered = []
        for auv, calls in owned:
            ukf = ReferenceUKF(truth[index(calls[0][0])], REFERENCE_P0, calls[0][0], q, sigma_m_rad)
            for t_s, bearings in calls:
                ukf.add(bearings)
                if np.isfinite(errors[auv][index(t_s)]):
                    delivered.append(float(np.hypot(*(ukf.estimate(t_s)[0][:2] - truth[index(t_s), :2]))))
        central = []
        if samples:
            ukf = ReferenceUKF(truth[0], REFERENCE_P0, float(rec.times[0]), q, sigma_m_rad)
            taken = [b.t_s for b in own_bearings]
            fed = 0
            for i, _ in samples:
                t_s = float(rec.times[i])
                end = bisect.bisect_right(taken, t_s + 1e-9)
                ukf.add(own_bearings[fed:end])
                fed = max(fed, end)
                central.append(float(np.hypot(*(ukf.estimate(t_s)[0][:2] - truth[i, :2]))))
        out[f"{q:g}"] = {"delivered": delivered, "central": central}
    return out


def one_run(name: str, seed: int, method: str, reference: tuple[float, ...] = ()) -> dict[str, Any]:
    """One in-process mission: its metrics, its pooled error samples and the estimator's time per call;
    with ``reference`` (a grid of q), the reference UKF's errors on the same samples too."""
    from auv_swarm.agent import core
    from auv_swarm.contract.config import load_scenario
    from auv_swarm.orchestrator.mission.api import run_mission
    from auv_swarm.results.metrics import tracking_errors

    scenario = load_scenario(name).with_overrides(seed=seed)
    scenario = scenario.replace(estimator=dataclasses.replace(scenario.estimator, method=method))
    calls: list[float] = []
    histories: list[list[tuple[float, list[Any]]]] = []
    make = core.make_estimator

    def timed_make(cfg: Any, sigma: float, auv: int | None = None) -> Any:
        est = make(cfg, sigma, auv)
        update = est.update
        history: list[tuple[float, list[Any]]] = []
        histories.append(history)

        def timed(bearings: Any, t_s: float) -> Any:
            if reference:
                bearings = list(bearings)
                history.append((t_s, bearings))
            start = time.perf_counter()
            out = update(bearings, t_s)
            calls.append(time.perf_counter() - start)
            return out

        est.update = timed
        return est

    core.make_estimator = timed_make
    try:
        result = run_mission(scenario)
    finally:
        core.make_estimator = make
    rec, metrics = result.record, result.metrics
    errors = np.concatenate(list(tracking_errors(rec).values()))
    out = {
        "metrics": metrics,
        "errors": errors[np.isfinite(errors)].tolist(),
        "estimator_ms": [1e3 * c for c in calls],
    }
    if reference:
        out["reference"] = reference_errors(rec, histories, reference, math.radians(scenario.sensor.sigma_m_deg))
    return out


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
        **({"reference": _pool_reference(runs)} if all("reference" in r for r in runs) else {}),
    }


def _pool_reference(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per feed (delivered, central): the pooled mean and p95 for each q, and the q with the lowest mean."""
    out: dict[str, Any] = {}
    for feed in ("delivered", "central"):
        by_q = {}
        for q in runs[0]["reference"]:
            e = np.concatenate([np.asarray(r["reference"][q][feed], dtype=float) for r in runs])
            if e.size:
                by_q[q] = {"mean_m": float(np.mean(e)), "p95_m": float(np.percentile(e, 95))}
        best = min(by_q, key=lambda q: by_q[q]["mean_m"], default=None)
        out[feed] = {"best_q": best, **(by_q[best] if best else {"mean_m": None, "p95_m": None}), "by_q": by_q}
    return out


def run(
    seeds: list[int], scenarios: list[str], methods: tuple[str, ...], workers: int, reference: tuple[float, ...] = ()
) -> dict[str, Any]:
    """Every (scenario, method, seed) mission, pooled per (scenario, method); the reference UKF, when asked
    for, on the first method's missions."""
    jobs = [(s, seed, m) for s in scenarios for m in methods for seed in seeds]
    refs = [reference if m == methods[0] else () for _, _, m in jobs]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(one_run, *zip(*jobs, strict=True), refs))
    table: dict[str, dict[str, Any]] = {}
    for s in scenarios:
        table[s] = {}
        for m in methods:
            table[s][m] = _pool([r for (js, _, jm), r in zip(jobs, results, strict=True) if js == s and jm == m])
    return {
        "seeds": seeds_text(seeds),
        "methods": list(methods),
        "reference_qs": list(reference),
        "scenarios": table,
        "wall_s": time.perf_counter() - start,
    }


def _fmt(v: Any, spec: str) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def _pct(fraction: float | None, width: int) -> str:
    return f"{'-' if fraction is None else format(100 * fraction, '.0f') + '%':>{width}}"


def _table(result: dict[str, Any]) -> str:
    width = max(20, 2 + max((len(s) for s in result["scenarios"]), default=0))
    lines = [
        f"bench manoeuvre: seeds {result['seeds']}, in process; error pooled over live AUVs, ticks and seeds; "
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
            for feed, label in (("delivered", "UKF, delivered"), ("central", "UKF, central")):
                ref = r.get("reference", {}).get(feed)
                if ref:
                    lines.append(
                        f"{s:<{width}}{label:<17}{_fmt(ref['mean_m'], '8.1f')}{_fmt(ref['p95_m'], '8.1f')}"
                        f"   reference on {m}'s missions, best q = {ref['best_q']} m^2/s^3"
                    )
    lines += [
        "",
        "<15m: fraction of samples under 15 m after convergence (mean over converged runs); conv: runs that "
        "converged; lost: AUV track losses (> 50 m for > 60 s); NEES: position NEES (2 = consistent), in band: "
        "inside [0.05, 7.38]",
        *(
            [
                "UKF: Stone Soup's constant-velocity UKF started at the true state, best process noise q of "
                f"{', '.join(f'{q:g}' for q in result['reference_qs'])} m^2/s^3; delivered: fed each AUV's bearings as "
                "its estimator got them (late ones re-filtered in time order); central: every AUV's bearings at "
                "once, lossless"
            ]
            if result.get("reference_qs")
            else []
        ),
        f"wall {result['wall_s']:.0f} s",
    ]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """``auv-swarm bench manoeuvre [--seeds A-B|N] [--scenarios ...] [--methods ...] [--workers W] [--json]``."""
    from auv_swarm.contract.config import ESTIMATOR_METHODS, ConfigError, builtin_scenarios, load_scenario
    from auv_swarm.contract.usage import SEEDS_HELP, fail, parse_seeds, plain_description

    parser = argparse.ArgumentParser(prog="auv-swarm bench manoeuvre", description=plain_description(__doc__))
    parser.add_argument("--seeds", default="10", help=f"{SEEDS_HELP}, per scenario and method (default 10)")
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
    parser.add_argument(
        "--reference",
        action="store_true",
        help="also replay the first method's missions through a reference UKF started at the truth (what the "
        "bearings each AUV holds allow) and through the same UKF fed every bearing at once",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    args = parser.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        return fail(str(exc))
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
    if not args.methods:
        parser.error("--methods needs at least one method")
    result = run(seeds, args.scenarios, tuple(args.methods), args.workers, REFERENCE_QS if args.reference else ())
    print(json.dumps(result) if args.json else _table(result))
    return 0
