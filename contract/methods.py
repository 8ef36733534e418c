"""The names ``planner.method`` and ``estimator.method`` may take: one registry of the methods and where each lives.

A method is one of

- a built-in (:data:`BUILTIN`: its name and where its factory is, ``module:QualName``);
- registered by name in this process (``agent.methods.register``, ``agent.estimator.register``), with the
  reference of its factory (``module:QualName``, or ``/path/to/file.py:QualName`` for a script's) or none
  (a lambda, a closure: it runs in this process only);
- handed down by reference in :data:`METHODS_ENV` (the launcher sets it for its children and the sweep's client
  for its workers' missions, from the registrations above);
- an installed plug-in: an entry point of the group :data:`GROUPS` names (``auv_swarm.planners``,
  ``auv_swarm.estimators``), read with ``importlib.metadata`` without importing it.

This module knows names, references and versions only; the factories are the agent's (``agent/plugins.py``
resolves a reference). A plug-in that raises is a failed mission (``incomplete_reason`` :data:`METHOD_ERROR`,
docs/python.md).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

KINDS = ("planner", "estimator")
"""The two kinds of method; a scenario picks one of each (``planner.method``, ``estimator.method``)."""

GROUPS = {"planner": "auv_swarm.planners", "estimator": "auv_swarm.estimators"}
"""The entry point group of each kind: a package declares ``name = "module:QualName"`` under it."""

BUILTIN: dict[str, dict[str, str | None]] = {
    "planner": {
        "dmpc": "auv_swarm.agent.planner.protocol:DmpcPlanner",
        "dec-mpc": "auv_swarm.agent.baselines.decmpc:DecMpcPlanner",
        "dpso": "auv_swarm.agent.baselines.dpso:DpsoPlanner",
        "centralised": None,  # the AUVs do not plan: they follow the central planner (central/)
    },
    "estimator": {
        "wls-cv": "auv_swarm.agent.estimator.window:BearingEstimator",
        "adaptive-window": "auv_swarm.agent.estimator.adaptive:AdaptiveWindowEstimator",
    },
}
"""The built-in methods of each kind, name -> factory reference: the one list of them."""

METHODS_ENV = "AUVSWARM_METHODS"
"""Environment variable: JSON ``{"planner": {name: reference}, "estimator": {...}}`` of methods registered by
reference in a parent process (set by the launcher for its children and by a sweep for its missions)."""

METHOD_ERROR = "method_error"
"""The ``incomplete_reason`` of a mission whose plug-in method raised; an AUV process says it on its last line as
``error: method_error: <message>`` before it exits 1."""


class MethodError(RuntimeError):
    """A plug-in method raised, or gave the agent something it cannot use; the message is one line."""


@dataclass(frozen=True)
class Method:
    """One method: its kind and name, where it comes from and, for a plug-in, its package and version.

    ``origin`` is ``built-in``, ``registered`` (in this process or handed down by :data:`METHODS_ENV`) or
    ``entry point``; ``ref`` the factory's reference (None for ``centralised`` and a factory that cannot be
    referenced, whose ``what`` says why: a lambda, a closure).
    """

    kind: str
    name: str
    origin: str
    ref: str | None
    distribution: str | None = None
    version: str | None = None
    what: str = ""

    def record(self) -> dict[str, Any]:
        """What metrics.json and the sweep store keep of a plug-in: kind, name, reference, package, version."""
        dist, version = self.distribution, self.version
        if dist is None and version is None and self.ref is not None:
            dist, version = _provenance(self.ref)
        return {"kind": self.kind, "name": self.name, "ref": self.ref, "distribution": dist, "version": version}


_registered: dict[str, dict[str, Method]] = {kind: {} for kind in KINDS}


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")


@functools.cache
def entry_points(kind: str) -> dict[str, Method]:
    """The installed plug-ins of ``kind`` by name (read once per process, nothing imported); a built-in name is
    the built-in's."""
    _check_kind(kind)
    found: dict[str, Method] = {}
    for ep in metadata.entry_points(group=GROUPS[kind]):
        if ep.name in BUILTIN[kind] or ep.name in found:
            continue
        dist = getattr(ep, "dist", None)
        found[ep.name] = Method(
            kind,
            ep.name,
            "entry point",
            ep.value.replace(" ", ""),
            None if dist is None else dist.name,
            None if dist is None else dist.version,
        )
    return found


def _handed_down(kind: str) -> dict[str, str]:
    text = os.environ.get(METHODS_ENV, "")
    if not text:
        return {}
    try:
        table = json.loads(text).get(kind, {})
    except (ValueError, AttributeError):
        return {}
    return {str(k): str(v) for k, v in table.items()} if isinstance(table, dict) else {}


def lookup(kind: str, name: str) -> Method | None:
    """The method ``name`` of ``kind``, or None: built-in first, then registered here, handed down, installed."""
    _check_kind(kind)
    if name in BUILTIN[kind]:
        return Method(kind, name, "built-in", BUILTIN[kind][name])
    if name in _registered[kind]:
        return _registered[kind][name]
    ref = _handed_down(kind).get(name)
    if ref is not None:
        return Method(kind, name, "registered", ref)
    return entry_points(kind).get(name)


def names(kind: str) -> tuple[str, ...]:
    """Every name ``kind`` may take here: the built-ins, then the registered, handed-down and installed ones."""
    _check_kind(kind)
    seen = dict.fromkeys([*BUILTIN[kind], *_registered[kind], *_handed_down(kind), *sorted(entry_points(kind))])
    return tuple(seen)


def add(kind: str, name: str, ref: str | None, what: str = "") -> None:
    """Make ``name`` a method of ``kind`` in this process, its factory at ``ref`` (None: not referenceable, ``what``
    says what it is). ``agent.methods.register`` and ``agent.estimator.register`` call it. Raises ValueError for
    an empty name, a built-in's or one taken by another factory (the same reference again is no change)."""
    _check_kind(kind)
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"a {kind}'s name must be a non-empty string, got {name!r}")
    if name in BUILTIN[kind]:
        raise ValueError(f"{kind} method {name!r} is built in ({', '.join(BUILTIN[kind])}); choose another name")
    have = lookup(kind, name)
    if have is not None and (ref is None or have.ref != ref):
        where = f"from {have.ref}" if have.ref else f"({have.what})"
        raise ValueError(f"{kind} method {name!r} is registered already ({have.origin} {where})")
    _registered[kind][name] = Method(kind, name, "registered", ref, what=what)


def remove(kind: str, name: str) -> None:
    """Forget the method ``name`` registered in this process (tests)."""
    _registered[kind].pop(name, None)


def picked(scenario: Any) -> list[tuple[str, str]]:
    """(kind, name) of the two methods ``scenario`` picks."""
    return [("planner", scenario.planner.method), ("estimator", scenario.estimator.method)]


def plugins(scenario: Any) -> list[dict[str, Any]]:
    """:meth:`Method.record` of every method of ``scenario`` that is not built in (metrics.json ``plugins``)."""
    found = [lookup(kind, name) for kind, name in picked(scenario) if name not in BUILTIN[kind]]
    return [m.record() for m in found if m is not None]


def not_portable(kind: str, name: str) -> str | None:
    """One line if the method ``name`` exists in this process only (a lambda, a closure registered here), else
    None: another process (an AUV process, a sweep worker) cannot import its factory."""
    m = lookup(kind, name)
    if m is None or m.origin != "registered" or m.ref is not None:
        return None
    return (
        f"{kind} method {name!r} is {m.what}, which another process cannot import: define it at the top level of "
        "a module or script and register that"
    )


def child_env() -> dict[str, str]:
    """``{METHODS_ENV: ...}`` with every method registered by reference here (and handed down to here), for a
    child process or a sweep's mission; empty when there is none."""
    table: dict[str, dict[str, str]] = {}
    for kind in KINDS:
        refs = {**_handed_down(kind), **{n: m.ref for n, m in _registered[kind].items() if m.ref is not None}}
        if refs:
            table[kind] = refs
    return {METHODS_ENV: json.dumps(table, sort_keys=True)} if table else {}


def method_error_line(log: str) -> str | None:
    """The message of the last ``error: method_error: ...`` line of an AUV process's log, or None."""
    mark = f"error: {METHOD_ERROR}: "
    found = [line[len(mark) :].strip() for line in log.splitlines() if line.startswith(mark)]
    return found[-1] if found else None


class MethodNames:
    """The ``choices`` of ``planner.method`` or ``estimator.method``: the names :func:`names` gives, looked up when
    a value is checked (so a registration or an installed plug-in counts at once). ``builtin`` are the built-ins
    alone (the scenario reference, docs/scenarios.md)."""

    def __init__(self, kind: str) -> None:
        _check_kind(kind)
        self.kind = kind
        self.builtin = tuple(BUILTIN[kind])

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and lookup(self.kind, name) is not None

    def __iter__(self):
        return iter(names(self.kind))

    def __len__(self) -> int:
        return len(names(self.kind))

    def __bool__(self) -> bool:  # a check ``if choices`` needs no look at the installed packages
        return True


@functools.cache
def _provenance(ref: str) -> tuple[str | None, str | None]:
    """(package, version) of a factory's reference: for a script (``/path/file.py:QualName``) no package and
    ``sha256:<12 hex>`` of the file; for ``module:QualName`` the installed package that holds the module and its
    version, or (None, None)."""
    target = ref.rpartition(":")[0]
    if target.endswith(".py"):
        try:
            return None, "sha256:" + hashlib.sha256(Path(target).read_bytes()).hexdigest()[:12]
        except OSError:
            return None, None
    for dist in metadata.packages_distributions().get(target.split(".")[0], []):
        try:
            return dist, metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return None, None
