"""The grid of a sweep (``auv-swarm sweep``, docs/sweeps.md): base scenarios, axes, seeds and duration, and the
missions they make.

An axis is a dotted scenario key with a list of values (``channel.pdr=0.3,0.5``, applied as
:meth:`~auv_swarm.contract.config.Scenario.with_keys` does), the axis ``scenario`` (base scenarios), or, in a
sweep file, a named-variant axis whose values are tables of keys (``geometry = {surround = {...}, ...}``); its
column holds the variant's name. The grid is the product of the axes; every cell is checked before the first
mission starts (:meth:`Grid.check`). The grid's hash covers its base scenarios, axes and their values, seeds and
duration, and the content of every resolved cell's scenario with the files it names
(:func:`~auv_swarm.contract.config.named_files`): an edited scenario file makes another grid. The default folder
is ``sweeps/<base>-<8 hex>/``, named by the command alone (so the same command meets its edited grid there).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from auv_swarm.contract import usage
from auv_swarm.contract.config import ConfigError, Scenario, dump_toml, load_scenario, named_files

SCENARIO_AXIS = "scenario"
"""The axis over base scenarios (names or TOML paths)."""
DEFAULT_SEEDS = 10
"""Seeds 1..N when none are given."""
SWEEP_TABLE = "sweep"
"""The table that makes a TOML file a sweep file."""
SWEEP_KEYS = ("scenario", "axes", "seeds", "duration", "skip_invalid", "description")


class GridError(ValueError):
    """The grid's input is wrong; the message is one line for the user."""


@dataclass(frozen=True)
class Axis:
    """One axis: a dotted key (or ``scenario``, or a variant axis's name) and its values.

    ``variants`` is given for a named-variant axis: variant name -> the keys it sets; then ``values`` are the
    names.
    """

    key: str
    values: tuple[Any, ...]
    variants: dict[str, dict[str, Any]] | None = None

    def keys_for(self, value: Any) -> dict[str, Any]:
        """The scenario keys this axis sets for one of its values."""
        if self.key == SCENARIO_AXIS:
            return {}
        if self.variants is not None:
            return dict(self.variants[value])
        return {self.key: value}

    @property
    def numeric(self) -> bool:
        """True if every value is a number (not a bool): the axis can be a plot's x axis."""
        return self.variants is None and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in self.values
        )

    def plain(self) -> list[Any]:
        """JSON form for the grid's record and hash."""
        if self.variants is not None:
            return [self.key, {name: self.variants[name] for name in self.values}]
        return [self.key, list(self.values)]


@dataclass(frozen=True)
class Cell:
    """One grid cell: its base scenario, the axis values (column -> value) and the scenario it resolves to."""

    base: str
    labels: dict[str, Any]
    scenario: Scenario

    @cached_property
    def sha256(self) -> str:
        """SHA-256 of the fully resolved scenario TOML, the seed left out (run.seed written as 0)."""
        return scenario_sha256(self.scenario)


@dataclass(frozen=True)
class Mission:
    """One mission of the sweep: a cell and a seed."""

    cell: Cell
    seed: int

    @property
    def key(self) -> tuple[str, int]:
        return (self.cell.sha256, self.seed)

    def scenario(self) -> Scenario:
        return self.cell.scenario.with_keys({"run.seed": self.seed})


@dataclass
class Grid:
    """Base scenarios, axes, seeds and duration (None: each scenario's own) of a sweep."""

    bases: list[str]
    axes: list[Axis]
    seeds: list[int]
    duration_s: float | None = None
    skip_invalid: bool = False
    stem: str | None = None
    """The sweep file's stem (its default folder's name), or None on the command line."""
    skipped: list[tuple[dict[str, Any], str]] = field(default_factory=list)
    """Cells dropped by ``skip_invalid`` (labels, reason), filled by :meth:`check`."""
    content_sha256: str | None = None
    """SHA-256 over every valid cell's resolved scenario and the files it names, set by :meth:`check`."""

    @property
    def columns(self) -> list[str]:
        """The axis columns of the store, in axis order (``scenario`` first when it is an axis)."""
        return [a.key for a in self.axes]

    def command(self) -> dict[str, Any]:
        """The grid as given: base scenarios, axes and their values, seeds, duration (names the default folder)."""
        return {
            "bases": list(self.bases),
            "axes": [a.plain() for a in self.axes],
            "seeds": list(self.seeds),
            "duration_s": self.duration_s,
        }

    def plain(self) -> dict[str, Any]:
        """Exactly what the hash covers: :meth:`command` and the cells' content (``content_sha256``)."""
        return {**self.command(), "content_sha256": self.content_sha256}

    @property
    def hash(self) -> str:
        """The grid's SHA-256 (hex), after :meth:`check` (it covers the resolved scenarios' content)."""
        if self.content_sha256 is None:
            raise RuntimeError("Grid.hash needs the resolved cells: call Grid.check() first")
        return _sha256_json(self.plain())

    @property
    def base_name(self) -> str:
        """``<base>`` of the default folder: the sweep file's stem, ``multi`` for a scenario axis, else the
        scenario's name (a path's last part without ``.toml``), as one safe folder name."""
        if self.stem:
            return folder_name(self.stem)
        if any(a.key == SCENARIO_AXIS for a in self.axes) or len(self.bases) != 1:
            return "multi"
        return folder_name(self.bases[0])

    def default_folder(self, root: Path = Path("sweeps")) -> Path:
        """``sweeps/<base>-<8 hex of the command>``: always one folder directly under ``root``."""
        return root / f"{self.base_name}-{_sha256_json(self.command())[:8]}"

    def check(self) -> list[Cell]:
        """Resolve and check every cell; returns the valid cells.

        Raises :class:`GridError` listing every invalid cell (its labels, the key and the reason), unless
        ``skip_invalid``, which drops them (counted in :attr:`skipped`).
        """
        from auv_swarm.orchestrator.mission.api import check_runnable

        base_axis = next((a for a in self.axes if a.key == SCENARIO_AXIS), None)
        loaded: dict[str, Scenario] = {}
        for name in base_axis.values if base_axis else self.bases:
            try:
                loaded[name] = load_scenario(name)
            except ConfigError as exc:
                raise GridError(str(exc)) from exc  # it names the scenario or its file
        cells, bad = [], []
        self.skipped = []
        for combo in itertools.product(*(a.values for a in self.axes)):
            labels = dict(zip(self.columns, combo, strict=True))
            base = labels.get(SCENARIO_AXIS, self.bases[0] if self.bases else None)
            keys: dict[str, Any] = {}
            for axis, value in zip(self.axes, combo, strict=True):
                keys.update(axis.keys_for(value))
            if self.duration_s is not None:
                keys["run.duration_s"] = self.duration_s
            try:
                scenario = loaded[base].with_keys(keys)
                check_runnable(scenario, "inprocess")  # builds a missing Bellhop table once; the workers get it shipped
            except (ConfigError, ValueError) as exc:
                bad.append((labels, str(exc)))
                continue
            cells.append(Cell(base, labels, scenario))
        if bad and not self.skip_invalid:
            raise GridError(f"{len(bad)} of {len(bad) + len(cells)} grid cells are invalid: {_bad_listing(bad)}")
        self.skipped = bad
        if not cells:
            raise GridError("the grid has no valid cell")
        self.content_sha256 = content_sha256(cells)
        return cells

    def missions(self, cells: list[Cell]) -> list[Mission]:
        return [Mission(cell, seed) for cell in cells for seed in self.seeds]


def _label_text(labels: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in labels.items()) or "(the base scenario)"


def _bad_listing(bad: list[tuple[dict[str, Any], str]]) -> str:
    """The invalid cells, one reason each; a reason shared by several cells (an unknown key) is given once, with
    the cells it concerns."""
    by_reason: dict[str, list[str]] = {}
    for labels, reason in bad:
        by_reason.setdefault(reason, []).append(_label_text(labels))
    parts = []
    for reason, cells in by_reason.items():
        parts.append(
            f"{cells[0]}: {reason}" if len(cells) == 1 else f"{len(cells)} cells ({'; '.join(cells)}): {reason}"
        )
    return "; ".join(parts)


def folder_name(name: str) -> str:
    """One safe folder name from a scenario name or path: its last part without ``.toml``, characters other than
    letters, digits, ``.``, ``_`` and ``-`` as ``-``, no leading dot (never ``..``, never a path)."""
    last = Path(str(name).rstrip("/")).name
    last = last.removesuffix(".toml")
    safe = re.sub(r"[^A-Za-z0-9._-]", "-", last).lstrip(".")
    return safe or "scenario"


def _sha256_json(data: Any) -> str:
    return hashlib.sha256(json.dumps(data, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def content_sha256(cells: list[Cell]) -> str:
    """SHA-256 over the cells' resolved scenarios (:attr:`Cell.sha256`) and the content of the files they name
    (a missing file counts as missing): what makes an edited scenario file another grid."""
    files: dict[str, str] = {}
    for cell in cells:
        for path in named_files(cell.scenario):
            try:
                files[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
            except OSError:
                files[str(path)] = "missing"
    return _sha256_json({"cells": sorted(c.sha256 for c in cells), "files": files})


def scenario_sha256(scenario: Scenario) -> str:
    """SHA-256 (hex) of the resolved scenario's TOML with ``run.seed`` written as 0."""
    return hashlib.sha256(dump_toml(scenario.with_keys({"run.seed": 0})).encode()).hexdigest()


def parse_value(text: str) -> Any:
    """A command-line axis value: a TOML scalar (``0.5``, ``3``, ``true``, ``"x"``), else the text as a string."""
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    if isinstance(value, float) and not math.isfinite(value):
        return text
    return value


def parse_axis(item: str) -> Axis:
    """``KEY=V1,V2,...`` -> Axis (GridError naming the item if it is not that shape)."""
    key, sep, values = item.partition("=")
    key = key.strip()
    if not sep or not key or not values.strip():
        raise GridError(f"axis {item!r}: expected KEY=V1,V2,... (e.g. channel.pdr=0.3,0.5)")
    parts = [v.strip() for v in values.split(",")]
    if any(not p for p in parts):
        raise GridError(f"axis {item!r}: an empty value")
    parsed = tuple(p if key == SCENARIO_AXIS else parse_value(p) for p in parts)
    if len(set(map(repr, parsed))) != len(parsed):
        raise GridError(f"axis {key!r}: a value is given twice")
    return Axis(key, parsed)


def parse_seeds(value: Any) -> list[int]:
    """``A-B`` (inclusive) or ``N`` (1..N), as every ``--seeds`` takes them (:func:`contract.usage.parse_seeds`);
    an int N, or (in a sweep file) a list of ints."""
    if isinstance(value, list):
        if not value or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value):
            raise GridError(f"seeds: a list of integers >= 0 expected, got {value!r}")
        return sorted(set(value))
    if isinstance(value, bool) or not isinstance(value, int | str):
        raise GridError(f"seeds must be A-B or N, got {value!r}")
    try:
        return usage.parse_seeds(value)
    except ValueError as exc:
        raise GridError(str(exc)) from None


def _check_axes(axes: list[Axis]) -> None:
    seen: dict[str, str] = {}
    for a in axes:
        if a.key.lower() in seen:
            twice = (
                "is given twice" if seen[a.key.lower()] == a.key else f"and {seen[a.key.lower()]!r} differ only in case"
            )
            raise GridError(f"axis {a.key!r} {twice}")
        seen[a.key.lower()] = a.key
        if not a.values:
            raise GridError(f"axis {a.key!r} has no value")


def from_command_line(scenario: str | None, axis_items: list[str], seeds: str | None, duration_s: float | None) -> Grid:
    """The grid of ``auv-swarm sweep [SCENARIO] [KEY=V1,...]...``."""
    axes = [parse_axis(item) for item in axis_items]
    _check_axes(axes)
    has_scenario_axis = any(a.key == SCENARIO_AXIS for a in axes)
    if has_scenario_axis and scenario is not None:
        raise GridError("give either SCENARIO or a scenario= axis, not both")
    axes.sort(key=lambda a: a.key != SCENARIO_AXIS)
    bases = [] if has_scenario_axis else [scenario or "paper-3.2-challenging"]
    return Grid(bases, axes, parse_seeds(seeds if seeds is not None else DEFAULT_SEEDS), parse_duration(duration_s))


def parse_duration(value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value <= 1e7:
        raise GridError(f"duration must be a number of seconds in (0, 1e7], got {value!r}")
    return float(value)


def is_sweep_file(path: str) -> bool:
    """True if ``path`` is a TOML file with a ``[sweep]`` table."""
    p = Path(path)
    if p.suffix != ".toml" or not p.is_file():
        return False
    try:
        return SWEEP_TABLE in tomllib.loads(p.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return False


def from_file(path: str | Path, seeds: str | None = None, duration_s: float | None = None) -> Grid:
    """The grid of a sweep file (its ``[sweep]`` table; docs/sweeps.md); ``seeds``/``duration_s`` override it."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))[SWEEP_TABLE]
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise GridError(f"sweep file {path}: {exc}") from exc
    unknown = sorted(set(data) - set(SWEEP_KEYS))
    if unknown:
        raise GridError(f"sweep file {path}: unknown key sweep.{unknown[0]} (known: {', '.join(SWEEP_KEYS)})")
    axes = []
    for key, spec in (data.get("axes") or {}).items():
        if isinstance(spec, list):
            axes.append(Axis(key, tuple(spec)))
        elif isinstance(spec, dict) and spec and all(isinstance(v, dict) for v in spec.values()):
            axes.append(Axis(key, tuple(spec), variants={k: dict(v) for k, v in spec.items()}))
        else:
            raise GridError(
                f"sweep file {path}: sweep.axes.{key} must be a list of values or a table of named variants (tables)"
            )
    _check_axes(axes)
    has_scenario_axis = any(a.key == SCENARIO_AXIS for a in axes)
    base = data.get("scenario")
    if has_scenario_axis and base is not None:
        raise GridError(f"sweep file {path}: give either sweep.scenario or a scenario axis, not both")
    if not has_scenario_axis and not isinstance(base, str):
        raise GridError(f"sweep file {path}: sweep.scenario (a scenario name or TOML path) is required")
    if isinstance(base, str) and base.endswith(".toml") and not Path(base).is_absolute():
        base = str(path.parent / base)
    axes.sort(key=lambda a: a.key != SCENARIO_AXIS)
    skip = data.get("skip_invalid", False)
    if not isinstance(skip, bool):
        raise GridError(f"sweep file {path}: sweep.skip_invalid must be true or false")
    return Grid(
        [] if has_scenario_axis else [base],
        axes,
        parse_seeds(seeds if seeds is not None else data.get("seeds", DEFAULT_SEEDS)),
        parse_duration(duration_s if duration_s is not None else data.get("duration")),
        skip_invalid=skip,
        stem=path.stem,
    )
