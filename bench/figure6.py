"""``auv-swarm bench figure6 [--seeds A-B|N] [--duration S] [--out DIR] [--json]``: the paper's section 3.1 and Fig. 6.

Runs ``paper-3.1-scenario1``, ``-scenario2`` and ``-scenario3`` in process over the seeds (default 1-10) on a
pool of at most two processes, and scenario 3 once more under the paper's literal reading of eq. (37) (the dB
SNR Laplacian, no anchor: :data:`LITERAL_KEYS`), beside the built-in's documented departure (the
``"topology"`` reading with a drifting anchor, docs/studies/section-3.1.md). It draws Fig. 6 in one PNG: (a, b,
c) the trajectories of the first seed of scenarios 1, 2 and 3 with the source's, (c') scenario 3 under the
literal reading, (d) J_g + J_d against time for gamma 0.3 (scenario 2) and 0.8 (scenario 3, both readings),
mean and min-max spread over the seeds, (e) the formation spread per seed. It prints, and puts in the JSON,
the figures of issues 27 and 46 (keys in docs/bench.md). Definitions, from the true positions: J(t) =
1/sigma_min(Phi(t)) (eqs. 34-35) + the mean over AUVs of d_i / d*; its settling time is the last time J is
outside +-10 % of its mean over the final 60 s; the formation spread is the mean over AUV pairs of the std of
their distance over t >= 300 s, its fast part (the wiggle) the same about each pair distance's 120 s moving
mean. It also reports how close the AUVs came to each other (against the safety distance d_S of eq. 50) and to
the source after 300 s (against d*), which eq. (50) checks only at the ends of the planning steps.
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
from auv_swarm.contract.usage import SEEDS_HELP, fail, parse_seeds, plain_description, seeds_text
from auv_swarm.orchestrator.mission import outdir

SCENARIOS = ("paper-3.1-scenario1", "paper-3.1-scenario2", "paper-3.1-scenario3")
LITERAL = "paper-3.1-scenario3-literal"
"""The label of scenario 3 run under the paper's literal reading of eq. (37), beside the built-in's departure."""
LITERAL_KEYS = {"planner.connectivity": "db", "planner.anchor_tau_s": 0.0}
"""The keys that undo the built-in scenario 3's departure: the dB SNR Laplacian of eqs. (22)-(26), no anchor."""
RUNS = (*SCENARIOS, LITERAL)
"""Every run label of the bench, in order."""
LATE_S = 300.0
"""Figures of items 2 and 3 are taken over t >= LATE_S (s)."""
FINAL_S = 120.0
"""Item 4 is taken over the last FINAL_S seconds."""
SETTLE_WINDOW_S = 60.0
WIGGLE_WINDOW_S = 120.0
"""The formation wiggle is taken about each pair distance's moving mean over WIGGLE_WINDOW_S (s)."""
SETTLE_BAND = 0.10
MAX_WORKERS = 2


def base_scenario(label: str) -> str:
    """The built-in scenario a run label stands for (:data:`LITERAL` is scenario 3)."""
    return SCENARIOS[2] if label == LITERAL else label


def one_run(name: str, seed: int, duration_s: float | None, keys: dict | None = None) -> dict:
    """The series and metrics of one in-process mission that the figures need (true positions, source, J);
    ``name`` a label of :data:`RUNS`; ``keys``: dotted scenario keys set first (``--set``)."""
    from auv_swarm.orchestrator.mission.api import run_mission

    keys = {**(keys or {}), **(LITERAL_KEYS if name == LITERAL else {})}
    scenario = load_scenario(base_scenario(name)).with_keys(keys).with_overrides(seed=seed, duration_s=duration_s)
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
        "connectivity": scenario.planner.connectivity,
        "anchor_tau_s": scenario.planner.anchor_tau_s,
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


def _scenario1_seed(run: dict, s: dict) -> dict:
    """Scenario 1's figures of one seed (items 2 and 4): ranges after 300 s, no-estimate share, final geometry."""
    late = s["t"] >= LATE_S - 1e-9
    final = s["t"] >= s["t"][-1] - FINAL_S
    no_est = [ag.get("no_estimate_fraction_after_300s") for ag in run["metrics"]["agents"].values()]
    jg_final = s["Jg"][final]
    sigma_min = 1.0 / jg_final[np.isfinite(jg_final) & (jg_final > 0)]
    n = s["pos"].shape[0]
    ranges_final = np.mean(s["range"][:, final], axis=1) if final.any() else np.full(n, math.nan)
    return {
        "s1_max_range_after_300s_m": float(np.max(s["range"][:, late])) if late.any() else None,
        "s1_max_no_estimate_fraction_after_300s": max((v for v in no_est if v is not None), default=None),
        "s1_sigma_min_final_mean": float(np.mean(sigma_min)) if sigma_min.size else None,
        "s1_sigma_min_optimum": math.sqrt(n / 2.0),
        "s1_mean_range_final_m": [float(r) for r in ranges_final],
    }


def _gamma_seed(tag: str, run: dict, s: dict) -> dict:
    """One gamma scenario's figures of one seed (item 3), keys prefixed ``tag`` (s2, s3, s3lit)."""
    late = s["t"] >= LATE_S - 1e-9
    return {
        f"{tag}_formation_spread_m": formation_spread(s["t"], s["pos"]),
        f"{tag}_formation_wiggle_m": formation_wiggle(s["t"], s["pos"]),
        f"{tag}_settling_s": settling_time(s["t"], s["J"]),
        f"{tag}_mean_range_after_300s_m": float(np.mean(s["range"][:, late])) if late.any() else None,
        f"{tag}_tracking_error_m": run["metrics"]["tracking_error_mean_m"],
        f"{tag}_min_pair_distance_m": closest_pair_m(s["pos"]),
        f"{tag}_min_range_after_300s_m": float(np.min(s["range"][:, late])) if late.any() else None,
    }


TAGS = {SCENARIOS[0]: "s1", SCENARIOS[1]: "s2", SCENARIOS[2]: "s3", LITERAL: "s3lit"}
"""The per-seed key prefix of each run label."""


def per_seed_figures(runs: dict[tuple[str, int], dict], seed: int) -> dict:
    """Every per-seed figure of one seed (keys in docs/bench.md)."""
    row: dict = {"seed": seed}
    for label, tag in TAGS.items():
        if (label, seed) not in runs:
            continue
        s = series(runs[(label, seed)])
        gamma = _gamma_seed(tag, runs[(label, seed)], s)
        if tag == "s1":
            row.update(_scenario1_seed(runs[(label, seed)], s))
            gamma = {k: v for k, v in gamma.items() if "min_" in k}
        row.update(gamma)
    return row


def _both(a, b) -> bool:
    return a is not None and b is not None


def gamma_counts(per_seed: list[dict], tag: str, d_star: float) -> dict:
    """Seeds where scenario ``tag`` (s3, s3lit) against scenario 2 meets each of item 3's conditions."""

    def spread_ok(p: dict) -> bool:
        s2, s3 = p["s2_formation_spread_m"], p[f"{tag}_formation_spread_m"]
        return bool(s2) and s3 is not None and s3 <= 0.7 * s2

    def settle_ok(p: dict) -> bool:
        s2, s3 = p["s2_settling_s"], p[f"{tag}_settling_s"]
        return _both(s2, s3) and s3 > s2

    def error_ok(p: dict) -> bool:
        e2, e3 = p["s2_tracking_error_m"], p[f"{tag}_tracking_error_m"]
        return _both(e2, e3) and e3 <= 1.2 * e2

    def range_ok(p: dict) -> bool:
        r = p[f"{tag}_mean_range_after_300s_m"]
        return r is not None and r <= 2 * d_star

    conditions = {
        "seeds_spread_30pct_lower": spread_ok,
        "seeds_settling_later": settle_ok,
        "seeds_s3_range_le_2dstar": range_ok,
        "seeds_s3_error_le_1p2x": error_ok,
        "seeds_s3_error_le_1p2x_and_range_le_2dstar": lambda p: error_ok(p) and range_ok(p),
    }
    out: dict = {name: sum(1 for p in per_seed if cond(p)) for name, cond in conditions.items()}
    out["spread_s3_mean_m"] = _mean([p[f"{tag}_formation_spread_m"] for p in per_seed])
    out["wiggle_s3_mean_m"] = _mean([p[f"{tag}_formation_wiggle_m"] for p in per_seed])
    return out


def targets(count: int) -> dict[str, int]:
    """The targets for ``count`` seeds: issue 46's Done-when (over seeds 11-30: 20, 20, 16, 14, 18, 17 of 20)."""
    return {
        "item2_seeds_within_2dstar_after_300s": count,
        "item2_seeds_no_estimate_after_300s_le_2pct": count,
        "item3_seeds_spread_30pct_lower": math.ceil(0.8 * count),
        "item3_seeds_settling_later": math.ceil(0.7 * count),
        "item3_seeds_s3_error_le_1p2x_and_range_le_2dstar": math.ceil(0.9 * count),
        "item4_seeds_at_optimum": math.ceil(0.85 * count),
    }


def _safety(per_seed: list[dict], d_star: float, d_safe: float) -> dict:
    """How close AUVs came to each other and to the source, over every mission (every run label)."""
    tags = [t for t in TAGS.values() if any(f"{t}_min_pair_distance_m" in p for p in per_seed)]
    pair_min = [p.get(f"{t}_min_pair_distance_m") for p in per_seed for t in tags]
    range_min = [p.get(f"{t}_min_range_after_300s_m") for p in per_seed for t in tags]
    return {
        "safety_missions": len(tags) * len(per_seed),
        "safety_min_pair_distance_m": min((v for v in pair_min if v is not None), default=None),
        "safety_missions_closer_than_d_safe": sum(1 for v in pair_min if v is not None and v < d_safe),
        "safety_min_range_after_300s_m": min((v for v in range_min if v is not None), default=None),
        "safety_missions_within_half_dstar_after_300s": sum(1 for v in range_min if v is not None and v < 0.5 * d_star),
    }


def item_figures(runs: dict[tuple[str, int], dict], seeds: list[int]) -> dict:
    """The figures of issue 27's items 2-4 (issue 46's Done-when), per seed and as counts against the targets;
    ``literal_*`` the same for scenario 3 under the literal reading where it ran."""
    s1 = SCENARIOS[0]
    d_star, d_safe = runs[(s1, seeds[0])]["d_star_m"], runs[(s1, seeds[0])]["d_safe_m"]
    per_seed = [per_seed_figures(runs, k) for k in seeds]

    def holds(cond) -> int:
        return sum(1 for p in per_seed if cond(p))

    built = gamma_counts(per_seed, "s3", d_star)
    out = {
        "seeds": len(seeds),
        "seed_list": list(seeds),
        "per_seed": per_seed,
        **_safety(per_seed, d_star, d_safe),
        "item2_seeds_within_2dstar_after_300s": holds(
            lambda p: p["s1_max_range_after_300s_m"] is not None and p["s1_max_range_after_300s_m"] <= 2 * d_star
        ),
        "item2_seeds_no_estimate_after_300s_le_2pct": holds(
            lambda p: (
                p["s1_max_no_estimate_fraction_after_300s"] is not None
                and p["s1_max_no_estimate_fraction_after_300s"] <= 0.02
            )
        ),
        "item2_max_range_after_300s_m": max((p["s1_max_range_after_300s_m"] or 0.0) for p in per_seed),
        "item2_max_no_estimate_fraction_after_300s": max(
            (p["s1_max_no_estimate_fraction_after_300s"] or 0.0) for p in per_seed
        ),
        **{f"item3_{k}": v for k, v in built.items()},
        "item3_spread_s2_mean_m": _mean([p["s2_formation_spread_m"] for p in per_seed]),
        "item3_wiggle_s2_mean_m": _mean([p["s2_formation_wiggle_m"] for p in per_seed]),
        "item4_seeds_at_optimum": holds(
            lambda p: (
                p["s1_sigma_min_final_mean"] is not None
                and p["s1_sigma_min_final_mean"] >= 0.95 * p["s1_sigma_min_optimum"]
                and all(d_star <= r <= 2 * d_star for r in p["s1_mean_range_final_m"])
            )
        ),
        "item4_sigma_min_final_mean": _mean([p["s1_sigma_min_final_mean"] for p in per_seed]),
        "targets": targets(len(seeds)),
    }
    if all((LITERAL, k) in runs for k in seeds):
        out["literal"] = {f"item3_{k}": v for k, v in gamma_counts(per_seed, "s3lit", d_star).items()}
    return out


def _reading(run: dict) -> str:
    """The connectivity reading of a run, for a title: ``db``, or ``topology, anchor tau 120 s``."""
    if run.get("connectivity", "db") == "topology" and run.get("anchor_tau_s"):
        return f"topology, anchor tau {run['anchor_tau_s']:g} s"
    return run.get("connectivity", "db")


def _trajectories(ax, run: dict, title: str) -> None:
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
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="best")


GAMMA_RUNS = ((SCENARIOS[1], "tab:blue"), (SCENARIOS[2], "tab:red"), (LITERAL, "tab:gray"))
"""Panels (d) and (e): scenario 2, scenario 3 as built in, scenario 3 under the literal reading, and their colours."""


def _objective(ax, runs: dict[tuple[str, int], dict], seeds: list[int]) -> None:
    """Panel (d): J_g + J_d against time, mean and min-max band over the seeds, on a linear axis."""
    for name, colour in GAMMA_RUNS:
        if (name, seeds[0]) not in runs:
            continue
        js = [series(runs[(name, k)]) for k in seeds]
        t = js[0]["t"]
        stack = np.array([s["J"][: t.size] for s in js])
        stack[~np.isfinite(stack)] = np.nan
        run = runs[(name, seeds[0])]
        label = f"gamma {run['gamma']:g}, {_reading(run)} (mean of {len(seeds)})"
        ax.plot(t, np.nanmean(stack, axis=0), color=colour, label=label)
        ax.fill_between(t, np.nanmin(stack, axis=0), np.nanmax(stack, axis=0), color=colour, alpha=0.15)
    finite = [runs[(n, k)] for n, _ in GAMMA_RUNS for k in seeds if (n, k) in runs]
    late = [v for r in finite for v in series(r)["J"][series(r)["t"] >= 0.5 * LATE_S] if np.isfinite(v)]
    if late:
        ax.set_ylim(
            0.0, 1.5 * float(np.percentile(late, 99))
        )  # the first minutes' J (1/sigma_min of a cluster) is off the scale
    ax.set_xlabel("t (s)")
    ax.set_ylabel("J_g + J_d = 1/sigma_min + mean d_i / d*")
    ax.set_title("(d) J_g + J_d, scenarios 2 and 3 (band: min-max over seeds)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)


def _spreads(ax, per_seed: list[dict]) -> None:
    """Panel (e): the formation spread over t >= 300 s per seed, scenario 2 against both readings of scenario 3."""
    names = ("scenario 2 (gamma 0.3)", "scenario 3 as built in", "scenario 3, literal reading (db)")
    for (_, colour), tag, marker, name in zip(GAMMA_RUNS, ("s2", "s3", "s3lit"), "os^", names, strict=True):
        xs = [p["seed"] for p in per_seed if p.get(f"{tag}_formation_spread_m") is not None]
        ys = [p[f"{tag}_formation_spread_m"] for p in per_seed if p.get(f"{tag}_formation_spread_m") is not None]
        if xs:
            ax.plot(xs, ys, marker, color=colour, label=name)
    xs = [p["seed"] for p in per_seed if p.get("s2_formation_spread_m") is not None]
    ax.plot(
        xs,
        [0.7 * p["s2_formation_spread_m"] for p in per_seed if p.get("s2_formation_spread_m") is not None],
        "_",
        color="tab:blue",
        ms=12,
        label="0.7 x scenario 2 (the target)",
    )
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.set_xlabel("seed")
    ax.set_ylabel("formation spread over t >= 300 s (m)")
    ax.set_title("(e) formation spread per seed", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)


def figure(runs: dict[tuple[str, int], dict], seeds: list[int], path: Path, per_seed: list[dict]) -> None:
    """Fig. 6 in one PNG: (a-c) the first seed's trajectories of scenarios 1-3 with the source, (c') scenario 3
    under the literal reading, (d) J_g + J_d against time, (e) the formation spread per seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(16, 10), constrained_layout=True)
    panels = [(SCENARIOS[0], "a"), (SCENARIOS[1], "b"), (SCENARIOS[2], "c"), (LITERAL, "c'")]
    for ax, (name, letter) in zip(axes.flat[:4], panels, strict=True):
        if (name, seeds[0]) not in runs:
            ax.set_axis_off()
            continue
        run = runs[(name, seeds[0])]
        short = base_scenario(name).replace("paper-3.1-", "")
        extra = "" if name == SCENARIOS[0] else f", {_reading(run)}"
        _trajectories(ax, run, f"({letter}) {short}: gamma {run['gamma']:g}{extra}, seed {seeds[0]}")
    _objective(axes.flat[4], runs, seeds)
    _spreads(axes.flat[5], per_seed)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _fmt(v, spec: str = ".3g") -> str:
    return "-" if v is None else format(v, spec)


def text(out: dict) -> str:
    """The figures against their targets (the literal reading's count beside), then one line per seed."""
    f, tg = out["figures"], out["figures"]["targets"]
    literal = f.get("literal", {})
    lines = [f"bench figure6: seeds {out['seeds']}, {out['cpu_s']} s CPU, {out['wall_s']} s wall"]
    for key in tg:
        beside = f"   literal reading: {literal[key]} of {f['seeds']}" if key in literal else ""
        lines.append(f"  {key:<50} {f[key]:>3} of {f['seeds']}  (target >= {tg[key]}){beside}")
    for key in ("item3_seeds_s3_range_le_2dstar", "item3_seeds_s3_error_le_1p2x"):
        beside = f"   literal reading: {literal[key]} of {f['seeds']}" if key in literal else ""
        lines.append(f"  {key:<50} {f[key]:>3} of {f['seeds']}{beside}")
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
        beside = f"   literal reading: {_fmt(literal[key])}" if key in literal else ""
        lines.append(f"  {key:<50} {_fmt(f[key])}{beside}")
    for key in ("safety_missions_closer_than_d_safe", "safety_missions_within_half_dstar_after_300s"):
        lines.append(f"  {key:<50} {f[key]:>3} of {f['safety_missions']} missions")
    lines.append(
        "  seed  s1 max range  s1 no-est  s1 sigma_min  s2/s3/lit spread m  s2/s3/lit settle s  s3 range"
        "  s2/s3/lit error m"
    )
    for p in f["per_seed"]:
        tags = ("s2", "s3", "s3lit")
        lines.append(
            f"  {p['seed']:>4}  {_fmt(p['s1_max_range_after_300s_m'], '12.1f')}  "
            f"{_fmt(p['s1_max_no_estimate_fraction_after_300s'], '9.3f')}  {_fmt(p['s1_sigma_min_final_mean'], '12.3f')}  "
            + f"{'/'.join(_fmt(p.get(f'{t}_formation_spread_m'), '.1f') for t in tags):>18}  "
            + f"{'/'.join(_fmt(p.get(f'{t}_settling_s'), '.0f') for t in tags):>18}  "
            + f"{_fmt(p['s3_mean_range_after_300s_m'], '8.1f')}  "
            + "/".join(_fmt(p.get(f"{t}_tracking_error_m"), ".2f") for t in tags)
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


def build_parser() -> argparse.ArgumentParser:
    """The bench's options."""
    parser = argparse.ArgumentParser(prog="auv-swarm bench figure6", description=plain_description(__doc__))
    parser.add_argument("--seeds", default="10", help=f"{SEEDS_HELP}, per scenario (default 10)")
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
        "prefixed s1:, s2: or s3: (s3:planner.gamma=0.9), in that scenario only; the literal reading of scenario 3 "
        "takes scenario 3's keys, then planner.connectivity = db with no anchor",
    )
    return parser


def main(argv: list[str]) -> int:
    """Run the section 3.1 scenarios over the seeds, write figure6.png (and figure6.json) to --out, print the figures."""
    args = build_parser().parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        return fail(str(exc))
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        return fail(f"--duration must be a positive number of seconds, got {args.duration}")
    try:
        keys, only = parse_sets(args.set)
    except ValueError as exc:
        return fail(str(exc))
    scenario_keys = {name: {**keys, **only.get(base_scenario(name), {})} for name in RUNS}
    try:
        for name in RUNS:
            extra = LITERAL_KEYS if name == LITERAL else {}
            load_scenario(base_scenario(name)).with_keys({**scenario_keys[name], **extra}).with_overrides(
                duration_s=args.duration
            )
        if args.out is not None:
            outdir.prepare(args.out, force=args.force)
    except (ConfigError, outdir.OutDirError) as exc:
        return fail(str(exc))
    jobs = [(s, k, args.duration, scenario_keys[s]) for s in RUNS for k in seeds]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=min(MAX_WORKERS, len(jobs))) as pool:
        done = list(pool.map(one_run, *zip(*jobs, strict=True)))
    runs = {(r["scenario"], r["seed"]): r for r in done}
    out = {
        "scenarios": list(RUNS),
        "literal_keys": LITERAL_KEYS,
        "seeds": seeds_text(seeds),
        "duration_s": args.duration,
        "keys": keys,
        "scenario_keys": {name: only[name] for name in SCENARIOS if name in only},
        "wall_s": round(time.perf_counter() - start, 1),
        "cpu_s": round(sum(r["cpu_s"] for r in done), 1),
        "figures": item_figures(runs, seeds),
    }
    if args.out is not None:
        figure(runs, seeds, args.out / "figure6.png", out["figures"]["per_seed"])
        (args.out / "figure6.json").write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(out))
    else:
        print(text(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
