"""``auv-swarm sweep`` on its default LocalCluster, as a user runs it: rows equal ``auv-swarm run``'s metrics,
resume, a sweep over the DMPC and an installed plug-in whose missions raise or kill their worker, Ctrl-C, a client SIGKILLed (no worker left, integrity, resume without
duplicates), bad input. Every process is started in its own session and stopped by pid."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from auv_swarm.contract.config import dump_toml, load_scenario
from auv_swarm.orchestrator.mission import procs
from auv_swarm.orchestrator.sweep import store as st
from auv_swarm.results.metrics import comparable

pytestmark = pytest.mark.integration

SCENARIO = "paper-3.3-sim2"


def sweep(*args: str, env: dict[str, str] | None = None, timeout: float = 240.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*procs.python_argv("auv_swarm.orchestrator.cli.sweep"), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )


def spawn_sweep(out: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.Popen:
    return procs.spawn(
        [*procs.python_argv("auv_swarm.orchestrator.cli.sweep"), *args, "--out", str(out)],
        "sweep",
        env=env,
        log_path=out.parent / f"{out.name}.log",
    )


def done_rows(out: Path) -> int:
    try:
        db = sqlite3.connect(f"file:{out / st.STORE_FILE}?mode=ro", uri=True, timeout=5)
        try:
            return db.execute("SELECT count(*) FROM missions WHERE status = 'done'").fetchone()[0]
        finally:
            db.close()
    except sqlite3.OperationalError:
        return 0


def wait_rows(out: Path, n: int, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while done_rows(out) < n:
        assert proc.poll() is None, procs.read_log(proc)
        assert time.monotonic() < deadline, procs.read_log(proc)
        time.sleep(0.1)


def test_rows_equal_auv_swarm_run_and_the_same_command_resumes(tmp_path: Path) -> None:
    out = tmp_path / "s"
    args = [
        SCENARIO,
        "planner.method=dmpc,dec-mpc",
        "channel.pdr=0.5",
        "--seeds",
        "1-2",
        "--duration",
        "60",
        "--out",
        str(out),
        "--workers",
        "2",
        "--json",
    ]
    done = sweep(*args)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["axes"] == ["planner.method", "channel.pdr"] and len(summary["cells"]) == 2
    assert summary["cells"][0]["stats"]["tracking_error_mean_m"]["n"] == 2
    rows = st.read_rows(out)
    assert len(rows) == 4 and {r["status"] for r in rows} == {"done"}
    cols = [c for c in rows[0] if c not in ("planner.method", "channel.pdr")]
    assert cols == list(st.FIXED_NAMES)
    metrics = json.loads(rows[0]["metrics"])
    numbers = [k for k, v in metrics.items() if isinstance(v, int | float) or v is None]
    assert sorted(set(numbers) - {"seed", "after_first_kill", "incomplete_reason", "error"}) == sorted(
        n for n, _ in st.METRIC_COLUMNS
    )
    for name in ("missions.parquet", "summary.md", "summary.json", "tracking_error_mean_m-vs-channel.pdr.png"):
        assert (out / name).is_file(), name
    # the row of dec-mpc seed 2 against auv-swarm run --mode inprocess of the same scenario, keys and seed
    row = next(r for r in rows if r["planner.method"] == "dec-mpc" and r["seed"] == 2)
    run_out = tmp_path / "run"
    toml = tmp_path / "keys.toml"
    toml.write_text(dump_toml(load_scenario(SCENARIO).with_keys({"planner.method": "dec-mpc", "channel.pdr": 0.5})))
    ran = subprocess.run(
        [
            *procs.python_argv("auv_swarm.orchestrator.cli.run"),
            "--scenario",
            str(toml),
            "--mode",
            "inprocess",
            "--seed",
            "2",
            "--duration",
            "60",
            "--out",
            str(run_out),
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert ran.returncode == 0, ran.stderr
    expected = json.loads((run_out / "metrics.json").read_text())
    got = json.loads(row["metrics"])
    assert comparable(got) == comparable(json.loads(json.dumps(expected)))
    assert row["tracking_error_mean_m"] == expected["tracking_error_mean_m"]
    again = sweep(*args[:-1])
    assert again.returncode == 0, again.stderr
    assert "0 done, 4 skipped, 0 failed / 4 missions" in again.stderr
    assert len(st.read_rows(out)) == 4


def test_a_sweep_over_dmpc_and_a_plugin_whose_missions_raise_has_failed_rows_and_exit_1(
    tmp_path: Path, fault_plugins: dict[str, str]
) -> None:
    """The installed plug-in ``fault-raise`` (tests/plugins/faults) raises in its plans of seed 2."""
    out = tmp_path / "f"
    args = [SCENARIO, "planner.method=dmpc,fault-raise", "--seeds", "2", "--duration", "60", "--out", str(out)]
    done = sweep(*args, "--workers", "1", env=fault_plugins)
    assert done.returncode == 1, done.stderr
    assert "error: 1 of 4 missions failed" in done.stderr and "Traceback" not in done.stderr
    rows = {(r["planner.method"], r["seed"]): r for r in st.read_rows(out)}
    failed = rows[("fault-raise", 2)]
    assert failed["status"] == "failed" and failed["complete"] == 0 and failed["exit_code"] == 1
    assert "planner 'fault-raise' raised RuntimeError: failure injected by the fault-raise planner" in failed["error"]
    assert json.loads(failed["metrics"])["incomplete_reason"] == "method_error"
    assert {k: r["status"] for k, r in rows.items() if k != ("fault-raise", 2)} == dict.fromkeys(
        [("dmpc", 1), ("dmpc", 2), ("fault-raise", 1)], "done"
    )
    plugin = {"kind": "planner", "name": "fault-raise", "ref": "auv_swarm_test_faults:RaiseOnSeed"}
    plugin |= {"distribution": "auv-swarm-test-faults", "version": "1.0.0"}
    assert json.loads(rows[("fault-raise", 1)]["plugins"]) == [plugin] == json.loads(failed["plugins"])
    assert json.loads(rows[("dmpc", 1)]["plugins"]) == []
    assert rows[("fault-raise", 1)]["tracking_error_mean_m"] == rows[("dmpc", 1)]["tracking_error_mean_m"]
    again = sweep(*args, "--workers", "1", env=fault_plugins)
    assert again.returncode == 1, again.stderr
    assert "0 done, 3 skipped, 1 failed" in again.stderr  # the failed one ran again


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["channel.pdr=0.5,2"], "1 of 2 grid cells are invalid: channel.pdr=2: channel.pdr must be in [0, 1]"),
        (["planner.method=dmpc,nope"], "planner.method=nope: planner.method must be one of"),
        (["channel.pdr"], "expected KEY=V1,V2"),
        (["--seeds", "3-1"], "--seeds must be A-B"),
        (["no-such-scenario"], "no-such-scenario"),
    ],
)
def test_bad_axes_and_values_exit_2_with_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    first = [] if args[0] == "no-such-scenario" else [SCENARIO]
    done = sweep(*first, *args, "--out", str(tmp_path / "b"))
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "b").exists()


def test_ctrl_c_exits_130_and_says_the_same_command_resumes(tmp_path: Path) -> None:
    out = tmp_path / "c"
    proc = spawn_sweep(out, SCENARIO, "--seeds", "1-12", "--workers", "2")
    try:
        wait_rows(out, 1, proc)
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole foreground group
        assert proc.wait(timeout=60) == 130
    finally:
        procs.stop(proc)
    log = procs.read_log(proc)
    assert "the same command resumes" in log and "Traceback" not in log
    assert not procs.group_alive(proc.pid)
    kept = done_rows(out)
    assert 1 <= kept < 12


def test_a_client_killed_leaves_no_worker_and_an_intact_store_that_resumes(tmp_path: Path) -> None:
    out = tmp_path / "k"
    args = [SCENARIO, "--seeds", "1-10", "--workers", "2"]
    proc = spawn_sweep(out, *args)
    try:
        wait_rows(out, 2, proc)
        os.kill(proc.pid, signal.SIGKILL)  # the client alone: its workers must notice and end
        proc.wait(timeout=10)
        deadline = time.monotonic() + 10.0
        while procs.group_alive(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not procs.group_alive(proc.pid), "a LocalCluster worker outlived its client by 10 s"
    finally:
        procs.stop(proc)
    db = sqlite3.connect(out / st.STORE_FILE)
    assert db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    before = db.execute("SELECT count(*) FROM missions").fetchone()[0]
    db.close()
    assert 2 <= before < 10
    done = sweep(*args, "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert f"{before} skipped" in done.stderr
    rows = st.read_rows(out)
    assert len(rows) == 10 and len({(r["scenario_sha256"], r["seed"]) for r in rows}) == 10


def test_a_folder_in_use_and_other_verbs(tmp_path: Path) -> None:
    out = tmp_path / "u"
    proc = spawn_sweep(out, SCENARIO, "--seeds", "1-8", "--workers", "1")
    try:
        wait_rows(out, 1, proc)
        second = sweep(SCENARIO, "--seeds", "1-8", "--workers", "1", "--out", str(out))
        assert second.returncode == 2 and "in use by another sweep" in second.stderr
    finally:
        procs.stop(proc)
    ran = subprocess.run(
        [
            *procs.python_argv("auv_swarm.orchestrator.cli.run"),
            "--scenario",
            SCENARIO,
            "--duration",
            "10",
            "--mode",
            "inprocess",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ran.returncode == 2 and "sweep.sqlite" in ran.stderr
    other = sweep(SCENARIO, "--seeds", "1-2", "--duration", "20", "--workers", "1", "--out", str(out))
    assert other.returncode == 2 and "another grid" in other.stderr
    forced = sweep(SCENARIO, "--seeds", "1-2", "--duration", "20", "--workers", "1", "--out", str(out), "--force")
    assert forced.returncode == 0, forced.stderr
    assert list(out.glob("aside-*/sweep.sqlite")) and len(st.read_rows(out)) == 2


def test_the_verb_is_registered() -> None:
    done = subprocess.run([sys.executable, "-P", "-m", "auv_swarm", "--help"], capture_output=True, text=True)
    if done.returncode != 0:
        done = subprocess.run(["auv-swarm", "--help"], capture_output=True, text=True)
    assert "sweep" in done.stdout


def test_a_sweep_file_with_named_variants_and_a_scenario_axis(tmp_path: Path) -> None:
    study = tmp_path / "geo.toml"
    study.write_text(
        "[sweep]\nseeds = 1\nduration = 20\n[sweep.axes]\n"
        'scenario = ["paper-3.3-sim1", "paper-3.3-sim2"]\n'
        "[sweep.axes.geometry]\n"
        'near = { "agents.positions_m" = [], "agents.spawn_box_m" = [-300.0, -300.0, 300.0, 300.0] }\n'
        'far = { "agents.positions_m" = [], "agents.spawn_box_m" = [1300.0, -150.0, 1600.0, 150.0] }\n'
    )
    out = tmp_path / "g"
    done = sweep(str(study), "--out", str(out), "--workers", "1", "--quiet")
    assert done.returncode == 0, done.stderr
    rows = st.read_rows(out)
    assert sorted((r["scenario"], r["geometry"]) for r in rows) == [
        ("paper-3.3-sim1", "far"),
        ("paper-3.3-sim1", "near"),
        ("paper-3.3-sim2", "far"),
        ("paper-3.3-sim2", "near"),
    ]
    assert len({r["scenario_sha256"] for r in rows}) == 4
    assert (out / "tracking_error_mean_m-bars.png").is_file()


def test_a_mission_whose_worker_dies_three_times_is_failed(tmp_path: Path, fault_plugins: dict[str, str]) -> None:
    """The installed plug-in ``fault-die`` (tests/plugins/faults) kills its worker in the missions of seed 2."""
    out = tmp_path / "d"
    args = [SCENARIO, "planner.method=fault-die", "--seeds", "3", "--duration", "20", "--out", str(out)]
    done = sweep(*args, "--workers", "2", env=fault_plugins)
    assert done.returncode == 1, done.stderr
    assert "error: 1 of 3 missions failed" in done.stderr and "Traceback" not in done.stderr
    rows = {r["seed"]: r for r in st.read_rows(out)}
    assert rows[2]["status"] == "failed" and rows[2]["error"] == "its worker died 3 times"
    assert rows[1]["status"] == rows[3]["status"] == "done"
