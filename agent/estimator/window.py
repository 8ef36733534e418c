"""The fast path of ``wls-cv``: moving-window pseudo-linear WLS with Gauss-Newton, eqs. (5)-(15) and (21).

Every AUV keeps a moving window of bearings, its own and those received over the
acoustic link. An estimate is computed in five stages:

1. Pseudo-linear weighted least squares (6)-(13), referenced at the oldest sample t0:
   ``[sin b, -cos b, dt sin b, -dt cos b] . xi(t0) = sin b * xs - cos b * ys``,
   each row weighted by the inverse of its noise variance (10), ``1 / (r_hat * sigma)^2``,
   with ``r_hat`` the range predicted by the previous solve and ``sigma^2 = sigma_m^2 / 3``
   the variance of the uniform bearing noise of half-width ``sigma_m``; a bearing that carries its own
   noise std (``Bearing.sigma_rad``, a physical ocean's sensor) has it as its sigma in every stage
   (its residual whitened by sigma / sigma_k, ``kernels.Rows.q``).
2. Outlier gating on the true bearing residual ``wrap(b - atan2(y - ys, x - xs))``: a gate
   that starts wide (three robust standard deviations of the residuals) and shrinks to
   ``gate_sigma * sigma_m``, re-solving on the survivors, a bounded number of times.
3. Gauss-Newton refinement on the true bearing residuals (removes most of the bias of the
   pseudo-linear solution); a step is kept only if it lowers the sum of squared residuals.
4. Covariance (15) from the bearing Jacobian ``J`` of the final iterate,
   ``P(t0) = sigma^2 (J^T J)^-1``. Row k of ``J`` is ``-[sin b, -cos b, dt sin b, -dt cos b] / r``
   evaluated at the predicted bearing, so this is (15) with ``R = diag(r^2 sigma^2)``.
5. Propagation to the query time with (14): ``F = [[I, dt I], [0, I]]``, ``P -> F P F^T``, then
   plausibility: a position std above ``max_position_std_m`` or a target speed above
   ``max_speed_mps`` makes the estimate not ok. In weak early geometry the bearing cost has a
   second basin far down the bearing lines whose solution moves at tens of m/s with a small
   claimed covariance; the speed bound is the prior that rejects it.

Warm path: when the previous estimate was ok and the window changed by at most a quarter of its
rows, stages 1-2 are skipped: Gauss-Newton starts from the previous solution, propagated to the
new t0, with the fixed gate applied at that start. The result is kept only if the inlier set
settles, few gate decisions change and every check of stages 4-5 passes; otherwise the full
path runs. Either way an estimate is a deterministic function of the call history.

Stages 1 and 3-5 without the gate and the warm path are written plainly in
``agent.estimator.reference``; the property tests compare the two.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from auv_swarm.agent.estimator.base import RANGE_FLOOR_M, Bearing, Estimate, consensus, not_ok, transition
from auv_swarm.agent.estimator.kernels import (
    NORMAL_EQ_MAX_COND,
    Rows,
    column_scale,
    cost,
    evaluate,
    gate,
    gn_step,
    information_inverse,
    lstsq,
    on_one_track,
)
from auv_swarm.contract.config import EstimatorConfig

NEAR_FIELD_M = 3.0
"""Bearings whose sensor was within this range (m) of the solution are left out of the covariance
and the checks (a close pass), so the window does not stay "collapsed onto a sensor" for minutes."""
_MAX_GATE_ROUNDS = 12
_MAX_OUTER_ROUNDS = 4
_MAX_STEP_HALVINGS = 6
_ROBUST_GATE = 3.0 * 1.4826
_GN_TOL = 1e-4
"""Gauss-Newton stops when a full step would lower the cost by less than this many sigma^2, that is when
xi is within about 0.01 standard deviations of the optimum."""
_WARM_MAX_CHANGE = 0.25
"""Warm start only if (rows new since the last solve + rows dropped) <= this fraction of the window."""
_WARM_MAX_FLIPS = 3
_WARM_FLIP_FRACTION = 0.05
"""A warm solution whose inlier decisions differ from the previous ones (new rows: from inlier) in more
than max(_WARM_MAX_FLIPS, _WARM_FLIP_FRACTION * rows) rows is discarded for the full robust path."""
_WARM_MAX_REJECTED = 0.2
"""A solution that rejects more than this fraction of its rows is not used as a warm start (a gate that
throws away that much data more likely sits in a wrong basin than on real outliers)."""


class _WarmStart(NamedTuple):
    """The last accepted solution: xi at the oldest used sample ``t0_s``, the rows it used and rejected,
    its condition number."""

    t0_s: float
    xi0: np.ndarray
    n_rows: int
    n_rejected: int
    condition: float


class BearingEstimator:
    """Moving-window share-and-estimate tracker of one AUV (section 2.2, eqs. 11-15, 21).

    The window is held as columns ``(t_s, source, x, y, bearing)`` sorted by ``(t_s, source)``. An
    estimate is a deterministic function of the sequence of ``add``/``estimate`` calls: it does not
    depend on the order of bearings within or between ``add`` calls before an ``estimate``.
    """

    def __init__(self, cfg: EstimatorConfig, sigma_m_rad: float) -> None:
        """``sigma_m_rad``: half-width of the uniform bearing noise (rad), in (0, pi]."""
        if not (isinstance(sigma_m_rad, (int, float)) and math.isfinite(sigma_m_rad) and 0.0 < sigma_m_rad <= math.pi):
            raise ValueError(f"sigma_m (sigma_m_rad) must be in (0, pi] rad, got {sigma_m_rad!r}")
        self.cfg = cfg
        self.sigma_m_rad = float(sigma_m_rad)
        self.sigma_rad = self.sigma_m_rad / math.sqrt(3.0)
        self._store: dict[tuple[float, int], Bearing] = {}
        self._sorted: list[Bearing] | None = []
        self._invalid = 0
        self._pending: list[tuple[float, float, float, float, float, float]] = []
        self._buf = np.empty((6, 0))
        self._flag = np.empty(0, dtype=np.int8)
        self._lo = 0
        self._hi = 0
        self._source_rows: dict[float, int] = {}
        self._last_key = (-math.inf, -math.inf)
        self._warm: _WarmStart | None = None
        self._warm_starts = 0
        self._cold_solves = 0

    @property
    def invalid_count(self) -> int:
        """Bearings refused by ``add`` because a field was not finite."""
        return self._invalid

    @property
    def warm_starts(self) -> int:
        """Estimates solved by the warm path (Gauss-Newton from the previous solution)."""
        return self._warm_starts

    @property
    def cold_solves(self) -> int:
        """Estimates solved by the full robust path (pseudo-linear start, shrinking gate)."""
        return self._cold_solves

    def __len__(self) -> int:
        return len(self._store)

    def update(self, bearings: Iterable[Bearing], t_s: float) -> Estimate:
        """The ``Estimator`` verb: ``add(bearings)`` then ``estimate(t_s)``."""
        self.add(bearings)
        return self.estimate(t_s)

    def columns(self, t_from: float, t_to: float, sigma: bool = False) -> np.ndarray:
        """Columns (t_s, x, y, bearing) of the measurements held with ``t_from <= t_s <= t_to``, sorted by
        (t_s, source), as of the last ``estimate`` call (4 x k, a copy); with ``sigma`` a fifth, each bearing's
        own noise std (rad, NaN where it has none)."""
        cols = self._buf[:, self._lo : self._hi]
        lo, hi = cols[0].searchsorted(t_from, side="left"), cols[0].searchsorted(t_to, side="right")
        return cols[[0, 2, 3, 4, 5] if sigma else [0, 2, 3, 4], lo:hi].copy()

    def window(self) -> list[Bearing]:
        """The measurements held, in canonical order (t_s, source); a copy."""
        if self._sorted is None:
            self._sorted = [self._store[k] for k in sorted(self._store)]
        return list(self._sorted)

    def add(self, bearings: Iterable[Bearing]) -> int:
        """Insert measurements; duplicates by (source, t_s) and non-finite ones are skipped. Returns how many were added."""
        added = 0
        store, pending = self._store, self._pending
        for b in bearings:
            t_s, x, y, bearing = b.t_s, b.sensor_xy[0], b.sensor_xy[1], b.bearing_rad
            sigma = getattr(b, "sigma_rad", None)
            sigma = math.nan if sigma is None or not (isinstance(sigma, (int, float)) and sigma > 0.0) else sigma
            if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (t_s, x, y, bearing)):
                self._invalid += 1
                continue
            key = (float(t_s), int(b.source))
            if key in store:
                continue
            store[key] = b
            pending.append((key[0], float(key[1]), float(x), float(y), float(bearing), float(sigma)))
            added += 1
        if added:
            self._sorted = None
        return added

    def _merge(self) -> None:
        """Move pending rows into the sorted columns; new rows carry the flag -1 (not in the last solve).

        The columns live in ``_buf[:, _lo:_hi]`` (flags in ``_flag``), a buffer with spare room at the
        end: rows later than every held one are appended, others are sorted in with the held rows from
        the first one not earlier than them. ``_last_key`` is the ``(t_s, source)`` of the last held row.
        """
        if not self._pending:
            return
        pending = sorted(self._pending)
        self._pending = []
        m = len(pending)
        lo, hi = self._lo, self._hi
        size = hi - lo
        if hi + m > self._buf.shape[1]:
            buf = np.empty((6, max(2 * (size + m), 256)))
            flag = np.empty(buf.shape[1], dtype=np.int8)
            buf[:, :size] = self._buf[:, lo:hi]
            flag[:size] = self._flag[lo:hi]
            self._buf, self._flag = buf, flag
            lo, hi = 0, size
            self._lo = 0
        buf, flag = self._buf, self._flag
        new = np.array(pending, dtype=float).T
        last = pending[-1][:2]
        if size and self._last_key >= pending[0][:2]:
            last = max(last, self._last_key)
            p = lo + int(buf[0, lo:hi].searchsorted(pending[0][0], side="left"))
            tail = np.concatenate((buf[:, p:hi], new), axis=1)
            tail_flag = np.concatenate((flag[p:hi], np.full(m, -1, dtype=np.int8)))
            order = np.lexsort((tail[1], tail[0]))
            buf[:, p : hi + m] = tail[:, order]
            flag[p : hi + m] = tail_flag[order]
        else:
            buf[:, hi : hi + m] = new
            flag[hi : hi + m] = -1
        self._hi = hi + m
        self._last_key = last
        counts = self._source_rows
        for row in pending:
            counts[row[1]] = counts.get(row[1], 0) + 1

    def _prune(self, t_now: float) -> None:
        horizon = t_now - self.cfg.window_s
        lo = self._lo
        if lo == self._hi or self._buf[0, lo] >= horizon:
            return
        k = int(self._buf[0, lo : self._hi].searchsorted(horizon, side="left"))
        missed = False
        counts = self._source_rows
        for t_s, source in zip(self._buf[0, lo : lo + k].tolist(), self._buf[1, lo : lo + k].tolist(), strict=True):
            missed |= self._store.pop((t_s, int(source)), None) is None
            left = counts[source] - 1
            if left:
                counts[source] = left
            else:
                del counts[source]
        if missed:
            for key in [key for key in self._store if key[0] < horizon]:
                del self._store[key]
        self._lo = lo + k
        self._sorted = None

    def _sources(self, n: int) -> int:
        """Distinct sources among the first ``n`` rows of the window (from per-source row counts)."""
        counts = self._source_rows
        first = self._lo + n
        if first == self._hi:
            return len(counts)
        later: dict[float, int] = {}
        for source in self._buf[1, first : self._hi].tolist():
            later[source] = later.get(source, 0) + 1
        return sum(1 for source, rows in counts.items() if rows > later.get(source, 0))

    def estimate(self, t_now: float) -> Estimate:
        """Estimate xi(t_now) from the window (eqs. 12-15); never raises, never returns NaN.

        Measurements older than ``t_now - window_s`` are dropped for good; those later than
        ``t_now`` are kept for later calls but not used. When the previous solution passed its
        checks and the window changed by at most a quarter of its rows, Gauss-Newton starts from
        that solution (warm path); if the warm path fails any check, the full robust path runs.
        """
        if not math.isfinite(t_now):
            return not_ok(0.0, f"t_now must be finite, got {t_now!r}")
        self._merge()
        self._prune(t_now)
        lo, hi = self._lo, self._hi
        if hi > lo and self._buf[0, hi - 1] <= t_now:
            n = hi - lo
        else:
            n = int(self._buf[0, lo:hi].searchsorted(t_now, side="right"))
        need = self.cfg.min_measurements
        if n < need:
            self._warm = None
            return not_ok(t_now, f"only {n} measurements, need {need}", n_used=n)
        sources = self._sources(n)
        if sources < self.cfg.min_sources:
            self._warm = None
            reason = f"bearings from {sources} AUV(s), need {self.cfg.min_sources} for geometric diversity"
            return not_ok(t_now, reason, n_used=n)
        try:
            est, inlier, warm = self._solve(t_now, self._buf[:, lo : lo + n], self._flag[lo : lo + n])
        except np.linalg.LinAlgError as exc:
            est, inlier, warm = not_ok(t_now, f"linear algebra failure: {exc}", n_used=n), None, None
        self._warm = warm
        if warm is not None:
            self._flag[lo : lo + n] = 1 if inlier is None else inlier
            if lo + n < hi:
                self._flag[lo + n : hi] = -1
        return est

    @np.errstate(all="ignore")
    def _solve(
        self, t_now: float, cols: np.ndarray, flag: np.ndarray
    ) -> tuple[Estimate, np.ndarray | None, _WarmStart | None]:
        """Estimate from the used columns; also, if the solution is usable as a warm start, the inlier
        mask (None: every row) and the warm-start state (else None). Runs under ``np.errstate(all="ignore")``.

        """
        n = cols.shape[1]
        t0 = float(cols[0, 0])
        dt = cols[0] - t0
        scale = column_scale(float(dt[-1]))
        scale2 = np.outer(scale, scale)
        sigma = cols[5]
        q = None if np.isnan(sigma).all() else self.sigma_rad / np.where(np.isnan(sigma), self.sigma_rad, sigma)
        rows = Rows(dt, cols[2], cols[3], cols[4], scale, scale2, q)
        if on_one_track(rows.dt, rows.sx, rows.sy):
            reason = "all bearings taken from one non-manoeuvring sensor track: range unobservable"
            return not_ok(t_now, reason, n_used=n), None, None
        warm = self._warm
        if warm is not None and self.cfg.gauss_newton_iters > 0:
            common = int(np.count_nonzero(flag >= 0))
            if (n - common) + (warm.n_rows - common) <= _WARM_MAX_CHANGE * n:
                xi0 = transition(t0 - warm.t0_s) @ warm.xi0
                found = self._warm_solve(t_now, t0, xi0, rows, flag, warm)
                if found is not None:
                    self._warm_starts += 1
                    return found
        self._cold_solves += 1
        return self._cold_solve(t_now, t0, rows)

    def _warm_solve(
        self,
        t_now: float,
        t0: float,
        xi: np.ndarray,
        rows: Rows,
        flag: np.ndarray,
        warm: _WarmStart,
    ) -> tuple[Estimate, np.ndarray | None, _WarmStart] | None:
        """Gauss-Newton and fixed-gate rounds from the previous solution ``warm``; None if any check fails.

        ``flag`` per row: 1 inlier and 0 rejected in the previous solve, -1 new since then (no row is 0
        if that solve rejected none). A flip is a row whose decision changed, or a new row that is rejected.
        """
        n = rows.dt.size
        first = evaluate(xi, rows)
        inlier = gate(first[0], self.cfg.gate_sigma * self.sigma_m_rad)
        if inlier is not None and np.count_nonzero(inlier) < self.cfg.min_measurements:
            return None
        fast = warm.condition <= NORMAL_EQ_MAX_COND
        xi, inlier, r2, Jt, Ns, settled = self._refine(xi, rows, inlier, fast, first)
        if not settled:
            return None
        if inlier is None:
            flips = int(np.count_nonzero(flag == 0)) if warm.n_rejected else 0
        elif warm.n_rejected:
            flips = int(np.count_nonzero(inlier != (flag != 0)))
        else:
            flips = n - int(np.count_nonzero(inlier))
        if flips > max(_WARM_MAX_FLIPS, _WARM_FLIP_FRACTION * n):
            return None
        found = self._finish(t_now, t0, xi, inlier, r2, Jt, Ns, rows)
        return found if found[2] is not None else None

    def _cold_solve(self, t_now: float, t0: float, rows: Rows) -> tuple[Estimate, np.ndarray | None, _WarmStart | None]:
        """Pseudo-linear WLS (6)-(13), shrinking outlier gate, then Gauss-Newton and fixed-gate rounds.

        A gate round whose xi is the one already evaluated reuses that evaluation.
        """
        dt, sx, sy, bearing = rows.dt, rows.sx, rows.sy, rows.bearing
        n = dt.size
        need = self.cfg.min_measurements
        sb, cb = np.sin(bearing), np.cos(bearing)
        A = np.column_stack((sb, -cb, dt * sb, -dt * cb))
        z = sb * sx - cb * sy
        xi, _ = lstsq(A, z, rows.scale)
        xi, cond = self._pseudo_linear(A, z, xi, rows, None)
        if not cond <= self.cfg.max_condition:
            reason = f"collinear or degenerate geometry: condition number {cond:.3g} > {self.cfg.max_condition:.3g}"
            return not_ok(t_now, reason, n_used=n, condition=cond), None, None
        limit = self.cfg.gate_sigma * self.sigma_m_rad
        inlier = np.ones(n, dtype=bool)
        n_in = n
        tau = math.inf
        seen = None
        for _ in range(_MAX_GATE_ROUNDS):
            if seen is not xi:
                seen = xi
                evaluated = evaluate(xi, rows)
                res = np.abs(evaluated[0])
                robust = _ROBUST_GATE * float(np.median(res))
            tau = max(limit, min(tau, robust))
            new = res <= tau
            kept = int(np.count_nonzero(new))
            if kept < need:
                reason = (
                    f"only {kept} of {n} measurements pass the outlier gate, need {need} "
                    "(gross outliers, or geometry too weak to fix the range)"
                )
                return not_ok(t_now, reason, n_used=kept, n_rejected=n - kept), None, None
            if kept == n_in and np.array_equal(new, inlier):
                if tau == limit:
                    break
                tau = max(limit, 0.5 * tau)
                continue
            inlier, n_in = new, kept
            xi, cond = self._pseudo_linear(A, z, xi, rows, inlier)
        fast = cond <= NORMAL_EQ_MAX_COND
        first = evaluated if seen is xi else None
        use = None if n_in == n else inlier
        xi, use, r2, Jt, Ns, _ = self._refine(xi, rows, use, fast, first)
        return self._finish(t_now, t0, xi, use, r2, Jt, Ns, rows)

    def _refine(
        self,
        xi: np.ndarray,
        rows: Rows,
        inlier: np.ndarray | None,
        fast: bool,
        first: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, np.ndarray | None, bool]:
        """Gauss-Newton on the inliers, then the fixed gate on all rows, until the inlier set is stable.

        ``inlier``: the inlier mask, None for every row (a mask is then never all True). ``first``: what
        ``_evaluate`` gives at ``xi``, if already computed; ``fast``: solve steps by the normal equations.
        Returns xi, the inlier mask (or None), squared ranges (m^2) and transposed Jacobian of all rows
        at xi, the inliers' column-scaled normal matrix at xi (or None), and whether the inlier set
        settled within ``_MAX_OUTER_ROUNDS``.
        """
        limit = self.cfg.gate_sigma * self.sigma_m_rad
        for _ in range(_MAX_OUTER_ROUNDS):
            xi, res, r2, Jt, Ns = self._gauss_newton(xi, rows, inlier, fast, first)
            first = (res, r2, Jt)
            new = gate(res, limit)
            if new is None or inlier is None:
                if new is inlier:
                    return xi, inlier, r2, Jt, Ns, True
            elif np.array_equal(new, inlier):
                return xi, inlier, r2, Jt, Ns, True
            if new is not None and np.count_nonzero(new) < self.cfg.min_measurements:
                return xi, inlier, r2, Jt, Ns, False
            inlier = new
        return xi, inlier, r2, Jt, None, False

    def _finish(
        self,
        t_now: float,
        t0: float,
        xi: np.ndarray,
        inlier: np.ndarray | None,
        r2: np.ndarray,
        Jt: np.ndarray,
        Ns: np.ndarray | None,
        rows: Rows,
    ) -> tuple[Estimate, np.ndarray | None, _WarmStart | None]:
        """Observability checks, covariance (15) from the bearing Jacobian and propagation (14) to ``t_now``.

        ``inlier``: the inlier mask, None for every row; ``Ns``: the inliers' column-scaled normal matrix
        ``scale2 * J^T J`` at xi if known. Returns the estimate and, if it is ok and rejects at most
        ``_WARM_MAX_REJECTED`` of the rows, the inlier mask (None: every row) and the state for the next
        warm start (else None, None).
        A not-ok solution (even one only "too uncertain") is never a warm start: in weak geometry the
        cost has several basins and the cold path may find a better one.
        """
        n = r2.size
        near = r2 < NEAR_FIELD_M**2
        if near.any():
            # a close pass: bearings taken within NEAR_FIELD_M of the solution swing with every
            # decimetre of error and dominate the information (weight 1/r^2); they are left out
            # rather than making the whole window "collapsed" until they age out of it
            inlier = ~near if inlier is None else inlier & ~near
            Ns = None
            if int(np.count_nonzero(inlier)) < self.cfg.min_measurements:
                reason = f"too few bearings farther than {NEAR_FIELD_M:g} m from the solution (close pass)"
                return not_ok(t_now, reason, n_used=int(np.count_nonzero(inlier)), n_rejected=n), None, None
        m = n if inlier is None else int(np.count_nonzero(inlier))
        if Ns is None:
            Jw = (
                Jt.copy() if inlier is None else Jt * inlier
            )  # a copy: numpy sends Jt @ Jt.T to syrk, rounded differently
            Ns = (Jw @ Jt.T) * rows.scale2
        cond, inverse = information_inverse(Ns, Jt, inlier, rows.scale)
        if not cond <= self.cfg.max_condition:
            reason = f"unobservable at the solution: condition number {cond:.3g} > {self.cfg.max_condition:.3g}"
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        closest = math.sqrt(float(np.min(r2 if inlier is None else r2[inlier])))
        if closest < RANGE_FLOOR_M:
            reason = (
                f"solution collapsed onto a sensor (range {closest:.3g} m < {RANGE_FLOOR_M:g} m): range unobservable"
            )
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        P0 = self.sigma_rad**2 * inverse * rows.scale2
        F = transition(t_now - t0)
        x_now = F @ xi
        P = F @ P0 @ F.T
        P = 0.5 * (P + P.T)
        if not (np.isfinite(x_now).all() and np.isfinite(P).all()):
            return not_ok(t_now, "non-finite solution", n_used=m, n_rejected=n - m, condition=cond), None, None
        position_std = math.sqrt(max(0.0, P[0, 0] + P[1, 1]))
        if position_std > self.cfg.max_position_std_m:
            reason = f"too uncertain: position std {position_std:.3g} m > {self.cfg.max_position_std_m:g} m"
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        speed = math.hypot(x_now[2], x_now[3])
        if speed > self.cfg.max_speed_mps:
            reason = f"implausible target speed {speed:.3g} m/s > {self.cfg.max_speed_mps:g} m/s (likely a wrong basin)"
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        est = Estimate(True, "ok", float(t_now), x_now, P, m, n - m, cond)
        if n - m > _WARM_MAX_REJECTED * n:
            return est, None, None
        return est, inlier, _WarmStart(t0, xi, n, n - m, cond)

    def _pseudo_linear(
        self, A: np.ndarray, z: np.ndarray, xi: np.ndarray, rows: Rows, use: np.ndarray | None
    ) -> tuple[np.ndarray, float]:
        """Two reweighted WLS passes of eqs. (12)-(13), weights 1/(r_hat sigma)^2 of eq. (10), on rows ``use`` (None: all)."""
        if use is None:
            dt, sx, sy = rows.dt, rows.sx, rows.sy
        else:
            dt, sx, sy = rows.dt[use], rows.sx[use], rows.sy[use]
            A, z = A[use], z[use]
        cond = math.inf
        for _ in range(2):
            x0, y0, vx, vy = xi.tolist()
            r_hat = np.hypot(dt * vx + x0 - sx, dt * vy + y0 - sy)
            w = 1.0 / (np.maximum(r_hat, RANGE_FLOOR_M) * self.sigma_rad)  # square root of the weight (10)
            if rows.q is not None:
                w = w * (rows.q if use is None else rows.q[use])
            xi_new, cond = lstsq(A * w[:, None], z * w, rows.scale)
            if not np.isfinite(xi_new).all():
                break
            xi = xi_new
        return xi, cond

    def _gauss_newton(
        self,
        xi: np.ndarray,
        rows: Rows,
        use: np.ndarray | None,
        fast: bool,
        first: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Up to ``gauss_newton_iters`` damped Gauss-Newton steps on the sum of squared bearing residuals of rows ``use``.

        ``use``: a mask, None for every row (weights of one are then not multiplied in). A step is halved
        (up to ``_MAX_STEP_HALVINGS`` times) until it lowers the cost. The iteration stops early once the
        full step would lower the cost by less than ``_GN_TOL * sigma^2``, that is once xi is within about
        0.01 standard deviations of the optimum. All rows are evaluated (rows outside ``use`` get weight
        0), so the returned residuals, squared ranges and Jacobian at the final xi serve the next gating
        round; the last item is the column-scaled normal matrix ``scale2 * J^T J`` of rows ``use`` at the
        final xi, or None if it was not computed there.
        """
        res, r2, Jt = evaluate(xi, rows) if first is None else first
        w = None if use is None else use.astype(float)
        current = cost(res, w)
        tol = _GN_TOL * self.sigma_rad**2
        Ns = None
        for _ in range(self.cfg.gauss_newton_iters):
            Jw = Jt.copy() if w is None else Jt * w  # a copy: numpy sends Jt @ Jt.T to syrk, rounded differently
            Ns = (Jw @ Jt.T) * rows.scale2
            step, decrease = gn_step(Ns, Jw @ res, Jw, res, rows.scale, fast)
            if not (decrease > tol and np.isfinite(step).all()):
                return xi, res, r2, Jt, Ns
            for halving in range(_MAX_STEP_HALVINGS):
                trial = xi + step if halving == 0 else xi + 0.5**halving * step
                res_t, r2_t, Jt_t = evaluate(trial, rows)
                cost_t = cost(res_t, w)
                if cost_t < current:
                    xi, res, r2, Jt, current = trial, res_t, r2_t, Jt_t, cost_t
                    break
            else:
                return xi, res, r2, Jt, Ns
            Ns = None
        return xi, res, r2, Jt, Ns

    def consensus(self, own: Estimate, neighbours: list[Estimate]) -> Estimate:
        """Consensus correction of eq. (21) with this estimator's ``consensus_gain`` (see ``base.consensus``)."""
        return consensus(own, neighbours, self.cfg.consensus_gain)
