"""The swarm's mutual TLS without a network: what ``auv-swarm credentials --tls DIR`` writes, the checks a process
makes of its own certificate before it connects, and the zenoh configs built from them (issue 45)."""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
import stat

import pytest
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from auv_swarm.bus import credentials, shell, tls, zbus
from auv_swarm.orchestrator.cli import run as run_cli
from auv_swarm.orchestrator.mission import router

NOW = datetime.datetime(2030, 1, 1, tzinfo=datetime.UTC)
DAY = datetime.timedelta(days=1)


def _cert(path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def _usages(cert: x509.Certificate) -> set:
    return set(cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value)


def test_credentials_tls_writes_one_private_certificate_per_user_and_keeps_its_ca(tmp_path) -> None:
    folder = tmp_path / "tls"
    hosts = ["--router-host", "10.1.2.3", "--router-host", "ship.local"]
    assert credentials.main(["--tls", str(folder), "--agents", "2", *hosts, "--days", "5"]) == 0
    names = [*credentials.users(2), tls.ROUTER]
    expected = {"ca.pem", "ca.key"} | {f"{n}.{ext}" for n in names for ext in ("pem", "key")}
    assert {p.name for p in folder.iterdir()} == expected
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    assert all(stat.S_IMODE(p.stat().st_mode) == 0o600 for p in folder.iterdir())
    ca = _cert(folder / "ca.pem")
    for name in names:
        cert = _cert(folder / f"{name}.pem")
        cert.verify_directly_issued_by(ca)
        assert [a.value for a in cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)] == [name]
        lifetime = cert.not_valid_after_utc - cert.not_valid_before_utc
        assert lifetime == datetime.timedelta(days=5)
        server = name == tls.ROUTER
        assert (ExtendedKeyUsageOID.SERVER_AUTH in _usages(cert)) == server
        assert ExtendedKeyUsageOID.CLIENT_AUTH in _usages(cert)
    sans = _cert(folder / "router.pem").extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert sans.get_values_for_type(x509.DNSName) == ["ship.local"]
    assert [str(a) for a in sans.get_values_for_type(x509.IPAddress)] == ["10.1.2.3"]

    first_ca, first_auv = (folder / "ca.pem").read_bytes(), (folder / "auv0.pem").read_bytes()
    assert credentials.main(["--tls", str(folder), "--agents", "2"]) == 0  # rotation: the same CA, fresh pairs
    assert (folder / "ca.pem").read_bytes() == first_ca and (folder / "auv0.pem").read_bytes() != first_auv
    (folder / "ca.key").unlink()  # a host's copy holds no CA key: it cannot issue
    assert credentials.main(["--tls", str(folder), "--agents", "2"]) == 2
    assert credentials.main(["--tls", str(tmp_path / "x"), "--router-host", "not a host"]) == 2
    assert credentials.main(["--tls", str(tmp_path / "x"), "--days", "0"]) == 2
    assert credentials.main(["--out", str(tmp_path / "x"), "--router-host", "h"]) == 2
    assert not (tmp_path / "x").exists()


def test_check_identity_names_what_is_wrong_before_zenoh_would_time_out(tmp_path) -> None:
    folder, other = tmp_path / "ours", tmp_path / "theirs"
    tls.write_zenoh(folder, ("auv0", "auv1"), days=3, now=NOW)
    tls.write_zenoh(other, ("auv0",), now=NOW)
    assert tls.check_identity(folder, "auv0", now=NOW) == NOW - datetime.timedelta(seconds=tls.CLOCK_SKEW_S) + 3 * DAY
    with pytest.raises(tls.TLSError, match="expired on"):
        tls.check_identity(folder, "auv0", now=NOW + 3 * DAY)
    with pytest.raises(tls.TLSError, match="this host's clock"):
        tls.check_identity(folder, "auv0", now=NOW - DAY)
    with pytest.raises(tls.TLSError, match="cannot read .*world.pem"):
        tls.check_identity(folder, "world", now=NOW)
    shutil.copy(folder / "auv1.pem", folder / "auv0.pem")
    with pytest.raises(tls.TLSError, match="certificate of auv1, not auv0"):
        tls.check_identity(folder, "auv0", now=NOW)
    shutil.copy(other / "auv0.pem", folder / "auv0.pem")
    with pytest.raises(tls.TLSError, match="not signed by the CA"):
        tls.check_identity(folder, "auv0", now=NOW)
    shutil.copy(folder / "auv1.key", folder / "auv1.pem.key")
    shutil.copy(other / "auv0.key", folder / "auv1.key")
    with pytest.raises(tls.TLSError, match="auv1.key is not the key of"):
        tls.check_identity(folder, "auv1", now=NOW)
    with pytest.raises(ValueError, match="DNS name or an IP address"):
        tls.split_hosts(("ok.example", "-bad"))
    assert tls.split_hosts(("ok.example", "::1", "10.0.0.1")) == (("ok.example",), ("::1", "10.0.0.1"))


def _json(config, key: str):
    return json.loads(config.get_json(key))


def test_zenoh_configs_over_mutual_tls(tmp_path) -> None:
    tls.write_zenoh(tmp_path, credentials.users(2))
    client = zbus.client_config("tls/10.0.0.1:7447", "auv0", tls_dir=tmp_path)
    section = _json(client, "transport/link/tls")
    assert section["enable_mtls"] is True and section["connect_certificate"].endswith("auv0.pem")
    assert section["connect_private_key"].endswith("auv0.key") and section["root_ca_certificate"].endswith("ca.pem")
    assert _json(client, "transport/auth/usrpwd/user") is None

    routed = zbus.router_config("tls/0.0.0.0:7447", {}, agents=2, tls_dir=tmp_path)
    section = _json(routed, "transport/link/tls")
    assert section["enable_mtls"] is True and section["listen_certificate"].endswith("router.pem")
    acl = _json(routed, "access_control")
    assert acl["default_permission"] == "deny"
    assert {s["id"]: s["cert_common_names"] for s in acl["subjects"]}["auv1"] == ["auv1"]
    assert all(s.get("usernames") is None for s in acl["subjects"])
    assert _json(routed, "adminspace/enabled") is True
    plain = zbus.router_config("tcp/127.0.0.1:7447", {"auv0": "pw"}, agents=1, dictionary_file=tmp_path / "u.txt")
    assert all(s.get("cert_common_names") is None for s in _json(plain, "access_control")["subjects"])
    assert _json(plain, "adminspace/enabled") is False

    for bad in (
        lambda: zbus.client_config("tcp/127.0.0.1:7447", "auv0", tls_dir=tmp_path),
        lambda: zbus.client_config("tls/127.0.0.1:7447", "auv0", "pw"),
        lambda: zbus.client_config("tls/127.0.0.1:7447", "auv0", "pw", tls_dir=tmp_path),
        lambda: zbus.router_config("tls/127.0.0.1:7447", {"auv0": "pw"}, tls_dir=tmp_path),
        lambda: zbus.access_control([], subject="interfaces"),
    ):
        with pytest.raises(ValueError):
            bad()


def _shell_args(router_endpoint: str, tls_dir=None, **extra) -> argparse.Namespace:
    values = {"password_file": None, "password_fd": None, "insecure_dev": False, **extra}
    return argparse.Namespace(router=router_endpoint, tls_dir=tls_dir, **values)


def test_a_process_refuses_to_start_on_a_certificate_that_will_not_do(tmp_path, capsys) -> None:
    tls.write_zenoh(tmp_path, ("auv0",), days=1, now=datetime.datetime.now(datetime.UTC) - 2 * DAY)  # expired
    refusals = {
        "expired on": _shell_args("tls/127.0.0.1:7447", tmp_path),
        "mutual TLS: give --tls-dir": _shell_args("tls/127.0.0.1:7447", insecure_dev=True),
        "with --tls-dir the endpoint must be tls/": _shell_args("tcp/127.0.0.1:7447", tmp_path),
        "no --password-file": _shell_args("tls/127.0.0.1:7447", tmp_path, password_file="pw"),
    }
    for says, args in refusals.items():
        with pytest.raises(SystemExit) as exit_:
            shell.login(args, "auv0")
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and says in err and err.count("\n") == 1
    tls.write_zenoh(tmp_path, ("auv0",))
    assert shell.login(_shell_args("tls/127.0.0.1:7447", tmp_path), "auv0") == {"tls_dir": tmp_path}


def test_router_and_run_verbs_refuse_mixed_logins(tmp_path, capsys) -> None:
    tls.write_zenoh(tmp_path, ("auv0",))
    assert router.main(["--tls-dir", str(tmp_path), "--listen", "tcp/127.0.0.1:7447"]) == 2
    assert router.main(["--tls-dir", str(tmp_path), "--insecure-dev"]) == 2
    assert router.main(["--tls-dir", str(tmp_path / "missing")]) == 2
    assert router.main(["--listen", "tls/127.0.0.1:7447", "--insecure-dev"]) == 2
    assert run_cli.main(["--tls", "--mode", "inprocess", "--duration", "4"]) == 2
    assert run_cli.main(["--tls", "--credentials", str(tmp_path), "--duration", "4"]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 6 and "missing/ca.pem" in lines[2] and "--tls goes with --mode processes" in lines[4]


def test_shared_names_finds_a_certificate_held_twice() -> None:
    sessions = {"a1": "auv0", "b2": "auv1", "c3": "auv0", "d4": "", "e5": ""}
    assert router.shared_names(sessions) == {"auv0": ["a1", "c3"]}
    assert router.shared_names({"a1": "auv0"}) == {}
