"""The figures of merit of one mission (``metrics.json``), computed from its :class:`~auv_swarm.results.record.RunRecord`.

Every metric is defined in docs/results.md; its name, label, unit and kind are in :data:`METRIC_INFO`
(:mod:`.metric_info`). Pure numpy: no clock, no I/O (the files are written by
:func:`auv_swarm.results.report.write_results`).

Frames and units: positions in metres in the inertial frame, headings in rad
from +x counter-clockwise, times in seconds of simulated time, planner wall
times in milliseconds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from auv_swarm.contract import methods
from auv_swarm.results.metric_info import METRIC_INFO  # noqa: F401  (results.metrics.METRIC_INFO: every name)
from auv_swarm.results.record import RunRecord
from auv_swarm.results.tracking import position_nees, tracking_metrics

PAPER_ERROR_BOUND_M = 15.0
"""The 15 m acceptable tracking-error bound drawn in the paper's Fig. 7b (m)."""

CONVERGENCE_HOLD_S = 60.0
"""How long the team-mean error must stay within run.convergence_error_m to count as converged (s)."""


LATE_S = 300.0
"""Mission time (s) after which ``agents.<id>.no_estimate_fraction_after_300s`` counts (issue 27)."""


def no_estimate_fraction_after(times: np.ndarray, alive: np.ndarray, ok: np.ndarray, t_from_s: float) -> float | None:
    """Share of the live samples at t >= ``t_from_s`` (mission time) without an estimate; None if none."""
    late = alive & (times - (times[0] if times.size else 0.0) >= t_from_s - 1e-9)
    n = int(np.sum(late))
    return int(np.sum(late & ~ok)) / n if n else None


# ---------------------------------------------------------------------------- metrics


def tracking_errors(rec: RunRecord) -> dict[int, np.ndarray]:
    """Per-AUV tracking error |estimate - true position| (m) per tick; NaN when dead or without an estimate."""
    truth = rec.target[:, :2] if len(rec.times) else np.empty((0, 2))
    out = {}
    for i, s in rec.agents.items():
        err = np.linalg.norm(s.estimate - truth, axis=1) if len(truth) else np.empty(0)
        out[i] = np.where(s.alive & s.estimate_ok, err, np.nan)
    return out


def navigation_errors(rec: RunRecord) -> np.ndarray:
    """|believed - true position| (m) over every (live AUV, tick) sample whose believed position is known."""
    per_agent = [np.linalg.norm(s.believed - s.position, axis=1)[s.alive] for _, s in sorted(rec.agents.items())]
    err = np.concatenate(per_agent) if per_agent else np.empty(0)
    return err[np.isfinite(err)]


def team_error(errors: Mapping[int, np.ndarray], n_ticks: int) -> np.ndarray:
    """Team-mean tracking error per tick (m): mean over AUVs with a valid error, NaN where none has one."""
    if not errors or n_ticks == 0:
        return np.full(n_ticks, np.nan)
    stack = np.vstack([errors[i] for i in sorted(errors)])
    valid = np.isfinite(stack)
    count = valid.sum(axis=0)
    total = np.where(valid, stack, 0.0).sum(axis=0)
    return np.divide(total, count, out=np.full(n_ticks, np.nan), where=count > 0)


def convergence_time(
    times: np.ndarray, error: np.ndarray, threshold_m: float, hold_s: float = CONVERGENCE_HOLD_S
) -> float | None:
    """Earliest sample time t_c whose window [t_c, t_c + hold_s] lies inside the run and holds only
    samples with error <= threshold_m (a NaN sample, i.e. no estimate, breaks the window).

    Returns t_c (s, on the ``times`` axis) or None if no such window exists.
    """
    if threshold_m <= 0 or not math.isfinite(threshold_m):
        raise ValueError(f"threshold_m must be in (0, inf), got {threshold_m!r}")
    if hold_s < 0 or not math.isfinite(hold_s):
        raise ValueError(f"hold_s must be in [0, inf), got {hold_s!r}")
    t = np.asarray(times, dtype=float)
    e = np.asarray(error, dtype=float)
    if len(t) == 0:
        return None
    good = np.isfinite(e) & (e <= threshold_m)
    bad_idx = np.flatnonzero(~good)
    eps = 1e-9 * max(1.0, abs(float(t[-1])))
    for k in np.flatnonzero(good):
        end = t[k] + hold_s
        if end > t[-1] + eps:
            return None
        last = np.searchsorted(t, end + eps, side="right")
        nxt = np.searchsorted(bad_idx, k)
        if nxt == len(bad_idx) or bad_idx[nxt] >= last:
            return float(t[k])
    return None


def alive_counts(rec: RunRecord) -> np.ndarray:
    """Number of live AUVs per tick."""
    if not rec.agents:
        return np.zeros(len(rec.times), dtype=int)
    return np.sum([s.alive for s in rec.agents.values()], axis=0).astype(int)


def _stats(values: np.ndarray) -> tuple[float | None, float | None]:
    v = values[np.isfinite(values)]
    if len(v) == 0:
        return None, None
    return float(np.mean(v)), float(np.std(v))


def compute_metrics(rec: RunRecord, hold_s: float = CONVERGENCE_HOLD_S) -> dict[str, Any]:
    """The run's figures of merit as JSON-safe data (None where undefined); docs/results.md defines each.

    Tracking error: over every (live AUV, tick) sample with a valid estimate
    (population std). Convergence: :func:`convergence_time` of the team-mean error
    against run.convergence_error_m. FQI: time-average of geometry_cost /
    sqrt(2 / n_alive) over ticks with >= 2 live AUVs (1 = optimal geometry).
    """
    n_ticks = len(rec.times)
    errors = tracking_errors(rec)
    all_err = np.concatenate([errors[i] for i in sorted(errors)]) if errors else np.empty(0)
    err_mean, err_std = _stats(all_err)
    alive_samples = int(sum(int(np.sum(s.alive)) for s in rec.agents.values()))
    missing = int(sum(int(np.sum(s.alive & ~s.estimate_ok)) for s in rec.agents.values()))

    team = team_error(errors, n_ticks)
    threshold = rec.scenario.run.convergence_error_m
    t_conv = convergence_time(rec.times, team, threshold, hold_s)
    t0 = float(rec.times[0]) if n_ticks else 0.0
    steady_mean = None
    if t_conv is not None:
        after = rec.times >= t_conv
        steady_mean, _ = _stats(np.concatenate([errors[i][after] for i in sorted(errors)]))

    n_alive = alive_counts(rec)
    use = n_alive >= 2
    ratio = rec.geometry_cost[use] / np.sqrt(2.0 / n_alive[use])
    degenerate = int(np.sum(~np.isfinite(ratio)))
    fqi = float(np.mean(ratio[np.isfinite(ratio)])) if np.any(np.isfinite(ratio)) else None

    truth = rec.target[:, :2] if n_ticks else np.empty((0, 2))
    nees = {i: position_nees(s.estimate - truth, s.estimate_cov) for i, s in rec.agents.items()}
    alive = {i: s.alive for i, s in rec.agents.items()}
    team_track, per_track = tracking_metrics(rec.times, errors, alive, nees, t_conv, rec.scenario.run.tick_s)

    wall = np.array([w for s in rec.agents.values() for w in s.plan_wall_ms], dtype=float)
    duplicates: dict[int, int] = {}
    for ev in rec.events:
        if ev["kind"] == "duplicate_login":
            duplicates[int(ev["agent"])] = duplicates.get(int(ev["agent"]), 0) + 1
    agents = {}
    end_s = float(rec.times[-1]) if n_ticks else 0.0
    for i in sorted(rec.agents):
        s = rec.agents[i]
        m, sd = _stats(errors[i])
        alive_i = int(np.sum(s.alive))
        agents[str(i)] = {
            "alive_until_s": s.alive_until_s,
            "alive_intervals_s": alive_intervals(rec.times, s.alive),
            "hung_intervals_s": [[a, b if b is not None else end_s] for a, b in s.hung_intervals_s],
            "tracking_error_mean_m": m,
            "tracking_error_std_m": sd,
            **per_track[i],
            "no_estimate_fraction": (int(np.sum(s.alive & ~s.estimate_ok)) / alive_i) if alive_i else None,
            "no_estimate_fraction_after_300s": no_estimate_fraction_after(rec.times, s.alive, s.estimate_ok, LATE_S),
            "plans": len(s.plan_wall_ms),
            "plan_time_median_ms": float(np.median(s.plan_wall_ms)) if s.plan_wall_ms else None,
            "duplicate_logins": duplicates.get(i, 0),
        }

    metrics = {
        "scenario": rec.scenario.name,
        "seed": rec.scenario.run.seed,
        "mode": rec.mode,
        "n_agents": len(rec.agents),
        "complete": rec.complete,
        "incomplete_reason": rec.incomplete_reason,
        "exit_code": rec.exit_code,
        "error": rec.error,
        "plugins": methods.plugins(rec.scenario),
        "sim_duration_s": float(rec.times[-1] - rec.times[0]) if n_ticks else 0.0,
        "wall_time_s": rec.wall_time_s,
        "run_wall_time_s": rec.run_wall_time_s,
        "ticks": n_ticks,
        "tracking_error_mean_m": err_mean,
        "tracking_error_std_m": err_std,
        "tracking_error_samples": int(np.sum(np.isfinite(all_err))),
        "no_estimate_fraction": missing / alive_samples if alive_samples else None,
        "convergence_error_m": threshold,
        "convergence_hold_s": hold_s,
        "convergence_time_s": None if t_conv is None else t_conv - t0,
        "tracking_error_steady_mean_m": steady_mean,
        **team_track,
        "fqi": fqi,
        "fqi_degenerate_ticks": degenerate,
        "plan_count": int(len(wall)),
        "plan_time_median_ms": float(np.median(wall)) if len(wall) else None,
        "plan_time_max_ms": float(np.max(wall)) if len(wall) else None,
        "kills": sorted(
            (
                {"agent": i, "t_s": rec.agents[i].alive_until_s}
                for i in rec.agents
                if rec.agents[i].alive_until_s is not None
            ),
            key=lambda k: (k["t_s"], k["agent"]),
        ),
        "after_first_kill": _after_first_kill(rec, errors, threshold),
        "duplicate_logins": sum(duplicates.values()),
        "compromised_auvs": sorted(duplicates),
        **_navigation_metrics(rec),
        "agents": agents,
        "channel": _channel_metrics(rec),
    }
    return json_safe(metrics)


def alive_intervals(times: np.ndarray, alive: np.ndarray) -> list[list[float]]:
    """[start, end] sim times (s) of each stretch an AUV was alive: from its first live tick to the first tick
    it was not (a death at t ends the stretch at t), or to the last tick of the run."""
    out: list[list[float]] = []
    start = None
    for t, up in zip(times.tolist(), alive.tolist(), strict=True):
        if up and start is None:
            start = t
        elif not up and start is not None:
            out.append([start, t])
            start = None
    if start is not None:
        out.append([start, float(times[-1])])
    return out


def _after_first_kill(rec: RunRecord, errors: dict[int, np.ndarray], threshold_m: float) -> dict[str, Any] | None:
    """Tracking error of the survivors after the first AUV loss (the paper's Fig. 7b check); None if nobody died."""
    kill_times = [s.alive_until_s for s in rec.agents.values() if s.alive_until_s is not None]
    if not kill_times:
        return None
    t_kill = min(kill_times)
    after = rec.times > t_kill
    samples = np.concatenate([errors[i][after] for i in sorted(errors)])
    samples = samples[np.isfinite(samples)]
    if samples.size == 0:
        return {"t_s": t_kill, "samples": 0}
    return {
        "t_s": t_kill,
        "samples": int(samples.size),
        "tracking_error_mean_m": float(np.mean(samples)),
        "tracking_error_p95_m": float(np.percentile(samples, 95)),
        "fraction_below_threshold": float(np.mean(samples <= threshold_m)),
    }


def _navigation_metrics(rec: RunRecord) -> dict[str, float | None]:
    """nav_error_mean_m and nav_error_max_m (docs/results.md): 0.0 under perfect navigation, None without samples."""
    err = navigation_errors(rec)
    if err.size == 0:
        none = 0.0 if rec.scenario.navigation.perfect else None
        return {"nav_error_mean_m": none, "nav_error_max_m": none}
    return {"nav_error_mean_m": float(np.mean(err)), "nav_error_max_m": float(np.max(err))}


def _channel_metrics(rec: RunRecord) -> dict[str, Any]:
    c = rec.channel_counters
    dropped = {k[len("dropped_") :]: int(v) for k, v in sorted(c.items()) if k.startswith("dropped_")}
    delivered = int(c.get("delivered", 0))
    attempts = delivered + sum(dropped.values())
    lat = np.asarray(rec.latencies_s, dtype=float)
    return {
        "sent": int(c.get("sent", 0)),
        "delivered": delivered,
        "deferred": int(c.get("deferred", 0)),
        "in_flight_at_end": int(c.get("in_flight_at_end", 0)),
        "dropped": dropped,
        "dropped_total": sum(dropped.values()),
        "delivery_ratio": delivered / attempts if attempts else None,
        "latency_mean_s": float(np.mean(lat)) if len(lat) else None,
        "latency_max_s": float(np.max(lat)) if len(lat) else None,
    }


def json_safe(obj: Any) -> Any:
    """Recursively convert to JSON-ready data: numpy scalars/arrays to Python, NaN/inf to None, tuples to lists."""
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


WALL_CLOCK_KEYS = ("wall_time_s", "run_wall_time_s", "plan_time_median_ms", "plan_time_max_ms", "mode")


def comparable(metrics: dict) -> dict:
    """Metrics without wall-clock figures (and the mode), for determinism checks."""
    out = {k: v for k, v in metrics.items() if k not in WALL_CLOCK_KEYS}
    out["agents"] = {
        a: {k: v for k, v in m.items() if "ms" not in k and "wall" not in k} for a, m in metrics["agents"].items()
    }
    return out
