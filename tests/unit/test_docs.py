"""The docs tables that restate code (tools/gendocs.py) agree with the code."""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def gendocs():
    spec = importlib.util.spec_from_file_location("gendocs", ROOT / "tools" / "gendocs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _copy_docs(tmp_path: Path) -> Path:
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    return tmp_path


def test_generated_tables_match_the_code():
    result = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "gendocs.py"), "--check"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr


def test_check_names_a_stale_block_and_regenerating_fixes_it(gendocs, tmp_path):
    root = _copy_docs(tmp_path)
    wire_md = root / "docs" / "wire.md"
    text = wire_md.read_text()
    assert "| `auvswarm/world/clock` | world |" in text
    wire_md.write_text(text.replace("| `auvswarm/world/clock` | world |", "| `auvswarm/world/clock` | channel |"))
    assert gendocs.run(check=True, root=root) == ["docs/wire.md: generated block(s) keys out of date with the code"]
    assert gendocs.run(check=False, root=root) == []
    assert wire_md.read_text() == text
    assert gendocs.run(check=True, root=root) == []


def test_every_scenario_key_and_message_is_in_the_docs(gendocs):
    from auv_swarm.contract import wire
    from auv_swarm.contract.config import describe

    scenarios = (ROOT / "docs" / "scenarios.md").read_text()
    wire_md = (ROOT / "docs" / "wire.md").read_text()
    assert all(f"| `{key}` |" in scenarios for key, _, _ in describe())
    assert all(f"| `{cls.__name__}` |" in wire_md for cls in wire.MESSAGE_TYPES)
    assert all(f"| `{row.key}` |" in wire_md for row in wire.key_table())


def test_a_missing_block_is_reported(gendocs, tmp_path):
    root = _copy_docs(tmp_path)
    page = root / "docs" / "scenarios.md"
    text = page.read_text()
    start = text.index("<!-- generated:scenario-keys -->")
    end = text.index("<!-- /generated -->", start)
    page.write_text(text[:start] + text[end + len("<!-- /generated -->") :])
    assert gendocs.run(check=True, root=root) == ["docs/scenarios.md: no block 'scenario-keys'"]


def test_a_figure_is_written_once_and_its_quotes_follow_it(gendocs, tmp_path):
    root = _copy_docs(tmp_path)
    (root / "README.md").write_text("wall: <!-- figure:drill-time -->1 s<!-- /figure -->\n", encoding="utf-8")
    problems = gendocs.run_figures(check=True, root=root)
    assert any("README.md: figure(s) drill-time differ" in p for p in problems), problems
    gendocs.run_figures(check=False, root=root)
    text = (root / "README.md").read_text(encoding="utf-8")
    figures = gendocs.tomllib.loads((root / "docs" / "figures.toml").read_text(encoding="utf-8"))
    assert text == f"wall: <!-- figure:drill-time -->{figures['drill-time']['text']}<!-- /figure -->\n"
    assert not any("differ" in p for p in gendocs.run_figures(check=True, root=root))
    (root / "README.md").write_text("<!-- figure:no-such -->x<!-- /figure -->\n", encoding="utf-8")
    with pytest.raises(SystemExit, match="no-such"):
        gendocs.run_figures(check=True, root=root)
