"""``auv-swarm router``: the swarm's zenoh router, with user/password authentication and access control.

Every other process is a zenoh client of this router. Passwords are derived
from the run's secret (env ``AUVSWARM_SECRET``, else the documented dev
default), so the router and the clients agree without a password file.
"""

from __future__ import annotations

import argparse
import sys

from contract import shell, wire, zbus
from orchestrator.procs import free_port

EXAMPLE = """\
# start the router on a fixed port (AUVSWARM_SECRET must be the same for every process of the run):
export AUVSWARM_SECRET=$(python3 -c 'import secrets; print(secrets.token_hex(16))')
auv-swarm router --listen tcp/127.0.0.1:7447 --agents 3
# then, in other shells, clients connect to it:
auv-swarm channel --router tcp/127.0.0.1:7447 --scenario paper-3.2-challenging"""


def interface_text(agents: int, prefix: str = wire.PREFIX) -> str:
    """What the router does, and the access-control table it enforces."""
    lines = [
        "router: zenoh router (mode router, multicast scouting off); every other process connects as a client.",
        "authentication: zenoh usrpwd, password = HMAC-SHA256(AUVSWARM_SECRET, user) hex[:32].",
        "access control: default deny; per user:",
    ]
    for role in zbus.acl_roles(agents, prefix):
        lines.append(f"  {role.user}")
        for label, keys in (
            ("put", role.publish),
            ("subscribe", role.subscribe),
            ("liveliness token", role.tokens),
            ("watch liveliness", role.watch),
        ):
            if keys:
                lines.append(f"    {label:<17} {', '.join(keys)}")
    return "\n".join(lines)


def run(listen: str, acl: bool, auth: bool, agents: int) -> int:
    """Serve as the router on ``listen`` until SIGTERM/SIGINT; prints the endpoint once it listens."""
    stop = zbus.shutdown_event()
    creds = zbus.credentials(shell.secret(), agents) if auth else {}
    config = zbus.router_config(listen, creds, acl=acl and auth, agents=agents)
    with zbus.open_router(config):
        mode = "acl" if acl and auth else ("auth only" if auth else "open")
        print(f"router listening on {listen} ({mode}, {agents} agents)", flush=True)
        stop.wait()
    print("router stopped", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm router``."""
    parser = argparse.ArgumentParser(prog="auv-swarm router", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--listen", default=None, help="endpoint, e.g. tcp/127.0.0.1:7447 (default: a free loopback port)"
    )
    parser.add_argument("--agents", type=int, default=zbus.MAX_AGENTS, help="AUV users auv0..auv<N-1> (1..16)")
    parser.add_argument("--no-acl", action="store_true", help="no access control (authentication stays on)")
    parser.add_argument("--no-auth", action="store_true", help="no authentication and no access control (debugging)")
    parser.add_argument(
        "--scenario", default=None, help="refuse to start unless this scenario has --agents AUVs (compose files)"
    )
    parser.add_argument("--example", action="store_true", help="print a sample invocation and exit")
    parser.add_argument("--interface", action="store_true", help="print what the router does and its ACL, and exit")
    args = parser.parse_args(argv)
    if not 1 <= args.agents <= zbus.MAX_AGENTS:
        parser.error(f"--agents must be in [1, {zbus.MAX_AGENTS}], got {args.agents}")
    if args.example:
        print(EXAMPLE)
        return 0
    if args.interface:
        print(interface_text(args.agents))
        return 0
    if args.scenario is not None:
        from contract.config import ConfigError, load_scenario
        from orchestrator.collector import compose_refusal

        try:
            refusal = compose_refusal(load_scenario(args.scenario), args.agents)
        except ConfigError as exc:
            refusal = str(exc)
        if refusal is not None:
            print(f"error: {refusal}", file=sys.stderr, flush=True)
            return 2
    listen = args.listen or f"tcp/127.0.0.1:{free_port()}"
    try:
        return run(listen, acl=not args.no_acl, auth=not args.no_auth, agents=args.agents)
    except (ValueError, ConnectionError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
