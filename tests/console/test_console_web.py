"""`missionctl web`: the console served to a browser by textual-serve on
loopback, an observer unless `--operator` (with a login); and the observer
console it serves (`missionctl console --observer`).

Not here: a browser driving the page (issue 32 asks for headless Chromium)."""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import urllib.error
import urllib.request

import pytest
from console_state import account_known, inject, make_app, mars_mid_execution, screen_text

from backend.client.client import ClientError
from backend.core.ops import Control
from backend.transport import free_port
from console.cli import OBSERVER
from console.operations import ReadOnlyBackend
from console.web import console_command, register


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    return parser.parse_args(["web", *argv])


def test_each_tab_runs_an_observer_console_unless_operator():
    observer = shlex.split(console_command(_args("--connect", "tcp/127.0.0.1:9")))
    assert observer[1:] == [
        "-m", "backend.cli", "console", "--connect", "tcp/127.0.0.1:9", "--yes", "--observer",
    ]  # fmt: skip
    operator = shlex.split(
        console_command(_args("--operator", "--user", "ops", "--password-file", "ops.pw"))
    )
    assert "--observer" not in operator
    assert operator[-4:] == ["--user", "ops", "--password-file", "ops.pw"]


def test_an_operator_view_needs_a_login(capsys):
    from backend.cli.main import main

    assert main(["web", "--operator"]) == 2
    assert "--operator needs a login" in capsys.readouterr().err
    assert main(["web", "--port", "0"]) == 2


async def test_an_observer_console_stays_read_only_whatever_its_account():
    app = make_app(observer=OBSERVER)
    async with app.run_test(size=(100, 30)) as pilot:
        await inject(app, pilot, mars_mid_execution())
        app.post_message(account_known(""))  # an operator's account
        await pilot.pause()
        await pilot.pause()
        assert app.model.read_only == OBSERVER
        assert "read-only: observer" in screen_text(app)
    with pytest.raises(ClientError, match="read-only: observer"):
        await ReadOnlyBackend(OBSERVER).submit(Control(op="run", robot="lru1"))


def test_the_page_is_served_on_loopback():
    port = free_port()
    argv = [sys.executable, "-m", "backend.cli", "web", "--port", str(port)]
    env = {**os.environ, "COLUMNS": "200"}  # textual-serve's banner on one line
    server = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )
    try:
        assert server.stdout is not None
        for line in server.stdout:  # the event: textual-serve starts listening
            if "Serving" in line:
                break
        else:
            raise AssertionError("missionctl web ended without serving")
        for attempt in range(50):  # it binds right after saying so
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as r:
                    page = r.read().decode()
                break
            except urllib.error.URLError as e:
                if attempt == 49 or not isinstance(e.reason, ConnectionRefusedError):
                    raise
        assert "textual.js" in page and "missionctl" in page
    finally:
        server.terminate()
        server.wait(timeout=10)
