"""Alerts from the robots' telemetry: a battery falling below `LOW_BATTERY`
(once per crossing, again after it was back above) and a robot leaving
communication range (once per loss). The server raises them, so every
console shows the same alerts and one that was away finds them in the state
snapshot."""

from __future__ import annotations

from backend.core.alerts import LOW_BATTERY, AlertKind, Raises
from backend.protocol.messages import Telemetry


class TelemetryWatch:
    def __init__(self, host: Raises) -> None:
        self._host = host
        self._in_range: dict[str, bool] = {}  # robot -> in range at its last sample
        self._low: dict[str, bool] = {}  # robot -> battery below LOW_BATTERY at its last sample

    def took(self, t: Telemetry) -> None:
        """One sample (on the server's loop)."""
        r = t.robot
        was_in = self._in_range.get(r, True)
        self._in_range[r] = t.in_range
        if was_in and not t.in_range:
            self._host.alert(
                f"{r} is out of communication range", kind=AlertKind.OUT_OF_RANGE, robot=r
            )
        low = t.battery < LOW_BATTERY
        was_low = self._low.get(r, False)
        self._low[r] = low
        if low and not was_low:
            self._host.alert(
                f"{r}: battery low ({int(t.battery * 100)} % < {int(LOW_BATTERY * 100)} %)",
                kind=AlertKind.LOW_BATTERY,
                robot=r,
            )
