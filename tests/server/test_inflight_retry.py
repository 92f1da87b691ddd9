"""A request retried while its robot has not answered yet (a client whose
reply was lost, or two hand-overs in one pass of the server's event loop) is
applied once: the robot gets one command, both askers the same reply."""

from __future__ import annotations

import asyncio
import json

from backend.core.ops import Sync
from backend.protocol.messages import CommandReply, Request, dumps
from backend.server.server import MissionServer
from backend.transport import free_port, loopback_endpoint

from .harness import TUTORIAL, RawRobot


class CountingRobot(RawRobot):
    """Accepts every command and counts the enqueues."""

    def __init__(self, endpoint: str, name: str):
        self.enqueued: list[list[str]] = []
        super().__init__(endpoint, name)

    def answer(self, enqueued: list[str]) -> CommandReply:
        if enqueued:
            self.enqueued.append(enqueued)
        return super().answer(enqueued)


def test_a_robot_request_handed_over_twice_before_the_robot_answers_is_applied_once(tmp_path):
    async def scenario() -> None:
        endpoint = loopback_endpoint(free_port())
        server = MissionServer(db=tmp_path / "m.db", mission_file=TUTORIAL, listen=[endpoint])
        await server.start()
        robot = CountingRobot(endpoint, "lru1")
        try:
            await robot.register("lru_science")
            payload = dumps(
                Request(client="c", request_id="sync-1", op=Sync(robot="lru1", through="lru1-1"))
            )
            # both handed over in the same pass of the loop, before either
            # has sent its command: the second waits for the first
            first, second = server._handle_op(payload), server._handle_op(payload)
            replies = await asyncio.wait_for(asyncio.gather(first, second), 30)
            assert robot.enqueued == [["lru1-1"]]
            assert replies[0] == replies[1]
            assert json.loads(replies[0])["value"]["synchronized"] == ["lru1-1"]
            # and once answered, a retry is a duplicate, not a second command
            again = json.loads(server._handle_op(payload))
            assert again["duplicate"] is True and robot.enqueued == [["lru1-1"]]
        finally:
            robot.close()
            await server.stop()

    asyncio.run(scenario())
