"""Where a process finds its own password, and the router its user table (bus.credentials)."""

from __future__ import annotations

import argparse
import os
import stat

import pytest

from auv_swarm.bus import credentials
from auv_swarm.bus.credentials import CredentialError


def _args(*argv: str, router: bool = False) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    (credentials.add_users_args if router else credentials.add_password_args)(parser)
    return parser.parse_args(list(argv))


@pytest.fixture(autouse=True)
def _no_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for var in credentials.CREDENTIAL_ENV:
        monkeypatch.delenv(var, raising=False)


def test_credentials_verb_writes_private_per_user_files_and_the_router_table(tmp_path) -> None:
    assert credentials.main(["--out", str(tmp_path / "c"), "--agents", "2"]) == 0
    names = sorted(p.name for p in (tmp_path / "c").iterdir())
    assert names == sorted([f"{u}.password" for u in credentials.users(2)] + ["users.txt"])
    for path in (tmp_path / "c").iterdir():
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
    table = credentials.parse_users((tmp_path / "c" / "users.txt").read_text(), "users.txt")
    assert table["auv1"] == (tmp_path / "c" / "auv1.password").read_text().strip()
    assert len(set(table.values())) == len(table), "every user gets its own password"
    assert credentials.main(["--out", str(tmp_path / "d"), "--agents", "0"]) == 2


def test_folders_layout_gives_each_container_a_folder_of_its_own(tmp_path) -> None:
    assert credentials.main(["--out", str(tmp_path / "c"), "--agents", "2", "--folders"]) == 0
    out = tmp_path / "c"
    assert sorted(p.name for p in out.iterdir()) == sorted([*credentials.users(2), "router"])
    for user in credentials.users(2):
        assert [p.name for p in (out / user).iterdir()] == ["password"]
        assert stat.S_IMODE((out / user / "password").stat().st_mode) == 0o600
    table = credentials.parse_users((out / "router" / "users.txt").read_text(), "users.txt")
    assert table["auv1"] == (out / "auv1" / "password").read_text().strip()
    first = table["auv0"]
    credentials.write_credentials(out, 2, folders=True)  # fresh per run, in the same folders
    assert (out / "auv0" / "password").read_text().strip() != first


def test_password_from_a_pipe_a_file_or_the_environment(tmp_path, monkeypatch) -> None:
    read, write = os.pipe()
    os.write(write, b"from-the-pipe\n")
    os.close(write)
    assert credentials.password(_args("--password-fd", str(read)), "auv0") == "from-the-pipe"
    (tmp_path / "pw").write_text("from-a-file\n")
    assert credentials.password(_args("--password-file", str(tmp_path / "pw")), "auv0") == "from-a-file"
    monkeypatch.setenv(credentials.PASSWORD_FILE_ENV, str(tmp_path / "pw"))
    assert credentials.password(_args(), "auv0") == "from-a-file"


def test_no_credentials_is_an_error_and_insecure_dev_warns(capsys) -> None:
    with pytest.raises(CredentialError, match="no credentials for user world: give --password-file"):
        credentials.password(_args(), "world")
    dev = credentials.password(_args("--insecure-dev"), "world")
    assert dev == credentials.password_for("world", credentials.DEV_SECRET)
    assert "warning: --insecure-dev" in capsys.readouterr().err
    with pytest.raises(CredentialError, match="no user table"):
        credentials.user_table(_args(router=True), 3)
    assert credentials.user_table(_args("--insecure-dev", router=True), 3) == credentials.derive(
        credentials.DEV_SECRET, 3
    )


@pytest.mark.parametrize(
    ("text", "match"),
    [("", "one non-empty line"), ("a\nb\n", "one non-empty line")],
)
def test_a_bad_password_file_is_named(tmp_path, text, match) -> None:
    (tmp_path / "pw").write_text(text)
    with pytest.raises(CredentialError, match=match):
        credentials.password(_args("--password-file", str(tmp_path / "pw")), "auv0")
    with pytest.raises(CredentialError, match="cannot read the password file"):
        credentials.password(_args("--password-file", str(tmp_path / "missing")), "auv0")


def test_user_table_parsing() -> None:
    assert credentials.parse_users("# swarm\nworld:abc\n\nauv0:d:e\n", "t") == {"world": "abc", "auv0": "d:e"}
    with pytest.raises(CredentialError, match="t: line 2 must be user:password"):
        credentials.parse_users("world:abc\nnocolon\n", "t")
    with pytest.raises(CredentialError, match="no user:password lines"):
        credentials.parse_users("# empty\n", "t")
    assert credentials.users_text({"a": "1", "b": "2"}) == "a:1\nb:2\n"
    with pytest.raises(ValueError, match="without ':'"):
        credentials.users_text({"a:b": "1"})


def test_once_per_run_keeps_the_passwords_of_the_same_run_and_renews_them_for_the_next(tmp_path) -> None:
    run, out = tmp_path / "run", tmp_path / "creds"
    run.mkdir()
    (run / credentials.PREPARED_STAMP).write_text("host1 aaaa\n")
    first, fresh = credentials.write_once_per_run(out, 3, run)
    assert fresh
    kept = {u: p.read_text() for u, p in first.items()}
    again, fresh = credentials.write_once_per_run(out, 3, run)  # the one-shot started again mid-run
    assert not fresh and {u: p.read_text() for u, p in again.items()} == kept
    (run / credentials.PREPARED_STAMP).write_text("host2 bbbb\n")  # the next run
    _, fresh = credentials.write_once_per_run(out, 3, run)
    assert fresh and (out / "auv0" / "password").read_text() != kept["auv0"]
    (out / "auv1" / "password").unlink()  # a file gone: written again
    assert credentials.write_once_per_run(out, 3, run)[1]
    assert credentials.main(["--out", str(out), "--run-folder", str(run)]) == 2, "--run-folder needs --folders"
