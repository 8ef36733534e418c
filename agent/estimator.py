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
5. Propagation to the query time with (14): ``F = [[I, dt I], [0, I]]``, ``P -> F P F^T``.

State ``xi = [x, y, vx, vy]`` in m and m/s, inertial frame; bearings in rad from +x,
counter-clockwise (eq. 2).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from auv_core.config import EstimatorConfig

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


def transition(dt_s: float) -> np.ndarray:
    """Constant-velocity transition F = exp(A dt) of eqs. (3), (14) for a step of ``dt_s`` seconds."""
    F = np.eye(4)
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
    J = np.column_stack((gx, gy, dt * gx, dt * gy))
    return np.arctan2(ey, ex), np.sqrt(r2), J


class BearingEstimator:
    """Moving-window share-and-estimate tracker of one AUV (section 2.2, eqs. 11-15, 21)."""

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

    @property
    def invalid_count(self) -> int:
        """Bearings refused by ``add`` because a field was not finite."""
        return self._invalid

    def __len__(self) -> int:
        return len(self._store)

    def window(self) -> list[Bearing]:
        """The measurements held, in canonical order (t_s, source); a copy."""
        return list(self._canonical())

    def _canonical(self) -> list[Bearing]:
        if self._sorted is None:
            self._sorted = [self._store[k] for k in sorted(self._store)]
        return self._sorted

    def add(self, bearings: Iterable[Bearing]) -> int:
        """Insert measurements; duplicates by (source, t_s) and non-finite ones are skipped. Returns how many were added."""
        added = 0
        for b in bearings:
            values = (b.t_s, b.sensor_xy[0], b.sensor_xy[1], b.bearing_rad)
            if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
                self._invalid += 1
                continue
            key = (float(b.t_s), int(b.source))
            if key in self._store:
                continue
            self._store[key] = b
            added += 1
        if added:
            self._sorted = None
        return added

    def _prune(self, t_now: float) -> None:
        horizon = t_now - self.cfg.window_s
        old = [k for k in self._store if k[0] < horizon]
        for k in old:
            del self._store[k]
        if old:
            self._sorted = None

    def estimate(self, t_now: float) -> Estimate:
        """Estimate xi(t_now) from the window (eqs. 12-15); never raises, never returns NaN.

        Measurements older than ``t_now - window_s`` are dropped for good; those later than
        ``t_now`` are kept for later calls but not used.
        """
        if not math.isfinite(t_now):
            return not_ok(0.0, f"t_now must be finite, got {t_now!r}")
        self._prune(t_now)
        rows = [b for b in self._canonical() if b.t_s <= t_now]
        need = self.cfg.min_measurements
        if len(rows) < need:
            return not_ok(t_now, f"only {len(rows)} measurements, need {need}", n_used=len(rows))
        t = np.array([b.t_s for b in rows], dtype=float)
        sx = np.array([b.sensor_xy[0] for b in rows], dtype=float)
        sy = np.array([b.sensor_xy[1] for b in rows], dtype=float)
        bearing = np.array([b.bearing_rad for b in rows], dtype=float)
        with np.errstate(all="ignore"):
            try:
                return self._solve(t_now, t, sx, sy, bearing)
            except np.linalg.LinAlgError as exc:
                return not_ok(t_now, f"linear algebra failure: {exc}", n_used=len(rows))

    def _solve(self, t_now: float, t: np.ndarray, sx: np.ndarray, sy: np.ndarray, bearing: np.ndarray) -> Estimate:
        n = t.size
        need = self.cfg.min_measurements
        t0 = float(t[0])
        dt = t - t0
        span = float(dt[-1])
        if _on_one_track(dt, sx, sy):
            return not_ok(
                t_now,
                "all bearings taken from one non-manoeuvring sensor track: range unobservable",
                n_used=n,
            )
        sb, cb = np.sin(bearing), np.cos(bearing)
        A = np.column_stack((sb, -cb, dt * sb, -dt * cb))
        z = sb * sx - cb * sy
        xi, _ = _lstsq(A, z, span)
        xi, cond = self._pseudo_linear(A, z, xi, dt, sx, sy, np.ones(n, dtype=bool), span)
        if not cond <= self.cfg.max_condition:
            return not_ok(
                t_now,
                f"collinear or degenerate geometry: condition number {cond:.3g} > {self.cfg.max_condition:.3g}",
                n_used=n,
                condition=cond,
            )
        gate = self.cfg.gate_sigma * self.sigma_m_rad
        inlier = np.ones(n, dtype=bool)
        tau = math.inf
        for _ in range(_MAX_GATE_ROUNDS):
            pred, _, _ = bearing_jacobian(xi, dt, sx, sy)
            res = np.abs(wrap_angle(bearing - pred))
            tau = max(gate, min(tau, _ROBUST_GATE * float(np.median(res))))
            new = res <= tau
            if new.sum() < need:
                return not_ok(
                    t_now,
                    f"only {int(new.sum())} of {n} measurements pass the outlier gate, need {need} "
                    "(gross outliers, or geometry too weak to fix the range)",
                    n_used=int(new.sum()),
                    n_rejected=int(n - new.sum()),
                )
            if np.array_equal(new, inlier):
                if tau == gate:
                    break
                tau = max(gate, 0.5 * tau)
                continue
            inlier = new
            xi, _ = self._pseudo_linear(A, z, xi, dt, sx, sy, inlier, span)
        for _ in range(_MAX_OUTER_ROUNDS):
            xi = self._gauss_newton(xi, dt, sx, sy, bearing, inlier, span)
            pred, _, _ = bearing_jacobian(xi, dt, sx, sy)
            new = np.abs(wrap_angle(bearing - pred)) <= gate
            if np.array_equal(new, inlier) or new.sum() < need:
                break
            inlier = new
        m = int(inlier.sum())
        _, rng, J = bearing_jacobian(xi, dt[inlier], sx[inlier], sy[inlier])
        cond = scaled_condition(J, span)
        if not cond <= self.cfg.max_condition:
            return not_ok(
                t_now,
                f"unobservable at the solution: condition number {cond:.3g} > {self.cfg.max_condition:.3g}",
                n_used=m,
                n_rejected=n - m,
                condition=cond,
            )
        if float(rng.min()) < RANGE_FLOOR_M:
            return not_ok(
                t_now,
                f"solution collapsed onto a sensor (range {float(rng.min()):.3g} m < {RANGE_FLOOR_M:g} m): range unobservable",
                n_used=m,
                n_rejected=n - m,
                condition=cond,
            )
        scale = _column_scale(span)
        _, sv, Vt = np.linalg.svd(J * scale, full_matrices=False)
        P0 = self.sigma_rad**2 * ((Vt.T / sv**2) @ Vt) * np.outer(scale, scale)
        F = transition(t_now - t0)
        x_now = F @ xi
        P = F @ P0 @ F.T
        P = 0.5 * (P + P.T)
        if not (np.all(np.isfinite(x_now)) and np.all(np.isfinite(P))):
            return not_ok(t_now, "non-finite solution", n_used=m, n_rejected=n - m, condition=cond)
        position_std = math.sqrt(max(0.0, float(P[0, 0] + P[1, 1])))
        if position_std > self.cfg.max_position_std_m:
            return not_ok(
                t_now,
                f"too uncertain: position std {position_std:.3g} m > {self.cfg.max_position_std_m:g} m",
                n_used=m,
                n_rejected=n - m,
                condition=cond,
            )
        return Estimate(
            ok=True, reason="ok", t_s=float(t_now), xi=x_now, P=P, n_used=m, n_rejected=n - m, condition=cond
        )

    def _pseudo_linear(
        self,
        A: np.ndarray,
        z: np.ndarray,
        xi: np.ndarray,
        dt: np.ndarray,
        sx: np.ndarray,
        sy: np.ndarray,
        use: np.ndarray,
        span: float,
    ) -> tuple[np.ndarray, float]:
        """Two reweighted WLS passes of eqs. (12)-(13), weights 1/(r_hat sigma)^2 of eq. (10), on rows ``use``."""
        cond = math.inf
        for _ in range(2):
            _, rng, _ = bearing_jacobian(xi, dt[use], sx[use], sy[use])
            w = 1.0 / (np.maximum(rng, RANGE_FLOOR_M) * self.sigma_rad)
            xi_new, cond = _lstsq(A[use] * w[:, None], z[use] * w, span)
            if not np.all(np.isfinite(xi_new)):
                break
            xi = xi_new
        return xi, cond

    def _gauss_newton(
        self,
        xi: np.ndarray,
        dt: np.ndarray,
        sx: np.ndarray,
        sy: np.ndarray,
        bearing: np.ndarray,
        use: np.ndarray,
        span: float,
    ) -> np.ndarray:
        """Up to ``gauss_newton_iters`` damped Gauss-Newton steps on sum of squared bearing residuals (rows ``use``)."""
        dt, sx, sy, bearing = dt[use], sx[use], sy[use], bearing[use]
        pred, _, J = bearing_jacobian(xi, dt, sx, sy)
        res = wrap_angle(bearing - pred)
        cost = float(res @ res)
        for _ in range(self.cfg.gauss_newton_iters):
            step, _ = _lstsq(J, res, span)
            if not np.all(np.isfinite(step)):
                break
            accepted = converged = False
            scale = 1.0
            for _ in range(_MAX_STEP_HALVINGS):
                trial = xi + scale * step
                pred_t, _, J_t = bearing_jacobian(trial, dt, sx, sy)
                res_t = wrap_angle(bearing - pred_t)
                cost_t = float(res_t @ res_t)
                if cost_t < cost:
                    xi, J, res, accepted = trial, J_t, res_t, True
                    converged = cost - cost_t <= 1e-12 * cost
                    cost = cost_t
                    break
                scale *= 0.5
            if not accepted or converged:
                break
        return xi

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


def _lstsq(M: np.ndarray, y: np.ndarray, span_s: float) -> tuple[np.ndarray, float]:
    """Least-squares solution of M x = y and the condition number of M with velocity columns divided by ``span_s``."""
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(y))):
        return np.full(M.shape[1], np.nan), math.inf
    scale = _column_scale(span_s)
    U, s, Vt = np.linalg.svd(M * scale, full_matrices=False)
    if s[-1] <= 0.0:
        return np.full(M.shape[1], np.nan), math.inf
    x = (Vt.T @ ((U.T @ y) / s)) * scale
    return x, float(s[0] / s[-1])


def _on_one_track(dt: np.ndarray, sx: np.ndarray, sy: np.ndarray) -> bool:
    """True if every sensor position lies within TRACK_TOL_M of one constant-velocity track s0 + dt * v."""
    if np.ptp(dt) == 0.0:
        return bool(np.ptp(sx) <= TRACK_TOL_M and np.ptp(sy) <= TRACK_TOL_M)
    T = np.column_stack((np.ones_like(dt), dt))
    coef, *_ = np.linalg.lstsq(T, np.column_stack((sx, sy)), rcond=None)
    dev = np.column_stack((sx, sy)) - T @ coef
    return bool(np.max(np.hypot(dev[:, 0], dev[:, 1])) <= TRACK_TOL_M)
