"""The server answers an operation before it publishes the operation's event
batch: both travel on the requester's link, and a reply queued behind the
batch waited for the requester to take the batch in first."""

from __future__ import annotations

import threading

import zenoh
from zenoh.handlers import Callback

from backend.core.ops import EditSkill
from backend.protocol.keys import Keys
from backend.protocol.messages import Request, dumps
from backend.transport import client_config
from backend.transport.session import close_session, open_session


def test_the_requester_gets_its_reply_before_the_event_batch(cluster):
    session = open_session(client_config([cluster.endpoint]))
    arrivals: list[str] = []
    both = threading.Event()

    def arrived(what: str) -> None:
        arrivals.append(what)  # direct callbacks: called in arrival order on the link's thread
        if {"reply", "events"} <= set(arrivals):
            both.set()

    try:
        sub = session.declare_subscriber(
            Keys.EVENTS, Callback(lambda _s: arrived("events"), indirect=False)
        )
        request = Request(client="order", request_id="r1", op=EditSkill(id="lru1-1", label="order"))
        session.get(
            Keys.OP,
            Callback(lambda _r: arrived("reply"), lambda: None, indirect=False),
            payload=dumps(request),
            timeout=10.0,
            consolidation=zenoh.ConsolidationMode.NONE,
        )
        assert both.wait(10), f"only {arrivals} arrived"
        assert arrivals == ["reply", "events"]
        sub.undeclare()
    finally:
        close_session(session)
