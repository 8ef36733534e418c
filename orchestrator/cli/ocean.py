"""Show what a physical scenario's ocean does: the sound-speed profile, the TL field, SNR and delivery and
detection probability against range (named figures), and the ranges at which delivery and detection fall to
0.5. KEY=VALUE arguments override scenario keys as a sweep axis does (ocean.wind_mps=20). With
ocean.propagation = bellhop the TL table is built (the [bellhop] extra) and cached, so that processes started
by hand find it; --table-out writes the table as a .npz file (docs/ocean.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from auv_swarm.contract.config import ConfigError, load_scenario
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.sweep.grid import parse_value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="auv-swarm ocean", description=plain_description(__doc__))
    parser.add_argument("scenario", help="built-in scenario name or TOML path (ocean.model = physical)")
    parser.add_argument("keys", nargs="*", metavar="KEY=VALUE", help="scenario keys to override")
    parser.add_argument("--out", type=Path, default=None, help="figure folder (default ocean/<scenario>/)")
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object, nothing else")
    parser.add_argument("--table-out", type=Path, default=None, help="also write the scenario's TL table (.npz) there")
    return parser


def overrides(items: list[str]) -> dict[str, object]:
    """``KEY=VALUE`` arguments as dotted keys and values (TOML scalars, else strings); ConfigError if malformed."""
    keys: dict[str, object] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise ConfigError(f"argument {item!r}: expected KEY=VALUE (e.g. ocean.wind_mps=20)")
        keys[key.strip()] = parse_value(value.strip())
    return keys


def main(argv: list[str]) -> int:
    from auv_swarm.orchestrator.mission import ocean_report, tables

    args = build_parser().parse_args(argv)
    try:
        scenario = load_scenario(args.scenario)
        scenario = scenario.with_keys(overrides(args.keys)) if args.keys else scenario
        scenario = tables.resolve(scenario)
        ocean, table = ocean_report.load(scenario)
    except ConfigError as exc:
        return fail(str(exc))
    folder = args.out if args.out is not None else Path("ocean") / scenario.name
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if args.table_out is not None:
            if table is None:
                return fail(
                    f"scenario {scenario.name!r} uses the practical law (ocean.propagation): no TL table to write"
                )
            args.table_out.parent.mkdir(parents=True, exist_ok=True)
            args.table_out.write_bytes(table.to_bytes())
        figures = ocean_report.write_figures(scenario, ocean, table, folder)
    except OSError as exc:
        return fail(f"--out {folder}: cannot write there ({exc.strerror or exc})")
    result = {**ocean_report.summary(scenario, ocean), "figures": figures}
    (folder / "ocean.json").write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(result))
        return 0
    print(
        f"{scenario.name}: noise {result['noise_level_modem_db']:.1f} dB in the modem band, "
        f"{result['noise_level_source_db']:.1f} dB in the source band"
    )
    print(
        f"  modem link: SNR {result['link_snr_at_d_star_db']:.1f} dB at d*, delivery of a {result['frame_bits']}-bit "
        f"frame falls to 0.5 at {result['link_range_50_m']:.0f} m"
    )
    print(
        f"  source: SNR {result['source_snr_at_d_star_db']:.1f} dB at d*, detection falls to 0.5 at "
        f"{result['detection_range_50_m']:.0f} m"
    )
    print(f"figures in {folder}", file=sys.stderr)
    return 0
