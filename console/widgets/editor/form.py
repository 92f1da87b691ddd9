"""The editor's form for one skill, composed: its title and notes, the label,
one group of inputs per parameter (console/widgets/editor/inputs.py), the
policies, and the apply and revert buttons while it is editable."""

from __future__ import annotations

from dataclasses import dataclass

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.widgets import Button, Label, Static

from backend.core.library import SkillSpec
from backend.core.model import Mission, SkillInstance
from backend.core.params import ParamSpec
from console.state.keys import KeyNames
from console.state.text import GLYPHS, STATUS_CSS
from console.widgets.editor.fields import FieldInput
from console.widgets.editor.inputs import param_inputs, policy_inputs, spec_hint
from console.widgets.editor.notes import FieldNotes

NO_SKILL = "Select a skill in the schedule to see and edit its parameters."


@dataclass(frozen=True)
class Editing:
    """What the form shows: a skill, on its robot; `read_only` says why not editable."""

    robot: str
    skill: SkillInstance
    spec: SkillSpec | None
    read_only: str | None
    mission: Mission | None


def _note(text: str, id: str, css: str) -> Static:
    """A note of the form (an empty one takes no room)."""
    return Static(text, id=id, classes=css + ("" if text else " -empty"))


def title_text(robot: str, s: SkillInstance) -> Text:
    title = Text()
    title.append(f"{GLYPHS[s.status]} ", style="bold")
    title.append(f"{s.id}", style="bold")
    title.append(f"  {s.skill} on {robot}")
    if s.attempt > 1:
        title.append(f"  attempt {s.attempt}")
    return title


def _head(e: Editing, notes: FieldNotes) -> ComposeResult:
    s = e.skill
    yield Static(title_text(e.robot, s), classes=f"title status-{STATUS_CSS[s.status]}")
    if e.spec is not None and e.spec.description:
        yield Static(e.spec.description, classes="skill-desc")
    if e.read_only:
        yield Static(f"read-only: {e.read_only}", id="readonly", classes="readonly")
    yield _note(notes.server_error, "server-error", "server-error")
    yield _note(notes.stale_note, "stale", "stale")
    # always one line while editable, so its words never move the fields under the cursor
    yield Static("", id="dirty", classes="dirty" + ("" if e.read_only is None else " -empty"))


def _label(e: Editing) -> ComposeResult:
    with Vertical(classes="param", id="param-label"):
        yield Label(Text.assemble(("label", "bold"), ("  text", "dim")), classes="plabel")
        yield FieldInput(
            e.skill.label,
            id="f-label",
            compact=True,
            disabled=e.read_only is not None,
            placeholder=e.skill.skill,
        )


def _param(e: Editing, name: str, pspec: ParamSpec, error: str) -> ComposeResult:
    with Vertical(classes="param", id=f"param-{name}"):
        yield Label(
            Text.assemble((name, "bold"), ("  " + spec_hint(pspec), "dim")), classes="plabel"
        )
        yield from param_inputs(name, pspec, e.skill, e.mission, disabled=e.read_only is not None)
        if pspec.description:
            yield Static(pspec.description, classes="pdesc")
        yield _note(error, f"err-{name}", "perror")


def _buttons(keys: KeyNames) -> ComposeResult:
    with Horizontal(classes="buttons"):
        apply, revert = keys.short("editor.apply"), keys.short("editor.revert")
        yield Button(f"Apply {apply}", id="apply", variant="primary", compact=True)
        yield Button(f"Revert {revert}", id="revert", compact=True)


def skill_form(e: Editing, notes: FieldNotes, keys: KeyNames) -> ComposeResult:
    yield from _head(e, notes)
    yield from _label(e)
    if e.spec is None:
        yield Static(f"skill '{e.skill.skill}' is not in the library", classes="perror")
        return
    for name, pspec in e.spec.params.items():
        yield from _param(e, name, pspec, notes.errors.get(name, ""))
    yield from policy_inputs(e.skill.policies, disabled=e.read_only is not None)
    if e.read_only is None:
        yield from _buttons(keys)
