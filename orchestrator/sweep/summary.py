"""A sweep's summaries (docs/sweeps.md): ``summary.json`` and ``summary.md`` per grid cell, and its figures.

Per cell (one combination of the axis values) and for each of :data:`SUMMARY_METRICS`: n (missions done with
a value), the mean over the seeds, the sample std (n - 1) and an interval: for n >= 3 the 95 % percentile
bootstrap interval of the mean (:data:`BOOTSTRAP_RESAMPLES` resamples of the seeds, a fixed generator: the same
values give the same interval, and it lies inside the values' range), for n = 2 the two values, for n = 1
none. ``summary.md`` prints each as ``mean [lo, hi] (n)`` in plain decimals of three significant digits
(:func:`plain`), fractions as fractions, every metric under its label and unit
(:data:`~auv_swarm.results.metric_info.METRIC_INFO`). Figures: for each numeric axis one PNG per
:data:`HEADLINE_METRICS` (the metric against the axis, one line per combination of the other axes, the interval
as a band), grouped bars when the grid's axes are all categorical, none for a grid without an axis.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from auv_swarm.results.metric_info import METRIC_INFO
from auv_swarm.results.metric_info import label as metric_label

SUMMARY_METRICS = (
    "tracking_error_mean_m",
    "tracking_error_p95_m",
    "convergence_time_s",
    "nees_in_band_fraction",
    "fqi",
    "plan_time_median_ms",
    "nav_error_mean_m",
)
HEADLINE_METRICS = SUMMARY_METRICS[:4]
"""The metrics drawn against each numeric axis: mean error, p95, convergence time, NEES in band."""
BOOTSTRAP_RESAMPLES = 4000
BOOTSTRAP_SEED = 0
"""The bootstrap's generator seed: a summary is a function of the store's rows."""
SCHEMA_VERSION = 2
SUMMARY_SCHEMA = {
    "schema": "int, the schema version (2)",
    "grid_hash": "str, the grid's SHA-256",
    "axes": "list of str, the axis columns",
    "metrics": "list of str, the summarised metrics",
    "cells": (
        "list, one per grid cell: {labels: {axis: value}, missions: int, done: int, failed: int, "
        "stats: {metric: {n: int, mean: float|null, std: float|null, lo: float|null, hi: float|null, "
        "interval: str|null}}}"
    ),
}
"""summary.json's fields (docs/sweeps.md)."""

INTERVALS = {
    "bootstrap95": "the 95 % percentile bootstrap interval of the mean over the seeds (n >= 3)",
    "values": "the two values (n = 2)",
}
"""The kinds of ``interval`` in summary.json (null for n < 2)."""


def interval(values: list[float]) -> tuple[float | None, float | None, str | None]:
    """(lo, hi, kind) of ``values``: the 95 % percentile bootstrap interval of their mean for three or more, the
    two values for two, nothing for fewer. Inside [min, max] of the values by construction."""
    v = np.sort(np.asarray(values, dtype=float))
    if v.size < 2:
        return None, None, None
    if v.size == 2:
        return float(v[0]), float(v[1]), "values"
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    means = v[rng.integers(0, v.size, size=(BOOTSTRAP_RESAMPLES, v.size))].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(max(lo, v[0])), float(min(hi, v[-1])), "bootstrap95"


def stats(values: list[Any]) -> dict[str, Any]:
    """n, mean, sample std (n - 1) and :func:`interval` of the finite numbers in ``values``."""
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    n = len(v)
    out: dict[str, Any] = {"n": n, "mean": None, "std": None, "lo": None, "hi": None, "interval": None}
    if n == 0:
        return out
    mean = sum(v) / n
    out["mean"] = mean
    if n >= 2:
        out["std"] = math.sqrt(sum((x - mean) ** 2 for x in v) / (n - 1))
    out["lo"], out["hi"], out["interval"] = interval(v)
    return out


def plain(x: float | None) -> str:
    """``x`` as a plain decimal with three significant digits, never in e-notation: 1230, 88.1, 0.877, 0.000123;
    "-" for None."""
    if x is None or not math.isfinite(x):
        return "-"
    if x == 0:
        return "0"
    v = float(f"{x:.3g}")
    decimals = max(0, 2 - math.floor(math.log10(abs(v))))
    return f"{v:.{decimals}f}"


def cell_text(s: dict[str, Any]) -> str:
    """One metric of one cell: ``mean [lo, hi] (n)``, ``mean (1)`` for one value, ``-`` for none."""
    if s["mean"] is None:
        return "-"
    if s["lo"] is None:
        return f"{plain(s['mean'])} ({s['n']})"
    return f"{plain(s['mean'])} [{plain(s['lo'])}, {plain(s['hi'])}] ({s['n']})"


def axis_meaning(key: str) -> str | None:
    """The start of a scenario key's meaning (``packet delivery ratio of the Bernoulli loss model``), or None for
    a variant or ``scenario`` axis."""
    from auv_swarm.contract.config import describe

    doc = {k: d for k, _, d in describe()}.get(key)
    if not doc:
        return None
    short = doc.split(":")[0].split(";")[0].strip()
    return short.split(" (")[0] if len(short) > 60 else short


def axis_label(key: str) -> str:
    """A sweep axis as a figure label: the key and the start of its meaning (``channel.pdr: packet delivery ratio
    of the Bernoulli loss model``); a variant or ``scenario`` axis as itself."""
    meaning = axis_meaning(key)
    return f"{key}: {meaning}" if meaning else key


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


LEGEND = (
    "Per grid cell: missions done and failed, then each metric as `mean [lo, hi] (n)` over the seeds: n counts "
    "the missions where the metric is not null; [lo, hi] is the 95 % percentile bootstrap interval of the mean "
    f"({BOOTSTRAP_RESAMPLES} resamples of the seeds; it lies inside the values' range) for n >= 3, the two "
    "values for n = 2, left out for n = 1. Three significant digits; fractions are fractions of 1. "
    "summary.json also holds each metric's sample std (n - 1)."
)


def markdown(summary: dict[str, Any]) -> str:
    """summary.md: one row per cell, each metric as :func:`cell_text` under its label and unit."""
    axes, metrics = summary["axes"], summary["metrics"]
    lines = [
        f"# Sweep summary (grid {summary['grid_hash'][:8]})",
        "",
        LEGEND,
        "",
        "| " + " | ".join([*axes, "done", "failed", *(metric_label(m) for m in metrics)]) + " |",
        "|" + "---|" * (len(axes) + 2 + len(metrics)),
    ]
    for c in summary["cells"]:
        vals = [str(c["labels"][a]) for a in axes] + [str(c["done"]), str(c["failed"])]
        vals += [cell_text(c["stats"][m]) for m in metrics]
        lines.append("| " + " | ".join(vals) + " |")
    return "\n".join(lines) + "\n"


def _title(metric: str) -> str:
    label = METRIC_INFO[metric].label if metric in METRIC_INFO else metric
    return label[:1].upper() + label[1:]


def _numeric(rows: list[dict[str, Any]], axis: str) -> bool:
    vals = [r.get(axis) for r in rows]
    return bool(vals) and all(isinstance(v, int | float) and not isinstance(v, bool) for v in vals)


def _band(ss: list[dict[str, Any]]) -> tuple[list[float], list[float], list[float]]:
    """Means and the interval's edges of a line's points (NaN where there is no value; the mean where no
    interval)."""
    mean = [s["mean"] if s["mean"] is not None else math.nan for s in ss]
    lo = [s["lo"] if s["lo"] is not None else m for s, m in zip(ss, mean, strict=True)]
    hi = [s["hi"] if s["hi"] is not None else m for s, m in zip(ss, mean, strict=True)]
    return mean, lo, hi


def _line_figure(done: list[dict], x_axis: str, numeric: list[str], categorical: list[str], metric: str, path: Path):
    """One metric against one numeric axis: a line (and its interval band) per combination of the categorical
    axes."""
    import matplotlib.pyplot as plt

    xs = sorted({r[x_axis] for r in done})
    combos = list(dict.fromkeys(tuple(r.get(a) for a in categorical) for r in done))
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    for combo in combos:
        sel = [r for r in done if tuple(r.get(a) for a in categorical) == combo]
        mean, lo, hi = _band([stats([r.get(metric) for r in sel if r[x_axis] == x]) for x in xs])
        label = ", ".join(f"{a} = {v}" for a, v in zip(categorical, combo, strict=True)) or "mean over the seeds"
        (line,) = ax.plot(xs, mean, "o-", label=label)
        ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
    others = [a for a in numeric if a != x_axis]
    note = f"; pooled over {', '.join(others)}" if others else ""
    ax.set_xlabel(axis_label(x_axis))
    ax.set_ylabel(metric_label(metric))
    ax.set_title(
        f"{_title(metric)} against {axis_meaning(x_axis) or x_axis}\n"
        f"mean over the seeds, band: the 95 % bootstrap interval of the mean (n = 2: the two values){note}",
        fontsize=9,
    )
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _bar_figure(done: list[dict], categorical: list[str], metric: str, path: Path) -> None:
    """One metric as grouped bars: groups by the first axis, one bar per combination of the others."""
    import matplotlib.pyplot as plt

    groups = list(dict.fromkeys(r.get(categorical[0]) for r in done))
    rest = categorical[1:]
    bars = list(dict.fromkeys(tuple(r.get(a) for a in rest) for r in done))
    width = 0.8 / len(bars)
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * len(groups) * len(bars) ** 0.5), 4.5), constrained_layout=True)
    for k, combo in enumerate(bars):
        means, errs = [], [[], []]
        for g in groups:
            sel = [r for r in done if r.get(categorical[0]) == g and tuple(r.get(a) for a in rest) == combo]
            (mean,), (lo,), (hi,) = _band([stats([r.get(metric) for r in sel])])
            means.append(mean)
            errs[0].append(max(0.0, mean - lo) if math.isfinite(mean) else 0.0)
            errs[1].append(max(0.0, hi - mean) if math.isfinite(mean) else 0.0)
        xs = [i + (k - (len(bars) - 1) / 2) * width for i in range(len(groups))]
        label = ", ".join(f"{a} = {v}" for a, v in zip(rest, combo, strict=True)) or None
        ax.bar(xs, means, width, yerr=errs, capsize=2, label=label)
    ax.set_xticks(range(len(groups)), [str(g) for g in groups], fontsize=8)
    ax.set_xlabel(axis_label(categorical[0]))
    ax.set_ylabel(metric_label(metric))
    ax.set_title(
        f"{_title(metric)}: mean over the seeds, whiskers the 95 % bootstrap interval (n = 2: the two values)",
        fontsize=9,
    )
    if rest:
        ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figures(rows: list[dict[str, Any]], axes: list[str], folder: Path) -> list[Path]:
    """The PNGs of the sweep in ``folder`` (none for a grid without an axis); returns their paths."""
    import matplotlib

    matplotlib.use("Agg")

    if not axes:
        return []
    paths = []
    for metric in HEADLINE_METRICS:
        done = [r for r in rows if r.get("status") == "done" and r.get(metric) is not None]
        if not done:
            continue
        numeric = [a for a in axes if _numeric(done, a)]
        categorical = [a for a in axes if a not in numeric]
        for x_axis in numeric:
            paths.append(folder / f"{metric}-vs-{x_axis}.png")
            _line_figure(done, x_axis, numeric, categorical, metric, paths[-1])
        if not numeric:
            paths.append(folder / f"{metric}-bars.png")
            _bar_figure(done, categorical, metric, paths[-1])
    return paths


def write(rows: list[dict[str, Any]], axes: list[str], folder: Path, grid_hash: str) -> dict[str, Any]:
    """summary.json, summary.md and the figures into ``folder``; returns the summary."""
    summary = summarise(rows, axes, grid_hash)
    (folder / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    (folder / "summary.md").write_text(markdown(summary), encoding="utf-8")
    figures(rows, axes, folder)
    return summary
