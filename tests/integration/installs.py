"""Installs for the tests that run what a user installs: the wheel of ``git archive HEAD`` in a fresh virtual
environment, and the test-only plug-in package ``tests/plugins/faults`` in a folder of its own. Both offline:
``pip --no-build-isolation --no-deps --no-index`` with this interpreter's setuptools and wheel. The fixtures that
call them are session-wide (tests/integration/conftest.py): each is built once per test run.
"""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLUGINS = ROOT / "tests" / "plugins"


def run(argv: list[str], **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(argv, capture_output=True, text=True, timeout=600, check=False, **kwargs)


def wheel_venv(tmp: Path) -> dict[str, Path | set[str]]:
    """The wheel of ``git archive HEAD`` installed into a fresh venv under ``tmp`` that sees this interpreter's
    site-packages through a ``.pth`` path list (which, unlike a site directory, runs no ``.pth`` file there, so an
    editable install of the checkout stays invisible). Skips without git or a checkout."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a git checkout (the wheel is built from git archive HEAD)")
    src, dist, env = tmp / "src", tmp / "dist", tmp / "venv"
    src.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "HEAD"], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    built = run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w", str(dist), str(src)])
    assert built.returncode == 0, built.stderr[-3000:]
    wheel = next(dist.glob("auv_swarm-*.whl"))
    run([sys.executable, "-m", "venv", str(env)]).check_returncode()
    py = env / "bin" / "python"
    purelib = Path(run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    before = {p.name for p in purelib.iterdir()}
    done = run([str(py), "-m", "pip", "install", "--no-deps", "--no-index", str(wheel)])
    assert done.returncode == 0, done.stderr[-3000:]
    added = {p.name for p in purelib.iterdir()} - before
    ours = sorted({*site.getsitepackages(), sysconfig.get_paths()["purelib"]})
    (purelib / "zz-dependencies.pth").write_text("\n".join(ours) + "\n", encoding="utf-8")
    away = tmp / "elsewhere"
    away.mkdir()
    return {"wheel": wheel, "env": env, "py": py, "added": added, "away": away}


def plugin_package(name: str, tmp: Path) -> dict[str, str]:
    """``tests/plugins/<name>`` installed (pip, offline) into ``tmp/site``; the environment that makes it visible
    to a process and every process it starts (``PYTHONPATH``, which ``python -P`` keeps). Built from a copy, so
    nothing is written into the checkout."""
    src, target = tmp / "src", tmp / "site"
    shutil.copytree(PLUGINS / name, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    argv = [sys.executable, "-m", "pip", "install", "-q", "--no-build-isolation", "--no-deps", "--no-index"]
    done = run([*argv, "--target", str(target), str(src)])
    assert done.returncode == 0, done.stderr[-3000:]
    paths = [str(target), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return {"PYTHONPATH": os.pathsep.join(paths)}
