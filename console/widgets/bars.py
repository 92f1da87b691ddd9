"""One-line bars: the top bar (mission, revision, connection), the status
line (the last outcome, refusal or explanation), the part-2 screens' title
bar and the map's info line (cursor, selection, feed)."""

from __future__ import annotations

from textual.widgets import Static


class TopBar(Static):
    DEFAULT_CSS = """
    TopBar { height: 1; background: $panel; color: $text; padding: 0 1; }
    TopBar.-reconnecting { background: $warning 40%; }
    TopBar.-unreachable, TopBar.-offline { background: $error 30%; }
    """


class StatusLine(Static):
    DEFAULT_CSS = """
    StatusLine { height: 1; padding: 0 1; background: $surface; color: $text-muted; text-wrap: nowrap; text-overflow: ellipsis; }
    StatusLine.-error { color: $error; text-style: bold; }
    StatusLine.-warning { color: $warning; }
    StatusLine.-ok { color: $success; }
    """


class TitleBar(Static):
    DEFAULT_CSS = """
    TitleBar { height: 1; background: $panel; color: $text; padding: 0 1; }
    """


class InfoLine(Static):
    DEFAULT_CSS = """
    InfoLine { height: 1; padding: 0 1; background: $panel; text-wrap: nowrap; text-overflow: ellipsis; }
    InfoLine.-nofeed { color: $warning; }
    """
