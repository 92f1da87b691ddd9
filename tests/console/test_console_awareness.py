"""The fleet, event-log and alert screens, themes and 16 colours, driven
with keys (pilot) on injected state (console_state.awareness_scenario)."""

from __future__ import annotations

import pytest
from console_state import (
    MARS,
    T0,
    Builder,
    alert_received,
    awareness_scenario,
    fleet_changed,
    inject,
    make_app,
    mars_fleet_with_manifests,
    screen_text,
    state_loaded,
    wait_until,
)

from backend.protocol.messages import Alert, RobotInfo
from console.config import ConsoleConfig, load_config
from console.screens.alerts import AlertScreen
from console.screens.dialogs import PathPrompt, SkillPicker
from console.screens.fleet import FleetScreen
from console.screens.log import EventLogScreen
from console.screens.mission import MissionScreen
from console.state.changes import Topic, change
from console.state.eventlog import read_jsonl
from console.themes.loader import ANSI16_STATUS

SIZE = (130, 30)


async def test_keys_switch_between_the_screens():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        for key, screen in (
            ("3", FleetScreen),
            ("f5", EventLogScreen),
            ("f6", AlertScreen),
            ("f2", MissionScreen),
            ("f4", FleetScreen),
            ("f2", MissionScreen),
            ("4", EventLogScreen),
            ("f2", MissionScreen),
            ("5", AlertScreen),
            ("f2", MissionScreen),
        ):
            await pilot.press(key)
            await wait_until(
                pilot,
                lambda screen=screen: isinstance(app.screen, screen),
                what=f"{screen.__name__} after {key}",
            )
        assert app.screen is app.mission_screen  # the same schedule screen, not a new one


async def test_fleet_screen_shows_presence_manifest_history_and_activity():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        await pilot.press("f4")
        await wait_until(pilot, lambda: "Fleet" in screen_text(app), what="fleet screen")
        text = screen_text(app)
        assert "4 robots, 2 online" in text  # the lander went offline
        for needle in ("lru1", "● online", "○ offline 10:42:07", "lru_manipulator", "drone", "15%"):
            assert needle in text, needle
        assert any(ch in text for ch in "▁▂▃▄▅▆▇"), "battery/link sparklines"
        # the selected robot's manifest and what it does
        assert "modules: nav 2.1.0, science_cam 1.4.2" in text
        # as the robot sent them (JSON), like `ctl robots`: not Python's True / ['...']
        assert 'properties: max_speed=1.0, simulated=true, capabilities=["science_camera"]' in text
        assert "doing: ▶ lru1-1 running" in text
        assert "last report: ▶ lru1-1 running 10:42:07" in text
        # a robot that never registered
        table = app.screen.query_one("DataTable")
        table.focus()
        await pilot.press("down", "down")
        await wait_until(
            pilot, lambda: "never registered" in screen_text(app), what="ardea's detail"
        )


async def test_digits_switch_screens_until_typing_starts_the_filter():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await awareness_scenario(app, pilot)
        await pilot.press("3")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
        fleet = app.screen
        await pilot.press(*"lru2")  # a letter moves to the filter; then digits are text
        field = fleet.query_one("#filter")
        await wait_until(pilot, lambda: field.value == "lru2", what="typed into the filter")
        assert field.has_focus and fleet.shown == ["lru2"]
        await pilot.press("escape", "4")  # back on the table: digits switch screens again
        await wait_until(pilot, lambda: isinstance(app.screen, EventLogScreen), what="log after 4")


async def test_workflow_filter_the_fleet_by_capability():
    app = make_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await awareness_scenario(app, pilot)
        await pilot.press("f4")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
        screen = app.screen
        await pilot.press(*"pick_stone")
        await wait_until(
            pilot, lambda: screen.shown == ["lru2"], what="only lru2 offers pick_stone"
        )
        text = screen_text(app)
        assert "1 match 'pick_stone'" in text and "lru1 " not in text
        assert "modules: nav 2.1.0, arm 0.9.3" in text  # lru2's detail follows the filter
        for _ in "pick_stone":
            await pilot.press("backspace")
        await pilot.press(*"type:lru")
        await wait_until(pilot, lambda: screen.shown == ["lru1", "lru2"], what="the two LRUs")
        await pilot.press("ctrl+u")  # clear the input, then a capability nobody has
        await pilot.press(*"teleport")
        await wait_until(
            pilot,
            lambda: "no robot matches the filter" in screen_text(app),
            what="empty result explained",
        )
        # a robot that registers later with the capability appears while filtered
        await pilot.press("ctrl+u")
        await pilot.press(*"module:arm")
        await wait_until(pilot, lambda: screen.shown == ["lru2"], what="lru2 by module")


async def test_skill_picker_says_which_other_robots_offer_a_skill():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        b = Builder(MARS)
        app.post_message(state_loaded(b.snapshot(), b.library, mars_fleet_with_manifests()))
        await inject(app, pilot, None)
        app.mission_screen.schedule.select("lru1-2")
        await pilot.pause()
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, SkillPicker), what="picker")
        await pilot.press(*"identify")
        await wait_until(
            pilot,
            lambda: "also offered by: lru2" in screen_text(app),
            what="who else offers identify_stone",
        )


async def test_event_log_lists_operations_reports_refusals_failures_and_alerts():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        await pilot.press("f5")
        await wait_until(pilot, lambda: isinstance(app.screen, EventLogScreen), what="log")
        text = screen_text(app)
        for needle in (
            "ada@host-4711-a1b2c3",
            "edit: lru2-2 label=find a good stone",
            "sync_ack",
            "▶ lru1-1 running",
            "✗ lru2-2 failure: no stone in reach",
            "Run refused: [lru1] lru1 is already executing",
            "robot lander went offline",
            "battery low",
            "last 10,000 entries",
        ):
            assert needle in text, needle
        kinds = {e.kind for e in app.event_log.entries}
        assert kinds == {"operation", "report", "failure", "refusal", "alert"}
        screen = app.screen
        await pilot.press(*"kind:failure")
        await wait_until(pilot, lambda: len(screen.rows) == 1, what="one failure")
        await pilot.press("ctrl+u")
        await pilot.press(*"robot:lander")
        await wait_until(
            pilot,
            lambda: len(screen.rows) == 1 and "went offline" in screen_text(app),
            what="lander's line",
        )
        await pilot.press("ctrl+u")
        await pilot.press(*"lru2-2")
        await wait_until(
            pilot, lambda: len(screen.rows) == 4, what="text filter"
        )  # edit, sync, running, failure
        # new entries appear while the log is shown (filtered)
        n = len(screen.rows)
        app.post_message(fleet_changed(RobotInfo(name="lru2", online=False)))
        gone = Alert(id=7, kind="offline", robot="lru2", message="robot lru2 went offline", at=T0)
        app.post_message(alert_received(gone))  # the server's
        app.post_message(alert_received(gone))  # again (in a snapshot, say): taken once
        await pilot.press("ctrl+u")
        await wait_until(
            pilot, lambda: "robot lru2 went offline" in screen_text(app), what="live entry"
        )
        assert len(screen.rows) > n


async def test_export_the_log_to_json_lines(tmp_path):
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        await pilot.press("f5")
        await wait_until(pilot, lambda: isinstance(app.screen, EventLogScreen), what="log")
        log_screen = app.screen
        await pilot.press(*"robot:lru2")
        await wait_until(
            pilot,
            lambda: len(log_screen.rows) == len(app.event_log.select("robot:lru2")),
            what="filtered",
        )
        await pilot.press("ctrl+s")
        await wait_until(pilot, lambda: isinstance(app.screen, PathPrompt), what="path prompt")
        target = tmp_path / "lru2.jsonl"
        prompt = app.screen.query_one("Input")
        prompt.value = str(target)
        await pilot.press("enter")
        await wait_until(
            pilot, lambda: target.exists() and app.screen is log_screen, what="exported"
        )
        back = read_jsonl(target)
        assert back == app.event_log.select("robot:lru2") and len(back) >= 5
        assert all("lru2" in e.robots for e in back)
        assert {e.kind for e in back} >= {"operation", "report", "failure", "alert"}


async def test_alerts_badge_list_and_acknowledge():
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        # failure (merged with the server's), refusal, offline (merged), out of range, low battery
        assert app.alerts.unacknowledged == 5
        assert app.bells == 5
        # about robots: the server's alone (the console raises none of its own)
        assert {a.source for a in app.alerts.alerts if a.kind != "refusal"} == {"server"}
        assert "⚠ 5 alerts (F6)" in screen_text(app)
        await pilot.press("f6")
        await wait_until(pilot, lambda: isinstance(app.screen, AlertScreen), what="alert list")
        text = screen_text(app)
        assert "5 unacknowledged of 5" in text
        for needle in (
            "low battery",
            "out of range",
            "offline",
            "refusal",
            "failure",
            "no stone in reach",
            "server",
        ):
            assert needle in text, needle
        await pilot.press("enter")  # the newest: low battery
        await wait_until(pilot, lambda: app.alerts.unacknowledged == 4, what="one acknowledged")
        assert [a.kind for a in app.alerts.alerts if a.acknowledged] == ["low_battery"]
        assert "4 unacknowledged of 5" in screen_text(app)
        await pilot.press("A")
        await wait_until(pilot, lambda: app.alerts.unacknowledged == 0, what="all acknowledged")
        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen is app.mission_screen, what="schedule")
        assert "alert" not in screen_text(app).splitlines()[0]  # no badge


async def test_theme_option_and_palette_choice_remembered_in_the_config(tmp_path):
    path = tmp_path / "config.toml"
    path.write_text('[keymap]\n"mission.sync" = "S"\n')
    app = make_app(theme="missionctl-high-contrast", config=load_config(path))
    async with app.run_test(size=SIZE) as pilot:
        assert app.theme == "missionctl-high-contrast"
        await pilot.press("ctrl+p")
        await pilot.pause()
        await pilot.press(*"theme")
        await wait_until(
            pilot,
            lambda: "Change theme" in screen_text(app) or "Theme" in screen_text(app),
            what="theme command",
        )
        await pilot.press("enter")
        await wait_until(
            pilot, lambda: "Search for themes" in screen_text(app), what="theme palette"
        )
        await pilot.press(*"missionctl-light")
        await wait_until(
            pilot, lambda: "missionctl-light" in screen_text(app), what="light theme offered"
        )
        await pilot.press("enter")
        await wait_until(pilot, lambda: app.theme == "missionctl-light", what="theme changed")
        await wait_until(
            pilot, lambda: load_config(path).theme == "missionctl-light", what="theme saved"
        )
    cfg = load_config(path)
    assert cfg.keymap == {"mission.sync": "S"} and cfg.problems == []
    app2 = make_app(config=cfg)
    async with app2.run_test(size=SIZE):
        assert app2.theme == "missionctl-light"


async def test_user_themes_and_a_broken_one_named_in_a_notice(tmp_path, monkeypatch):
    themes = tmp_path / "xdg" / "missionctl" / "themes"
    themes.mkdir(parents=True)
    from console.themes.loader import SHIPPED_DIR

    (themes / "mine.yaml").write_text(
        (SHIPPED_DIR / "light.yaml").read_text().replace("missionctl-light", "my-light")
    )
    (themes / "broken.yaml").write_text(
        "name: broken\ndark: maybe\nprimary: '#000000'\nvariables: {}\n"
    )
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    app = make_app(config=ConsoleConfig(theme="my-light"))
    async with app.run_test(size=SIZE) as pilot:
        await pilot.pause()
        assert app.theme == "my-light"
        assert "missionctl-dark" in app.available_themes
        broken = [n for n in app.notices if "broken.yaml" in n]
        assert broken and broken[0].startswith(f"{themes / 'broken.yaml'}:2:")  # dark: maybe


async def test_sixteen_colours_give_each_status_its_own_ansi_colour():
    app = make_app(colors=16)
    async with app.run_test(size=SIZE) as pilot:
        await inject(app, pilot, Builder(MARS))
        assert app.ansi16
        statuses = [
            "status-idle",
            "status-idle-synchronized",
            "status-synchwaiting",
            "status-running",
            "status-paused",
            "status-success",
            "status-failure",
        ]
        colours = [app.theme_variables[s] for s in statuses]
        assert colours == [ANSI16_STATUS[s] for s in statuses]
        assert len(set(colours)) == len(statuses)  # none merge
        app.theme = "missionctl-light"  # any theme: the statuses stay ANSI
        await pilot.pause()
        assert app.theme_variables["status-failure"] == ANSI16_STATUS["status-failure"]


async def test_log_screen_shows_the_last_entries_of_a_long_log():
    from console.screens.log import SHOW_LIMIT

    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        app.event_log.entries = type(app.event_log.entries)(
            app.event_log.entries, maxlen=SHOW_LIMIT + 200
        )
        for i in range(SHOW_LIMIT + 300):  # the log forgets its oldest 100 + scenario entries
            app.event_log.add("report", f"▶ lru1-{i} running", app.clock(), robots=["lru1"])
        await pilot.press("f5")
        await wait_until(pilot, lambda: isinstance(app.screen, EventLogScreen), what="log")
        screen = app.screen
        assert len(screen.rows) == SHOW_LIMIT and screen.matching == SHOW_LIMIT + 200
        assert f"showing the last {SHOW_LIMIT:,}" in screen_text(app)
        app.event_log.add("refusal", "one more", app.clock(), robots=["lru2"])
        app.publish(change(Topic.LOG))
        await pilot.pause()
        assert screen.rows[-1] == app.event_log.seq and len(screen.rows) == SHOW_LIMIT
        assert screen.rows[0] >= app.event_log.entries[0].seq
        await pilot.press(*"robot:lru2")
        await wait_until(
            pilot,
            lambda: screen.matching == 1 and screen.rows == [app.event_log.seq],
            what="only the lru2 line left in the log",
        )


TERM_PROBE = """
import sys
from console.app import MissionApp

class Probe(MissionApp):
    def on_mount(self):
        super().on_mount()
        self.set_timer(0.2, lambda: self.exit(0))

app = Probe()
app.run()
print(f"ansi16={app.ansi16} failure={app.theme_variables.get('status-failure')}", file=sys.stderr)
"""


@pytest.mark.parametrize(("term", "ansi16"), [("xterm", True), ("xterm-256color", False)])
def test_a_16_colour_terminal_is_detected(term, ansi16):
    """A real terminal (pty) with TERM=xterm and no COLORTERM, as over SSH."""
    import os
    import pty
    import select
    import subprocess
    import sys
    import time

    from console_state import ROOT

    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("COLORTERM", "TEXTUAL_COLOR_SYSTEM", "NO_COLOR")
    }
    env["TERM"] = term
    master, slave = pty.openpty()
    p = subprocess.Popen(
        [sys.executable, "-c", TERM_PROBE],
        stdin=slave,
        stdout=slave,
        stderr=subprocess.PIPE,
        env=env,
        cwd=ROOT,
    )
    os.close(slave)
    deadline = time.monotonic() + 30
    try:
        while p.poll() is None and time.monotonic() < deadline:
            if select.select([master], [], [], 0.2)[0]:
                try:
                    os.read(master, 65536)  # drain the screen output
                except OSError:
                    break
        assert p.wait(max(0.1, deadline - time.monotonic())) == 0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        os.close(master)
    report = p.stderr.read().decode(errors="replace")
    p.stderr.close()
    expected = ANSI16_STATUS["status-failure"] if ansi16 else "#ff5f5f"
    assert f"ansi16={ansi16} failure={expected}" in report


async def test_screen_keys_are_remappable():
    app = make_app(
        config=ConsoleConfig(keymap={"app.show_fleet": "f9", "alerts.ack_all": "ctrl+a"})
    )
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        assert app.model.keys.say("app.show_fleet") == "F9"  # what sentences name
        await pilot.press("f4")  # no longer bound
        await pilot.pause()
        assert app.screen is app.mission_screen
        await pilot.press("f9")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet on f9")
        await pilot.press("f6")
        await wait_until(pilot, lambda: isinstance(app.screen, AlertScreen), what="alerts")
        await pilot.press("ctrl+a")
        await wait_until(
            pilot, lambda: app.alerts.unacknowledged == 0, what="all acknowledged with ctrl+a"
        )


async def test_palette_offers_the_shown_screens_own_actions():
    from console.commands import MissionCommands

    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await awareness_scenario(app, pilot)
        await pilot.press("f5")
        await wait_until(pilot, lambda: isinstance(app.screen, EventLogScreen), what="log")
        titles = {str(h.display) for h in [h async for h in MissionCommands(app.screen).discover()]}
        assert {"Event log: Export", "Screen: Alerts", "Mission: Sync"} <= titles
        assert "Alerts: Ack all" not in titles  # that one belongs to the alert list
        await pilot.press("ctrl+p")
        await pilot.pause()
        await pilot.press(*"export")
        await wait_until(
            pilot, lambda: "Event log: Export" in screen_text(app), what="palette entry"
        )
        await pilot.press("enter")
        await wait_until(
            pilot, lambda: isinstance(app.screen, PathPrompt), what="export prompt from the palette"
        )


async def test_what_happened_while_reconnecting_raises_alerts():
    from console_state import MARS_FLEET, T0, fleet, mars_mid_execution, state_loaded

    from backend.protocol.messages import Alert

    # what the server raised meanwhile: its state snapshot repeats its last alerts
    missed = [
        Alert(
            id=1,
            level="error",
            kind="failure",
            robot="lru1",
            skill="lru1-2",
            message="lru1: lru1-2 failed: wheel stuck in sand",
            at=T0,
        ),
        Alert(id=2, kind="offline", robot="lru2", message="robot lru2 went offline", at=T0),
    ]
    robots = fleet({**MARS_FLEET, "lru2": False})
    b = mars_mid_execution()
    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await inject(app, pilot, b)  # the first state: ardea offline and failed already, not news
        assert app.bells == 0 and app.alerts.unacknowledged == 0
        # the console was away; meanwhile lru1's skill failed and lru2 went offline
        b.report("lru1", "lru1-2", "failure", "wheel stuck in sand")
        app.post_message(state_loaded(b.snapshot(), b.library, robots, alerts=missed))
        await wait_until(pilot, lambda: app.alerts.unacknowledged == 2, what="two alerts")
        kinds = {(a.kind, a.robot, a.skill) for a in app.alerts.alerts}
        assert kinds == {("failure", "lru1", "lru1-2"), ("offline", "lru2", None)}
        assert app.bells == 2
        assert any(
            e.kind == "failure" and "wheel stuck in sand" in e.text for e in app.event_log.entries
        )
        # the same state again (another resync): nothing new
        app.post_message(state_loaded(b.snapshot(), b.library, robots, alerts=missed))
        await pilot.pause()
        assert app.alerts.unacknowledged == 2 and app.bells == 2


async def test_an_unreadable_message_raises_one_alert_naming_its_key_and_field():
    """The client library reports a message it could not read (once per key);
    the model makes it an alert of the robot whose key it came on."""
    from console_state import incoming

    from backend.client.client import Malformed

    app = make_app()
    async with app.run_test(size=SIZE) as pilot:
        await inject(app, pilot, Builder(MARS))
        m = Malformed(
            "telemetry",
            "mc/v1/robot/lru1/telemetry",
            "battery: Input should be less than or equal to 1",
        )
        app.post_message(incoming(m))
        await wait_until(pilot, lambda: app.alerts.unacknowledged == 1, what="an alert")
        [a] = app.alerts.alerts
        assert (a.kind, a.robot, a.level) == ("malformed", "lru1", "warning")
        assert "mc/v1/robot/lru1/telemetry" in a.message and "battery:" in a.message
        await pilot.press("f6")
        await wait_until(pilot, lambda: isinstance(app.screen, AlertScreen), what="alert list")
        assert "unreadable message" in screen_text(app)
        # the same again (another client session, say): merged, not a second alert
        app.post_message(incoming(m))
        await pilot.pause()
        assert len(app.alerts.alerts) == 1
