"""Certificates for mutual TLS: a certificate authority (CA) of our own and the certificates it signs.

Generic, for every link we secure with TLS: one CA per deployment, one certificate per role or user, each
naming its peer by common name (and, where the peer checks it, by DNS name or IP address in the subject
alternative name), marked for the side of the handshake it plays (``client``: it connects and proves who it
is; ``server``: it listens; a peer that does both, as a Dask worker, gets both). Keys are ECDSA P-256
(PKCS #8, PEM), certificates SHA-256 signed X.509 v3. A certificate is valid from :data:`CLOCK_SKEW_S` before
its making (hosts' clocks differ) for ``days`` days, never past its CA.

Users:

- ``auv-swarm sweep`` makes a CA and its certificates in memory for each LocalCluster
  (:func:`dask_certificates`, orchestrator/sweep/cluster.py): nothing is written, the CA key is dropped
  once the certificates are signed.
- ``auv-swarm credentials --dask DIR`` writes them as files (:func:`write_dask`) for a cluster started by
  hand (docs/sweeps.md).
- ``auv-swarm credentials --tls DIR`` writes the swarm's (:func:`write_zenoh`): one certificate per zenoh
  user, named as the user, for the router's mutual TLS and access control (docs/deploy.md); ``auv-swarm run
  --tls`` writes them into a private folder of its own for one mission. Every process checks its own files
  (:func:`check_identity`) before it connects.

Files are written mode 0600 in a folder made 0700 (:func:`write_private`). The CA key (``ca.key``) stays
where it was made: the same command on the same folder issues fresh certificates from it; only ``ca.pem``
and a role's own pair are copied to the hosts of that role. No zenoh and no Dask here.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import re
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

CA_DAYS = 365
"""Lifetime of a new CA (days)."""
DEFAULT_DAYS = 30
"""Default lifetime of a certificate (days): ``auv-swarm credentials --dask DIR --days N`` sets another."""
CLOCK_SKEW_S = 300
"""A certificate is valid from this long before it was made (s): another host's clock may lag."""
ORGANISATION = "auv-swarm"


class TLSError(ValueError):
    """A CA or certificate that cannot be read or used; the message is one line for the user."""


@dataclass(frozen=True)
class Pair:
    """A private key and its certificate, both PEM (bytes)."""

    key_pem: bytes
    cert_pem: bytes

    def expires(self) -> datetime.datetime:
        """When the certificate stops being valid (UTC)."""
        return x509.load_pem_x509_certificate(self.cert_pem).not_valid_after_utc


@dataclass(frozen=True)
class Authority:
    """A CA: its signing key and its self-signed certificate."""

    key: ec.EllipticCurvePrivateKey
    cert: x509.Certificate

    def pair(self) -> Pair:
        """The CA as PEM (key and certificate)."""
        return Pair(_key_pem(self.key), self.cert.public_bytes(serialization.Encoding.PEM))


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def _name(common_name: str) -> x509.Name:
    if not common_name or not isinstance(common_name, str):
        raise ValueError(f"common_name must be a non-empty string, got {common_name!r}")
    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, ORGANISATION),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def _now(now: datetime.datetime | None) -> datetime.datetime:
    return now if now is not None else datetime.datetime.now(datetime.UTC)


def _key_usage(authority: bool) -> x509.KeyUsage:
    """Signatures only; a CA's key also signs certificates and revocation lists."""
    return x509.KeyUsage(
        digital_signature=True,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=False,
        key_cert_sign=authority,
        crl_sign=authority,
        encipher_only=False,
        decipher_only=False,
    )


def new_authority(common_name: str, *, days: int = CA_DAYS, now: datetime.datetime | None = None) -> Authority:
    """A fresh CA named ``common_name``, valid ``days`` days from ``now`` (default: the clock), that signs
    certificates only (``keyCertSign``, ``cRLSign``; path length 0: no intermediate CA)."""
    if days < 1:
        raise ValueError(f"days must be >= 1, got {days}")
    start = _now(now) - datetime.timedelta(seconds=CLOCK_SKEW_S)
    key = ec.generate_private_key(ec.SECP256R1())
    name = _name(common_name)
    usage = _key_usage(authority=True)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(start + datetime.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(usage, critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return Authority(key, cert)


def issue(
    ca: Authority,
    common_name: str,
    *,
    client: bool = True,
    server: bool = False,
    dns: tuple[str, ...] = (),
    ips: tuple[str, ...] = (),
    days: int = DEFAULT_DAYS,
    now: datetime.datetime | None = None,
) -> Pair:
    """A fresh key and its certificate for ``common_name``, signed by ``ca``.

    ``client``/``server``: the extended key usages (TLS client and/or server authentication; at least one).
    ``dns``/``ips``: the subject alternative names a peer may check against the address it dialled (Dask does
    not; a zenoh client does). Valid ``days`` days from ``now``, cut at the CA's own end.
    """
    if not (client or server):
        raise ValueError("a certificate must be for a client, a server or both")
    if days < 1:
        raise ValueError(f"days must be >= 1, got {days}")
    start = _now(now) - datetime.timedelta(seconds=CLOCK_SKEW_S)
    end = min(start + datetime.timedelta(days=days), ca.cert.not_valid_after_utc)
    if end <= _now(now):
        raise TLSError(f"the CA {ca.cert.subject.rfc4514_string()} expired on {ca.cert.not_valid_after_utc:%Y-%m-%d}")
    key = ec.generate_private_key(ec.SECP256R1())
    purposes = [ExtendedKeyUsageOID.CLIENT_AUTH] * client + [ExtendedKeyUsageOID.SERVER_AUTH] * server
    usage = _key_usage(authority=False)
    builder = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(ca.cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(usage, critical=True)
        .add_extension(x509.ExtendedKeyUsage(purposes), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca.key.public_key()), critical=False)
    )
    names = [x509.DNSName(d) for d in dns] + [x509.IPAddress(ipaddress.ip_address(a)) for a in ips]
    if names:
        builder = builder.add_extension(x509.SubjectAlternativeName(names), critical=False)
    return Pair(_key_pem(key), builder.sign(ca.key, hashes.SHA256()).public_bytes(serialization.Encoding.PEM))


def load_authority(cert_path: Path, key_path: Path) -> Authority:
    """The CA in ``cert_path`` (PEM certificate) and ``key_path`` (PEM key); TLSError if unreadable or not a CA."""
    try:
        cert = x509.load_pem_x509_certificate(Path(cert_path).read_bytes())
        key = serialization.load_pem_private_key(Path(key_path).read_bytes(), password=None)
    except OSError as exc:
        raise TLSError(f"cannot read the CA in {cert_path}, {key_path}: {exc.strerror}") from None
    except (ValueError, TypeError) as exc:
        raise TLSError(f"{cert_path} and {key_path} are not a PEM certificate and key: {exc}") from None
    try:
        is_ca = cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        is_ca = False
    if not is_ca or not isinstance(key, ec.EllipticCurvePrivateKey) or key.public_key() != cert.public_key():
        raise TLSError(f"{cert_path} and {key_path} are not the certificate and key of one CA")
    return Authority(key, cert)


DASK_ROLES = {"scheduler": (True, True), "worker": (True, True), "client": (True, False)}
"""Dask's roles -> (client, server) usages: the scheduler and the workers both listen and connect (to each
other); the client only connects."""


def dask_certificates(ca: Authority, *, days: int = DEFAULT_DAYS, now: datetime.datetime | None = None) -> dict:
    """One certificate per Dask role (:data:`DASK_ROLES`), signed by ``ca``; role -> :class:`Pair`.

    Dask verifies the peer's chain to the CA, in both directions, and not its name (it dials IP addresses)."""
    return {
        role: issue(ca, f"dask-{role}", client=c, server=s, days=days, now=now) for role, (c, s) in DASK_ROLES.items()
    }


def dask_files(folder: Path) -> dict[str, Path]:
    """The files of :func:`write_dask` in ``folder``: ``ca.pem``, ``ca.key``, then ``<role>.pem`` and
    ``<role>.key`` for each role; name -> path."""
    folder = Path(folder)
    names = ["ca.pem", "ca.key"] + [f"{role}.{ext}" for role in DASK_ROLES for ext in ("pem", "key")]
    return {n: folder / n for n in names}


DASK_CA = "auv-swarm dask CA"
"""The common name of the CA :func:`write_dask` makes."""


def write_dask(folder: Path, *, days: int = DEFAULT_DAYS, now: datetime.datetime | None = None) -> tuple[dict, bool]:
    """Write a Dask cluster's TLS files into ``folder`` (:func:`dask_files`, each mode 0600); (name -> path, new CA).

    A CA already in ``folder`` (``ca.pem`` and ``ca.key``) is kept and signs fresh certificates, so hosts that
    hold its ``ca.pem`` need only the new pairs; otherwise a new CA is made. TLSError if ``folder`` holds a
    ``ca.pem`` without its key (a copy: issue certificates where the CA was made) or an unusable CA."""
    paths = dask_files(folder)
    ca, made = authority_in(folder, DASK_CA, days=days, now=now)
    for role, pair in dask_certificates(ca, days=days, now=now).items():
        write_private(paths[f"{role}.key"], pair.key_pem)
        write_private(paths[f"{role}.pem"], pair.cert_pem)
    return paths, made


def authority_in(
    folder: Path, common_name: str, *, days: int = DEFAULT_DAYS, now: datetime.datetime | None = None
) -> tuple[Authority, bool]:
    """The CA of ``folder`` (``ca.pem`` and ``ca.key``), or a new one named ``common_name`` written there (0600, the
    folder made 0700); (CA, made). TLSError for a ``ca.pem`` without its key (a copy: issue certificates where the
    CA was made), an unusable CA, or a CA of another name: the swarm's CA and a sweep cluster's are never one, or
    every swarm certificate would be a Dask client able to run code on the cluster."""
    folder = Path(folder)
    cert_path, key_path = folder / "ca.pem", folder / "ca.key"
    if cert_path.exists():
        if not key_path.exists():
            raise TLSError(f"{cert_path} has no ca.key beside it: issue certificates where the CA was made")
        ca = load_authority(cert_path, key_path)
        names = ca.cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
        found = str(names[0].value) if names else ""
        if found != common_name:
            raise TLSError(
                f"{cert_path} is the CA {found!r}, not {common_name!r}: give each CA a folder of its own "
                "(credentials --tls and --dask)"
            )
        return ca, False
    ca = new_authority(common_name, days=max(CA_DAYS, days), now=now)
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    write_private(key_path, ca.pair().key_pem)
    write_private(cert_path, ca.pair().cert_pem)
    return ca, True


ZENOH_CA = "auv-swarm zenoh CA"
"""The common name of the CA :func:`write_zenoh` makes."""
ROUTER = "router"
"""The common name of the zenoh router's certificate (a server and a client certificate: no ACL user has it)."""
DEFAULT_ROUTER_HOSTS = ("localhost", "127.0.0.1")
"""The names a client may dial the router by when none are given: this host only."""
_DNS_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def split_hosts(hosts: tuple[str, ...]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``hosts`` as (DNS names, IP addresses) for a certificate's subject alternative names; ValueError naming a
    host that is neither."""
    dns: list[str] = []
    ips: list[str] = []
    for host in hosts:
        try:
            ips.append(str(ipaddress.ip_address(host)))
            continue
        except ValueError:
            pass
        if not host or len(host) > 253 or not all(_DNS_LABEL.match(label) for label in host.rstrip(".").split(".")):
            raise ValueError(f"a router host must be a DNS name or an IP address, got {host!r}")
        dns.append(host)
    return tuple(dns), tuple(ips)


def zenoh_files(folder: Path, name: str) -> dict[str, Path]:
    """The files a zenoh process named ``name`` reads from its TLS folder: ``ca`` (``ca.pem``, the CA that signed
    every certificate of the swarm), ``cert`` (``<name>.pem``) and ``key`` (``<name>.key``)."""
    folder = Path(folder)
    return {"ca": folder / "ca.pem", "cert": folder / f"{name}.pem", "key": folder / f"{name}.key"}


def write_zenoh(
    folder: Path,
    names: tuple[str, ...],
    *,
    router_hosts: tuple[str, ...] = DEFAULT_ROUTER_HOSTS,
    days: int = DEFAULT_DAYS,
    now: datetime.datetime | None = None,
) -> tuple[dict[str, dict[str, Path]], bool]:
    """Write the swarm's mutual-TLS files into ``folder`` (each mode 0600); (name -> :func:`zenoh_files`, new CA).

    One client certificate per zenoh user in ``names``, its common name the user's name (the router's access
    control reads it), and the router's (:data:`ROUTER`: server and client, its subject alternative names the
    ``router_hosts`` clients dial). The CA is the folder's own (:func:`authority_in`): kept when there, so issuing
    again rotates every certificate under the same CA. ValueError for a bad host, TLSError for an unusable CA."""
    dns, ips = split_hosts(router_hosts)
    ca, made = authority_in(folder, ZENOH_CA, days=days, now=now)
    pairs = {ROUTER: issue(ca, ROUTER, client=True, server=True, dns=dns, ips=ips, days=days, now=now)}
    pairs.update({name: issue(ca, name, days=days, now=now) for name in names if name != ROUTER})
    paths = {}
    for name, pair in pairs.items():
        paths[name] = zenoh_files(folder, name)
        write_private(paths[name]["key"], pair.key_pem)
        write_private(paths[name]["cert"], pair.cert_pem)
    return paths, made


def zenoh_section(folder: Path, name: str, side: str) -> dict[str, object]:
    """zenoh's ``transport/link/tls`` section for the process ``name`` with its files in ``folder``
    (:func:`zenoh_files`): the swarm's CA, its own key and certificate on ``side`` (``listen``: the router;
    ``connect``: a client), mutual TLS on (without ``enable_mtls`` a client sends no certificate and the router
    asks for none), and a link closed when a certificate on it expires."""
    if side not in ("listen", "connect"):
        raise ValueError(f"side must be listen or connect, got {side!r}")
    files = {k: str(Path(v).resolve()) for k, v in zenoh_files(folder, name).items()}
    return {
        "root_ca_certificate": files["ca"],
        f"{side}_private_key": files["key"],
        f"{side}_certificate": files["cert"],
        "enable_mtls": True,
        "close_link_on_expiration": True,
    }


def check_scheme(endpoint: str, folder: Path | None, flag: str = "tls_dir") -> None:
    """A zenoh ``tls/`` endpoint goes with a TLS folder (the option ``flag``), and a TLS folder with a ``tls/``
    endpoint; ValueError otherwise."""
    is_tls = str(endpoint).startswith("tls/")
    if folder is not None and not is_tls:
        raise ValueError(f"with {flag} the endpoint must be tls/HOST:PORT, got {endpoint!r}")
    if folder is None and is_tls:
        raise ValueError(f"the endpoint {endpoint} is mutual TLS: give {flag} (the folder of the certificates)")


def check_identity(folder: Path, name: str, now: datetime.datetime | None = None) -> datetime.datetime:
    """When the certificate of ``name`` in ``folder`` expires (UTC), after checking what zenoh would only report as
    a timeout: the three files of :func:`zenoh_files` are readable, the certificate names ``name``, the folder's
    CA signed it, it is valid ``now`` and the key is its own. TLSError, one line naming the file, otherwise."""
    files = zenoh_files(folder, name)
    try:
        ca = x509.load_pem_x509_certificate(files["ca"].read_bytes())
        cert = x509.load_pem_x509_certificate(files["cert"].read_bytes())
        key = serialization.load_pem_private_key(files["key"].read_bytes(), password=None)
    except OSError as exc:
        raise TLSError(
            f"cannot read {exc.filename}: {exc.strerror} (auv-swarm credentials --tls DIR writes the files)"
        ) from None
    except (ValueError, TypeError) as exc:
        raise TLSError(f"{files['ca']}, {files['cert']} and {files['key']} must be PEM files: {exc}") from None
    names = [a.value for a in cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)]
    if names != [name]:
        raise TLSError(f"{files['cert']} is the certificate of {', '.join(map(str, names)) or 'nobody'}, not {name}")
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise TLSError(f"{files['cert']} is not signed by the CA in {files['ca']}") from None
    moment = _now(now)
    if moment < cert.not_valid_before_utc:
        raise TLSError(
            f"{files['cert']} is valid only from {cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC: is this host's clock "
            "right?"
        )
    if moment >= cert.not_valid_after_utc:
        raise TLSError(
            f"{files['cert']} expired on {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC: issue fresh certificates "
            "(docs/deploy.md)"
        )
    if not hasattr(key, "public_key") or key.public_key() != cert.public_key():
        raise TLSError(f"{files['key']} is not the key of {files['cert']}")
    return cert.not_valid_after_utc


def write_private(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` readable and writable by its owner only (0600, also when it existed)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.fchmod(fd, 0o600)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
