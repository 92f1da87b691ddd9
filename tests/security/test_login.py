"""Logins: a refused login is one clear line and exit code 3 (ctl, console,
robots); operators change the mission, observers are refused; the server
records the logged-in user, not what the request claims."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from .helpers import CLI, ROBOTS_SCRIPT, ROOT, env

EXIT_BAD_INPUT, EXIT_UNREACHABLE = 2, 3


def _one_line(stderr: str) -> str:
    assert "Traceback" not in stderr
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    return lines[0]


def test_wrong_password_is_refused_with_a_clear_line(server, accounts):
    bad = accounts.write_secret("bad.pw", "not-the-password")
    r = server.ctl(None, "--user", "ops", "--password-file", str(bad), "state")
    assert r.returncode == EXIT_UNREACHABLE
    assert _one_line(r.stderr).startswith(
        f"missionctl: login refused for user ops at {server.endpoint}"
    )


def test_unknown_user_and_missing_credentials_are_refused(server, accounts):
    r = server.ctl(
        None, "--user", "mallory", "--password-file", str(accounts.pw_file("ops")), "state"
    )
    assert r.returncode == EXIT_UNREACHABLE
    assert f"login refused for user mallory at {server.endpoint}" in _one_line(r.stderr)
    r = server.ctl(None, "state")
    assert r.returncode == EXIT_UNREACHABLE
    assert _one_line(r.stderr) == (
        f"missionctl: login refused at {server.endpoint}: the server requires an account "
        "(give --user and --password-file)"
    )


def test_unreachable_is_not_reported_as_a_refused_login(accounts):
    from backend.transport import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens
    r = subprocess.run(
        [*CLI, "ctl", "--connect", endpoint, *accounts.login_args("ops"), "state"],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == EXIT_UNREACHABLE
    line = _one_line(r.stderr)
    assert "login refused" not in line and "cannot reach the mission server" in line


def test_console_cli_wrong_password_exits_3_with_one_line(server, accounts):
    bad = accounts.write_secret("bad.pw", "not-the-password")
    r = subprocess.run(
        [
            *CLI,
            "console",
            "--connect",
            server.endpoint,
            "--user",
            "watch",
            "--password-file",
            str(bad),
        ],
        cwd=ROOT,
        env={**env(), "TERM": "xterm-256color"},
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == EXIT_UNREACHABLE, r.stderr
    assert _one_line(r.stderr).startswith(
        f"missionctl console: login refused for user watch at {server.endpoint}"
    )


def test_robot_with_wrong_password_exits_3(server, accounts):
    bad = accounts.write_secret("bad.pw", "not-the-password")
    r = subprocess.run(
        [
            sys.executable,
            str(ROBOTS_SCRIPT),
            "--connect",
            server.endpoint,
            "--user",
            "rover1",
            "--password-file",
            str(bad),
            "lru1:lru_science",
        ],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == EXIT_UNREACHABLE
    assert f"login refused for user rover1 at {server.endpoint}" in _one_line(r.stderr)


def test_password_file_readable_by_others_is_refused(server, accounts):
    loose = accounts.write_secret("loose.pw", accounts.passwords["ops"])
    os.chmod(loose, 0o644)
    r = server.ctl(None, "--user", "ops", "--password-file", str(loose), "state")
    assert r.returncode == EXIT_BAD_INPUT
    assert f"chmod 600 {loose}" in _one_line(r.stderr)


def test_operator_changes_the_mission_as_itself(server):
    r = server.ctl("ops", "--json", "add", "lru1", "recharge", "--label", "by ops")
    assert r.returncode == 0, r.stderr
    st = json.loads(server.ctl("watch", "state", "--json").stdout)
    assert any(s["label"] == "by ops" for s in st["tasks"]["lru1"])
    # the journal names the logged-in account as the actor
    import sqlite3

    with sqlite3.connect(server.db) as db:
        actors = [row[0] for row in db.execute("select actor from batches")]
    assert actors == ["ops@sec-test"]


def test_observer_reads_but_every_operation_is_refused(server):
    st = server.ctl("watch", "state", "--json")
    assert st.returncode == 0, st.stderr
    before = json.loads(st.stdout)["revision"]
    for args in (
        ["add", "lru1", "recharge"],
        ["run", "--all"],
        ["new", "x"],
        ["marker", "delete", "POI-A"],
        ["answer", "1", "wider"],  # a robot's question (issue 29): an operator's to answer
    ):
        r = server.ctl("watch", *args)
        assert r.returncode == 1, (args, r.stderr)
        assert _one_line(r.stderr) == "missionctl: refused: read-only: logged in as observer watch"
    assert json.loads(server.ctl("watch", "state", "--json").stdout)["revision"] == before


def test_accounts_file_errors_name_file_line_and_field(tmp_path):
    bad = tmp_path / "accounts.yaml"
    bad.write_text(
        "format: missionctl/accounts@1\naccounts:\n  ops: {role: admin, password_file: x.pw}\n"
    )
    r = subprocess.run(
        [
            *CLI,
            "server",
            "--mission",
            str(ROOT / "missions" / "tutorial.yaml"),
            "--db",
            str(tmp_path / "m.db"),
            "--listen",
            "tcp/127.0.0.1:1",
            "--accounts",
            str(bad),
        ],
        cwd=ROOT,
        env=env(),
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == EXIT_BAD_INPUT
    line = _one_line(r.stderr)
    assert f"{bad}:3:" in line and "accounts.ops.role" in line
