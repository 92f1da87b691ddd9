"""A deterministic map feed for console tests: the Mars site's geometry with
a hand-made explored area, terrain, coverage and objects (no simulator)."""

from __future__ import annotations

import numpy as np

from backend.client.mapfollow import MapUpdate
from backend.protocol import mapfeed as mf


def mars_snapshot(size: int = 160, cell: float = 2.0, seq: int = 3) -> mf.MapSnapshot:
    """A size x size grid centred on the lander: explored around it and over
    the east plain, a rock field, a sand patch, coverage near the lander."""
    x0 = y0 = -size * cell / 2
    meta = mf.MapMeta(world="test site", seed=1, x0=x0, y0=y0, cell=cell, width=size, height=size)
    ys, xs = np.mgrid[0:size, 0:size]
    x = x0 + (xs + 0.5) * cell
    y = y0 + (ys + 0.5) * cell
    terrain = np.full((size, size), mf.T_FREE, dtype=np.uint8)
    terrain[(x - 60) ** 2 + (y + 30) ** 2 < 12**2] = mf.T_SLOW
    terrain[(x + 20) ** 2 + (y - 20) ** 2 < 7**2] = mf.T_ROCK
    terrain[(y > 33) & (y < 40) & (x < -8) & (x > -110)] = mf.T_ROCK
    explored = (x**2 + y**2 < 55**2) | ((x > 30) & (x < 80) & (y > 0) & (y < 40))
    terrain = np.where(explored, terrain, mf.T_UNKNOWN).astype(np.uint8)
    coverage = np.where(x**2 + y**2 < 60**2, 200, 0).astype(np.uint8)
    enc = mf.TileEncoder(meta)
    enc.delta({"terrain": terrain, "coverage": coverage})
    objects = mf.MapObjects(
        lander=mf.LanderItem(x=0, y=0, pad_radius=5, comm_radius=60),
        boxes=[
            mf.BoxItem(box="sample_box", kind="sample", where="shelf", slot=1, x=0, y=0),
            mf.BoxItem(box="wifi_box_1", kind="wifi", where="ground", x=25, y=-12, on=True),
        ],
        rss=[mf.RssItem(rss="RSS-A", x=45, y=21, radius=7, top_score=1.0)],
        stones=[
            mf.StoneItem(id="RSS-A-s1", rss="RSS-A", x=47, y=23, score=1.0, state="identified")
        ],
    )
    return mf.MapSnapshot(
        feed="test", meta=meta, seq=seq, sim_time=120.0, tiles=enc.full(), objects=objects
    )


def mirror_of(snap: mf.MapSnapshot) -> mf.MapMirror:
    m = mf.MapMirror()
    m.apply_snapshot(snap)
    return m


def map_message(snap: mf.MapSnapshot | None = None):
    from console_state import map_fed

    snap = snap or mars_snapshot()
    return map_fed(mirror_of(snap), MapUpdate("snapshot", objects=True))
