"""A robot's contact with the ground as the console says it (no Textual here).

The server computes each robot's contact state (backend/core/contact.py) and
publishes it on `RobotInfo.contact`: in contact (until its window closes, if
it has windows), out of contact (present, its window closed: the next one
opens at T), or offline. Its times are on the clock it names: the
simulator's (sim seconds) or the wall's (POSIX seconds); the console writes
them in its one mission clock, with their unit. A robot without windows is
always in contact: nothing more is said of it.
"""

from __future__ import annotations

from rich.cells import cell_len

from backend.protocol.messages import RobotContact, RobotInfo
from console.state.clock import MissionClock, sim_clock_text

CONTACT_GLYPH = "◌"  # present, not reachable: its window is closed (✕ is offline)


def contact_of(info: RobotInfo | None) -> RobotContact | None:
    """The robot's contact state while it is present (None: offline or unknown,
    which its presence says already)."""
    if info is None or not info.online or info.contact is None:
        return None
    return info.contact if info.contact.state != "offline" else None


def out_of_contact(info: RobotInfo | None) -> bool:
    c = contact_of(info)
    return c is not None and c.state == "out_of_contact"


def contact_time_text(c: RobotContact, t: float, clock: MissionClock) -> str:
    """A time of the contact's, in mission time with its unit: 'sim 0:20:00', '15:42:10'."""
    if c.clock == "sim":  # the simulator's seconds: mission time itself
        return f"sim {sim_clock_text(t)}"
    return clock.ts_text(t)


def next_contact_text(c: RobotContact, clock: MissionClock) -> str:
    """'next contact sim 0:20:00' (or 'no window ahead')."""
    if c.next_contact is None:
        return "no window ahead"
    return f"next contact {contact_time_text(c, c.next_contact, clock)}"


def contact_words(info: RobotInfo | None, clock: MissionClock) -> str:
    """The contact state in a sentence: 'out of contact: window closed, next
    contact sim 0:20:00', 'in contact until sim 0:32:00'; '' when the robot has no
    windows (always in contact) or is not present."""
    c = contact_of(info)
    if c is None:
        return ""
    if c.state == "out_of_contact":
        return f"out of contact: window closed, {next_contact_text(c, clock)}"
    if c.closes is not None:
        return f"in contact until {contact_time_text(c, c.closes, clock)}"
    return ""


def presence_words(info: RobotInfo | None, clock: MissionClock) -> str:
    """The fleet table's presence, when the contact says more than 'online':
    '◌ out of contact, next sim 0:20:00', '● in contact until sim 0:32:00'; '' otherwise."""
    c = contact_of(info)
    if c is None:
        return ""
    if c.state == "out_of_contact":
        if c.next_contact is None:
            return f"{CONTACT_GLYPH} out of contact, no window ahead"
        return f"{CONTACT_GLYPH} out of contact, next {contact_time_text(c, c.next_contact, clock)}"
    if c.closes is not None:
        return f"● in contact until {contact_time_text(c, c.closes, clock)}"
    return ""


def header_contact(info: RobotInfo | None, clock: MissionClock, room: int) -> str:
    """A column header's word on the contact, the longest that fits in `room`
    cells: '◌ next sim 0:20:00' ('◌ → sim 0:20:00' at 80 columns) out of contact, '● until
    sim 0:32:00' in contact with windows; '' when there is nothing to say or no room
    (the caller's own word stands)."""
    c = contact_of(info)
    if c is None:
        return ""
    if c.state == "out_of_contact":
        words = _away_words(c, clock)
    else:
        words = [] if c.closes is None else [f"● until {contact_time_text(c, c.closes, clock)}"]
    return next((w for w in words if cell_len(w) <= room), "")


def _away_words(c: RobotContact, clock: MissionClock) -> list[str]:
    """Out of contact, longest first; a time never without its unit."""
    if c.next_contact is None:
        return [f"{CONTACT_GLYPH} no contact", f"{CONTACT_GLYPH} out", CONTACT_GLYPH]
    at = contact_time_text(c, c.next_contact, clock)
    return [
        f"{CONTACT_GLYPH} next {at}",
        f"{CONTACT_GLYPH} → {at}",
        f"{CONTACT_GLYPH} →{at}",  # 'ardea ◌ →sim 2:00:00' at 80 columns
        f"{CONTACT_GLYPH} {at}",
        CONTACT_GLYPH,
    ]
