"""The files of a results folder: metrics.json, events.jsonl, the raw data tables and the three figures (matplotlib
imported on use)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from auv_swarm.results.metrics import (
    PAPER_ERROR_BOUND_M,
    alive_counts,
    compute_metrics,
    json_safe,
    team_error,
    tracking_errors,
)
from auv_swarm.results.record import RunRecord
from auv_swarm.results.tables import write_tables

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def write_results(
    rec: RunRecord, out_dir: Path, finish: Callable[[dict[str, Any]], None] | None = None
) -> dict[str, Any]:
    """Write events.jsonl, the raw data (record.parquet, truth.parquet, bearings.parquet, links.parquet:
    :mod:`.tables`), trajectories.png, tracking_error.png, costs.png and, last, metrics.json into ``out_dir``
    (created if needed); return the metrics. ``finish(metrics)`` is called just before metrics.json is written
    (``run_mission`` sets the run's wall time there, the figures included)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = compute_metrics(rec)
    with (out / "events.jsonl").open("w", encoding="utf-8") as fh:
        fh.writelines(line + "\n" for line in event_lines(rec))
    write_tables(rec, out)
    errors = tracking_errors(rec)
    _save(plot_trajectories(rec), out / "trajectories.png")
    _save(plot_tracking_error(rec, errors, metrics), out / "tracking_error.png")
    _save(plot_costs(rec), out / "costs.png")
    if finish is not None:
        finish(metrics)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return metrics


def event_lines(rec: RunRecord) -> list[str]:
    """The lines of events.jsonl: every event of ``rec`` as compact JSON, sorted by ``t_s`` (stable)."""
    events = sorted(rec.events, key=lambda e: e["t_s"])
    return [json.dumps(json_safe(ev), allow_nan=False, separators=(",", ":")) for ev in events]


def figure(**kwargs: Any) -> Figure:
    """A matplotlib figure on an Agg canvas (matplotlib is imported on first use, not with this module)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> None:
    fig.savefig(path, dpi=110)


def _colour(k: int) -> str:
    return f"C{k % 10}"


def _kill_times(rec: RunRecord) -> list[tuple[int, float]]:
    return [(i, s.alive_until_s) for i, s in sorted(rec.agents.items()) if s.alive_until_s is not None]


def plot_trajectories(rec: RunRecord) -> Figure:
    """Plan view: each AUV's path while alive (circle at the start, square at the end, cross where it was lost) and
    the target's true path."""
    fig = figure(figsize=(9.5, 7.0))
    ax = fig.add_subplot()
    if len(rec.times):
        tx, ty = rec.target[:, 0], rec.target[:, 1]
        ax.plot(tx, ty, "k--", lw=1.5, label="target (truth)")
        ax.plot(tx[0], ty[0], "ko", ms=6)
        ax.plot(tx[-1], ty[-1], "k*", ms=10)
    for k, (i, s) in enumerate(sorted(rec.agents.items())):
        idx = np.flatnonzero(s.alive & np.all(np.isfinite(s.position), axis=1))
        if len(idx) == 0:
            continue
        p = s.position[idx]
        c = _colour(k)
        ax.plot(p[:, 0], p[:, 1], "-", color=c, lw=1.2, label=f"AUV {i}")
        ax.plot(p[0, 0], p[0, 1], "o", color=c, ms=6)
        if s.alive_until_s is not None:
            ax.plot(p[-1, 0], p[-1, 1], "x", color=c, ms=12, mew=3, label=f"AUV {i} lost at {s.alive_until_s:g} s")
        else:
            ax.plot(p[-1, 0], p[-1, 1], "s", color=c, ms=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{rec.scenario.name}: trajectories (circle start; end: square, target star; cross: lost)")
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:  # beside the plot, so that it never hides a path's end or a cross
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0.0)
    fig.tight_layout()
    return fig


def plot_tracking_error(
    rec: RunRecord, errors: Mapping[int, np.ndarray] | None = None, metrics: Mapping[str, Any] | None = None
) -> Figure:
    """Tracking error of every AUV vs sim time, the paper's 15 m bound, kill times and the convergence time."""
    errors = tracking_errors(rec) if errors is None else errors
    fig = figure(figsize=(11.0, 4.8))
    ax = fig.add_subplot()
    peak = 0.0
    for k, i in enumerate(sorted(errors)):
        e = errors[i]
        if np.any(np.isfinite(e)):
            peak = max(peak, float(np.nanmax(e)))
        ax.plot(rec.times, e, "-", color=_colour(k), lw=1.0, label=f"AUV {i}")
        ax.plot(rec.times, e, ".", color=_colour(k), ms=2.0)  # every sample, also one isolated between gaps
    if errors and len(rec.times):
        team = team_error(errors, len(rec.times))
        ax.plot(rec.times, team, "-", color="black", lw=1.8, label="team mean (convergence is taken on it)")
    source = " (paper, Fig. 7b)" if rec.scenario.name.startswith("paper-") else ""
    ax.axhline(PAPER_ERROR_BOUND_M, color="red", ls="--", lw=1.2, label=f"{PAPER_ERROR_BOUND_M:g} m bound{source}")
    for i, t in _kill_times(rec):
        ax.axvline(t, color="0.3", ls=":", lw=1.2)
        ax.annotate(
            f"AUV {i} lost",
            (t, 0.97),
            xycoords=("data", "axes fraction"),
            rotation=90,
            va="top",
            ha="right",
            fontsize=8,
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
        )
    t_conv = None if metrics is None else metrics.get("convergence_time_s")
    if t_conv is not None and len(rec.times):
        t_c = float(rec.times[0]) + t_conv  # in black, as the team mean it is taken on: no AUV's colour
        ax.axvline(t_c, color="black", ls="-.", lw=1.2, label=f"converged at {t_conv:g} s")
    if peak > 20 * PAPER_ERROR_BOUND_M:
        ax.set_yscale("log")
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("tracking error (m)")
    ax.set_title(f"{rec.scenario.name}: tracking error per AUV")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)  # off the kill labels
    fig.tight_layout()
    return fig


def _planned_alone(rec: RunRecord) -> bool:
    """Whether some plan had a connectivity term of exactly 0: a plan made with no neighbour (with one, 1/lambda_2 > 0)."""
    return any(row.get("connectivity") == 0.0 for s in rec.agents.values() for row in s.plan_terms)


def plot_costs(rec: RunRecord) -> Figure:
    """Each AUV's planned cost terms (geometry, distance, connectivity) per plan, and the true-geometry cost."""
    fig = figure(figsize=(9.0, 9.0))
    axes = fig.subplots(4, 1, sharex=True)
    panels = (
        ("geometry", "geometry cost (eq. 35)"),
        ("distance", "distance cost (eq. 36)"),
        ("connectivity", "connectivity cost (eq. 37)"),
    )
    for ax, (key, label) in zip(axes[:3], panels, strict=True):
        for k, (i, s) in enumerate(sorted(rec.agents.items())):
            if not s.plan_times_s:
                continue
            v = np.array([row.get(key, math.nan) for row in s.plan_terms], dtype=float)
            v[~np.isfinite(v)] = np.nan
            ax.plot(s.plan_times_s, v, ".-", color=_colour(k), lw=1.0, label=f"AUV {i}")
        ax.set_ylabel(label, fontsize=9)
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=8)
        if key == "connectivity" and _planned_alone(rec):
            ax.text(
                0.01,
                0.04,
                "0: the AUV planned alone (no neighbour heard for 4 TDMA frames): no graph, no term",
                transform=ax.transAxes,
                fontsize=8,
                color="0.3",
            )
    ax = axes[3]
    g = np.where(np.isfinite(rec.geometry_cost), rec.geometry_cost, np.nan)
    ax.plot(rec.times, g, "k-", lw=1.0, label="1/sigma_min(Phi), true geometry")
    n_alive = alive_counts(rec)
    optimum = np.where(n_alive >= 2, np.sqrt(2.0 / np.maximum(n_alive, 1)), np.nan)
    ax.plot(rec.times, optimum, color="green", ls="--", lw=1.0, label="optimum sqrt(2/n_alive)")
    positive = g[np.isfinite(g) & (g > 0)]
    if len(positive) and positive.max() > 20 * positive.min():
        ax.set_yscale("log")
    ax.set_ylabel("true geometry cost", fontsize=9)
    ax.set_xlabel("sim time (s)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    for _, t in _kill_times(rec):
        for a in axes:
            a.axvline(t, color="0.3", ls=":", lw=1.0)
    axes[0].set_title(f"{rec.scenario.name}: planned cost terms (per plan) and true geometry")
    fig.tight_layout()
    return fig
