"""A manoeuvring-target model for the window: a piecewise-linear track with a random-walk velocity prior.

The constant-velocity window (``window.py``) fits one straight track to every bearing it holds, so a
turn inside the window bends its estimate. This model fits a track that may turn: the source's
position is linear between knots every ``spline_knot_s`` seconds on a fixed time grid, and the knot
positions ``P_j`` (m, inertial) are the unknowns. A prior ties them together the way a
constant-velocity model with white acceleration noise of intensity ``q`` (m^2/s^3) does: each second
difference ``P_{j+1} - 2 P_j + P_{j-1}`` (a velocity change times the knot spacing ``D``) is zero-mean
with variance ``(2/3) q D^3`` per axis. The estimate maximises the posterior of the bearings in the
last ``spline_span_s`` seconds (eqs. 2, 4) under that prior: Gauss-Newton on

    sum_i wrap(b_i - h_i(P))^2 / sigma^2 + sum_j |P_{j+1} - 2 P_j + P_{j-1}|^2 / ((2/3) q D^3),

the batch form of the Kalman smoother of a CV model with process noise ``q`` (what Stone Soup's CV
filters run recursively). Late, out-of-order bearings cost nothing: they are rows of the batch. The
state at ``t`` is the position on the last segment and that segment's velocity; its covariance is
the inverse of the Gauss-Newton information matrix mapped onto them.

``reference_spline_fit`` below writes the same fit row by row for the tests. Bearings in rad, times
in s, positions in m (inertial).
"""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.agent.estimator.base import RANGE_FLOOR_M, Estimate, not_ok

_GN_ITERS = 4
"""Gauss-Newton steps per call at most (each halved up to ``_HALVINGS`` times until the cost drops)."""
_HALVINGS = 5
_GN_TOL = 1e-4
"""Stop once a full step lowers the cost (in units of sigma^2) by less than this."""


def knot_grid(t_first: float, t_now: float, knot_s: float) -> np.ndarray:
    """Knot indices k (knot time ``k * knot_s``) covering [t_first, t_now], at least two."""
    k0 = math.floor(t_first / knot_s)
    k1 = max(k0 + 1, math.ceil(t_now / knot_s))
    return np.arange(k0, k1 + 1)


def design(t: np.ndarray, knots: np.ndarray, knot_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Segment index j and fraction a in [0, 1] of every time ``t`` (s): ``p(t) = (1 - a) P_j + a P_{j+1}``."""
    u = t / knot_s - knots[0]
    j = np.clip(np.floor(u).astype(int), 0, knots.size - 2)
    return j, u - j


def second_difference(n: int) -> np.ndarray:
    """(n - 2) x n matrix of second differences of n knots."""
    D = np.zeros((max(n - 2, 0), n))
    for r in range(n - 2):
        D[r, r : r + 3] = (1.0, -2.0, 1.0)
    return D


class SplineFit:
    """The piecewise-linear track fit of one window of bearings (see the module docstring).

    ``fit(cols, t_now, start)`` takes the window's columns (t_s, x, y, bearing) sorted by time and a
    starting track, and returns the estimate at ``t_now``; the knots of an ok fit warm-start the next.
    """

    def __init__(
        self,
        sigma_rad: float,
        knot_s: float,
        q: float,
        gate_rad: float,
        max_std_m: float,
        max_speed_mps: float,
        min_rows: int,
    ) -> None:
        self.sigma2 = sigma_rad**2
        self.knot_s = knot_s
        self.prior_var = (2.0 / 3.0) * q * knot_s**3
        self.gate_rad = gate_rad
        self.max_std_m = max_std_m
        self.max_speed_mps = max_speed_mps
        self.min_rows = min_rows
        self.knots: np.ndarray | None = None
        """Knot indices of the last ok fit, and ``self.P`` its knot positions (n x 2, m)."""
        self.P = np.zeros((0, 2))
        self._priors: dict[int, np.ndarray] = {}

    def start_from(self, knots: np.ndarray, xi: np.ndarray, t_s: float) -> np.ndarray:
        """Knot positions (n x 2) for ``knots``: the last ok fit where it has them, extrapolated linearly beyond
        it; without one, the constant-velocity track of ``xi`` at ``t_s``."""
        times = knots * self.knot_s
        if self.knots is not None and self.knots.size >= 2 and knots[0] >= self.knots[0] and knots[0] <= self.knots[-1]:
            out = np.empty((knots.size, 2))
            have = knots <= self.knots[-1]
            out[have] = self.P[knots[have] - self.knots[0]]
            v = (self.P[-1] - self.P[-2]) / self.knot_s
            extra = ~have
            out[extra] = self.P[-1] + np.outer(times[extra] - self.knots[-1] * self.knot_s, v)
            return out
        return xi[:2] + np.outer(times - t_s, xi[2:])

    def fit(
        self, cols: np.ndarray, t_now: float, start_xi: np.ndarray, start_t: float, sigma: np.ndarray | None = None
    ) -> Estimate:
        """Estimate at ``t_now`` from columns (t_s, x, y, bearing) of the bearings taken up to ``t_now``;
        ``sigma``: each bearing's own noise std (rad; NaN: the fit's), weighting and gating it (None: the fit's)."""
        t, sx, sy, b = cols
        ratio = None
        if sigma is not None:
            ratio = np.where(np.isnan(sigma), 1.0, sigma / math.sqrt(self.sigma2))
        m = t.size
        if m < self.min_rows:
            self.knots = None
            return not_ok(t_now, f"only {m} measurements, need {self.min_rows}", n_used=m)
        knots = knot_grid(float(t[0]), t_now, self.knot_s)
        n = knots.size
        track = Track(*design(t, knots, self.knot_s), sx, sy, b, n)
        prior = self._priors.get(n)
        if prior is None:  # the prior's information matrix (1/m^2), parameters interleaved x0, y0, x1, y1, ...
            D = second_difference(n)
            prior = self._priors[n] = np.kron(D.T @ D, np.eye(2)) / self.prior_var
        flat = self.start_from(knots, start_xi, start_t).reshape(-1)
        res, gx, gy = track.residuals(flat)
        gate = self.gate_rad if ratio is None else self.gate_rad * ratio
        keep = np.abs(res) <= gate
        for _ in range(3):  # Gauss-Newton on the inliers, then the gate once more, until the inliers settle
            if np.count_nonzero(keep) < self.min_rows:
                self.knots = None
                return not_ok(t_now, "too few bearings pass the outlier gate", n_used=int(keep.sum()), n_rejected=m)
            w = keep / self.sigma2 if ratio is None else keep / (self.sigma2 * ratio * ratio)
            flat, res, gx, gy, H = self._gauss_newton(track, flat, res, gx, gy, w, prior)
            new = np.abs(res) <= gate
            if np.array_equal(new, keep):
                break
            keep = new
        used = int(np.count_nonzero(keep))
        jn, an = design(np.array([t_now]), knots, self.knot_s)
        k, a = int(jn[0]), float(an[0])
        L = np.zeros((4, 2 * n))
        for axis in range(2):
            L[axis, 2 * k + axis] = 1.0 - a
            L[axis, 2 * k + 2 + axis] = a
            L[2 + axis, 2 * k + axis] = -1.0 / self.knot_s
            L[2 + axis, 2 * k + 2 + axis] = 1.0 / self.knot_s
        try:
            Pxi = L @ np.linalg.solve(H, L.T)
        except np.linalg.LinAlgError:
            self.knots = None
            return not_ok(t_now, "singular information matrix", n_used=used)
        xi = L @ flat
        Pxi = 0.5 * (Pxi + Pxi.T)
        if not (np.isfinite(xi).all() and np.isfinite(Pxi).all()):
            self.knots = None
            return not_ok(t_now, "non-finite solution", n_used=used)
        if not np.linalg.eigvalsh(Pxi)[0] > 0.0:
            self.knots = None
            return not_ok(t_now, "unobservable: the information matrix is singular", n_used=used)
        std = math.sqrt(max(0.0, Pxi[0, 0] + Pxi[1, 1]))
        if std > self.max_std_m:
            self.knots = None
            return not_ok(t_now, f"too uncertain: position std {std:.3g} m > {self.max_std_m:g} m", n_used=used)
        speed = math.hypot(xi[2], xi[3])
        if speed > self.max_speed_mps:
            self.knots = None
            return not_ok(t_now, f"implausible target speed {speed:.3g} m/s > {self.max_speed_mps:g} m/s", n_used=used)
        self.knots, self.P = knots, flat.reshape(-1, 2)
        return Estimate(True, "ok", float(t_now), xi, Pxi, used, m - used, math.inf)

    def _gauss_newton(self, track, flat, res, gx, gy, w, prior):
        """Damped Gauss-Newton on the posterior cost from knots ``flat`` (residuals ``res`` and bearing gradients
        there); returns the knots, their residuals and gradients and the information matrix (1/m^2) there."""
        current = float(np.sum(w * res * res) + flat @ prior @ flat)
        H, g = track.normal(res, gx, gy, w)
        H += prior
        for _ in range(_GN_ITERS):
            try:
                step = np.linalg.solve(H, g - prior @ flat)
            except np.linalg.LinAlgError:
                break
            if not np.isfinite(step).all() or float((g - prior @ flat) @ step) < _GN_TOL:
                break
            for h in range(_HALVINGS):
                trial = flat + step * 0.5**h
                r_t, gx_t, gy_t = track.residuals(trial)
                c = float(np.sum(w * r_t * r_t) + trial @ prior @ trial)
                if c < current:
                    flat, current, res, gx, gy = trial, c, r_t, gx_t, gy_t
                    break
            else:
                break
            H, g = track.normal(res, gx, gy, w)
            H += prior
        return flat, res, gx, gy, H


class Track:
    """The bearings of one fit on a piecewise-linear track: segment ``j`` and fraction ``a`` of every row,
    sensor positions (m), bearings (rad) and the number of knots ``n``."""

    def __init__(self, j, a, sx, sy, b, n) -> None:
        self.j, self.a, self.sx, self.sy, self.b, self.n = j, a, sx, sy, b, n
        self.c = ((1.0 - a) ** 2, a * (1.0 - a), a * a)

    def residuals(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals wrap(b - h) (rad) and the bearing's gradient d(h)/d(position) (1/m) of every row."""
        P = flat.reshape(-1, 2)
        j, a = self.j, self.a
        ex = (1.0 - a) * P[j, 0] + a * P[j + 1, 0] - self.sx
        ey = (1.0 - a) * P[j, 1] + a * P[j + 1, 1] - self.sy
        r2 = np.maximum(ex * ex + ey * ey, RANGE_FLOOR_M**2)
        res = self.b - np.arctan2(ey, ex)
        res = np.arctan2(np.sin(res), np.cos(res))
        return res, -ey / r2, ex / r2

    def normal(self, res, gx, gy, w) -> tuple[np.ndarray, np.ndarray]:
        """``J^T W J`` (2n x 2n, block tridiagonal) and ``J^T W res`` of the knots, summed segment by segment."""
        n, j = self.n, self.j
        seg = n - 1
        idx = np.arange(seg)
        H = np.zeros((n, 2, n, 2))
        wxx, wxy, wyy = w * gx * gx, w * gx * gy, w * gy * gy
        for c, (dj, dk) in zip(self.c, ((0, 0), (0, 1), (1, 1)), strict=True):
            M = np.empty((seg, 2, 2))
            M[:, 0, 0] = np.bincount(j, wxx * c, seg)
            M[:, 0, 1] = M[:, 1, 0] = np.bincount(j, wxy * c, seg)
            M[:, 1, 1] = np.bincount(j, wyy * c, seg)
            H[idx + dj, :, idx + dk, :] += M
            if dj != dk:
                H[idx + dk, :, idx + dj, :] += M
        wr = w * res
        g = np.zeros((n, 2))
        for axis, u in enumerate((gx, gy)):
            g[:-1, axis] += np.bincount(j, wr * u * (1.0 - self.a), seg)
            g[1:, axis] += np.bincount(j, wr * u * self.a, seg)
        return H.reshape(2 * n, 2 * n), g.reshape(-1)
