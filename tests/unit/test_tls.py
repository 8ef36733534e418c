"""bus/tls.py: a CA and the certificates it signs, checked by real TLS handshakes (in memory, OpenSSL through
Python's ssl) and by what ``auv-swarm credentials --dask DIR`` writes."""

from __future__ import annotations

import datetime
import ssl
import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from auv_swarm.bus import credentials, tls

NOW = datetime.datetime(2030, 1, 1, tzinfo=datetime.UTC)


def _files(tmp: Path, name: str, pair: tls.Pair) -> tuple[str, str]:
    cert, key = tmp / f"{name}.pem", tmp / f"{name}.key"
    tls.write_private(cert, pair.cert_pem)
    tls.write_private(key, pair.key_pem)
    return str(cert), str(key)


def _context(purpose: ssl.Purpose, ca: tls.Authority, pair: tls.Pair | None, tmp: Path, name: str) -> ssl.SSLContext:
    """As Dask makes its contexts: verify the peer against ``ca`` (both sides), no host name check."""
    ctx = ssl.create_default_context(purpose, cadata=ca.pair().cert_pem.decode())
    ctx.check_hostname = False
    ctx.verify_mode = ssl.CERT_REQUIRED
    if pair is not None:
        ctx.load_cert_chain(*_files(tmp, name, pair))
    return ctx


def handshake(server_ctx: ssl.SSLContext, client_ctx: ssl.SSLContext) -> str | None:
    """A TLS handshake and one byte each way over memory buffers; None if it went through, else who refused."""
    s_in, s_out, c_in, c_out = ssl.MemoryBIO(), ssl.MemoryBIO(), ssl.MemoryBIO(), ssl.MemoryBIO()
    server = server_ctx.wrap_bio(s_in, s_out, server_side=True)
    client = client_ctx.wrap_bio(c_in, c_out, server_side=False)
    steps = {"client": lambda: (client.do_handshake(), client.write(b"x"), client.read(1)),
             "server": lambda: (server.do_handshake(), server.read(1), server.write(b"y"))}  # fmt: skip
    done: set[str] = set()
    for _ in range(20):
        for side, step in steps.items():
            if side in done:
                continue
            try:
                step()
                done.add(side)
            except (ssl.SSLWantReadError, ssl.SSLWantWriteError):
                pass
            except ssl.SSLError:
                return side
            c_in.write(s_out.read())
            s_in.write(c_out.read())
        if done == set(steps):
            return None
    raise AssertionError("the handshake neither finished nor failed")


def test_a_ca_signs_certificates_for_the_roles_asked(tmp_path) -> None:
    ca = tls.new_authority("test CA", days=10, now=NOW)
    assert ca.cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    leaf = tls.issue(ca, "auv3", client=True, server=True, dns=("router.local",), ips=("10.0.0.7",), days=3, now=NOW)
    cert = x509.load_pem_x509_certificate(leaf.cert_pem)
    assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == "auv3"
    assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    usages = set(cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value)
    assert usages == {ExtendedKeyUsageOID.CLIENT_AUTH, ExtendedKeyUsageOID.SERVER_AUTH}
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert sans.get_values_for_type(x509.DNSName) == ["router.local"]
    assert [str(a) for a in sans.get_values_for_type(x509.IPAddress)] == ["10.0.0.7"]
    skew = datetime.timedelta(seconds=tls.CLOCK_SKEW_S)
    assert cert.not_valid_before_utc == NOW - skew and leaf.expires() == NOW - skew + datetime.timedelta(days=3)
    assert tls.issue(ca, "long", days=30, now=NOW).expires() == ca.cert.not_valid_after_utc  # never past its CA
    with pytest.raises(tls.TLSError, match="expired"):
        tls.issue(ca, "late", now=NOW + datetime.timedelta(days=11))
    with pytest.raises(ValueError):
        tls.issue(ca, "nobody", client=False, server=False)


def test_handshakes_admit_the_cas_certificates_only(tmp_path) -> None:
    ca, other = tls.new_authority("ours"), tls.new_authority("theirs")
    server = tls.issue(ca, "worker", client=True, server=True)
    client, stranger = tls.issue(ca, "client"), tls.issue(other, "client")
    listening = _context(ssl.Purpose.CLIENT_AUTH, ca, server, tmp_path, "server")

    def dial(pair: tls.Pair | None, name: str, trust: tls.Authority = ca) -> ssl.SSLContext:
        return _context(ssl.Purpose.SERVER_AUTH, trust, pair, tmp_path, name)

    assert handshake(listening, dial(client, "client")) is None
    assert handshake(listening, dial(None, "none")) == "server"  # no certificate: refused
    assert handshake(listening, dial(stranger, "stranger")) == "server"  # another CA's: refused
    as_server = _context(ssl.Purpose.CLIENT_AUTH, ca, client, tmp_path, "client-as-server")
    assert handshake(as_server, dial(client, "client2")) == "client"  # a client-only certificate cannot serve
    impostor = _context(ssl.Purpose.CLIENT_AUTH, other, tls.issue(other, "w", server=True), tmp_path, "impostor")
    assert handshake(impostor, dial(client, "client3")) == "client"  # a server of another CA: refused


def test_credentials_dask_writes_private_files_and_keeps_its_ca(tmp_path) -> None:
    folder = tmp_path / "dask"
    assert credentials.main(["--dask", str(folder), "--days", "7"]) == 0
    paths = tls.dask_files(folder)
    assert sorted(p.name for p in folder.iterdir()) == sorted(paths)
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    assert all(stat.S_IMODE(p.stat().st_mode) == 0o600 for p in paths.values())
    ca = tls.load_authority(paths["ca.pem"], paths["ca.key"])
    for role, (c, s) in tls.DASK_ROLES.items():
        cert = x509.load_pem_x509_certificate(paths[f"{role}.pem"].read_bytes())
        cert.verify_directly_issued_by(ca.cert)
        usages = set(cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value)
        assert (ExtendedKeyUsageOID.CLIENT_AUTH in usages, ExtendedKeyUsageOID.SERVER_AUTH in usages) == (c, s)
    first_ca, first_client = paths["ca.pem"].read_bytes(), paths["client.pem"].read_bytes()
    assert credentials.main(["--dask", str(folder)]) == 0  # again: the same CA, fresh certificates
    assert paths["ca.pem"].read_bytes() == first_ca and paths["client.pem"].read_bytes() != first_client
    paths["ca.key"].unlink()  # a copy of the folder (a worker's host) cannot issue
    assert credentials.main(["--dask", str(folder)]) == 2
    assert credentials.main(["--dask", str(tmp_path / "x"), "--days", "0"]) == 2
    assert credentials.main(["--dask", str(tmp_path / "x"), "--folders"]) == 2
    assert credentials.main(["--out", str(tmp_path / "x"), "--days", "3"]) == 2
    assert not (tmp_path / "x").exists()


def test_the_swarms_ca_and_a_clusters_are_never_one(tmp_path, capsys) -> None:
    """credentials --tls and --dask write ca.pem/ca.key by the same names: pointed at one folder, the second is
    refused (one line, exit 2, nothing written), or every swarm certificate would be a Dask client of the cluster."""
    for first, second in ((["--dask"], ["--tls"]), (["--tls"], ["--dask"])):
        folder = tmp_path / first[0].strip("-")
        assert credentials.main([*first, str(folder)]) == 0
        before = {p.name: p.read_bytes() for p in folder.rglob("*") if p.is_file()}
        capsys.readouterr()
        assert credentials.main([*second, str(folder)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "give each CA a folder of its own" in err, err
        assert {p.name: p.read_bytes() for p in folder.rglob("*") if p.is_file()} == before


def test_a_certificate_is_not_a_ca(tmp_path) -> None:
    ca = tls.new_authority("ca")
    leaf = tls.issue(ca, "leaf")
    cert, key = _files(tmp_path, "leaf", leaf)
    with pytest.raises(tls.TLSError, match="not the certificate and key of one CA"):
        tls.load_authority(Path(cert), Path(key))
    with pytest.raises(tls.TLSError, match="cannot read"):
        tls.load_authority(tmp_path / "nope.pem", tmp_path / "nope.key")
