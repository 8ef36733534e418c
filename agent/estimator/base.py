"""What every estimator shares: the measurement, the estimate, the constant-velocity model and the protocol.

State ``xi = [x, y, vx, vy]`` in m and m/s, inertial frame; bearings in rad from +x,
counter-clockwise (eq. 2). Time is sim time in seconds, always passed in explicitly.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

UNKNOWN_VARIANCE = 1e12
"""Diagonal of P (m^2, m^2/s^2) reported with a not-ok estimate."""

RANGE_FLOOR_M = 1.0
"""Smallest range (m) used in weights and Jacobians; a smaller predicted range means collapse."""


@dataclass(frozen=True)
class Bearing:
    """One direction-of-arrival measurement (eq. 4).

    ``t_s``: sim time (s); ``sensor_xy``: sensor position (m, inertial); ``bearing_rad``:
    bearing from +x, counter-clockwise (rad); ``source``: id of the AUV that measured it;
    ``sigma_rad``: the bearing's own noise std (rad) when the sensor reports one (``ocean.model =
    "physical"``), None otherwise: estimators that ignore it keep working, the built-in ones weight by it.
    """

    t_s: float
    sensor_xy: tuple[float, float]
    bearing_rad: float
    source: int
    sigma_rad: float | None = None


@dataclass(frozen=True, eq=False)
class Estimate:
    """Target state estimate at ``t_s`` (s).

    ``xi = [x, y, vx, vy]`` (m, m/s, inertial) and its covariance ``P`` (4x4) are stored as
    read-only copies and are always finite: when ``ok`` is False they are zeros and
    ``UNKNOWN_VARIANCE * I``, and ``reason`` says why. ``n_used``: measurements the solution rests
    on (when not ok: those available); ``n_rejected``: measurements removed by the outlier gate;
    ``condition``: condition number of the noise-whitened regressor with its velocity columns
    divided by the window span (inf if singular or not computed).

    ``model_error_m2``: a position variance per axis (m^2) for error the estimator's model does not explain
    (``adaptive-window`` step 6), 0 by default. ``P`` is the covariance of eq. (15) that the planner
    uses, as the paper's does; :attr:`reported_P` adds the term to the x and y variances and is the
    covariance the AUV reports (telemetry, NEES).
    """

    ok: bool
    reason: str
    t_s: float
    xi: np.ndarray
    P: np.ndarray
    n_used: int
    n_rejected: int
    condition: float
    model_error_m2: float = 0.0

    def __post_init__(self) -> None:
        for name in ("xi", "P"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def reported_P(self) -> np.ndarray:
        """``P`` with ``model_error_m2`` added to the variance of x and of y (4x4)."""
        if self.model_error_m2 <= 0.0:
            return self.P
        return self.P + np.diag([self.model_error_m2, self.model_error_m2, 0.0, 0.0])


class Estimator(Protocol):
    """One AUV's target estimator: the role every ``estimator.method`` fills.

    ``update`` takes the bearings that arrived since the last call (the AUV's own and those
    received over the link, in any order) and returns the estimate at ``t_s``; it never raises
    and never returns NaN. ``len()`` is the number of measurements held.
    """

    def update(self, bearings: Iterable[Bearing], t_s: float) -> Estimate:
        """Add ``bearings`` and estimate the target state at sim time ``t_s`` (s)."""
        ...

    def __len__(self) -> int: ...


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


def bearing_jacobian(
    xi0: np.ndarray, dt: np.ndarray, sx: np.ndarray, sy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted bearings (rad), ranges (m) and d(bearing)/d(xi(t0)) (M x 4) for a CV target (eqs. 2, 3).

    The bearing of a target at ``p(t0 + dt) = [x0 + dt vx, y0 + dt vy]`` seen from ``(sx, sy)`` is
    ``atan2(ey, ex)`` with ``e = p - s``; its gradient is ``[-ey, ex, -dt ey, dt ex] / r^2``.
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


def consensus(own: Estimate, neighbours: list[Estimate], gain: float) -> Estimate:
    """Consensus correction of eq. (21) with scalar gain Omega = ``gain``.

    ``xi <- xi - gain * sum_j (xi - xi_j)`` over ok neighbours, each first propagated to
    ``own.t_s`` with (14). The covariance is kept. Stable for gain * (number of neighbours) <= 1.
    A gain of 0, a not-ok ``own`` or no ok neighbour returns ``own`` unchanged.
    """
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
