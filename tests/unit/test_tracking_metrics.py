"""Lost-track and covariance-honesty metrics (results/tracking.py) on hand-made series."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auv_swarm.results.tracking import NEES_BAND, position_nees, runs_over, tracking_metrics


def test_nees_band_is_the_two_sided_95_percent_chi2_2_band():
    assert NEES_BAND[0] == pytest.approx(-2.0 * math.log(0.975), abs=1e-4)
    assert NEES_BAND[1] == pytest.approx(-2.0 * math.log(0.025), abs=1e-3)


def test_position_nees_of_a_diagonal_covariance():
    err = np.array([[3.0, 4.0], [1.0, 0.0]])
    cov = np.array([[9.0, 0.0, 16.0], [0.0, 0.0, 1.0]])  # the second is singular
    nees = position_nees(err, cov)
    assert nees[0] == pytest.approx(2.0)
    assert math.isnan(nees[1])


def test_nees_of_consistent_gaussian_errors_is_about_two_and_95_percent_in_band():
    rng = np.random.default_rng(0)
    L = np.array([[10.0, 0.0], [6.0, 4.0]])
    P = L @ L.T
    err = rng.normal(size=(20000, 2)) @ L.T
    nees = position_nees(err, np.tile([P[0, 0], P[0, 1], P[1, 1]], (20000, 1)))
    assert np.mean(nees) == pytest.approx(2.0, rel=0.03)
    assert np.mean((nees >= NEES_BAND[0]) & (nees <= NEES_BAND[1])) == pytest.approx(0.95, abs=0.01)


def test_runs_over_counts_isolated_ticks_and_runs_to_the_end():
    times = np.arange(10.0) * 2.0
    over = np.array([1, 0, 1, 1, 1, 0, 0, 1, 1, 1], dtype=bool)
    assert runs_over(times, over, 2.0) == [2.0, 6.0, 6.0]


def test_tracking_metrics_after_convergence():
    times = np.arange(0.0, 400.0, 2.0)
    e0 = np.full(times.size, 5.0)
    e0[(times >= 100) & (times < 180)] = 80.0  # 80 s above 50 m: one lost track, an 80 s excursion
    e1 = np.full(times.size, 5.0)
    e1[times == 300.0] = np.nan  # no estimate for one tick: counts as over 15 m
    alive = {0: np.ones(times.size, bool), 1: np.ones(times.size, bool)}
    nees = {0: np.full(times.size, 2.0), 1: np.full(times.size, 10.0)}
    team, per = tracking_metrics(times, {0: e0, 1: e1}, alive, nees, 50.0, 2.0)
    after = np.sum(times >= 50.0)
    assert team["under_15m_after_convergence_fraction"] == pytest.approx((2 * after - 40 - 1) / (2 * after))
    assert team["longest_excursion_s"] == 80.0
    assert per[0]["track_lost"] == 1 and per[1]["track_lost"] == 0
    assert per[1]["longest_excursion_s"] == 2.0
    assert team["nees_in_band_fraction"] == pytest.approx(0.5, abs=0.01)
    assert team["tracking_error_p95_m"] == pytest.approx(np.percentile(np.r_[e0, e1[np.isfinite(e1)]], 95))


def test_tracking_metrics_without_convergence_are_none():
    times = np.arange(0.0, 10.0, 2.0)
    team, per = tracking_metrics(times, {0: np.full(5, 99.0)}, {0: np.ones(5, bool)}, {0: np.ones(5)}, None, 2.0)
    assert team["under_15m_after_convergence_fraction"] is None and per[0]["track_lost"] is None
    assert team["tracking_error_p95_m"] == 99.0
