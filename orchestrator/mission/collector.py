"""``auv-swarm collect``: the results writer as a process of its own (the ``collector`` service of compose).

It listens on the bus as ``auv-swarm run`` does (zenoh user ``orchestrator``:
truth, telemetry, packet events, channel counters, world events), holds a
liveliness token so the world waits for it, and when the world announces the
end writes the same results folder as ``auv-swarm run`` (metrics.json,
events.jsonl, the PNGs) through :mod:`auv_swarm.results.collect` and
:mod:`auv_swarm.results.metrics`, and judges the run as ``auv-swarm run`` does
(:class:`orchestrator.supervise.Supervisor`). Its exit status is the mission's
exit code, also in metrics.json (``exit_code``, ``complete``,
``incomplete_reason``): 0 complete, 1 incomplete (the world aborted, or vanished
before the end for longer than ``--grace-s``, or never came up), 130 interrupted.

``auv-swarm collect --prepare`` is the one-shot that comes first under compose:
it picks the run folder (``RUNS/RUN_ID``, else ``RUNS/<scenario>-<timestamp>``),
refuses one that holds results unless ``--force`` (env ``FORCE=1``), writes scenario.toml there (the
scenario every service then loads) and points ``RUNS/latest`` at it.
"""

from __future__ import annotations

import argparse
import os
import queue
import secrets
import signal
import socket
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

from auv_swarm.bus import credentials
from auv_swarm.bus.shell import add_common_args, connect, handle_info_flags, scenario_from_args
from auv_swarm.contract import wire
from auv_swarm.contract.config import DEFAULT_SCENARIO, ConfigError, Scenario, dump_toml, load_scenario
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission import outdir
from auv_swarm.orchestrator.mission.listen import RESULT_KEYS, supervised, supervisor_for
from auv_swarm.orchestrator.mission.supervise import Outcome
from auv_swarm.results.collect import MessageLog
from auv_swarm.results.report import write_results
from auv_swarm.results.summary import summary_table

LATEST = "latest"
"""The symlink in the runs folder naming the run being prepared or run (relative, so it resolves on the host too)."""

COMPOSE_FAULTS = {("auv", "kill")}
"""(target kind, action) pairs of scheduled faults a compose stack can carry out without a launcher."""


def compose_refusal(scenario: Scenario, agents: int | None = None) -> str | None:
    """Why ``scenario`` cannot run under a compose file for ``agents`` AUVs, or None when it can.

    A scheduled AUV kill works (the AUV's process exits, its container stops); any other
    scheduled fault needs the launcher of ``auv-swarm run``.
    """
    if agents is not None and scenario.agents.count != agents:
        return (
            f"scenario {scenario.name!r} has {scenario.agents.count} AUVs but this compose file runs {agents}: "
            f"write one for it with `auv-swarm compose --agents {scenario.agents.count}` "
            f"and use it with `docker-compose -f docker-compose.{scenario.agents.count}.yml up`"
        )
    if scenario.planner.method == "centralised":
        return (
            "planner.method = 'centralised' needs the central planner process that `auv-swarm run` starts; "
            "the compose file has no service for it"
        )
    for i, fault in enumerate(getattr(scenario, "faults", ()) or ()):
        target = str(getattr(fault, "target", ""))
        action = str(getattr(fault, "action", ""))
        if (target.partition(":")[0], action) not in COMPOSE_FAULTS:
            return (
                f"faults[{i}] ({action} {target}) needs the launcher of `auv-swarm run`: under compose only "
                "scheduled AUV kills run; use `docker-compose kill/stop/restart SERVICE` by hand for the others"
            )
    return None


def in_container() -> bool:
    """Docker puts ``/.dockerenv`` in every container."""
    return Path("/.dockerenv").exists()


def restarted_setup(runs: Path, run_id: str | None) -> Path | None:
    """The run folder this very container prepared, if its mission has not ended, else None.

    ``docker compose start agent1`` (v2) starts the one-shot services it depends on again;
    the setup container restarted mid-mission must then leave the run alone (no new folder,
    no refusal, no FORCE wipe). Recognised by the stamp :data:`PREPARED_STAMP` naming this
    container (its hostname) in the folder ``latest`` points at; only inside a container."""
    if not in_container():
        return None
    try:
        current = (runs / LATEST).resolve(strict=True)
        stamp = (current / credentials.PREPARED_STAMP).read_text(encoding="utf-8").split()
    except OSError:
        return None
    same_run = run_id is None or run_id == current.name
    ended = (current / "metrics.json").exists()
    return current if stamp[:1] == [socket.gethostname()] and same_run and not ended else None


def prepare(runs: Path, run_id: str | None, force: bool, scenario: Scenario, agents: int | None) -> tuple[int, str]:
    """Create the run folder and scenario.toml, point ``runs/latest`` at it; (exit code, message)."""
    refusal = compose_refusal(scenario, agents)
    if refusal is not None:
        return 2, f"error: {refusal}"
    again = restarted_setup(runs, run_id)
    if again is not None:
        return 0, f"run folder {again} already prepared by this container; its mission goes on"
    name = run_id or f"{scenario.name}-{datetime.now().strftime('%Y%m%d-%H%M%S')}"
    if name in (LATEST, ".", "..") or "/" in name:
        return 2, f"error: RUN_ID must be a plain folder name (not {LATEST!r}), got {name!r}"
    try:
        out = outdir.prepare(runs / name, force=force, flag="RUN_ID folder")
    except outdir.OutDirError as exc:
        return 2, f"error: {exc} (under compose: another RUN_ID, or FORCE=1)"
    (out / "logs").mkdir(parents=True, exist_ok=True)
    (out / "scenario.toml").write_text(dump_toml(scenario), encoding="utf-8")
    stamp = f"{socket.gethostname()} {secrets.token_hex(8)}\n"  # the run's identity for `credentials --run-folder`
    (out / credentials.PREPARED_STAMP).write_text(stamp, encoding="utf-8")
    link = runs / LATEST
    tmp = runs / f".{LATEST}.{os.getpid()}"
    tmp.unlink(missing_ok=True)
    tmp.symlink_to(name)
    tmp.replace(link)
    return 0, f"run folder {out} ready for {scenario.name} (seed {scenario.run.seed}, {scenario.agents.count} AUVs)"


def listen(
    bus: object, scenario: Scenario, stop: threading.Event, wait_s: float, grace_s: float
) -> tuple[MessageLog, Outcome, float]:
    """Collect until the world ends the mission or the run fails; (log, outcome, mission wall seconds).

    The run is judged as ``auv-swarm run`` judges it (:class:`orchestrator.supervise.Supervisor`:
    the world's ``abort``, a silent world), and besides: the world not up within ``wait_s``
    (``start_failed``), or its liveliness token gone longer than ``grace_s`` before the end
    (``world_died``). The mission's wall time runs from the world's start event to its end event.
    """
    log = MessageLog()
    sup = supervisor_for(scenario.run)
    inbound: queue.Queue[object] = queue.Queue()
    world_key = wire.liveliness_component("world")
    world: dict[str, object] = {"seen": False, "lost_at": None}

    def on_bytes(_key: str, data: bytes) -> None:
        try:
            inbound.put(wire.decode(data))
        except wire.DecodeError as exc:
            log.malformed += 1
            print(f"collector: dropped malformed message: {exc}", file=sys.stderr, flush=True)

    def on_alive(key: str, alive: bool) -> None:
        if key == world_key:
            world["seen"] = world["seen"] or alive
            world["lost_at"] = None if alive else time.monotonic()

    for key in RESULT_KEYS:
        bus.subscribe(key, on_bytes)
    bus.subscribe_liveliness(world_key, on_alive)
    bus.declare_liveliness(wire.liveliness_component("orchestrator"))
    print(f"collector ready: collecting {scenario.name}", flush=True)
    started = time.monotonic()
    t_start = t_end = None
    said = 0
    for now, msg in supervised(inbound, log, sup, stop):
        if isinstance(msg, wire.WorldEvent):
            if msg.kind == "start" and t_start is None:
                t_start = now
                print(f"collector: mission started at unix time {time.time():.3f}", flush=True)
            elif msg.kind in ("end", "abort"):
                t_end = now
                print(f"collector: mission {msg.kind}ed at unix time {time.time():.3f}", flush=True)
        if not world["seen"] and now - started > wait_s:
            sup.fail("start_failed", f"the world did not come up within {wait_s:g} s")
        lost_at = world["lost_at"]
        if lost_at is not None and now - lost_at > grace_s and not sup.ended:
            reason = "world_died" if sup.started else "start_failed"
            sup.fail(reason, f"the world's liveliness has been gone {grace_s:g} s at t = {sup.t_s:g} s")
        sup.on_wall(now)
        for line in sup.lines[said:]:
            print(f"collector: {line}", file=sys.stderr, flush=True)
        said = len(sup.lines)
    if sup.ended:
        log.wait_complete(inbound, scenario, timeout=5.0)
    outcome = sup.final()
    for line in sup.lines[said:]:
        print(f"collector: {line}", file=sys.stderr, flush=True)
    wall = (t_end or time.monotonic()) - (t_start or started)
    return log, outcome, wall


def _env_number(name: str, kind: type, given: float | None) -> float | None:
    """``given`` if set, else the environment variable ``name`` (empty = unset), parsed as ``kind``."""
    if given is not None:
        return given
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    try:
        return kind(text)
    except ValueError:
        raise ValueError(f"{name} must be {'an integer' if kind is int else 'a number'}, got {text!r}") from None


def _prepared_scenario(args: argparse.Namespace) -> Scenario:
    """The scenario of ``--prepare``: --scenario/--seed/--duration, else env SCENARIO/SEED/DURATION."""
    name = os.environ.get("SCENARIO", "").strip() if args.scenario == DEFAULT_SCENARIO else args.scenario
    return load_scenario(name or DEFAULT_SCENARIO).with_overrides(
        seed=_env_number("SEED", int, args.seed), duration_s=_env_number("DURATION", float, args.duration)
    )


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm collect``."""
    parser = argparse.ArgumentParser(prog="auv-swarm collect", description=plain_description(__doc__))
    add_common_args(parser)
    parser.add_argument("--out", type=Path, default=None, help="results folder (metrics.json, events.jsonl, PNGs)")
    parser.add_argument("--wait-s", type=float, default=120.0, help="wall seconds to wait for the world to come up")
    parser.add_argument(
        "--grace-s", type=float, default=None, help="wall s the world may be gone (default: the scenario's run.grace_s)"
    )
    parser.add_argument(
        "--host-runs",
        default=None,
        help="the runs folder as the host names it (compose: ${RUNS_DIR:-./runs}); the last line names the run there",
    )
    parser.add_argument("--prepare", action="store_true", help="only create the run folder (compose's first step)")
    parser.add_argument("--runs", type=Path, default=Path("runs"), help="with --prepare: the runs folder")
    parser.add_argument("--run-id", default=os.environ.get("RUN_ID") or None, help="with --prepare: env RUN_ID")
    parser.add_argument("--force", action="store_true", help="with --prepare: overwrite an existing run folder")
    parser.add_argument("--compose-agents", type=int, default=None, help="with --prepare: the compose file's AUVs")
    args = parser.parse_args(argv)
    if handle_info_flags(args, "orchestrator"):
        return 0
    if args.prepare:
        try:
            scenario = _prepared_scenario(args)
        except (ConfigError, ValueError) as exc:
            return fail(str(exc))
        force = args.force or os.environ.get("FORCE", "0") not in ("", "0")
        code, message = prepare(args.runs, args.run_id, force, scenario, args.compose_agents)
        print(message, file=sys.stderr if code else sys.stdout, flush=True)
        return code
    if args.out is None:
        return fail("--out DIR is required (the results folder)")
    scenario = scenario_from_args(args)

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    bus = connect(args, "orchestrator")
    with bus:
        grace_s = scenario.run.grace_s if args.grace_s is None else args.grace_s
        log, outcome, wall = listen(bus, scenario, stop, args.wait_s, grace_s)
    record = log.to_record(scenario, "compose", wall)
    record.set_outcome(outcome.complete, outcome.reason, outcome.exit_code)
    metrics = write_results(record, args.out)
    print(summary_table(metrics), flush=True)
    code = outcome.exit_code
    where = args.out if args.host_runs is None else f"{args.host_runs.rstrip('/')}/{args.out.resolve().name}"
    print(f"results in {where}; mission exit code {code}" + (f" ({outcome.reason})" if code else ""), flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
