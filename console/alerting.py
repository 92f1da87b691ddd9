"""Announcing alerts: the bell and a notification for each new one, and the
prompt of a robot's question (objects the app owns, subscribed to the
model's changes). What they are and where they are listed is the model's
(console/state/eventlog.py); the mission screen says an error on its status
line itself."""

from __future__ import annotations

from typing import Any

from console.screens.question import open_question
from console.state.changes import StateChange, Topic
from console.state.eventlog import AlertEntry, toast_text


def prompted(a: AlertEntry) -> bool:
    """A robot asks: its dialog says it (or, another dialog open, the
    prompter's note), not a toast over the dialog's countdown. How a
    question ended (level info) is a toast."""
    return a.kind == "question" and a.level != "info"


class AlertAnnouncer:
    def __init__(self, app: Any) -> None:
        self.app = app
        self.bells = 0  # how often the bell rang (tests)

    def start(self, changes: Any) -> None:
        changes.subscribe(self.app, self._changed)

    def _changed(self, c: StateChange) -> None:
        for a in c.alerts:
            if a.level != "info":
                self.ring()
            if not c.notified and not prompted(a):
                self._toast(a)

    def _toast(self, a: AlertEntry) -> None:
        severity = {"error": "error", "warning": "warning"}.get(a.level, "information")
        title, text = toast_text(self.app.model.alerts, a)  # robots offline together: one
        timeout = 8 if a.level == "error" else 5
        self.app.notify(text, title=title, severity=severity, timeout=timeout)

    def ring(self) -> None:
        self.bells += 1
        self.app.bell()


class QuestionPrompter:
    """A robot asks (a `question` alert): its dialog opens on this console,
    once the question is in the mirror (the alert and the event batch that
    opened it come on different keys: either may be first)."""

    def __init__(self, app: Any) -> None:
        self.app = app
        self.waiting: list[int] = []  # alerted questions not in the mirror yet

    def start(self, changes: Any) -> None:
        changes.subscribe(self.app, self._changed)

    def _changed(self, c: StateChange) -> None:
        self.waiting += [a.question for a in c.alerts if a.kind == "question" and a.question]
        if self.waiting and (c.about(Topic.ALERTS) or c.about(Topic.MISSION)):
            self._prompt()

    def _prompt(self) -> None:
        m = self.app.model.mission
        for qid in list(self.waiting):
            q = m.question(qid) if m is not None else None
            if q is None:
                continue  # its batch is still on its way
            self.waiting.remove(qid)
            if q.is_open:
                open_question(self.app, qid, auto=True)
