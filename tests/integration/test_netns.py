"""The swarm across hosts (issue 45): network namespaces as hosts, every link mutual TLS, latency added.

The router, the world, the channel, the recorder and the results collector (``auv-swarm collect``) run in one
namespace, each AUV in a namespace of its own joined to it by a veth link (tests/integration/netns.py), and
every AUV reaches the router through a relay that holds each byte ``DELAY_MS`` each way (tests/integration/
delay_relay.py; ``tc netem`` is not available on this project's CI). Each process is started by hand with its
role verb and ``--tls-dir``, as on real machines (docs/deploy.md). Needs root and iproute2: elsewhere the tests
are skipped with the reason printed.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from auv_swarm.bus import credentials, tls
from auv_swarm.contract.config import dump_toml, load_scenario
from auv_swarm.orchestrator.mission import procs
from auv_swarm.orchestrator.mission.api import run_mission
from auv_swarm.results.metrics import comparable
from tests.integration import netns

pytestmark = pytest.mark.integration

AGENTS = 3
DELAY_MS = 10
"""Added one-way latency between each AUV and the router (ms)."""
ROUTER_PORT, RELAY_PORT = 7447, 7448
"""Ports inside the namespaces (each namespace has ports of its own)."""
RELAY = Path(__file__).with_name("delay_relay.py")


@pytest.fixture(scope="module")
def can_make_hosts() -> None:
    reason = netns.unavailable()
    if reason is not None:
        print(f"skipped: {reason}")
        pytest.skip(reason)


@pytest.fixture
def hosts(can_make_hosts, tmp_path: Path):
    """:class:`netns.Hosts` for ``AGENTS`` AUVs; checked gone, namespaces and processes, at teardown."""
    made = netns.Hosts(AGENTS, tmp_path / "logs")
    yield made
    made.close()
    assert made.left() == []
    assert [p.pid for p in made.started if procs.pid_alive(p.pid)] == []


def scenario_file(tmp_path: Path, duration_s: float, tick_timeout_s: float = 5.0) -> Path:
    """paper-3.2-challenging (3 AUVs) cut to ``duration_s`` (sim s), seed 7, as a TOML every host reads."""
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=duration_s, seed=7)
    scenario = dataclasses.replace(
        scenario, name="netns-test", run=dataclasses.replace(scenario.run, tick_timeout_s=tick_timeout_s)
    )
    path = tmp_path / "scenario.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    return path


def start_mission(hosts: netns.Hosts, tmp_path: Path, scenario: Path, speed: float = 0.0) -> dict:
    """Issue the certificates and start every process of a mission on its host; name -> process."""
    folder = tmp_path / "tls"
    router_hosts = ("127.0.0.1", *(netns.infra_address(n) for n in range(AGENTS)))
    tls.write_zenoh(folder, credentials.users(AGENTS), router_hosts=router_hosts, days=1)
    inside = f"tls/127.0.0.1:{ROUTER_PORT}"
    common = ["--scenario", str(scenario), "--tls-dir", str(folder)]
    router = ["router", "--listen", f"tls/0.0.0.0:{ROUTER_PORT}", "--tls-dir", str(folder), "--agents", str(AGENTS)]
    started = {"router": hosts.spawn(hosts.infra, procs.python_argv("auv_swarm", *router), "router")}
    routes = [f"{netns.infra_address(n)}:{RELAY_PORT}=127.0.0.1:{ROUTER_PORT}" for n in range(AGENTS)]
    started["relay"] = hosts.spawn(hosts.infra, [sys.executable, str(RELAY), str(DELAY_MS), *routes], "relay")
    procs.wait_for_line(started["router"], "router listening", timeout=30.0)
    procs.wait_for_line(started["relay"], "relay listening", timeout=30.0)
    out = tmp_path / "run"
    infra = {
        "channel": ["channel"],
        "recorder": ["recorder", "--out", str(out)],
        "collect": ["collect", "--out", str(out), "--wait-s", "60"],
        "world": ["world", "--wait-for", "recorder,orchestrator", "--speed", str(speed)],
    }
    for name, argv in infra.items():
        started[name] = hosts.spawn(
            hosts.infra, procs.python_argv("auv_swarm", *argv, "--router", inside, *common), name
        )
    for n in range(AGENTS):
        dial = f"tls/{netns.infra_address(n)}:{RELAY_PORT}"
        argv = procs.python_argv("auv_swarm", "agent", "--id", str(n), "--router", dial, *common)
        started[f"auv{n}"] = hosts.spawn(hosts.auvs[n], argv, f"auv{n}")
    started["out"] = out
    return started


def finish(started: dict, timeout: float = 120.0) -> dict:
    """Wait for the collector's exit; the metrics it wrote."""
    collect = started["collect"]
    try:
        code = collect.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the collector did not finish within {timeout:g} s:\n{procs.read_log(started['world'])[-3000:]}")
    assert code == 0, procs.read_log(collect)[-3000:]
    return json.loads((started["out"] / "metrics.json").read_text())


def events(started: dict) -> list[dict]:
    lines = (started["out"] / "events.jsonl").read_text().splitlines()
    return [e for e in map(json.loads, lines) if not e["kind"].startswith("packet")]


def test_a_mission_across_hosts_over_mutual_tls_equals_the_one_host_run(hosts, tmp_path) -> None:
    scenario = scenario_file(tmp_path, duration_s=120.0)
    started = start_mission(hosts, tmp_path, scenario)
    metrics = finish(started)
    assert comparable(metrics) == comparable(run_mission(load_scenario(str(scenario))).metrics)
    assert (started["out"] / "recording.rrd").stat().st_size > 1000
    for name in ("auv0", "auv1", "auv2", "world", "channel"):
        assert started[name].wait(timeout=30.0) == 0, procs.read_log(started[name])[-2000:]
    assert "ready on tls/10.45.1.1" in procs.read_log(started["auv1"])


def test_a_removed_host_is_a_dead_auv_and_a_cut_link_a_hung_one(hosts, tmp_path) -> None:
    """AUV 1's link goes down for 2.5 s (its processes and session live on): the world stops waiting for it
    (``hung``) and takes it back when it answers (``resume``). AUV 2's whole host then vanishes, its link first: the
    router drops its session at zenoh's lease (10 s), the world declares it dead (``death``), and the mission ends
    complete with the two others, as after a killed AUV. The clock is paced at 10x (``--speed``) so that the faults,
    timed in wall seconds, land mid-mission."""
    scenario = scenario_file(tmp_path, duration_s=230.0, tick_timeout_s=1.0)
    started = start_mission(hosts, tmp_path, scenario, speed=10.0)
    procs.wait_for_line(started["world"], "processes up, starting", timeout=60.0)
    time.sleep(2.0)
    hosts.cut(1)
    time.sleep(2.5)
    hosts.cut(1, up=True)
    time.sleep(2.0)
    hosts.remove(2)
    metrics = finish(started)
    said = [(e["kind"], e["agent"]) for e in events(started)]
    assert ("hung", 1) in said and ("resume", 1) in said and ("death", 1) not in said, said
    assert ("death", 2) in said, said
    assert metrics["complete"] is True
    assert [metrics["agents"][a]["alive_until_s"] is None for a in ("0", "1", "2")] == [True, True, False]
    assert [k["agent"] for k in metrics["kills"]] == [2]
    assert "holds" not in procs.read_log(started["router"])  # no certificate seen twice on the way
