"""Behaviour check for refactors: every built-in scenario x seeds, in process, compared with a saved baseline.

    python tools/refcheck.py record BASELINE.json [--seeds A-B|N]      (default 1-3)
    python tools/refcheck.py check BASELINE.json [--seeds A-B|N] [--rel 1e-9]

``record`` runs every built-in scenario for each seed and saves the comparable metrics
(wall and plan times and the mode removed) plus a hash of every plan the AUVs sent.
``check`` runs them again and reports, per mission, IDENTICAL (bitwise), CLOSE (every float
within ``--rel`` relative, the same plans) or DIFFERENT; it exits 1 on any DIFFERENT.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
from concurrent.futures import ProcessPoolExecutor

from auv_swarm.contract.usage import SEEDS_HELP, fail, parse_seeds


class PlanHash:
    """Hashes the plans of every telemetry message, in arrival order."""

    def __init__(self) -> None:
        self.h = hashlib.sha256()

    def on_message(self, msg: object) -> None:
        if type(msg).__name__ == "Telemetry":
            plan = getattr(msg, "plan", None)
            self.h.update(repr((getattr(msg, "auv", None), getattr(msg, "tick", None), plan)).encode())


def one(name: str, seed: int) -> tuple[str, int, dict, str]:
    """Comparable metrics and the plan hash of one in-process mission (:func:`auv_swarm.run_mission`)."""
    from auv_swarm import load_scenario, run_mission
    from auv_swarm.results.metrics import comparable

    plans = PlanHash()
    result = run_mission(load_scenario(name).with_overrides(seed=seed), sinks=[plans])
    return name, seed, comparable(result.metrics), plans.h.hexdigest()


def _close(a: object, b: object, rel: float) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) and math.isnan(b):
            return True
        return a == b or abs(a - b) <= rel * max(abs(a), abs(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k], rel) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y, rel) for x, y in zip(a, b, strict=True))
    return a == b


def _only_keys_of(base: object, now: object) -> object:
    """``now`` without the dict keys ``base`` lacks (metrics added since the baseline are not compared)."""
    if isinstance(base, dict) and isinstance(now, dict):
        return {k: _only_keys_of(base[k], v) if k in base else v for k, v in now.items() if k in base}
    return now


def run_all(seeds: list[int]) -> dict[str, dict]:
    from auv_swarm.contract.config import builtin_scenarios

    jobs = [(n, s) for n in sorted(builtin_scenarios()) for s in seeds]
    with ProcessPoolExecutor() as pool:
        results = list(pool.map(one, *zip(*jobs, strict=True)))
    return {f"{n}@{s}": {"metrics": m, "plans": p} for n, s, m, p in results}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=("record", "check"))
    parser.add_argument("baseline")
    parser.add_argument("--seeds", default="1-3", help=f"{SEEDS_HELP} (default 1-3)")
    parser.add_argument("--rel", type=float, default=1e-9)
    args = parser.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        return fail(str(exc))
    now = run_all(seeds)
    if args.action == "record":
        with open(args.baseline, "w", encoding="utf-8") as f:
            json.dump(now, f, indent=1, sort_keys=True)
        print(f"recorded {len(now)} missions to {args.baseline}")
        return 0
    with open(args.baseline, encoding="utf-8") as f:
        base = json.load(f)
    now = json.loads(json.dumps(now))  # the same JSON types as the baseline
    bad = 0
    for key in sorted(base):
        if key not in now:
            print(f"{key}: MISSING")
            bad += 1
            continue
        b, n = (
            base[key],
            {"metrics": _only_keys_of(base[key]["metrics"], now[key]["metrics"]), "plans": now[key]["plans"]},
        )
        if b == n:
            verdict = "IDENTICAL"
        elif b["plans"] == n["plans"] and _close(b["metrics"], n["metrics"], args.rel):
            verdict = "CLOSE"
        else:
            verdict = "DIFFERENT"
            bad += 1
        print(f"{key}: {verdict}")
    print(f"{len(base) - bad} of {len(base)} missions match")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
