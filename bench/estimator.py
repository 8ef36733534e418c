"""``auv-swarm bench estimator``: estimator accuracy against the Cramer-Rao bound.

Three stationary sensors 500 m from the target's position at the end of the window,
120 deg apart (the optimal geometry, random rotation per trial), one bearing per sensor
every 2 s over a 60 s window, uniform bearing noise of +/-4.5 deg. The target is either
static or moves at 0.5 m/s on a random heading. The estimate is taken at the window end.

The bound is the CRLB of the same 4-state constant-velocity model (eq. 3) with every bearing
of the window, computed with the noise's standard deviation sigma_m / sqrt(3) and propagated
to the window end with eq. (14); ``crlb_m = sqrt(mean over trials of trace(P_pos))``.

Cost of the default ``estimator.method`` per call (the target: under 1 ms median): the same three
sensors feed it one bearing each every 2 s tick for 900 s of a source at 1.2 m/s that reverses at
300 s, and every ``update`` call is timed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from typing import Any

import numpy as np

from auv_swarm.agent.estimator import Bearing, BearingEstimator, bearing_jacobian, make_estimator, transition
from auv_swarm.contract.config import EstimatorConfig
from auv_swarm.contract.rng import stream
from auv_swarm.contract.usage import plain_description
from auv_swarm.results.tracking import in_band_fraction

NOISE_DEG = 4.5
WINDOW_S = 60.0
PERIOD_S = 2.0
RANGE_M = 500.0
SPEED_MPS = 0.5
N_SENSORS = 3
TARGET_RATIO = 1.3


def _trial(rng: np.random.Generator, speed_mps: float) -> tuple[list[Bearing], np.ndarray, np.ndarray]:
    """One window of bearings; returns them, the true state at the window end and the CRLB (4x4) there."""
    heading = rng.uniform(-math.pi, math.pi)
    xi_end = np.array([0.0, 0.0, speed_mps * math.cos(heading), speed_mps * math.sin(heading)])
    phase = rng.uniform(0.0, 2.0 * math.pi)
    angles = phase + 2.0 * math.pi * np.arange(N_SENSORS) / N_SENSORS
    sensors = RANGE_M * np.column_stack((np.cos(angles), np.sin(angles)))
    times = np.arange(0.0, WINDOW_S + 1e-9, PERIOD_S)
    t = np.repeat(times, N_SENSORS)
    sx = np.tile(sensors[:, 0], times.size)
    sy = np.tile(sensors[:, 1], times.size)
    xi0 = transition(-WINDOW_S) @ xi_end
    true_bearing, _, J = bearing_jacobian(xi0, t, sx, sy)
    noise = rng.uniform(-1.0, 1.0, t.size) * math.radians(NOISE_DEG)
    bearings = [
        Bearing(
            t_s=float(t[k]),
            sensor_xy=(float(sx[k]), float(sy[k])),
            bearing_rad=float(true_bearing[k] + noise[k]),
            source=k % N_SENSORS,
        )
        for k in range(t.size)
    ]
    sigma = math.radians(NOISE_DEG) / math.sqrt(3.0)
    F = transition(WINDOW_S)
    crlb = F @ (sigma**2 * np.linalg.inv(J.T @ J)) @ F.T
    return bearings, xi_end, crlb


def _case(trials: int, seed: int, name: str, speed_mps: float) -> dict[str, Any]:
    cfg = EstimatorConfig(window_s=WINDOW_S)
    sq_pos, sq_vel, crlb_pos, crlb_vel, nees, nees_pos, wall_ms = [], [], [], [], [], [], []
    not_ok = 0
    for k in range(trials):
        bearings, truth, crlb = _trial(stream(seed, f"bench_estimator/{name}", k), speed_mps)
        est = BearingEstimator(cfg, math.radians(NOISE_DEG))
        est.add(bearings)
        t0 = time.perf_counter()
        e = est.estimate(WINDOW_S)
        wall_ms.append(1e3 * (time.perf_counter() - t0))
        crlb_pos.append(crlb[0, 0] + crlb[1, 1])
        crlb_vel.append(crlb[2, 2] + crlb[3, 3])
        if not e.ok:
            not_ok += 1
            continue
        err = e.xi - truth
        sq_pos.append(err[0] ** 2 + err[1] ** 2)
        sq_vel.append(err[2] ** 2 + err[3] ** 2)
        nees.append(float(err @ np.linalg.solve(e.reported_P, err)))
        nees_pos.append(float(err[:2] @ np.linalg.solve(e.reported_P[:2, :2], err[:2])))
    rmse = math.sqrt(float(np.mean(sq_pos))) if sq_pos else math.inf
    crlb_m = math.sqrt(float(np.mean(crlb_pos)))
    return {
        "trials": trials,
        "not_ok": not_ok,
        "rmse_m": rmse,
        "crlb_m": crlb_m,
        "rmse_over_crlb": rmse / crlb_m,
        "velocity_rmse_mps": math.sqrt(float(np.mean(sq_vel))) if sq_vel else math.inf,
        "velocity_crlb_mps": math.sqrt(float(np.mean(crlb_vel))),
        "mean_nees": float(np.mean(nees)) if nees else math.inf,
        "nees_mean": float(np.mean(nees_pos)) if nees_pos else math.inf,
        "nees_in_band_fraction": in_band_fraction(nees_pos) if nees_pos else 0.0,
        "estimate_ms_median": float(np.median(wall_ms)),
        "estimate_ms_max": float(np.max(wall_ms)),
        "target_speed_mps": speed_mps,
    }


STREAM_S = 900.0
TARGET_MS = 1.0


def _reversing_stream(seed: int) -> dict[str, Any]:
    """The default method on a 900 s stream of three sensors (a reversing source): time per ``update`` call (ms),
    and, after 200 s, its position error and position NEES (reported covariance) beside ``wls-cv``'s on the same
    bearings."""
    rng = stream(seed, "bench_estimator/stream")
    cfg = EstimatorConfig()
    est = make_estimator(cfg, math.radians(NOISE_DEG))
    fixed = make_estimator(dataclasses.replace(cfg, method="wls-cv"), math.radians(NOISE_DEG))
    sensors = RANGE_M * np.array([[1.0, 0.0], [-0.5, 0.866], [-0.5, -0.866]])
    wall_ms = []
    samples: dict[str, tuple[list[float], list[float]]] = {"default": ([], []), "wls-cv": ([], [])}
    for t in np.arange(0.0, STREAM_S + 1e-9, PERIOD_S):
        x = -360.0 + 1.2 * t if t <= 300.0 else -1.2 * (t - 300.0)  # reverses in place at 300 s
        y = 0.0 if t <= 300.0 else 80.0
        batch = [
            Bearing(
                float(t),
                (float(sx), float(sy)),
                math.atan2(y - sy, x - sx) + rng.uniform(-1, 1) * math.radians(NOISE_DEG),
                i,
            )
            for i, (sx, sy) in enumerate(sensors)
        ]
        t0 = time.perf_counter()
        e = est.update(batch, float(t))
        wall_ms.append(1e3 * (time.perf_counter() - t0))
        for name, out in (("default", e), ("wls-cv", fixed.update(batch, float(t)))):
            if out.ok and t >= 200.0:
                err = out.xi[:2] - np.array([x, y])
                samples[name][0].append(float(np.hypot(*err)))
                samples[name][1].append(float(err @ np.linalg.solve(out.reported_P[:2, :2], err)))

    def figures(name: str) -> dict[str, float]:
        errors, nees = (np.array(v) for v in samples[name])
        return {
            "error_mean_m": float(errors.mean()),
            "nees_mean": float(nees.mean()),
            "nees_in_band_fraction": in_band_fraction(nees),
        }

    return {
        "method": cfg.method,
        "calls": len(wall_ms),
        "ms_median": float(np.median(wall_ms)),
        "ms_p95": float(np.percentile(wall_ms, 95)),
        "target_ms": TARGET_MS,
        **figures("default"),
        "wls_cv": figures("wls-cv"),
    }


def run(trials: int = 200, seed: int = 0) -> dict[str, Any]:
    """Run ``trials`` seeded trials of a static and of a constant-velocity target; returns the figures.

    One untimed estimate runs first so that library warm-up does not count in the timings.
    """
    if trials < 1:
        raise ValueError(f"trials must be >= 1, got {trials}")
    warm_up, _, _ = _trial(stream(seed, "bench_estimator/warm_up"), 0.0)
    est = BearingEstimator(EstimatorConfig(window_s=WINDOW_S), math.radians(NOISE_DEG))
    est.add(warm_up)
    est.estimate(WINDOW_S)
    static = _case(trials, seed, "static", 0.0)
    moving = _case(trials, seed, "constant_velocity", SPEED_MPS)
    return {
        "default_method_cost": _reversing_stream(seed),
        "static": static,
        "constant_velocity": moving,
        "noise_deg": NOISE_DEG,
        "window_s": WINDOW_S,
        "period_s": PERIOD_S,
        "sensors": N_SENSORS,
        "range_m": RANGE_M,
        "seed": seed,
        "target_ratio": TARGET_RATIO,
        "meets_target": bool(static["rmse_over_crlb"] <= TARGET_RATIO and moving["rmse_over_crlb"] <= TARGET_RATIO),
    }


def _table(result: dict[str, Any]) -> str:
    head = (
        f"estimator bench: {result['sensors']} sensors at {result['range_m']:g} m, 120 deg apart; "
        f"+/-{result['noise_deg']:g} deg uniform noise; one bearing per sensor every {result['period_s']:g} s; "
        f"{result['window_s']:g} s window; seed {result['seed']}"
    )
    cols = f"{'target':<18}{'trials':>7}{'not ok':>7}{'RMSE m':>9}{'CRLB m':>9}{'ratio':>7}{'v RMSE':>8}{'v CRLB':>8}{'NEES':>6}{'pNEES':>7}{'band':>6}{'ms med':>8}{'ms max':>8}"
    lines = [head, "", cols]
    for name in ("static", "constant_velocity"):
        r = result[name]
        lines.append(
            f"{name:<18}{r['trials']:>7}{r['not_ok']:>7}{r['rmse_m']:>9.2f}{r['crlb_m']:>9.2f}{r['rmse_over_crlb']:>7.3f}"
            f"{r['velocity_rmse_mps']:>8.3f}{r['velocity_crlb_mps']:>8.3f}{r['mean_nees']:>6.2f}{r['nees_mean']:>7.2f}{100 * r['nees_in_band_fraction']:>5.0f}%"
            f"{r['estimate_ms_median']:>8.2f}{r['estimate_ms_max']:>8.2f}"
        )
    verdict = "meets" if result["meets_target"] else "MISSES"
    lines += [
        "",
        f"position RMSE / CRLB {verdict} the target <= {result['target_ratio']:g} (NEES of a consistent estimator: 4; "
        "pNEES: position NEES, 2 if consistent; band: fraction in the 95 % chi2_2 band [0.05, 7.38])",
    ]
    c = result["default_method_cost"]
    verdict = "meets" if c["ms_median"] < c["target_ms"] else "MISSES"
    lines.append(
        f"default method {c['method']!r}, {c['calls']} calls on a {STREAM_S:g} s stream of three sensors "
        f"(a source that reverses): {c['ms_median']:.2f} ms median, {c['ms_p95']:.2f} ms p95 per call; "
        f"{verdict} the target < {c['target_ms']:g} ms median; after 200 s: error {c['error_mean_m']:.1f} m mean, "
        f"pNEES {c['nees_mean']:.2f}, {100 * c['nees_in_band_fraction']:.0f}% in band "
        f"(wls-cv on the same bearings: {c['wls_cv']['error_mean_m']:.1f} m, pNEES {c['wls_cv']['nees_mean']:.1f}, "
        f"{100 * c['wls_cv']['nees_in_band_fraction']:.0f}% in band)"
    )
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """``auv-swarm bench estimator [--json] [--trials N] [--seed S]``."""
    parser = argparse.ArgumentParser(prog="auv-swarm bench estimator", description=plain_description(__doc__))
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--trials", type=int, default=200, help="seeded trials per target type (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    args = parser.parse_args(argv)
    if args.trials < 1:
        parser.error(f"--trials must be >= 1, got {args.trials}")
    if args.seed < 0:
        parser.error(f"--seed must be >= 0, got {args.seed}")
    result = run(trials=args.trials, seed=args.seed)
    print(json.dumps(result) if args.json else _table(result))
    return 0
