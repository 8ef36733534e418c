"""What one physical ocean does, as numbers and named figures: ``auv-swarm ocean`` and ``bench ocean``
(docs/ocean.md).

Figures (PNG, in the output folder): ``sound_speed`` (the profile), ``tl_field`` (TL over range and depth at the
modem's frequency, the AUVs' and the source's depths marked), ``snr`` (SNR against range of the modem link and
of the source at an AUV), ``probability`` (delivery of the largest frame and detection against range).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from auv_swarm.contract import propagation
from auv_swarm.contract.config import Scenario
from auv_swarm.contract.ocean import OceanModel, build_ocean, noise_levels_db, slot_frame_bits, sound_speed_profile
from auv_swarm.contract.tltable import TLTable, load_table

SEARCH_M = 100_000.0
"""How far out (m) the 50 % ranges are searched; a range never reached is reported as this."""
SEARCH_STEP_M = 1.0
FIGURES = ("sound_speed", "tl_field", "snr", "probability")
PLOT_RANGE_M = 5000.0


def frame_bits(scenario: Scenario) -> int:
    """The largest frame a slot carries (bits): the delivery curve is drawn and summarised for it."""
    return slot_frame_bits(scenario.channel, scenario.ocean)


def curves(ocean: OceanModel, ranges: np.ndarray, bits: int) -> dict[str, np.ndarray]:
    """Against ``ranges`` (m): the link's and the source's SNR (dB), delivery of a ``bits`` frame, detection Pd
    and the probability that a measurement reports a bearing."""
    link_snr = ocean.link.snr_db(ranges)
    source_snr = ocean.sensor.snr_db(ranges)
    sightings = [ocean.sensor.sighting(float(s)) for s in source_snr]
    return {
        "link_snr_db": link_snr,
        "source_snr_db": source_snr,
        "delivery": ocean.link.curve.delivery(link_snr, bits),
        "detection": np.array([s.pd for s in sightings]),
        "report": np.array([s.p_report for s in sightings]),
    }


def range_below(ranges: np.ndarray, p: np.ndarray, level: float = 0.5) -> float:
    """The first range (m) at which ``p`` is below ``level``, or the last range if it never is."""
    below = np.flatnonzero(p < level)
    return float(ranges[below[0]]) if below.size else float(ranges[-1])


def summary(scenario: Scenario, ocean: OceanModel) -> dict[str, Any]:
    """The ocean in numbers: noise levels, SNR at d* and d_M, and the ranges at which the largest frame's
    delivery and the detection probability fall to 0.5, searched out to :data:`SEARCH_M` (that value if never)."""
    ranges = np.arange(0.0, SEARCH_M + SEARCH_STEP_M, SEARCH_STEP_M)
    bits = frame_bits(scenario)
    c = curves_fast(ocean, ranges, bits)
    nl_modem, nl_source = noise_levels_db(scenario.channel, scenario.ocean)
    pl = scenario.planner
    at = np.array([pl.d_star_m, pl.d_max_m])
    return {
        "scenario": scenario.name,
        "propagation": scenario.ocean.propagation,
        "noise_level_modem_db": nl_modem,
        "noise_level_source_db": nl_source,
        "frame_bits": bits,
        "link_snr_at_d_star_db": float(ocean.link.snr_db(at)[0]),
        "link_snr_at_d_max_db": float(ocean.link.snr_db(at)[1]),
        "source_snr_at_d_star_db": float(ocean.sensor.snr_db(at)[0]),
        "source_snr_at_d_max_db": float(ocean.sensor.snr_db(at)[1]),
        "link_range_50_m": range_below(ranges, c["delivery"]),
        "detection_range_50_m": range_below(ranges, c["detection"]),
    }


def curves_fast(ocean: OceanModel, ranges: np.ndarray, bits: int) -> dict[str, np.ndarray]:
    """Delivery and detection probability over many ranges (vectorised through the sensor's Pd table)."""
    sensor = ocean.sensor
    return {
        "delivery": ocean.link.curve.delivery(ocean.link.snr_db(ranges), bits),
        "detection": sensor.pd(sensor.snr_db(ranges)),
    }


def load(scenario: Scenario) -> tuple[OceanModel, TLTable | None]:
    """The scenario's ocean and its TL table (None for the practical law); ConfigError for a paper scenario."""
    from auv_swarm.contract.params import ConfigError

    if scenario.ocean.model != "physical":
        raise ConfigError(f"scenario {scenario.name!r} has ocean.model = 'paper': there is no ocean to show")
    table = load_table(scenario)
    return build_ocean(scenario.channel, scenario.sensor, scenario.ocean, table), table


def _figure(width: float = 6.4, height: float = 4.0):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=110)
    FigureCanvasAgg(fig)
    return fig


def _tl_field(scenario: Scenario, table: TLTable | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ranges m, depths m, TL dB (depths, ranges)) at the modem's frequency: the table's field, or the
    practical law (the same at every depth)."""
    f = scenario.channel.frequency_khz
    if table is not None:
        i = table.frequency_index(f)
        keep = table.ranges_m <= PLOT_RANGE_M
        return table.ranges_m[keep], table.depths_m, table.tl_db[i][:, keep]
    r = np.linspace(0.0, PLOT_RANGE_M, 251)
    z = np.linspace(0.0, scenario.ocean.depth_m, 51)
    return r, z, np.tile(propagation.practical_tl_db(r, f), (z.size, 1))


def write_figures(scenario: Scenario, ocean: OceanModel, table: TLTable | None, folder: Path) -> dict[str, str]:
    """The four named figures (see the module docstring) in ``folder``; {name: path}."""
    oc = scenario.ocean
    folder = Path(folder)
    out: dict[str, str] = {}
    fig = _figure(4.0, 5.0)
    ax = fig.add_subplot()
    z, c = zip(*sound_speed_profile(oc), strict=True)
    ax.plot(c, z, "b-")
    ax.invert_yaxis()
    ax.set(xlabel="sound speed (m/s)", ylabel="depth (m)", title=f"{oc.sound_speed} profile")
    out["sound_speed"] = _save(fig, folder, "sound_speed")

    r, z, tl = _tl_field(scenario, table)
    fig = _figure(7.0, 4.0)
    ax = fig.add_subplot()
    mesh = ax.pcolormesh(r / 1e3, z, tl, shading="auto", cmap="viridis_r", vmin=30.0, vmax=110.0)
    fig.colorbar(mesh, ax=ax, label="TL (dB)")
    ax.axhline(oc.auv_depth_m, color="w", ls="--", lw=1, label=f"AUVs {oc.auv_depth_m:g} m")
    ax.axhline(oc.source_depth_m, color="r", ls=":", lw=1, label=f"source {oc.source_depth_m:g} m")
    ax.invert_yaxis()
    ax.legend(loc="lower right", fontsize=8)
    ax.set(
        xlabel="range (km)",
        ylabel="depth (m)",
        title=f"TL at {scenario.channel.frequency_khz:g} kHz ({oc.propagation})",
    )
    out["tl_field"] = _save(fig, folder, "tl_field")

    ranges = np.geomspace(10.0, SEARCH_M, 600)
    cv = curves(ocean, ranges, frame_bits(scenario))
    table_end = None if table is None else float(table.ranges_m[-1]) / 1e3
    fig = _figure()
    ax = fig.add_subplot()
    ax.semilogx(ranges / 1e3, cv["link_snr_db"], label="modem link")
    ax.semilogx(ranges / 1e3, cv["source_snr_db"], label="source at an AUV")
    ax.axhline(ocean.link.threshold_db, color="C0", ls=":", lw=1, label="modem 50 % (one frame)")
    _mark_table_end(ax, table_end)
    ax.set(xlabel="range (km)", ylabel="SNR (dB)", title=f"SNR, wind {oc.wind_mps:g} m/s, shipping {oc.shipping:g}")
    ax.legend(fontsize=8)
    out["snr"] = _save(fig, folder, "snr")

    fig = _figure()
    ax = fig.add_subplot()
    ax.semilogx(ranges / 1e3, cv["delivery"], label=f"delivery ({frame_bits(scenario)} bits, {oc.modem})")
    ax.semilogx(ranges / 1e3, cv["detection"], label="detection Pd")
    ax.semilogx(ranges / 1e3, cv["report"], ls="--", label="a bearing reported")
    ax.axhline(0.5, color="k", ls=":", lw=0.8)
    _mark_table_end(ax, table_end)
    ax.set(xlabel="range (km)", ylabel="probability", ylim=(-0.02, 1.02), title="delivery and detection")
    ax.legend(fontsize=8)
    out["probability"] = _save(fig, folder, "probability")
    return out


def _mark_table_end(ax: Any, table_end_km: float | None) -> None:
    """A grey line where the TL table ends (beyond it TL is extended by cylindrical spreading)."""
    if table_end_km is not None:
        ax.axvline(table_end_km, color="grey", ls="--", lw=0.8, label="end of the TL table")


def _save(fig: Any, folder: Path, name: str) -> str:
    path = folder / f"{name}.png"
    fig.tight_layout()
    fig.savefig(path)
    return str(path)
