"""Unapplied changes per skill: kept as a draft when the editor shows another
skill (or is rebuilt), restored when it shows that skill again, dropped — and
said — when the skill leaves idle or is deleted."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from textual.dom import DOMNode

from backend.core.model import SkillInstance, Status
from console.state.model import ConsoleModel
from console.state.text import STATUS_WORDS
from console.widgets.editor.inputs import INPUTS, set_widget_value, widget_value


@dataclass
class Draft:
    """Unapplied changes to a skill the editor does not show right now."""

    values: dict[str, Any]  # widget id -> what was typed / chosen
    rev: int  # the skill's revision when the editing started
    base_revision: int  # the mission revision the changes were made against
    changed: list[str]  # what differs (for messages)


def capture(form: DOMNode, rev: int, base_revision: int, changed: list[str]) -> Draft:
    """What the form's fields hold now."""
    values = {w.id: widget_value(w) for w in form.query(INPUTS) if w.id}
    return Draft(values=values, rev=rev, base_revision=base_revision, changed=list(changed))


def restore(form: DOMNode, draft: Draft) -> None:
    """Put a draft's values back in the form's fields (as they were typed)."""
    for w in form.query(INPUTS):
        if w.id in draft.values:
            try:
                set_widget_value(w, draft.values[w.id])
            except Exception:  # e.g. a marker that no longer exists: keep the shown value
                pass


def dropped_text(sid: str, draft: Draft, found: tuple[str, int, SkillInstance] | None) -> str:
    """Why a draft was dropped, in a sentence."""
    what = ", ".join(draft.changed) or "changes"
    if found is None:
        return f"{sid} was deleted: your unapplied changes to it ({what}) are discarded"
    return (
        f"{sid} is now {STATUS_WORDS[found[2].status]} on {found[0]}: your unapplied "
        f"changes to it ({what}) are discarded — only idle skills can be edited"
    )


class DraftBook(dict[str, Draft]):
    """skill id -> its draft."""

    def prune(self, model: ConsoleModel) -> list[str]:
        """Drop the drafts whose skill was deleted or is no longer idle; say which."""
        said: list[str] = []
        for sid in list(self):
            found = model.find(sid)
            if found is None or found[2].status != Status.IDLE:
                said.append(dropped_text(sid, self.pop(sid), found))
        return said

    def unapplied(self, shown: str | None) -> frozenset[str]:
        """The skills with unapplied changes: the drafts' and `shown` (the
        skill the editor shows, when it has some)."""
        return frozenset(self) | ({shown} if shown else frozenset())
