"""``auv-swarm run``: bring up a swarm, run a mission, write the results.

``--mode processes`` (default) starts the zenoh router, the world, the channel
emulator and one process per AUV as separate OS processes on loopback, and
listens on the bus like a recorder. ``--mode inprocess`` runs the same cores
and tick protocol in this process. Both write the same results folder.
"""

from __future__ import annotations

import argparse
import os
import queue
import secrets
import signal
import subprocess
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

from auv_swarm.contract import wire
from auv_swarm.contract.config import ConfigError, Fault, Scenario, builtin_scenarios, dump_toml, load_scenario
from auv_swarm.contract.credentials import CredentialError, derive, read_password, users, users_text
from auv_swarm.contract.identity import OBSERVER_AHEAD_TICKS, Gate
from auv_swarm.contract.lifeline import PARENT_ENV
from auv_swarm.contract.shell import DEFAULT_SCENARIO
from auv_swarm.contract.usage import fail
from auv_swarm.orchestrator import outdir
from auv_swarm.orchestrator.collect import MessageLog
from auv_swarm.orchestrator.faults import ComponentFaults
from auv_swarm.orchestrator.inprocess import run_inprocess
from auv_swarm.orchestrator.listen import RESULT_KEYS, supervised, supervisor_for
from auv_swarm.orchestrator.progress import Progress
from auv_swarm.orchestrator.report import write_results
from auv_swarm.orchestrator.results import summary_table
from auv_swarm.orchestrator.supervise import Outcome, Supervisor
from auv_swarm.recorder import web
from auv_swarm.recorder.view import add_web_args, wait_for_interrupt, web_ports
from auv_swarm.world.service import WorldService

DESCRIPTION = (
    "Run one mission and write its results folder (metrics.json, events.jsonl, plots, recording.rrd). "
    "--mode processes (default) starts the zenoh router, the world, the channel emulator, the recorder and "
    "one process per AUV on loopback; --mode inprocess runs the same cores in this process (faster, same metrics)."
)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="auv-swarm run", description=DESCRIPTION)
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO, help="built-in scenario name or TOML path")
    parser.add_argument("--seed", type=int, default=None, help="override run.seed")
    parser.add_argument("--duration", type=float, default=None, help="override run.duration_s (sim seconds)")
    parser.add_argument("--agents", type=int, default=None, help="override agents.count")
    parser.add_argument("--out", type=Path, default=None, help="results folder (default runs/<scenario>-<timestamp>)")
    parser.add_argument("--force", action="store_true", help="write into --out even if it already holds results")
    parser.add_argument(
        "--mode",
        choices=("processes", "inprocess"),
        default="processes",
        help="processes: one OS process per component over zenoh (default); inprocess: all in this process",
    )
    parser.add_argument("--speed", type=float, default=0.0, help="pace the clock at X times real time (processes mode)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    parser.add_argument("--viewer", action="store_true", help="also spawn the rerun viewer and stream to it live")
    parser.add_argument("--rerun-url", default=None, help="stream live to a rerun viewer at this URL (never blocks)")
    parser.add_argument(
        "--restart",
        default="no",
        help="no (default), or on-failure[:DELAY_S]: restart an AUV process that died unscheduled (processes mode)",
    )
    parser.add_argument(
        "--credentials",
        type=Path,
        default=None,
        help="use DIR/<user>.password (auv-swarm credentials --out DIR) instead of fresh per-run passwords",
    )
    add_web_args(parser)
    return parser.parse_args(argv)


def parse_restart(text: str) -> float | None:
    """``--restart``: ``no`` gives None; ``on-failure`` a delay of 0 s; ``on-failure:DELAY_S`` that delay (s)."""
    if text == "no":
        return None
    policy, _, delay = text.partition(":")
    if policy != "on-failure":
        raise ValueError(f"must be no or on-failure[:DELAY_S], got {text!r}")
    try:
        value = float(delay) if delay else 0.0
    except ValueError:
        raise ValueError(f"DELAY_S must be a number of seconds, got {delay!r}") from None
    if not 0.0 <= value <= 3600.0:
        raise ValueError(f"DELAY_S must be in [0, 3600] s, got {value:g}")
    return value


def load_checked(args: argparse.Namespace) -> Scenario:
    """The scenario with the CLI overrides, checked runnable before any process starts (ConfigError if not).

    Kills naming an AUV beyond ``--agents`` are dropped with a warning; a scenario file that names an AUV
    beyond its own ``agents.count`` is an error (from the config's validation).
    """
    base = load_scenario(args.scenario)
    if args.agents is not None:
        for i, k in enumerate(base.kills):
            if k.agent >= args.agents:
                print(
                    f"warning: kills[{i}] names AUV {k.agent}, but --agents {args.agents} runs AUVs "
                    f"0..{args.agents - 1}: that kill is dropped",
                    file=sys.stderr,
                )
    scenario = base.with_overrides(seed=args.seed, duration_s=args.duration, agents=args.agents)
    try:
        WorldService(scenario)
    except ValueError as exc:
        raise ConfigError(f"the world rejects scenario {scenario.name!r}: {exc}") from exc
    return scenario


def main(argv: list[str] | None = None) -> int:
    """Run one mission and write metrics.json, events.jsonl and plots; exit 0 complete, 1 incomplete, 2 bad input,
    130 interrupted (docs/exit-codes.md)."""
    args = parse_args(argv)
    try:
        scenario = load_checked(args)
    except ConfigError as exc:
        return fail(str(exc))
    if args.speed < 0:
        return fail(f"--speed must be >= 0, got {args.speed}")
    try:
        restart_delay_s = parse_restart(args.restart)
    except ValueError as exc:
        return fail(f"--restart: {exc}")
    if args.mode == "inprocess":
        only_processes = [f"faults[{i}]" for i, f in enumerate(scenario.faults) if f.auv is None]
        if only_processes:
            print(
                f"error: {only_processes[0]}: faults of the channel, router, world or recorder exist only in "
                "processes mode (--mode processes)",
                file=sys.stderr,
            )
            return 2
    if args.rerun_url is not None:
        from auv_swarm.recorder.core import check_url

        try:
            check_url(args.rerun_url)
        except ValueError as exc:
            return fail(f"--rerun-url: {exc}")
    try:
        creds = launcher_credentials(scenario.agents.count, args.credentials)
    except CredentialError as exc:
        return fail(str(exc))
    try:
        ports = web_ports(args) if args.web is not None else None
    except ValueError as exc:
        return fail(str(exc))
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    try:
        out = outdir.prepare(args.out or Path("runs") / f"{scenario.name}-{stamp}", force=args.force)
    except outdir.OutDirError as exc:
        return fail(str(exc))
    if args.viewer and not viewer_possible(out):
        args.viewer = False
    (out / "scenario.toml").write_text(dump_toml(scenario), encoding="utf-8")
    web_viewer = None
    if ports is not None:
        try:
            web_viewer = web.start(*ports, out / "logs" / "web-viewer.log")
        except (RuntimeError, FileNotFoundError) as exc:
            return fail(str(exc), 1)
        print(f"web viewer: open {web.page_url('localhost', *ports)}", flush=True)
        args.rerun_url = web.proxy_url("127.0.0.1", ports[1])
    try:
        return mission(scenario, out, args, ports, creds, restart_delay_s)
    finally:
        if web_viewer is not None:
            web.stop(web_viewer)


def mission(
    scenario: Scenario,
    out: Path,
    args: argparse.Namespace,
    ports: tuple[int, int] | None,
    creds: dict[str, str],
    restart_delay_s: float | None,
) -> int:
    """Run the mission, write the results; with the web viewer on, keep serving until Ctrl-C. The exit code."""
    progress = Progress("mission", scenario.run.duration_s, "s sim time", enabled=not args.quiet)
    log = MessageLog()
    start = time.perf_counter()
    if args.mode == "inprocess":
        outcome = run_inprocess_mode(scenario, out, log, progress, args)
    else:
        viewer_args = (["--viewer"] if args.viewer else []) + (
            ["--rerun-url", args.rerun_url] if args.rerun_url else []
        )
        outcome = run_processes(
            scenario, out, log, progress, args.speed, viewer_args, creds=creds, restart_delay_s=restart_delay_s
        )
    progress.close()
    if args.viewer and args.mode == "processes":
        relay_viewer_warnings(out / "logs" / "recorder.log")
    wall = time.perf_counter() - start
    record = log.to_record(scenario, args.mode, wall)
    record.set_outcome(outcome.complete, outcome.reason, outcome.exit_code)
    metrics = write_results(record, out)
    print(summary_table(metrics))
    print(f"results in {out}")
    if not outcome.complete:
        print(f"run incomplete ({outcome.reason}): {outcome.line}", file=sys.stderr)
    if ports is not None and outcome.reason != "interrupted":
        url = web.page_url("localhost", *ports)
        print(f"mission over; the web viewer keeps serving {url} until Ctrl-C", flush=True)
        wait_for_interrupt()
    return outcome.exit_code


def run_inprocess_mode(
    scenario: Scenario, out: Path, log: MessageLog, progress: Progress, args: argparse.Namespace
) -> Outcome:
    """The mission in this process, recorded to ``out/recording.rrd``; Ctrl-C makes it an interrupted run."""
    from auv_swarm.recorder.core import RerunRecorder

    try:
        with RerunRecorder(scenario, out / "recording.rrd", spawn_viewer=args.viewer, url=args.rerun_url) as recorder:
            run_inprocess(scenario, [log, recorder], progress)
    except KeyboardInterrupt:
        t_s = max((tr.t_s for tr in log.truth.values()), default=0.0)
        progress.clear()
        line = f"interrupted at t = {t_s:g} s; the results cover the part that ran"
        print(line, file=sys.stderr)
        return Outcome(False, "interrupted", line)
    return Outcome()


def viewer_possible(out: Path) -> bool:
    """Whether ``--viewer`` can open a viewer window here; if not, say so in one line (the recording carries on)."""
    from auv_swarm.recorder.viewer import window_problem

    problem = window_problem()
    if problem is not None:
        print(
            f"warning: --viewer: {problem}; recording to {out / 'recording.rrd'} only "
            f"(view it later with: auv-swarm view {out})",
            file=sys.stderr,
        )
    return problem is None


def relay_viewer_warnings(recorder_log: Path) -> None:
    """Repeat in the terminal what the recorder process logged about a viewer it could not start or reach."""
    try:
        lines = recorder_log.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return
    for line in lines:
        if line.startswith("recorder:") and "viewer" in line:
            print(f"warning: {line}", file=sys.stderr)


def scenarios_main(argv: list[str] | None = None) -> int:
    """``auv-swarm scenarios``: list the built-in scenarios with their descriptions."""
    argparse.ArgumentParser(
        prog="auv-swarm scenarios", description="List the built-in scenarios (names for --scenario)."
    ).parse_args(argv)
    for name in builtin_scenarios():
        s = load_scenario(name)
        first = s.description.strip().splitlines()[0] if s.description.strip() else ""
        print(f"{name:<24} {first}")
    return 0


def launcher_credentials(agents: int, folder: Path | None = None) -> dict[str, str]:
    """user -> password for every process of a run: derived from a fresh secret that never leaves this
    process, or read from ``folder/<user>.password``. Raises CredentialError for a missing or bad file."""
    if folder is None:
        return derive(secrets.token_hex(16), agents)
    return {u: read_password(folder / f"{u}.password", u) for u in users(agents)}


def run_processes(
    scenario: Scenario,
    out: Path,
    log: MessageLog,
    progress: Progress,
    speed: float,
    recorder_args: list[str] | None = None,
    creds: dict[str, str] | None = None,
    restart_delay_s: float | None = None,
    external: tuple[Fault, ...] = (),
) -> Outcome:
    """Start router, channel, AUVs, recorder and world as OS processes; listen until the world ends the mission
    or the run fails (see ``orchestrator.supervise``).

    ``recorder_args`` None runs without the rerun recorder process; a list (maybe
    empty) starts it with those extra arguments (--viewer, --rerun-url). Every
    process started is stopped and checked gone by pid before returning. Each
    child watches this process's pid (``AUVSWARM_PARENT_PID``), so a SIGKILL of
    the launcher takes them with it too. ``restart_delay_s`` (``--restart on-failure``): an AUV process that
    died without a scheduled fault is started again after that many wall seconds; the world re-admits it.
    ``external``: AUV faults the launcher injects unannounced (``orchestrator.faults``; drills).

    Each child gets only its own password (``creds``, default :func:`launcher_credentials`) on a
    pipe it reads at start, the router only the user table (``contract.credentials``).
    """
    from auv_swarm.contract.zbus import ZenohBus
    from auv_swarm.orchestrator.procs import free_port, pid_alive, stop

    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    creds = creds or launcher_credentials(scenario.agents.count)
    env = {"PYTHONUNBUFFERED": "1", PARENT_ENV: str(os.getpid())}
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--scenario", str((out / "scenario.toml").resolve()), "--router", endpoint]
    procs: dict[str, subprocess.Popen] = {}
    inbound: queue.Queue[object] = queue.Queue()
    sup = supervisor_for(scenario.run)
    interrupted = threading.Event()
    faults: ComponentFaults | None = None
    previous = {sig: signal.signal(sig, lambda *_: interrupted.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        start = _Starter(procs, env, logs, creds)
        start(
            "router",
            ["router", "--listen", endpoint, "--agents", str(scenario.agents.count)],
            "listening",
            ["--grace-s", str(scenario.run.grace_s)],
        )

        gate = Gate("orchestrator")
        newest_truth = [0]

        def on_bytes(key: str, data: bytes) -> None:
            msg = gate.receive(key, data, max_tick=newest_truth[0] + OBSERVER_AHEAD_TICKS)
            if msg is None:
                log.malformed += 1
                return
            if isinstance(msg, wire.Truth):
                newest_truth[0] = max(newest_truth[0], msg.tick)
            inbound.put(msg)

        with ZenohBus(endpoint, user="orchestrator", password=creds["orchestrator"]) as bus:
            for key in RESULT_KEYS:
                bus.subscribe(key, on_bytes)
            start("channel", ["channel", *common])
            if scenario.planner.method == "centralised":
                start("central", ["central", *common])
            for a in range(scenario.agents.count):
                start(f"auv{a}", ["agent", "--id", str(a), *common])
            if recorder_args is not None:
                start("recorder", ["recorder", *common, "--out", str(out), *recorder_args], "recorder ready")
            start("world", ["world", *common, *(["--speed", str(speed)] if speed > 0 else [])])
            faults = ComponentFaults(scenario.faults, procs, start.again, sup.expect_exit, sup.lines.append, external)
            _watch(sup, procs, inbound, log, progress, scenario, interrupted, faults, restart_delay_s, start)
            if sup.ended and sup.outcome is None:
                log.wait_complete(inbound, scenario, timeout=5.0)
                _wait_all(procs, timeout=10.0)
    except (TimeoutError, ConnectionError) as exc:
        sup.fail("start_failed", f"start failed: {exc}".splitlines()[0])
        _say(progress, sup.lines)
    finally:
        for p in procs.values():
            stop(p, timeout=5.0)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        leftovers = [name for name, p in procs.items() if pid_alive(p.pid)]
        if leftovers:
            print(f"warning: processes still alive after stop: {leftovers}", file=sys.stderr)
    outcome = sup.outcome or Outcome()
    outcome.events = sup.events
    outcome.injected = faults.injected if faults is not None else []
    return outcome


POLL_S = 0.1
"""How often (wall s) the launcher looks at its children's exit status and its timers, at most."""


class _Starter:
    """Starts one child (``python -m orchestrator ROLE ...``, log in ``logs/NAME.log``), optionally waiting for a
    line of its log; a child that exits first or stays silent raises TimeoutError naming it.

    The child named ``router`` gets the user table of ``creds`` on its stdin pipe (``--users-fd 0``), every
    other child its own password only (``--password-fd 0``): nothing in its environment or command line."""

    def __init__(
        self, procs: dict[str, subprocess.Popen], env: dict[str, str], logs: Path, creds: dict[str, str]
    ) -> None:
        self.procs, self.env, self.logs, self.creds = procs, env, logs, creds
        self.started: dict[str, tuple[list[str], str]] = {}
        self.restarted: set[str] = set()

    def __call__(self, name: str, args: list[str], ready: str | None = None, extra: list[str] | None = None) -> None:
        from auv_swarm.orchestrator.procs import process_argv, read_log, spawn, wait_for_line

        log_path = self.logs / f"{name}.log"
        argv = process_argv(*args, *(extra or []))
        if name == "router":
            argv, secret = [*argv, "--users-fd", "0"], users_text(self.creds)
        else:
            argv, secret = [*argv, "--password-fd", "0"], self.creds[name]
        self.started[name] = (argv, secret)
        self.procs[name] = spawn(argv, name, env=self.env, log_path=log_path, secret=secret)
        if ready is not None:
            try:
                wait_for_line(self.procs[name], ready, timeout=30.0)
            except TimeoutError:
                proc = self.procs[name]
                how = "is still silent after 30 s" if proc.poll() is None else f"exited with {proc.returncode}"
                last = (read_log(log_path).strip().splitlines() or ["(empty log)"])[-1]
                raise TimeoutError(f"{name} {how} before it was ready: {last} (see {log_path})") from None

    def again(self, name: str) -> None:
        """Start a fresh process of ``name`` with the same command line and credentials (its log continues)."""
        from auv_swarm.orchestrator.procs import spawn

        argv, secret = self.started[name]
        self.procs[name] = spawn(argv, name, env=self.env, log_path=self.logs / f"{name}.log", secret=secret)
        self.restarted.add(name)


def _watch(
    sup: Supervisor,
    procs: dict[str, subprocess.Popen],
    inbound: queue.Queue,
    log: MessageLog,
    progress: Progress,
    scenario: Scenario,
    interrupted: threading.Event,
    faults: ComponentFaults,
    restart_delay_s: float | None,
    start: _Starter,
) -> None:
    """Listen until the world ends the mission, the run fails or Ctrl-C; print every line the supervisor has.
    Scheduled faults and the restart policy act here too."""
    reported: dict[str, bool] = {}
    restarts: dict[str, float] = {}
    next_poll = 0.0
    for now, msg in supervised(inbound, log, sup, interrupted):
        if isinstance(msg, wire.Truth):
            faults.on_time(msg.t_s, now)
            progress(msg.t_s, scenario.run.duration_s)
        elif isinstance(msg, wire.WorldEvent):
            if msg.kind == "kill" and f"auv{msg.auv}" in procs:
                _auv_fault(procs, msg, start)
            elif msg.kind in ("hung", "resume") and msg.text.startswith("stop:") and f"auv{msg.auv}" in procs:
                procs[f"auv{msg.auv}"].send_signal(signal.SIGSTOP if msg.kind == "hung" else signal.SIGCONT)
        for name in start.restarted:
            reported[name] = False
        start.restarted.clear()
        if now < next_poll:
            continue
        next_poll = now + POLL_S
        for name, proc in list(procs.items()):
            if not reported.get(name) and proc.poll() is not None:
                reported[name] = True
                sup.on_exit(name, proc.returncode)
                crashed = name.startswith("auv") and int(name[3:]) not in sup.planned_kills
                if crashed and restart_delay_s is not None and sup.started and not sup.done:
                    restarts[name] = now + restart_delay_s
        for name, due in list(restarts.items()):
            if now >= due:
                del restarts[name]
                sup.lines.append(f"restarting {name} (--restart on-failure)")
                start.again(name)
        faults.on_wall(now)
        sup.on_wall(now)
        _say(progress, sup.lines)
    faults.resume_all()


def _auv_fault(procs: dict[str, subprocess.Popen], event: wire.WorldEvent, start: _Starter) -> bool:
    """Act on the world's ``kill`` of an AUV: SIGTERM for a ``term:`` fault, else SIGKILL; a ``restart:`` fault
    starts a fresh process of the same AUV at once (the world re-admits it when it is due). True if restarted."""
    name = f"auv{event.auv}"
    action = event.text.partition(":")[0]
    proc = procs[name]
    proc.send_signal(signal.SIGTERM if action == "term" else signal.SIGKILL)
    if action != "restart":
        return False
    proc.wait(timeout=10.0)
    start.again(name)
    return True


def _say(progress: Progress, lines: list[str]) -> None:
    """Print the supervisor's new lines on stderr, each on a line of its own (not inside the progress bar)."""
    if lines:
        progress.clear()
        for line in lines:
            print(line, file=sys.stderr, flush=True)
        lines.clear()


def _wait_all(procs: dict[str, subprocess.Popen], timeout: float) -> None:
    """Give every child up to ``timeout`` s (together) to end by itself after the mission's end."""
    deadline = time.monotonic() + timeout
    for proc in procs.values():
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            return


if __name__ == "__main__":
    sys.exit(main())
