"""`missionctl web`: the console served to a browser by textual-serve on
loopback, an observer unless `--operator` (with a login); the observer
console it serves (`missionctl console --observer`); and Debian's Chromium,
driven by Playwright, showing the live mission and refusing an observer's
change."""

from __future__ import annotations

import argparse
import codecs
import os
import re
import shlex
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from console_state import account_known, inject, make_app, mars_mid_execution, screen_text

from backend.client.client import ClientError
from backend.core.ops import Control
from backend.transport import free_port
from console.cli import OBSERVER
from console.operations import ReadOnlyBackend
from console.web import console_command, register
from tests.cli.helpers import Server, ids, state


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


@contextmanager
def served(*args: str) -> Iterator[str]:
    """`missionctl web ARGS` on a free port; yields its address once it listens."""
    port = free_port()
    argv = [sys.executable, "-m", "backend.cli", "web", "--port", str(port), *args]
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
        yield f"http://127.0.0.1:{port}/"
    finally:
        server.terminate()
        server.wait(timeout=10)


def test_the_page_is_served_on_loopback():
    with served() as url:
        for attempt in range(50):  # it binds right after saying so
            try:
                with urllib.request.urlopen(url, timeout=5) as r:
                    page = r.read().decode()
                break
            except urllib.error.URLError as e:
                if attempt == 49 or not isinstance(e.reason, ConnectionRefusedError):
                    raise
        assert "textual.js" in page and "missionctl" in page


# -- a real browser ------------------------------------------------------------

CHROMIUM = Path("/usr/bin/chromium")  # Debian's; .ci/run installs it
# as the machine's notes say: without the background-networking flags Chromium
# keeps dialling Google's hosts, which a closed network refuses
CHROMIUM_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
# what the terminal in the page is sent, less its escape sequences (colours,
# cursor moves, window titles): the text it draws, in the order it is drawn
ESCAPES = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b\][^\x07]*\x07|\x1b[()=>][0-9A-Za-z]?")


class DrawnText:
    """The text a page's terminal is sent over its websocket (the page draws
    on a canvas, so this is where its words can be read)."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.text = ""
        self._utf8 = codecs.getincrementaldecoder("utf-8")("replace")
        ws.on("framereceived", self._received)

    def _received(self, payload: str | bytes) -> None:
        if isinstance(payload, bytes):  # the console's output; str frames are control
            self.text += ESCAPES.sub("", self._utf8.decode(payload))

    def wait_for(self, words: str, after: int = 0, timeout: float = 30.0) -> None:
        """Wait until the terminal is sent `words` (after `after` characters)."""
        if words in self.text[after:]:
            return
        self.ws.wait_for_event(
            "framereceived", lambda _: words in self.text[after:], timeout=timeout * 1000
        )


def _browser_or_skip():
    sync_api = pytest.importorskip("playwright.sync_api")
    if not CHROMIUM.exists():
        if os.environ.get("MISSIONCTL_BROWSER_REQUIRED"):  # set by .ci/run
            pytest.fail(f"{CHROMIUM} is missing: apt-get install chromium")
        pytest.skip(f"no {CHROMIUM} (apt-get install chromium)")
    return sync_api


def test_a_browser_shows_the_live_mission_and_an_observer_changes_nothing(tmp_path):
    sync_api = _browser_or_skip()
    server = Server(tmp_path)
    try:
        with served("--connect", server.endpoint) as url, sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_FLAGS)
            try:
                page = browser.new_page(viewport={"width": 1400, "height": 900})
                with page.expect_websocket(timeout=30_000) as opened:
                    page.goto(url)
                drawn = DrawnText(opened.value)
                # the schedule: the mission's name, its robots, their plans
                drawn.wait_for("Tutorial")
                for words in ("lru1", "lru2", "drive to POI-A", "find a stone"):
                    drawn.wait_for(words)
                drawn.wait_for("observer")
                # keys reach the console: the next skill's details open
                page.mouse.click(300, 300)
                mark = len(drawn.text)
                page.keyboard.press("ArrowDown")
                drawn.wait_for("lru1-2", after=mark)
                # an observer's delete is refused in the page, and the server
                # never hears of it
                mark = len(drawn.text)
                page.keyboard.press("d")
                page.keyboard.press("Enter")
                drawn.wait_for("Delete does not apply", after=mark)
                page.screenshot(path=str(tmp_path / "page.png"))
            finally:
                browser.close()
        after = state(server.endpoint)
        assert after["revision"] == 0, after
        assert ids(after, "lru1") == ["lru1-1", "lru1-2"]
    finally:
        server.stop()
