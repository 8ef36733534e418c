"""``auv-swarm bench planner``: speed and exactness of the DMPC planner on seeded random instances.

Instances follow the paper's Sim 3 planner (Table 1): 7 headings x 3 speeds = 21 controls (the default
speed ladder is the paper's {0, u_e, u_max} where a step at u_max is shorter than d*, docs/planner.md),
H = 5, 9 sigma points, dtheta_max = pi/2, T_o = 130 s, u_max = 2 m/s, d* = 500 m,
d_M = 2 km, d_S = 100 m, NL = 50 dB. Geometry: the target 500-1500 m from the planning agent,
neighbours within 2 km of it, a random target covariance. Each n = 3 instance's plan is checked
against the brute-force search with the plain reference cost (``agent.planner.reference``: the
same optimal cost within 1e-9 relative and the same sequence, unless the reference costs of the
two sequences agree within 1e-9); the n = 5 and n = 10 instances are timed and the first
``--check-scaling`` of each are checked. ``--ocean SCENARIO``: the link weights of eqs. (25)-(26) come from that
physical scenario's ocean (its TL table, noise and modem) instead of NL = 50 dB (docs/ocean.md).
Only ``plan()`` is timed: every instance is planned once first (building the cached merge graph
of each control-set shape), then each instance is timed ``--repeat`` times and its fastest run
kept, which filters out interference from other processes on the machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time

import numpy as np

from auv_swarm.agent.planner import Neighbour, PlanProblem, base_speed, brute_force, control_set, plan, speed_set
from auv_swarm.agent.planner.reference import same_optimum
from auv_swarm.contract.config import ChannelConfig, PlannerConfig
from auv_swarm.contract.rng import stream
from auv_swarm.contract.usage import plain_description
from auv_swarm.orchestrator.mission.progress import Progress

U_MAX = 2.0
R_MAX = 0.05
PLANNER = PlannerConfig(
    horizon=5,
    step_s=130.0,
    n_headings=7,
    dtheta_max_rad=math.pi / 2,
    d_star_m=500.0,
    d_max_m=2000.0,
    d_safe_m=100.0,
)
CHANNEL = ChannelConfig(noise_level_db=50.0)


def random_instance(rng: np.random.Generator, n_agents: int) -> PlanProblem:
    """One planning problem for an agent at the origin with ``n_agents - 1`` neighbours."""
    bearing = rng.uniform(-math.pi, math.pi)
    rng_m = rng.uniform(500.0, 1500.0)
    v_dir = rng.uniform(-math.pi, math.pi)
    v = rng.uniform(0.0, 1.0)
    xi = np.array([rng_m * math.cos(bearing), rng_m * math.sin(bearing), v * math.cos(v_dir), v * math.sin(v_dir)])
    stds = np.array([rng.uniform(10.0, 200.0)] * 2 + [rng.uniform(0.05, 1.0)] * 2)
    a = rng.normal(size=(4, 4))
    corr = a @ a.T
    d = np.sqrt(np.diag(corr))
    P = stds[:, None] * (corr / np.outer(d, d)) * stds[None, :]
    u_e = base_speed(rng_m, PLANNER.d_star_m, v, PLANNER.step_s, U_MAX)
    controls = control_set(PLANNER, u_e, U_MAX, R_MAX)
    neighbours = []
    for j in range(1, n_agents):
        r = math.sqrt(rng.uniform(0.15**2, 1.0)) * 2000.0
        b = rng.uniform(-math.pi, math.pi)
        nb_controls = control_set(PLANNER, rng.uniform(0.0, U_MAX), U_MAX, R_MAX).controls
        seq = nb_controls[rng.integers(0, len(nb_controls), PLANNER.horizon)]
        neighbours.append(
            Neighbour(
                id=j, position=(r * math.cos(b), r * math.sin(b)), heading=rng.uniform(-math.pi, math.pi), sequence=seq
            )
        )
    return PlanProblem(
        position=np.zeros(2),
        heading=rng.uniform(-math.pi, math.pi),
        xi=xi,
        P=P,
        neighbours=tuple(neighbours),
        controls=controls,
        planner=PLANNER,
        channel=CHANNEL,
    )


def _time_ms(problem: PlanProblem, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        plan(problem)
        best = min(best, time.perf_counter() - start)
    return best * 1e3


def _group(problems: list[PlanProblem], repeat: int, check: int, progress: Progress) -> dict:
    """Plan, time and check one group of instances; ``progress`` advances once per timed and per checked instance."""
    plans = [plan(p) for p in problems]
    times = []
    for p in problems:
        times.append(_time_ms(p, repeat))
        progress.advance()
    times = np.array(times)
    matches = 0
    for p, got in zip(problems[:check], plans[:check], strict=False):
        matches += same_optimum(p, got, brute_force(p))
        progress.advance()
    return {
        "instances": len(problems),
        "checked": min(check, len(problems)),
        "exact_matches": matches,
        "median_ms": float(np.median(times)),
        "p90_ms": float(np.percentile(times, 90)),
        "max_ms": float(np.max(times)),
        "median_nodes": float(np.median([r.nodes for r in plans])),
        "max_nodes": int(max(r.nodes for r in plans)),
        "feasible": int(sum(r.feasible for r in plans)),
    }


def main(argv: list[str]) -> int:
    """Run the planner benchmark; exit 1 if any checked instance differs from brute force."""
    parser = argparse.ArgumentParser(prog="auv-swarm bench planner", description=plain_description(__doc__))
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--instances", type=int, default=50, help="n = 3 instances (default 50)")
    parser.add_argument("--scaling-instances", type=int, default=10, help="instances for n = 5 and n = 10 (default 10)")
    parser.add_argument(
        "--check-scaling", type=int, default=2, help="n = 5 and n = 10 instances checked against brute force"
    )
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per instance, fastest kept (default 3)")
    parser.add_argument("--seed", type=int, default=1, help="master seed (default 1)")
    parser.add_argument("--no-check", action="store_true", help="skip the brute-force exactness checks")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    parser.add_argument("--ocean", default=None, help="a physical scenario whose ocean weights the links")
    args = parser.parse_args(argv)
    for name in ("instances", "repeat"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be >= 1")
    if args.scaling_instances < 0 or args.check_scaling < 0:
        parser.error("--scaling-instances and --check-scaling must be >= 0")
    start = time.perf_counter()
    sets = {
        n: [random_instance(stream(args.seed, "bench_planner", 1000 * n + i), n) for i in range(count)]
        for n, count in ((3, args.instances), (5, args.scaling_instances), (10, args.scaling_instances))
    }
    if args.ocean is not None:
        from auv_swarm.contract.config import ConfigError, load_scenario
        from auv_swarm.contract.tltable import ocean_for
        from auv_swarm.contract.usage import fail

        try:
            ocean = ocean_for(load_scenario(args.ocean))
        except ConfigError as exc:
            return fail(str(exc))
        if ocean is None:
            return fail(f"--ocean {args.ocean}: not a physical scenario (ocean.model = 'paper')")
        sets = {n: [dataclasses.replace(p, link=ocean.link) for p in group] for n, group in sets.items()}
    checks = {
        n: 0 if args.no_check else min(len(sets[n]), args.instances if n == 3 else args.check_scaling) for n in sets
    }
    steps = sum(len(group) for group in sets.values()) + sum(checks.values())
    with Progress("bench planner", steps, "instances timed or checked", enabled=not args.quiet) as progress:
        main_group = _group(sets[3], args.repeat, checks[3], progress)
        scaling = {str(n): _group(sets[n], args.repeat, checks[n], progress) for n in (5, 10) if sets[n]}
    result = {
        **main_group,
        "scaling": scaling,
        "controls": PLANNER.n_headings * len(speed_set(PLANNER, 0.0, U_MAX)),
        "horizon": PLANNER.horizon,
        "sigma_points": 9,
        "repeat": args.repeat,
        "seed": args.seed,
        "ocean": args.ocean,
        "wall_s": round(time.perf_counter() - start, 1),
    }
    ok = result["exact_matches"] == result["checked"] and all(
        g["exact_matches"] == g["checked"] for g in scaling.values()
    )
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"planner benchmark: {result['controls']} controls, H = {result['horizon']}, 9 sigma points, seed {args.seed}"
        )
        print(
            f"{'n':>3} {'inst':>5} {'checked':>8} {'exact':>6} {'median ms':>10} {'p90 ms':>8} {'max ms':>8} {'nodes':>7}"
        )
        rows = [("3", main_group)] + list(scaling.items())
        for n, g in rows:
            print(
                f"{n:>3} {g['instances']:>5} {g['checked']:>8} {g['exact_matches']:>6} {g['median_ms']:>10.2f} "
                f"{g['p90_ms']:>8.2f} {g['max_ms']:>8.2f} {g['median_nodes']:>7.0f}"
            )
        print(f"wall time {result['wall_s']} s; {'all checked plans exact' if ok else 'MISMATCH with brute force'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
