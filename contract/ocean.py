"""One acoustic environment for the bearing sensor, the modem and the connectivity graph (docs/ocean.md).

``ocean.model = "paper"`` keeps eqs. (22)-(24) with a fixed noise level (no :class:`OceanModel`);
``"physical"`` builds one :class:`OceanModel` from the ``[ocean]`` section: the sound-speed profile and seabed
presets, the ambient noise in each receiver's band, a TL model per path (practical law or a table made by a
propagation model), the modem (:class:`contract.modem.LinkModel`) and the passive sensor
(:class:`contract.detection.SensorModel`). Units: depths and ranges in m, speeds in m/s, frequencies in kHz,
levels in dB. Pure, apart from :func:`ocean_for`, which reads a TL table file (``contract.tltable``) the way
configuration is read.

What is simplified: motion is 2-D at fixed depths (every AUV at ``ocean.auv_depth_m``, the source at
``ocean.source_depth_m``); the environment is range-independent; TL is evaluated at each band's centre frequency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from auv_swarm.contract import propagation
from auv_swarm.contract.detection import SensorModel
from auv_swarm.contract.modem import MODEMS, LinkModel
from auv_swarm.contract.payload import slot_budget_bits
from auv_swarm.contract.sections import ChannelConfig, OceanConfig, SensorConfig

MUNK_AXIS_M = 1300.0
MUNK_EPSILON = 0.00737
"""The canonical Munk (1974) profile: c(z) = 1500 (1 + eps (zt - 1 + exp(-zt))), zt = 2 (z - 1300) / 1300."""

SUMMER_POINTS = ((0.0, 1520.0), (10.0, 1520.0), (30.0, 1490.0), (100.0, 1488.0))
"""The summer thermocline (assumption, docs/ocean.md): a 10 m mixed layer at 1520 m/s over a thermocline down to
1490 m/s at 30 m, then a slow decrease to 1488 m/s at 100 m; held constant below."""


def munk_speed(depth_m: np.ndarray) -> np.ndarray:
    """Munk's canonical deep-water profile c(z) (m/s) at depths z (m)."""
    zt = 2.0 * (np.asarray(depth_m, dtype=float) - MUNK_AXIS_M) / MUNK_AXIS_M
    return 1500.0 * (1.0 + MUNK_EPSILON * (zt - 1.0 + np.exp(-zt)))


def sound_speed_profile(oc: OceanConfig) -> tuple[tuple[float, float], ...]:
    """The profile as (depth m, speed m/s) points from 0 to ``oc.depth_m`` inclusive, linear in between."""
    depth = oc.depth_m
    if oc.sound_speed == "isovelocity":
        return ((0.0, 1500.0), (depth, 1500.0))
    if oc.sound_speed == "munk":
        z = np.linspace(0.0, depth, 101)
        return tuple((float(a), round(float(c), 3)) for a, c in zip(z, munk_speed(z), strict=True))
    points = SUMMER_POINTS if oc.sound_speed == "summer" else oc.sound_speed_profile
    zs = np.array([p[0] for p in points])
    cs = np.array([p[1] for p in points])
    inside = [(float(a), float(c)) for a, c in points if a < depth]
    return (*inside, (depth, float(np.interp(depth, zs, cs))))


def profile_speeds(oc: OceanConfig) -> tuple[float, float]:
    """(minimum, depth-averaged mean) sound speed of the profile (m/s): the slot budget's and the delay's."""
    z, c = (np.array(v) for v in zip(*sound_speed_profile(oc), strict=True))
    mean = float(np.sum(0.5 * (c[1:] + c[:-1]) * np.diff(z)) / (z[-1] - z[0])) if z[-1] > z[0] else float(c[0])
    return float(np.min(c)), mean


def slot_sound_speed(ch: ChannelConfig, oc: OceanConfig) -> float:
    """The sound speed (m/s) of the slot budget: ``channel.sound_speed_mps``, or the profile's minimum (physical)."""
    return ch.sound_speed_mps if oc.model == "paper" else profile_speeds(oc)[0]


def slot_frame_bits(ch: ChannelConfig, oc: OceanConfig) -> int:
    """The largest frame a TDMA slot carries (bits): ``payload.slot_budget_bits`` of the channel at the slot's sound
    speed (:func:`slot_sound_speed`). The one budget the config check, the agents, the channel and the reports use."""
    return slot_budget_bits(ch.bit_rate_bps, ch.slot_s, ch.guard_s, ch.max_range_m, slot_sound_speed(ch, oc))


def band_centre_khz(band: tuple[float, float]) -> float:
    """The centre (kHz) of a [low, high] band: where TL is evaluated."""
    return 0.5 * (band[0] + band[1])


def modem_band(ch: ChannelConfig, oc: OceanConfig) -> tuple[float, float]:
    """The modem's band (kHz): ``ocean.modem_band_khz`` wide, centred on ``channel.frequency_khz``."""
    half = 0.5 * oc.modem_band_khz
    return ch.frequency_khz - half, ch.frequency_khz + half


def noise_levels_db(ch: ChannelConfig, oc: OceanConfig) -> tuple[float, float]:
    """Ambient noise (dB re 1 uPa^2) in the modem's band and in the source's band."""
    lo, hi = modem_band(ch, oc)
    modem = propagation.noise_band_level_db(lo, hi, oc.wind_mps, oc.shipping)
    source = propagation.noise_band_level_db(*oc.source_band_khz, oc.wind_mps, oc.shipping)
    return modem, source


def time_bandwidth(oc: OceanConfig) -> float:
    """N = source band (Hz) x integration time (s): the samples the sensor's energy detector integrates."""
    return (oc.source_band_khz[1] - oc.source_band_khz[0]) * 1e3 * oc.integration_s


@dataclass(frozen=True, eq=False)
class OceanModel:
    """One physical ocean: the modem ``link``, the passive ``sensor``, and the profile's sound speeds (m/s)."""

    link: LinkModel
    sensor: SensorModel
    min_sound_speed_mps: float
    mean_sound_speed_mps: float
    config: OceanConfig


def build_ocean(ch: ChannelConfig, sensor: SensorConfig, oc: OceanConfig, table: object | None) -> OceanModel:
    """The :class:`OceanModel` of a physical ``[ocean]`` section; ``table`` a ``contract.tltable.TLTable`` (its
    fields for the AUV depth, by reciprocity also the source's path) or None for the practical law."""
    f_modem = ch.frequency_khz
    f_source = band_centre_khz(oc.source_band_khz)
    if table is None:
        tl_link, tl_source = propagation.PracticalTL(f_modem), propagation.PracticalTL(f_source)
    else:
        tl_link = table.curve(f_modem, oc.auv_depth_m)
        tl_source = table.curve(f_source, oc.source_depth_m)
    nl_modem, nl_source = noise_levels_db(ch, oc)
    c_min, c_mean = profile_speeds(oc)
    link = LinkModel(
        tl_link,
        MODEMS[oc.modem],
        ch.source_level_db,
        nl_modem,
        ch.directivity_index_db,
        c_mean,
        ch.snr_max_db,
    )
    floor = math.radians(sensor.sigma_m_deg) / math.sqrt(3.0)
    source = SensorModel(
        tl_source,
        oc.source_level_db,
        nl_source,
        time_bandwidth(oc),
        oc.false_alarm_probability,
        oc.bearing_cells,
        floor,
    )
    return OceanModel(link=link, sensor=source, min_sound_speed_mps=c_min, mean_sound_speed_mps=c_mean, config=oc)
