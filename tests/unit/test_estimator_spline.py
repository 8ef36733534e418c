"""The manoeuvring-track model (agent/estimator/spline.py) against its readable reference (agent/estimator/reference.py).

Both minimise the same posterior cost from the same start; the fast path stops once a step would lower
the cost by less than 1e-4 (about 0.01 standard deviations from the optimum), the reference iterates to
convergence, so the state must agree within 0.05 standard deviations and the covariance within 5 %.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from auv_swarm.agent.estimator import Bearing
from auv_swarm.agent.estimator.reference import reference_track_fit
from auv_swarm.agent.estimator.spline import SplineFit, Track, design, knot_grid


def truth(t: float, speed: float, heading: float, turn_at: float, rate: float) -> np.ndarray:
    """Position (m) of a source on a straight course that turns at ``rate`` (rad/s) from ``turn_at`` (s) on."""
    if t <= turn_at or rate == 0.0:
        return np.array([speed * t * math.cos(heading), speed * t * math.sin(heading)])
    p0 = truth(turn_at, speed, heading, turn_at, 0.0)
    h = heading + rate * (t - turn_at)
    return p0 + speed / rate * np.array([math.sin(h) - math.sin(heading), -math.cos(h) + math.cos(heading)])


@st.composite
def tracks(draw):
    """Bearings of a turning source from 3-4 sensors around it over 200-300 s, uniform noise."""
    sigma_m = math.radians(draw(st.floats(1.0, 6.0)))
    speed, heading = draw(st.floats(0.0, 1.5)), draw(st.floats(-math.pi, math.pi))
    turn_at, rate = draw(st.floats(50.0, 250.0)), draw(st.sampled_from([0.0, 0.01, -0.03]))
    span = draw(st.sampled_from([200.0, 300.0]))
    t_first = draw(st.floats(0.0, 100.0))
    n_sensors = draw(st.integers(3, 4))  # two sensors 180 deg apart would be collinear with the source
    phase = draw(st.floats(0.0, 2 * math.pi))
    sensors = [
        (draw(st.floats(300.0, 900.0)), phase + 2 * math.pi * i / n_sensors + draw(st.floats(-0.3, 0.3)))
        for i in range(n_sensors)
    ]
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    out = []
    for t in np.arange(t_first, t_first + span + 1e-9, 2.0):
        p = truth(t, speed, heading, turn_at, rate)
        for i, (r, a) in enumerate(sensors):
            xs, ys = r * math.cos(a), r * math.sin(a)
            b = math.atan2(p[1] - ys, p[0] - xs) + rng.uniform(-sigma_m, sigma_m)
            out.append(Bearing(float(t), (xs, ys), float(b), i))
    t_now = t_first + span
    p, p_prev = truth(t_now, speed, heading, turn_at, rate), truth(t_now - 1.0, speed, heading, turn_at, rate)
    return out, t_now, sigma_m, np.array([*p, *(p - p_prev)])


def columns(bearings: list[Bearing]) -> np.ndarray:
    return np.array([[b.t_s, *b.sensor_xy, b.bearing_rad] for b in bearings]).T


def _case_from_file(name: str):
    """A property-test case kept as a file: bearing rows (t, sensor x, y, bearing, sensor), t_now, sigma, truth."""
    data = np.load(Path(__file__).parent / "data" / name)
    bearings = [Bearing(float(t), (float(x), float(y)), float(b), int(i)) for t, x, y, b, i in data["bearings"]]
    return bearings, float(data["t_now"]), float(data["sigma_m"]), np.asarray(data["xi_true"], dtype=float)


@settings(max_examples=30, deadline=None)
@given(tracks())
# Found by CI: a still source watched from four sides, whose cross-covariances of x and y (2e-4 against variances
# of 1.2 and 1.8) differed by 5.2 % of themselves, though by 1e-5 of the variances' scale.
@example(_case_from_file("spline_near_zero_cross_covariance.npz"))
def test_fast_fit_equals_the_reference(case):
    bearings, t_now, sigma_m, xi_true = case
    knot_s, q = 30.0, 3e-3
    fit = SplineFit(sigma_m / math.sqrt(3.0), knot_s, q, 100.0, 1e6, 1e3, 6)
    for _ in range(3):  # as in the agent, each call continues from the last fit (4 Gauss-Newton steps at most)
        est = fit.fit(columns(bearings), t_now, xi_true, t_now)
    assume(est.ok and est.n_rejected == 0)
    knots = knot_grid(bearings[0].t_s, t_now, knot_s)
    start = xi_true[:2] + np.outer(knots * knot_s - t_now, xi_true[2:])
    xi, P = reference_track_fit(bearings, t_now, knot_s, q, sigma_m, start)
    std = np.sqrt(np.diag(P))
    assert np.all(np.abs(est.xi - xi) <= 0.05 * std + 1e-6), (est.xi, xi, std)
    # Equal within 5 % of each entry's scale sqrt(P_ii P_jj): the variances within 5 %, the correlations within 0.05
    # (an entry near zero is not held to 5 % of itself).
    scale = np.sqrt(np.outer(np.diag(P), np.diag(P)))
    assert np.all(np.abs(est.P - P) <= 0.05 * scale), (est.P, P)


def test_normal_equations_equal_the_dense_jacobian():
    rng = np.random.default_rng(0)
    m = 400
    t = np.sort(rng.uniform(0.0, 300.0, m))
    sx, sy, b = rng.uniform(-500, 500, m), rng.uniform(-500, 500, m), rng.uniform(-3, 3, m)
    knots = knot_grid(float(t[0]), 300.0, 30.0)
    n = knots.size
    track = Track(*design(t, knots, 30.0), sx, sy, b, n)
    flat = rng.normal(0.0, 100.0, 2 * n)
    res, gx, gy = track.residuals(flat)
    w = rng.uniform(0.0, 2.0, m)
    H, g = track.normal(res, gx, gy, w)
    J = np.zeros((m, 2 * n))
    j, a, rows = track.j, track.a, np.arange(m)
    J[rows, 2 * j], J[rows, 2 * j + 1] = (1 - a) * gx, (1 - a) * gy
    J[rows, 2 * j + 2], J[rows, 2 * j + 3] = a * gx, a * gy
    np.testing.assert_allclose(H, (J.T * w) @ J, rtol=1e-12, atol=1e-15 * np.abs(H).max())
    np.testing.assert_allclose(g, (J.T * w) @ res, rtol=1e-12, atol=1e-15 * np.abs(g).max())


def test_noise_free_straight_track_is_recovered_exactly():
    xi_true = np.array([120.0, -40.0, 0.6, -0.3])
    sensors = [(600.0, 0.0), (-300.0, 520.0), (-300.0, -520.0)]
    bearings = []
    for t in np.arange(0.0, 300.0 + 1e-9, 2.0):
        p = xi_true[:2] + (t - 300.0) * xi_true[2:]
        bearings += [Bearing(float(t), s, math.atan2(p[1] - s[1], p[0] - s[0]), i) for i, s in enumerate(sensors)]
    fit = SplineFit(math.radians(4.5) / math.sqrt(3.0), 30.0, 3e-3, math.radians(13.5), 100.0, 5.0, 6)
    est = fit.fit(columns(bearings), 300.0, xi_true + np.array([30.0, -20.0, 0.2, 0.1]), 300.0)
    assert est.ok
    np.testing.assert_allclose(est.xi, xi_true, atol=1e-2)  # the fit stops within ~0.01 std


def test_too_few_bearings_give_a_finite_not_ok_estimate():
    fit = SplineFit(0.05, 30.0, 3e-3, 0.2, 100.0, 5.0, 6)
    est = fit.fit(np.zeros((4, 3)), 10.0, np.zeros(4), 10.0)
    assert not est.ok and np.isfinite(est.xi).all() and np.isfinite(est.P).all()
