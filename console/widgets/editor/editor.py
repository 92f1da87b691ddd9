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
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.message import Message
from textual.widgets import Button, Input, Label, Select, Static, Switch, TextArea

from backend.core.model import Policies, SkillInstance, Status
from backend.core.ops import EditSkill
from console.bindings import bindings, key_names
from console.state.markers import relabel
from console.state.model import ConsoleModel
from console.state.text import GLYPHS, STATUS_CSS, STATUS_WORDS
from console.widgets.editor.changes import ReadsEdits
from console.widgets.editor.fields import EnterPressed, FieldInput
from console.widgets.editor.inputs import (
    INPUTS,
    POLICY_HINTS,
    TYPED,
    param_inputs,
    policy_inputs,
    read_binding,
    read_policies,
    set_widget_value,
    spec_hint,
    widget_value,
)


@dataclass
class Draft:
    """Unapplied changes to a skill the editor does not show right now."""

    values: dict[str, Any]  # widget id -> what was typed / chosen
    rev: int  # the skill's revision when the editing started
    base_revision: int  # the mission revision the changes were made against
    changed: list[str]  # what differs (for messages)


def settle_cursors(root: Any) -> None:
    """No blinking cursors when the app asks for none (deterministic snapshots)."""
    if not getattr(root.app, "cursor_blink", True):
        for w in root.query("Input, TextArea"):
            w.cursor_blink = False


class ParamEditor(ReadsEdits, VerticalScroll):
    """Edits one skill. Posts `ApplyRequested` with only what changed.
    Its look: editor.tcss (loaded by the app)."""

    # apply (also enter in a field: Input.Submitted), revert, leave: the actions table's
    BINDINGS = bindings("editor")

    class ApplyRequested(Message):
        def __init__(
            self,
            skill_id: str,
            label: str | None,
            params: dict[str, Any],
            bindings: dict[str, str | None],
            base_revision: int,
            policies: Policies | None = None,
        ) -> None:
            super().__init__()
            self.skill_id = skill_id
            self.label = label
            self.params = params
            self.bindings = bindings
            self.base_revision = base_revision
            self.policies = policies

        def operation(self) -> EditSkill:
            return EditSkill(
                id=self.skill_id,
                label=self.label,
                params=self.params,
                bindings=self.bindings,
                policies=self.policies,
            )

        def changed(self) -> list[str]:
            """What the operation changes (for the status line), each once: a
            typed value replacing a binding changes both for one parameter."""
            return list(
                dict.fromkeys(
                    [*self.params, *self.bindings]
                    + (["label"] if self.label is not None else [])
                    + (["policies"] if self.policies is not None else [])
                )
            )

    class DraftsChanged(Message):
        """Which skills have unapplied changes; `discarded`: sentences about
        drafts dropped because their skill left idle or was deleted."""

        def __init__(self, unapplied: frozenset[str], discarded: list[str]) -> None:
            super().__init__()
            self.unapplied = unapplied
            self.discarded = discarded

    class Left(Message):
        """The operator left the editor (escape)."""

    def __init__(self, model: ConsoleModel, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.model = model
        self.skill_id: str | None = None
        self.loaded_rev = -1
        self.base_revision = 0
        self.errors: dict[str, str] = {}
        self.server_error = ""
        self.stale_note = ""
        self.can_focus = False
        self._load_lock = asyncio.Lock()
        self.drafts: dict[str, Draft] = {}
        self.dirty: list[str] = []  # what differs in the shown skill (empty: nothing)
        self._unapplied: frozenset[str] = frozenset()
        self._choices: dict[str, str | None] = {}  # Select id -> the marker it showed

    # -- what is shown ------------------------------------------------------------------
    def _skill(self) -> tuple[str, SkillInstance] | None:
        found = self.model.find(self.skill_id)
        return (found[0], found[2]) if found else None

    def _spec(self, skill: SkillInstance):
        lib = self.model.library
        return lib.skills.get(skill.skill) if lib else None

    @property
    def read_only_reason(self) -> str | None:
        if self.skill_id is None:
            return "no skill selected"
        return self.model.read_only_reason(self.skill_id)

    @property
    def loading(self) -> bool:
        """A skill is being (re)loaded: the fields are being rebuilt."""
        return self._load_lock.locked()

    async def show_skill(
        self, skill_id: str | None, *, force: bool = False, discard: bool = False
    ) -> None:
        """Load a skill (serialized: the app and the screen both call this,
        from different message pumps, and two rebuilds must not interleave).
        Unapplied changes of the skill shown so far are kept as its draft
        unless `discard`."""
        async with self._load_lock:
            await self._show_skill(skill_id, force=force, discard=discard)

    async def _show_skill(
        self, skill_id: str | None, *, force: bool = False, discard: bool = False
    ) -> None:
        found = self.model.find(skill_id)
        rev = found[2].rev if found else -1
        if not force and skill_id == self.skill_id and rev == self.loaded_rev:
            return
        if self.skill_id is not None:
            if discard:
                self.drafts.pop(self.skill_id, None)
            elif self.dirty:
                # against the skill as it is now (our own apply leaves nothing);
                # a deleted skill keeps what was last seen, for the message
                pending = (
                    self.changed_names(even_read_only=True)
                    if self._skill() is not None
                    else self.dirty
                )
                if pending:
                    self.dirty = pending
                    self.drafts[self.skill_id] = self._capture()
        same = skill_id == self.skill_id
        if not same:
            self.errors = {}
            self.server_error = ""
        self.skill_id = skill_id
        self.loaded_rev = rev
        self.stale_note = ""
        self.base_revision = self.model.mission.revision if self.model.mission else 0
        self.dirty = []
        had_focus = self.focus_within()
        focused = self.screen.focused if had_focus and same else None
        field = focused.id if focused is not None else None  # after an apply: stay in it
        draft = (
            self.drafts.pop(skill_id, None)
            if skill_id is not None and self.read_only_reason is None
            else None
        )
        if draft is not None and draft.rev != rev:
            self.stale_note = (
                f"{skill_id} was changed by someone else since you started these changes "
                f"(revision {rev}): revert to see it; applying will be refused as stale"
            )
        await self.recompose()
        settle_cursors(self)
        self._choices = {  # what each marker choice shows (a label may name it)
            w.id: None if w.value in (TYPED, Select.NULL) else str(w.value)
            for w in self.query(Select)
            if w.id
        }
        if draft is not None:
            self._restore(draft)
        self._validate_all()
        self._update_dirty()
        if had_focus:  # the focused field was rebuilt: keep the operator in it
            self.focus_field(field)

    # -- drafts: unapplied changes per skill ---------------------------------------------
    def _capture(self) -> Draft:
        values = {w.id: widget_value(w) for w in self.query(INPUTS) if w.id}
        return Draft(
            values=values,
            rev=self.loaded_rev,
            base_revision=self.base_revision,
            changed=list(self.dirty),
        )

    def _restore(self, draft: Draft) -> None:
        self.base_revision = draft.base_revision
        for w in self.query(INPUTS):
            if w.id in draft.values:
                try:
                    set_widget_value(w, draft.values[w.id])
                except Exception:  # e.g. a marker that no longer exists: keep the shown value
                    pass
        for name in [
            w.id.removeprefix("bind-")
            for w in self.query(Select)
            if w.id and w.id.startswith("bind-")
        ]:
            self._sync_bound_fields(name)

    def prune_drafts(self) -> list[str]:
        """Drop drafts whose skill was deleted or is no longer idle; say which."""
        said: list[str] = []
        for sid in list(self.drafts):
            found = self.model.find(sid)
            if found is not None and found[2].status == Status.IDLE:
                continue
            draft = self.drafts.pop(sid)
            what = ", ".join(draft.changed) or "changes"
            if found is None:
                said.append(
                    f"{sid} was deleted: your unapplied changes to it ({what}) are discarded"
                )
            else:
                said.append(
                    f"{sid} is now {STATUS_WORDS[found[2].status]} on {found[0]}: your unapplied "
                    f"changes to it ({what}) are discarded — only idle skills can be edited"
                )
        self._post_drafts(said)
        return said

    def _post_drafts(self, discarded: list[str] | None = None) -> None:
        unapplied = frozenset(self.drafts) | (
            {self.skill_id} if self.dirty and self.skill_id else frozenset()
        )
        if unapplied != self._unapplied or discarded:
            self._unapplied = frozenset(unapplied)
            self.post_message(self.DraftsChanged(self._unapplied, list(discarded or [])))

    def _update_dirty(self) -> None:
        """Recompute what differs from the skill; show it; tell the screen."""
        self.dirty = self.changed_names()
        keys = key_names(self)
        how = f"{keys.say('editor.apply')} applies, {keys.say('editor.revert')} reverts"
        try:
            line = self.query_one("#dirty", Static)
        except Exception:
            line = None  # being rebuilt
        if line is not None:
            changes = f"unapplied changes: {', '.join(self.dirty)} — " if self.dirty else ""
            line.update(changes + how)
            line.set_class(not self.dirty, "-clean")
        self._post_drafts()

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

    async def model_changed(self) -> None:
        """The mission changed: reload unless the operator has unapplied changes."""
        found = self.model.find(self.skill_id)
        if found is None:
            if self.skill_id is not None:
                await self.show_skill(None)
            return
        s = found[2]
        ro_changed = (self.read_only_reason is None) != self._was_editable
        if s.rev != self.loaded_rev or ro_changed:
            # dirty against the new version (our own apply leaves nothing dirty)
            if not ro_changed and self.is_dirty():
                self.stale_note = (
                    f"{s.id} was changed by someone else (revision {s.rev}): revert to see it; "
                    "applying will be refused as stale"
                )
                self._set_static("#stale", self.stale_note)
            else:  # unapplied changes become a draft: restored, or dropped (and said) if not idle
                await self.show_skill(self.skill_id, force=True)

    def compose(self) -> ComposeResult:
        found = self._skill()
        self._was_editable = False
        if found is None:
            yield Static(
                "Select a skill in the schedule to see and edit its parameters.", classes="empty"
            )
            return
        robot, s = found
        spec = self._spec(s)
        ro = self.read_only_reason
        self._was_editable = ro is None
        title = Text()
        title.append(f"{GLYPHS[s.status]} ", style="bold")
        title.append(f"{s.id}", style="bold")
        title.append(f"  {s.skill} on {robot}")
        if s.attempt > 1:
            title.append(f"  attempt {s.attempt}")
        yield Static(title, classes=f"title status-{STATUS_CSS[s.status]}")
        if spec is not None and spec.description:
            yield Static(spec.description, classes="skill-desc")
        if ro:
            yield Static(f"read-only: {ro}", id="readonly", classes="readonly")
        yield Static(
            self.server_error,
            id="server-error",
            classes="server-error" + ("" if self.server_error else " -empty"),
        )
        yield Static(
            self.stale_note, id="stale", classes="stale" + ("" if self.stale_note else " -empty")
        )
        # always one line while editable, so its words never move the fields under the cursor
        yield Static("", id="dirty", classes="dirty" + ("" if ro is None else " -empty"))
        with Vertical(classes="param", id="param-label"):
            yield Label(Text.assemble(("label", "bold"), ("  text", "dim")), classes="plabel")
            yield FieldInput(
                s.label, id="f-label", compact=True, disabled=ro is not None, placeholder=s.skill
            )
        if spec is None:
            yield Static(f"skill '{s.skill}' is not in the library", classes="perror")
            return
        for name, pspec in spec.params.items():
            with Vertical(classes="param", id=f"param-{name}"):
                yield Label(
                    Text.assemble((name, "bold"), ("  " + spec_hint(pspec), "dim")),
                    classes="plabel",
                )
                yield from param_inputs(name, pspec, s, self.model.mission, disabled=ro is not None)
                if pspec.description:
                    yield Static(pspec.description, classes="pdesc")
                err = self.errors.get(name, "")
                yield Static(err, id=f"err-{name}", classes="perror" + ("" if err else " -empty"))
        yield from policy_inputs(s.policies, disabled=ro is not None)
        if ro is None:
            with Horizontal(classes="buttons"):
                keys = key_names(self)
                apply, revert = keys.short("editor.apply"), keys.short("editor.revert")
                yield Button(f"Apply {apply}", id="apply", variant="primary", compact=True)
                yield Button(f"Revert {revert}", id="revert", compact=True)

    # -- messages next to fields --------------------------------------------------------------
    def _set_static(self, selector: str, text: str) -> None:
        try:
            w = self.query_one(selector, Static)
        except Exception:
            return
        w.update(text)
        w.set_class(not text, "-empty")

    def show_param_error(self, param: str | None, message: str) -> None:
        """A refusal from the server: next to its field, else on top."""
        if param and self.query(f"#err-{param}"):
            self.errors[param] = message
            self._set_static(f"#err-{param}", message)
        else:
            self.server_error = message
            self._set_static("#server-error", message)

    def clear_server_errors(self) -> None:
        self.server_error = ""
        self._set_static("#server-error", "")

    def _validate_all(self) -> None:
        if self._skill() is None or self.read_only_reason is not None:
            return
        _, _, _, problems = self.collect()
        spec = self._spec(self._skill()[1])
        for name in spec.params if spec else []:
            msg = problems.get(name) or self.errors.get(name, "")
            self._set_static(f"#err-{name}", msg)
        _, policy_problems = read_policies(self)
        for name in POLICY_HINTS:
            self._set_static(f"#perr-{name}", policy_problems.get(name, ""))

    def _field_changed(self, widget_id: str | None) -> None:
        if not widget_id or self.skill_id is None:
            return
        if widget_id.startswith("pf-"):
            name = widget_id.removeprefix("pf-")
            for sw in self.query(f"#pf-{name}").results(Switch):
                self._set_static(f"#pv-{name}", "yes" if sw.value else "no")
            self._validate_all()
            self._update_dirty()
            return
        name = widget_id.removeprefix("f-").removeprefix("bind-")
        found = self._skill()
        spec = self._spec(found[1]) if found else None
        if spec is None:
            return
        for pname in spec.params:
            if name == pname or name.startswith(pname + "-"):
                self.errors.pop(pname, None)  # a server message is about the old value
                break
        if widget_id.startswith("bind-") or widget_id.startswith("f-"):
            self._relabel(widget_id)
        if widget_id.startswith("bind-"):
            self._sync_bound_fields(name)
        for sw in self.query(f"#f-{name}").results(Switch):  # the value in words, not only colour
            self._set_static(f"#v-{name}", "yes" if sw.value else "no")
        self._validate_all()
        self._update_dirty()

    def _relabel(self, widget_id: str) -> None:
        """A marker chosen instead of another: a label naming the old marker
        ("drive to POI-A") names the new one, in the label field (applied
        with the rest, or reverted)."""
        try:
            select = self.query_one(f"#{widget_id}", Select)
            label = self.query_one("#f-label", Input)
        except Exception:
            return  # not a choice (or being rebuilt)
        chosen = None if select.value in (TYPED, Select.NULL) else str(select.value)
        before = self._choices.get(widget_id)
        self._choices[widget_id] = chosen
        new = relabel(label.value, before, chosen)
        if new is not None:
            label.value = new

    def _sync_bound_fields(self, name: str) -> None:
        bound = read_binding(self, name)
        for w in self.query(f"#param-{name} Input, #param-{name} TextArea"):
            w.disabled = bound is not None or self.read_only_reason is not None

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
        label, params, bindings, problems = self.collect()
        policies, policy_problems = self.policies_change()
        if problems or policy_problems:
            for name, msg in problems.items():
                self._set_static(f"#err-{name}", msg)
            for name, msg in policy_problems.items():
                self._set_static(f"#perr-{name}", msg)
            what, first = (
                ("parameter", next(iter(problems)))
                if problems
                else ("policy", next(iter(policy_problems)))
            )
            self.app.notify(
                f"{found[1].id}, {what} {first}: {(problems or policy_problems)[first]}",
                title="Not applied",
                severity="error",
            )
            return
        if label is None and not params and not bindings and policies is None:
            self.app.notify("nothing changed", timeout=2)
            return
        self.clear_server_errors()
        self.post_message(
            self.ApplyRequested(found[1].id, label, params, bindings, self.base_revision, policies)
        )

    async def action_revert(self) -> None:
        self.errors = {}
        self.server_error = ""
        await self.show_skill(self.skill_id, force=True, discard=True)

    def action_leave(self) -> None:
        if self.focus_within():  # at once: a key typed right after escape is not the field's
            self.screen.set_focus(None)
        self.post_message(self.Left())
