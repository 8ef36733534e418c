"""`docker-compose up` of the 3-AUV swarm: build the images (a plug-in wheel in docker/plugins/ goes in), a paced
mission with agent1 killed and started again, then a fault-free mission whose metrics and raw data equal
`auv-swarm run`'s (and export as CSV, Parquet and MCAP); nothing of the project is left.

Skipped, with the reason printed, where Docker or docker-compose is absent. The base image comes
from docker/base-image.sh (debootstrap, where no registry answers), reused when it exists.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from auv_swarm.results.metrics import comparable
from tests.integration.conftest import built_base_image, docker_reason
from tests.integration.export_checks import assert_exports, assert_same_raw_data, assert_tracking_error_reproduced

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = os.environ.get("AUVSWARM_TEST_COMPOSE", "docker-compose").split()
"""The compose tool: docker-compose 1.29 by default; e.g. ``AUVSWARM_TEST_COMPOSE="docker compose"`` for v2."""


def _docker_ready() -> str | None:
    """Why the test cannot run here, or None."""
    return docker_reason(COMPOSE[0])


class Project:
    """One compose project with a unique name, its own runs and credentials folders."""

    def __init__(self, tmp: Path, compose_file: Path = ROOT / "docker-compose.yml", agents: int = 3) -> None:
        from auv_swarm.orchestrator.mission import compose

        self.name = f"auvtest{uuid.uuid4().hex[:8]}"
        self.compose_file = compose_file
        self.runs = tmp / "runs"
        self.credentials = tmp / "credentials"
        for name in compose.secret_folders(agents):  # as a clone holds them in .credentials/
            (self.credentials / name).mkdir(parents=True)
        self.env = {
            **os.environ,
            "RUNS_DIR": str(self.runs),
            "CREDENTIALS_DIR": str(self.credentials),
            "SCENARIO": "paper-3.2-challenging",
            "SEED": "1",
        }

    def command(self) -> list[str]:
        """docker-compose with this project's name and its compose file."""
        return [*COMPOSE, "-p", self.name, "--project-directory", str(ROOT), "-f", str(self.compose_file)]

    def compose(self, *args: str, timeout: float = 300.0, check: bool = True, **env: str) -> str:
        cmd = self.command()
        done = subprocess.run(
            [*cmd, *args], env={**self.env, **env}, capture_output=True, text=True, timeout=timeout, cwd=ROOT
        )
        assert "undefined secret" not in done.stderr, done.stderr  # a correct set-up prints no warning
        if check and done.returncode != 0:
            raise AssertionError(
                f"{' '.join(COMPOSE)} {' '.join(args)} failed ({done.returncode}):\n{done.stderr[-3000:]}"
            )
        return done.stdout

    def up(self, **env: str) -> subprocess.Popen:
        cmd = self.command()
        return subprocess.Popen(
            [*cmd, "up", "--no-build", "--no-color"],
            env={**self.env, **env},
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )

    def state(self, service: str) -> dict:
        cid = self.compose("ps", "-a", "-q", service).strip()
        if not cid:
            return {}
        done = subprocess.run(["docker", "inspect", cid], capture_output=True, text=True, check=True)
        return json.loads(done.stdout)[0]["State"]

    def leftovers(self) -> list[str]:
        label = f"label=com.docker.compose.project={self.name}"
        found = []
        for kind in (["ps", "-aq"], ["network", "ls", "-q"], ["volume", "ls", "-q"]):
            done = subprocess.run(["docker", *kind, "--filter", label], capture_output=True, text=True, check=True)
            found += [f"{kind[0]} {x}" for x in done.stdout.split()]
        return found


def _each_container_holds_only_its_own_password(project: Project) -> None:
    """No password in `docker inspect`; a container's /run/secrets holds its own folder only."""
    passwords = [p.read_text().strip() for p in project.credentials.glob("*/password")]
    assert len(passwords) >= 8, f"the credentials service wrote {len(passwords)} passwords"
    ids = project.compose("ps", "-q").split()
    inspect = subprocess.run(["docker", "inspect", *ids], capture_output=True, text=True, check=True).stdout
    assert not [p for p in passwords if p in inspect], "a password shows in docker inspect"
    agent0 = project.compose("ps", "-q", "agent0").strip()
    listing = subprocess.run(
        ["docker", "exec", agent0, "find", "/run/secrets", "-type", "f"], capture_output=True, text=True, check=True
    ).stdout.split()
    assert listing == ["/run/secrets/auv0/password"], listing


@pytest.fixture
def base_image() -> str:
    """The tag of the base image docker/base-image.sh builds (or reuses); the test is skipped, the reason printed,
    where Docker is not ready."""
    return built_base_image(_docker_ready())


@contextmanager
def _built(project: Project, base_image: str) -> Iterator[Project]:
    """``project`` with its images built on ``base_image``; on leaving, taken down and checked gone."""
    try:
        project.compose("build", timeout=900, BASE_IMAGE=base_image)
        yield project
    finally:
        project.compose("down", "-v", "--remove-orphans", check=False)
        left = project.leftovers()
        assert left == [], f"left behind: {left}"


def _wait(predicate, timeout: float, what: str, poll_s: float = 0.5) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(poll_s)


def _finish(up: subprocess.Popen, project: Project, timeout: float) -> str:
    """Wait for `docker-compose up` to return by itself (the mission ended); its output."""
    try:
        out, _ = up.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        up.kill()
        out, _ = up.communicate()
        running = project.compose("ps", check=False)
        raise AssertionError(f"`docker-compose up` did not return within {timeout:g} s; still up:\n{running}") from None
    return out


@contextmanager
def _plugin_wheel(tmp: Path) -> Iterator[None]:
    """The test plug-in package (tests/plugins/faults) as a wheel in docker/plugins/ while the images build, as a
    user puts one there (docs/containers.md); removed after."""
    src = tmp / "plugin-src"
    shutil.copytree(ROOT / "tests" / "plugins" / "faults", src)
    argv = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(tmp)]
    done = subprocess.run([*argv, str(src)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    wheel = next(tmp.glob("auv_swarm_test_faults-*.whl"))
    placed = ROOT / "docker" / "plugins" / wheel.name
    shutil.copyfile(wheel, placed)
    try:
        yield
    finally:
        placed.unlink(missing_ok=True)


def _image_knows_the_plugin() -> None:
    code = "from auv_swarm.contract import methods; print(*methods.names('planner'), *methods.names('estimator'))"
    done = subprocess.run(
        ["docker", "run", "--rm", "--entrypoint", "python3", "auv-swarm:latest", "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and done.stdout.split().count("fault-raise") == 2, done.stdout + done.stderr


@pytest.mark.timeout(1500)
def test_compose_mission_with_a_drill_then_equal_to_auv_swarm_run(tmp_path, base_image) -> None:
    with _plugin_wheel(tmp_path), _built(Project(tmp_path), base_image) as project:
        _image_knows_the_plugin()  # a plug-in wheel in docker/plugins/ is in the image
        # 1. A paced mission; agent1 is killed mid-mission and started again.
        up = project.up(RUN_ID="drill", DURATION="400", SPEED="8")
        world_log = project.runs / "drill" / "logs" / "world.log"
        _wait(lambda: world_log.is_file() and "starting" in world_log.read_text(errors="replace"), 180, "the start")
        time.sleep(8.0)
        _each_container_holds_only_its_own_password(project)
        project.compose("kill", "agent1")
        time.sleep(5.0)
        project.compose("start", "agent1")
        output = _finish(up, project, timeout=240)
        run = project.runs / "drill"
        assert "WARNING" not in output and "undefined secret" not in output, output[:3000]
        assert f"results in {project.runs}/drill; mission exit code 0" in output, output[-3000:]
        assert "AUV 1 rejoined at t = " in output, output[-3000:]
        for name in ("metrics.json", "events.jsonl", "scenario.toml", "recording.rrd", "trajectories.png"):
            assert (run / name).is_file(), f"{name} missing from {run}"
        for service in ("router", "world", "channel", "auv0", "auv1", "auv2", "recorder", "collector"):
            assert (run / "logs" / f"{service}.log").is_file(), f"no log of {service}"
        metrics = json.loads((run / "metrics.json").read_text(encoding="utf-8"))
        assert metrics["exit_code"] == 0 and metrics["complete"] is True
        assert project.state("collector")["ExitCode"] == 0
        intervals = {a: metrics["agents"][a]["alive_intervals_s"] for a in ("0", "1", "2")}
        assert len(intervals["1"]) == 2, f"agent1 died and rejoined: {intervals['1']}"
        assert len(intervals["0"]) == 1 and len(intervals["2"]) == 1, intervals
        project.compose("down", "-v", "--remove-orphans")

        # 2. A fault-free lockstep mission: the same metrics as `auv-swarm run` (wall and plan times aside).
        up = project.up(RUN_ID="plain", DURATION="300", SPEED="0")
        _finish(up, project, timeout=240)
        compose_metrics = json.loads((project.runs / "plain" / "metrics.json").read_text(encoding="utf-8"))
        assert project.state("collector")["ExitCode"] == 0
        project.compose("down", "-v", "--remove-orphans")
        local = tmp_path / "local"
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "auv_swarm",
                "run",
                "--seed",
                "1",
                "--duration",
                "300",
                "--quiet",
                "--out",
                str(local),
            ],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=ROOT,
        )
        assert done.returncode == 0, done.stderr[-3000:]
        run_metrics = json.loads((local / "metrics.json").read_text(encoding="utf-8"))
        ours, theirs = comparable(compose_metrics), comparable(run_metrics)
        shared = set(ours) & set(theirs)
        assert set(theirs) <= set(ours), f"keys missing under compose: {set(theirs) - set(ours)}"
        assert {k: ours[k] for k in shared} == {k: theirs[k] for k in shared}

        # 3. The collector's raw data (issue 47): the same tables as `auv-swarm run`'s, the tracking error
        # reproduced from them, and `auv-swarm export` in all three formats (MCAP topics and schemas checked).
        plain = project.runs / "plain"
        assert_same_raw_data(plain, local)
        assert_tracking_error_reproduced(plain)
        assert_exports(plain, tmp_path / "plain-export")


@pytest.mark.slow
@pytest.mark.timeout(1500)
def test_a_five_auv_swarm_from_the_generated_file(tmp_path, base_image) -> None:
    from auv_swarm.orchestrator.mission import compose

    five = tmp_path / "docker-compose.5.yml"
    five.write_text(compose.compose_text(5), encoding="utf-8")
    scenario = tmp_path / "five.toml"
    from auv_swarm.contract.config import dump_toml, load_scenario

    scenario.write_text(dump_toml(load_scenario("paper-3.2-challenging").with_overrides(agents=5)), encoding="utf-8")
    with _built(Project(tmp_path, five, agents=5), base_image) as project:
        up = project.up(RUN_ID="five", DURATION="300", SPEED="0", SCENARIO="five.toml", SCENARIOS_DIR=str(tmp_path))
        _finish(up, project, timeout=300)
        metrics = json.loads((project.runs / "five" / "metrics.json").read_text(encoding="utf-8"))
        assert metrics["n_agents"] == 5 and metrics["complete"] is True
        assert project.state("collector")["ExitCode"] == 0
