"""A deployment on loopback for the relay tests: the ground's `missionctl
server`, the long link (a DelayProxy), the site's `missionctl router` behind
it and the tutorial's trivial robots connected to the relay; free ports;
every process stopped and the proxy closed in teardown (`close`)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from delay_proxy import DelayProxy

from backend.client.client import MissionClient
from backend.transport import client_config, free_port, loopback_endpoint
from backend.transport.login import Login
from backend.transport.session import close_session, open_session
from tests.server.harness import ROOT, TUTORIAL, Proc

CLI = [sys.executable, "-m", "backend.cli"]
ROBOTS = ("lru1:lru_science", "lru2:lru_manipulator")


class Site:
    def __init__(self, tmp: Path, delay: float = 0.0):
        self.tmp = tmp
        self.delay = delay
        self.hint = ["--link-delay-hint", f"{delay:g}"]
        self.ground = loopback_endpoint(free_port())
        self.site = loopback_endpoint(free_port())
        self.proxy: DelayProxy | None = None
        self.server: Proc | None = None
        self.relay: Proc | None = None
        self.robots: Proc | None = None
        self.procs: list[Proc] = []
        self.clients: list[MissionClient] = []
        self.sessions: list[Any] = []

    def _start(self, args: list[str]) -> Proc:
        proc = Proc(args)
        self.procs.append(proc)  # before waiting: stopped in teardown even if never ready
        return proc

    def start_server(self, *extra: str) -> Proc:
        self.server = self._start(
            [*CLI, "server", "--mission", str(TUTORIAL), "--db", str(self.tmp / "mission.db"),
             "--listen", self.ground, *self.hint, *extra]
        )  # fmt: skip
        self.server.wait_line("listening on")
        return self.server

    def start_link(self) -> DelayProxy:
        port = int(self.ground.rsplit(":", 1)[1])
        self.proxy = DelayProxy(("127.0.0.1", port), self.delay).start()
        return self.proxy

    def start_relay(self, *extra: str, connect: str | None = None) -> Proc:
        assert self.proxy is not None or connect is not None
        ground = connect or loopback_endpoint(self.proxy.port)
        self.relay = self._start(
            [*CLI, "router", "--listen", self.site, "--connect", ground, *self.hint, *extra]
        )
        self.relay.wait_line("relaying")
        return self.relay

    def start_robots(self, *extra: str, wait: bool = True) -> Proc:
        self.robots = self._start(
            [sys.executable, str(ROOT / "docs" / "examples" / "trivial_robots.py"),
             "--connect", self.site, *self.hint, "-v", *extra, *ROBOTS]
        )  # fmt: skip
        if wait:
            for r in ROBOTS:
                self.robots.wait_line(f"ready {r.split(':')[0]}", timeout=60 + 20 * self.delay)
        return self.robots

    def start(self) -> None:
        """Server, link, relay, robots (registered)."""
        self.start_server()
        self.start_link()
        self.start_relay()
        self.start_robots()

    async def client(self, endpoint: str | None = None, **kw: object) -> MissionClient:
        """A client at the ground (or at `endpoint`), closed in `aclose`."""
        login = kw.pop("login", None) or Login(link_delay_hint=self.delay)
        c = MissionClient(endpoint or self.ground, login=login, **kw)  # type: ignore[arg-type]
        self.clients.append(c)
        await c.connect()
        return c

    def site_session(self) -> Any:
        """A plain Zenoh session at the site (a tool beside the robots), closed in `close`."""
        session = open_session(client_config([self.site]))
        self.sessions.append(session)
        return session

    async def aclose(self) -> None:
        for c in self.clients:
            await c.close()
        self.close()

    def close(self) -> None:
        for session in self.sessions:
            close_session(session)
        for proc in reversed(self.procs):
            proc.stop()
        if self.proxy is not None:
            self.proxy.close()


def wait_count(proc: Proc, needle: str, count: int, timeout: float) -> None:
    """Wait until `proc` printed `count` lines containing `needle` (e.g. the
    relay's second "ground link up")."""

    def seen() -> int:
        return sum(needle in line for line in proc.lines)

    with proc._cond:
        if not proc._cond.wait_for(lambda: seen() >= count or proc.p.poll() is not None, timeout):
            raise AssertionError(f"{needle!r} not {count} times in {timeout}s:\n{proc.output()}")
        if seen() < count:
            raise AssertionError(f"process ended:\n{proc.output()}")
