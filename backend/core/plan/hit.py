"""What a plan check finds about one subject (backend.core.plan.checks)."""

from __future__ import annotations

from typing import NamedTuple


class Hit(NamedTuple):
    subject: str  # what the finding is about, in its id
    message: str
    robot: str | None = None
    skills: tuple[str, ...] = ()
