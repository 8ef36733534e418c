"""A yardstick for the estimator: the unscented Kalman filter Stone Soup runs, given every bearing an AUV holds.

``ReferenceUKF`` is a constant-velocity UKF with white-acceleration process noise of intensity ``q``
(m^2/s^3), the model of Stone Soup's ``ConstantVelocity`` transition, a bearing measurement with
Gaussian noise of the uniform noise's variance ``sigma_m^2 / 3`` (eq. 4), and the sigma points and
circular bearing mean of Stone Soup's ``UnscentedKalmanUpdater`` (alpha 0.5, beta 2, kappa 3 - n).
State ``[x, y, vx, vy]`` (m, m/s); bearings in rad from +x, counter-clockwise (eq. 2).

Shared bearings arrive a TDMA frame late and out of order. The filter handles them exactly: it keeps
every bearing and the state after each one, and when a bearing older than the newest arrives it
filters again from just before it. The estimate at ``t`` is therefore the one a filter would give had
it seen the same bearings in time order. ``bench manoeuvre --reference`` starts it at the true state,
so its error is what the bearings an AUV holds allow, not what a start-up costs.

Not an AUV estimator: it needs the truth to start and it re-filters up to a frame per arrival. It has
no outlier gate, so it is a yardstick only where ``sensor.outlier_rate = 0`` (every built-in).
Pure numpy, no I/O.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable

import numpy as np

from auv_swarm.agent.estimator import Bearing, transition
from auv_swarm.contract.geometry import wrap_angle

ALPHA = 0.5  # Stone Soup's UnscentedKalmanUpdater defaults (and kappa = 3 - n)
BETA = 2.0
N_STATE = 4


def cv_transition(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (14)'s ``F`` for ``[x, y, vx, vy]`` and the white-acceleration noise ``Q`` (q [dt^3/3, dt^2/2; dt^2/2, dt] per axis)."""
    F = transition(dt)
    Q = np.zeros((N_STATE, N_STATE))
    block = q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    Q[np.ix_((0, 2), (0, 2))] = block
    Q[np.ix_((1, 3), (1, 3))] = block
    return F, Q


def _weights() -> tuple[float, np.ndarray, np.ndarray]:
    """Stone Soup's ``gauss2sigma``: the squared spread ``c`` of the sigma points, their mean and covariance weights."""
    kappa = 3.0 - N_STATE
    lam = ALPHA**2 * (N_STATE + kappa) - N_STATE
    c = N_STATE + lam
    wm = np.full(2 * N_STATE + 1, 0.5 / c)
    wm[0] = lam / c
    wc = wm.copy()
    wc[0] += 1.0 - ALPHA**2 + BETA
    return c, wm, wc


class ReferenceUKF:
    """CV-UKF over bearings in time order, re-filtering when a late bearing arrives."""

    def __init__(self, xi0: np.ndarray, P0: np.ndarray, t0_s: float, q: float, sigma_m_rad: float) -> None:
        self.q = q
        self.var = sigma_m_rad**2 / 3.0
        self._start = (t0_s, np.array(xi0, dtype=float), np.array(P0, dtype=float))
        self._keys: list[tuple[float, int]] = []
        self._bearings: list[Bearing] = []
        self._states: list[tuple[float, np.ndarray, np.ndarray]] = []  # after each bearing
        self._c, self._wm, self._wc = _weights()
        self.before_start = 0
        """Bearings left out because they were taken before ``t0_s``."""

    def __len__(self) -> int:
        return len(self._bearings)

    def predict(self, t_s: float, xi: np.ndarray, P: np.ndarray, t1_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Propagate ``(xi, P)`` from ``t_s`` to ``t1_s`` (eq. 14 plus process noise); never backwards."""
        if t1_s <= t_s:
            return xi, P
        F, Q = cv_transition(t1_s - t_s, self.q)
        return F @ xi, F @ P @ F.T + Q

    def correct(self, xi: np.ndarray, P: np.ndarray, b: Bearing) -> tuple[np.ndarray, np.ndarray]:
        """One unscented update with bearing ``b`` (eq. 4), the circular mean of the sigma points' bearings."""
        root = np.linalg.cholesky(P) * math.sqrt(self._c)
        X = np.vstack([xi, xi + root.T, xi - root.T])
        Z = np.arctan2(X[:, 1] - b.sensor_xy[1], X[:, 0] - b.sensor_xy[0])
        z_mean = math.atan2(float(self._wm @ np.sin(Z)), float(self._wm @ np.cos(Z)))
        dz = wrap_angle(Z - z_mean)
        s = float(self._wc @ (dz * dz)) + self.var
        gain = ((self._wc * dz) @ (X - xi)) / s
        return xi + gain * float(wrap_angle(b.bearing_rad - z_mean)), P - np.outer(gain, gain) * s

    def add(self, bearings: Iterable[Bearing]) -> None:
        """Take bearings in any order (the first copy of a ``(t_s, source)`` wins); re-filter from the oldest new one.

        Bearings taken before the start are left out: the start state already stands for what they would tell."""
        first = len(self._bearings)
        for b in bearings:
            if b.t_s < self._start[0]:
                self.before_start += 1
                continue
            key = (b.t_s, b.source)
            k = bisect.bisect_left(self._keys, key)
            if k < len(self._keys) and self._keys[k] == key:
                continue
            self._keys.insert(k, key)
            self._bearings.insert(k, b)
            first = min(first, k)
        del self._states[first:]
        t, xi, P = self._states[-1] if self._states else self._start
        for b in self._bearings[first:]:
            xi, P = self.predict(t, xi, P, b.t_s)
            t = max(t, b.t_s)
            xi, P = self.correct(xi, P, b)
            self._states.append((t, xi, P))

    def estimate(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The state and covariance at ``t_s``, from every bearing held (none newer than ``t_s`` is expected)."""
        t, xi, P = self._states[-1] if self._states else self._start
        return self.predict(t, xi, P, t_s)


def filter_in_order(
    bearings: Iterable[Bearing], xi0: np.ndarray, P0: np.ndarray, t0_s: float, q: float, sigma_m_rad: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """The plain form: sort the bearings by (t_s, source) and filter once. Returns the last state and its time."""
    ukf = ReferenceUKF(xi0, P0, t0_s, q, sigma_m_rad)
    t, xi, P = t0_s, np.array(xi0, dtype=float), np.array(P0, dtype=float)
    for b in sorted({(b.t_s, b.source): b for b in reversed(list(bearings))}.values(), key=lambda b: (b.t_s, b.source)):
        xi, P = ukf.predict(t, xi, P, b.t_s)
        t = max(t, b.t_s)
        xi, P = ukf.correct(xi, P, b)
    return xi, P, t
