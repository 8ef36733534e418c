"""Your own estimator beside the default: register it by name, run both on the same seeds, compare.

    python examples/own_estimator.py [--scenario paper-3.2-challenging] [--seeds A-B|N] [--duration S]

``Triangulate`` is a deliberately simple estimator: the least-squares intersection of the bearing lines
of the last ``window_s`` seconds (a static source, eqs. 6-9 without the velocity columns). Registered as
``estimator.method = "triangulate"``, every AUV of an in-process mission runs it instead of the default.
The NEES is counted after the team's convergence (docs/results.md): a mission that never converges has none.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

import auv_swarm
from auv_swarm.agent import estimator
from auv_swarm.agent.estimator import Bearing, Estimate, not_ok
from auv_swarm.contract.usage import SEEDS_HELP, parse_seeds


class Triangulate:
    """Least-squares intersection of recent bearing lines; velocity zero with a wide variance."""

    def __init__(self, cfg, sigma_m_rad: float) -> None:  # cfg: the scenario's EstimatorConfig
        self.window_s = min(cfg.window_s, 300.0)
        self.sigma_m_rad = sigma_m_rad
        self.held: list[Bearing] = []

    def __len__(self) -> int:
        return len(self.held)

    def update(self, bearings, t_s: float) -> Estimate:
        self.held = [b for b in [*self.held, *bearings] if t_s - b.t_s <= self.window_s]
        if len(self.held) < 4:
            return not_ok(t_s, "too few bearings", n_used=len(self.held))
        b = np.array([m.bearing_rad for m in self.held])
        xy = np.array([m.sensor_xy for m in self.held])
        A = np.column_stack([np.sin(b), -np.cos(b)])  # each row: the normal of a bearing line
        z = np.sin(b) * xy[:, 0] - np.cos(b) * xy[:, 1]
        position, *_ = np.linalg.lstsq(A, z, rcond=None)
        if np.linalg.cond(A) > 1e6:  # the lines are (nearly) parallel: no fix
            return not_ok(t_s, "bearing lines nearly parallel", n_used=len(self.held))
        r = np.median(np.hypot(*(position - xy).T))  # typical range: the lines' cross-range noise is r * sigma
        cov = np.linalg.inv(A.T @ A) * (r * self.sigma_m_rad) ** 2 / 3.0
        P = np.diag([cov[0, 0], cov[1, 1], 1.0, 1.0])
        P[0, 1] = P[1, 0] = cov[0, 1]
        xi = np.array([position[0], position[1], 0.0, 0.0])
        return Estimate(True, "triangulated", t_s, xi, P, len(self.held), 0, float(np.linalg.cond(A)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper-3.2-challenging")
    parser.add_argument("--seeds", default="1-2", help=f"{SEEDS_HELP} (default 1-2)")
    parser.add_argument("--duration", type=float, default=None, help="sim seconds (default: the scenario's)")
    args = parser.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        parser.error(str(exc))

    estimator.register("triangulate", Triangulate)  # estimator.method = "triangulate" is now valid here
    base = auv_swarm.load_scenario(args.scenario).with_overrides(duration_s=args.duration)
    print(f"{base.name}: mean / p95 tracking error (m), NEES in band after convergence")
    for seed in seeds:
        for method in ("adaptive-window", "triangulate"):
            m = auv_swarm.run_mission(base.with_keys({"estimator.method": method, "run.seed": seed})).metrics
            mean, p95, band = m["tracking_error_mean_m"], m["tracking_error_p95_m"], m["nees_in_band_fraction"]
            text = "no estimate" if mean is None else f"{mean:6.1f} / {p95:6.1f}"
            if band is None or math.isnan(band):  # the NEES counts after convergence only
                band_text = "- (never converged)" if m["convergence_time_s"] is None else "- (no NEES sample)"
            else:
                band_text = f"{100 * band:.0f} %"
            print(f"seed {seed}  {method:<16} {text}   {band_text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
