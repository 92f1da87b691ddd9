"""The server's alerts from telemetry: low battery once per crossing, out of
range once per loss (consoles raise none of their own about robots)."""

from __future__ import annotations

from datetime import UTC, datetime

from backend.core.alerts import AlertKind
from backend.protocol.messages import Telemetry
from backend.server.telemetry import TelemetryWatch

T0 = datetime(2026, 3, 14, 10, 42, 7, tzinfo=UTC)


class Host:
    def __init__(self) -> None:
        self.raised: list[tuple[AlertKind, str | None, str]] = []

    def alert(self, message: str, *, kind: AlertKind, robot: str | None = None, **_kw) -> None:
        self.raised.append((kind, robot, message))


def test_low_battery_once_per_crossing_and_out_of_range_once_per_loss():
    host = Host()
    watch = TelemetryWatch(host)
    for battery, in_range in (
        (0.5, True),
        (0.15, True),
        (0.10, False),
        (0.12, False),
        (0.5, True),
        (0.1, False),
    ):
        watch.took(Telemetry(robot="lru1", battery=battery, in_range=in_range, at=T0))
    assert [k for k, _, _ in host.raised] == [
        "low_battery",
        "out_of_range",
        "out_of_range",
        "low_battery",
    ]
    assert {r for _, r, _ in host.raised} == {"lru1"}
    assert host.raised[0][2] == "lru1: battery low (15 % < 20 %)"
    # robots are watched apart
    watch.took(Telemetry(robot="lru2", battery=0.1, at=T0))
    assert host.raised[-1][:2] == ("low_battery", "lru2")
