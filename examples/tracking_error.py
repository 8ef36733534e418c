"""Run one mission in process and plot every AUV's tracking error against time.

    python examples/tracking_error.py [--scenario paper-3.2-challenging] [--seed 1] [--duration S] [--png FILE]

The same mission as ``auv-swarm run --mode inprocess``; nothing is written but the PNG.
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import auv_swarm  # noqa: E402
from auv_swarm.results.metrics import tracking_errors  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper-3.2-challenging", help="built-in name or TOML path")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=None, help="sim seconds (default: the scenario's)")
    parser.add_argument("--png", default="tracking_error.png")
    args = parser.parse_args(argv)

    scenario = auv_swarm.load_scenario(args.scenario).with_overrides(seed=args.seed, duration_s=args.duration)
    result = auv_swarm.run_mission(scenario)  # mode="inprocess" by default
    record, metrics = result.record, result.metrics

    fig, ax = plt.subplots(figsize=(8, 4))
    for auv, error in tracking_errors(record).items():  # NaN where dead or without an estimate
        ax.plot(record.times, error, lw=1, label=f"AUV {auv}")
    ax.axhline(15.0, color="red", ls="--", lw=1, label="15 m")
    ax.set(xlabel="sim time (s)", ylabel="tracking error (m)", title=f"{scenario.name}, seed {args.seed}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.png, dpi=100)

    print(f"{metrics['ticks']} ticks, complete: {metrics['complete']}")
    print(f"tracking error {metrics['tracking_error_mean_m']:.1f} m mean, p95 {metrics['tracking_error_p95_m']:.1f} m")
    print(f"wrote {args.png}")
    return result.exit_code


if __name__ == "__main__":
    raise SystemExit(main())
