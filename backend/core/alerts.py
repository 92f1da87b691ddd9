"""Alerts: what needs a person, raised by the server about robots and the mission.

The rules say which alerts an operation raises (`Change.alerts`); the server
stamps and numbers them and publishes each as a protocol `Alert`
(backend/protocol/messages.py). Consoles raise none about robots: only about
themselves (their refusals, unreadable messages, their connection).
"""

from __future__ import annotations

from enum import StrEnum
from typing import Literal, Protocol

from pydantic import Field

from backend.core.model import Name, SkillId, Strict

Level = Literal["info", "warning", "error"]


LOW_BATTERY = 0.20  # a robot's battery below this is alerted (once per crossing)


class AlertKind(StrEnum):
    """What happened (MEANING says it in a sentence: the protocol document's table)."""

    FAILURE = "failure"
    OFFLINE = "offline"
    LOW_BATTERY = "low_battery"
    OUT_OF_RANGE = "out_of_range"
    RECONCILE = "reconcile"
    REPORT_REFUSED = "report_refused"
    COMMAND = "command"
    ROBOT_ERROR = "robot_error"
    JOURNAL = "journal"
    OVERDUE = "overdue"
    TEAM = "team"
    QUESTION = "question"
    CHOSEN = "chosen"


MEANING: dict[AlertKind, str] = {
    AlertKind.FAILURE: "a skill failed (the robot's report)",
    AlertKind.OFFLINE: "a robot's presence went away",
    AlertKind.LOW_BATTERY: f"a robot's battery fell below {LOW_BATTERY:.0%}",
    AlertKind.OUT_OF_RANGE: "a robot's telemetry says it left communication range",
    AlertKind.RECONCILE: "a registering robot's queue and the mission disagreed",
    AlertKind.REPORT_REFUSED: "a robot's report or answer broke the rules (consumed, refused)",
    AlertKind.COMMAND: "a robot refused a command, it expired, or was applied after the ground "
    "gave up on it",
    AlertKind.ROBOT_ERROR: "a robot sent something wrong (a gap, an unreadable message)",
    AlertKind.JOURNAL: "the server cannot write its journal (or can again)",
    AlertKind.OVERDUE: "a command's verification stage (sent, received, started, completed) "
    "is later than its due time and tolerance (backend/core/verification.py)",
    AlertKind.TEAM: "a robot asked to join the mission, was added or was retired",
    AlertKind.QUESTION: "a robot's skill asks the operators a question (answer it before its "
    "default applies on board)",
    AlertKind.CHOSEN: "a robot chose the place of a marker chosen on board (or two robots "
    "chose it differently)",
}


class RaisedAlert(Strict):
    """An alert a rule raises: what, about whom, in a sentence."""

    level: Level = "warning"
    kind: AlertKind
    robot: Name | None = None
    skill: SkillId | None = None
    command: int | None = Field(None, description="the command it is about, if any")
    question: int | None = Field(
        None, exclude_if=lambda v: v is None, description="the question it is about, if any"
    )
    message: str


class Raises(Protocol):
    """What raises an alert (the server; its parts are handed it)."""

    def alert(
        self,
        message: str,
        *,
        kind: AlertKind,
        level: Level = "warning",
        robot: str | None = None,
        skill: str | None = None,
        command: int | None = None,
        question: int | None = None,
    ) -> None: ...
