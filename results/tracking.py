"""Metrics that show a lost track and an honest covariance (issue 18), from the per-tick errors of a run.

Pure numpy. ``after`` masks select the ticks at or after the convergence time. A live AUV's sample
counts as "over" a bound when its error exceeds it or when it has no estimate at that tick.

NEES of the position (2 states): ``e^T P_pos^-1 e`` with ``e`` the position error (m) and ``P_pos``
the 2x2 position block of the AUV's reported covariance (eq. 15 propagated with eq. 14). A consistent
estimator gives chi-square samples with 2 degrees of freedom: mean 2, and 95 % of the samples in the
two-sided band [chi2_2(0.025), chi2_2(0.975)] = [0.0506, 7.38].
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

NEES_BAND = (0.0506, 7.378)
"""Two-sided 95 % band of a chi-square variable with 2 degrees of freedom: -2 ln(0.975), -2 ln(0.025)."""

UNDER_M = 15.0
"""Bound of ``under_15m_after_convergence_fraction`` and ``longest_excursion_s`` (m): the paper's Fig. 7b bound."""

LOST_M = 50.0
LOST_S = 60.0
"""A track is lost when the error stays above ``LOST_M`` metres for more than ``LOST_S`` seconds."""


def position_nees(err_xy: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """NEES ``e^T P^-1 e`` per sample from errors (N, 2) and covariances (N, 3) = (Pxx, Pxy, Pyy); NaN where undefined."""
    pxx, pxy, pyy = cov[:, 0], cov[:, 1], cov[:, 2]
    det = pxx * pyy - pxy * pxy
    ex, ey = err_xy[:, 0], err_xy[:, 1]
    with np.errstate(all="ignore"):
        nees = (pyy * ex * ex - 2.0 * pxy * ex * ey + pxx * ey * ey) / det
    return np.where(det > 0.0, nees, np.nan)


def in_band_fraction(nees: np.ndarray) -> float:
    """Share of the NEES samples ``nees`` inside :data:`NEES_BAND`."""
    nees = np.asarray(nees, dtype=float)
    return float(np.mean((nees >= NEES_BAND[0]) & (nees <= NEES_BAND[1])))


def runs_over(times: np.ndarray, over: np.ndarray, tick_s: float) -> list[float]:
    """Durations (s) of the maximal runs of consecutive ticks where ``over`` is True (a run of one tick lasts tick_s)."""
    out = []
    start = None
    for k, flag in enumerate(over):
        if flag and start is None:
            start = k
        if start is not None and (not flag or k == len(over) - 1):
            last = k if flag else k - 1
            out.append(float(times[last] - times[start]) + tick_s)
            start = None
    return out


def tracking_metrics(
    times: np.ndarray,
    errors: Mapping[int, np.ndarray],
    alive: Mapping[int, np.ndarray],
    nees: Mapping[int, np.ndarray],
    t_conv: float | None,
    tick_s: float,
) -> tuple[dict[str, Any], dict[int, dict[str, Any]]]:
    """Team-level and per-AUV metrics: p95, fraction under 15 m, longest excursion, track losses, NEES.

    ``errors``: per AUV, error (m) per tick, NaN when dead or without an estimate; ``alive``: per AUV,
    alive per tick; ``nees``: per AUV, position NEES per tick (NaN where undefined); ``t_conv``: the
    convergence time on the ``times`` axis, or None (then every after-convergence figure is None).
    """
    pooled = np.concatenate([e[np.isfinite(e)] for e in errors.values()]) if errors else np.empty(0)
    team: dict[str, Any] = {
        "tracking_error_p95_m": float(np.percentile(pooled, 95)) if pooled.size else None,
        "under_15m_after_convergence_fraction": None,
        "longest_excursion_s": None,
        "nees_mean": None,
        "nees_in_band_fraction": None,
        "nees_samples": 0,
    }
    per: dict[int, dict[str, Any]] = {
        i: {"tracking_error_p95_m": _p95(errors[i]), "track_lost": None, "longest_excursion_s": None} for i in errors
    }
    if t_conv is None:
        return team, per
    after = times >= t_conv
    under, counted, longest, nees_all = 0, 0, 0.0, []
    for i, e in errors.items():
        live = alive[i] & after
        err = np.where(np.isfinite(e), e, math.inf)
        counted += int(np.sum(live))
        under += int(np.sum(live & (err <= UNDER_M)))
        excursions = runs_over(times, live & (err > UNDER_M), tick_s)
        lost = [d for d in runs_over(times, live & (err > LOST_M), tick_s) if d > LOST_S]
        per[i]["longest_excursion_s"] = max(excursions, default=0.0)
        per[i]["track_lost"] = len(lost)
        longest = max(longest, per[i]["longest_excursion_s"])
        n = nees[i][live & np.isfinite(nees[i])]
        nees_all.append(n)
    samples = np.concatenate(nees_all) if nees_all else np.empty(0)
    team["under_15m_after_convergence_fraction"] = under / counted if counted else None
    team["longest_excursion_s"] = longest
    if samples.size:
        team["nees_mean"] = float(np.mean(samples))
        team["nees_in_band_fraction"] = in_band_fraction(samples)
        team["nees_samples"] = int(samples.size)
    return team, per


def _p95(e: np.ndarray) -> float | None:
    v = e[np.isfinite(e)]
    return float(np.percentile(v, 95)) if v.size else None
