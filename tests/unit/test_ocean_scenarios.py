"""The [ocean] section and its TL tables: refusals, presets, bad input (one line, exit 2), payload version 3."""

from __future__ import annotations

import io
import math
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auv_swarm.contract import payload, tltable
from auv_swarm.contract.config import REPLACED_BY_OCEAN, ConfigError, Scenario, builtin_scenarios, load_scenario
from auv_swarm.contract.ocean import profile_speeds, slot_sound_speed, sound_speed_profile
from auv_swarm.contract.tltable import ocean_for
from auv_swarm.contract.wire import DecodeError

PHYSICAL = [n for n in builtin_scenarios() if load_scenario(n).ocean.model == "physical"]
BASE = {"ocean.model": "physical"}


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    """Every test with its own empty table cache and nothing installed in the process."""
    monkeypatch.setenv(tltable.CACHE_ENV, str(tmp_path / "cache"))
    saved = dict(tltable._LOADED)
    tltable._LOADED.clear()
    yield
    tltable._LOADED.clear()
    tltable._LOADED.update(saved)


def test_every_builtin_but_the_ocean_ones_is_paper() -> None:
    assert len(PHYSICAL) >= 3 and all(n.startswith("ocean-") for n in PHYSICAL)
    assert all(load_scenario(n).ocean.model == "paper" for n in builtin_scenarios() if n not in PHYSICAL)


@pytest.mark.parametrize(("section", "key", "instead"), REPLACED_BY_OCEAN)
def test_a_paper_knob_is_refused_under_physical_naming_its_replacement(section: str, key: str, instead: str) -> None:
    value = {"outlier_rate": 0.1, "max_range_m": 2000.0, "sound_speed_mps": 1480.0}.get(key, 37.0)
    Scenario().with_keys({f"{section}.{key}": value})  # fine under "paper"
    with pytest.raises(ConfigError) as err:
        Scenario().with_keys({**BASE, f"{section}.{key}": value})
    assert f"{section}.{key}" in str(err.value) and instead.split(" ")[0] in str(err.value)


@pytest.mark.parametrize(
    ("keys", "match"),
    [
        ({"ocean.sound_speed": "arctic"}, "ocean.sound_speed must be one of"),
        ({"ocean.seabed": "clay"}, "ocean.seabed must be one of"),
        ({"ocean.modem": "evologics"}, "ocean.modem must be one of"),
        (
            {"ocean.sound_speed": "profile", "ocean.sound_speed_profile": [[0.0, 1500.0], [50.0, 1490.0]]},
            "shallower than the water",
        ),
        (
            {"ocean.sound_speed": "profile", "ocean.sound_speed_profile": [[5.0, 1500.0], [150.0, 1490.0]]},
            "start at 0 m",
        ),
        (
            {"ocean.sound_speed": "profile", "ocean.sound_speed_profile": [[0.0, 900.0], [150.0, 1490.0]]},
            r"\[1300, 1800\]",
        ),
        ({"ocean.auv_depth_m": 150.0}, "ocean.auv_depth_m must be in"),
        ({"ocean.source_band_khz": [12.0, 11.0]}, "ocean.source_band_khz"),
        ({"ocean.integration_s": 3.0}, "ocean.integration_s must be <= sensor.period_s"),
        ({"ocean.source_band_khz": [1.0, 20.0]}, "Albersheim"),
        ({"ocean.propagation": "table"}, "ocean.tl_table must name"),
        ({"ocean.wind_mps": 60.0}, r"ocean.wind_mps must be in \[0, 40\]"),
    ],
)
def test_bad_ocean_values_name_the_key(keys: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        Scenario().with_keys({**BASE, **keys})


def test_presets_reach_the_bottom_and_set_the_slot_and_delay_speeds() -> None:
    for preset in ("isovelocity", "summer", "munk"):
        oc = Scenario().with_keys({**BASE, "ocean.sound_speed": preset, "ocean.depth_m": 300.0}).ocean
        z, c = zip(*sound_speed_profile(oc), strict=True)
        assert z[0] == 0.0 and z[-1] == 300.0 and all(b > a for a, b in zip(z, z[1:], strict=False))
        c_min, c_mean = profile_speeds(oc)
        assert c_min == min(c) <= c_mean <= max(c)
    s = Scenario().with_keys({**BASE, "ocean.sound_speed": "summer"})
    assert (
        slot_sound_speed(s.channel, s.ocean) == 1488.0
        and slot_sound_speed(Scenario().channel, Scenario().ocean) == 1500.0
    )
    assert sound_speed_profile(
        Scenario().with_keys({**BASE, "ocean.sound_speed": "munk", "ocean.depth_m": 5000.0}).ocean
    )[26][1] == pytest.approx(1500.0 * (1 + 0.00737 * (-0.0 - 1 + 1)), abs=0.2)


def _table(**changes) -> bytes:
    fields = {
        "ranges_m": np.linspace(0.0, 5000.0, 51),
        "depths_m": np.linspace(0.0, 100.0, 11),
        "frequencies_khz": np.array([10.0, 11.1]),
        "source_depth_m": np.float64(20.0),
        "tl_db": np.full((2, 11, 51), 60.0),
    }
    fields.update(changes)
    fields = {k: v for k, v in fields.items() if v is not None}
    buf = io.BytesIO()
    np.savez(buf, **fields)
    return buf.getvalue()


def _table_scenario(tmp_path, data: bytes, **keys) -> Scenario:
    path = tmp_path / "t.npz"
    path.write_bytes(data)
    return Scenario().with_keys({**BASE, "ocean.propagation": "table", "ocean.tl_table": str(path), **keys})


@pytest.mark.parametrize(
    ("data", "keys", "match"),
    [
        (b"not a zip", {}, "not a readable .npz"),
        (_table(tl_db=None), {}, "missing tl_db"),
        (_table(tl_db=np.zeros((2, 11, 50))), {}, "must have shape"),
        (_table(tl_db=np.full((2, 11, 51), np.nan)), {}, "finite"),
        (_table(), {"channel.max_range_m": 6000.0}, "do not cover"),
        (_table(), {"ocean.source_depth_m": 150.0, "ocean.depth_m": 300.0}, "do not cover ocean.source_depth_m"),
        (_table(frequencies_khz=np.array([10.0, 12.0])), {}, "no field at 11.1 kHz"),
        (_table(source_depth_m=np.float64(50.0)), {}, "source_depth_m 50 m must be ocean.auv_depth_m"),
        (_table(), {"ocean.tl_table_sha256": "ab" * 32}, "SHA-256"),
    ],
)
def test_a_bad_table_is_a_config_error(tmp_path, data: bytes, keys: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        ocean_for(_table_scenario(tmp_path, data, **keys))


def test_a_missing_table_file_and_an_unknown_builtin(tmp_path) -> None:
    with pytest.raises(ConfigError, match="cannot read the TL table"):
        ocean_for(
            Scenario().with_keys({**BASE, "ocean.propagation": "table", "ocean.tl_table": str(tmp_path / "no.npz")})
        )
    with pytest.raises(ConfigError, match="not a built-in table; built-ins: builtin:coastal-summer"):
        ocean_for(Scenario().with_keys({**BASE, "ocean.propagation": "table", "ocean.tl_table": "builtin:atlantis"}))


def test_a_good_table_is_used_and_a_relative_path_follows_the_scenario_file(tmp_path) -> None:
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "t.npz").write_bytes(_table())
    (tmp_path / "s.toml").write_text('[ocean]\nmodel = "physical"\npropagation = "table"\ntl_table = "tables/t.npz"\n')
    s = load_scenario(tmp_path / "s.toml")
    assert s.ocean.tl_table == str(tmp_path / "tables" / "t.npz")
    ocean = ocean_for(s)
    assert float(ocean.link.snr_db(1000.0)) == pytest.approx(186.0 - 60.0 - ocean.link.noise_level_db)


def _run_cli(main, argv: list[str], capsys) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err.strip()


def test_cli_bad_table_one_line_exit_2(tmp_path, capsys) -> None:
    from auv_swarm.orchestrator.cli.run import main

    (tmp_path / "t.npz").write_bytes(b"junk")
    (tmp_path / "s.toml").write_text('[ocean]\nmodel = "physical"\npropagation = "table"\ntl_table = "t.npz"\n')
    code, err = _run_cli(
        main, ["--scenario", str(tmp_path / "s.toml"), "--mode", "inprocess", "--out", str(tmp_path / "o")], capsys
    )
    assert code == 2 and err.startswith("error:") and len(err.splitlines()) == 1 and "not a readable .npz" in err


def test_bellhop_without_the_extra_is_one_line_exit_2(tmp_path, monkeypatch, capsys) -> None:
    from auv_swarm.orchestrator.cli.ocean import main

    monkeypatch.setitem(sys.modules, "pelagic", None)
    code, err = _run_cli(main, ["ocean-coastal-summer", "ocean.propagation=bellhop", "--out", str(tmp_path)], capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "pip install 'auv-swarm[bellhop]'" in err


def test_a_role_process_never_builds_a_table(tmp_path, capsys) -> None:
    from auv_swarm.world.node import main

    (tmp_path / "s.toml").write_text('[ocean]\nmodel = "physical"\npropagation = "bellhop"\n')
    with pytest.raises(SystemExit) as exit_:
        main(["--scenario", str(tmp_path / "s.toml"), "--insecure-dev"])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and len(err.splitlines()) == 1 and "run `auv-swarm ocean SCENARIO`" in err


def test_tables_are_shipped_to_a_worker_without_cache(tmp_path) -> None:
    pytest.importorskip("pelagic")
    from auv_swarm.orchestrator.mission import tables

    s = load_scenario("ocean-storm").with_keys({"ocean.propagation": "bellhop", "ocean.table_range_m": 4000.0})
    shipped = tables.ship([s, s])
    assert list(shipped) == [tltable.table_key(s)]
    tltable.cache_path(tltable.table_key(s)).unlink()
    tltable._LOADED.clear()
    with pytest.raises(ConfigError, match="no Bellhop TL table"):
        ocean_for(s)
    tables.install(shipped)
    assert ocean_for(s).link.snr_db(500.0) > 0.0


@settings(max_examples=60, deadline=None)
@given(
    bearings=st.lists(
        st.tuples(
            st.floats(0.0, 100.0),
            st.floats(-200, 200),
            st.floats(-200, 200),
            st.floats(-3.1, 3.1),
            st.floats(1e-4, 3.0),
        ),
        max_size=12,
    )
)
def test_payload_version_3_round_trip(bearings) -> None:
    p = payload.AcousticPayload(
        sender=1,
        t_s=100.0,
        x=0.0,
        y=0.0,
        theta=0.0,
        u_e=1.0,
        plan=((4, 1),) * 5,
        round=3,
        bearings=tuple(bearings),
        sigma=True,
    )
    data, dropped = payload.encode_payload(p, 4000, 9)
    assert data[0] >> 4 == payload.PAYLOAD_VERSION_SIGMA and dropped == 0
    q = payload.decode_payload(data, 9)
    assert q.sigma and len(q.bearings) == len(bearings)
    for got, (_, _, _, _, sigma) in zip(q.bearings, bearings, strict=True):
        deg = max(math.degrees(sigma), payload.SIGMA_MIN_DEG)
        assert abs(math.log2(math.degrees(got[4]) / min(deg, 146.0))) <= 1 / 12 + 1e-9 or math.degrees(sigma) > 146.0
    assert payload.encode_payload(q, 4000, 9)[0] == data
    with pytest.raises(DecodeError):
        payload.decode_payload(data[:-1] if len(data) > 15 else data + b"\x00", 9)


@pytest.mark.parametrize("name", PHYSICAL)
def test_bits_per_bearing_and_bearings_per_frame_of_the_physical_builtins(name: str) -> None:
    """docs/ocean.md's table: 46 bits per bearing (40 + a 6-bit sigma); 23 bearings in a slot of 1237-1240 bits
    (120 bps x (14 - 1 - 4000 m / the profile's minimum sound speed) s)."""
    s = load_scenario(name)
    ch = s.channel
    budget = payload.slot_budget_bits(
        ch.bit_rate_bps, ch.slot_s, ch.guard_s, ch.max_range_m, slot_sound_speed(ch, s.ocean)
    )
    assert payload.bearing_bits(sigma=True) == 46
    assert (budget, payload.max_bearings(budget, s.planner.horizon, s.planner.n_headings, sigma=True)) == {
        "ocean-coastal-summer": (1237, 23),
        "ocean-deep-munk": (1240, 23),
        "ocean-storm": (1240, 23),
    }[name]


def test_an_ocean_key_under_the_paper_model_is_refused() -> None:
    """A key that would change nothing is an error, not a silent no-op (a sweep over wind on a paper scenario)."""
    with pytest.raises(ConfigError, match=r"ocean.wind_mps has no effect under ocean.model = 'paper'"):
        Scenario().with_keys({"ocean.wind_mps": 10.0})
    assert Scenario().with_keys({"ocean.model": "paper"}).ocean.model == "paper"


def test_an_edited_table_file_is_another_sweep_grid(tmp_path) -> None:
    from auv_swarm.contract.config import named_files

    (tmp_path / "t.npz").write_bytes(_table())
    (tmp_path / "s.toml").write_text('[ocean]\nmodel = "physical"\npropagation = "table"\ntl_table = "t.npz"\n')
    assert named_files(load_scenario(tmp_path / "s.toml")) == [tmp_path / "t.npz"]
    assert named_files(load_scenario("ocean-storm")) == []  # builtin: tables are package data
