"""Event batches of operations the server handled in a row leave as one
message, a JSON array in revision order (each message costs every client a
wake-up of two threads); a lone operation's batch is a plain object, as
before. Grouping never reorders publications across keys."""

from __future__ import annotations

import asyncio
import json
from contextlib import asynccontextmanager

import pytest
from pydantic import ValidationError
from zenoh.handlers import Callback

from backend.core.alerts import AlertKind
from backend.core.events import EventBatch, SkillEdited, read_batches
from backend.core.ops import EditSkill
from backend.protocol.keys import Keys
from backend.protocol.messages import Alert, Request, StateSnapshot, dumps
from backend.transport import client_config
from backend.transport.session import close_session, open_session

from .harness import serving


def _edit(request_id: str, label: str) -> bytes:
    return dumps(
        Request(client="grouping", request_id=request_id, op=EditSkill(id="lru1-1", label=label))
    )


class _Listener:
    """A plain Zenoh session taking in the events and alerts keys, in arrival
    order (direct callbacks: on the link's thread, one after the other; a
    Python thread per subscriber could take them in either order)."""

    def __init__(self, endpoint: str, loop: asyncio.AbstractEventLoop):
        self.session = open_session(client_config([endpoint]))
        self.messages: asyncio.Queue[tuple[str, bytes]] = asyncio.Queue()
        for key in (Keys.ALERTS, Keys.EVENTS):  # events last: a batch received proves both known
            self.session.declare_subscriber(
                key,
                Callback(
                    lambda s, key=key: loop.call_soon_threadsafe(
                        self.messages.put_nowait, (key, s.payload.to_bytes())
                    ),
                    indirect=False,
                ),
            )

    async def next(self) -> tuple[str, bytes]:
        return await asyncio.wait_for(self.messages.get(), 10)

    async def ready(self, client) -> None:
        """Until the server's router knows of our subscribers, puts skip us."""
        for i in range(100):
            await client.submit(EditSkill(id="lru1-2", label=f"probe {i}"))
            try:
                await asyncio.wait_for(self.messages.get(), 0.2)
                break
            except TimeoutError:
                continue
        else:
            raise AssertionError("the listener never received an event batch")
        while not self.messages.empty():
            self.messages.get_nowait()


@asynccontextmanager
async def listening(db):
    """A server in this process, its client, and a listener it knows of."""
    async with serving(db) as (server, client):
        listener = _Listener(server.listen[0], asyncio.get_running_loop())
        try:
            await listener.ready(client)
            yield server, client, listener
        finally:
            close_session(listener.session)


def test_operations_handled_in_a_row_share_one_message_in_order(tmp_path):
    async def scenario() -> None:
        async with listening(tmp_path / "m.db") as (server, client, listener):
            start = server.mission.revision
            # three operations in one loop callback, as when queries arrive together
            for i in range(3):
                server._handle_op(_edit(f"r{i}", f"in a row {i}"))
            key, payload = await listener.next()
            assert key == Keys.EVENTS
            assert payload.startswith(b"[")
            batches = [EventBatch.model_validate(b) for b in json.loads(payload)]
            assert [b.revision for b in batches] == [start + 1, start + 2, start + 3]
            assert [b.events[0].label for b in batches] == [f"in a row {i}" for i in range(3)]
            # the client library applies the whole array
            mission = await client.wait_for(lambda m: m.revision == start + 3)
            assert mission.find("lru1-1")[2].label == "in a row 2"
            # a lone operation's batch is a plain object
            await client.submit(EditSkill(id="lru1-1", label="alone"))
            key, payload = await listener.next()
            assert key == Keys.EVENTS and payload.startswith(b"{")
            assert EventBatch.model_validate_json(payload).revision == start + 4

    asyncio.run(scenario())


def test_grouping_never_moves_a_batch_past_another_keys_publication(tmp_path):
    async def scenario() -> None:
        async with listening(tmp_path / "m.db") as (server, client, listener):
            start = server.mission.revision
            server._handle_op(_edit("a", "before the alert"))
            server.alert("between the two", kind=AlertKind.JOURNAL)
            server._handle_op(_edit("b", "after the alert"))
            server._handle_op(_edit("c", "after the alert too"))
            got = [await listener.next() for _ in range(3)]
            assert [key for key, _ in got] == [Keys.EVENTS, Keys.ALERTS, Keys.EVENTS]
            assert [b.revision for b in read_batches(got[0][1])] == [start + 1]
            assert Alert.model_validate_json(got[1][1]).message == "between the two"
            assert [b.revision for b in read_batches(got[2][1])] == [start + 2, start + 3]
            # numbered, and kept for the state snapshot (a console that was away)
            server.alert("another", kind=AlertKind.OFFLINE, robot="lru1")
            snap = StateSnapshot.model_validate_json(server._handle_state(b""))
            assert [(a.id, a.message) for a in snap.alerts][-2:] == [
                (snap.alerts[-2].id, "between the two"),
                (snap.alerts[-2].id + 1, "another"),
            ]

    asyncio.run(scenario())


def test_read_batches_takes_one_batch_or_an_array_and_names_a_bad_field():
    one = EventBatch(revision=7, events=[SkillEdited(id="a-1", label="x")], actor="c")
    two = one.model_copy(update={"revision": 8})
    assert read_batches(one.model_dump_json().encode()) == [one]
    array = b"[" + one.model_dump_json().encode() + b"," + two.model_dump_json().encode() + b"]"
    assert read_batches(array) == [one, two]
    with pytest.raises(ValidationError) as bad:
        read_batches(b'[{"revision": "seven", "events": []}]')
    assert bad.value.errors()[0]["loc"][:2] == (0, "revision")
