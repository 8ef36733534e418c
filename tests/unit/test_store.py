"""The sweep's store: columns, uniqueness, resume bookkeeping, refusal of another grid, --force, the lock."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from auv_swarm.orchestrator.mission import outdir
from auv_swarm.orchestrator.sweep import store as st

AXES = {"channel.pdr": [0.5, 0.95], "planner.method": ["dmpc", "dpso"]}


def _open(folder: Path, grid_hash: str = "h1", version: str = "v1", force: bool = False) -> st.Store:
    return st.open_store(folder, AXES, {"axes": list(AXES)}, grid_hash, version, force)


def test_columns_are_the_axes_then_the_fixed_list(tmp_path: Path) -> None:
    s = _open(tmp_path)
    cols = [r[1] for r in s.db.execute("PRAGMA table_info(missions)")]
    assert cols == ["channel.pdr", "planner.method", *st.FIXED_NAMES]
    assert s.db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert s.meta()["grid_hash"] == "h1" and s.meta()["version"] == "v1"


def test_one_row_per_scenario_and_seed(tmp_path: Path) -> None:
    s = _open(tmp_path)
    labels = {"channel.pdr": 0.5, "planner.method": "dmpc"}
    s.put(labels, {"seed": 1, "scenario_sha256": "a", "status": "failed", "error": "boom", "attempts": 1})
    assert s.done() == set()
    s.put(
        labels,
        {
            "seed": 1,
            "scenario_sha256": "a",
            "status": "done",
            "attempts": 2,
            "fqi": 1.2,
            "plan_walls_ms": [1.0, 2.0],
            "metrics": {"fqi": 1.2},
            "complete": True,
        },
    )
    rows = s.rows()
    assert len(rows) == 1 and rows[0]["status"] == "done" and rows[0]["error"] is None
    assert rows[0]["plan_walls_ms"] == "[1.0, 2.0]" and rows[0]["complete"] == 1
    assert s.done() == {("a", 1)}
    with pytest.raises(sqlite3.IntegrityError):
        s.db.execute("INSERT INTO missions (seed, status, scenario_sha256, attempts) VALUES (1, 'done', 'a', 1)")
    s.close()
    out = st.export_parquet(st.read_rows(tmp_path), tmp_path / st.PARQUET_FILE)
    import pyarrow.parquet as pq

    assert pq.read_table(out).column("channel.pdr").to_pylist() == [0.5]


def test_another_grid_or_version_is_refused_unless_forced(tmp_path: Path) -> None:
    _open(tmp_path).close()
    _open(tmp_path).close()  # the same grid and version: resumed
    with pytest.raises(st.StoreError, match="another grid"):
        _open(tmp_path, grid_hash="h2")
    with pytest.raises(st.StoreError, match=r"another auv-swarm version \(v1, this one v2\)"):
        _open(tmp_path, version="v2")
    s = _open(tmp_path, grid_hash="h2", force=True)
    assert s.meta()["grid_hash"] == "h2"
    assert [p.name for p in tmp_path.glob("aside-*/sweep.sqlite")] == ["sweep.sqlite"]


def test_force_moves_the_summary_parquet_and_figures_aside_with_the_store(tmp_path: Path) -> None:
    s = _open(tmp_path)
    s.put(
        {"channel.pdr": 0.5, "planner.method": "dmpc"},
        {"seed": 1, "scenario_sha256": "a", "status": "done", "attempts": 1},
    )
    st.export_parquet(s.rows(), tmp_path / st.PARQUET_FILE)
    s.close()
    made = [st.PARQUET_FILE, "summary.md", "summary.json", "tracking_error_mean_m-vs-channel.pdr.png"]
    for name in made[1:]:
        (tmp_path / name).write_text("old")
    _open(tmp_path, grid_hash="h2", force=True).close()
    (aside,) = tmp_path.glob("aside-*")
    assert sorted(p.name for p in aside.iterdir() if not p.name.startswith("sweep.sqlite-")) == sorted(
        [st.STORE_FILE, *made]
    )
    assert not any((tmp_path / name).exists() for name in made)  # nothing of the old grid is left to be overwritten
    assert (aside / "summary.md").read_text() == "old"


def _damage(path: Path) -> None:
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 3000] = bytes((7 * k) % 251 for k in range(3000))
    path.write_bytes(bytes(data))


def test_a_damaged_store_is_one_line_naming_the_file_and_force(tmp_path: Path) -> None:
    s = _open(tmp_path)
    for seed in range(150):
        s.put(
            {}, {"seed": seed, "scenario_sha256": "a", "status": "done", "attempts": 1, "metrics": {"pad": "x" * 400}}
        )
    s.close()
    _damage(tmp_path / st.STORE_FILE)
    with pytest.raises(st.StoreError) as err:
        _open(tmp_path)
    text = str(err.value)
    assert str(tmp_path / st.STORE_FILE) in text and "--force" in text and "damaged" in text and "\n" not in text
    fresh = _open(tmp_path, force=True)
    assert fresh.rows() == [] and len(list(tmp_path.glob("aside-*/sweep.sqlite"))) == 1
    fresh.close()
    (tmp_path / st.STORE_FILE).write_bytes(b"not a database at all" * 100)  # another kind of file
    with pytest.raises(st.StoreError, match="damaged or not a sweep store"):
        _open(tmp_path)


def test_a_second_sweep_on_a_folder_in_use_is_refused(tmp_path: Path) -> None:
    lock = st.Lock(tmp_path)
    with pytest.raises(st.StoreError, match="in use by another sweep"):
        st.Lock(tmp_path)
    lock.release()
    st.Lock(tmp_path).release()


def test_other_verbs_refuse_a_sweep_folder(tmp_path: Path) -> None:
    _open(tmp_path).close()
    with pytest.raises(outdir.OutDirError, match="sweep.sqlite"):
        outdir.prepare(tmp_path)
    assert outdir.prepare(tmp_path, own=(st.STORE_FILE,)) == tmp_path


def test_an_axis_named_as_a_fixed_column_is_refused(tmp_path: Path) -> None:
    with pytest.raises(st.StoreError, match="'seed'"):
        st.open_store(tmp_path, {"seed": [1]}, {}, "h", "v", False)


@pytest.mark.parametrize("axis", ["STATUS", "Seed", "FQI", "Wall_Time_S"])
def test_a_clash_in_any_case_is_refused_before_sqlite_sees_it(tmp_path: Path, axis: str) -> None:
    with pytest.raises(st.StoreError, match=f"axis '{axis}' has the name of the store's column"):
        st.open_store(tmp_path, {axis: ["a", "b"]}, {}, "h", "v", False)
    with pytest.raises(st.StoreError, match="differ only in case"):
        st.check_axis_names(["geometry", "Geometry"])
    assert not (tmp_path / st.STORE_FILE).exists()
