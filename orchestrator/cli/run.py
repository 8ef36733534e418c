"""``auv-swarm run``: one mission (:func:`auv_swarm.run_mission`) into a results folder, with its summary.

``--mode processes`` (default) starts the zenoh router, the world, the channel
emulator and one process per AUV as separate OS processes on loopback
(:mod:`~auv_swarm.orchestrator.mission.launcher`). ``--mode inprocess`` runs the same cores
and tick protocol in this process. Both write the same results folder.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from datetime import datetime
from pathlib import Path

from auv_swarm.bus.credentials import CredentialError
from auv_swarm.contract.config import DEFAULT_SCENARIO, ConfigError, Scenario, builtin_scenarios, load_scenario
from auv_swarm.contract.faults import after_end
from auv_swarm.contract.usage import fail
from auv_swarm.orchestrator.cli.main import STARTED
from auv_swarm.orchestrator.cli.view import add_web_args, wait_for_interrupt, web_bind, web_ports
from auv_swarm.orchestrator.mission import outdir
from auv_swarm.orchestrator.mission.api import Launch, LaunchError, MissionWarning, check_runnable, run_mission
from auv_swarm.orchestrator.mission.launcher import launcher_credentials
from auv_swarm.orchestrator.mission.progress import Progress
from auv_swarm.recorder import web
from auv_swarm.results.summary import summary_table

DESCRIPTION = (
    "Run one mission and write its results folder (metrics.json, events.jsonl, plots, recording.rrd). "
    "--mode processes (default) starts the zenoh router, the world, the channel emulator, the recorder and "
    "one process per AUV on loopback; --mode inprocess runs the same cores in this process (faster, same metrics)."
)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="auv-swarm run", description=DESCRIPTION)
    parser.add_argument(
        "scenario_arg", nargs="?", default=None, metavar="SCENARIO", help=f"the scenario (default {DEFAULT_SCENARIO})"
    )
    parser.add_argument("--scenario", default=None, help="built-in scenario name or TOML path, as SCENARIO")
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
    parser.add_argument(
        "--tls",
        action="store_true",
        help="processes mode over mutual TLS: a certificate per process, made for this run, instead of passwords "
        "(how the swarm runs across hosts, docs/deploy.md)",
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
    """The scenario with the CLI overrides, checked runnable in ``--mode`` before any process starts (ConfigError
    if not).

    Kills and faults naming an AUV beyond ``--agents`` are dropped with a warning; a scenario file that names an
    AUV beyond its own ``agents.count`` is an error (from the config's validation). A kill or fault after the
    mission's end (``--duration`` shorter than the scenario's schedule, or a typo) is a warning naming it.
    """
    base = load_scenario(scenario_name(args))
    if args.agents is not None and args.agents >= 1:  # a count out of range is with_overrides' one line below
        team = f"--agents {args.agents} runs AUVs 0..{args.agents - 1}"
        for i, k in enumerate(base.kills):
            if k.agent >= args.agents:
                print(f"warning: kills[{i}] names AUV {k.agent}, but {team}: that kill is dropped", file=sys.stderr)
        for i, f in enumerate(base.faults):
            if f.auv is not None and f.auv >= args.agents:
                print(f"warning: faults[{i}] names {f.target}, but {team}: that fault is dropped", file=sys.stderr)
    scenario = base.with_overrides(seed=args.seed, duration_s=args.duration, agents=args.agents)
    for line in after_end(base, scenario.run.duration_s, scenario.agents.count):
        print(f"warning: {line}", file=sys.stderr)
    check_runnable(scenario, args.mode)
    return scenario


def scenario_name(args: argparse.Namespace) -> str:
    """The scenario named positionally or with ``--scenario`` (the default when neither); ConfigError if both are
    given and differ."""
    given, option = getattr(args, "scenario_arg", None), args.scenario
    if given is not None and option is not None and given != option:
        raise ConfigError(f"two scenarios given: {given!r} and --scenario {option!r}; give one")
    return given or option or DEFAULT_SCENARIO


def launch_from(args: argparse.Namespace) -> Launch:
    """The :class:`Launch` the flags ask for; ConfigError naming the flag (``--restart``, ``--speed``,
    ``--rerun-url``). The credentials, and the web viewer's URL with ``--web``, are added when known."""
    try:
        restart_delay_s = parse_restart(args.restart)
    except ValueError as exc:
        raise ConfigError(f"--restart: {exc}") from None
    if args.mode == "inprocess" and (args.speed or restart_delay_s is not None):
        flag = "--speed" if args.speed else "--restart"
        raise ConfigError(f"{flag} applies to --mode processes; --mode inprocess runs as fast as it can in one process")
    if args.tls and (args.mode != "processes" or args.credentials is not None):
        raise ConfigError("--tls goes with --mode processes and without --credentials (its certificates are the login)")
    try:
        return Launch(
            speed=args.speed,
            viewer=args.viewer,
            rerun_url=args.rerun_url,
            restart_delay_s=restart_delay_s,
            tls=args.tls,
        )
    except LaunchError as exc:
        raise ConfigError(f"--{exc.field.replace('_', '-')}{exc.problem}") from None


def main(argv: list[str] | None = None) -> int:
    """Run one mission and write metrics.json, events.jsonl and plots; exit 0 complete, 1 incomplete, 2 bad input,
    130 interrupted (docs/exit-codes.md)."""
    args = parse_args(argv)
    try:
        scenario = load_checked(args)
        launch = launch_from(args)
    except ConfigError as exc:
        return fail(str(exc))
    try:
        creds = launcher_credentials(scenario.agents.count, args.credentials)
    except CredentialError as exc:
        return fail(str(exc))
    try:
        ports = web_ports(args) if args.web is not None else None
        bind = web_bind(args) if args.web is not None else web.LOOPBACK
    except ValueError as exc:
        return fail(str(exc))
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    try:
        out = outdir.prepare(args.out or Path("runs") / f"{scenario.name}-{stamp}", force=args.force)
    except outdir.OutDirError as exc:
        return fail(str(exc))
    viewer = launch.viewer and viewer_possible(out)
    rerun_url = web.proxy_url(web.local_host(bind), ports[1]) if ports is not None else launch.rerun_url
    launch = dataclasses.replace(launch, viewer=viewer, rerun_url=rerun_url, credentials=creds)
    web_viewer: list = []  # the web viewer's process; mission() replaces it by one serving the finished recording
    if ports is not None:
        try:
            web_viewer.append(web.start(*ports, out / "logs" / "web-viewer.log", bind=bind))
        except (RuntimeError, FileNotFoundError) as exc:
            return fail(str(exc), 1)
        print(f"web viewer: open {web.page_url(web.public_host(bind), *ports)}", flush=True)
    try:
        return mission(
            scenario, out, args.mode, launch, quiet=args.quiet, ports=ports, web_viewer=web_viewer, bind=bind
        )
    finally:
        for proc in web_viewer:
            web.stop(proc)


def mission(
    scenario: Scenario,
    out: Path,
    mode: str,
    launch: Launch,
    *,
    quiet: bool,
    ports: tuple[int, int] | None,
    web_viewer: list | None = None,
    bind: str = web.LOOPBACK,
) -> int:
    """Run the mission (``scenario`` checked runnable in ``mode`` by :func:`load_checked`), print its summary;
    with the web viewer on, keep serving until Ctrl-C. The exit code.

    At the end the web viewer is restarted on the same ports serving the finished, compacted
    ``recording.rrd`` (``web.serve_recording``): its proxy had kept every small chunk of the live stream,
    which a page opened afterwards loads one by one (minutes for a long run), the file's few large
    chunks in seconds (issue 28 item 6).
    """
    progress = Progress("mission", scenario.run.duration_s, "s sim time", enabled=not quiet)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MissionWarning)  # load_checked printed them, before any process started
        result = run_mission(
            scenario, mode=mode, out=out, progress=progress, launch=launch, checked=True, started=STARTED
        )
    walls = result.metrics
    progress.close(f"mission wall {walls['wall_time_s']:.1f} s, run wall {walls['run_wall_time_s']:.1f} s")
    if launch.viewer and mode == "processes":
        relay_viewer_warnings(out / "logs" / "recorder.log")
    print(summary_table(result.metrics))
    print(f"results in {out}")
    outcome = result.outcome
    if not outcome.complete:
        print(f"run incomplete ({outcome.reason}): {outcome.line}", file=sys.stderr)
    if ports is not None and outcome.reason != "interrupted":
        url = web.page_url(web.public_host(bind), *ports)
        rrd = out / "recording.rrd"
        if web_viewer and rrd.is_file():
            try:
                log = out / "logs" / "web-viewer.log"
                web_viewer[0] = web.serve_recording(web_viewer[0], *ports, log, rrd, bind=bind)
            except RuntimeError as exc:
                print(f"warning: the web viewer could not reload the finished recording: {exc}", file=sys.stderr)
                return result.exit_code
        print(f"mission over; the web viewer keeps serving {url} (the finished recording) until Ctrl-C", flush=True)
        wait_for_interrupt()
    return result.exit_code


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


if __name__ == "__main__":
    sys.exit(main())
