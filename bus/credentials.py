"""Per-process credentials: where a process finds its own zenoh password, and the router its user table.

Every process logs in to the router as its own user (``world``, ``channel``,
``recorder``, ``orchestrator``, ``auv<N>``) and holds only that user's password.
It reads it, in this order, from:

1. ``--password-fd FD``: a pipe the launcher (``auv-swarm run``) wrote the password
   to and closed; the child reads it once at start. Nothing lands in the
   environment, the command line or a file.
2. ``--password-file PATH``, or the file named by ``AUVSWARM_PASSWORD_FILE`` (under compose,
   each container's ``secrets:`` entry mounts only its own folder ``/run/secrets/<user>/``,
   holding ``password``).
3. ``--insecure-dev``: the documented development password (HMAC of
   :data:`DEV_SECRET`), with a warning on every start. Anyone who read the docs can
   log in with it.

Without any of them the process refuses to start with a one-line error (exit 2).
The router reads its ``user:password`` table (zenoh's usrpwd dictionary format, one
per line) from ``--users-fd``, ``--users-file`` or ``AUVSWARM_USERS_FILE``, or the
dev table with ``--insecure-dev``. ``auv-swarm credentials --out DIR`` writes fresh
``DIR/<user>.password`` files (mode 0600) and ``DIR/users.txt``; with ``--folders`` it
writes ``DIR/<user>/password`` and ``DIR/router/users.txt`` instead, one folder per
container (the compose layout, :func:`folder_layout`).

Pure apart from reading and writing those files: no zenoh here.
"""

from __future__ import annotations

import argparse
import hashlib
import hmac
import os
import secrets
import sys
from pathlib import Path

from auv_swarm.bus import tls
from auv_swarm.contract.params import MAX_AGENTS, agent_user
from auv_swarm.contract.usage import fail

DEV_SECRET = "auv-swarm-dev-secret"
"""The documented, public development secret: ``--insecure-dev`` passwords are derived from it."""
PASSWORD_FILE_ENV = "AUVSWARM_PASSWORD_FILE"
USERS_FILE_ENV = "AUVSWARM_USERS_FILE"
TLS_DIR_ENV = "AUVSWARM_TLS_DIR"
"""Env: the folder of a process's certificates for a ``tls/`` router (``--tls-dir``)."""
CREDENTIAL_ENV = (PASSWORD_FILE_ENV, USERS_FILE_ENV, TLS_DIR_ENV, "AUVSWARM_SECRET")
"""Environment variables that name or hold credentials; the launcher never passes them to its children."""
COMPONENT_USERS = ("world", "channel", "recorder", "orchestrator", "central")
MAX_SECRET_BYTES = 4096


class CredentialError(ValueError):
    """No usable credentials (missing, unreadable or malformed); the message is one line for the user."""


def users(agents: int = MAX_AGENTS) -> tuple[str, ...]:
    """Every user name of a swarm of ``agents`` AUVs: the components, then auv0..auv<agents-1>."""
    if isinstance(agents, bool) or not isinstance(agents, int) or not 1 <= agents <= MAX_AGENTS:
        raise ValueError(f"agents must be an integer in [1, {MAX_AGENTS}], got {agents!r}")
    return COMPONENT_USERS + tuple(agent_user(n) for n in range(agents))


def password_for(user: str, secret: str) -> str:
    """The password of ``user`` derived from ``secret``: HMAC-SHA256, hex, first 32 characters.

    The launcher derives every password from a secret it keeps to itself; a process
    never sees the secret, only its own password.
    """
    if not user or not isinstance(user, str):
        raise ValueError(f"user must be a non-empty string, got {user!r}")
    if not secret or not isinstance(secret, str):
        raise ValueError("secret must be a non-empty string")
    return hmac.new(secret.encode(), user.encode(), hashlib.sha256).hexdigest()[:32]


def derive(secret: str, agents: int = MAX_AGENTS) -> dict[str, str]:
    """user -> password for every user of :func:`users`, derived from ``secret``."""
    return {u: password_for(u, secret) for u in users(agents)}


def users_text(table: dict[str, str]) -> str:
    """The router's user table in zenoh's usrpwd dictionary format: ``user:password`` per line."""
    for user, password in table.items():
        if not user or ":" in user or "\n" in user or not password or "\n" in password:
            raise ValueError(f"users must map non-empty names without ':' to one-line passwords, got {user!r}")
    return "".join(f"{u}:{p}\n" for u, p in table.items())


def parse_users(text: str, where: str) -> dict[str, str]:
    """Parse a ``user:password`` table (blank lines and ``#`` comments allowed); CredentialError names the line."""
    table: dict[str, str] = {}
    for n, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        user, sep, password = line.partition(":")
        if not sep or not user or not password:
            raise CredentialError(f"{where}: line {n} must be user:password")
        table[user] = password
    if not table:
        raise CredentialError(f"{where}: no user:password lines")
    return table


def _read_fd(fd: int, what: str) -> str:
    try:
        with os.fdopen(fd, "rb", closefd=True) as fh:
            data = fh.read(MAX_SECRET_BYTES + 1)
    except OSError as exc:
        raise CredentialError(f"cannot read the {what} from file descriptor {fd}: {exc.strerror}") from None
    if len(data) > MAX_SECRET_BYTES:
        raise CredentialError(f"the {what} on file descriptor {fd} is longer than {MAX_SECRET_BYTES} bytes")
    return data.decode("utf-8", errors="replace")


def _read_file(path: str, what: str) -> str:
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_SECRET_BYTES * 16 + 1)
    except OSError as exc:
        raise CredentialError(f"cannot read the {what} file {path}: {exc.strerror}") from None
    if len(data) > MAX_SECRET_BYTES * 16:
        raise CredentialError(f"the {what} file {path} is too large")
    return data.decode("utf-8", errors="replace")


def add_password_args(parser: argparse.ArgumentParser) -> None:
    """--password-file, --password-fd and --insecure-dev (every client process)."""
    parser.add_argument(
        "--password-file", default=None, help=f"file holding this process's password (env {PASSWORD_FILE_ENV})"
    )
    parser.add_argument("--password-fd", type=int, default=None, help="read the password from this pipe (launcher)")
    parser.add_argument(
        "--insecure-dev", action="store_true", help="use the documented public dev password (local trials only)"
    )


def add_users_args(parser: argparse.ArgumentParser) -> None:
    """--users-file, --users-fd and --insecure-dev (the router)."""
    parser.add_argument("--users-file", default=None, help=f"user:password table, one per line (env {USERS_FILE_ENV})")
    parser.add_argument("--users-fd", type=int, default=None, help="read the user table from this pipe (launcher)")
    parser.add_argument(
        "--insecure-dev", action="store_true", help="use the documented public dev passwords (local trials only)"
    )


def _warn_insecure(what: str) -> None:
    print(
        f"warning: --insecure-dev: {what} the documented public development secret; "
        "anyone who read the docs can log in. Never use it on a shared host or network.",
        file=sys.stderr,
        flush=True,
    )


def read_password(path: Path | str, user: str) -> str:
    """The one-line password of ``user`` in the file ``path``; CredentialError if unreadable or not one line."""
    return _one_line(_read_file(str(path), "password"), user)


def _one_line(text: str, user: str) -> str:
    value = text.strip()
    if not value or "\n" in value:
        raise CredentialError(f"the password for user {user} must be one non-empty line")
    return value


def password(args: argparse.Namespace, user: str) -> str:
    """This process's password for ``user`` (see the module docstring for the order); CredentialError if none."""
    path = args.password_file or os.environ.get(PASSWORD_FILE_ENV)
    if args.password_fd is not None:
        text = _read_fd(args.password_fd, "password")
    elif path:
        text = _read_file(path, "password")
    elif args.insecure_dev:
        _warn_insecure(f"user {user} logs in with a password derived from")
        return password_for(user, DEV_SECRET)
    else:
        raise CredentialError(
            f"no credentials for user {user}: give --password-file PATH or set {PASSWORD_FILE_ENV} "
            "(auv-swarm credentials --out DIR writes them), or --insecure-dev for a local trial"
        )
    return _one_line(text, user)


def user_table(args: argparse.Namespace, agents: int) -> dict[str, str]:
    """The router's user table (see the module docstring for the order); CredentialError if none."""
    path = args.users_file or os.environ.get(USERS_FILE_ENV)
    if args.users_fd is not None:
        return parse_users(_read_fd(args.users_fd, "user table"), f"file descriptor {args.users_fd}")
    if path:
        return parse_users(_read_file(path, "users"), path)
    if args.insecure_dev:
        _warn_insecure("every user's password is derived from")
        return derive(DEV_SECRET, agents)
    raise CredentialError(
        f"no user table: give --users-file PATH or set {USERS_FILE_ENV} "
        "(auv-swarm credentials --out DIR writes DIR/users.txt), or --insecure-dev for a local trial"
    )


PREPARED_STAMP = ".prepared"
"""In a compose run folder: ``<setup container's hostname> <random token>``, written once per run by ``collect --prepare``."""
RUN_STAMP = ".run"
"""In the credentials folder: the :data:`PREPARED_STAMP` of the run its passwords were written for."""
ROUTER_FOLDER = "router"
"""With the folder layout, the router's user table is ``DIR/router/users.txt``."""


def folder_layout(out: Path, agents: int = MAX_AGENTS) -> dict[str, Path]:
    """The compose layout: ``out/<user>/password`` per user and ``out/router/users.txt``; user -> path.

    One folder per container, because a compose file secret (a bind mount) must exist when
    ``docker compose`` v2 creates the containers, before the ``credentials`` service has run:
    the folders exist beforehand (``.credentials/<user>/`` in the repository, or made by
    ``auv-swarm compose``), the files in them are written fresh by every run."""
    out = Path(out)
    paths = {u: out / u / "password" for u in users(agents)}
    paths["users.txt"] = out / ROUTER_FOLDER / "users.txt"
    return paths


def write_credentials(out: Path, agents: int = MAX_AGENTS, *, folders: bool = False) -> dict[str, Path]:
    """Write fresh random passwords, one per user, and the router's table (all mode 0600); user -> path.

    Flat layout ``out/<user>.password`` and ``out/users.txt``, or :func:`folder_layout`."""
    out = Path(out)
    table = {u: secrets.token_hex(16) for u in users(agents)}
    if folders:
        paths = folder_layout(out, agents)
    else:
        paths = {u: out / f"{u}.password" for u in table}
        paths["users.txt"] = out / "users.txt"
    for user, path in paths.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        tls.write_private(path, (users_text(table) if user == "users.txt" else table[user] + "\n").encode())
    return paths


def write_once_per_run(out: Path, agents: int, run_folder: Path) -> tuple[dict[str, Path], bool]:
    """Fresh folder-layout credentials for the run in ``run_folder``, kept if already written for it; (paths, fresh).

    ``docker compose start SERVICE`` (v2) starts the ``credentials`` one-shot again mid-mission:
    new passwords then would lock the restarted AUV out of the router, which holds the run's table."""
    try:
        run = (Path(run_folder) / PREPARED_STAMP).read_text(encoding="utf-8")
    except OSError:
        run = None
    paths = folder_layout(out, agents)
    try:
        done = run is not None and (Path(out) / RUN_STAMP).read_text(encoding="utf-8") == run
    except OSError:
        done = False
    if done and all(p.is_file() for p in paths.values()):
        return paths, False
    paths = write_credentials(out, agents, folders=True)
    if run is not None:
        tls.write_private(Path(out) / RUN_STAMP, run.encode())
    return paths, True


def _parser() -> argparse.ArgumentParser:
    """The options of ``auv-swarm credentials`` (see :func:`main`)."""
    parser = argparse.ArgumentParser(
        prog="auv-swarm credentials",
        description="write fresh DIR/<user>.password files (one per process, mode 0600) and DIR/users.txt (router); "
        "or, with --tls DIR, a CA and one certificate per process for mutual TLS across hosts (docs/deploy.md); "
        "or, with --dask DIR, a CA and the TLS certificates of a Dask cluster for auv-swarm sweep (docs/sweeps.md)",
    )
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", type=Path, default=None, help="folder for the password files (created if missing)")
    where.add_argument(
        "--dask",
        type=Path,
        default=None,
        metavar="DIR",
        help="write ca.pem, ca.key and the scheduler's, workers' and client's .pem/.key (0600); a CA already in DIR "
        "signs fresh certificates",
    )
    where.add_argument(
        "--tls",
        type=Path,
        default=None,
        metavar="DIR",
        help="write ca.pem, ca.key, router.pem/.key and <user>.pem/.key per process (0600), each certificate named "
        "as its zenoh user; a CA already in DIR signs fresh certificates (rotation)",
    )
    parser.add_argument(
        "--router-host",
        action="append",
        default=None,
        metavar="HOST",
        help=f"with --tls: a DNS name or IP address clients dial the router by, once per name (default: "
        f"{', '.join(tls.DEFAULT_ROUTER_HOSTS)})",
    )
    parser.add_argument("--agents", type=int, default=MAX_AGENTS, help=f"AUV users auv0..auv<N-1> (1..{MAX_AGENTS})")
    parser.add_argument(
        "--folders", action="store_true", help="write DIR/<user>/password and DIR/router/users.txt (compose layout)"
    )
    parser.add_argument(
        "--run-folder",
        type=Path,
        default=None,
        help="with --folders: fresh once per run (the run folder's .prepared stamp); kept when restarted mid-run",
    )
    parser.add_argument(
        "--days",
        type=int,
        default=None,
        help=f"with --tls or --dask: the certificates' lifetime (default {tls.DEFAULT_DAYS})",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """``auv-swarm credentials --out DIR [--agents N]``: fresh per-user password files for a hand-started swarm;
    ``auv-swarm credentials --tls DIR [--agents N] [--router-host H ...] [--days N]``: a CA and one certificate per
    process for a swarm across hosts (docs/deploy.md); ``auv-swarm credentials --dask DIR [--days N]``: a CA and
    the certificates of a Dask cluster (bus/tls.py)."""
    args = _parser().parse_args(argv)
    if args.out is None and (args.folders or args.run_folder is not None):
        return fail("--folders and --run-folder go with --out (password files)")
    if args.tls is None and args.router_host is not None:
        return fail("--router-host goes with --tls")
    if not 1 <= args.agents <= MAX_AGENTS:
        return fail(f"--agents must be in [1, {MAX_AGENTS}], got {args.agents}")
    days = tls.DEFAULT_DAYS if args.days is None else args.days
    if args.dask is not None:
        return _write_dask(args.dask, days)
    if args.tls is not None:
        return _write_tls(args.tls, args.agents, tuple(args.router_host or tls.DEFAULT_ROUTER_HOSTS), days)
    if args.days is not None:
        return fail("--days goes with --tls or --dask")
    if args.run_folder is not None and not args.folders:
        return fail("--run-folder goes with --folders")
    try:
        if args.run_folder is not None:
            paths, fresh = write_once_per_run(args.out, args.agents, args.run_folder)
            if not fresh:
                print(f"kept the credentials already written to {args.out} for the run in {args.run_folder}")
                return 0
        else:
            paths = write_credentials(args.out, args.agents, folders=args.folders)
    except OSError as exc:
        return fail(f"cannot write credentials to {args.out}: {exc.strerror}")
    print(f"wrote {len(paths) - 1} password files and users.txt to {args.out}")
    if not args.folders:
        print(f"start each process with --password-file {args.out}/<user>.password, the router with --users-file")
    return 0


def _write_tls(folder: Path, agents: int, hosts: tuple[str, ...], days: int) -> int:
    """``--tls DIR``: the swarm's CA and a certificate per process (:func:`tls.write_zenoh`), and where each goes."""
    if not 1 <= days <= tls.CA_DAYS:
        return fail(f"--days must be in [1, {tls.CA_DAYS}], got {days}")
    try:
        paths, made = tls.write_zenoh(folder, users(agents), router_hosts=hosts, days=days)
    except (tls.TLSError, ValueError) as exc:
        return fail(f"--router-host: {exc}" if "router host" in str(exc) else str(exc))
    except OSError as exc:
        return fail(f"cannot write the certificates to {folder}: {exc.strerror}")
    expires = tls.Pair(b"", paths[tls.ROUTER]["cert"].read_bytes()).expires()
    ca = "a new CA (ca.pem, ca.key)" if made else "the CA already there"
    print(f"wrote {len(paths)} certificates signed by {ca} to {folder}, valid until {expires:%Y-%m-%d %H:%M} UTC")
    print(f"the router answers to {', '.join(hosts)}; keep ca.key here, copy ca.pem and <user>.pem/.key to each host")
    print(
        f"auv-swarm router --listen tls/0.0.0.0:7447 --tls-dir {folder}; every other process --router "
        f"tls/{hosts[0]}:7447 --tls-dir {folder} (docs/deploy.md)"
    )
    return 0


def _write_dask(folder: Path, days: int) -> int:
    """``--dask DIR``: the Dask cluster's CA and certificates, and where each file goes."""
    if not 1 <= days <= tls.CA_DAYS:
        return fail(f"--days must be in [1, {tls.CA_DAYS}], got {days}")
    try:
        paths, made = tls.write_dask(folder, days=days)
    except tls.TLSError as exc:
        return fail(str(exc))
    except OSError as exc:
        return fail(f"cannot write the Dask certificates to {folder}: {exc.strerror}")
    expires = tls.Pair(b"", paths["client.pem"].read_bytes()).expires()
    ca = "a new CA (ca.pem, ca.key)" if made else "the CA already there"
    print(f"wrote certificates signed by {ca} to {folder}, valid until {expires:%Y-%m-%d %H:%M} UTC")
    print(
        "keep ca.key here; copy ca.pem with worker.pem/worker.key to the workers' hosts, scheduler.* to the scheduler's"
    )
    print(f"auv-swarm sweep ... --scheduler tls://HOST:PORT --tls-dir {folder} (docs/sweeps.md)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
