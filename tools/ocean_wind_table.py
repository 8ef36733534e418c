"""The wind table of docs/studies/ocean.md from a finished sweep over one axis (``ocean.wind_mps`` by default).

    python tools/ocean_wind_table.py SWEEP_DIR [--axis KEY] [--base VALUE] [--against VALUE]

Per axis value: the cell means of ``bearing_detection_fraction``, ``tracking_error_mean_m`` (a mission without any
estimate enters at its ``planner.d_max_m`` and is named by seed), ``links_delivered_fraction`` and
``no_estimate_fraction``; then the per-seed difference of the tracking error between ``--against`` and ``--base``
(default the largest and the smallest value), its mean, standard error and their ratio.
"""

from __future__ import annotations

import argparse
import json
import math
import sqlite3
import statistics
import sys
from pathlib import Path


def rows(folder: Path, axis: str) -> dict[object, dict[int, dict]]:
    """{axis value: {seed: metrics}} of the done missions of a sweep folder."""
    con = sqlite3.connect(folder / "sweep.sqlite")
    out: dict[object, dict[int, dict]] = {}
    for value, seed, metrics in con.execute(f'SELECT "{axis}", seed, metrics FROM missions WHERE status = "done"'):
        out.setdefault(json.loads(value) if isinstance(value, str) and value[:1] in "[{" else value, {})[seed] = (
            json.loads(metrics)
        )
    return out


def error_or_dmax(m: dict, d_max: float) -> float:
    """The mission's tracking error, or ``d_max`` (m) when it never had an estimate."""
    e = m.get("tracking_error_mean_m")
    return d_max if e is None else float(e)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--axis", default="ocean.wind_mps")
    parser.add_argument("--base", default=None)
    parser.add_argument("--against", default=None)
    parser.add_argument("--d-max", type=float, default=1000.0, help="planner.d_max_m of the scenario (m)")
    args = parser.parse_args(argv)
    data = rows(args.folder, args.axis)
    values = sorted(data)
    print(
        f"| {args.axis} | bearing_detection_fraction | tracking error (m) | links_delivered_fraction | no_estimate_fraction | missions without an estimate (seeds) |"
    )
    print("|---|---|---|---|---|---|")
    for v in values:
        ms = data[v]
        det = statistics.mean(m["bearing_detection_fraction"] for m in ms.values())
        err = statistics.mean(error_or_dmax(m, args.d_max) for m in ms.values())
        links = statistics.mean(m["links_delivered_fraction"] for m in ms.values())
        none = statistics.mean(m["no_estimate_fraction"] for m in ms.values())
        never = sorted(s for s, m in ms.items() if m.get("tracking_error_mean_m") is None)
        print(f"| {v:g} | {det:.3f} | {err:.1f} | {links:.3f} | {none:.3f} | {', '.join(map(str, never)) or '-'} |")
    base = float(args.base) if args.base is not None else values[0]
    against = float(args.against) if args.against is not None else values[-1]
    seeds = sorted(set(data[base]) & set(data[against]))
    diff = [error_or_dmax(data[against][s], args.d_max) - error_or_dmax(data[base][s], args.d_max) for s in seeds]
    mean = statistics.mean(diff)
    se = statistics.stdev(diff) / math.sqrt(len(diff)) if len(diff) > 1 else math.nan
    print(
        f"\nper-seed error difference {against:g} - {base:g} over {len(diff)} seeds: mean {mean:.1f} m, "
        f"standard error {se:.1f} m, mean / SE = {mean / se:.1f}"
    )
    print("differences (m): " + ", ".join(f"s{s} {d:.1f}" for s, d in zip(seeds, diff, strict=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
