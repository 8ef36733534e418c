"""The sweep's grid: axes from the command line and sweep files, seeds, validation of every cell, the hash."""

from __future__ import annotations

from pathlib import Path

import pytest

from auv_swarm.contract.config import BUILTIN_DIR as ROOT_SCENARIOS
from auv_swarm.orchestrator.sweep import grid as g


def test_axis_values_are_toml_scalars_else_strings() -> None:
    axis = g.parse_axis("channel.pdr=0.3,0.5")
    assert axis.values == (0.3, 0.5) and axis.numeric
    assert g.parse_axis("planner.method=dmpc,dec-mpc").values == ("dmpc", "dec-mpc")
    assert g.parse_axis("agents.count=3,6").values == (3, 6)
    assert g.parse_axis('x.y=true,"a b"').values == (True, "a b")
    assert g.parse_axis("scenario=paper-3.3-sim1,paper-3.3-sim2").values == ("paper-3.3-sim1", "paper-3.3-sim2")


@pytest.mark.parametrize("item", ["channel.pdr", "=1,2", "channel.pdr=", "channel.pdr=1,,2", "channel.pdr=1,1"])
def test_bad_axes_are_one_line_errors(item: str) -> None:
    with pytest.raises(g.GridError):
        g.parse_axis(item)


def test_seeds() -> None:
    assert g.parse_seeds("3-5") == [3, 4, 5]
    assert g.parse_seeds("4") == [1, 2, 3, 4]
    assert g.parse_seeds(2) == [1, 2]
    for bad in ("0", "5-3", "x", "-1"):
        with pytest.raises(g.GridError, match="--seeds"):
            g.parse_seeds(bad)


def test_every_invalid_cell_is_listed_with_its_key_and_reason() -> None:
    grid = g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.5,1.5", "planner.method=dmpc,nope"], "1", 20.0)
    with pytest.raises(g.GridError) as err:
        grid.check()
    text = str(err.value)
    assert text.startswith("3 of 4 grid cells are invalid")
    assert "channel.pdr=1.5" in text and "channel.pdr must be in [0, 1]" in text
    assert "planner.method=nope" in text and "planner.method must be one of" in text
    assert "\n" not in text


def test_unknown_key_is_named() -> None:
    with pytest.raises(g.GridError, match="unknown key 'channel.nope'|channel.nope"):
        g.from_command_line("paper-3.3-sim2", ["channel.nope=1,2"], "1", None).check()


def _checked(grid: g.Grid) -> g.Grid:
    grid.check()
    return grid


def test_the_hash_covers_exactly_the_grid_and_names_the_default_folder() -> None:
    a = _checked(g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-3", 60.0))
    same = _checked(g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-3", 60.0))
    assert a.hash == same.hash and a.default_folder() == same.default_folder()
    assert str(a.default_folder()).startswith("sweeps/paper-3.3-sim2-") and len(a.default_folder().name) == 23
    for other in (
        g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.6"], "1-3", 60.0),
        g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-4", 60.0),
        g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-3", 61.0),
        g.from_command_line("paper-3.3-sim1", ["channel.pdr=0.3,0.5"], "1-3", 60.0),
    ):
        assert _checked(other).hash != a.hash and other.default_folder() != a.default_folder()
    with pytest.raises(RuntimeError, match="check"):
        _ = g.from_command_line("paper-3.3-sim2", [], "1", 60.0).hash
    multi = g.from_command_line(None, ["scenario=paper-3.3-sim1,paper-3.3-sim2"], "1", None)
    assert multi.base_name == "multi" and multi.columns == ["scenario"]
    with pytest.raises(g.GridError, match="either SCENARIO or a scenario= axis"):
        g.from_command_line("paper-3.3-sim1", ["scenario=paper-3.3-sim2"], "1", None)


def test_cells_resolve_as_with_keys_and_the_sha_leaves_the_seed_out() -> None:
    grid = g.from_command_line("paper-3.3-sim2", ["agents.count=3,6"], "1-2", 30.0)
    cells = grid.check()
    assert [c.scenario.agents.count for c in cells] == [3, 6]
    missions = grid.missions(cells)
    assert len(missions) == 4
    assert missions[0].cell.sha256 == missions[1].cell.sha256 != missions[2].cell.sha256
    assert missions[1].scenario().run.seed == 2 and missions[1].scenario().run.duration_s == 30.0


SWEEP_FILE = """
[sweep]
scenario = "paper-3.3-sim2"
seeds = "1-2"
duration = 40

[sweep.axes]
"channel.pdr" = [0.5, 0.95]

[sweep.axes.geometry]
surround = { "agents.positions_m" = [], "agents.spawn_box_m" = [-600.0, -600.0, 600.0, 600.0] }
clustered = { "agents.positions_m" = [], "agents.spawn_box_m" = [1300.0, -100.0, 1500.0, 100.0] }
"""


def test_sweep_file_with_named_variants(tmp_path: Path) -> None:
    path = tmp_path / "study.toml"
    path.write_text(SWEEP_FILE)
    assert g.is_sweep_file(str(path))
    grid = g.from_file(path)
    assert grid.base_name == "study" and grid.seeds == [1, 2] and grid.duration_s == 40.0
    assert grid.columns == ["channel.pdr", "geometry"]
    cells = grid.check()
    assert [c.labels["geometry"] for c in cells] == ["surround", "clustered"] * 2
    assert cells[1].scenario.agents.spawn_box_m == (1300.0, -100.0, 1500.0, 100.0)
    assert g.from_file(path, seeds="5").seeds == [1, 2, 3, 4, 5]


def test_skip_invalid_drops_and_counts_cells(tmp_path: Path) -> None:
    path = tmp_path / "slots.toml"
    path.write_text(
        '[sweep]\nscenario = "paper-3.3-sim2"\nseeds = 1\nskip_invalid = true\n'
        '[sweep.axes]\n"channel.slot_s" = [2.0, 14.0]\n"channel.bit_rate_bps" = [10.0, 120.0]\n'
    )
    grid = g.from_file(path)
    cells = grid.check()
    assert len(cells) + len(grid.skipped) == 4 and grid.skipped
    assert all(reason for _labels, reason in grid.skipped)


def test_bad_sweep_file_keys(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('[sweep]\nscenario = "paper-3.3-sim2"\nnope = 1\n')
    with pytest.raises(g.GridError, match="unknown key sweep.nope"):
        g.from_file(path)


@pytest.mark.parametrize("base", ["../../outside", "/abs/dir/scenario", "a/b/c", "x.toml/", "..", "we ird$name"])
def test_the_default_folder_is_always_one_folder_under_sweeps(base: str) -> None:
    folder = g.Grid([base], [], [1]).default_folder()
    assert folder.parent == Path("sweeps") and ".." not in folder.parts and not folder.name.startswith(".")


def test_an_edited_scenario_file_is_another_grid_in_the_same_folder(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    text = (ROOT_SCENARIOS / "paper-3.3-sim2.toml").read_text()
    path.write_text(text)
    before = _checked(g.from_command_line(str(path), ["channel.pdr=0.3,0.5"], "1", 30.0))
    path.write_text(text.replace("sigma_m_deg = ", "sigma_m_deg = 2.0 #", 1))
    after = _checked(g.from_command_line(str(path), ["agents.count=3,4"], "1", 30.0))
    edited = _checked(g.from_command_line(str(path), ["channel.pdr=0.3,0.5"], "1", 30.0))
    assert edited.default_folder() == before.default_folder()  # the same command finds its folder...
    assert edited.hash != before.hash  # ...and the store there refuses the edited grid
    assert after.hash != edited.hash
    path.write_text(text)
    assert _checked(g.from_command_line(str(path), ["channel.pdr=0.3,0.5"], "1", 30.0)).hash == before.hash


def test_the_hash_covers_the_content_of_the_files_a_scenario_names(tmp_path: Path, monkeypatch) -> None:
    import auv_swarm.contract.config as config

    table = tmp_path / "table.bin"
    table.write_bytes(b"one")
    monkeypatch.setattr(config, "FILE_KEYS", ("description",))  # a key whose value names a file, for this test
    grid = g.from_command_line("paper-3.3-sim2", [f"description={table}"], "1", 30.0)
    first = _checked(grid).hash
    table.write_bytes(b"two")
    assert _checked(g.from_command_line("paper-3.3-sim2", [f"description={table}"], "1", 30.0)).hash != first
    assert config.named_files(grid.check()[0].scenario) == [table]


def test_a_missing_scenario_is_named_once_with_a_suggestion() -> None:
    with pytest.raises(g.GridError) as err:
        g.from_command_line("paper-3.3-sim7", [], "1", None).check()
    text = str(err.value)
    assert text.count("paper-3.3-sim7") == 1 and "did you mean 'paper-3.3-sim" in text


def test_a_reason_shared_by_every_cell_is_given_once() -> None:
    grid = g.from_command_line("paper-3.3-sim2", ["channel.nope=1,2,3", "channel.pdr=0.3,0.5"], "1", None)
    with pytest.raises(g.GridError) as err:
        grid.check()
    text = str(err.value)
    assert text.startswith("6 of 6 grid cells are invalid: 6 cells (")
    assert text.count("unknown") == 1, text


def test_axes_that_differ_only_in_case_are_refused() -> None:
    with pytest.raises(g.GridError, match="differ only in case"):
        g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3", "CHANNEL.PDR=0.5"], "1", None)
