"""Acoustic link budget and SNR-weighted connectivity graph, eqs. (22)-(26).

Units: ranges in metres, frequencies in kHz, levels in dB (SL in dB re 1 uPa @ 1 m).
All functions are vectorised over numpy arrays and pure (no I/O, no randomness).

Choices where the paper is silent (docs/channel.md, "Acoustic link model"):

- the range in eq. (23) is clamped to ``d >= 1 m`` so that co-located nodes give
  ``TL = 0`` instead of ``-inf``;
- a link exists when ``rho_ij >= DT`` (eq. 25) *and* ``rho_ij > 0`` dB, so that a
  negative threshold can never produce negative edge weights;
- the normaliser ``rho_M`` of eq. (26) defaults to ``SL - NL + DI`` (the SNR at
  ``TL = 0``), so normalised weights lie in ``(0, 1]``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from auv_swarm.contract.sections import ChannelConfig

MIN_RANGE_M = 1.0
"""Ranges below this are clamped to it in eq. (23) (m)."""


def _out(x: np.ndarray) -> float | np.ndarray:
    """Return a Python float for 0-d results, the array otherwise."""
    return float(x) if np.ndim(x) == 0 else x


def thorp_absorption_db_per_km(f_khz: ArrayLike) -> float | np.ndarray:
    """Thorp absorption coefficient alpha(f) of eq. (24), in dB/km, for f in kHz (f >= 0)."""
    f = f_khz if type(f_khz) is float else np.asarray(f_khz, dtype=float)
    if not (np.isfinite(f) & (f >= 0.0)).all():
        raise ValueError(f"f_khz must be finite and in [0, inf) kHz, got {f_khz!r}")
    f2 = f * f
    return _out(0.11 * f2 / (1.0 + f2) + 44.0 * f2 / (4100.0 + f2) + 2.75e-4 * f2 + 0.003)


def transmission_loss_db(range_m: ArrayLike, f_khz: ArrayLike) -> float | np.ndarray:
    """Transmission loss of eq. (23), in dB: 20 log10(d) + d * alpha(f) * 1e-3.

    ``d`` is in metres and clamped to ``d >= 1 m`` (co-located nodes lose nothing);
    the factor 1e-3 converts metres to the kilometres of alpha(f) in dB/km.
    """
    d = np.asarray(range_m, dtype=float)
    if not (d >= 0.0).all():
        raise ValueError(f"range_m must be in [0, inf) m, got {range_m!r}")
    d = np.maximum(d, MIN_RANGE_M)
    return _out(20.0 * np.log10(d) + d * np.asarray(thorp_absorption_db_per_km(f_khz)) * 1e-3)


def snr_db(
    range_m: ArrayLike,
    source_level_db: float,
    noise_level_db: float,
    directivity_index_db: float,
    f_khz: float,
) -> float | np.ndarray:
    """Link SNR rho_ij of eq. (22), in dB: SL - TL(d, f) - NL + DI."""
    tl = np.asarray(transmission_loss_db(range_m, f_khz))
    return _out(source_level_db - tl - noise_level_db + directivity_index_db)


def snr_db_cfg(range_m: ArrayLike, ch: ChannelConfig) -> float | np.ndarray:
    """Eq. (22) with SL, NL, DI and f taken from the channel configuration."""
    return snr_db(range_m, ch.source_level_db, ch.noise_level_db, ch.directivity_index_db, ch.frequency_khz)


def snr_max_db(ch: ChannelConfig) -> float:
    """Normaliser rho_M of eq. (26), in dB: ``ch.snr_max_db`` if > 0, else SL - NL + DI (the SNR at TL = 0)."""
    if ch.snr_max_db > 0.0:
        return float(ch.snr_max_db)
    return float(ch.source_level_db - ch.noise_level_db + ch.directivity_index_db)


def laplacian_from_weights(weights: ArrayLike) -> np.ndarray:
    """Weighted graph Laplacian L = Delta - Lambda of eq. (19) from edge weights (..., n, n).

    The diagonal of ``weights`` is ignored; weights must be finite and >= 0.
    """
    w = np.array(weights, dtype=float)
    if w.ndim < 2 or w.shape[-1] != w.shape[-2]:
        raise ValueError(f"weights must have shape (..., n, n), got {w.shape}")
    if not (np.isfinite(w) & (w >= 0.0)).all():
        raise ValueError("weights must be finite and in [0, inf)")
    n = w.shape[-1]
    idx = np.arange(n)
    w[..., idx, idx] = 0.0
    lap = -w
    lap[..., idx, idx] = w.sum(axis=-1)
    return lap


def snr_laplacian(positions: ArrayLike, ch: ChannelConfig, link: object | None = None) -> np.ndarray:
    """Normalised SNR Laplacian of eqs. (25)-(26) for node positions (..., n, 2) in metres.

    Edge weight w_ij = rho_ij / rho_M when rho_ij >= DT (``ch.detection_threshold_db``)
    and rho_ij > 0 dB; otherwise the link is absent (weight 0). Returns (..., n, n).
    ``link``: a physical ocean's ``contract.modem.LinkModel``, whose SNR, DT and rho_M replace eqs. (22)-(24).
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim < 2 or p.shape[-1] != 2:
        raise ValueError(f"positions must have shape (..., n, 2), got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("positions must be finite")
    diff = p[..., :, None, :] - p[..., None, :, :]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    if link is None:
        rho, threshold, rho_m = np.asarray(snr_db_cfg(dist, ch)), ch.detection_threshold_db, snr_max_db(ch)
    else:
        rho, threshold, rho_m = np.asarray(link.snr_db(dist)), link.threshold_db, link.rho_max_db
    n = p.shape[-2]
    edge = (rho >= threshold) & (rho > 0.0) & ~np.eye(n, dtype=bool)
    scale = rho_m if rho_m > 0.0 else 1.0
    weights = np.where(edge, rho / scale, 0.0)
    return laplacian_from_weights(weights)


def fiedler_value(laplacian: ArrayLike) -> float:
    """Algebraic connectivity lambda_2 (second-smallest eigenvalue) of a symmetric Laplacian, eqs. (25)-(26).

    Exactly 0.0 for a disconnected graph (decided combinatorially from the positive
    off-diagonal weights, not from the eigenvalue) and for n = 1; otherwise >= 0.
    """
    lap = np.asarray(laplacian, dtype=float)
    if lap.ndim != 2 or lap.shape[0] != lap.shape[1]:
        raise ValueError(f"laplacian must be a square (n, n) matrix, got shape {lap.shape}")
    if not np.isfinite(lap).all():
        raise ValueError("laplacian must be finite")
    if not (np.abs(lap - lap.T) <= 1e-12 + 1e-9 * np.abs(lap.T)).all():
        raise ValueError("laplacian must be symmetric")
    n = lap.shape[0]
    if n <= 1:
        return 0.0
    if not _connected(~np.eye(n, dtype=bool) & (-lap > 0.0)):
        return 0.0
    return max(float(np.linalg.eigvalsh(lap)[1]), 0.0)


def _connected(adjacency: np.ndarray) -> bool:
    """True if the undirected graph with boolean ``adjacency`` (n, n) is connected (breadth-first search)."""
    reached = np.zeros(adjacency.shape[0], dtype=bool)
    reached[0] = True
    frontier = reached.copy()
    while frontier.any():
        frontier = adjacency[frontier].any(axis=0) & ~reached
        reached |= frontier
    return bool(reached.all())


def fiedler_value_3(w12: ArrayLike, w13: ArrayLike, w23: ArrayLike) -> float | np.ndarray:
    """Closed-form lambda_2 of a 3-node Laplacian with edge weights w12, w13, w23 (>= 0), vectorised.

    lambda_2 = 3Q / (S + sqrt(S^2 - 3Q)) with S = sum of weights and Q = sum of pairwise
    products; S^2 - 3Q is evaluated as half the sum of squared weight differences (>= 0).
    Q, hence lambda_2, is exactly 0 when the graph is disconnected (two weights zero).
    """
    a, b, c = np.broadcast_arrays(*(np.asarray(w, dtype=float) for w in (w12, w13, w23)))
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(c))):
        raise ValueError("w12, w13, w23 must be finite")
    if np.any(a < 0.0) or np.any(b < 0.0) or np.any(c < 0.0):
        raise ValueError("w12, w13, w23 must be in [0, inf)")
    s = a + b + c
    q = a * b + a * c + b * c
    disc = 0.5 * ((a - b) ** 2 + (a - c) ** 2 + (b - c) ** 2)
    den = s + np.sqrt(disc)
    lam = np.where(den > 0.0, 3.0 * q / np.where(den > 0.0, den, 1.0), 0.0)
    return _out(lam)
