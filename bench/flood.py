"""``auv-swarm bench flood [--scenario S] [--duration S] [--seeds A-B|N] [--auv A] [--frames F] [--bytes B]
[--order before|after|both] [--json]``.

One AUV floods its own uplink (issue 28): besides its own frames it submits ``--frames`` frames of
``--bytes`` bytes (a payload no recipient can decode) on every tick, before its own frames or after them
(``--order``; issue 44: which frames the channel keeps must not depend on which came first), through the
in-process swarm (the
same channel model, node and intake gate as the processes run). Its commands count only its own frames, as
when a second client floods the AUV's key: the channel refuses the undeclared frames (``tx_undeclared``) before
the model; what a sender declares is held by the transmit backlog bound (``tx_backlog_full``, unit-tested).
The channel's time per tick is its thread's CPU time, which other processes on the machine do not inflate. For each seed the mission runs without
and with the flood and the bench reports: the frames the channel put on the air and refused by reason
(``tx_backlog_full`` among them), the links still in flight at the end, the other AUVs' mean tracking
error in both runs and their ratio, and the channel's mean CPU time per tick over the last 60 ticks
against the first 60. Targets: the others' error within 10 % of the run without the flood, the tick
time ratio at most 1.5 (on ``paper-3.2-challenging``, 300 s, seeds 1-3).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import time
from dataclasses import dataclass
from typing import Any

FLOOD_SEQ0 = 1_000_000_000
"""First ``seq`` of the flood's frames: far above any the AUV's own counter reaches."""
WINDOW_TICKS = 60
"""Ticks averaged at each end of the mission for the channel's time per tick."""
ERROR_TARGET = 1.10
TICK_TIME_TARGET = 1.5
REFUSALS = (
    "dropped_tx_backlog_full",
    "tx_undeclared",
    "tx_over_rate",
    "tx_over_budget",
    "tx_queue_full",
    "tx_replay",
    "tx_late",
)
"""The channel's counters of refused frames the bench reports (the model's, the intake's and the gate's)."""


@dataclass(frozen=True)
class Flood:
    """Who floods and how: ``frames`` extra frames of ``nbytes`` bytes per tick from AUV ``auv``; its commands
    count only its own frames, as when a second client floods the AUV's key."""

    auv: int
    frames: int
    nbytes: int
    order: str = "after"
    """``before``: the flood goes out before the AUV's own frames of the tick; ``after``: after them."""


def _flooding_node(flood: Flood) -> Any:
    """An ``agent_node`` factory for ``run_inprocess``: AUV ``flood.auv`` publishes the flood before its own frames
    of every tick or after them (``flood.order``), always before its command."""
    from auv_swarm.agent.node import AgentNode
    from auv_swarm.contract import wire

    class FloodingNode(AgentNode):
        def _run(self, msg: wire.Message) -> list[tuple[str, wire.Message]]:
            own = super()._run(msg)
            cmd = next((m for _, m in own if isinstance(m, wire.Command)), None)
            if cmd is None:
                return own
            junk = [
                (
                    wire.modem_tx(cmd.auv),
                    wire.ModemTx(
                        t_s=cmd.t_s,
                        source=cmd.source,
                        tick=cmd.tick,
                        auv=cmd.auv,
                        seq=FLOOD_SEQ0 + cmd.tick * flood.frames + i,
                        payload=bytes([i % 256]) * flood.nbytes,
                    ),
                )
                for i in range(flood.frames)
            ]
            if flood.order == "before":
                return junk + own
            at = next(i for i, (_, m) in enumerate(own) if m is cmd)
            return own[:at] + junk + own[at:]

    def make(core: Any) -> AgentNode:
        return FloodingNode(core) if core.auv == flood.auv else AgentNode(core)

    return make


def _timed_channel(times: list[float]) -> Any:
    """A ``channel_node`` class for ``run_inprocess`` that appends the CPU time (s) of every tick it runs."""
    from auv_swarm.channel_sim.node import ChannelNode

    class TimedChannel(ChannelNode):
        def _run_tick(self, msg: Any, txs: list) -> None:
            start = time.thread_time()
            super()._run_tick(msg, txs)
            times.append(time.thread_time() - start)

    return TimedChannel


def one_run(scenario: Any, flood: Flood | None) -> dict[str, Any]:
    """One in-process mission (with ``flood`` or without): its metrics, channel counters and tick times."""
    from auv_swarm.agent.node import AgentNode
    from auv_swarm.orchestrator.mission.inprocess import run_inprocess
    from auv_swarm.results.collect import MessageLog
    from auv_swarm.results.metrics import compute_metrics

    log, times = MessageLog(), []
    start = time.perf_counter()
    node = AgentNode if flood is None else _flooding_node(flood)
    run_inprocess(scenario, [log], agent_node=node, channel_node=_timed_channel(times))
    record = log.to_record(scenario, "inprocess", time.perf_counter() - start)
    return {"metrics": compute_metrics(record), "counters": dict(record.channel_counters), "tick_s": times}


def _mean(values: list[float]) -> float:
    return sum(values) / len(values) if values else float("nan")


def compare(scenario: Any, flood: Flood) -> dict[str, Any]:
    """The seed's run without and with the flood, and the figures of the module docstring."""
    calm, flooded = one_run(scenario, None), one_run(scenario, flood)
    others = [a for a in sorted(flooded["metrics"]["agents"], key=int) if int(a) != flood.auv]
    errors = {}
    for a in others:
        before = calm["metrics"]["agents"][a]["tracking_error_mean_m"]
        after = flooded["metrics"]["agents"][a]["tracking_error_mean_m"]
        errors[a] = {"without_m": before, "with_m": after, "ratio": after / before if before and after else None}
    ticks = flooded["tick_s"]
    first, last = _mean(ticks[:WINDOW_TICKS]), _mean(ticks[-WINDOW_TICKS:])
    c = flooded["counters"]
    return {
        "seed": scenario.run.seed,
        "frames_on_air": {"without": calm["counters"].get("sent", 0), "with": c.get("sent", 0)},
        "refused": {k: c.get(k, 0) for k in REFUSALS},
        "in_flight_at_end": {
            "without": calm["counters"].get("in_flight_at_end", 0),
            "with": c.get("in_flight_at_end", 0),
        },
        "others_error": errors,
        "others_error_worst_ratio": max((e["ratio"] for e in errors.values() if e["ratio"] is not None), default=None),
        "channel_tick_first_ms": 1e3 * first,
        "channel_tick_last_ms": 1e3 * last,
        "channel_tick_ratio": last / first if first > 0 else None,
        "ticks": len(ticks),
    }


def _table(result: dict[str, Any]) -> str:
    f = result["flood"]
    lines = [
        f"{result['scenario']}, {result['duration_s']:g} s: AUV {f['auv']} floods {f['frames']} frames of "
        f"{f['nbytes']} bytes per tick (not counted by its commands), {f['order']} its own frames",
        "seed  on air (calm/flood)  refused backlog/undeclared/queue/budget  in flight end  others' error m (without -> with)"
        "  worst  tick ms first/last  ratio",
    ]
    for r in result["runs"]:
        ref = r["refused"]
        errs = ", ".join(
            f"AUV {a} {e['without_m']:.1f} -> {e['with_m']:.1f}" for a, e in r["others_error"].items() if e["with_m"]
        )
        worst = "-" if r["others_error_worst_ratio"] is None else f"{r['others_error_worst_ratio']:.3f}"
        ratio = "-" if r["channel_tick_ratio"] is None else f"{r['channel_tick_ratio']:.2f}"
        lines.append(
            f"{r['seed']:>4}  {r['frames_on_air']['without']:>5} / {r['frames_on_air']['with']:<5}"
            f"        {ref['dropped_tx_backlog_full']:>5} / {ref['tx_undeclared']} / {ref['tx_queue_full']} / "
            f"{ref['tx_over_budget']}   {r['in_flight_at_end']['without']:>3} / {r['in_flight_at_end']['with']:<3}"
            f"   {errs}  {worst}  {r['channel_tick_first_ms']:.3f} / {r['channel_tick_last_ms']:.3f}"
            f"  {ratio}"
        )
    pooled = result["others_error_pooled_m"]
    lines.append(
        f"others' error over every seed: {pooled['without']:.1f} m without the flood, {pooled['with']:.1f} m with it"
    )
    lines.append(
        f"targets: others' error within {ERROR_TARGET:.2f}x ({'met' if result['error_target_met'] else 'NOT met'}), "
        f"tick time ratio <= {TICK_TIME_TARGET:g} ({'met' if result['tick_target_met'] else 'NOT met'})"
    )
    return "\n".join(lines)


def run(name: str, duration_s: float, seeds: list[int], flood: Flood) -> dict[str, Any]:
    """Every seed's comparison, one mission at a time (one order of the flood)."""
    from auv_swarm.contract.config import load_scenario

    base = load_scenario(name).with_overrides(duration_s=duration_s)
    runs = [compare(base.with_overrides(seed=s), flood) for s in seeds]
    pooled = {
        side: _mean([e[f"{side}_m"] for r in runs for e in r["others_error"].values() if e[f"{side}_m"] is not None])
        for side in ("without", "with")
    }
    return {
        "scenario": base.name,
        "duration_s": duration_s,
        "flood": dataclasses.asdict(flood),
        "runs": runs,
        "others_error_pooled_m": pooled,
        "error_target_met": all((r["others_error_worst_ratio"] or 0.0) <= ERROR_TARGET for r in runs),
        "tick_target_met": all((r["channel_tick_ratio"] or 0.0) <= TICK_TIME_TARGET for r in runs),
    }


def main(argv: list[str]) -> int:
    """``auv-swarm bench flood``: see the module docstring."""
    from auv_swarm.contract.config import ConfigError, load_scenario
    from auv_swarm.contract.usage import SEEDS_HELP, fail, parse_seeds, plain_description

    parser = argparse.ArgumentParser(prog="auv-swarm bench flood", description=plain_description(__doc__))
    parser.add_argument("--scenario", default="paper-3.2-challenging", help="scenario name or TOML path")
    parser.add_argument("--duration", type=float, default=300.0, help="mission length (s of sim time, default 300)")
    parser.add_argument("--seeds", default="1-3", help=f"{SEEDS_HELP} (default 1-3)")
    parser.add_argument("--auv", type=int, default=1, help="the AUV that floods its uplink (default 1)")
    parser.add_argument("--frames", type=int, default=60, help="extra frames per tick (default 60)")
    parser.add_argument("--bytes", type=int, default=9, help="bytes per extra frame (default 9: 16 fit a slot)")
    parser.add_argument(
        "--order",
        choices=("before", "after", "both"),
        default="both",
        help="the flood goes out before the AUV's own frames of each tick, after them, or both runs (default both)",
    )
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object on stdout (a list with --order both)"
    )
    args = parser.parse_args(argv)
    if args.duration <= 0:
        parser.error(f"--duration must be > 0 s, got {args.duration:g}")
    if args.frames < 1 or args.bytes < 1:
        parser.error(f"--frames and --bytes must be >= 1, got {args.frames} and {args.bytes}")
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        return fail(str(exc))
    try:
        scenario = load_scenario(args.scenario)
    except ConfigError as exc:
        return fail(f"--scenario: {exc}")
    if args.auv not in scenario.slot_order:
        parser.error(f"--auv must be one of the scenario's AUVs {list(scenario.slot_order)}, got {args.auv}")
    logging.getLogger("channel").setLevel(logging.ERROR)  # the refusals are counted in the table
    orders = ("before", "after") if args.order == "both" else (args.order,)
    results = [run(args.scenario, args.duration, seeds, Flood(args.auv, args.frames, args.bytes, o)) for o in orders]
    if args.json:
        print(json.dumps(results if len(results) > 1 else results[0]))
    else:
        print("\n\n".join(_table(r) for r in results))
    return 0
