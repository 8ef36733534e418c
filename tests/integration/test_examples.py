"""The examples/ scripts run as a user runs them (short missions), from a folder outside the checkout;
``own_planner.py`` also from a plain install of the wheel (the ``installed`` fixture)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

pytestmark = [pytest.mark.integration, pytest.mark.xdist_group("installed-wheel")]  # one wheel build, one worker


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


GREEDY_LINE = r"greedy, (\w+): mean tracking error ([0-9.]+) m, complete: True"


def _own_planner(where: str, installed: dict | None, tmp_path: Path, *args: str) -> str:
    """``examples/own_planner.py`` run as a user runs it: from the checkout (this interpreter, the editable install)
    or, ``where = "wheel"``, copied next to a user of a plain ``pip install`` of the wheel (``python -I``, nothing
    of the checkout on any path)."""
    if where == "checkout":
        return _run(tmp_path, "own_planner.py", *args)
    script = installed["away"] / "own_planner.py"
    shutil.copyfile(EXAMPLES / "own_planner.py", script)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    argv = [str(installed["py"]), "-I", str(script), *args]
    done = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


@pytest.fixture(scope="module")
def greedy_error_120s(tmp_path_factory) -> str:
    """The in-process mission's error of the greedy planner over 120 s (what the other modes must give)."""
    out = _run(tmp_path_factory.mktemp("greedy"), "own_planner.py", "--duration", "120")
    return re.search(GREEDY_LINE, out).group(2)


@pytest.fixture(params=["checkout", "wheel"])
def where(request) -> tuple[str, dict | None]:
    return request.param, request.getfixturevalue("installed") if request.param == "wheel" else None


def test_own_planner_runs_a_short_mission_with_no_argument(where, tmp_path) -> None:
    out = _own_planner(*where, tmp_path)
    assert re.fullmatch(GREEDY_LINE + "\n", out) and re.match(GREEDY_LINE, out).group(1) == "inprocess", out


def test_own_planner_runs_as_processes_by_reference(where, tmp_path, greedy_error_120s) -> None:
    out = _own_planner(*where, tmp_path, "--mode", "processes", "--duration", "120")
    assert re.match(GREEDY_LINE, out).groups() == ("processes", greedy_error_120s), out


def test_own_planner_runs_in_a_two_worker_sweep_against_dmpc(where, tmp_path, greedy_error_120s) -> None:
    out = _own_planner(*where, tmp_path, "--sweep", "--duration", "120")
    rows = [line.split() for line in out.splitlines()]
    assert [(r[0], r[2], r[3]) for r in rows] == [
        ("dmpc", "1:", "done,"),
        ("dmpc", "2:", "done,"),
        ("greedy", "1:", "done,"),
        ("greedy", "2:", "done,"),
    ], out
    assert rows[2][4] == greedy_error_120s != rows[0][4], out  # the workers ran the greedy planner
