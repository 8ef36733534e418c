"""The sweep verb's arguments (issue 46 items 3 and 5): the scenario both ways, a name clash in any case, and
the help that lists every verb and bench; all refused before Dask or a store is touched."""

from __future__ import annotations

from pathlib import Path

import pytest

from auv_swarm.bench import BENCHES
from auv_swarm.orchestrator.cli import main as cli
from auv_swarm.orchestrator.cli.sweep import grid_from_args
from auv_swarm.orchestrator.cli.sweep import main as sweep_main
from auv_swarm.orchestrator.sweep.grid import GridError


def test_the_scenario_is_positional_or_an_option_and_two_different_ones_are_refused(capsys) -> None:
    assert grid_from_args([], "1", None, "paper-3.3-sim2").bases == ["paper-3.3-sim2"]
    assert grid_from_args(["paper-3.3-sim2"], "1", None, None).bases == ["paper-3.3-sim2"]
    assert grid_from_args(["paper-3.3-sim2"], "1", None, "paper-3.3-sim2").bases == ["paper-3.3-sim2"]
    with pytest.raises(GridError, match="two scenarios given"):
        grid_from_args(["paper-3.3-sim1"], "1", None, "paper-3.3-sim2")
    assert sweep_main(["paper-3.3-sim1", "--scenario", "paper-3.3-sim2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: two scenarios given")


def test_a_variant_axis_named_status_is_one_line_before_any_folder_is_made(tmp_path: Path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    study = tmp_path / "study.toml"
    study.write_text(
        '[sweep]\nscenario = "paper-3.3-sim2"\nseeds = 1\nduration = 20\n'
        '[sweep.axes.STATUS]\na = { "channel.pdr" = 0.5 }\nb = { "channel.pdr" = 0.9 }\n'
    )
    assert sweep_main([str(study)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "axis 'STATUS' has the name of the store's column 'status'" in err
    assert not (tmp_path / "sweeps").exists()


def test_the_help_lists_every_verb_and_every_bench(capsys) -> None:
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(f"  {verb} " in out for verb in cli.VERBS)
    assert all(f"  {name} " in out for name in BENCHES) and cli.benches() == BENCHES
