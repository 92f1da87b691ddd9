"""Logins through a site relay: the ground's server (TLS, accounts) <- the
relay (its own account, role relay; the site's accounts) <- robots and a
console at the site. Each site account may do through the relay what it may
at the ground, and no more: the relay enforces its rules where it logs in."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from backend.transport import free_port

from .helpers import CLI, ROOT, Accounts, SecureServer, ctl, env, stop_process

EXIT_UNREACHABLE = 3


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("pki")
    r = subprocess.run([*CLI, "certs", str(d)], cwd=ROOT, env=env(), capture_output=True,
                       text=True, timeout=60)  # fmt: skip
    assert r.returncode == 0, r.stderr
    return d


def _site_accounts(accounts: Accounts) -> Path:
    """The site's accounts: the same names, roles and password files as at the ground."""
    site = accounts.dir / "site-accounts.yaml"
    site.write_text(
        "format: missionctl/accounts@1\naccounts:\n"
        "  fleet: {role: robot, robots: [lru1, lru2], password_file: secrets/fleet.pw}\n"
        "  watch: {role: observer, password_file: secrets/watch.pw}\n"
    )
    return site


def _start(args: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(args, cwd=ROOT, env=env(), stdout=log.open("w"),
                            stderr=subprocess.STDOUT, text=True)  # fmt: skip


def _wait_for(log: Path, proc: subprocess.Popen, text: str, timeout: float = 30.0) -> None:
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:  # bounded polling of a log file on readiness only
        if text in log.read_text():
            return
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    raise AssertionError(f"no {text!r} in {log.name}:\n{log.read_text()}")


def test_a_robot_account_logs_in_through_the_relay_and_gets_no_more(tmp_path, accounts, pki):
    ca = ["--ca", str(pki / "ca.pem")]
    server = SecureServer(
        tmp_path, accounts, scheme="tls", client_tls=ca,
        extra=["--tls-cert", str(pki / "server.pem"), "--tls-key", str(pki / "server.key")],
    )  # fmt: skip
    site = f"tcp/127.0.0.1:{free_port()}"
    relay_log, robots_log = tmp_path / "relay.log", tmp_path / "robots.log"
    relay = robots = None
    try:
        relay = _start(
            [*CLI, "router", "--listen", site, "--connect", server.endpoint, *ca,
             *accounts.login_args("lander"), "--accounts", str(_site_accounts(accounts))],
            relay_log,
        )  # fmt: skip
        _wait_for(relay_log, relay, "ground link up")
        assert "site logins required" in relay_log.read_text()
        robots = _start(
            [sys.executable, str(ROOT / "docs" / "examples" / "trivial_robots.py"),
             "--connect", site, *accounts.login_args("fleet"), "lru1:lru_science",
             "lru2:lru_manipulator"],
            robots_log,
        )  # fmt: skip
        _wait_for(robots_log, robots, "ready lru2")
        r = server.ctl("ops", "robots")
        assert r.returncode == 0 and r.stdout.count("online since") == 2, r.stdout
        # an observer at the site reads the mission through the relay
        r = ctl(site, *accounts.login_args("watch"), "state", "--json")
        assert r.returncode == 0, r.stderr
        # the robot account may not read it there either, nor may an unknown login come in
        r = ctl(site, *accounts.login_args("fleet"), "state", "--timeout", "3")
        assert r.returncode == EXIT_UNREACHABLE
        assert "may not read the mission" in r.stderr
        r = ctl(site, *accounts.login_args("ops"), "state", "--timeout", "3")  # not a site account
        assert r.returncode == EXIT_UNREACHABLE
        assert "login refused for user ops" in r.stderr
    finally:
        for p in (robots, relay):
            if p is not None:
                stop_process(p)
        server.stop()


def test_a_relay_with_accounts_needs_a_tls_link_and_an_open_site_is_refused(tmp_path, accounts):
    def router(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([*CLI, "router", *args], cwd=ROOT, env=env(), capture_output=True,
                              text=True, timeout=30)  # fmt: skip

    r = router("--accounts", str(accounts.file), "--connect", "tcp/127.0.0.1:7447")
    assert r.returncode == 2
    assert "needs a tls/ --connect endpoint" in r.stderr
    r = router("--listen", "tcp/0.0.0.0:7448", *accounts.login_args("lander"))
    assert r.returncode == 2
    assert "would let anyone reaching tcp/0.0.0.0:7448 in: give --accounts" in r.stderr
