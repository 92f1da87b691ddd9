"""The editor's messages beside its fields: a refusal of the server (next to
its parameter, else on top), a check's problem under each field, the note
that someone else changed the skill meanwhile. They are kept here across a
rebuild of the form (the form is composed with them)."""

from __future__ import annotations

from collections.abc import Iterable

from textual.dom import DOMNode
from textual.widgets import Static

from console.widgets.editor.inputs import POLICY_HINTS


def set_note(form: DOMNode, selector: str, text: str) -> None:
    """The text of a note of the form; an empty one takes no room."""
    try:
        w = form.query_one(selector, Static)
    except Exception:  # being rebuilt
        return
    w.update(text)
    w.set_class(not text, "-empty")


class FieldNotes:
    def __init__(self, form: DOMNode) -> None:
        self.form = form
        self.errors: dict[str, str] = {}  # parameter -> the server's refusal of it
        self.server_error = ""  # a refusal about no parameter in particular
        self.stale_note = ""  # the skill changed since the editing started

    def clear(self) -> None:
        self.errors = {}
        self.server_error = ""

    def refused(self, param: str | None, message: str) -> None:
        """A refusal from the server: next to its field, else on top."""
        if param and self.form.query(f"#err-{param}"):
            self.errors[param] = message
            set_note(self.form, f"#err-{param}", message)
        else:
            self.server_error = message
            set_note(self.form, "#server-error", message)

    def clear_server_error(self) -> None:
        self.server_error = ""
        set_note(self.form, "#server-error", "")

    def forget(self, param: str | None) -> None:
        """The parameter was edited: the server's message was about the old value."""
        if param is not None:
            self.errors.pop(param, None)

    def stale(self, skill_id: str, rev: int, *, since_draft: bool = False) -> None:
        """Someone else changed the skill (to revision `rev`) while it was edited."""
        since = " since you started these changes" if since_draft else ""
        self.stale_note = (
            f"{skill_id} was changed by someone else{since} (revision {rev}): revert to see it; "
            "applying will be refused as stale"
        )
        set_note(self.form, "#stale", self.stale_note)

    def show_problems(self, params: Iterable[str], problems: dict[str, str]) -> None:
        """Under each parameter, what its check finds (else the server's refusal)."""
        for name in params:
            set_note(self.form, f"#err-{name}", problems.get(name) or self.errors.get(name, ""))

    def show_policy_problems(self, problems: dict[str, str]) -> None:
        """Under each policy, what is wrong with it (nothing: no note)."""
        for name in POLICY_HINTS:
            set_note(self.form, f"#perr-{name}", problems.get(name, ""))

    def mark(self, problems: dict[str, str], policy_problems: dict[str, str]) -> None:
        """Why an apply was refused here: under each field at fault."""
        for name, msg in problems.items():
            set_note(self.form, f"#err-{name}", msg)
        for name, msg in policy_problems.items():
            set_note(self.form, f"#perr-{name}", msg)
