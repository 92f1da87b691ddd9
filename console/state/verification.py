"""A command's verification stage as the console says it (no Textual here).

The server verifies every command under way (backend/core/verification.py)
and publishes its stages with the robot (`RobotInfo.verification`): the
console says the stage a command waits for and when its evidence is due, in
mission time: 'received due sim 0:32:00', 'started OVERDUE 6m'.
"""

from __future__ import annotations

from backend.core.verification import Stage, Verification
from backend.protocol.messages import RobotInfo
from console.state.clock import MissionClock

OVERDUE_GLYPH = "⚠"


def verifying(info: RobotInfo | None) -> list[Verification]:
    """The robot's commands under way, as the server verifies them."""
    return info.verification if info is not None else []


def stage_words(stage: Stage, clock: MissionClock) -> str:
    """'received due 14:32:05', 'started ⚠ OVERDUE 6m', 'started (no due)'."""
    if stage.due is None:
        return f"{stage.name} (no due)"
    if stage.state == "overdue":
        late = (clock() - stage.due).total_seconds()
        return f"{stage.name} {OVERDUE_GLYPH} OVERDUE {clock.duration_text(late)}"
    return f"{stage.name} due {clock.stamp_text(stage.due)}"


def command_stage(info: RobotInfo | None, command: int, clock: MissionClock) -> str:
    """The stage command `command` waits for, in words ('' when the server said nothing)."""
    v = next((v for v in verifying(info) if v.command == command), None)
    stage = v.current if v is not None else None
    return stage_words(stage, clock) if stage is not None else ""


def executing(info: RobotInfo | None) -> list[Verification]:
    """The robot's commands it applied whose skills have not all ended."""
    return [v for v in verifying(info) if v.stage("received").state == "ok"]
