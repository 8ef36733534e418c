"""A small Monte-Carlo: seeds x two planner methods, in process, and a table of the tracking error.

    python examples/monte_carlo.py [--scenario paper-3.3-sim2] [--seeds A-B|N] [--duration S]

For grids of hundreds of missions, resumable and on a cluster, use ``auv-swarm sweep`` (docs/sweeps.md).
"""

from __future__ import annotations

import argparse
import statistics

import auv_swarm
from auv_swarm.contract.usage import SEEDS_HELP, parse_seeds, seeds_text

METHODS = ("dmpc", "dec-mpc")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper-3.3-sim2")
    parser.add_argument("--seeds", default="5", help=f"{SEEDS_HELP} (default 5)")
    parser.add_argument("--duration", type=float, default=None, help="sim seconds (default: the scenario's)")
    args = parser.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        parser.error(str(exc))

    base = auv_swarm.load_scenario(args.scenario).with_overrides(duration_s=args.duration)
    errors: dict[str, list[float]] = {m: [] for m in METHODS}
    for method in METHODS:
        for seed in seeds:
            scenario = base.with_keys({"planner.method": method, "run.seed": seed})
            metrics = auv_swarm.run_mission(scenario).metrics
            if metrics["tracking_error_mean_m"] is not None:  # None: no estimate in the whole run
                errors[method].append(metrics["tracking_error_mean_m"])

    print(f"{base.name}, seeds {seeds_text(seeds)}: mean tracking error per mission (m); std over seeds (n - 1)")
    print(f"{'method':<10} {'n':>3} {'mean':>7} {'std':>7} {'min':>7} {'max':>7}")
    for method, values in errors.items():
        if not values:
            print(f"{method:<10} {0:>3}       -")
            continue
        std = statistics.stdev(values) if len(values) > 1 else 0.0
        print(
            f"{method:<10} {len(values):>3} {statistics.mean(values):>7.1f} {std:>7.1f}"
            f" {min(values):>7.1f} {max(values):>7.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
