"""The robot link's timing, as docs/protocol.md states it: when the server
transmits a robot's uplink and how long it waits for a receipt. The server
(`backend.server.uplink`) acts by these numbers; the document is generated
from them."""

from __future__ import annotations

RECEIPT_S = 5.0  # a receipt is immediate: the robot's processing and a near link's round trip
DELAY_MARGIN = 3  # one-way delays a receipt may take: the round trip (2) and one of jitter
RETRY_S = 0.5  # first retry of an undelivered transmission, doubling up to RETRY_MAX_S
RETRY_MAX_S = 5.0
RESEND_SENT_S = 30.0  # sent, not answered: sent again, and not before 3 one-way delays
RESEND_DELAYS = 3
HEARTBEAT_S = 5.0  # robots send a Downlink at least this often (RegisterReply says so)


def query_timeout_s(one_way_delay_s: float) -> float:
    """How long a transmission waits for the robot's receipt, from the
    expected one-way delay D in seconds: RECEIPT_S + 3·D (the query and its
    receipt each cross the link once, 2·D, plus D of margin). 5 s for a
    near robot, 23 s at D = 6 s, about an hour at D = 20 minutes."""
    return RECEIPT_S + DELAY_MARGIN * max(0.0, one_way_delay_s)


def resend_after_s(one_way_delay_s: float) -> float:
    """After a receipt, how long a sent command may go unanswered before it
    is transmitted again: RESEND_SENT_S, or 3·D when that is longer."""
    return max(RESEND_SENT_S, RESEND_DELAYS * max(0.0, one_way_delay_s))
