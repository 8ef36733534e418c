"""Readable reference of the ``wls-cv`` estimate: eqs. (6)-(15) and a Gauss-Newton refinement, written plainly.

No gate, no warm start, no scaling tricks: what the fast path (``agent.estimator.window``) computes
when no measurement is an outlier. The property tests run both on generated windows and compare.
Too slow for the agent (pseudo-inverses and Python loops), and not meant to be fast.

State ``xi = [x, y, vx, vy]`` (m, m/s) of a constant-velocity target (eq. 3); bearings (rad) from +x,
counter-clockwise (eq. 2); the bearing noise is uniform of half-width ``sigma_m`` (rad), so its
standard deviation is ``sigma = sigma_m / sqrt(3)``.
"""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.agent.estimator.base import Bearing, transition

PSEUDO_LINEAR_PASSES = 2
"""Reweighted WLS passes after the unweighted start (each uses ranges from the previous solution)."""


def regressor(bearings: list[Bearing], t0_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-linear regressor Phi (M x 4) and measurement vector z (M) of eqs. (6)-(9), (11).

    Bearing ``b`` from sensor ``(xs, ys)`` at ``t = t0 + dt``: the target lies on the bearing line, so
    ``sin b (x(t) - xs) - cos b (y(t) - ys) = 0`` with ``x(t) = x0 + dt vx``, ``y(t) = y0 + dt vy``, i.e.
    ``[sin b, -cos b, dt sin b, -dt cos b] . xi(t0) = sin b xs - cos b ys``.
    """
    Phi = np.zeros((len(bearings), 4))
    z = np.zeros(len(bearings))
    for k, m in enumerate(bearings):
        dt = m.t_s - t0_s
        s, c = math.sin(m.bearing_rad), math.cos(m.bearing_rad)
        xs, ys = m.sensor_xy
        Phi[k] = [s, -c, dt * s, -dt * c]
        z[k] = s * xs - c * ys
    return Phi, z


def predicted(xi0: np.ndarray, m: Bearing, t0_s: float) -> tuple[float, float, np.ndarray]:
    """Predicted bearing (rad), range (m) and bearing gradient d(bearing)/d(xi(t0)) for one measurement (eq. 2)."""
    dt = m.t_s - t0_s
    x = xi0[0] + dt * xi0[2]
    y = xi0[1] + dt * xi0[3]
    ex, ey = x - m.sensor_xy[0], y - m.sensor_xy[1]
    r2 = ex * ex + ey * ey
    gradient = np.array([-ey, ex, -dt * ey, dt * ex]) / r2
    return math.atan2(ey, ex), math.sqrt(r2), gradient


def wrap(angle: float) -> float:
    """An angle (rad) wrapped to [-pi, pi]."""
    return math.atan2(math.sin(angle), math.cos(angle))


def pseudo_linear_wls(bearings: list[Bearing], t0_s: float, sigma_rad: float) -> np.ndarray:
    """xi(t0) from eq. (13): ``Phi^+ z``, then WLS passes with ``R = diag((r_hat sigma)^2)`` of eq. (10)."""
    Phi, z = regressor(bearings, t0_s)
    xi = np.linalg.pinv(Phi) @ z
    for _ in range(PSEUDO_LINEAR_PASSES):
        ranges = np.array([predicted(xi, m, t0_s)[1] for m in bearings])
        R_inv = np.diag(1.0 / (ranges * sigma_rad) ** 2)
        xi = np.linalg.solve(Phi.T @ R_inv @ Phi, Phi.T @ R_inv @ z)
    return xi


def residuals_and_jacobian(xi0: np.ndarray, bearings: list[Bearing], t0_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Bearing residuals ``wrap(b - h(xi))`` (rad) and the Jacobian dh/d(xi(t0)) (M x 4)."""
    res = np.zeros(len(bearings))
    J = np.zeros((len(bearings), 4))
    for k, m in enumerate(bearings):
        h, _, gradient = predicted(xi0, m, t0_s)
        res[k] = wrap(m.bearing_rad - h)
        J[k] = gradient
    return res, J


def gauss_newton(
    xi0: np.ndarray, bearings: list[Bearing], t0_s: float, iterations: int, tol_rad2: float
) -> tuple[np.ndarray, np.ndarray]:
    """Minimise the sum of squared bearing residuals from ``xi0``; returns xi(t0) and the final Jacobian.

    Each step solves ``J step = res`` in the least-squares sense; it is halved (up to 6 times) until
    the cost drops. The iteration stops when the predicted decrease ``|J step|^2`` is below ``tol_rad2``.
    """
    xi = np.array(xi0, dtype=float)
    res, J = residuals_and_jacobian(xi, bearings, t0_s)
    for _ in range(iterations):
        step = np.linalg.lstsq(J, res, rcond=None)[0]
        if not float(np.sum((J @ step) ** 2)) > tol_rad2:
            break
        for halving in range(6):
            trial = xi + step / 2**halving
            res_t, J_t = residuals_and_jacobian(trial, bearings, t0_s)
            if res_t @ res_t < res @ res:
                xi, res, J = trial, res_t, J_t
                break
        else:
            break
    return xi, J


def reference_estimate(
    bearings: list[Bearing], t_s: float, sigma_m_rad: float, iterations: int = 3, tol: float = 1e-4
) -> tuple[np.ndarray, np.ndarray]:
    """xi(t_s) and P(t_s) from every bearing: eqs. (6)-(13), Gauss-Newton, covariance (15), propagation (14).

    The covariance is (15) for the bearing model linearised at the solution: with the Jacobian ``J``
    of the predicted bearings, ``P(t0) = sigma^2 (J^T J)^-1``; then ``P(t) = F P(t0) F^T`` and
    ``xi(t) = F xi(t0)`` with ``F = exp(A (t - t0))``. ``tol`` is in units of ``sigma^2``.
    """
    sigma = sigma_m_rad / math.sqrt(3.0)
    t0 = min(m.t_s for m in bearings)
    xi0 = pseudo_linear_wls(bearings, t0, sigma)
    xi0, J = gauss_newton(xi0, bearings, t0, iterations, tol * sigma**2)
    P0 = sigma**2 * np.linalg.inv(J.T @ J)
    F = transition(t_s - t0)
    return F @ xi0, F @ P0 @ F.T


def reference_track_fit(
    bearings: list[Bearing],
    t_now: float,
    knot_s: float,
    q: float,
    sigma_m_rad: float,
    start: np.ndarray,
    iters: int = 30,
) -> tuple[np.ndarray, np.ndarray]:
    """The manoeuvring-track estimate (``agent.estimator.spline``) written plainly: returns ``xi`` and ``P`` at ``t_now``.

    Knots every ``knot_s`` s on the grid ``k * knot_s`` from the oldest bearing to ``t_now``; the unknowns
    are the knot positions ``start`` (n x 2, m) refined by Gauss-Newton (``np.linalg.lstsq`` steps, halved
    until the cost drops) on the stacked whitened system: one row per bearing, ``wrap(b - h) / sigma``,
    and two rows per interior knot, the second difference of the knots divided by ``sqrt((2/3) q D^3)``.
    No gate. The covariance is the inverse of the final ``A^T A``, mapped onto the state at ``t_now``.
    """
    sigma = sigma_m_rad / math.sqrt(3.0)
    k0 = math.floor(min(m.t_s for m in bearings) / knot_s)
    n = max(k0 + 1, math.ceil(t_now / knot_s)) - k0 + 1
    prior_std = math.sqrt((2.0 / 3.0) * q * knot_s**3)

    def segment(t: float) -> tuple[int, float]:
        u = t / knot_s - k0
        j = min(max(math.floor(u), 0), n - 2)
        return j, u - j

    def system(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        knots = theta.reshape(n, 2)
        rows, rhs = [], []
        for m in bearings:
            j, a = segment(m.t_s)
            p = (1.0 - a) * knots[j] + a * knots[j + 1]
            ex, ey = p[0] - m.sensor_xy[0], p[1] - m.sensor_xy[1]
            r2 = max(ex * ex + ey * ey, 1.0)
            row = np.zeros(2 * n)
            row[2 * j : 2 * j + 2] = (1.0 - a) * np.array([-ey, ex]) / r2
            row[2 * j + 2 : 2 * j + 4] = a * np.array([-ey, ex]) / r2
            nu = m.bearing_rad - math.atan2(ey, ex)
            rows.append(row / sigma)
            rhs.append(math.atan2(math.sin(nu), math.cos(nu)) / sigma)
        for i in range(1, n - 1):
            for axis in range(2):
                row = np.zeros(2 * n)
                row[2 * (i - 1) + axis], row[2 * i + axis], row[2 * (i + 1) + axis] = 1.0, -2.0, 1.0
                rows.append(row / prior_std)
                rhs.append(-(row @ theta) / prior_std)
        return np.array(rows), np.array(rhs)

    theta = np.array(start, dtype=float).reshape(-1)
    A, r = system(theta)
    for _ in range(iters):
        step = np.linalg.lstsq(A, r, rcond=None)[0]
        for h in range(8):
            A_t, r_t = system(theta + step * 0.5**h)
            if r_t @ r_t < r @ r:
                theta, A, r = theta + step * 0.5**h, A_t, r_t
                break
        else:
            break
    j, a = segment(t_now)
    L = np.zeros((4, 2 * n))
    L[0:2, 2 * j : 2 * j + 2] = (1.0 - a) * np.eye(2)
    L[0:2, 2 * j + 2 : 2 * j + 4] = a * np.eye(2)
    L[2:4, 2 * j : 2 * j + 2] = -np.eye(2) / knot_s
    L[2:4, 2 * j + 2 : 2 * j + 4] = np.eye(2) / knot_s
    return L @ theta, L @ np.linalg.inv(A.T @ A) @ L.T
