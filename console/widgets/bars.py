"""One-line bars: the top bar (mission, revision, connection), the status
line (the last outcome, refusal or explanation), the mission screen's key
bar (the keys that apply to the selection), the part-2 screens' title bar
and the map's info line (cursor, selection, feed). Their look: bars.tcss
(loaded by the app)."""

from __future__ import annotations

from rich.style import Style
from rich.text import Text
from textual.widgets import Static

from console.state.context import FooterKey

# the connection's state, as a glyph (the word follows it)
CONNECTION_GLYPHS = {
    "connected": "●",
    "reconnecting": "⟳",
    "connecting": "…",
    "unreachable": "✕",
    "offline": "○",
}


def connection_text(state: str) -> str:
    """'● connected', '⟳ reconnecting', …"""
    return f"{CONNECTION_GLYPHS.get(state, '?')} {state}"


class TopBar(Static):
    """Mission, revision and connection (styled by state: -reconnecting, -unreachable, …)."""

    shown = ""  # the text shown (plain): an unchanged one is not drawn again

    def show(self, text: Text, state: str) -> None:
        """Show `text`, styled by the connection's `state` (-reconnecting, …)."""
        if text.plain == self.shown:
            return
        self.shown = text.plain
        self.update(text, layout=False)
        for c in CONNECTION_GLYPHS:
            self.set_class(state == c, f"-{c}")


class StatusLine(Static):
    """The last outcome, refusal or explanation (-error, -warning, -ok)."""

    def show(self, text: str, severity: str = "info") -> None:
        self.update(text, layout=False)
        for c in ("error", "warning", "ok"):
            self.set_class(severity == c, f"-{c}")


class TitleBar(Static):
    """The title of a part-2 screen (fleet, event log, alerts)."""


class InfoLine(Static):
    """The map's cursor, selection and feed (-nofeed when there is none)."""


class KeyBar(Static):
    """The mission screen's footer: the keys that apply to the selection
    first (console/state/context.py); a click on one runs it."""

    COMPONENT_CLASSES = {"keybar--key"}
    shown: tuple[FooterKey, ...] = ()

    def show(self, keys: list[FooterKey]) -> None:
        if tuple(keys) == self.shown:
            return
        self.shown = tuple(keys)
        key_style = self.get_component_rich_style("keybar--key", partial=True)
        t = Text(no_wrap=True, overflow="ellipsis")
        for k in keys:
            click = Style(meta={"@click": f"screen.footer_key('{k.action}')"})
            t.append(k.key, style=key_style + click)
            t.append(f" {k.label} ", style=click)
        self.update(t, layout=False)
