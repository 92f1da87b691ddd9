"""The mission screen's quicker plan actions: `c` duplicates a skill, `T`
retries a failed one as an idle copy to edit first, `/` finds a skill and
jumps to it, and after an undo or redo the cursor goes to the skill it
brought back. Mixed into `MissionScreen` (console/screens/mission.py)."""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

from backend.core import events as ev
from backend.core.model import Status
from backend.core.ops import AddSkill, Redo, RetryEdit, Undo
from console.screens.dialogs import SkillSearch
from console.state.model import ConsoleModel
from console.state.search import search_skills

if TYPE_CHECKING:
    from textual.app import App

    from console.widgets.schedule.view import ScheduleView


class PlanActions:
    model: ConsoleModel
    app: App[Any]
    pending_select: str | None
    edit_after_select: bool

    if TYPE_CHECKING:  # what MissionScreen (and Textual's Screen) provide

        @property
        def schedule(self) -> ScheduleView: ...
        def say(self, text: str, severity: str = "info") -> None: ...
        def submit(self, op: Any, what: str, **kw: Any) -> None: ...
        def selection(self) -> tuple[str | None, str | None]: ...
        def call_after_refresh(self, callback: Any, *args: Any) -> bool: ...
        async def _edit_selected(self) -> None: ...

    # -- where the cursor goes after an operation adds or moves a skill ----------------
    def _recent_changes(self) -> deque[tuple[int, list[str]]]:
        """(revision, skills it added or moved) of the last few batches."""
        if not hasattr(self, "_changes_seen"):
            self._changes_seen: deque[tuple[int, list[str]]] = deque(maxlen=16)
        return self._changes_seen

    def batch_seen(self, batch: ev.EventBatch) -> None:
        """The app applied `batch`: remember what it added or moved, and go to
        it if an undo or redo of ours was waiting for it."""
        ids = [
            e.skill.id if isinstance(e, ev.SkillAdded) else e.id
            for e in batch.events
            if isinstance(e, ev.SkillAdded | ev.SkillMoved)
        ]
        self._recent_changes().append((batch.revision, ids))
        if ids and getattr(self, "_follow_revision", None) == batch.revision:
            self._follow_revision = None
            self._go_to(ids[0])

    def _follow(self, revision: int) -> None:
        """Put the cursor on what the operation at `revision` added or moved
        (now, or when its events arrive: the reply and the events race)."""
        for rev, ids in self._recent_changes():
            if rev == revision:
                if ids:
                    self._go_to(ids[0])
                return
        self._follow_revision = revision

    def _go_to(self, skill_id: str) -> None:
        if self.model.owner(skill_id) is not None:
            self.schedule.select(skill_id)

    def action_undo(self) -> None:
        def ok(r: Any) -> None:
            self.say(f"undone: {r.value.get('undone', 'last edit')}", "ok")
            self._follow(r.revision)

        self.submit(Undo(), "undo", on_ok=ok)

    def action_redo(self) -> None:
        def ok(r: Any) -> None:
            self.say(f"redone: {r.value.get('redone', 'edit')}", "ok")
            self._follow(r.revision)

        self.submit(Redo(), "redo", on_ok=ok)

    # -- new skills from old ones ------------------------------------------------------
    def _select_new(self, new: str, *, edit: bool) -> None:
        """Select a skill just added (when its event arrives), maybe editing it."""
        self.edit_after_select = edit
        if self.model.owner(new):
            self.schedule.select(new)
            if edit:
                self.call_after_refresh(self._edit_selected)
        else:
            self.pending_select = new

    def action_duplicate(self) -> None:
        robot, sid = self.selection()
        found = self.model.find(sid)
        if robot is None or found is None:
            return
        s = found[2]
        at, where = self.model.insertion_point(robot, sid)
        op = AddSkill(
            robot=robot,
            skill=s.skill,
            label=s.label,
            params={k: v for k, v in s.params.items() if k not in s.bindings},
            bindings=dict(s.bindings),
            policies=s.policies,
            at=at,
        )

        def ok(reply: Any) -> None:
            new = reply.value.get("id")
            if new:
                self.say(f"duplicated {s.id} as {new} ({where}): idle, edit it as you like", "ok")
                self._select_new(new, edit=False)

        self.submit(op, f"duplicate {s.id}", robot=robot, skill=s.id, on_ok=ok)

    def action_retry_edit(self) -> None:
        robot, sid = self.selection()
        found = self.model.find(sid)
        if robot is None or found is None or found[2].status != Status.FAILURE:
            return

        def ok(reply: Any) -> None:
            new = reply.value.get("id")
            if new:
                self.say(
                    f"{new}: the next attempt of {sid}, first in {robot}'s plan — "
                    "edit it, then s synchronizes it",
                    "ok",
                )
                self._select_new(new, edit=True)

        self.submit(RetryEdit(id=sid), f"edit and retry {sid}", robot=robot, skill=sid, on_ok=ok)

    # -- finding a skill -----------------------------------------------------------------
    def action_search(self) -> None:
        def find(query: str) -> list[tuple[str, str]]:
            return [(m.skill_id, m.text) for m in search_skills(self.model, query)]

        def chosen(choice: str | None) -> None:
            if choice:
                self._go_to(choice)
                self.say(f"{choice} selected")

        # pushed at once (not from a worker): what is typed right after / is the query
        self.app.push_screen(SkillSearch(find), chosen)
