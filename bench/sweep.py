"""``auv-swarm bench sweep [--seeds A-B|N] [--duration S] [--scenario NAME] [--json]``: the sweep engine's cost.

The same missions (default paper-3.2-challenging, 300 s, seeds 1-40) three ways: direct in-process calls of
``run_mission`` in this process; the engine (``auv-swarm sweep``'s LocalCluster with its mutual TLS, store and
all) on one worker; and on two. Reports the two-worker speed-up (the target is at least 1.7 on two idle
cores), the engine's per-mission overhead against the direct calls (target at most 5 % of a mission's time),
and, apart, the cluster's start-up and each worker's first import of auv-swarm. What TLS costs is measured
apart (:func:`tls_cost`): a TLS and a plain-TCP LocalCluster side by side, the same tasks on each in turn.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

from auv_swarm.contract.usage import SEEDS_HELP, fail, plain_description


def first_import(scenario: str) -> float:
    """Seconds to import what a mission needs and run a two-tick mission (a process's first mission pays for its
    imports; measured apart, on each worker and in this process before the direct calls)."""
    t0 = time.perf_counter()
    from auv_swarm.contract.config import load_scenario
    from auv_swarm.orchestrator.mission.api import MissionWarning, run_mission

    s = load_scenario(scenario)
    with warnings.catch_warnings():  # its kills fall after a two-tick mission's end, as the sweep's workers ignore
        warnings.simplefilter("ignore", MissionWarning)
        run_mission(s.with_keys({"run.duration_s": 2 * s.run.tick_s}), mode="inprocess")
    return time.perf_counter() - t0


ROUND_TRIPS = 200
"""No-op tasks per cluster in :func:`tls_cost`."""
TLS_MISSIONS = 10
"""Missions per cluster in :func:`tls_cost` (the first of the grid)."""


def noop(i: int) -> int:
    """A task that does nothing (it runs on a worker)."""
    return i


def tls_cost(scenario: str, missions: list) -> dict:
    """What the sweep's TLS costs: a LocalCluster of one worker with TLS and one over plain TCP, both up at once,
    the same tasks on each in turn (so a busy machine's load falls on both alike), each awaited before the next:
    :data:`ROUND_TRIPS` no-op tasks, then :data:`TLS_MISSIONS` missions. Medians (ms) of a no-op task's round
    trip and of a mission's engine time (the client's wall minus the mission's own on the worker), per cluster."""
    from statistics import median

    from auv_swarm.contract.config import dump_toml
    from auv_swarm.orchestrator.sweep import engine as sweep_engine
    from auv_swarm.orchestrator.sweep.worker import client_env, run_one

    env, tomls = client_env(), [dump_toml(m.scenario()) for m in missions[:TLS_MISSIONS]]
    trips: dict[str, list[float]] = {"tls": [], "tcp": []}
    engine_ms: dict[str, list[float]] = {"tls": [], "tcp": []}
    with (
        sweep_engine.connect(1, None, False) as tls_client,
        sweep_engine.connect(1, None, False, secure=False) as tcp_client,
    ):
        clients = [("tls", tls_client), ("tcp", tcp_client)]
        for _name, client in clients:
            client.wait_for_workers(1)
            client.run(first_import, scenario)
        for i in range(ROUND_TRIPS):
            for name, client in clients if i % 2 else clients[::-1]:
                t0 = time.perf_counter()
                client.submit(noop, i, pure=False).result()
                trips[name].append(1000 * (time.perf_counter() - t0))
        for i, toml in enumerate(tomls):
            for name, client in clients if i % 2 else clients[::-1]:
                t0 = time.perf_counter()
                row = client.submit(run_one, toml, env, pure=False).result()
                engine_ms[name].append(1000 * (time.perf_counter() - t0 - row["run_wall_time_s"]))
    return {
        name: {
            "task_round_trip_ms": round(median(trips[name]), 2),
            "mission_engine_ms": round(median(engine_ms[name]), 2),
        }
        for name in trips
    }


def engine(grid, cells, workers: int) -> dict:
    """The missions on a fresh LocalCluster of ``workers``: start-up, first import, missions' wall."""
    from auv_swarm.orchestrator.sweep import engine as sweep_engine
    from auv_swarm.orchestrator.sweep import store as storemod
    from auv_swarm.orchestrator.sweep.version import version

    missions = grid.missions(cells)
    with tempfile.TemporaryDirectory(prefix="auv-swarm-bench-sweep-") as tmp:
        store = storemod.open_store(Path(tmp), {}, grid.plain(), grid.hash, version(), False)
        t0 = time.perf_counter()
        with sweep_engine.connect(workers, None, False) as client:
            client.wait_for_workers(workers)
            startup = time.perf_counter() - t0
            imports = client.run(first_import, grid.bases[0])
            t1 = time.perf_counter()
            counts = sweep_engine.run(missions, store, version(), client)
            wall = time.perf_counter() - t1
        rows = store.rows()
        store.close()
    if counts.failed:
        raise RuntimeError(f"{counts.failed} missions failed: {counts.failures[:1]}")
    return {
        "workers": workers,
        "cluster_startup_s": round(startup, 2),
        "first_import_s": {w: round(v, 2) for w, v in imports.items()},
        "missions_wall_s": round(wall, 2),
        "mission_wall_mean_s": round(sum(r["run_wall_time_s"] for r in rows) / len(rows), 3),
    }


def main(argv: list[str]) -> int:
    from auv_swarm.orchestrator.mission.api import MissionWarning, run_mission
    from auv_swarm.orchestrator.sweep import grid as gridmod

    parser = argparse.ArgumentParser(prog="auv-swarm bench sweep", description=plain_description(__doc__))
    parser.add_argument("--seeds", default="1-40", help=f"{SEEDS_HELP} (default 1-40)")
    parser.add_argument("--duration", type=float, default=300.0, help="mission length, s of sim time (default 300)")
    parser.add_argument("--scenario", default="paper-3.2-challenging", help="the scenario (default the README's)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    args = parser.parse_args(argv)
    try:
        grid = gridmod.Grid([args.scenario], [], gridmod.parse_seeds(args.seeds), gridmod.parse_duration(args.duration))
        cells = grid.check()
    except gridmod.GridError as exc:
        return fail(str(exc))
    missions = grid.missions(cells)
    local_import = first_import(args.scenario)
    t0 = time.perf_counter()
    with warnings.catch_warnings():  # a kill after a short mission's end is the grid's choice (as on the workers)
        warnings.simplefilter("ignore", MissionWarning)
        for m in missions:
            run_mission(m.scenario(), mode="inprocess")
    direct = time.perf_counter() - t0
    one = engine(grid, cells, 1)
    two = engine(grid, cells, 2)
    tls = tls_cost(args.scenario, missions)
    tls_extra_ms = tls["tls"]["mission_engine_ms"] - tls["tcp"]["mission_engine_ms"]
    n = len(missions)
    out = {
        "scenario": args.scenario,
        "duration_s": grid.duration_s,
        "missions": n,
        "direct_first_import_s": round(local_import, 2),
        "direct_wall_s": round(direct, 2),
        "direct_per_mission_s": round(direct / n, 3),
        "one_worker": one,
        "two_workers": two,
        "speedup_two_over_one": round(one["missions_wall_s"] / two["missions_wall_s"], 2),
        "engine_overhead_fraction": round((one["missions_wall_s"] - direct) / direct, 3),
        "tls_cost": tls,
        "tls_extra_ms_per_mission": round(tls_extra_ms, 2),
        "tls_extra_fraction": round(tls_extra_ms / 1000 / (direct / n), 4),
        "targets": {"speedup_at_least": 1.7, "overhead_at_most": 0.05},
    }
    if args.json:
        print(json.dumps(out))
    else:
        print(
            f"{n} missions of {args.scenario}, {grid.duration_s:g} s: direct {direct:.1f} s "
            f"({direct / n:.2f} s each); engine on 1 worker {one['missions_wall_s']} s, on 2 "
            f"{two['missions_wall_s']} s: speed-up {out['speedup_two_over_one']} (target >= 1.7 on idle cores); "
            f"engine overhead {100 * out['engine_overhead_fraction']:.1f} % (target <= 5 %), of which TLS "
            f"{tls_extra_ms:.1f} ms a mission ({100 * out['tls_extra_fraction']:.2f} %; engine time "
            f"{tls['tls']['mission_engine_ms']} ms with TLS, {tls['tcp']['mission_engine_ms']} ms over TCP; a no-op "
            f"task {tls['tls']['task_round_trip_ms']} / {tls['tcp']['task_round_trip_ms']} ms); cluster start-up "
            f"{one['cluster_startup_s']} / {two['cluster_startup_s']} s, first import "
            f"{', '.join(f'{v} s' for v in two['first_import_s'].values())} (reported apart)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
