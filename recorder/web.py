"""rerun's web viewer, served from this machine: the page on one port, its gRPC proxy on the next.

``rerun --serve-web`` (the viewer binary shipped in rerun-sdk) serves the web
viewer over HTTP and runs a gRPC proxy that logging SDKs stream into and the
page reads from, in the browser: both ports must be reachable from the browser.
The proxy buffers what it received (up to ``--server-memory-limit``,
:data:`SERVER_MEMORY_LIMIT` here), so a page opened late, or after the mission,
still gets everything. Used by ``auv-swarm run --web``, ``auv-swarm view --web``
and the compose ``viewer`` service.

Neither port authenticates anyone: whoever reaches them reads the live recording
(ground truth included) and can write into what every page shows. Both listen on
loopback (:data:`LOOPBACK`) unless ``--web-bind ADDR`` says otherwise, which warns
(:func:`exposure`); docs/web-viewer.md, docs/security.md.
"""

from __future__ import annotations

import ipaddress
import os
import signal
import socket
import subprocess
import time
from pathlib import Path
from urllib.parse import quote

from auv_swarm.recorder.viewer import viewer_binary

DEFAULT_WEB_PORT = 9090
LOOPBACK = "127.0.0.1"
"""Where the page and the proxy listen unless ``--web-bind`` names another address."""
SERVER_MEMORY_LIMIT = "128MiB"
"""What the proxy may buffer for pages opened late (rerun's ``--server-memory-limit``; beyond it rerun drops the
oldest data; rerun's default is 1 GiB). Twice what the heaviest mission measured needs: 16 AUVs, 1500 s at
``--speed 5`` (18,178 live chunks, the proxy 33 to 104 MB resident) stayed within 64 MiB (docs/web-viewer.md)."""
START_S = 30.0
"""Wall seconds the web viewer gets to listen on both ports."""


def proxy_url(host: str, grpc_port: int) -> str:
    """The gRPC proxy's url, as the recorder (``--rerun-url``) and the page use it."""
    host = f"[{host}]" if ":" in host and not host.startswith("[") else host
    return f"rerun+http://{host}:{grpc_port}/proxy"


def page_url(host: str, web_port: int, grpc_port: int) -> str:
    """The address to open in a browser: the page, told where its gRPC proxy is."""
    bracketed = f"[{host}]" if ":" in host and not host.startswith("[") else host
    return f"http://{bracketed}:{web_port}/?url={quote(proxy_url(host, grpc_port), safe='')}"


def check_bind(bind: str) -> None:
    """ValueError unless ``bind`` is an IP address (``--web-bind``: rerun binds an address, not a name)."""
    try:
        ipaddress.ip_address(bind)
    except ValueError:
        raise ValueError(
            f"--web-bind must be an IP address (127.0.0.1, 0.0.0.0, ::, an interface's), got {bind!r}"
        ) from None


def is_loopback(bind: str) -> bool:
    """True if ``bind`` (an IP address) is reachable from this machine only."""
    return ipaddress.ip_address(bind).is_loopback


def local_host(bind: str) -> str:
    """The address this machine reaches a server bound to ``bind`` at (the wildcards: loopback)."""
    address = ipaddress.ip_address(bind)
    if address.is_unspecified:
        return "::1" if address.version == 6 else LOOPBACK
    return str(address)


def public_host(bind: str, given: str = "localhost") -> str:
    """The host name to print in the page's address: ``given`` unless the server listens on one interface only."""
    address = ipaddress.ip_address(bind)
    return given if address.is_loopback or address.is_unspecified else str(address)


def exposure(bind: str, web_port: int, grpc_port: int) -> str | None:
    """The one-line warning for a bind address beyond loopback, None for loopback."""
    if is_loopback(bind):
        return None
    return (
        f"warning: --web-bind {bind}: the web viewer ({web_port}) and its gRPC proxy ({grpc_port}) accept anyone "
        "who can reach them, without authentication: they can read the live recording, ground truth included, "
        "and write into what every viewer shows"
    )


def check_ports(web_port: int, grpc_port: int) -> None:
    """ValueError naming the bad port (each in [1, 65535], and different)."""
    for name, port in (("--web", web_port), ("--web-grpc-port", grpc_port)):
        if not 1 <= port <= 65535:
            raise ValueError(f"{name} port must be in [1, 65535], got {port}")
    if web_port == grpc_port:
        raise ValueError(f"the web port and --web-grpc-port must differ, both are {web_port}")


def listening(port: int, host: str = LOOPBACK) -> bool:
    """True when a TCP connection to ``host:port`` opens."""
    try:
        with socket.create_connection((host, port), timeout=0.5):
            return True
    except OSError:
        return False


def start(
    web_port: int, grpc_port: int, log_path: Path, rrd: Path | None = None, bind: str = LOOPBACK
) -> subprocess.Popen:
    """Start ``rerun --serve-web`` in its own session, both ports on ``bind`` (with ``rrd`` loaded, if given);
    return once both ports listen.

    Raises RuntimeError if a port is taken or the server does not come up within START_S.
    """
    check_ports(web_port, grpc_port)
    check_bind(bind)
    host = local_host(bind)
    busy = [p for p in (web_port, grpc_port) if listening(p, host)]
    if busy:
        raise RuntimeError(f"port {busy[0]} is already in use (choose others with --web PORT --web-grpc-port PORT)")
    cmd = [viewer_binary(), "--serve-web", "--bind", bind, "--web-viewer-port", str(web_port), "--port", str(grpc_port)]
    cmd += ["--server-memory-limit", SERVER_MEMORY_LIMIT]
    cmd += [str(rrd)] if rrd is not None else []
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, "ab") as out:
        proc = subprocess.Popen(
            cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
    deadline = time.monotonic() + START_S
    while not (listening(web_port, host) and listening(grpc_port, host)):
        if proc.poll() is not None or time.monotonic() > deadline:
            stop(proc)
            raise RuntimeError(f"the web viewer did not come up on ports {web_port}/{grpc_port}; see {log_path}")
        time.sleep(0.1)
    return proc


def serve_recording(
    proc: subprocess.Popen,
    web_port: int,
    grpc_port: int,
    log_path: Path,
    rrd: Path,
    wait_s: float = 10.0,
    bind: str = LOOPBACK,
) -> subprocess.Popen:
    """Replace the web viewer ``proc`` by one on the same ports serving the finished recording ``rrd``.

    The live viewer's proxy keeps every chunk it was sent (a 1500 s run at ``--speed 5``: thousands), and
    a page opened after the mission takes them in one by one; the compacted file holds a few hundred
    large chunks and loads in seconds (issue 28 item 6). A page already open loses its stream and keeps
    what it shows. Waits up to ``wait_s`` for the old process to free the ports; RuntimeError if the new
    one does not come up.
    """
    stop(proc)
    host = local_host(bind)
    deadline = time.monotonic() + wait_s
    while (listening(web_port, host) or listening(grpc_port, host)) and time.monotonic() < deadline:
        time.sleep(0.1)
    return start(web_port, grpc_port, log_path, rrd, bind)


def stop(proc: subprocess.Popen, timeout_s: float = 5.0) -> None:
    """Stop the web viewer's process group (SIGTERM, then SIGKILL) and reap it."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=timeout_s)
        except ProcessLookupError:
            pass
    proc.poll()
