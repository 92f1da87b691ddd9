"""The simulator's live status as patches: what goes on the wire, and a
follower's mirror (backend.protocol.mapfeed, backend.client.simstatus)."""

from __future__ import annotations

import asyncio

from backend.client.simstatus import SimStatusFeed
from backend.protocol import mapfeed as mf
from backend.transport import (
    client_config,
    close_session,
    declare_publisher,
    free_port,
    loopback_endpoint,
    open_session,
    router_config,
    serve,
)

WAIT = 10.0


def status(sim_time: float, **kw) -> mf.SimStatus:
    robot = mf.RobotStatus(name="lru1", type="lru_science", kind="rover", x=1.0, y=2.0,
                           battery=0.9, in_range=True, link=1.0)  # fmt: skip
    fields = {"world": "w", "seed": 1, "speed": 1.0, "sim_time": sim_time, "score": 0.0}
    return mf.SimStatus(**{**fields, "robots": {"lru1": robot}, **kw})


def test_a_merge_patch_carries_what_changed_and_rebuilds_the_rest():
    old = status(10.0).model_dump(mode="json")
    new = status(12.0, score=0.5, rss_found=["RSS-A"]).model_dump(mode="json")
    new["robots"]["lru1"]["x"] = 3.0
    del new["robots"]["lru1"]["activity"]
    patch = mf.merge_patch(old, new)
    assert patch == {
        "sim_time": 12.0,
        "score": 0.5,
        "rss_found": ["RSS-A"],
        "robots": {"lru1": {"x": 3.0, "activity": None}},
    }
    assert mf.apply_merge_patch(old, patch) == new
    assert mf.merge_patch(new, new) is None


def _update(seq: int, feed: str = "f1", **kw) -> bytes:
    return mf.dump(mf.StatusUpdate(feed=feed, seq=seq, **kw))


def test_a_mirror_applies_patches_in_order_and_asks_again_after_a_gap():
    m = mf.StatusMirror()
    assert not m.apply(_update(2, patch={"score": 1.0}))  # no status yet: query it
    assert m.apply(_update(1, full=status(1.0)))
    assert m.apply(_update(2, patch={"score": 1.0, "sim_time": 2.0}))
    assert m.status is not None and (m.status.score, m.status.seq) == (1.0, 2)
    assert m.status.robots["lru1"].x == 1.0  # untouched fields kept
    assert m.apply(_update(2, patch={"score": 9.0}))  # old news: ignored
    assert m.status.score == 1.0
    assert not m.apply(_update(4, patch={"score": 2.0}))  # seq 3 missed
    assert not m.apply(_update(3, feed="f2", patch={"score": 2.0}))  # the simulator restarted
    m.apply_full(status(3.0, feed="f1", seq=3))  # what the status query says
    assert m.apply(_update(4, patch={"score": 2.0}))
    assert m.status.score == 2.0


def test_a_plain_status_of_an_older_simulator_is_a_full_one():
    m = mf.StatusMirror()
    assert m.apply(mf.dump(status(5.0, speed=20.0)))
    assert m.status is not None and m.status.speed == 20.0


async def test_a_follower_queries_the_status_then_follows_the_patches():
    endpoint = loopback_endpoint(free_port())
    router = open_session(router_config([endpoint]))
    sim = open_session(client_config([endpoint]))
    console = open_session(client_config([endpoint]))
    current = status(1.0, feed="f1", seq=1)
    seen = asyncio.Event()
    feed = SimStatusFeed(console, lambda _st: seen.set())
    try:
        queryable = serve(sim, mf.KEY_STATUS, lambda _p: mf.dump(current))
        live = declare_publisher(sim, mf.KEY_STATUS_LIVE)
        await feed.start()
        assert feed.status is not None and feed.status.seq == 1
        seen.clear()
        live.put(_update(2, patch={"score": 0.5}))
        await asyncio.wait_for(seen.wait(), WAIT)
        assert feed.status.score == 0.5
        current = status(4.0, feed="f1", seq=4, score=1.5)  # seq 3 is lost on the way
        seen.clear()
        live.put(_update(4, patch={"sim_time": 4.0}))
        await asyncio.wait_for(seen.wait(), WAIT)  # a gap: queried again
        assert (feed.status.seq, feed.status.score, feed.queries) == (4, 1.5, 2)
        del queryable, live
    finally:
        feed.close()
        for s in (console, sim, router):
            close_session(s)
