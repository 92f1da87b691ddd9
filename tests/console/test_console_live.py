"""End-to-end: the console against a REAL mission server (subprocess) with
robot agents (subprocess, backend.agent.RobotAgent), driven with keys."""

from __future__ import annotations

import os
import pty
import select
import signal
import subprocess
import sys
import time
from typing import Any

import pytest
from console_live import ROOT, running
from console_state import TUTORIAL, make_app, screen_text, wait_until

from backend.core.model import Status
from console.demo import CHILD_NICENESS
from console.screens.dialogs import SkillPicker

SIZE = (150, 40)
SLOW = 30.0  # bound for things that take well under a second normally


@pytest.fixture
def live(tmp_path):
    with running(tmp_path, TUTORIAL) as env:
        yield env


def skill(app, sid):
    found = app.model.find(sid)
    return found[2] if found else None


def status(app, sid):
    s = skill(app, sid)
    return s.status if s else None


async def connected(app, pilot, *online: str) -> None:
    await wait_until(
        pilot,
        lambda: app.model.connected and app.model.mission is not None,
        SLOW,
        "connected with state",
    )
    for r in online:
        await wait_until(pilot, lambda r=r: app.model.is_online(r), SLOW, f"{r} online")


async def pick(app, pilot, sid: str) -> None:
    schedule = app.mission_screen.schedule
    # the model has the state before the screen draws it (its own turn): a select
    # before that draw is undone by the first rebuild
    await wait_until(
        pilot, lambda: any(sid in c.line_of for c in schedule.columns), SLOW, f"{sid} shown"
    )
    schedule.select(sid)
    schedule.focus()
    await wait_until(pilot, lambda: app.model.selection.skill == sid, SLOW, f"{sid} selected")


async def test_add_edit_sync_run_success(live):
    live.start_robots()
    app = make_app(connect=live.endpoint, user="op1")
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot, "lru1", "lru2")
        assert "lru1" in screen_text(app) and "● online" in screen_text(app)
        await pick(app, pilot, "lru1-2")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, SkillPicker), SLOW, "picker")
        await pilot.press(*"recharge", "enter")
        await wait_until(pilot, lambda: skill(app, "lru1-3") is not None, SLOW, "lru1-3 added")
        assert skill(app, "lru1-3").skill == "recharge"
        editor = app.mission_screen.editor
        await wait_until(
            pilot,
            lambda: editor.skill_id == "lru1-3" and editor.query("#f-target_level"),
            SLOW,
            "editor on lru1-3",
        )
        editor.query_one("#f-target_level").value = "0.6"
        editor.query_one("#f-label").value = "top up"
        await pilot.pause()
        await pilot.press("enter")  # enter in a field applies
        await wait_until(
            pilot,
            lambda: skill(app, "lru1-3").params.get("target_level") == 0.6,
            SLOW,
            "edit applied on the server",
        )
        assert skill(app, "lru1-3").label == "top up"
        await pilot.press("escape")
        await pick(app, pilot, "lru1-3")
        await pilot.press("s")
        await wait_until(
            pilot,
            lambda: all(status(app, f"lru1-{i}") == Status.IDLE_SYNCHRONIZED for i in (1, 2, 3)),
            SLOW,
            "synchronized",
        )
        await pilot.press("r")
        await wait_until(
            pilot,
            lambda: "run lru1: queued for lru1 (command " in app.mission_screen.message,
            SLOW,
            "the run's command",
        )
        await wait_until(
            pilot,
            lambda: all(status(app, f"lru1-{i}") == Status.SUCCESS for i in (1, 2, 3)),
            SLOW,
            "all succeeded",
        )
        await pilot.pause()
        text = screen_text(app)
        assert "✓ drive to POI-A" in text and "✓ top up" in text


async def test_unsync_takes_queued_skills_back(live):
    live.start_robots()
    app = make_app(connect=live.endpoint)
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot, "lru1", "lru2")
        await pick(app, pilot, "lru2-2")
        await pilot.press("s")
        await wait_until(
            pilot, lambda: status(app, "lru2-2") == Status.IDLE_SYNCHRONIZED, SLOW, "synchronized"
        )
        await pick(app, pilot, "lru2-1")
        await pilot.press("u")
        await wait_until(
            pilot,
            lambda: status(app, "lru2-1") == Status.IDLE and status(app, "lru2-2") == Status.IDLE,
            SLOW,
            "back in the plan",
        )
        await wait_until(
            pilot,
            lambda: "unsync queued (command 2): lru2-1, lru2-2" in app.mission_screen.message,
            SLOW,
            "status line",
        )


async def test_failure_then_retry(live):
    live.start_robots()
    app = make_app(connect=live.endpoint)
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot, "lru1")
        await pick(app, pilot, "lru1-1")
        editor = app.mission_screen.editor
        await wait_until(
            pilot, lambda: editor.skill_id == "lru1-1" and editor.query("#f-label"), SLOW, "editor"
        )
        editor.query_one("#f-label").value = "drive [fail]"
        await pilot.pause()
        editor.action_apply()
        await wait_until(
            pilot, lambda: skill(app, "lru1-1").label == "drive [fail]", SLOW, "label applied"
        )
        await pick(app, pilot, "lru1-1")
        await pilot.press("s")
        await wait_until(
            pilot, lambda: status(app, "lru1-1") == Status.IDLE_SYNCHRONIZED, SLOW, "synchronized"
        )
        await pilot.press("r")
        await wait_until(pilot, lambda: status(app, "lru1-1") == Status.FAILURE, SLOW, "failed")
        await wait_until(
            pilot,
            lambda: "simulated failure of drive_to" in screen_text(app),
            SLOW,
            "the reason on screen",
        )
        await pick(app, pilot, "lru1-1")
        await pilot.press("t")
        await wait_until(
            pilot, lambda: status(app, "lru1-1.2") == Status.IDLE_SYNCHRONIZED, SLOW, "retry queued"
        )
        await pilot.press("r")
        await wait_until(
            pilot, lambda: status(app, "lru1-1.2") == Status.SUCCESS, SLOW, "retry succeeded"
        )
        assert status(app, "lru1-1") == Status.FAILURE  # the log keeps the failed attempt
        await pilot.pause()
        assert "#2" in screen_text(app)


async def test_barrier_across_two_robots(live):
    live.start_robots()
    app = make_app(connect=live.endpoint)
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot, "lru1", "lru2")
        await pick(app, pilot, "lru1-1")
        await pilot.press("space")
        await pick(app, pilot, "lru2-1")
        await pilot.press("space", "b")
        await wait_until(
            pilot, lambda: app.model.barrier_of("lru1-1") is not None, SLOW, "barrier made"
        )
        bid = app.model.barrier_of("lru1-1")
        assert app.model.barrier_of("lru2-1") == bid
        await pilot.pause()
        assert screen_text(app).count(f"[{bid}]") == 2
        await pick(app, pilot, "lru1-1")
        await pilot.press("s")
        await pick(app, pilot, "lru2-1")
        await pilot.press("s")
        await wait_until(
            pilot,
            lambda: status(app, "lru1-1") == status(app, "lru2-1") == Status.IDLE_SYNCHRONIZED,
            SLOW,
            "both synchronized",
        )
        await pilot.press("R")  # run all
        await wait_until(
            pilot,
            lambda: status(app, "lru1-1") == status(app, "lru2-1") == Status.SUCCESS,
            SLOW,
            "both ran",
        )


async def test_a_second_console_sees_the_first_ones_edit(live):
    one = make_app(connect=live.endpoint, user="op1")
    two = make_app(connect=live.endpoint, user="op2")
    async with one.run_test(size=SIZE) as p1, two.run_test(size=SIZE) as p2:
        await connected(one, p1)
        await connected(two, p2)
        await pick(one, p1, "lru2-2")
        editor = one.mission_screen.editor
        await wait_until(
            p1,
            lambda: editor.skill_id == "lru2-2" and editor.query("#f-search_radius"),
            SLOW,
            "editor",
        )
        editor.query_one("#f-search_radius").value = "4.5"
        await p1.pause()
        editor.action_apply()
        await wait_until(
            p2,
            lambda: (
                skill(two, "lru2-2") is not None
                and skill(two, "lru2-2").params.get("search_radius") == 4.5
            ),
            SLOW,
            "the other console sees it",
        )
        await pick(two, p2, "lru2-2")
        await wait_until(
            p2,
            lambda: (
                two.mission_screen.editor.query("#f-search_radius")
                and two.mission_screen.editor.query_one("#f-search_radius").value == "4.5"
            ),
            SLOW,
            "shown in its editor",
        )


async def test_robot_killed_shows_offline(live):
    live.start_robots()
    app = make_app(connect=live.endpoint)
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot, "lru1", "lru2")
        live.kill_robots()
        await wait_until(
            pilot,
            lambda: not app.model.is_online("lru1") and not app.model.is_online("lru2"),
            SLOW,
            "offline",
        )
        await wait_until(
            pilot, lambda: screen_text(app).count("✕ offline") == 2, SLOW, "offline in both headers"
        )
        await pick(app, pilot, "lru1-1")
        await pilot.press("s")  # queued for the robot: it gets it when it is back
        await wait_until(
            pilot, lambda: "sync queued (command" in app.mission_screen.message, SLOW, "queued"
        )
        await wait_until(pilot, lambda: "⇡ " in screen_text(app), SLOW, "the skill uplinking")
        assert "sync #1 " in screen_text(app)


async def test_server_restart_console_resyncs(live):
    app = make_app(connect=live.endpoint)
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot)
        await pick(app, pilot, "lru1-2")
        editor = app.mission_screen.editor
        await wait_until(
            pilot, lambda: editor.skill_id == "lru1-2" and editor.query("#f-label"), SLOW, "editor"
        )
        editor.query_one("#f-label").value = "look closer"
        await pilot.pause()
        editor.action_apply()
        await wait_until(
            pilot, lambda: skill(app, "lru1-2").label == "look closer", SLOW, "edit applied"
        )
        revision = app.model.mission.revision
        live.stop_server()
        await wait_until(
            pilot, lambda: app.model.connection == "reconnecting", SLOW, "reconnecting"
        )
        await wait_until(
            pilot, lambda: "reconnecting" in screen_text(app), SLOW, "reconnecting shown"
        )
        live.start_server()
        await wait_until(pilot, lambda: app.model.connection == "connected", SLOW, "reconnected")
        await wait_until(
            pilot, lambda: "resynchronized" in app.mission_screen.message, SLOW, "resync said"
        )
        assert (
            app.model.mission.revision == revision and skill(app, "lru1-2").label == "look closer"
        )
        # and it works: a new edit goes through
        editor.query_one("#f-label").value = "look closer again"
        await pilot.pause()
        editor.action_apply()
        await wait_until(
            pilot,
            lambda: skill(app, "lru1-2").label == "look closer again",
            SLOW,
            "edit after restart",
        )


def _drain_until_exit(fd: int, p: subprocess.Popen, timeout: float) -> int | None:
    """Keep reading the terminal (a full pty blocks the app's writes) until it exits."""
    deadline = time.monotonic() + timeout
    while p.poll() is None and time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            try:
                if not os.read(fd, 65536):
                    break
            except OSError:
                break
    try:
        return p.wait(max(0.1, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        return None


def _read_until(fd: int, needle: bytes, timeout: float) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout
    while needle not in out and time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            try:
                chunk = os.read(fd, 65536)
            except OSError:
                break
            if not chunk:
                break
            out += chunk
    return out


@pytest.mark.parametrize("how", ["sighup", "ctrl+q"])
def test_console_process_exits_cleanly_on_hangup_and_ctrl_q(live, how):
    """In a real terminal (a pty): SIGHUP (the SSH link dropped) or ctrl+q
    ends the process promptly, closing its Zenoh session (no exit hang)."""
    master, slave = pty.openpty()
    env = {
        **os.environ,
        "TERM": "xterm-256color",
        "COLUMNS": "100",
        "LINES": "30",
        "MISSIONCTL_CONFIG": "/nonexistent.toml",
    }
    p = subprocess.Popen(
        [sys.executable, "-m", "backend.cli", "console", "--connect", live.endpoint],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        cwd=ROOT,
        env=env,
        start_new_session=True,
    )
    os.close(slave)
    try:
        out = _read_until(master, b"Tutorial", 30)
        assert b"Tutorial" in out, out[-2000:]
        if how == "sighup":
            p.send_signal(signal.SIGHUP)
        else:
            os.write(master, b"\x11")
        code = _drain_until_exit(master, p, 15)
        assert code in (0, -signal.SIGHUP), code
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(10)
        os.close(master)


def test_demo_starts_server_and_console_and_stops_everything(tmp_path):
    """`missionctl demo --link-delay 20s --break … --join …` in a pty: the
    console shows the Mars mission, the sim runs with the delay and the team's
    events; ctrl+q stops the console, the server and the sim (no process left
    behind)."""
    master, slave = pty.openpty()
    env = {
        **os.environ,
        "TERM": "xterm-256color",
        "TMPDIR": str(tmp_path),
        "MISSIONCTL_CONFIG": "/nonexistent.toml",
    }
    p = subprocess.Popen(
        [
            *(sys.executable, "-m", "backend.cli", "demo", "--link-delay", "20s", "--speed", "5"),
            *("--break", "lru1@12m", "--join", "lru3:lru_science@15m"),
        ],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        cwd=ROOT,
        env=env,
        start_new_session=True,
    )
    os.close(slave)
    try:
        # the plan from the file at once, then the server's state once connected
        out = _read_until(master, b"Mars sample return", 60)
        assert b"Mars sample return" in out, out[-3000:]
        out = _read_until(master, b"connected", 60)  # (not "connecting")
        assert b"connected" in out, out[-3000:]
        children = _processes_mentioning(str(tmp_path))
        assert children, "the demo's server was not found among the processes"
        # its sim got the link delay (after its --speed: not the demo's own command line)
        sims = _processes_mentioning(
            "--speed\x005\x00--link-delay\x0020s\x00--break\x00lru1@12m\x00"
            "--join\x00lru3:lru_science@15m"
        )
        assert sims, "no delayed sim with the team's events"
        # the server and the sim yield the CPU to the console (console/demo.py)
        for child in {*children, *sims}:
            assert _niceness(child) == _niceness(p.pid) + CHILD_NICENESS, child
        os.write(master, b"\x11")
        assert _drain_until_exit(master, p, 30) == 0
        deadline = time.monotonic() + 10
        while _processes_mentioning(str(tmp_path)) and time.monotonic() < deadline:
            time.sleep(0.1)  # the children were terminated; the kernel reaps them
        assert not _processes_mentioning(str(tmp_path))
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(10)
        os.close(master)


# run a command with the pty on stdin as its controlling terminal, as a terminal
# emulator or sshd does (then closing the master sends the kernel's SIGHUP)
WITH_CONTROLLING_TTY = (
    "import fcntl, os, sys, termios; os.setsid(); fcntl.ioctl(0, termios.TIOCSCTTY, 0); "
    "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])"
)


def test_demo_hung_up_terminal_stops_everything(tmp_path):
    """The SSH link drops for real: the terminal goes away (writes to it fail)
    and the kernel sends SIGHUP. The demo must still end, with its server and sim."""
    master, slave = pty.openpty()
    env = {
        **os.environ,
        "TERM": "xterm-256color",
        "TMPDIR": str(tmp_path),
        "MISSIONCTL_CONFIG": "/nonexistent.toml",
    }
    p = subprocess.Popen(
        [sys.executable, "-c", WITH_CONTROLLING_TTY, "-m", "backend.cli", "demo", "--speed", "5"],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        cwd=ROOT,
        env=env,
    )
    os.close(slave)
    try:
        # the plan from the file at once, then the server's state once connected
        out = _read_until(master, b"Mars sample return", 60)
        assert b"Mars sample return" in out, out[-3000:]
        out = _read_until(master, b"connected", 60)  # (not "connecting")
        assert b"connected" in out, out[-3000:]
        assert _processes_mentioning(str(tmp_path))
        os.close(master)  # hang-up: SIGHUP, and every write to the terminal fails from now on
        master = -1
        p.wait(30)  # a clean exit, or the hang-up watchdog's (5 s)
        deadline = time.monotonic() + 10
        while _processes_mentioning(str(tmp_path)) and time.monotonic() < deadline:
            time.sleep(0.1)  # the children were terminated; the kernel reaps them
        assert not _processes_mentioning(str(tmp_path))
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(10)
        for pid in _processes_mentioning(str(tmp_path)):
            os.kill(pid, signal.SIGKILL)
        if master >= 0:
            os.close(master)


def _niceness(pid: int) -> int:
    with open(f"/proc/{pid}/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[16])  # field 19 of proc(5)


def _processes_mentioning(text: str) -> list[int]:
    pids = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/cmdline", "rb") as f:
                cmd = f.read().decode(errors="replace")
            with open(f"/proc/{d}/stat") as f:
                state = f.read().split(")")[-1].split()[0]
        except OSError:
            continue
        if text in cmd and state != "Z":
            pids.append(int(d))
    return pids


# -- part 2: an injected failure raises an alert that is acknowledged ----------------------------
# (the "[fail]" label makes console_robots.py fail the skill; the server raises
# the alert, the console logs the report: one alert, one bell)


def _other_rung(app: Any) -> list[Any]:
    """The alerts other than failures that ring the bell."""
    return [a for a in app.alerts.alerts if a.kind != "failure" and a.level != "info"]


async def test_workflow_injected_failure_raises_an_alert_that_is_acknowledged(live):
    live.start_robots()
    app = make_app(connect=live.endpoint, user="ada")
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot, "lru1")
        screen = app.mission_screen
        screen.schedule.select("lru1-1")
        await pilot.pause()
        editor = screen.editor
        await wait_until(
            pilot, lambda: editor.skill_id == "lru1-1" and editor.query("#f-label"), SLOW, "editor"
        )
        editor.query_one("#f-label").value = "drive [fail]"
        await pilot.pause()
        editor.action_apply()
        await wait_until(
            pilot,
            lambda: app.model.find("lru1-1")[2].label == "drive [fail]",
            SLOW,
            "label applied",
        )
        screen.schedule.select("lru1-1")
        screen.schedule.focus()
        await pilot.pause()
        bells, others = app.bells, len(_other_rung(app))
        await pilot.press("s")
        await wait_until(
            pilot, lambda: status(app, "lru1-1") == Status.IDLE_SYNCHRONIZED, SLOW, "synchronized"
        )
        await pilot.press("r")
        await wait_until(pilot, lambda: status(app, "lru1-1") == Status.FAILURE, SLOW, "failed")
        await wait_until(
            pilot,
            lambda: any(a.kind == "failure" for a in app.alerts.alerts),
            SLOW,
            "failure alert",
        )
        # the server's alert, the only one about the failure (the console raises none)
        await wait_until(
            pilot,
            lambda: [a.source for a in app.alerts.alerts if a.kind == "failure"] == ["server"],
            SLOW,
            "the server's alert",
        )
        failure = [a for a in app.alerts.alerts if a.kind == "failure"]
        assert len(failure) == 1 and failure[0].skill == "lru1-1" and failure[0].level == "error"
        # one bell for the failure (an overdue or offline alert of a loaded machine rings its own);
        # the bell rings on the app's turn after the alert book took the alert: wait for it
        await wait_until(
            pilot,
            lambda: app.bells == bells + 1 + len(_other_rung(app)) - others,
            SLOW,
            "one bell for the failure",
        )
        # the badge counts what is unacknowledged (a loaded machine may add overdue alerts)
        await wait_until(pilot, lambda: _badge(app) in screen_text(app), SLOW, "the badge")
        # the log names who synchronized: this console's user and client id
        sync = [e for e in app.event_log.entries if e.op == "sync"]  # queued by ada
        assert sync and sync[-1].user == "ada" and sync[-1].client == app.bridge.client.client_id
        assert any(e.kind == "failure" and e.skill == "lru1-1" for e in app.event_log.entries)
        await pilot.press("f6")
        from console.screens.alerts import AlertScreen

        await wait_until(pilot, lambda: isinstance(app.screen, AlertScreen), SLOW, "alert list")
        # the cursor on the failure (newest first: another alert may be above it)
        app.screen.query_one("#alerts").move_cursor(row=app.screen.ids.index(failure[0].id))
        await pilot.pause()
        assert "simulated failure of drive_to" in screen_text(app)
        await pilot.press("enter")
        await wait_until(
            pilot,
            lambda: [a.acknowledged for a in app.alerts.alerts if a.kind == "failure"] == [True],
            SLOW,
            "acknowledged",
        )
        book = app.alerts
        await wait_until(
            pilot,
            lambda: (
                f"{book.unacknowledged} unacknowledged of {len(book.alerts)}" in screen_text(app)
            ),
            SLOW,
            "the count said",
        )
        await pilot.press("A")  # acknowledge all: the badge goes
        await wait_until(pilot, lambda: book.unacknowledged == 0, SLOW, "all acknowledged")
        await pilot.press("f2")
        await wait_until(
            pilot, lambda: app.screen is app.mission_screen, SLOW, "back to the schedule"
        )
        # no badge (unless an alert came after: then it counts that one)
        await wait_until(
            pilot,
            lambda: ("⚠" in screen_text(app).splitlines()[0]) == bool(book.unacknowledged),
            SLOW,
            "the badge gone",
        )


def _badge(app: Any) -> str:
    """The top bar's alert badge for what is unacknowledged now."""
    n = app.alerts.unacknowledged
    return f"⚠ {n} alert{'' if n == 1 else 's'} (F6)"


async def test_a_robots_question_is_answered_from_the_console(live):
    """The robot asks; the console's dialog opens by itself; a key answers;
    the answer goes up the robot's uplink and the robot goes on with it."""
    from backend.client.client import MissionClient
    from backend.core.ops import Control, EditSkill, Sync
    from console.screens.question import QuestionScreen

    live.start_robots()
    app = make_app(connect=live.endpoint, user="op1")
    async with app.run_test(size=SIZE) as pilot:
        await connected(app, pilot, "lru1")
        async with MissionClient(live.endpoint, client_id="script") as client:
            await client.submit(EditSkill(id="lru1-1", label="drive [ask]"))
            await client.submit(Sync(robot="lru1", through="lru1-1"))
            await client.submit(Control(op="run", robot="lru1"))
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), SLOW, "dialog")
        # pushed is not drawn yet: wait for its text
        await wait_until(pilot, lambda: "Go on?" in screen_text(app), SLOW, "its text")
        assert "Question #1 from lru1" in screen_text(app)
        assert any(a.kind == "question" for a in app.model.alerts.alerts)
        await pilot.press("2")
        line = live.robots.wait_line("lru1-1: ")
        assert "stop here (answered True by op1@" in line
        await wait_until(pilot, lambda: status(app, "lru1-1") == Status.FAILURE, SLOW, "failure")
        q = app.model.mission.question(1)
        assert q.state.value == "answered" and q.answered_by.startswith("op1@")
        log = "\n".join(e.text for e in app.model.log.entries)
        assert "question #1 from lru1 (lru1-1): Go on?" in log
        assert "question #1 answered: the robot goes on with stop here" in log
