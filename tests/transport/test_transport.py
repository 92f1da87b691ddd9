"""backend.transport against a real Zenoh router running in a subprocess."""

from __future__ import annotations

import asyncio
import json
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh

from backend.transport import (
    Message,
    NoResponder,
    QueryError,
    QueryTimeout,
    ReplyError,
    TransportChange,
    TransportUnreachable,
    client_config,
    close_session,
    declare_publisher,
    free_port,
    load_config_file,
    loopback_endpoint,
    open_session,
    query,
    query_all,
    query_sync,
    router_config,
    serve,
    serve_async,
    subscribe_to_queue,
    transport_events,
    wait_matching,
    watch_liveliness,
)

WAIT = 5.0  # upper bound for events that normally take milliseconds


# ---------------------------------------------------------------- configs


def _get(config: zenoh.Config, path: str) -> object:
    return json.loads(config.get_json(path))


def test_router_config_is_loopback_only_and_timestamped() -> None:
    config = router_config(["tcp/127.0.0.1:7447"])
    assert _get(config, "mode") == "router"
    assert _get(config, "listen/endpoints") == ["tcp/127.0.0.1:7447"]
    assert _get(config, "scouting/multicast/enabled") is False
    assert _get(config, "scouting/gossip/enabled") is False
    assert _get(config, "scouting/delay") == 0
    assert _get(config, "timestamping/enabled") is True


BATCHING = "transport/link/tx/queue/batching/enabled"


def test_server_sends_at_once_unless_its_config_file_says_otherwise() -> None:
    # batching held an operation's reply back ~1 ms behind its event batch (p99 tail)
    assert _get(router_config(["tcp/127.0.0.1:7447"]), BATCHING) is False
    assert _get(router_config(["tcp/127.0.0.1:7447"], extra={BATCHING: True}), BATCHING) is True
    assert _get(client_config(["tcp/127.0.0.1:7447"]), BATCHING) is True  # Zenoh's default


def test_client_config_options_and_extra() -> None:
    plain = client_config(["tcp/127.0.0.1:7447"])
    assert _get(plain, "mode") == "client"
    assert _get(plain, "connect/endpoints") == ["tcp/127.0.0.1:7447"]
    assert _get(plain, "listen/endpoints") == []
    assert _get(plain, "scouting/multicast/enabled") is False
    assert _get(plain, "connect/timeout_ms") is None

    config = client_config(
        ["tcp/127.0.0.1:7447"],
        lease_ms=2500,
        wait_for_router=True,
        extra={"transport.auth.usrpwd.user": "alice", "queries_default_timeout": 1234},
    )
    assert _get(config, "connect/timeout_ms") == -1
    assert _get(config, "transport/link/tx/lease") == 2500
    assert _get(config, "transport/auth/usrpwd/user") == "alice"
    assert _get(config, "queries_default_timeout") == 1234

    with pytest.raises(ValueError, match="no/such/key"):
        client_config(["tcp/127.0.0.1:7447"], extra={"no/such/key": 1})


def test_load_config_file_returns_only_changed_options(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text(
        "{\n  // JSON5: comments and trailing commas\n"
        "  transport: { link: { tx: { lease: 3000 } } },\n"
        '  connect: { endpoints: ["tcp/127.0.0.1:7448"] },\n}\n'
    )
    extra = load_config_file(path)
    assert extra == {"transport/link/tx/lease": 3000, "connect/endpoints": ["tcp/127.0.0.1:7448"]}
    assert (
        _get(client_config(["tcp/127.0.0.1:7447"], extra=extra), "transport/link/tx/lease") == 3000
    )

    bad = tmp_path / "bad.json5"
    bad.write_text("{ transport: { nope: 1 } }")
    with pytest.raises(ValueError, match="nope"):
        load_config_file(bad)


# ---------------------------------------------------------------- sessions


def test_unreachable_router_fails_fast_with_endpoint_in_message() -> None:
    endpoint = loopback_endpoint(free_port())  # nothing listens there
    started = time.monotonic()
    with pytest.raises(TransportUnreachable) as info:
        open_session(client_config([endpoint]))
    assert time.monotonic() - started < 2.0
    message = str(info.value)
    assert message.startswith(f"cannot reach the mission server at {endpoint}: ")
    assert "\n" not in message and ".rs:" not in message
    assert info.value.endpoints == [endpoint]


def test_process_with_subscriber_exits_promptly_after_close(router: Any, spawn) -> None:
    proc = spawn("sub-and-close", router.endpoint)
    try:
        proc.popen.wait(timeout=15)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("process with a closed session did not exit")
    assert proc.popen.returncode == 0
    assert proc.next_line() == "closed"


class _IsClosedForbidden:
    """A session whose `is_closed()` fails the test: called with the GIL held,
    it can deadlock against a liveliness query's done callback."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.closes = 0

    def is_closed(self) -> bool:
        raise AssertionError("close_session asked is_closed()")

    def close(self) -> None:
        self.closes += 1
        self.session.close()


def test_close_session_closes_without_asking_is_closed_and_can_repeat(
    router: Any, open_client
) -> None:
    session = open_client(router.endpoint)  # closed in teardown too, should this test fail
    wrapped = _IsClosedForbidden(session)
    close_session(wrapped)  # type: ignore[arg-type]
    close_session(wrapped)  # type: ignore[arg-type]  # a second close is harmless
    assert wrapped.closes == 2
    assert session.is_closed()  # no query can be running on a closed session


# ---------------------------------------------------------------- queries


def test_query_round_trip_sync_and_async(router: Any, open_client) -> None:
    session = open_client(router.endpoint)
    assert query_sync(session, "test/echo", b"hello", timeout=WAIT) == b"echo:hello"
    assert query_sync(session, "test/echo", None, timeout=WAIT) == b"echo:"
    assert asyncio.run(query(session, "test/echo", b"async", timeout=WAIT)) == b"echo:async"


def test_refusal_becomes_query_error(router: Any, open_client) -> None:
    session = open_client(router.endpoint)
    with pytest.raises(QueryError) as info:
        query_sync(session, "test/refuse", b"x", timeout=WAIT)
    assert info.value.message == "skill is not idle"
    assert info.value.payload == b"skill is not idle"
    with pytest.raises(QueryError, match="skill is not idle"):
        asyncio.run(query(session, "test/refuse", b"x", timeout=WAIT))


def test_handler_exception_becomes_query_error(router: Any, open_client) -> None:
    session = open_client(router.endpoint)
    with pytest.raises(QueryError) as info:
        query_sync(session, "test/boom", b"x", timeout=WAIT)
    assert "ValueError: kaboom" in info.value.message
    assert "test/boom" in info.value.message


def test_no_queryable_raises_no_responder_at_once(router: Any, open_client) -> None:
    session = open_client(router.endpoint)
    started = time.monotonic()
    with pytest.raises(NoResponder):
        query_sync(session, "test/nobody", b"x", timeout=WAIT)
    with pytest.raises(NoResponder):
        asyncio.run(query(session, "test/nobody", b"x", timeout=WAIT))
    assert time.monotonic() - started < 1.0


def test_slow_queryable_raises_query_timeout(router: Any, open_client) -> None:
    session = open_client(router.endpoint)
    with pytest.raises(QueryTimeout):
        query_sync(session, "test/slow", b"x", timeout=0.1)


def test_async_query_does_not_block_the_loop(router: Any, open_client) -> None:
    session = open_client(router.endpoint)

    async def scenario() -> tuple[bytes, int]:
        ticks = 0
        stop = asyncio.Event()

        async def ticker() -> None:
            nonlocal ticks
            while not stop.is_set():
                ticks += 1
                await asyncio.sleep(0.01)

        task = asyncio.create_task(ticker())
        try:
            result = await query(session, "test/slow", b"zzz", timeout=WAIT)  # ~0.5 s
        finally:
            stop.set()
            await task
        return result, ticks

    result, ticks = asyncio.run(scenario())
    assert result == b"zzz"
    assert ticks >= 10  # ~50 expected; 1 if the query had blocked the loop


def wait_for_queryables(session: Any, key: str, count: int = 1, timeout: float = WAIT) -> None:
    """Queryables declared on another client reach us through the router:
    wait until `count` of them match `key` (a querier's matching listener)."""
    querier = session.declare_querier(key)
    matched = threading.Event()
    listener = querier.declare_matching_listener(
        lambda status: matched.set() if status.matching else None
    )
    try:
        if not querier.matching_status.matching:
            assert matched.wait(timeout), f"no queryable on {key} within {timeout}s"
    finally:
        listener.undeclare()
        querier.undeclare()


def test_serve_async_and_query_all_between_clients(router: Any, open_client) -> None:
    server = open_client(router.endpoint)
    other = open_client(router.endpoint)
    caller = open_client(router.endpoint)
    serve(other, "robots/r2/ping", lambda payload: b"r2")

    async def scenario() -> None:
        loop_thread = threading.get_ident()

        async def handler(payload: bytes) -> bytes:
            assert threading.get_ident() == loop_thread  # runs on the event loop
            if payload == b"no":
                raise ReplyError("r1 refuses")
            await asyncio.sleep(0)
            return b"r1:" + payload

        serve_async(server, "robots/r1/ping", handler)
        await asyncio.to_thread(wait_for_queryables, caller, "robots/r1/ping")
        await asyncio.to_thread(wait_for_queryables, caller, "robots/r2/ping")
        assert await query(caller, "robots/r1/ping", b"hi", timeout=WAIT) == b"r1:hi"
        with pytest.raises(QueryError, match="r1 refuses"):
            await query(caller, "robots/r1/ping", b"no", timeout=WAIT)
        replies = await query_all(caller, "robots/*/ping", b"all", timeout=WAIT)
        assert sorted((r.key, r.payload, r.ok) for r in replies) == [
            ("robots/r1/ping", b"r1:all", True),
            ("robots/r2/ping", b"r2", True),
        ]
        assert await query_all(caller, "nobody/*", timeout=WAIT) == []

    asyncio.run(scenario())


def test_serve_async_plain_handler_answers_at_once_or_with_an_awaitable(
    router: Any, open_client
) -> None:
    server = open_client(router.endpoint)
    caller = open_client(router.endpoint)

    async def scenario() -> None:
        loop_thread = threading.get_ident()
        seen_threads: set[int] = set()

        async def later(payload: bytes) -> bytes:
            await asyncio.sleep(0)
            return b"later:" + payload

        def handler(payload: bytes) -> bytes | Any:
            seen_threads.add(threading.get_ident())
            if payload == b"no":
                raise ReplyError("plainly not")
            if payload == b"bug":
                raise KeyError("oops")
            if payload == b"wrong":
                return "not bytes"
            if payload.startswith(b"wait"):
                return later(payload)  # answered when it completes
            return b"now:" + payload

        serve_async(server, "svc/plain", handler)
        await asyncio.to_thread(wait_for_queryables, caller, "svc/plain")
        assert await query(caller, "svc/plain", b"hi", timeout=WAIT) == b"now:hi"
        assert await query(caller, "svc/plain", b"wait1", timeout=WAIT) == b"later:wait1"
        with pytest.raises(QueryError, match="plainly not"):
            await query(caller, "svc/plain", b"no", timeout=WAIT)
        with pytest.raises(QueryError, match="internal error .*KeyError"):
            await query(caller, "svc/plain", b"bug", timeout=WAIT)
        with pytest.raises(QueryError, match="returned str, expected bytes"):
            await query(caller, "svc/plain", b"wrong", timeout=WAIT)
        # concurrent queries whose answers wait are all answered
        got = await asyncio.gather(
            *(query(caller, "svc/plain", f"wait{i}".encode(), timeout=WAIT) for i in range(20))
        )
        assert got == [f"later:wait{i}".encode() for i in range(20)]
        assert seen_threads == {loop_thread}  # every call ran on the event loop

    asyncio.run(scenario())


def test_query_returns_the_answer_before_the_responder_ends_the_query(
    router: Any, open_client
) -> None:
    # a single responder's answer is used at once; Zenoh ends the query only
    # when the responder drops it (here: once the caller has its answer)
    server = open_client(router.endpoint)
    caller = open_client(router.endpoint)
    release = threading.Event()

    def on_query(q: zenoh.Query) -> None:
        q.reply("svc/slow-end", b"early")
        threading.Thread(target=lambda: (release.wait(WAIT * 4), q.drop()), daemon=True).start()

    server.declare_queryable("svc/slow-end", on_query)
    wait_for_queryables(caller, "svc/slow-end")

    async def scenario() -> bytes:
        try:
            return await asyncio.wait_for(query(caller, "svc/slow-end", timeout=WAIT * 4), WAIT)
        finally:
            release.set()

    assert asyncio.run(scenario()) == b"early"


# ---------------------------------------------------------------- pub/sub


def test_pubsub_between_two_clients_through_router(router: Any, open_client) -> None:
    sub_session = open_client(router.endpoint)
    pub_session = open_client(router.endpoint)

    async def scenario() -> list[Message]:
        _, inbox = subscribe_to_queue(sub_session, "fleet/*/state")
        publisher = declare_publisher(pub_session, "fleet/r1/state")
        # Subscriber declarations reach the publisher via the router: wait for it.
        assert await asyncio.to_thread(wait_matching, publisher, WAIT)
        for i in range(100):
            publisher.put(f"s{i}".encode())
        publisher.delete()
        return [await asyncio.wait_for(inbox.get(), WAIT) for _ in range(101)]

    messages = asyncio.run(scenario())
    assert [m.payload for m in messages[:100]] == [f"s{i}".encode() for i in range(100)]
    assert all(m.key == "fleet/r1/state" and m.kind == "put" for m in messages[:100])
    assert messages[100] == Message("fleet/r1/state", b"", "delete")


# ---------------------------------------------------------------- presence and links


def test_liveliness_history_and_delete_when_holder_is_killed(
    router: Any, open_client, spawn
) -> None:
    holder = spawn("token", router.endpoint, "robots/r7/alive")
    assert holder.next_line() == "ready"

    session = open_client(router.endpoint)
    changes: list[tuple[str, bool]] = []
    alive, gone = threading.Event(), threading.Event()

    def on_change(key: str, is_alive: bool) -> None:
        changes.append((key, is_alive))
        (alive if is_alive else gone).set()

    # The token existed before we subscribed: history reports it.
    watch_liveliness(session, "robots/*/alive", on_change)
    assert alive.wait(WAIT)
    holder.kill()
    assert gone.wait(WAIT)
    assert changes == [("robots/r7/alive", True), ("robots/r7/alive", False)]


def test_transport_events_report_router_loss(make_router, open_client) -> None:
    router = make_router()
    session = open_client(router.endpoint)
    changes: list[TransportChange] = []
    up, down = threading.Event(), threading.Event()

    def on_change(change: TransportChange) -> None:
        changes.append(change)
        (up if change.connected else down).set()

    transport_events(session, on_change)
    assert up.wait(WAIT)  # history: the already open router link
    router.proc.kill()
    assert down.wait(WAIT)
    assert [(c.whatami, c.connected) for c in changes] == [("router", True), ("router", False)]
    assert changes[0].zid == changes[1].zid
