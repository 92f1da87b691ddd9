"""One-line bars: the top bar (mission, revision, connection), the status
line (the last outcome, refusal or explanation), the part-2 screens' title
bar and the map's info line (cursor, selection, feed). Their look:
bars.tcss (loaded by the app)."""

from __future__ import annotations

from textual.widgets import Static


class TopBar(Static):
    """Mission, revision and connection (styled by state: -reconnecting, -unreachable, …)."""


class StatusLine(Static):
    """The last outcome, refusal or explanation (-error, -warning, -ok)."""


class TitleBar(Static):
    """The title of a part-2 screen (fleet, event log, alerts)."""


class InfoLine(Static):
    """The map's cursor, selection and feed (-nofeed when there is none)."""
