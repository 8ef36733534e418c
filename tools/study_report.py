"""A Markdown report of a finished sweep folder: its grid, a pivot of the tracking error by planner method, the
summary table and the figures.

    python tools/study_report.py DIR [--out FILE] [--metric NAME] [--title TEXT]

DIR is a sweep folder (``auv-swarm sweep studies/coordination.toml`` writes ``sweeps/coordination-<hash>/``).
Numbers come from ``DIR/summary.json`` (docs/sweeps.md); figures are linked relative to ``FILE``'s folder.
"""

from __future__ import annotations

import argparse
import json
import os
import sqlite3
import sys
from pathlib import Path

from auv_swarm.orchestrator.sweep.summary import SUMMARY_METRICS, cell_text, markdown, metric_label

PIVOT_AXIS = "planner.method"


def pivot(summary: dict, metric: str) -> list[str]:
    """One row per combination of the other axes, one column per planner method: ``mean [lo, hi] (n)`` as in
    summary.md."""
    axes = summary["axes"]
    if PIVOT_AXIS not in axes:
        return []
    others = [a for a in axes if a != PIVOT_AXIS]
    methods = list(dict.fromkeys(c["labels"][PIVOT_AXIS] for c in summary["cells"]))
    table: dict[tuple, dict[str, dict]] = {}
    for c in summary["cells"]:
        key = tuple(c["labels"][a] for a in others)
        table.setdefault(key, {})[c["labels"][PIVOT_AXIS]] = c["stats"][metric]
    lines = [
        "| " + " | ".join([*others, *methods]) + " |",
        "|" + "---|" * (len(others) + len(methods)),
    ]
    for key, by in table.items():
        cells = [str(v) for v in key] + [cell_text(by[m]) if m in by else "-" for m in methods]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def report(folder: Path, out: Path | None, metric: str, title: str | None) -> str:
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    db = sqlite3.connect(f"file:{folder / 'sweep.sqlite'}?mode=ro", uri=True)
    try:
        meta = dict(db.execute("SELECT key, value FROM meta").fetchall())
        n, failed = db.execute("SELECT count(*), sum(status = 'failed') FROM missions").fetchone()
    finally:
        db.close()
    grid = json.loads(meta.get("grid", "{}"))
    axes = "; ".join(f"{a[0]}: {', '.join(map(str, a[1]))}" for a in grid.get("axes", []))
    seeds = grid.get("seeds", [])
    lines = [
        f"# {title or folder.name}",
        "",
        f"Grid {meta.get('grid_hash', '')[:8]}, auv-swarm {meta.get('version')}: base "
        f"{', '.join(grid.get('bases', [])) or '(scenario axis)'}; axes {axes or 'none'}; seeds "
        f"{seeds[0] if seeds else '-'}-{seeds[-1] if seeds else '-'} ({len(seeds)}); duration "
        f"{grid.get('duration_s') or 'each scenario'} s. {n} missions, {failed or 0} failed.",
        "",
    ]
    rows = pivot(summary, metric)
    if rows:
        lines += [f"## {metric_label(metric)} by {PIVOT_AXIS} (mean [95 % bootstrap interval] (n))", "", *rows, ""]
    lines += ["## Every cell", "", *markdown(summary).splitlines()[2:], ""]
    base = (out.parent if out else Path.cwd()).resolve()
    for png in sorted(folder.glob("*.png")):
        lines += [f"![{png.stem}]({os.path.relpath(png.resolve(), base)})", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--out", type=Path, default=None, help="write here instead of stdout")
    parser.add_argument("--metric", default="tracking_error_mean_m", choices=SUMMARY_METRICS)
    parser.add_argument("--title", default=None)
    args = parser.parse_args(argv)
    if not (args.folder / "summary.json").is_file():
        print(f"error: {args.folder} holds no summary.json (a finished sweep folder?)", file=sys.stderr)
        return 2
    text = report(args.folder, args.out, args.metric, args.title)
    if args.out:
        args.out.write_text(text, encoding="utf-8")
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
