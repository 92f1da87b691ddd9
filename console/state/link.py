"""The robot link as the console shows it (no Textual here).

Every command to a robot is an entry of its uplink in the mission
(backend.core.model.UplinkCommand): queued, then sent, then settled by the
robot's answer (acked, refused) or never applied (expired, cancelled). While
one is pending its skills are *uplinking*: locked, drawn with ⇡ and the
command's age. A robot's one-way delay (RobotInfo.delay_s) and when the
server last heard it come with its fleet entry.
"""

from __future__ import annotations

from datetime import datetime
from typing import Protocol

from backend.core.model import CommandState, Mission, UplinkCommand
from backend.protocol.messages import RobotInfo
from console.state.text import fmt_duration

UPLINK_GLYPH = "⇡"
DELAY_GLYPH = "⇄"
SHOWN_DELAY_S = 1.0  # a shorter delay is a LAN's: not worth a word


def age_s(c: UplinkCommand, now: datetime) -> float:
    """How long the command has been waiting for its answer."""
    return max(0.0, (now - c.created).total_seconds())


def command_text(c: UplinkCommand, now: datetime) -> str:
    """'sync #17 sent 40s' / 'run #18 queued 2m05s, expires in 28m'."""
    state = "sent" if c.state == CommandState.SENT else "queued"
    text = f"{c.op} #{c.id} {state} {fmt_duration(age_s(c, now))}"
    if c.cancel_requested:
        text += ", cancel asked"
    if c.expires is not None:
        left = (c.expires - now).total_seconds()
        text += f", expires in {fmt_duration(left)}" if left > 0 else ", expiring"
    return text


def waiting_text(sid: str, c: UplinkCommand, now: datetime) -> str:
    """The status line on an uplinking skill: its command and how to withdraw it."""
    return (
        f"{sid}: {command_text(c, now)}, waiting for {c.robot}'s answer "
        f"(ctl cancel {c.id} withdraws it)"
    )


def pending_text(cmds: list[UplinkCommand], now: datetime) -> str:
    """A column header's word on a robot's pending commands: '⇡2 1m10s'
    (how many, the oldest one's age); '' when none."""
    if not cmds:
        return ""
    oldest = max(age_s(c, now) for c in cmds)
    return f"{UPLINK_GLYPH}{len(cmds)} {fmt_duration(oldest)}"


def delay_text(delay_s: float | None) -> str:
    """'⇄20s': the robot's estimated one-way delay, when it matters."""
    if delay_s is None or delay_s < SHOWN_DELAY_S:
        return ""
    return f"{DELAY_GLYPH}{fmt_duration(delay_s)}"


def uplinking(mission: Mission | None) -> dict[str, UplinkCommand]:
    """skill id -> the pending command that locks it (the oldest)."""
    return mission.command_locks() if mission is not None else {}


def risks(mission: Mission | None, now: datetime) -> list[str]:
    """Quit's word on commands still waiting for their robot, per robot."""
    if mission is None:
        return []
    by_robot: dict[str, list[str]] = {}
    for c in mission.pending_commands():
        by_robot.setdefault(c.robot, []).append(command_text(c, now))
    return [f"{r}: {', '.join(texts)}" for r, texts in by_robot.items()]


class Linked(Protocol):
    """What `link_text` reads of the console's model."""

    robots: dict[str, RobotInfo]

    def pending(self, robot: str) -> list[UplinkCommand]: ...


def link_text(model: Linked, robot: str, now: datetime) -> str:
    """The robot's link in words: 'one-way delay 20s · heard 5s ago ·
    waiting for its answer: sync #17 sent 40s'."""
    info = model.robots.get(robot)
    parts = []
    if info is not None and info.delay_s is not None:
        parts.append(f"one-way delay {fmt_duration(info.delay_s)}")
    if info is not None and info.heard is not None:
        parts.append(f"heard {fmt_duration((now - info.heard).total_seconds())} ago")
    cmds = model.pending(robot)
    if cmds:
        parts.append("waiting for its answer: " + ", ".join(command_text(c, now) for c in cmds))
    else:
        parts.append("no command waiting")
    return " · ".join(parts)
