"""Every entry point says its expected errors in a line, with its exit code:
no traceback for a second sim, a dead server, a bad file. (A refused login:
tests/security/test_login.py; ctl and a dead server: tests/cli.)"""

from __future__ import annotations

import subprocess
import sys

from backend.transport import free_port, loopback_endpoint

from .harness import ROOT, Proc

EXIT_REFUSED, EXIT_BAD_INPUT, EXIT_UNREACHABLE = 1, 2, 3


def missionctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=90,
    )


def one_line(r: subprocess.CompletedProcess[str]) -> str:
    assert "Traceback" not in r.stderr, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, r.stderr
    return lines[0]


def sim(endpoint: str, *more: str) -> list[str]:
    return ["sim", "--mission", "missions/tutorial.yaml", "--connect", endpoint, *more]


def test_a_second_sim_for_the_same_robots_is_one_line(cluster):
    first = Proc([sys.executable, "-m", "backend.cli", *sim(cluster.endpoint)])
    cluster.procs.append(first)
    first.wait_line("connected to", timeout=60)
    r = missionctl(*sim(cluster.endpoint))
    assert r.returncode == EXIT_REFUSED, r.stdout + r.stderr
    assert one_line(r).startswith("missionctl sim: robot lru1 is already connected")


def test_a_sim_without_a_server_is_one_line():
    r = missionctl(*sim(loopback_endpoint(free_port()), "--connect-timeout", "0"))
    assert r.returncode == EXIT_UNREACHABLE
    assert one_line(r).startswith("missionctl sim: cannot reach the mission server")


def test_a_sim_on_a_bad_file_is_located():
    bomb = "tests/files/corpus/limit_alias_bomb.yaml"
    r = missionctl("sim", "--mission", bomb, "--connect", loopback_endpoint(free_port()))
    assert r.returncode == EXIT_BAD_INPUT
    assert one_line(r).startswith(f"{bomb}:10:14: g[2]: the file expands to more than")
