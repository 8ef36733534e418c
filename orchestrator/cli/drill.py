"""``auv-swarm drill``: kill-a-process failure drills, each a processes-mode mission with one fault.

Every drill runs the scenario (default ``paper-3.2-challenging``) in processes mode,
injects its fault after the team has converged (at ``--fault-at`` of the mission,
default 45 %), and checks what the swarm promises (docs/drills.md). The report goes
to ``--out`` (default ``runs/drill-<timestamp>/``): ``drill-report.md``,
``drill-report.json`` (``{"drills": [{"name": ..., "passed": ..., ...}]}``), one
folder of results per drill and ``<name>.png`` (team error against time, fault
marked). Exit 0 only if every drill passed, 1 otherwise, 2 on bad usage.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from auv_swarm.contract.config import DEFAULT_SCENARIO, ConfigError, Fault, Scenario, dump_toml, load_scenario
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission.procs import children_of
from auv_swarm.orchestrator.mission.supervise import Outcome
from auv_swarm.results.channel_books import frame_balance, link_balance
from auv_swarm.results.metrics import team_error, tracking_errors
from auv_swarm.results.record import RunRecord

VICTIM = 2
"""The AUV the AUV drills hurt."""
MAX_DETECTION_MS = 1000.0
"""kill -9 of an AUV must be detected within this wall time."""
MAX_REJOIN_FRAMES = 3.0
"""A restarted AUV must send again (its state and plan, in its TDMA slot), and be in a neighbour's plan again,
within this many TDMA frames of its rejoin."""
RECONVERGE_WITHIN_S = 300.0
"""A restarted AUV's own error must be under ``run.convergence_error_m`` within this sim time of its rejoin."""


@dataclass(frozen=True)
class Trial:
    """What one drill's mission left, as the drill's checks read it: the scenario run, its record, metrics and
    outcome, the fault time (sim s) and every AUV's tracking error against ``rec.times`` (m)."""

    scenario: Scenario
    rec: RunRecord
    metrics: dict[str, Any]
    outcome: Outcome
    fault_at_s: float
    errors: dict[int, np.ndarray]

    @property
    def threshold(self) -> float:
        """``run.convergence_error_m`` (m)."""
        return self.scenario.run.convergence_error_m

    @property
    def injected(self) -> dict[str, Any] | None:
        """The first fault the launcher injected (its sim time ``t_s`` and wall time ``wall``), or None."""
        return self.outcome.injected[0] if self.outcome.injected else None

    @property
    def events(self) -> list[tuple[Any, float]]:
        """The world's events about the victim or the whole team, with their wall time (s)."""
        return [(ev, wall) for ev, wall in self.outcome.events if ev.auv == VICTIM or ev.auv == -1]


Check = Callable[[Trial, dict[str, Any]], dict[str, bool]]
"""A drill's own checks: adds the drill's figures to its report entry and returns its checks by name."""


@dataclass(frozen=True)
class Drill:
    """One drill: its fault (scheduled in the scenario, or injected by the launcher unannounced) and checks."""

    name: str
    summary: str
    scheduled: Callable[[float], tuple[Fault, ...]] = lambda at: ()
    external: Callable[[float], tuple[Fault, ...]] = lambda at: ()
    expect_complete: bool = True
    on_slot: bool = False
    """The fault falls at the start of the first TDMA slot at or after the fault time, when the slot's owner
    has just handed the channel a frame: the restart-channel drill always has frames to account for."""
    check: Check = lambda trial, entry: {}
    """The drill's own checks, after those every mission drill has (complete or not, no process left, results
    readable)."""
    runner: Callable[[Drill, Scenario, Path, float], dict[str, Any]] | None = None
    """A drill that is not one mission with a fault runs itself (``runner(drill, base, out, fault_at_s)``
    returns its whole report entry)."""


def _death_detected(t: Trial, entry: dict[str, Any]) -> dict[str, bool]:
    """kill-auv: the world declares the AUV dead within :data:`MAX_DETECTION_MS` of the kill (wall time) and
    the survivors keep their error under the threshold."""
    death = next(((ev, wall) for ev, wall in t.events if ev.kind == "death"), None)
    if death is not None and t.injected is not None:
        entry["detection_ms"] = round(1000.0 * (death[1] - float(t.injected["wall"])), 1)
        entry["detection_ticks"] = round((death[0].t_s - float(t.injected["t_s"])) / t.scenario.run.tick_s)
    survivors = entry["survivors_error_mean_m"]
    return {
        "death_detected_within_1_s": entry.get("detection_ms", math.inf) <= MAX_DETECTION_MS,
        "survivors_under_threshold": survivors is not None and survivors < t.threshold,
    }


def _rejoined(t: Trial, entry: dict[str, Any]) -> dict[str, bool]:
    """restart-auv: the AUV rejoins, sends and is in a neighbour's plan within :data:`MAX_REJOIN_FRAMES` TDMA
    frames, and (when the mission lasts long enough) its own error is under the threshold within
    :data:`RECONVERGE_WITHIN_S`."""
    rejoin = next((ev for ev, _wall in t.events if ev.kind == "rejoin"), None)
    if rejoin is None:
        return {"rejoined": False, "sends_within_3_frames": False, "state_in_neighbours_plans_within_3_frames": False}
    back = rejoin.t_s
    frame_s = t.scenario.channel.slot_s * t.scenario.agents.count
    entry["rejoin_t_s"] = back
    for key, at in _rejoin_chain(t.rec, t.errors[VICTIM], back).items():
        if at is not None:
            entry[f"rejoin_to_{key}_frames"] = round((at - back) / frame_s, 2)
    checks = {
        "rejoined": True,
        "sends_within_3_frames": entry.get("rejoin_to_frame_frames", math.inf) <= MAX_REJOIN_FRAMES,
        "state_in_neighbours_plans_within_3_frames": entry.get("rejoin_to_in_plans_frames", math.inf)
        <= MAX_REJOIN_FRAMES,
    }
    own = _first_under(t.rec.times, t.errors[VICTIM], t.threshold, back)
    entry["own_error_under_threshold_after_s"] = None if own is None else own - back
    if t.rec.times[-1] - back >= RECONVERGE_WITHIN_S:
        checks["own_error_under_threshold_within_300_s"] = own is not None and own - back <= RECONVERGE_WITHIN_S
    return checks


def _hung_and_resumed(t: Trial, entry: dict[str, Any]) -> dict[str, bool]:
    """stop-auv: the AUV is reported hung, resumes before the end, and is never declared lost."""
    victim = t.metrics["agents"][str(VICTIM)]
    hung = victim["hung_intervals_s"]
    return {
        "reported_hung": bool(hung),
        "resumed": bool(hung) and hung[0][1] < t.metrics["sim_duration_s"],
        "not_lost": victim["alive_until_s"] is None,
    }


def _no_auv_lost(t: Trial, entry: dict[str, Any]) -> dict[str, bool]:
    """restart-router: no AUV is declared lost."""
    return {"no_auv_lost": not entry["agents_lost"]}


def _no_auv_lost_and_every_link_accounted(t: Trial, entry: dict[str, Any]) -> dict[str, bool]:
    """restart-channel: no AUV is declared lost, and the channel's books balance (:func:`_books`)."""
    return {"no_auv_lost": not entry["agents_lost"], "every_link_accounted": entry["channel_books"]["balanced"]}


def run_drill(drill: Drill, base: Scenario, fault_at_s: float, out: Path) -> dict[str, Any]:
    """Run one drill into ``out`` and return its report entry."""
    out.mkdir(parents=True, exist_ok=True)
    if drill.on_slot:
        fault_at_s = slot_start_at_or_after(base, fault_at_s)
    if drill.runner is not None:
        return drill.runner(drill, base, out, fault_at_s)
    from auv_swarm.orchestrator.mission.api import Launch, run_mission
    from auv_swarm.orchestrator.mission.procs import pid_alive

    scenario = base.replace(name=f"drill-{drill.name}", faults=drill.scheduled(fault_at_s))
    result = run_mission(scenario, mode="processes", out=out, launch=Launch(external_faults=drill.external(fault_at_s)))
    record, metrics, outcome = result.record, result.metrics, result.outcome
    left = [c for c in children_of(os.getpid()) if pid_alive(c)]
    entry = _measure(drill, Trial(scenario, record, metrics, outcome, fault_at_s, tracking_errors(record)))
    entry["processes_left"] = len(left)
    entry["results_readable"] = _readable(out)
    entry["checks"]["no_process_left"] = not left
    entry["checks"]["results_readable"] = entry["results_readable"]
    entry["passed"] = all(entry["checks"].values())
    _plot(record, fault_at_s, drill, out.parent / f"{drill.name}.png", outcome.injected)
    return entry


def slot_start_at_or_after(scenario: Scenario, t_s: float) -> float:
    """The first TDMA slot start at or after ``t_s`` (sim s), on a tick (slot starts are multiples of
    ``channel.slot_s``)."""
    slot, tick = scenario.channel.slot_s, scenario.run.tick_s
    start = math.ceil(t_s / slot - 1e-9) * slot
    return math.ceil(start / tick - 1e-9) * tick


def _books(metrics: dict, counters: dict[str, int], n_agents: int) -> dict[str, Any]:
    """The channel's books of the run (``results.channel_books``): both sides of the per-link identity
    ``sent * (n - 1) == delivered + link drops + in_flight_at_end``, and the frames the senders said they sent
    against the frames the channel accounts for."""
    ch = metrics["channel"]
    senders, channel = frame_balance(counters)
    sent_links, accounted = link_balance(ch["dropped"], ch["sent"], ch["delivered"], ch["in_flight_at_end"], n_agents)
    return {
        "sent_links": sent_links,
        "delivered": ch["delivered"],
        "lost_links": accounted - ch["delivered"] - ch["in_flight_at_end"],
        "in_flight_at_end": ch["in_flight_at_end"],
        "balanced": sent_links == accounted,
        "frames_senders": senders,
        "frames_channel": channel,
    }


def _measure(drill: Drill, t: Trial) -> dict[str, Any]:
    """The figures of one mission drill and its checks (docs/drills.md): those every drill has, then the drill's
    own (:attr:`Drill.check`)."""
    metrics = t.metrics
    injected = t.injected
    entry: dict[str, Any] = {
        "name": drill.name,
        "summary": drill.summary,
        "injected": {
            "t_s": injected["t_s"] if injected else t.fault_at_s,
            "faults": [dataclasses.asdict(f) for f in drill.scheduled(t.fault_at_s) + drill.external(t.fault_at_s)],
        },
        "complete": metrics["complete"],
        "incomplete_reason": metrics["incomplete_reason"],
        "exit_code": metrics["exit_code"],
        "sim_duration_s": metrics["sim_duration_s"],
        "frames_lost_by_reason": metrics["channel"]["dropped"],
        "channel_books": _books(metrics, t.rec.channel_counters, t.scenario.agents.count),
        "agents_lost": [a for a, m in metrics["agents"].items() if m["alive_until_s"] is not None],
        "alive_intervals_s": {a: m["alive_intervals_s"] for a, m in metrics["agents"].items()},
        "hung_intervals_s": {a: m["hung_intervals_s"] for a, m in metrics["agents"].items() if m["hung_intervals_s"]},
    }
    if drill.expect_complete:
        checks = {"complete": metrics["complete"]}
    else:
        checks = {"incomplete_and_says_so": not metrics["complete"] and metrics["exit_code"] == 1}
    after = t.rec.times >= t.fault_at_s
    survivors = [t.errors[a][after] for a in t.errors if a != VICTIM]
    surv = np.concatenate(survivors) if survivors else np.empty(0)
    surv = surv[np.isfinite(surv)]
    entry["survivors_error_mean_m"] = float(np.mean(surv)) if surv.size else None
    team = team_error(t.errors, len(t.rec.times))
    reconverge = _first_under(t.rec.times, team, t.threshold, t.fault_at_s)
    entry["team_reconverged_after_s"] = None if reconverge is None else reconverge - t.fault_at_s
    checks.update(drill.check(t, entry))
    entry["checks"] = checks
    return entry


def _rejoin_chain(rec: RunRecord, own_error: np.ndarray, back: float) -> dict[str, float | None]:
    """When (sim s), after the rejoin at ``back``, the restarted AUV: put its first frame on the air (``frame``:
    its state, for the neighbours that receive it); was first in a neighbour's plan (``in_plans``: the first plan a
    neighbour made after receiving one of its frames, so with its fresh state); first heard a neighbour (``heard``:
    the bearings it carries; alone, at rest, its own bearings leave the range unobservable); first had an estimate
    (``estimate``); first planned (``plan``: at its first slot start with an estimate); had its plan first in a
    neighbour's plan (``plan_in_plans``: the first plan a neighbour made after receiving a frame it sent at or
    after its first plan)."""
    packets = [e for e in rec.events if e["t_s"] >= back]
    sent = {e["correlation_id"]: e["t_s"] for e in packets if e["kind"] == "packet_sent" and e.get("sender") == VICTIM}
    heard = [e["t_s"] for e in packets if e["kind"] == "packet_delivered" and e.get("recipient") == VICTIM]
    valid = np.flatnonzero((rec.times >= back) & np.isfinite(own_error))
    plan = min((t for t in rec.agents[VICTIM].plan_times_s if t >= back), default=None)

    def neighbour_plans_after(frames: set[str]) -> float | None:
        """The first plan of a neighbour made at or after it received one of ``frames``."""
        firsts = []
        for j, series in rec.agents.items():
            got = [
                e["t_s"]
                for e in packets
                if e["kind"] == "packet_delivered" and e.get("recipient") == j and e["correlation_id"] in frames
            ]
            if got:
                firsts += [t for t in series.plan_times_s if t >= min(got)][:1]
        return min(firsts, default=None)

    return {
        "frame": min(sent.values(), default=None),
        "in_plans": neighbour_plans_after(set(sent)),
        "heard": min(heard, default=None),
        "estimate": float(rec.times[valid[0]]) if valid.size else None,
        "plan": plan,
        "plan_in_plans": None if plan is None else neighbour_plans_after({c for c, t in sent.items() if t >= plan}),
    }


def _first_under(times: np.ndarray, error: np.ndarray, threshold: float, after_s: float) -> float | None:
    """The first sim time at or after ``after_s`` when ``error`` is at or under ``threshold`` (None if never)."""
    ok = (times >= after_s) & np.isfinite(error) & (error <= threshold)
    idx = np.flatnonzero(ok)
    return float(times[idx[0]]) if idx.size else None


KILL_LAUNCHER_WALL_S = 8.0
"""Wall time the kill-launcher drill's mission is paced to last (s)."""


def _kill_launcher(drill: Drill, base: Scenario, out: Path, fault_at_s: float) -> dict[str, Any]:
    """``auv-swarm run`` as a child, SIGKILLed once the mission passed ``fault_at_s``; count what is left."""
    scenario = base.replace(name=f"drill-{drill.name}")
    path = out / "input.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    run_dir = out / "run"
    # Paced so the mission lasts KILL_LAUNCHER_WALL_S of wall time on any machine: the kill then falls
    # at ``fault_at_s`` of sim time, mid-mission, however fast the lockstep would run unpaced.
    speed = scenario.run.duration_s / KILL_LAUNCHER_WALL_S
    argv = [sys.executable, "-m", "auv_swarm", "run", "--quiet", "--scenario", str(path), "--out", str(run_dir)]
    proc = subprocess.Popen(
        [*argv, "--speed", f"{speed:g}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    world_log = run_dir / "logs" / "world.log"
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline and proc.poll() is None:
        if world_log.exists() and "starting" in world_log.read_text(errors="replace"):
            break
        time.sleep(0.05)
    time.sleep(fault_at_s / speed)
    children = children_of(proc.pid)
    killed_at = time.monotonic()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    while children_of(proc.pid) and time.monotonic() - killed_at < 5.0:
        time.sleep(0.1)
    left = children_of(proc.pid)
    gone_s = time.monotonic() - killed_at
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    readable = _rrd_readable(run_dir / "recording.rrd")
    checks = {"children_started": len(children) >= 5, "no_process_left": not left, "recording_readable": readable}
    return {
        "name": drill.name,
        "summary": drill.summary,
        "injected": {"what": "SIGKILL of auv-swarm run", "children": len(children)},
        "processes_left": len(left),
        "all_gone_within_s": round(gone_s, 2) if not left else None,
        "results_readable": readable,
        "checks": checks,
        "passed": all(checks.values()),
    }


CATALOGUE: tuple[Drill, ...] = (
    Drill(
        "kill-auv",
        "kill -9 of AUV 2 from outside, unannounced to the world",
        external=lambda at: (Fault(at_s=at, target=f"auv:{VICTIM}", action="kill"),),
        check=_death_detected,
    ),
    Drill(
        "restart-auv",
        "AUV 2 killed and started again 60 sim s later (a scheduled restart)",
        scheduled=lambda at: (Fault(at_s=at, target=f"auv:{VICTIM}", action="restart", down_s=60.0),),
        check=_rejoined,
    ),
    Drill(
        "stop-auv",
        "AUV 2 stopped (SIGSTOP) for 60 sim s, then continued (SIGCONT)",
        scheduled=lambda at: (Fault(at_s=at, target=f"auv:{VICTIM}", action="stop", duration_s=60.0),),
        check=_hung_and_resumed,
    ),
    Drill(
        "restart-channel",
        "the channel killed at the start of a TDMA slot and started again 0.5 s later",
        scheduled=lambda at: (Fault(at_s=at, target="channel", action="restart", down_s=0.5),),
        on_slot=True,
        check=_no_auv_lost_and_every_link_accounted,
    ),
    Drill(
        "restart-router",
        "the router killed and started again 0.5 s later",
        scheduled=lambda at: (Fault(at_s=at, target="router", action="restart", down_s=0.5),),
        check=_no_auv_lost,
    ),
    Drill(
        "kill-world",
        "kill -9 of the world: the run must say it is incomplete",
        scheduled=lambda at: (Fault(at_s=at, target="world", action="kill"),),
        expect_complete=False,
    ),
    Drill("kill-launcher", "kill -9 of auv-swarm run itself: no process may be left 5 s later", runner=_kill_launcher),
)
NAMES = tuple(d.name for d in CATALOGUE)


def _readable(out: Path) -> bool:
    try:
        json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return _rrd_readable(out / "recording.rrd")


def _rrd_readable(path: Path) -> bool:
    """True if the recording opens and holds at least one chunk (a recording cut by kill -9 included)."""
    try:
        from rerun.chunk import RrdReader

        return any(True for _ in RrdReader(str(path)).stream())
    except Exception:  # noqa: BLE001 - any failure to read is "not readable", reported, never raised
        return False


SYMLOG_LINEAR_M = 20.0
"""The drill plot's error axis is linear up to this many metres and logarithmic above (``symlog``)."""


def _plot(rec: RunRecord, fault_at_s: float, drill: Drill, path: Path, injected: list[dict[str, Any]]) -> None:
    """Team error against sim time, the fault, every restart of a component and every AUV's rejoin marked."""
    from auv_swarm.results.report import figure

    fig = figure(figsize=(7, 3.5))
    ax = fig.add_subplot(1, 1, 1)
    errors = tracking_errors(rec)
    ax.plot(rec.times, team_error(errors, len(rec.times)), label="team mean")
    if VICTIM in errors:
        ax.plot(rec.times, errors[VICTIM], lw=0.8, alpha=0.7, label=f"AUV {VICTIM}")
    ax.axvline(fault_at_s, color="red", ls="--", label=f"fault ({drill.name})")
    restarts = [f["t_s"] for f in injected if f.get("action") == "restart"]
    rejoins = [e["t_s"] for e in rec.events if e.get("kind") == "rejoin"]
    for k, t in enumerate(restarts):
        ax.axvline(t, color="purple", ls="-.", lw=1.0, label="restarted" if k == 0 else None)
    for k, t in enumerate(rejoins):
        ax.axvline(t, color="green", ls=":", lw=1.2, label="AUV rejoined" if k == 0 else None)
    ax.axhline(rec.scenario.run.convergence_error_m, color="grey", ls=":", label="threshold")
    ax.set_xlabel("sim time (s)")
    ax.set_yscale("symlog", linthresh=SYMLOG_LINEAR_M)
    ax.set_ylabel(f"tracking error (m)\nlinear below {SYMLOG_LINEAR_M:g} m, log above", fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(drill.summary, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def report_markdown(entries: list[dict[str, Any]]) -> str:
    """The drill report as Markdown: one summary table, then each drill's figures."""
    lines = [
        "# Drill report",
        "",
        "| drill | passed | detection | rejoin | lost | complete | left |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in entries:
        detection = f"{e['detection_ms']:g} ms ({e['detection_ticks']} ticks)" if "detection_ms" in e else "-"
        rejoin = f"{e['rejoin_to_frame_frames']:g} frames" if "rejoin_to_frame_frames" in e else "-"
        lost = ", ".join(e.get("agents_lost", [])) or "-"
        lines.append(
            f"| {e['name']} | {'yes' if e['passed'] else '**no**'} | {detection} | {rejoin} | {lost} | "
            f"{e.get('complete', '-')} | {e['processes_left']} |"
        )
    for e in entries:
        lines += ["", f"## {e['name']}", "", e["summary"], ""]
        lines += [f"- {k}: {'pass' if v else 'FAIL'}" for k, v in e["checks"].items()]
        for key in (
            "survivors_error_mean_m",
            "team_reconverged_after_s",
            "own_error_under_threshold_after_s",
            "rejoin_to_heard_frames",
            "rejoin_to_estimate_frames",
            "rejoin_to_plan_frames",
            "rejoin_to_in_plans_frames",
            "rejoin_to_plan_in_plans_frames",
            "frames_lost_by_reason",
            "channel_books",
            "hung_intervals_s",
            "incomplete_reason",
            "all_gone_within_s",
        ):
            if key in e:
                lines.append(f"- {key}: {e[key]}")
        if e["name"] != "kill-launcher":
            lines.append(f"\n![{e['name']}]({e['name']}.png)")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the catalogue (or ``--only NAME``) and write the report; 0 if every drill passed, 1 otherwise."""
    parser = argparse.ArgumentParser(prog="auv-swarm drill", description=plain_description(__doc__))
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO, help="built-in scenario name or TOML path")
    parser.add_argument("--duration", type=float, default=900.0, help="mission length of every drill (sim s)")
    parser.add_argument("--fault-at", type=float, default=0.45, help="fault time as a fraction of the mission")
    parser.add_argument("--only", action="append", choices=NAMES, help="run only this drill (repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="report folder (default runs/drill-<timestamp>)")
    parser.add_argument("--json", action="store_true", help="print the JSON report on stdout")
    args = parser.parse_args(argv)
    if not 0.0 < args.fault_at < 1.0:
        parser.error(f"--fault-at must be in (0, 1), got {args.fault_at}")
    try:
        base = load_scenario(args.scenario).with_overrides(duration_s=args.duration)
    except ConfigError as exc:
        return fail(str(exc))
    base = base.replace(kills=(), faults=())
    if base.agents.count <= VICTIM:
        return fail(f"the drills hurt AUV {VICTIM}: the scenario needs at least {VICTIM + 1} AUVs")
    out = args.out or Path("runs") / f"drill-{datetime.now().strftime('%Y%m%d-%H%M%S')}"
    out.mkdir(parents=True, exist_ok=True)
    fault_at_s = round(args.fault_at * args.duration / base.run.tick_s) * base.run.tick_s
    entries = []
    for drill in CATALOGUE:
        if args.only and drill.name not in args.only:
            continue
        print(f"drill {drill.name}: {drill.summary} ...", file=sys.stderr, flush=True)
        entry = run_drill(drill, base, fault_at_s, out / drill.name)
        print(f"drill {drill.name}: {'passed' if entry['passed'] else 'FAILED'} {entry['checks']}", file=sys.stderr)
        entries.append(entry)
    report = {"scenario": base.name, "duration_s": args.duration, "fault_at_s": fault_at_s, "drills": entries}
    (out / "drill-report.json").write_text(json.dumps(report, indent=2, default=str) + "\n", encoding="utf-8")
    (out / "drill-report.md").write_text(report_markdown(entries), encoding="utf-8")
    if args.json:
        print(json.dumps(report, default=str))
    print(f"drill report in {out}", file=sys.stderr)
    return 0 if all(e["passed"] for e in entries) else 1


if __name__ == "__main__":
    sys.exit(main())
