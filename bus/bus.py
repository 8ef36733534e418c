"""The message bus interface, and a deterministic in-memory implementation.

Every process shell talks to the others through a :class:`Bus`: ``publish`` bytes
on a key, ``subscribe`` a callback to a key expression. :class:`InMemoryBus` runs
a whole swarm in one process (unit tests, fast Monte-Carlo batches);
``bus.zbus.ZenohBus`` carries the same traffic over eclipse-zenoh.

Key expressions follow zenoh: keys are ``/``-separated non-empty chunks; in an
expression ``*`` matches exactly one chunk and ``**`` matches any number of
chunks (including none).
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from functools import lru_cache
from typing import Any, Protocol

from auv_swarm.contract.methods import MethodError

log = logging.getLogger(__name__)

Callback = Callable[[str, Any], None]
LivelinessCallback = Callable[[str, bool], None]

_WILDCARDS = ("*", "**")


class Handle(Protocol):
    """What ``subscribe`` returns: call ``undeclare()`` to stop the deliveries."""

    def undeclare(self) -> None: ...


class Bus(Protocol):
    """Publish/subscribe transport between the swarm's components."""

    def publish(self, key: str, payload: bytes) -> None:
        """Send ``payload`` on the concrete key ``key``."""

    def subscribe(self, key_expr: str, callback: Callback) -> Handle:
        """Call ``callback(key, payload)`` for every publication matching ``key_expr``."""

    def close(self) -> None:
        """Release the bus; no delivery happens afterwards."""


class LivelinessBus(Bus, Protocol):
    """A bus that also carries liveliness tokens (presence of a component)."""

    def declare_liveliness(self, key: str) -> Handle:
        """Announce that this component is alive under ``key`` until the handle is undeclared or the bus closes."""

    def subscribe_liveliness(self, key_expr: str, on_change: LivelinessCallback, history: bool = True) -> Handle:
        """Call ``on_change(key, alive)`` when a token matching ``key_expr`` appears or vanishes."""


def _chunks(text: str, what: str, allow_wildcards: bool) -> list[str]:
    if not isinstance(text, str) or not text:
        raise ValueError(f"{what} must be a non-empty string of '/'-separated chunks, got {text!r}")
    parts = text.split("/")
    for part in parts:
        if not part:
            raise ValueError(f"{what} must not have empty chunks (leading, trailing or double '/'), got {text!r}")
        if "*" in part and (not allow_wildcards or part not in _WILDCARDS):
            allowed = "'*' or '**' as a whole chunk" if allow_wildcards else "no wildcards"
            raise ValueError(f"{what} may contain {allowed}, got {text!r}")
    return parts


def check_key(key: str) -> str:
    """Return ``key`` if it is a valid concrete key (no wildcards), else raise ValueError naming it."""
    _chunks(key, "key", allow_wildcards=False)
    return key


def check_key_expr(key_expr: str) -> str:
    """Return ``key_expr`` if it is a valid key expression (``*``/``**`` chunks allowed), else raise ValueError."""
    _chunks(key_expr, "key_expr", allow_wildcards=True)
    return key_expr


@lru_cache(maxsize=4096)
def key_matches(expr: str, key: str) -> bool:
    """True if the concrete ``key`` matches the key expression ``expr`` (``*`` one chunk, ``**`` any chunks)."""
    pattern = _chunks(expr, "key_expr", allow_wildcards=True)
    chunks = _chunks(key, "key", allow_wildcards=False)
    # reachable[j]: pattern[:i] can match chunks[:j]
    reachable = [True] + [False] * len(chunks)
    for part in pattern:
        if part == "**":
            seen = False
            for j in range(len(reachable)):
                seen = seen or reachable[j]
                reachable[j] = seen
        else:
            reachable = [False] + [reachable[j] and (part == "*" or part == chunks[j]) for j in range(len(chunks))]
    return reachable[-1]


class _Subscription:
    """A data subscription (``callback(key, payload)``) or a liveliness one (``callback(key, alive)``); ``drop``
    takes it off its bus's list when it is undeclared."""

    def __init__(self, key_expr: str, callback: Callable[..., None], drop: Callable[[_Subscription], None]) -> None:
        self.key_expr = key_expr
        self.callback = callback
        self.active = True
        self._drop = drop

    def undeclare(self) -> None:
        self.active = False
        self._drop(self)


class _Token:
    def __init__(self, bus: InMemoryBus, key: str) -> None:
        self._bus = bus
        self.key = key
        self.active = True

    def undeclare(self) -> None:
        if self.active:
            self.active = False
            self._bus._drop_token(self)


class InMemoryBus:
    """A synchronous, deterministic bus inside one process.

    Deliveries run in subscription order. A publication made from inside a
    callback is queued and delivered after the current one (first in, first
    out), so when a top-level ``publish`` returns every cascade it caused has
    been delivered. A callback that raises is logged and counted in
    ``callback_errors``; the other subscribers still get the message.

    Payloads are delivered as published: bytes-like payloads as an immutable
    ``bytes`` copy, anything else (the in-process swarm passes decoded, frozen
    ``contract.wire`` messages) as the same object.
    """

    def __init__(self) -> None:
        self._subs: list[_Subscription] = []
        self._routes: dict[str, tuple[tuple[_Subscription, Callback], ...]] = {}
        self._tokens: list[_Token] = []
        self._live_subs: list[_Subscription] = []
        self._queue: deque[tuple[tuple[tuple[Any, Callable[..., None]], ...], tuple[Any, ...]]] = deque()
        self._dispatching = False
        self._closed = False
        self.callback_errors = 0
        self.published = 0

    def publish(self, key: str, payload: Any) -> None:
        """Deliver ``payload`` to every subscription whose expression matches ``key``."""
        targets = self._routes.get(key)
        if targets is None:  # close() empties the routes, so a cached route implies an open bus
            self._check_open()
            check_key(key)
            targets = self._routes[key] = tuple(
                (sub, sub.callback) for sub in self._subs if key_matches(sub.key_expr, key)
            )
        self.published += 1
        if isinstance(payload, (bytearray, memoryview)):
            payload = bytes(payload)
        self._queue.append((targets, (key, payload)))
        if not self._dispatching:
            self._drain()

    def subscribe(self, key_expr: str, callback: Callback) -> _Subscription:
        """Register ``callback(key, payload)`` for keys matching ``key_expr``."""
        self._check_open()
        check_key_expr(key_expr)
        sub = _Subscription(key_expr, callback, self._drop_subscription)
        self._subs.append(sub)
        self._routes.clear()
        return sub

    def declare_liveliness(self, key: str) -> _Token:
        """Declare a liveliness token; subscribers see ``(key, True)`` now and ``(key, False)`` on undeclare/close."""
        self._check_open()
        check_key(key)
        token = _Token(self, key)
        self._tokens.append(token)
        self._notify_liveliness(key, True)
        return token

    def subscribe_liveliness(self, key_expr: str, on_change: LivelinessCallback, history: bool = True) -> _Subscription:
        """Call ``on_change(key, alive)`` for tokens matching ``key_expr``; ``history`` replays the live ones."""
        self._check_open()
        check_key_expr(key_expr)
        sub = _Subscription(key_expr, on_change, self._drop_liveliness_subscription)
        self._live_subs.append(sub)
        if history:
            for key in sorted({t.key for t in self._tokens}):
                if key_matches(key_expr, key):
                    self._queue.append((((sub, on_change),), (key, True)))
            self._drain()
        return sub

    def close(self) -> None:
        """Undeclare every token (subscribers are told) and drop every subscription."""
        if self._closed:
            return
        for token in list(self._tokens):
            token.undeclare()
        self._closed = True
        self._subs.clear()
        self._routes.clear()
        self._live_subs.clear()
        self._queue.clear()

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return self._closed

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("InMemoryBus is closed")

    def _drain(self) -> None:
        """Deliver the queued publications in order, each to its targets in subscription order."""
        if self._dispatching:
            return
        self._dispatching = True
        queue = self._queue
        try:
            while queue:
                targets, args = queue.popleft()
                for sub, fn in targets:
                    if not sub.active or self._closed:
                        continue
                    try:
                        fn(*args)
                    except MethodError:  # a plug-in method failed: the in-process mission ends (docs/python.md)
                        raise
                    except Exception:
                        self.callback_errors += 1
                        log.exception("bus callback failed for %r", args[0])
        finally:
            self._dispatching = False

    def _notify_liveliness(self, key: str, alive: bool) -> None:
        for sub in list(self._live_subs):
            if key_matches(sub.key_expr, key):
                self._queue.append((((sub, sub.callback),), (key, alive)))
        self._drain()

    def _drop_subscription(self, sub: _Subscription) -> None:
        if sub in self._subs:
            self._subs.remove(sub)
        self._routes.clear()

    def _drop_liveliness_subscription(self, sub: _Subscription) -> None:
        if sub in self._live_subs:
            self._live_subs.remove(sub)

    def _drop_token(self, token: _Token) -> None:
        self._tokens.remove(token)
        if not any(t.key == token.key for t in self._tokens):
            self._notify_liveliness(token.key, False)
