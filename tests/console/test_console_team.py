"""The team in the console (issue 30): a robot that asks to join is
announced (fleet screen, alert) and added with one key; "give to…" lists
the robots ranked by the forecast and gives the skills; undo returns them."""

from __future__ import annotations

from console_state import (
    MARS,
    MARS_FLEET,
    T0,
    TUTORIAL,
    Builder,
    EngineBackend,
    alert_received,
    connection_changed,
    engine_app,
    fleet,
    fleet_changed,
    make_app,
    manifest,
    post_all,
    screen_text,
    settle,
    state_loaded,
    telemetry_changed,
    wait_until,
)

from backend.core.model import Pose
from backend.core.ops import AddRobot, AddSkill, Control, Reassign, RetireRobot
from backend.protocol.messages import Alert, OpReply, RobotInfo, Telemetry
from console.screens.dialogs import SkillPicker
from console.screens.fleet import FleetScreen
from console.screens.give_to import GiveToScreen
from console.state.team import gift, ranked

SIZE = (100, 30)


def _lru3(b: Builder) -> RobotInfo:
    skills = b.library.skills_of("lru_science")
    return RobotInfo(
        name="lru3",
        joining=True,
        since=T0,
        manifest=manifest("lru3", "lru_science", skills, {"nav": "2.1.0"}),
    )


def _announce(app, b: Builder) -> None:
    app.post_message(fleet_changed(_lru3(b)))
    alert = Alert(
        id=1,
        at=T0,
        kind="team",
        robot="lru3",
        message="robot lru3 (lru_science) asks to join the mission: add it with "
        "`missionctl ctl robots add lru3` or from the fleet screen",
    )
    app.post_message(alert_received(alert))


async def _load(app, pilot, b: Builder, online: dict[str, bool]) -> None:
    post_all(app, connection_changed("connected"))
    app.post_message(state_loaded(b.snapshot(), b.library, fleet(online)))
    await settle(pilot)


async def _joining_on_fleet(app, pilot, b: Builder) -> None:
    await _load(app, pilot, b, {"lru1": True, "lru2": True})
    _announce(app, b)
    await settle(pilot)
    await pilot.press("f4")
    await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
    await wait_until(pilot, lambda: "asks to join" in screen_text(app), what="announcement")


async def test_the_robot_added_stays_selected_where_the_fleet_order_puts_it():
    """Seen in the demo: lru3 (dynamic) moves above the static lander once added,
    and the selection used to stay on the row (the lander) instead of lru3."""
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=SIZE) as pilot:
        await _load(app, pilot, b, MARS_FLEET)
        _announce(app, b)
        await pilot.press("f4")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
        await wait_until(pilot, lambda: "asks to join" in screen_text(app), what="announcement")
        fleet_screen = app.screen
        assert fleet_screen.shown[-1] == "lru3"
        await pilot.press(*["down"] * len(fleet_screen.shown))
        assert fleet_screen.selected == "lru3"
        await pilot.press("insert")
        await wait_until(pilot, lambda: "lru3" in app.model.mission.robots, what="added")
        await settle(pilot)
        assert fleet_screen.shown.index("lru3") < fleet_screen.shown.index("lander")
        assert fleet_screen.selected == "lru3"
        assert "lru3  lru_science" in screen_text(app)  # its detail, not the lander's


async def test_the_selected_robot_stays_in_sight_when_its_detail_is_longer():
    """Seen in the demo walk at 80x24: selecting lru3 (last of 5) showed its long
    manifest, the table lost a row and lru3's row scrolled out of sight."""
    b = Builder(MARS)
    app, _ = engine_app(b)
    async with app.run_test(size=(80, 24)) as pilot:
        await _load(app, pilot, b, MARS_FLEET)
        _announce(app, b)
        # the sim's manifest: modules and properties take 6 lines at 80 columns
        sims = {"missionctl-sim": "0.1.0", "nav": "1.0.0", "science_camera": "1.0.0"}
        sims["stereo_camera"] = "1.0.0"
        props = dict(simulated=True, kind="rover", capabilities=["science_camera", "stereo"])
        props |= dict(max_speed_mps=1.0, sensor_range_m=10.0)
        props |= dict(metres_per_battery=350.0, camera_range_m=15.0, radio_range_m=0.0)
        skills = b.library.skills_of("lru_science")
        man = manifest("lru3", "lru_science", skills, sims, **props)
        app.post_message(fleet_changed(_lru3(b).model_copy(update={"manifest": man})))
        await pilot.press("f4")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
        await wait_until(pilot, lambda: _props(app, "lru3"), what="lru3's manifest")
        await pilot.press(*["down"] * len(app.screen.shown))
        assert app.screen.selected == "lru3"
        await settle(pilot)
        rows = [line for line in screen_text(app).splitlines() if line.startswith(" lru3  ")]
        assert any("✚ asks to join (lru_science)  lru_science" in r for r in rows)


def _props(app, robot: str) -> dict:
    info = app.model.robots.get(robot)
    return info.manifest.properties if info is not None and info.manifest else {}


def _retired_lru1() -> Builder:
    b = Builder(TUTORIAL)
    b.engine.submit(AddRobot(name="lru3", type="lru_science"))
    b.engine.submit(RetireRobot(name="lru1", reason="stopped responding"))
    return b


async def test_a_robot_that_asks_to_join_is_announced_and_added_with_one_key():
    b = Builder(TUTORIAL)
    app, backend = engine_app(b)
    async with app.run_test(size=SIZE) as pilot:
        await _joining_on_fleet(app, pilot, b)
        text = screen_text(app)
        assert "✚ lru3 asks to join (insert: add)" in text
        assert "✚ asks to join (lru_science)" in text
        assert app.model.alerts.unacknowledged >= 1  # the alert, on every console
        await pilot.press("insert")  # the only robot that asks: no need to select it
        await wait_until(pilot, lambda: "lru3" in app.model.mission.robots, what="added")
        assert backend.ops[-1] == AddRobot(name="lru3", type="lru_science")
        await pilot.press("f2")
        # its column appears on the schedule
        schedule = app.mission_screen.schedule
        await wait_until(
            pilot, lambda: "lru3" in [c.robot for c in schedule.columns], what="lru3's column"
        )


async def test_give_to_lists_robots_ranked_and_gives_a_retired_robots_plan():
    b = _retired_lru1()
    app, backend = engine_app(b)
    async with app.run_test(size=SIZE) as pilot:
        await _load(app, pilot, b, {"lru1": False, "lru2": True, "lru3": True})
        app.mission_screen.schedule.select("lru1-1")  # on the retired robot's column
        await pilot.press("G")
        await wait_until(pilot, lambda: isinstance(app.screen, GiveToScreen), what="give to")
        text = screen_text(app)
        assert "Give lru1's plan (2 skills: lru1-1, lru1-2) to…" in text
        assert "lru3" in text and "★ best" in text and "battery left" in text
        # lru2 could take the drive only: after lru3, saying why the other stays
        assert "lru1-2 stays: lru2 (lru_manipulator) has no skill" in text
        assert "takes 1 of 2, ends" in text  # lru2's row says how much it would take
        await pilot.press("enter")
        await wait_until(
            pilot,
            lambda: [s.id for s in app.model.task("lru3")] == ["lru1-1", "lru1-2"],
            what="given",
        )
        assert backend.ops[-1] == Reassign(from_robot="lru1", to="lru3")
        await pilot.press("ctrl+z")  # undo: back where they were
        await wait_until(
            pilot,
            lambda: [s.id for s in app.model.task("lru1")] == ["lru1-1", "lru1-2"],
            what="undone",
        )


async def test_give_to_says_why_when_no_robot_can_take_it():
    b = Builder(TUTORIAL)
    app, _ = engine_app(b)
    async with app.run_test(size=SIZE) as pilot:
        await _load(app, pilot, b, {"lru1": True})
        app.mission_screen.schedule.select("lru1-2")  # take_science_image: lru2 cannot
        await pilot.press("G")
        await wait_until(
            pilot, lambda: "no robot can take lru1-2" in screen_text(app), what="why not"
        )
        assert not isinstance(app.screen, GiveToScreen)


def _toasts(app, title: str) -> list[str]:
    return [n.message for n in app._notifications if n.title == title]


async def test_retire_and_give_to_say_their_notes_in_one_notification():
    """Two notes of one reply used to be two toasts of one title, folded into
    the last one with "(×2)": the first note was lost."""
    b = Builder(TUTORIAL)
    b.engine.submit(AddRobot(name="lru3", type="lru_science"))
    app, _ = engine_app(b)
    async with app.run_test(size=SIZE) as pilot:
        await _load(app, pilot, b, {"lru1": True, "lru2": True, "lru3": True})
        await pilot.press("f4")
        await wait_until(pilot, lambda: isinstance(app.screen, FleetScreen), what="fleet")
        app.clear_notifications()
        await pilot.press("ctrl+x")  # lru1, the first row
        await wait_until(pilot, lambda: "Retire lru1" in screen_text(app), what="the prompt")
        await pilot.press(*"broken", "enter")
        await wait_until(pilot, lambda: _toasts(app, "retire lru1"), what="the notes")
        (said,) = _toasts(app, "retire lru1")
        assert "lru1 retired: no new syncs" in said and "awaits reassignment" in said
        assert "(×" not in said
        await settle(pilot)
        # and no second one saying it went well (the fleet screen's "✓ retire lru1")
        assert [n.title for n in app._notifications] == ["retire lru1"]

        await pilot.press("f2")
        await wait_until(pilot, lambda: app.screen is app.mission_screen, what="schedule")
        app.clear_notifications()
        app.mission_screen.schedule.select("lru1-1")
        await pilot.press("G")
        await wait_until(pilot, lambda: isinstance(app.screen, GiveToScreen), what="give to")
        await pilot.press("down", "enter")  # lru2: it takes the drive, not the image
        what = "give lru1's plan (2 skills: lru1-1, lru1-2) to lru2"
        await wait_until(pilot, lambda: _toasts(app, what), what="the notes")
        (said,) = _toasts(app, what)
        assert "1 skill(s) given to lru2: lru1-1" in said and "lru1-2 stays:" in said
        assert "(×" not in said
        await settle(pilot)
        assert [n.title for n in app._notifications] == [what]  # the status line says it went


class _ControlNotes(EngineBackend):
    """Control through the rules, as the server does: its reply has the notes."""

    async def submit(self, op, *, expected_revision=None):
        if not isinstance(op, Control):
            return await super().submit(op, expected_revision=expected_revision)
        applied = self.b.engine.submit(op)
        self._post(applied)
        return OpReply(revision=applied.revision, value=applied.value, notes=applied.notes)


async def test_run_all_says_a_robot_it_did_not_reach_once():
    """The notes of "run all" were notified twice: by the operation service and
    again, note by note, as "run: partly applied" (folded "(×2)")."""
    b = Builder(TUTORIAL)
    backend = _ControlNotes(b)
    app = make_app(backend=backend)
    backend.app = app
    async with app.run_test(size=SIZE) as pilot:
        await _load(app, pilot, b, {"lru1": True, "lru2": True})
        b.sync("lru2")  # lru1 has nothing to run
        await _load(app, pilot, b, {"lru1": True, "lru2": True})
        app.clear_notifications()
        await pilot.press("R")
        await wait_until(pilot, lambda: app._notifications, what="the note")
        await settle(pilot)
        [n] = app._notifications
        assert n.title == "run all robots", n.message
        assert "lru1 has nothing to run" in n.message


async def test_give_to_says_how_long_each_robot_would_be_out_of_coverage():
    from plan_state import show_plan

    b = Builder(TUTORIAL)
    b.engine.submit(AddRobot(name="lru3", type="lru_science"))
    far = {"goal": {"x": 120.0, "y": -40.0}}  # the test map's coverage ends 60 m out
    sid = b.engine.submit(AddSkill(robot="lru1", skill="drive_to", params=far)).value["id"]
    app, _ = engine_app(b)
    here = [
        Telemetry(robot=r, pose=Pose(x=5.0, y=0.0), battery=0.9, at=T0) for r in ("lru2", "lru3")
    ]
    async with app.run_test(size=SIZE) as pilot:
        await show_plan(app, pilot, b, telemetry=here)
        app.mission_screen.schedule.select(sid)
        await pilot.press("G")
        await wait_until(pilot, lambda: isinstance(app.screen, GiveToScreen), what="give to")
        text = screen_text(app)
        assert "ranked: most taken, soonest end, least out of coverage" in text
        hints = {h.robot: h for h in ranked(app.model, gift(app.model, "lru1", sid, []))}
        out = hints["lru3"].out_of_coverage_s
        assert out is not None and out > 30  # about 70 of its 125 m, at 0.5 m/s
        shown = app.model.clock.duration_text(out)
        assert f"{shown} out of coverage" in text, text


async def test_the_add_skill_picker_ranks_the_robots_that_can_do_the_skill():
    """The allocation hint where a skill is added: ranked as ctl suggest ranks
    them (lru3 is free, lru1 has its plan first), and who cannot."""
    b = Builder(TUTORIAL)
    b.engine.submit(AddRobot(name="lru3", type="lru_science"))
    app, _ = engine_app(b)
    here = [
        Telemetry(robot=r, pose=Pose(x=0.0, y=0.0), battery=level, at=T0)
        for r, level in (("lru1", 0.5), ("lru2", 0.8), ("lru3", 0.7))
    ]
    async with app.run_test(size=SIZE) as pilot:
        await _load(app, pilot, b, {"lru1": False, "lru2": True, "lru3": True})
        for t in here:
            app.post_message(telemetry_changed(t))
        await settle(pilot)
        app.mission_screen.schedule.select("lru1-2")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, SkillPicker), what="picker")
        await pilot.press(*"science")
        who = app.screen.query_one("#who")
        await wait_until(pilot, lambda: "take_science_image:" in str(who.render()), what="hint")
        said = str(who.render())
        assert said.startswith("take_science_image: ★ lru3 ends ")
        assert "69% left · lru1 (here) (offline) ends " in said and said.endswith("cannot: lru2")
        # the same ranking as ctl suggest
        order = [h.robot for h in suggest_hints(app.model, "take_science_image")]
        assert order[:2] == ["lru3", "lru1"]
        await pilot.press("escape")


def suggest_hints(model, skill: str):
    from backend.core.plan.suggest import Manifests, suggest

    inputs = model.plan.inputs(model.telemetry, model.clock().timestamp())
    return suggest(model.mission, model.library, inputs, [skill], Manifests.of(model.robots))


# -- snapshots (deterministic: the app's clock at T0; each asserts real content first) ---------


def test_fleet_announces_a_robot_that_asks_to_join(snap_compare):
    b = Builder(TUTORIAL)
    app, _ = engine_app(b)

    async def run_before(pilot):
        await _joining_on_fleet(app, pilot, b)
        app.clear_notifications()
        await pilot.pause()
        assert "✚ asks to join (lru_science)" in screen_text(app)

    assert snap_compare(app, terminal_size=SIZE, run_before=run_before)


def test_give_to_dialog(snap_compare):
    b = _retired_lru1()
    app, _ = engine_app(b)

    async def run_before(pilot):
        await _load(app, pilot, b, {"lru1": False, "lru2": True, "lru3": True})
        app.mission_screen.schedule.select("lru1-1")
        await pilot.press("G")
        await wait_until(pilot, lambda: isinstance(app.screen, GiveToScreen), what="give to")
        app.clear_notifications()
        await pilot.pause()
        assert "★ best" in screen_text(app)

    assert snap_compare(app, terminal_size=SIZE, run_before=run_before)
