"""`missionctl demo`: server + simulated fleet + console on loopback.

The server and the sim run as subprocesses (started before this process
opens any Zenoh session: never fork after Zenoh is open). Quitting the
console — or any error — stops them: terminate, then kill after a timeout.
For a quick start, `launch()` only spawns the server; the caller loads the
console meanwhile, then `wait_ready()` waits for the server and starts the sim.
Both children run at a lower CPU priority (`CHILD_NICENESS`): on a busy machine
the console the operator watches paints and answers first, and the children
take what it leaves (on an idle one they run as fast as ever).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from importlib.metadata import entry_points
from pathlib import Path
from typing import IO

from backend.transport import free_port, loopback_endpoint

DEFAULT_MISSION = Path(__file__).resolve().parents[1] / "missions" / "mars_sample_return.yaml"
READY_MARK = "listening on"
CHILD_NICENESS = 10  # the server's and the sim's, above the console's (os.setpriority)


class DemoError(Exception):
    """The demo could not start; `str()` says why (with the server's words)."""


def _tail(path: Path, lines: int = 8) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    return "\n".join(text.strip().splitlines()[-lines:])


def _port_taken(log: str) -> bool:
    """Whether a server's last words say its port was in use."""
    low = log.lower()
    return "address" in low and "use" in low


def _lower_priority(pid: int) -> None:
    """The child's niceness goes up by CHILD_NICENESS (threads it starts later inherit it).
    Where that is not possible, it runs as it is: only start-up is slower."""
    try:
        os.setpriority(os.PRIO_PROCESS, pid, os.getpriority(os.PRIO_PROCESS, 0) + CHILD_NICENESS)
    except (AttributeError, OSError):  # no setpriority (Windows), or the child is gone
        pass


def sim_available() -> bool:
    """Whether `missionctl sim` is installed (another package plugs it in),
    from the package metadata: no process to start, nothing imported (a sim
    that then fails to start is reported by the demo app)."""
    plugged = any(ep.name == "sim" for ep in entry_points(group="missionctl.commands"))
    return plugged and importlib.util.find_spec("sim") is not None


class DemoProcesses:
    """The server (and the sim when available) as child processes."""

    def __init__(
        self,
        mission: str | Path = DEFAULT_MISSION,
        *,
        speed: float = 1.0,
        sim_options: Sequence[str] = (),
        python: str = sys.executable,
        workdir: str | Path | None = None,
        with_sim: bool | None = None,
    ):
        self.mission = Path(mission).resolve()
        self.speed = speed
        # the sim's own options as given (--link-delay 10m, --break lru1@12m, …): it checks them
        self.sim_options = list(sim_options)
        self.python = python
        self._own_dir = workdir is None
        self.workdir = (
            Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="missionctl-demo-"))
        )
        self.with_sim = with_sim
        self.endpoint = ""
        self.server: subprocess.Popen | None = None
        self.sim: subprocess.Popen | None = None
        self.notices: list[str] = []
        self._attempt = 0
        self._logs: list[IO] = []
        # the console waits for the server in a thread (console/demo_app.py): once stopped,
        # nothing is spawned any more (a sim started after stop() would outlive the demo)
        self._lock = threading.Lock()
        self._stopped = False

    @property
    def server_log(self) -> Path:
        return self.workdir / "server.log"

    @property
    def sim_log(self) -> Path:
        return self.workdir / "sim.log"

    def _spawn(self, role: str, args: list[str], log: Path) -> None:
        """Start the server or the sim (`role`: the attribute that holds it)."""
        with self._lock:
            if self._stopped:
                raise DemoError("the demo is stopping: nothing more is started")
            f = open(log, "w", encoding="utf-8")  # noqa: SIM115 (closed in stop())
            self._logs.append(f)
            p = subprocess.Popen(
                [self.python, "-m", "backend.cli", *args],
                stdout=f,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
            )
            _lower_priority(p.pid)
            setattr(self, role, p)

    def start(self, timeout: float = 30.0) -> None:
        self.launch()
        self.wait_ready(timeout)

    def _spawn_server(self) -> None:
        self.endpoint = loopback_endpoint(free_port())
        db = self.workdir / f"demo-{self._attempt}.db"
        self._spawn(
            "server",
            ["server", "--mission", str(self.mission), "--listen", self.endpoint, "--db", str(db)],
            self.server_log,
        )

    def launch(self) -> None:
        """Spawn the server (and the sim check); returns at once."""
        if not self.mission.is_file():
            raise DemoError(f"{self.mission}: no such mission file")
        self._spawn_server()

    def wait_ready(self, timeout: float = 30.0) -> None:
        """Until the server listens (retrying on a port taken meanwhile); then start the sim."""
        while not self._wait_ready(timeout):
            self._server_failed()  # raises, or spawned it again
        want_sim = sim_available() if self.with_sim is None else self.with_sim
        if want_sim:
            self._spawn_sim()
        else:
            self.notices.append(
                "the simulated fleet is unavailable (`missionctl sim` is not installed): "
                "robots stay offline; the plan can still be edited"
            )

    def _server_failed(self) -> None:
        """The server stopped or did not listen in time: again on another port
        if its port was taken meanwhile (twice at most), else DemoError with its words."""
        code = self.server.poll() if self.server is not None else None
        tail = _tail(self.server_log)
        self._stop_one(self.server)
        if code is not None and _port_taken(tail) and self._attempt < 2:
            self._attempt += 1
            self._spawn_server()
            return
        how = f" (exit code {code})" if code is not None else " in time"
        raise DemoError(f"the mission server did not start{how}:\n{tail}")

    def _spawn_sim(self) -> None:
        self._spawn(
            "sim",
            [
                "sim",
                "--mission",
                str(self.mission),
                "--connect",
                self.endpoint,
                "--speed",
                f"{self.speed:g}",
                *self.sim_options,
            ],
            self.sim_log,
        )

    def _wait_ready(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.server is None or self.server.poll() is not None:
                return False
            try:
                if READY_MARK in self.server_log.read_text(encoding="utf-8", errors="replace"):
                    return True
            except OSError:
                pass
            time.sleep(0.05)  # polling a child's log: there is nothing to wait on
        return False

    def sim_problem(self) -> str | None:
        """If the sim ended: why, in a sentence (its log's last line when it
        failed; the log itself is sim.log in the demo's folder)."""
        if self.sim is None or self.sim.poll() is None:
            return None
        code = self.sim.returncode
        if code < 0:
            return f"the simulated fleet was stopped (signal {-code}): the robots are offline"
        last = _tail(self.sim_log, 1)
        return f"the simulated fleet stopped (exit code {code})" + (f": {last}" if last else "")

    @staticmethod
    def _stop_one(p: subprocess.Popen | None, timeout: float = 5.0) -> None:
        if p is None or p.poll() is not None:
            return
        p.terminate()
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout)

    def stop(self) -> None:
        with self._lock:
            self._stopped = True
        self._stop_one(self.sim)
        self._stop_one(self.server)
        for f in self._logs:
            f.close()
        self._logs.clear()
        if self._own_dir:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> DemoProcesses:
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
