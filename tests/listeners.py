"""Who listens where, and who gets in: the TCP listeners of a process tree read from /proc (no psutil, no ss),
and a Dask peer's view of a listener (does it answer ``identity`` to plain TCP, to TLS without a certificate,
to TLS with a certificate of another CA?). For the checks that a sweep's cluster and the web viewer listen on
loopback only (issue 42) and that the cluster admits only holders of its certificates."""

from __future__ import annotations

import asyncio
import socket
import ssl
import struct
from dataclasses import dataclass
from pathlib import Path

WILDCARD = ("0.0.0.0", "::")
"""Listening on these is listening on every interface (``ss`` prints them as ``0.0.0.0``, ``[::]`` or ``*``)."""
LISTEN = "0A"
"""The LISTEN state in /proc/net/tcp."""


@dataclass(frozen=True)
class Listener:
    """A listening TCP socket: the address it is bound to, its port and a process holding it."""

    host: str
    port: int
    pid: int

    @property
    def wildcard(self) -> bool:
        return self.host in WILDCARD


def descendants(pid: int) -> list[int]:
    """``pid`` and every live process below it."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text(errors="replace").rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(ppid, []).append(int(entry.name))
    tree, todo = [], [pid]
    while todo:
        p = todo.pop()
        tree.append(p)
        todo += children.get(p, [])
    return tree


def _address(hex_addr: str) -> tuple[str, int]:
    host, port = hex_addr.split(":")
    raw = bytes.fromhex(host)
    words = b"".join(struct.pack("<I", w) for w in struct.unpack(f">{len(raw) // 4}I", raw))
    family = socket.AF_INET if len(raw) == 4 else socket.AF_INET6
    return socket.inet_ntop(family, words), int(port, 16)


def listening_table() -> dict[int, tuple[str, int]]:
    """Socket inode -> (address, port) of every TCP socket in LISTEN state (IPv4 and IPv6)."""
    table = {}
    for name in ("tcp", "tcp6"):
        try:
            lines = Path(f"/proc/net/{name}").read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if fields[3] == LISTEN:
                table[int(fields[9])] = _address(fields[1])
    return table


def _socket_inodes(pid: int) -> set[int]:
    inodes = set()
    try:
        fds = list(Path(f"/proc/{pid}/fd").iterdir())
    except OSError:
        return inodes
    for fd in fds:
        try:
            target = fd.readlink().name
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(int(target[8:-1]))
    return inodes


def listeners(pid: int) -> list[Listener]:
    """Every TCP listener held by ``pid`` or a process below it."""
    table = listening_table()
    found = {}
    for p in descendants(pid):
        for inode in _socket_inodes(p):
            if inode in table:
                found[inode] = Listener(*table[inode], p)
    return sorted(found.values(), key=lambda x: (x.pid, x.port))


def http_status(host: str, port: int, path: str = "/health", timeout: float = 3.0) -> int | None:
    """The status code of ``GET path`` on ``host:port``, or None if no HTTP answer comes."""
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            sock.sendall(f"GET {path} HTTP/1.0\r\nHost: {host}\r\n\r\n".encode())
            head = sock.recv(64)
    except OSError:
        return None
    parts = head.split()
    return int(parts[1]) if head.startswith(b"HTTP/") and len(parts) > 1 and parts[1].isdigit() else None


def client_context(cert: Path | None = None, key: Path | None = None, ca: Path | None = None) -> ssl.SSLContext:
    """A TLS client context presenting ``cert``/``key`` (none: no certificate) that checks the server against
    ``ca`` (none: accepts any server, so a refusal can only be the server's)."""
    ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH)
    ctx.check_hostname = False
    if ca is None:
        ctx.verify_mode = ssl.CERT_NONE
    else:
        ctx.load_verify_locations(str(ca))
    if cert is not None:
        ctx.load_cert_chain(str(cert), str(key))
    return ctx


async def _identity(address: str, ctx: ssl.SSLContext | None, timeout: float) -> str:
    from distributed.comm import connect

    args = {"ssl_context": ctx} if ctx is not None else {}
    try:
        comm = await asyncio.wait_for(connect(address, timeout=timeout, **args), timeout + 1.0)
        try:
            await comm.write({"op": "identity", "reply": True})
            reply = await asyncio.wait_for(comm.read(), timeout)
        finally:
            comm.abort()
    except Exception as exc:  # any failure to get an answer is a refusal; its kind is reported
        return f"refused ({type(exc).__name__})"
    return f"answered: {reply.get('type') if isinstance(reply, dict) else reply!r}"


def dask_identity(attempts: list[tuple[str, ssl.SSLContext | None]], timeout: float = 3.0) -> list[str]:
    """Ask the Dask server at each ``(address, ctx)`` (``tcp://`` or ``tls://HOST:PORT``, ``ctx`` for TLS) for its
    identity, all at once; for each, ``answered: <its type>`` or ``refused (<exception>)``."""

    async def ask() -> list[str]:
        return await asyncio.gather(*(_identity(a, ctx, timeout) for a, ctx in attempts))

    return asyncio.run(ask())
