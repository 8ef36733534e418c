"""Transmission loss and ambient noise as pure functions (docs/ocean.md), beside the paper's eqs. (22)-(24).

Units: ranges and depths in metres, frequencies in kHz, levels in dB (noise spectra in dB re 1 uPa^2/Hz, band
levels in dB re 1 uPa^2, TL in dB re 1 m). Everything is vectorised over numpy arrays, pure (no I/O, no randomness).

- Ambient noise: the four spectra of Coates (1990) in the form Stojanovic (2007, eqs. 7-8) gives them -
  turbulence, distant shipping (activity s in [0, 1]), surface wind (w in m/s) and thermal noise - summed as
  powers and integrated over a receiver's band. Empirical fits of the Wenz (1962) curves: meaningful from about
  10 Hz to 100 kHz and for winds up to about 20 m/s (sea state 6); outside that they are extrapolations.
- Practical spreading (Stojanovic 2007, k = 1.5): TL = 15 log10(d) + d alpha(f), alpha from Thorp (eq. 24).
- :class:`TLCurve`: a TL curve over range (a row of a table computed by a propagation model) looked up by linear
  interpolation, extended beyond its last range by cylindrical spreading and Thorp absorption.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from auv_swarm.contract.acoustics import MIN_RANGE_M, thorp_absorption_db_per_km

PRACTICAL_SPREADING_K = 1.5
"""Spreading exponent k of the practical law (Stojanovic 2007): between cylindrical (1) and spherical (2)."""

_BAND_POINTS = 257
"""Points of the band integration of the noise spectrum (composite Simpson rule on a log-frequency grid)."""


def noise_spectra_db(f_khz: ArrayLike, wind_mps: float, shipping: float) -> dict[str, np.ndarray]:
    """The four ambient-noise spectra of Coates (1990) as Stojanovic (2007) writes them, dB re 1 uPa^2/Hz, f in kHz:

    turbulence 17 - 30 log f; shipping 40 + 20 (s - 0.5) + 26 log f - 60 log(f + 0.03);
    wind 50 + 7.5 w^0.5 + 20 log f - 40 log(f + 0.4); thermal -15 + 20 log f.
    """
    f = np.asarray(f_khz, dtype=float)
    if not (np.isfinite(f) & (f > 0.0)).all():
        raise ValueError(f"f_khz must be finite and in (0, inf) kHz, got {f_khz!r}")
    if not (math.isfinite(wind_mps) and wind_mps >= 0.0):
        raise ValueError(f"wind_mps must be in [0, inf) m/s, got {wind_mps!r}")
    if not 0.0 <= shipping <= 1.0:
        raise ValueError(f"shipping must be in [0, 1], got {shipping!r}")
    lf = np.log10(f)
    return {
        "turbulence": 17.0 - 30.0 * lf,
        "shipping": 40.0 + 20.0 * (shipping - 0.5) + 26.0 * lf - 60.0 * np.log10(f + 0.03),
        "wind": 50.0 + 7.5 * math.sqrt(wind_mps) + 20.0 * lf - 40.0 * np.log10(f + 0.4),
        "thermal": -15.0 + 20.0 * lf,
    }


def noise_psd_db(f_khz: ArrayLike, wind_mps: float, shipping: float) -> np.ndarray:
    """Total ambient-noise spectral level N(f) (dB re 1 uPa^2/Hz): the four spectra summed as powers."""
    parts = noise_spectra_db(f_khz, wind_mps, shipping)
    return 10.0 * np.log10(sum(10.0 ** (v / 10.0) for v in parts.values()))


def noise_band_level_db(f_lo_khz: float, f_hi_khz: float, wind_mps: float, shipping: float) -> float:
    """Ambient noise level in the band [f_lo, f_hi] kHz (dB re 1 uPa^2): 10 log10 of the integral of N(f) over the
    band in Hz (composite Simpson rule in log f; error well under 0.01 dB for these smooth spectra)."""
    if not (math.isfinite(f_lo_khz) and math.isfinite(f_hi_khz) and 0.0 < f_lo_khz < f_hi_khz):
        raise ValueError(f"the band must satisfy 0 < f_lo < f_hi (kHz), got [{f_lo_khz!r}, {f_hi_khz!r}]")
    u = np.linspace(math.log(f_lo_khz), math.log(f_hi_khz), _BAND_POINTS)
    f = np.exp(u)
    # integral of N(f) df (f in Hz) = integral of N(f) f du * 1000 with u = ln f (f in kHz)
    g = 10.0 ** (noise_psd_db(f, wind_mps, shipping) / 10.0) * f * 1e3
    h = u[1] - u[0]
    weights = np.ones(_BAND_POINTS)
    weights[1:-1:2] = 4.0
    weights[2:-1:2] = 2.0
    return float(10.0 * np.log10(h / 3.0 * float(weights @ g)))


def practical_tl_db(range_m: ArrayLike, f_khz: float) -> float | np.ndarray:
    """Practical-spreading transmission loss (dB): 15 log10(d) + d alpha(f) 1e-3, d in m clamped to >= 1 m."""
    d = np.maximum(np.asarray(range_m, dtype=float), MIN_RANGE_M)
    tl = PRACTICAL_SPREADING_K * 10.0 * np.log10(d) + d * (float(thorp_absorption_db_per_km(f_khz)) * 1e-3)
    return float(tl) if np.ndim(tl) == 0 else tl


class TLCurve:
    """Transmission loss (dB) over range at one receiver depth and frequency, from samples on a uniform grid.

    ``ranges_m`` (R,) uniform and increasing from r_0 >= 0, ``tl_db`` (R,) finite. Between samples TL is linear in
    range; below r_0 it is the first sample; beyond the last range r_N it continues by cylindrical spreading and
    absorption, TL(r_N) + 10 log10(r / r_N) + (r - r_N) alpha(f) (the far field of a waveguide; docs/ocean.md).
    :meth:`floor_beyond` is the smallest TL at or beyond a range: what the planner's bounds need.
    """

    def __init__(self, ranges_m: ArrayLike, tl_db: ArrayLike, f_khz: float) -> None:
        r = np.asarray(ranges_m, dtype=float)
        tl = np.asarray(tl_db, dtype=float)
        if r.ndim != 1 or r.size < 2 or tl.shape != r.shape:
            raise ValueError(f"ranges_m and tl_db must be 1-D of the same length >= 2, got {r.shape}, {tl.shape}")
        if not (np.isfinite(r).all() and np.isfinite(tl).all()) or r[0] < 0.0:
            raise ValueError("ranges_m and tl_db must be finite, ranges_m >= 0")
        step = np.diff(r)
        if not (step > 0.0).all() or np.ptp(step) > 1e-6 * max(step[0], 1.0):
            raise ValueError("ranges_m must be uniform and increasing")
        self.r0 = float(r[0])
        self.dr = float((r[-1] - r[0]) / (r.size - 1))
        self.r_end = float(r[-1])
        self.tl = tl.copy()
        self.alpha_db_per_m = float(thorp_absorption_db_per_km(f_khz)) * 1e-3
        # the smallest TL at or after sample i, and beyond the table (increasing there)
        self._floor = np.minimum.accumulate(tl[::-1])[::-1]

    def __call__(self, range_m: ArrayLike) -> np.ndarray:
        """TL (dB) at ``range_m`` (m, any shape)."""
        d = np.asarray(range_m, dtype=float)
        x = (np.clip(d, self.r0, self.r_end) - self.r0) / self.dr
        i = np.minimum(x.astype(np.int64), self.tl.size - 2)
        frac = x - i
        inside = self.tl[i] + frac * (self.tl[i + 1] - self.tl[i])
        beyond = d > self.r_end
        if not np.any(beyond):
            return inside
        far = np.maximum(d, self.r_end)
        tail = self.tl[-1] + 10.0 * np.log10(far / self.r_end) + (far - self.r_end) * self.alpha_db_per_m
        return np.where(beyond, tail, inside)

    def floor_beyond(self, range_m: ArrayLike) -> np.ndarray:
        """A lower bound (dB) of TL over [range_m, inf): the smallest sample at or after the one below ``range_m``
        (exact on the samples, a little low between them), the tail's TL beyond the table."""
        d = np.asarray(range_m, dtype=float)
        x = (np.clip(d, self.r0, self.r_end) - self.r0) / self.dr
        i = np.minimum(x.astype(np.int64), self.tl.size - 1)
        inside = self._floor[i]
        return np.where(d > self.r_end, self(d), inside)

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The grid (ranges m, TL dB) the curve was made from."""
        return self.r0 + self.dr * np.arange(self.tl.size), self.tl.copy()


class PracticalTL:
    """The practical law as a TL model with :class:`TLCurve`'s interface (exact at every range, increasing)."""

    def __init__(self, f_khz: float) -> None:
        self.f_khz = float(f_khz)

    def __call__(self, range_m: ArrayLike) -> np.ndarray:
        """TL (dB) at ``range_m`` (m)."""
        return np.asarray(practical_tl_db(range_m, self.f_khz), dtype=float)

    def floor_beyond(self, range_m: ArrayLike) -> np.ndarray:
        """The smallest TL over [range_m, inf): TL(range_m), the law increasing with range."""
        return self(range_m)

    def samples(self, max_range_m: float = 5000.0, step_m: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
        """The law sampled every ``step_m`` m out to ``max_range_m`` (for figures)."""
        r = np.arange(int(math.ceil(max_range_m / step_m)) + 1) * step_m
        return r, self(r)
