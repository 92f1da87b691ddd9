"""The forecast a client sends with a sync (`Sync.forecast`): the predicted
start and end of the skills it synchronizes, as the plan had them then. The
journal keeps it with the operation; a review draws the plan against what
happened from it (backend/files/record/report.py, the review's timeline)."""

from __future__ import annotations

from datetime import UTC, datetime

from backend.core.model import SkillInstance, Status
from backend.core.ops import Predicted
from backend.core.plan.forecast import Forecast


def syncing(task: list[SkillInstance], through: str | None) -> list[SkillInstance]:
    """The skills a sync through `through` sends: the idle ones down to it (all without)."""
    out: list[SkillInstance] = []
    for s in task:
        if s.status == Status.IDLE:
            out.append(s)
        if s.id == through:
            break
    return out


def at_sync(
    forecast: Forecast | None, task: list[SkillInstance], through: str | None
) -> dict[str, Predicted]:
    """skill id -> its predicted start and end, for the skills a sync sends
    (those without a prediction, e.g. behind a barrier never passed, left out)."""
    if forecast is None:
        return {}
    out: dict[str, Predicted] = {}
    for s in syncing(task, through):
        f = forecast.skill(s.id)
        if f is not None:
            out[s.id] = Predicted(
                start=datetime.fromtimestamp(f.start, UTC), end=datetime.fromtimestamp(f.end, UTC)
            )
    return out
