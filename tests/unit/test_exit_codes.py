"""docs/exit-codes.md names every verb of the CLI, and the CLI's own failures keep the codes it lists."""

from __future__ import annotations

import re
from pathlib import Path

from auv_swarm.orchestrator.cli import main as cli

DOC = Path(__file__).resolve().parents[2] / "docs" / "exit-codes.md"


def test_the_exit_code_table_has_a_row_per_verb() -> None:
    rows = set(re.findall(r"^\| `([a-z]+)` \|", DOC.read_text(encoding="utf-8"), flags=re.M))
    assert rows == set(cli.VERBS)


def test_unknown_verb_is_usage_and_ctrl_c_is_130(monkeypatch, capsys) -> None:
    assert cli.main(["no-such-verb"]) == 2

    def interrupted(_argv: list[str]) -> int:
        raise KeyboardInterrupt

    import auv_swarm.orchestrator.cli.run as run

    monkeypatch.setattr(run, "scenarios_main", interrupted)
    assert cli.main(["scenarios"]) == 130
    assert "interrupted" in capsys.readouterr().err
