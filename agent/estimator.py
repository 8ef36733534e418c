"""Share-and-estimate bearing-only tracking of a constant-velocity source, eqs. (5)-(15) and (21).

Every AUV keeps a moving window of bearings, its own and those received over the
acoustic link. An estimate is computed in five stages:

1. Pseudo-linear weighted least squares (6)-(13), referenced at the oldest sample t0:
   ``[sin b, -cos b, dt sin b, -dt cos b] . xi(t0) = sin b * xs - cos b * ys``,
   each row weighted by the inverse of its noise variance (10), ``1 / (r_hat * sigma)^2``,
   with ``r_hat`` the range predicted by the previous solve and ``sigma^2 = sigma_m^2 / 3``
   the variance of the uniform bearing noise of half-width ``sigma_m``.
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

State ``xi = [x, y, vx, vy]`` in m and m/s, inertial frame; bearings in rad from +x,
counter-clockwise (eq. 2).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

try:
    from numpy.linalg import _umath_linalg

    _SOLVE1, _EIGH_LO = _umath_linalg.solve1, _umath_linalg.eigh_lo
except (ImportError, AttributeError):
    _SOLVE1 = _EIGH_LO = None

from contract.config import EstimatorConfig

UNKNOWN_VARIANCE = 1e12
"""Diagonal of P (m^2, m^2/s^2) reported with a not-ok estimate."""

RANGE_FLOOR_M = 1.0
"""Smallest range (m) used in weights and Jacobians; a smaller predicted range means collapse."""

TRACK_TOL_M = 1e-3
"""If every sensor position lies within this distance (m) of one constant-velocity track,
the range is unobservable (classic bearings-only ambiguity) and no estimate is given."""

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
_NORMAL_EQ_MAX_COND = 1e4
"""Least-squares solves use the 4x4 normal equations when the regressor's scaled condition number is at most
this (their relative error is then about 1e-8), and an SVD of the regressor otherwise."""
_IDENTITY4 = np.eye(4)
_IDENTITY4.setflags(write=False)
_HALF, _ONE, _RANGE_FLOOR, _RANGE_FLOOR2, _TURN, _INV_TURN = (
    np.array(c) for c in (0.5, 1.0, RANGE_FLOOR_M, RANGE_FLOOR_M**2, 2.0 * math.pi, 0.5 / math.pi)
)
"""Scalar operands of hot ufunc calls as 0-d arrays (a Python float operand is converted on every call)."""


@dataclass(frozen=True)
class Bearing:
    """One direction-of-arrival measurement (eq. 4).

    ``t_s``: sim time (s); ``sensor_xy``: sensor position (m, inertial); ``bearing_rad``:
    bearing from +x, counter-clockwise (rad); ``source``: id of the AUV that measured it.
    """

    t_s: float
    sensor_xy: tuple[float, float]
    bearing_rad: float
    source: int


@dataclass(frozen=True, eq=False)
class Estimate:
    """Target state estimate at ``t_s`` (s).

    ``xi = [x, y, vx, vy]`` (m, m/s, inertial) and its covariance ``P`` (4x4) are stored as
    read-only copies and are always finite: when ``ok`` is False they are zeros and
    ``UNKNOWN_VARIANCE * I``, and ``reason`` says why. ``n_used``: measurements the solution rests
    on (when not ok: those available); ``n_rejected``: measurements removed by the outlier gate;
    ``condition``: condition number of the noise-whitened regressor with its velocity columns
    divided by the window span (inf if singular or not computed).
    """

    ok: bool
    reason: str
    t_s: float
    xi: np.ndarray
    P: np.ndarray
    n_used: int
    n_rejected: int
    condition: float

    def __post_init__(self) -> None:
        for name in ("xi", "P"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)


def _owning_estimate(
    t_s: float, xi: np.ndarray, P: np.ndarray, n_used: int, n_rejected: int, condition: float
) -> Estimate:
    """An ok ``Estimate`` that takes over the freshly computed float arrays ``xi`` and ``P`` (made read-only
    in place instead of copied)."""
    xi.setflags(write=False)
    P.setflags(write=False)
    est = object.__new__(Estimate)
    vars(est).update(
        ok=True, reason="ok", t_s=t_s, xi=xi, P=P, n_used=n_used, n_rejected=n_rejected, condition=condition
    )
    return est


def transition(dt_s: float) -> np.ndarray:
    """Constant-velocity transition F = exp(A dt) of eqs. (3), (14) for a step of ``dt_s`` seconds."""
    F = _IDENTITY4.copy()
    F[0, 2] = F[1, 3] = dt_s
    return F


def not_ok(t_s: float, reason: str, n_used: int = 0, n_rejected: int = 0, condition: float = math.inf) -> Estimate:
    """A finite placeholder estimate that carries the reason no estimate is available."""
    return Estimate(
        ok=False,
        reason=reason,
        t_s=float(t_s),
        xi=np.zeros(4),
        P=np.eye(4) * UNKNOWN_VARIANCE,
        n_used=n_used,
        n_rejected=n_rejected,
        condition=condition,
    )


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap angles (rad) to [-pi, pi]."""
    return np.arctan2(np.sin(a), np.cos(a))


def scaled_condition(M: np.ndarray, span_s: float) -> float:
    """2-norm condition number of a 4-column regressor with its velocity columns divided by the window span.

    Dividing by ``span_s`` (s) measures velocity in metres per window, so the number does not
    depend on the time unit; it is inf if ``M`` is singular or not finite.
    """
    if not np.all(np.isfinite(M)):
        return math.inf
    s = np.linalg.svd(M * _column_scale(span_s), compute_uv=False)
    if s[-1] <= 0.0:
        return math.inf
    return float(s[0] / s[-1])


def bearing_jacobian(
    xi0: np.ndarray, dt: np.ndarray, sx: np.ndarray, sy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted bearings (rad), ranges (m) and d(bearing)/d(xi(t0)) (M x 4) for a CV target (eqs. 2, 3).

    Ranges are floored at ``RANGE_FLOOR_M`` inside the Jacobian; the returned ranges are not.
    """
    ex = xi0[0] + dt * xi0[2] - sx
    ey = xi0[1] + dt * xi0[3] - sy
    r2 = ex * ex + ey * ey
    inv = 1.0 / np.maximum(r2, RANGE_FLOOR_M**2)
    gx = -ey * inv
    gy = ex * inv
    J = np.empty((dt.size, 4))
    J[:, 0] = gx
    J[:, 1] = gy
    J[:, 2] = dt * gx
    J[:, 3] = dt * gy
    return np.arctan2(ey, ex), np.sqrt(r2), J


class _Rows(NamedTuple):
    """The bearings an estimate uses, in canonical order, and the column scale of the solve.

    ``dt`` (s) from the oldest one t0, sensor ``sx``, ``sy`` (m), ``bearing`` (rad); ``scale``:
    ``_column_scale`` of the window span, ``scale2`` its outer product.
    """

    dt: np.ndarray
    sx: np.ndarray
    sy: np.ndarray
    bearing: np.ndarray
    scale: np.ndarray
    scale2: np.ndarray


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
        self._sigma, self._sigma2 = np.array(self.sigma_rad), np.array(self.sigma_rad**2)
        self._store: dict[tuple[float, int], Bearing] = {}
        self._sorted: list[Bearing] | None = []
        self._invalid = 0
        self._pending: list[tuple[float, float, float, float, float]] = []
        self._buf = np.empty((5, 0))
        self._flag = np.empty(0, dtype=np.int8)
        self._lo = 0
        self._hi = 0
        self._source_rows: dict[float, int] = {}
        self._last_key = (-math.inf, -math.inf)
        self._scale: tuple[float, np.ndarray, np.ndarray] = (math.nan, _IDENTITY4[0], _IDENTITY4)  # span, scale, scale2
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
            if not (
                type(t_s) is float
                and type(x) is float
                and type(y) is float
                and type(bearing) is float
                and math.isfinite(t_s + x + y + bearing)
            ) and not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (t_s, x, y, bearing)):
                self._invalid += 1
                continue
            key = (float(t_s), int(b.source))
            if key in store:
                continue
            store[key] = b
            pending.append((key[0], float(key[1]), float(x), float(y), float(bearing)))
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
            buf = np.empty((5, max(2 * (size + m), 256)))
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

        The column scale of a window span is reused while the span repeats (windows on a sampling grid).
        """
        n = cols.shape[1]
        t0 = cols.item(0, 0)
        dt = cols[0] - t0
        span = dt.item(-1)
        if self._scale[0] != span:
            scale = _column_scale(span)
            scale2 = scale[:, None] * scale
            scale.setflags(write=False)
            scale2.setflags(write=False)
            self._scale = (span, scale, scale2)
        _, scale, scale2 = self._scale
        rows = _Rows(dt, cols[2], cols[3], cols[4], scale, scale2)
        if _on_one_track(rows.dt, rows.sx, rows.sy):
            reason = "all bearings taken from one non-manoeuvring sensor track: range unobservable"
            return not_ok(t_now, reason, n_used=n), None, None
        warm = self._warm
        if warm is not None and self.cfg.gauss_newton_iters > 0:
            common = int(np.count_nonzero(flag >= 0))
            if (n - common) + (warm.n_rows - common) <= _WARM_MAX_CHANGE * n:
                if t0 == warm.t0_s and all(warm.xi0.tolist()):
                    xi0 = warm.xi0  # transition(0.0) @ xi0 is xi0 itself when no component is (signed) zero
                else:
                    xi0 = np.dot(transition(t0 - warm.t0_s), warm.xi0)
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
        rows: _Rows,
        flag: np.ndarray,
        warm: _WarmStart,
    ) -> tuple[Estimate, np.ndarray | None, _WarmStart] | None:
        """Gauss-Newton and fixed-gate rounds from the previous solution ``warm``; None if any check fails.

        ``flag`` per row: 1 inlier and 0 rejected in the previous solve, -1 new since then (no row is 0
        if that solve rejected none). A flip is a row whose decision changed, or a new row that is rejected.
        """
        n = rows.dt.size
        first = _evaluate(xi, rows)
        inlier = _gate(first[0], self.cfg.gate_sigma * self.sigma_m_rad)
        if inlier is not None and np.count_nonzero(inlier) < self.cfg.min_measurements:
            return None
        fast = warm.condition <= _NORMAL_EQ_MAX_COND
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

    def _cold_solve(
        self, t_now: float, t0: float, rows: _Rows
    ) -> tuple[Estimate, np.ndarray | None, _WarmStart | None]:
        """Pseudo-linear WLS (6)-(13), shrinking outlier gate, then Gauss-Newton and fixed-gate rounds.

        A gate round whose xi is the one already evaluated reuses that evaluation.
        """
        dt, sx, sy, bearing = rows.dt, rows.sx, rows.sy, rows.bearing
        n = dt.size
        need = self.cfg.min_measurements
        sb, cb = np.sin(bearing), np.cos(bearing)
        A = np.column_stack((sb, -cb, dt * sb, -dt * cb))
        z = sb * sx - cb * sy
        xi, _ = _lstsq(A, z, rows.scale)
        xi, cond = self._pseudo_linear(A, z, xi, rows, None)
        if not cond <= self.cfg.max_condition:
            reason = f"collinear or degenerate geometry: condition number {cond:.3g} > {self.cfg.max_condition:.3g}"
            return not_ok(t_now, reason, n_used=n, condition=cond), None, None
        gate = self.cfg.gate_sigma * self.sigma_m_rad
        inlier = np.ones(n, dtype=bool)
        n_in = n
        tau = math.inf
        seen = None
        for _ in range(_MAX_GATE_ROUNDS):
            if seen is not xi:
                seen = xi
                evaluated = _evaluate(xi, rows)
                res = np.abs(evaluated[0])
                robust = _ROBUST_GATE * _median(res)
            tau = max(gate, min(tau, robust))
            new = res <= tau
            kept = int(np.count_nonzero(new))
            if kept < need:
                reason = (
                    f"only {kept} of {n} measurements pass the outlier gate, need {need} "
                    "(gross outliers, or geometry too weak to fix the range)"
                )
                return not_ok(t_now, reason, n_used=kept, n_rejected=n - kept), None, None
            if kept == n_in and np.array_equal(new, inlier):
                if tau == gate:
                    break
                tau = max(gate, 0.5 * tau)
                continue
            inlier, n_in = new, kept
            xi, cond = self._pseudo_linear(A, z, xi, rows, inlier)
        fast = cond <= _NORMAL_EQ_MAX_COND
        first = evaluated if seen is xi else None
        use = None if n_in == n else inlier
        xi, use, r2, Jt, Ns, _ = self._refine(xi, rows, use, fast, first)
        return self._finish(t_now, t0, xi, use, r2, Jt, Ns, rows)

    def _refine(
        self,
        xi: np.ndarray,
        rows: _Rows,
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
        gate = self.cfg.gate_sigma * self.sigma_m_rad
        for _ in range(_MAX_OUTER_ROUNDS):
            xi, res, r2, Jt, Ns = self._gauss_newton(xi, rows, inlier, fast, first)
            first = (res, r2, Jt)
            new = _gate(res, gate)
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
        rows: _Rows,
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
        m = n if inlier is None else int(np.count_nonzero(inlier))
        if Ns is None:
            Jw = Jt.copy() if inlier is None else Jt * inlier
            Ns = np.dot(Jw, Jt.T)
            Ns *= rows.scale2
        cond, inverse = _information_inverse(Ns, Jt, inlier, rows.scale)
        if not cond <= self.cfg.max_condition:
            reason = f"unobservable at the solution: condition number {cond:.3g} > {self.cfg.max_condition:.3g}"
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        if inlier is None:
            closest = math.sqrt(float(np.minimum.reduce(r2, initial=math.inf)))
        else:
            closest = math.sqrt(float(np.minimum.reduce(r2, initial=math.inf, where=inlier)))
        if closest < RANGE_FLOOR_M:
            reason = (
                f"solution collapsed onto a sensor (range {closest:.3g} m < {RANGE_FLOOR_M:g} m): range unobservable"
            )
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        P0 = self._sigma2 * inverse * rows.scale2
        F = transition(t_now - t0)
        x_now = np.dot(F, xi)
        P = np.dot(np.dot(F, P0), F.T)
        P = _HALF * (P + P.T)
        if not (_finite_sum(x_now) and math.isfinite(float(np.add.reduce(P, axis=None)))):
            return not_ok(t_now, "non-finite solution", n_used=m, n_rejected=n - m, condition=cond), None, None
        position_std = math.sqrt(max(0.0, P.item(0, 0) + P.item(1, 1)))
        if position_std > self.cfg.max_position_std_m:
            reason = f"too uncertain: position std {position_std:.3g} m > {self.cfg.max_position_std_m:g} m"
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        speed = math.hypot(x_now.item(2), x_now.item(3))
        if speed > self.cfg.max_speed_mps:
            reason = f"implausible target speed {speed:.3g} m/s > {self.cfg.max_speed_mps:g} m/s (likely a wrong basin)"
            return not_ok(t_now, reason, n_used=m, n_rejected=n - m, condition=cond), None, None
        est = _owning_estimate(float(t_now), x_now, P, m, n - m, cond)
        if n - m > _WARM_MAX_REJECTED * n:
            return est, None, None
        return est, inlier, _WarmStart(t0, xi, n, n - m, cond)

    def _pseudo_linear(
        self, A: np.ndarray, z: np.ndarray, xi: np.ndarray, rows: _Rows, use: np.ndarray | None
    ) -> tuple[np.ndarray, float]:
        """Two reweighted WLS passes of eqs. (12)-(13), weights 1/(r_hat sigma)^2 of eq. (10), on rows ``use`` (None: all)."""
        if use is None:
            dt, sx, sy = rows.dt, rows.sx, rows.sy
        else:
            dt, sx, sy = rows.dt[use], rows.sx[use], rows.sy[use]
            A, z = A.compress(use, axis=0), z[use]
        cond = math.inf
        for _ in range(2):
            x0, y0, vx, vy = xi[0, ...], xi[1, ...], xi[2, ...], xi[3, ...]
            ex = dt * vx
            ex += x0
            ex -= sx
            ey = dt * vy
            ey += y0
            ey -= sy
            w = np.hypot(ex, ey, out=ex)
            np.maximum(w, _RANGE_FLOOR, out=w)
            w *= self._sigma
            np.divide(_ONE, w, w)
            xi_new, cond = _lstsq(A * w[:, None], z * w, rows.scale)
            if not all(map(math.isfinite, xi_new.tolist())):
                break
            xi = xi_new
        return xi, cond

    def _gauss_newton(
        self,
        xi: np.ndarray,
        rows: _Rows,
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
        res, r2, Jt = _evaluate(xi, rows) if first is None else first
        w = None if use is None else use.astype(float)
        cost = _cost(res, w)
        tol = _GN_TOL * self.sigma_rad**2
        Ns = None
        for _ in range(self.cfg.gauss_newton_iters):
            Jw = Jt.copy() if w is None else Jt * w
            Ns = np.dot(Jw, Jt.T)
            Ns *= rows.scale2
            step, decrease = _gn_step(Ns, np.dot(Jw, res), Jw, res, rows.scale, fast)
            if not (decrease > tol and _finite_sum(step)):
                return xi, res, r2, Jt, Ns
            for halving in range(_MAX_STEP_HALVINGS):
                trial = xi + step if halving == 0 else xi + 0.5**halving * step
                res_t, r2_t, Jt_t = _evaluate(trial, rows)
                cost_t = _cost(res_t, w)
                if cost_t < cost:
                    xi, res, r2, Jt, cost = trial, res_t, r2_t, Jt_t, cost_t
                    break
            else:
                return xi, res, r2, Jt, Ns
            Ns = None
        return xi, res, r2, Jt, Ns

    def consensus(self, own: Estimate, neighbours: list[Estimate]) -> Estimate:
        """Consensus correction of eq. (21) with scalar gain Omega = ``consensus_gain``.

        ``xi <- xi - gain * sum_j (xi - xi_j)`` over ok neighbours, each first propagated to
        ``own.t_s`` with (14). The covariance is kept. Stable for gain * (number of neighbours) <= 1.
        A gain of 0, a not-ok ``own`` or no ok neighbour returns ``own`` unchanged.
        """
        gain = self.cfg.consensus_gain
        peers = [e for e in neighbours if e.ok]
        if gain == 0.0 or not own.ok or not peers:
            return own
        xi = np.array(own.xi, dtype=float)
        correction = np.zeros(4)
        for e in peers:
            correction += xi - transition(own.t_s - e.t_s) @ e.xi
        new = xi - gain * correction
        if not np.all(np.isfinite(new)):
            return own
        return Estimate(
            ok=True,
            reason=own.reason,
            t_s=own.t_s,
            xi=new,
            P=np.array(own.P, dtype=float),
            n_used=own.n_used,
            n_rejected=own.n_rejected,
            condition=own.condition,
        )


def _column_scale(span_s: float) -> np.ndarray:
    inv = 1.0 / span_s if span_s > 0.0 else 1.0
    return np.array([1.0, 1.0, inv, inv])


def _evaluate(xi0: np.ndarray, rows: _Rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bearing residuals b - h(xi) wrapped to [-pi, pi] (rad), squared ranges (m^2) and the transposed
    Jacobian dh/d(xi(t0)) (4 x M) of the predicted bearings h of eqs. (2), (3); as ``bearing_jacobian``.

    Scalar operands are 0-d arrays (``xi0[k, ...]`` and module constants), which ufuncs take without conversion."""
    x0, y0, vx, vy = xi0[0, ...], xi0[1, ...], xi0[2, ...], xi0[3, ...]
    dt = rows.dt
    ex = dt * vx
    ex += x0
    ex -= rows.sx
    ey = dt * vy
    ey += y0
    ey -= rows.sy
    r2 = ex * ex
    inv = ey * ey
    r2 += inv
    np.maximum(r2, _RANGE_FLOOR2, out=inv)
    np.divide(_ONE, inv, inv)
    Jt = np.empty((4, dt.size))
    gx, gy = Jt[0], Jt[1]
    np.multiply(ey, inv, gx)
    np.negative(gx, gx)
    np.multiply(ex, inv, gy)
    np.multiply(dt, gx, Jt[2])
    np.multiply(dt, gy, Jt[3])
    res = np.arctan2(ey, ex)
    np.subtract(rows.bearing, res, res)
    turns = np.multiply(res, _INV_TURN, ex)
    np.rint(turns, turns)
    turns *= _TURN
    res -= turns
    return res, r2, Jt


def _gate(res: np.ndarray, gate: float) -> np.ndarray | None:
    """The rows whose residual passes the gate, ``|res| <= gate``: None if every row does, else the mask."""
    size = np.abs(res)
    if np.maximum.reduce(size) <= gate:
        return None
    return size <= gate


def _finite_sum(v: np.ndarray) -> bool:
    """``math.isfinite(np.add.reduce(v))`` for a 4-vector, summed in numpy's order."""
    a, b, c, d = v.tolist()
    return math.isfinite(a + b + c + d)


def _median(x: np.ndarray) -> float:
    """``np.median`` of a 1-D float array, the same value (NaN if any element is), from one partition."""
    n = x.size
    h = n // 2
    part = np.partition(x, (h - 1, h, n - 1) if n % 2 == 0 else (h, n - 1))
    if math.isnan(part[-1]):
        return math.nan
    return float(part[h]) if n % 2 else (float(part[h - 1]) + float(part[h])) / 2.0


def _cost(res: np.ndarray, w: np.ndarray | None) -> float:
    """Sum of squared weighted residuals ``|res * w|^2``; ``w`` None: weights of one."""
    if w is None:
        return float(np.dot(res, res))
    rw = res * w
    return float(np.dot(rw, rw))


def _normal_inverse(Ns: np.ndarray) -> tuple[float, np.ndarray] | None:
    """Condition number of a regressor and the inverse of its 4x4 normal matrix ``Ns``, from ``eigh(Ns)``.

    None unless ``Ns`` is finite and the condition number is at most ``_NORMAL_EQ_MAX_COND`` (then
    the relative error is about 1e-8 and an SVD of the regressor is not needed).
    """
    if not math.isfinite(float(np.add.reduce(Ns, axis=None))):
        return None
    lam, V = _eigh(Ns)
    lo, hi = lam.item(0), lam.item(-1)
    if lo > 0.0 and hi <= _NORMAL_EQ_MAX_COND**2 * lo:
        return math.sqrt(hi / lo), np.dot(V / lam, V.T)
    return None


def _eigh(Ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.linalg.eigh(Ns)`` of a finite symmetric 4x4 matrix, by the same LAPACK gufunc without the wrapper's checks.

    Called under ``np.errstate(all="ignore")``, where the gufunc reports non-convergence as NaN
    eigenvalues; that is raised as the ``LinAlgError`` ``np.linalg.eigh`` raises.
    """
    if _EIGH_LO is None:
        return np.linalg.eigh(Ns)
    lam, V = _EIGH_LO(Ns)
    if math.isnan(lam[0]):
        raise np.linalg.LinAlgError("Eigenvalues did not converge")
    return lam, V


def _solve_4x4(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.linalg.solve(A, b)`` by the same LAPACK gufunc without the wrapper; NaN where A is singular.

    Falls back to ``np.linalg.solve`` on a numpy without that (private) gufunc.
    """
    if _SOLVE1 is not None:
        return _SOLVE1(A, b)
    try:
        return np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return np.full(b.shape, np.nan)


def _lstsq(M: np.ndarray, y: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares solution of M x = y and the condition number of M with its columns multiplied by ``scale``.

    Normal equations when well conditioned (``_normal_inverse``), an SVD of M otherwise.
    """
    Ms = M * scale
    fast = _normal_inverse(np.dot(Ms.T, Ms))
    if fast is not None:
        cond, inverse = fast
        return np.dot(inverse, np.dot(Ms.T, y)) * scale, cond
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(y))):
        return np.full(M.shape[1], np.nan), math.inf
    U, s, Vt = np.linalg.svd(Ms, full_matrices=False)
    if s[-1] <= 0.0:
        return np.full(M.shape[1], np.nan), math.inf
    x = (Vt.T @ ((U.T @ y) / s)) * scale
    return x, float(s[0] / s[-1])


def _information_inverse(
    Ns: np.ndarray, Jt: np.ndarray, use: np.ndarray | None, scale: np.ndarray
) -> tuple[float, np.ndarray]:
    """Condition number of the column-scaled Jacobian of rows ``use`` (None: all) and the inverse of its normal matrix ``Ns``.

    ``_normal_inverse(Ns)`` gives both when the problem is well conditioned; otherwise an SVD of the
    scaled rows of ``Jt.T`` does. Returns (inf, zeros) if the rows are singular or not finite.
    """
    fast = _normal_inverse(Ns)
    if fast is not None:
        return fast
    if not math.isfinite(float(Ns.sum())):
        return math.inf, np.zeros((4, 4))
    _, sv, Vt = np.linalg.svd((Jt if use is None else Jt[:, use]).T * scale, full_matrices=False)
    if not sv[-1] > 0.0:
        return math.inf, np.zeros((4, 4))
    return float(sv[0] / sv[-1]), (Vt.T / sv**2) @ Vt


def _gn_step(
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
    solve the column-scaled 4x4 normal equations ``Ns s = scale * g`` (by the LAPACK gufunc behind
    ``np.linalg.solve``; under ``np.errstate(all="ignore")`` a singular matrix gives a NaN step), else
    use an SVD of ``Jw``. The predicted decrease of the sum of squared
    residuals is ``|J step|^2`` (rad^2); the step is NaN if it is undefined.
    """
    if fast:
        gs = g * scale
        step = _solve_4x4(Ns, gs)
        return step * scale, float(np.dot(gs, step))
    Js = Jw.T * scale
    if not (math.isfinite(float(Js.sum())) and math.isfinite(float(res.sum()))):
        return np.full(4, np.nan), math.nan
    U, s, Vt = np.linalg.svd(Js, full_matrices=False)
    if s[-1] <= 0.0:
        return np.full(4, np.nan), math.nan
    c = U.T @ res
    return (Vt.T @ (c / s)) * scale, float(c @ c)


def _on_one_track(dt: np.ndarray, sx: np.ndarray, sy: np.ndarray) -> bool:
    """True if every sensor position lies within TRACK_TOL_M of one constant-velocity track s0 + dt * v.

    ``dt`` (s) is sorted with ``dt[0] = 0``. Quick exit first: if all points were within the tolerance
    of a track, every point would be within twice the tolerance of the straight interpolation between
    the first and the last point, so one probe further away than that settles the answer.
    """
    t0, n = dt.item(0), dt.size
    span = dt.item(-1) - t0
    if span == 0.0:
        return bool(np.ptp(sx) <= TRACK_TOL_M and np.ptp(sy) <= TRACK_TOL_M)
    x0, y0, x1, y1 = sx.item(0), sy.item(0), sx.item(-1), sy.item(-1)
    for k in (n // 2, n // 4, (3 * n) // 4):
        lam = (dt.item(k) - t0) / span
        if math.hypot(sx.item(k) - (x0 + lam * (x1 - x0)), sy.item(k) - (y0 + lam * (y1 - y0))) > 3.0 * TRACK_TOL_M:
            return False
    T = np.column_stack((np.ones_like(dt), dt))
    coef, *_ = np.linalg.lstsq(T, np.column_stack((sx, sy)), rcond=None)
    dev = np.column_stack((sx, sy)) - T @ coef
    return bool(np.max(np.hypot(dev[:, 0], dev[:, 1])) <= TRACK_TOL_M)
