"""`missionctl certs`: a private CA, a server certificate and client certificates.

Enough PKI for a test or a small field deployment: one CA signs the router's
certificate (names and IP addresses it is reached by) and one certificate per
client (its common name is what Zenoh's access control sees as
`cert_common_names` under mutual TLS). Keys are ECDSA P-256 in PKCS#8 PEM,
written with mode 0600; certificates are PEM.

Uses the `cryptography` package, imported only when the command runs.
"""

from __future__ import annotations

import argparse
import datetime as dt
import ipaddress
import os
import re
import sys
from pathlib import Path

from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "certs",
        help="make a CA, a server certificate and client certificates for TLS endpoints",
        description="Writes DIR/ca.pem (+ ca.key), DIR/server.pem (+ server.key) and DIR/client-NAME.pem "
        "(+ .key) per --client. An existing DIR/ca.pem is reused, so clients can be added later.",
    )
    p.add_argument("dir", metavar="DIR", help="directory to write into (created)")
    p.add_argument(
        "--server-name",
        metavar="NAME",
        action="append",
        help="DNS name or IP address clients use to reach the server; repeatable "
        "(default: localhost and 127.0.0.1). Given, the server certificate is (re)made.",
    )
    p.add_argument(
        "--client",
        metavar="NAME",
        action="append",
        default=[],
        help="make a client certificate with this common name; repeatable",
    )
    p.add_argument(
        "--days",
        type=int,
        default=365,
        metavar="N",
        help="validity of new certificates (default 365)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    bad = [n for n in args.client if not _NAME.match(n)]
    if bad:
        print(
            f"missionctl certs: invalid client name(s) {', '.join(map(repr, bad))}: use letters, digits, '.', '_', '-'",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    if args.days < 1:
        print("missionctl certs: --days must be at least 1", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        written = make_certs(
            Path(args.dir), server_names=args.server_name, clients=args.client, days=args.days
        )
    except ImportError:
        print(
            "missionctl certs: needs the 'cryptography' package (pip install cryptography)",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    except (OSError, ValueError) as e:
        print(f"missionctl certs: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    for path in written:
        print(path)
    return EXIT_OK


def make_certs(
    directory: Path,
    *,
    server_names: list[str] | None = None,
    clients: list[str] = (),
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


def _new_key():
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _name(common_name: str):
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "missionctl"),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def _builder(subject, issuer, public_key, days: int):
    from cryptography import x509

    now = dt.datetime.now(dt.UTC)
    return (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(issuer)
        .public_key(public_key)
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))  # tolerate small clock skew
        .not_valid_after(now + dt.timedelta(days=days))
    )


def _make_ca(days: int):
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


def _make_leaf(common_name: str, names: list[str], ca_cert, ca_key, days: int, *, server: bool):
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


def _san(name: str):
    from cryptography import x509

    try:
        return x509.IPAddress(ipaddress.ip_address(name))
    except ValueError:
        if not re.match(r"^[A-Za-z0-9*][A-Za-z0-9.-]*$", name):
            raise ValueError(
                f"--server-name {name!r} is neither a DNS name nor an IP address"
            ) from None
        return x509.DNSName(name)


def _write(cert, key, cert_path: Path, key_path: Path) -> list[Path]:
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


def _load(cert_path: Path, key_path: Path):
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    try:
        cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except ValueError as e:
        raise ValueError(f"{cert_path} / {key_path}: not a PEM certificate and key ({e})") from None
    return cert, key
