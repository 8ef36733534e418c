"""A run never lies (issue 12): what dies is named, metrics.json says the run is incomplete, the exit code says so,
and no process is left behind, over real processes on loopback."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from auv_swarm.orchestrator.mission.procs import children_of
from tests.processes import cmdline, kill_group, role_line, start

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]


class Run:
    """``auv-swarm run`` in its own session, with helpers to find and hurt its children; leaving a ``with`` block
    finishes it (:meth:`finish`)."""

    def __init__(self, tmp_path: Path, *args: str, env: dict[str, str] | None = None, cwd: Path = REPO_ROOT) -> None:
        self.out = tmp_path / "run"
        argv = [sys.executable, "-m", "auv_swarm", "run", "--quiet", "--out", str(self.out), *args]
        self.proc = start(argv, env={**os.environ, **(env or {})}, cwd=cwd)
        self.stdout = self.stderr = ""

    def __enter__(self) -> Run:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.finish()

    def wait_started(self, timeout: float = 60.0) -> None:
        world_log = self.out / "logs" / "world.log"
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if world_log.exists() and "starting" in world_log.read_text():
                return
            assert self.proc.poll() is None, self.proc.communicate()
            time.sleep(0.05)
        raise AssertionError("the mission did not start")

    def child(self, role: str) -> int:
        """The pid of the child whose command line has the role word (``world``, ``channel``, ``--id 2``)."""
        pids = [p for p in children_of(self.proc.pid) if f" {role} " in role_line(p)]
        assert len(pids) == 1, (role, [cmdline(p) for p in children_of(self.proc.pid)])
        return pids[0]

    def left(self, within_s: float = 5.0) -> list[str]:
        """Command lines of the launcher's children still running ``within_s`` wall seconds from now."""
        deadline = time.monotonic() + within_s
        while time.monotonic() < deadline and children_of(self.proc.pid):
            time.sleep(0.1)
        return [cmdline(p) for p in children_of(self.proc.pid)]

    def finish(self, timeout: float = 120.0) -> int:
        """Wait up to ``timeout`` s for the launcher and keep its output; its group is SIGKILLed if it still runs."""
        try:
            self.stdout, self.stderr = self.proc.communicate(timeout=timeout)
        finally:
            kill_group(self.proc)
        return self.proc.returncode

    def metrics(self) -> dict:
        return json.loads((self.out / "metrics.json").read_text())


@pytest.mark.parametrize(
    ("role", "reason", "line"),
    [
        ("world", "world_died", "world died at t = "),
        ("router", "router_lost", "router died at t = "),
        ("channel", "channel_lost", "channel died at t = "),
    ],
)
def test_a_critical_process_killed_mid_mission_makes_the_run_incomplete(
    tmp_path: Path, role: str, reason: str, line: str
) -> None:
    with Run(tmp_path, "--duration", "600", "--speed", "40") as run:
        run.wait_started()
        time.sleep(1.0)
        os.kill(run.child(role), signal.SIGKILL)
        code = run.finish()
    assert code == 1, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["complete"] is False and metrics["incomplete_reason"] == reason and metrics["exit_code"] == 1
    assert 0 < metrics["sim_duration_s"] < 600
    assert line in run.stderr and "signal 9" in run.stderr
    assert f"run incomplete ({reason})" in run.stderr
    assert run.left() == []


def test_a_router_down_longer_than_the_grace_makes_the_run_incomplete(tmp_path: Path) -> None:
    """A scheduled router restart whose outage (3 s) outlasts ``run.grace_s`` (1 s): the world, the channel and the
    AUVs give up on it, and the run says the router was lost."""
    from auv_swarm.contract.config import Fault, dump_toml, load_scenario

    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=200.0)
    scenario = scenario.replace(
        kills=(),
        faults=(Fault(at_s=40.0, target="router", action="restart", down_s=3.0),),
        run=dataclasses.replace(scenario.run, grace_s=1.0),
    )
    path = tmp_path / "router-outage.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    run = Run(tmp_path, "--scenario", str(path), "--speed", "40")
    code = run.finish()
    assert code == 1, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["complete"] is False and metrics["incomplete_reason"] == "router_lost" and metrics["exit_code"] == 1
    assert 40.0 <= metrics["sim_duration_s"] < 200.0
    assert "fault: restart router at t = 40 s" in run.stderr and "router lost at t = 40 s" in run.stderr
    assert "run incomplete (router_lost)" in run.stderr
    assert run.left() == []


def test_an_auv_crash_is_a_death_with_its_reason_and_the_run_completes(tmp_path: Path) -> None:
    with Run(tmp_path, "--duration", "200", "--speed", "40") as run:
        run.wait_started()
        os.kill(run.child("--id 2"), signal.SIGKILL)
        code = run.finish()
    assert code == 0, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["complete"] is True and metrics["incomplete_reason"] is None and metrics["exit_code"] == 0
    assert metrics["sim_duration_s"] == pytest.approx(200.0)
    assert metrics["agents"]["2"]["alive_until_s"] is not None
    assert "warning: AUV 2 died at t = " in run.stderr
    events = [json.loads(x) for x in (run.out / "events.jsonl").read_text().splitlines()]
    deaths = [e for e in events if e["kind"] == "death"]
    assert [d["agent"] for d in deaths] == [2] and "liveliness" in deaths[0]["reason"]
    assert [e["agent"] for e in events if e["kind"] == "kill"] == []
    ends = [e for e in events if e["kind"] == "end"]
    assert len(ends) == 1 and ends[0]["t_s"] == pytest.approx(200.0)
    assert run.left() == []


def test_ctrl_c_prints_interrupted_and_exits_130(tmp_path: Path) -> None:
    with Run(tmp_path, "--duration", "600", "--speed", "40") as run:
        run.wait_started()
        time.sleep(1.0)
        run.proc.send_signal(signal.SIGINT)
        code = run.finish()
    assert code == 130, run.stderr[-2000:]
    assert "interrupted at t = " in run.stderr
    metrics = run.metrics()
    assert metrics["complete"] is False and metrics["incomplete_reason"] == "interrupted"
    assert metrics["exit_code"] == 130
    assert run.left() == []


def test_a_sigkilled_launcher_leaves_no_process_and_a_readable_recording(tmp_path: Path) -> None:
    with Run(tmp_path, "--duration", "600", "--speed", "40") as run:
        run.wait_started()
        time.sleep(2.0)
        children = children_of(run.proc.pid)
        assert len(children) == 7, [cmdline(p) for p in children]
        roles = " ".join(role_line(p) for p in children)
        for word in (" world ", " channel ", " router ", " recorder ", " agent --id 0 ", " agent --id 2 "):
            assert word in roles, word
        run.proc.send_signal(signal.SIGKILL)
        run.proc.wait(timeout=5)
        assert run.left(within_s=5.0) == []
    from rerun.chunk import RrdReader

    chunks = list(RrdReader(str(run.out / "recording.rrd")).stream())
    assert len(chunks) > 0


def test_start_failure_and_bad_input_exit_codes(tmp_path: Path) -> None:
    bad = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "run", "--quiet", "--agents", "17", "--out", str(tmp_path / "bad")],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and "agents.count" in bad.stderr and "Traceback" not in bad.stderr
    assert not (tmp_path / "bad").exists()
    broken = tmp_path / "broken.toml"
    broken.write_text("[run]\nduration_s = 10.0\n[agents]\ncount = 2\n[[kills]]\nagent = 3\ntime_s = 5.0\n")
    bad = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "run", "--quiet", "--scenario", str(broken)],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and "kills[0].agent" in bad.stderr
    run = Run(tmp_path, "--duration", "20")
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and run.proc.poll() is None:
        channel = [p for p in children_of(run.proc.pid) if " channel " in role_line(p)]
        if channel:
            os.kill(channel[0], signal.SIGKILL)  # before it is ready: the world cannot start without it
            break
        time.sleep(0.01)
    assert run.finish() == 1, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["complete"] is False and metrics["incomplete_reason"] == "start_failed"
    assert "channel died before the mission started (signal 9)" in run.stderr
    assert run.left() == []


@pytest.mark.parametrize("agents", [1, 7, 16])
def test_any_team_size_runs_to_the_end(tmp_path: Path, agents: int) -> None:
    run = Run(tmp_path, "--agents", str(agents), "--duration", "40")
    assert run.finish(timeout=180) == 0, run.stderr[-2000:]
    metrics = run.metrics()
    assert metrics["complete"] is True and metrics["n_agents"] == agents
    assert metrics["sim_duration_s"] == pytest.approx(40.0)
    assert all(a["alive_until_s"] is None for a in metrics["agents"].values())
    if agents == 1:
        assert "kills[0] names AUV 1" in run.stderr and "dropped" in run.stderr
    assert run.left() == []


def _by_hand(tmp_path: Path, spawner, run_secret: str, duration_s: float) -> dict[str, subprocess.Popen]:
    """Router, channel, one AUV and the world started one by one, as a user (or docker-compose) would."""
    from auv_swarm.contract.config import dump_toml, load_scenario
    from auv_swarm.orchestrator.mission import procs

    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=duration_s, agents=1)
    scenario = scenario.replace(kills=(), run=dataclasses.replace(scenario.run, grace_s=1.0))
    path = tmp_path / "one.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    endpoint = f"tcp/127.0.0.1:{procs.free_port()}"
    common = ["--scenario", str(path), "--router", endpoint]
    started = {
        "router": spawner(
            procs.python_argv("auv_swarm", "router", "--listen", endpoint, "--agents", "1", "--grace-s", "1"),
            "router",
        )
    }
    procs.wait_for_line(started["router"], "router listening", timeout=30)
    started["channel"] = spawner(procs.python_argv("auv_swarm", "channel", *common), "channel")
    started["auv0"] = spawner(procs.python_argv("auv_swarm", "agent", "--id", "0", *common), "auv0")
    for name in ("channel", "auv0"):
        procs.wait_for_line(started[name], "ready", timeout=30)
    started["world"] = spawner(procs.python_argv("auv_swarm", "world", *common), "world")
    procs.wait_for_line(started["world"], "starting", timeout=30)
    return started


def test_processes_started_by_hand_end_with_the_mission(tmp_path: Path, spawner, run_secret: str) -> None:
    started = _by_hand(tmp_path, spawner, run_secret, duration_s=20.0)
    for name, proc in started.items():
        assert proc.wait(timeout=20) == 0, (name, Path(proc.log_path).read_text()[-1000:])
    assert "the world announced the end" in Path(started["channel"].log_path).read_text()
    assert "the mission is over and its clients have left" in Path(started["router"].log_path).read_text()


def test_processes_started_by_hand_end_when_the_world_is_gone_past_the_grace(
    tmp_path: Path, spawner, run_secret: str
) -> None:
    started = _by_hand(tmp_path, spawner, run_secret, duration_s=100000.0)
    killed_at = time.monotonic()
    started["world"].send_signal(signal.SIGKILL)
    for name in ("router", "channel", "auv0"):
        assert started[name].wait(timeout=10) == 1, name
        assert "the world's liveliness has been gone for more than 1 s" in Path(started[name].log_path).read_text()
    assert time.monotonic() - killed_at < 5.0
