"""The console summary of one mission: the block ``auv-swarm run`` prints from its ``metrics.json``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def _fmt(value: Any, spec: str = ".1f", unit: str = "") -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:{spec}}{unit}"
    return f"{value}{unit}"


def summary_table(metrics: Mapping[str, Any]) -> str:
    """The console summary of one run's metrics (as returned by :func:`compute_metrics`)."""
    m = metrics
    ch = m.get("channel", {})
    err = (
        "-"
        if m.get("tracking_error_mean_m") is None
        else (
            f"{m['tracking_error_mean_m']:.1f} +/- {m['tracking_error_std_m']:.1f} m  (mean +/- std over the samples, "
            "ddof 0"
        )
    )
    drops = ", ".join(f"{k} {v}" for k, v in ch.get("dropped", {}).items() if v) or "none"
    rows = [
        ("scenario", f"{m.get('scenario')}  (seed {m.get('seed')}, mode {m.get('mode')})"),
        (
            "sim time",
            f"{_fmt(m.get('sim_duration_s'), '.0f', ' s')}; mission wall {_fmt(m.get('wall_time_s'), '.1f', ' s')}, "
            f"run wall {_fmt(m.get('run_wall_time_s'), '.1f', ' s')}",
        ),
        (
            "tracking error",
            f"{err}; no estimate {_fmt(_pct(m.get('no_estimate_fraction')), '.1f', ' %')} of them)"
            if m.get("tracking_error_mean_m") is not None
            else f"- (no estimate {_fmt(_pct(m.get('no_estimate_fraction')), '.1f', ' %')} of samples)",
        ),
        (
            "convergence",
            f"{'never' if m.get('convergence_time_s') is None else _fmt(m['convergence_time_s'], '.0f', ' s')} "
            f"(team-mean error <= {_fmt(m.get('convergence_error_m'), 'g', ' m')} held "
            f"{_fmt(m.get('convergence_hold_s'), 'g', ' s')}); "
            f"steady error {_fmt(m.get('tracking_error_steady_mean_m'), '.1f', ' m')}",
        ),
        (
            "after convergence",
            f"{_fmt(_pct(m.get('under_15m_after_convergence_fraction')), '.1f', ' %')} of samples <= 15 m, "
            f"longest excursion {_fmt(m.get('longest_excursion_s'), '.0f', ' s')}; "
            f"error p95 {_fmt(m.get('tracking_error_p95_m'), '.1f', ' m')}",
        ),
        (
            "NEES (position)",
            f"mean {_fmt(m.get('nees_mean'), '.2f')} (2 = consistent), "
            f"{_fmt(_pct(m.get('nees_in_band_fraction')), '.1f', ' %')} in the 95 % band [0.05, 7.38]",
        ),
        ("FQI", f"{_fmt(m.get('fqi'), '.2f')}  (1 = optimal geometry)"),
        (
            "navigation error",
            f"mean {_fmt(m.get('nav_error_mean_m'), '.1f', ' m')}, max {_fmt(m.get('nav_error_max_m'), '.1f', ' m')} "
            "(believed against true position)",
        ),
    ]
    after = m.get("after_first_kill")
    if after and after.get("samples"):
        rows.append(
            (
                "after 1st loss",
                f"t > {_fmt(after['t_s'], 'g', ' s')}: survivors' error {_fmt(after['tracking_error_mean_m'], '.1f', ' m')} "
                f"mean, {_fmt(after['tracking_error_p95_m'], '.1f', ' m')} p95, "
                f"{_fmt(_pct(after['fraction_below_threshold']), '.1f', ' %')} of samples <= "
                f"{_fmt(m.get('convergence_error_m'), 'g', ' m')}",
            )
        )
    rows += [
        (
            "plan time",
            f"median {_fmt(m.get('plan_time_median_ms'), '.1f', ' ms')}, max {_fmt(m.get('plan_time_max_ms'), '.1f', ' ms')} "
            f"({m.get('plan_count', 0)} plans)",
        ),
        (
            "channel",
            f"frames: {ch.get('sent', 0)} sent, {ch.get('deferred', 0)} deferred; "
            f"links (frame to one recipient): {ch.get('delivered', 0)} delivered, "
            f"{ch.get('dropped_total', 0)} dropped ({drops}), "
            f"{_fmt(_pct(ch.get('delivery_ratio')), '.0f', ' %')} delivered; "
            f"latency {_fmt(ch.get('latency_mean_s'), '.2f', ' s')}",
        ),
    ]
    width = max(len(k) for k, _ in rows)
    lines = [f"{k:<{width}}  {v}" for k, v in rows]
    header = ("AUV", "alive until", "error mean", "error std", "p95", "lost", "no est.", "plans", "plan median")
    table = [header]
    for i, a in m.get("agents", {}).items():
        table.append(
            (
                i,
                _fmt(a.get("alive_until_s"), "g", " s") if a.get("alive_until_s") is not None else "end",
                _fmt(a.get("tracking_error_mean_m"), ".1f", " m"),
                _fmt(a.get("tracking_error_std_m"), ".1f", " m"),
                _fmt(a.get("tracking_error_p95_m"), ".1f", " m"),
                _fmt(a.get("track_lost"), "d"),
                _fmt(_pct(a.get("no_estimate_fraction")), ".1f", " %"),
                str(a.get("plans", 0)),
                _fmt(a.get("plan_time_median_ms"), ".1f", " ms"),
            )
        )
    widths = [max(len(r[c]) for r in table) for c in range(len(header))]
    lines.append("")
    for r in table:
        lines.append("  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True)).rstrip())
    return "\n".join(lines)


def _pct(fraction: float | None) -> float | None:
    return None if fraction is None else 100.0 * fraction
