"""``auv-swarm bench {planner,estimator,swarm,table3,manoeuvre,figure6,sweep,flood,compose,ocean} [options]``: the
benchmarks."""

from __future__ import annotations

import importlib
import sys

BENCHES: dict[str, tuple[str, str]] = {
    "planner": ("auv_swarm.bench.planner", "DMPC planner speed and exactness against brute force (about 3 min)"),
    "estimator": ("auv_swarm.bench.estimator", "estimator accuracy against the Cramer-Rao bound"),
    "swarm": ("auv_swarm.bench.swarm", "one mission as processes and in process: wall times, identical metrics"),
    "table3": ("auv_swarm.bench.table3", "the paper's Table 3 comparison, Monte-Carlo over seeds, in process"),
    "manoeuvre": (
        "auv_swarm.bench.manoeuvre",
        "manoeuvring sources over seeds: adaptive vs fixed-window estimator (--reference: a UKF yardstick)",
    ),
    "figure6": (
        "auv_swarm.bench.figure6",
        "the paper's section 3.1 over seeds: Fig. 6 in one PNG, the formation, optimum and no-AUV-lost figures",
    ),
    "sweep": (
        "auv_swarm.bench.sweep",
        "the sweep engine: 40 missions on one Dask worker and on two (ratio), engine against direct calls (overhead), "
        "what its TLS costs (TLS and plain TCP side by side)",
    ),
    "flood": (
        "auv_swarm.bench.flood",
        "one AUV floods its uplink: frames refused, links in flight, the others' error, channel time per tick",
    ),
    "compose": (
        "auv_swarm.bench.compose",
        "one mission under docker-compose against auv-swarm run: mission time ratio",
    ),
    "ocean": (
        "auv_swarm.bench.ocean",
        "a physical scenario against the same with ocean.model = paper: wall-time ratio, the ocean's share, Bellhop build",
    ),
}


def usage() -> str:
    """The list of benchmarks, one line each."""
    lines = ["usage: auv-swarm bench BENCH [options]   (auv-swarm bench BENCH --help for its options)", "", "benches:"]
    lines += [f"  {name:<10} {doc}" for name, (_, doc) in BENCHES.items()]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """Dispatch to one benchmark module's ``main(argv)``; ``--help`` lists them, a missing or unknown one is a usage error."""
    if argv and argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0
    if not argv or argv[0] not in BENCHES:
        what = f"unknown bench {argv[0]!r}" if argv else "a bench is required"
        print(f"auv-swarm bench: {what}\n\n{usage()}", file=sys.stderr)
        return 2
    return int(importlib.import_module(BENCHES[argv[0]][0]).main(argv[1:]) or 0)
