"""Your own planner in every mode: a greedy one (step by step, the control ending nearest d* from the estimate).

python examples/own_planner.py [--mode processes] [--sweep (dmpc and greedy on 2 workers)] [--duration S]
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

import auv_swarm
from auv_swarm.agent import methods
from auv_swarm.agent.planner import Plan
from auv_swarm.orchestrator.sweep.execute import execute
from auv_swarm.orchestrator.sweep.grid import Axis, Grid


class Greedy:
    def __init__(self, scenario, auv: int) -> None:  # every planner is built with (scenario, auv)
        self.step_s, self.d_star = scenario.planner.step_s, scenario.planner.d_star_m

    def plan(self, problem) -> Plan:
        controls = problem.controls.controls  # (m, 2) rows (heading change rad, speed m/s)
        xy, heading, source = np.asarray(problem.position), problem.heading, problem.xi[:2]
        picks, ends = [], []
        for _ in range(problem.planner.horizon):
            headings = heading + controls[:, 0]
            reach = xy + (controls[:, 1] * self.step_s)[:, None] * np.column_stack([np.cos(headings), np.sin(headings)])
            i = int(np.argmin(np.abs(np.hypot(*(reach - source).T) - self.d_star)))
            picks.append(i), ends.append(reach[i])
            xy, heading = reach[i], headings[i]
        cost = abs(float(np.hypot(*(xy - source))) - self.d_star) / self.d_star
        return Plan(controls[picks], np.array(picks), cost, {"distance": cost}, True, np.array(ends), len(controls))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=("inprocess", "processes"), default="inprocess")
    parser.add_argument("--sweep", action="store_true", help="dmpc and greedy, seeds 1-2, on 2 Dask workers")
    parser.add_argument("--duration", type=float, default=300.0, help="sim seconds (default 300)")
    args = parser.parse_args(argv)
    methods.register("greedy", Greedy)  # by reference (this file, Greedy): in process, AUV processes, sweep workers
    base = auv_swarm.load_scenario("paper-3.2-challenging").with_keys({"run.duration_s": args.duration})
    if args.sweep:
        grid = Grid([base.name], [Axis("planner.method", ("dmpc", "greedy"))], [1, 2], args.duration)
        with tempfile.TemporaryDirectory() as tmp:
            done = execute(grid, tmp, workers=2, quiet=True)
        for r in sorted(done.rows, key=lambda r: (r["planner.method"], r["seed"])):
            print(f"{r['planner.method']} seed {r['seed']}: {r['status']}, {r['tracking_error_mean_m']:.1f} m")
        return done.code
    m = auv_swarm.run_mission(base.with_keys({"planner.method": "greedy"}), mode=args.mode).metrics
    print(f"greedy, {args.mode}: mean tracking error {m['tracking_error_mean_m']:.1f} m, complete: {m['complete']}")
    return m["exit_code"]


if __name__ == "__main__":
    raise SystemExit(main())
