"""``auv-swarm bench figure6 [--seeds N] [--duration S] [--out DIR] [--json]``: the paper's section 3.1 and Fig. 6.

Runs ``paper-3.1-scenario1``, ``-scenario2`` and ``-scenario3`` in process over seeds 1..N (default
10) on a pool of at most two processes, and draws the four panels of Fig. 6 in one PNG: (a, b, c)
the trajectories of seed 1 of scenarios 1, 2 and 3 with the source's, (d) J_g + J_d against time for
gamma 0.3 (scenario 2) and 0.8 (scenario 3), mean and min-max spread over the seeds. It prints, and
puts in the JSON, the figures of issue 27's items 2-4 (keys in docs/bench.md). Definitions, from the
true positions: J(t) = 1/sigma_min(Phi(t)) (eqs. 34-35) + the mean over AUVs of d_i / d*; its
settling time is the last time J is outside +-10 % of its mean over the final 60 s; the formation
spread is the mean over AUV pairs of the std of their distance over t >= 300 s, its fast part (the
wiggle) the same about each pair distance's 120 s moving mean. It also reports how close the AUVs
came to each other (against the safety distance d_S of eq. 50) and to the source after 300 s
(against d*), which eq. (50) checks only at the ends of the planning steps.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import tomllib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from auv_swarm.contract.config import ConfigError, load_scenario
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission import outdir

SCENARIOS = ("paper-3.1-scenario1", "paper-3.1-scenario2", "paper-3.1-scenario3")
LATE_S = 300.0
"""Figures of items 2 and 3 are taken over t >= LATE_S (s)."""
FINAL_S = 120.0
"""Item 4 is taken over the last FINAL_S seconds."""
SETTLE_WINDOW_S = 60.0
WIGGLE_WINDOW_S = 120.0
"""The formation wiggle is taken about each pair distance's moving mean over WIGGLE_WINDOW_S (s)."""
SETTLE_BAND = 0.10
MAX_WORKERS = 2


def one_run(name: str, seed: int, duration_s: float | None, keys: dict | None = None) -> dict:
    """The series and metrics of one in-process mission that the figures need (true positions, source, J);
    ``keys``: dotted scenario keys set first (``--set``)."""
    from auv_swarm.orchestrator.mission.api import run_mission

    scenario = load_scenario(name).with_keys(keys or {}).with_overrides(seed=seed, duration_s=duration_s)
    cpu0 = time.process_time()
    result = run_mission(scenario, mode="inprocess")
    cpu_s = time.process_time() - cpu0
    rec = result.record
    ids = sorted(rec.agents)
    return {
        "scenario": name,
        "seed": seed,
        "d_star_m": scenario.planner.d_star_m,
        "d_safe_m": scenario.planner.d_safe_m,
        "gamma": scenario.planner.gamma,
        "times": rec.times.tolist(),
        "target": rec.target[:, :2].tolist(),
        "positions": {str(i): rec.agents[i].position.tolist() for i in ids},
        "geometry_cost": rec.geometry_cost.tolist(),
        "metrics": result.metrics,
        "cpu_s": cpu_s,
    }


def series(run: dict) -> dict:
    """Numpy views of one run: times (T,), target (T, 2), positions (n, T, 2), ranges (n, T), J (T,)."""
    t = np.asarray(run["times"], dtype=float)
    tgt = np.asarray(run["target"], dtype=float).reshape(-1, 2)
    pos = np.array([run["positions"][k] for k in sorted(run["positions"], key=int)], dtype=float).reshape(-1, t.size, 2)
    rng = np.hypot(pos[..., 0] - tgt[:, 0], pos[..., 1] - tgt[:, 1])
    jg = np.asarray(run["geometry_cost"], dtype=float)
    j = jg + np.mean(rng, axis=0) / run["d_star_m"]
    return {"t": t - (t[0] if t.size else 0.0), "target": tgt, "pos": pos, "range": rng, "J": j, "Jg": jg}


def settling_time(t: np.ndarray, j: np.ndarray) -> float | None:
    """Last time (s) J is outside +-10 % of its mean over the final 60 s (0 if never); None without data."""
    ok = np.isfinite(j)
    if not ok.any():
        return None
    t, j = t[ok], j[ok]
    final = t >= t[-1] - SETTLE_WINDOW_S
    ref = float(np.mean(j[final]))
    out = np.abs(j - ref) > SETTLE_BAND * abs(ref)
    return float(t[out][-1]) if out.any() else 0.0


def formation_spread(t: np.ndarray, pos: np.ndarray) -> float | None:
    """Mean over AUV pairs of the std (m) of their distance over t >= LATE_S; None without samples."""
    late = t >= LATE_S - 1e-9
    if not late.any() or pos.shape[0] < 2:
        return None
    return float(np.mean([np.std(d) for d in _pair_distances(pos[:, late])]))


def _pair_distances(pos: np.ndarray) -> list[np.ndarray]:
    """Distance series (m) of every AUV pair, pos (n, T, 2)."""
    n = pos.shape[0]
    return [np.hypot(*(pos[a] - pos[b]).T) for a in range(n) for b in range(a + 1, n)]


def formation_wiggle(t: np.ndarray, pos: np.ndarray) -> float | None:
    """Mean over AUV pairs of the std (m) of their distance about its centred WIGGLE_WINDOW_S moving mean, t >= LATE_S.

    The fast part of :func:`formation_spread`: what remains once slow changes of the formation
    (an AUV moving to another place round the source) are taken out. None without a full window.
    """
    late = t >= LATE_S - 1e-9
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    k = int(round(WIGGLE_WINDOW_S / dt)) | 1 if dt > 0 else 0
    if pos.shape[0] < 2 or k < 3 or int(late.sum()) < k:
        return None
    stds = []
    for d in _pair_distances(pos[:, late]):
        mean = np.convolve(d, np.ones(k) / k, mode="valid")
        stds.append(float(np.std(d[k // 2 : k // 2 + mean.size] - mean)))
    return float(np.mean(stds))


def closest_pair_m(pos: np.ndarray) -> float | None:
    """Smallest distance (m) between any two AUVs over the whole series; None for fewer than two AUVs."""
    pairs = _pair_distances(pos)
    return float(min(d.min() for d in pairs)) if pairs and pos.shape[1] else None


def _mean(values: list) -> float | None:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(vals)) if vals else None


def item_figures(runs: dict[tuple[str, int], dict], seeds: list[int]) -> dict:
    """Issue 27's figures of items 2-4, per seed and as counts against the targets."""
    s1, s2, s3 = SCENARIOS
    d_star = runs[(s1, seeds[0])]["d_star_m"]
    per_seed = []
    for k in seeds:
        a, b, c = (series(runs[(s, k)]) for s in SCENARIOS)
        late1 = a["t"] >= LATE_S - 1e-9
        final1 = a["t"] >= a["t"][-1] - FINAL_S
        m1 = runs[(s1, k)]["metrics"]
        no_est = [ag.get("no_estimate_fraction_after_300s") for ag in m1["agents"].values()]
        jg_final = a["Jg"][final1]
        sigma_min = 1.0 / jg_final[np.isfinite(jg_final) & (jg_final > 0)]
        n = a["pos"].shape[0]
        ranges_final = np.mean(a["range"][:, final1], axis=1) if final1.any() else np.full(n, math.nan)
        sp2, sp3 = formation_spread(b["t"], b["pos"]), formation_spread(c["t"], c["pos"])
        safety = {}
        for tag, run in zip(("s1", "s2", "s3"), (a, b, c), strict=True):
            late = run["t"] >= LATE_S - 1e-9
            safety[f"{tag}_min_pair_distance_m"] = closest_pair_m(run["pos"])
            safety[f"{tag}_min_range_after_300s_m"] = float(np.min(run["range"][:, late])) if late.any() else None
        late3 = c["t"] >= LATE_S - 1e-9
        e2 = runs[(s2, k)]["metrics"]["tracking_error_mean_m"]
        e3 = runs[(s3, k)]["metrics"]["tracking_error_mean_m"]
        per_seed.append(
            {
                "seed": k,
                "s1_max_range_after_300s_m": float(np.max(a["range"][:, late1])) if late1.any() else None,
                "s1_max_no_estimate_fraction_after_300s": max((v for v in no_est if v is not None), default=None),
                "s1_sigma_min_final_mean": float(np.mean(sigma_min)) if sigma_min.size else None,
                "s1_sigma_min_optimum": math.sqrt(n / 2.0),
                "s1_mean_range_final_m": [float(r) for r in ranges_final],
                "s2_formation_spread_m": sp2,
                "s3_formation_spread_m": sp3,
                "s2_formation_wiggle_m": formation_wiggle(b["t"], b["pos"]),
                "s3_formation_wiggle_m": formation_wiggle(c["t"], c["pos"]),
                "s2_settling_s": settling_time(b["t"], b["J"]),
                "s3_settling_s": settling_time(c["t"], c["J"]),
                "s3_mean_range_after_300s_m": float(np.mean(c["range"][:, late3])) if late3.any() else None,
                "s2_tracking_error_m": e2,
                "s3_tracking_error_m": e3,
                **safety,
            }
        )
    count = len(seeds)

    def holds(cond) -> int:
        return sum(1 for p in per_seed if cond(p))

    item2_range = holds(
        lambda p: p["s1_max_range_after_300s_m"] is not None and p["s1_max_range_after_300s_m"] <= 2 * d_star
    )
    item2_noest = holds(
        lambda p: (
            p["s1_max_no_estimate_fraction_after_300s"] is not None
            and p["s1_max_no_estimate_fraction_after_300s"] <= 0.02
        )
    )
    item3_spread = holds(
        lambda p: (
            p["s2_formation_spread_m"]
            and p["s3_formation_spread_m"] is not None
            and p["s3_formation_spread_m"] <= 0.7 * p["s2_formation_spread_m"]
        )
    )
    item3_settle = holds(
        lambda p: (
            p["s2_settling_s"] is not None
            and p["s3_settling_s"] is not None
            and p["s3_settling_s"] > p["s2_settling_s"]
        )
    )
    item3_range = holds(
        lambda p: p["s3_mean_range_after_300s_m"] is not None and p["s3_mean_range_after_300s_m"] <= 2 * d_star
    )
    item3_error = holds(
        lambda p: (
            p["s2_tracking_error_m"] is not None
            and p["s3_tracking_error_m"] is not None
            and p["s3_tracking_error_m"] <= 1.2 * p["s2_tracking_error_m"]
        )
    )
    item4 = holds(
        lambda p: (
            p["s1_sigma_min_final_mean"] is not None
            and p["s1_sigma_min_final_mean"] >= 0.95 * p["s1_sigma_min_optimum"]
            and all(d_star <= r <= 2 * d_star for r in p["s1_mean_range_final_m"])
        )
    )
    pair_min = [p[f"{s}_min_pair_distance_m"] for p in per_seed for s in ("s1", "s2", "s3")]
    range_min = [p[f"{s}_min_range_after_300s_m"] for p in per_seed for s in ("s1", "s2", "s3")]
    d_safe = runs[(s1, seeds[0])]["d_safe_m"]
    return {
        "seeds": count,
        "per_seed": per_seed,
        "safety_min_pair_distance_m": min((v for v in pair_min if v is not None), default=None),
        "safety_missions_closer_than_d_safe": sum(1 for v in pair_min if v is not None and v < d_safe),
        "safety_min_range_after_300s_m": min((v for v in range_min if v is not None), default=None),
        "safety_missions_within_half_dstar_after_300s": sum(1 for v in range_min if v is not None and v < 0.5 * d_star),
        "item2_seeds_within_2dstar_after_300s": item2_range,
        "item2_seeds_no_estimate_after_300s_le_2pct": item2_noest,
        "item2_max_range_after_300s_m": max((p["s1_max_range_after_300s_m"] or 0.0) for p in per_seed),
        "item2_max_no_estimate_fraction_after_300s": max(
            (p["s1_max_no_estimate_fraction_after_300s"] or 0.0) for p in per_seed
        ),
        "item3_seeds_spread_30pct_lower": item3_spread,
        "item3_seeds_settling_later": item3_settle,
        "item3_seeds_s3_range_le_2dstar": item3_range,
        "item3_seeds_s3_error_le_1p2x": item3_error,
        "item3_spread_s2_mean_m": _mean([p["s2_formation_spread_m"] for p in per_seed]),
        "item3_spread_s3_mean_m": _mean([p["s3_formation_spread_m"] for p in per_seed]),
        "item3_wiggle_s2_mean_m": _mean([p["s2_formation_wiggle_m"] for p in per_seed]),
        "item3_wiggle_s3_mean_m": _mean([p["s3_formation_wiggle_m"] for p in per_seed]),
        "item4_seeds_at_optimum": item4,
        "item4_sigma_min_final_mean": _mean([p["s1_sigma_min_final_mean"] for p in per_seed]),
        "targets": {
            "item2_seeds_within_2dstar_after_300s": count,
            "item2_seeds_no_estimate_after_300s_le_2pct": count,
            "item3_seeds_spread_30pct_lower": math.ceil(0.8 * count),
            "item3_seeds_settling_later": math.ceil(0.7 * count),
            "item3_seeds_s3_range_le_2dstar": count,
            "item3_seeds_s3_error_le_1p2x": count,
            "item4_seeds_at_optimum": math.ceil(0.9 * count),
        },
    }


def figure(runs: dict[tuple[str, int], dict], seeds: list[int], path: Path) -> None:
    """Fig. 6 in one PNG: (a-c) seed-1 trajectories of scenarios 1-3 with the source, (d) J_g + J_d against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 10), constrained_layout=True)
    for ax, name, letter in zip(axes.flat[:3], SCENARIOS, "abc", strict=True):
        run = runs[(name, seeds[0])]
        s = series(run)
        ax.plot(s["target"][:, 0], s["target"][:, 1], "k--", lw=1.2, label="source (truth)")
        ax.plot(*s["target"][-1], "k*", ms=12)
        for i in range(s["pos"].shape[0]):
            (line,) = ax.plot(s["pos"][i, :, 0], s["pos"][i, :, 1], lw=1.2, label=f"AUV {i}")
            ax.plot(*s["pos"][i, 0], "o", color=line.get_color())
            ax.plot(*s["pos"][i, -1], "s", color=line.get_color())
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"({letter}) {name.replace('paper-3.1-', '')}: gamma {run['gamma']:g}, seed {seeds[0]}")
        ax.legend(fontsize=8, loc="best")
    ax = axes.flat[3]
    for name, colour in ((SCENARIOS[1], "tab:blue"), (SCENARIOS[2], "tab:red")):
        js = [series(runs[(name, k)]) for k in seeds]
        t = js[0]["t"]
        stack = np.array([s["J"][: t.size] for s in js])
        stack[~np.isfinite(stack)] = np.nan
        mean = np.nanmean(stack, axis=0)
        ax.plot(t, mean, color=colour, label=f"gamma {runs[(name, seeds[0])]['gamma']:g} (mean of {len(seeds)})")
        ax.fill_between(t, np.nanmin(stack, axis=0), np.nanmax(stack, axis=0), color=colour, alpha=0.2)
    ax.set_yscale("log")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("J_g + J_d = 1/sigma_min + mean d_i / d*")
    ax.set_title("(d) J_g + J_d, scenarios 2, 3 (band: min-max over seeds)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(v, spec: str = ".3g") -> str:
    return "-" if v is None else format(v, spec)


def text(out: dict) -> str:
    """The figures of items 2-4 against their targets, then one line per seed."""
    f, tg = out["figures"], out["figures"]["targets"]
    lines = [f"bench figure6: {f['seeds']} seed(s), {out['cpu_s']} s CPU, {out['wall_s']} s wall"]
    for key in tg:
        lines.append(f"  {key:<46} {f[key]:>3} of {f['seeds']}  (target >= {tg[key]})")
    for key in (
        "item2_max_range_after_300s_m",
        "item2_max_no_estimate_fraction_after_300s",
        "item3_spread_s2_mean_m",
        "item3_spread_s3_mean_m",
        "item3_wiggle_s2_mean_m",
        "item3_wiggle_s3_mean_m",
        "item4_sigma_min_final_mean",
        "safety_min_pair_distance_m",
        "safety_min_range_after_300s_m",
    ):
        lines.append(f"  {key:<46} {_fmt(f[key])}")
    missions = 3 * f["seeds"]
    lines.append(
        f"  {'safety_missions_closer_than_d_safe':<46} {f['safety_missions_closer_than_d_safe']:>3} of {missions}"
    )
    lines.append(
        f"  {'safety_missions_within_half_dstar_after_300s':<46} "
        f"{f['safety_missions_within_half_dstar_after_300s']:>3} of {missions}"
    )
    lines.append(
        "  seed  s1 max range  s1 no-est  s1 sigma_min  s2/s3 spread m  s2/s3 settle s  s3 range  s2/s3 error m"
    )
    for p in f["per_seed"]:
        lines.append(
            f"  {p['seed']:>4}  {_fmt(p['s1_max_range_after_300s_m'], '10.1f')}  "
            f"{_fmt(p['s1_max_no_estimate_fraction_after_300s'], '9.3f')}  {_fmt(p['s1_sigma_min_final_mean'], '12.3f')}  "
            f"{_fmt(p['s2_formation_spread_m'], '6.1f')}/{_fmt(p['s3_formation_spread_m'], '<6.1f')}  "
            f"{_fmt(p['s2_settling_s'], '6.0f')}/{_fmt(p['s3_settling_s'], '<6.0f')}  "
            f"{_fmt(p['s3_mean_range_after_300s_m'], '8.1f')}  "
            f"{_fmt(p['s2_tracking_error_m'], '.2f')}/{_fmt(p['s3_tracking_error_m'], '.2f')}"
        )
    return "\n".join(lines)


def toml_value(raw: str):
    """A ``--set`` value: a TOML value (number, boolean, array, quoted string), else the bare text as a string."""
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw.strip()


def parse_sets(items: list[str]) -> tuple[dict, dict[str, dict]]:
    """``--set`` arguments as (keys for all three scenarios, {scenario: its own keys}); ValueError names a bad one.

    ``KEY=VALUE`` sets KEY in every scenario; ``s1:KEY=VALUE`` (``s2:``, ``s3:``) in that scenario only, over
    the common value whatever the order."""
    prefixes = {f"s{i}": name for i, name in enumerate(SCENARIOS, start=1)}
    keys: dict = {}
    only: dict[str, dict] = {}
    for item in items:
        key, eq, raw = item.partition("=")
        prefix, colon, key = key.strip().rpartition(":")
        if not eq or not key.strip():
            raise ValueError(f"--set takes [s1:|s2:|s3:]KEY=VALUE, got {item!r}")
        if colon and prefix not in prefixes:
            raise ValueError(f"--set: unknown scenario prefix {prefix!r} in {item!r} (s1, s2 or s3)")
        (only.setdefault(prefixes[prefix], {}) if colon else keys)[key.strip()] = toml_value(raw)
    return keys, only


def main(argv: list[str]) -> int:
    """Run the three section 3.1 scenarios over seeds 1..N, write figure6.png (and figure6.json) to --out, print the figures."""
    parser = argparse.ArgumentParser(prog="auv-swarm bench figure6", description=plain_description(__doc__))
    parser.add_argument("--seeds", type=int, default=10, help="seeds 1..N per scenario (default 10)")
    parser.add_argument("--duration", type=float, default=None, help="override run.duration_s (sim seconds)")
    parser.add_argument("--out", type=Path, default=None, help="write figure6.png and figure6.json here")
    parser.add_argument("--force", action="store_true", help="write into --out even if it already holds results")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="[sN:]KEY=VALUE",
        help="set a scenario key in all three scenarios, VALUE in TOML (repeatable; e.g. planner.leg_constraint=arc); "
        "prefixed s1:, s2: or s3: (s3:planner.connectivity=topology), in that scenario only",
    )
    args = parser.parse_args(argv)
    if args.seeds < 1:
        return fail(f"--seeds must be >= 1, got {args.seeds}")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        return fail(f"--duration must be a positive number of seconds, got {args.duration}")
    try:
        keys, only = parse_sets(args.set)
    except ValueError as exc:
        return fail(str(exc))
    scenario_keys = {name: {**keys, **only.get(name, {})} for name in SCENARIOS}
    try:
        for name in SCENARIOS:
            load_scenario(name).with_keys(scenario_keys[name]).with_overrides(duration_s=args.duration)
        if args.out is not None:
            outdir.prepare(args.out, force=args.force)
    except (ConfigError, outdir.OutDirError) as exc:
        return fail(str(exc))
    seeds = list(range(1, args.seeds + 1))
    jobs = [(s, k, args.duration, scenario_keys[s]) for s in SCENARIOS for k in seeds]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=min(MAX_WORKERS, len(jobs))) as pool:
        done = list(pool.map(one_run, *zip(*jobs, strict=True)))
    runs = {(r["scenario"], r["seed"]): r for r in done}
    out = {
        "scenarios": list(SCENARIOS),
        "seeds": args.seeds,
        "duration_s": args.duration,
        "keys": keys,
        "scenario_keys": {name: only[name] for name in SCENARIOS if name in only},
        "wall_s": round(time.perf_counter() - start, 1),
        "cpu_s": round(sum(r["cpu_s"] for r in done), 1),
        "figures": item_figures(runs, seeds),
    }
    if args.out is not None:
        figure(runs, seeds, args.out / "figure6.png")
        (args.out / "figure6.json").write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(out))
    else:
        print(text(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
