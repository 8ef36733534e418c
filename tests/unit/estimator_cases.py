"""Bearing streams and estimators for the estimator's tests: CV targets seen from static or moving sensors."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st

from auv_swarm.agent.estimator import UNKNOWN_VARIANCE, Bearing, BearingEstimator, Estimate
from auv_swarm.contract.config import EstimatorConfig

SIGMA_M = math.radians(4.5)
TIMES = np.arange(0.0, 60.0 + 1e-9, 2.0)


def make_bearings(sensors, target0, times=TIMES, noise_rad=0.0, rng=None, outlier_every=0):
    """Bearings of a CV target ``target0 = [x, y, vx, vy]`` at t = 0 from ``sensors(t) -> [(x, y), ...]``.

    With ``outlier_every = k`` every k-th bearing (in generation order) is a gross outlier, off by
    30-330 deg. Returns the bearings and the indices of the outliers.
    """
    out, outliers = [], []
    for t in times:
        p = np.asarray(target0[:2], dtype=float) + t * np.asarray(target0[2:], dtype=float)
        for i, (x, y) in enumerate(sensors(t)):
            b = math.atan2(p[1] - y, p[0] - x)
            if noise_rad:
                b += rng.uniform(-noise_rad, noise_rad)
            if outlier_every and len(out) % outlier_every == outlier_every // 2:
                b = b + rng.uniform(math.radians(30.0), math.radians(330.0))
                outliers.append(len(out))
            out.append(Bearing(t_s=float(t), sensor_xy=(float(x), float(y)), bearing_rad=float(b), source=i))
    return out, outliers


def triangle(radius=500.0, centre=(0.0, 0.0), phase=0.3):
    pts = [
        (
            centre[0] + radius * math.cos(phase + k * 2 * math.pi / 3),
            centre[1] + radius * math.sin(phase + k * 2 * math.pi / 3),
        )
        for k in range(3)
    ]
    return lambda t: pts


def estimator(**cfg) -> BearingEstimator:
    return BearingEstimator(EstimatorConfig(**cfg), SIGMA_M)


def assert_finite_not_ok(e: Estimate) -> None:
    assert not e.ok
    assert e.reason
    assert e.xi.shape == (4,) and e.P.shape == (4, 4)
    assert np.all(np.isfinite(e.xi)) and np.all(np.isfinite(e.P))
    np.testing.assert_array_equal(e.P, np.eye(4) * UNKNOWN_VARIANCE)


def moving_sensors(t):
    return [(400.0 + 1.5 * t, -300.0 + 0.5 * t), (-450.0, 200.0 - 1.2 * t), (100.0 * math.cos(t / 20.0), 600.0)]


finite = st.floats(-5e3, 5e3, allow_nan=False)
"""A finite coordinate (m) or bearing for the property tests."""
