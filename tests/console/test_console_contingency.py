"""The editor's Contingency group and the rows' contingency marks."""

from __future__ import annotations

from console_state import TUTORIAL, Builder, engine_app, inject, screen_text, wait_until

from backend.core.model import Fallback, FallbackSkill, Goto, Policies, Taken

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
