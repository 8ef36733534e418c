"""Where a sweep's missions run, and who may talk to them: mutual TLS on every Dask link (docs/sweeps.md).

Dask runs whatever a peer of the cluster sends it (tasks are pickled functions, results pickled values), so a
peer is whoever holds a certificate of the cluster's CA, nobody else:

- **The LocalCluster** (no ``--scheduler``): a CA made in memory for this sweep alone signs the scheduler's,
  the workers' (and their nannies') and the client's certificates (:func:`local_tls`, bus/tls.py); the CA
  key is dropped once they are signed and nothing is written. Every Dask listener is ``tls://127.0.0.1``, the
  scheduler's and workers' HTTP servers (which Dask always starts) too, serving no route without
  ``--dashboard`` (:func:`http_settings`).
- **An existing cluster**: ``--scheduler tls://HOST:PORT --tls-dir DIR``, ``DIR`` holding the CA certificate and
  the client's pair that ``auv-swarm credentials --dask DIR`` wrote (:func:`client_tls`). A ``tcp://`` or
  scheme-less address is refused (plain TCP lets anyone who reaches a port run code as the sweep's user and
  rewrite its rows) unless ``--insecure-scheduler``, which warns on every start.

Every refusal here is a :class:`ClusterError` (bad input, one line, exit 2), raised before the sweep's folder
is made. No Dask here: the engine turns a :class:`ClusterTLS` into Dask's ``Security``.
"""

from __future__ import annotations

import argparse
import datetime
import ssl
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from auv_swarm.bus import tls

LOCAL_HOST = "127.0.0.1"
"""Where every listener of the LocalCluster binds."""
CLIENT_FILES = ("ca.pem", "client.pem", "client.key")
"""What the client reads from ``--tls-dir`` (the rest of the folder is the cluster's)."""


class ClusterError(ValueError):
    """A ``--scheduler``, ``--tls-dir`` or ``--insecure-scheduler`` that cannot be used; one line for the user."""


@dataclass(frozen=True)
class ClusterTLS:
    """Dask's mutual TLS: the CA certificate and each role's certificate and key (``scheduler``, ``worker``,
    ``client``), each a file path or PEM text (Dask takes either); the engine makes Dask's ``Security`` of it."""

    ca: str
    roles: dict[str, tuple[str, str]] = field(default_factory=dict)

    def security_args(self) -> dict[str, Any]:
        """The keyword arguments of ``distributed.Security``: encryption required, the CA, each role's pair."""
        args: dict[str, Any] = {"require_encryption": True, "tls_ca_file": self.ca}
        for role, (cert, key) in self.roles.items():
            args |= {f"tls_{role}_cert": cert, f"tls_{role}_key": key}
        return args


@dataclass(frozen=True)
class Scheduler:
    """An existing Dask scheduler: its address and the client's TLS (None: plain TCP, ``--insecure-scheduler``)."""

    address: str
    tls: ClusterTLS | None


def add_scheduler_args(parser: argparse.ArgumentParser) -> None:
    """``--scheduler``, ``--tls-dir`` and ``--insecure-scheduler`` (``auv-swarm sweep``, ``bench table3``)."""
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="an existing Dask scheduler, tls://HOST:PORT (docs/sweeps.md)",
    )
    parser.add_argument(
        "--tls-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="with --scheduler: ca.pem, client.pem and client.key (auv-swarm credentials --dask DIR)",
    )
    parser.add_argument(
        "--insecure-scheduler",
        action="store_true",
        help="accept a tcp:// scheduler: anyone who reaches it can run code as you (trusted networks only)",
    )


def scheduler_from_args(args: argparse.Namespace) -> Scheduler | None:
    """The scheduler the flags name (None: the LocalCluster); ClusterError on a bad combination or address."""
    if args.scheduler is None:
        if args.tls_dir is not None:
            raise ClusterError("--tls-dir goes with --scheduler tls://HOST:PORT (the LocalCluster makes its own)")
        if args.insecure_scheduler:
            raise ClusterError("--insecure-scheduler goes with --scheduler tcp://HOST:PORT")
        return None
    return parse_scheduler(args.scheduler, args.tls_dir, args.insecure_scheduler)


def parse_scheduler(address: str, tls_dir: Path | None, insecure: bool = False) -> Scheduler:
    """Check ``address`` (``tls://HOST:PORT``; ``tcp://HOST:PORT`` or ``HOST:PORT`` with ``insecure``) and read
    the client's credentials from ``tls_dir``; ClusterError names what is wrong."""
    scheme, sep, location = address.strip().rpartition("://")
    scheme = scheme.lower() if sep else ""
    if scheme not in ("tls", "tcp", ""):
        raise ClusterError(f"--scheduler {address}: the address must be tls://HOST:PORT, got scheme {scheme}://")
    _host_port(address, location)
    if scheme == "tls":
        if insecure:
            raise ClusterError("--insecure-scheduler goes with a tcp:// address; a tls:// scheduler needs --tls-dir")
        if tls_dir is None:
            raise ClusterError(
                f"--scheduler {address} needs --tls-dir DIR: the CA and the client's certificate "
                "(auv-swarm credentials --dask DIR, docs/sweeps.md)"
            )
        return Scheduler(f"tls://{location}", client_tls(tls_dir))
    if not insecure:
        raise ClusterError(
            f"--scheduler {address}: plain TCP lets anyone who reaches the cluster run code as you; use "
            "tls://HOST:PORT with --tls-dir DIR (docs/sweeps.md), or --insecure-scheduler on a trusted network"
        )
    if tls_dir is not None:
        raise ClusterError(f"--tls-dir goes with a tls:// scheduler, not {address}")
    print(
        f"warning: --insecure-scheduler: plain TCP to tcp://{location}: anyone who can reach the scheduler or a "
        "worker can run code as you and change the sweep's rows",
        file=sys.stderr,
        flush=True,
    )
    return Scheduler(f"tcp://{location}", None)


def _host_port(address: str, location: str) -> tuple[str, int]:
    bad = ClusterError(f"--scheduler {address}: expected tls://HOST:PORT (a port in [1, 65535]; IPv6 as [ADDR])")
    if not location or any(c in location for c in "/ @?#"):
        raise bad
    try:
        parts = urlsplit(f"//{location}")
        host, port = parts.hostname, parts.port
    except ValueError:
        raise bad from None
    if not host or port is None or not 1 <= port <= 65535:
        raise bad
    return host, port


def client_tls(tls_dir: Path, now: datetime.datetime | None = None) -> ClusterTLS:
    """The client's TLS from ``tls_dir`` (:data:`CLIENT_FILES`); ClusterError if one is missing, unreadable,
    not a certificate and key that match, or expired (at ``now``, default the clock)."""
    paths = [Path(tls_dir) / name for name in CLIENT_FILES]
    for path in paths:
        try:
            path.read_bytes()
        except OSError as exc:
            raise ClusterError(
                f"--tls-dir: cannot read {path}: {exc.strerror} (auv-swarm credentials --dask {tls_dir} writes it)"
            ) from None
    ca, cert, key = (str(p) for p in paths)
    try:
        expires = tls.Pair(b"", paths[1].read_bytes()).expires()
    except ValueError:
        raise ClusterError(f"--tls-dir: {cert} is not a PEM certificate") from None
    if expires <= (now or datetime.datetime.now(datetime.UTC)):
        raise ClusterError(
            f"--tls-dir: {cert} expired on {expires:%Y-%m-%d %H:%M} UTC; "
            f"auv-swarm credentials --dask {tls_dir} issues fresh certificates"
        )
    try:  # what Dask will do with them
        ssl.create_default_context(cafile=ca).load_cert_chain(cert, key)
    except (OSError, ValueError) as exc:  # ssl.SSLError is an OSError
        raise ClusterError(f"--tls-dir: {ca}, {cert} and {key} are not a usable CA and client pair: {exc}") from None
    return ClusterTLS(ca, {"client": (cert, key)})


def local_tls() -> ClusterTLS:
    """Mutual TLS for one LocalCluster: a fresh in-memory CA and its certificates for each Dask role
    (bus/tls.py), as PEM text, which Dask passes to the worker processes it starts; the CA key is dropped."""
    ca = tls.new_authority("auv-swarm sweep CA")
    pairs = tls.dask_certificates(ca)
    roles = {role: (pair.cert_pem.decode(), pair.key_pem.decode()) for role, pair in pairs.items()}
    return ClusterTLS(ca.pair().cert_pem.decode(), roles)


def http_settings(dashboard: bool) -> dict[str, Any]:
    """Dask settings for the HTTP servers its scheduler and workers always start: with the dashboard Dask's own
    routes, without it none (every path 404: no worker list, logs or call stacks to read)."""
    if dashboard:
        return {}
    return {"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []}
