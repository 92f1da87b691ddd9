"""Map feed of a site: wire models, keys, tile codec and a mirror.

The simulator (sim.fleet) publishes it; consoles follow it through
`backend.client.mapfollow.MapFeed`. Kept free of transport code (pydantic + numpy
only) so any process can use the models and the codec. numpy is imported only by
the functions that make or read a grid: the models alone (a console's first frame,
a plan's inputs) do without its ~0.1 s import.

Key space (all JSON from the models below):

    mc/v2/sim/map/snapshot   queryable  -> MapSnapshot (late joiners)
    mc/v2/sim/map/delta      publication: MapDelta, seq consecutive, at most ~2 Hz
    mc/v2/sim/status         queryable  -> SimStatus (score, deliveries, regions, robots)
    mc/v2/sim/status/live    publication: StatusUpdate, seq consecutive: the full status
                             or what changed (a merge patch), on change, at least every 10 s

(under the protocol's prefix, `backend.protocol.keys.PREFIX`)

Two views of the world. Everything above is the *ground view*: what the robots
reported over the link (regions discovered, top scores revealed, stones
identified and delivered, the score, robots as last heard); a robot out of
coverage keeps its news until it is back in range. The truth (every region and
stone, where each robot really is, the referee's log) is only in
`SimStatus.truth`, filled when the status query's payload is `{"truth": true}`
(`missionctl sim-status --truth`, for evaluation); never in a publication.

A console's score and clock line: `objects.score` (map feed) or `SimStatus.score`,
`sim_time` of the latest delta, snapshot or status, and `speed` (sim seconds per
wall second: the clock moves on between messages).

Grids are cut into `tile` x `tile` cells; a tile is sent as base64(zlib(raw
uint8 bytes, row-major)) and only when it changed. Rows go south to north
(row 0 at `y0`), columns west to east (column 0 at `x0`). Layers:

- `terrain`: 0 unknown (not explored yet), 1 free, 2 slow (sand), 3 impassable;
- `coverage`: 0 no link, 1..255 link quality.

Robot poses are not in the feed: they ride on the robots' telemetry.

A late joiner subscribes to the deltas first, then queries the snapshot, and
applies deltas whose seq follows the snapshot's (`MapMirror` does this; a gap,
or a delta of another `feed` run, means: query the snapshot again).

The live status follows the same rule (`StatusMirror`): the status query's
`SimStatus` says which publication it is as of (`feed`, `seq`); each
`StatusUpdate` carries the full status (the first, and one a minute) or a
JSON merge patch (RFC 7386) of what changed since the previous one: a few
fields instead of the whole status, for a narrow link. A plain `SimStatus`
on the live key (an older simulator) is taken as a full one.
"""

from __future__ import annotations

import base64
import json
import zlib
from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

if TYPE_CHECKING:
    import numpy as np

FEED_VERSION = 1
# under the protocol's prefix (backend.protocol.keys.PREFIX; spelled out to
# keep this module self-contained, tests/server/test_protocol_doc.py checks it)
PREFIX = "mc/v2/sim"
KEY_MAP_SNAPSHOT = f"{PREFIX}/map/snapshot"
KEY_MAP_DELTA = f"{PREFIX}/map/delta"
KEY_STATUS = f"{PREFIX}/status"
KEY_STATUS_LIVE = f"{PREFIX}/status/live"
TRUTH_QUERY = b'{"truth": true}'  # the status query's payload that asks for the truth too

LAYERS = ("terrain", "coverage")
T_UNKNOWN, T_FREE, T_SLOW, T_ROCK = 0, 1, 2, 3


class _Wire(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


# ---------------------------------------------------------------- map


class MapMeta(_Wire):
    version: int = FEED_VERSION
    world: str
    seed: int
    x0: float = Field(description="west edge of column 0, metres")
    y0: float = Field(description="south edge of row 0, metres")
    cell: float = Field(description="cell size, metres")
    width: int = Field(description="columns")
    height: int = Field(description="rows")
    tile: int = 16
    layers: list[str] = Field(default_factory=lambda: list(LAYERS))


class Tile(_Wire):
    layer: Literal["terrain", "coverage"]
    tx: int = Field(ge=0, description="tile column")
    ty: int = Field(ge=0, description="tile row")
    data: str = Field(description="base64(zlib(uint8 cells, row-major))")


class LanderItem(_Wire):
    x: float
    y: float
    pad_radius: float
    comm_radius: float


class BoxItem(_Wire):
    box: str
    kind: str
    where: Literal["shelf", "storage", "ground", "carried"]
    slot: int | None = None
    x: float
    y: float
    holder: str | None = None
    on: bool = False


class RssItem(_Wire):
    rss: str
    x: float
    y: float
    radius: float
    top_score: float | None = Field(
        None, description="known once LRU1 imaged it with its science camera"
    )


class StoneItem(_Wire):
    id: str
    rss: str
    x: float
    y: float
    score: float | None = None
    state: Literal["identified", "carried", "ground", "delivered"]
    holder: str | None = None


class MapObjects(_Wire):
    lander: LanderItem
    boxes: list[BoxItem] = Field(default_factory=list)
    rss: list[RssItem] = Field(
        default_factory=list, description="discovered regions (as reported to the ground)"
    )
    stones: list[StoneItem] = Field(default_factory=list, description="identified stones")
    score: float = Field(
        0.0, description="the score as reported: the sum of the delivered stones' scores"
    )


class MapDelta(_Wire):
    feed: str = Field(
        "",
        description="id of this run of the feed; another id means the publisher restarted: "
        "fetch the snapshot",
    )
    seq: int = Field(ge=1, description="consecutive; a gap means: fetch the snapshot")
    sim_time: float = Field(description="sim seconds since the simulator started")
    speed: float = Field(1.0, description="sim seconds per wall second")
    tiles: list[Tile] = Field(default_factory=list)
    objects: MapObjects | None = Field(None, description="all objects, when any changed")


class MapSnapshot(_Wire):
    feed: str = Field("", description="id of this run of the feed (as in its deltas)")
    meta: MapMeta
    seq: int = Field(ge=0, description="the last delta included")
    sim_time: float = Field(description="sim seconds since the simulator started")
    speed: float = Field(1.0, description="sim seconds per wall second")
    tiles: list[Tile] = Field(description="every tile of every layer")
    objects: MapObjects


# ---------------------------------------------------------------- status


class RobotStatus(_Wire):
    """A robot as last heard (ground view), or as it is (in `SimTruth`)."""

    name: str
    type: str
    kind: Literal["rover", "drone", "static"]
    x: float
    y: float
    z: float = 0.0
    yaw: float = 0.0
    battery: float
    in_range: bool = Field(description="the ground hears it now")
    link: float = Field(description="link quality where it was (0: no link)")
    heard_at: float | None = Field(
        None, description="sim time of the state shown (ground view: its last report)"
    )
    airborne: bool = False
    docked: bool = False
    box: str | None = None
    stones: list[str] = Field(default_factory=list)
    activity: str | None = None
    result: str = Field(
        "", description="outcome of its last skill, e.g. 'identified RSS-A-s1 ..., score 1'"
    )
    odometer_m: float = 0.0
    sim_seconds: float = Field(0.0, description="robot time stepped by its skills")
    knows: dict[str, int] = Field(
        default_factory=dict, description="rss/stones/boxes in its own world model (truth only)"
    )


class Delivery(_Wire):
    stone: str
    rss: str
    score: float
    by: str
    sim_time: float


class RegionTruth(_Wire):
    rss: str
    x: float
    y: float
    radius: float
    max_score: float
    stones: int = Field(description="stones in the region not identified yet")
    found_by: list[str] = Field(default_factory=list)


class StoneTruth(_Wire):
    id: str
    rss: str
    x: float
    y: float
    score: float | None = None
    state: Literal["hidden", "identified", "carried", "ground", "delivered"]
    holder: str | None = None


class SimTruth(_Wire):
    """The world as it is, for evaluation (`missionctl sim-status --truth`)."""

    score: float
    delivered: list[Delivery] = Field(default_factory=list)
    regions: list[RegionTruth] = Field(default_factory=list)
    stones: list[StoneTruth] = Field(default_factory=list, description="every stone")
    explored: float = Field(0.0, description="fraction of the site explored by any robot")
    robots: dict[str, RobotStatus] = Field(default_factory=dict)
    exchanges: dict[str, int] = Field(default_factory=dict, description="robot-to-robot asks/tells")
    exchange_log: list[str] = Field(default_factory=list, description="the latest exchanges")
    events: list[str] = Field(default_factory=list, description="the referee's latest log lines")


class CommsWindowSpec(_Wire):
    """The ground link's contact: `open_s` at the start of every `period_s`,
    from `offset_s` on (sim seconds since the simulator started)."""

    open_s: float = Field(gt=0)
    period_s: float = Field(gt=0)
    offset_s: float = 0.0


class SimStatus(_Wire):
    """The ground view (what robots reported), plus the truth when asked for it."""

    version: int = FEED_VERSION
    world: str
    seed: int
    speed: float = Field(description="sim seconds per wall second")
    link_delay_s: float = Field(0.0, description="one-way ground link delay, sim seconds")
    comms_window: CommsWindowSpec | None = Field(
        None, description="when the ground can reach the robots (None: always)"
    )
    sim_time: float = Field(description="sim seconds since the simulator started")
    score: float = Field(description="the delivered stones' scores, as reported")
    delivered: list[Delivery] = Field(default_factory=list, description="as reported")
    rss_found: list[str] = Field(
        default_factory=list, description="regions the robots reported discovering"
    )
    top_scores: dict[str, float] = Field(
        default_factory=dict, description="region -> top stone score a science image revealed"
    )
    explored: float = Field(0.0, description="fraction of the site explored, as reported")
    robots: dict[str, RobotStatus] = Field(
        default_factory=dict, description="robots as last heard (a robot never heard is absent)"
    )
    truth: SimTruth | None = Field(
        None, description='only in a reply to the payload {"truth": true}'
    )
    feed: str = Field("", description="the live publication's run (as in `StatusUpdate`)")
    seq: int = Field(0, ge=0, description="the last live publication this status includes")


class StatusUpdate(_Wire):
    """The live status publication: the full status, or what changed since
    the previous publication as a JSON merge patch (RFC 7386) of `SimStatus`."""

    feed: str = Field(description="id of this run of the publisher; another id: query the status")
    seq: int = Field(ge=1, description="consecutive; a gap means: query the status")
    full: SimStatus | None = Field(None, description="the whole status (no patch)")
    patch: dict[str, Any] | None = Field(
        None, description="what changed: new values; null removes; objects merge, lists replace"
    )


def merge_patch(old: Any, new: Any) -> Any:
    """The JSON merge patch (RFC 7386) that turns `old` into `new` (None: no change)."""
    if not isinstance(old, dict) or not isinstance(new, dict):
        return None if old == new else new
    patch: dict[str, Any] = {}
    for key, value in new.items():
        if key not in old:
            patch[key] = value
        elif old[key] != value:
            patch[key] = merge_patch(old[key], value) if isinstance(value, dict) else value
    for key in old.keys() - new.keys():
        patch[key] = None
    return patch or None


def apply_merge_patch(target: Any, patch: Any) -> Any:
    if not isinstance(patch, dict):
        return patch
    out = dict(target) if isinstance(target, dict) else {}
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        else:
            out[key] = apply_merge_patch(out.get(key), value)
    return out


class StatusMirror:
    """Receiver side of the live status (a console): full statuses and patches.

    mirror = StatusMirror()
    mirror.apply_full(SimStatus.model_validate_json(queried))
    ok = mirror.apply(payload_of_a_publication)  # False: gap or restart, query again
    mirror.status                                 # SimStatus | None
    """

    def __init__(self) -> None:
        self.status: SimStatus | None = None
        self._raw: dict[str, Any] | None = None

    def apply_full(self, status: SimStatus) -> None:
        if self.status is not None and status.feed == self.status.feed:
            if status.seq < self.status.seq:
                return  # older than what the publications brought
        self.status = status
        self._raw = status.model_dump(mode="json")

    def apply(self, payload: bytes | str) -> bool:
        """Apply one publication; False when one was missed or the publisher
        restarted (query the status, then `apply_full`). Raises ValueError
        on what is not a status."""
        raw = json.loads(payload)
        if isinstance(raw, dict) and "world" in raw:  # a plain SimStatus: an older simulator
            self.apply_full(SimStatus.model_validate(raw))
            return True
        update = StatusUpdate.model_validate(raw)
        if update.full is not None:
            self.apply_full(update.full.model_copy(update={"feed": update.feed, "seq": update.seq}))
            return True
        current = self.status
        if current is None or self._raw is None or update.feed != current.feed:
            return False
        if update.seq <= current.seq:
            return True  # already in the status
        if update.seq != current.seq + 1:
            return False
        merged = apply_merge_patch(self._raw, update.patch or {})
        merged.update(feed=update.feed, seq=update.seq)
        self.status = SimStatus.model_validate(merged)
        self._raw = merged
        return True


# ---------------------------------------------------------------- tiles


def encode_tile(cells: np.ndarray) -> str:
    import numpy as np

    return base64.b64encode(
        zlib.compress(np.ascontiguousarray(cells, dtype=np.uint8).tobytes(), 6)
    ).decode("ascii")


def decode_tile(data: str, shape: tuple[int, int]) -> np.ndarray:
    import numpy as np

    raw = zlib.decompress(base64.b64decode(data))
    if len(raw) != shape[0] * shape[1]:
        raise ValueError(f"tile holds {len(raw)} cells, expected {shape[0]}x{shape[1]}")
    return np.frombuffer(raw, dtype=np.uint8).reshape(shape).copy()


def tile_shape(meta: MapMeta, tx: int, ty: int) -> tuple[int, int]:
    """Edge tiles are smaller when the grid is not a multiple of the tile size."""
    return min(meta.tile, meta.height - ty * meta.tile), min(meta.tile, meta.width - tx * meta.tile)


def changed_tiles(old: np.ndarray | None, new: np.ndarray, tile: int) -> list[tuple[int, int]]:
    """(tx, ty) of the tiles where `new` differs from `old` (all when old is None)."""
    import numpy as np

    h, w = new.shape
    nty, ntx = -(-h // tile), -(-w // tile)
    if old is None:
        return [(tx, ty) for ty in range(nty) for tx in range(ntx)]
    diff = old != new
    ph, pw = nty * tile - h, ntx * tile - w
    if ph or pw:
        diff = np.pad(diff, ((0, ph), (0, pw)))
    per_tile = diff.reshape(nty, tile, ntx, tile).any(axis=(1, 3))
    ty, tx = np.nonzero(per_tile)
    return [(int(a), int(b)) for a, b in zip(tx, ty, strict=True)]


def _tile(layer: str, tx: int, ty: int, cells: np.ndarray) -> Tile:
    # the meta's layer names are plain strings on the wire: checked here, at run time
    return Tile.model_validate({"layer": layer, "tx": tx, "ty": ty, "data": encode_tile(cells)})


class TileEncoder:
    """Sender side: remembers what was sent, encodes only the changed tiles."""

    def __init__(self, meta: MapMeta):
        self.meta = meta
        self.sent: dict[str, np.ndarray] = {}

    def delta(self, layers: dict[str, np.ndarray]) -> list[Tile]:
        out: list[Tile] = []
        t = self.meta.tile
        for name in self.meta.layers:
            grid = layers[name]
            for tx, ty in changed_tiles(self.sent.get(name), grid, t):
                cells = grid[ty * t : (ty + 1) * t, tx * t : (tx + 1) * t]
                out.append(_tile(name, tx, ty, cells))
            self.sent[name] = grid.copy()
        return out

    def full(self) -> list[Tile]:
        """Every tile of what was sent so far (for snapshots)."""
        import numpy as np

        out: list[Tile] = []
        t = self.meta.tile
        for name in self.meta.layers:
            grid = self.sent.get(name)
            if grid is None:
                grid = np.zeros((self.meta.height, self.meta.width), dtype=np.uint8)
            for tx, ty in changed_tiles(None, grid, t):
                cells = grid[ty * t : (ty + 1) * t, tx * t : (tx + 1) * t]
                out.append(_tile(name, tx, ty, cells))
        return out


class MapMirror:
    """Receiver side (a console): the map from a snapshot plus deltas.

    mirror = MapMirror()
    mirror.apply_snapshot(MapSnapshot.model_validate_json(raw))
    ok = mirror.apply_delta(MapDelta.model_validate_json(raw))  # False: gap, re-query the snapshot
    terrain = mirror.layers["terrain"]  # numpy uint8 (rows south->north)
    """

    def __init__(self) -> None:
        self.meta: MapMeta | None = None
        self.feed = ""
        self.seq = -1
        self.sim_time = 0.0
        self.speed = 1.0  # sim seconds per wall second, as the feed last said
        self.layers: dict[str, np.ndarray] = {}
        self.objects: MapObjects | None = None
        self._early: list[MapDelta] = []  # deltas received before the snapshot

    @property
    def ready(self) -> bool:
        return self.meta is not None

    def _apply_tiles(self, tiles: list[Tile]) -> None:
        assert self.meta is not None
        t = self.meta.tile
        for tile in tiles:
            grid = self.layers.get(tile.layer)
            if grid is None:
                continue
            shape = tile_shape(self.meta, tile.tx, tile.ty)
            if shape[0] <= 0 or shape[1] <= 0:
                raise ValueError(
                    f"tile ({tile.tx}, {tile.ty}) lies outside the "
                    f"{self.meta.width}x{self.meta.height} grid"
                )
            grid[tile.ty * t : tile.ty * t + shape[0], tile.tx * t : tile.tx * t + shape[1]] = (
                decode_tile(tile.data, shape)
            )

    def apply_snapshot(self, snap: MapSnapshot) -> None:
        import numpy as np

        self.meta = snap.meta
        self.feed = snap.feed
        self.layers = {
            n: np.zeros((snap.meta.height, snap.meta.width), dtype=np.uint8)
            for n in snap.meta.layers
        }
        self._apply_tiles(snap.tiles)
        self.seq = snap.seq
        self.sim_time = snap.sim_time
        self.speed = snap.speed
        self.objects = snap.objects
        early, self._early = self._early, []
        for d in sorted(early, key=lambda d: d.seq):
            if d.seq > self.seq and d.feed == self.feed:
                self.apply_delta(d)

    def apply_delta(self, delta: MapDelta) -> bool:
        """Apply a delta; False when one was missed or the publisher restarted
        (query the snapshot again)."""
        if self.meta is None:
            self._early.append(delta)
            return True
        if delta.feed != self.feed:
            return False
        if delta.seq <= self.seq:
            return True  # already in the snapshot
        if delta.seq != self.seq + 1:
            return False
        self._apply_tiles(delta.tiles)
        self.seq = delta.seq
        self.sim_time = delta.sim_time
        self.speed = delta.speed
        if delta.objects is not None:
            self.objects = delta.objects
        return True

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """(row, col) of a site position, or None outside the map."""
        if self.meta is None:
            return None
        j = int((x - self.meta.x0) // self.meta.cell)
        i = int((y - self.meta.y0) // self.meta.cell)
        if 0 <= i < self.meta.height and 0 <= j < self.meta.width:
            return i, j
        return None


def dump(model: _Wire) -> bytes:
    return model.model_dump_json().encode()


def parse(kind: type[_Wire], payload: bytes | str) -> Any:
    return kind.model_validate_json(payload)
