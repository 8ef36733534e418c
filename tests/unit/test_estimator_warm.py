"""The estimator's warm path: each estimate starts from the last one, and matches a cold solve of the same window."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from auv_swarm.agent.estimator import Bearing, BearingEstimator, Estimate, transition
from tests.unit.estimator_cases import SIGMA_M, estimator, finite, make_bearings, moving_sensors, triangle


def stream(sensors, target0, times, noise_rad=0.0, seed=0):
    """Bearings grouped by tick: a list of (t, [Bearing, ...]) for ``make_bearings``'s geometry."""
    bearings, _ = make_bearings(
        sensors, target0, times=times, noise_rad=noise_rad, rng=np.random.default_rng(seed) if noise_rad else None
    )
    ticks: dict[float, list[Bearing]] = {}
    for b in bearings:
        ticks.setdefault(b.t_s, []).append(b)
    return sorted(ticks.items())


def cold_estimate(est: BearingEstimator, t_now: float, **cfg) -> Estimate:
    """What a fresh estimator (full robust path) gives on ``est``'s current window."""
    fresh = estimator(**cfg)
    fresh.add(est.window())
    e = fresh.estimate(t_now)
    assert fresh.warm_starts == 0
    return e


STREAM_TIMES = np.arange(0.0, 240.0 + 1e-9, 2.0)


def test_warm_path_matches_cold_on_noise_free_stream():
    target0 = (-40.0, 25.0, 0.4, -0.3)
    est = estimator(window_s=60.0)
    for t, batch in stream(moving_sensors, target0, STREAM_TIMES):
        est.add(batch)
        e = est.estimate(t)
        if t < 20.0:
            continue
        assert e.ok, e.reason
        np.testing.assert_allclose(e.xi, transition(t) @ np.array(target0), atol=1e-6)
        cold = cold_estimate(est, t, window_s=60.0)
        np.testing.assert_allclose(e.xi, cold.xi, atol=1e-6)
        np.testing.assert_allclose(e.P, cold.P, rtol=1e-6, atol=1e-9)
        assert (e.n_used, e.n_rejected) == (cold.n_used, cold.n_rejected)
    assert est.warm_starts >= len(STREAM_TIMES) - 15


def test_warm_path_stays_within_a_small_fraction_of_a_std_of_cold_on_noisy_stream():
    target0 = (20.0, -10.0, 0.3, 0.4)
    est = estimator(window_s=120.0)
    for t, batch in stream(triangle(), target0, STREAM_TIMES, noise_rad=SIGMA_M, seed=4):
        est.add(batch)
        e = est.estimate(t)
        if t < 20.0:
            continue
        cold = cold_estimate(est, t, window_s=120.0)
        assert e.ok and cold.ok
        std = np.sqrt(np.diag(cold.P))
        assert np.all(np.abs(e.xi - cold.xi) <= 0.05 * std)
        np.testing.assert_allclose(e.P, cold.P, rtol=0.02)
    assert est.warm_starts >= len(STREAM_TIMES) - 15


def test_outlier_appearing_mid_stream_is_rejected_by_the_warm_path():
    target0 = (20.0, -10.0, 0.3, 0.4)
    est = estimator(window_s=120.0)
    for t, batch in stream(triangle(), target0, STREAM_TIMES, noise_rad=SIGMA_M, seed=5):
        if t == 150.0:
            b = batch[1]
            batch = [*batch[:1], dataclasses.replace(b, bearing_rad=b.bearing_rad + 2.0), *batch[2:]]
        est.add(batch)
        warm_before = est.warm_starts
        e = est.estimate(t)
        if t >= 150.0:
            assert est.warm_starts == warm_before + 1
            assert e.ok and e.n_rejected == 1
            truth = transition(t) @ np.array(target0)
            assert np.hypot(*(e.xi[:2] - truth[:2])) < 4.0 * math.sqrt(e.P[0, 0] + e.P[1, 1])
            cold = cold_estimate(est, t, window_s=120.0)
            assert cold.n_rejected == 1
            assert np.all(np.abs(e.xi - cold.xi) <= 0.05 * np.sqrt(np.diag(cold.P)))


def test_window_that_jumps_after_a_long_gap_falls_back_to_cold():
    target0 = (20.0, -10.0, 0.3, 0.4)
    ticks = stream(triangle(), target0, STREAM_TIMES, noise_rad=SIGMA_M, seed=6)
    est = estimator(window_s=60.0)
    for t, batch in ticks:
        if 100.0 < t < 130.0:
            continue
        est.add(batch)
        warm_before, cold_before = est.warm_starts, est.cold_solves
        e = est.estimate(t)
        if t == 130.0:
            assert (est.warm_starts, est.cold_solves) == (warm_before, cold_before + 1)
            cold = cold_estimate(est, t, window_s=60.0)
            assert e.xi.tobytes() == cold.xi.tobytes() and e.P.tobytes() == cold.P.tobytes()
        elif t == 132.0:
            assert est.warm_starts == warm_before + 1


def test_no_warm_start_without_gauss_newton():
    target0 = (20.0, -10.0, 0.3, 0.4)
    est = estimator(window_s=60.0, gauss_newton_iters=0)
    for t, batch in stream(triangle(), target0, STREAM_TIMES[:60], noise_rad=SIGMA_M, seed=7):
        est.add(batch)
        e = est.estimate(t)
        cold = cold_estimate(est, t, window_s=60.0, gauss_newton_iters=0)
        assert e.xi.tobytes() == cold.xi.tobytes()
    assert est.warm_starts == 0


def test_stream_is_deterministic_and_independent_of_arrival_order():
    ticks = stream(moving_sensors, (10.0, 5.0, -0.2, 0.3), STREAM_TIMES, noise_rad=SIGMA_M, seed=8)
    held: list[Bearing] = []
    for k, (_, batch) in enumerate(ticks):
        held += [b for b in batch if b.source == 2]
        batch[:] = [b for b in batch if b.source != 2]
        if k % 7 == 6:
            batch += held
            held = []
    runs = []
    for k in range(4):
        rng = np.random.default_rng(k)
        est = estimator(window_s=90.0)
        out = []
        for t, batch in ticks:
            if k >= 2:
                batch = [batch[i] for i in rng.permutation(len(batch))]
            for chunk in np.array_split(np.arange(len(batch)), 3 if k == 3 else 1):
                est.add([batch[i] for i in chunk])
            e = est.estimate(t)
            out.append((e.ok, e.xi.tobytes(), e.P.tobytes(), e.n_used, e.n_rejected, e.condition))
        runs.append((out, est.warm_starts))
    assert runs[0][1] > len(ticks) // 2
    assert runs[1] == runs[0] and runs[2] == runs[0] and runs[3] == runs[0]


@settings(max_examples=40, deadline=None)
@given(
    ticks=st.lists(
        st.tuples(
            st.floats(0.0, 20.0),
            st.lists(st.tuples(finite, finite, st.floats(-10.0, 10.0), st.integers(0, 3)), max_size=6),
        ),
        max_size=25,
    )
)
def test_arbitrary_streams_never_raise_or_return_nan(ticks):
    est = estimator(window_s=30.0)
    t = 0.0
    for step, rows in ticks:
        t += step
        est.add(Bearing(t, (x, y), b, s) for x, y, b, s in rows)
        e = est.estimate(t)
        assert np.all(np.isfinite(e.xi)) and np.all(np.isfinite(e.P))
        assert e.ok or e.reason
        assert not math.isnan(e.condition)
