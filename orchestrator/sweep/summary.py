"""A sweep's summaries (docs/sweeps.md): ``summary.json`` and ``summary.md`` per grid cell, and its figures.

Per cell (one combination of the axis values) and for each of :data:`SUMMARY_METRICS`: n (missions done with
a value), mean, std (sample, n - 1) and the 95 % confidence interval of the mean (Student's t with n - 1
degrees of freedom; null for n < 2). Figures: one PNG per numeric axis (the tracking error against it, one
line per combination of the categorical axes, the confidence interval as a band), or grouped bars when the
grid has no numeric axis.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

SUMMARY_METRICS = (
    "tracking_error_mean_m",
    "tracking_error_p95_m",
    "convergence_time_s",
    "nees_in_band_fraction",
    "fqi",
    "plan_time_median_ms",
    "nav_error_mean_m",
)
SCHEMA_VERSION = 1
SUMMARY_SCHEMA = {
    "schema": "int, the schema version (1)",
    "grid_hash": "str, the grid's SHA-256",
    "axes": "list of str, the axis columns",
    "metrics": "list of str, the summarised metrics",
    "cells": (
        "list, one per grid cell: {labels: {axis: value}, missions: int, done: int, failed: int, "
        "stats: {metric: {n: int, mean: float|null, std: float|null, ci95_low: float|null, ci95_high: float|null}}}"
    ),
}
"""summary.json's fields (docs/sweeps.md)."""


def stats(values: list[float]) -> dict[str, Any]:
    """n, mean, sample std and the 95 % Student-t confidence interval of the mean of ``values``."""
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    n = len(v)
    out: dict[str, Any] = {"n": n, "mean": None, "std": None, "ci95_low": None, "ci95_high": None}
    if n == 0:
        return out
    mean = sum(v) / n
    out["mean"] = mean
    if n >= 2:
        from scipy.stats import t

        std = math.sqrt(sum((x - mean) ** 2 for x in v) / (n - 1))
        half = float(t.ppf(0.975, n - 1)) * std / math.sqrt(n)
        out.update(std=std, ci95_low=mean - half, ci95_high=mean + half)
    return out


def summarise(rows: list[dict[str, Any]], axes: list[str], grid_hash: str = "") -> dict[str, Any]:
    """summary.json: the rows grouped by their axis values (cells in first-seen order)."""
    cells: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        cells.setdefault(tuple(r.get(a) for a in axes), []).append(r)
    out_cells = []
    for labels, members in cells.items():
        done = [r for r in members if r.get("status") == "done"]
        out_cells.append(
            {
                "labels": dict(zip(axes, labels, strict=True)),
                "missions": len(members),
                "done": len(done),
                "failed": len(members) - len(done),
                "stats": {m: stats([r.get(m) for r in done]) for m in SUMMARY_METRICS},
            }
        )
    return {
        "schema": SCHEMA_VERSION,
        "grid_hash": grid_hash,
        "axes": list(axes),
        "metrics": list(SUMMARY_METRICS),
        "cells": out_cells,
    }


def _fmt(s: dict[str, Any]) -> str:
    if s["mean"] is None:
        return "-"
    if s["ci95_low"] is None:
        return f"{s['mean']:.3g}"
    return f"{s['mean']:.3g} ± {(s['ci95_high'] - s['mean']):.2g}"


def markdown(summary: dict[str, Any]) -> str:
    """summary.md: one row per cell, mean ± 95 % CI half-width of each metric."""
    axes, metrics = summary["axes"], summary["metrics"]
    lines = [
        f"# Sweep summary (grid {summary['grid_hash'][:8]})",
        "",
        "Per grid cell: missions done / failed, then each metric's mean ± the half-width of the 95 % confidence "
        "interval of the mean (Student's t, n - 1 degrees of freedom); n of a metric counts the missions where "
        "it is not null. summary.json holds n, mean, std and the interval.",
        "",
        "| " + " | ".join([*axes, "done", "failed", *metrics]) + " |",
        "|" + "---|" * (len(axes) + 2 + len(metrics)),
    ]
    for c in summary["cells"]:
        vals = [str(c["labels"][a]) for a in axes] + [str(c["done"]), str(c["failed"])]
        vals += [_fmt(c["stats"][m]) for m in metrics]
        lines.append("| " + " | ".join(vals) + " |")
    return "\n".join(lines) + "\n"


def _numeric(rows: list[dict[str, Any]], axis: str) -> bool:
    vals = [r.get(axis) for r in rows]
    return bool(vals) and all(isinstance(v, int | float) and not isinstance(v, bool) for v in vals)


def figures(
    rows: list[dict[str, Any]], axes: list[str], folder: Path, metric: str = "tracking_error_mean_m"
) -> list[Path]:
    """The PNGs of the sweep in ``folder``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = [r for r in rows if r.get("status") == "done" and r.get(metric) is not None]
    if not done:
        return []
    numeric = [a for a in axes if _numeric(done, a)]
    categorical = [a for a in axes if a not in numeric]
    combos = list(dict.fromkeys(tuple(r.get(a) for a in categorical) for r in done))
    paths = []
    for x_axis in numeric:
        xs = sorted({r[x_axis] for r in done})
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        for combo in combos:
            sel = [r for r in done if tuple(r.get(a) for a in categorical) == combo]
            ss = [stats([r[metric] for r in sel if r[x_axis] == x]) for x in xs]
            mean = [s["mean"] if s["mean"] is not None else math.nan for s in ss]
            lo = [s["ci95_low"] if s["ci95_low"] is not None else m for s, m in zip(ss, mean, strict=True)]
            hi = [s["ci95_high"] if s["ci95_high"] is not None else m for s, m in zip(ss, mean, strict=True)]
            label = ", ".join(f"{a}={v}" for a, v in zip(categorical, combo, strict=True)) or "all"
            (line,) = ax.plot(xs, mean, "o-", label=label)
            ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
        others = [a for a in numeric if a != x_axis]
        note = f" (pooled over {', '.join(others)})" if others else ""
        ax.set_xlabel(x_axis)
        ax.set_ylabel(f"{metric} (mean, 95 % CI band)")
        ax.set_title(f"{metric} against {x_axis}{note}", fontsize=10)
        ax.legend(fontsize=7)
        path = folder / f"{metric}-vs-{x_axis}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    if not numeric:
        groups = list(dict.fromkeys(r.get(categorical[0]) for r in done)) if categorical else [None]
        rest = categorical[1:]
        bars = list(dict.fromkeys(tuple(r.get(a) for a in rest) for r in done))
        width = 0.8 / max(1, len(bars))
        fig, ax = plt.subplots(
            figsize=(max(6, 1.2 * len(groups) * max(1, len(bars)) ** 0.5), 4.5), constrained_layout=True
        )
        for k, combo in enumerate(bars):
            means, errs = [], []
            for g in groups:
                sel = [
                    r[metric]
                    for r in done
                    if (not categorical or r.get(categorical[0]) == g) and tuple(r.get(a) for a in rest) == combo
                ]
                s = stats(sel)
                means.append(s["mean"] if s["mean"] is not None else math.nan)
                errs.append(0.0 if s["ci95_high"] is None else s["ci95_high"] - s["mean"])
            xs = [i + (k - (len(bars) - 1) / 2) * width for i in range(len(groups))]
            label = ", ".join(f"{a}={v}" for a, v in zip(rest, combo, strict=True)) or metric
            ax.bar(xs, means, width, yerr=errs, capsize=2, label=label)
        ax.set_xticks(range(len(groups)), [str(g) for g in groups], fontsize=8)
        if categorical:
            ax.set_xlabel(categorical[0])
        ax.set_ylabel(f"{metric} (mean, 95 % CI)")
        ax.legend(fontsize=7)
        path = folder / f"{metric}-bars.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def write(rows: list[dict[str, Any]], axes: list[str], folder: Path, grid_hash: str) -> dict[str, Any]:
    """summary.json, summary.md and the figures into ``folder``; returns the summary."""
    summary = summarise(rows, axes, grid_hash)
    (folder / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    (folder / "summary.md").write_text(markdown(summary), encoding="utf-8")
    figures(rows, axes, folder)
    return summary
