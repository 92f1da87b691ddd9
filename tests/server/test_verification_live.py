"""Verification stages live: a server, a robot behind an injected link delay, and
`ctl wait` / `ctl pending` as an operator runs them (backend/core/verification.py)."""

from __future__ import annotations

import asyncio
import json
from datetime import UTC, datetime, timedelta

import pytest

import backend.core.verification as verification
from backend.core.ops import Sync
from backend.exit_codes import EXIT_OK, EXIT_OVERDUE
from backend.protocol.messages import Downlink

from ..cli.helpers import ctl
from .harness import RawRobot, serving

WAIT = 10.0
DELAY_S = 0.3  # the robot's one-way delay, as its `sent` times say


class FarRobot(RawRobot):
    """A robot whose messages say they left DELAY_S ago: the server's delay estimate."""

    def downlink(self, messages: list) -> Downlink:
        dl = super().downlink(messages)
        return dl.model_copy(update={"sent": dl.sent - timedelta(seconds=DELAY_S)})


async def _ctl(endpoint: str, *args: str):
    return await asyncio.to_thread(ctl, endpoint, *args)


@pytest.fixture
def short_tolerance(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(verification, "TOLERANCE_MIN_S", 0.2)


def test_received_is_reached_and_a_silent_robot_falls_overdue(tmp_path, short_tolerance) -> None:
    async def main() -> None:
        async with serving(tmp_path / "m.db") as (server, client):
            endpoint = server.listen[0]
            robot = FarRobot(endpoint, "lru1")
            try:
                await robot.register("lru_science", sent=datetime.now(UTC) - timedelta(seconds=1))
                await client.wait_for(lambda _m: client.robots["lru1"].online, WAIT)
                # the robot answers: received
                reply = await client.submit(Sync(robot="lru1", through="lru1-1"))
                cid = int(reply.value["command"])
                r = await _ctl(endpoint, "wait", str(cid), "--until", "received")
                assert r.returncode == EXIT_OK, r.stderr
                assert f"command {cid}: received at" in r.stdout

                # cut off: it takes the command but never answers
                robot.hold = True
                reply = await client.submit(Sync(robot="lru1"))
                cid = int(reply.value["command"])
                pending = json.loads((await _ctl(endpoint, "pending", "--json")).stdout)
                (mine,) = [c for c in pending["pending"] if c["id"] == cid]
                stages = {s["name"]: s for s in mine["stages"]}
                assert list(stages) == ["queued", "sent", "received", "started", "completed"]
                assert stages["received"]["due"] is not None
                r = await _ctl(endpoint, "wait", str(cid), "--until", "received", "--json")
                assert r.returncode == EXIT_OVERDUE, r.stderr
                out = json.loads(r.stdout)
                assert out["outcome"] == "overdue" and "OVERDUE" in out["message"]
                await client.wait_for(
                    lambda _m: any(a.kind == "overdue" for a in server.alerts), WAIT
                )
                alert = next(a for a in server.alerts if a.kind == "overdue")
                assert alert.command == cid and alert.robot == "lru1"
                assert "has not been received by lru1: due" in alert.message
                assert " late" in alert.message
            finally:
                robot.close()

    asyncio.run(main())
