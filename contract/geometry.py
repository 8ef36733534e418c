"""Plane geometry shared by the world and the agents (pure numpy): the angle wrap and sigma_min of eq. (34).

Angles are in radians, counter-clockwise from +x. Every wrapped angle in the project is in
(-pi, pi]: -pi itself maps to +pi.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

_TWO_PI = 2.0 * math.pi


def wrap_angle(a: ArrayLike) -> float | np.ndarray:
    """Angles (rad) wrapped to (-pi, pi]; a float for a scalar, else an array of the same shape."""
    if type(a) is float or type(a) is np.float64:
        w = (a + math.pi) % _TWO_PI - math.pi
        return float(w + _TWO_PI if w <= -math.pi else w)
    x = np.asarray(a, dtype=float)
    w = np.mod(x + math.pi, _TWO_PI) - math.pi
    w = np.where(w <= -math.pi, w + _TWO_PI, w)
    return float(w) if w.ndim == 0 else w


def least_singular_value(bearings_rad: ArrayLike) -> np.ndarray:
    """sigma_min of Phi (eq. 34), the matrix with rows [sin b_i, -cos b_i], for bearings (..., n) in rad.

    sigma_min^2 is the smallest eigenvalue of the 2 x 2 matrix Phi^T Phi = [[a, b], [b, c]]:
    det / lambda_max with lambda_max = (a + c + sqrt((a - c)^2 + 4 b^2)) / 2 and the determinant,
    by Cauchy-Binet, the sum of the squared 2 x 2 minors of Phi (no cancellation for nearly
    parallel bearings). One bearing (a 1 x 2 Phi) has the single singular value 1. The optimum
    for n bearings is sqrt(n / 2) (Fig. 3: 120 or 60 degrees apart for n = 3).
    """
    b = np.asarray(bearings_rad, dtype=float)
    if b.ndim < 1 or b.shape[-1] < 1:
        raise ValueError("bearings_rad must have at least one bearing on its last axis")
    phi_x, phi_y = np.sin(b), -np.cos(b)
    n = b.shape[-1]
    if n == 1:
        return np.ones(b.shape[:-1])
    a = np.sum(phi_x * phi_x, axis=-1)
    c = np.sum(phi_y * phi_y, axis=-1)
    off = np.sum(phi_x * phi_y, axis=-1)
    det = np.zeros(b.shape[:-1])
    for i in range(n):
        for j in range(i + 1, n):
            minor = phi_x[..., i] * phi_y[..., j] - phi_y[..., i] * phi_x[..., j]
            det = det + minor * minor
    lam_max = 0.5 * (a + c + np.sqrt((a - c) ** 2 + 4.0 * off * off))
    return np.sqrt(det / lam_max)
