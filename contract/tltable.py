"""Transmission-loss tables: the documented file format, where tables live, and reading them (docs/ocean.md).

A TL table is a ``.npz`` file (numpy, no pickles) with

=================  ============  ==================================================================
key                shape         meaning
=================  ============  ==================================================================
``ranges_m``       (R,)          horizontal ranges from the source (m), increasing, R >= 2
``depths_m``       (D,)          receiver depths (m), increasing, D >= 1
``frequencies_khz`` (F,)         frequencies (kHz), F >= 1
``source_depth_m`` ()            the source's depth (m)
``tl_db``          (F, D, R)     transmission loss (dB re 1 m), finite
=================  ============  ==================================================================

made by any propagation model. The mission uses the field of the modem's frequency at the AUVs' depth (a
source at ``ocean.auv_depth_m``) and, by reciprocity, the field of the source band's centre at the source's
depth: ``source_depth_m`` must be the AUVs' depth, and the frequencies must include both (within 0.5 %).

Where tables come from: ``builtin:NAME`` (package data, computed with Bellhop), a file (``ocean.tl_table``),
or the cache that ``propagation = "bellhop"`` fills, keyed by :func:`table_key`, in :func:`cache_dir`. This
module only reads (the way configuration is read); building and writing tables is the mission layer's
(``orchestrator.mission.tables``).
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auv_swarm.contract.ocean import OceanModel, band_centre_khz, build_ocean, sound_speed_profile
from auv_swarm.contract.params import ConfigError
from auv_swarm.contract.propagation import TLCurve
from auv_swarm.contract.seabed import SEABEDS

TABLE_KEYS = ("ranges_m", "depths_m", "frequencies_khz", "source_depth_m", "tl_db")
BUILTIN_PREFIX = "builtin:"
BUILTIN_TABLES = Path(__file__).resolve().parent / "tables"
CACHE_ENV = "AUVSWARM_CACHE_DIR"
FREQ_TOL = 5e-3
"""Relative tolerance of a table frequency against the one the mission needs."""
DEPTH_TOL_M = 0.5
MAX_SAMPLES = 200_000
"""Most range samples a table is resampled to (a uniform grid at its finest spacing)."""
BELLHOP_BEAMS = 2000
"""Beams of the Bellhop runs that fill the cache (part of :func:`table_spec`)."""
RANGE_AVERAGE = 0.05
"""Bellhop tables are averaged in intensity over +- this fraction of each range (part of :func:`table_spec`)."""
SPEC_VERSION = 1

_LOADED: dict[str, TLTable] = {}
"""Tables read or installed in this process, by content hash (file tables) or :func:`table_key` (Bellhop)."""


@dataclass(frozen=True, eq=False)
class TLTable:
    """A TL field over (frequency, depth, range) for one source depth (see the module docstring)."""

    ranges_m: np.ndarray
    depths_m: np.ndarray
    frequencies_khz: np.ndarray
    source_depth_m: float
    tl_db: np.ndarray

    def frequency_index(self, f_khz: float) -> int | None:
        """The index of the table's frequency within FREQ_TOL of ``f_khz``, or None."""
        rel = np.abs(self.frequencies_khz - f_khz) / f_khz
        i = int(np.argmin(rel))
        return i if rel[i] <= FREQ_TOL else None

    def curve(self, f_khz: float, depth_m: float) -> TLCurve:
        """TL over range at ``depth_m`` (rows interpolated linearly in depth) for frequency ``f_khz``."""
        i = self.frequency_index(f_khz)
        if i is None:
            raise ConfigError(f"the TL table has no field at {f_khz:g} kHz")
        field = self.tl_db[i]
        if self.depths_m.size == 1:
            row = field[0]
        else:
            j = int(np.clip(np.searchsorted(self.depths_m, depth_m) - 1, 0, self.depths_m.size - 2))
            z0, z1 = self.depths_m[j], self.depths_m[j + 1]
            w = min(max((depth_m - z0) / (z1 - z0), 0.0), 1.0)
            row = (1.0 - w) * field[j] + w * field[j + 1]
        return TLCurve(self.ranges_m, row, f_khz)

    def to_bytes(self) -> bytes:
        """The table as ``.npz`` bytes (the documented format)."""
        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            ranges_m=self.ranges_m,
            depths_m=self.depths_m,
            frequencies_khz=self.frequencies_khz,
            source_depth_m=np.float64(self.source_depth_m),
            tl_db=self.tl_db.astype(np.float32),
        )
        return buf.getvalue()


def _uniform(ranges: np.ndarray, tl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Resample a table on non-uniform ranges onto a uniform grid at its finest spacing (linear in range)."""
    step = np.diff(ranges)
    if np.ptp(step) <= 1e-6 * max(float(step[0]), 1.0):
        return ranges, tl
    n = min(MAX_SAMPLES, int(math.ceil((ranges[-1] - ranges[0]) / float(np.min(step)))) + 1)
    grid = np.linspace(ranges[0], ranges[-1], n)
    flat = tl.reshape(-1, ranges.size)
    out = np.stack([np.interp(grid, ranges, row) for row in flat]).reshape(tl.shape[:-1] + (n,))
    return grid, out


def parse_table(data: bytes, where: str) -> TLTable:
    """A :class:`TLTable` from ``.npz`` bytes; ConfigError naming ``where`` and what is wrong."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            missing = [k for k in TABLE_KEYS if k not in z.files]
            if missing:
                raise ConfigError(f"{where}: not a TL table: missing {', '.join(missing)} (docs/ocean.md)")
            arrays = {k: np.asarray(z[k], dtype=float) for k in TABLE_KEYS}
    except ConfigError:
        raise
    except Exception as exc:  # any unreadable file: not a zip, a pickle, a truncated array
        raise ConfigError(f"{where}: not a readable .npz TL table ({type(exc).__name__}: {exc})") from None
    r, z, f, tl = arrays["ranges_m"], arrays["depths_m"], arrays["frequencies_khz"], arrays["tl_db"]
    problems = [
        (r.ndim != 1 or r.size < 2, "ranges_m must be 1-D with at least 2 ranges"),
        (z.ndim != 1 or z.size < 1, "depths_m must be 1-D with at least 1 depth"),
        (f.ndim != 1 or f.size < 1, "frequencies_khz must be 1-D with at least 1 frequency"),
        (arrays["source_depth_m"].ndim != 0, "source_depth_m must be a number"),
        (tl.shape != (f.size, z.size, r.size), f"tl_db must have shape (F, D, R) = {(f.size, z.size, r.size)}"),
    ]
    for bad, text in problems:
        if bad:
            raise ConfigError(f"{where}: malformed TL table: {text}, got tl_db {tl.shape}")
    if not all(np.isfinite(a).all() for a in arrays.values()):
        raise ConfigError(f"{where}: malformed TL table: every value must be finite")
    if not ((np.diff(r) > 0).all() and (np.diff(z) > 0).all() and r[0] >= 0 and (f > 0).all()):
        raise ConfigError(f"{where}: malformed TL table: ranges and depths must increase, ranges >= 0, frequencies > 0")
    r, tl = _uniform(r, tl)
    return TLTable(r, z, f, float(arrays["source_depth_m"]), tl)


def check_covers(table: TLTable, scenario: object, where: str) -> None:
    """ConfigError unless ``table`` covers the mission: source at the AUVs' depth, the modem's and the source
    band's frequencies, both depths, and ranges out to ``channel.max_range_m``."""
    oc, ch = scenario.ocean, scenario.channel
    if abs(table.source_depth_m - oc.auv_depth_m) > DEPTH_TOL_M:
        raise ConfigError(
            f"{where}: the TL table's source_depth_m {table.source_depth_m:g} m must be ocean.auv_depth_m = "
            f"{oc.auv_depth_m:g} m"
        )
    for name, f in (
        ("channel.frequency_khz", ch.frequency_khz),
        ("the source band", band_centre_khz(oc.source_band_khz)),
    ):
        if table.frequency_index(f) is None:
            have = ", ".join(f"{v:g}" for v in table.frequencies_khz)
            raise ConfigError(f"{where}: the TL table has no field at {f:g} kHz ({name}); it has {have} kHz")
    lo, hi = float(table.depths_m[0]) - DEPTH_TOL_M, float(table.depths_m[-1]) + DEPTH_TOL_M
    for name, d in (("ocean.auv_depth_m", oc.auv_depth_m), ("ocean.source_depth_m", oc.source_depth_m)):
        if not lo <= d <= hi:
            raise ConfigError(f"{where}: the TL table's depths [{lo:g}, {hi:g}] m do not cover {name} = {d:g} m")
    if table.ranges_m[0] > 1.0 or table.ranges_m[-1] < ch.max_range_m:
        raise ConfigError(
            f"{where}: the TL table's ranges [{table.ranges_m[0]:g}, {table.ranges_m[-1]:g}] m do not cover "
            f"[1, channel.max_range_m = {ch.max_range_m:g}] m"
        )


def cache_dir() -> Path:
    """Where Bellhop tables are cached: ``$AUVSWARM_CACHE_DIR``, else ``$XDG_CACHE_HOME/auv-swarm``, else
    ``~/.cache/auv-swarm``; tables in its ``tl/`` folder."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "auv-swarm"


def table_spec(scenario: object) -> dict:
    """Everything a Bellhop table depends on: environment, frequencies, source depth, grids, beams."""
    oc, ch = scenario.ocean, scenario.channel
    deepest = max(oc.auv_depth_m, oc.source_depth_m)
    depth_max = min(oc.depth_m, max(2.0 * deepest + 20.0, min(oc.depth_m, 200.0)))
    n_depths = int(min(101, max(11, math.ceil(depth_max / 2.0) + 1)))
    r_max = max(oc.table_range_m, ch.max_range_m)
    seabed = SEABEDS[oc.seabed]
    return {
        "version": SPEC_VERSION,
        "solver": "bellhop",
        "beams": BELLHOP_BEAMS,
        "range_average": RANGE_AVERAGE,
        "depth_m": oc.depth_m,
        "ssp": [list(p) for p in sound_speed_profile(oc)],
        "seabed": [seabed.cp_mps, seabed.rho_gcc, seabed.ap_db_per_wavelength],
        "frequencies_khz": sorted({ch.frequency_khz, band_centre_khz(oc.source_band_khz)}),
        "source_depth_m": oc.auv_depth_m,
        "depths_m": [0.0, depth_max, n_depths],
        "ranges_m": [0.0, r_max, int(min(2001, math.ceil(r_max / 10.0) + 1))],
    }


def table_key(scenario: object) -> str:
    """The hash of :func:`table_spec`: the cache entry's name and the in-process key."""
    text = json.dumps(table_spec(scenario), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def cache_path(key: str) -> Path:
    """The cache file of the Bellhop table ``key``."""
    return cache_dir() / "tl" / f"{key}.npz"


def install(key: str, table: TLTable) -> None:
    """Make ``table`` the one this process uses for ``key`` (a sweep worker given its client's tables)."""
    _LOADED[key] = table


def installed(key: str) -> bool:
    """True when this process holds the table ``key`` (:func:`install`, or read before)."""
    return key in _LOADED


def table_file(scenario: object) -> Path:
    """The file ``ocean.tl_table`` names (``builtin:NAME`` is package data)."""
    name = scenario.ocean.tl_table
    if not name:
        raise ConfigError("ocean.tl_table must name a TL table when ocean.propagation = 'table'")
    if name.startswith(BUILTIN_PREFIX):
        stem = name[len(BUILTIN_PREFIX) :]
        path = BUILTIN_TABLES / f"{stem}.npz"
        if not stem or not path.is_file():
            have = ", ".join(sorted(BUILTIN_PREFIX + p.stem for p in BUILTIN_TABLES.glob("*.npz")))
            raise ConfigError(f"ocean.tl_table {name!r} is not a built-in table; built-ins: {have or 'none'}")
        return path
    return Path(name)


def _read_file(scenario: object) -> TLTable:
    path = table_file(scenario)
    where = f"ocean.tl_table {scenario.ocean.tl_table!r}"
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{where}: cannot read the TL table: {exc.strerror or exc}") from None
    digest = hashlib.sha256(data).hexdigest()
    want = scenario.ocean.tl_table_sha256
    if want and want != digest:
        raise ConfigError(f"{where}: the file's SHA-256 is {digest}, ocean.tl_table_sha256 says {want}")
    table = _LOADED.get(digest)
    if table is None:
        table = _LOADED[digest] = parse_table(data, where)
    return table


def load_table(scenario: object) -> TLTable | None:
    """The TL table a physical scenario uses (None for the practical law), checked to cover the mission.

    Never computes one: a Bellhop table must be in this process (:func:`install`) or in the cache."""
    oc = scenario.ocean
    if oc.model != "physical" or oc.propagation == "practical":
        return None
    if oc.propagation == "table":
        table = _read_file(scenario)
        check_covers(table, scenario, f"ocean.tl_table {oc.tl_table!r}")
        return table
    key = table_key(scenario)
    table = _LOADED.get(key)
    if table is None:
        path = cache_path(key)
        if not path.is_file():
            name = getattr(scenario, "name", "custom")
            raise ConfigError(
                f"no Bellhop TL table for this environment in the cache ({path}); run `auv-swarm ocean "
                f"{'SCENARIO' if name == 'custom' else name}` on this scenario once (it needs the [bellhop] extra)"
            )
        table = _LOADED[key] = parse_table(path.read_bytes(), str(path))
    check_covers(table, scenario, "the Bellhop TL table")
    return table


def ocean_for(scenario: object) -> OceanModel | None:
    """The scenario's :class:`contract.ocean.OceanModel` (None under ``ocean.model = "paper"``), its TL table read
    from a ``builtin:`` or ``table`` file, this process or the cache (:func:`load_table`); ConfigError when it is
    missing, malformed or does not cover the mission."""
    if scenario.ocean.model == "paper":
        return None
    return build_ocean(scenario.channel, scenario.sensor, scenario.ocean, load_table(scenario))
