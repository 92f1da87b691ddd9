"""What a transmission's outcome journals, and when the next one leaves."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime
from types import SimpleNamespace

from backend.core.model import CommandState
from backend.core.ops import UplinkSent, UplinkSettle
from backend.protocol.timing import RETRY_MAX_S, RETRY_S, resend_after_s
from backend.server.uplink import UplinkSender

LEFT = datetime(2030, 7, 1, 8, 0, tzinfo=UTC)


class Link:
    def __init__(self) -> None:
        self.submitted: list[tuple[object, str]] = []

    def submit(self, op: object, actor: str) -> None:
        self.submitted.append((op, actor))

    def delay_of(self, robot: str) -> float | None:
        return 2.0


def pending() -> list[SimpleNamespace]:
    return [
        SimpleNamespace(id=1, cancel_requested=True),
        SimpleNamespace(id=2, cancel_requested=False),
        SimpleNamespace(id=3, cancel_requested=True),  # not in this transmission
    ]


async def test_an_undelivered_transmission_withdraws_what_was_cancelled_on_the_way():
    link = Link()
    sender = UplinkSender(link, "lru1")
    sender._settle("undelivered", pending(), [1, 2], LEFT)
    ((op, actor),) = link.submitted
    assert actor == "server" and isinstance(op, UplinkSettle)
    assert (op.robot, op.ids, op.state) == ("lru1", [1], CommandState.CANCELLED)
    assert op.reason == "cancelled before it reached lru1"
    assert sender._missed and sender._retry == 2 * RETRY_S
    link.submitted.clear()
    sender._settle("absent", pending(), [2], LEFT)  # nothing was cancelled on the way
    assert link.submitted == [] and sender._missed and sender._retry == 4 * RETRY_S
    for _ in range(5):
        sender._settle("absent", pending(), [], LEFT)
    assert link.submitted == [] and sender._retry == RETRY_MAX_S


async def test_a_transmission_that_may_have_arrived_is_sent_and_retried():
    link = Link()
    sender = UplinkSender(link, "lru1")
    now = asyncio.get_running_loop().time()
    sender._settle("maybe", pending(), [1, 2], LEFT)
    ((op, actor),) = link.submitted
    assert actor == "server" and op == UplinkSent(robot="lru1", ids=[1, 2], at=LEFT)
    assert not sender._missed and sender._retry == 2 * RETRY_S
    assert now + RETRY_S <= sender._due <= asyncio.get_running_loop().time() + RETRY_S


async def test_a_delivered_transmission_is_resent_after_the_round_trip():
    link = Link()
    sender = UplinkSender(link, "lru1")
    sender._retry = RETRY_MAX_S
    sender._settle("delivered", pending(), [2], LEFT)
    assert [type(op) for op, _ in link.submitted] == [UplinkSent]
    assert not sender._missed and sender._retry == RETRY_S
    due = asyncio.get_running_loop().time() + resend_after_s(2.0)
    assert due - 1.0 <= sender._due <= due
