"""Method factories by reference: what :mod:`agent.methods` and :mod:`agent.estimator` build a named method with.

The names, and where each factory is, are :mod:`auv_swarm.contract.methods`'s. A reference is ``module:QualName``
(an importable module) or ``/path/to/file.py:QualName`` (a script, loaded under a module name of its own, so its
``if __name__ == "__main__":`` block does not run). This module turns a factory into its reference
(:func:`reference`), a reference into the factory (:func:`load`), and wraps a plug-in so that what it raises, or
returns and the agent cannot use, is a :class:`~auv_swarm.contract.methods.MethodError` naming the AUV and the
method (a failed mission, ``incomplete_reason = "method_error"``).
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from auv_swarm.contract import methods
from auv_swarm.contract.methods import MethodError
from auv_swarm.contract.params import ConfigError

_factories: dict[tuple[str, str], Callable[..., Any]] = {}
"""(kind, name) -> factory, for what was registered or loaded in this process."""


def reference(factory: Any) -> tuple[str | None, str]:
    """(reference, what it is) of ``factory``; the reference is None for what another process cannot import."""
    qual, module = getattr(factory, "__qualname__", None), getattr(factory, "__module__", None)
    if not isinstance(qual, str) or not isinstance(module, str):
        return None, f"{type(factory).__name__} {factory!r} (no module and qualified name)"
    if "<lambda>" in qual:
        return None, f"a lambda ({module}.{qual})"
    if "<locals>" in qual:
        return None, f"defined inside a function ({module}.{qual}: a closure)"
    mod = sys.modules.get(module)
    if "." in module or mod is None:
        return f"{module}:{qual}", f"{module}.{qual}"
    path = getattr(mod, "__file__", None)
    if not path:
        return None, f"defined without a file ({module}.{qual}: an interactive session)"
    return f"{Path(path).resolve()}:{qual}", f"{qual} of {path}"


def _load_file(path: Path) -> Any:
    name = "auv_swarm_plugin_" + hashlib.sha256(str(path).encode()).hexdigest()[:12]
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path} as a module")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def load(ref: str) -> Any:
    """The object ``ref`` names (``module:QualName`` or ``/path/file.py:QualName``); ImportError, OSError or
    AttributeError when it is not there."""
    target, _, qual = ref.rpartition(":")
    if not target or not qual:
        raise ImportError(f"a reference is module:QualName or path/to/file.py:QualName, got {ref!r}")
    obj = _load_file(Path(target)) if target.endswith(".py") else importlib.import_module(target)
    for part in qual.split("."):
        obj = getattr(obj, part)
    return obj


def register(kind: str, name: str, factory: Callable[..., Any]) -> None:
    """Make ``<kind>.method = name`` build ``factory`` here, and in the processes this one starts when ``factory``
    has a reference (contract.methods.add). ValueError for a bad name, a taken one or a factory not callable."""
    if not callable(factory):
        raise ValueError(f"the factory of {kind} {name!r} must be callable, got {factory!r}")
    ref, what = reference(factory)
    methods.add(kind, name, ref, what)
    _factories[(kind, name)] = factory


def forget(kind: str, name: str) -> None:
    """Undo :func:`register` (tests)."""
    methods.remove(kind, name)
    _factories.pop((kind, name), None)


def factory(kind: str, name: str) -> Callable[..., Any]:
    """The factory of the method ``name``: ConfigError naming ``<kind>.method`` for an unknown name or one without
    a factory; MethodError for a plug-in that cannot be loaded here."""
    known = _factories.get((kind, name))
    if known is not None:
        return known
    m = methods.lookup(kind, name)
    if m is None:
        allowed = ", ".join(repr(n) for n in methods.names(kind) if methods.lookup(kind, n).ref is not None)
        raise ConfigError(f"{kind}.method must be one of {allowed}, got {name!r}")
    if m.ref is None:
        why = "the AUVs follow the central planner" if m.origin == "built-in" else f"it is {m.what}"
        raise ConfigError(f"{kind}.method {name!r} has no per-AUV {kind} here: {why}")
    try:
        found = load(m.ref)
    except Exception as exc:
        if m.origin == "built-in":
            raise
        raise MethodError(f"{kind} {name!r}: cannot load {m.ref} ({type(exc).__name__}: {exc})") from None
    _factories[(kind, name)] = found
    return found


def problem(kind: str, name: str, other_process: bool = False) -> str | None:
    """What keeps the method ``name`` of ``kind`` from being built here (``other_process``: in a process this one
    starts), one line, or None."""
    m = methods.lookup(kind, name)
    if m is None:
        return f"{kind}.method {name!r} is not known here (known: {', '.join(methods.names(kind))})"
    line = methods.not_portable(kind, name) if other_process else None
    if line is not None or m.ref is None:
        return line
    try:
        factory(kind, name)
    except MethodError as exc:
        return str(exc)
    return None


def build(kind: str, name: str, auv: int | None, *args: Any) -> Any:
    """The method's object ``factory(*args)``; a plug-in's wrapped so that its errors are MethodErrors."""
    make = factory(kind, name)
    if name in methods.BUILTIN[kind]:
        return make(*args)
    who = f"AUV {auv}: " if auv is not None else ""
    try:
        obj = make(*args)
    except Exception as exc:
        raise MethodError(f"{who}{kind} {name!r} raised {_text(exc)} when built") from exc
    return GuardedPlanner(obj, f"{who}planner {name!r}") if kind == "planner" else GuardedEstimator(obj, who, name)


def _text(exc: BaseException) -> str:
    return " ".join(f"{type(exc).__name__}: {exc}".split())


class GuardedPlanner:
    """A plug-in planner: ``plan`` errors and a plan the agent cannot send become MethodError."""

    def __init__(self, planner: Any, label: str) -> None:
        self.planner, self.label = planner, label

    def __getattr__(self, attr: str) -> Any:
        return getattr(self.planner, attr)

    def plan(self, problem: Any) -> Any:
        try:
            result = self.planner.plan(problem)
        except Exception as exc:
            raise MethodError(f"{self.label} raised {_text(exc)}") from exc
        bad = plan_problem(result, problem)
        if bad:
            raise MethodError(f"{self.label} returned an unusable plan: {bad}")
        return result


def plan_problem(result: Any, problem: Any) -> str:
    """What is wrong with ``result`` as the Plan of ``problem`` ("" if nothing): the agent sends its indices."""
    horizon, size = int(problem.planner.horizon), problem.controls.size
    try:
        controls = np.asarray(result.controls, dtype=float)
        indices = np.asarray(result.indices)
        waypoints = np.asarray(result.waypoints, dtype=float)
        [float(v) for v in dict(result.terms).values()]
    except (AttributeError, TypeError, ValueError) as exc:
        return f"{_text(exc)} (a Plan has controls, indices, waypoints and terms)"
    if controls.shape != (horizon, 2) or not np.all(np.isfinite(controls)):
        return f"controls must be finite, of shape ({horizon}, 2), got shape {controls.shape}"
    if indices.shape != (horizon,) or not np.issubdtype(indices.dtype, np.integer):
        return f"indices must be {horizon} integers, got {indices.tolist()!r}"
    if np.any(indices < 0) or np.any(indices >= size):
        return f"indices must be in [0, {size - 1}] (problem.controls), got {indices.tolist()}"
    if waypoints.shape != (horizon, 2):
        return f"waypoints must be of shape ({horizon}, 2), got {waypoints.shape}"
    return ""


class GuardedEstimator:
    """A plug-in estimator: ``update`` errors and a result that is no Estimate become MethodError."""

    def __init__(self, estimator: Any, who: str, name: str) -> None:
        self.estimator, self.label = estimator, f"{who}estimator {name!r}"

    def __getattr__(self, attr: str) -> Any:
        return getattr(self.estimator, attr)

    def __len__(self) -> int:
        return len(self.estimator)

    def update(self, bearings: Any, t_s: float) -> Any:
        from auv_swarm.agent.estimator.base import Estimate

        try:
            est = self.estimator.update(bearings, t_s)
        except Exception as exc:
            raise MethodError(f"{self.label} raised {_text(exc)} at t = {t_s:g} s") from exc
        if not isinstance(est, Estimate):
            raise MethodError(f"{self.label} returned {type(est).__name__}, not an Estimate, at t = {t_s:g} s")
        return est
