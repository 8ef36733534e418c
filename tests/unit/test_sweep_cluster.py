"""orchestrator/sweep/cluster.py: which schedulers a sweep accepts, with which credentials; the LocalCluster's own
certificates. Refusals are one line and exit 2 before the sweep's folder is made (the processes are in
tests/integration/test_sweep_scheduler.py and test_sweep_tls.py)."""

from __future__ import annotations

import datetime

import pytest
from cryptography import x509
from cryptography.exceptions import InvalidSignature

from auv_swarm.bus import tls
from auv_swarm.orchestrator.cli import sweep as sweep_verb
from auv_swarm.orchestrator.sweep import cluster
from auv_swarm.orchestrator.sweep.cluster import ClusterError


@pytest.fixture(scope="module")
def tls_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tls")
    tls.write_dask(folder)
    return folder


@pytest.mark.parametrize("address", ["tcp://10.0.0.5:8786", "10.0.0.5:8786", "TCP://h:1", "[::1]:8786"])
def test_plain_tcp_is_refused_unless_asked_for(address, capsys) -> None:
    with pytest.raises(ClusterError, match="plain TCP lets anyone .* --insecure-scheduler"):
        cluster.parse_scheduler(address, None)
    scheduler = cluster.parse_scheduler(address, None, insecure=True)
    assert scheduler.tls is None and scheduler.address == "tcp://" + address.split("://")[-1]
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("warning: --insecure-scheduler: plain TCP to tcp://")


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("tls://10.0.0.5", "expected tls://HOST:PORT"),
        ("tls://10.0.0.5:0", "expected tls://HOST:PORT"),
        ("tls://10.0.0.5:70000", "expected tls://HOST:PORT"),
        ("tls://:8786", "expected tls://HOST:PORT"),
        ("tls://a b:8786", "expected tls://HOST:PORT"),
        ("tls://h:8786/x", "expected tls://HOST:PORT"),
        ("tls://::1:8786", "expected tls://HOST:PORT"),
        ("ucx://h:8786", "must be tls://HOST:PORT, got scheme ucx://"),
        ("", "expected tls://HOST:PORT"),
    ],
)
def test_a_malformed_address_is_named(address, message, tls_dir) -> None:
    with pytest.raises(ClusterError, match=message):
        cluster.parse_scheduler(address, tls_dir)


def test_a_tls_scheduler_reads_the_clients_files(tls_dir, tmp_path) -> None:
    scheduler = cluster.parse_scheduler("tls://[::1]:8786", tls_dir)
    assert scheduler.address == "tls://[::1]:8786"
    args = scheduler.tls.security_args()
    assert args == {
        "require_encryption": True,
        "tls_ca_file": str(tls_dir / "ca.pem"),
        "tls_client_cert": str(tls_dir / "client.pem"),
        "tls_client_key": str(tls_dir / "client.key"),
    }
    with pytest.raises(ClusterError, match="needs --tls-dir DIR"):
        cluster.parse_scheduler("tls://h:8786", None)
    with pytest.raises(ClusterError, match="--insecure-scheduler goes with a tcp://"):
        cluster.parse_scheduler("tls://h:8786", tls_dir, insecure=True)
    with pytest.raises(ClusterError, match="cannot read .*ca.pem: No such file .* credentials --dask"):
        cluster.client_tls(tmp_path)  # nothing there
    later = datetime.datetime.now(datetime.UTC) + datetime.timedelta(days=tls.DEFAULT_DAYS + 1)
    with pytest.raises(ClusterError, match="expired on .* issues fresh certificates"):
        cluster.client_tls(tls_dir, now=later)
    mixed = tmp_path / "mixed"
    tls.write_dask(mixed)
    (mixed / "client.key").write_bytes((tls_dir / "client.key").read_bytes())  # another pair's key
    with pytest.raises(ClusterError, match="not a usable CA and client pair"):
        cluster.client_tls(mixed)


def test_the_local_cluster_gets_its_own_ca_and_a_pair_per_role() -> None:
    one, two = cluster.local_tls(), cluster.local_tls()
    assert one.ca != two.ca and set(one.roles) == {"scheduler", "worker", "client"}
    ca = x509.load_pem_x509_certificate(one.ca.encode())
    for cert, key in one.roles.values():
        x509.load_pem_x509_certificate(cert.encode()).verify_directly_issued_by(ca)
        with pytest.raises(InvalidSignature):  # the same name, another key
            x509.load_pem_x509_certificate(cert.encode()).verify_directly_issued_by(
                x509.load_pem_x509_certificate(two.ca.encode())
            )
        assert "PRIVATE KEY" in key
    assert cluster.http_settings(False) == {
        "distributed.scheduler.http.routes": [],
        "distributed.worker.http.routes": [],
    }
    assert cluster.http_settings(True) == {}


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--scheduler", "tcp://127.0.0.1:8786"], "plain TCP lets anyone"),
        (["--scheduler", "127.0.0.1:8786"], "plain TCP lets anyone"),
        (["--scheduler", "tls://127.0.0.1"], "expected tls://HOST:PORT"),
        (["--scheduler", "tls://127.0.0.1:8786"], "needs --tls-dir DIR"),
        (["--tls-dir", "x"], "--tls-dir goes with --scheduler"),
        (["--insecure-scheduler"], "--insecure-scheduler goes with --scheduler tcp://"),
    ],
)
def test_the_verb_refuses_in_one_line_before_making_the_folder(flags, message, tmp_path, capsys) -> None:
    out = tmp_path / "s"
    assert sweep_verb.main(["--seeds", "1", "--duration", "20", "--out", str(out), *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
    assert not out.exists()
