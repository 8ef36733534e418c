"""Argument handling shared by every process shell (world, channel, agent, router, recorder).

Each process can be started alone from a shell with a scenario and a router
endpoint, and prints a sample config (``--example``) and the keys it publishes
and subscribes (``--interface``), as MOOS-IvP apps do.
"""

from __future__ import annotations

import argparse
import os
import queue
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, Protocol

import tomli_w

from auv_swarm.bus import credentials, tls
from auv_swarm.bus.lifeline import Lifeline, parent_from_env
from auv_swarm.contract import wire
from auv_swarm.contract.config import (
    DEFAULT_SCENARIO,
    EXAMPLE_TOML,
    LIST_ITEMS,
    ConfigError,
    Scenario,
    describe,
    load_scenario,
)

if TYPE_CHECKING:
    from auv_swarm.bus.zbus import ZenohBus


def add_common_args(parser: argparse.ArgumentParser, *, router: bool = True) -> None:
    """--scenario, --seed, --duration, --agents, --example, --interface; with ``router``: --router, --tls-dir and
    the credential options (``bus.credentials.add_password_args``)."""
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO, help="built-in scenario name or TOML path")
    parser.add_argument("--seed", type=int, default=None, help="override run.seed")
    parser.add_argument("--duration", type=float, default=None, help="override run.duration_s (sim seconds)")
    parser.add_argument("--agents", type=int, default=None, help="override agents.count")
    if router:
        parser.add_argument(
            "--router",
            default=os.environ.get("AUVSWARM_ROUTER", "tcp/127.0.0.1:7447"),
            help="zenoh router endpoint (env AUVSWARM_ROUTER)",
        )
        parser.add_argument(
            "--tls-dir",
            type=Path,
            default=os.environ.get(credentials.TLS_DIR_ENV) or None,
            help=f"mutual TLS to a tls/HOST:PORT router with ca.pem and this process's <user>.pem and <user>.key "
            f"from this folder instead of a password (env {credentials.TLS_DIR_ENV}; auv-swarm credentials --tls DIR)",
        )
        credentials.add_password_args(parser)
    parser.add_argument("--example", action="store_true", help="print a sample scenario config and exit")
    parser.add_argument("--interface", action="store_true", help="print the keys this process uses and exit")


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    """Load the scenario and apply the CLI overrides; exit with a clear message on a bad value.

    A physical scenario's TL table must be readable here (``builtin:``, a file, or the cache entry that
    ``auv-swarm ocean`` or ``auv-swarm run`` wrote): a role process never builds one (docs/ocean.md)."""
    from auv_swarm.contract.tltable import ocean_for

    try:
        scenario = load_scenario(args.scenario).with_overrides(
            seed=args.seed, duration_s=args.duration, agents=args.agents
        )
        ocean_for(scenario)
        return scenario
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from exc


CONNECT_TRIES = 5
"""How many times a process shell tries to open its session before it gives up."""


def login(args: argparse.Namespace, user: str) -> dict[str, object]:
    """How ``user`` logs in to ``args.router``: ``{"tls_dir": DIR}`` (its certificate, checked here) for a ``tls/``
    router, else ``{"password": ...}`` (``credentials.password``). Exits 2 with one line on stderr when the endpoint,
    the certificate or the password will not do."""
    from auv_swarm.bus.zbus import check_endpoint

    tls_dir = getattr(args, "tls_dir", None)
    try:
        check_endpoint(args.router)
        tls.check_scheme(args.router, tls_dir, "--tls-dir")
    except ValueError as exc:
        _refuse(f"--router: {exc}")
    try:
        if tls_dir is None:
            return {"password": credentials.password(args, user)}
        if args.password_file or args.password_fd is not None or args.insecure_dev:
            raise ValueError(
                "--tls-dir logs in with a certificate: no --password-file, --password-fd or --insecure-dev"
            )
        tls.check_identity(tls_dir, user)
    except ValueError as exc:  # CredentialError and TLSError too
        _refuse(str(exc))
    return {"tls_dir": tls_dir}


def _refuse(text: str) -> NoReturn:
    print(f"error: {text}", file=sys.stderr, flush=True)
    raise SystemExit(2)


def connect(args: argparse.Namespace, user: str) -> ZenohBus:
    """Open this process's bus to ``args.router`` as ``user`` with its own password, or its own certificate under
    ``--tls-dir`` (:func:`login`).

    Exits with one line on stderr: code 2 without usable credentials, 1 when the
    router refused the login ("authentication failed") or cannot be reached after
    ``CONNECT_TRIES`` tries one second apart (a router restarting, a loaded host).
    """
    from auv_swarm.bus.zbus import ZenohBus

    how = login(args, user)
    for attempt in range(1, CONNECT_TRIES + 1):
        try:
            return ZenohBus(args.router, user=user, **how)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr, flush=True)
            raise SystemExit(1) from None
        except ConnectionError as exc:
            if attempt == CONNECT_TRIES:
                print(f"error: {exc}", file=sys.stderr, flush=True)
                raise SystemExit(1) from None
            time.sleep(1.0)
    raise AssertionError("unreachable")


class Node(Protocol):
    """What :func:`serve` runs: the keys a shell listens to, and what to publish for one sample."""

    def subscriptions(self) -> list[str]: ...

    def on_bytes(self, key: str, data: bytes) -> list[tuple[str, bytes]]: ...


def serve(
    args: argparse.Namespace,
    user: str,
    name: str,
    token: str | Callable[[str], str],
    grace_s: float,
    node: Node,
    side: Mapping[str, Callable[[bytes], int | None]] | None = None,
) -> int:
    """Run ``node`` as a process shell until its mission ends; the shell's exit code.

    Connects as ``user`` (:func:`connect`), subscribes to ``node.subscriptions()`` and to ``side``'s keys,
    holds a :class:`bus.lifeline.Lifeline` of ``grace_s`` (s), declares the liveliness ``token`` (a function of
    the bus session's id gives a token per session) and
    prints ``{name} ready on {router}``. Then every sample, in arrival order, goes to ``node.on_bytes`` and
    what it returns is published; a sample on a ``side`` key goes to that key's handler instead, and a
    handler's non-None return ends the shell with that exit code.
    """
    from auv_swarm.bus.zbus import shutdown_event

    side = side or {}
    inbound: queue.Queue[tuple[str, bytes]] = queue.Queue()
    stop = shutdown_event()
    lifeline = Lifeline(grace_s, parent_from_env())
    with connect(args, user) as bus:
        for key in [*node.subscriptions(), *side]:
            bus.subscribe(key, lambda key, data: inbound.put((key, data)))
        lifeline.attach(bus, stop, name)
        bus.declare_liveliness(token(bus.session_id) if callable(token) else token)
        print(f"{name} ready on {args.router}", flush=True)
        while not stop.is_set():
            try:
                key, data = inbound.get(timeout=0.2)
            except queue.Empty:
                continue
            handler = side.get(key)
            if handler is None:
                for out_key, payload in node.on_bytes(key, data):
                    bus.publish(out_key, payload)
                continue
            code = handler(data)
            if code is not None:
                return code
    return lifeline.shell_exit_code(stop)


def example_text(sections: Sequence[str] | None = None) -> str:
    """A sample scenario, every key with its range and meaning, as TOML comments."""
    lines = ["# auv-swarm scenario: every key, its allowed range and meaning (defaults shown)", ""]
    current = None
    defaults = Scenario().to_dict()
    for key, rng, doc in describe():
        section, _, name = key.rpartition(".")
        if key.partition(".")[0].partition("[")[0] in LIST_ITEMS or (sections is not None and section not in sections):
            continue  # kills, faults: arrays of tables, shown as the comment at the end
        if section != current:
            lines.append(f"\n[{section}]" if section else "")
            current = section
        value = defaults
        for part in key.split("."):
            value = value[part]
        lines.append(f"# {doc}{' ' + rng if rng else ''}")
        lines.append(tomli_w.dumps({name: value}).rstrip("\n"))
    fields = [f"#   {key}: {doc}{' ' + rng if rng else ''}" for key, rng, doc in describe() if "[]." in key]
    sample = [f"# {line}".rstrip() for line in EXAMPLE_TOML.splitlines()]
    lines.append("\n# scheduled failures (kills) and faults (drills), any number of each; their fields:")
    lines += [*fields, "# for example:", *sample]
    return "\n".join(lines)


def interface_text(component: str) -> str:
    """The keys ``component`` publishes and subscribes, from the wire contract's key table."""
    rows = wire.interface_rows(component)
    pubs = [f"  {r.key:<36} {r.message}" for r in rows if component in r.publisher]
    subs = [f"  {r.key:<36} {r.message}" for r in rows if component in r.subscribers]
    return "\n".join([f"{component} publishes:", *pubs, f"{component} subscribes:", *subs])


def handle_info_flags(args: argparse.Namespace, component: str, sections: Sequence[str] | None = None) -> bool:
    """Print --example / --interface if asked; True when the process should exit."""
    if args.example:
        print(example_text(sections))
        return True
    if args.interface:
        print(interface_text(component))
        return True
    return False
