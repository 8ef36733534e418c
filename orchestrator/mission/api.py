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
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from auv_swarm.contract.config import ConfigError, Fault, Scenario, dump_toml
from auv_swarm.orchestrator.mission.listen import Sink
from auv_swarm.orchestrator.mission.supervise import Outcome
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

    ``metrics`` is exactly the dict ``metrics.json`` holds; ``record`` the run record it comes from (per-AUV
    truth, estimates, plans, events, channel counters); ``outcome`` how the run ended (complete or not, why,
    the world's events, the faults injected); ``wall_s`` the mission's wall time (s); ``out`` the results
    folder written, or None.
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


def check_runnable(scenario: Scenario, mode: str = "inprocess") -> None:
    """Raise ConfigError, naming what is wrong, if ``scenario`` cannot run in ``mode`` (before any work starts).

    Builds no world: the world's one check of a valid scenario, the team's placement, is made alone
    (:func:`~auv_swarm.world.service.check_scenario`).
    """
    from auv_swarm.world.service import check_scenario

    if mode not in MODES:
        raise ConfigError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    try:
        check_scenario(scenario)
    except ValueError as exc:
        raise ConfigError(f"the world rejects scenario {scenario.name!r}: {exc}") from exc
    if mode == "inprocess":
        for i, f in enumerate(scenario.faults):
            if f.auv is None:
                raise ConfigError(
                    f"faults[{i}]: faults of the channel, router, world or recorder exist only in processes mode "
                    "(--mode processes)"
                )


def run_mission(
    scenario: Scenario,
    *,
    mode: str = "inprocess",
    out: Path | str | None = None,
    sinks: Iterable[Sink] = (),
    progress: Callable[[float, float], None] | None = None,
    launch: Launch | None = None,
    checked: bool = False,
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
    """
    launch = launch or Launch()
    if not checked:
        check_runnable(scenario, mode)
    if mode == "inprocess" and (launch.viewer or launch.rerun_url) and (out is None or not launch.recorder):
        raise ValueError("a live viewer in process streams the recording: give run_mission an out folder")
    folder = None if out is None else Path(out)
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "scenario.toml").write_text(dump_toml(scenario), encoding="utf-8")
    log = MessageLog()
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
    record = log.to_record(scenario, mode, wall)
    record.set_outcome(outcome.complete, outcome.reason, outcome.exit_code)
    if folder is not None:
        from auv_swarm.results.report import write_results

        metrics = write_results(record, folder)
    else:
        metrics = compute_metrics(record)
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
            run_inprocess(scenario, [log, *([rec] if rec is not None else []), *sinks], progress)
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
