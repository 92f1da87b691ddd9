"""Notifications an operator can read at 80x24: one per situation, folded
when they pile up, without absolute file paths (an object the app owns: its
`notify` hands every notification to `NotificationFolder.notify`)."""

from __future__ import annotations

from typing import Any

from textual.notifications import Notification, SeverityLevel

from console.bindings import key_names

MAX_TOASTS = 3  # notifications on screen at once (at 80x24 more cover the schedule)


class NotificationFolder:
    def __init__(self, app: Any) -> None:
        self.app = app
        self._repeats: dict[str, int] = {}  # toast identity -> how many times it was said
        self._folded: tuple[str, int] = ("", 0)  # the "N more" toast: its identity and N

    def notify(
        self,
        message: str,
        *,
        title: str = "",
        severity: SeverityLevel = "information",
        timeout: float | None = None,
        markup: bool = True,
    ) -> None:
        """A toast (on the app's thread), but one per situation (the same
        title and severity replace the earlier toast, counted: "(×3)"), at
        most MAX_TOASTS on screen (the oldest fold into one "N more" toast:
        the alert list and the event log keep them all)."""
        app = self.app
        repeats = 1 + self._take_same(title, severity)
        others = [n for n in app._notifications if n.identity != self._folded[0]]
        if len(others) > MAX_TOASTS - 2:
            self._fold(others[: len(others) - (MAX_TOASTS - 2)])
        n = Notification(
            message + (f" (×{repeats})" if repeats > 1 else ""),
            title,
            severity,
            app.NOTIFICATION_TIMEOUT if timeout is None else timeout,
            markup=markup,
        )
        self._repeats[n.identity] = repeats
        app._notifications.add(n)
        app._refresh_notifications()

    def _take_same(self, title: str, severity: SeverityLevel) -> int:
        """Remove the toasts of this situation (title and severity; not the
        fold); how many times they had said it."""
        app = self.app
        said = 0
        for n in list(app._notifications):  # (iterating drops the expired ones)
            if n.title == title and n.severity == severity and n.identity != self._folded[0]:
                said += self._repeats.pop(n.identity, 1)
                app._unnotify(n, refresh=False)
        return said

    def _fold(self, oldest: list[Notification]) -> None:
        """Replace the oldest toasts (and an earlier fold) with one that counts them."""
        notes = self.app._notifications
        folded_id, count = self._folded
        if not any(n.identity == folded_id for n in notes):
            count = 0  # the earlier fold has expired
        for n in list(notes):
            if n.identity == folded_id or n in oldest:
                self.app._unnotify(n, refresh=False)
        count += len(oldest)
        rest = list(notes)  # shown after the fold (it is the oldest news)
        for n in rest:
            self.app._unnotify(n, refresh=False)
        keys = key_names(self.app)
        fold = Notification(
            f"{count} more — {keys.say('app.show_alerts')} lists the alerts, "
            f"{keys.say('app.show_log')} the event log",
            "Notifications folded",
            timeout=10,
        )
        self._folded = (fold.identity, count)
        notes.add(fold)
        for n in rest:
            notes.add(n)
