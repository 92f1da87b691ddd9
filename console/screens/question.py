"""A robot's question (issue 29): a dialog naming robot and skill, the text,
the choices one key each, the default and when it applies on board (the
mission clock, counting down). A choice key answers (dismissed with the
choice); escape leaves the question open: it stays reachable from the
alerts screen, the palette and the app's answer key. Once the question
ended (answered elsewhere, its default applied) the dialog says how and
stays until escape: a choice key pressed as it ends must not fall through
to the screen beneath. An observer console shows it and cannot answer.

`open_question(app, id)` opens it in a worker and submits the answer; the
app, its alert prompter and the palette call it (screens never import the app)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.signal import Signal
from textual.widgets import Static

from backend.core.model import Question
from backend.core.ops import AnswerQuestion
from console.bindings import bind, key_names
from console.state.changes import StateChange, Topic
from console.state.link import robot_delay_s
from console.state.model import ConsoleModel
from console.state.questions import answer_text, due_text, ended_text, not_open_text, pick

TCSS = Path(__file__).with_name("question.tcss")
TICK_S = 1.0  # the countdown's step (wall seconds)


def choice_keys(keys: Any) -> list[str]:
    """The keys of the choices, in order (the actions table's `dialog.choose`)."""
    return [k.strip() for k in keys.keys("dialog.choose").split(",") if k.strip()]


class QuestionScreen(ModalScreen[str | None]):
    """One question; dismissed with the chosen choice, or None (later)."""

    CSS_PATH = TCSS
    BINDINGS = [bind("dialog.cancel", "later")]

    def __init__(self, question: Question, model: ConsoleModel, changes: Signal[StateChange]):
        super().__init__()
        self.question = question
        self.model = model
        self.changes = changes
        self.keys = choice_keys(model.keys)[: len(question.choices)]
        for n, key in enumerate(self.keys):
            self._bindings.bind(key, f"choose({n})", show=False, priority=True)

    def compose(self) -> ComposeResult:
        q = self.question
        with Vertical():
            yield Static(Text(f"Question #{q.id} from {q.robot}", style="bold"), classes="head")
            yield Static(self._skill_line(), classes="skill")
            yield Static(q.text, classes="text")
            yield Static(self._choices(), id="choices")
            yield Static(self._due_line(), id="due")
            yield _shown(self._answer_line(), id="answered")
            yield _shown(self._read_only_line(), id="read-only", classes="warning")
            yield Static(self._hint(), classes="hint")

    def _due_line(self) -> str:
        """When the default applies, and what of it the link leaves an answer."""
        delay = robot_delay_s(self.model.robots, self.question.robot)
        return due_text(self.question, self.model.clock, delay)

    def _skill_line(self) -> str:
        q = self.question
        found = self.model.find(q.skill)
        what = f" ({found[2].skill})" if found is not None else ""
        return f"{q.skill}{what} asks; it waits on board for the answer"

    def _choices(self) -> Text:
        q = self.question
        text = Text()
        for key, choice in zip(self.keys, q.choices, strict=False):
            text.append(f" {key} ", style="reverse bold")
            text.append(f"  {choice}")
            text.append("  (default)\n" if choice == q.default else "\n", style="dim")
        return text

    def _answer_line(self) -> str:
        m = self.model.mission
        return answer_text(self.question, m, self.model.clock) if m is not None else ""

    def _read_only_line(self) -> str:
        ro = self.model.read_only
        return f"read-only ({ro}): this console cannot answer" if ro else ""

    def _hint(self) -> str:
        keys = key_names(self)
        first, last = self.keys[0], self.keys[-1]
        later = keys.hint(("dialog.cancel", "later (it stays open"))
        return f"{first}–{last}: answer · {later}: alerts, palette or {keys.say('app.answer')})"

    def on_mount(self) -> None:
        self.changes.subscribe(self, self._changed)
        self.set_interval(TICK_S, self._tick)

    def _tick(self) -> None:
        if self.question.is_open:
            self.query_one("#due", Static).update(self._due_line())

    def _changed(self, c: StateChange) -> None:
        m = self.model.mission
        if not c.about(Topic.MISSION) or m is None or not self.question.is_open:
            return
        q = m.question(self.question.id)
        if q is None:  # a mission loaded without it
            self.dismiss(None)
            return
        self.question = q
        if not q.is_open:  # answered elsewhere, defaulted, withdrawn
            self._ended()
            return
        answered = self.query_one("#answered", Static)
        answered.update(self._answer_line())
        answered.display = bool(self._answer_line())

    def _ended(self) -> None:
        """Say how the question ended; the choices no longer answer."""
        self.query_one("#choices", Static).add_class("ended")
        self.query_one("#due", Static).update(ended_text(self.question))
        self.query_one("#answered", Static).display = False
        close = key_names(self).hint(("dialog.cancel", "close"))
        self.query_one(".hint", Static).update(f"nothing to answer any more · {close}")

    def action_choose(self, n: int) -> None:
        if not self.question.is_open:
            self.notify(ended_text(self.question), title="Question")
            return
        if self.model.read_only:
            self.notify(self._read_only_line(), severity="warning", title="Question")
            return
        self.dismiss(self.question.choices[n])

    def action_later(self) -> None:
        self.dismiss(None)


def _shown(text: str, **kw: Any) -> Static:
    """A line shown only when it says something."""
    line = Static(text, **kw)
    line.display = bool(text)
    return line


def open_question(app: Any, question_id: int | None = None, *, auto: bool = False) -> None:
    """Open a question's dialog (None: the oldest open one) and submit its
    answer, in a dialog worker (what keys typed meanwhile wait for). `auto`:
    a question just asked; another dialog open is not covered (a note says
    how to answer it)."""
    app.run_worker(_answer(app, question_id, auto), group="dialog")


async def _answer(app: Any, question_id: int | None, auto: bool) -> None:
    model = app.model
    q = pick(model.mission, question_id)
    if q is None:
        if not auto:
            app.notify(not_open_text(model.mission, question_id), title="Question")
        return
    if isinstance(app.screen, ModalScreen):
        if auto or isinstance(app.screen, QuestionScreen):
            later = key_names(app).say("app.answer")
            app.notify(f"#{q.id} from {q.robot}: {q.text} ({later}: answer)", title="A robot asks")
            return
    choice = await app.push_screen_wait(QuestionScreen(q, model, app.changes))
    if choice is None:
        return
    await app.ops.submit(
        AnswerQuestion(question=q.id, choice=choice),
        f"answer question #{q.id} of {q.robot}: {choice}",
        robot=q.robot,
        skill=q.skill,
    )
