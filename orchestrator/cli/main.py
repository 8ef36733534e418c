"""The ``auv-swarm`` command line: one entry point, each verb in its own module.

Every verb is ``module:function`` taking the remaining argv and returning an exit
code, so a process can equally be started as ``python -m <package>``.
"""

from __future__ import annotations

import importlib
import os
import sys
import time

STARTED = time.perf_counter()
"""When the command started (``time.perf_counter()``, as this module is imported): where a run's wall time
(``run_wall_time_s``) counts from."""

EXIT_CLOSED_PIPE = 141
"""Exit code when the reader of stdout went away (``auv-swarm scenarios | head -1``): 128 + SIGPIPE, as a shell reports."""

VERBS: dict[str, tuple[str, str]] = {
    "run": ("auv_swarm.orchestrator.cli.run", "run a mission (default scenario paper-3.2-challenging)"),
    "sweep": (
        "auv_swarm.orchestrator.cli.sweep",
        "a grid of missions on Dask into a resumable store (sweep.sqlite; docs/sweeps.md)",
    ),
    "scenarios": ("auv_swarm.orchestrator.cli.run:scenarios_main", "list the built-in scenarios"),
    "ocean": (
        "auv_swarm.orchestrator.cli.ocean",
        "a physical scenario's ocean: profile, TL field, SNR, delivery and detection against range (docs/ocean.md)",
    ),
    "bench": ("auv_swarm.bench:main", "benchmarks, each a bench of its own (listed below; auv-swarm bench --help)"),
    "drill": ("auv_swarm.orchestrator.cli.drill", "kill-a-process failure drills and their report"),
    "router": ("auv_swarm.orchestrator.mission.router", "run the zenoh router with access control"),
    "credentials": (
        "auv_swarm.bus.credentials",
        "write fresh per-process password files and the router's user table, or certificates (--tls, --dask)",
    ),
    "world": ("auv_swarm.world.node", "run the world (ground truth and clock) process"),
    "channel": ("auv_swarm.channel_sim.node", "run the acoustic channel emulator process"),
    "agent": ("auv_swarm.agent.node", "run one AUV process"),
    "central": ("auv_swarm.central.node", "run the central planner process (centralised MPC baseline only)"),
    "recorder": ("auv_swarm.recorder.node", "run the rerun recorder process (recording.rrd, live viewer)"),
    "collect": (
        "auv_swarm.orchestrator.mission.collector",
        "run the results writer process (metrics.json, events, plots)",
    ),
    "compose": ("auv_swarm.orchestrator.cli.compose", "write a docker-compose file for N AUVs"),
    "view": ("auv_swarm.orchestrator.cli.view", "open a past run's recording in the rerun viewer"),
    "export": (
        "auv_swarm.orchestrator.cli.export",
        "a run's tracks as CSV, Parquet or MCAP (Foxglove, rerun); a sweep's store as CSV or Parquet",
    ),
    "compare": (
        "auv_swarm.orchestrator.cli.compare",
        "runs side by side: their metrics and scenario keys that differ, compare.png of their team error",
    ),
}


def benches() -> dict[str, tuple[str, str]]:
    """The benches of ``auv-swarm bench`` (name -> module, one line), read from the bench verb's own module as the
    dispatch does (this layer imports no bench statically)."""
    module = importlib.import_module(VERBS["bench"][0].partition(":")[0])
    return dict(module.BENCHES)


def _usage() -> str:
    """The top-level help: every verb of :data:`VERBS`, then every bench."""
    lines = ["usage: auv-swarm VERB [options]   (auv-swarm VERB --help for a verb's options)", "", "verbs:"]
    lines += [f"  {verb:<12} {doc}" for verb, (_, doc) in VERBS.items()]
    lines += ["", "benches (auv-swarm bench NAME [options]):"]
    lines += [f"  {name:<12} {doc}" for name, (_, doc) in benches().items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``auv-swarm VERB ...`` to the verb's module; a reader of stdout that went away ends it quietly."""
    try:
        try:
            code = _dispatch(list(sys.argv[1:] if argv is None else argv))
        finally:
            sys.stdout.flush()  # here, not at the interpreter's exit, so that a closed pipe is caught below
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_CLOSED_PIPE
    return code


def _dispatch(args: list[str]) -> int:
    if not args:
        print(f"auv-swarm: a verb is required\n\n{_usage()}", file=sys.stderr)
        return 2
    if args[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0
    verb, rest = args[0], args[1:]
    if verb not in VERBS:
        print(f"auv-swarm: unknown verb {verb!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    from auv_swarm.orchestrator.cli.logtee import start_from_env

    start_from_env()
    target = VERBS[verb][0]
    module_name, _, func_name = target.partition(":")
    try:
        module = importlib.import_module(module_name)
        return int(getattr(module, func_name or "main")(rest) or 0)
    except KeyboardInterrupt:
        print(f"\nauv-swarm {verb}: interrupted", file=sys.stderr)
        return 130


def _quiet_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's last flush does not fail on the closed pipe again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


if __name__ == "__main__":
    sys.exit(main())
