"""``auv-swarm router``: the swarm's zenoh router, with user/password authentication and access control.

Every other process is a zenoh client of this router and logs in as its own user.
The router reads the user table (``user:password`` per line, zenoh's usrpwd
dictionary format) from ``--users-file`` / env ``AUVSWARM_USERS_FILE`` (or a pipe
from ``auv-swarm run``); ``auv-swarm credentials --out DIR`` writes one. Without
it the router refuses to start, unless ``--insecure-dev`` (public dev passwords).

Across hosts, ``--listen tls/ADDR:PORT --tls-dir DIR`` instead: mutual TLS, each
client known by the name on its certificate (``auv-swarm credentials --tls DIR``),
the same access control per name, and a warning when one name holds two sessions
(docs/deploy.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh

from auv_swarm.bus import credentials, tls, zbus
from auv_swarm.bus.lifeline import Lifeline, parent_from_env
from auv_swarm.contract import wire
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission.procs import free_port

LINGER_S = 10.0
"""After the world's end, the router waits at most this long (wall s) for its clients to leave."""
DEFAULT_GRACE_S = 10.0
"""Default of ``--grace-s``: the scenario key ``run.grace_s`` (the router reads no scenario)."""

EXAMPLE = """\
# fresh per-process passwords (DIR/<user>.password, mode 0600) and the router's table DIR/users.txt:
auv-swarm credentials --out creds --agents 3
auv-swarm router --listen tcp/127.0.0.1:7447 --agents 3 --users-file creds/users.txt
# then, in other shells, each process with its own password file:
auv-swarm channel --router tcp/127.0.0.1:7447 --password-file creds/channel.password
# across hosts: mutual TLS, one certificate per process, named as its user (docs/deploy.md):
auv-swarm credentials --tls tls --agents 3 --router-host ship.example.org
auv-swarm router --listen tls/0.0.0.0:7447 --agents 3 --tls-dir tls
auv-swarm agent --id 0 --router tls/ship.example.org:7447 --tls-dir tls"""


def interface_text(agents: int, prefix: str = wire.PREFIX) -> str:
    """What the router does, and the access-control table it enforces."""
    lines = [
        "router: zenoh router (mode router, multicast scouting off); every other process connects as a client.",
        "authentication: zenoh usrpwd; the user table comes from --users-file (one user:password per line);",
        "  with --tls-dir: mutual TLS, each client known by its certificate's common name (its user name).",
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


class SessionBus:
    """The two subscriptions a :class:`bus.lifeline.Lifeline` needs, on the router's own session."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.handles: list[object] = []

    def subscribe(self, key_expr: str, callback: Callable[[str, bytes], None]) -> None:
        sub = self.session.declare_subscriber(key_expr, lambda s: callback(str(s.key_expr), s.payload.to_bytes()))
        self.handles.append(sub)

    def subscribe_liveliness(self, key_expr: str, on_change: Callable[[str, bool], None], history: bool = True) -> None:
        def on_sample(sample: zenoh.Sample) -> None:
            on_change(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

        self.handles.append(self.session.liveliness().declare_subscriber(key_expr, on_sample, history=history))


class Clients:
    """Which client tokens are held, and whether the world closed the mission (router's end of the mission)."""

    def __init__(self, on_end: Callable[[], None] | None = None) -> None:
        self.lock = threading.Lock()
        self.tokens: set[str] = set()
        self.ended_at: float | None = None
        self.on_end = on_end

    def on_token(self, key: str, alive: bool) -> None:
        with self.lock:
            (self.tokens.add if alive else self.tokens.discard)(key)

    def on_event(self, _key: str, data: bytes) -> None:
        try:
            msg = wire.decode(data)
        except wire.DecodeError:
            return
        if isinstance(msg, wire.WorldEvent) and msg.kind in ("end", "abort") and self.ended_at is None:
            self.ended_at = time.monotonic()
            if self.on_end is not None:
                self.on_end()

    def done(self, now: float) -> bool:
        """True once the mission ended and every client has left (or ``LINGER_S`` passed since the end)."""
        if self.ended_at is None:
            return False
        with self.lock:
            left = {k for k in self.tokens if k != wire.liveliness_component("world")}
        return not left or now - self.ended_at > LINGER_S


def session_names(session: zenoh.Session, timeout_s: float = 1.0) -> dict[str, str]:
    """The router's session list, from its admin space (on under mutual TLS, :func:`zbus.router_config`): client
    zid -> the name its link authenticated with (its certificate's common name; "" for none)."""
    names: dict[str, str] = {}
    for reply in session.get(f"@/{session.zid()}/session/transport/unicast/*/link/*", timeout=timeout_s):
        if reply.ok is None:
            continue
        try:
            link = json.loads(reply.ok.payload.to_bytes())
        except ValueError:
            continue
        names[str(reply.ok.key_expr).split("/")[-3]] = str(link.get("auth_identifier") or "")
    return names


def shared_names(sessions: dict[str, str]) -> dict[str, list[str]]:
    """The names that more than one session of ``sessions`` (zid -> name) holds: name -> their zids."""
    held: dict[str, list[str]] = {}
    for zid, name in sessions.items():
        if name:
            held.setdefault(name, []).append(zid)
    return {name: sorted(zids) for name, zids in held.items() if len(zids) > 1}


class SessionWatch:
    """Under mutual TLS, one line on stderr when a certificate's name comes to hold a second session (a copy of
    its key in use, or a restarted process whose old session has not closed yet), and again after it was alone."""

    def __init__(self, poll_s: float = 1.0) -> None:
        self.poll_s = poll_s
        self.next_s = 0.0
        self.shared: set[str] = set()

    def poll(self, session: zenoh.Session, now: float) -> None:
        if now < self.next_s:
            return
        self.next_s = now + self.poll_s
        shared = shared_names(session_names(session))
        for name in sorted(set(shared) - self.shared):
            zids = ", ".join(shared[name])
            print(f"router: warning: certificate {name} holds {len(shared[name])} sessions ({zids})", file=sys.stderr)
        self.shared = set(shared)


def run(
    listen: str,
    acl: bool,
    creds: dict[str, str],
    agents: int,
    grace_s: float = DEFAULT_GRACE_S,
    tls_dir: Path | None = None,
) -> int:
    """Serve as the router on ``listen`` until the mission is over and its clients left, the world's token is gone
    longer than ``grace_s``, the launcher is gone, or SIGTERM/SIGINT; prints the endpoint once it listens.

    ``creds`` is the user table (user -> password); empty means no authentication and no ACL, unless ``tls_dir``
    (mutual TLS: each client is known by its certificate, :class:`SessionWatch` watches the names).
    """
    stop = zbus.shutdown_event()
    auth = bool(creds) or tls_dir is not None
    config = zbus.router_config(listen, creds, acl=acl and auth, agents=agents, tls_dir=tls_dir)
    lifeline = Lifeline(grace_s, parent_from_env())
    clients = Clients(on_end=lifeline.note_end)
    watch = SessionWatch() if tls_dir is not None else None
    with zbus.open_router(config) as session:
        bus = SessionBus(session)
        bus.subscribe(wire.world_events(), clients.on_event)
        bus.subscribe_liveliness(wire.all_liveliness(), clients.on_token)
        lifeline.attach(bus, stop, "router", follow_end=False)
        mode = "acl" if acl and auth else ("auth only" if auth else "open")
        mode = f"mutual TLS, {mode}" if tls_dir is not None else mode
        print(f"router listening on {listen} ({mode}, {agents} agents)", flush=True)
        while not stop.wait(0.1):
            if watch is not None:
                watch.poll(session, time.monotonic())
            if clients.done(time.monotonic()):
                print("router: the mission is over and its clients have left", flush=True)
                break
        for handle in bus.handles:
            handle.undeclare()
    print("router stopped", flush=True)
    return lifeline.shell_exit_code(stop)


def swarm_users(table: dict[str, str], agents: int) -> dict[str, str]:
    """The entries of ``table`` for the users of a swarm of ``agents`` AUVs; others may not log in.

    A swarm user missing from the table is named in a warning: its process will be refused.
    """
    wanted = credentials.users(agents)
    missing = [u for u in wanted if u not in table]
    if missing:
        print(f"warning: the user table has no password for {', '.join(missing)}: they cannot log in", file=sys.stderr)
    kept = {u: table[u] for u in wanted if u in table}
    if not kept:
        raise credentials.CredentialError(
            f"the user table holds none of the swarm's users ({', '.join(wanted[:3])}, ...)"
        )
    return kept


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm router``."""
    parser = argparse.ArgumentParser(prog="auv-swarm router", description=plain_description(__doc__))
    parser.add_argument(
        "--listen", default=None, help="endpoint, e.g. tcp/127.0.0.1:7447 (default: a free loopback port)"
    )
    parser.add_argument("--agents", type=int, default=zbus.MAX_AGENTS, help="AUV users auv0..auv<N-1> (1..16)")
    parser.add_argument("--no-acl", action="store_true", help="no access control (authentication stays on)")
    parser.add_argument("--no-auth", action="store_true", help="no authentication and no access control (debugging)")
    parser.add_argument(
        "--grace-s",
        type=float,
        default=None,
        help=f"exit when the world's liveliness is gone this long (wall s; default: --scenario's run.grace_s, "
        f"else {DEFAULT_GRACE_S:g})",
    )
    parser.add_argument(
        "--scenario", default=None, help="refuse to start unless this scenario has --agents AUVs (compose files)"
    )
    parser.add_argument(
        "--tls-dir",
        type=Path,
        default=None,
        help="mutual TLS on a tls/ADDR:PORT endpoint with ca.pem, router.pem and router.key from this folder; each "
        "client is known by its certificate, no user table (auv-swarm credentials --tls DIR; docs/deploy.md)",
    )
    credentials.add_users_args(parser)
    parser.add_argument("--example", action="store_true", help="print a sample invocation and exit")
    parser.add_argument("--interface", action="store_true", help="print what the router does and its ACL, and exit")
    args = parser.parse_args(argv)
    if not 1 <= args.agents <= zbus.MAX_AGENTS:
        parser.error(f"--agents must be in [1, {zbus.MAX_AGENTS}], got {args.agents}")
    if args.grace_s is not None and not 0 < args.grace_s <= 600:
        parser.error(f"--grace-s must be in (0, 600] s, got {args.grace_s}")
    if args.example:
        print(EXAMPLE)
        return 0
    if args.interface:
        print(interface_text(args.agents))
        return 0
    grace_s = DEFAULT_GRACE_S if args.grace_s is None else args.grace_s
    if args.scenario is not None:
        from auv_swarm.contract.config import ConfigError, load_scenario
        from auv_swarm.orchestrator.mission.collector import compose_refusal

        try:
            scenario = load_scenario(args.scenario)
        except ConfigError as exc:
            return fail(str(exc))
        refusal = compose_refusal(scenario, args.agents)
        if refusal is not None:
            return fail(f"{refusal}")
        grace_s = scenario.run.grace_s if args.grace_s is None else args.grace_s
    return serve(args, grace_s)


def serve(args: argparse.Namespace, grace_s: float) -> int:
    """Check the login options (a user table, or ``--tls-dir`` and the router's certificate) and :func:`run`."""
    tls_dir = args.tls_dir
    listen = args.listen or f"{'tcp' if tls_dir is None else 'tls'}/127.0.0.1:{free_port()}"
    try:
        tls.check_scheme(listen, tls_dir, "--tls-dir")
        if tls_dir is None:
            creds = {} if args.no_auth else swarm_users(credentials.user_table(args, args.agents), args.agents)
        elif args.no_auth or args.users_file or args.users_fd is not None or args.insecure_dev:
            return fail(
                "--tls-dir knows each client by its certificate: no --no-auth, --users-file, --users-fd or "
                "--insecure-dev"
            )
        else:
            tls.check_identity(tls_dir, tls.ROUTER)
            creds = {}
        return run(listen, acl=not args.no_acl, creds=creds, agents=args.agents, grace_s=grace_s, tls_dir=tls_dir)
    except (ValueError, ConnectionError) as exc:
        return fail(str(exc))


if __name__ == "__main__":
    sys.exit(main())
