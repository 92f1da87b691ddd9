"""A message the client library cannot read (a third-party robot speaking
another protocol, say) is ignored, and said once per key with the field that
is wrong: an integrator bringing up a robot learns why its telemetry never
shows, and a 10 Hz stream does not flood anyone."""

from __future__ import annotations

import asyncio
import json
from datetime import UTC, datetime

from backend.client.client import Malformed
from backend.protocol.keys import Keys
from backend.protocol.messages import Telemetry, dumps
from backend.transport import client_config, declare_publisher, wait_matching
from backend.transport.session import close_session, open_session

from .harness import drive


def test_unreadable_telemetry_is_said_once_with_its_field(cluster):
    session = open_session(client_config([cluster.endpoint]))
    try:

        async def scenario(c):
            seen: list[Malformed] = []
            c.add_listener(lambda e: seen.append(e) if isinstance(e, Malformed) else None)
            key = Keys.telemetry("lru1")
            pub = declare_publisher(
                session, key
            )  # blocks rather than drops: the last one must arrive
            # a fresh session drops what it puts until it knows of the client's subscriber
            assert await asyncio.to_thread(wait_matching, pub, 10), (
                "the client's telemetry subscriber never showed"
            )
            bad = {"robot": "lru1", "battery": 1.7, "at": datetime.now(UTC).isoformat()}
            for _ in range(3):  # a stream of them
                pub.put(json.dumps(bad))
            # then a readable one from the same publisher: it arrives after them
            pub.put(dumps(Telemetry(robot="lru1", battery=0.5, at=datetime.now(UTC))))
            await c.wait_for(lambda _m: "lru1" in c.telemetry, 10)
            assert c.telemetry["lru1"].battery == 0.5
            [m] = seen
            assert (m.what, m.key) == ("telemetry", key)
            assert m.error.startswith("battery: ") and "1" in m.error
            assert key in m.sentence() and "protocol" in m.sentence()

        drive(cluster, scenario)
    finally:
        close_session(session)
