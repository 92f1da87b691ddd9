"""Helpers of tests/security: a mission server with accounts (and optionally
TLS) in a subprocess on a free loopback port, the accounts' password files,
and raw Zenoh sessions logged in as an account. Readiness is polled with
bounded retries; every process and session is stopped/closed in teardown."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from backend.transport import client_config, close_session, free_port, open_session
from backend.transport.login import Login

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "missions" / "tutorial.yaml"
ROBOTS_SCRIPT = ROOT / "docs" / "examples" / "trivial_robots.py"
CLI = [sys.executable, "-m", "backend.cli"]

# account -> (role, robots); passwords are random per test run
ACCOUNTS = {
    "ops": ("operator", []),
    "watch": ("observer", []),
    "rover1": ("robot", ["lru1"]),
    "rover2": ("robot", ["lru2"]),
    "fleet": ("robot", ["lru1", "lru2"]),  # the simulator: one account for its robots
    "lander": ("relay", []),  # a site relay (missionctl router)
}


def env() -> dict[str, str]:
    e = {k: v for k, v in os.environ.items() if not k.startswith("MISSIONCTL_")}
    e["PYTHONUNBUFFERED"] = "1"
    return e


def stop_process(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    """SIGTERM, then SIGKILL if it does not end within `timeout`."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


class Accounts:
    """accounts.yaml + secrets/NAME.pw (mode 0600) in a temporary directory."""

    def __init__(self, tmp: Path):
        self.dir = tmp
        (tmp / "secrets").mkdir(mode=0o700)
        self.passwords: dict[str, str] = {}
        lines = ["format: missionctl/accounts@1", "accounts:"]
        for user, (role, robots) in ACCOUNTS.items():
            self.passwords[user] = os.urandom(12).hex()
            self.write_secret(f"{user}.pw", self.passwords[user])
            extra = f", robots: [{', '.join(robots)}]" if robots else ""
            lines.append(f"  {user}: {{role: {role}, password_file: secrets/{user}.pw{extra}}}")
        self.file = tmp / "accounts.yaml"
        self.file.write_text("\n".join(lines) + "\n")

    def write_secret(self, name: str, text: str) -> Path:
        path = self.dir / "secrets" / name
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(text + "\n")
        return path

    def pw_file(self, user: str) -> Path:
        return self.dir / "secrets" / f"{user}.pw"

    def login_args(self, user: str) -> list[str]:
        return ["--user", user, "--password-file", str(self.pw_file(user))]

    def login(self, user: str, **tls: str) -> Login:
        return Login(user=user, password=self.passwords[user], **tls)


def ctl(endpoint: str, *args: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*CLI, "ctl", "--connect", endpoint, "--client-id", "sec-test", *args],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


class SecureServer:
    """`missionctl server --accounts …` (plus `extra` options such as TLS)."""

    def __init__(
        self,
        tmp: Path,
        accounts: Accounts,
        *,
        scheme: str = "tcp",
        extra: list[str] = (),
        client_tls: list[str] = (),
    ):
        self.accounts = accounts
        self.client_tls = list(client_tls)
        self.log_path = tmp / "server.log"
        self.db = tmp / "mission.db"
        for _attempt in range(3):  # another process may take the free port first
            self.endpoint = f"{scheme}/127.0.0.1:{free_port()}"
            self.log = open(self.log_path, "w")  # noqa: SIM115 - closed in stop()
            self.proc = subprocess.Popen(
                [
                    *CLI,
                    "server",
                    "--mission",
                    str(TUTORIAL),
                    "--listen",
                    self.endpoint,
                    "--db",
                    str(self.db),
                    "--accounts",
                    str(accounts.file),
                    "-v",
                    *extra,
                ],
                cwd=ROOT,
                env=env(),
                stdout=self.log,
                stderr=subprocess.STDOUT,
                text=True,
            )
            if self._wait_ready():
                return
            self.stop()
        raise AssertionError(f"the mission server did not start; log:\n{self.log_path.read_text()}")

    def _wait_ready(self, attempts: int = 80) -> bool:
        for _ in range(attempts):  # bounded retries on readiness only
            if self.proc.poll() is not None:
                return False
            if self.ctl("ops", "state", "--json", "--timeout", "2").returncode == 0:
                return True
            time.sleep(0.25)
        return False

    def ctl(self, user: str | None, *args: str) -> subprocess.CompletedProcess:
        login = self.accounts.login_args(user) if user else []
        return ctl(self.endpoint, *login, *self.client_tls, *args)

    def stop(self) -> None:
        stop_process(self.proc)
        self.log.close()


@contextmanager
def raw_session(endpoint: str, login: Login):
    """A plain Zenoh client session logged in as an account (not our client library)."""
    session = open_session(client_config([endpoint], extra=login.zenoh_options()))
    try:
        yield session
    finally:
        close_session(session)
