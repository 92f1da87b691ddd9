"""A robot's question in the console (issue 29): it comes as an alert and a
dialog naming robot, skill, text, the choices one key each and the default
with its countdown (mission time); a key answers (the operation goes to the
server); escape leaves it open, reachable again from the alerts screen, the
palette and the app's answer key; keys typed while it opens go to it; an
observer console cannot answer; the event log says what happened."""

from __future__ import annotations

from datetime import timedelta

from console_state import (
    T0,
    TUTORIAL,
    Builder,
    account_known,
    alert_received,
    applied_batch,
    connection_changed,
    engine_app,
    fleet,
    make_app,
    post_all,
    screen_text,
    settle,
    state_loaded,
    wait_until,
)

from backend.core import events as ev
from backend.core.model import QuestionState
from backend.core.ops import AnswerQuestion, Ask, AskEnded
from backend.protocol.messages import Alert
from console.screens.alerts import AlertScreen
from console.screens.dialogs import ConfirmScreen
from console.screens.question import QuestionScreen
from console.state.eventlog import EventLog

DUE = T0 + timedelta(minutes=5)


def asking() -> Builder:
    """lru2 runs identify_stone (lru2-2), which asks whether to search wider."""
    b = Builder(TUTORIAL)
    b.engine.clock = lambda: T0 + timedelta(seconds=20)  # as the console's, pinned
    b.sync("lru2")
    b.report("lru2", "lru2-1", "running")
    b.report("lru2", "lru2-1", "success")
    b.report("lru2", "lru2-2", "running")
    b.seqs["lru2"] += 1
    b.engine.submit(
        Ask(
            robot="lru2",
            seq=b.seqs["lru2"],
            ref="s-1",
            skill="lru2-2",
            text="Nothing found within 6 m of (10.0, 5.0): search wider (12 m)?",
            choices=["wider", "give up"],
            default="wider",
            timeout_s=300,
            at=T0,
            due=DUE,
        )
    )
    return b


def question_alert() -> Alert:
    return Alert(
        id=7,
        at=T0,
        kind="question",
        robot="lru2",
        skill="lru2-2",
        question=1,
        message="lru2 asks (question 1 (lru2, lru2-2)): Nothing found… — wider, give up",
    )


async def _asked(app, pilot, b: Builder) -> None:
    """The state with the question, then its alert: the dialog opens."""
    post_all(app, connection_changed("connected"))
    app.post_message(state_loaded(b.snapshot(), b.library, fleet({"lru1": True, "lru2": True})))
    await settle(pilot)
    app.post_message(alert_received(question_alert()))
    await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), what="the dialog")
    await settle(pilot)


async def test_a_question_opens_a_dialog_naming_everything_and_a_key_answers():
    b = asking()
    app, backend = engine_app(b)
    async with app.run_test(size=(100, 30)) as pilot:
        await _asked(app, pilot, b)
        text = screen_text(app)
        assert "Question #1 from lru2" in text
        assert "lru2-2 (identify_stone) asks" in text
        assert "search wider (12 m)?" in text
        assert " 1   wider  (default)" in text and " 2   give up" in text
        assert "default wider at 10:47:07, in 5m00s" in text  # the mission clock (wall: no sim)
        assert "escape: later" in text and "F9" in text
        assert app.model.alerts.alerts[-1].question == 1
        assert _toasts(app) == []  # the dialog says it: no toast over its countdown
        await pilot.press("2")
        await wait_until(pilot, lambda: backend.ops, what="the answer submitted")
        assert backend.ops[-1] == AnswerQuestion(question=1, choice="give up")
        await wait_until(pilot, lambda: not isinstance(app.screen, QuestionScreen), what="closed")
        await wait_until(
            pilot, lambda: app.model.mission.question(1).answer is not None, what="its batch"
        )
        q = app.model.mission.question(1)
        assert (q.answer, q.answered_by) == ("give up", "console") and q.is_open
        log = [e.text for e in app.model.log.entries]
        assert any("question #1 answered give up by console" in t for t in log)


def _toasts(app) -> list[str]:
    return [f"{n.title}: {n.message}" for n in app._notifications]


async def test_another_dialog_open_is_not_covered_a_toast_says_how_to_answer():
    b = asking()
    app, _ = engine_app(b)
    async with app.run_test(size=(100, 30)) as pilot:
        post_all(app, connection_changed("connected"))
        app.post_message(state_loaded(b.snapshot(), b.library, fleet({"lru2": True})))
        await settle(pilot)
        app.push_screen(ConfirmScreen("Delete it?"))
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), what="confirm")
        app.post_message(alert_received(question_alert()))
        await wait_until(pilot, lambda: _toasts(app), what="the note")
        assert isinstance(app.screen, ConfirmScreen)
        assert _toasts(app) == [
            "A robot asks: #1 from lru2: Nothing found within 6 m of (10.0, 5.0): "
            "search wider (12 m)? (F9: answer)"
        ]


async def test_later_leaves_it_open_and_it_is_reachable_again():
    b = asking()
    app, backend = engine_app(b)
    async with app.run_test(size=(100, 30)) as pilot:
        await _asked(app, pilot, b)
        await pilot.press("escape")
        await wait_until(pilot, lambda: not isinstance(app.screen, QuestionScreen), what="later")
        assert app.model.mission.question(1).is_open and backend.ops == []
        # the palette offers it
        from console.commands import MissionCommands

        hits = {
            str(h.display): h for h in [h async for h in MissionCommands(app.screen).discover()]
        }
        entry = hits["Answer question #1 from lru2…"]
        assert "search wider" in entry.help and "default wider" in entry.help
        # the app's answer key opens the oldest open one
        await pilot.press("f9")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), what="f9")
        await pilot.press("escape")
        # the alerts screen: the selected alert's question
        await pilot.press("f6")
        await wait_until(pilot, lambda: isinstance(app.screen, AlertScreen), what="alerts")
        assert "question" in screen_text(app) and "o: answer ·" in screen_text(app)
        await pilot.press("o")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), what="from alerts")
        await pilot.press("1")
        await wait_until(pilot, lambda: backend.ops, what="answered")
        assert backend.ops[-1] == AnswerQuestion(question=1, choice="wider")


async def test_keys_typed_as_it_opens_go_to_the_dialog():
    b = asking()
    app, backend = engine_app(b)
    async with app.run_test(size=(100, 30)) as pilot:
        post_all(app, connection_changed("connected"))
        app.post_message(state_loaded(b.snapshot(), b.library, fleet({"lru2": True})))
        await settle(pilot)
        await pilot.press("f9", "2")  # typed at once: the 2 waits for the dialog
        await wait_until(pilot, lambda: backend.ops, what="the answer")
        assert backend.ops == [AnswerQuestion(question=1, choice="give up")]
        assert app.mission_screen is not None and app.typeahead.dropped == 0


async def test_an_observer_sees_it_and_cannot_answer():
    b = asking()
    app = make_app(observer="a browser view")
    async with app.run_test(size=(100, 30)) as pilot:
        app.post_message(account_known())
        await _asked(app, pilot, b)
        assert "read-only (a browser view): this console cannot answer" in screen_text(app)
        await pilot.press("1")
        await settle(pilot)
        assert isinstance(app.screen, QuestionScreen)  # nothing was answered
        assert app.model.mission.question(1).answer is None


async def test_the_dialog_says_the_default_applied_and_keeps_a_late_key():
    b = asking()
    app, _ = engine_app(b)
    async with app.run_test(size=(100, 30)) as pilot:
        await _asked(app, pilot, b)
        b.seqs["lru2"] += 1
        ended = AskEnded(
            robot="lru2", seq=b.seqs["lru2"], ref="s-1", outcome="default", choice="wider", at=DUE
        )
        applied = b.engine.submit(ended, actor="lru2")
        app.post_message(applied_batch(applied.batch(actor="lru2", op="ask_ended")))
        await wait_until(pilot, lambda: "defaulted with wider" in screen_text(app), what="ended")
        assert app.model.mission.question(1).state == QuestionState.DEFAULTED
        assert "nothing to answer any more" in screen_text(app)
        # a choice key pressed as the question ends stays in the dialog: it neither
        # answers nor reaches the screen beneath (`2` there would open the map)
        await pilot.press("2")
        await settle(pilot)
        assert isinstance(app.screen, QuestionScreen)
        assert app.model.mission.question(1).answer is None
        await pilot.press("escape")
        await wait_until(pilot, lambda: not isinstance(app.screen, QuestionScreen), what="closed")
        log = [e.text for e in app.model.log.entries]
        assert any(
            "question #1 defaulted: no answer in time, the robot goes on with wider" in t
            for t in log
        )


def test_the_log_says_asked_answered_and_how_it_ended():
    b = asking()
    q = b.mission.question(1)
    log = EventLog()
    owner = {"lru2-2": "lru2"}.get
    batches = [
        ev.EventBatch(revision=30, events=[ev.QuestionAsked(question=q)], actor="lru2", op="ask"),
        ev.EventBatch(
            revision=31,
            events=[ev.QuestionAnswered(id=1, choice="give up", by="ann@c1", at=T0, command=4)],
            actor="ann@c1",
            op="answer_question",
        ),
        ev.EventBatch(
            revision=32,
            events=[ev.QuestionClosed(id=1, state=QuestionState.ANSWERED, choice="give up")],
            actor="lru2",
            op="answer",
        ),
    ]
    for batch in batches:
        log.add_batch(batch, owner, T0)
    asked, answered, closed = log.entries
    assert (
        asked.robots == ["lru2"] and "question #1 from lru2 (lru2-2): Nothing found" in asked.text
    )
    assert "[wider / give up; default wider]" in asked.text
    assert answered.text == "answer_question: question #1 answered give up by ann@c1 (command 4)"
    assert answered.user == "ann"
    assert closed.text == "answer: question #1 answered: the robot goes on with give up"


# -- snapshots (the app's clock at T0; each asserts real content first) -----------------------


def _snapshot(snap_compare, size: tuple[int, int]) -> None:
    b = asking()
    app, _ = engine_app(b)

    async def run_before(pilot):
        await _asked(app, pilot, b)
        app.clear_notifications()
        await settle(pilot)
        assert "search wider (12 m)?" in screen_text(app)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


def test_question_dialog_80x24(snap_compare):
    _snapshot(snap_compare, (80, 24))


def test_question_dialog_120x40(snap_compare):
    _snapshot(snap_compare, (120, 40))


def test_the_due_line_says_what_the_link_leaves_of_the_time():
    """Under a delay the on-board deadline alone promises too much: an answer
    must cross the link before it."""
    from console.state.clock import MissionClock
    from console.state.questions import due_text

    q = asking().engine.mission.question(1)
    clock = MissionClock(wall=lambda: T0 + timedelta(seconds=20))  # 4m40s before the default
    assert due_text(q, clock) == "default wider at 10:47:07, in 4m40s"
    assert due_text(q, clock, 0.2) == "default wider at 10:47:07, in 4m40s"  # a LAN's
    assert due_text(q, clock, 120) == (
        "default wider at 10:47:07, in 4m40s; answer within 2m40s (the link takes 2m00s)"
    )
    assert due_text(q, clock, 600) == (
        "default wider at 10:47:07, in 4m40s; an answer sent now arrives after it"
        " (the link takes 10m00s)"
    )
    late = MissionClock(wall=lambda: DUE + timedelta(seconds=1))
    assert due_text(q, late, 600) == "default wider applied on lru2 at 10:47:07 (not confirmed yet)"
