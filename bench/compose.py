"""``auv-swarm bench compose [--json]``: a mission under docker-compose against the same mission of ``auv-swarm run``.

The mission's own time runs from the world's start event to its end event, as a
subscriber hears them (the collector under compose, the launcher's listener
for ``auv-swarm run``); start-up (``docker-compose up`` to the start event) and
shut-down (the end event to the last container's exit) are reported apart.
Also: the images' sizes, each container's memory in mid-mission
(``docker stats``), and whether both runs give the same metrics (wall and plan
times and the mode aside). Needs the images built (docs/containers.md).
Target (issue 14): mission time under compose at most 2x that of ``auv-swarm run``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import tempfile
import time
import uuid
from pathlib import Path

from auv_swarm.contract.config import DEFAULT_SCENARIO, load_scenario
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission.compose import IMAGE, secret_folders
from auv_swarm.results.metrics import comparable

ROOT = Path(__file__).resolve().parents[1]
TARGET_RATIO = 2.0
SHUTDOWN_WAIT_S = 60.0
"""Wall seconds the other containers get to exit after the collector did."""


class TimedLog:
    """A sink that notes the wall time of the world's start and end events."""

    def __init__(self) -> None:
        self.started: float | None = None
        self.ended: float | None = None

    def on_message(self, msg: object) -> None:
        kind = getattr(msg, "kind", None)
        if kind == "start" and self.started is None:
            self.started = time.monotonic()
        elif kind == "end" and self.ended is None:
            self.ended = time.monotonic()


def run_local(scenario_name: str, seed: int | None, duration: float | None, out: Path) -> tuple[dict, float, float]:
    """``auv-swarm run`` (processes mode, with the recorder): (metrics, mission s, whole run s)."""
    from auv_swarm.orchestrator.mission.api import run_mission

    scenario = load_scenario(scenario_name).with_overrides(seed=seed, duration_s=duration)
    log = TimedLog()
    start = time.monotonic()
    result = run_mission(scenario, mode="processes", out=out, sinks=[log])
    if not result.outcome.complete:
        raise RuntimeError(f"auv-swarm run was incomplete: {result.outcome.line}")
    whole = time.monotonic() - start
    if log.started is None or log.ended is None:
        raise RuntimeError("auv-swarm run ended without the world's start and end events")
    return result.metrics, log.ended - log.started, whole


def compose_cmd(project: str, compose_file: Path) -> list[str]:
    return ["docker-compose", "-p", project, "-f", str(compose_file), "--project-directory", str(ROOT)]


def project_containers(project: str) -> list[str]:
    """Ids of every container (running or not) of a compose project."""
    done = subprocess.run(
        ["docker", "ps", "-aq", "--filter", f"label=com.docker.compose.project={project}"],
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.split()


def container_state(cid: str) -> dict:
    done = subprocess.run(["docker", "inspect", cid], capture_output=True, text=True, check=True)
    info = json.loads(done.stdout)[0]
    return {"name": info["Config"]["Labels"].get("com.docker.compose.service", info["Name"]), **info["State"]}


def memory_mib(project: str) -> dict[str, float]:
    """Each running container's memory use now (MiB), by service name."""
    ids = [c for c in project_containers(project) if container_state(c)["Running"]]
    if not ids:
        return {}
    done = subprocess.run(
        ["docker", "stats", "--no-stream", "--format", "{{.ID}} {{.MemUsage}}", *ids],
        capture_output=True,
        text=True,
        timeout=60,
    )
    units = {"B": 1 / 2**20, "KiB": 1 / 1024, "MiB": 1.0, "GiB": 1024.0}
    out = {}
    for line in done.stdout.splitlines():
        cid, usage = line.split(" ", 1)
        m = re.match(r"([\d.]+)\s*([KMG]?i?B)", usage)
        if m:
            name = next(container_state(c)["name"] for c in ids if c.startswith(cid) or cid.startswith(c))
            out[name] = round(float(m.group(1)) * units[m.group(2)], 1)
    return out


def run_compose(
    scenario_name: str, seed: int | None, duration: float | None, runs: Path, timeout_s: float = 600.0
) -> dict:
    """One mission under docker-compose (detached, waited on by polling); always brought down."""
    project = f"auvbench{uuid.uuid4().hex[:8]}"
    compose_file = ROOT / "docker-compose.yml"
    env = {
        **os.environ,
        "SCENARIO": scenario_name,
        "SEED": "" if seed is None else str(seed),
        "DURATION": "" if duration is None else str(duration),
        "RUN_ID": "bench",
        "RUNS_DIR": str(runs),
        "CREDENTIALS_DIR": str(runs.parent / "credentials"),
        "SPEED": "0",
    }
    for name in secret_folders(3):  # as .credentials/ holds them in a clone (docker compose v2 needs them)
        (runs.parent / "credentials" / name).mkdir(parents=True, exist_ok=True)
    cmd = compose_cmd(project, compose_file)
    t0 = time.time()
    try:
        subprocess.run([*cmd, "up", "-d", "--no-build"], env=env, check=True, capture_output=True, timeout=300)
        memory: dict[str, float] = {}
        deadline = time.monotonic() + timeout_s
        log = runs / "bench" / "logs" / "collector.log"
        collector_done: float | None = None
        while time.monotonic() < deadline:
            states = [container_state(c) for c in project_containers(project)]
            if not memory and "mission started" in (log.read_text(errors="replace") if log.is_file() else ""):
                memory = memory_mib(project)
            collector = next((s for s in states if s["name"] == "collector"), None)
            if collector is not None and collector["Status"] == "exited" and collector_done is None:
                collector_done = time.monotonic()
            all_done = states and not any(s["Running"] for s in states)
            if all_done or (collector_done is not None and time.monotonic() - collector_done > SHUTDOWN_WAIT_S):
                break
            time.sleep(0.5)
        else:
            raise TimeoutError(f"the compose mission did not end within {timeout_s:g} s")
        finished = max(_unix(s["FinishedAt"]) for s in states) if all_done else None
        still_running = sorted(s["name"] for s in states if s["Running"])
    finally:
        subprocess.run([*cmd, "down", "-v", "--remove-orphans"], env=env, capture_output=True, timeout=300)
    text = log.read_text(errors="replace")
    started = float(re.search(r"mission started at unix time ([\d.]+)", text).group(1))
    ended = float(re.search(r"mission ended at unix time ([\d.]+)", text).group(1))
    metrics = json.loads((runs / "bench" / "metrics.json").read_text(encoding="utf-8"))
    return {
        "metrics": metrics,
        "mission_s": ended - started,
        "startup_s": started - t0,
        "shutdown_s": None if finished is None else finished - ended,
        "still_running": still_running,
        "exit_code": collector["ExitCode"],
        "memory_mib": memory,
    }


def _unix(stamp: str) -> float:
    """Docker's RFC 3339 time with nanoseconds -> unix seconds."""
    from datetime import datetime

    head, _, frac = stamp.rstrip("Z").partition(".")
    return datetime.fromisoformat(head + "+00:00").timestamp() + float("0." + (frac or "0")[:6])


def image_mib(tag: str) -> float | None:
    done = subprocess.run(["docker", "image", "inspect", "-f", "{{.Size}}", tag], capture_output=True, text=True)
    return round(int(done.stdout.strip()) / 2**20, 1) if done.returncode == 0 else None


def main(argv: list[str]) -> int:
    """Print the compose and ``auv-swarm run`` mission times, their ratio, start-up, shut-down, sizes, memory."""
    parser = argparse.ArgumentParser(prog="auv-swarm bench compose", description=plain_description(__doc__))
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO, help="built-in scenario name")
    parser.add_argument("--seed", type=int, default=None, help="override run.seed")
    parser.add_argument("--duration", type=float, default=None, help="sim seconds (default: the scenario's, 1500)")
    parser.add_argument("--base-image", default="auv-swarm-base:bookworm", help="reported with the app image size")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args(argv)
    if image_mib(args.base_image) is None:
        return fail(
            f"base image {args.base_image} not found: build it first (docker/base-image.sh, docs/containers.md)", 1
        )
    # The image must hold this checkout's code, or the comparison measures an older build: build (cached) first.
    build = subprocess.run(
        [*compose_cmd(f"auvbench{uuid.uuid4().hex[:8]}", ROOT / "docker-compose.yml"), "build"],
        env={**os.environ, "BASE_IMAGE": args.base_image},
        capture_output=True,
        text=True,
        timeout=1800,
    )
    if build.returncode != 0:
        tail = (build.stderr or build.stdout).strip().splitlines()[-1:] or ["no output"]
        return fail(f"docker-compose build failed: {tail[0]}", 1)
    with tempfile.TemporaryDirectory(prefix="auv-bench-compose-") as tmp:
        local, mission_local, whole_local = run_local(args.scenario, args.seed, args.duration, Path(tmp) / "run")
        comp = run_compose(args.scenario, args.seed, args.duration, Path(tmp) / "runs")
    ours, theirs = comparable(comp["metrics"]), comparable(local)
    differ = sorted(k for k in theirs if ours.get(k) != theirs[k])
    same = not differ
    ratio = comp["mission_s"] / mission_local if mission_local > 0 else None
    result = {
        "scenario": args.scenario,
        "sim_duration_s": local["sim_duration_s"],
        "run_mission_s": round(mission_local, 3),
        "run_whole_s": round(whole_local, 3),
        "compose_mission_s": round(comp["mission_s"], 3),
        "ratio": round(ratio, 2) if ratio else None,
        "compose_startup_s": round(comp["startup_s"], 3),
        "compose_shutdown_s": None if comp["shutdown_s"] is None else round(comp["shutdown_s"], 3),
        "compose_still_running_after_end": comp["still_running"],
        "compose_exit_code": comp["exit_code"],
        "metrics_equal": same,
        "metrics_differ": {k: {"compose": ours.get(k), "run": theirs[k]} for k in differ},
        "image_mib": {IMAGE: image_mib(IMAGE), args.base_image: image_mib(args.base_image)},
        "memory_mib": comp["memory_mib"],
        "memory_total_mib": round(sum(comp["memory_mib"].values()), 1),
        "target_ratio_max": TARGET_RATIO,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for key, value in result.items():
            print(f"{key:<22} {value}")
    return 0 if same and comp["exit_code"] == 0 else 1
