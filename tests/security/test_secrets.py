"""No password in process arguments or environments, in logs (server, robots,
ctl, simulator, all verbose), or in the journal; the simulated fleet and
robots work under their robot accounts."""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import time
from pathlib import Path

from backend.protocol.keys import Keys
from backend.protocol.mapfeed import KEY_MAP_DELTA, KEY_STATUS_LIVE

from .helpers import CLI, ROBOTS_SCRIPT, ROOT, TUTORIAL, env, raw_session, stop_process


class Bg:
    """A background process whose output goes to a log file."""

    def __init__(self, args: list[str], log: Path):
        self.log_path = log
        self.log = open(log, "w")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(
            args, cwd=ROOT, env=env(), stdout=self.log, stderr=subprocess.STDOUT, text=True
        )

    def wait_for(self, needle: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while needle not in self.log_path.read_text():
            assert self.proc.poll() is None, f"exited: {self.log_path.read_text()}"
            assert time.monotonic() < deadline, f"no {needle!r} in {self.log_path.read_text()}"
            time.sleep(0.05)

    def proc_files(self) -> bytes:
        pid = self.proc.pid
        return Path(f"/proc/{pid}/cmdline").read_bytes() + Path(f"/proc/{pid}/environ").read_bytes()

    def stop(self) -> None:
        stop_process(self.proc)
        self.log.close()


def _until(server, pred, what: str, timeout: float = 30.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        st = json.loads(server.ctl("watch", "state", "--json").stdout)
        if pred(st):
            return st
        assert time.monotonic() < deadline, f"{what} not reached: {st['tasks']}"
        time.sleep(0.1)


def test_no_password_in_arguments_logs_or_journal(tmp_path, server, accounts):
    ep = server.endpoint
    robots = Bg(
        [
            sys.executable,
            str(ROBOTS_SCRIPT),
            "--connect",
            ep,
            "-v",
            *accounts.login_args("rover1"),
            "lru1:lru_science",
        ],
        tmp_path / "robots.log",
    )
    watch = Bg(
        [*CLI, "ctl", "--connect", ep, *accounts.login_args("watch"), "watch"],
        tmp_path / "watch.log",
    )
    outputs: list[str] = []
    try:
        robots.wait_for("ready lru1")
        for args in (["add", "lru1", "recharge"], ["sync", "lru1"], ["run", "lru1"]):
            r = server.ctl("ops", *args)
            assert r.returncode == 0, r.stderr
            outputs += [r.stdout, r.stderr]
        _until(
            server,
            lambda st: all(s["status"] == "success" for s in st["tasks"]["lru1"]),
            "lru1 done",
        )
        # the observer sees presence and telemetry (its rules cover what consoles read)
        seen_by_watch = json.loads(server.ctl("watch", "robots", "--json").stdout)["robots"]["lru1"]
        assert seen_by_watch["online"] and seen_by_watch["telemetry"] is not None
        refused = server.ctl("watch", "run", "lru1")
        outputs += [refused.stdout, refused.stderr]
        watch.wait_for("recharge")
        seen = server.proc.pid, robots.proc_files(), watch.proc_files()
        args = (
            Path(f"/proc/{seen[0]}/cmdline").read_bytes()
            + Path(f"/proc/{seen[0]}/environ").read_bytes()
            + seen[1]
            + seen[2]
        )
    finally:
        robots.stop()
        watch.stop()
        server.stop()
    logs = [
        server.log_path.read_bytes(),
        robots.log_path.read_bytes(),
        watch.log_path.read_bytes(),
        "".join(outputs).encode(),
    ]
    assert b"recharge" in logs[2] and b"read-only" in logs[3]  # the captures are real
    journal = b"".join(p.read_bytes() for p in tmp_path.glob("mission.db*"))
    assert b"recharge" in journal
    for user, password in accounts.passwords.items():
        secret = password.encode()
        assert secret not in args, f"{user}'s password in a command line or environment"
        for log in logs:
            assert secret not in log, f"{user}'s password in a log"
        assert secret not in journal, f"{user}'s password in the journal"


def test_simulated_fleet_runs_under_a_robot_account(tmp_path, server, accounts):
    sim = Bg(
        [
            *CLI,
            "sim",
            "--mission",
            str(TUTORIAL),
            "--connect",
            server.endpoint,
            "--speed",
            "20",
            "-v",
            *accounts.login_args("fleet"),
        ],
        tmp_path / "sim.log",
    )
    try:
        sim.wait_for("missionctl sim: world")
        r = server.ctl("ops", "robots", "--json")
        assert r.returncode == 0, r.stderr
        deadline = time.monotonic() + 30
        while not all(info["online"] for info in json.loads(r.stdout)["robots"].values()):
            assert time.monotonic() < deadline, r.stdout
            time.sleep(0.1)
            r = server.ctl("ops", "robots", "--json")
        # the simulator's live feeds and the robots' telemetry reach an observer
        with raw_session(server.endpoint, accounts.login("watch")) as watch:
            got: queue.Queue = queue.Queue()
            subs = [
                watch.declare_subscriber(k, lambda s: got.put(str(s.key_expr)))
                for k in (KEY_STATUS_LIVE, KEY_MAP_DELTA, Keys.ALL_TELEMETRY)
            ]
            seen: set[str] = set()
            deadline = time.monotonic() + 30
            while not {KEY_STATUS_LIVE, Keys.telemetry("lru1"), Keys.telemetry("lru2")} <= seen:
                seen.add(got.get(timeout=max(0.1, deadline - time.monotonic())))
            for sub in subs:
                sub.undeclare()
        status = subprocess.run(
            [*CLI, "sim-status", "--connect", server.endpoint, *accounts.login_args("watch")],
            cwd=ROOT,
            env=env(),
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert status.returncode == 0, status.stderr
        assert "robots:" in status.stdout and "lru1" in status.stdout
    finally:
        sim.stop()
    assert accounts.passwords["fleet"].encode() not in sim.log_path.read_bytes()
