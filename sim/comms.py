"""The ground link's schedule in sim time: a one-way delay and comms windows.

`--link-delay 20m` and `--comms-window 20m/2h` are sim time, like everything
the simulator does, so a Mars-like link (minutes one way, a relay orbiter
overhead 20 minutes every 2 hours) plays at sim speed: at `--speed 60` a
20-minute delay is 20 s of wall time. Out of a window no robot can reach the
ground nor the ground a robot: commands stay queued (or sent) on the server,
reports wait in the robots' outboxes, the map feed waits aboard.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from functools import cached_property

from backend.core.contact import ContactWindows, RepeatingWindow
from backend.core.durations import duration_s

SIM_UNITS = ("ms", "s", "m", "min", "h")

DURATION_EXAMPLES = "500ms, 2s, 90s, 20m, 1.5h; a bare number is seconds"


def parse_duration(text: str) -> float:
    """'500ms', '90s', '20m', '1.5h', '2' (seconds) -> seconds (argparse `type`)."""
    seconds = duration_s(text, SIM_UNITS)
    if seconds is None:
        raise argparse.ArgumentTypeError(
            f"not a duration: {text!r} (examples: {DURATION_EXAMPLES})"
        )
    return seconds


@dataclass(frozen=True)
class CommsWindow:
    """Contact for `open_s` at the start of every `period_s` (sim seconds),
    from sim time `offset_s` on: the window is open at sim time 0 unless an
    offset puts the first one later."""

    open_s: float
    period_s: float
    offset_s: float = 0.0

    @cached_property
    def windows(self) -> ContactWindows:
        """As the ground computes contact (backend.core.contact): one reading
        of a window for the robots and for the server."""
        return ContactWindows(
            repeating=RepeatingWindow(
                open_s=self.open_s, period_s=self.period_s, offset_s=self.offset_s
            )
        )

    def is_open(self, sim_t: float) -> bool:
        return self.windows.is_open(sim_t)

    def next_change(self, sim_t: float) -> float:
        """The sim time at which the window next opens or closes."""
        w = self.windows
        change = w.closes_at(sim_t) if w.is_open(sim_t) else w.next_opening(sim_t)
        assert change is not None  # a repeating window always closes and opens again
        return change

    def describe(self) -> str:
        first = f", the first at {_show(self.offset_s)}" if self.offset_s else ""
        return f"{_show(self.open_s)} of contact every {_show(self.period_s)} (sim time{first})"


WINDOW_SYNTAX = "OPEN/PERIOD[@OFFSET], e.g. 20m/2h (20 min of contact every 2 h) or 20m/2h@1h"


def parse_window(text: str) -> CommsWindow:
    """'20m/2h' or '20m/2h@30m' -> CommsWindow (argparse `type`)."""
    head, _, offset = text.partition("@")
    opened, slash, period = head.partition("/")
    if not slash:
        raise argparse.ArgumentTypeError(f"not a comms window: {text!r} ({WINDOW_SYNTAX})")
    try:
        w = CommsWindow(
            open_s=parse_duration(opened),
            period_s=parse_duration(period),
            offset_s=parse_duration(offset) if offset else 0.0,
        )
    except argparse.ArgumentTypeError as e:
        raise argparse.ArgumentTypeError(f"comms window {text!r}: {e} ({WINDOW_SYNTAX})") from None
    if not 0 < w.open_s < w.period_s:
        raise argparse.ArgumentTypeError(
            f"comms window {text!r}: the contact ({_show(w.open_s)}) must be longer than 0 and "
            f"shorter than the period ({_show(w.period_s)})"
        )
    return w


def _show(seconds: float) -> str:
    for unit, size in (("h", 3600.0), ("min", 60.0)):
        if seconds >= size and (seconds / size) == round(seconds / size, 2):
            return f"{seconds / size:g} {unit}"
    return f"{seconds:g} s"
