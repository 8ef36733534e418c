"""Numerical kernels of the fast window estimator (``agent.estimator.window``).

Each function works on the rows of one window (``Rows``); they are checked against the
readable reference (``agent.estimator.reference``) by the property tests.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import lapack

from auv_swarm.agent.estimator.base import RANGE_FLOOR_M

TRACK_TOL_M = 1e-3
"""If every sensor position lies within this distance (m) of one constant-velocity track,
the range is unobservable (classic bearings-only ambiguity) and no estimate is given."""

NORMAL_EQ_MAX_COND = 1e4
"""Least-squares solves use the 4x4 normal equations when the regressor's scaled condition number is at most
this (their relative error is then about 1e-8), and an SVD of the regressor otherwise."""

_INV_TURN = 0.5 / math.pi
_TURN = 2.0 * math.pi


class Rows(NamedTuple):
    """The bearings an estimate uses, in canonical order, and the column scale of the solve.

    ``dt`` (s) from the oldest one t0, sensor ``sx``, ``sy`` (m), ``bearing`` (rad); ``scale``:
    ``column_scale`` of the window span, ``scale2`` its outer product; ``q`` each row's whitening factor
    sigma / sigma_k (the window's noise std over the bearing's own), None when every bearing has the window's.
    """

    dt: np.ndarray
    sx: np.ndarray
    sy: np.ndarray
    bearing: np.ndarray
    scale: np.ndarray
    scale2: np.ndarray
    q: np.ndarray | None = None


def column_scale(span_s: float) -> np.ndarray:
    """Column scale [1, 1, 1/span, 1/span]: velocity in metres per window, so conditioning is unit-free."""
    inv = 1.0 / span_s if span_s > 0.0 else 1.0
    return np.array([1.0, 1.0, inv, inv])


def evaluate(xi0: np.ndarray, rows: Rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bearing residuals b - h(xi) wrapped to [-pi, pi] (rad), squared ranges (m^2) and the transposed
    Jacobian dh/d(xi(t0)) (4 x M) of the predicted bearings h of eqs. (2), (3); as ``bearing_jacobian``.
    With ``rows.q`` the residuals and the Jacobian's columns are whitened, multiplied by q (rows weighted by
    1 / sigma_k^2 in every least-squares sum, gated in units of their own sigma)."""
    x0, y0, vx, vy = xi0.tolist()
    dt = rows.dt
    ex = dt * vx + x0 - rows.sx
    ey = dt * vy + y0 - rows.sy
    r2 = ex * ex + ey * ey
    inv = 1.0 / np.maximum(r2, RANGE_FLOOR_M**2)
    gx = -(ey * inv)
    gy = ex * inv
    Jt = np.array((gx, gy, dt * gx, dt * gy))
    res = rows.bearing - np.arctan2(ey, ex)
    res -= np.rint(res * _INV_TURN) * _TURN
    if rows.q is not None:
        return res * rows.q, r2, Jt * rows.q
    return res, r2, Jt


def gate(res: np.ndarray, limit: float) -> np.ndarray | None:
    """The rows whose residual passes the gate, ``|res| <= limit``: None if every row does, else the mask."""
    inside = np.abs(res) <= limit
    return None if inside.all() else inside


def cost(res: np.ndarray, w: np.ndarray | None) -> float:
    """Sum of squared weighted residuals ``|res * w|^2``; ``w`` None: weights of one."""
    rw = res if w is None else res * w
    return float(rw @ rw)


def eigh(N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and eigenvectors of a finite symmetric matrix from its lower triangle.

    LAPACK ``dsyevd`` through ``scipy.linalg.lapack``: the routine and the results of ``np.linalg.eigh``
    at less than half its call overhead (about 14 vs 31 us for a 4x4). Raises ``LinAlgError`` if it
    does not converge.
    """
    lam, V, info = lapack.dsyevd(N, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"eigenvalues did not converge (dsyevd info {info})")
    return lam, V


def solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solution of ``A x = b`` (LAPACK ``dgesv`` through ``scipy.linalg.lapack``, the results of
    ``np.linalg.solve`` at a fifth of its call overhead); NaN if ``A`` is singular or not finite."""
    _, _, x, info = lapack.dgesv(A, b)
    return x if info == 0 else np.full(b.shape, np.nan)


def normal_inverse(Ns: np.ndarray) -> tuple[float, np.ndarray] | None:
    """Condition number of a regressor and the inverse of its 4x4 normal matrix ``Ns``, from ``eigh(Ns)``.

    None unless ``Ns`` is finite and the condition number is at most ``NORMAL_EQ_MAX_COND`` (then
    the relative error is about 1e-8 and an SVD of the regressor is not needed).
    """
    if not np.isfinite(Ns).all():
        return None
    lam, V = eigh(Ns)
    lo, hi = lam[0], lam[-1]
    if lo > 0.0 and hi <= NORMAL_EQ_MAX_COND**2 * lo:
        return math.sqrt(hi / lo), (V / lam) @ V.T
    return None


def lstsq(M: np.ndarray, y: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares solution of M x = y and the condition number of M with its columns multiplied by ``scale``.

    Normal equations when well conditioned (``normal_inverse``), an SVD of M otherwise.
    """
    Ms = M * scale
    fast = normal_inverse(Ms.T @ Ms)
    if fast is not None:
        cond, inverse = fast
        return inverse @ (Ms.T @ y) * scale, cond
    if not (np.isfinite(M).all() and np.isfinite(y).all()):
        return np.full(M.shape[1], np.nan), math.inf
    U, s, Vt = np.linalg.svd(Ms, full_matrices=False)
    if s[-1] <= 0.0:
        return np.full(M.shape[1], np.nan), math.inf
    x = (Vt.T @ ((U.T @ y) / s)) * scale
    return x, float(s[0] / s[-1])


def information_inverse(
    Ns: np.ndarray, Jt: np.ndarray, use: np.ndarray | None, scale: np.ndarray
) -> tuple[float, np.ndarray]:
    """Condition number of the column-scaled Jacobian of rows ``use`` (None: all) and the inverse of its normal matrix ``Ns``.

    ``normal_inverse(Ns)`` gives both when the problem is well conditioned; otherwise an SVD of the
    scaled rows of ``Jt.T`` does. Returns (inf, zeros) if the rows are singular or not finite.
    """
    fast = normal_inverse(Ns)
    if fast is not None:
        return fast
    if not np.isfinite(Ns).all():
        return math.inf, np.zeros((4, 4))
    _, sv, Vt = np.linalg.svd((Jt if use is None else Jt[:, use]).T * scale, full_matrices=False)
    if not sv[-1] > 0.0:
        return math.inf, np.zeros((4, 4))
    return float(sv[0] / sv[-1]), (Vt.T / sv**2) @ Vt


def gn_step(
    Ns: np.ndarray,
    g: np.ndarray,
    Jw: np.ndarray,
    res: np.ndarray,
    scale: np.ndarray,
    fast: bool,
) -> tuple[np.ndarray, float]:
    """Gauss-Newton step solving ``J step = res`` in the least-squares sense, and the cost decrease it predicts.

    ``Jw``: the weighted transposed Jacobian (4 x M), ``g = Jw res``; ``Ns = scale2 * (Jw J)``: the
    column-scaled normal matrix, ``scale2`` the outer product of the column scale ``scale``. ``fast``:
    solve the column-scaled 4x4 normal equations ``Ns s = scale * g`` (a singular or non-finite matrix gives a NaN
    step), else use an SVD of ``Jw``. The predicted decrease of the sum of squared residuals is
    ``|J step|^2`` (rad^2); the step is NaN if it is undefined.
    """
    if fast:
        gs = g * scale
        step = solve(Ns, gs)
        return step * scale, float(gs @ step)
    Js = Jw.T * scale
    if not (np.isfinite(Js).all() and np.isfinite(res).all()):
        return np.full(4, np.nan), math.nan
    U, s, Vt = np.linalg.svd(Js, full_matrices=False)
    if s[-1] <= 0.0:
        return np.full(4, np.nan), math.nan
    c = U.T @ res
    return (Vt.T @ (c / s)) * scale, float(c @ c)


def on_one_track(dt: np.ndarray, sx: np.ndarray, sy: np.ndarray) -> bool:
    """True if every sensor position lies within TRACK_TOL_M of one constant-velocity track s0 + dt * v.

    ``dt`` (s) is sorted with ``dt[0] = 0``. Quick exit first: if all points were within the tolerance
    of a track, every point would be within twice the tolerance of the straight interpolation between
    the first and the last point, so one probe further away than that settles the answer.
    """
    n = dt.size
    span = dt[-1] - dt[0]
    if span == 0.0:
        return bool(np.ptp(sx) <= TRACK_TOL_M and np.ptp(sy) <= TRACK_TOL_M)
    for k in (n // 2, n // 4, (3 * n) // 4):
        lam = (dt[k] - dt[0]) / span
        off_x = sx[k] - (sx[0] + lam * (sx[-1] - sx[0]))
        off_y = sy[k] - (sy[0] + lam * (sy[-1] - sy[0]))
        if math.hypot(off_x, off_y) > 3.0 * TRACK_TOL_M:
            return False
    T = np.column_stack((np.ones_like(dt), dt))
    coef, *_ = np.linalg.lstsq(T, np.column_stack((sx, sy)), rcond=None)
    dev = np.column_stack((sx, sy)) - T @ coef
    return bool(np.max(np.hypot(dev[:, 0], dev[:, 1])) <= TRACK_TOL_M)
