"""What a router (mission server, site relay) takes to listen with TLS: the
--tls-* options and a tls/ endpoint go together, or each says what is missing."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from backend.cli.listening import tls_listen_options


def _args(listen: list[str] | None, cert: str = "", key: str = "", ca: str = "") -> Any:
    return argparse.Namespace(listen=listen, tls_cert=cert, tls_key=key, tls_ca=ca)


@pytest.fixture
def pem(tmp_path: Path) -> dict[str, str]:
    files = {name: tmp_path / f"{name}.pem" for name in ("cert", "key", "ca")}
    for f in files.values():
        f.write_text("not read here\n")
    return {name: str(f) for name, f in files.items()}


def test_no_tls_asked_no_options() -> None:
    assert tls_listen_options(_args(None)) == {}
    assert tls_listen_options(_args(["tcp/127.0.0.1:7447"])) == {}


def test_a_tls_endpoint_without_a_certificate_says_what_to_give() -> None:
    with pytest.raises(ValueError) as e:
        tls_listen_options(_args(["tcp/127.0.0.1:7447", "tls/127.0.0.1:7448"]))
    assert str(e.value) == (
        "a tls/ endpoint needs --tls-cert FILE and --tls-key FILE (see missionctl certs)"
    )


@pytest.mark.parametrize("given", [("cert",), ("key",), ("ca",), ("cert", "ca")])
def test_a_certificate_and_its_key_go_together(pem: dict[str, str], given: tuple) -> None:
    options = {name: pem[name] for name in given}
    with pytest.raises(ValueError) as e:
        tls_listen_options(_args(["tls/127.0.0.1:7448"], **options))
    assert str(e.value) == "--tls-cert and --tls-key go together"


def test_tls_options_without_a_tls_endpoint_say_so(pem: dict[str, str]) -> None:
    with pytest.raises(ValueError) as e:
        tls_listen_options(_args(["tcp/127.0.0.1:7447"], cert=pem["cert"], key=pem["key"]))
    assert str(e.value) == (
        "--tls-cert/--tls-key/--tls-ca need a tls/ endpoint in --listen "
        "(e.g. --listen tls/0.0.0.0:7447)"
    )


def test_tls_with_and_without_client_certificates(pem: dict[str, str]) -> None:
    listen = ["tls/127.0.0.1:7448"]
    plain = tls_listen_options(_args(listen, cert=pem["cert"], key=pem["key"]))
    assert plain == {
        "transport/link/tls/listen_certificate": str(Path(pem["cert"]).resolve()),
        "transport/link/tls/listen_private_key": str(Path(pem["key"]).resolve()),
    }
    mutual = tls_listen_options(_args(listen, **pem))
    assert mutual == plain | {
        "transport/link/tls/root_ca_certificate": str(Path(pem["ca"]).resolve()),
        "transport/link/tls/enable_mtls": True,
    }
