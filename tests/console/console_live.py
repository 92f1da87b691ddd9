"""Real processes for the console's end-to-end tests: a mission server and
robot agents as subprocesses on a free loopback port (never forked after
Zenoh is open), stopped in teardown. Waiting is on output lines and app
state with deadlines, never on sleeps."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from backend.transport import free_port, loopback_endpoint

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
LIBRARY = ROOT / "missions" / "libraries" / "mars.yaml"


class Proc:
    def __init__(self, args: list[str], *, cwd: Path = ROOT, env: dict | None = None):
        self.args = args
        self.output: list[str] = []
        self.p = subprocess.Popen(
            args,
            cwd=cwd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
            env={**os.environ, **(env or {})},
        )

    def wait_line(self, needle: str, timeout: float = 30.0) -> str:
        deadline = time.monotonic() + timeout
        assert self.p.stdout is not None
        while time.monotonic() < deadline:
            ready, _, _ = select.select(
                [self.p.stdout], [], [], max(0.0, deadline - time.monotonic())
            )
            if not ready:
                break
            line = self.p.stdout.readline()
            if not line:
                break  # exited
            self.output.append(line)
            if needle in line:
                return line
        raise AssertionError(
            f"{self.args[3:5]}: no line with {needle!r} within {timeout:g} s; "
            f"output:\n{''.join(self.output)}"
        )

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int | None:
        if self.p.poll() is None:
            try:
                if self.p.stdin:
                    self.p.stdin.close()
            except OSError:
                pass
            self.p.send_signal(sig)
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait(timeout)
        if self.p.stdout:
            self.p.stdout.close()
        return self.p.returncode


class Live:
    """One mission server and (optionally) robots lru1 and lru2."""

    def __init__(self, tmp: Path, mission: Path):
        self.tmp = tmp
        self.mission = mission
        self.port = free_port()
        self.endpoint = loopback_endpoint(self.port)
        self.db = tmp / "mission.db"
        self.server: Proc | None = None
        self.robots: Proc | None = None

    def start_server(self) -> None:
        self.server = Proc(
            [
                sys.executable,
                "-m",
                "backend.cli",
                "server",
                "--mission",
                str(self.mission),
                "--listen",
                self.endpoint,
                "--db",
                str(self.db),
            ]
        )
        self.server.wait_line("listening on")

    def stop_server(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None

    def start_robots(self, *specs: str) -> None:
        specs = specs or ("lru1:lru_science", "lru2:lru_manipulator")
        self.robots = Proc(
            [sys.executable, str(HERE / "console_robots.py"), self.endpoint, str(LIBRARY), *specs]
        )
        self.robots.wait_line("ready")

    def start_sim(self, speed: float = 50.0) -> None:
        """The simulated fleet of the mission's site (instead of start_robots)."""
        self.robots = Proc(
            [
                sys.executable,
                "-m",
                "backend.cli",
                "sim",
                "--mission",
                str(self.mission),
                "--connect",
                self.endpoint,
                "--speed",
                f"{speed:g}",
                "--seed",
                "1",
            ],
            env={"PYTHONUNBUFFERED": "1"},
        )
        self.robots.wait_line("missionctl sim: world")

    def kill_robots(self) -> None:
        if self.robots is not None:
            self.robots.stop(signal.SIGKILL)
            self.robots = None

    def close(self) -> None:
        if self.robots is not None:
            self.robots.stop()
        self.stop_server()


@contextmanager
def running(tmp: Path, mission: Path) -> Iterator[Live]:
    """A started mission server (robots added by the test), closed at the end."""
    env = Live(tmp, mission)
    env.start_server()
    try:
        yield env
    finally:
        env.close()
