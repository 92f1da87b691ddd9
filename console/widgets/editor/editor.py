"""The parameter editor: one typed input per parameter of the selected skill.

bool: switch; int/float: number input with unit and bounds in the label;
str: text; enum: a choice; pose: six fields, position: three; area, list and
dict: YAML text; marker: a choice of markers of the allowed kinds; robot: a
choice of the mission's robots. Pose, position and area parameters can also
be bound to a marker. Values are checked as you type with the same checks the
server runs (`backend.core.library.check_value`); the server's refusal for a
parameter appears next to that field. Below the parameters, the skill's
policies (autonomous retries, pause out of comms range, recharge below a
battery level), checked with the protocol's own model. Read-only, with the
reason, when the skill is not idle.

Unapplied changes are kept per skill as a draft when the cursor moves away
(or the editor is rebuilt), and restored when the skill is shown again; the
schedule marks such skills. A draft is dropped — and the operator told — when
its skill leaves idle or is deleted; it survives a lost connection.

The widget loads a skill and follows its fields; what it shows is composed by
form.py, read back by changes.py; the notes beside the fields (notes.py), the
marker choices (choices.py) and the drafts (drafts.py) are objects it owns.
"""

from __future__ import annotations

import asyncio
from typing import Any

from textual import on
from textual.app import ComposeResult
from textual.containers import VerticalScroll
from textual.message import Message
from textual.widgets import Button, Input, Select, Static, Switch, TextArea

from backend.core.library import SkillSpec
from backend.core.model import SkillInstance
from console.bindings import bindings, key_names
from console.state.keys import KeyNames
from console.state.model import ConsoleModel
from console.widgets.editor import changes
from console.widgets.editor.changes import Collected
from console.widgets.editor.choices import MarkerChoices
from console.widgets.editor.drafts import Draft, DraftBook, capture, restore
from console.widgets.editor.fields import EnterPressed
from console.widgets.editor.form import NO_SKILL, Editing, skill_form
from console.widgets.editor.inputs import read_policies
from console.widgets.editor.messages import ApplyRequested, DraftsChanged, EditorLeft
from console.widgets.editor.notes import FieldNotes, set_note


def settle_cursors(root: Any) -> None:
    """No blinking cursors when the app asks for none (deterministic snapshots)."""
    if not getattr(root.app, "cursor_blink", True):
        for w in root.query("Input, TextArea"):
            w.cursor_blink = False


def param_of(name: str, params: dict[str, Any]) -> str | None:
    """The parameter a field belongs to (`goal-x`: `goal`)."""
    return next((p for p in params if name == p or name.startswith(p + "-")), None)


def dirty_text(dirty: list[str], keys: KeyNames) -> str:
    how = f"{keys.say('editor.apply')} applies, {keys.say('editor.revert')} reverts"
    return (f"unapplied changes: {', '.join(dirty)} — " if dirty else "") + how


class ParamEditor(VerticalScroll):
    """Edits one skill. Posts `ApplyRequested` with only what changed.
    Its look: editor.tcss (loaded by the app)."""

    # apply (also enter in a field: Input.Submitted), revert, leave: the actions table's
    BINDINGS = bindings("editor")

    ApplyRequested = ApplyRequested
    DraftsChanged = DraftsChanged
    Left = EditorLeft

    def __init__(self, model: ConsoleModel, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.model = model
        self.skill_id: str | None = None
        self.loaded_rev = -1
        self.base_revision = 0
        self.can_focus = False
        self._load_lock = asyncio.Lock()
        self.drafts = DraftBook()
        self.dirty: list[str] = []  # what differs in the shown skill (empty: nothing)
        self._unapplied: frozenset[str] = frozenset()
        self._was_editable = False
        self.notes = FieldNotes(self)
        self.choices = MarkerChoices(self)

    # -- what is shown ------------------------------------------------------------------
    def _skill(self) -> tuple[str, SkillInstance] | None:
        found = self.model.find(self.skill_id)
        return (found[0], found[2]) if found else None

    def _spec(self, skill: SkillInstance) -> SkillSpec | None:
        lib = self.model.library
        return lib.skills.get(skill.skill) if lib else None

    @property
    def read_only_reason(self) -> str | None:
        if self.skill_id is None:
            return "no skill selected"
        return self.model.read_only_reason(self.skill_id)

    @property
    def errors(self) -> dict[str, str]:
        """parameter -> the server's refusal of it."""
        return self.notes.errors

    @property
    def loading(self) -> bool:
        """A skill is being (re)loaded: the fields are being rebuilt."""
        return self._load_lock.locked()

    # -- reading the form back (changes.py) -------------------------------------------------
    def collect(self) -> Collected:
        """(label change, params changed, bindings changed, problems per parameter)."""
        found = self._skill()
        if found is None:
            return None, {}, {}, {}
        s = found[1]
        return changes.collect(self, s, self._spec(s), self.model.mission)

    def changed_names(self, *, even_read_only: bool = False) -> list[str]:
        """What differs from the skill (including fields that do not read)."""
        found = self._skill()
        if found is None or (self.read_only_reason is not None and not even_read_only):
            return []
        s = found[1]
        return changes.changed_names(self, s, self._spec(s), self.model.mission)

    def is_dirty(self) -> bool:
        return bool(self.changed_names())

    # -- loading a skill --------------------------------------------------------------------
    async def show_skill(
        self, skill_id: str | None, *, force: bool = False, discard: bool = False
    ) -> None:
        """Load a skill (serialized: the app and the screen both call this,
        from different message pumps, and two rebuilds must not interleave).
        Unapplied changes of the skill shown so far are kept as its draft
        unless `discard`."""
        async with self._load_lock:
            await self._show_skill(skill_id, force=force, discard=discard)

    async def _show_skill(self, skill_id: str | None, *, force: bool, discard: bool) -> None:
        found = self.model.find(skill_id)
        rev = found[2].rev if found else -1
        if not force and (skill_id, rev) == (self.skill_id, self.loaded_rev):
            return  # shown as it is
        self._keep_draft(discard)
        same = skill_id == self.skill_id
        had_focus = self.focus_within()
        field = self._focused_id() if had_focus and same else None  # after an apply: stay in it
        self._start(skill_id, rev, same)
        draft = self._draft_for(skill_id, rev)
        await self.recompose()
        self._composed(draft)
        if had_focus:  # the focused field was rebuilt: keep the operator in it
            self.focus_field(field)

    def _keep_draft(self, discard: bool) -> None:
        """The unapplied changes of the skill shown so far become its draft (unless `discard`)."""
        if self.skill_id is None:
            return
        if discard:
            self.drafts.pop(self.skill_id, None)
            return
        if not self.dirty:
            return
        # against the skill as it is now (our own apply leaves nothing);
        # a deleted skill keeps what was last seen, for the message
        exists = self._skill() is not None
        pending = self.changed_names(even_read_only=True) if exists else self.dirty
        if pending:
            self.dirty = pending
            self.drafts[self.skill_id] = capture(self, self.loaded_rev, self.base_revision, pending)

    def _start(self, skill_id: str | None, rev: int, same: bool) -> None:
        if not same:
            self.notes.clear()
        self.skill_id = skill_id
        self.loaded_rev = rev
        self.notes.stale_note = ""
        self.base_revision = self.model.mission.revision if self.model.mission else 0
        self.dirty = []

    def _draft_for(self, skill_id: str | None, rev: int) -> Draft | None:
        """The skill's draft, if it has one and may be edited."""
        if skill_id is None or self.read_only_reason is not None:
            return None
        draft = self.drafts.pop(skill_id, None)
        if draft is not None and draft.rev != rev:
            self.notes.stale(skill_id, rev, since_draft=True)
        return draft

    def _composed(self, draft: Draft | None) -> None:
        """A new form: the draft's values back, checked."""
        settle_cursors(self)
        self.choices.remember()
        if draft is not None:
            self.base_revision = draft.base_revision
            restore(self, draft)
            self.choices.sync_all_bound(self.read_only_reason is not None)
        self._validate_all()
        self._update_dirty()

    def compose(self) -> ComposeResult:
        found = self._skill()
        self._was_editable = False
        if found is None:
            yield Static(NO_SKILL, classes="empty")
            return
        robot, s = found
        ro = self.read_only_reason
        self._was_editable = ro is None
        editing = Editing(robot, s, self._spec(s), ro, self.model.mission)
        yield from skill_form(editing, self.notes, key_names(self))

    async def model_changed(self) -> None:
        """The mission changed: reload unless the operator has unapplied changes."""
        found = self.model.find(self.skill_id)
        if found is None:
            if self.skill_id is not None:
                await self.show_skill(None)
            return
        s = found[2]
        ro_changed = (self.read_only_reason is None) != self._was_editable
        if s.rev == self.loaded_rev and not ro_changed:
            return
        # dirty against the new version (our own apply leaves nothing dirty)
        if not ro_changed and self.is_dirty():
            self.notes.stale(s.id, s.rev)
        else:  # unapplied changes become a draft: restored, or dropped (and said) if not idle
            await self.show_skill(self.skill_id, force=True)

    # -- drafts: unapplied changes per skill (drafts.py) -------------------------------------
    def prune_drafts(self) -> list[str]:
        """Drop drafts whose skill was deleted or is no longer idle; say which."""
        said = self.drafts.prune(self.model)
        self._post_drafts(said)
        return said

    def _post_drafts(self, discarded: list[str] | None = None) -> None:
        unapplied = self.drafts.unapplied(self.skill_id if self.dirty else None)
        if unapplied != self._unapplied or discarded:
            self._unapplied = unapplied
            self.post_message(DraftsChanged(unapplied, list(discarded or [])))

    def _update_dirty(self) -> None:
        """Recompute what differs from the skill; show it; tell the screen."""
        self.dirty = self.changed_names()
        try:
            line = self.query_one("#dirty", Static)
        except Exception:
            line = None  # being rebuilt
        if line is not None:
            line.update(dirty_text(self.dirty, key_names(self)))
            line.set_class(not self.dirty, "-clean")
        self._post_drafts()

    # -- focus ------------------------------------------------------------------------------
    def _focused_id(self) -> str | None:
        focused = self.screen.focused
        return focused.id if focused is not None else None

    def focus_within(self) -> bool:
        focused = self.screen.focused if self.is_attached else None
        return focused is not None and self in focused.ancestors_with_self

    def focus_field(self, field: str | None) -> None:
        """Focus the field with this id (the one the operator was in), else the first."""
        found = self.query(f"#{field}") if field else None
        if found and found.first().focusable:
            self.screen.set_focus(found.first())
        else:
            self.focus_first()

    def focus_first(self) -> None:
        for w in self.query("Input, Switch, Select, TextArea, Button"):
            if w.focusable:
                self.screen.set_focus(w)
                return
        self.can_focus = True
        self.screen.set_focus(self)

    # -- the fields as they change --------------------------------------------------------
    def show_param_error(self, param: str | None, message: str) -> None:
        """A refusal from the server: next to its field, else on top."""
        self.notes.refused(param, message)

    def _validate_all(self) -> None:
        found = self._skill()
        if found is None or self.read_only_reason is not None:
            return
        spec = self._spec(found[1])
        self.notes.show_problems(spec.params if spec else [], self.collect()[3])
        self.notes.show_policy_problems(read_policies(self)[1])

    def _field_changed(self, widget_id: str | None) -> None:
        if not widget_id or self.skill_id is None:
            return
        if widget_id.startswith("pf-"):
            self._say_switch("pf-", "pv-", widget_id.removeprefix("pf-"))
        elif not self._param_field_changed(widget_id):
            return
        self._validate_all()
        self._update_dirty()

    def _param_field_changed(self, widget_id: str) -> bool:
        """A parameter's field (or its marker choice) changed (False: the skill has no spec)."""
        found = self._skill()
        spec = self._spec(found[1]) if found else None
        if spec is None:
            return False
        name = widget_id.removeprefix("f-").removeprefix("bind-")
        self.notes.forget(param_of(name, spec.params))  # a server message is about the old value
        if widget_id.startswith(("bind-", "f-")):
            self.choices.relabel(widget_id)
        if widget_id.startswith("bind-"):
            self.choices.sync_bound(name, self.read_only_reason is not None)
        self._say_switch("f-", "v-", name)
        return True

    def _say_switch(self, field: str, words: str, name: str) -> None:
        """A switch's value in words beside it, not only in colour."""
        for sw in self.query(f"#{field}{name}").results(Switch):
            set_note(self, f"#{words}{name}", "yes" if sw.value else "no")

    @on(Input.Changed)
    @on(Switch.Changed)
    @on(Select.Changed)
    @on(TextArea.Changed)
    def _on_field(self, event: Message) -> None:
        control = getattr(event, "control", None)
        self._field_changed(getattr(control, "id", None))

    @on(Button.Pressed, "#apply")
    def _apply_pressed(self) -> None:
        self.action_apply()

    @on(Input.Submitted)
    @on(EnterPressed)
    def _field_submitted(self, event: Message) -> None:
        """Enter in a field applies the edits (as in a form), a choice's and a switch's too."""
        event.stop()
        self.action_apply()

    @on(Button.Pressed, "#revert")
    async def _revert_pressed(self) -> None:
        await self.action_revert()

    # -- actions ---------------------------------------------------------------------------------
    def action_apply(self) -> None:
        found = self._skill()
        if found is None:
            return
        ro = self.read_only_reason
        if ro is not None:
            self.app.notify(ro, title="Read-only", severity="warning")
            return
        label, params, binds, problems = self.collect()
        policies, policy_problems = changes.policies_change(self, found[1])
        apply = ApplyRequested(found[1].id, label, params, binds, self.base_revision, policies)
        if problems or policy_problems:
            self._not_applied(found[1].id, problems, policy_problems)
        elif not apply.changed():
            self.app.notify("nothing changed", timeout=2)
        else:
            self.notes.clear_server_error()
            self.post_message(apply)

    def _not_applied(
        self, skill_id: str, problems: dict[str, str], policy_problems: dict[str, str]
    ) -> None:
        """Say what stops an apply: under each field at fault, and in a notification."""
        self.notes.mark(problems, policy_problems)
        what, faults = ("parameter", problems) if problems else ("policy", policy_problems)
        first = next(iter(faults))
        self.app.notify(
            f"{skill_id}, {what} {first}: {faults[first]}", title="Not applied", severity="error"
        )

    async def action_revert(self) -> None:
        self.notes.clear()
        await self.show_skill(self.skill_id, force=True, discard=True)

    def action_leave(self) -> None:
        if self.focus_within():  # at once: a key typed right after escape is not the field's
            self.screen.set_focus(None)
        self.post_message(EditorLeft())
