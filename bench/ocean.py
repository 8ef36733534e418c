"""``auv-swarm bench ocean [--scenario NAME] [--repeats N] [--json]``: what the physical ocean costs.

Runs one physical scenario in process (seed 1) and the same scenario with ``ocean.model = "paper"`` (every
``[ocean]`` key at its default), each ``--repeats`` times, and reports the median wall times, their ratio
(target: at most 1.25 with a cached table), the ocean's share of the physical mission's wall time (time inside
the link and sensor models: SNR lookups, delivery, detection, the planner's link weights) and, with the
[bellhop] extra, the wall time of building the scenario's table with Bellhop (target: at most 30 s). The two
missions differ in what the AUVs hear and do, so the ratio measures the whole mission, not only the lookups.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import statistics
import time

from auv_swarm.contract import detection, modem
from auv_swarm.contract.config import ConfigError, OceanConfig, load_scenario
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission.api import run_mission

DEFAULT = "ocean-coastal-summer"
TIMED = (
    (modem.LinkModel, ("snr_db", "delivery", "weight", "weight_bound")),
    (detection.SensorModel, ("snr_db", "sighting")),
)
"""The ocean's methods whose time counts as the ocean's share."""


class _Clock:
    """Wall time spent inside the :data:`TIMED` methods while installed (the outermost call counts)."""

    def __init__(self) -> None:
        self.total_s = 0.0
        self._depth = 0
        self._saved: list[tuple[type, str, object]] = []

    def __enter__(self) -> _Clock:
        for cls, names in TIMED:
            for name in names:
                original = getattr(cls, name)
                self._saved.append((cls, name, original))
                setattr(cls, name, self._wrap(original))
        return self

    def __exit__(self, *exc: object) -> None:
        for cls, name, original in self._saved:
            setattr(cls, name, original)

    def _wrap(self, fn):
        @functools.wraps(fn)
        def timed(*args, **kwargs):
            self._depth += 1
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self._depth -= 1
                if self._depth == 0:
                    self.total_s += time.perf_counter() - start

        return timed


def measure(scenario_name: str, repeats: int) -> dict:
    """The bench's numbers (see the module docstring)."""
    physical = load_scenario(scenario_name).with_overrides(seed=1)
    if physical.ocean.model != "physical":
        raise ConfigError(f"scenario {scenario_name!r} is not physical (ocean.model = 'paper')")
    paper = dataclasses.replace(physical, ocean=OceanConfig())
    run_mission(physical)  # a warm-up: imports, the planner's merge graph, the table read once
    walls: dict[str, list[float]] = {"paper": [], "physical": []}
    shares = []
    for _ in range(repeats):
        walls["paper"].append(run_mission(paper).wall_s)
        with _Clock() as clock:
            wall = run_mission(physical).wall_s
        walls["physical"].append(wall)
        shares.append(clock.total_s / wall)
    med = {k: statistics.median(v) for k, v in walls.items()}
    out = {
        "scenario": scenario_name,
        "repeats": repeats,
        "paper_wall_s": med["paper"],
        "physical_wall_s": med["physical"],
        "ratio": med["physical"] / med["paper"],
        "ratio_target": 1.25,
        "ocean_share_of_wall": statistics.median(shares),
        "bellhop_build_s": None,
        "bellhop_target_s": 30.0,
    }
    from auv_swarm.orchestrator.mission import solvers, tables

    if solvers.available():
        _, out["bellhop_build_s"] = tables.build_table(physical.with_keys({"ocean.propagation": "bellhop"}))
    return out


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="auv-swarm bench ocean", description=plain_description(__doc__))
    parser.add_argument("--scenario", default=DEFAULT, help=f"a physical scenario (default {DEFAULT})")
    parser.add_argument("--repeats", type=int, default=3, help="missions per model; the median is reported")
    parser.add_argument("--json", action="store_true", help="print the numbers as JSON")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        return fail(f"--repeats must be >= 1, got {args.repeats}")
    try:
        out = measure(args.scenario, args.repeats)
    except ConfigError as exc:
        return fail(str(exc))
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{out['scenario']}, seed 1, median of {out['repeats']} in-process missions:")
    print(f"  paper    {out['paper_wall_s']:.2f} s")
    print(f"  physical {out['physical_wall_s']:.2f} s   ratio {out['ratio']:.2f} (target <= 1.25)")
    print(f"  the ocean's share of the physical mission's wall time: {100 * out['ocean_share_of_wall']:.1f} %")
    if out["bellhop_build_s"] is None:
        print("  Bellhop table build: not measured (pelagic, the [bellhop] extra, is not installed)")
    else:
        print(f"  Bellhop table build: {out['bellhop_build_s']:.1f} s (target <= 30 s)")
    return 0
