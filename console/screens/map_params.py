"""The map screen's parameter actions on the schedule's selected skill: bind
one of its parameters to the selected marker, or set one to the cursor (an
object the screen owns; its keys call these). When several parameters fit,
the operator chooses one first."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from rich.text import Text

from backend.core.library import SkillSpec
from backend.core.model import SkillInstance
from backend.core.ops import EditSkill
from console.bindings import key_names
from console.screens.dialogs import ChoiceScreen
from console.state.markers import bind_choices, picked_value, relabel
from console.state.text import fmt_value

Selected = tuple[str, SkillInstance, SkillSpec]  # robot, skill, its spec


def _now_text(ps: Any, s: SkillInstance, n: str) -> Text:
    """What a parameter holds now (@MARKER when bound to one)."""
    if n in s.bindings:
        return Text(f"@{s.bindings[n]}")
    if s.params.get(n) is not None:
        return Text(fmt_value(ps, s.params[n]))
    return Text("not set", style="dim")


def param_rows(spec: Any, s: Any, names: list[str]) -> list[tuple[str, Text]]:
    """Rows for choosing among a skill's parameters: name, type and what it
    holds now (@MARKER when bound to one), in aligned columns."""
    wn = max(len(n) for n in names)
    wt = max(len(spec.params[n].type) for n in names)
    rows = []
    for n in names:
        ps = spec.params[n]
        text = Text.assemble(
            (n.ljust(wn), "bold"), "  ", (ps.type.ljust(wt), "dim"), "  ", _now_text(ps, s, n)
        )
        rows.append((n, text))
    return rows


def no_fit_text(s: SkillInstance, spec: SkillSpec, kind: str) -> str:
    kinds = ", ".join(f"{p} ({ps.type})" for p, ps in spec.params.items()) or "none"
    return f"{s.id} ({s.skill}) has no parameter for a {kind} marker; its parameters: {kinds}"


def bind_edit(s: SkillInstance, pname: str, marker: str, *, fits: bool) -> EditSkill:
    """The edit binding `pname` to `marker` (`fits` False: a marker-typed
    parameter takes its name); a label naming the marker bound before ("drive
    to POI-A") names the new one."""
    before = s.bindings.get(pname) or (s.params.get(pname) if not fits else None)
    label = relabel(s.label, before if isinstance(before, str) else None, marker)
    if fits:
        return EditSkill(id=s.id, bindings={pname: marker}, label=label)
    return EditSkill(id=s.id, params={pname: marker}, label=label)


class ParamActions:
    def __init__(self, screen: Any) -> None:
        self.screen = screen  # MapScreen: model, view, say, submit, app, sync_selection
        self.view = screen.view

    def selected(self) -> Selected | None:
        """The schedule's selected skill, if it can be edited (else the operator is told why)."""
        s = self.screen
        s.sync_selection()
        found = s.model.find(self.view.selected_skill)
        if found is None:
            back, here = (key_names(s).say(a) for a in ("app.show_mission", "app.show_map"))
            why = f"select a skill on the schedule first ({back}), then come back ({here})"
            s.say(why, "warning")
            return None
        why = s.model.read_only_reason(found[2].id)
        if why:
            s.say(f"{found[2].id}: {why}", "warning")
            return None
        spec = s.model.library.skills.get(found[2].skill) if s.model.library else None
        if spec is None:
            s.say(f"{found[2].skill} is not in the skill library", "error")
            return None
        return found[0], found[2], spec

    def _choose(
        self,
        question: str,
        spec: SkillSpec,
        skill: SkillInstance,
        names: list[str],
        then: Callable[[str], None],
        *,
        cancelled: str,
        highlighted: int = 0,
    ) -> None:
        """`then(name)` at once when one parameter fits; when several do, the
        operator picks one first (escape: nothing is sent)."""
        if len(names) == 1:
            then(names[0])
            return
        s = self.screen

        def chosen(pname: str | None) -> None:
            if pname is None:
                s.say(cancelled)
                return
            # it may have changed while the dialog was open
            why = s.model.read_only_reason(skill.id)
            if why:
                s.say(f"{skill.id}: {why}", "warning")
                return
            then(pname)

        rows = param_rows(spec, skill, names)
        s.app.push_screen(ChoiceScreen(question, rows, highlighted), chosen)

    def bind(self, marker: Any) -> None:
        """Bind a parameter of the selected skill to the selected marker."""
        got = self.selected()
        if got is None:
            return
        robot, sk, spec = got
        name = self.view.selected_marker
        # a parameter the marker can give a value is bound to it; a marker-typed one takes its name
        fits, names = bind_choices(spec, marker)
        if not fits and not names:
            self.screen.say(no_fit_text(sk, spec, marker.kind), "warning")
            return

        def bind(pname: str) -> None:
            op = bind_edit(sk, pname, name, fits=pname in fits)
            also = f"; label now '{op.label}'" if op.label is not None else ""
            said = f"{sk.id}: {pname} bound to marker {name}{also}"
            self.screen.submit(
                op,
                f"bind {sk.id}.{pname} to {name}",
                robot=robot,
                skill=sk.id,
                on_ok=lambda r: self.screen.say(said, "ok"),
            )

        def holds(p: str) -> bool:
            return sk.bindings.get(p) == name or (p in names and sk.params.get(p) == name)

        candidates = fits + names
        first = next((i for i, p in enumerate(candidates) if not holds(p)), 0)  # the likely choice
        self._choose(
            f"Bind {name} to which parameter of {sk.id}?",
            spec,
            sk,
            candidates,
            bind,
            highlighted=first,
            cancelled=f"bind cancelled: {sk.id} unchanged",
        )

    def pick(self) -> None:
        """Set a pose or position parameter of the selected skill to the cursor."""
        got = self.selected()
        if got is None:
            return
        robot, sk, spec = got
        params = [p for p, ps in spec.params.items() if ps.type in ("pose", "position")]
        if not params:
            self.screen.say(f"{sk.id} ({sk.skill}) has no pose or position parameter", "warning")
            return
        x, y = (round(c, 1) for c in self.view.cursor)

        def pick(pname: str) -> None:
            ptype = spec.params[pname].type
            heading = self.view.heading
            turned = f" heading {math.degrees(heading):.0f}°" if ptype == "pose" else ""
            unbound = " (its marker binding is replaced)" if pname in sk.bindings else ""
            said = f"{sk.id}: {pname} = ({x:g}, {y:g}){turned}{unbound}"
            self.screen.submit(
                EditSkill(id=sk.id, params={pname: picked_value(ptype, x, y, heading)}),
                f"set {sk.id}.{pname}",
                robot=robot,
                skill=sk.id,
                on_ok=lambda r: self.screen.say(said, "ok"),
            )

        self._choose(
            f"Set which parameter of {sk.id} to the cursor ({x:g}, {y:g})?",
            spec,
            sk,
            params,
            pick,
            cancelled=f"pick cancelled: {sk.id} unchanged",
        )
