"""Notifications an operator can read at 80x24: one per situation, folded
when they pile up, without absolute file paths (mixed into the app)."""

from __future__ import annotations

import threading

from textual.app import App
from textual.notifications import Notification, SeverityLevel

from console.bindings import key_names
from console.state.text import without_paths

MAX_TOASTS = 3  # notifications on screen at once (at 80x24 more cover the schedule)


class FoldingNotifications(App[int]):
    def notify(
        self,
        message: str,
        *,
        title: str = "",
        severity: SeverityLevel = "information",
        timeout: float | None = None,
        markup: bool = True,
    ) -> None:
        """A toast, but one per situation (the same title and severity
        replace the earlier toast, counted: "(×3)"), at most MAX_TOASTS on
        screen (the oldest fold into one "N more" toast: the alert list and
        the event log keep them all), and no absolute file paths."""
        message, title = without_paths(str(message)), without_paths(title)
        if threading.get_ident() != self._thread_id:  # from another thread: as Textual does
            super().notify(message, title=title, severity=severity, timeout=timeout, markup=markup)
            return
        live = list(self._notifications)  # (iterating drops the expired ones)
        repeats = 1
        for n in live:
            if n.title == title and n.severity == severity and n.identity != self._folded[0]:
                repeats += self._repeats.pop(n.identity, 1)
                self._unnotify(n, refresh=False)
        others = [n for n in self._notifications if n.identity != self._folded[0]]
        if len(others) > MAX_TOASTS - 2:
            self._fold(others[: len(others) - (MAX_TOASTS - 2)])
        n = Notification(
            message + (f" (×{repeats})" if repeats > 1 else ""),
            title,
            severity,
            self.NOTIFICATION_TIMEOUT if timeout is None else timeout,
            markup=markup,
        )
        self._repeats[n.identity] = repeats
        self._notifications.add(n)
        self._refresh_notifications()

    def _fold(self, oldest: list[Notification]) -> None:
        """Replace the oldest toasts (and an earlier fold) with one that counts them."""
        folded_id, count = self._folded
        if not any(n.identity == folded_id for n in self._notifications):
            count = 0  # the earlier fold has expired
        for n in list(self._notifications):
            if n.identity == folded_id or n in oldest:
                self._unnotify(n, refresh=False)
        count += len(oldest)
        rest = list(self._notifications)  # shown after the fold (it is the oldest news)
        for n in rest:
            self._unnotify(n, refresh=False)
        keys = key_names(self)
        fold = Notification(
            f"{count} more — {keys.say('app.show_alerts')} lists the alerts, "
            f"{keys.say('app.show_log')} the event log",
            "Notifications folded",
            timeout=10,
        )
        self._folded = (fold.identity, count)
        self._notifications.add(fold)
        for n in rest:
            self._notifications.add(n)

    @property
    def _repeats(self) -> dict[str, int]:
        """Toast identity -> how many times it was said."""
        if not hasattr(self, "_repeat_counts"):
            self._repeat_counts: dict[str, int] = {}
        return self._repeat_counts

    @property
    def _folded(self) -> tuple[str, int]:
        """The "N more" toast: its identity and N."""
        return getattr(self, "_fold_state", ("", 0))

    @_folded.setter
    def _folded(self, value: tuple[str, int]) -> None:
        self._fold_state = value
