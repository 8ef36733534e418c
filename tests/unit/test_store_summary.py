"""A sweep's summaries (per cell: `mean [lo, hi] (n)`, a bootstrap interval, plain decimals, labels from
METRIC_INFO), its figures, ``sweep --summary``, and tools/study_report.py: one test per rule of issue 46 item 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as hs

from auv_swarm.orchestrator.sweep import store as st
from auv_swarm.orchestrator.sweep import summary as ss

ROOT = Path(__file__).resolve().parents[2]


def test_three_or_more_values_get_a_bootstrap_interval_of_the_mean_inside_their_range() -> None:
    values = [88.0, 2.0, 3.0, 250.0, 5.0]  # skewed, as p95 over few seeds: a t interval would reach below 0
    s = ss.stats(values)
    assert s["n"] == 5 and s["mean"] == pytest.approx(69.6) and s["interval"] == "bootstrap95"
    assert s["std"] == pytest.approx(float(np.std(values, ddof=1)))  # the sample std, n - 1
    assert min(values) <= s["lo"] < s["mean"] < s["hi"] <= max(values)
    assert ss.stats(list(reversed(values))) == s  # a function of the values, not of their order or a clock
    fractions = ss.stats([0.9, 1.0, 1.0, 1.0])
    assert 0.9 <= fractions["lo"] <= fractions["hi"] <= 1.0  # a fraction's interval stays a fraction


def test_two_values_are_shown_as_both_and_one_alone() -> None:
    two = ss.stats([4.0, 9.0, None])
    assert (two["n"], two["lo"], two["hi"], two["interval"]) == (2, 4.0, 9.0, "values")
    assert ss.cell_text(two) == "6.50 [4.00, 9.00] (2)"
    one = ss.stats([5.0, None])
    assert one == {"n": 1, "mean": 5.0, "std": None, "lo": None, "hi": None, "interval": None}
    assert ss.cell_text(one) == "5.00 (1)"
    assert ss.stats([])["mean"] is None and ss.cell_text(ss.stats([])) == "-"


def test_numbers_are_plain_decimals_with_three_significant_digits() -> None:
    assert [ss.plain(x) for x in (1234.0, 88.12, 0.8771, 0.000123456, 123456.0, -45.26, 0.0, 0.99996)] == [
        "1230", "88.1", "0.877", "0.000123", "123000", "-45.3", "0", "1.00"
    ]  # fmt: skip
    assert ss.plain(None) == "-" and ss.plain(float("nan")) == "-"


@given(hs.floats(min_value=-1e12, max_value=1e12, allow_nan=False).filter(lambda x: x == 0 or abs(x) > 1e-12))
def test_plain_never_uses_e_notation_and_keeps_three_digits(x: float) -> None:
    text = ss.plain(x)
    assert "e" not in text.lower()
    assert float(text) == pytest.approx(x, rel=5e-3, abs=1e-300)


def _rows() -> list[dict]:
    rows = []
    for method in ("dmpc", "dpso"):
        for pdr in (0.5, 0.95):
            for seed in (1, 2, 3):
                err = (10.0 if method == "dmpc" else 14.0) + 2 * pdr + seed
                rows.append(
                    {
                        "planner.method": method,
                        "channel.pdr": pdr,
                        "seed": seed,
                        "status": "done",
                        "tracking_error_mean_m": err,
                        "fqi": 1.2,
                        "scenario_sha256": f"{method}{pdr}",
                    }
                )
    rows.append(
        {
            "planner.method": "dpso",
            "channel.pdr": 0.95,
            "seed": 4,
            "status": "failed",
            "tracking_error_mean_m": None,
            "scenario_sha256": "dpso0.95",
        }
    )
    return rows


def test_summary_md_reads_mean_interval_n_under_labels_and_units(tmp_path: Path) -> None:
    rows = _rows()
    rows[0].update(tracking_error_p95_m=1.5e-5, nees_in_band_fraction=0.877)  # one seed: the value alone
    text = ss.markdown(ss.summarise(rows, ["planner.method", "channel.pdr"], "ab" * 32))
    header = text.splitlines()[4]
    assert "mean tracking error (m)" in header and "NEES in band" in header and "tracking_error_mean_m" not in header
    assert "| dmpc | 0.5 | 3 | 0 | 13.0 [12.0, 14.0] (3) | 0.0000150 (1) |" in text
    assert "0.877 (1)" in text and "±" not in text and "e-0" not in text and "e+0" not in text
    assert "bootstrap" in text and "n - 1" in text  # the interval and the std convention are stated


def test_a_figure_per_headline_metric_and_axis_with_labels_and_none_without_an_axis(tmp_path: Path) -> None:
    rows = _rows()
    for r in rows:
        if r["status"] == "done":
            r.update(tracking_error_p95_m=3 * r["tracking_error_mean_m"], convergence_time_s=100.0 + r["seed"])
            r["nees_in_band_fraction"] = 0.8
    paths = ss.figures(rows, ["planner.method", "channel.pdr"], tmp_path)
    assert sorted(p.name for p in paths) == sorted(f"{m}-vs-channel.pdr.png" for m in ss.HEADLINE_METRICS)
    assert all(p.is_file() for p in paths)
    assert ss.axis_label("channel.pdr").startswith("channel.pdr: packet delivery ratio")
    assert ss.metric_label("tracking_error_p95_m") == "tracking error p95 (m)"
    assert ss.figures(rows, [], tmp_path / "none") == []  # no axis: no bar labelled None
    bars = tmp_path / "bars"
    bars.mkdir()
    assert [p.name for p in ss.figures(rows, ["planner.method"], bars)] == [
        f"{m}-bars.png" for m in ss.HEADLINE_METRICS
    ]


def test_cells_figures_and_the_study_report(tmp_path: Path) -> None:
    rows = _rows()
    summary = ss.write(rows, ["planner.method", "channel.pdr"], tmp_path, "ab" * 32)
    assert [c["labels"] for c in summary["cells"]][0] == {"planner.method": "dmpc", "channel.pdr": 0.5}
    last = summary["cells"][-1]
    assert (last["missions"], last["done"], last["failed"]) == (4, 3, 1)
    assert last["stats"]["tracking_error_mean_m"]["mean"] == 14.0 + 1.9 + 2.0
    assert last["stats"]["nees_in_band_fraction"]["n"] == 0
    assert json.loads((tmp_path / "summary.json").read_text())["schema"] == ss.SCHEMA_VERSION
    assert (tmp_path / "tracking_error_mean_m-vs-channel.pdr.png").is_file()
    assert "| dpso | 0.95 | 3 | 1 |" in (tmp_path / "summary.md").read_text()
    store = st.open_store(
        tmp_path,
        {"planner.method": ["dmpc", "dpso"], "channel.pdr": [0.5, 0.95]},
        {"bases": ["paper-3.3-sim2"], "axes": [], "seeds": [1, 2, 3, 4], "duration_s": 60.0},
        "ab" * 32,
        "v",
        False,
    )
    for r in rows:
        store.put(r, dict(r, attempts=1))
    store.close()
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "study_report.py"), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert "13 missions, 1 failed" in done.stdout
    assert "| channel.pdr | dmpc | dpso |" in done.stdout
    assert "| 0.5 | 13.0 [12.0, 14.0] (3) | 17.0 [16.0, 18.0] (3) |" in done.stdout


def test_sweep_summary_dir_rebuilds_from_the_store_alone(tmp_path: Path, capsys) -> None:
    from auv_swarm.orchestrator.cli.sweep import main

    store = st.open_store(
        tmp_path,
        {"planner.method": ["dmpc", "dpso"], "channel.pdr": [0.5, 0.95]},
        {"axes": [["planner.method", ["dmpc", "dpso"]], ["channel.pdr", [0.5, 0.95]]], "seeds": [1, 2, 3]},
        "ef" * 32,
        "v",
        False,
    )
    for r in _rows():
        store.put(r, dict(r, attempts=1))
    store.close()
    assert main(["--summary", str(tmp_path)]) == 0
    assert "| dmpc | 0.5 | 3 | 0 | 13.0 [12.0, 14.0] (3) |" in capsys.readouterr().out
    assert json.loads((tmp_path / "summary.json").read_text())["grid_hash"] == "ef" * 32
    assert (tmp_path / st.PARQUET_FILE).is_file() and (tmp_path / "tracking_error_mean_m-vs-channel.pdr.png").is_file()
    assert main(["--summary", str(tmp_path), "--seeds", "3"]) == 2
    assert main(["--summary", str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "--summary DIR runs nothing: leave out --seeds" in err[0] and "no sweep.sqlite there" in err[1]
