"""The tables of docs/studies/ocean.md from a finished sweep store.

    python tools/ocean_tables.py SWEEP_DIR [--axis KEY] [--by KEY] [--base VALUE] [--against VALUE] [--d-max M]
        [--d-max-for VALUE=M ...] [--figure PNG]

Per value of ``--axis`` (and of ``--by``, as columns, if given): the cell means of ``bearing_detection_fraction``,
the tracking error (a mission without any estimate enters at ``--d-max``, its ``planner.d_max_m`` - or at
``--d-max-for`` for an axis value that sets another - and is named by seed), ``links_delivered_fraction`` and ``no_estimate_fraction``. Without ``--by``: the per-seed difference
of the tracking error between ``--against`` and ``--base`` (default the last and the first value), its mean,
standard error and their ratio.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

from auv_swarm.contract.usage import fail
from auv_swarm.orchestrator.sweep.store import STORE_FILE, read_rows

METRICS = ("bearing_detection_fraction", "error", "links_delivered_fraction", "no_estimate_fraction")


def load(folder: Path, axis: str, by: str | None) -> dict[tuple, dict[int, dict]]:
    """{(axis value, by value): {seed: metrics}} of the done missions of a sweep folder."""
    out: dict[tuple, dict[int, dict]] = {}
    rows = read_rows(folder)
    for key in (k for k in (axis, by) if k and rows and k not in rows[0]):
        raise KeyError(f"{folder}: the store has no column {key!r}")
    for row in rows:  # read-only: a wrong folder is an error, not a new empty store
        if row["status"] == "done":
            key = (row[axis], row[by] if by else None)
            out.setdefault(key, {})[row["seed"]] = json.loads(row["metrics"])
    return out


def value(m: dict, name: str, d_max: float) -> float:
    """A mission's metric; ``error`` is the tracking error or ``d_max`` (m) when it never had an estimate."""
    if name == "error":
        e = m.get("tracking_error_mean_m")
        return d_max if e is None else float(e)
    return float(m[name])


def cell(ms: dict[int, dict], d_max: float) -> dict[str, float]:
    """Means over the seeds of a cell, the error's standard error, and the seeds without any estimate."""
    out = {name: statistics.mean(value(m, name, d_max) for m in ms.values()) for name in METRICS}
    errors = [value(m, "error", d_max) for m in ms.values()]
    out["error_se"] = statistics.stdev(errors) / math.sqrt(len(errors)) if len(errors) > 1 else math.nan
    out["never"] = sorted(s for s, m in ms.items() if m.get("tracking_error_mean_m") is None)
    return out


def single(data: dict, args: argparse.Namespace) -> None:
    values = sorted(k[0] for k in data)
    print(
        f"| {args.axis} | bearing_detection_fraction | tracking error (m) | links_delivered_fraction | no_estimate_fraction | seeds without an estimate |"
    )
    print("|---|---|---|---|---|---|")

    def d_max(v) -> float:
        return args.d_max_for.get(str(v), args.d_max)

    for v in values:
        c = cell(data[(v, None)], d_max(v))
        print(
            f"| {v} | {c['bearing_detection_fraction']:.3f} | {c['error']:.1f} | {c['links_delivered_fraction']:.3f} "
            f"| {c['no_estimate_fraction']:.3f} | {', '.join(map(str, c['never'])) or '-'} |"
        )
    base = values[0] if args.base is None else type(values[0])(args.base)
    against = values[-1] if args.against is None else type(values[0])(args.against)
    a, b = data[(against, None)], data[(base, None)]
    seeds = sorted(set(a) & set(b))
    diff = [value(a[s], "error", d_max(against)) - value(b[s], "error", d_max(base)) for s in seeds]
    mean, se = statistics.mean(diff), statistics.stdev(diff) / math.sqrt(len(diff))
    print(
        f"\nper-seed error difference {against} - {base} over {len(diff)} seeds: mean {mean:.1f} m, standard error {se:.1f} m, mean / SE = {mean / se:.1f}"
    )
    print("differences (m): " + ", ".join(f"s{s} {d:.1f}" for s, d in zip(seeds, diff, strict=True)))


def pivot(data: dict, args: argparse.Namespace) -> None:
    rows = list(dict.fromkeys(k[0] for k in data))
    cols = list(dict.fromkeys(k[1] for k in data))
    for name, fmt in (
        ("error", "{:.1f} ± {:.1f}"),
        ("bearing_detection_fraction", "{:.3f}"),
        ("no_estimate_fraction", "{:.3f}"),
        ("links_delivered_fraction", "{:.3f}"),
    ):
        print(f"\n{name} by {args.axis} (rows) and {args.by} (columns)\n")
        print(f"| {args.axis} | " + " | ".join(map(str, cols)) + " |")
        print("|---|" + "---|" * len(cols))
        for r in rows:
            cells = []
            for c in cols:
                if (r, c) not in data:
                    cells.append("-")
                    continue
                s = cell(data[(r, c)], args.d_max_for.get(str(r), args.d_max))
                text = fmt.format(s[name], s["error_se"]) if name == "error" else fmt.format(s[name])
                cells.append(text + (f" ({len(s['never'])} w/o est.)" if name == "error" and s["never"] else ""))
            print(f"| {r} | " + " | ".join(cells) + " |")


def figure(data: dict, args: argparse.Namespace, path: Path) -> None:
    """Two panels by ``--axis`` value (rows) and ``--by`` value (bars): the tracking error (log scale, mean and
    standard error, missions without an estimate at their d_max) and the bearing detection fraction."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = list(dict.fromkeys(k[0] for k in data))
    cols = list(dict.fromkeys(k[1] for k in data))
    fig = Figure(figsize=(10.0, 0.42 * len(rows) + 1.6), dpi=110)
    FigureCanvasAgg(fig)
    err_ax, det_ax = fig.subplots(1, 2, sharey=True)
    height = 0.8 / len(cols)
    for j, c in enumerate(cols):
        cells = [cell(data[(r, c)], args.d_max_for.get(str(r), args.d_max)) for r in rows]
        y = [i + (j - (len(cols) - 1) / 2) * height for i in range(len(rows))]
        err_ax.barh(y, [x["error"] for x in cells], height, xerr=[x["error_se"] for x in cells], label=str(c))
        det_ax.barh(y, [x["bearing_detection_fraction"] for x in cells], height, label=str(c))
    err_ax.set(
        xscale="log", xlabel="tracking error (m; no estimate at all: d_max), mean +- SE", yticks=range(len(rows))
    )
    err_ax.set_yticklabels([str(r) for r in rows])
    err_ax.invert_yaxis()
    det_ax.set(xlabel="bearing detection fraction", xlim=(0.0, 1.05))
    det_ax.legend(title=args.by, fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--axis", default="ocean.wind_mps")
    parser.add_argument("--by", default=None)
    parser.add_argument("--base", default=None)
    parser.add_argument("--against", default=None)
    parser.add_argument("--d-max", type=float, default=1000.0, help="planner.d_max_m of the scenario (m)")
    parser.add_argument("--d-max-for", nargs="*", default=[], help="VALUE=M: planner.d_max_m of an axis value")
    parser.add_argument("--figure", type=Path, default=None, help="with --by: write the two-panel figure there")
    args = parser.parse_args(argv)
    args.d_max_for = {k: float(v) for k, _, v in (item.partition("=") for item in args.d_max_for)}
    if not (args.folder / STORE_FILE).is_file():
        return fail(f"{args.folder}: no {STORE_FILE} (give a sweep's folder)")
    try:
        data = load(args.folder, args.axis, args.by)
    except KeyError as exc:
        return fail(exc.args[0])
    (pivot if args.by else single)(data, args)
    if args.figure is not None and args.by:
        figure(data, args, args.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
