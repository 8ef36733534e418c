"""TL tables on the mission side: build Bellhop tables into the disk cache, copy a mission's table into its run
folder, ship tables to sweep workers (docs/ocean.md).

Reading tables is ``contract.tltable``'s (the role processes read, never build); this module builds them with
``orchestrator.mission.solvers`` (pelagic, the [bellhop] extra) before a mission or a sweep starts.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import time
from pathlib import Path

from auv_swarm.contract import tltable
from auv_swarm.contract.config import Scenario
from auv_swarm.orchestrator.mission import solvers


def needs_bellhop(scenario: Scenario) -> bool:
    """True for a physical scenario whose TL comes from Bellhop (the cache)."""
    oc = scenario.ocean
    return oc.model == "physical" and oc.propagation == "bellhop"


def write_cache(key: str, data: bytes) -> Path:
    """Write a table's bytes to the cache entry ``key`` atomically (a temporary file renamed into place)."""
    path = tltable.cache_path(key)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{key[:12]}-", suffix=".npz")
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.replace(tmp, path)
    return path


def build_table(scenario: Scenario) -> tuple[tltable.TLTable, float]:
    """Compute the scenario's Bellhop table (no cache); returns it and the wall time (s) it took."""
    start = time.perf_counter()
    table = solvers.bellhop_table(tltable.table_spec(scenario))
    return table, time.perf_counter() - start


def ensure_table(scenario: Scenario) -> Path | None:
    """Make sure the cache holds the scenario's Bellhop table (building it with pelagic if not); its path, or None
    when the scenario needs none. Raises ``solvers.SolverMissing`` (a ConfigError) without the extra."""
    if not needs_bellhop(scenario):
        return None
    key = tltable.table_key(scenario)
    path = tltable.cache_path(key)
    if path.is_file() or tltable.installed(key):
        return path
    table, _ = build_table(scenario)
    return write_cache(key, table.to_bytes())


def table_bytes(scenario: Scenario) -> tuple[str, bytes] | None:
    """The scenario's table file as (SHA-256, bytes), built or read from the cache; None for the practical law."""
    oc = scenario.ocean
    if oc.model != "physical" or oc.propagation == "practical":
        return None
    path = ensure_table(scenario) if oc.propagation == "bellhop" else tltable.table_file(scenario)
    data = Path(path).read_bytes()
    return hashlib.sha256(data).hexdigest(), data


def resolve(scenario: Scenario) -> Scenario:
    """The scenario as a run records it: its Bellhop table built into the cache if needed, and its table file's
    SHA-256 in ``ocean.tl_table_sha256`` (``propagation = "table"``; a mismatch with a given one is a ConfigError)."""
    if not needs_bellhop(scenario) and (scenario.ocean.model != "physical" or scenario.ocean.propagation != "table"):
        return scenario
    if needs_bellhop(scenario):
        ensure_table(scenario)
        return scenario
    tltable.load_table(scenario)  # checks the file, its hash if given, and that it covers the mission
    digest = hashlib.sha256(tltable.table_file(scenario).read_bytes()).hexdigest()
    return scenario.with_keys({"ocean.tl_table_sha256": digest})


def copy_table(scenario: Scenario, folder: Path) -> None:
    """A copy of the scenario's TL table in the run folder (``tl_table.npz``), if it has one."""
    oc = scenario.ocean
    if oc.model != "physical" or oc.propagation == "practical":
        return
    key = tltable.table_key(scenario)
    if oc.propagation == "bellhop" and not tltable.cache_path(key).is_file():
        (Path(folder) / "tl_table.npz").write_bytes(tltable.load_table(scenario).to_bytes())
        return
    found = table_bytes(scenario)
    if found is not None:
        (Path(folder) / "tl_table.npz").write_bytes(found[1])


def ship(scenarios: list[Scenario]) -> dict[str, bytes]:
    """The Bellhop tables of ``scenarios``, built once each on the client: {table_key: npz bytes} for the workers."""
    out: dict[str, bytes] = {}
    for s in scenarios:
        if needs_bellhop(s):
            key = tltable.table_key(s)
            if key not in out:
                out[key] = ensure_table(s).read_bytes()
    return out


def install(shipped: dict[str, bytes]) -> None:
    """On a worker: use the client's tables in this process (no pelagic, no cache needed)."""
    for key, data in shipped.items():
        tltable.install(key, tltable.parse_table(data, f"shipped table {key[:12]}"))
