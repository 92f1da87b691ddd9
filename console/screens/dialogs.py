"""Modal dialogs: confirm, file path prompt, skill picker, choice list, marker
name, help, unreachable."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from rich.console import Group
from rich.table import Table
from rich.text import Text
from textual import events, on
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.fuzzy import Matcher
from textual.screen import ModalScreen, Screen
from textual.widgets import Button, Footer, Input, Label, OptionList, Select, Static
from textual.widgets.option_list import Option

from backend.core.library import Library
from backend.core.model import NAME_RE, Status
from console.bindings import bind, key_names
from console.state.actions import ACTIONS, EDITOR_NOTES, NAV_KEYS, Action
from console.state.files import complete, completions, full_path, path_note, save_risks, shown_path
from console.state.keys import KeyNames
from console.state.text import GLYPHS, STATUS_CSS, STATUS_WORDS
from console.widgets.editor.editor import settle_cursors
from console.widgets.select import SafeSelect

# this module's look (CSS_PATH); absolute, so a subclass defined elsewhere finds it too
TCSS = Path(__file__).with_name("dialogs.tcss")


class ConfirmScreen(ModalScreen[bool]):
    """Yes/no: yes (y) confirms; no (n), cancel (escape) or the focused Cancel button does not."""

    BINDINGS = [
        bind("dialog.yes", "answer(True)"),
        bind("dialog.no", "answer(False)"),
        bind("dialog.cancel", "answer(False)"),
    ]

    CSS_PATH = TCSS

    def __init__(self, question: str, yes: str = "Yes", no: str = "Cancel") -> None:
        super().__init__()
        self.question = question
        self.yes = yes
        self.no = no

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(self.question, classes="question")
            keys = key_names(self)
            with Horizontal():
                yield Button(f"{self.yes} ({keys.say('dialog.yes')})", id="yes", variant="error")
                yield Button(f"{self.no} ({keys.say('dialog.no')})", id="no")

    def on_mount(self) -> None:
        self.query_one("#no", Button).focus()

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


class QuitScreen(ModalScreen[str | None]):
    """Quit although something is under way: says what, and what quitting
    does to it. Dismissed with "quit", "save" (save the mission first) or
    None (stay). Starts on "Stay": enter alone never quits."""

    BINDINGS = [
        bind("dialog.quit", "answer('quit')"),
        bind("dialog.save_first", "answer('save')"),
        bind("dialog.no", "answer(None)"),
        bind("dialog.cancel", "answer(None)"),
    ]

    CSS_PATH = TCSS

    def __init__(self, risks: list[str], consequence: str, *, can_save: bool) -> None:
        super().__init__()
        self.risks = risks
        self.consequence = consequence
        self.can_save = can_save

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static("Quit now?", classes="head")
            yield Static("\n".join(f"• {r}" for r in self.risks), classes="risks")
            yield Static(self.consequence, classes="question")
            keys = key_names(self)
            with Horizontal():
                if self.can_save:
                    save = f"Save, then quit ({keys.say('dialog.save_first')})"
                    yield Button(save, id="save", variant="primary", compact=True)
                quit_ = f"Quit ({keys.say('dialog.quit')})"
                yield Button(quit_, id="quit", variant="error", compact=True)
                yield Button(f"Stay ({keys.say('dialog.no')})", id="stay", compact=True)

    def on_mount(self) -> None:
        self.query_one("#stay", Button).focus()

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        self.dismiss(None if event.button.id == "stay" else event.button.id)

    def action_answer(self, answer: str | None) -> None:
        if answer == "save" and not self.can_save:
            return
        self.dismiss(answer)


class PathPrompt(ModalScreen[str | None]):
    """Asks for a file path (save / load a mission, export the log).

    Shows what the typed path means in full (the working folder is not
    guessed at), completes it with tab, lists the recent files (↓ to choose
    one) and, when saving, asks before a file is replaced or anything is
    written into the shipped examples' folder (`save_risks`; the question
    starts on "Cancel", so enter twice never replaces a file). Dismissed with
    the full path, or None.
    """

    BINDINGS = [
        bind("dialog.cancel", "cancel"),
        bind("dialog.ok", "ok"),
        bind("dialog.complete", "complete"),
        bind("dialog.next", "to_choices"),
    ]

    CSS_PATH = TCSS

    def __init__(
        self,
        title: str,
        default: str,
        *,
        must_exist: bool = False,
        recent: list[str] | tuple[str, ...] = (),
        suffixes: tuple[str, ...] = (),
        also_writes: Callable[[Path], list[Path]] | None = None,
        cwd: Path | None = None,
    ) -> None:
        super().__init__()
        self.title_text = title
        self.default = default
        self.must_exist = must_exist
        self.recent = list(recent)
        self.suffixes = suffixes
        self.also_writes = also_writes
        self.cwd = cwd or Path.cwd()
        self.asking = False  # the overwrite question is open

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text)
            yield Input(self.default, id="path", compact=True)
            yield Static("", id="note", classes="note")
            yield Static("", id="choices-title", classes="hint")
            yield OptionList(id="choices")
            hint = key_names(self).hint(
                ("dialog.ok", "ok"),
                ("dialog.complete", "complete"),
                ("dialog.next", "choose below"),
                ("dialog.cancel", "cancel"),
            )
            yield Static(hint, classes="hint")
            yield Static("", id="error", classes="error")

    def on_mount(self) -> None:
        settle_cursors(self)
        field = self.query_one("#path", Input)
        field.focus()
        field.cursor_position = len(field.value)
        self._noted(field.value)
        self._show_choices(self.recent, "recent files")

    def _show_choices(self, items: list[str], title: str, *, names: bool = False) -> None:
        """List paths to choose from (`names`: one folder's, by name only)."""
        ol = self.query_one("#choices", OptionList)
        ol.clear_options()

        def shown(x: str) -> str:
            if names:
                return x.rstrip("/").rpartition("/")[2] + ("/" if x.endswith("/") else "")
            return shown_path(full_path(x, self.cwd))

        ol.add_options([Option(shown(x), id=x) for x in items[:50]])
        ol.display = bool(items)
        self.query_one("#choices-title", Static).update(f"{title}:" if items else "")

    def _noted(self, text: str) -> None:
        complete = key_names(self).say("dialog.complete")
        note, severity = path_note(
            text, must_exist=self.must_exist, cwd=self.cwd, complete=complete
        )
        w = self.query_one("#note", Static)
        w.update(f"→ {note}")
        for c in ("ok", "warning", "hint"):
            w.set_class(severity == c, f"-{c}")

    @on(Input.Changed, "#path")
    def _changed(self, event: Input.Changed) -> None:
        self._noted(event.value)
        self.query_one("#error", Static).update("")
        if event.value.endswith("/"):  # a folder: what is in it
            found = completions(event.value, self.cwd, self.suffixes)
            self._show_choices(found, "in this folder", names=True)

    def action_complete(self) -> None:
        field = self.query_one("#path", Input)
        if not field.has_focus:
            field.focus()
            return
        done = complete(field.value, self.cwd, self.suffixes)
        if done != field.value:
            field.value = done
            field.cursor_position = len(done)
        found = completions(field.value, self.cwd, self.suffixes)
        if len(found) != 1 or found[0] != field.value:
            self._show_choices(found, "completions" if found else "no completions", names=True)

    def action_to_choices(self) -> None:
        ol = self.query_one("#choices", OptionList)
        if ol.display and ol.option_count and not ol.has_focus:
            ol.focus()
            if ol.highlighted is None:
                ol.highlighted = 0

    @on(OptionList.OptionSelected, "#choices")
    def _chosen(self, event: OptionList.OptionSelected) -> None:
        field = self.query_one("#path", Input)
        choice = str(event.option.id)
        field.value = choice
        field.cursor_position = len(choice)
        field.focus()
        if not choice.endswith("/"):
            self._submit(choice)

    @on(Input.Submitted, "#path")
    def _submitted(self, event: Input.Submitted) -> None:
        self._submit(event.value)

    def action_ok(self) -> None:
        """Ok by the table's key where the focused widget does not take it (a remapped key)."""
        self._submit(self.query_one("#path", Input).value)

    def _submit(self, text: str) -> None:
        error = self.query_one("#error", Static)
        if not text.strip():
            error.update("give a file path")
            return
        p = full_path(text, self.cwd)
        problem = self._problem(p)
        if problem is not None:
            error.update(problem)
            return
        risks = self._risks(p)
        if not risks:
            self.dismiss(str(p))
            return
        self._confirm(p, risks, error)

    def _problem(self, p: Path) -> str | None:
        """Why `p` cannot be opened (or written to); None: it can."""
        if p.is_dir():
            return f"{shown_path(p)} is a folder: add a file name"
        if self.must_exist:
            return None if p.is_file() else f"{shown_path(p)}: no such file"
        if not p.parent.is_dir():
            return f"{shown_path(p.parent)}: no such folder"
        return None

    def _risks(self, p: Path) -> list[str]:
        """What writing `p` would replace (a file to open: nothing)."""
        if self.must_exist:
            return []
        return save_risks(p, self.also_writes(p) if self.also_writes else [])

    def _confirm(self, p: Path, risks: list[str], error: Static) -> None:
        """Ask before writing over what `risks` names; no: say nothing was written."""
        self.asking = True

        def answered(yes: bool | None) -> None:
            self.asking = False
            if yes:
                self.dismiss(str(p))
            else:
                cancel = key_names(self).say("dialog.cancel")
                error.update(f"nothing written: change the name, or {cancel}")
                self.query_one("#path", Input).focus()

        self.app.push_screen(
            ConfirmScreen(
                "\n".join(f"• {r}" for r in risks) + "\n\nWrite there anyway?", yes="Replace"
            ),
            answered,
        )

    def action_cancel(self) -> None:
        self.dismiss(None)


class ListChoice(ModalScreen[str | None]):
    """A list to choose from: next/previous move, ok (`choose_highlighted`) or a
    click chooses (the option's id), cancel (None)."""

    BINDINGS = [
        bind("dialog.cancel", "cancel"),
        bind("dialog.ok", "choose"),
        bind("dialog.next", "move(1)"),
        bind("dialog.previous", "move(-1)"),
    ]

    def hint(self, what: str) -> str:
        """'enter: add · ↑↓: choose · escape: cancel', with the user's keys."""
        return key_names(self).hint(
            ("dialog.ok", what),
            (("dialog.previous", "dialog.next"), "choose"),
            ("dialog.cancel", "cancel"),
        )

    def action_choose(self) -> None:
        self.choose_highlighted()

    CSS_PATH = TCSS

    def choose_highlighted(self) -> None:
        ol = self.query_one(OptionList)
        if ol.highlighted is not None and ol.option_count:
            self.dismiss(ol.get_option_at_index(ol.highlighted).id)

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        self.dismiss(event.option.id)

    def action_move(self, step: int) -> None:
        ol = self.query_one(OptionList)
        if ol.option_count:
            cur = ol.highlighted if ol.highlighted is not None else -step
            ol.highlighted = min(max(cur + step, 0), ol.option_count - 1)

    def action_cancel(self) -> None:
        self.dismiss(None)


class SkillPicker(ListChoice):
    """Pick one of the robot's skills: type to filter (fuzzy), enter to add."""

    def __init__(
        self,
        robot: str,
        skills: list[str],
        library: Library,
        where: str,
        offered_by: dict[str, str] | None = None,
        who_can: Callable[[str], str] | None = None,
    ) -> None:
        super().__init__()
        self.robot = robot
        self.skills = skills
        self.library = library
        self.where = where
        self.offered_by = offered_by or {}  # skill -> "also offered by: lru2"
        self.who_can = who_can  # skill -> a line ranking the robots for it ('': none)

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(
                Text.assemble(
                    ("Add a skill to ", ""), (self.robot, "bold"), (f" — {self.where}", "dim")
                )
            )
            yield Input(placeholder="type to filter…", id="filter")
            yield OptionList(id="skills")
            yield Static("", id="who")
            yield Static(self.hint("add"), classes="hint")

    def on_mount(self) -> None:
        settle_cursors(self)
        self._fill("")
        self.query_one(Input).focus()

    def _option(self, name: str, matcher: Matcher | None) -> Option:
        spec = self.library.skills.get(name)
        desc = spec.description if spec else ""
        title = matcher.highlight(name) if matcher else Text(name)
        others = self.offered_by.get(name)
        prompt = Text.assemble(
            title if isinstance(title, Text) else Text(str(title)),
            (f"  · {others}" if others else "", "italic"),
            "\n",
            (f"  {desc}", "dim"),
        )
        return Option(prompt, id=name)

    def _fill(self, query: str) -> None:
        ol = self.query_one(OptionList)
        ol.clear_options()
        matcher = Matcher(query) if query else None
        names = self._ranked(matcher) if matcher is not None else list(self.skills)
        ol.add_options([self._option(n, matcher) for n in names])
        if names:
            ol.highlighted = 0

    def _ranked(self, matcher: Matcher) -> list[str]:
        """The skills the query matches, best first (a description's match counts half)."""
        scored = []
        for name in self.skills:
            spec = self.library.skills.get(name)
            score = max(matcher.match(name), 0.5 * matcher.match(spec.description if spec else ""))
            if score > 0:
                scored.append((score, name))
        return [n for _, n in sorted(scored, key=lambda x: -x[0])]

    @on(OptionList.OptionHighlighted, "#skills")
    def _highlighted(self, event: OptionList.OptionHighlighted) -> None:
        """The allocation hint of the highlighted skill: who can do it, ranked."""
        if self.who_can is not None and event.option.id is not None:
            self.query_one("#who", Static).update(self.who_can(event.option.id))

    @on(Input.Changed, "#filter")
    def _filter(self, event: Input.Changed) -> None:
        self._fill(event.value)

    @on(Input.Submitted, "#filter")
    def _submit(self) -> None:
        self.choose_highlighted()


class SkillSearch(ListChoice):
    """`/`: type what you remember of a skill (id, label, skill, robot,
    status, a parameter); enter jumps to the highlighted one."""

    def __init__(self, find: Callable[[str], list[tuple[str, str]]], query: str = "") -> None:
        super().__init__()
        self.find = find  # query -> [(skill id, one line about it)], best first
        self.query_text = query
        self.filled_for: str | None = None  # the query the list shows

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("Find a skill: id, label, skill, robot, status or a parameter")
            yield Input(self.query_text, placeholder="type to search…", id="query", compact=True)
            yield OptionList(id="found")
            yield Static("", id="count", classes="hint")
            yield Static(self.hint("go to it"), classes="hint")

    def on_mount(self) -> None:
        settle_cursors(self)
        self._fill(self.query_text)
        self.query_one(Input).focus()

    def _fill(self, query: str) -> None:
        self.filled_for = query
        found = self.find(query)
        ol = self.query_one(OptionList)
        ol.clear_options()
        width = max(20, (ol.size.width or self.app.size.width - 10) - 4)

        def line(text: str) -> Text:  # one line each: the list is for choosing
            t = Text(text)
            t.truncate(width, overflow="ellipsis")
            return t

        ol.add_options([Option(line(text), id=sid) for sid, text in found])
        if found:
            ol.highlighted = 0
        n = len(found)
        self.query_one("#count", Static).update(
            f"{n} skill{'s' if n != 1 else ''}" if n else "no skill matches: fewer words?"
        )

    @on(Input.Changed, "#query")
    def _changed(self, event: Input.Changed) -> None:
        self._fill(event.value)

    @on(Input.Submitted, "#query")
    def _submit(self) -> None:
        query = self.query_one("#query", Input).value
        if query != self.filled_for:  # typed faster than the list followed
            self._fill(query)
        self.choose_highlighted()

    def on_key(self, event: events.Key) -> None:
        """Keys typed before the query field has the focus are the query's."""
        field = self.query_one("#query", Input)
        if field.has_focus or not self.is_mounted:
            return
        if event.key == "enter":
            event.stop()
            self._submit()
        elif event.is_printable and event.character:
            event.stop()
            field.insert_text_at_cursor(event.character)


class ChoiceScreen(ModalScreen[str | None]):
    """Choose one of a few rows: ok chooses (its id), cancel (None)."""

    BINDINGS = [bind("dialog.cancel", "cancel")]

    CSS_PATH = TCSS

    def __init__(self, question: str, rows: list[tuple[str, Text]], highlighted: int = 0) -> None:
        super().__init__()
        self.question = question
        self.rows = rows  # (id, what the row shows)
        self.highlighted = highlighted

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(Text(self.question), classes="question")
            yield OptionList(*(Option(prompt, id=rid) for rid, prompt in self.rows), id="choices")
            hint = key_names(self).hint(
                ("dialog.ok", "choose"),
                (("dialog.previous", "dialog.next"), "move"),
                ("dialog.cancel", "cancel"),
            )
            yield Static(hint, classes="hint")

    def on_mount(self) -> None:
        ol = self.query_one(OptionList)
        ol.highlighted = self.highlighted
        ol.focus()

    @on(OptionList.OptionSelected)
    def _selected(self, event: OptionList.OptionSelected) -> None:
        self.dismiss(event.option.id)

    def action_cancel(self) -> None:
        self.dismiss(None)


class MarkerPrompt(ModalScreen[tuple[str, str] | None]):
    """Name (and kind) of a new marker; or a new name for one."""

    BINDINGS = [bind("dialog.cancel", "cancel")]
    CSS_PATH = TCSS

    def __init__(self, title: str, default: str, *, kinds: bool = True, kind: str = "pose") -> None:
        super().__init__()
        self.title_text = title
        self.default = default
        self.kinds = kinds
        self.kind = kind

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text)
            yield Input(self.default, id="name")
            if self.kinds:
                yield SafeSelect(
                    [
                        ("pose (position + heading)", "pose"),
                        ("position", "position"),
                        ("area (square around the cursor)", "area"),
                    ],
                    value=self.kind,
                    allow_blank=False,
                    id="kind",
                )
            hint = key_names(self).hint(("dialog.ok", "ok"), ("dialog.cancel", "cancel"))
            yield Static(hint, classes="hint")
            yield Static("", id="error", classes="error")

    def on_mount(self) -> None:
        self.query_one(Input).focus()

    @on(Input.Submitted)
    def _submitted(self, event: Input.Submitted) -> None:
        name = event.value.strip()
        if not NAME_RE.match(name):
            self.query_one("#error", Static).update(
                "a name starts with a letter; then letters, digits, _ or -"
            )
            return
        kind = str(self.query_one("#kind", Select).value) if self.kinds else ""
        self.dismiss((name, kind))

    def action_cancel(self) -> None:
        self.dismiss(None)


class HelpScreen(ModalScreen[None]):
    """The key map (with the user's remappings) and the status legend."""

    BINDINGS = [bind("dialog.cancel", "close"), bind("app.help", "close")]

    CSS_PATH = TCSS

    def __init__(self, keys: KeyNames, actions: list[Action] = ACTIONS) -> None:
        super().__init__()
        self.keys = keys  # the user's keys
        self.actions = actions  # the app's (a review adds its own)

    def compose(self) -> ComposeResult:
        with VerticalScroll():
            yield Static(self._text(), id="help-text")

    def _text(self) -> Group:
        """Headings and key tables; descriptions wrap in their own column
        (at 80 columns too), never under the keys."""
        parts: list = []

        def heading(title: str) -> None:
            parts.append(Text(f"\n{title}", style="bold underline"))

        def table(
            rows: list[tuple[str | Text, str | Text, str]],
            key_width: int = 16,
            label_width: int = 13,
        ) -> None:
            grid = Table.grid(padding=(0, 1))
            grid.add_column(min_width=key_width, no_wrap=True, style="bold")
            grid.add_column(min_width=label_width, no_wrap=True)
            grid.add_column(ratio=1, style="dim")
            for key, label, desc in rows:
                grid.add_row(Text(" ") + key if isinstance(key, Text) else " " + key, label, desc)
            parts.append(grid)

        intro = Text()
        intro.append("missionctl — operator console", style="bold")
        close = self.keys.say("dialog.cancel")
        intro.append(f"   ({close} closes; keys can be remapped: see the end)", style="dim")
        parts.append(intro)
        heading("Navigation")
        table(NAV_KEYS)
        groups: dict[str, list] = {}
        for a in self.actions:
            groups.setdefault(a.group, []).append(a)
        for group, actions in groups.items():
            heading(group)
            table([(self.keys.all(a.binding_id), a.label, a.description) for a in actions])
        heading("Typing values")
        table(EDITOR_NOTES)
        heading("Statuses")
        colours = getattr(self.app, "theme_variables", {})  # the theme's status colours

        def coloured(status: Status, text: str, bold: bool = False) -> Text:
            colour = colours.get(f"status-{STATUS_CSS[status]}", "")
            return Text(text, style=f"{'bold ' if bold else ''}{colour}".strip())

        table(
            [
                (
                    coloured(status, glyph, True),
                    coloured(status, status.value),
                    STATUS_WORDS[status],
                )
                for status, glyph in GLYPHS.items()
            ],
            key_width=3,
            label_width=18,
        )
        table(
            [
                ("[b1]", "", "barrier tag: partner skills wait for each other"),
                ("⇠id ⇢id", "", "after: it starts after skill id / skill id starts after it"),
                ("+", "", f"marked for a new barrier ({self.keys.say('mission.mark')})"),
                (
                    "*label",
                    "",
                    "unapplied changes in the editor (kept per skill until applied or reverted)",
                ),
            ],
            key_width=7,
            label_width=0,
        )
        heading("Remapping keys")
        parts.append(
            Text(
                '  ~/.config/missionctl/config.toml:  [keymap]  "mission.sync" = "S"\n'
                "  binding ids: " + ", ".join(a.binding_id for a in self.actions if not a.fixed),
                style="dim",
            )
        )
        return Group(*parts)

    def action_close(self) -> None:
        self.dismiss(None)


class UnreachableScreen(Screen[str]):
    """The server cannot be reached: one clear message, retry or quit."""

    BINDINGS = [
        bind("dialog.retry", "retry", show=True),
        bind("dialog.quit", "quit_app", show=True),
    ]

    CSS_PATH = TCSS

    def __init__(self, endpoint: str, message: str) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.message = message

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(f"Cannot reach the mission server at {self.endpoint}", classes="head")
            yield Static(self.message, classes="detail", id="unreachable-detail")
            yield Static(
                "Is `missionctl server` running there? Check the endpoint (--connect), "
                "the network and, across machines, TLS and credentials.",
                classes="hint",
            )
            hint = key_names(self).hint(("dialog.retry", "retry"), ("dialog.quit", "quit"))
            yield Static(hint, classes="hint")
        yield Footer()

    def action_retry(self) -> None:
        self.dismiss("retry")

    def action_quit_app(self) -> None:
        self.dismiss("quit")
