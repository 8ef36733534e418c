"""An installed plug-in package (tests/plugins/faults, entry points) in both modes, as ``auv-swarm run`` runs it:
its names are valid in every process, and its estimator raising is a failed mission with the same message, exit 1
and the plug-ins recorded, in process and as processes (whose AUV processes load it themselves)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest
import tomli_w

from auv_swarm.contract.config import load_scenario
from auv_swarm.orchestrator.mission import procs

pytestmark = pytest.mark.integration


@pytest.mark.parametrize("mode", ["inprocess", "processes"])
def test_an_installed_plugin_that_raises_fails_the_mission(tmp_path: Path, fault_plugins: dict[str, str], mode) -> None:
    scenario = tmp_path / "faults.toml"  # names this process does not know: the plug-in is not installed here
    data = load_scenario("paper-3.2-challenging").with_keys({"run.duration_s": 40.0}).to_dict()
    data["planner"]["method"] = data["estimator"]["method"] = "fault-raise"
    scenario.write_text(tomli_w.dumps(data), encoding="utf-8")
    out = tmp_path / "run"
    argv = [*procs.python_argv("auv_swarm"), "run", "--quiet", "--mode", mode, "--seed", "1"]
    done = subprocess.run(
        [*argv, "--scenario", str(scenario), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, **fault_plugins},
    )
    assert done.returncode == 1, done.stderr[-3000:]
    error = (
        "AUV 0: estimator 'fault-raise' raised ValueError: failure injected by the fault-raise estimator at t = 30 s"
    )
    assert f"run incomplete (method_error): {error}" in done.stderr and "Traceback" not in done.stderr, done.stderr
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert (m["complete"], m["incomplete_reason"], m["exit_code"], m["error"]) == (False, "method_error", 1, error)
    package = {"distribution": "auv-swarm-test-faults", "version": "1.0.0"}
    assert m["plugins"] == [
        {"kind": "planner", "name": "fault-raise", "ref": "auv_swarm_test_faults:RaiseOnSeed", **package},
        {"kind": "estimator", "name": "fault-raise", "ref": "auv_swarm_test_faults:RaiseAfter", **package},
    ]
    if mode == "processes":
        assert f"error: method_error: {error}" in (out / "logs" / "auv0.log").read_text(encoding="utf-8")
