"""The sweep engine: a sweep's missions on Dask distributed, each row written to the store as it finishes.

Without a scheduler address the missions run on a ``LocalCluster`` on loopback, mutual TLS on every link with
certificates made for it (worker processes with one thread each, ``distributed.scheduler.allowed-failures = 2``: a mission whose worker dies three times fails
with ``KilledWorker``). With ``scheduler`` the client connects to an existing cluster (``dask scheduler`` and
``dask worker`` started by hand, or dask-jobqueue; over TLS unless ``--insecure-scheduler``, cluster.py); its settings are not the client's, so the client counts
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
from distributed import Client, Future, KilledWorker, LocalCluster, Security, as_completed

from auv_swarm.contract import methods
from auv_swarm.orchestrator.sweep import cluster
from auv_swarm.orchestrator.sweep.cluster import Scheduler
from auv_swarm.orchestrator.sweep.grid import Mission
from auv_swarm.orchestrator.sweep.store import Store
from auv_swarm.orchestrator.sweep.worker import SweepWorkerPlugin, client_env, lacking, run_one

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
def connect(workers: int | None, scheduler: Scheduler | None, dashboard: bool, *, secure: bool = True):
    """A Dask client: on a new LocalCluster on loopback (mutual TLS with certificates made for it, unless
    ``secure`` is False: plain TCP, for ``bench sweep``'s measurement of what TLS costs), or on ``scheduler``
    (:mod:`~auv_swarm.orchestrator.sweep.cluster`). EngineError if the scheduler cannot be reached."""
    _quiet_logs()
    if scheduler is not None:
        try:
            client = Client(
                scheduler.address, security=_security(scheduler.tls), timeout=CONNECT_TIMEOUT_S, set_as_default=False
            )
        except (OSError, TimeoutError, ValueError) as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise EngineError(f"cannot reach the Dask scheduler at {scheduler.address}: {reason}") from None
        try:
            yield client
        finally:
            client.close(timeout=5)
        return
    show = _dashboard_wanted(dashboard)
    with dask.config.set(_local_settings(show)):
        security = {"security": _security(cluster.local_tls()), "protocol": "tls://"} if secure else {}
        local = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            host=cluster.LOCAL_HOST,
            dashboard_address=f"{cluster.LOCAL_HOST}:0",  # the scheduler's HTTP server, on loopback, any port
            scheduler_kwargs={"dashboard": show},
            silence_logs=logging.CRITICAL,
            **security,
        )
    try:
        if show:
            print(f"dashboard: {local.dashboard_link} (readable by every user of this machine)", file=sys.stderr)
        client = Client(local, set_as_default=False)
        try:
            yield client
        finally:
            client.close(timeout=5)
    finally:
        local.close(timeout=10)


def _security(tls: cluster.ClusterTLS | None) -> Security | None:
    return Security(**tls.security_args()) if tls is not None else None


def _local_settings(show: bool) -> dict:
    """Dask settings of the LocalCluster (``show``: the dashboard is served)."""
    # Dask's nanny sets OMP/MKL/OPENBLAS_NUM_THREADS=1 and MALLOC_TRIM_THRESHOLD_=65536 in its workers (None
    # unsets one); ours get the client's environment instead, as `auv-swarm run` gives its processes (BLAS reads
    # these when it loads, before any task runs). The malloc setting alone made every mission 1.5 times slower
    # (0.55 s against 0.35 s: glibc handing small numpy buffers back to the kernel), measured by bench sweep.
    environ = {key: None for key in NANNY_ENV} | client_env()
    return {
        "distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
        "distributed.nanny.pre-spawn-environ": environ,
        # A worker's statistical profiler (a stack sample every 10 ms, for the dashboard) and its 0.1-0.5 s
        # monitors took the GIL from the missions: 0.398 s a mission with them, 0.381 s without, 0.364 s direct.
        "distributed.worker.profile.enabled": show,
        "distributed.worker.memory.monitor-interval": "2s",
        "distributed.admin.system-monitor.interval": "2s",
        **cluster.http_settings(show),
    }


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
    client.register_plugin(SweepWorkerPlugin())
    check_workers(client, todo, client_env())
    shipped = _ship_tables(client, todo)
    sweep = _Sweep(client, store, version, counts, on_result, Ledger(count_deaths), client_env(), shipped)
    results = as_completed([sweep.submit(m) for m in todo], loop=client.loop)
    counts.startup_s = time.perf_counter() - start
    try:
        sweep.drain(results)
    except KeyboardInterrupt:
        client.cancel(sweep.ledger.futures())
        raise Interrupted() from None
    except EngineError:
        client.cancel(sweep.ledger.futures())
        raise
    return counts


def check_workers(client: Client, missions: list[Mission], env: dict[str, str]) -> None:
    """EngineError, one line naming the worker, if a worker now on the cluster cannot build a plug-in method that
    ``missions`` pick (asked of each with ``client.run``; ``env`` hands down the methods registered here), or if a
    method is registered here in a form no worker can import (a lambda, a closure)."""
    wanted = sorted(
        {(k, n) for m in missions for k, n in methods.picked(m.cell.scenario) if n not in methods.BUILTIN[k]}
    )
    if not wanted:
        return
    for kind, name in wanted:
        line = methods.not_portable(kind, name)
        if line is not None:
            raise EngineError(line)
    for worker, problem in sorted(client.run(lacking, wanted, env).items()):
        if problem is not None:
            raise EngineError(f"worker {worker} cannot run this sweep: {problem}")


class Ledger:
    """One run's bookkeeping, no Dask call in it: the missions in flight (task key -> future and mission), how
    many times each mission was submitted and how many times its worker died, which worker each task was last
    seen on, and the tasks the client gave up.

    One death rule (:meth:`died`): every death of a mission's worker counts once, whoever sees it (the client's
    look at the cluster, :meth:`departed`, or a future the cluster lost); the mission is over at
    :data:`MAX_DEATHS`. Seen on the cluster, the death is the client's to act on only with ``count_deaths`` (a
    scheduler given by address); a LocalCluster's scheduler fails the mission itself (``KilledWorker``).
    """

    def __init__(self, count_deaths: bool) -> None:
        self.count_deaths = count_deaths
        self.in_flight: dict[str, tuple[Future, Mission]] = {}
        self.attempts: dict[tuple[str, int], int] = {}
        self.deaths: dict[tuple[str, int], int] = {}
        self.seen_on: dict[str, str] = {}
        self.given_up: set[str] = set()

    def next_attempt(self, m: Mission) -> str:
        """Count one more submission of ``m``; the key of its task."""
        self.attempts[m.key] = self.attempts.get(m.key, 0) + 1
        return f"mission-{m.cell.sha256[:16]}-s{m.seed}-a{self.attempts[m.key]}"

    def started(self, key: str, fut: Future, m: Mission) -> None:
        """``m``'s task ``key`` is in flight as ``fut``."""
        self.in_flight[key] = (fut, m)

    def ended(self, key: str) -> Mission | None:
        """The mission of the task ``key`` that came back, or None if the client gave it up (its row written)."""
        _fut, m = self.in_flight.pop(key)
        return None if key in self.given_up else m

    def futures(self) -> list[Future]:
        """The futures still in flight."""
        return [fut for fut, _m in self.in_flight.values()]

    def died(self, m: Mission) -> bool:
        """The death rule: one more death of ``m``'s worker; True once it has died :data:`MAX_DEATHS` times."""
        self.deaths[m.key] = self.deaths.get(m.key, 0) + 1
        return self.deaths[m.key] >= MAX_DEATHS

    def departed(self, processing: dict[str, list], present: set[str]) -> list[tuple[Future, Mission]]:
        """Apply the death rule to the tasks whose worker left since the last look (``processing``: worker ->
        task keys now, ``present``: the workers now); returns those the client gives up (marked given up)."""
        gone = [key for key, w in self.seen_on.items() if w not in present]
        for key in gone:
            del self.seen_on[key]
        for w, keys in processing.items():
            for key in keys:
                self.seen_on[str(key)] = w
        given_up = []
        for key in gone:
            if key not in self.in_flight or key in self.given_up:
                continue
            fut, m = self.in_flight[key]
            if self.died(m) and self.count_deaths:
                self.given_up.add(key)
                given_up.append((fut, m))
        return given_up

    def failed_row(self, m: Mission, error: str | None = None) -> dict[str, Any]:
        """The row of a failed mission: ``error``, or (None) its worker's deaths, at least :data:`MAX_DEATHS` (a
        ``KilledWorker`` from the scheduler, which counts deaths the client may not have seen)."""
        deaths = self.deaths.get(m.key, 0)
        why = error if error is not None else f"its worker died {max(MAX_DEATHS, deaths)} times"
        return {"status": "failed", "error": why, "attempts": deaths or MAX_DEATHS}


@dataclass
class _Sweep:
    """The client's side of one run: submits missions, writes each row to the store, applies the ledger's
    decisions to the cluster."""

    client: Client
    store: Store
    version: str
    counts: Counts
    on_result: Callable[[Counts], None] | None
    ledger: Ledger
    env: dict[str, str]
    shipped: object | None = None
    """The client's Bellhop tables scattered to the workers (:func:`_ship_tables`), or None."""

    def submit(self, m: Mission) -> Future:
        key = self.ledger.next_attempt(m)
        fut = self.client.submit(run_one, _toml(m), self.env, self.shipped, key=key, pure=False, retries=0)
        self.ledger.started(key, fut, m)
        return fut

    def drain(self, results: as_completed) -> None:
        """Write every mission's row as it comes back; look for departed workers at most once a second."""
        last_look = 0.0
        while not results.is_empty():
            batch = results.next_batch(block=False)
            for fut in batch:
                again = self.settle(fut)
                if again is not None:
                    results.add(again)
            if batch:
                continue
            time.sleep(POLL_S)
            if time.monotonic() - last_look >= 1.0:
                last_look = time.monotonic()
                self.look_at_workers()

    def settle(self, fut: Future) -> Future | None:
        """Write the row of a future that came back; returns the mission's next attempt when it runs again."""
        m = self.ledger.ended(fut.key)
        if m is None:
            return None
        again = None
        if fut.status == "finished":
            row = self._checked(fut.result())
            row["attempts"] = self.ledger.attempts[m.key]
            self._write(m, row)
        elif fut.status == "error":
            exc = fut.exception()
            error = None if isinstance(exc, KilledWorker) else f"{type(exc).__name__}: {exc}"
            self._write(m, self.ledger.failed_row(m, error))
        elif self.ledger.died(m):  # lost or cancelled by the cluster (its worker went away)
            self._write(m, self.ledger.failed_row(m))
        else:
            again = self.submit(m)
        if self.on_result:
            self.on_result(self.counts)
        return again

    def look_at_workers(self) -> None:
        """Count the deaths of the workers that left under a mission; fail the missions the client gives up."""
        try:
            processing = self.client.processing()
            present = set(self.client.scheduler_info(n_workers=-1)["workers"])
        except (OSError, TimeoutError, KeyError, TypeError):
            return
        for fut, m in self.ledger.departed(processing, present):
            fut.cancel()
            self._write(m, self.ledger.failed_row(m))
            if self.on_result:
                self.on_result(self.counts)

    def _checked(self, row: dict[str, Any]) -> dict[str, Any]:
        if row.get("version") != self.version:
            raise EngineError(
                f"worker {row.get('worker')} runs auv-swarm {row.get('version')}, this client "
                f"{self.version}: every worker must run the client's version"
            )
        return row

    def _write(self, m: Mission, row: dict[str, Any]) -> None:
        row = dict(row, seed=m.seed, scenario_sha256=m.cell.sha256)
        self.store.put(m.cell.labels, row)
        if row["status"] == "done":
            self.counts.done += 1
        else:
            self.counts.failed += 1
            self.counts.failures.append(f"{_name(m)}: {row.get('error')}")


def _ship_tables(client: Client, missions: list[Mission]) -> object | None:
    """The Bellhop TL tables of ``missions``, built once each here (the client needs the [bellhop] extra) and
    scattered to every worker, which then needs no pelagic (docs/ocean.md); None when no mission needs one."""
    from auv_swarm.contract.tltable import table_key
    from auv_swarm.orchestrator.mission import tables

    seen: dict[str, object] = {}
    for m in missions:
        s = m.scenario()
        if tables.needs_bellhop(s):
            seen.setdefault(table_key(s), s)
    if not seen:
        return None
    return client.scatter([tables.ship(list(seen.values()))], broadcast=True)[0]


def _toml(m: Mission) -> str:
    from auv_swarm.contract.config import dump_toml

    return dump_toml(m.scenario())


def _name(m: Mission) -> str:
    labels = ", ".join(f"{k}={v}" for k, v in m.cell.labels.items())
    return f"{labels + ', ' if labels else ''}seed {m.seed}"
