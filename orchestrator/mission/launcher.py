"""The processes-mode launcher: one object for one mission's OS processes, their supervision, faults and restarts.

:class:`Launcher` starts the zenoh router, the channel emulator, the central planner (centralised MPC only),
one process per AUV, the recorder and the world on a free loopback port, listens on the bus like a
recorder, and stops every process at the end (checked gone by pid). What the run means is the
:class:`~auv_swarm.orchestrator.mission.supervise.Supervisor`'s business; scheduled component faults are
:class:`~auv_swarm.orchestrator.mission.faults.ComponentFaults`'; ``--restart on-failure`` is
:attr:`Launcher.restart_delay_s`. :func:`auv_swarm.orchestrator.mission.api.run_mission` is its one user.
"""

from __future__ import annotations

import os
import queue
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from auv_swarm.bus import tls
from auv_swarm.bus.credentials import derive, read_password, users, users_text
from auv_swarm.bus.identity import OBSERVER_AHEAD_TICKS, Gate
from auv_swarm.bus.lifeline import PARENT_ENV
from auv_swarm.contract import methods, wire
from auv_swarm.contract.config import Fault, Scenario
from auv_swarm.orchestrator.mission.faults import ComponentFaults
from auv_swarm.orchestrator.mission.listen import RESULT_KEYS, Fanout, supervised, supervisor_for
from auv_swarm.orchestrator.mission.procs import (
    free_port,
    pid_alive,
    process_argv,
    read_log,
    spawn,
    stop,
    wait_for_line,
)
from auv_swarm.orchestrator.mission.supervise import Outcome
from auv_swarm.results.collect import MessageLog

POLL_S = 0.1
"""How often (wall s) the launcher looks at its children's exit status and its timers, at most."""


def launcher_credentials(agents: int, folder: Path | None = None) -> dict[str, str]:
    """user -> password for every process of a run: derived from a fresh secret that never leaves this
    process, or read from ``folder/<user>.password``. Raises CredentialError for a missing or bad file."""
    if folder is None:
        return derive(secrets.token_hex(16), agents)
    return {u: read_password(folder / f"{u}.password", u) for u in users(agents)}


def launcher_certificates(agents: int) -> Path:
    """A private folder (0700, removed by the caller) of fresh certificates for every process of a run on this
    host over mutual TLS (``--tls``): the router answers to 127.0.0.1, everything lives one day, and the CA key is
    dropped once they are signed (:func:`tls.write_zenoh`)."""
    folder = Path(tempfile.mkdtemp(prefix="auvswarm-tls-"))
    try:
        tls.write_zenoh(folder, users(agents), router_hosts=("127.0.0.1",), days=1)
        (folder / "ca.key").unlink()
    except BaseException:  # nothing of a half-written folder (a CA key among it) is left behind
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return folder


class Starter:
    """Starts one child (``python -m <its module>``, log in ``logs/NAME.log``), optionally waiting for a line of
    its log; a child that exits first or stays silent raises TimeoutError naming it.

    The child named ``router`` gets the user table of ``creds`` on its stdin pipe (``--users-fd 0``), every
    other child its own password only (``--password-fd 0``): nothing in its environment or command line.
    With ``tls_dir`` every child gets ``--tls-dir`` instead: its certificate is its login."""

    def __init__(
        self,
        procs: dict[str, subprocess.Popen],
        env: dict[str, str],
        logs: Path,
        creds: dict[str, str],
        tls_dir: Path | None = None,
    ) -> None:
        self.procs, self.env, self.logs, self.creds, self.tls_dir = procs, env, logs, creds, tls_dir
        self.started: dict[str, tuple[list[str], str | None]] = {}
        self.restarted: set[str] = set()

    def __call__(self, name: str, args: list[str], ready: str | None = None, extra: list[str] | None = None) -> None:
        """Start ``name`` as the process ``args[0]`` (a key of ``procs.PROCESS_MODULES``) with ``args[1:]``."""
        log_path = self.logs / f"{name}.log"
        argv = process_argv(*args, *(extra or []))
        if self.tls_dir is not None:
            argv, secret = [*argv, "--tls-dir", str(self.tls_dir)], None
        elif name == "router":
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
        argv, secret = self.started[name]
        self.procs[name] = spawn(argv, name, env=self.env, log_path=self.logs / f"{name}.log", secret=secret)
        self.restarted.add(name)


class Launcher:
    """One processes-mode mission (see the module docstring).

    ``sinks`` receive every message the launcher hears, the first of them the :class:`MessageLog` the run
    record is built from. ``progress(t_s, duration_s)`` follows the sim time (its ``clear()``, if it has one,
    is called before a line is printed). ``recorder_args`` None runs without the recorder process; a list
    (maybe empty) starts it with those extra arguments (``--viewer``, ``--rerun-url``). ``creds``: user ->
    password (default fresh ones). ``restart_delay_s``: an AUV process that died without a scheduled fault is
    started again after that many wall seconds (the world re-admits it); None never. ``external``: AUV faults
    the launcher injects unannounced (drills). ``handle_signals``: SIGINT and SIGTERM end the run as
    ``interrupted`` (only from the main thread, where Python can install handlers). ``tls``: every link mutual
    TLS on a ``tls/`` loopback endpoint, with certificates made for this run (:func:`launcher_certificates`)
    instead of passwords.

    Each child watches this process's pid (``AUVSWARM_PARENT_PID``), so a SIGKILL of the launcher takes them
    with it too.
    """

    def __init__(
        self,
        scenario: Scenario,
        out: Path,
        log: MessageLog,
        sinks: list | None = None,
        progress: Callable[[float, float], None] | None = None,
        *,
        speed: float = 0.0,
        recorder_args: list[str] | None = None,
        creds: dict[str, str] | None = None,
        restart_delay_s: float | None = None,
        external: tuple[Fault, ...] = (),
        handle_signals: bool = True,
        tls: bool = False,
    ) -> None:
        self.scenario = scenario
        self.out = out
        self.log = log
        self.listeners = Fanout([log, *(sinks or [])])
        self.progress = progress
        self.speed = speed
        self.recorder_args = recorder_args
        self.creds = creds or launcher_credentials(scenario.agents.count)
        self.restart_delay_s = restart_delay_s
        self.external = external
        self.handle_signals = handle_signals and threading.current_thread() is threading.main_thread()
        self.procs: dict[str, subprocess.Popen] = {}
        self.inbound: queue.Queue[object] = queue.Queue()
        self.sup = supervisor_for(scenario.run)
        self.interrupted = threading.Event()
        self.faults: ComponentFaults | None = None
        self.gate = Gate("orchestrator")
        self.newest_truth = 0
        self.reported: dict[str, bool] = {}
        self.restarts: dict[str, float] = {}
        logs = out / "logs"
        logs.mkdir(parents=True, exist_ok=True)
        self.tls_dir = launcher_certificates(scenario.agents.count) if tls else None
        env = {"PYTHONUNBUFFERED": "1", PARENT_ENV: str(os.getpid()), **methods.child_env()}
        self.start = Starter(self.procs, env, logs, self.creds, self.tls_dir)

    def run(self) -> Outcome:
        """Start every process, listen until the world ends the mission or the run fails, stop every process;
        the outcome (its events and the faults injected included)."""
        from auv_swarm.bus.zbus import ZenohBus

        scenario = self.scenario
        endpoint = f"{'tcp' if self.tls_dir is None else 'tls'}/127.0.0.1:{free_port()}"
        login = {"password": self.creds["orchestrator"]} if self.tls_dir is None else {"tls_dir": self.tls_dir}
        common = ["--scenario", str((self.out / "scenario.toml").resolve()), "--router", endpoint]
        previous = {}
        if self.handle_signals:
            previous = {
                sig: signal.signal(sig, lambda *_: self.interrupted.set()) for sig in (signal.SIGINT, signal.SIGTERM)
            }
        try:
            self.start(
                "router",
                ["router", "--listen", endpoint, "--agents", str(scenario.agents.count)],
                "listening",
                ["--grace-s", str(scenario.run.grace_s)],
            )
            with ZenohBus(endpoint, user="orchestrator", **login) as bus:
                for key in RESULT_KEYS:
                    bus.subscribe(key, self.on_bytes)
                self.start("channel", ["channel", *common])
                if scenario.planner.method == "centralised":
                    self.start("central", ["central", *common])
                for a in range(scenario.agents.count):
                    self.start(f"auv{a}", ["agent", "--id", str(a), *common])
                if self.recorder_args is not None:
                    self.start(
                        "recorder", ["recorder", *common, "--out", str(self.out), *self.recorder_args], "recorder ready"
                    )
                speed = ["--speed", str(self.speed)] if self.speed > 0 else []
                self.faults = ComponentFaults(
                    scenario.faults,
                    self.procs,
                    self.start.again,
                    self.sup,
                    lambda msg: bus.publish(wire.faults_injected(), wire.encode(msg)),
                    self.external,
                )
                holds = self.faults.hold_at()
                hold = ["--hold-at", ",".join(repr(t) for t in holds)] if holds else []
                self.start("world", ["world", *common, *speed, *hold])
                self.watch()
                if self.sup.ended and self.sup.outcome is None:
                    self.log.wait_complete(self.inbound, scenario, timeout=5.0, file=self.listeners.on_message)
                    self.wait_all(timeout=10.0)
                    for name, proc in self.procs.items():  # an AUV's plug-in raised just before the end
                        self.method_error(name, proc)
                    self.say()
        except (TimeoutError, ConnectionError) as exc:
            self.sup.fail("start_failed", f"start failed: {exc}".splitlines()[0])
            self.say()
        finally:
            self.stop_all(previous)
        outcome = self.sup.final()
        self.say()
        outcome.events = self.sup.events
        outcome.injected = self.faults.injected if self.faults is not None else []
        return outcome

    def stop_all(self, handlers: dict) -> None:
        """Stop every child, put the signal ``handlers`` back, remove the run's certificates (``tls``); warn of a
        child still alive."""
        for p in self.procs.values():
            stop(p, timeout=5.0)
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        if self.tls_dir is not None:
            shutil.rmtree(self.tls_dir, ignore_errors=True)
        leftovers = [name for name, p in self.procs.items() if pid_alive(p.pid)]
        if leftovers:
            print(f"warning: processes still alive after stop: {leftovers}", file=sys.stderr)

    def on_bytes(self, key: str, data: bytes) -> None:
        """A message from the bus (a zenoh thread): admitted through the identity and replay check, queued."""
        msg = self.gate.receive(key, data, max_tick=self.newest_truth + OBSERVER_AHEAD_TICKS)
        if msg is None:
            self.log.malformed += 1
            return
        if isinstance(msg, wire.Truth):
            self.newest_truth = max(self.newest_truth, msg.tick)
        self.inbound.put(msg)

    def watch(self) -> None:
        """Listen until the world ends the mission, the run fails or Ctrl-C; print every line the supervisor has.
        Scheduled faults (injected on the truth of their tick, at which the world holds the clock until the
        launcher confirms them) and the restart policy act here too."""
        next_poll = 0.0
        for now, msg in supervised(self.inbound, self.listeners, self.sup, self.interrupted):
            if isinstance(msg, wire.Truth):
                self.faults.on_truth(msg, now)
                if self.progress is not None:
                    self.progress(msg.t_s, self.scenario.run.duration_s)
            elif isinstance(msg, wire.WorldEvent):
                self.on_world_event(msg)
            for name in self.start.restarted:
                self.reported[name] = False
            self.start.restarted.clear()
            if now < next_poll:
                continue
            next_poll = now + POLL_S
            self.poll_exits(now)
            self.restart_due(now)
            self.faults.on_wall(now)
            self.sup.on_wall(now)
            self.say()
        self.faults.resume_all()

    def on_world_event(self, event: wire.WorldEvent) -> None:
        """Act on the world's ``kill`` of an AUV (SIGTERM for a ``term:`` fault, else SIGKILL; a ``restart:`` fault
        starts a fresh process of the same AUV at once, the world re-admits it when it is due), and on its
        ``stop:`` faults (SIGSTOP at ``hung``, SIGCONT at ``resume``)."""
        name = f"auv{event.auv}"
        if name not in self.procs:
            return
        if event.kind == "kill":
            action = event.text.partition(":")[0]
            proc = self.procs[name]
            proc.send_signal(signal.SIGTERM if action == "term" else signal.SIGKILL)
            if action == "restart":
                proc.wait(timeout=10.0)
                self.start.again(name)
        elif event.kind in ("hung", "resume") and event.text.startswith("stop:"):
            self.procs[name].send_signal(signal.SIGSTOP if event.kind == "hung" else signal.SIGCONT)

    def poll_exits(self, now: float) -> None:
        """Tell the supervisor of every child that exited since the last look; schedule the restart of a crashed
        AUV under the restart policy."""
        for name, proc in list(self.procs.items()):
            if self.reported.get(name) or proc.poll() is None:
                continue
            self.reported[name] = True
            if self.method_error(name, proc):
                continue
            self.sup.on_exit(name, proc.returncode)
            crashed = name.startswith("auv") and int(name[3:]) not in self.sup.planned_kills
            if crashed and self.restart_delay_s is not None and self.sup.started and not self.sup.done:
                self.restarts[name] = now + self.restart_delay_s

    def method_error(self, name: str, proc: subprocess.Popen) -> bool:
        """True, and the run failed (``method_error``), if ``name`` is an AUV that exited saying its plug-in method
        raised (``error: method_error: ...``, agent/node.py)."""
        if not name.startswith("auv") or not proc.returncode:
            return False
        error = methods.method_error_line(read_log(proc))
        if error is not None:
            self.sup.fail(methods.METHOD_ERROR, error)
        return error is not None

    def restart_due(self, now: float) -> None:
        """Start again every crashed AUV whose restart delay has passed."""
        for name, due in list(self.restarts.items()):
            if now >= due:
                del self.restarts[name]
                self.sup.lines.append(f"restarting {name} (--restart on-failure)")
                self.start.again(name)

    def say(self) -> None:
        """Print the supervisor's new lines on stderr, each on a line of its own (not inside the progress bar)."""
        if not self.sup.lines:
            return
        clear = getattr(self.progress, "clear", None)
        if clear is not None:
            clear()
        for line in self.sup.lines:
            print(line, file=sys.stderr, flush=True)
        self.sup.lines.clear()

    def wait_all(self, timeout: float) -> None:
        """Give every child up to ``timeout`` s (together) to end by itself after the mission's end."""
        deadline = time.monotonic() + timeout
        for proc in self.procs.values():
            try:
                proc.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                return
