"""Fixtures for the simulated-fleet tests.

Integration tests run the real mission server and `missionctl sim` as
subprocesses on a free loopback port and drive them with
backend.client.client.MissionClient. Waiting is always on state (the client's
mirror, the sim's live status publication), never on sleeps.

`async def` tests run with the shared runner (tests/conftest.py).
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from backend import transport
from backend.client.client import MissionClient
from backend.protocol import mapfeed as mf
from backend.transport import free_port, loopback_endpoint

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "missions" / "mars_sample_return.yaml"
WORLD = ROOT / "missions" / "worlds" / "mars.yaml"
LIBRARY_FILE = ROOT / "missions" / "libraries" / "mars.yaml"
STARTUP = 20.0


class Proc:
    """A subprocess whose output is collected by a reader thread."""

    def __init__(self, args: list[str], name: str):
        self.name = name
        self.args = args
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.p = subprocess.Popen(
            args,
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
        )
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()

    def wait_line(self, text: str, timeout: float = STARTUP) -> str:
        with self._cond:
            ok = self._cond.wait_for(
                lambda: any(text in ln for ln in self.lines) or self.p.poll() is not None, timeout
            )
            found = [ln for ln in self.lines if text in ln]
        if not ok or not found:
            raise AssertionError(f"{self.name} did not print {text!r}; output:\n" + self.output())
        return found[0]

    def output(self) -> str:
        with self._cond:
            return "\n".join(self.lines)

    def signal(self, sig: int) -> None:
        if self.p.poll() is None:
            self.p.send_signal(sig)

    def stop(self, timeout: float = 10.0) -> int | None:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait(5)
        self._reader.join(2)
        return self.p.returncode


def world_file(
    tmp_path: Path, robots: dict[str, dict[str, Any]] | None = None, **changes: Any
) -> Path:
    """The default world with some robots' starts (battery, pose) changed."""
    data = yaml.safe_load(WORLD.read_text())
    for name, values in (robots or {}).items():
        data["robots"].setdefault(name, {}).update(values)
    data.update(changes)
    out = tmp_path / "world.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


class Stack:
    """Mission server + simulated fleet, as subprocesses."""

    def __init__(self, tmp_path: Path):
        self.tmp_path = tmp_path
        self.endpoint = ""
        self.server: Proc | None = None
        self.sim: Proc | None = None

    def start_server(self) -> str:
        for _attempt in range(3):
            port = free_port()
            self.endpoint = loopback_endpoint(port)
            self.server = Proc(
                [
                    sys.executable,
                    "-m",
                    "backend.cli",
                    "server",
                    "--mission",
                    str(MISSION),
                    "--listen",
                    self.endpoint,
                    "--db",
                    str(self.tmp_path / f"mission-{port}.db"),
                ],
                "server",
            )
            try:
                self.server.wait_line("listening on")
                return self.endpoint
            except AssertionError:
                self.server.stop()
                if "cannot listen" not in self.server.output():
                    raise
        raise AssertionError("no free port for the server")  # pragma: no cover

    def start_sim(
        self,
        *,
        speed: float = 50.0,
        seed: int = 1,
        world: Path | None = None,
        extra: list[str] | None = None,
    ) -> None:
        args = [
            sys.executable,
            "-m",
            "backend.cli",
            "sim",
            "--mission",
            str(MISSION),
            "--connect",
            self.endpoint,
            "--speed",
            str(speed),
            "--seed",
            str(seed),
        ]
        if world is not None:
            args += ["--world", str(world)]
        self.sim = Proc(args + (extra or []), "sim")
        self.sim.wait_line("missionctl sim: world")

    def start(self, **sim_args: Any) -> str:
        """Server, then sim (for tests without a client)."""
        self.start_server()
        self.start_sim(**sim_args)
        return self.endpoint

    def close(self) -> None:
        if self.sim is not None:
            self.sim.stop()
        if self.server is not None:
            self.server.stop()


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[Stack]:
    s = Stack(tmp_path)
    yield s
    s.close()


class SimWatch:
    """The sim's live status on the client's session; `until(pred)` waits on publications."""

    def __init__(self, client: MissionClient):
        self.client = client
        self.status: mf.SimStatus | None = None
        self.changed = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        assert client.session is not None
        self._sub = transport.subscribe(client.session, mf.KEY_STATUS_LIVE, self._on)

    def _on(self, msg: transport.Message) -> None:
        st = mf.SimStatus.model_validate_json(msg.payload)
        self._loop.call_soon_threadsafe(self._set, st)

    def _set(self, st: mf.SimStatus) -> None:
        if self.status is None or st.sim_time >= self.status.sim_time:
            self.status = st
        self.changed.set()

    async def query(self) -> mf.SimStatus:
        """The ground view: what the robots reported."""
        assert self.client.session is not None
        raw = await transport.query(self.client.session, mf.KEY_STATUS, b"", timeout=10.0)
        return mf.SimStatus.model_validate_json(raw)

    async def truth(self) -> mf.SimTruth:
        """The world as it is (evaluation only: an operator's strategy never reads it)."""
        assert self.client.session is not None
        raw = await transport.query(
            self.client.session, mf.KEY_STATUS, mf.TRUTH_QUERY, timeout=10.0
        )
        truth = mf.SimStatus.model_validate_json(raw).truth
        assert truth is not None
        return truth

    async def until(
        self, pred: Callable[[mf.SimStatus], bool], timeout: float = 30.0, what: str = ""
    ) -> mf.SimStatus:
        try:
            async with asyncio.timeout(timeout):
                while self.status is None or not pred(self.status):
                    self.changed.clear()
                    await self.changed.wait()
        except TimeoutError:
            raise AssertionError(
                f"timed out waiting for {what or pred}; last status: {self.status}"
            ) from None
        return self.status

    def close(self) -> None:
        try:
            self._sub.undeclare()
        except Exception:
            pass


async def connect(stack: Stack, **sim_args: Any) -> tuple[MissionClient, SimWatch]:
    """Server, client, then the sim: the client holds the state before the robots
    register, so it sees them come online through fleet events (see the report
    on MissionClient.resync dropping fleet events that race the snapshot)."""
    endpoint = stack.start_server()
    client = MissionClient(endpoint)
    await client.connect()
    watch = SimWatch(client)
    try:
        await asyncio.to_thread(stack.start_sim, **sim_args)
        await client.wait_for(lambda m: all(client.robots[r].online for r in m.robots), STARTUP)
    except BaseException:
        watch.close()
        await client.close()
        raise
    return client, watch


def skill(mission: Any, skill_id: str) -> Any:
    found = mission.find(skill_id)
    assert found is not None, skill_id
    return found[2]


def status_of(mission: Any, skill_id: str) -> str:
    return skill(mission, skill_id).status.value
