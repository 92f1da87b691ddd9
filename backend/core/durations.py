"""Durations as people type them: 500ms, 90s, 20m, 1.5h, 2d; a bare number
is seconds. One reading for every option that takes one (ctl, server, sim)."""

from __future__ import annotations

import re
from collections.abc import Collection
from datetime import UTC, datetime

UNIT_S = {"ms": 0.001, "s": 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}
_DURATION = re.compile(r"^\s*([0-9]+(?:\.[0-9]+)?)\s*([a-z]+)?\s*$")


def duration_s(text: str, units: Collection[str] = UNIT_S.keys()) -> float | None:
    """Seconds, or None when `text` is not a duration in `units`."""
    m = _DURATION.match(text)
    if not m or (m.group(2) is not None and m.group(2) not in units):
        return None
    return float(m.group(1)) * UNIT_S[m.group(2) or "s"]


_CLOCK = re.compile(r"^(?:(\d+):)?(\d{1,2}):(\d{2})$")


def instant_s(text: str) -> float | None:
    """A mission-clock instant as people type it, or None: 'sim 2:00:00',
    '2:00:00', '90:00' and '2h' are sim seconds (a simulation's clock); an ISO
    date and time ('2030-07-01 14:32', UTC unless it says) POSIX seconds."""
    t = text.strip().lower().removeprefix("sim").strip()
    clock = _CLOCK.match(t)
    if clock is not None:
        h, m, sec = (int(g) if g else 0 for g in clock.groups())
        return float(h * 3600 + m * 60 + sec)
    seconds = duration_s(t)
    return seconds if seconds is not None else _posix(text.strip())


def _posix(text: str) -> float | None:
    try:
        at = datetime.fromisoformat(text.removesuffix("UTC").strip())
    except ValueError:
        return None
    return (at if at.tzinfo is not None else at.replace(tzinfo=UTC)).timestamp()
