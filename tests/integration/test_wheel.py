"""The wheel of ``git archive HEAD``, installed into a fresh virtual environment, run outside the checkout.

It must add exactly one import package of ours to site-packages (``auv_swarm``) and the ``auv-swarm``
script, and run a mission in both modes with ``python -I`` from a folder far from the repository, its
children importing the installed package (nothing of the checkout on any path). The dependencies are
not downloaded again: the fresh environment sees this interpreter's site-packages through a ``.pth``
path list (which, unlike a site directory, runs no ``.pth`` file there, so an editable install of the
checkout stays invisible).
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.integration


def _run(argv: list[str], **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(argv, capture_output=True, text=True, timeout=600, check=False, **kwargs)


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict[str, Path]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a git checkout (the wheel is built from git archive HEAD)")
    tmp = tmp_path_factory.mktemp("wheel")
    src, dist, env = tmp / "src", tmp / "dist", tmp / "venv"
    src.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "HEAD"], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w", str(dist), str(src)])
    assert built.returncode == 0, built.stderr[-3000:]
    wheel = next(dist.glob("auv_swarm-*.whl"))
    _run([sys.executable, "-m", "venv", str(env)]).check_returncode()
    py = env / "bin" / "python"
    purelib = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    before = {p.name for p in purelib.iterdir()}
    done = _run([str(py), "-m", "pip", "install", "--no-deps", "--no-index", str(wheel)])
    assert done.returncode == 0, done.stderr[-3000:]
    added = {p.name for p in purelib.iterdir()} - before
    ours = sorted({*site.getsitepackages(), sysconfig.get_paths()["purelib"]})
    (purelib / "zz-dependencies.pth").write_text("\n".join(ours) + "\n", encoding="utf-8")
    away = tmp / "elsewhere"
    away.mkdir()
    return {"wheel": wheel, "env": env, "py": py, "added": added, "away": away}


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
