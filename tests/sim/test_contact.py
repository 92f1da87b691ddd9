"""The simulator's comms windows reach the server: each robot's contact
state there follows the sim's `--comms-window`, on the sim clock."""

from __future__ import annotations

from .conftest import STARTUP, Stack, connect


async def test_the_sims_window_gives_the_server_each_robots_contact(stack: Stack) -> None:
    client, watch = await connect(stack, speed=50, extra=["--comms-window", "20m/2h"])
    try:

        def from_sim() -> bool:
            return all(
                (c := client.robots[r].contact) is not None and c.source == "sim"
                for r in client.mission.robots
            )

        await client.wait_for(lambda _m: from_sim(), STARTUP)
        for name in client.mission.robots:
            c = client.robots[name].contact
            assert c is not None
            # the sim opened its first window at sim time 0, for 20 min
            assert (c.state, c.closes, c.next_contact, c.clock) == (
                "in_contact",
                1200.0,
                None,
                "sim",
            ), name
    finally:
        watch.close()
        await client.close()
