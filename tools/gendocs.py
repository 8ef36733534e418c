"""Regenerate the docs tables that restate code, or check that they are current.

    python tools/gendocs.py          rewrite every generated block in docs/
    python tools/gendocs.py --check  exit 1 (and name the blocks) when docs/ and the code disagree

A generated block sits between ``<!-- generated:NAME -->`` and ``<!-- /generated -->``
in a Markdown page; everything between the two markers belongs to this script.
A measured figure quoted on several pages sits inline between ``<!-- figure:NAME -->`` and
``<!-- /figure -->`` (in README.md and any page under docs/); its text comes from
``docs/figures.toml``, the one place it is written, with what it counts and how it was measured.
The blocks:

- ``keys`` (docs/wire.md): the key expressions, publishers, subscribers and
  messages, from ``contract.wire.key_table()``;
- ``messages`` (docs/wire.md): each message's fields and the first line of its
  docstring, from the message dataclasses in ``contract.wire``;
- ``scenario-keys`` (docs/scenarios.md): every scenario key with its default,
  allowed range and meaning, from ``contract.config.describe()`` (the fields of a
  ``[[kills]]`` or ``[[faults]]`` entry as ``kills[].time_s`` and so on);
- ``faults-example`` (docs/scenarios.md): a sample of ``[[kills]]`` and ``[[faults]]``
  entries, ``contract.faults.EXAMPLE_TOML`` (a unit test loads it);
- ``acl`` (docs/bus.md): the router's access-control table, one row per user, from
  ``bus.acl.acl_roles()``;
- ``benches`` (docs/bench.md): every ``auv-swarm bench`` verb and what it measures,
  from ``bench.BENCHES``;
- ``store-columns`` (docs/sweeps.md): the sweep store's fixed columns, their types and meanings, from
  ``orchestrator.sweep.store.FIXED_COLUMNS``;
- ``record-columns`` (docs/results.md): every column of a run's raw data tables (record.parquet and its
  companions) with its type, unit and frame, from ``results.tables.TABLES``;
- ``metrics`` (docs/results.md): every name of ``metrics.json`` with its label, unit, kind and meaning, from
  ``results.metric_info.METRIC_INFO``;
- ``verbs`` (docs/cli.md): every verb and every bench with its one-line help, from the dispatcher's ``VERBS`` and
  ``bench.BENCHES`` (what ``auv-swarm --help`` prints);
- ``builtin-scenarios`` (docs/scenarios.md): every built-in scenario with its description, from
  ``contract/scenarios/*.toml`` (what ``auv-swarm scenarios`` prints).
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from auv_swarm.bench import BENCHES  # noqa: E402
from auv_swarm.bus.zbus import acl_roles, agent_user  # noqa: E402
from auv_swarm.contract import wire  # noqa: E402
from auv_swarm.contract.config import (  # noqa: E402
    EXAMPLE_TOML,
    LIST_ITEMS,
    Scenario,
    builtin_scenarios,
    describe,
    load_scenario,
)
from auv_swarm.orchestrator.cli.main import VERBS  # noqa: E402
from auv_swarm.orchestrator.sweep.store import FIXED_COLUMNS  # noqa: E402
from auv_swarm.results.metric_info import table_markdown as metrics_table  # noqa: E402
from auv_swarm.results.tables import columns_table  # noqa: E402

_BLOCK = re.compile(r"(<!-- generated:(?P<name>[a-z0-9-]+) -->\n)(?P<body>.*?)(<!-- /generated -->)", re.S)
_FIGURE = re.compile(r"(<!-- figure:(?P<name>[a-z0-9-]+) -->)(?P<body>.*?)(<!-- /figure -->)", re.S)
FIGURES_FILE = "docs/figures.toml"
_COMMON_FIELDS = {f.name for f in dataclasses.fields(wire.Message)}


def _cell(text: str) -> str:
    """Markdown-table-safe text: no pipes, no line breaks, RST literals as Markdown code."""
    return " ".join(text.replace("|", "\\|").replace("``", "`").split())


def keys_table() -> str:
    """The wire contract's key table, as Markdown."""
    return wire.format_key_table(markdown=True)


def messages_table() -> str:
    """One row per wire message: its fields beyond the common ones and its docstring's first line."""
    lines = ["| message | fields beyond version, t_s, source | meaning |", "|---|---|---|"]
    for cls in wire.MESSAGE_TYPES:
        fields = ", ".join(f.name for f in dataclasses.fields(cls) if f.name not in _COMMON_FIELDS)
        doc = (cls.__doc__ or "").strip().splitlines()[0] if cls.__doc__ else ""
        lines.append(f"| `{cls.__name__}` | {fields} | {_cell(doc)} |")
    return "\n".join(lines)


def _default(key: str) -> str:
    head, entry, field = key.partition("[].")
    if entry:  # a field of one [[kills]] or [[faults]] entry: that dataclass's default
        value: object = dataclasses.asdict(LIST_ITEMS[head]())[field]
    else:
        value = Scenario().to_dict()
        for part in key.split("."):
            value = value[part]  # type: ignore[index]
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[]" if not value else "[" + ", ".join(repr(v) for v in value) + "]"
    return repr(value)


def scenario_keys_table() -> str:
    """Every scenario key with its default, allowed range and meaning, as Markdown."""
    lines = ["| key | default | allowed | meaning |", "|---|---|---|---|"]
    for key, allowed, doc in describe():
        lines.append(f"| `{key}` | `{_default(key)}` | {_cell(allowed.removeprefix('in ')) or '-'} | {_cell(doc)} |")
    return "\n".join(lines)


def faults_example() -> str:
    """A sample of ``[[kills]]`` and ``[[faults]]`` entries (``contract.faults.EXAMPLE_TOML``), as a TOML block."""
    return f"```toml\n{EXAMPLE_TOML.rstrip()}\n```"


def benches_table() -> str:
    """One row per shipped benchmark: its command and what it measures."""
    lines = ["| command | what it measures |", "|---|---|"]
    lines += [f"| `auv-swarm bench {name}` | {_cell(doc)} |" for name, (_, doc) in BENCHES.items()]
    return "\n".join(lines)


def acl_table() -> str:
    """The router's access-control list (default deny), one row per user; AUV 0's row written for every AUV N."""
    prefix = f"{wire.PREFIX}/"

    def keys(exprs: tuple[str, ...]) -> str:
        cells = [re.sub(r"\bauv/0(?=/|$)", "auv/<N>", e.removeprefix(prefix)) for e in exprs]
        return ", ".join(f"`{c}`" for c in cells) or "nothing"

    lines = [
        "| user | may put on | may subscribe to | liveliness token | watches liveliness |",
        "|---|---|---|---|---|",
    ]
    for role in acl_roles(agents=1):
        user = "auv<N>" if role.user == agent_user(0) else role.user
        lines.append(
            f"| `{user}` | {keys(role.publish)} | {keys(role.subscribe)} | {keys(role.tokens)} | {keys(role.watch)} |"
        )
    return "\n".join(lines)


def store_columns_table() -> str:
    """The sweep store's columns after the axis columns, in order."""
    lines = ["| column | type | meaning |", "|---|---|---|"]
    lines += [f"| `{name}` | {kind} | {_cell(doc)} |" for name, kind, doc in FIXED_COLUMNS]
    return "\n".join(lines)


def verbs_table() -> str:
    """Every verb, then every bench, with its one-line help: what ``auv-swarm --help`` lists."""
    lines = ["| command | what it does |", "|---|---|"]
    lines += [f"| `auv-swarm {verb}` | {_cell(doc)} |" for verb, (_, doc) in VERBS.items()]
    lines += [f"| `auv-swarm bench {name}` | {_cell(doc)} |" for name, (_, doc) in BENCHES.items()]
    return "\n".join(lines)


def builtin_scenarios_table() -> str:
    """Every built-in scenario with its description: what ``auv-swarm scenarios`` lists."""
    lines = ["| name | description |", "|---|---|"]
    for name in builtin_scenarios():
        lines.append(f"| `{name}` | {_cell(load_scenario(name).description.strip().splitlines()[0])} |")
    return "\n".join(lines)


BLOCKS: dict[str, tuple[str, Callable[[], str]]] = {
    "acl": ("docs/bus.md", acl_table),
    "keys": ("docs/wire.md", keys_table),
    "messages": ("docs/wire.md", messages_table),
    "scenario-keys": ("docs/scenarios.md", scenario_keys_table),
    "faults-example": ("docs/scenarios.md", faults_example),
    "benches": ("docs/bench.md", benches_table),
    "store-columns": ("docs/sweeps.md", store_columns_table),
    "record-columns": ("docs/results.md", columns_table),
    "metrics": ("docs/results.md", metrics_table),
    "verbs": ("docs/cli.md", verbs_table),
    "builtin-scenarios": ("docs/scenarios.md", builtin_scenarios_table),
}


def render(text: str, page: str) -> tuple[str, list[str], list[str]]:
    """``text`` with every generated block of ``page`` rewritten; the blocks found; those that changed."""
    found: list[str] = []
    changed: list[str] = []

    def repl(m: re.Match[str]) -> str:
        name = m.group("name")
        if name not in BLOCKS or BLOCKS[name][0] != page:
            raise SystemExit(f"error: {page}: unknown generated block {name!r}")
        found.append(name)
        body = BLOCKS[name][1]() + "\n"
        if body != m.group("body"):
            changed.append(name)
        return m.group(1) + body + m.group(4)

    return _BLOCK.sub(repl, text), found, changed


def render_figures(text: str, page: str, figures: dict[str, dict]) -> tuple[str, list[str], list[str]]:
    """``text`` with every inline figure rewritten from ``figures``; the figures found; those that changed."""
    found: list[str] = []
    changed: list[str] = []

    def repl(m: re.Match[str]) -> str:
        name = m.group("name")
        if name not in figures:
            raise SystemExit(f"error: {page}: figure {name!r} is not in {FIGURES_FILE}")
        found.append(name)
        if figures[name]["text"] != m.group("body"):
            changed.append(name)
        return m.group(1) + figures[name]["text"] + m.group(4)

    return _FIGURE.sub(repl, text), found, changed


def run_figures(check: bool, root: Path = ROOT) -> list[str]:
    """Rewrite (or compare) the inline figures of README.md and docs/*.md; return what is wrong."""
    figures = tomllib.loads((root / FIGURES_FILE).read_text(encoding="utf-8"))
    problems = [
        f"{FIGURES_FILE}: [{n}] needs text, command and measured"
        for n, f in figures.items()
        if not {"text", "command", "measured"} <= set(f)
    ]
    used: set[str] = set()
    for path in [p for p in [root / "README.md", *sorted((root / "docs").rglob("*.md"))] if p.is_file()]:
        page = str(path.relative_to(root))
        old = path.read_text(encoding="utf-8")
        new, found, changed = render_figures(old, page, figures)
        used |= set(found)
        if changed and check:
            problems.append(f"{page}: figure(s) {', '.join(changed)} differ from {FIGURES_FILE}")
        elif changed:
            path.write_text(new, encoding="utf-8")
    problems += [f"{FIGURES_FILE}: [{name}] is quoted on no page" for name in sorted(set(figures) - used)]
    return problems


def run(check: bool, root: Path = ROOT) -> list[str]:
    """Rewrite (or, with ``check``, only compare) every page; return what is missing or out of date."""
    problems: list[str] = run_figures(check, root)
    for page in sorted({page for page, _ in BLOCKS.values()}):
        path = root / page
        if not path.is_file():
            problems.append(f"{page}: missing")
            continue
        old = path.read_text(encoding="utf-8")
        new, found, changed = render(old, page)
        problems += [f"{page}: no block {name!r}" for name, (p, _) in BLOCKS.items() if p == page and name not in found]
        if changed and check:
            problems.append(f"{page}: generated block(s) {', '.join(changed)} out of date with the code")
        elif changed:
            path.write_text(new, encoding="utf-8")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 when docs/ are out of date")
    args = parser.parse_args(argv)
    problems = run(args.check)
    for problem in problems:
        print(f"gendocs: {problem}", file=sys.stderr)
    if problems:
        if args.check:
            print("gendocs: run `python tools/gendocs.py` to regenerate", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
