"""The Bellhop path (pelagic, the [bellhop] extra, in the dev extra) against analytic and modal references, and
the one-module rule for pelagic (docs/ocean.md)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from auv_swarm.contract.config import builtin_scenarios, load_scenario
from auv_swarm.contract.ocean import munk_speed
from auv_swarm.contract.tltable import load_table, table_spec

ROOT = Path(__file__).resolve().parents[2]


def test_pelagic_is_imported_in_one_module_only() -> None:
    pattern = re.compile(r"^\s*(import pelagic|from pelagic)", re.MULTILINE)
    users = sorted(
        str(p.relative_to(ROOT))
        for p in ROOT.rglob("*.py")
        if not {".venv", "tests", ".git"} & set(p.relative_to(ROOT).parts) and pattern.search(p.read_text())
    )
    assert users == ["orchestrator/mission/solvers.py"]


def _image_sum_tl(ranges: np.ndarray, zr: float, zs: float, depth: float, images: int = 3000) -> np.ndarray:
    """Incoherent image sum of a point source in isovelocity water between a pressure-release surface and a rigid
    bottom: every image (2 m D +- z_s) has a reflection coefficient of magnitude 1, TL = -10 log10 sum 1 / R^2."""
    m = np.arange(-images, images + 1)
    zi = np.concatenate([2 * m * depth + zs, 2 * m * depth - zs])
    r2 = ranges[:, None] ** 2 + (zr - zi[None, :]) ** 2
    return -10 * np.log10(np.sum(1 / r2, axis=1))


def test_bellhop_matches_the_image_sum_within_half_a_db() -> None:
    solvers = pytest.importorskip("auv_swarm.orchestrator.mission.solvers")
    pytest.importorskip("pelagic")
    depth, zs = 100.0, 20.0
    case = solvers.bellhop_case(
        10.0, depth, [[0, 1500], [depth, 1500]], None, zs, (20.0, 80.0, 3), (0.0, 3000.0, 151), 2000, thorp=False
    )
    ranges, depths, tl = solvers.run_tl(case)
    checked = 0
    for row, zr in zip(tl, depths, strict=True):
        ref = _image_sum_tl(ranges[1:], zr, zs, depth)
        use = ref < 100.0
        checked += int(use.sum())
        assert np.max(np.abs(row[1:][use] - ref[use])) < 0.5
    assert checked > 400


def _km_average(ranges: np.ndarray, tl: np.ndarray, km: int) -> np.ndarray:
    """TL of the mean intensity in each 1 km of range from 1 km to ``km`` km."""
    return np.array(
        [
            -10 * np.log10(np.mean(10 ** (-tl[(ranges >= a * 1e3) & (ranges < (a + 1) * 1e3)] / 10)))
            for a in range(1, km)
        ]
    )


def test_bellhop_against_kraken_on_a_munk_case() -> None:
    """Munk (1974) profile over 5000 m, sand-like half-space, 100 Hz, source 1000 m, receiver 800 m, 0-50 km.
    Kraken's coherent field and the incoherent Bellhop field the tables use, each averaged over 1 km of range:
    within 3.5 dB (median within 1.5 dB) wherever Kraken's TL is below 90 dB. In the ray shadow zone
    (about 13-33 km here) they part by up to 20 dB: Kraken's trapped modes leave out the steep bottom-bounce paths
    that Bellhop keeps (docs/ocean.md)."""
    solvers = pytest.importorskip("auv_swarm.orchestrator.mission.solvers")
    pytest.importorskip("pelagic")
    z = np.linspace(0.0, 5000.0, 51)
    ssp = [[float(a), float(c)] for a, c in zip(z, munk_speed(z), strict=True)]
    bed = [1600.0, 1.8, 0.8]
    kraken = solvers.kraken_case(0.1, 5000.0, ssp, bed, 1000.0, 800.0, (0.0, 50000.0, 5001))
    kraken["kraken"]["addition"] = "coherent"
    rk, _, tk = solvers.run_tl(kraken)
    bellhop = solvers.bellhop_case(
        0.1, 5000.0, ssp, bed, 1000.0, (800.0, 800.0, 1), (0.0, 50000.0, 2001), 2000, thorp=False
    )
    rb, _, tb = solvers.run_tl(bellhop)
    k, b = _km_average(rk, tk[0], 50), _km_average(rb, tb[0], 50)
    lit = k < 90.0
    assert lit.sum() >= 20
    diff = np.abs(b - k)[lit]
    assert diff.max() < 3.5 and np.median(diff) < 1.5


@pytest.mark.parametrize("name", [n for n in builtin_scenarios() if load_scenario(n).ocean.model == "physical"])
def test_builtin_tables_recomputed_with_bellhop(name: str) -> None:
    """A built-in physical scenario's shipped table, at the two depths a mission reads (the AUVs' and the
    source's), equals a fresh Bellhop run of the same environment, range-averaged as the tables are, within
    0.05 dB (float32 storage)."""
    solvers = pytest.importorskip("auv_swarm.orchestrator.mission.solvers")
    pytest.importorskip("pelagic")
    scenario = load_scenario(name)
    table = load_table(scenario)
    spec = table_spec(scenario.with_keys({"ocean.propagation": "bellhop"}))
    for i, f in enumerate(table.frequencies_khz):
        for zr in (scenario.ocean.auv_depth_m, scenario.ocean.source_depth_m):
            row = int(np.argmin(np.abs(table.depths_m - zr)))
            z = float(table.depths_m[row])
            case = solvers.bellhop_case(
                f,
                spec["depth_m"],
                spec["ssp"],
                spec["seabed"],
                spec["source_depth_m"],
                (z, z, 1),
                tuple(spec["ranges_m"]),
                spec["beams"],
            )
            ranges, _, tl = solvers.run_tl(case)
            assert np.allclose(ranges, table.ranges_m)
            fresh = solvers.range_average(ranges, np.where(ranges < 1.0, 0.0, tl[0]), spec["range_average"])
            assert np.max(np.abs(fresh - table.tl_db[i, row])) < 0.05


def test_run_builds_a_missing_bellhop_table_into_the_cache(tmp_path: Path, monkeypatch, capsys) -> None:
    """`auv-swarm run` on a Bellhop scenario whose table is not cached builds it (docs/ocean.md) rather than
    refusing the scenario in its first check."""
    pytest.importorskip("pelagic")
    from auv_swarm.contract.config import dump_toml
    from auv_swarm.orchestrator.cli.main import main

    monkeypatch.setenv("AUVSWARM_CACHE_DIR", str(tmp_path / "cache"))
    scenario = load_scenario("ocean-coastal-summer").with_keys({"ocean.propagation": "bellhop", "run.duration_s": 20.0})
    path = tmp_path / "bellhop.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    out = tmp_path / "run"
    assert main(["run", str(path), "--mode", "inprocess", "--out", str(out)]) == 0, capsys.readouterr().err
    assert len(list((tmp_path / "cache" / "tl").glob("*.npz"))) == 1
    assert (out / "metrics.json").is_file()
