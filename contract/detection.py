"""The passive bearing sensor under ``ocean.model = "physical"``: detection, bearing noise, outliers (eqs. 2, 4).

Units: levels in dB, angles in radians, probabilities in [0, 1]. Pure: no I/O, no randomness.

- Received SNR of the source at an AUV: SNR = SL - TL(d) - NL_band in the source's band (the same TL model and
  noise spectra as the modem, ``contract.propagation``).
- Detection: an energy (square-law) detector integrating N = band x integration time complex samples of a
  steady signal in Gaussian noise, with its exact law: the statistic is chi-square with 2N degrees of freedom
  under noise alone and non-central chi-square with non-centrality 2 N s (s the linear SNR) with the signal, the
  threshold set for Pfa. Albersheim's (1981) closed form approximates it,
  SNR_dB = -5 log10 N + (6.2 + 4.54 / sqrt(N + 0.44)) log10(A + 0.12 A B + 1.7 B), A = ln(0.62 / Pfa),
  B = ln(Pd / (1 - Pd)), stated for 1e-7 <= Pfa <= 1e-3, 0.1 <= Pd <= 0.9, 1 <= N <= 8096
  (:func:`albersheim_snr_db`; the tests compare the two). The exact law is used because Albersheim's form,
  solved for Pd outside its range, does not fall to Pfa at zero signal (it levels off at a few per cent).
- Bearing noise: the Cramer-Rao bound of a two-hydrophone time-delay estimate (Carter 1981) for a pair half a
  wavelength apart at broadside, var = 1 / (2 pi^2 N SNR_eff) rad^2 with SNR_eff = s^2 / (1 + 2 s), s the linear
  SNR; combined with the sensor's own accuracy sigma_0 as sqrt(sigma_0^2 + var), capped at pi / sqrt(3).
- Outliers: the sensor reports the strongest of ``cells`` bearing cells; a measurement reports when the source is
  detected or, failing that, some cell has a false alarm (P_fa,scan = 1 - (1 - Pfa)^cells); a report is a false
  alarm - an outlier, uniform in bearing - with probability (1 - Pd) P_fa,scan / P(report), which grows as Pd
  falls towards the detection limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

MAX_BEARING_SIGMA_RAD = math.pi / math.sqrt(3.0)
"""The largest bearing std (rad): that of a bearing uniform on the circle."""


def _albersheim_terms(n: float, pfa: float) -> tuple[float, float]:
    if not (math.isfinite(n) and n >= 1.0):
        raise ValueError(f"n (samples integrated) must be >= 1, got {n!r}")
    if not 0.0 < pfa < 0.62:
        raise ValueError(f"pfa must be in (0, 0.62), got {pfa!r}")
    return math.log(0.62 / pfa), 6.2 + 4.54 / math.sqrt(n + 0.44)


def albersheim_snr_db(pd: ArrayLike, pfa: float, n: float) -> np.ndarray:
    """Albersheim's (1981) required single-sample SNR (dB) for detection probability ``pd`` at false-alarm
    probability ``pfa`` after integrating ``n`` samples non-coherently."""
    a, slope = _albersheim_terms(n, pfa)
    p = np.asarray(pd, dtype=float)
    if not ((p > 0.0) & (p < 1.0)).all():
        raise ValueError(f"pd must be in (0, 1), got {pd!r}")
    b = np.log(p / (1.0 - p))
    return -5.0 * math.log10(n) + slope * np.log10(a + 0.12 * a * b + 1.7 * b)


def detection_probability(snr_db: ArrayLike, pfa: float, n: float) -> np.ndarray:
    """Pd of the energy detector at single-sample SNR ``snr_db`` (dB): P(ncx2(2n, 2 n s) > chi2.isf(pfa, 2n))."""
    from scipy import stats  # here, not at the top: 0.6 s of import every process would pay under "paper"

    _albersheim_terms(n, pfa)
    s = 10.0 ** (np.asarray(snr_db, dtype=float) / 10.0)
    threshold = stats.chi2.isf(pfa, 2.0 * n)
    return np.asarray(stats.ncx2.sf(threshold, 2.0 * n, 2.0 * n * s), dtype=float)


PD_TABLE_DB = (-40.0, 40.0, 8001)
"""SNR grid (dB: first, last, points) on which :class:`SensorModel` tabulates Pd once (0.01 dB steps)."""


def bearing_sigma_rad(snr_db: ArrayLike, n: float, floor_rad: float) -> np.ndarray:
    """Bearing std (rad): sqrt(floor^2 + 1 / (2 pi^2 n SNR_eff)), SNR_eff = s^2 / (1 + 2 s), capped at pi/sqrt(3)."""
    s = 10.0 ** (np.asarray(snr_db, dtype=float) / 10.0)
    eff = s * s / (1.0 + 2.0 * s)
    with np.errstate(divide="ignore"):
        var = np.where(eff > 0.0, 1.0 / (2.0 * math.pi**2 * n * np.maximum(eff, 1e-300)), np.inf)
    return np.minimum(np.sqrt(floor_rad * floor_rad + var), MAX_BEARING_SIGMA_RAD)


@dataclass(frozen=True)
class Sighting:
    """What the sensor can do at one SNR: P(report), P(outlier | report), bearing std (rad), detection Pd."""

    p_report: float
    p_outlier: float
    sigma_rad: float
    pd: float


class SensorModel:
    """The passive bearing sensor of a physical ocean (see the module docstring).

    ``tl``: TL model of range for the path source -> AUV (``contract.propagation``); ``source_level_db`` and
    ``noise_level_db`` in the source's band; ``samples`` = N, the time-bandwidth product; ``pfa`` per cell and
    measurement; ``cells`` bearing cells searched; ``floor_rad`` the sensor's own bearing std.
    """

    def __init__(
        self,
        tl: object,
        source_level_db: float,
        noise_level_db: float,
        samples: float,
        pfa: float,
        cells: int,
        floor_rad: float,
    ) -> None:
        _albersheim_terms(samples, pfa)
        self._pd_snr = np.linspace(*PD_TABLE_DB)
        self._pd = detection_probability(self._pd_snr, pfa, samples)
        self.tl = tl
        self.noise_level_db = float(noise_level_db)
        self.snr_at_tl0_db = float(source_level_db - noise_level_db)
        self.samples = float(samples)
        self.pfa = float(pfa)
        self.p_fa_scan = 1.0 - (1.0 - pfa) ** int(cells)
        self.floor_rad = float(floor_rad)

    def snr_db(self, range_m: ArrayLike) -> np.ndarray:
        """The source's SNR (dB) at an AUV ``range_m`` (m) away: SL - TL(d) - NL."""
        return self.snr_at_tl0_db - self.tl(range_m)

    def pd(self, snr_db: ArrayLike) -> np.ndarray:
        """Detection probability at ``snr_db`` (dB, any shape), from the table made at construction."""
        return np.interp(snr_db, self._pd_snr, self._pd)

    def sighting(self, snr_db: float) -> Sighting:
        """Report and outlier probabilities and the bearing std at ``snr_db``."""
        pd = float(self.pd(snr_db))
        false = (1.0 - pd) * self.p_fa_scan
        report = pd + false
        sigma = float(bearing_sigma_rad(snr_db, self.samples, self.floor_rad))
        return Sighting(p_report=report, p_outlier=false / report if report > 0.0 else 0.0, sigma_rad=sigma, pd=pd)
