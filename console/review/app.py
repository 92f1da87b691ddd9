"""The review console: the operator console, read-only, fed by a `Replay`.

Every screen is the live console's (schedule, map, fleet, log, alerts,
timeline, checks) with the same model and the same `StateChange` signal; only
the source differs: a journal and its telemetry archive played by
`console.state.replay.Replay` instead of a client. A review bar on top of
every screen says which clock, the time, how far through the journal, and
the review's keys (from `REVIEW_ACTIONS`, like every key): step, go to,
play at a speed, switch clocks. Nothing can be changed: the model is
read-only and the app has no connection to submit through.
"""

from __future__ import annotations

from functools import partial
from typing import Any

from rich.text import Text
from textual.command import DiscoveryHit, Hit, Hits, Provider
from textual.screen import ModalScreen, Screen
from textual.widgets import Static

from console.app import MissionApp
from console.bindings import bindings, key_names
from console.review.goto import GotoScreen
from console.state.actions import ACTIONS, REVIEW_ACTIONS
from console.state.changes import StateChange
from console.state.model import REVIEW
from console.state.replay import GROUND, ROBOT, SPEEDS, Replay

PLAY_TICK_S = 0.25  # how often playing moves the time on (wall seconds)


class ReviewBar(Static):
    """Which clock, when, how far; the review's keys."""

    DEFAULT_CSS = """
    ReviewBar {
        dock: top; height: 1; padding: 0 1;
        background: $accent 35%; color: $text;
        text-wrap: nowrap; text-overflow: ellipsis;
    }
    """


class ReviewCommands(Provider):
    """The review's actions in the command palette."""

    def _entries(self):
        keys = key_names(self)
        for a in REVIEW_ACTIONS:
            yield a, f"{keys.all(a.binding_id)} · {a.description}"

    async def discover(self) -> Hits:
        for a, help_text in self._entries():
            yield DiscoveryHit(
                a.palette_title, partial(self.app.run_action, a.name), help=help_text
            )

    async def search(self, query: str) -> Hits:
        matcher = self.matcher(query)
        for a, help_text in self._entries():
            score = matcher.match(a.palette_title)
            if score > 0:
                run = partial(self.app.run_action, a.name)
                yield Hit(score, matcher.highlight(a.palette_title), run, help=help_text)


class ReviewApp(MissionApp):
    TITLE = "missionctl review"
    ACTIONS = [*ACTIONS, *REVIEW_ACTIONS]
    BINDINGS = [*MissionApp.BINDINGS, *bindings("review", show=False, actions=REVIEW_ACTIONS)]
    COMMANDS = MissionApp.COMMANDS | {ReviewCommands}

    def __init__(self, make_replay: Any, *, what: str, at: float | None = None, **kw: Any) -> None:
        """`make_replay(model)`: the Replay feeding this app's model; `what`
        names the recording (its file) on the top bar; `at`: where to start
        (default: the end, the mission as it was left)."""
        super().__init__(ask_before_quit=False, **kw)
        self.replay: Replay = make_replay(self.model)
        self.model.read_only = f"review of {what}"
        self.model.connection = REVIEW
        self.start_at = at
        self.playing = False
        self.speed = 10.0
        self.bars: list[ReviewBar] = []

    # -- start ------------------------------------------------------------------------------
    def on_mount(self) -> None:
        super().on_mount()
        self.screen_change_signal.subscribe(self, self._screen_changed)
        self._screen_changed(self.screen)
        start = self.start_at if self.start_at is not None else self.replay.span()[1]
        self.show(self.replay.seek(start))
        self.set_interval(PLAY_TICK_S, self._tick)

    def on_unmount(self) -> None:
        self.replay.release()

    def _screen_changed(self, screen: Screen) -> None:
        """Every full screen gets the review bar (dialogs are over one)."""
        if isinstance(screen, ModalScreen) or screen.query(ReviewBar):
            return
        bar = ReviewBar(self.bar_text())
        self.bars.append(bar)
        screen.mount(bar)

    # -- what shows ---------------------------------------------------------------------------
    def show(self, c: StateChange) -> None:
        self.publish(c)
        self.refresh_plan()
        text = self.bar_text()
        for bar in list(self.bars):
            if bar.is_attached:
                bar.update(text)
            else:
                self.bars.remove(bar)

    def bar_text(self) -> Text:
        t = Text(no_wrap=True)
        t.append(self.replay.where(), style="bold")
        t.append(f" · {'playing' if self.playing else 'paused'} ×{self.speed:g}  ")
        keys = key_names(self)
        for a in REVIEW_ACTIONS:
            t.append(f" {keys.short(a.binding_id)}", style="bold")
            t.append(f" {a.label}")
        return t

    # -- the review's actions ------------------------------------------------------------------
    def action_review_next(self) -> None:
        self.playing = False
        self.show(self.replay.step(1))

    def action_review_prev(self) -> None:
        self.playing = False
        self.show(self.replay.step(-1))

    def action_review_goto(self) -> None:
        self.playing = False
        self.push_screen(GotoScreen(self.replay.cursor.at, self.replay.clock), self._go)

    def _go(self, target: tuple[str, float] | None) -> None:
        if target is None:
            return
        kind, value = target
        try:
            c = (
                self.replay.seek_revision(int(value))
                if kind == "revision"
                else self.replay.seek(value)
            )
        except ValueError as e:
            self.notify(str(e), title="Go to", severity="warning")
            return
        self.show(c)

    def action_review_play(self) -> None:
        self.playing = not self.playing and not self.replay.at_end
        self.show(StateChange())

    def _speed(self, by: int) -> None:
        k = min(range(len(SPEEDS)), key=lambda i: abs(SPEEDS[i] - self.speed))
        self.speed = SPEEDS[max(0, min(len(SPEEDS) - 1, k + by))]
        self.show(StateChange())

    def action_review_faster(self) -> None:
        self._speed(1)

    def action_review_slower(self) -> None:
        self._speed(-1)

    def action_review_clock(self) -> None:
        other = ROBOT if self.replay.clock == GROUND else GROUND
        self.show(self.replay.set_clock(other))

    def _tick(self) -> None:
        if not self.playing:
            return
        c = self.replay.advance(PLAY_TICK_S * self.speed)
        if self.replay.at_end:
            self.playing = False
        self.show(c)
