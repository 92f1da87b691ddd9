"""A robot's contact with the ground: its windows -> its contact state at an instant.

Times are mission time, in seconds on one clock: the simulator's (sim
seconds since it started) when a simulator gives the windows, the wall's
(POSIX seconds, UTC) when a deployment's file does. A window is open from
its start (included) to its end (excluded). A repeating window repeats every
period before and after its offset, exactly as the simulator's
`--comms-window` does (sim/comms.py), so the ground's view and the robots'
agree. No windows at all: always in contact. No presence: offline, whatever
the windows say.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Final, Literal

from pydantic import AwareDatetime, BeforeValidator, Field, model_validator

from backend.core.durations import duration_s
from backend.core.model import Name, Strict

ContactStateName = Literal["in_contact", "out_of_contact", "offline"]
IN_CONTACT: Final = "in_contact"
OUT_OF_CONTACT: Final = "out_of_contact"
OFFLINE: Final = "offline"

MAX_PASSES = 10_000  # declared passes per robot (a year of 20-minute passes every hour)
_MERGE_STEPS = 1_000  # overlapping windows followed to find where the contact ends


class RepeatingWindow(Strict):
    """Contact for `open_s` at the start of every `period_s`, the periods
    aligned on `offset_s` (seconds of mission time; repeats both ways)."""

    open_s: float = Field(gt=0, description="how long each window lasts (s)")
    period_s: float = Field(gt=0, description="from one window's opening to the next (s)")
    offset_s: float = Field(0.0, description="a mission time at which a window opens")

    @model_validator(mode="after")
    def _shorter_than_period(self) -> RepeatingWindow:
        if self.open_s >= self.period_s:
            raise ValueError(
                f"a window ({self.open_s:g} s) must be shorter than its period "
                f"({self.period_s:g} s); for contact all the time declare no windows"
            )
        return self

    def window_at(self, t: float) -> tuple[float, float]:
        """The window of the period holding `t`: (start, end), open or not at `t`."""
        start = t - (t - self.offset_s) % self.period_s
        return start, start + self.open_s


class ContactPass(Strict):
    """One window: contact from `start` (included) to `end` (excluded)."""

    start: float
    end: float

    @model_validator(mode="after")
    def _ends_after_start(self) -> ContactPass:
        if self.end <= self.start:
            raise ValueError("a pass must end after it starts")
        return self


class ContactWindows(Strict):
    """A robot's windows: a repeating one, single passes, or both (their union)."""

    repeating: RepeatingWindow | None = None
    passes: list[ContactPass] = Field(default_factory=list, max_length=MAX_PASSES)

    @property
    def always(self) -> bool:
        """No windows declared: the robot is always in contact."""
        return self.repeating is None and not self.passes

    def _open(self, t: float) -> list[tuple[float, float]]:
        """The windows open at `t`."""
        found = [(p.start, p.end) for p in self.passes if p.start <= t < p.end]
        if self.repeating is not None:
            start, end = self.repeating.window_at(t)
            if t < end:
                found.append((start, end))
        return found

    def is_open(self, t: float) -> bool:
        return self.always or bool(self._open(t))

    def next_opening(self, t: float) -> float | None:
        """The first window start after `t` (None: no window ahead)."""
        starts = [p.start for p in self.passes if p.start > t]
        if self.repeating is not None:
            start, _ = self.repeating.window_at(t)
            starts.append(start if start > t else start + self.repeating.period_s)
        return min(starts, default=None)

    def closes_at(self, t: float) -> float | None:
        """When the contact open at `t` ends, across overlapping windows
        (None: not open at `t`, or no windows: never closes)."""
        open_now = self._open(t)
        if not open_now:
            return None
        end = max(e for _, e in open_now)
        for _ in range(_MERGE_STEPS):
            later = self._open(end)
            further = max((e for _, e in later), default=end)
            if further <= end:
                break
            end = further
        return end


class Contact(Strict):
    """A robot's contact state at an instant (times: mission time, s)."""

    state: ContactStateName = Field(
        description="in_contact; out_of_contact (it is present, its window is closed); "
        "offline (no presence)"
    )
    next_contact: float | None = Field(
        None, description="out of contact: when the next window opens (None: no window ahead)"
    )
    closes: float | None = Field(
        None, description="in contact: when its window closes (None: it does not)"
    )


def contact_at(windows: ContactWindows | None, t: float, *, present: bool) -> Contact:
    """The contact state of a robot at mission time `t`; offline wins."""
    if not present:
        return Contact(state=OFFLINE)
    if windows is None or windows.always:
        return Contact(state=IN_CONTACT)
    if windows.is_open(t):
        return Contact(state=IN_CONTACT, closes=windows.closes_at(t))
    return Contact(state=OUT_OF_CONTACT, next_contact=windows.next_opening(t))


# ---------------------------------------------------------------- the deployment's file

CONTACT_FORMAT = "missionctl/contact-windows@1"
DURATION_HELP = "a duration: 500ms, 90s, 20m, 1.5h, 2d (a bare number is seconds)"


def _duration(value: Any) -> Any:
    if isinstance(value, str):
        seconds = duration_s(value)
        if seconds is None:
            raise ValueError(f"not {DURATION_HELP}")
        return seconds
    return value


Duration = Annotated[float, BeforeValidator(_duration), Field(gt=0, description=DURATION_HELP)]


class DeclaredRepeating(Strict):
    """`open` of contact every `every`, one of the windows opening at `first`."""

    open: Duration
    every: Duration
    first: AwareDatetime = Field(description="when one of the windows opens (with its zone)")

    @model_validator(mode="after")
    def _shorter_than_period(self) -> DeclaredRepeating:
        if self.open >= self.every:
            raise ValueError(
                f"open ({self.open:g} s) must be shorter than every ({self.every:g} s); "
                "for contact all the time list no windows for the robot"
            )
        return self


class DeclaredPass(Strict):
    start: AwareDatetime = Field(description="when the pass begins (with its zone)")
    end: AwareDatetime

    @model_validator(mode="after")
    def _ends_after_start(self) -> DeclaredPass:
        if self.end <= self.start:
            raise ValueError("end must come after start")
        return self


class DeclaredWindows(Strict):
    """A robot's windows: a repeating one, single passes, or both."""

    repeating: DeclaredRepeating | None = None
    passes: list[DeclaredPass] = Field(default_factory=list, max_length=MAX_PASSES)

    def on_wall_clock(self) -> ContactWindows:
        """The windows in POSIX seconds (mission time without a simulator)."""
        r = self.repeating
        return ContactWindows(
            repeating=None
            if r is None
            else RepeatingWindow(open_s=r.open, period_s=r.every, offset_s=_posix(r.first)),
            passes=[ContactPass(start=_posix(p.start), end=_posix(p.end)) for p in self.passes],
        )


class ContactWindowsFile(Strict):
    """A deployment's contact windows per robot (`missionctl server
    --contact-windows FILE`), on the wall clock (UTC)."""

    format: Literal["missionctl/contact-windows@1"] = Field(description="this file's format")
    robots: dict[Name, DeclaredWindows] = Field(
        default_factory=dict, description="robot -> its windows; a robot not listed: always"
    )


def _posix(t: datetime) -> float:
    return t.timestamp()


def sim_time_text(seconds: float) -> str:
    """Sim time as h:mm:ss, hours always shown (0:20:00 is never read as 20 o'clock)."""
    s = max(0, int(seconds))
    h, rest = divmod(s, 3600)
    m, sec = divmod(rest, 60)
    return f"{h}:{m:02d}:{sec:02d}"
