"""Fixtures: a router in a subprocess per test, client sessions closed in teardown."""

from __future__ import annotations

import queue
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from backend.transport import (
    client_config,
    close_session,
    free_port,
    loopback_endpoint,
    open_session,
)

PROCS = Path(__file__).with_name("zenoh_procs.py")
STARTUP_TIMEOUT = 15.0


class Proc:
    """A helper process from zenoh_procs.py whose stdout lines we can await."""

    def __init__(self, *args: str):
        self.popen = subprocess.Popen(
            [sys.executable, str(PROCS), *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self._lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self._lines.put(line.strip())
        self._lines.put(None)

    def next_line(self, timeout: float = STARTUP_TIMEOUT) -> str | None:
        """The next stdout line, or None at EOF."""
        return self._lines.get(timeout=timeout)

    def stop(self, timeout: float = 5.0) -> int:
        """Close stdin (the process then closes its session and exits); kill if it hangs."""
        if self.popen.poll() is None:
            try:
                assert self.popen.stdin is not None
                self.popen.stdin.close()
            except OSError:
                pass
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        return self.popen.returncode

    def kill(self) -> None:
        self.popen.kill()
        self.popen.wait()


class Router:
    def __init__(self) -> None:
        for _ in range(5):  # another process may take our free port first
            self.endpoint = loopback_endpoint(free_port())
            self.proc = Proc("router", self.endpoint)
            line = self.proc.next_line()
            if line == "ready":
                return
            self.proc.stop()
            if line != "listen-failed":
                raise RuntimeError(f"router process failed to start (said {line!r})")
        raise RuntimeError("no free port for the router after 5 attempts")


@pytest.fixture
def make_router() -> Iterator[Callable[[], Router]]:
    """make_router() -> Router in a subprocess on a free loopback port; stopped after the test."""
    routers: list[Router] = []

    def _make() -> Router:
        routers.append(Router())
        return routers[-1]

    yield _make
    for r in routers:
        r.proc.stop()


@pytest.fixture
def router(make_router: Callable[[], Router]) -> Router:
    return make_router()


@pytest.fixture
def open_client() -> Iterator[Callable[..., zenoh.Session]]:
    """open_client(endpoint, **client_config kwargs) -> Session, closed after the test."""
    sessions: list[zenoh.Session] = []

    def _open(endpoint: str, **kwargs: object) -> zenoh.Session:
        session = open_session(client_config([endpoint], **kwargs))  # type: ignore[arg-type]
        sessions.append(session)
        return session

    yield _open
    for session in reversed(sessions):
        close_session(session)


@pytest.fixture
def spawn() -> Iterator[Callable[..., Proc]]:
    """spawn(*args) -> Proc running zenoh_procs.py; stopped after the test."""
    procs: list[Proc] = []

    def _spawn(*args: str) -> Proc:
        proc = Proc(*args)
        procs.append(proc)
        return proc

    yield _spawn
    for proc in procs:
        proc.stop()
