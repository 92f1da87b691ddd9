"""Announcing alerts: the bell and a notification for each new one (an
object the app owns, subscribed to the model's changes). What they are and
where they are listed is the model's (console/state/eventlog.py); the
mission screen says an error on its status line itself."""

from __future__ import annotations

from typing import Any

from console.state.changes import StateChange
from console.state.eventlog import toast_text


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
            if not c.notified:
                severity = {"error": "error", "warning": "warning"}.get(a.level, "information")
                title, text = toast_text(self.app.model.alerts, a)  # robots offline together: one
                timeout = 8 if a.level == "error" else 5
                self.app.notify(text, title=title, severity=severity, timeout=timeout)

    def ring(self) -> None:
        self.bells += 1
        self.app.bell()
