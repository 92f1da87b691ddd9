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
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.fuzzy import Matcher
from textual.screen import ModalScreen, Screen
from textual.widgets import Button, Footer, Input, Label, OptionList, Select, Static
from textual.widgets.option_list import Option

from backend.core.library import Library
from backend.core.model import NAME_RE, Status
from console.state.actions import ACTIONS, APP_KEYS, EDITOR_KEYS, NAV_KEYS, Action
from console.state.context import help_keys
from console.state.files import complete, completions, full_path, path_note, save_risks, shown_path
from console.state.text import GLYPHS, STATUS_CSS, STATUS_WORDS
from console.widgets.editor.editor import settle_cursors
from console.widgets.select import SafeSelect

# this module's look (CSS_PATH); absolute, so a subclass defined elsewhere finds it too
TCSS = Path(__file__).with_name("dialogs.tcss")


class ConfirmScreen(ModalScreen[bool]):
    """Yes/no. Enter or y confirms, escape or n cancels."""

    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n,escape", "answer(False)", "No"),
    ]

    CSS_PATH = TCSS

    def __init__(self, question: str, yes: str = "Yes") -> None:
        super().__init__()
        self.question = question
        self.yes = yes

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(self.question, classes="question")
            with Horizontal():
                yield Button(f"{self.yes} (y)", id="yes", variant="error")
                yield Button("Cancel (n)", id="no")

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
        Binding("q,y,ctrl+q", "answer('quit')", "Quit", priority=True),
        Binding("s", "answer('save')", "Save first"),
        Binding("n,escape", "answer(None)", "Stay"),
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
            with Horizontal():
                if self.can_save:
                    yield Button("Save, then quit (s)", id="save", variant="primary", compact=True)
                yield Button("Quit (q)", id="quit", variant="error", compact=True)
                yield Button("Stay (n)", id="stay", compact=True)

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
        Binding("escape", "cancel", "Cancel"),
        Binding("tab", "complete", "Complete", priority=True, show=False),
        Binding("down", "to_choices", "Choose", show=False),
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
            yield Static(
                "enter: ok · tab: complete · ↓: choose below · escape: cancel", classes="hint"
            )
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
        note, severity = path_note(text, must_exist=self.must_exist, cwd=self.cwd)
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

    def _submit(self, text: str) -> None:
        error = self.query_one("#error", Static)
        if not text.strip():
            error.update("give a file path")
            return
        p = full_path(text, self.cwd)
        if p.is_dir():
            error.update(f"{shown_path(p)} is a folder: add a file name")
            return
        if self.must_exist:
            if not p.is_file():
                error.update(f"{shown_path(p)}: no such file")
                return
            self.dismiss(str(p))
            return
        if not p.parent.is_dir():
            error.update(f"{shown_path(p.parent)}: no such folder")
            return
        risks = save_risks(p, self.also_writes(p) if self.also_writes else [])
        if not risks:
            self.dismiss(str(p))
            return
        self.asking = True

        def answered(yes: bool | None) -> None:
            self.asking = False
            if yes:
                self.dismiss(str(p))
            else:
                error.update("nothing written: change the name, or escape")
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
    """A list to choose from: ↑↓ move, enter (`choose_highlighted`) or a
    click chooses (the option's id), escape cancels (None)."""

    BINDINGS = [
        Binding("escape", "cancel", "Cancel"),
        Binding("down", "move(1)", "Next", show=False),
        Binding("up", "move(-1)", "Previous", show=False),
    ]

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
    ) -> None:
        super().__init__()
        self.robot = robot
        self.skills = skills
        self.library = library
        self.where = where
        self.offered_by = offered_by or {}  # skill -> "also offered by: lru2"

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(
                Text.assemble(
                    ("Add a skill to ", ""), (self.robot, "bold"), (f" — {self.where}", "dim")
                )
            )
            yield Input(placeholder="type to filter…", id="filter")
            yield OptionList(id="skills")
            yield Static("enter: add · ↑↓: choose · escape: cancel", classes="hint")

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
        if query:
            matcher = Matcher(query)
            scored = []
            for name in self.skills:
                spec = self.library.skills.get(name)
                score = max(
                    matcher.match(name), 0.5 * matcher.match(spec.description if spec else "")
                )
                if score > 0:
                    scored.append((score, name))
            names = [n for _, n in sorted(scored, key=lambda x: -x[0])]
        else:
            matcher = None
            names = list(self.skills)
        ol.add_options([self._option(n, matcher) for n in names])
        if names:
            ol.highlighted = 0

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
            yield Static("enter: go to it · ↑↓: choose · escape: cancel", classes="hint")

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
    """Choose one of a few rows: enter chooses (its id), escape cancels (None)."""

    BINDINGS = [Binding("escape", "cancel", "Cancel")]

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
            yield Static("enter: choose · ↑↓: move · escape: cancel", classes="hint")

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

    BINDINGS = [Binding("escape", "cancel", "Cancel")]
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
            yield Static("enter: ok · escape: cancel", classes="hint")
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

    BINDINGS = [Binding("escape,q,f1,question_mark", "close", "Close")]

    CSS_PATH = TCSS

    def __init__(self, keys: dict[str, str], actions: list[Action] = ACTIONS) -> None:
        super().__init__()
        self.keys = keys  # action name -> current key display
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
        intro.append("   (escape closes; keys can be remapped: see the end)", style="dim")
        parts.append(intro)
        heading("Navigation")
        table(NAV_KEYS)
        groups: dict[str, list] = {}
        for a in self.actions:
            groups.setdefault(a.group, []).append(a)
        for group, actions in groups.items():
            heading(group)
            table(
                [(help_keys(self.keys.get(a.name, a.key)), a.label, a.description) for a in actions]
            )
        heading("Parameter editor")
        table(EDITOR_KEYS)
        heading("App")
        table(APP_KEYS)
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
                ("+", "", "marked for a new barrier (space)"),
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
                "  binding ids: " + ", ".join(a.binding_id for a in self.actions),
                style="dim",
            )
        )
        return Group(*parts)

    def action_close(self) -> None:
        self.dismiss(None)


class UnreachableScreen(Screen[str]):
    """The server cannot be reached: one clear message, retry or quit."""

    BINDINGS = [
        Binding("r", "retry", "Retry", priority=True),
        Binding("q", "quit_app", "Quit", priority=True),
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
            yield Static("r: retry   q: quit", classes="hint")
        yield Footer()

    def action_retry(self) -> None:
        self.dismiss("retry")

    def action_quit_app(self) -> None:
        self.dismiss("quit")
