"""The package layout: one import package ``auv_swarm``, its layers, and what an import loads.

Static checks over the source (AST): no bare first-party import anywhere, the layering rules of
docs/README.md, no import cycle between modules at import time, and pyproject's package list
complete. The wheel built from ``git archive HEAD`` is checked in tests/integration/test_wheel.py.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SUBPACKAGES = (
    "agent",
    "bench",
    "bus",
    "central",
    "channel_sim",
    "contract",
    "orchestrator",
    "recorder",
    "results",
    "world",
)
"""The repository's top-level folders that are subpackages of ``auv_swarm``."""

UNITS = (
    "contract",
    "bus",
    "agent",
    "channel_sim",
    "world",
    "results",
    "recorder",
    "central",
    "orchestrator.mission",
    "orchestrator.sweep",
    "orchestrator.cli",
    "bench",
    "root",
)
"""The layers: every top-level package, orchestrator's three rooms, and the package root (``pkg/``)."""

_EVERYTHING = set(UNITS) - {"root"}
LAYERS: dict[str, set[str]] = {
    "contract": set(),
    "bus": {"contract"},
    "agent": {"contract"},
    "channel_sim": {"contract"},
    "world": {"contract"},
    "results": {"contract"},
    "recorder": {"contract"},
    "central": {"contract", "agent"},
    "orchestrator.mission": _EVERYTHING - {"orchestrator.mission", "orchestrator.sweep", "orchestrator.cli", "bench"},
    "orchestrator.sweep": {"contract", "bus", "results", "orchestrator.mission"},
    "orchestrator.cli": _EVERYTHING - {"orchestrator.cli", "bench"},
    "bench": _EVERYTHING - {"bench", "orchestrator.cli"},
    "root": {"orchestrator.mission", "contract", "results"},
}
"""What each layer may import of ``auv_swarm`` besides itself (every import, also inside functions)."""

SHELL_ALSO = {"bus"}
"""What a process shell (a layer's ``node.py`` and ``__main__.py``) may import besides its layer's own."""
ROOT_MAIN_ALSO = {"orchestrator.cli"}
"""``pkg/__main__.py`` (``python -m auv_swarm``) dispatches to the command line."""


def unit_of_module(name: str) -> str | None:
    """The layer of the ``auv_swarm`` module ``name`` (None for names outside the package)."""
    parts = name.split(".")
    if parts[0] != "auv_swarm":
        return None
    if len(parts) == 1:
        return "root"
    if parts[1] == "orchestrator":
        return f"orchestrator.{parts[2]}" if len(parts) > 2 and f"orchestrator.{parts[2]}" in UNITS else "orchestrator"
    return parts[1] if parts[1] in UNITS else "root"


def unit_of_path(path: Path) -> str:
    """The layer of the source file ``path`` (inside the package)."""
    rel = path.relative_to(ROOT).parts
    if rel[0] == "pkg":
        return "root"
    if rel[0] == "orchestrator" and len(rel) > 2:
        return f"orchestrator.{rel[1]}"
    return rel[0]


def _sources() -> list[Path]:
    folders = [ROOT / p for p in (*SUBPACKAGES, "pkg", "tests", "tools", "examples")]
    return sorted(f for d in folders if d.is_dir() for f in d.rglob("*.py"))


def _imports(path: Path, top_level_only: bool = False) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in ``path`` (relative ones resolved)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    nodes = tree.body if top_level_only else ast.walk(tree)
    out = []
    for node in nodes:
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out += [(node.lineno, node.module)]
            out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return out


def _module_of(path: Path) -> str | None:
    """The ``auv_swarm`` module a source file is installed as, or None outside the package."""
    rel = path.relative_to(ROOT)
    if rel.parts[0] == "pkg":
        parts = ["auv_swarm", *rel.with_suffix("").parts[1:]]
    elif rel.parts[0] in SUBPACKAGES:
        parts = ["auv_swarm", *rel.with_suffix("").parts]
    else:
        return None
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def test_no_bare_first_party_import() -> None:
    bare = [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for path in _sources()
        for line, name in _imports(path)
        if name.split(".")[0] in SUBPACKAGES
    ]
    assert not bare, "imports must use the auv_swarm. form:\n" + "\n".join(bare)


def test_no_module_imports_another_modules_private_name() -> None:
    """A name with a leading underscore is its module's own: another module (or a test) that needs it needs a
    public name."""
    found = []
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("auv_swarm"):
                private = [a.name for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
                found += [f"{path.relative_to(ROOT)}:{node.lineno}: {node.module}.{name}" for name in private]
    assert found == [], found


def test_every_subpackage_is_listed_in_pyproject() -> None:
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    on_disk = {"auv_swarm"} | {
        "auv_swarm." + ".".join(init.parent.relative_to(ROOT).parts)
        for top in SUBPACKAGES
        for init in (ROOT / top).rglob("__init__.py")
    }
    assert set(tool["packages"]) == on_disk
    assert tool["package-dir"] == {"auv_swarm": "pkg", **{f"auv_swarm.{p}": p for p in SUBPACKAGES}}
    assert not (ROOT / "auv_swarm").exists(), "a repository folder named auv_swarm would shadow the installed package"


def test_the_layers_import_only_what_they_may() -> None:
    wrong = []
    for top in (*SUBPACKAGES, "pkg"):
        for path in (ROOT / top).rglob("*.py"):
            unit = unit_of_path(path)
            allowed = LAYERS.get(unit, set()) | {unit}
            if path.name in ("node.py", "__main__.py"):
                allowed |= SHELL_ALSO | (ROOT_MAIN_ALSO if unit == "root" else set())
            for line, name in _imports(path):
                target = unit_of_module(name)
                if target is not None and target != "root" and target not in allowed:
                    wrong.append(f"{path.relative_to(ROOT)}:{line}: {name} ({unit} may not import {target})")
    assert not wrong, "layering (docs/README.md):\n" + "\n".join(sorted(set(wrong)))


def test_the_roots_lazy_names_come_from_its_layers() -> None:
    """``auv_swarm.run_mission`` and the other names the root loads on first use obey the root's layer too."""
    import auv_swarm

    targets = {unit_of_module(module) for module in auv_swarm._LAZY.values()}
    assert targets <= LAYERS["root"], targets


def test_every_package_has_a_layer() -> None:
    units = {unit_of_path(init) for top in (*SUBPACKAGES, "pkg") for init in (ROOT / top).rglob("__init__.py")}
    assert units - {"orchestrator"} == set(LAYERS) == set(UNITS)
    assert {p.name for p in (ROOT / "orchestrator").glob("*.py")} == {"__init__.py"}, "orchestrator/ holds rooms only"


def test_contract_imports_no_zenoh() -> None:
    found = [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for path in (ROOT / "contract").rglob("*.py")
        for line, name in _imports(path)
        if name.split(".")[0] == "zenoh"
    ]
    assert not found, found


def test_the_planner_imports_no_baseline() -> None:
    bad = [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for path in (ROOT / "agent" / "planner").rglob("*.py")
        for line, name in _imports(path)
        if name.startswith(("auv_swarm.agent.baselines", "auv_swarm.agent.methods"))
    ]
    assert not bad, "\n".join(bad)


def _strongly_connected(graph: dict[str, set[str]]) -> list[set[str]]:
    """Tarjan's strongly connected components of ``graph`` (node -> successors)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[set[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            out.append(component)

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return out


def test_no_import_cycle() -> None:
    """No two modules import each other, directly or round a circle (imports inside functions count too)."""
    modules = {m: p for p in _sources() if (m := _module_of(p)) is not None}
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        deps = set()
        for _line, name in _imports(path):
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name and name != module and not module.startswith(name + "."):
                deps.add(name)
        graph[module] = deps
    cycles = [sorted(c) for c in _strongly_connected(graph) if len(c) > 1]
    assert not cycles, "modules that import each other (directly or round a circle):\n" + "\n".join(map(str, cycles))


@pytest.mark.parametrize(
    "module",
    [
        "auv_swarm",
        "auv_swarm.agent",
        "auv_swarm.agent.core",
        "auv_swarm.contract.config",
        "auv_swarm.channel_sim.model",
    ],
)
def test_importing_a_component_loads_no_orchestrator_or_results(module: str) -> None:
    code = (
        f"import sys, {module}\n"
        "bad = sorted(m for m in sys.modules if m.startswith(('auv_swarm.orchestrator', 'auv_swarm.results')))\n"
        "print(bad)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert done.stdout.strip() == "[]", done.stdout


@pytest.mark.parametrize(
    "module",
    [
        "auv_swarm.agent.node",
        "auv_swarm.world.node",
        "auv_swarm.channel_sim.node",
        "auv_swarm.recorder.node",
        "auv_swarm.central.node",
        "auv_swarm.orchestrator.mission.collector",
        "auv_swarm.orchestrator.cli.run",
    ],
)
def test_a_process_starts_without_the_physical_oceans_heavy_imports(module: str) -> None:
    """scipy.stats (0.6 s) and pelagic load only when a physical ocean asks for them: every process pays its imports
    at each mission's start (the main command's run wall went from 9.7 to 12.3 s when contract/ocean.py pulled
    scipy.stats in at the top)."""
    code = f"import sys, {module}\nprint(sorted(m for m in ('scipy.stats', 'pelagic') if m in sys.modules))\n"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert done.stdout.strip() == "[]", done.stdout


def test_the_root_exposes_the_api_lazily() -> None:
    code = (
        "import sys, auv_swarm\n"
        "assert 'auv_swarm.orchestrator.mission.api' not in sys.modules\n"
        "from auv_swarm import run_mission, load_scenario, Launch, MissionResult\n"
        "assert 'auv_swarm.orchestrator.mission.api' in sys.modules\n"
        "try:\n    auv_swarm.no_such_name\nexcept AttributeError as exc:\n    print(exc)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert "no attribute 'no_such_name'" in done.stdout


def test_zenoh_and_rerun_are_imported_where_docs_readme_says() -> None:
    where = {"zenoh": set(), "rerun": set()}
    for top in SUBPACKAGES:
        for path in (ROOT / top).rglob("*.py"):
            for _line, name in _imports(path):
                if name.split(".")[0] in where:
                    where[name.split(".")[0]].add(str(path.relative_to(ROOT)))
    assert where["zenoh"] == {"bus/zbus.py", "orchestrator/mission/router.py"}
    writers = {p for p in where["rerun"] if not p.startswith("recorder/")}
    assert writers <= {"orchestrator/cli/drill.py"}  # the drill reads a recording back (rerun.chunk), writes none


def test_docs_readme_maps_every_folder_and_names_only_paths_that_exist() -> None:
    import re

    text = (ROOT / "docs" / "README.md").read_text(encoding="utf-8")
    tree = text[text.index("## The tree") :]
    for folder in (*SUBPACKAGES, "pkg"):
        assert f"| `{folder}/` |" in tree, f"docs/README.md's tree lacks {folder}/"
    paths = set(re.findall(r"`([a-z_]+/[A-Za-z0-9_./]*)`", text))
    missing = sorted(p for p in paths if not (ROOT / p).exists())
    assert not missing, f"docs/README.md names paths that do not exist: {missing}"


def test_dask_is_imported_only_by_the_sweep_engine_and_its_worker_task() -> None:
    where = set()
    for top in SUBPACKAGES:
        for path in (ROOT / top).rglob("*.py"):
            if any(name.split(".")[0] in ("dask", "distributed", "dask_jobqueue") for _line, name in _imports(path)):
                where.add(str(path.relative_to(ROOT)))
    assert where == {"orchestrator/sweep/engine.py", "orchestrator/sweep/worker.py"}


READABLE_MODULES = (
    "orchestrator/sweep/engine.py",
    "contract/wire.py",
    "recorder/core.py",
    "orchestrator/cli/drill.py",
    "agent/planner/context.py",
)
"""The house step's five hard spots (issue 39): no function over MAX_FUNCTION_LINES, no nesting over MAX_NESTING."""
MAX_FUNCTION_LINES = 60
MAX_NESTING = 4
MAX_FILE_LINES = 600

_BLOCKS = (ast.If, ast.For, ast.AsyncFor, ast.While, ast.With, ast.AsyncWith, ast.Try, ast.TryStar, ast.Match)
_FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)


def _nesting(node: ast.AST, depth: int = 0) -> int:
    """The deepest block nesting under ``node``: each if/for/while/with/try/match and each nested function or
    lambda adds one; an ``elif`` is the same level as its ``if``."""
    deepest = depth
    for child in ast.iter_child_nodes(node):
        is_elif = isinstance(node, ast.If) and isinstance(child, ast.If) and node.orelse == [child]
        step = 1 if isinstance(child, (*_BLOCKS, *_FUNCTIONS)) and not is_elif else 0
        deepest = max(deepest, _nesting(child, depth + step))
    return deepest


def function_stats(path: Path) -> list[tuple[str, int, int]]:
    """(qualified name, lines, nesting) of every function and method in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out: list[tuple[str, int, int]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = f"{prefix}{child.name}"
                out.append((name, child.end_lineno - child.lineno + 1, _nesting(child)))
                visit(child, name + ".")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def test_nesting_counts_blocks_and_closures_not_elif() -> None:
    code = "def f(x):\n    if x:\n        for i in x:\n            pass\n    elif x == 1:\n        pass\n"
    tree = ast.parse(code)
    assert _nesting(tree.body[0]) == 2
    code = "def g():\n    def h():\n        with a:\n            try:\n                pass\n            except E:\n                pass\n"
    assert _nesting(ast.parse(code).body[0]) == 3


@pytest.mark.parametrize("module", READABLE_MODULES)
def test_the_hard_spots_read_in_short_shallow_functions(module: str) -> None:
    long = [(n, lines, depth) for n, lines, depth in function_stats(ROOT / module) if lines > MAX_FUNCTION_LINES]
    deep = [(n, lines, depth) for n, lines, depth in function_stats(ROOT / module) if depth > MAX_NESTING]
    assert not long, f"{module}: functions over {MAX_FUNCTION_LINES} lines: {long}"
    assert not deep, f"{module}: functions nested deeper than {MAX_NESTING}: {deep}"


def test_no_python_file_over_600_lines() -> None:
    files = subprocess.run(["git", "ls-files", "*.py"], capture_output=True, text=True, cwd=ROOT, check=True)
    long = {}
    for name in files.stdout.split():
        path = ROOT / name
        if path.exists():
            n = len(path.read_text(encoding="utf-8").splitlines())
            if n > MAX_FILE_LINES:
                long[name] = n
    assert not long, f"files over {MAX_FILE_LINES} lines: {long}"
