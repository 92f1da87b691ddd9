"""`missionctl ctl` when nothing, or no mission server, answers: exit 3 at
once with one clear line, never a traceback."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time

from backend.transport import free_port, loopback_endpoint

from .helpers import ROOT, ctl, env


def test_unreachable_state_exits_3_quickly():
    endpoint = loopback_endpoint(free_port())  # nothing listens there
    t0 = time.monotonic()
    r = ctl(endpoint, "state")
    elapsed = time.monotonic() - t0
    assert r.returncode == 3, r
    assert elapsed < 8.0  # a refused connection fails at once (the rest is interpreter start-up)
    assert r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"missionctl: cannot reach the mission server at {endpoint}")
    assert "Traceback" not in r.stderr


def test_unreachable_json_and_operations():
    endpoint = loopback_endpoint(free_port())
    r = ctl(endpoint, "--json", "add", "lru1", "recharge", "--param", "target_level=0.9")
    assert r.returncode == 3
    obj = json.loads(r.stdout)
    assert obj == {"ok": False, "code": "unreachable", "message": obj["message"]}
    assert endpoint in obj["message"]
    assert "cannot reach the mission server" in r.stderr and "Traceback" not in r.stderr
    for args in (
        ["sync", "lru1"],
        ["run", "--all"],
        ["robots"],
        ["watch", "--count", "1"],
        ["save", "/tmp/x.yaml"],
    ):
        r = ctl(endpoint, *args)
        assert r.returncode == 3, (args, r)
        assert r.stderr.startswith("missionctl: cannot reach the mission server"), (args, r.stderr)


def test_default_endpoint_from_environment():
    endpoint = loopback_endpoint(free_port())
    r = subprocess.run(
        [*_ctl_cmd(), "state"],
        cwd=ROOT,
        env={**env(), "MISSIONCTL_CONNECT": endpoint},
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == 3
    assert endpoint in r.stderr


_ROUTER = """
import sys
from backend.transport import router_config, session_scope
with session_scope(router_config([sys.argv[1]])):
    print("ready", flush=True)
    sys.stdin.read()
"""


def test_router_without_mission_server_exits_3():
    """A Zenoh router answers, but no missionctl server behind it."""
    for _ in range(3):
        endpoint = loopback_endpoint(free_port())
        router = subprocess.Popen(
            [sys.executable, "-c", _ROUTER, endpoint],
            cwd=ROOT,
            env=env(),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            if router.stdout.readline().strip() != "ready":
                continue  # the port was taken meanwhile
            r = ctl(endpoint, "state", "--timeout", "3")
            assert r.returncode == 3, r
            assert "no mission server answers" in r.stderr or "did not answer" in r.stderr, r.stderr
            assert "Traceback" not in r.stderr
            return
        finally:
            router.stdin.close()
            try:
                router.wait(10)
            except subprocess.TimeoutExpired:
                router.kill()
                router.wait()
    raise AssertionError("could not start a router on a free port")


def _ctl_cmd():
    from .helpers import CTL_CMD

    return CTL_CMD


def test_a_server_that_accepts_but_never_answers_is_not_a_login_problem():
    """A stopped (SIGSTOP) or hung server: the kernel still accepts the TCP
    connection, then nothing answers. Not 'the server requires an account',
    and given up after --timeout rather than Zenoh's 10 s."""
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)  # never accepted, never answered
        endpoint = loopback_endpoint(silent.getsockname()[1])
        r = ctl(endpoint, "--json", "state", "--timeout", "2", timeout=8)
    assert r.returncode == 3, r
    assert "did not answer within 2 s" in r.stderr and "stopped or overloaded" in r.stderr, r.stderr
    assert "login" not in r.stderr and "account" not in r.stderr
    assert json.loads(r.stdout)["code"] == "unreachable"


def test_ctl_loads_only_what_a_client_needs():
    # every scripted call pays for what it imports: no numpy (the sim's map
    # feed), no server, journal or mission files, no console/sim plug-ins
    code = (
        "import sys\n"
        "from backend.cli.main import main\n"
        f"rc = main(['ctl', '--connect', {loopback_endpoint(free_port())!r}, 'state'])\n"
        "print(rc, *sorted(m for m in sys.modules if m.split('.')[0] in "
        "{'numpy', 'backend', 'sim', 'console', 'textual', 'yaml'}))\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    rc, *loaded = r.stdout.split()
    assert rc == "3", r.stderr  # nothing listens there: the client was used
    assert "backend.client.client" in loaded
    heavy = [
        m
        for m in loaded
        if m.split(".")[0] in {"numpy", "sim", "console", "textual", "yaml"}
        or m
        in {
            "backend.server.server",
            "backend.server.journal",
            "backend.files.missions",
            "backend.protocol.mapfeed",
            "backend.server.acl",
        }
    ]
    assert heavy == []
