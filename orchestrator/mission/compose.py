"""The docker-compose file of an N-AUV swarm (`auv-swarm compose`, :mod:`auv_swarm.orchestrator.cli.compose`).

The checked-in ``docker-compose.yml`` is this generator's output for 3 AUVs (a test
keeps them equal). The file follows the Compose Specification with nothing
v2-only (no top-level ``version:`` or ``name:``), so docker-compose 1.29 and
``docker compose`` v2 both run it. One container per process; the service names
are the hostnames (clients connect to ``tcp/router:7447``, no multicast scouting).

Start order: ``setup`` (one-shot: run folder, scenario.toml) and ``credentials``
(one-shot: one password file per process) complete first; then the router;
then the channel, the AUVs, the recorder and the collector, which retry the
router until ``CONNECT_RETRY_S``; the world waits for all of them by their
liveliness tokens (no healthchecks: each is a ``docker exec`` per interval).
Every process ends with the mission, so ``docker-compose up`` returns; the
collector's exit status is the mission's exit code.
"""

from __future__ import annotations

import json
from typing import Any

from auv_swarm.bus import credentials, zbus

ROUTER_PORT = 7447
WEB_PORT = 9090
IMAGE = "auv-swarm:latest"
SCENARIO_FILE = "/runs/latest/scenario.toml"
ROUTER = f"tcp/router:{ROUTER_PORT}"
SERVICE_USERS = ("world", "channel", "recorder", "orchestrator")
"""Zenoh users with a service of their own (besides the AUVs); the collector logs in as ``orchestrator``."""


CREDENTIALS_DIR = "${CREDENTIALS_DIR:-./.credentials}"
BLAS_FROM_HOST: dict[str, None] = {"OPENBLAS_CORETYPE": None, "OPENBLAS_NUM_THREADS": None}
"""Passed through from the host when set there (a null value in compose): OpenBLAS picks its kernels by CPU
(e.g. Haswell or SkylakeX), and their last bits differ in small LAPACK solves, enough to flip a borderline
outlier gate; with the host's settings the containers compute what `auv-swarm run` computes, bit for bit."""


def secret_folders(agents: int) -> list[str]:
    """The credential folders of the compose file (``<CREDENTIALS_DIR>/<name>/``), one per container that logs in.

    Each is bind-mounted read-only into its own container only, at ``/run/secrets/<name>/``
    (``password``, the router's ``users.txt``): a folder, because ``docker compose`` v2 checks every mount's
    source exists when it creates the containers, before the ``credentials`` service writes the files; a
    mount, not a compose ``secrets:`` entry, because a secret's ``file`` must be a file (docker-compose 1.29
    warns ``uses an undefined secret file`` for a folder on every command)."""
    return [credentials.ROUTER_FOLDER, *(u for u in zbus.users(agents) if u in SERVICE_USERS or u.startswith("auv"))]


def _credentials_mount(name: str) -> str:
    """The read-only mount of the credential folder ``name`` at ``/run/secrets/<name>``."""
    return f"{CREDENTIALS_DIR}/{name}:/run/secrets/{name}:ro"


def _service(command: list[str], *, user_name: str | None = None, extra_env: dict[str, str] | None = None) -> dict:
    """A long-running service of the swarm: the image, the run folder, its own password, its log file."""
    env = {
        "AUVSWARM_ROUTER": ROUTER,
        "AUVSWARM_CONNECT_RETRY_S": "${CONNECT_RETRY_S:-60}",
        "AUVSWARM_LOG_FILE": f"/runs/latest/logs/{command[0] if user_name is None else user_name}.log",
        "HOME": "/tmp",
        "MPLCONFIGDIR": "/tmp/matplotlib",
        **BLAS_FROM_HOST,
        **(extra_env or {}),
    }
    service: dict[str, Any] = {
        "image": IMAGE,
        "init": True,
        "user": "${AUVSWARM_UID:-0}:${AUVSWARM_GID:-0}",
        "command": command,
        "environment": env,
        "volumes": ["${RUNS_DIR:-./runs}:/runs"],
        "depends_on": {
            "setup": {"condition": "service_completed_successfully"},
            "credentials": {"condition": "service_completed_successfully"},
        },
    }
    if user_name is not None:
        env[credentials.PASSWORD_FILE_ENV] = f"/run/secrets/{user_name}/password"
        service["volumes"].append(_credentials_mount(user_name))
    return service


def compose_spec(agents: int) -> dict[str, Any]:
    """The compose file for ``agents`` AUVs, as data."""
    scen = ["--scenario", SCENARIO_FILE]
    client = [*scen, "--router", ROUTER]
    after_router = {"router": {"condition": "service_started"}}
    services: dict[str, Any] = {
        "setup": {
            "image": IMAGE,
            "build": {"context": ".", "args": {"BASE_IMAGE": "${BASE_IMAGE:-python:3.11-slim}"}},
            "user": "${AUVSWARM_UID:-0}:${AUVSWARM_GID:-0}",
            "command": ["collect", "--prepare", "--runs", "/runs", "--compose-agents", str(agents)],
            "environment": {
                "SCENARIO": "${SCENARIO:-paper-3.2-challenging}",
                "SEED": "${SEED:-}",
                "DURATION": "${DURATION:-}",
                "RUN_ID": "${RUN_ID:-}",
                "FORCE": "${FORCE:-0}",
                "HOME": "/tmp",
            },
            "working_dir": "/scenarios",
            "volumes": ["${RUNS_DIR:-./runs}:/runs", "${SCENARIOS_DIR:-.}:/scenarios:ro"],
        },
        "credentials": {
            "image": IMAGE,
            "user": "${AUVSWARM_UID:-0}:${AUVSWARM_GID:-0}",
            "command": [
                "credentials",
                "--out",
                "/credentials",
                "--agents",
                str(agents),
                "--folders",
                "--run-folder",
                "/runs/latest",
            ],
            "volumes": [f"{CREDENTIALS_DIR}:/credentials", "${RUNS_DIR:-./runs}:/runs:ro"],
            "depends_on": {"setup": {"condition": "service_completed_successfully"}},
        },
        "router": {
            **_service(
                ["router", "--listen", f"tcp/0.0.0.0:{ROUTER_PORT}", "--agents", str(agents), *scen],
                extra_env={credentials.USERS_FILE_ENV: f"/run/secrets/{credentials.ROUTER_FOLDER}/users.txt"},
            ),
            "volumes": ["${RUNS_DIR:-./runs}:/runs", _credentials_mount(credentials.ROUTER_FOLDER)],
        },
        "channel": _service(["channel", *client], user_name="channel"),
    }
    services["channel"]["depends_on"] |= after_router
    for a in range(agents):
        svc = _service(["agent", "--id", str(a), *client], user_name=f"auv{a}")
        svc["depends_on"] |= after_router
        services[f"agent{a}"] = svc
    services["recorder"] = _service(
        ["recorder", *client, "--out", "/runs/latest", "--web-viewer", f"viewer:${{WEB_GRPC_PORT:-{WEB_PORT + 1}}}"],
        user_name="recorder",
    )
    services["recorder"]["depends_on"] |= after_router
    services["collector"] = _service(
        ["collect", *client, "--out", "/runs/latest", "--host-runs", "${RUNS_DIR:-./runs}"], user_name="orchestrator"
    )
    services["collector"]["environment"]["AUVSWARM_LOG_FILE"] = "/runs/latest/logs/collector.log"
    services["collector"]["depends_on"] |= after_router
    world_cmd = ["world", *client, "--wait-for", "recorder,orchestrator", "--speed", "${SPEED:-0}"]
    services["world"] = _service(world_cmd, user_name="world")
    services["world"]["depends_on"] |= {name: {"condition": "service_started"} for name in services if name != "world"}
    web, grpc = f"${{WEB_PORT:-{WEB_PORT}}}", f"${{WEB_GRPC_PORT:-{WEB_PORT + 1}}}"
    services["viewer"] = {
        "image": IMAGE,
        "init": True,
        "profiles": ["viewer"],
        # every interface of its container (the recorder streams in over the compose network), published on the
        # host's loopback only: neither port authenticates anyone (docs/web-viewer.md)
        "command": [
            "view",
            "--web",
            web,
            "--web-grpc-port",
            grpc,
            "--web-bind",
            "0.0.0.0",
            "--public-host",
            "localhost",
        ],
        "environment": {"HOME": "/tmp"},
        "ports": [f"127.0.0.1:{web}:{web}", f"127.0.0.1:{grpc}:{grpc}"],
    }
    return {"services": services}


def _yaml(value: Any, indent: int = 0) -> list[str]:
    """Block-style YAML of dicts, lists and scalars (scalars as JSON strings, which YAML reads the same)."""
    pad = "  " * indent
    lines: list[str] = []
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, dict) and item:
                lines += [f"{pad}{key}:", *_yaml(item, indent + 1)]
            elif isinstance(item, list) and item and any(isinstance(x, (dict, list)) for x in item):
                lines += [f"{pad}{key}:", *_yaml(item, indent + 1)]
            else:
                lines.append(f"{pad}{key}: {_flow(item)}")
    elif isinstance(value, list):
        for item in value:
            lines.append(f"{pad}- {_flow(item)}")
    return lines


def _flow(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_flow(x) for x in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str) and value.replace("_", "").replace("-", "").isalnum() and not value[:1].isdigit():
        return value if value not in ("true", "false", "null", "yes", "no", "on", "off") else json.dumps(value)
    return json.dumps(value)


def compose_text(agents: int) -> str:
    """The compose file for ``agents`` AUVs, as YAML text."""
    header = [
        f"# Generated by `auv-swarm compose --agents {agents}`: edit orchestrator/mission/compose.py, not this file.",
        "# Build: BASE_IMAGE=$(docker/base-image.sh | tail -1) docker-compose build   (docs/containers.md)",
        "# Run:   docker-compose up   (settings from the environment or .env: SCENARIO SEED DURATION RUN_ID SPEED FORCE)",
        "# Watch: docker-compose --profile viewer up, then open http://localhost:9090 (docs/web-viewer.md)",
    ]
    return "\n".join(header + _yaml(compose_spec(agents))) + "\n"
