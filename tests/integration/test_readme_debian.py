"""The README's first command, taken unchanged from the README, on Debian 12's own Python.

Debian's and Ubuntu's system Python refuse ``pip install`` outside a virtual environment
(PEP 668, ``externally-managed-environment``), so the command makes one. It runs here in the
Debian 12 base image that docker/base-image.sh builds (python3 and python3-venv, nothing else),
offline (``--network none``: zenoh on the container's loopback), with pip pointed at the wheels
base-image.sh downloads (``PIP_NO_INDEX=1``, ``PIP_FIND_LINKS=docker/wheels/``). Skipped, with the
reason printed, where Docker is absent.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import uuid
from pathlib import Path

import pytest

from tests.integration.conftest import built_base_image, docker_reason

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]


def readme_commands() -> list[str]:
    """The one-line commands of the README's Quick start, in order (each fenced block's line)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    quick = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    return [block.strip() for block in re.findall(r"```\n(.*?)\n```", quick, re.S)]


def _source_copy(dest: Path) -> Path:
    """The files a clone holds (tracked, and new files not ignored) plus the wheelhouse, copied to ``dest``."""
    listed = subprocess.run(
        ["git", "ls-files", "-z", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True, check=True
    ).stdout.split(b"\0")
    for name in [n.decode() for n in listed if n] + [
        str(p.relative_to(ROOT)) for p in (ROOT / "docker" / "wheels").glob("*") if p.is_file()
    ]:
        if (ROOT / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)
    return dest


def test_the_readme_names_a_virtual_environment_in_both_commands() -> None:
    first, tests = readme_commands()[:2]
    for command in (first, tests):
        assert command.startswith("python3 -m venv .venv && . .venv/bin/activate && "), command
    assert first.endswith("pip install . && auv-swarm run"), first
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert tests in ci, ".ci/run must run the README's test command unchanged"


@pytest.mark.timeout(1500)
def test_the_first_command_works_on_debian_12_python(tmp_path: Path) -> None:
    image = built_base_image(docker_reason())
    src = _source_copy(tmp_path / "src")
    command = readme_commands()[0]
    name = f"auvtest-readme-{uuid.uuid4().hex[:8]}"
    try:
        done = subprocess.run(
            ["docker", "run", "--rm", "--name", name, "--network", "none", "-v", f"{src}:/src", "-w", "/src"]
            + ["-e", "PIP_NO_INDEX=1", "-e", "PIP_FIND_LINKS=docker/wheels/", "-e", "PIP_DISABLE_PIP_VERSION_CHECK=1"]
            + [image, "bash", "-c", command],
            capture_output=True,
            text=True,
            timeout=1200,
        )
    finally:
        subprocess.run(["docker", "rm", "-f", name], capture_output=True)
    out = done.stdout + done.stderr
    assert done.returncode == 0, out[-4000:]
    assert "externally-managed-environment" not in out
    metrics = [json.loads(p.read_text(encoding="utf-8")) for p in (src / "runs").glob("*/metrics.json")]
    assert len(metrics) == 1, out[-3000:]
    assert metrics[0]["complete"] is True and metrics[0]["mode"] == "processes", metrics[0].get("incomplete_reason")
    left = subprocess.run(["docker", "ps", "-aq", "--filter", f"name={name}"], capture_output=True, text=True)
    assert left.stdout.strip() == ""
