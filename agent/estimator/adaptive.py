"""``adaptive-window`` (the default): the 600 s constant-velocity window and a manoeuvring-track model, mixed by the
likelihood of their innovations with a prior for the window (IMM-style).

A constant-velocity fit over a long window is the most accurate estimate while the source keeps
its course, and badly biased after a turn, a stop or a reversal. This estimator runs, on the same
bearings, the moving-window WLS (``window.BearingEstimator``) over ``window_s`` (and any shorter
``adaptive_windows_s``, none by default) and the manoeuvring-track model of ``spline.py`` (a
piecewise-linear track with an acceleration-noise prior over the last ``spline_span_s``), and mixes
them by how well each one predicted the bearings that just arrived:

1. Innovations: every new bearing ``b`` (own or received, taken at ``t_k``) is predicted by each
   model's previous estimate along its CV track (eqs. 2, 3, 14); ``nu = wrap(b - h(xi))`` (rad)
   is normalised by its predicted variance ``var = sigma^2 + J P J^T`` (bearing noise plus the
   model's own uncertainty). Innovations beyond the outlier gate ``gate_sigma * sigma_m`` are
   left out, as the models leave such bearings out.
2. Likelihood: each model keeps the faded sum ``score = sum (nu^2 / var + log(var / sigma^2))``,
   its Gaussian negative log-likelihood up to a constant, with memory
   ``exp(-dt / likelihood_memory_s)``.
3. Prior: ``adaptive_prior`` per step down in window length and ``spline_prior`` for the track model
   are added to the scores (twice the log prior odds for the long window): a model other than the
   long window takes over only when the recent bearings reject the long window by that margin, so
   on a source that holds its course the long window's accuracy is kept.
4. Mixing, as an IMM mixes its models' outputs: weights ``w_k = exp(-(score_k + prior_k - min) / 2)``
   over the models with an ok estimate, ``xi = sum w_k xi_k``,
   ``P = sum w_k (P_k + (xi_k - xi)(xi_k - xi)^T)``; the spread term keeps the covariance honest
   when the models disagree. While the long window is not ok (early in a mission, weak geometry),
   neither is the mix: the long window decides whether the geometry fixes the source at all.
5. Waking: the track model is fitted only while it can matter. Its prior keeps it out of the mix
   until the long window's score exceeds the track model's by ``spline_prior``; a model that fits
   has ``nu^2 / var`` of about one per innovation, so that needs the long window's *excess*
   ``sum (nu^2 / var - 1)`` (faded alike; a chi-square test of its normalised innovations) to be
   large. While the excess stays under the larger of ``spline_wake`` (< ``spline_prior``) and three
   standard deviations of the excess of innovations that fit (``3 sqrt(0.8 n)`` for the faded
   count ``n``; with many AUVs sharing bearings a fixed threshold is passed by chance), the track
   model sleeps (not fitted, not in the mix). It wakes when the excess passes that threshold (the
   constant-velocity model broke), with the long window's score as its own (no evidence either way
   yet), and sleeps again once the excess is back under half of that threshold and the track model
   scores no better than the long window. On a source that holds its course it mostly sleeps, which
   keeps the cost of the window alone.
6. Model error in the covariance. The window's covariance (eq. 15) knows the bearing noise only; a source
   that bends away from its constant-velocity course leaves a bias it does not claim (NEES far above 2 on
   section 3.2). The long window's innovations measure it: ``E[nu^2] = var + b^2 / r^2`` for a cross-range
   error ``b`` at range ``r``, so the faded ``sum (nu^2 - var) r^2`` over their faded count (the moment
   estimate of ``b^2``, with the likelihood's memory), if positive, is the model error per axis. It is
   carried as ``Estimate.model_error_m2`` while the track model sleeps, and ``Estimate.reported_P`` adds it
   to the variance of x and of y: the covariance the AUV reports. While the track model is awake the mix's
   spread term speaks for the models' disagreement. The estimate and ``P``, which the planner uses, are
   unchanged: handing the planner the larger covariance changed its geometry and cost the U-turn 3-5 m of
   mean error.

Every model sees every bearing and the sums run in canonical order, so the estimate is a
deterministic function of the call history. Bearings in rad, times in s, positions in m (inertial).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from auv_swarm.agent.estimator.base import RANGE_FLOOR_M, Bearing, Estimate, not_ok
from auv_swarm.agent.estimator.spline import SplineFit
from auv_swarm.agent.estimator.window import BearingEstimator
from auv_swarm.contract.config import EstimatorConfig
from auv_swarm.contract.geometry import wrap_angle

WAKE_SIGMAS = 3.0
"""The wake test's threshold is at least this many standard deviations of the excess of innovations that fit."""


@dataclass
class Model:
    """One model of the mix: what it last estimated and how well that predicted the bearings since."""

    name: str
    """``window <L> s`` or ``track``."""
    prior: float
    """Penalty added to its score: twice the log prior odds for the longest window (steps 3-4)."""
    score: float = 0.0
    """Faded negative log-likelihood of its innovations (dimensionless; step 2)."""
    previous: Estimate | None = None
    """Its last ok estimate, which the next bearings are scored against."""
    chosen: int = 0
    """How many times it had the largest weight in the mix."""


@dataclass
class Misfit:
    """The long window's faded innovation statistics beyond a fit (steps 5 and 6)."""

    excess: float = 0.0
    """Faded ``sum (nu^2 / var - 1)``: the chi-square excess of its normalised innovations."""
    count: float = 0.0
    """Faded number of those innovations."""
    cross_range_m2: float = 0.0
    """Faded ``sum (nu^2 - var) r^2`` (m^2): their cross-range excess."""

    def fade(self, factor: float) -> None:
        self.excess *= factor
        self.count *= factor
        self.cross_range_m2 *= factor

    def add(self, q: float, n: int, cross_range_m2: float) -> None:
        self.excess += q - n
        self.count += n
        self.cross_range_m2 += cross_range_m2


class AdaptiveWindowEstimator:
    """The ``Estimator`` of method ``adaptive-window`` (see the module docstring).

    Models (:attr:`models`): the windows ``cfg.window_s`` and every shorter ``cfg.adaptive_windows_s`` (s),
    longest first, then the manoeuvring-track model (:attr:`track`) if ``cfg.spline_knot_s > 0``.
    """

    def __init__(self, cfg: EstimatorConfig, sigma_m_rad: float) -> None:
        """``sigma_m_rad``: half-width of the uniform bearing noise (rad), in (0, pi]."""
        lengths = sorted({cfg.window_s, *(w for w in cfg.adaptive_windows_s if w < cfg.window_s)}, reverse=True)
        self.cfg = cfg
        self.bank = [BearingEstimator(dataclasses.replace(cfg, window_s=w), sigma_m_rad) for w in lengths]
        self.sigma2 = (sigma_m_rad / math.sqrt(3.0)) ** 2
        self.gate_rad = cfg.gate_sigma * sigma_m_rad
        self.spline = (
            SplineFit(
                sigma_m_rad / math.sqrt(3.0),
                cfg.spline_knot_s,
                cfg.spline_q,
                cfg.gate_sigma * sigma_m_rad,
                cfg.max_position_std_m,
                cfg.max_speed_mps,
                cfg.min_measurements,
            )
            if cfg.spline_knot_s > 0.0
            else None
        )
        self.models = [Model(f"window {w:g} s", cfg.adaptive_prior * k) for k, w in enumerate(lengths)]
        self.track = Model("track", cfg.spline_prior) if self.spline is not None else None
        if self.track is not None:
            self.models.append(self.track)
        self.long = self.models[0]
        """The longest window: it decides whether the geometry fixes the source, and its misfit wakes the track."""
        self.misfit = Misfit()
        self.t_last = math.nan
        self.awake = self.spline is not None and cfg.spline_wake <= 0.0
        """Whether the track model is being fitted (see "Waking" in the module docstring)."""

    @property
    def windows_s(self) -> list[float]:
        """Window lengths (s), longest first."""
        return [est.cfg.window_s for est in self.bank]

    @property
    def chosen(self) -> list[int]:
        """How many times each model (longest window first, the track model last) had the largest weight."""
        return [m.chosen for m in self.models]

    def __len__(self) -> int:
        return len(self.bank[0])

    def update(self, bearings: Iterable[Bearing], t_s: float) -> Estimate:
        """Score every model's last estimate on the new ``bearings``, update every model, return their mix."""
        batch = list(bearings)
        if math.isfinite(t_s) and math.isfinite(self.t_last):
            fade = math.exp(-max(0.0, t_s - self.t_last) / self.cfg.likelihood_memory_s)
            for m in self.models:
                m.score *= fade
            self.misfit.fade(fade)
        rows = _columns(batch)
        if rows:
            for m in self.models:
                if m.previous is not None:
                    q, log_var, n, cross_range_m2 = self._innovations(m.previous, rows)
                    m.score += q + log_var
                    if m is self.long:
                        self.misfit.add(q, n, cross_range_m2)
        estimates = [est.update(batch, t_s) for est in self.bank]
        if not math.isfinite(t_s):
            return estimates[0]
        if self.spline is not None:
            estimates.append(self._track(estimates, t_s))
        self.t_last = t_s
        for m, e in zip(self.models, estimates, strict=True):
            m.previous = e if e.ok else None
        ok = [k for k, e in enumerate(estimates) if e.ok]
        if not estimates[0].ok:  # the longest window decides whether the geometry fixes the source at all
            return estimates[0]
        if len(ok) == 1:  # the track model asleep: nothing to mix
            self.long.chosen += 1
            return self._with_model_error(estimates[0])
        total = [self.models[k].score + self.models[k].prior for k in ok]
        best = min(total)
        w = np.array([math.exp(-0.5 * (t - best)) for t in total])
        w /= w.sum()
        top_k = ok[int(np.argmax(w))]
        self.models[top_k].chosen += 1
        xs = np.array([estimates[k].xi for k in ok])
        xi = w @ xs
        P = sum(
            wk * (estimates[k].P + np.outer(estimates[k].xi - xi, estimates[k].xi - xi))
            for wk, k in zip(w, ok, strict=True)
        )
        top = estimates[top_k]
        return Estimate(
            ok=True,
            reason=top.reason,
            t_s=top.t_s,
            xi=xi,
            P=0.5 * (P + P.T),
            n_used=top.n_used,
            n_rejected=top.n_rejected,
            condition=estimates[0].condition,
        )

    def model_error_m2(self) -> float:
        """Step 6 of the module docstring: the variance (m^2, per axis) of the position error the long window's
        innovations show beyond what its covariance and the bearing noise explain (0 when they show none)."""
        m = self.misfit
        return max(0.0, m.cross_range_m2 / m.count) if m.count > 0.0 else 0.0

    def _with_model_error(self, e: Estimate) -> Estimate:
        """``e`` carrying :meth:`model_error_m2` (``Estimate.reported_P`` adds it; ``P`` stays eq. 15's)."""
        m2 = self.model_error_m2()
        return dataclasses.replace(e, model_error_m2=m2) if m2 > 0.0 else e

    def _track(self, estimates: list[Estimate], t_s: float) -> Estimate:
        """The track model's estimate if it is awake (waking or putting it to sleep first), else not ok."""
        # The excess of n innovations that fit has a standard deviation of about sqrt(0.8 n) (uniform bearing
        # noise): with many AUVs sharing bearings the fixed threshold alone would be passed by chance.
        excess, count = self.misfit.excess, self.misfit.count
        wake = max(self.cfg.spline_wake, WAKE_SIGMAS * math.sqrt(0.8 * count)) if self.cfg.spline_wake > 0 else 0.0
        if not self.awake and excess > wake:
            self.awake = True
            self.track.score = self.long.score  # no evidence either way yet
        elif self.awake and wake > 0.0 and excess < 0.5 * wake and self.track.score >= self.long.score:
            self.awake = False
        if not self.awake:
            return not_ok(t_s, "manoeuvring-track model asleep: the constant-velocity window fits")
        return self._spline(estimates, t_s)

    def _spline(self, estimates: list[Estimate], t_s: float) -> Estimate:
        """The piecewise-linear track fit over the last ``spline_span_s``, started from its last fit or an ok window."""
        cols = self.bank[0].columns(t_s - self.cfg.spline_span_s, t_s, sigma=True)
        prev = self.track.previous
        start = prev if prev is not None else next((e for e in estimates if e.ok), None)
        if start is None:
            return estimates[0]
        sigma = None if np.isnan(cols[4]).all() else cols[4]
        return self.spline.fit(cols[:4], t_s, np.asarray(start.xi), start.t_s, sigma)

    def _innovations(
        self, e: Estimate, rows: list[tuple[float, float, float, float, float | None]]
    ) -> tuple[float, float, int, float]:
        """Innovations of ``rows`` (t, x, y, bearing, own sigma or None) against the CV track of ``e``: sum of
        ``nu^2 / var``, sum of ``log(var / sigma^2)``, their number and the sum of ``(nu^2 - var) r^2`` (m^2),
        with ``var = sigma^2 + J P J^T`` (rad^2), sigma the bearing's own where it has one, and ``r`` the
        predicted range (m).

        Innovations beyond the outlier gate (``gate_sigma * sigma_m``, scaled by the bearing's own sigma over
        the estimator's) are left out, as the windows leave them out.
        A plain loop: a tick brings a handful of bearings, too few for numpy to pay off.
        """
        x0, y0, vx, vy = (float(v) for v in e.xi)
        P = e.P.tolist()
        q = log_var = miss = 0.0
        n = 0
        for row in rows:
            t, sx, sy, bearing = row[:4]
            own = row[4] if len(row) > 4 else None
            dt = t - e.t_s
            ex, ey = x0 + dt * vx - sx, y0 + dt * vy - sy
            r2 = max(ex * ex + ey * ey, RANGE_FLOOR_M**2)
            nu = wrap_angle(bearing - math.atan2(ey, ex))
            s2, gate = (
                (self.sigma2, self.gate_rad)
                if own is None
                else (own * own, self.gate_rad * own / math.sqrt(self.sigma2))
            )
            if abs(nu) > gate:
                continue
            # J = (a, b, dt a, dt b) with (a, b) = (-ey, ex) / r2, so J P J^T = (a, b) Ppos (a, b)^T, where Ppos is
            # the position block of P carried dt along the CV model (eq. 14).
            a, b = -ey / r2, ex / r2
            pxx = P[0][0] + 2.0 * dt * P[0][2] + dt * dt * P[2][2]
            pxy = P[0][1] + dt * (P[0][3] + P[2][1]) + dt * dt * P[2][3]
            pyy = P[1][1] + 2.0 * dt * P[1][3] + dt * dt * P[3][3]
            var = s2 + a * a * pxx + 2.0 * a * b * pxy + b * b * pyy
            q += nu * nu / var
            log_var += math.log(var / s2)
            miss += (nu * nu - var) * r2
            n += 1
        return q, log_var, n, miss


def _columns(batch: list[Bearing]) -> list[tuple[float, float, float, float, float | None]]:
    """The finite bearings of ``batch`` as rows (t_s, x, y, bearing, own sigma or None), sorted by (t_s, source)."""
    rows = sorted(
        (
            (b.t_s, b.source, b.sensor_xy[0], b.sensor_xy[1], b.bearing_rad, _own_sigma(b))
            for b in batch
            if all(isinstance(v, (int, float)) and math.isfinite(v) for v in (b.t_s, *b.sensor_xy, b.bearing_rad))
        ),
        key=lambda row: row[:5],
    )  # canonical order, so the sums do not depend on the arrival order
    return [(float(t), float(x), float(y), float(bearing), own) for t, _, x, y, bearing, own in rows]


def _own_sigma(b: Bearing) -> float | None:
    """The bearing's own noise std (rad) if it carries a usable one, else None."""
    s = getattr(b, "sigma_rad", None)
    return float(s) if isinstance(s, (int, float)) and math.isfinite(s) and s > 0.0 else None
