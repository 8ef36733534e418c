"""A sweep's summaries (per cell: n, mean, std, Student-t 95 % CI), its figures, and tools/study_report.py."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from auv_swarm.orchestrator.sweep import store as st
from auv_swarm.orchestrator.sweep import summary as ss

ROOT = Path(__file__).resolve().parents[2]


def test_stats_are_the_student_t_interval_of_the_mean() -> None:
    s = ss.stats([1.0, 2.0, 3.0])
    assert s["n"] == 3 and s["mean"] == 2.0 and s["std"] == 1.0
    half = 4.302652729911275 / math.sqrt(3)  # t(0.975, 2 dof)
    assert math.isclose(s["ci95_high"] - 2.0, half, rel_tol=1e-9) and math.isclose(2.0 - s["ci95_low"], half)
    one = ss.stats([5.0, None])
    assert one == {"n": 1, "mean": 5.0, "std": None, "ci95_low": None, "ci95_high": None}
    assert ss.stats([])["mean"] is None


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
    bars = tmp_path / "bars"
    bars.mkdir()
    ss.write(rows, ["planner.method"], bars, "cd" * 32)
    assert (bars / "tracking_error_mean_m-bars.png").is_file()
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
    assert "| channel.pdr | dmpc | dpso |" in done.stdout and "| 0.5 | 13.0 ± 2.5 | 17.0 ± 2.5 |" in done.stdout
