"""TLS endpoints: `missionctl certs` makes the files; a client with the CA
connects, one without it is told why; mutual TLS requires a client
certificate, and under mutual TLS an account's certificate must carry its
user name (the router's rules match both)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from .helpers import CLI, ROOT, SecureServer, ctl, env

EXIT_UNREACHABLE = 3


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("pki")
    r = subprocess.run(
        [*CLI, "certs", str(d), "--client", "ops", "--client", "watch"],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    for name in (
        "ca.pem",
        "ca.key",
        "server.pem",
        "server.key",
        "client-ops.pem",
        "client-ops.key",
    ):
        assert str(d / name) in r.stdout.splitlines()
    assert (d / "server.key").stat().st_mode & 0o777 == 0o600
    return d


def _server_args(pki: Path, mtls: bool) -> list[str]:
    args = ["--tls-cert", str(pki / "server.pem"), "--tls-key", str(pki / "server.key")]
    return args + (["--tls-ca", str(pki / "ca.pem")] if mtls else [])


def _client(pki: Path, cert: str | None = None) -> list[str]:
    args = ["--ca", str(pki / "ca.pem")]
    return args + (
        ["--cert", str(pki / f"client-{cert}.pem"), "--key", str(pki / f"client-{cert}.key")]
        if cert
        else []
    )


def test_tls_works_with_the_ca_and_fails_clearly_without(tmp_path, accounts, pki):
    server = SecureServer(
        tmp_path, accounts, scheme="tls", extra=_server_args(pki, False), client_tls=_client(pki)
    )
    try:
        assert server.endpoint.startswith("tls/")
        r = server.ctl("watch", "state", "--json")
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["name"] == "Tutorial"
        r = ctl(server.endpoint, *accounts.login_args("watch"), "state")  # no --ca
        assert r.returncode == EXIT_UNREACHABLE
        assert "Traceback" not in r.stderr
        assert f"TLS: the server certificate at {server.endpoint} is not trusted" in r.stderr
        assert "give --ca FILE" in r.stderr
    finally:
        server.stop()


def test_mutual_tls_needs_a_client_certificate_named_after_the_account(tmp_path, accounts, pki):
    server = SecureServer(
        tmp_path,
        accounts,
        scheme="tls",
        extra=_server_args(pki, True),
        client_tls=_client(pki, "ops"),
    )
    try:
        assert server.ctl("ops", "add", "lru1", "recharge").returncode == 0
        r = ctl(
            server.endpoint, *accounts.login_args("ops"), *_client(pki), "state"
        )  # no client certificate
        assert r.returncode == EXIT_UNREACHABLE
        assert f"the server at {server.endpoint} requires a client certificate" in r.stderr
        # ops's password with watch's certificate: no subject of the rules
        # matches, nothing is allowed
        r = ctl(
            server.endpoint,
            *accounts.login_args("ops"),
            *_client(pki, "watch"),
            "--timeout",
            "2",
            "add",
            "lru1",
            "recharge",
        )
        assert r.returncode == EXIT_UNREACHABLE, r.stderr
        assert "this account may not read the mission" in r.stderr
        r = server.ctl("ops", "state", "--json")
        assert [s["skill"] for s in json.loads(r.stdout)["tasks"]["lru1"]].count("recharge") == 1
    finally:
        server.stop()


def test_certs_reuses_the_ca_and_refuses_bad_names(tmp_path, pki):
    d = tmp_path / "more"
    d.mkdir()
    for name in ("ca.pem", "ca.key"):
        (d / name).write_bytes((pki / name).read_bytes())
    r = subprocess.run(
        [*CLI, "certs", str(d), "--client", "lru1"],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    assert (d / "ca.pem").read_bytes() == (pki / "ca.pem").read_bytes()
    assert str(d / "client-lru1.pem") in r.stdout
    r = subprocess.run(
        [*CLI, "certs", str(d), "--client", "bad name"],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "invalid client name" in r.stderr


def test_certs_into_a_folder_that_cannot_be_made_says_which_and_why(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    r = subprocess.run(
        [*CLI, "certs", str(blocker / "pki")],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2
    assert r.stderr.startswith(f"missionctl certs: cannot write into {blocker / 'pki'}: "), r.stderr
    assert "choose a DIR" in r.stderr and "Traceback" not in r.stderr and "[Errno" not in r.stderr
