"""``auv-swarm bench {planner,estimator,swarm,table3,compose} [--json]``: the shipped benchmarks."""

from __future__ import annotations

import importlib
import sys

BENCHES = {
    "planner": "bench.planner",
    "estimator": "bench.estimator",
    "swarm": "bench.swarm",
    "table3": "bench.table3",
    "compose": "bench.compose",
}


def main(argv: list[str]) -> int:
    """Dispatch to one benchmark module's ``main(argv)``."""
    if not argv or argv[0] not in BENCHES:
        print(f"usage: auv-swarm bench {{{','.join(BENCHES)}}} [--json] [options]", file=sys.stderr)
        return 2
    return int(importlib.import_module(BENCHES[argv[0]]).main(argv[1:]) or 0)
