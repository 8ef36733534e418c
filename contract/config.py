"""Typed scenario configuration: the one home of every scenario parameter.

A scenario is a TOML file with the sections below. Every key is declared once,
with its meaning, unit and allowed range; unknown keys, wrong types and
out-of-range values raise :class:`ConfigError` naming the dotted key and the
allowed range. Symbols refer to Table 1 and Table 2 of the paper.
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomli_w

from auv_swarm.contract import methods, payload

# The scenario's names in one place for its users: a fault, a kill, their sample and late-entry check, the error
# and the range check are imported from contract.config (and ConfigError from auv_swarm), wherever in the contract
# they are defined.
from auv_swarm.contract.faults import (  # noqa: F401
    EXAMPLE_TOML,
    FAULT_ACTIONS,
    FAULT_COMPONENTS,
    Fault,
    KillEvent,
    after_end,
    check_faults,
)
from auv_swarm.contract.ocean import slot_frame_bits
from auv_swarm.contract.params import MAX_AGENTS, MAX_HORIZON, ConfigError, check_range, param, range_text  # noqa: F401
from auv_swarm.contract.sections import (  # noqa: F401  the sections, imported from here by their users
    ESTIMATOR_METHODS,
    PLANNER_METHODS,
    AgentsConfig,
    ChannelConfig,
    EstimatorConfig,
    NavigationConfig,
    OceanConfig,
    PlannerConfig,
    RunConfig,
    SensorConfig,
    TargetConfig,
)


@dataclass(frozen=True)
class Scenario:
    """A complete scenario: one TOML file."""

    name: str = param("custom", "scenario name")
    description: str = param("", "free text")
    run: RunConfig = param(None, "mission settings", factory=RunConfig)
    target: TargetConfig = param(None, "target motion", factory=TargetConfig)
    agents: AgentsConfig = param(None, "the AUV team", factory=AgentsConfig)
    sensor: SensorConfig = param(None, "bearing sensor", factory=SensorConfig)
    channel: ChannelConfig = param(None, "acoustic channel", factory=ChannelConfig)
    ocean: OceanConfig = param(None, "acoustic environment (docs/ocean.md)", factory=OceanConfig)
    estimator: EstimatorConfig = param(None, "estimator", factory=EstimatorConfig)
    planner: PlannerConfig = param(None, "planner", factory=PlannerConfig)
    navigation: NavigationConfig = param(None, "the AUVs' own navigation", factory=NavigationConfig)
    kills: tuple[KillEvent, ...] = param((), "scheduled AUV failures", factory=tuple)
    faults: tuple[Fault, ...] = param((), "scheduled faults of any process (drills)", factory=tuple)

    def __post_init__(self) -> None:
        _cross_check(self)

    def replace(self, **changes: Any) -> Scenario:
        """Return a copy with top-level sections or fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def with_overrides(
        self, *, seed: int | None = None, duration_s: float | None = None, agents: int | None = None
    ) -> Scenario:
        """Apply the CLI overrides --seed, --duration and --agents."""
        run = self.run
        if seed is not None:
            run = _build(RunConfig, {**dataclasses.asdict(run), "seed": seed}, "run")
        if duration_s is not None:
            run = _build(RunConfig, {**dataclasses.asdict(run), "duration_s": duration_s}, "run")
        ag = self.agents
        ch = self.channel
        if agents is not None:
            d = dataclasses.asdict(ag)
            d["count"] = agents
            if len(d["positions_m"]) != agents:
                d["positions_m"] = ()
            if len(d["headings_rad"]) != agents:
                d["headings_rad"] = ()
            ag = _build(AgentsConfig, d, "agents")
            if ch.slot_order and len(ch.slot_order) != agents:
                ch = _build(ChannelConfig, {**dataclasses.asdict(ch), "slot_order": ()}, "channel")
        kills = tuple(k for k in self.kills if k.agent < ag.count)
        faults = tuple(f for f in self.faults if f.auv is None or f.auv < ag.count)
        return dataclasses.replace(self, run=run, agents=ag, channel=ch, kills=kills, faults=faults)

    def with_keys(self, keys: Mapping[str, Any]) -> Scenario:
        """A copy with dotted keys set (``{"channel.pdr": 0.5, "planner.method": "dec-mpc"}``), validated exactly
        as a TOML file is (ConfigError naming the key and its range).

        ``agents.count`` behaves as ``--agents`` (:meth:`with_overrides`): fixed start positions, headings and a
        slot order that no longer match fall back to the spawn box, the default heading and the id order, and
        kills or faults of AUVs beyond the team are dropped; the other keys are set after it, so a key such as
        ``agents.positions_m`` given with it is kept. ``run.seed`` and ``run.duration_s`` are keys like any other.
        """
        rest = dict(keys)
        scenario = self
        if "agents.count" in rest:
            scenario = scenario.with_overrides(agents=rest.pop("agents.count"))
        if not rest:
            return scenario
        data = scenario.to_dict()
        for dotted, value in rest.items():
            parts = str(dotted).split(".")
            table = data
            for i, part in enumerate(parts[:-1]):
                sub = table.get(part) if isinstance(table, dict) else None
                if not isinstance(sub, dict):
                    where = ".".join(parts[: i + 1])
                    tables = ", ".join(sorted(k for k, v in table.items() if isinstance(v, dict)))
                    raise ConfigError(f"unknown key {dotted!r}: {where!r} is not a table (tables here: {tables})")
                table = sub
            table[parts[-1]] = _to_plain(value)
        return scenario_from_dict(data)

    @property
    def slot_order(self) -> tuple[int, ...]:
        """AUV ids in TDMA slot order."""
        return self.channel.slot_order or tuple(range(self.agents.count))

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form (TOML/JSON friendly)."""
        return _to_plain(dataclasses.asdict(self))


LIST_ITEMS: dict[str, type] = {"kills": KillEvent, "faults": Fault}
"""The scenario's arrays of tables (``[[kills]]``, ``[[faults]]``) and the dataclass of one entry."""


def _to_plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_plain(v) for v in obj]
    return obj


def _cross_check(s: Scenario) -> None:
    n = s.agents.count
    if s.agents.positions_m and len(s.agents.positions_m) != n:
        raise ConfigError(f"agents.positions_m must have agents.count = {n} entries, got {len(s.agents.positions_m)}")
    if s.agents.headings_rad and len(s.agents.headings_rad) != n:
        raise ConfigError(f"agents.headings_rad must have agents.count = {n} entries, got {len(s.agents.headings_rad)}")
    box = s.agents.spawn_box_m
    if not (box[0] < box[2] and box[1] < box[3]):
        raise ConfigError(
            f"agents.spawn_box_m must be [xmin, ymin, xmax, ymax] with xmin < xmax and ymin < ymax, got {list(box)}"
        )
    if s.channel.slot_order and sorted(s.channel.slot_order) != list(range(n)):
        raise ConfigError(f"channel.slot_order must be a permutation of 0..{n - 1}, got {list(s.channel.slot_order)}")
    if s.channel.guard_s >= s.channel.slot_s:
        raise ConfigError(f"channel.guard_s must be < channel.slot_s = {s.channel.slot_s:g}, got {s.channel.guard_s:g}")
    ch = s.channel
    check_ocean(s)
    try:
        budget = slot_frame_bits(ch, s.ocean)
        payload.max_bearings(budget, s.planner.horizon, s.planner.n_headings, sigma=s.ocean.model == "physical")
    except ValueError as exc:
        raise ConfigError(f"channel: a slot cannot carry an acoustic payload: {exc}") from exc
    if s.planner.d_max_m <= s.planner.d_star_m:
        raise ConfigError(
            f"planner.d_max_m must be > planner.d_star_m = {s.planner.d_star_m:g}, got {s.planner.d_max_m:g}"
        )
    if s.planner.anchor_tau_s > 0.0 and s.planner.connectivity != "topology":
        raise ConfigError(
            "planner.anchor_tau_s applies to planner.connectivity = 'topology' only, "
            f"got {s.planner.anchor_tau_s:g} with {s.planner.connectivity!r}"
        )
    if s.navigation.fix_sigma_m > 0.0 and s.navigation.fix_period_s == 0.0:
        raise ConfigError(
            f"navigation.fix_sigma_m = {s.navigation.fix_sigma_m:g} m needs navigation.fix_period_s > 0 (no fix is made)"
        )
    ratio = s.sensor.period_s / s.run.tick_s
    if abs(ratio - round(ratio)) > 1e-9:
        raise ConfigError(f"run.tick_s must divide sensor.period_s = {s.sensor.period_s:g}, got {s.run.tick_s:g}")
    tg = s.target
    if tg.model == "waypoints" and not tg.waypoints_m:
        raise ConfigError("target.waypoints_m must hold at least one [x, y] when target.model = 'waypoints'")
    if tg.leg_speeds_mps and len(tg.leg_speeds_mps) not in (1, len(tg.waypoints_m)):
        raise ConfigError(
            f"target.leg_speeds_mps must have 1 or len(target.waypoints_m) = {len(tg.waypoints_m)} entries, "
            f"got {len(tg.leg_speeds_mps)}"
        )
    for i, v in enumerate(tg.leg_speeds_mps):
        if not 0.0 <= v <= 50.0:
            raise ConfigError(f"target.leg_speeds_mps[{i}] must be in [0, 50], got {v!r}")
    for i, w in enumerate(s.estimator.adaptive_windows_s):
        if not 0.0 < w <= 1e5:
            raise ConfigError(f"estimator.adaptive_windows_s[{i}] must be in (0, 100000], got {w!r}")
    for i, k in enumerate(s.kills):
        if k.agent >= n:
            raise ConfigError(f"kills[{i}].agent must be in [0, {n - 1}], got {k.agent}")
    check_faults(s)


REPLACED_BY_OCEAN = (
    ("channel", "noise_level_db", "ocean.wind_mps and ocean.shipping (the ambient noise)"),
    ("channel", "detection_threshold_db", "ocean.modem (its packet-error curve)"),
    ("channel", "snr_transition_db", "ocean.modem (its packet-error curve)"),
    ("channel", "sound_speed_mps", "ocean.sound_speed (the profile: its minimum for the slot, its mean for delays)"),
    ("sensor", "max_range_m", "ocean.source_level_db (detection by the energy detector's law from the source's SNR)"),
    ("sensor", "outlier_rate", "ocean.false_alarm_probability and ocean.bearing_cells"),
)
"""The paper's knobs the physical ocean computes: (section, key, the ocean key that replaces it)."""


def _check_paper_ocean(oc: OceanConfig) -> None:
    """Under "paper" the other ``[ocean]`` keys would change nothing: one set away from its default is refused."""
    for f in dataclasses.fields(oc):
        if f.name != "model" and getattr(oc, f.name) != _default(f):
            raise ConfigError(
                f"ocean.{f.name} has no effect under ocean.model = 'paper' (eqs. 22-24): set ocean.model = 'physical' "
                "to use it, or leave it out"
            )


def _default(f: dataclasses.Field) -> Any:
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


def check_ocean(s: Scenario) -> None:
    """Cross-checks of ``[ocean]``: under "physical" the paper's knobs it replaces keep their defaults, the
    profile reaches the bottom, depths lie in the water, the bands are positive, the detector is in range."""
    oc = s.ocean
    if oc.model == "paper":
        _check_paper_ocean(oc)
        return
    for section, key, instead in REPLACED_BY_OCEAN:
        cls = type(getattr(s, section))
        default = next(f.default for f in dataclasses.fields(cls) if f.name == key)
        if getattr(getattr(s, section), key) != default:
            raise ConfigError(f"{section}.{key} is computed by the ocean under ocean.model = 'physical': set {instead}")
    if oc.sound_speed == "profile":
        _check_profile(oc)
    for key in ("auv_depth_m", "source_depth_m"):
        if getattr(oc, key) >= oc.depth_m:
            raise ConfigError(f"ocean.{key} must be in [0, ocean.depth_m = {oc.depth_m:g}) m, got {getattr(oc, key):g}")
    lo, hi = oc.source_band_khz
    if not 0.0 < lo < hi <= 1000.0:
        raise ConfigError(f"ocean.source_band_khz must be [low, high] with 0 < low < high <= 1000 kHz, got {[lo, hi]}")
    if oc.modem_band_khz >= 2.0 * s.channel.frequency_khz:
        raise ConfigError(
            f"ocean.modem_band_khz must be < 2 x channel.frequency_khz = {2.0 * s.channel.frequency_khz:g} kHz, "
            f"got {oc.modem_band_khz:g}"
        )
    if oc.integration_s > s.sensor.period_s:
        raise ConfigError(
            f"ocean.integration_s must be <= sensor.period_s = {s.sensor.period_s:g} s, got {oc.integration_s:g}"
        )
    n = (hi - lo) * 1e3 * oc.integration_s
    if not 1.0 <= n <= 8096.0:
        raise ConfigError(
            f"ocean.source_band_khz x ocean.integration_s must give 1 to 8096 samples (Albersheim's range), got {n:g}"
        )
    if oc.propagation == "table" and not oc.tl_table:
        raise ConfigError(
            "ocean.tl_table must name a TL table (builtin:NAME or a path) when ocean.propagation = 'table'"
        )


def _check_profile(oc: OceanConfig) -> None:
    points = oc.sound_speed_profile
    if len(points) < 2:
        raise ConfigError(
            "ocean.sound_speed_profile must hold at least 2 [depth, speed] points when ocean.sound_speed = 'profile'"
        )
    depths = [p[0] for p in points]
    if depths[0] != 0.0 or any(b <= a for a, b in zip(depths, depths[1:], strict=False)):
        raise ConfigError(f"ocean.sound_speed_profile depths must start at 0 m and increase, got {depths}")
    if depths[-1] < oc.depth_m:
        raise ConfigError(
            f"ocean.sound_speed_profile ends at {depths[-1]:g} m, shallower than the water (ocean.depth_m = {oc.depth_m:g} m)"
        )
    for i, (_, c) in enumerate(points):
        if not 1300.0 <= c <= 1800.0:
            raise ConfigError(f"ocean.sound_speed_profile[{i}] speed must be in [1300, 1800] m/s, got {c!r}")


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


def _coerce(name: str, tp: Any, value: Any, meta: dict) -> Any:
    """Convert one TOML value to the declared type, or raise ConfigError."""
    t = tp if not isinstance(tp, str) else eval(tp, globals())  # annotations are strings
    origin = getattr(t, "__origin__", None)
    if dataclasses.is_dataclass(t):
        if not isinstance(value, dict):
            raise ConfigError(f"{name} must be a table, got {type(value).__name__}")
        return _build(t, value, name)
    if t is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{name} must be true or false, got {value!r}")
        return value
    if t is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{name} must be an integer {range_text(meta)}, got {value!r}")
        check_range(name, value, meta)
        return value
    if t is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{name} must be a number {range_text(meta)}, got {value!r}")
        check_range(name, float(value), meta)
        return float(value)
    if t is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name} must be a string, got {value!r}")
        if meta.get("choices") and value not in meta["choices"]:
            raise ConfigError(f"{name} must be {range_text(meta)}, got {value!r}")
        return value
    if origin is tuple:
        args = t.__args__
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{name} must be an array, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(f"{name}[{i}]", args[0], v, {}) for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{name} must have {len(args)} elements, got {len(value)}")
        return tuple(_coerce(f"{name}[{i}]", a, v, {}) for i, (a, v) in enumerate(zip(args, value, strict=True)))
    raise ConfigError(f"{name}: unsupported type {_type_name(t)}")


def _build(cls: type, data: dict[str, Any], prefix: str) -> Any:
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key in data:
        if key not in fields:
            where = f"{prefix}.{key}" if prefix else key
            raise ConfigError(f"unknown key {where!r}; allowed keys: {', '.join(sorted(fields))}")
    kwargs = {}
    for key, value in data.items():
        f = fields[key]
        where = f"{prefix}.{key}" if prefix else key
        if key in LIST_ITEMS:
            if not isinstance(value, (list, tuple)):
                raise ConfigError(f"{where} must be an array of tables, got {value!r}")
            item = LIST_ITEMS[key]
            kwargs[key] = tuple(
                _coerce(f"{where}[{i}]", item, v if not dataclasses.is_dataclass(v) else dataclasses.asdict(v), {})
                for i, v in enumerate(value)
            )
            continue
        if dataclasses.is_dataclass(value):
            value = dataclasses.asdict(value)
        kwargs[key] = _coerce(where, f.type, value, dict(f.metadata))
    return cls(**kwargs)


def scenario_from_dict(data: dict[str, Any]) -> Scenario:
    """Build and validate a Scenario from plain data (e.g. parsed TOML)."""
    if not isinstance(data, dict):
        raise ConfigError(f"a scenario must be a table, got {type(data).__name__}")
    return _build(Scenario, data, "")


BUILTIN_DIR = Path(__file__).resolve().parent / "scenarios"
DEFAULT_SCENARIO = "paper-3.2-challenging"
"""The scenario of ``auv-swarm run`` and of every process started without ``--scenario``."""


FILE_KEYS: tuple[str, ...] = ("ocean.tl_table",)
"""Scenario keys whose value names a file the scenario reads: a sweep grid's hash covers the content of each such
file (:func:`named_files`), so an edited file makes another grid. A ``builtin:NAME`` table is package data, covered
by the package's version."""


def named_files(scenario: Scenario) -> list[Path]:
    """The files ``scenario`` names through :data:`FILE_KEYS` (those with a value), in key order."""
    data = scenario.to_dict()
    out = []
    for key in FILE_KEYS:
        value: Any = data
        for part in key.split("."):
            value = value.get(part) if isinstance(value, dict) else None
        if value and not str(value).startswith("builtin:"):
            out.append(Path(str(value)))
    return out


def builtin_scenarios() -> list[str]:
    """Names of the shipped scenarios, sorted."""
    return sorted(p.stem for p in BUILTIN_DIR.glob("*.toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name, or a user's TOML file by path."""
    text = str(name_or_path)
    path = Path(text)
    if path.suffix != ".toml" and (BUILTIN_DIR / f"{text}.toml").exists():
        path = BUILTIN_DIR / f"{text}.toml"
    if not path.exists():
        close = difflib.get_close_matches(text, builtin_scenarios(), n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ConfigError(
            f"scenario {text!r} is neither a file nor a built-in scenario; {hint}"
            f"built-ins: {', '.join(builtin_scenarios())}"
        )
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not a UTF-8 text file (byte {exc.object[exc.start]:#04x} at offset {exc.start}); "
            "a scenario is a TOML text file"
        ) from exc
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the scenario file: {exc.strerror or exc}") from exc
    table = data.get("ocean", {}).get("tl_table") if isinstance(data.get("ocean"), dict) else None
    if isinstance(table, str) and table and not table.startswith("builtin:") and not Path(table).is_absolute():
        data["ocean"]["tl_table"] = str((path.parent / table).resolve())
    try:
        return scenario_from_dict(data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def describe(cls: type = Scenario, prefix: str = "") -> list[tuple[str, str, str]]:
    """(dotted key, allowed range, meaning) for every parameter: used by --example and docs/scenarios.md. An array
    of tables (``kills``, ``faults``) has its own row, then one row per field of an entry (``kills[].time_s``)."""
    rows = []
    for f in dataclasses.fields(cls):
        t = eval(f.type, globals()) if isinstance(f.type, str) else f.type
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(t):
            rows.extend(describe(t, key + "."))
        elif cls is Scenario and f.name in LIST_ITEMS:
            rows.append((key, "", f.metadata.get("doc", "")))
            rows.extend(describe(LIST_ITEMS[f.name], key + "[]."))
        else:
            meta = dict(f.metadata)
            if isinstance(meta.get("choices"), methods.MethodNames):  # the reference names the built-ins only
                meta["choices"] = meta["choices"].builtin
            rows.append(
                (
                    key,
                    range_text(meta) if meta.get("lo") is not None or meta.get("choices") else "",
                    meta.get("doc", ""),
                )
            )
    return rows


def dump_toml(scenario: Scenario) -> str:
    """Serialise a scenario to TOML that ``load_scenario`` reads back to an equal Scenario."""
    return tomli_w.dumps(scenario.to_dict())
