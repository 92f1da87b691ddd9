"""The router's access-control rules, checked with RAW Zenoh sessions logged in
as each account (not through our client library, which refuses locally).

A query the router refuses gets no reply at all, while the mission server
answers every query it receives (a reply or an error): so "no reply" proves
the router stopped it. A refused publication is shown absent by sending a
real one after it on an ordered path and seeing only the real one arrive."""

from __future__ import annotations

import queue
import time
from datetime import UTC, datetime

import zenoh

from backend.core.events import EventBatch
from backend.core.model import Pose
from backend.core.ops import AddSkill, Report
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    Downlink,
    DownlinkAck,
    Manifest,
    Register,
    RegisterReply,
    Request,
    StateSnapshot,
    Telemetry,
    dumps,
)
from backend.transport import declare_publisher, wait_matching

from .helpers import raw_session

TIMEOUT = 3.0


def _replies(session: zenoh.Session, key: str, payload: bytes = b"") -> list[tuple[bool, bytes]]:
    out = []
    for reply in session.get(
        key, payload=payload, timeout=TIMEOUT, consolidation=zenoh.ConsolidationMode.NONE
    ):
        if reply.ok is not None:
            out.append((True, reply.ok.payload.to_bytes()))
        else:
            out.append((False, reply.err.payload.to_bytes()))
    return out


def _add(user_claim: str = "") -> bytes:
    return dumps(
        Request(
            client="raw",
            request_id=datetime.now(UTC).isoformat(),
            user=user_claim,
            op=AddSkill(robot="lru1", skill="recharge", label="raw"),
        )
    )


def _revision(session: zenoh.Session) -> int:
    ((ok, raw),) = _replies(session, Keys.STATE)
    assert ok
    return StateSnapshot.model_validate_json(raw).revision


def test_observer_reads_state_but_the_router_drops_every_operation(server, accounts):
    ep = server.endpoint
    with (
        raw_session(ep, accounts.login("watch")) as watch,
        raw_session(ep, accounts.login("ops")) as ops,
    ):
        before = _revision(watch)  # reading works
        for key in (Keys.OP, Keys.op_as("watch"), Keys.op_as("ops")):
            assert _replies(watch, key, _add()) == [], f"{key} answered an observer"
        assert _revision(ops) == before
        # control: the operator's own key works, and the server records the
        # logged-in account whatever the request claims
        events: queue.Queue = queue.Queue()
        sub = ops.declare_subscriber(Keys.EVENTS, lambda s: events.put(s.payload.to_bytes()))
        try:
            ((ok, _raw),) = _replies(ops, Keys.op_as("ops"), _add(user_claim="someone-else"))
            assert ok
            batch = EventBatch.model_validate_json(events.get(timeout=10))
            assert batch.actor == "ops@raw"
        finally:
            sub.undeclare()
        # an operator cannot act under another operator's key either
        assert _replies(ops, Keys.OP, _add()) == []
        assert _revision(ops) == before + 1


def test_observer_publications_are_not_delivered(server, accounts):
    ep = server.endpoint
    with (
        raw_session(ep, accounts.login("watch")) as watch,
        raw_session(ep, accounts.login("ops")) as ops,
    ):
        got: queue.Queue = queue.Queue()
        sub = ops.declare_subscriber(Keys.EVENTS, lambda s: got.put(s.payload.to_bytes()))
        try:
            _revision(ops)  # the subscription has reached the router
            fake = (
                EventBatch(revision=999, events=[], actor="watch", op="fake")
                .model_dump_json()
                .encode()
            )
            watch.put(Keys.EVENTS, fake)
            watch.delete(Keys.EVENTS)
            _revision(
                watch
            )  # a round trip on the observer's link: its put was routed (or dropped) before
            ((ok, _),) = _replies(ops, Keys.op_as("ops"), _add())
            assert ok
            first = EventBatch.model_validate_json(got.get(timeout=10))
            assert first.revision == 1 and first.actor != "watch"
        finally:
            sub.undeclare()


def _telemetry(robot: str, info: str) -> bytes:
    return (
        Telemetry(robot=robot, pose=Pose(), info=info, at=datetime.now(UTC))
        .model_dump_json()
        .encode()
    )


def test_robot_publishes_only_its_own_telemetry(server, accounts):
    ep = server.endpoint
    with (
        raw_session(ep, accounts.login("rover1")) as rover1,
        raw_session(ep, accounts.login("watch")) as watch,
        raw_session(ep, accounts.login("ops")) as ops,
    ):
        got: queue.Queue = queue.Queue()
        sub = ops.declare_subscriber(
            Keys.ALL_TELEMETRY, lambda s: got.put((str(s.key_expr), s.payload.to_bytes()))
        )
        try:
            _revision(ops)
            watch.put(Keys.telemetry("lru1"), _telemetry("lru1", "fake from observer"))
            _revision(watch)
            rover1.put(Keys.telemetry("lru2"), _telemetry("lru2", "fake from rover1"))
            own = declare_publisher(rover1, Keys.telemetry("lru1"))  # blocks rather than drops
            # a session drops what it publishes until it knows of a subscriber
            assert wait_matching(own, 10), "rover1 never learned of the operator's subscription"
            own.put(_telemetry("lru1", "real"))
            key, raw = got.get(timeout=10)
            assert key == Keys.telemetry("lru1")
            assert Telemetry.model_validate_json(raw).info == "real"
        finally:
            sub.undeclare()


def test_robot_cannot_report_or_register_for_another_robot_nor_change_the_mission(server, accounts):
    ep = server.endpoint
    with (
        raw_session(ep, accounts.login("rover1")) as rover1,
        raw_session(ep, accounts.login("ops")) as ops,
    ):
        before = _revision(ops)

        def downlink(robot: str, *reports: Report) -> bytes:
            return dumps(
                Downlink(robot=robot, session="s1", messages=list(reports), sent=datetime.now(UTC))
            )

        # control: its own downlink key answers (it has not registered: the server says so)
        ((ok, raw),) = _replies(rover1, Keys.downlink("lru1"), downlink("lru1"))
        assert not ok and b"not_registered" in raw
        # another robot's keys: the router drops the query
        report = Report(robot="lru2", seq=1, id="lru2-1", status="success")
        assert _replies(rover1, Keys.downlink("lru2"), downlink("lru2", report)) == []
        assert _replies(rover1, Keys.register("lru2"), b"{}") == []
        # operations and the state are not a robot's business
        for key in (Keys.OP, Keys.op_as("rover1"), Keys.op_as("ops"), Keys.STATE):
            assert _replies(rover1, key, _add()) == [], key
        assert _revision(ops) == before
        # registered, its own key carrying another robot's report: the server
        # refuses that message (its number is used up), lru2 is untouched
        manifest = Manifest(name="lru1", type="lru_science")
        ((ok, raw),) = _replies(
            rover1, Keys.register("lru1"), dumps(Register(manifest=manifest, session="s1"))
        )
        assert ok and RegisterReply.model_validate_json(raw).accepted
        ((ok, raw),) = _replies(rover1, Keys.downlink("lru1"), downlink("lru1", report))
        ack = DownlinkAck.model_validate_json(raw)
        assert ok and ack.last_seq == 1 and [r.seq for r in ack.refused] == [1]
        assert ack.refused[0].code == "bad_message"
        assert "lru1 cannot send messages of lru2" in ack.refused[0].message
        ((ok, raw),) = _replies(ops, Keys.STATE)
        lru2 = StateSnapshot.model_validate_json(raw).mission.tasks["lru2"]
        assert [s.status.value for s in lru2] == ["idle", "idle"]


def test_robots_ask_each_other_but_cannot_pose_as_another(server, accounts):
    ep = server.endpoint
    with (
        raw_session(ep, accounts.login("rover1")) as rover1,
        raw_session(ep, accounts.login("rover2")) as rover2,
    ):
        # the fake first: once `own` is reachable, the router has handled the
        # fake's declaration (same link)
        fake = rover1.declare_queryable(
            Keys.world("lru2"), lambda q: q.reply(Keys.world("lru2"), b"rover1 posing as lru2")
        )
        own = rover1.declare_queryable(
            Keys.world("lru1"), lambda q: q.reply(Keys.world("lru1"), b"lru1 here")
        )
        try:
            deadline = time.monotonic() + 10
            while not (
                answers := _replies(rover2, Keys.world("lru1"))
            ):  # until the declaration has reached the router
                assert time.monotonic() < deadline, "lru1's world queryable never became reachable"
            assert answers == [(True, b"lru1 here")]
            assert _replies(rover2, Keys.world("lru2")) == []
        finally:
            own.undeclare()
            fake.undeclare()
