"""A site relay with the delay in the network: the ground's server <- a TCP
proxy delaying every byte by D each way <- `missionctl router` <- robots.

Every process is given `--link-delay-hint D` and nothing else. D = 6 s runs
in real time (~1.5 min: marked `slow`, run by CI's full suite; deselect with
`-m "not slow"`)."""

from __future__ import annotations

import asyncio
import time
from datetime import UTC, datetime

import pytest
from deployment import Site, wait_count

from backend.client.client import MissionClient
from backend.core.model import Status
from backend.core.ops import AddBarrier, Control, EditSkill, Sync
from backend.protocol.keys import Keys
from backend.protocol.messages import Telemetry, WorldMessage, dumps
from backend.transport import query, subscribe
from tests.server.harness import status

DONE = ["lru1-1", "lru1-2", "lru2-1", "lru2-2"]


def _all(m, wanted: str) -> bool:
    return all(status(m, sid) == wanted for sid in DONE)


async def _plan_and_run(c: MissionClient) -> None:
    """The tutorial's plan with a barrier between the robots' second skills:
    synchronized and run in one go (the commands share one transmission)."""
    await c.submit(AddBarrier(ids=["lru1-2", "lru2-2"]))
    await c.submit(Sync(robot="lru1"))
    await c.submit(Sync(robot="lru2"))
    await c.submit(Control(op="run"))


async def _through_the_relay(tmp_path, delay: float) -> None:
    site = Site(tmp_path, delay)
    try:
        await asyncio.to_thread(site.start)
        c = await site.client()
        await c.wait_for(lambda m: all(c.robots[r].online for r in m.robots), 30 + 6 * delay)
        sent = time.monotonic()
        await _plan_and_run(c)
        m = await c.wait_for(lambda m: _all(m, "success"), 30 + 6 * delay)
        # the answers came back through the delay: the network's, not the SDK's
        assert time.monotonic() - sent >= 2 * delay
        # met at the barrier across the relay: neither started before both were there
        lru1, lru2 = m.find("lru1-2")[2], m.find("lru2-2")[2]
        assert abs((lru1.started_at - lru2.started_at).total_seconds()) < 2.0
        assert c.robots["lru1"].delay_s is not None
        up, down = site.proxy.counts()
        assert up > 0 and down > 0  # everything crossed the proxy
    finally:
        await site.aclose()


@pytest.mark.parametrize("delay", [0.0, 1.3])
async def test_sync_run_report_and_barrier_through_a_relay(tmp_path, delay):
    await _through_the_relay(tmp_path, delay)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_six_seconds_each_way_with_only_the_hint(tmp_path):
    """Zenoh's defaults fail at D = 5 s (the handshake outlasts the 10 s
    accept timeout); the hint alone makes it work. Longer than the async
    tests' 120 s guard: run here with its own."""
    asyncio.run(asyncio.wait_for(_through_the_relay(tmp_path, 6.0), 240))


LEASE_2S = "{transport: {link: {tx: {lease: 2000}}}}"


async def test_the_site_works_on_while_the_link_is_cut_and_nothing_is_lost(tmp_path):
    """The ground link is cut for longer than its lease: both ends drop it (the
    ground sees the robots go offline), the robots meet at their barrier and
    finish their plan through the relay, their reports wait aboard; healed, the
    relay reconnects by itself and every report reaches the ground.

    The leases are 2 s here (a --zenoh-config on server and relay) and the cut
    ~5 s: the same course as a 20 s cut with the default 10 s lease (the lease
    ends, the link is re-opened), in a quarter of the time."""
    config = tmp_path / "lease.json5"
    config.write_text(LEASE_2S)
    site = Site(tmp_path)
    try:
        site.start_server("--zenoh-config", str(config))
        site.start_link()
        site.start_relay("--zenoh-config", str(config))
        site.start_robots()
        c = await site.client()
        await c.wait_for(lambda m: all(c.robots[r].online for r in m.robots), 30)
        await c.submit(EditSkill(id="lru1-1", label="hold"))  # runs until told "release"
        await _plan_and_run(c)
        await c.wait_for(
            lambda m: status(m, "lru1-1") == "running" and status(m, "lru2-2") == "synchwaiting",
            30,
        )
        at_site = site.site_session()  # a tool beside the robots
        done_at_site, _sub = _watch_telemetry(at_site, "lru1", lambda t: t.skill is None)
        site.proxy.cut()
        await asyncio.to_thread(site.relay.wait_line, "ground link down", 20)
        await c.wait_for(lambda m: not any(c.robots[r].online for r in m.robots), 20)
        # cut off from the ground, the site goes on: lru1 released, both meet at the barrier
        release = WorldMessage(kind="tell", sender="test", topic="release", data={"id": "lru1-1"})
        await query(at_site, Keys.world("lru1"), dumps(release), 5.0)
        await asyncio.wait_for(done_at_site.wait(), 20)
        assert status(c.mission, "lru1-1") == "running"  # the ground has not heard yet
        site.proxy.heal()
        await asyncio.to_thread(wait_count, site.relay, "ground link up", 2, 30)
        m = await c.wait_for(lambda m: _all(m, "success"), 30)
        await c.wait_for(lambda m: all(c.robots[r].online for r in m.robots), 10)
        lru1, lru2 = m.find("lru1-2")[2], m.find("lru2-2")[2]
        assert abs((lru1.started_at - lru2.started_at).total_seconds()) < 2.0
    finally:
        await site.aclose()


def _watch_telemetry(session, robot: str, pred) -> tuple[asyncio.Event, object]:
    """An event set once `robot` publishes a sample meeting `pred` after its
    lru1-2 ran, and the subscriber (keep it while waiting)."""
    loop = asyncio.get_running_loop()
    seen = asyncio.Event()
    ran: set[str] = set()

    def on_sample(msg) -> None:  # a Zenoh thread
        t = Telemetry.model_validate_json(msg.payload)
        if t.skill is not None:
            ran.add(t.skill)
        if "lru1-2" in ran and pred(t):
            loop.call_soon_threadsafe(seen.set)

    return seen, subscribe(session, Keys.telemetry(robot), on_sample)


async def test_robots_wait_at_the_relay_for_a_ground_that_is_not_there_yet(tmp_path):
    site = Site(tmp_path)
    try:
        site.start_link()  # nothing behind it yet
        site.start_relay()
        robots = await asyncio.to_thread(site.start_robots, wait=False)
        site.start_server()
        for r in ("lru1", "lru2"):
            await asyncio.to_thread(robots.wait_line, f"ready {r}", 30)
        await asyncio.to_thread(site.relay.wait_line, "ground link up", 10)
        c = await site.client()
        assert all(c.robots[r].online for r in c.mission.robots)
        assert c.robots["lru1"].since is not None and c.robots["lru1"].since <= datetime.now(UTC)
        assert c.mission.tasks["lru1"][0].status == Status.IDLE
    finally:
        await site.aclose()
