"""The mission screen: schedule panel, parameter editor, control keys.

Layout: top bar / schedule | parameter editor / status line / footer. From
100 columns the editor is a side panel beside the schedule; below, it is a
toggle (enter / e opens it beside the schedule, escape closes it). Part 2
adds the map, fleet and event-log screens as further app modes next to this one.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.text import Text
from textual import events, on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.screen import Screen

from backend.core.model import Status
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    Control,
    DeleteSkills,
    MoveSkill,
    RemoveBarrier,
    Retry,
    Sync,
    Unsync,
)
from console.bindings import bind, key_names
from console.messages import HelpRequested, OperationRequested
from console.screens.cancel import ask_and_cancel
from console.screens.dialogs import ConfirmScreen, SkillPicker
from console.screens.mission_files import MissionFiles
from console.screens.mission_plan import PlanActions
from console.screens.schedule_keys import (
    added_text,
    footer_now,
    refused_off_schedule,
    schedule_action,
)
from console.state import link
from console.state.actions import BY_NAME
from console.state.capability import also_offered_by
from console.state.defaults import default_params
from console.state.eventlog import AlertBook
from console.state.files import RecentFiles
from console.state.keys import KeyNames
from console.state.model import CONNECTED, ConsoleModel
from console.state.site import site_text
from console.widgets.bars import KeyBar, StatusLine, TopBar, connection_text
from console.widgets.editor.editor import ParamEditor
from console.widgets.schedule.view import ScheduleView

# this module's look (CSS_PATH); absolute, so a subclass defined elsewhere finds it too
TCSS = Path(__file__).with_name("mission.tcss")

NARROW = 100


def top_text(m: ConsoleModel, unacked: int, marks: list[str], keys: KeyNames) -> Text:
    """The top bar: alert badge, mission and revision, connection, read-only, marks."""
    t = Text()
    t.append("missionctl", style="bold")
    if unacked:  # the badge, first so 80 columns show it, with the key that lists them
        plural = "s" if unacked > 1 else ""
        badge = f" ⚠ {unacked} alert{plural} ({keys.say('app.show_alerts')}) "
        t.append(badge, style="bold reverse")
    if m.site is not None:  # the pilot study's score and clock, before what 80 columns cut
        t.append(f"  {site_text(m.site, m.clock)}", style="bold")
    if m.mission is not None:
        t.append(f"  {m.mission.name}", style="bold")
        t.append(f"  rev {m.mission.revision}", style="dim")
    t.append(f"   {connection_text(m.connection)}")
    if m.endpoint:
        t.append(f" {m.endpoint}", style="dim")
    if m.connection_detail and m.connection != CONNECTED:
        t.append(f" — {m.connection_detail}", style="dim")
    if m.read_only:
        t.append(f"   {m.read_only}", style="bold")
    if marks:
        t.append(f"   marked: {', '.join(marks)}", style="bold")
    return t


class MissionScreen(MissionFiles, PlanActions, Screen):
    SCOPE = "mission"  # its actions (console/state/actions.py)
    # the actions table's keys are dispatched by on_key (mission_keys), not bound
    BINDINGS = [
        bind("app.help", "help", show=False),
        Binding("escape", "clear_marks", "Clear marks", show=False),
    ]

    CSS_PATH = TCSS

    def __init__(
        self,
        model: ConsoleModel,
        alerts: AlertBook | None = None,
        recent: RecentFiles | None = None,
    ) -> None:
        super().__init__()
        self.model = model
        self.alerts = alerts  # its count of unacknowledged alerts is the top bar's badge
        self.recent = recent or RecentFiles()  # saved and loaded files, newest first
        self.last_path: str | None = None  # of the last save or load: the next one's default
        self.pending_select: str | None = None
        # kept as attributes: messages may arrive while the screen is being torn down
        self._topbar = TopBar(id="topbar")
        self._schedule = ScheduleView(model, id="schedule")
        self._editor = ParamEditor(model, id="editor")
        self._status = StatusLine("", id="status")
        self._footer = KeyBar("", id="keys")
        self.edit_after_select = False
        self.message = ""

    def compose(self) -> ComposeResult:
        yield self._topbar
        with Horizontal(id="main"):
            yield self._schedule
            yield self._editor
        yield self._status
        yield self._footer

    @property
    def schedule(self) -> ScheduleView:
        return self._schedule

    @property
    def editor(self) -> ParamEditor:
        return self._editor

    def _set_narrow(self, narrow: bool) -> None:
        self.set_class(narrow, "-narrow")

    def on_mount(self) -> None:
        self._set_narrow(self.app.size.width < NARROW)
        self.schedule.focus()
        self.update_top()
        self.schedule.rebuild()
        self._stale: frozenset[str] = frozenset()
        # "as of 25s ago" counts up; a robot falling silent turns stale without a message
        self.set_interval(1.0, self.freshness_tick)

    def freshness_tick(self) -> None:
        """Redraw what shows how old a robot's state is: all of it when a
        robot turned stale or fresh, else the stale robots' headers."""
        if self.model.site is not None:
            self.update_top()  # the sim clock moves on between map messages
        stale = frozenset(r for r in self.model.robot_order() if self.model.freshness(r).stale)
        if stale != self._stale:
            self._stale = stale
            self.schedule.refresh()
            return
        for robot in stale:
            self.schedule.refresh_telemetry(robot)
        for robot in self.model.robot_order():  # the ages of commands waiting for a robot
            if self.model.pending(robot):
                self.schedule.refresh_uplinking(robot)

    def on_resize(self, event: events.Resize) -> None:
        self.update_keys()
        narrow = event.size.width < NARROW
        if narrow != self.has_class("-narrow"):
            self._set_narrow(narrow)
            if not narrow:
                self.remove_class("-editing")
                self.run_worker(
                    self.editor.show_skill(self.schedule.cursor_id), group="editor", exclusive=True
                )

    @property
    def editor_visible(self) -> bool:
        return not self.has_class("-narrow") or self.has_class("-editing")

    # -- the model changed ------------------------------------------------------------------
    async def model_changed(self, robots: set[str] | None) -> None:
        self.schedule.rebuild(robots)
        self.schedule.marks = [m for m in self.schedule.marks if self.model.owner(m) is not None]
        if self.pending_select and self.model.owner(self.pending_select):
            sid, self.pending_select = self.pending_select, None
            self.schedule.select(sid)
            if self.edit_after_select:
                self.call_after_refresh(self._edit_selected)
        self.update_top()
        self.refresh_availability()
        if self.editor_visible:
            if self.editor.skill_id != self.schedule.cursor_id:
                await self.editor.show_skill(self.schedule.cursor_id)
            else:
                await self.editor.model_changed()
        self.editor.prune_drafts()

    async def connection_changed(self) -> None:
        self.update_top()
        self.refresh_availability()
        if self.editor_visible:
            await self.editor.model_changed()

    def robot_changed(self, robot: str) -> None:
        self.schedule.refresh()  # partners' columns show it too (barriers)
        self.refresh_availability()

    def telemetry_changed(self, robot: str) -> None:
        self.schedule.refresh_telemetry(robot)

    def plan_changed(self) -> None:
        """The plan checks' findings changed: the rows' glyphs and what sync allows."""
        self.schedule.refresh()
        self.refresh_availability()

    def on_screen_resume(self) -> None:
        """Back from the timeline or the checks: the cursor follows their selection."""
        sid, cols = self.model.selection.skill, self.schedule.columns
        if sid and cols and sid not in cols[self.schedule.cursor_col].line_of:
            self.schedule.select(sid)

    def update_top(self) -> None:
        unacked = self.alerts.unacknowledged if self.alerts is not None else 0
        text = top_text(self.model, unacked, self.schedule.marks, key_names(self))
        self._topbar.show(text, self.model.connection)

    def say(self, text: str, severity: str = "info") -> None:
        """The status line: the last outcome, refusal or explanation."""
        self.message = text
        self._status.show(text, severity)

    # -- selection ---------------------------------------------------------------------------------
    @on(ScheduleView.CursorMoved)
    async def _cursor_moved(self, event: ScheduleView.CursorMoved) -> None:
        self.refresh_availability()
        c = self.model.uplinking(event.skill_id) if event.skill_id else None
        if c is not None:  # its row may have no room for the command: the status line has
            cancel = key_names(self).say("mission.cancel")
            self.say(link.waiting_text(event.skill_id, c, self.model.clock, cancel))
        if self.editor_visible:
            await self.editor.show_skill(event.skill_id)

    def selection(self) -> tuple[str | None, str | None]:
        return self.schedule.cursor_robot, self.schedule.cursor_id

    def refresh_availability(self) -> None:
        """The footer shows the keys that apply now (keys are checked again
        when pressed: `run_named`)."""
        self.update_keys()

    def update_keys(self) -> None:
        """The footer: the keys that apply now (console/screens/schedule_keys.py)."""
        if self.is_mounted:
            self._footer.show(footer_now(self))

    def on_descendant_focus(self, event: events.DescendantFocus) -> None:
        self.update_keys()

    def on_descendant_blur(self, event: events.DescendantBlur) -> None:
        self.update_keys()

    async def action_footer_key(self, action: str) -> None:
        """A click on a key in the footer."""
        if action in BY_NAME:
            await self.run_named(action)
        elif action == "command_palette":
            self.app.action_command_palette()
        elif action == "quit":
            await self.app.run_action("quit")
        elif action == "apply":
            self.editor.action_apply()
        elif action == "revert":
            await self.editor.action_revert()
        elif action == "leave":
            self.editor.action_leave()
        else:
            await self.run_action(action)

    def why_disabled(self, action: str) -> str | None:
        if action not in BY_NAME:
            return None
        robot, sid = self.selection()
        return self.model.why_not(action, robot, sid, self.schedule.marks)

    def explain(self, action: str) -> bool:
        """Say why an action does not apply; True if it does not."""
        why = self.why_disabled(action)
        if why:
            label = BY_NAME[action].label if action in BY_NAME else action
            self.say(f"{label}: {why}", "warning")
            self.app.notify(why, title=f"{label} does not apply", severity="warning", timeout=4)
            return True
        return False

    async def on_key(self, event: events.Key) -> None:
        """The schedule's keys (console/screens/schedule_keys.py)."""
        action = schedule_action(self, event)
        if action is not None:
            event.stop()
            event.prevent_default()
            refused = refused_off_schedule(self, action, event)
            if refused:
                self.say(refused, "warning")
            else:
                await self.run_named(action)

    async def run_named(self, action: str) -> None:
        """From the command palette: run it, or say why not."""
        if not self.explain(action):
            await self.run_action(action)

    # -- submitting --------------------------------------------------------------------------------
    def submit(self, op: Any, what: str, **kw: Any) -> None:
        """The app submits it (OperationRequested) and reports on the status line."""
        self.post_message(OperationRequested(op, what, **kw))

    # -- actions: plan -----------------------------------------------------------------------------
    def action_help(self) -> None:
        self.post_message(HelpRequested())

    def action_clear_marks(self) -> None:
        if self.schedule.marks:
            self.schedule.clear_marks()
            self.update_top()
            self.refresh_availability()
            self.say("marks cleared")

    def action_toggle_static(self) -> None:
        self.schedule.set_expand_static(not self.schedule.expand_static)

    @work(group="dialog")
    async def action_add(self) -> None:
        robot, sid = self.selection()
        if robot is None or self.model.library is None:
            return
        at, where = self.model.insertion_point(robot, sid)
        skills = self.model.skills_of(robot)
        offered = {name: also_offered_by(self.model, name, robot) for name in skills}
        choice = await self.app.push_screen_wait(
            SkillPicker(robot, skills, self.model.library, where, offered)
        )
        if not choice:
            return
        spec = self.model.library.skills[choice]
        params, bindings = default_params(spec.params, self.model, robot)
        op = AddSkill(robot=robot, skill=choice, params=params, bindings=bindings, at=at)

        def added(reply: Any) -> None:
            new = reply.value.get("id")
            if not new:
                return
            self.say(added_text(key_names(self), f"{new} ({choice}) to {robot} {where}"), "ok")
            self.edit_after_select = True
            if self.model.owner(new):
                self.schedule.select(new)
                self.call_after_refresh(self._edit_selected)
            else:
                self.pending_select = new  # selected (and edited) when its event arrives

        self.submit(op, f"add {choice} to {robot}", robot=robot, on_ok=added)

    async def action_edit(self) -> None:
        if self.has_class("-narrow"):
            self.add_class("-editing")
        await self.editor.show_skill(self.schedule.cursor_id)
        self.editor.focus_first()

    async def _edit_selected(self) -> None:
        if self.edit_after_select:
            self.edit_after_select = False
            await self.action_edit()

    @on(ParamEditor.Left)
    def _editor_left(self) -> None:
        self.remove_class("-editing")
        self.editor.can_focus = False
        self.schedule.focus()

    @on(ParamEditor.DraftsChanged)
    def _drafts_changed(self, event: ParamEditor.DraftsChanged) -> None:
        self.schedule.set_drafts(event.unapplied)
        for text in event.discarded:
            self.say(text, "warning")
            self.app.notify(
                text, title="Unapplied changes discarded", severity="warning", timeout=8
            )

    @on(ParamEditor.ApplyRequested)
    def _apply(self, event: ParamEditor.ApplyRequested) -> None:
        robot = self.model.owner(event.skill_id)
        changed = ", ".join(event.changed())

        def refused(reply: Any) -> None:
            if reply.skill in (None, event.skill_id) and self.editor.skill_id == event.skill_id:
                self.editor.show_param_error(reply.param, reply.message)

        def ok(reply: Any) -> None:
            self.say(f"{event.skill_id}: applied {changed}", "ok")

        self.submit(
            event.operation(),
            f"edit {event.skill_id}",
            robot=robot,
            skill=event.skill_id,
            expected_revision=event.base_revision,
            on_ok=ok,
            on_refused=refused,
        )

    @work(group="dialog")
    async def action_delete(self) -> None:
        robot, sid = self.selection()
        found = self.model.find(sid)
        if found is None:
            return
        s = found[2]
        bid = self.model.barrier_of(s.id)
        extra = f" It leaves barrier {bid}." if bid else ""
        if not await self.app.push_screen_wait(
            ConfirmScreen(f"Delete {s.display()} from {robot}'s plan?{extra}", yes="Delete")
        ):
            self.say("delete cancelled")
            return
        self.submit(DeleteSkills(ids=[s.id]), f"delete {s.id}", robot=robot, skill=s.id)

    def _move(self, step: int) -> None:
        robot, sid = self.selection()
        if robot is None or sid is None:
            return
        idle = [s.id for s in self.model.task(robot) if s.status == Status.IDLE]
        if sid not in idle:
            return
        index = idle.index(sid) + step
        self.submit(
            MoveSkill(id=sid, index=index),
            f"move {sid} {'up' if step < 0 else 'down'}",
            robot=robot,
            skill=sid,
        )

    def action_move_up(self) -> None:
        self._move(-1)

    def action_move_down(self) -> None:
        self._move(1)

    # -- actions: synchronization ------------------------------------------------------------------
    def action_sync(self) -> None:
        robot, sid = self.selection()
        if robot is None or sid is None:
            return
        self.submit(
            Sync(robot=robot, through=sid),
            f"sync {robot} through {sid}",
            robot=robot,
            skill=sid,
            on_ok=lambda r: self.say(_queued(robot, "sync", r.value), "ok"),
        )

    def action_unsync(self) -> None:
        robot, sid = self.selection()
        if robot is None or sid is None:
            return

        self.submit(
            Unsync(robot=robot, from_id=sid),
            f"unsync {robot} from {sid}",
            robot=robot,
            skill=sid,
            on_ok=lambda r: self.say(_queued(robot, "unsync", r.value), "ok"),
        )

    def action_mark(self) -> None:
        robot, sid = self.selection()
        if sid is None:
            return
        marked = self.schedule.toggle_mark(sid)
        self.update_top()
        self.refresh_availability()
        n = len(self.schedule.marks)
        barrier = key_names(self).say("mission.barrier")
        self.say(
            f"{'marked' if marked else 'unmarked'} {sid}; {n} marked"
            + (f" — {barrier} makes the barrier" if n >= 2 else " — mark a skill of another robot")
        )

    def action_barrier(self) -> None:
        ids = list(self.schedule.marks)

        def ok(r: Any) -> None:
            self.schedule.clear_marks()
            self.update_top()
            self.say(f"barrier {r.value.get('barrier', '')}: {', '.join(ids)} start together", "ok")

        self.submit(AddBarrier(ids=ids), f"barrier {', '.join(ids)}", on_ok=ok)

    def action_unbarrier(self) -> None:
        robot, sid = self.selection()
        bid = self.model.barrier_of(sid) if sid else None
        if bid is None:
            return
        self.submit(
            RemoveBarrier(barrier=bid),
            f"remove barrier {bid}",
            robot=robot,
            skill=sid,
            on_ok=lambda r: self.say(f"barrier {bid} removed", "ok"),
        )

    @work(group="dialog")
    async def action_cancel(self) -> None:
        c = self.model.uplinking(self.schedule.cursor_id or "")
        if c is not None:
            await ask_and_cancel(self, c, self.say)

    def action_retry(self) -> None:
        robot, sid = self.selection()
        if sid is None:
            return
        self.submit(
            Retry(id=sid),
            f"retry {sid}",
            robot=robot,
            skill=sid,
            on_ok=lambda r: self.say(
                f"{robot}: {r.value.get('id', '')} queued right after {sid} (run to start it)", "ok"
            ),
        )

    # -- actions: execution ------------------------------------------------------------------------
    def _control(self, op: str, robot: str | None) -> None:
        who = robot or "all robots"

        def ok(r: Any) -> None:
            notes = "; ".join(r.notes)
            commands = r.value.get("commands", {}) if isinstance(r.value, dict) else {}
            # the robot's answer comes later (its skills then change): say what waits for it
            queued = ", ".join(f"{rb} (command {c})" for rb, c in commands.items())
            done = f"queued for {queued}" if queued else "ok"
            self.say(
                f"{op} {who}: {done}" + (f" — {notes}" if notes else ""),
                "warning" if notes else "ok",
            )
            for n in r.notes:
                self.app.notify(n, title=f"{op}: partly applied", severity="warning")

        self.submit(Control(op=op, robot=robot), f"{op} {who}", robot=robot, on_ok=ok)

    def action_run(self) -> None:
        self._control("run", self.schedule.cursor_robot)

    def action_pause(self) -> None:
        self._control("pause", self.schedule.cursor_robot)

    def action_stop(self) -> None:
        self._control("stop", self.schedule.cursor_robot)

    @work(group="dialog")
    async def action_reset(self) -> None:
        robot = self.schedule.cursor_robot
        if robot and await self.app.push_screen_wait(
            ConfirmScreen(
                f"Reset {robot}? Its active skill stops and everything queued returns to the plan.",
                yes="Reset",
            )
        ):
            self._control("reset", robot)

    def action_run_all(self) -> None:
        self._control("run", None)

    def action_pause_all(self) -> None:
        self._control("pause", None)

    def action_stop_all(self) -> None:
        self._control("stop", None)

    @work(group="dialog")
    async def action_reset_all(self) -> None:
        if await self.app.push_screen_wait(
            ConfirmScreen(
                "Reset ALL robots? Active skills stop and everything queued returns to the plan.",
                yes="Reset all",
            )
        ):
            self._control("reset", None)


def _queued(robot: str, what: str, value: dict[str, Any]) -> str:
    """Protocol 2: the operation returns once its command is queued for the
    robot; the skills change when the robot answers."""
    skills = ", ".join(value.get("skills", []))
    return f"{robot}: {what} queued (command {value.get('command')}): {skills}"
