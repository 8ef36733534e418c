"""The reference UKF of ``bench manoeuvre --reference`` (bench/reference_filter.py): late bearings re-filtered
exactly, noise-free data recovers the truth, and the same numbers as Stone Soup's UKF where Stone Soup is installed."""

from __future__ import annotations

import datetime
import json
import math
import random
from pathlib import Path

import numpy as np
import pytest

from auv_swarm.agent.estimator import Bearing
from auv_swarm.bench.reference_filter import ReferenceUKF, cv_transition, filter_in_order

SIGMA = math.radians(4.5)
P0 = np.diag([50.0**2, 50.0**2, 0.5**2, 0.5**2])


def target(t: float) -> np.ndarray:
    return np.array([-300.0 + 1.2 * t, 100.0 - 0.4 * t, 1.2, -0.4])


def sensor(k: int, t: float) -> tuple[float, float]:
    a = 2.0 * math.pi * k / 3.0 + 0.002 * t
    return (400.0 * math.cos(a), 400.0 * math.sin(a))


def bearings(noise: bool, duration: float = 400.0, seed: int = 1) -> list[Bearing]:
    rng = np.random.default_rng(seed)
    out = []
    for t in np.arange(0.0, duration, 2.0):
        for k in range(3):
            s = sensor(k, t)
            x = target(t)
            b = math.atan2(x[1] - s[1], x[0] - s[0]) + (rng.uniform(-SIGMA, SIGMA) if noise else 0.0)
            out.append(Bearing(t_s=float(t), sensor_xy=s, bearing_rad=math.remainder(b, 2 * math.pi), source=k))
    return out


def test_the_transition_is_the_white_acceleration_model():
    F, Q = cv_transition(3.0, 0.01)
    assert np.array_equal(F @ target(0.0), target(3.0))
    assert Q[0, 0] == pytest.approx(0.01 * 27 / 3) and Q[0, 2] == pytest.approx(0.01 * 9 / 2)
    assert Q[2, 2] == pytest.approx(0.03) and Q[0, 1] == 0.0 and np.allclose(Q, Q.T)


def test_late_bearings_are_refiltered_as_if_they_came_in_time_order():
    """Sensor 0's bearings arrive at once, the others' one 56 s frame late, shuffled, with duplicates; at every
    tick the estimate equals the plain filter run once over the bearings held, in time order."""
    data = bearings(noise=True)
    shuffle = random.Random(3)
    ukf = ReferenceUKF(target(0.0), P0, 0.0, 1e-3, SIGMA)
    held: list[Bearing] = []
    for t in np.arange(0.0, 400.0, 2.0):
        batch = [b for b in data if b.source == 0 and b.t_s == t]
        if t % 56.0 == 0.0:
            batch += [b for b in data if b.source != 0 and t - 112.0 <= b.t_s < t - 56.0 + 1e-9]
        shuffle.shuffle(batch)
        ukf.add(batch)
        held += batch
        xi, P = ukf.estimate(float(t))
        x_ref, P_ref, t_ref = filter_in_order(held, target(0.0), P0, 0.0, 1e-3, SIGMA)
        x_ref, P_ref = ukf.predict(t_ref, x_ref, P_ref, float(t))
        assert np.allclose(xi, x_ref, rtol=0, atol=1e-9) and np.allclose(P, P_ref, rtol=1e-9, atol=1e-9)
    assert len(ukf) == len({(b.t_s, b.source) for b in held})


def test_bearings_taken_before_the_start_are_left_out():
    data = bearings(noise=True, duration=200.0)
    late = ReferenceUKF(target(100.0), P0, 100.0, 1e-3, SIGMA)
    late.add(data)
    after = ReferenceUKF(target(100.0), P0, 100.0, 1e-3, SIGMA)
    after.add([b for b in data if b.t_s >= 100.0])
    assert late.before_start == sum(b.t_s < 100.0 for b in data) > 0 and len(late) == len(after)
    assert np.array_equal(late.estimate(200.0)[0], after.estimate(200.0)[0])


def test_noise_free_bearings_recover_the_truth_from_a_wrong_start():
    ukf = ReferenceUKF(target(0.0) + np.array([60.0, -40.0, 0.5, 0.3]), P0, 0.0, 1e-4, SIGMA)
    ukf.add(bearings(noise=False))
    xi, P = ukf.estimate(400.0)
    assert np.hypot(*(xi[:2] - target(400.0)[:2])) < 1.0 and np.hypot(*(xi[2:] - target(400.0)[2:])) < 0.01
    assert np.all(np.linalg.eigvalsh(P) > 0)


def test_the_same_numbers_as_stone_soup():
    """Stone Soup's CV transition, KalmanPredictor and UnscentedKalmanUpdater (its defaults) on the same bearings.

    Its state is ordered [x, vx, y, vy], so its Cholesky factor, and with it the sigma points, differ from ours:
    the two agree to 1e-4 standard deviations (state) and 1e-4 in correlation units (covariance), not to the bit."""
    pytest.importorskip("stonesoup", reason="Stone Soup is the yardstick's yardstick; pip install stonesoup")
    from stonesoup.models.measurement.nonlinear import Cartesian2DToBearing
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.angle import Bearing as SSBearing
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import UnscentedKalmanUpdater

    q = 1e-3
    order = [0, 2, 1, 3]  # ours [x, y, vx, vy], Stone Soup's [x, vx, y, vy]
    epoch = datetime.datetime(2026, 1, 1)
    predictor = KalmanPredictor(CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)]))
    updater = UnscentedKalmanUpdater(measurement_model=None)
    state = GaussianState(target(0.0)[order].reshape(-1, 1), P0[np.ix_(order, order)], timestamp=epoch)
    ukf = ReferenceUKF(target(0.0), P0, 0.0, q, SIGMA)
    worst = worst_P = 0.0
    for b in bearings(noise=True, duration=200.0)[:240]:
        when = epoch + datetime.timedelta(seconds=b.t_s)
        model = Cartesian2DToBearing(
            ndim_state=4,
            mapping=(0, 2),
            noise_covar=np.array([[SIGMA**2 / 3]]),
            translation_offset=np.array([[b.sensor_xy[0]], [b.sensor_xy[1]]]),
        )
        detection = Detection(np.array([[SSBearing(b.bearing_rad)]]), timestamp=when, measurement_model=model)
        state = updater.update(SingleHypothesis(predictor.predict(state, timestamp=when), detection))
        ukf.add([b])
        xi, P = ukf.estimate(b.t_s)
        theirs = np.asarray(state.state_vector, dtype=float).ravel()
        worst = max(worst, float(np.max(np.abs(theirs - xi[order]) / np.sqrt(np.diag(P)[order]))))
        std = np.sqrt(np.diag(P)[order])
        worst_P = max(
            worst_P,
            float(np.max(np.abs(np.asarray(state.covar, dtype=float) - P[np.ix_(order, order)]) / np.outer(std, std))),
        )
    assert worst < 1e-4 and worst_P < 1e-4


def test_bench_manoeuvre_reference_scores_the_missions_own_samples(tmp_path, capsys):
    """``--reference`` replays a short U-turn mission: one reference error per pooled sample, for each feed."""
    from auv_swarm.bench import manoeuvre

    text = (Path(__file__).parents[2] / "contract" / "scenarios" / "manoeuvre-uturn.toml").read_text(encoding="utf-8")
    mine = tmp_path / "short.toml"
    mine.write_text(text.replace("duration_s = 1500.0", "duration_s = 300.0"), encoding="utf-8")
    run = manoeuvre.one_run(str(mine), 1, "adaptive-window", (1e-3, 1e-2))
    for q in ("0.001", "0.01"):
        for feed in ("delivered", "central"):
            e = np.asarray(run["reference"][q][feed])
            assert len(e) == len(run["errors"]) and np.all(np.isfinite(e)) and np.all(e >= 0)
    argv = [
        "--seeds",
        "1",
        "--methods",
        "adaptive-window",
        "--workers",
        "1",
        "--reference",
        "--json",
        "--scenarios",
        str(mine),
    ]
    assert manoeuvre.main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    ref = result["scenarios"][str(mine)]["adaptive-window"]["reference"]
    for feed in ("delivered", "central"):
        assert ref[feed]["best_q"] in ref[feed]["by_q"]
        assert ref[feed]["mean_m"] == min(v["mean_m"] for v in ref[feed]["by_q"].values())
    assert "UKF, delivered" in manoeuvre._table(result)
