"""The sweep's grid: axes from the command line and sweep files, seeds, validation of every cell, the hash."""

from __future__ import annotations

from pathlib import Path

import pytest

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


def test_the_hash_covers_exactly_the_grid_and_names_the_default_folder() -> None:
    a = g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-3", 60.0)
    same = g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-3", 60.0)
    assert a.hash == same.hash
    assert str(a.default_folder()) == f"sweeps/paper-3.3-sim2-{a.hash[:8]}"
    for other in (
        g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.6"], "1-3", 60.0),
        g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-4", 60.0),
        g.from_command_line("paper-3.3-sim2", ["channel.pdr=0.3,0.5"], "1-3", 61.0),
        g.from_command_line("paper-3.3-sim1", ["channel.pdr=0.3,0.5"], "1-3", 60.0),
    ):
        assert other.hash != a.hash
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
