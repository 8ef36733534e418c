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

from contract import wire
from contract.config import ConfigError, Scenario, builtin_scenarios, dump_toml, load_scenario
from contract.shell import DEFAULT_SCENARIO
from orchestrator.collect import MessageLog
from orchestrator.inprocess import run_inprocess
from orchestrator.results import summary_table, write_results
from recorder import web
from recorder.view import add_web_args, wait_for_interrupt, web_ports


class Progress:
    """A one-line progress bar in sim time, on stderr."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.last = -1

    def __call__(self, t_s: float, total_s: float) -> None:
        if not self.enabled:
            return
        pct = int(100 * min(1.0, t_s / total_s)) if total_s > 0 else 100
        if pct == self.last:
            return
        self.last = pct
        bar = "#" * (pct // 4) + "-" * (25 - pct // 4)
        print(f"\r[{bar}] {pct:3d}%  t = {t_s:7.0f} / {total_s:.0f} s", end="", file=sys.stderr, flush=True)
        if pct >= 100:
            print(file=sys.stderr, flush=True)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="auv-swarm run", description=__doc__)
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO, help="built-in scenario name or TOML path")
    parser.add_argument("--seed", type=int, default=None, help="override run.seed")
    parser.add_argument("--duration", type=float, default=None, help="override run.duration_s (sim seconds)")
    parser.add_argument("--agents", type=int, default=None, help="override agents.count")
    parser.add_argument("--out", type=Path, default=None, help="results folder (default runs/<scenario>-<timestamp>)")
    parser.add_argument("--mode", choices=("processes", "inprocess"), default="processes")
    parser.add_argument("--speed", type=float, default=0.0, help="pace the clock at X times real time (processes mode)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--viewer", action="store_true", help="also spawn the rerun viewer and stream to it live")
    parser.add_argument("--rerun-url", default=None, help="stream live to a rerun viewer at this URL (never blocks)")
    add_web_args(parser)
    return parser.parse_args(argv)


def load(args: argparse.Namespace) -> Scenario:
    """The scenario with the CLI overrides applied."""
    return load_scenario(args.scenario).with_overrides(seed=args.seed, duration_s=args.duration, agents=args.agents)


def main(argv: list[str] | None = None) -> int:
    """Run one mission and write metrics.json, events.jsonl and plots."""
    args = parse_args(argv)
    try:
        scenario = load(args)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.speed < 0:
        print(f"error: --speed must be >= 0, got {args.speed}", file=sys.stderr)
        return 2
    try:
        ports = web_ports(args) if args.web is not None else None
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    out = args.out or Path("runs") / f"{scenario.name}-{stamp}"
    out.mkdir(parents=True, exist_ok=True)
    (out / "scenario.toml").write_text(dump_toml(scenario), encoding="utf-8")
    web_viewer = None
    if ports is not None:
        try:
            web_viewer = web.start(*ports, out / "logs" / "web-viewer.log")
        except (RuntimeError, FileNotFoundError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        print(f"web viewer: open {web.page_url('localhost', *ports)}", flush=True)
        args.rerun_url = web.proxy_url("127.0.0.1", ports[1])
    progress = Progress(not args.quiet)
    log = MessageLog()
    start = time.perf_counter()
    interrupted = False
    try:
        if args.mode == "inprocess":
            from recorder.core import RerunRecorder

            rrd = out / "recording.rrd"
            with RerunRecorder(scenario, rrd, spawn_viewer=args.viewer, url=args.rerun_url) as recorder:
                run_inprocess(scenario, [log, recorder], progress)
        else:
            viewer_args = (["--viewer"] if args.viewer else []) + (
                ["--rerun-url", args.rerun_url] if args.rerun_url else []
            )
            interrupted = not run_processes(scenario, out, log, progress, args.speed, viewer_args)
    except KeyboardInterrupt:
        interrupted = True
    except BaseException:
        if web_viewer is not None:
            web.stop(web_viewer)
        raise
    wall = time.perf_counter() - start
    record = log.to_record(scenario, args.mode, wall)
    metrics = write_results(record, out)
    print(summary_table(metrics))
    print(f"results in {out}")
    if interrupted:
        if web_viewer is not None:
            web.stop(web_viewer)
        print("run interrupted: results cover the part that ran", file=sys.stderr)
        return 130
    if web_viewer is not None:
        print(
            f"mission over; the web viewer keeps serving {web.page_url('localhost', *ports)} until Ctrl-C", flush=True
        )
        try:
            wait_for_interrupt()
        finally:
            web.stop(web_viewer)
    return 0


def scenarios_main(argv: list[str] | None = None) -> int:
    """``auv-swarm scenarios``: list the built-in scenarios with their descriptions."""
    for name in builtin_scenarios():
        s = load_scenario(name)
        first = s.description.strip().splitlines()[0] if s.description.strip() else ""
        print(f"{name:<24} {first}")
    return 0


def run_processes(
    scenario: Scenario,
    out: Path,
    log: MessageLog,
    progress: Progress,
    speed: float,
    recorder_args: list[str] | None = None,
) -> bool:
    """Start router, channel, AUVs, recorder and world as OS processes; listen until the world ends.

    ``recorder_args`` None runs without the rerun recorder process; a list (maybe
    empty) starts it with those extra arguments (--viewer, --rerun-url).

    Returns False if interrupted. Every process started is stopped and checked
    gone by pid before returning.
    """
    from contract.zbus import ZenohBus, password_for
    from orchestrator.procs import free_port, pid_alive, spawn, stop, wait_for_line

    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    secret = secrets.token_hex(16)
    env = {**os.environ, "AUVSWARM_SECRET": secret, "PYTHONUNBUFFERED": "1"}
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    scenario_path = str((out / "scenario.toml").resolve())
    common = ["--scenario", scenario_path, "--router", endpoint]
    py = [sys.executable, "-m", "orchestrator"]
    procs: dict[str, object] = {}
    inbound: queue.Queue[object] = queue.Queue()
    interrupted = threading.Event()
    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, lambda *_: interrupted.set())
    try:
        procs["router"] = spawn(
            [*py, "router", "--listen", endpoint, "--agents", str(scenario.agents.count)],
            "router",
            env=env,
            log_path=logs / "router.log",
        )
        wait_for_line(logs / "router.log", "listening", timeout=30.0)

        def on_bytes(_key: str, data: bytes) -> None:
            try:
                inbound.put(wire.decode(data))
            except wire.DecodeError as exc:
                log.malformed += 1
                print(f"orchestrator: dropped malformed message: {exc}", file=sys.stderr)

        with ZenohBus(endpoint, user="orchestrator", password=password_for("orchestrator", secret)) as bus:
            for key in (
                wire.truth(),
                wire.all_telemetry(),
                wire.channel_events(),
                wire.channel_stats(),
                wire.world_events(),
            ):
                bus.subscribe(key, on_bytes)
            procs["channel"] = spawn([*py, "channel", *common], "channel", env=env, log_path=logs / "channel.log")
            for a in range(scenario.agents.count):
                procs[f"auv{a}"] = spawn(
                    [*py, "agent", "--id", str(a), *common], f"auv{a}", env=env, log_path=logs / f"auv{a}.log"
                )
            if recorder_args is not None:
                procs["recorder"] = spawn(
                    [*py, "recorder", *common, "--out", str(out), *recorder_args],
                    "recorder",
                    env=env,
                    log_path=logs / "recorder.log",
                )
                wait_for_line(logs / "recorder.log", "recorder ready", timeout=30.0)
            world_args = [*py, "world", *common] + (["--speed", str(speed)] if speed > 0 else [])
            procs["world"] = spawn(world_args, "world", env=env, log_path=logs / "world.log")
            ended = False
            while not ended and not interrupted.is_set():
                try:
                    msg = inbound.get(timeout=0.5)
                except queue.Empty:
                    if procs["world"].poll() is not None:
                        print(f"world exited with {procs['world'].returncode}; see {logs}", file=sys.stderr)
                        break
                    continue
                log.on_message(msg)
                if isinstance(msg, wire.Truth):
                    progress(msg.t_s, scenario.run.duration_s)
                elif isinstance(msg, wire.WorldEvent):
                    if msg.kind == "kill" and f"auv{msg.auv}" in procs:
                        procs[f"auv{msg.auv}"].send_signal(signal.SIGKILL)
                    ended = msg.kind == "end"
            if ended:
                stop(procs["channel"], timeout=5.0)
                log.wait_complete(inbound, scenario, timeout=5.0)
                if "recorder" in procs:
                    try:
                        procs["recorder"].wait(timeout=10.0)
                    except subprocess.TimeoutExpired:
                        stop(procs["recorder"], timeout=5.0)
    finally:
        for p in procs.values():
            stop(p, timeout=5.0)
        signal.signal(signal.SIGINT, previous)
        leftovers = [name for name, p in procs.items() if pid_alive(p.pid)]
        if leftovers:
            print(f"warning: processes still alive after stop: {leftovers}", file=sys.stderr)
    return not interrupted.is_set()


if __name__ == "__main__":
    sys.exit(main())
