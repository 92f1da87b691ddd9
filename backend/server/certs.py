"""The PKI of `missionctl certs`: a private CA, a server certificate and client certificates.

Enough PKI for a test or a small field deployment: one CA signs the router's
certificate (names and IP addresses it is reached by) and one certificate per
client (its common name is what Zenoh's access control sees as
`cert_common_names` under mutual TLS). Keys are ECDSA P-256 in PKCS#8 PEM,
written with mode 0600; certificates are PEM.

Uses the `cryptography` package, imported only when the command runs. The
command line is backend/cli/certs.py.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:  # imported when the command runs (see above)
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric.ec import EllipticCurvePrivateKey
    from cryptography.x509 import GeneralName


def make_certs(
    directory: Path,
    *,
    server_names: list[str] | None = None,
    clients: list[str] | tuple[str, ...] = (),
    days: int = 365,
) -> list[Path]:
    """Create what is missing (or asked for) in `directory`; return the files written."""
    directory.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    ca_cert_path, ca_key_path = directory / "ca.pem", directory / "ca.key"
    if ca_cert_path.exists() and ca_key_path.exists():
        ca_cert, ca_key = _load(ca_cert_path, ca_key_path)
    else:
        ca_cert, ca_key = _make_ca(days)
        written += _write(ca_cert, ca_key, ca_cert_path, ca_key_path)
    server_pem = directory / "server.pem"
    if server_names or not server_pem.exists():
        names = server_names or ["localhost", "127.0.0.1"]
        cert, key = _make_leaf("missionctl server", names, ca_cert, ca_key, days, server=True)
        written += _write(cert, key, server_pem, directory / "server.key")
    for name in clients:
        cert, key = _make_leaf(name, [], ca_cert, ca_key, days, server=False)
        written += _write(
            cert, key, directory / f"client-{name}.pem", directory / f"client-{name}.key"
        )
    return written


# ---------------------------------------------------------------- internals


def _new_key() -> EllipticCurvePrivateKey:
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _name(common_name: str) -> x509.Name:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "missionctl"),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def _builder(
    subject: x509.Name, issuer: x509.Name, public_key: object, days: int
) -> x509.CertificateBuilder:
    from cryptography import x509

    now = dt.datetime.now(dt.UTC)
    return (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(issuer)
        .public_key(public_key)  # type: ignore[arg-type]  # one of the key types it takes
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))  # tolerate small clock skew
        .not_valid_after(now + dt.timedelta(days=days))
    )


def _make_ca(days: int) -> tuple[x509.Certificate, EllipticCurvePrivateKey]:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    key = _new_key()
    name = _name("missionctl CA")
    cert = (
        _builder(name, name, key.public_key(), days * 5)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return cert, key


def _make_leaf(
    common_name: str,
    names: list[str],
    ca_cert: x509.Certificate,
    ca_key: EllipticCurvePrivateKey,
    days: int,
    *,
    server: bool,
) -> tuple[x509.Certificate, EllipticCurvePrivateKey]:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key = _new_key()
    builder = (
        _builder(_name(common_name), ca_cert.subject, key.public_key(), days)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False
        )
    )
    if names:  # clients need none: the verifier checks the chain, ACL reads the common name
        builder = builder.add_extension(
            x509.SubjectAlternativeName([_san(n) for n in names]), critical=False
        )
    return builder.sign(ca_key, hashes.SHA256()), key


def _san(name: str) -> GeneralName:
    from cryptography import x509

    try:
        return x509.IPAddress(ipaddress.ip_address(name))
    except ValueError:
        if not re.match(r"^[A-Za-z0-9*][A-Za-z0-9.-]*$", name):
            raise ValueError(
                f"--server-name {name!r} is neither a DNS name nor an IP address"
            ) from None
        return x509.DNSName(name)


def _write(
    cert: x509.Certificate, key: EllipticCurvePrivateKey, cert_path: Path, key_path: Path
) -> list[Path]:
    from cryptography.hazmat.primitives import serialization

    key_bytes = key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )
    # the key is created private from the start, never world-readable for a moment
    fd = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(key_bytes)
    os.chmod(key_path, 0o600)
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return [cert_path, key_path]


def _load(cert_path: Path, key_path: Path) -> tuple[x509.Certificate, EllipticCurvePrivateKey]:
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    try:
        cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except ValueError as e:
        raise ValueError(f"{cert_path} / {key_path}: not a PEM certificate and key ({e})") from None
    return cert, cast("EllipticCurvePrivateKey", key)  # ours: written by _write
