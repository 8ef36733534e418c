"""The zenoh side of the bus: client/router configs, credentials, access control and :class:`ZenohBus`.

This is the only module besides the process shells that imports zenoh.
Topology: one router process (``auv-swarm router``) listens on a TCP endpoint;
every other process is a zenoh *client* with that endpoint as its explicit
``connect`` endpoint and multicast scouting off. Clients authenticate with a
user name and password (zenoh ``usrpwd``); the router applies an access-control
list per user name with default deny (:func:`acl_roles`). Across hosts: a
``tls/HOST:PORT`` endpoint, mutual TLS, the list per certificate name (bus/tls.py).
"""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import zenoh

from auv_swarm.bus import tls
from auv_swarm.bus.acl import Role, access_control, acl_roles  # noqa: F401  (zbus.acl_roles etc., as before)
from auv_swarm.bus.bus import LivelinessCallback, check_key, check_key_expr
from auv_swarm.bus.credentials import (
    COMPONENT_USERS,
    MAX_AGENTS,
    agent_user,
    derive,
    password_for,
    users,
    users_text,
)
from auv_swarm.contract import keys, wire

__all__ = ["COMPONENT_USERS", "ZenohBus", "agent_user", "credentials", "password_for", "users"]

log = logging.getLogger(__name__)

DEFAULT_CONNECT_TIMEOUT_MS = 3000
RETRY_ENV = "AUVSWARM_CONNECT_RETRY_S"
"""Env: wall seconds a client keeps retrying an unreachable router before giving up (default 0: one try)."""
PROBE_TIMEOUT_S = 1.0
MAX_TRANSPORT_MESSAGE_BYTES = 2 * wire.MAX_MESSAGE_BYTES
"""The largest message a zenoh link reassembles (zenoh's default is 1 GiB): twice the largest wire message."""


def _harden(conf: zenoh.Config) -> None:
    """Bound what a peer can make this session hold: no shared-memory segments of other processes
    mapped in (zenoh maps a publisher's 16 MB pool into every local receiver), and no message
    reassembled beyond :data:`MAX_TRANSPORT_MESSAGE_BYTES`."""
    conf.insert_json5("transport/shared_memory/enabled", "false")
    conf.insert_json5("transport/link/rx/max_message_size", json.dumps(MAX_TRANSPORT_MESSAGE_BYTES))


def credentials(secret: str, agents: int = MAX_AGENTS) -> dict[str, str]:
    """user -> password for every user of :func:`bus.credentials.users`, derived from ``secret``."""
    return derive(secret, agents)


def client_config(
    endpoint: str,
    user: str | None = None,
    password: str | None = None,
    connect_timeout_ms: int = DEFAULT_CONNECT_TIMEOUT_MS,
    tls_dir: Path | None = None,
) -> zenoh.Config:
    """A zenoh client config: explicit ``connect`` endpoint (e.g. ``tcp/127.0.0.1:7447``), no multicast scouting.

    With ``user`` and ``password`` the client authenticates with zenoh ``usrpwd``; with ``user`` and ``tls_dir``
    (a ``tls/`` endpoint) by its certificate in that folder (:func:`tls.zenoh_section`).
    Opening fails after ``connect_timeout_ms`` (ms) when the router is not up.
    """
    check_endpoint(endpoint)
    tls.check_scheme(endpoint, tls_dir)
    if tls_dir is None and (user is None) != (password is None):
        raise ValueError("user and password must be given together (or neither)")
    if tls_dir is not None and (user is None or password is not None):
        raise ValueError("a TLS client names its user (its certificate's) and gives no password")
    if isinstance(connect_timeout_ms, bool) or not isinstance(connect_timeout_ms, int) or connect_timeout_ms < 1:
        raise ValueError(f"connect_timeout_ms must be an integer >= 1 ms, got {connect_timeout_ms!r}")
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("client"))
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("connect/timeout_ms", json.dumps(connect_timeout_ms))
    conf.insert_json5("scouting/multicast/enabled", "false")
    _harden(conf)
    if tls_dir is not None:
        conf.insert_json5("transport/link/tls", json.dumps(tls.zenoh_section(tls_dir, user, "connect")))
    elif user is not None:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return conf


def check_endpoint(endpoint: str) -> str:
    """``endpoint`` if it looks like ``tcp/HOST:PORT`` (or another zenoh protocol), else ValueError."""
    proto, sep, addr = str(endpoint).partition("/")
    if not sep or proto not in ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream") or not addr:
        raise ValueError(f"endpoint must look like tcp/HOST:PORT (e.g. tcp/127.0.0.1:7447), got {endpoint!r}")
    return endpoint


def router_config(
    listen: str,
    credentials: dict[str, str],
    acl: bool = True,
    *,
    agents: int = MAX_AGENTS,
    prefix: str = wire.PREFIX,
    dictionary_file: Path | None = None,
    tls_dir: Path | None = None,
) -> zenoh.Config:
    """A zenoh router config: ``listen`` endpoint, no scouting, ``usrpwd`` users and (with ``acl``) the ACL.

    zenoh reads the user/password dictionary from a file: it is written to
    ``dictionary_file`` or else to a private (mode 0600) temporary file; the path
    is in the config at ``transport/auth/usrpwd/dictionary_file``. zenoh reads the
    file when the session opens, so it may be deleted right after (as
    :func:`open_router` does). Empty ``credentials`` means no authentication (and
    then ``acl`` must be False: the ACL is keyed by user name).
    With ``tls_dir`` (a ``tls/`` endpoint, no ``credentials``): mutual TLS (:func:`tls.zenoh_section`), the
    ACL keyed by certificate name, and the admin space on (the router's session list; no client may query it).
    """
    check_endpoint(listen)
    tls.check_scheme(listen, tls_dir)
    if tls_dir is not None and credentials:
        raise ValueError("a TLS router knows its clients by their certificates: no user table")
    if acl and not credentials and tls_dir is None:
        raise ValueError("acl=True needs credentials: the access-control list is keyed by user name")
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("router"))
    conf.insert_json5("listen/endpoints", json.dumps([listen]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    _harden(conf)
    if tls_dir is not None:
        conf.insert_json5("transport/link/tls", json.dumps(tls.zenoh_section(tls_dir, tls.ROUTER, "listen")))
        conf.insert_json5("adminspace", json.dumps({"enabled": True, "permissions": {"read": True, "write": False}}))
    if credentials:
        text = users_text(credentials)
        if dictionary_file is None:
            fd, name = tempfile.mkstemp(prefix="auvswarm-users-", suffix=".txt")  # made 0600
            os.close(fd)
            dictionary_file = name
        dictionary_file = Path(dictionary_file)
        tls.write_private(dictionary_file, text.encode())
        conf.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(dictionary_file)))
    if acl:
        subject = "usernames" if tls_dir is None else "cert_common_names"
        conf.insert_json5("access_control", json.dumps(access_control(acl_roles(agents, prefix), prefix, subject)))
    return conf


def router_listening(endpoint: str, timeout_s: float = PROBE_TIMEOUT_S) -> bool:
    """True when a TCP connection to ``endpoint`` (``tcp/`` or ``tls/HOST:PORT``) opens: something listens there."""
    proto, _, addr = str(endpoint).partition("/")
    host, _, port = addr.rpartition(":")
    if proto not in ("tcp", "tls") or not host or not port.isdigit():
        return False
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s):
            return True
    except OSError:
        return False


def open_failure(config: zenoh.Config) -> str:
    """One line saying why a client session could not open: refused login or unreachable router.

    zenoh reports both as a timeout, so the router's TCP port is probed: if it accepts a
    connection, the router is up and refused the credentials.
    """
    endpoints = _config_value(config, "connect/endpoints") or _config_value(config, "listen/endpoints") or []
    user = _config_value(config, "transport/auth/usrpwd/user")
    cert = _config_value(config, "transport/link/tls/connect_certificate")
    who = f"user {user}" if user else "a client without credentials"
    if any(router_listening(e) for e in endpoints) and cert:
        return (
            f"authentication failed: no TLS session with the router at {', '.join(endpoints)}: it refused the "
            f"certificate {cert}, or its own does not name the host dialled (credentials --tls --router-host)"
        )
    if any(router_listening(e) for e in endpoints):
        return f"authentication failed: the router at {', '.join(endpoints)} refused {who}"
    return f"router unreachable at {', '.join(endpoints)} (nothing accepts connections there)"


def _config_value(config: zenoh.Config, key: str) -> Any:
    """A config value as Python data (zenoh returns JSON text)."""
    return json.loads(config.get_json(key))


@contextmanager
def open_router(config: zenoh.Config) -> Iterator[zenoh.Session]:
    """Open a router session from :func:`router_config`, delete its dictionary file, close it on exit."""
    path = _config_value(config, "transport/auth/usrpwd/dictionary_file")
    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:
        raise ConnectionError(
            f"zenoh router could not open on {_config_value(config, 'listen/endpoints')}: {exc}"
        ) from exc
    finally:
        if path:
            Path(path).unlink(missing_ok=True)
    try:
        yield session
    finally:
        session.close()


# The bus ------------------------------------------------------------------------------------------------------------


class Oversize:
    """Stands for a sample too large to copy (see :meth:`ZenohBus.subscribe`); ``len()`` is its size in bytes."""

    __slots__ = ("nbytes",)

    def __init__(self, nbytes: int) -> None:
        self.nbytes = nbytes

    def __len__(self) -> int:
        return self.nbytes


class ZenohBus:
    """:class:`bus.bus.Bus` over a zenoh session (use as a context manager, or call :meth:`close`).

    Publishers are declared once per key and cached. Callbacks run on zenoh's
    threads; an exception in one is logged and counted in ``callback_errors``,
    never propagated. A session with Python callbacks left open hangs the
    interpreter's exit, so :meth:`close` undeclares everything and closes it.
    """

    def __init__(
        self,
        target: str | zenoh.Config,
        user: str | None = None,
        password: str | None = None,
        connect_timeout_ms: int = DEFAULT_CONNECT_TIMEOUT_MS,
        tls_dir: Path | None = None,
    ) -> None:
        """Open a client session to the router endpoint ``target`` (e.g. ``tcp/127.0.0.1:7447``) as ``user``
        (:func:`client_config`), or a session from a ready ``zenoh.Config``. Raises ConnectionError when the
        session cannot open; its message says "authentication failed" when the router is up but refused the login, and
        "router unreachable" when nothing listens (see :func:`open_failure`)."""
        if isinstance(target, zenoh.Config):
            if user is not None or password is not None or tls_dir is not None:
                raise ValueError("user, password and tls_dir belong in the zenoh.Config when a config is given")
            config = target
        else:
            config = client_config(target, user, password, connect_timeout_ms, tls_dir)
        self._session = open_with_retry(config, retry_seconds())
        self._lock = threading.Lock()
        self._publishers: dict[str, Any] = {}
        self._handles: list[Any] = []
        self._closed = False
        self._session_id = str(self._session.zid())
        self._stamp = self._session_id.encode()
        self.callback_errors = 0

    @classmethod
    def connect(
        cls,
        endpoint: str,
        user: str,
        secret: str,
        connect_timeout_ms: int = DEFAULT_CONNECT_TIMEOUT_MS,
    ) -> ZenohBus:
        """A client bus to the router at ``endpoint`` as ``user``, its password derived from the run's ``secret``."""
        return cls(endpoint, user, password_for(user, secret), connect_timeout_ms)

    def __enter__(self) -> ZenohBus:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    @property
    def session(self) -> zenoh.Session:
        """The underlying zenoh session."""
        return self._session

    @property
    def session_id(self) -> str:
        """This session's zenoh id (hex): every publication carries it as its attachment (see :meth:`subscribe`)."""
        return self._session_id

    def publish(self, key: str, payload: bytes) -> None:
        """Put ``payload`` on ``key`` through a cached publisher.

        The publisher blocks while an outgoing queue is full (zenoh's default for a put drops the
        message), so a subscriber that falls behind, a process starved of CPU say, gets every
        message late rather than some never.
        """
        with self._lock:
            if self._closed:
                raise RuntimeError("ZenohBus is closed")
            pub = self._publishers.get(key)
            if pub is None:
                pub = self._session.declare_publisher(check_key(key), congestion_control=zenoh.CongestionControl.BLOCK)
                self._publishers[key] = pub
        pub.put(bytes(payload), attachment=self._stamp)

    def subscribe(
        self, key_expr: str, callback: Callable[..., None], max_bytes: int | None = None, sender: bool = False
    ) -> Any:
        """Call ``callback(key, payload)`` for every sample on ``key_expr``; returns the zenoh subscriber.

        With ``max_bytes``, a sample larger than that is not copied out of zenoh: the callback
        gets an :class:`Oversize` (whose ``len()`` is the sample's size) to count and drop.
        With ``sender``, ``callback(key, payload, session)``: ``session`` is the session id the publisher
        attached (:meth:`publish`), or None. The publisher writes it: a client can claim any session id,
        so it names a session only as far as the ids of the others stay unknown to it (docs/security.md).
        """
        check_key_expr(key_expr)

        def on_sample(sample: zenoh.Sample) -> None:
            payload = sample.payload
            n = len(payload)
            data = Oversize(n) if max_bytes is not None and n > max_bytes else payload.to_bytes()
            if sender:
                self._guard(callback, str(sample.key_expr), data, session_of(sample))
            else:
                self._guard(callback, str(sample.key_expr), data)

        return self._keep(self._session.declare_subscriber(key_expr, on_sample))

    def declare_liveliness(self, key: str) -> Any:
        """Declare a liveliness token on ``key``; it vanishes on undeclare, close, or process death."""
        return self._keep(self._session.liveliness().declare_token(check_key(key)))

    def subscribe_liveliness(self, key_expr: str, on_change: LivelinessCallback, history: bool = True) -> Any:
        """Call ``on_change(key, alive)`` when a token on ``key_expr`` appears (True) or vanishes (False).

        With ``history`` the tokens alive at declaration time are reported too.
        """
        check_key_expr(key_expr)

        def on_sample(sample: zenoh.Sample) -> None:
            self._guard(on_change, str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

        return self._keep(self._session.liveliness().declare_subscriber(key_expr, on_sample, history=history))

    def close(self) -> None:
        """Undeclare every publisher, subscriber and token, then close the session (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            entities = [*self._handles, *self._publishers.values()]
            self._handles.clear()
            self._publishers.clear()
        for entity in entities:
            try:
                entity.undeclare()
            except zenoh.ZError:
                log.debug("undeclare failed during close", exc_info=True)
        self._session.close()

    def _keep(self, handle: Any) -> Any:
        with self._lock:
            if self._closed:
                handle.undeclare()
                raise RuntimeError("ZenohBus is closed")
            self._handles.append(handle)
        return handle

    def _guard(self, fn: Callable[..., None], key: str, *args: Any) -> None:
        try:
            fn(key, *args)
        except Exception:
            with self._lock:
                self.callback_errors += 1
            log.exception("bus callback failed for %r", key)


def session_of(sample: zenoh.Sample) -> str | None:
    """The session id a sample's publisher attached (:meth:`ZenohBus.publish`), or None (none, or not one)."""
    attachment = sample.attachment
    if attachment is None:
        return None
    raw = attachment.to_bytes()
    if len(raw) > keys.MAX_SESSION_ID_CHARS:  # not decoded at all when longer
        return None
    text = raw.decode("ascii", errors="replace")
    return text if keys.is_session_id(text) else None


def retry_seconds() -> float:
    """How long clients retry an unreachable router (env ``AUVSWARM_CONNECT_RETRY_S``, wall s, default 0)."""
    text = os.environ.get(RETRY_ENV, "0")
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{RETRY_ENV} must be a number of seconds >= 0, got {text!r}") from None
    if not value >= 0:
        raise ValueError(f"{RETRY_ENV} must be a number of seconds >= 0, got {text!r}")
    return value


def open_with_retry(config: zenoh.Config, retry_s: float) -> zenoh.Session:
    """``zenoh.open(config)``; a client retries for ``retry_s`` wall seconds while the router is unreachable.

    A refused login (the router's port accepted a connection before and after the attempt,
    :func:`open_failure`) fails at once; a router that came up during the attempt is tried
    again. Raises ConnectionError with :func:`open_failure`'s one line.
    """
    endpoints = _config_value(config, "connect/endpoints") or []
    client = _config_value(config, "mode") == "client"
    deadline = time.monotonic() + retry_s
    while True:
        up_before = any(router_listening(e) for e in endpoints)
        try:
            return zenoh.open(config)
        except zenoh.ZError as exc:
            error = exc
        message = open_failure(config)
        refused = message.startswith("authentication failed")
        if not client or (refused and up_before) or time.monotonic() >= deadline:
            waited = f" (retried for {retry_s:g} s)" if retry_s > 0 and not refused else ""
            raise ConnectionError(message + waited) from error
        time.sleep(0.5)


def shutdown_event() -> threading.Event:
    """An event set by SIGTERM or SIGINT (install from the main thread of a process shell); the signal's number
    is kept as ``event.signum``."""
    event = threading.Event()

    def handler(signum: int, _frame: object) -> None:
        event.signum = signum  # type: ignore[attr-defined]
        event.set()

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)
    return event
