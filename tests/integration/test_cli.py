"""The CLI as a user meets it: the real ``auv-swarm`` entry point in subprocesses.

Help on every verb, usage and bad input as one line and exit 2, results folders
never overwritten by surprise, headless machines, progress in logs, and children
that run the parent's code.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from auv_swarm.bench import BENCHES
from auv_swarm.orchestrator.cli.main import VERBS
from auv_swarm.orchestrator.mission.procs import free_port
from tests.integration.cli_help import undocumented

pytestmark = pytest.mark.integration

AUV_SWARM = str(Path(sys.executable).with_name("auv-swarm"))
TIGHT_SCENARIO = """\
name = "tight"
[agents]
count = 5
spawn_box_m = [0.0, 0.0, 1.0, 1.0]
"""


def cli(*args: str, cwd: Path | None = None, env: dict[str, str] | None = None, timeout: float = 180.0):
    """Run ``auv-swarm ARGS`` to completion; returns the CompletedProcess (text)."""
    return subprocess.run(
        [AUV_SWARM, *args],
        cwd=cwd,
        env={**os.environ, **(env or {})},
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def cli_batch(
    commands: list[list[str]], cwd: Path | None = None, timeout: float = 240.0, envs: list[dict] | None = None
) -> list[tuple[int, str, str]]:
    """Run several ``auv-swarm`` commands at once; returns (exit code, stdout, stderr) of each, in order.

    ``envs``: one environment per command (default: this process's).
    """
    procs = [
        subprocess.Popen(
            [AUV_SWARM, *c],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=e or dict(os.environ),
        )
        for c, e in zip(commands, envs or [None] * len(commands), strict=True)
    ]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=timeout)
        results.append((p.returncode, out, err))
    return results


def one_line_error(stderr: str, progress: str | None = None) -> str:
    """The single line a failing command printed on stderr (asserts there is exactly one, and no traceback).

    ``progress``: the label of progress lines printed before the failure, left out. The warnings that a kill
    of the scenario falls after a ``--duration`` shorter than it (normal in these short runs) are left out too.
    """
    lines = [
        line
        for line in stderr.splitlines()
        if line.strip()
        and not (progress and line.startswith(progress + ":"))
        and not (line.startswith("warning: kills[") and "after the mission's end" in line)
    ]
    assert "Traceback" not in stderr and "panicked" not in stderr, stderr
    assert len(lines) == 1, stderr
    return lines[0]


SHORT = ["run", "--mode", "inprocess", "--duration", "10"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, int, str]]:
    """Short in-process runs, started together: name -> (results folder, exit code, stderr).

    recording: a plain run (its recording.rrd is rendered by the screenshot tests); forced: --force into a folder
    holding a metrics.json; new, empty, other: a new nested folder, an empty one, one holding only other files
    (new runs without --quiet, its stderr a pipe); viewer: --viewer with no display.
    """
    root = tmp_path_factory.mktemp("cli-runs")
    for name in ("forced", "empty", "other"):
        (root / name).mkdir()
    (root / "forced" / "metrics.json").write_text("{}", encoding="utf-8")
    (root / "other" / "notes.txt").write_text("mine", encoding="utf-8")
    headless = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    plan = {
        "recording": ([*SHORT, "--quiet", "--out", "recording"], None),
        "forced": ([*SHORT, "--quiet", "--out", "forced", "--force"], None),
        "new": ([*SHORT, "--out", "new/nested"], None),
        "empty": ([*SHORT, "--quiet", "--out", "empty"], None),
        "other": ([*SHORT, "--quiet", "--out", "other"], None),
        "viewer": ([*SHORT, "--quiet", "--viewer", "--out", "viewer"], headless),
    }
    results = cli_batch([c for c, _ in plan.values()], cwd=root, envs=[e for _, e in plan.values()])
    folders = {"new": root / "new" / "nested"}
    return {
        name: (folders.get(name, root / name), code, err) for name, (code, _out, err) in zip(plan, results, strict=True)
    }


@pytest.fixture(scope="module")
def recording(runs: dict[str, tuple[Path, int, str]]) -> Path:
    out, code, err = runs["recording"]
    assert code == 0, err
    return out


# Help ------------------------------------------------------------------------------------------------------------


def test_every_verb_and_bench_has_help_that_exits_0_and_documents_every_option() -> None:
    commands = [[verb, "--help"] for verb in VERBS] + [["bench", name, "--help"] for name in BENCHES]
    for command, (code, out, err) in zip(commands, cli_batch(commands), strict=True):
        assert code == 0, (command, err)
        assert out.startswith("usage: auv-swarm"), (command, out[:200])
        assert undocumented(out) == [], (command, undocumented(out))
        assert "``" not in out, (command, "raw reStructuredText in the help")
    run_help = cli("run", "--help").stdout
    assert "--mode {processes,inprocess}" in run_help and "--force" in run_help


def test_the_help_reader_catches_an_option_without_help() -> None:
    parser = argparse.ArgumentParser(prog="auv-swarm demo")
    parser.add_argument("--documented", help="a one-line help")
    parser.add_argument("--mode", choices=("processes", "inprocess"))
    parser.add_argument("--a-very-long-option-name-indeed", help="help on the next line")
    assert undocumented(parser.format_help()) == ["--mode {processes,inprocess}"]


def test_no_verb_lists_the_verbs_and_is_a_usage_error() -> None:
    (code, out, err), (hcode, hout, _), (bcode, bout, _), (ncode, _, nerr), (ucode, _, uerr) = cli_batch(
        [[], ["--help"], ["bench", "--help"], ["bench"], ["nosuchverb"]]
    )
    assert code == 2 and out == ""
    assert all(verb in err for verb in VERBS)
    assert hcode == 0 and all(verb in hout for verb in VERBS)
    assert bcode == 0 and all(name in bout for name in BENCHES)
    assert ncode == 2 and all(name in nerr for name in BENCHES)
    assert ucode == 2 and "unknown verb 'nosuchverb'" in uerr


# Bad input: one line, exit 2, before anything starts -------------------------------------------------------------


def test_bad_input_is_one_line_and_exit_2_everywhere(tmp_path: Path) -> None:
    (tmp_path / "garbage.toml").write_bytes(bytes(range(128, 256)) * 4)
    (tmp_path / "tight.toml").write_text(TIGHT_SCENARIO, encoding="utf-8")
    (tmp_path / "a-file").write_text("not a folder", encoding="utf-8")
    (tmp_path / "drift.toml").write_text("[navigation]\ndrift_fraction = -0.01\n", encoding="utf-8")
    cases = {
        "not a UTF-8 text file": ["run", "--scenario", "garbage.toml", "--out", "o1"],
        "cannot read the scenario file": ["run", "--scenario", str(tmp_path) + "/", "--out", "o2"],
        "is a file, not a folder": ["run", "--out", "a-file"],
        "/proc/auv-swarm-test: cannot write": ["run", "--out", "/proc/auv-swarm-test"],
        "/dev/null/x: cannot write": ["run", "--out", "/dev/null/x"],
        "--out /dev/null: is a file": ["run", "--out", "/dev/null"],
        "the world rejects scenario 'tight'": ["run", "--scenario", "tight.toml", "--mode", "inprocess", "--out", "o3"],
        "the world rejects": ["run", "--scenario", "tight.toml", "--out", "o4"],
        "unrecognized arguments: --bogus": ["scenarios", "--bogus"],
        "is neither a file nor a built-in scenario": ["bench", "swarm", "--scenario", "nope"],
        "'nope' is neither": ["bench", "table3", "--scenarios", "nope", "--seeds", "1"],
        "--scenarios: scenario 'nope' is neither": ["bench", "manoeuvre", "--scenarios", "nope", "--seeds", "1"],
        "endpoint must look like": ["agent", "--router", "bogus"],
        "endpoint must look like tcp": ["world", "--router", "bogus"],
        "must look like tcp/HOST:PORT": ["recorder", "--router", "bogus", "--out", "o5"],
        "navigation.drift_fraction must be in [0, 1], got -0.01": ["run", "--scenario", "drift.toml", "--out", "o6"],
        "fix_sigma_m = 5 m needs navigation.fix_period_s": [
            "sweep",
            "paper-3.3-sim2",
            "navigation.fix_sigma_m=5",
            "--out",
            "o7",
        ],
    }
    results = cli_batch(list(cases.values()), cwd=tmp_path)
    for (expected, command), (code, _out, err) in zip(cases.items(), results, strict=True):
        assert code == 2, (command, err)
        line = one_line_error(err) if "unrecognized" not in expected else err.strip().splitlines()[-1]
        assert expected in line, (command, line)
    written = [name for name in ("o1", "o2", "o3", "o4", "o6", "o7") if (tmp_path / name).exists()]
    assert not written, f"nothing written before the check, got {written}"


def test_out_on_a_read_only_file_system_is_refused_before_anything_starts(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(ro)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a read-only tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        done = cli("run", "--out", str(ro / "results"))
    finally:
        subprocess.run(["umount", str(ro)], check=True)
    assert done.returncode == 2
    assert "cannot write a results folder there (Read-only file system" in one_line_error(done.stderr)


# Results folders --------------------------------------------------------------------------------------------------


def test_a_folder_holding_results_is_refused_unless_forced(tmp_path: Path, runs) -> None:
    markers = ["metrics.json", "table3.json", "drill-report.json"]
    for marker in markers:
        (tmp_path / marker.split(".")[0]).mkdir()
        (tmp_path / marker.split(".")[0] / marker).write_text("{}", encoding="utf-8")
    results = cli_batch([[*SHORT, "--out", m.split(".")[0]] for m in markers], cwd=tmp_path)
    for marker, (code, _out, err) in zip(markers, results, strict=True):
        assert code == 2
        assert f"already holds results ({marker}); choose a new folder, or pass --force" in one_line_error(err)
        assert (tmp_path / marker.split(".")[0] / marker).read_text(encoding="utf-8") == "{}"
    out, code, err = runs["forced"]
    assert code == 0, err
    assert json.loads((out / "metrics.json").read_text(encoding="utf-8"))["sim_duration_s"] > 0


def test_a_new_empty_or_unrelated_folder_is_used(runs) -> None:
    for name in ("new", "empty", "other"):
        out, code, err = runs[name]
        assert code == 0, (name, err)
        assert (out / "metrics.json").is_file()
    assert (runs["other"][0] / "notes.txt").read_text(encoding="utf-8") == "mine"


def test_bench_table3_out_uses_the_same_check(tmp_path: Path) -> None:
    (tmp_path / "metrics.json").write_text("{}", encoding="utf-8")
    done = cli("bench", "table3", "--seeds", "1", "--scenarios", "paper-3.3-sim1", "--out", str(tmp_path))
    assert done.returncode == 2
    assert "already holds results (metrics.json)" in one_line_error(done.stderr)


def test_bench_sweep_runs_to_its_report_at_a_small_size() -> None:
    """The whole bench (direct, one and two workers, TLS beside plain TCP) on two 20 s missions: it once read a row
    field the worker no longer writes and failed at its very end, after every mission had run."""
    done = cli("bench", "sweep", "--seeds", "2", "--duration", "20", "--json", timeout=400.0)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout)
    assert out["missions"] == 2 and out["one_worker"]["workers"] == 1 and out["two_workers"]["workers"] == 2
    assert set(out["tls_cost"]) == {"tls", "tcp"}
    assert all(v["mission_engine_ms"] == v["mission_engine_ms"] for v in out["tls_cost"].values())  # not NaN


# Processes that cannot reach the router --------------------------------------------------------------------------


def test_an_auv_that_cannot_reach_the_router_says_so_in_one_line(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    password = tmp_path / "auv0.password"
    password.write_text("a-password-of-its-own\n", encoding="utf-8")
    password.chmod(0o600)
    done = cli("agent", "--id", "0", "--router", endpoint, "--password-file", str(password), timeout=60.0)
    assert done.returncode == 1
    assert f"error: router unreachable at {endpoint}" in one_line_error(done.stderr)


# Headless machines -------------------------------------------------------------------------------------------------


def test_screenshot_without_a_vulkan_driver_names_the_package(recording: Path, tmp_path: Path) -> None:
    done = cli(
        "view", str(recording), "--screenshot", str(tmp_path / "shot.png"), env={"VK_DRIVER_FILES": "/nonexistent.json"}
    )
    assert done.returncode == 1
    line = one_line_error(done.stderr)
    assert "no Vulkan driver" in line and "apt-get install mesa-vulkan-drivers" in line
    assert not (tmp_path / "shot.png").exists()


def test_screenshot_reads_the_viewer_when_its_driver_does_not_load(recording: Path, tmp_path: Path) -> None:
    manifest = tmp_path / "broken_icd.json"
    manifest.write_text(
        json.dumps(
            {"file_format_version": "1.0.0", "ICD": {"library_path": "/nonexistent/libvk.so", "api_version": "1.3.0"}}
        ),
        encoding="utf-8",
    )
    done = cli(
        "view", str(recording), "--screenshot", str(tmp_path / "shot.png"), env={"VK_DRIVER_FILES": str(manifest)}
    )
    assert done.returncode == 1
    assert "apt-get install mesa-vulkan-drivers" in one_line_error(done.stderr, progress="screenshot")


def test_view_without_a_display_says_how_to_render_headless(recording: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run(
        [AUV_SWARM, "view", str(recording)], env=env, capture_output=True, text=True, timeout=60.0, check=False
    )
    assert done.returncode == 1
    line = one_line_error(done.stderr)
    assert "no display" in line and "--screenshot" in line and f"auv-swarm view {recording} --web" in line


def test_a_closed_pipe_ends_every_verb_quietly() -> None:
    """``auv-swarm scenarios | head -1``: the reader goes away; no traceback, the shell's 141 (128 + SIGPIPE)."""
    for args in (["scenarios"], ["--help"], ["run", "--help"], ["bench", "--help"]):
        proc = subprocess.Popen([AUV_SWARM, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        proc.stdout.close()  # before the verb writes: its first write meets a closed pipe
        err = proc.stderr.read().decode()
        code = proc.wait(timeout=60)
        assert err == "", (args, err)
        assert code in (0, 141), (args, code)
    proc = subprocess.Popen([AUV_SWARM, "scenarios"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    assert proc.wait(timeout=60) == 141 and proc.stderr.read() == b""


def test_run_viewer_without_a_display_warns_once_and_keeps_recording(runs) -> None:
    out, code, err = runs["viewer"]
    assert code == 0, err
    assert "warning: --viewer: no display" in one_line_error(err)
    assert (out / "recording.rrd").stat().st_size > 0


# Progress ---------------------------------------------------------------------------------------------------------


def test_progress_into_a_log_is_plain_lines(runs) -> None:
    _out, code, err = runs["new"]
    assert code == 0, err
    assert "\r" not in err
    lines = [line for line in err.splitlines() if line.startswith("mission:")]
    assert len(lines) >= 2 and "100%" in lines[-1], err


# Children run the parent's code -------------------------------------------------------------------------------------


def test_children_import_the_parents_packages_not_the_current_folders(tmp_path: Path) -> None:
    for package in ("auv_swarm", "orchestrator", "agent", "world", "contract"):
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text(
            'raise SystemExit("DECOY package imported: " + __file__)\n', encoding="utf-8"
        )
    done = cli("run", "--duration", "10", "--quiet", "--out", "out", cwd=tmp_path, timeout=240.0)
    logs = "".join(p.read_text(encoding="utf-8", errors="replace") for p in (tmp_path / "out" / "logs").glob("*.log"))
    assert "DECOY" not in logs + done.stderr
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "out" / "metrics.json").read_text(encoding="utf-8"))["ticks"] > 0
