"""The examples/ scripts run as a user runs them (short missions), from a folder outside the checkout."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

pytestmark = pytest.mark.integration


def _run(tmp_path: Path, script: str, *args: str) -> str:
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args], cwd=tmp_path, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_tracking_error_plots_one_mission(tmp_path) -> None:
    out = _run(tmp_path, "tracking_error.py", "--duration", "300", "--png", "error.png")
    assert "151 ticks, complete: True" in out and "tracking error" in out
    assert (tmp_path / "error.png").stat().st_size > 10_000


def test_monte_carlo_prints_a_table_per_method(tmp_path) -> None:
    out = _run(tmp_path, "monte_carlo.py", "--seeds", "2", "--duration", "300")
    rows = [line.split() for line in out.splitlines() if line.startswith(("dmpc", "dec-mpc"))]
    assert [r[0] for r in rows] == ["dmpc", "dec-mpc"] and all(r[1] == "2" for r in rows), out


def test_own_estimator_is_registered_and_compared_with_the_default(tmp_path) -> None:
    out = _run(tmp_path, "own_estimator.py", "--seeds", "1-2", "--duration", "300")
    lines = [line for line in out.splitlines() if line.startswith("seed")]
    assert [line.split()[1:3] for line in lines] == [
        ["1", "adaptive-window"],
        ["1", "triangulate"],
        ["2", "adaptive-window"],
        ["2", "triangulate"],
    ], out
