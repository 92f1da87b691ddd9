"""Running `missionctl ctl` and a mission server as subprocesses (no sleeps as
synchronization: readiness is polled with bounded retries, behaviour waited
for through `state --json` with a deadline)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "missions" / "tutorial.yaml"
LIBRARY = ROOT / "missions" / "libraries" / "mars.yaml"
ROBOTS_SCRIPT = ROOT / "docs" / "examples" / "trivial_robots.py"
CTL_TIMEOUT = 30.0  # per ctl process; they normally take well under a second


CTL_CMD = [sys.executable, "-m", "backend.cli", "ctl"]


def env() -> dict[str, str]:
    e = {k: v for k, v in os.environ.items() if not k.startswith("MISSIONCTL_")}
    e["PYTHONUNBUFFERED"] = "1"
    return e


def ctl(
    endpoint: str | None,
    *args: str,
    client_id: str | None = "ctl-test",
    timeout: float = CTL_TIMEOUT,
) -> subprocess.CompletedProcess:
    cmd = list(CTL_CMD)
    if endpoint is not None:
        cmd += ["--connect", endpoint]
    if client_id is not None:
        cmd += ["--client-id", client_id]
    return subprocess.run(
        [*cmd, *args], cwd=ROOT, env=env(), capture_output=True, text=True, timeout=timeout
    )


def ok(endpoint: str, *args: str, **kw: Any) -> subprocess.CompletedProcess:
    r = ctl(endpoint, *args, **kw)
    assert r.returncode == 0, (
        f"ctl {' '.join(args)} -> {r.returncode}\nstdout: {r.stdout}\nstderr: {r.stderr}"
    )
    assert "Traceback" not in r.stderr
    return r


def ok_json(endpoint: str, *args: str, **kw: Any) -> dict:
    r = ok(endpoint, *args, "--json", **kw)
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 1, f"expected one JSON line, got: {r.stdout!r}"
    return json.loads(lines[0])


def state(endpoint: str) -> dict:
    return ok_json(endpoint, "state")


def until(
    endpoint: str, pred: Callable[[dict], bool], timeout: float = 20.0, what: str = "condition"
) -> dict:
    """Poll `state --json` until `pred(state)` holds (bounded by `timeout`)."""
    deadline = time.monotonic() + timeout
    last: dict = {}
    while time.monotonic() < deadline:
        last = state(endpoint)
        if pred(last):
            return last
        time.sleep(0.1)
    raise AssertionError(
        f"{what} not reached within {timeout}s; "
        f"last state tasks: {json.dumps(last.get('tasks'), indent=1)}"
    )


def skill(st: dict, sid: str) -> dict:
    for task in st["tasks"].values():
        for s in task:
            if s["id"] == sid:
                return s
    raise AssertionError(f"no skill {sid} in {[s['id'] for t in st['tasks'].values() for s in t]}")


def ids(st: dict, robot: str) -> list[str]:
    return [s["id"] for s in st["tasks"][robot]]


def stop_process(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    """SIGTERM, then SIGKILL if it does not end within `timeout`."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


class Server:
    """`missionctl server` in a subprocess on a free loopback port."""

    def __init__(
        self,
        tmp: Path,
        mission: Path = TUTORIAL,
        command: Callable[[str, Path], list[str]] | None = None,
    ):
        """`command(endpoint, db)`, if given, is the server's command line
        (e.g. one taken from a document), to listen on `endpoint` with journal `db`."""
        from backend.transport import free_port, loopback_endpoint

        self.log_path = tmp / "server.log"
        for _attempt in range(3):  # another process may take the free port first
            self.endpoint = loopback_endpoint(free_port())
            db = tmp / f"mission-{_attempt}.db"
            argv = (
                command(self.endpoint, db)
                if command
                else [
                    sys.executable,
                    "-m",
                    "backend.cli",
                    "server",
                    "--mission",
                    str(mission),
                    "--listen",
                    self.endpoint,
                    "--db",
                    str(db),
                ]
            )
            self.log = open(self.log_path, "w")  # noqa: SIM115 - closed in stop()
            self.proc = subprocess.Popen(
                argv,
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
        """Until `ctl state` answers (bounded retries on readiness only)."""
        for _ in range(attempts):
            if self.proc.poll() is not None:
                return False
            r = ctl(self.endpoint, "state", "--json", "--timeout", "2")
            if r.returncode == 0:
                return True
            time.sleep(0.25)
        return False

    def output(self) -> str:
        return self.log_path.read_text() if self.log_path.exists() else ""

    def stop(self) -> None:
        stop_process(self.proc)
        self.log.close()


class Robots:
    """docs/examples/trivial_robots.py (robot agents with scripted handlers)."""

    def __init__(self, endpoint: str, *robots: str, command: list[str] | None = None):
        """Robots NAME:TYPE; `command`, if given, is the command line that runs
        them (e.g. one taken from a document), connecting to `endpoint`."""
        self.proc = subprocess.Popen(
            command or [sys.executable, str(ROBOTS_SCRIPT), "--connect", endpoint, *robots],
            cwd=ROOT,
            env=env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        want = {r.split(":")[0] for r in robots}
        deadline = time.monotonic() + 30
        assert self.proc.stdout is not None
        while want and time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            self.lines.append(line)
            if line.startswith("ready "):
                want.discard(line.split()[1])
        if want:
            self.stop()
            raise AssertionError(f"robots {want} not ready; output:\n{''.join(self.lines)}")
        # keep reading: a full pipe would block the robots' logging, and with it their event loop
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)

    def stop(self) -> None:
        stop_process(self.proc)
