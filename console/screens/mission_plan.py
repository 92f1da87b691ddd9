"""The mission screen's plan actions (an object the screen owns; its keys
call these): add a skill (the picker), delete one (asked first), move it in
the plan, barriers, `c` duplicates a skill, `T` retries a failed one as an
idle copy to edit first, `/` finds a skill and jumps to it, undo and redo —
after which the cursor goes to the skill they brought back."""

from __future__ import annotations

from collections import deque
from functools import cache, partial
from typing import Any

from backend.core.contingency import span_text
from backend.core.model import BarrierTimeout, Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    DeleteSkills,
    EditBarrier,
    MoveSkill,
    Redo,
    RemoveBarrier,
    RetryEdit,
    Undo,
)
from console.bindings import key_names
from console.screens.barrier_wait import BarrierWaitPrompt
from console.screens.dialogs import ConfirmScreen, SkillPicker, SkillSearch
from console.screens.schedule_keys import added_text
from console.state.capability import also_offered_by
from console.state.defaults import default_params
from console.state.search import search_skills
from console.state.team import picker_hint


class PlanActions:
    def __init__(self, screen: Any) -> None:
        self.screen = screen  # MissionScreen: model, schedule, selection, say, submit, app
        self.model = screen.model
        # (revision, skills it added or moved) of the last few operations
        self._changes_seen: deque[tuple[int, tuple[str, ...]]] = deque(maxlen=16)
        self._follow_revision: int | None = None
        self.pending_select: str | None = None  # selected when its event arrives
        self.edit_after_select = False

    # -- where the cursor goes after an operation adds or moves a skill ----------------
    def seen(self, revision: int | None, moved: tuple[str, ...]) -> None:
        """An operation was applied: remember what it added or moved, and go
        to it if an undo or redo of ours was waiting for it."""
        if revision is None:
            return
        self._changes_seen.append((revision, moved))
        if moved and self._follow_revision == revision:
            self._follow_revision = None
            self.go_to(moved[0])

    def _follow(self, revision: int) -> None:
        """Put the cursor on what the operation at `revision` added or moved
        (now, or when its events arrive: the reply and the events race)."""
        for rev, ids in self._changes_seen:
            if rev == revision:
                if ids:
                    self.go_to(ids[0])
                return
        self._follow_revision = revision

    def go_to(self, skill_id: str) -> None:
        if self.model.owner(skill_id) is not None:
            self.screen.schedule.select(skill_id)

    def select_new(self, new: str, *, edit: bool) -> None:
        """Select a skill just added (when its event arrives), maybe editing it."""
        self.edit_after_select = edit
        if self.model.owner(new):
            self.screen.schedule.select(new)
            if edit:
                self.screen.call_after_refresh(self.screen.edit_selected)
        else:
            self.pending_select = new

    def arrived(self) -> None:
        """The model changed: a skill waited for may be there now."""
        if self.pending_select and self.model.owner(self.pending_select):
            sid, self.pending_select = self.pending_select, None
            self.screen.schedule.select(sid)
            if self.edit_after_select:
                self.screen.call_after_refresh(self.screen.edit_selected)

    def undo(self) -> None:
        def ok(r: Any) -> None:
            self.screen.say(f"undone: {r.value.get('undone', 'last edit')}", "ok")
            self._follow(r.revision)

        self.screen.submit(Undo(), "undo", then=ok)

    def redo(self) -> None:
        def ok(r: Any) -> None:
            self.screen.say(f"redone: {r.value.get('redone', 'edit')}", "ok")
            self._follow(r.revision)

        self.screen.submit(Redo(), "redo", then=ok)

    # -- adding, deleting, moving ----------------------------------------------------------
    async def add(self) -> None:
        s, m = self.screen, self.model
        robot, sid = s.selection()
        if robot is None or m.library is None:
            return
        at, where = m.insertion_point(robot, sid)
        skills = m.skills_of(robot)
        offered = {name: also_offered_by(m, name, robot) for name in skills}
        ranked = cache(partial(picker_hint, m, robot=robot))  # once a skill, while it is open
        picker = SkillPicker(robot, skills, m.library, where, offered, ranked)
        choice = await s.app.push_screen_wait(picker)
        if not choice:
            return
        spec = m.library.skills[choice]
        params, bindings = default_params(spec.params, m, robot)
        op = AddSkill(robot=robot, skill=choice, params=params, bindings=bindings, at=at)

        def added(reply: Any) -> None:
            new = reply.value.get("id")
            if not new:
                return
            s.say(added_text(key_names(s), f"{new} ({choice}) to {robot} {where}"), "ok")
            self.select_new(new, edit=True)

        s.submit(op, f"add {choice} to {robot}", robot=robot, then=added)

    async def delete(self) -> None:
        s = self.screen
        robot, sid = s.selection()
        found = self.model.find(sid)
        if found is None:
            return
        skill = found[2]
        bid = self.model.barrier_of(skill.id)
        extra = f" It leaves barrier {bid}." if bid else ""
        if not await s.app.push_screen_wait(
            ConfirmScreen(f"Delete {skill.display()} from {robot}'s plan?{extra}", yes="Delete")
        ):
            s.say("delete cancelled")
            return
        s.submit(DeleteSkills(ids=[skill.id]), f"delete {skill.id}", robot=robot, skill=skill.id)

    def move(self, step: int) -> None:
        robot, sid = self.screen.selection()
        if robot is None or sid is None:
            return
        idle = [x.id for x in self.model.task(robot) if x.status == Status.IDLE]
        if sid not in idle:
            return
        self.screen.submit(
            MoveSkill(id=sid, index=idle.index(sid) + step),
            f"move {sid} {'up' if step < 0 else 'down'}",
            robot=robot,
            skill=sid,
        )

    def barrier(self) -> None:
        s = self.screen
        ids = list(s.schedule.marks)
        if not ids:  # on a skill of a barrier: how long it waits
            self.barrier_wait()
            return

        def ok(r: Any) -> None:
            s.schedule.clear_marks()
            s.update_top()
            s.say(f"barrier {r.value.get('barrier', '')}: {', '.join(ids)} start together", "ok")

        s.submit(AddBarrier(ids=ids), f"barrier {', '.join(ids)}", then=ok)

    def barrier_wait(self) -> None:
        s = self.screen
        robot, sid = s.selection()
        bid = self.model.barrier_of(sid) if sid else None
        m = self.model.mission
        if bid is None or m is None or bid not in m.barriers:
            return

        def chosen(wait: BarrierTimeout | None) -> None:
            if wait is None:
                s.say(f"barrier {bid} unchanged")
                return
            how = (
                f"waits {span_text(wait.timeout)}, then {wait.on_timeout}"
                if wait.timeout is not None
                else "waits for ever"
            )
            s.submit(
                EditBarrier(barrier=bid, timeout=wait.timeout, on_timeout=wait.on_timeout),
                f"barrier {bid} wait",
                robot=robot,
                skill=sid,
                then=lambda r: s.say(f"barrier {bid} {how}", "ok"),
            )

        s.app.push_screen(BarrierWaitPrompt(bid, m.barriers[bid]), chosen)

    def unbarrier(self) -> None:
        s = self.screen
        robot, sid = s.selection()
        bid = self.model.barrier_of(sid) if sid else None
        if bid is None:
            return
        s.submit(
            RemoveBarrier(barrier=bid),
            f"remove barrier {bid}",
            robot=robot,
            skill=sid,
            then=lambda r: s.say(f"barrier {bid} removed", "ok"),
        )

    # -- new skills from old ones ------------------------------------------------------
    def duplicate(self) -> None:
        s = self.screen
        robot, sid = s.selection()
        found = self.model.find(sid)
        if robot is None or found is None:
            return
        old = found[2]
        at, where = self.model.insertion_point(robot, sid)
        op = AddSkill(
            robot=robot,
            skill=old.skill,
            label=old.label,
            params={k: v for k, v in old.params.items() if k not in old.bindings},
            bindings=dict(old.bindings),
            policies=old.policies,
            at=at,
        )

        def ok(reply: Any) -> None:
            new = reply.value.get("id")
            if new:
                s.say(f"duplicated {old.id} as {new} ({where}): idle, edit it as you like", "ok")
                self.select_new(new, edit=False)

        s.submit(op, f"duplicate {old.id}", robot=robot, skill=old.id, then=ok)

    def retry_edit(self) -> None:
        s = self.screen
        robot, sid = s.selection()
        found = self.model.find(sid)
        if robot is None or found is None or found[2].status != Status.FAILURE:
            return

        def ok(reply: Any) -> None:
            new = reply.value.get("id")
            if new:
                s.say(
                    f"{new}: the next attempt of {sid}, first in {robot}'s plan — "
                    "edit it, then s synchronizes it",
                    "ok",
                )
                self.select_new(new, edit=True)

        s.submit(RetryEdit(id=sid), f"edit and retry {sid}", robot=robot, skill=sid, then=ok)

    # -- finding a skill -----------------------------------------------------------------
    def search(self) -> None:
        def find(query: str) -> list[tuple[str, str]]:
            return [(m.skill_id, m.text) for m in search_skills(self.model, query)]

        def chosen(choice: str | None) -> None:
            if choice:
                self.go_to(choice)
                self.screen.say(f"{choice} selected")

        # pushed at once (not from a worker): what is typed right after / is the query
        self.screen.app.push_screen(SkillSearch(find), chosen)
