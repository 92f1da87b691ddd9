"""Durations as people type them: 500ms, 90s, 20m, 1.5h, 2d; a bare number
is seconds. One reading for every option that takes one (ctl, server, sim)."""

from __future__ import annotations

import re
from collections.abc import Collection

UNIT_S = {"ms": 0.001, "s": 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}
_DURATION = re.compile(r"^\s*([0-9]+(?:\.[0-9]+)?)\s*([a-z]+)?\s*$")


def duration_s(text: str, units: Collection[str] = UNIT_S.keys()) -> float | None:
    """Seconds, or None when `text` is not a duration in `units`."""
    m = _DURATION.match(text)
    if not m or (m.group(2) is not None and m.group(2) not in units):
        return None
    return float(m.group(1)) * UNIT_S[m.group(2) or "s"]
