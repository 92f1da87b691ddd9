"""The mission screen: schedule panel, parameter editor, control keys.

Layout: top bar / schedule | parameter editor / status line / footer. From
100 columns the editor is a side panel beside the schedule; below, it is a
toggle (enter / e opens it beside the schedule, escape closes it). Part 2
adds the map, fleet and event-log screens as further app modes next to this one.

It follows the model's changes (the app's signal) and redraws what they
touch; its actions are the keys' (thin), done by the objects it owns: the
plan's (mission_plan.py), execution's (mission_run.py) and files'
(mission_files.py). Operations go to the `OperationService`, awaited in the
screen's own workers (`submit`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.text import Text
from textual import events, on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.screen import Screen
from textual.signal import Signal

from console.bindings import bind, key_names
from console.messages import HelpRequested
from console.operations import OperationService
from console.screens.cancel import ask_and_cancel
from console.screens.give_to import give_action
from console.screens.mission_files import FileActions
from console.screens.mission_plan import PlanActions
from console.screens.mission_run import RunActions
from console.screens.schedule_keys import footer_now, refused_off_schedule, schedule_action
from console.state import link
from console.state.actions import BY_NAME
from console.state.changes import StateChange, Topic
from console.state.files import RecentFiles
from console.state.freshness import EtaTicks
from console.state.keys import KeyNames
from console.state.model import CONNECTED, REVIEW, ConsoleModel
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
    _connection(t, m)
    if m.read_only:
        t.append(f"   {m.read_only}", style="bold")
    if marks:
        t.append(f"   marked: {', '.join(marks)}", style="bold")
    return t


def _connection(t: Text, m: ConsoleModel) -> None:
    """The connection's state, where to, and why not (a review has none)."""
    if m.connection == REVIEW:
        return
    t.append(f"   {connection_text(m.connection)}")
    if m.endpoint:
        t.append(f" {m.endpoint}", style="dim")
    if m.connection_detail and m.connection != CONNECTED:
        t.append(f" — {m.connection_detail}", style="dim")


def connection_news(m: ConsoleModel, before: str) -> tuple[str, str] | None:
    """What the status line says when the connection went from `before` to now."""
    if m.connection == before:
        return None
    if m.connection == "reconnecting":
        return (
            f"connection to {m.endpoint} lost — reconnecting (the server may be restarting)…",
            "warning",
        )
    if m.connection == CONNECTED and before == "reconnecting":
        revision = m.mission.revision if m.mission else "?"
        return f"reconnected to {m.endpoint}: state resynchronized at revision {revision}", "ok"
    return None


class MissionScreen(Screen):
    SCOPE = "mission"  # its actions (console/state/actions.py)
    # the actions table's keys are dispatched by on_key (schedule_keys.py), not bound
    BINDINGS = [
        bind("app.help", "help", show=False),
        Binding("escape", "clear_marks", "Clear marks", show=False),
    ]
    CSS_PATH = TCSS
    action_give_to = give_action  # "give to…" (console/screens/give_to.py)

    def __init__(
        self,
        model: ConsoleModel,
        changes: Signal[StateChange],
        ops: OperationService,
        recent: RecentFiles | None = None,
    ) -> None:
        super().__init__()
        self.model = model
        self.changes = changes
        self.ops = ops
        # kept as attributes: messages may arrive while the screen is being torn down
        self._topbar = TopBar(id="topbar")
        self.schedule = ScheduleView(model, id="schedule")
        self.editor = ParamEditor(model, id="editor")
        self._status = StatusLine("", id="status")
        self._footer = KeyBar("", id="keys")
        self.message = ""
        self._connection = model.connection  # as last shown (what a change of it says)
        self.plan = PlanActions(self)
        self.run = RunActions(self)
        self.files = FileActions(self, recent or RecentFiles())

    def compose(self) -> ComposeResult:
        yield self._topbar
        with Horizontal(id="main"):
            yield self.schedule
            yield self.editor
        yield self._status
        yield self._footer

    def on_mount(self) -> None:
        self.set_class(self.app.size.width < NARROW, "-narrow")
        self.schedule.focus()
        self.update_top()
        self.schedule.rebuild()
        self._stale: frozenset[str] = frozenset()
        self._etas = EtaTicks()  # running skills' ETAs count down between samples
        self.changes.subscribe(self, self.changed)
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
        for robot in stale | self._etas.ticked(self.model):
            self.schedule.refresh_telemetry(robot)
        for robot in self.model.robot_order():  # the ages of commands waiting for a robot
            if self.model.pending(robot):
                self.schedule.refresh_uplinking(robot)

    def on_resize(self, event: events.Resize) -> None:
        self.update_keys()
        narrow = event.size.width < NARROW
        if narrow != self.has_class("-narrow"):
            self.set_class(narrow, "-narrow")
            if not narrow:
                self.remove_class("-editing")
                self.run_worker(
                    self.editor.show_skill(self.schedule.cursor_id), group="editor", exclusive=True
                )

    @property
    def editor_visible(self) -> bool:
        return not self.has_class("-narrow") or self.has_class("-editing")

    # -- the model changed ------------------------------------------------------------------
    async def changed(self, c: StateChange) -> None:
        """Redraw what the change touches."""
        if c.about(Topic.MISSION) and c.robots != frozenset():
            await self.model_changed(None if c.robots is None else set(c.robots))
            self.plan.seen(c.revision, c.moved)  # the cursor may follow an undo
        if c.about(Topic.FLEET):
            self.schedule.refresh()  # partners' columns show it too (barriers)
            self.update_keys()
        if c.about(Topic.TELEMETRY):
            for robot in c.robots or ():
                self.schedule.refresh_telemetry(robot)
        if c.about(Topic.CONNECTION):
            await self.connection_changed()
        if c.about(Topic.FINDINGS):  # the rows' check glyphs and what sync allows
            self.schedule.refresh()
            self.update_keys()
        if c.about(Topic.ALERTS) or c.about(Topic.MAP):
            self.update_top()  # the badge, the sim's score and clock
        for a in c.alerts:
            if a.level == "error":
                self.say(f"✗ {a.message}", "error")

    async def model_changed(self, robots: set[str] | None) -> None:
        self.schedule.rebuild(robots)
        self.schedule.marks = [m for m in self.schedule.marks if self.model.owner(m) is not None]
        self.plan.arrived()
        self.update_top()
        self.update_keys()
        if self.editor_visible:
            if self.editor.skill_id != self.schedule.cursor_id:
                await self.editor.show_skill(self.schedule.cursor_id)
            else:
                await self.editor.model_changed()
        self.editor.prune_drafts()

    async def connection_changed(self) -> None:
        before, self._connection = self._connection, self.model.connection
        news = connection_news(self.model, before)
        if news is not None:
            self.say(*news)
            if news[1] == "ok":
                self.app.notify("reconnected; state resynchronized", title="Server", timeout=3)
        self.update_top()
        self.update_keys()
        if self.editor_visible:
            await self.editor.model_changed()

    def on_screen_resume(self) -> None:
        """Back from the timeline or the checks: the cursor follows their selection."""
        sid, cols = self.model.selection.skill, self.schedule.columns
        if sid and cols and sid not in cols[self.schedule.cursor_col].line_of:
            self.schedule.select(sid)

    def update_top(self) -> None:
        keys = key_names(self)
        text = top_text(self.model, self.model.alerts.unacknowledged, self.schedule.marks, keys)
        self._topbar.show(text, self.model.connection)

    def say(self, text: str, severity: str = "info") -> None:
        """The status line: the last outcome, refusal or explanation."""
        self.message = text
        self._status.show(text, severity)

    # -- selection ---------------------------------------------------------------------------------
    @on(ScheduleView.CursorMoved)
    async def _cursor_moved(self, event: ScheduleView.CursorMoved) -> None:
        self.update_keys()
        c = self.model.uplinking(event.skill_id) if event.skill_id else None
        if c is not None:  # its row may have no room for the command: the status line has
            cancel = None if self.model.read_only else key_names(self).say("mission.cancel")
            self.say(link.waiting_text(event.skill_id, c, self.model.clock, cancel))
        if self.editor_visible:
            await self.editor.show_skill(event.skill_id)

    def selection(self) -> tuple[str | None, str | None]:
        return self.schedule.cursor_robot, self.schedule.cursor_id

    def update_keys(self) -> None:
        """The footer: the keys that apply now (console/screens/schedule_keys.py);
        keys are checked again when pressed (`run_named`)."""
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
    @work(group="ops", exit_on_error=False)
    async def submit(
        self,
        op: Any,
        what: str,
        *,
        then: Callable[[Any], object] | None = None,
        refused: Callable[[Any], object] | None = None,
        **kw: Any,
    ) -> None:
        """Submit `op` and await its outcome here (the service says it on the
        status line); `then(reply)` says what it did instead of "✓ what";
        `refused(error_reply)` after a refusal."""
        outcome = await self.ops.submit(op, what, say=self.say, done="" if then else None, **kw)
        if outcome.reply is not None and then is not None:
            then(outcome.reply)
        elif outcome.refusal is not None and refused is not None:
            refused(outcome.refusal)

    # -- the editor ------------------------------------------------------------------------------
    async def action_edit(self) -> None:
        if self.has_class("-narrow"):
            self.add_class("-editing")
        await self.editor.show_skill(self.schedule.cursor_id)
        self.editor.focus_first()

    async def edit_selected(self) -> None:
        if self.plan.edit_after_select:
            self.plan.edit_after_select = False
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
        changed = ", ".join(event.changed())

        def refused(reply: Any) -> None:
            if reply.skill in (None, event.skill_id) and self.editor.skill_id == event.skill_id:
                self.editor.show_param_error(reply.param, reply.message)

        self.submit(
            event.operation(),
            f"edit {event.skill_id}",
            robot=self.model.owner(event.skill_id),
            skill=event.skill_id,
            expected_revision=event.base_revision,
            then=lambda r: self.say(f"{event.skill_id}: applied {changed}", "ok"),
            refused=refused,
        )

    # -- the keys' actions: the screen's own, then its parts' -----------------------------------
    def action_help(self) -> None:
        self.post_message(HelpRequested())

    def action_clear_marks(self) -> None:
        if self.schedule.marks:
            self.schedule.clear_marks()
            self.update_top()
            self.update_keys()
            self.say("marks cleared")

    def action_toggle_static(self) -> None:
        self.schedule.set_expand_static(not self.schedule.expand_static)

    def action_mark(self) -> None:
        robot, sid = self.selection()
        if sid is None:
            return
        marked = self.schedule.toggle_mark(sid)
        self.update_top()
        self.update_keys()
        n = len(self.schedule.marks)
        barrier = key_names(self).say("mission.barrier")
        self.say(
            f"{'marked' if marked else 'unmarked'} {sid}; {n} marked"
            + (f" — {barrier} makes the barrier" if n >= 2 else " — mark a skill of another robot")
        )

    @work(group="dialog")
    async def action_add(self) -> None:
        await self.plan.add()

    @work(group="dialog")
    async def action_delete(self) -> None:
        await self.plan.delete()

    def action_move_up(self) -> None:
        self.plan.move(-1)

    def action_move_down(self) -> None:
        self.plan.move(1)

    def action_barrier(self) -> None:
        self.plan.barrier()

    def action_unbarrier(self) -> None:
        self.plan.unbarrier()

    def action_duplicate(self) -> None:
        self.plan.duplicate()

    def action_retry_edit(self) -> None:
        self.plan.retry_edit()

    def action_undo(self) -> None:
        self.plan.undo()

    def action_redo(self) -> None:
        self.plan.redo()

    def action_search(self) -> None:
        self.plan.search()

    def action_sync(self) -> None:
        self.run.sync()

    def action_unsync(self) -> None:
        self.run.sync(undo=True)

    @work(group="dialog")
    async def action_cancel(self) -> None:
        c = self.model.uplinking(self.schedule.cursor_id or "")
        if c is not None:
            await ask_and_cancel(self, self.ops, c, self.say)

    def action_retry(self) -> None:
        self.run.retry()

    def action_run(self) -> None:
        self.run.control("run", self.schedule.cursor_robot)

    def action_pause(self) -> None:
        self.run.control("pause", self.schedule.cursor_robot)

    def action_stop(self) -> None:
        self.run.control("stop", self.schedule.cursor_robot)

    @work(group="dialog")
    async def action_reset(self) -> None:
        if self.schedule.cursor_robot:
            await self.run.reset(self.schedule.cursor_robot)

    def action_run_all(self) -> None:
        self.run.control("run", None)

    def action_pause_all(self) -> None:
        self.run.control("pause", None)

    def action_stop_all(self) -> None:
        self.run.control("stop", None)

    @work(group="dialog")
    async def action_reset_all(self) -> None:
        await self.run.reset(None)

    @work(group="dialog")
    async def action_save(self) -> None:
        await self.files.save_mission()

    @work(group="dialog")
    async def action_load(self) -> None:
        await self.files.load()
