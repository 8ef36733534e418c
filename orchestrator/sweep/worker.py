"""What a Dask worker runs for one mission of a sweep (:func:`run_one`), and the worker's set-up
(:class:`SweepWorkerPlugin`).

The task sets the environment that ``auv-swarm run`` gives its processes (:data:`PASSED_ENV`, taken from the
client), ignores SIGINT (Ctrl-C is the client's), runs ``run_mission(scenario, mode="inprocess")`` and returns
the mission's row: the top-level numbers of ``metrics.json`` (``wall_time_s`` the mission's lockstep loop,
``run_wall_time_s`` the run_mission call), the whole metrics, the per-plan wall times, the worker's version and
address and its CPU time, the plug-in methods it ran. A mission that raises, or whose plug-in method raised
(``incomplete_reason = "method_error"``), returns a failed row with its message and its ``run_wall_time_s``
(until it raised).
"""

from __future__ import annotations

import os
import signal
import threading
import time
import tomllib
import warnings
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from auv_swarm.contract import methods

PASSED_ENV = (
    "OPENBLAS_CORETYPE",
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "OPENBLAS_VERBOSE",
)
"""Variables the client passes to every mission as ``auv-swarm run`` passes them to its processes (the
inherited environment): OpenBLAS picks its kernels by CPU and their last bits differ between machines."""


def client_env() -> dict[str, str]:
    """The client's values of :data:`PASSED_ENV` (those that are set), and the methods registered by reference in
    the client (``contract.methods.child_env``): a mission on any worker can build them."""
    return {k: os.environ[k] for k in PASSED_ENV if k in os.environ} | methods.child_env()


def lacking(wanted: list[tuple[str, str]], env: dict[str, str]) -> str | None:
    """Run on each worker before a sweep (``client.run``): what this worker cannot build of the ``wanted`` (kind,
    name) methods with the client's ``env``, one line, or None."""
    from auv_swarm.orchestrator.mission.api import method_problem

    os.environ.update(env)
    problems = [p for p in (method_problem(kind, name) for kind, name in wanted) if p is not None]
    return "; ".join(problems) or None


def ignore_sigint() -> None:
    """SIGINT ignored in this process (only possible from the main thread; a no-op elsewhere)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


class SweepWorkerPlugin(WorkerPlugin):
    """Registered by the client on every worker: SIGINT ignored (the worker's set-up runs on its main thread)."""

    name = "auv-swarm-sweep"

    def setup(self, worker: Any) -> None:
        ignore_sigint()


def run_one(scenario_toml: str, env: dict[str, str]) -> dict[str, Any]:
    """Run one mission (the fully resolved scenario as TOML, its seed set) in process; returns its row."""
    from distributed import get_worker

    from auv_swarm.contract.config import scenario_from_dict
    from auv_swarm.orchestrator.mission.api import MissionWarning, run_mission
    from auv_swarm.orchestrator.sweep.version import version

    os.environ.update(env)
    ignore_sigint()
    try:
        worker = get_worker().address
    except ValueError:
        worker = f"pid {os.getpid()}"
    row: dict[str, Any] = {"version": version(), "worker": worker}
    cpu0, wall0 = time.process_time(), time.perf_counter()
    try:
        scenario = scenario_from_dict(tomllib.loads(scenario_toml))
        row["plugins"] = methods.plugins(scenario)
        with warnings.catch_warnings():  # a kill after a short sweep's end is the grid's choice, not news
            warnings.simplefilter("ignore", MissionWarning)
            result = run_mission(scenario, mode="inprocess")
    except Exception as exc:  # the mission raised: a failed row, the sweep goes on
        row.update(status="failed", error=f"{type(exc).__name__}: {exc}")
        row.update(run_wall_time_s=time.perf_counter() - wall0, cpu_s=time.process_time() - cpu0)
        return row
    instants: dict[float, float] = {}
    for series in result.record.agents.values():
        for t_s, wall in zip(series.plan_times_s, series.plan_wall_ms, strict=True):
            instants.setdefault(t_s, wall)
    metrics = dict(result.metrics)
    row.update({k: v for k, v in metrics.items() if isinstance(v, int | float) or v is None})
    failed = metrics.get("incomplete_reason") == methods.METHOD_ERROR  # a plug-in method raised
    stolen = metrics.get("compromised_auvs") or []
    if stolen:  # a second login with an AUV's password: the world quarantined it
        error = f"compromised: AUV {', '.join(map(str, stolen))} (a second login with its password)"
    else:
        error = metrics.get("error") if failed else None
    row.update(
        status="failed" if failed or stolen else "done",
        error=error,
        metrics=metrics,
        plan_walls_ms=[instants[t] for t in sorted(instants)],
        cpu_s=time.process_time() - cpu0,
    )
    return row
