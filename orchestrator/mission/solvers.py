"""Propagation models run through ``pelagic`` (Bellhop and Kraken in Rust; GPL-3.0-or-later, the optional
``[bellhop]`` extra): the one module of the project that imports it (tests/unit/test_layout.py checks).

Every case is written as pelagic's JSON case (``Case.from_dict``), no files. Units: depths and ranges in m,
frequencies in kHz at this module's interface, TL in dB re 1 m.
"""

from __future__ import annotations

import numpy as np

from auv_swarm.contract.params import ConfigError
from auv_swarm.contract.tltable import TLTable

EXTRA_HINT = "pip install 'auv-swarm[bellhop]'"
TL_CAP_DB = 250.0
"""TL where a model gives no pressure (a perfect shadow): large and finite, so a table stays finite."""


class SolverMissing(ConfigError):
    """pelagic is not installed: a scenario asked for a propagation model that needs the [bellhop] extra."""


def _pelagic():
    try:
        import pelagic
    except ImportError:
        raise SolverMissing(f"ocean.propagation = 'bellhop' needs pelagic, the [bellhop] extra: {EXTRA_HINT}") from None
    return pelagic


def available() -> bool:
    """True when pelagic can be imported."""
    try:
        _pelagic()
    except SolverMissing:
        return False
    return True


def _range_km(ranges: tuple[float, float, int]) -> dict[str, object]:
    """A receiver range grid (from m, to m, count) as the case's range entry (km)."""
    return {"from": float(ranges[0]) / 1e3, "to": float(ranges[1]) / 1e3, "count": int(ranges[2]), "unit": "km"}


def _bottom(seabed: list[float] | None) -> object:
    if seabed is None:
        return "rigid"
    cp, rho, ap = seabed
    return {"type": "halfspace", "cp": float(cp), "rho": float(rho), "ap": float(ap)}


def _waveguide(
    model: str,
    title: str,
    frequency: float | list[float],
    depth_m: float,
    ssp: list[list[float]],
    seabed: list[float] | None,
    source_depth_m: float,
) -> dict:
    """The part of a pelagic JSON case both models share: the range-independent water column, its vacuum surface,
    its bottom and the source's depth (``frequency`` in Hz, as the model takes it: a number or a list)."""
    return {
        "pelagic": 2,
        "model": model,
        "title": title,
        "frequency": frequency,
        "interpolation": "c_linear",
        "media": [{"to": float(depth_m), "ssp": [[float(z), float(c)] for z, c in ssp]}],
        "surface": "vacuum",
        "bottom": _bottom(seabed),
        "source": {"depth": [float(source_depth_m)]},
    }


def bellhop_case(
    frequency_khz: float,
    depth_m: float,
    ssp: list[list[float]],
    seabed: list[float] | None,
    source_depth_m: float,
    depths: tuple[float, float, int],
    ranges: tuple[float, float, int],
    beams: int,
    thorp: bool = True,
) -> dict:
    """pelagic's JSON case of an incoherent Bellhop TL field: vacuum surface, a fluid half-space bottom
    (``seabed`` = [cp m/s, rho g/cm^3, ap dB/wavelength]; None: rigid), c-linear profile, Thorp volume
    attenuation, ray-centred geometric hat beams from -89 to 89 deg; receivers on ``depths`` and ``ranges`` (first, last, n)."""
    case = _waveguide("bellhop", "auv-swarm TL table", float(frequency_khz) * 1e3, depth_m, ssp, seabed, source_depth_m)
    case |= {
        "receivers": {
            "depth": {"from": float(depths[0]), "to": float(depths[1]), "count": int(depths[2])},
            "range": _range_km(ranges),
        },
        "bellhop": {
            "run": "incoherent",
            "beam": "geometric_hat_ray_centered",
            "angles": {"from": -89.0, "to": 89.0, "count": int(beams)},
            "box": {"depth": float(depth_m) * 1.05 + 1.0, "range": float(ranges[1]) * 1.05 + 10.0},
        },
    }
    if thorp:
        case["attenuation"] = {"volume": "thorp"}
    return case


def run_tl(case: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run a Bellhop or Kraken JSON case; (ranges m, depths m, TL dB (depths, ranges)) of its first source."""
    pelagic = _pelagic()
    module = pelagic.bellhop if case["model"] == "bellhop" else pelagic.kraken
    result = module.Case.from_dict(case).run()
    field = result.field if case["model"] == "bellhop" else result.frequencies[0].field
    with np.errstate(divide="ignore"):
        tl = np.asarray(field.transmission_loss()[0], dtype=float)
    tl = np.where(np.isfinite(tl), np.minimum(tl, TL_CAP_DB), TL_CAP_DB)
    return np.asarray(field.ranges_m, dtype=float), np.asarray(field.depths_m, dtype=float), tl


def range_average(ranges: np.ndarray, tl: np.ndarray, fraction: float) -> np.ndarray:
    """TL (dB, (..., R)) averaged in intensity over +- ``fraction`` of each range (whole samples; none at short
    range): it stands for the uncertainty of range and depth that blurs the caustics geometric beams draw as
    spikes of 20 dB over tens of metres (docs/ocean.md)."""
    if fraction <= 0.0:
        return tl
    step = float(ranges[1] - ranges[0])
    half = np.floor(fraction * ranges / step).astype(np.int64)
    idx = np.arange(ranges.size)
    lo, hi = np.maximum(idx - half, 0), np.minimum(idx + half, ranges.size - 1)
    power = 10.0 ** (-tl / 10.0)
    csum = np.concatenate([np.zeros(power.shape[:-1] + (1,)), np.cumsum(power, axis=-1)], axis=-1)
    mean = (csum[..., hi + 1] - csum[..., lo]) / (hi - lo + 1)
    return -10.0 * np.log10(np.maximum(mean, 10.0 ** (-TL_CAP_DB / 10.0)))


def bellhop_table(spec: dict) -> TLTable:
    """The TL table of ``contract.tltable.table_spec``: one Bellhop run per frequency, averaged in range by
    :func:`range_average` (``spec["range_average"]``). TL at range 0 (the source's singularity) is set to
    0 dB, TL re 1 m."""
    fields = []
    for f in spec["frequencies_khz"]:
        case = bellhop_case(
            f,
            spec["depth_m"],
            spec["ssp"],
            spec["seabed"],
            spec["source_depth_m"],
            tuple(spec["depths_m"]),
            tuple(spec["ranges_m"]),
            spec["beams"],
        )
        ranges, depths, tl = run_tl(case)
        tl[:, ranges < 1.0] = 0.0
        fields.append(range_average(ranges, tl, spec["range_average"]))
    return TLTable(
        ranges, depths, np.array(spec["frequencies_khz"], dtype=float), float(spec["source_depth_m"]), np.stack(fields)
    )


def kraken_case(
    frequency_khz: float,
    depth_m: float,
    ssp: list[list[float]],
    seabed: list[float],
    source_depth_m: float,
    receiver_depth_m: float,
    ranges: tuple[float, float, int],
) -> dict:
    """pelagic's JSON case of a Kraken incoherent mode-sum TL at one receiver depth (vacuum surface, fluid
    half-space bottom, phase speeds from the profile's minimum to the bottom's speed)."""
    cp = float(seabed[0])
    case = _waveguide(
        "kraken", "auv-swarm Kraken check", [float(frequency_khz) * 1e3], depth_m, ssp, seabed, source_depth_m
    )
    return case | {
        "receivers": {
            "depth": [float(receiver_depth_m)],
            "range": _range_km(ranges),
        },
        "kraken": {
            "solver": "kraken",
            "phase_speed": [min(c for _, c in ssp) - 1.0, cp],
            "max_range": float(ranges[1]),
            "mode_limit": 9999,
            "addition": "incoherent",
        },
    }
