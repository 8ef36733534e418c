"""``auv-swarm bench swarm [--json]``: whole-mission wall time, processes vs in-process.

Runs the same scenario and seed once with every component as its own OS process
over zenoh and once in one process, checks that both give identical metrics
(wall-clock figures aside), and reports the wall times and their ratio. Each
in-process mission runs in a fresh interpreter, so it pays for everything it
builds (the planner's merge graph among others), like a processes-mode mission.
The in-process wall is timed from the start of the mission, after the child's
imports (paid once per batch of in-process missions); the child's whole life,
interpreter start and imports included, is reported beside it.
Targets (issue 4): a 1500 s section 3.2 mission in processes mode in at most
60 s on a 2-core machine; in-process at least 5 times faster.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from auv_swarm.contract.config import ConfigError, dump_toml, load_scenario
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission.api import Launch, run_mission
from auv_swarm.orchestrator.mission.procs import python_argv
from auv_swarm.orchestrator.mission.progress import Progress
from auv_swarm.results.metrics import comparable


def run_mode(
    scenario,
    mode: str,
    recorder: bool = True,
    progress: Callable[[float, float], None] | None = None,
) -> tuple[dict, float]:
    """One mission in ``mode`` (processes mode with the recorder process unless ``recorder`` is False, as
    ``auv-swarm run`` does); returns (metrics, mission wall seconds). ``progress(t_s, duration_s)`` follows the
    sim time. Raises RuntimeError if the mission did not complete."""
    result = run_mission(scenario, mode=mode, progress=progress, launch=Launch(recorder=recorder))
    if not result.outcome.complete:
        raise RuntimeError(f"{mode} run incomplete ({result.outcome.reason}): {result.outcome.line}")
    return result.metrics, result.wall_s


def _inprocess_cold(scenario_toml: str) -> tuple[dict, float, float]:
    """One in-process mission in a fresh interpreter (nothing built or cached beforehand).

    Returns (metrics, mission wall s, the child's whole wall s including interpreter start and imports).
    """
    with tempfile.TemporaryDirectory(prefix="auv-bench-child-") as tmp:
        path = Path(tmp) / "scenario.toml"
        path.write_text(scenario_toml, encoding="utf-8")
        start = time.perf_counter()
        done = subprocess.run(
            python_argv("auv_swarm.bench.swarm", "--child", str(path)),
            capture_output=True,
            text=True,
            check=False,
        )
        whole = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"in-process bench child failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    return result["metrics"], result["wall_s"], whole


def _child(path: Path) -> int:
    """``--child PATH``: run one in-process mission of the scenario file and print its metrics and wall time."""
    scenario = load_scenario(str(path))
    metrics, wall = run_mode(scenario, "inprocess")
    print(json.dumps({"metrics": metrics, "wall_s": wall}))
    return 0


def main(argv: list[str]) -> int:
    """Print the processes and in-process wall times (medians over ``--repeat``), their ratio, and whether metrics agree."""
    parser = argparse.ArgumentParser(prog="auv-swarm bench swarm", description=plain_description(__doc__))
    parser.add_argument("--scenario", default="paper-3.2-challenging", help="built-in scenario name or TOML path")
    parser.add_argument("--seed", type=int, default=None, help="override run.seed")
    parser.add_argument("--duration", type=float, default=None, help="override run.duration_s (sim seconds)")
    parser.add_argument("--agents", type=int, default=None, help="override agents.count (1..16)")
    parser.add_argument("--no-recorder", action="store_true", help="processes mode without the recorder process")
    parser.add_argument("--repeat", type=int, default=1, help="missions per mode; walls are reported as medians")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        return _child(args.child)
    if args.repeat < 1:
        parser.error(f"--repeat must be >= 1, got {args.repeat}")
    try:
        base = load_scenario(args.scenario)
        kills = tuple(k for k in base.kills if args.agents is None or k.agent < args.agents)
        scenario = base.replace(kills=kills).with_overrides(
            seed=args.seed, duration_s=args.duration, agents=args.agents
        )
    except ConfigError as exc:
        return fail(str(exc))
    try:
        result = _measure(scenario, args.repeat, not args.no_recorder)
    except RuntimeError as exc:
        return fail(str(exc), 1)
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:<32} {value}")
    return 0


def _measure(scenario, repeat: int, recorder: bool) -> dict:
    """``repeat`` missions in each mode; the walls (medians) and whether every mission's metrics agree."""
    walls: dict[str, list[float]] = {"processes": [], "inprocess": [], "inprocess_whole": []}
    results: list[dict] = []
    progress = Progress("bench swarm", 2 * repeat, "missions (processes, then in process)")
    with progress:
        for k in range(repeat):

            def mission_progress(t_s: float, total_s: float, k: int = k) -> None:
                progress.update(2 * k + min(1.0, t_s / total_s if total_s > 0 else 1.0))

            m_proc, wall_proc = run_mode(scenario, "processes", recorder=recorder, progress=mission_progress)
            progress.update(2 * k + 1)
            m_inproc, wall_inproc, wall_whole = _inprocess_cold(dump_toml(scenario))
            progress.update(2 * k + 2)
            walls["processes"].append(wall_proc)
            walls["inprocess"].append(wall_inproc)
            walls["inprocess_whole"].append(wall_whole)
            results += [comparable(m_proc), comparable(m_inproc)]
    wall_proc, wall_inproc = statistics.median(walls["processes"]), statistics.median(walls["inprocess"])
    wall_whole = statistics.median(walls["inprocess_whole"])
    return {
        "scenario": scenario.name,
        "seed": scenario.run.seed,
        "sim_duration_s": scenario.run.duration_s,
        "n_agents": scenario.agents.count,
        "recorder": recorder,
        "repeat": repeat,
        "processes_wall_s": round(wall_proc, 3),
        "inprocess_wall_s": round(wall_inproc, 3),
        "processes_walls_s": [round(w, 3) for w in walls["processes"]],
        "inprocess_walls_s": [round(w, 3) for w in walls["inprocess"]],
        "speedup_inprocess": round(wall_proc / wall_inproc, 2) if wall_inproc > 0 else None,
        "inprocess_with_startup_wall_s": round(wall_whole, 3),
        "speedup_inprocess_with_startup": round(wall_proc / wall_whole, 2) if wall_whole > 0 else None,
        "metrics_identical": all(r == results[0] for r in results),
        "tracking_error_mean_m": m_inproc["tracking_error_mean_m"],
        "targets": {"processes_wall_s_max": 30.0, "inprocess_wall_s_max": 1.5},  # issue 11 point 4
    }


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
