"""Slopes of a sweep's metric against one numeric axis, per cell of the other axes, with 95 % intervals.

    python tools/study_slopes.py DIR --x AXIS [--metric NAME] [--per 0.01] [--against METHOD] [--png FILE]

For every seed and every combination of the other axes, the least-squares slope of the metric against
``AXIS`` over that seed's missions (the seeds are shared by every value of the axis, so each seed is its own
paired experiment); a group's slope is the mean of its seeds' slopes with the 95 % Student-t interval of that
mean (n - 1 degrees of freedom). With ``--against M`` (a ``planner.method`` value) each group also gets the
difference of its slope from method M's in the same cell of the other axes, paired by seed. Slopes are per
``--per`` units of the axis (e.g. ``--per 0.01``: per 1 % of ``navigation.drift_fraction``). Prints a Markdown
table; ``--png`` draws the slopes with their intervals. DIR is a finished sweep folder (its sweep.sqlite).
"""

from __future__ import annotations

import argparse
import json
import math
import sqlite3
import sys
from pathlib import Path

import numpy as np
from scipy.stats import t as student_t

METHOD_AXIS = "planner.method"


def load(folder: Path, x: str, metric: str) -> tuple[list[str], list[dict]]:
    """The store's done missions (axis values, seed, ``x`` and ``metric``) and the other axes' names."""
    db = sqlite3.connect(f"file:{folder / 'sweep.sqlite'}?mode=ro", uri=True)
    try:
        grid = json.loads(dict(db.execute("SELECT key, value FROM meta").fetchall())["grid"])
        axes = [a[0] for a in grid["axes"]]
        if x not in axes:
            raise SystemExit(f"error: {x!r} is not an axis of {folder} (axes: {', '.join(axes)})")
        cols = ", ".join(f'"{a}"' for a in axes)
        rows = db.execute(f"SELECT {cols}, seed, \"{metric}\" FROM missions WHERE status = 'done'").fetchall()
    finally:
        db.close()
    out = [dict(zip([*axes, "seed", metric], r, strict=True)) for r in rows]
    return [a for a in axes if a != x], [r for r in out if r[metric] is not None]


def mean_ci(values: list[float]) -> tuple[float, float]:
    """Mean and the half-width of its 95 % Student-t interval (nan with fewer than two values)."""
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return float(np.mean(v)) if v.size else math.nan, math.nan
    return float(v.mean()), float(student_t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))


def seed_slopes(rows: list[dict], others: list[str], x: str, metric: str, per: float) -> dict[tuple, dict]:
    """Group (values of the other axes) -> seed -> least-squares slope of ``metric`` against ``x`` (per ``per``)."""
    points: dict[tuple, dict[int, list[tuple[float, float]]]] = {}
    for r in rows:
        key = tuple(r[a] for a in others)
        points.setdefault(key, {}).setdefault(r["seed"], []).append((float(r[x]) / per, float(r[metric])))
    out: dict[tuple, dict] = {}
    for key, by_seed in points.items():
        slopes = {}
        for seed, pts in sorted(by_seed.items()):
            xs, ys = np.array(pts).T
            if np.ptp(xs) > 0:
                slopes[seed] = float(np.polyfit(xs, ys, 1)[0])
        out[key] = slopes
    return out


def table(others: list[str], slopes: dict[tuple, dict], against: str | None) -> tuple[list[str], list[tuple]]:
    """Markdown lines, and (label, slope, half-width) per group for the figure."""
    head = [*others, "seeds", "slope", "95 % CI"]
    method = others.index(METHOD_AXIS) if against and METHOD_AXIS in others else None
    if method is not None:
        head += [f"minus {against}", "95 % CI of the difference"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    bars = []
    for key, by_seed in slopes.items():
        m, half = mean_ci(list(by_seed.values()))
        cells = [str(v) for v in key] + [str(len(by_seed)), f"{m:.2f}", f"[{m - half:.2f}, {m + half:.2f}]"]
        if method is not None:
            ref = slopes.get(key[:method] + (against,) + key[method + 1 :], {})
            common = sorted(set(ref) & set(by_seed))
            d, dh = mean_ci([by_seed[s] - ref[s] for s in common]) if key[method] != against else (math.nan, math.nan)
            cells += ["-", "-"] if math.isnan(d) else [f"{d:+.2f}", f"[{d - dh:+.2f}, {d + dh:+.2f}]"]
        lines.append("| " + " | ".join(cells) + " |")
        bars.append((", ".join(str(v) for v in key), m, half))
    return lines, bars


def figure(bars: list[tuple], path: Path, x: str, metric: str, per: float) -> None:
    """Horizontal bars of every group's slope with its 95 % interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 0.45 * len(bars) + 1.2), constrained_layout=True)
    ys = range(len(bars))
    ax.errorbar([b[1] for b in bars], ys, xerr=[b[2] for b in bars], fmt="o", capsize=3)
    ax.axvline(0.0, color="grey", lw=0.8)
    ax.set_yticks(list(ys), [b[0] for b in bars], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel(f"{metric} per {per:g} of {x}")
    ax.set_title("slope: mean of the per-seed slopes, 95 % CI", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--x", required=True, help="the numeric axis to regress on")
    parser.add_argument("--metric", default="tracking_error_mean_m", help="a column of the store")
    parser.add_argument("--per", type=float, default=1.0, help="slope per this many units of the axis")
    parser.add_argument("--against", default=None, help="a planner.method to difference every slope against")
    parser.add_argument("--png", type=Path, default=None, help="also draw the slopes here")
    args = parser.parse_args(argv)
    if not (args.folder / "sweep.sqlite").is_file():
        print(f"error: {args.folder} holds no sweep.sqlite (a sweep folder?)", file=sys.stderr)
        return 2
    others, rows = load(args.folder, args.x, args.metric)
    slopes = seed_slopes(rows, others, args.x, args.metric, args.per)
    lines, bars = table(others, slopes, args.against)
    print("\n".join(lines))
    if args.png:
        figure(bars, args.png, args.x, args.metric, args.per)
    return 0


if __name__ == "__main__":
    sys.exit(main())
