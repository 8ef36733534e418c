"""Runs side by side (``auv-swarm compare``, ``auv_swarm.compare``): their metrics with the differences, the scenario
keys that differ, and ``compare.png``, their team-mean tracking error against sim time.

Each run is a results folder with metrics.json, scenario.toml and the raw data tables (record.parquet, truth.parquet;
:mod:`.tables`). The team-mean error is recomputed from those tables as docs/results.md defines it (the mean over the
live AUVs with an estimate of ``|estimate - truth|`` per tick), and plotted against each run's own sim time, whatever
the durations. Per-AUV figures (``agents``) and the kill list are left out of the side-by-side table.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from auv_swarm.contract.config import ConfigError, load_scenario
from auv_swarm.results.export import ExportError, read_tables
from auv_swarm.results.metrics import PAPER_ERROR_BOUND_M, team_error

FIGURE = "compare.png"
LEFT_OUT = ("agents", "kills")
"""metrics.json keys the side-by-side table leaves out (per AUV, per kill)."""


@dataclass
class Run:
    """One run folder as compared: its metrics, its scenario as plain data, and its team-mean error per tick."""

    path: Path
    metrics: dict[str, Any]
    scenario: dict[str, Any]
    times_s: np.ndarray
    team_error_m: np.ndarray


@dataclass
class Comparison:
    """What :func:`compare` found: per metric and per differing scenario key, one value per run (in the order
    given), the numeric differences to the first run, the warning when the base scenarios differ, the figure."""

    runs: list[Path]
    metrics: dict[str, list[Any]]
    differences: dict[str, list[float | None]]
    scenario_differences: dict[str, list[Any]]
    warning: str | None = None
    figure: Path | None = None
    labels: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (``--json``)."""
        return {
            "runs": [str(p) for p in self.runs],
            "metrics": self.metrics,
            "differences": self.differences,
            "scenario_differences": self.scenario_differences,
            "warning": self.warning,
            "figure": None if self.figure is None else str(self.figure),
        }

    def text(self) -> str:
        """The side-by-side table (metrics, differences to the first run), then the differing scenario keys."""
        labels = self.labels or [chr(ord("A") + k) for k in range(len(self.runs))]
        lines = [f"{lab} = {path}" for lab, path in zip(labels, self.runs, strict=True)]
        if self.warning:
            lines.insert(0, self.warning)
        head = ["metric", *labels, *(f"{lab} - {labels[0]}" for lab in labels[1:])]
        rows = [
            [k, *map(_fmt, v), *map(_fmt_diff, self.differences.get(k, [None] * len(v))[1:])]
            for k, v in self.metrics.items()
        ]
        lines += ["", *_columns([head, *rows])]
        lines += ["", "scenario keys that differ:" if self.scenario_differences else "scenario keys: all equal"]
        lines += _columns([["  " + k, *map(_fmt, v)] for k, v in self.scenario_differences.items()])
        return "\n".join(line.rstrip() for line in lines)


def compare(run_dirs: Sequence[Path | str], out: Path | str | None = None) -> Comparison:
    """Compare the run folders ``run_dirs`` (at least two) and write ``compare.png`` into ``out`` (default: the
    current folder); return the :class:`Comparison`. Raises :class:`~.export.ExportError` (a ValueError, one line)
    for a folder that is not a run with raw data."""
    if len(run_dirs) < 2:
        raise ExportError(f"compare needs at least two run folders, got {len(run_dirs)}")
    runs = [load_run(Path(p)) for p in run_dirs]
    metrics = _side_by_side([_flatten(r.metrics, LEFT_OUT) for r in runs])
    keys = _side_by_side([_flatten(r.scenario) for r in runs])
    names = sorted({str(r.scenario.get("name")) for r in runs})
    warning = None
    if len(names) > 1:
        warning = f"warning: the runs come from different base scenarios ({', '.join(names)}); every key is compared"
    result = Comparison(
        runs=[r.path for r in runs],
        metrics=metrics,
        differences={k: _diffs(v) for k, v in metrics.items()},
        scenario_differences={k: v for k, v in keys.items() if any(x != v[0] for x in v[1:])},
        warning=warning,
    )
    result.labels = [chr(ord("A") + k) if k < 26 else f"R{k}" for k in range(len(runs))]
    folder = Path(out) if out is not None else Path.cwd()
    folder.mkdir(parents=True, exist_ok=True)
    result.figure = folder / FIGURE
    _plot(runs, result).savefig(result.figure, dpi=110)
    return result


def load_run(path: Path) -> Run:
    """A run folder's metrics, scenario and team-mean error; :class:`~.export.ExportError` when something is
    missing or unreadable."""
    tables, _meta = read_tables(path)
    try:
        metrics = json.loads((path / "metrics.json").read_text(encoding="utf-8"))
        scenario = load_scenario(path / "scenario.toml").to_dict()
    except (OSError, ValueError, ConfigError) as exc:
        raise ExportError(f"{path}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    times, error = team_error_from_tables(tables["record"].to_pydict(), tables["truth"].to_pydict())
    return Run(path, metrics, scenario, times, error)


def team_error_from_tables(
    record: Mapping[str, Sequence[Any]], truth: Mapping[str, Sequence[Any]]
) -> tuple[np.ndarray, np.ndarray]:
    """(tick times s, team-mean tracking error m) from the columns of record.parquet and truth.parquet: each AUV's
    ``|est - source|`` per tick (NaN when dead or without an estimate), then :func:`~.metrics.team_error` of them,
    the mean metrics.json is made of."""
    t = np.asarray(truth["t_s"], dtype=float)
    tick = np.searchsorted(t, np.asarray(record["t_s"], dtype=float))
    sx = np.asarray(truth["source_x_m"], dtype=float)[tick]
    sy = np.asarray(truth["source_y_m"], dtype=float)[tick]
    err = np.hypot(np.asarray(record["est_x_m"], dtype=float) - sx, np.asarray(record["est_y_m"], dtype=float) - sy)
    valid = np.asarray(record["alive"], dtype=bool) & np.asarray(record["estimate_ok"], dtype=bool)
    auv = np.asarray(record["auv"], dtype=int)
    errors = {}
    for a in np.unique(auv):
        rows = auv == a
        errors[int(a)] = np.full(len(t), np.nan)
        errors[int(a)][tick[rows]] = np.where(valid[rows], err[rows], np.nan)
    return t, team_error(errors, len(t))


def _flatten(data: Mapping[str, Any], skip: Sequence[str] = (), prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in data.items():
        if key in skip and not prefix:
            continue
        if isinstance(value, Mapping):
            out.update(_flatten(value, (), f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _side_by_side(flat: Sequence[Mapping[str, Any]]) -> dict[str, list[Any]]:
    keys: list[str] = []
    for f in flat:
        keys += [k for k in f if k not in keys]
    return {k: [f.get(k) for f in flat] for k in keys}


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _diffs(values: Sequence[Any]) -> list[float | None]:
    first = values[0]
    return [v - first if _number(v) and _number(first) else None for v in values]


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, dict)):
        return json.dumps(v, separators=(",", ":"))
    return "null" if v is None else str(v)


def _fmt_diff(v: float | None) -> str:
    return "" if v is None else f"{v:+.6g}"


def _columns(rows: Sequence[Sequence[str]]) -> list[str]:
    if not rows:
        return []
    widths = [max(len(r[k]) for r in rows if k < len(r)) for k in range(max(len(r) for r in rows))]
    return ["  ".join(cell.ljust(widths[k]) for k, cell in enumerate(r)) for r in rows]


def _plot(runs: Sequence[Run], result: Comparison) -> Any:
    from auv_swarm.results.report import figure

    fig = figure(figsize=(9.0, 4.8))
    ax = fig.add_subplot()
    peak = 0.0
    for k, (label, run) in enumerate(zip(result.labels, runs, strict=True)):
        e = run.team_error_m
        if np.any(np.isfinite(e)):
            peak = max(peak, float(np.nanmax(e)))
        ax.plot(run.times_s, e, "-", color=f"C{k % 10}", lw=1.2, label=f"{label}: {run.path.name}")
    ax.axhline(PAPER_ERROR_BOUND_M, color="red", ls="--", lw=1.0, label=f"{PAPER_ERROR_BOUND_M:g} m bound")
    if peak > 20 * PAPER_ERROR_BOUND_M:
        ax.set_yscale("log")
    keys = ", ".join(result.scenario_differences) or "no scenario key"
    ax.set_title(f"team-mean tracking error; differing: {keys}"[:110], fontsize=10)
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("team-mean tracking error (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig
