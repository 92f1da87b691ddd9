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

import yaml
from pydantic import ValidationError
from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.message import Message
from textual.widgets import Button, Input, Label, Select, Static, Switch, TextArea

from backend.core.model import Policies, SkillInstance, Status
from backend.core.params import (
    POSE_FIELDS,
    POSITION_FIELDS,
    ParamSpec,
    check_value,
    normalize_value,
)
from console.state.model import ConsoleModel
from console.state.text import GLYPHS, STATUS_CSS, STATUS_WORDS, fmt_number
from console.widgets.select import SafeSelect

TYPED = "\x00typed"  # the bind choice meaning "no marker: a typed value"
BINDABLE_KINDS = {"pose": ("pose", "position"), "position": ("pose", "position"), "area": ("area",)}
YAML_TYPES = ("area", "list", "dict")
# policy -> (label, type hint); bounds and meaning come from backend.core.model.Policies
POLICY_HINTS = {
    "retries": ("retries", "int 0..20"),
    "pause_out_of_comms": ("pause out of comms", "bool"),
    "recharge_below": ("recharge below", "float 0..1, empty: off"),
}
INPUTS = "Input, Switch, Select, TextArea"


@dataclass
class Draft:
    """Unapplied changes to a skill the editor does not show right now."""

    values: dict[str, Any]  # widget id -> what was typed / chosen
    rev: int  # the skill's revision when the editing started
    base_revision: int  # the mission revision the changes were made against
    changed: list[str]  # what differs (for messages)


def widget_value(w: Any) -> Any:
    return w.text if isinstance(w, TextArea) else w.value


def set_widget_value(w: Any, value: Any) -> None:
    if isinstance(w, TextArea):
        w.text = value
    else:
        w.value = value


def settle_cursors(root: Any) -> None:
    """No blinking cursors when the app asks for none (deterministic snapshots)."""
    if not getattr(root.app, "cursor_blink", True):
        for w in root.query("Input, TextArea"):
            w.cursor_blink = False


def yaml_text(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, list) and value and all(isinstance(x, dict) for x in value):
        return "\n".join(
            "- " + yaml.safe_dump(x, default_flow_style=True, sort_keys=False).strip()
            for x in value
        )
    return yaml.safe_dump(
        value, default_flow_style=False, sort_keys=False, allow_unicode=True
    ).strip()


def spec_hint(spec: ParamSpec) -> str:
    """type, unit and bounds: 'float m/s 0.1..1'."""
    parts = [spec.type]
    if spec.unit:
        parts.append(spec.unit)
    if spec.min is not None or spec.max is not None:
        lo = f"{spec.min:g}" if spec.min is not None else ""
        hi = f"{spec.max:g}" if spec.max is not None else ""
        parts.append(f"{lo}..{hi}")
    if spec.type == "marker" and spec.marker_kinds:
        parts.append("/".join(spec.marker_kinds))
    if spec.is_required:
        parts.append("required")
    return " ".join(parts)


class ParamEditor(VerticalScroll):
    """Edits one skill. Posts `ApplyRequested` with only what changed.
    Its look: param_editor.tcss (loaded by the app)."""

    BINDINGS = [
        Binding("ctrl+s", "apply", "Apply", id="editor.apply"),
        Binding("ctrl+r", "revert", "Revert", id="editor.revert"),
        Binding("escape", "leave", "Back", id="editor.leave"),
    ]

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
        if skill_id != self.skill_id:
            self.errors = {}
            self.server_error = ""
        self.skill_id = skill_id
        self.loaded_rev = rev
        self.stale_note = ""
        self.base_revision = self.model.mission.revision if self.model.mission else 0
        self.dirty = []
        had_focus = self.focus_within()
        draft = (
            self.drafts.pop(skill_id, None)
            if skill_id is not None and self.read_only_reason is None
            else None
        )
        if draft is not None and draft.rev != rev:
            self.stale_note = f"{skill_id} was changed by someone else since you started these changes (revision {rev}): revert to see it; applying will be refused as stale"
        await self.recompose()
        settle_cursors(self)
        if draft is not None:
            self._restore(draft)
        self._validate_all()
        self._update_dirty()
        if had_focus:  # the focused field was rebuilt: keep the operator in the editor
            self.focus_first()

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
                    f"{sid} is now {STATUS_WORDS[found[2].status]} on {found[0]}: your unapplied changes to it ({what}) are discarded — only idle skills can be edited"
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
        if self.dirty:
            self._set_static(
                "#dirty",
                f"unapplied changes: {', '.join(self.dirty)} — ctrl+s applies, ctrl+r reverts",
            )
        else:
            self._set_static("#dirty", "")
        self._post_drafts()

    def focus_within(self) -> bool:
        focused = self.screen.focused if self.is_attached else None
        return focused is not None and self in focused.ancestors_with_self

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
            if (
                not ro_changed and self.is_dirty()
            ):  # against the new version: our own apply is not dirty
                self.stale_note = f"{s.id} was changed by someone else (revision {s.rev}): revert to see it; applying will be refused as stale"
                self._set_static("#stale", self.stale_note)
            else:  # unapplied changes become a draft: restored, or dropped (and said) if no longer idle
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
        yield Static("", id="dirty", classes="dirty -empty")
        with Vertical(classes="param", id="param-label"):
            yield Label(Text.assemble(("label", "bold"), ("  text", "dim")), classes="plabel")
            yield Input(
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
                yield from self._inputs(name, pspec, s, disabled=ro is not None)
                if pspec.description:
                    yield Static(pspec.description, classes="pdesc")
                err = self.errors.get(name, "")
                yield Static(err, id=f"err-{name}", classes="perror" + ("" if err else " -empty"))
        yield from self._policy_inputs(s.policies, disabled=ro is not None)
        if ro is None:
            with Horizontal(classes="buttons"):
                yield Button("Apply ^s", id="apply", variant="primary", compact=True)
                yield Button("Revert ^r", id="revert", compact=True)

    def _policy_inputs(self, p: Policies, *, disabled: bool) -> ComposeResult:
        yield Static("policies — applied by the robot itself", classes="section")
        fields = Policies.model_fields
        for name, (label, hint) in POLICY_HINTS.items():
            with Vertical(classes="param", id=f"policy-{name}"):
                yield Label(Text.assemble((label, "bold"), ("  " + hint, "dim")), classes="plabel")
                if name == "pause_out_of_comms":
                    with Horizontal(classes="fields"):
                        yield Switch(p.pause_out_of_comms, id=f"pf-{name}", disabled=disabled)
                        yield Label(
                            "yes" if p.pause_out_of_comms else "no",
                            id=f"pv-{name}",
                            classes="switch-value",
                        )
                elif name == "retries":
                    yield Input(
                        str(p.retries),
                        id=f"pf-{name}",
                        type="integer",
                        compact=True,
                        disabled=disabled,
                        placeholder="0",
                    )
                else:
                    text = "" if p.recharge_below is None else fmt_number(p.recharge_below)
                    yield Input(
                        text,
                        id=f"pf-{name}",
                        type="number",
                        compact=True,
                        disabled=disabled,
                        placeholder="off",
                    )
                yield Static(fields[name].description or "", classes="pdesc")
                yield Static("", id=f"perr-{name}", classes="perror -empty")

    def read_policies(self) -> tuple[Policies | None, dict[str, str]]:
        """The policies as typed (None if unreadable) and problems per policy."""
        raw: dict[str, Any] = {}
        problems: dict[str, str] = {}
        try:
            raw["pause_out_of_comms"] = self.query_one("#pf-pause_out_of_comms", Switch).value
            retries = self.query_one("#pf-retries", Input).value.strip()
            below = self.query_one("#pf-recharge_below", Input).value.strip()
        except Exception:  # not composed (no skill, or being rebuilt)
            return None, {}
        try:
            raw["retries"] = int(retries) if retries else 0
        except ValueError:
            problems["retries"] = f"expected an integer, got '{retries}'"
        if below.lower() in ("", "off"):
            raw["recharge_below"] = None
        else:
            try:
                raw["recharge_below"] = float(below)
            except ValueError:
                problems["recharge_below"] = (
                    f"expected a number between 0 and 1 (empty: off), got '{below}'"
                )
        if problems:
            return None, problems
        try:  # the protocol's own model: the same bounds the server checks
            return Policies(**raw), {}
        except ValidationError as e:
            for err in e.errors():
                name = str(err["loc"][0]) if err["loc"] else "retries"
                problems[name] = f"{err['input']!r}: {err['msg'].removeprefix('Input ')}"
            return None, problems

    def _inputs(
        self, name: str, spec: ParamSpec, s: SkillInstance, *, disabled: bool
    ) -> ComposeResult:
        value = s.params.get(name)
        bound = s.bindings.get(name)
        t = spec.type
        m = self.model.mission
        if t in BINDABLE_KINDS and m is not None:
            kinds = BINDABLE_KINDS[t]
            options = [("typed value", TYPED)] + [
                (f"@{mk}  ({marker.kind})", mk)
                for mk, marker in m.markers.items()
                if marker.kind in kinds
            ]
            if bound and bound not in m.markers:
                options.append((f"@{bound} (missing)", bound))
            yield SafeSelect(
                options,
                value=bound or TYPED,
                allow_blank=False,
                id=f"bind-{name}",
                compact=True,
                disabled=disabled,
                classes="bind",
            )
            disabled = disabled or bool(bound)
        if t == "bool":
            with Horizontal(classes="fields"):
                yield Switch(bool(value), id=f"f-{name}", disabled=disabled)
                yield Label("yes" if value else "no", id=f"v-{name}", classes="switch-value")
        elif t in ("int", "float", "str"):
            text = "" if value is None else (fmt_number(value) if t != "str" else str(value))
            kind = {"int": "integer", "float": "number", "str": "text"}[t]
            yield Input(
                text, id=f"f-{name}", type=kind, compact=True, disabled=disabled, placeholder=t
            )
        elif t in ("pose", "position"):
            fields = POSE_FIELDS if t == "pose" else POSITION_FIELDS
            v = value if isinstance(value, dict) else {}
            rows = [fields[:3], fields[3:]] if t == "pose" else [fields]
            for row in rows:
                with Horizontal(classes="fields"):
                    for f in row:
                        yield Label(f)
                        yield Input(
                            fmt_number(float(v.get(f, 0.0))),
                            id=f"f-{name}-{f}",
                            type="number",
                            compact=True,
                            disabled=disabled,
                        )
        elif t in YAML_TYPES:
            ta = TextArea(
                yaml_text(value),
                id=f"f-{name}",
                compact=True,
                disabled=disabled,
                soft_wrap=True,
                tab_behavior="focus",
            )
            yield ta
        elif t in ("enum", "marker", "robot"):
            if t == "enum":
                choices = list(spec.choices or [])
            elif t == "marker":
                markers = m.markers if m else {}
                choices = [
                    mk
                    for mk, marker in markers.items()
                    if not spec.marker_kinds or marker.kind in spec.marker_kinds
                ]
            else:
                choices = list(m.robots) if m else []
            if isinstance(value, str) and value not in choices:
                choices.append(value)
            yield SafeSelect(
                [(c, c) for c in choices],
                value=value if value in choices else Select.NULL,
                allow_blank=True,
                prompt="(default)" if not spec.is_required else "choose…",
                id=f"f-{name}",
                compact=True,
                disabled=disabled,
            )
        else:
            yield Static(f"unsupported type {t}", classes="perror")

    # -- reading values -------------------------------------------------------------------
    def _read(self, name: str, spec: ParamSpec) -> tuple[Any, str | None]:
        """(value, problem) of one parameter as typed; value None = unset."""
        t = spec.type
        try:
            if t == "bool":
                return self.query_one(f"#f-{name}", Switch).value, None
            if t in ("int", "float", "str"):
                raw = self.query_one(f"#f-{name}", Input).value
                if t == "str":
                    return raw, None
                raw = raw.strip()
                if not raw:
                    return None, None
                try:
                    return (int(raw) if t == "int" else float(raw)), None
                except ValueError:
                    return (
                        None,
                        f"expected {'an integer' if t == 'int' else 'a number'}, got '{raw}'",
                    )
            if t in ("pose", "position"):
                fields = POSE_FIELDS if t == "pose" else POSITION_FIELDS
                out: dict[str, float] = {}
                for f in fields:
                    raw = self.query_one(f"#f-{name}-{f}", Input).value.strip()
                    try:
                        out[f] = float(raw) if raw else 0.0
                    except ValueError:
                        return None, f"{f}: expected a number, got '{raw}'"
                return out, None
            if t in YAML_TYPES:
                raw = self.query_one(f"#f-{name}", TextArea).text
                if not raw.strip():
                    return None, None
                try:
                    return yaml.safe_load(raw), None
                except yaml.YAMLError as e:
                    mark = getattr(e, "problem_mark", None)
                    where = f" (line {mark.line + 1})" if mark is not None else ""
                    problem = getattr(e, "problem", None) or "cannot be read"
                    return None, f"not valid YAML{where}: {problem}"
            if t in ("enum", "marker", "robot"):
                v = self.query_one(f"#f-{name}", Select).value
                return (None if v is Select.NULL else v), None
        except Exception as e:  # the widgets are being rebuilt
            return None, f"cannot read the field ({type(e).__name__})"
        return None, f"unsupported type {t}"

    def _binding(self, name: str) -> str | None:
        try:
            v = self.query_one(f"#bind-{name}", Select).value
        except Exception:
            return None
        return None if v in (TYPED, Select.NULL) else str(v)

    def collect(self) -> tuple[str | None, dict[str, Any], dict[str, str | None], dict[str, str]]:
        """(label change, params changed, bindings changed, problems per parameter)."""
        found = self._skill()
        if found is None:
            return None, {}, {}, {}
        robot, s = found
        spec = self._spec(s)
        problems: dict[str, str] = {}
        params: dict[str, Any] = {}
        bindings: dict[str, str | None] = {}
        try:
            label = self.query_one("#f-label", Input).value
        except Exception:
            label = s.label
        label_change = label if label != s.label else None
        if spec is None:
            return label_change, params, bindings, problems
        m = self.model.mission
        for name, pspec in spec.params.items():
            bound = self._binding(name) if pspec.type in BINDABLE_KINDS else None
            old_bound = s.bindings.get(name)
            if bound is not None:
                if bound != old_bound:
                    bindings[name] = bound
                continue
            value, problem = self._read(name, pspec)
            if problem:
                problems[name] = problem
                continue
            if value is None:
                if pspec.is_required:
                    problems[name] = f"missing required {pspec.type} parameter '{name}'"
                    continue
                if name in s.params and (
                    pspec.default is None or s.params[name] != normalize_value(pspec, pspec.default)
                ):
                    params[name] = None  # back to the default
                continue
            found_problems = check_value(
                pspec, value, markers=m.markers if m else None, robots=set(m.robots) if m else None
            )
            if found_problems:
                rel, msg = found_problems[0]
                where = ".".join(str(x) for x in rel)
                problems[name] = f"{where}: {msg}" if where else msg
                continue
            norm = normalize_value(pspec, value)
            if old_bound is not None:
                bindings[name] = None
                params[name] = norm
            elif s.params.get(name) != norm:
                params[name] = norm
        return label_change, params, bindings, problems

    def policies_change(self) -> tuple[Policies | None, dict[str, str]]:
        """(new policies if they changed, problems per policy)."""
        found = self._skill()
        if found is None:
            return None, {}
        policies, problems = self.read_policies()
        return (
            policies if policies is not None and policies != found[1].policies else None
        ), problems

    def changed_names(self, *, even_read_only: bool = False) -> list[str]:
        """What differs from the skill (including fields that do not read)."""
        if self._skill() is None or (self.read_only_reason is not None and not even_read_only):
            return []
        label, params, bindings, problems = self.collect()
        policies, policy_problems = self.policies_change()
        names = (["label"] if label is not None else []) + list(
            dict.fromkeys([*params, *bindings, *problems])
        )
        if policies is not None or policy_problems:
            names.append("policies")
        return names

    def is_dirty(self) -> bool:
        return bool(self.changed_names())

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
        _, policy_problems = self.read_policies()
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
        if widget_id.startswith("bind-"):
            self._sync_bound_fields(name)
        for sw in self.query(f"#f-{name}").results(Switch):  # the value in words, not only colour
            self._set_static(f"#v-{name}", "yes" if sw.value else "no")
        self._validate_all()
        self._update_dirty()

    def _sync_bound_fields(self, name: str) -> None:
        bound = self._binding(name)
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
        self.post_message(self.Left())
