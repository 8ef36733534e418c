"""One mission, from Python: :func:`run_mission` (``auv_swarm.run_mission``), the one way every verb, bench, drill,
tool and the sweep engine runs a mission.

``mode="inprocess"`` runs the swarm's cores in this process over an in-memory bus
(:mod:`~auv_swarm.orchestrator.mission.inprocess`); ``mode="processes"`` starts one OS process per component over zenoh
on loopback (:class:`~auv_swarm.orchestrator.mission.launcher.Launcher`). A scenario and seed give the same metrics in
both (docs/python.md).
"""

from __future__ import annotations

import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from auv_swarm.agent import plugins
from auv_swarm.contract import methods
from auv_swarm.contract.config import ConfigError, Fault, Scenario, dump_toml
from auv_swarm.contract.faults import after_end
from auv_swarm.contract.methods import METHOD_ERROR, MethodError
from auv_swarm.orchestrator.mission.listen import Sink
from auv_swarm.orchestrator.mission.supervise import Outcome, compromised
from auv_swarm.results.collect import MessageLog
from auv_swarm.results.metrics import compute_metrics
from auv_swarm.results.record import RunRecord

MODES = ("inprocess", "processes")


class LaunchError(ConfigError):
    """A :class:`Launch` value the mission cannot run with. ``field`` names it and ``problem`` follows the name in
    the message (``Launch.speed must be >= 0, got -1.0``), so the run verb can name its flag instead."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"Launch.{field}{problem}")
        self.field = field
        self.problem = problem


@dataclass(frozen=True)
class Launch:
    """How a mission is launched: the recorder and viewer (both modes) and the processes-mode options.

    - ``speed``: pace the clock at this many times real time (0: as fast as the lockstep goes; processes mode).
    - ``recorder``: record ``recording.rrd`` into the results folder (the recorder process in processes mode;
      in process only when ``out`` is given).
    - ``viewer``: also spawn the native rerun viewer; ``rerun_url``: stream live to a viewer at this URL.
    - ``credentials``: user -> password for every process (default: fresh ones derived for this run).
    - ``restart_delay_s``: restart an AUV process that crashed after this many wall seconds (None: never).
    - ``external_faults``: AUV faults the launcher injects unannounced to the world (the drills).
    - ``handle_interrupt``: Ctrl-C (and SIGTERM in processes mode) ends the mission as ``interrupted`` with
      results covering the part that ran; False lets KeyboardInterrupt through (processes are stopped).
    - ``tls``: processes mode over mutual TLS, certificates made for the run instead of passwords (docs/deploy.md).
    """

    speed: float = 0.0
    recorder: bool = True
    viewer: bool = False
    rerun_url: str | None = None
    credentials: dict[str, str] | None = None
    restart_delay_s: float | None = None
    external_faults: tuple[Fault, ...] = ()
    handle_interrupt: bool = True
    tls: bool = False

    def __post_init__(self) -> None:
        """Raise :class:`LaunchError` (a ConfigError) naming the first value out of range."""
        if not self.speed >= 0:
            raise LaunchError("speed", f" must be >= 0, got {self.speed!r}")
        if self.restart_delay_s is not None and not 0 <= self.restart_delay_s <= 3600:
            raise LaunchError("restart_delay_s", f" must be in [0, 3600] s or None, got {self.restart_delay_s!r}")
        if self.rerun_url is not None:
            from auv_swarm.recorder.viewer import check_url

            try:
                check_url(self.rerun_url)
            except ValueError as exc:
                raise LaunchError("rerun_url", f": {exc}") from None


@dataclass(frozen=True)
class MissionResult:
    """What :func:`run_mission` returns.

    ``metrics`` is exactly the dict ``metrics.json`` holds (its ``wall_time_s`` the mission's lockstep loop,
    ``run_wall_time_s`` the run to its metrics); ``record`` the run record it comes from (per-AUV truth,
    estimates, plans, events, channel counters); ``outcome`` how the run ended (complete or not, why, the
    world's events, the faults injected); ``wall_s`` the mission's span in :func:`run_mission` (s): the loop
    with the processes' start and stop, results not included; ``out`` the results folder written, or None.
    """

    metrics: dict[str, Any]
    record: RunRecord
    outcome: Outcome
    wall_s: float
    out: Path | None = None

    @property
    def exit_code(self) -> int:
        """0 complete, 1 incomplete, 130 interrupted (docs/exit-codes.md)."""
        return self.outcome.exit_code

    def export(self, format: str = "parquet", out: Path | str | None = None) -> list[Path]:
        """The run's raw data as ``format`` (csv, parquet or mcap: docs/results.md) in the folder ``out`` (default
        ``self.out/export``; required when the mission wrote no folder); the files written. Raises
        :class:`~auv_swarm.results.export.ExportError` (a ValueError) for an unknown format or MCAP without the
        ``mcap`` package."""
        from auv_swarm.results.export import export_record

        if out is None and self.out is None:
            raise ValueError("MissionResult.export needs out= when run_mission wrote no folder")
        return export_record(self.record, format, Path(out) if out is not None else self.out / "export")


def method_problem(kind: str, name: str, other_process: bool = False) -> str | None:
    """What keeps this process (``other_process``: the processes it starts) from building the method ``name`` of
    ``kind`` (``planner`` or ``estimator``), one line, or None: an unknown name, a plug-in that does not load, a
    factory registered here that no other process can import (a lambda, a closure)."""
    return plugins.problem(kind, name, other_process)


def check_runnable(scenario: Scenario, mode: str = "inprocess") -> None:
    """Raise ConfigError, naming what is wrong, if ``scenario`` cannot run in ``mode`` (before any work starts).

    Builds no world: the world's one check of a valid scenario, the team's placement, is made alone
    (:func:`~auv_swarm.world.service.check_scenario`). A Bellhop scenario's table is built into the cache first if
    it is not there (the mission layer builds tables; the world's check only reads them).
    """
    from auv_swarm.orchestrator.mission.tables import ensure_table
    from auv_swarm.world.service import check_scenario

    if mode not in MODES:
        raise ConfigError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    ensure_table(scenario)  # without the [bellhop] extra: SolverMissing, a ConfigError naming it
    try:
        check_scenario(scenario)
    except ValueError as exc:
        raise ConfigError(f"the world rejects scenario {scenario.name!r}: {exc}") from exc
    for kind, name in methods.picked(scenario):
        problem = method_problem(kind, name, other_process=mode == "processes")
        if problem is not None:
            raise ConfigError(problem)
    if mode == "inprocess":
        for i, f in enumerate(scenario.faults):
            if f.auv is None:
                raise ConfigError(
                    f"faults[{i}]: faults of the channel, router, world or recorder exist only in processes mode "
                    "(--mode processes)"
                )


class MissionWarning(UserWarning):
    """Something in the scenario that will not happen as written (a kill or fault after the mission's end)."""


class LoopClock:
    """The progress callback :func:`run_mission` hands on: it notes the wall time of the first and the last tick
    (the mission's lockstep loop, ``wall_time_s``), then calls the caller's callback, if any."""

    def __init__(self, inner: Callable[[float, float], None] | None) -> None:
        self.inner = inner
        self.first: float | None = None
        self.last: float | None = None

    def __call__(self, t_s: float, duration_s: float) -> None:
        self.last = time.perf_counter()
        if self.first is None:
            self.first = self.last
        if self.inner is not None:
            self.inner(t_s, duration_s)

    def clear(self) -> None:
        """The caller's ``clear()`` (a progress bar's), if it has one."""
        clear = getattr(self.inner, "clear", None)
        if clear is not None:
            clear()

    @property
    def wall_s(self) -> float:
        """Wall time from the first tick to the last (s); 0 when fewer than two ticks ran."""
        return 0.0 if self.first is None or self.last is None else self.last - self.first


def run_mission(
    scenario: Scenario,
    *,
    mode: str = "inprocess",
    out: Path | str | None = None,
    sinks: Iterable[Sink] = (),
    progress: Callable[[float, float], None] | None = None,
    launch: Launch | None = None,
    checked: bool = False,
    started: float | None = None,
) -> MissionResult:
    """Run one mission of ``scenario`` and return its :class:`MissionResult`.

    ``sinks`` receive every message a recorder hears (truth, sensor, telemetry, channel and world events), as
    :class:`~auv_swarm.results.collect.MessageLog` does. ``progress(t_s, duration_s)`` follows the sim time.
    With ``out`` the folder ``auv-swarm run`` writes is written there (scenario.toml, metrics.json,
    events.jsonl, the figures, recording.rrd, logs/; existing files are overwritten); without it nothing is
    written (processes mode keeps its logs in a temporary folder, removed at the end). Raises ConfigError if
    the scenario cannot run in ``mode`` (``checked``: the caller made that check with :func:`check_runnable`, as
    the run verb does before it writes its folder) and ValueError for a live viewer in process without ``out``; a
    run that fails at run time returns an incomplete result instead. A :class:`Launch` checks itself when built.
    A kill or fault after the mission's end is a :class:`MissionWarning` (``warnings``). Two wall times go into
    the metrics: ``wall_time_s`` the lockstep loop, first tick to last; ``run_wall_time_s`` from ``started`` (a
    ``time.perf_counter()`` value: the command's start for ``auv-swarm run``; default this call) to the metrics.
    """
    from auv_swarm.orchestrator.mission import tables

    started = time.perf_counter() if started is None else started
    launch = launch or Launch()
    scenario = tables.resolve(scenario)
    if not checked:
        check_runnable(scenario, mode)
    for line in after_end(scenario):
        warnings.warn(line, MissionWarning, stacklevel=2)
    if mode == "inprocess" and (launch.viewer or launch.rerun_url) and (out is None or not launch.recorder):
        raise ValueError("a live viewer in process streams the recording: give run_mission an out folder")
    folder = None if out is None else Path(out)
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "scenario.toml").write_text(dump_toml(scenario), encoding="utf-8")
        tables.copy_table(scenario, folder)
    log = MessageLog()
    loop = LoopClock(progress)
    progress = loop
    start = time.perf_counter()
    if mode == "inprocess":
        outcome = _inprocess(scenario, folder, log, list(sinks), progress, launch)
    elif folder is not None:
        outcome = _processes(scenario, folder, log, list(sinks), progress, launch)
    else:
        with tempfile.TemporaryDirectory(prefix="auv-swarm-mission-") as tmp:
            (Path(tmp) / "scenario.toml").write_text(dump_toml(scenario), encoding="utf-8")
            outcome = _processes(scenario, Path(tmp), log, list(sinks), progress, launch)
    wall = time.perf_counter() - start
    record = log.to_record(scenario, mode, loop.wall_s)
    record.set_outcome(outcome.complete, outcome.reason, outcome.exit_code)

    def run_wall(metrics: dict[str, Any]) -> None:  # the run up to its metrics, figures included
        record.run_wall_time_s = metrics["run_wall_time_s"] = time.perf_counter() - started

    record.error = outcome.line if outcome.reason == METHOD_ERROR else None
    if folder is not None:
        from auv_swarm.results.report import write_results

        metrics = write_results(record, folder, finish=run_wall)
    else:
        metrics = compute_metrics(record)
        run_wall(metrics)
    return MissionResult(metrics=metrics, record=record, outcome=outcome, wall_s=wall, out=folder)


def _inprocess(
    scenario: Scenario,
    out: Path | None,
    log: MessageLog,
    sinks: list[Sink],
    progress: Callable[[float, float], None] | None,
    launch: Launch,
) -> Outcome:
    """The mission in this process, recorded to ``out/recording.rrd`` when there is a folder (or a viewer)."""
    from contextlib import nullcontext

    from auv_swarm.orchestrator.mission.inprocess import run_inprocess

    if out is not None and launch.recorder:
        from auv_swarm.recorder.core import RerunRecorder
        from auv_swarm.recorder.options import RecorderOptions

        options = RecorderOptions(spawn_viewer=launch.viewer, url=launch.rerun_url)
        recorder = RerunRecorder(scenario, out / "recording.rrd", options)
    else:
        recorder = nullcontext()
    try:
        with recorder as rec:
            run_inprocess(scenario, [log, *([rec] if rec is not None else []), *sinks], progress, frame_sinks=[log])
    except MethodError as exc:  # a plug-in method raised: a failed mission, as in processes mode
        return Outcome(False, METHOD_ERROR, str(exc))
    except KeyboardInterrupt:
        if not launch.handle_interrupt:
            raise
        t_s = max((tr.t_s for tr in log.truth.values()), default=0.0)
        clear = getattr(progress, "clear", None)
        if clear is not None:
            clear()
        line = f"interrupted at t = {t_s:g} s; the results cover the part that ran"
        print(line, file=sys.stderr)
        return Outcome(False, "interrupted", line)
    stolen = sorted({e.auv for e in log.world_events if e.kind == "duplicate_login"})
    if stolen:
        outcome = compromised(stolen)
        print(outcome.line, file=sys.stderr)
        return outcome
    return Outcome()


def _processes(
    scenario: Scenario,
    out: Path,
    log: MessageLog,
    sinks: list[Sink],
    progress: Callable[[float, float], None] | None,
    launch: Launch,
) -> Outcome:
    """The mission as OS processes (:class:`~auv_swarm.orchestrator.mission.launcher.Launcher`)."""
    from auv_swarm.orchestrator.mission.launcher import Launcher

    recorder_args = None
    if launch.recorder:
        recorder_args = ["--viewer"] if launch.viewer else []
        recorder_args += ["--rerun-url", launch.rerun_url] if launch.rerun_url else []
    return Launcher(
        scenario,
        out,
        log,
        sinks,
        progress,
        speed=launch.speed,
        recorder_args=recorder_args,
        creds=launch.credentials,
        restart_delay_s=launch.restart_delay_s,
        external=launch.external_faults,
        handle_signals=launch.handle_interrupt,
        tls=launch.tls,
    ).run()
