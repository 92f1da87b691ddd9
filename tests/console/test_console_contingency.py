"""The editor's Contingency group and the rows' contingency marks."""

from __future__ import annotations

from console_state import MARS, TUTORIAL, Builder, engine_app, inject, screen_text, wait_until

from backend.core.model import Fallback, FallbackSkill, Goto, Policies, Taken
from backend.core.ops import EditBarrier, EditSkill

WIDE = (150, 42)


def shows(editor, sid: str) -> bool:
    return editor.skill_id == sid and not editor.loading


async def test_contingency_is_typed_in_the_editor_and_marked_on_the_row():
    b = Builder(TUTORIAL)
    # a fallback with a bound marker: its parameters are not in the text, and stay
    keep = Fallback(fallback=[FallbackSkill(skill="drive_to", bindings={"goal": "POI-A"})])
    b.mission.find("lru2-2")[2].policies = Policies(on_failure=keep)
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        screen.schedule.select("lru2-1")
        await wait_until(pilot, lambda: shows(screen.editor, "lru2-1"), what="lru2-1 shown")
        ed = screen.editor
        ed.scroll_end(animate=False, immediate=True)
        await pilot.pause()
        assert "Contingency — decided on board" in screen_text(app)
        ed.query_one("#pf-timeout").value = "soon"
        ed.query_one("#pf-on_failure").value = "retry"
        await pilot.pause()
        assert "expected a mission-time duration" in str(ed.query_one("#perr-timeout").render())
        assert "goto:MARKER" in str(ed.query_one("#perr-on_failure").render())
        ed.action_apply()
        await pilot.pause()
        assert backend.ops == []  # nothing sent while invalid
        ed.query_one("#pf-timeout").value = "10m"
        ed.query_one("#pf-on_timeout").value = "skip"
        ed.query_one("#pf-on_failure").value = "goto:POI-A"
        await pilot.pause()
        ed.action_apply()
        want = Policies(timeout=600, on_timeout="skip", on_failure=Goto(goto="POI-A"))
        await wait_until(
            pilot, lambda: b.mission.find("lru2-1")[2].policies == want, what="applied"
        )
        await wait_until(pilot, lambda: "⏱10m→skip ✗…" in screen_text(app), what="row marks")
        assert "✗→drive_to@POI-A" in screen_text(app)  # lru2-2's fallback
        # editing lru2-2's timeout keeps its fallback whole
        screen.schedule.select("lru2-2")
        await wait_until(pilot, lambda: shows(ed, "lru2-2"), what="lru2-2 shown")
        assert ed.query_one("#pf-on_failure").value == "fallback:drive_to"
        ed.query_one("#pf-timeout").value = "1h"
        await pilot.pause()
        ed.action_apply()
        await wait_until(
            pilot,
            lambda: b.mission.find("lru2-2")[2].policies == Policies(timeout=3600, on_failure=keep),
            what="timeout added, fallback kept",
        )


def test_the_branch_taken_is_on_the_failed_row():
    from console.state.text import policy_marks

    s = Builder(TUTORIAL).mission.find("lru1-1")[2]
    s.policies = Policies(timeout="30s", on_timeout="skip")
    s.branch = Taken(trigger="timeout", branch="skip", reason="out of time after 30s")
    assert policy_marks(s) == ["⏱30s→skip"]


def _lru2_waits_for_the_lander() -> Builder:
    """lru2-1 starts only after lander-1 (policies.after), synchronized and
    waiting on board: its robot said what for."""
    b = Builder(MARS)
    b.engine.submit(EditSkill(id="lru2-1", policies=Policies(after="lander-1")))
    b.sync("lru2", "lru2-1")
    b.report("lru2", "lru2-1", "synchwaiting", "after lander-1 on lander: idle_synchronized")
    return b


async def test_both_rows_of_an_after_carry_its_tag_and_the_waiter_says_the_partner_is_off():
    b = _lru2_waits_for_the_lander()
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True, "ardea": True})
        text = screen_text(app)
        assert "⇠lander-1" in text  # the waiting row
        assert "⇢lru2-1" in text  # the awaited row, in the lander's column
        assert "after lander-1: lander …" in text  # OFFLINE, cut at this width
        assert "◷ lru2-1 after lander-1" in text  # the header: not "at barrier"
        # another robot's edit changes the awaited row's tag (in the lander's column)
        await backend.submit(EditSkill(id="lru2-2", policies=Policies(after="lander-1")))
        await wait_until(pilot, lambda: "⇢lru2-1+1" in screen_text(app), what="two wait")
        await backend.submit(EditSkill(id="lru2-2", policies=Policies()))
        await wait_until(pilot, lambda: "⇢lru2-1+1" not in screen_text(app), what="one waits")
        assert "⇢lru2-1" in screen_text(app)


def test_the_wait_for_an_after_says_what_the_ground_knows():
    from backend.protocol.messages import RobotInfo
    from console.state.model import ConsoleModel
    from console.widgets.schedule.lines import after_wait_text

    b = _lru2_waits_for_the_lander()
    m = ConsoleModel(mission=b.snapshot(), library=b.library)
    m.reindex()
    s = m.find("lru2-1")[2]
    assert after_wait_text(m, s) == "after lander-1: lander OFFLINE"
    m.robots["lander"] = RobotInfo(name="lander", online=True)
    assert after_wait_text(m, s) == "after lander-1: waiting for lander (idle)"
    s.status_info = "after lander-1 on lander: lander unreachable"  # the robot's own words
    assert after_wait_text(m, s) == s.status_info


def test_snapshot_an_after_waiting_for_an_offline_robot(snap_compare):
    """Both rows' tags, the waiter's line and header, at 120x40."""
    from console_state import make_app

    b = _lru2_waits_for_the_lander()

    async def run_before(pilot):
        await inject(pilot.app, pilot, b, online={"lru1": True, "lru2": True, "ardea": True})
        pilot.app.mission_screen.schedule.select("lander-1")
        await pilot.pause()
        text = screen_text(pilot.app)
        assert "⇢lru2-1" in text and "⇠lander-1" in text, text

    assert snap_compare(make_app(), terminal_size=(120, 40), run_before=run_before)


async def test_not_after_shows_and_reads_as_a_mission_clock_time():
    b = Builder(TUTORIAL)
    b.mission.find("lru2-1")[2].policies = Policies(not_after=5400, on_timeout="skip")
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await inject(app, pilot, b, online={"lru1": True, "lru2": True})
        screen = app.mission_screen
        await wait_until(pilot, lambda: "⏱≤sim 1:30:…" in screen_text(app), what="row mark")
        screen.schedule.select("lru2-1")
        await wait_until(pilot, lambda: shows(screen.editor, "lru2-1"), what="lru2-1 shown")
        ed = screen.editor
        assert ed.query_one("#pf-not_after").value == "sim 1:30:00"  # an instant, not "90m"
        ed.query_one("#pf-not_after").value = "at noon"
        await wait_until(
            pilot,
            lambda: "mission-clock time" in _shown(ed, "#perr-not_after"),
            what="the field says what it takes",
        )
        ed.query_one("#pf-not_after").value = "sim 2:00:00"
        await pilot.pause()
        ed.action_apply()
        await wait_until(
            pilot, lambda: b.mission.find("lru2-1")[2].policies.not_after == 7200, what="applied"
        )
        await wait_until(pilot, lambda: _value(ed, "#pf-not_after") == "sim 2:00:00", what="shown")


def _value(ed, selector: str) -> str:
    """A field's value ('' while the editor recomposes after an apply)."""
    found = ed.query(selector)
    return found.first().value if found else ""


def _shown(ed, selector: str) -> str:
    found = ed.query(selector)
    return str(found.first().render()) if found else ""


async def _open_barrier_wait(pilot, app, b) -> None:
    from console.screens.barrier_wait import BarrierWaitPrompt

    await inject(app, pilot, b, online={"lru1": True, "lru2": True, "ardea": True})
    app.mission_screen.schedule.select("lru2-3")  # a skill of barrier b1, nothing marked
    await pilot.pause()
    app.mission_screen.action_barrier()
    await wait_until(
        pilot,
        lambda: isinstance(app.screen, BarrierWaitPrompt) and "Barrier b1" in screen_text(app),
        what="the prompt",
    )


async def test_the_barrier_action_sets_how_long_a_barrier_waits():
    b = Builder(MARS)
    app, backend = engine_app(b)
    async with app.run_test(size=WIDE) as pilot:
        await _open_barrier_wait(pilot, app, b)
        assert "Barrier b1 (lru1-3, lru2-3)" in screen_text(app)
        app.screen.query_one("#timeout").value = "soon"
        await pilot.press("enter")
        assert "mission-time duration" in _shown(app.screen, "#error")  # still open, says why
        app.screen.query_one("#timeout").value = "10m"
        app.screen.query_one("#then").value = "continue"
        await pilot.pause()
        app.screen.query_one("#timeout").focus()
        await pilot.press("enter")
        await wait_until(
            pilot,
            lambda: (
                (b.mission.barriers["b1"].timeout, b.mission.barriers["b1"].on_timeout)
                == (600, "continue")
            ),
            what="applied",
        )
        await wait_until(
            pilot, lambda: "b1 waits 10m, then continue" in screen_text(app), what="said"
        )


def test_a_barrier_whose_skill_is_synchronized_keeps_its_wait():
    from console.state.availability import why_not
    from console.state.model import ConsoleModel

    b = Builder(MARS)
    b.sync("lru1", "lru1-3")
    m = ConsoleModel(mission=b.snapshot(), library=b.library, connection="connected")
    m.reindex()
    why = why_not(m, "barrier", "lru2", "lru2-3")
    assert why is not None and "barrier b1's wait changes only while its skills are idle" in why
    assert why_not(m, "barrier", "lru2", "lru2-4") is not None  # in no barrier, nothing marked


def test_snapshot_the_barrier_wait_prompt(snap_compare):
    from console_state import make_app

    b = Builder(MARS)
    b.engine.submit(EditBarrier(barrier="b1", timeout=300, on_timeout="continue"))

    async def run_before(pilot):
        await _open_barrier_wait(pilot, pilot.app, b)
        assert "how long does each robot wait" in screen_text(pilot.app)

    assert snap_compare(make_app(), terminal_size=(100, 30), run_before=run_before)
