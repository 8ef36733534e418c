"""The wheel of ``git archive HEAD``, installed into a fresh virtual environment, run outside the checkout.

The ``installed`` fixture (tests/integration/conftest.py, tests/integration/installs.py) builds and installs it once
per run. It must add exactly one import package of ours to site-packages (``auv_swarm``) and the ``auv-swarm``
script, and run a mission in both modes with ``python -I`` from a folder far from the repository, its
children importing the installed package (nothing of the checkout on any path). The dependencies are
not downloaded again: the fresh environment sees this interpreter's site-packages through a ``.pth``
path list (which, unlike a site directory, runs no ``.pth`` file there, so an editable install of the
checkout stays invisible).
"""

from __future__ import annotations

import json
import os
import subprocess
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.integration, pytest.mark.xdist_group("installed-wheel")]  # one wheel build, one worker


def _run(argv: list[str], **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(argv, capture_output=True, text=True, timeout=600, check=False, **kwargs)


def test_the_wheel_holds_one_import_package(installed) -> None:
    with zipfile.ZipFile(installed["wheel"]) as whl:
        tops = {name.split("/")[0] for name in whl.namelist()}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"auv_swarm"}
    assert {a for a in installed["added"] if not a.endswith(".dist-info") and a != "__pycache__"} == {"auv_swarm"}
    assert (installed["env"] / "bin" / "auv-swarm").exists()


def test_the_installed_package_is_imported_not_the_checkout(installed) -> None:
    code = "import auv_swarm, auv_swarm.agent.planner, auv_swarm.contract.config as c; print(auv_swarm.__file__); print(c.BUILTIN_DIR)"
    done = _run([str(installed["py"]), "-I", "-c", code], cwd=installed["away"])
    assert done.returncode == 0, done.stderr
    assert str(ROOT) not in done.stdout and str(installed["env"]) in done.stdout, done.stdout


@pytest.mark.parametrize("mode", ["inprocess", "processes"])
def test_a_mission_runs_from_the_installed_package(installed, mode) -> None:
    out = installed["away"] / f"run-{mode}"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    argv = [str(installed["py"]), "-I", "-m", "auv_swarm", "run", "--quiet", "--mode", mode, "--duration", "30"]
    done = _run([*argv, "--out", str(out)], cwd=installed["away"], env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["complete"] and metrics["ticks"] > 0
    if mode == "processes":
        logs = "".join(p.read_text(errors="replace") for p in (out / "logs").glob("*.log"))
        assert str(ROOT) not in logs
