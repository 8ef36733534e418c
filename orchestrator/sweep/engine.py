"""The sweep engine: a sweep's missions on Dask distributed, each row written to the store as it finishes.

Without a scheduler address the missions run on a ``LocalCluster`` on loopback (worker processes with one
thread each, ``distributed.scheduler.allowed-failures = 2``: a mission whose worker dies three times fails
with ``KilledWorker``). With ``scheduler`` the client connects to an existing cluster (``dask scheduler`` and
``dask worker`` started by hand, or dask-jobqueue); its settings are not the client's, so the client counts
the deaths under each mission itself (a worker that left while the mission was on it) and gives the mission
up at the third. Results come back with ``as_completed`` and are written by the client alone
(:class:`~auv_swarm.orchestrator.sweep.store.Store`). A result from another auv-swarm version stops the sweep.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import dask
from distributed import Client, Future, KilledWorker, LocalCluster, as_completed

from auv_swarm.orchestrator.sweep.grid import Mission
from auv_swarm.orchestrator.sweep.store import Store
from auv_swarm.orchestrator.sweep.worker import SweepWorkerPlugin, client_env, run_one

ALLOWED_FAILURES = 2
"""Deaths of a mission's worker Dask tolerates on the LocalCluster: the third fails the mission."""
MAX_DEATHS = ALLOWED_FAILURES + 1
"""Deaths after which a mission is marked failed (the client counts them itself with a scheduler address)."""
POLL_S = 0.25
"""How often the client looks for finished missions and departed workers (s)."""
CONNECT_TIMEOUT_S = 10.0
"""How long the client tries to reach a scheduler given by address (s)."""


class EngineError(RuntimeError):
    """The sweep cannot go on (scheduler unreachable, another version); the message is one line."""


class Interrupted(Exception):
    """Ctrl-C in the client: the pending missions were cancelled; finished rows are in the store."""


@dataclass
class Counts:
    """What the engine did: missions done, failed, skipped (done before), and the total."""

    total: int = 0
    skipped: int = 0
    done: int = 0
    failed: int = 0
    failures: list[str] = field(default_factory=list)
    startup_s: float = 0.0
    """Wall time from the call to the first mission submitted (cluster start or connect, worker set-up)."""


def _quiet_logs() -> None:
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker", "bokeh"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _dashboard_wanted(dashboard: bool) -> bool:
    """True if the dashboard is asked for and bokeh is there; a one-line note when it is not."""
    if not dashboard:
        return False
    try:
        import bokeh  # noqa: F401
    except ImportError:
        print("note: --dashboard needs bokeh: pip install 'auv-swarm[dashboard]'; running without it", file=sys.stderr)
        return False
    return True


NANNY_ENV = ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
"""What Dask's nanny would set in a worker's environment; a LocalCluster's workers keep the client's."""


@contextlib.contextmanager
def connect(workers: int | None, scheduler: str | None, dashboard: bool):
    """A Dask client: on a new LocalCluster on loopback, or on the scheduler at ``scheduler``."""
    _quiet_logs()
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise EngineError(f"cannot reach the Dask scheduler at {scheduler}: {reason}") from None
        try:
            yield client
        finally:
            client.close(timeout=5)
        return
    show = _dashboard_wanted(dashboard)
    # Dask's nanny sets OMP/MKL/OPENBLAS_NUM_THREADS=1 and MALLOC_TRIM_THRESHOLD_=65536 in its workers (None
    # unsets one); ours get the client's environment instead, as `auv-swarm run` gives its processes (BLAS reads
    # these when it loads, before any task runs). The malloc setting alone made every mission 1.5 times slower
    # (0.55 s against 0.35 s: glibc handing small numpy buffers back to the kernel), measured by bench sweep.
    environ = {key: None for key in NANNY_ENV} | client_env()
    settings = {
        "distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
        "distributed.nanny.pre-spawn-environ": environ,
        # A worker's statistical profiler (a stack sample every 10 ms, for the dashboard) and its 0.1-0.5 s
        # monitors took the GIL from the missions: 0.398 s a mission with them, 0.381 s without, 0.364 s direct.
        "distributed.worker.profile.enabled": show,
        "distributed.worker.memory.monitor-interval": "2s",
        "distributed.admin.system-monitor.interval": "2s",
    }
    with dask.config.set(settings):
        cluster = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",  # the scheduler's HTTP server (health routes) on loopback, any port
            scheduler_kwargs={"dashboard": show},
            silence_logs=logging.CRITICAL,
        )
    try:
        if show:
            print(f"dashboard: {cluster.dashboard_link}", file=sys.stderr)
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close(timeout=5)
    finally:
        cluster.close(timeout=10)


def run(
    missions: list[Mission],
    store: Store,
    version: str,
    client: Client,
    *,
    count_deaths: bool = False,
    on_result: Callable[[Counts], None] | None = None,
    counts: Counts | None = None,
) -> Counts:
    """Run the missions not yet done in ``store`` on ``client`` (:func:`connect`) and write each row as it
    finishes.

    ``count_deaths``: the client gives a mission up after :data:`MAX_DEATHS` deaths of its worker (a cluster
    whose scheduler settings are not the client's). Raises EngineError (another version) and Interrupted
    (Ctrl-C). ``on_result`` is called after each row (the progress line).
    """
    start = time.perf_counter()
    counts = counts or Counts()
    counts.total = len(missions)
    done_before = store.done()
    todo = [m for m in missions if m.key not in done_before]
    counts.skipped = len(missions) - len(todo)
    if on_result:
        on_result(counts)
    if not todo:
        return counts
    env = client_env()
    client.register_plugin(SweepWorkerPlugin())
    futures: dict[Future, Mission] = {}
    deaths: dict[tuple[str, int], int] = {}
    attempt: dict[tuple[str, int], int] = {}

    def submit(m: Mission) -> Future:
        attempt[m.key] = attempt.get(m.key, 0) + 1
        fut = client.submit(
            run_one,
            _toml(m),
            env,
            key=f"mission-{m.cell.sha256[:16]}-s{m.seed}-a{attempt[m.key]}",
            pure=False,
            retries=0,
        )
        futures[fut] = m
        return fut

    ac = as_completed([submit(m) for m in todo], loop=client.loop)
    counts.startup_s = time.perf_counter() - start
    seen_on: dict[str, str] = {}
    given_up: set[str] = set()
    last_poll = 0.0
    try:
        while not ac.is_empty():
            batch = ac.next_batch(block=False)
            if not batch:
                time.sleep(POLL_S)
                if time.monotonic() - last_poll >= 1.0:
                    last_poll = time.monotonic()
                    for key in _departed(client, seen_on):
                        fut = next((f for f in futures if f.key == key), None)
                        if fut is None or key in given_up:
                            continue
                        m = futures[fut]
                        deaths[m.key] = deaths.get(m.key, 0) + 1
                        if count_deaths and deaths[m.key] >= MAX_DEATHS:
                            given_up.add(key)
                            fut.cancel()
                            _failed(store, m, counts, f"its worker died {deaths[m.key]} times", deaths)
                            if on_result:
                                on_result(counts)
                continue
            for fut in batch:
                m = futures.pop(fut)
                if fut.key in given_up:
                    continue
                if fut.status == "finished":
                    row = fut.result()
                    if row.get("version") != version:
                        raise EngineError(
                            f"worker {row.get('worker')} runs auv-swarm {row.get('version')}, this client "
                            f"{version}: every worker must run the client's version"
                        )
                    row["attempts"] = attempt[m.key]
                    _write(store, m, row, counts)
                elif fut.status == "error":
                    exc = fut.exception()
                    if isinstance(exc, KilledWorker):
                        why = f"its worker died {max(MAX_DEATHS, deaths.get(m.key, 0))} times"
                    else:
                        why = f"{type(exc).__name__}: {exc}"
                    _failed(store, m, counts, why, deaths)
                else:  # lost or cancelled by the cluster (its worker went away): run it again
                    deaths[m.key] = deaths.get(m.key, 0) + 1
                    if deaths[m.key] >= MAX_DEATHS:
                        _failed(store, m, counts, f"its worker died {deaths[m.key]} times", deaths)
                    else:
                        ac.add(submit(m))
                if on_result:
                    on_result(counts)
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise Interrupted() from None
    except EngineError:
        client.cancel(list(futures))
        raise
    return counts


def _toml(m: Mission) -> str:
    from auv_swarm.contract.config import dump_toml

    return dump_toml(m.scenario())


def _departed(client: Client, seen_on: dict[str, str]) -> list[str]:
    """Keys of missions whose worker left since the last look (updates ``seen_on``: key -> worker)."""
    try:
        processing = client.processing()
        present = set(client.scheduler_info(n_workers=-1)["workers"])
    except (OSError, TimeoutError, KeyError, TypeError):
        return []
    gone = [key for key, w in seen_on.items() if w not in present]
    for key in gone:
        del seen_on[key]
    for w, keys in processing.items():
        for key in keys:
            seen_on[str(key)] = w
    return gone


def _write(store: Store, m: Mission, row: dict[str, Any], counts: Counts) -> None:
    row = dict(row, seed=m.seed, scenario_sha256=m.cell.sha256)
    store.put(m.cell.labels, row)
    if row["status"] == "done":
        counts.done += 1
    else:
        counts.failed += 1
        counts.failures.append(f"{_name(m)}: {row.get('error')}")


def _failed(store: Store, m: Mission, counts: Counts, error: str, deaths: dict[tuple[str, int], int]) -> None:
    row = {"status": "failed", "error": error, "attempts": deaths.get(m.key, 0) or MAX_DEATHS}
    _write(store, m, row, counts)


def _name(m: Mission) -> str:
    labels = ", ".join(f"{k}={v}" for k, v in m.cell.labels.items())
    return f"{labels + ', ' if labels else ''}seed {m.seed}"
