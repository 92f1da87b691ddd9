"""The robot link as the console shows it (no Textual here).

Every command to a robot is an entry of its uplink in the mission
(backend.core.model.UplinkCommand): queued, then sent, then settled by the
robot's answer (acked, refused) or never applied (expired, cancelled). While
one is pending its skills are *uplinking*: locked, drawn with ⇡ and the
command's age. A robot's one-way delay (RobotInfo.delay_s) and when the
server last heard it come with its fleet entry.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from backend.core.model import CommandState, Mission, UplinkCommand
from backend.core.verification import Verification
from backend.protocol.messages import RobotInfo
from console.state.clock import MissionClock
from console.state.contact import contact_words
from console.state.text import fmt_duration
from console.state.verification import command_stage, executing, stage_words

UPLINK_GLYPH = "⇡"
DELAY_GLYPH = "⇄"
SHOWN_DELAY_S = 1.0  # a shorter delay is a LAN's: not worth a word


def queued_for(c: UplinkCommand, clock: MissionClock) -> float:
    """Mission seconds since the command was queued (how long it has waited)."""
    return clock.since(c.created)


def command_text(c: UplinkCommand, clock: MissionClock) -> str:
    """'sync #17 sent 40s ago' / 'run #18 queued 2m05s ago, expires in 28m' (mission time;
    a sent command's age counts from its first transmission)."""
    if c.state == CommandState.SENT and c.sent is not None:
        text = f"{c.op} #{c.id} sent {clock.age_text(c.sent)} ago"
    else:
        text = f"{c.op} #{c.id} queued {clock.age_text(c.created)} ago"
    if c.cancel_requested:
        text += ", cancel asked"
    if c.expires is not None:
        left = (c.expires - clock()).total_seconds()
        text += f", expires in {clock.duration_text(left)}" if left > 0 else ", expiring"
    return text


def waiting_text(sid: str, c: UplinkCommand, clock: MissionClock, cancel_key: str | None) -> str:
    """The status line on an uplinking skill: its command and the key that
    cancels it (none for a console that cannot: an observer, a review)."""
    text = f"{sid}: {command_text(c, clock)}, waiting for {c.robot}'s answer"
    return f"{text} ({cancel_key} cancels it)" if cancel_key else text


def cancel_question(c: UplinkCommand, clock: MissionClock) -> str:
    """'Cancel sync #17 to lru1 (lru1-4, lru1-5)?' and what cancelling does now."""
    what = f" ({', '.join(c.skills)})" if c.skills else ""
    head = f"Cancel {c.op} #{c.id} to {c.robot}{what}?"
    if c.state == CommandState.SENT:
        sent = f" {clock.age_text(c.sent)} ago" if c.sent is not None else ""
        return (
            f"{head}\nIt was sent{sent}: {c.robot} may have it already. It is cancelled "
            f"unless {c.robot} applied it first; its answer says which."
        )
    return f"{head}\nIt has not left the ground: it is withdrawn at once."


def pending_text(cmds: list[UplinkCommand], clock: MissionClock) -> str:
    """A column header's word on a robot's pending commands: '⇡2 1m10s'
    (how many, how long the oldest has waited since queued); '' when none."""
    if not cmds:
        return ""
    oldest = max(queued_for(c, clock) for c in cmds)
    return f"{UPLINK_GLYPH}{len(cmds)} {fmt_duration(oldest)}"


def robot_delay_s(robots: Mapping[str, RobotInfo], robot: str) -> float | None:
    """The robot's estimated one-way delay, wall seconds (None: not known)."""
    info = robots.get(robot)
    return info.delay_s if info is not None else None


def delay_text(delay_s: float | None, clock: MissionClock) -> str:
    """'⇄10m': the robot's estimated one-way delay (wall seconds) in mission time,
    when it matters."""
    if delay_s is None or delay_s < SHOWN_DELAY_S:
        return ""
    return f"{DELAY_GLYPH}{clock.duration_text(delay_s)}"


def uplinking(mission: Mission | None) -> dict[str, UplinkCommand]:
    """skill id -> the pending command that locks it (the oldest)."""
    return mission.command_locks() if mission is not None else {}


def risks(mission: Mission | None, clock: MissionClock) -> list[str]:
    """Quit's word on commands still waiting for their robot, per robot."""
    if mission is None:
        return []
    by_robot: dict[str, list[str]] = {}
    for c in mission.pending_commands():
        by_robot.setdefault(c.robot, []).append(command_text(c, clock))
    return [f"{r}: {', '.join(texts)}" for r, texts in by_robot.items()]


class Linked(Protocol):
    """What `link_text` reads of the console's model."""

    robots: dict[str, RobotInfo]

    def pending(self, robot: str) -> list[UplinkCommand]: ...


def link_text(model: Linked, robot: str, clock: MissionClock) -> str:
    """The robot's link in words, in mission time: 'one-way delay 10m · heard 5s
    ago · waiting for its answer: sync #17 sent 40s ago', after its contact
    state when it has windows ('out of contact: window closed, next contact sim 0:20:00')."""
    info = model.robots.get(robot)
    executes = [executing_text(v, clock) for v in executing(info)]
    return " · ".join([*_known(info, clock), _waiting(model, robot, clock), *executes])


def _known(info: RobotInfo | None, clock: MissionClock) -> list[str]:
    """What the ground knows of the link: its contact state, one-way delay
    and when the robot was last heard, those known."""
    contact = contact_words(info, clock)
    parts = [contact] if contact else []
    if info is not None and info.delay_s is not None:
        parts.append(f"one-way delay {clock.duration_text(info.delay_s)}")
    if info is not None and info.heard is not None:
        parts.append(f"heard {clock.age_text(info.heard)} ago")
    return parts


def _waiting(model: Linked, robot: str, clock: MissionClock) -> str:
    """The robot's commands not answered yet, each with the stage it waits for."""
    cmds = model.pending(robot)
    if not cmds:
        return "no command waiting"
    return "waiting for its answer: " + ", ".join(staged_text(model, c, clock) for c in cmds)


def staged_text(model: Linked, c: UplinkCommand, clock: MissionClock) -> str:
    """'sync #17 sent 40s ago (received due 14:32:05)': with the stage it waits for."""
    stage = command_stage(model.robots.get(c.robot), c.id, clock)
    return command_text(c, clock) + (f" ({stage})" if stage else "")


def executing_stage(model: Linked, robot: str, sid: str, clock: MissionClock) -> str:
    """'completed due 14:40:00' on a skill of a command its robot applied and
    still executes: the stage the ground waits for ('' for other skills)."""
    v = next((v for v in executing(model.robots.get(robot)) if sid in v.skills), None)
    stage = v.current if v is not None else None
    return stage_words(stage, clock) if stage is not None else ""


def executing_text(v: Verification, clock: MissionClock) -> str:
    """'executing sync #17: started due 14:40:00' (an applied command's skills under way)."""
    stage = v.current
    return f"executing {v.op} #{v.command}" + (f": {stage_words(stage, clock)}" if stage else "")
