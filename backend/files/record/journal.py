"""A mission journal, read-only: the mission at any instant of either clock.

The server's journal (backend/server/journal.py writes it) holds a snapshot
of the whole mission every few hundred batches and every batch of events
in between. `JournalReader` opens it read-only and keeps a small index (each
batch's journal time; its robot time, built when first asked), so the state
after any number of batches in either clock's order (`order.Order`) is one
snapshot read and at most a snapshot's spacing of batches applied through
`backend.core.events.apply_events`, the one path every mirror uses.

In robot time batches are applied in another order than the journal's. A
batch that would not apply there (a robot's clock so far behind that its
report comes before the command it answers) is held back until what it
needs was applied, and left out if that never comes (`State.unplaced`).

The index starts at the oldest snapshot kept: a journal written by a server
that kept only its last snapshots cannot show what came before them
(`JournalReader.gap` says so).
"""

from __future__ import annotations

import itertools
import json
import sqlite3
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple

from pydantic import ValidationError

from backend.core import events as ev
from backend.core.bulk import gc_paused
from backend.core.clocks import CLOCKS, GROUND, ROBOT, ROBOT_TIMED, Order, robot_keys
from backend.core.model import Mission
from backend.core.records import RecordError, open_read_only, tables

# the journal formats this reader knows (backend/server/journal_file.py writes them)
READABLE_FORMATS = frozenset({"missionctl/journal@1"})


# the index of a journal by time: (revision, journal time, operation, robot time, robot)
IndexRow = tuple[int, float, str, float | None, str | None]


class Batch(NamedTuple):
    """One journaled batch, as read back."""

    revision: int
    ts: float  # journal time (the ground's clock), seconds since the epoch
    actor: str  # 'user@client', a client id, or the robot for its reports
    client: str
    op: dict[str, Any]  # the operation as journaled (its JSON; {"op": name} when not kept)
    batch: ev.EventBatch

    @property
    def name(self) -> str:
        return str(self.op.get("op", "")) or "change"

    def batch_time(self) -> datetime:
        return datetime.fromtimestamp(self.ts, UTC)


@dataclass
class State:
    """The mission after the first `position` batches of a clock's order."""

    clock: str
    position: int
    mission: Mission
    revision: int  # the last batch applied (journal order) or the snapshot's
    unplaced: list[int] = field(default_factory=list)  # revisions left out (robot time)
    # the last batches taken, as a console watching would have taken them (oldest
    # first): (the batch, the batch index whose time it was taken at — its own, or
    # in robot time that of the batch that let it apply)
    recent: list[tuple[ev.EventBatch, int]] = field(default_factory=list)


def op_of(text: str) -> dict[str, Any]:
    """A journaled operation's JSON as a dict ({"op": text} when it is only a name)."""
    if text.startswith("{"):
        try:
            op = json.loads(text)
        except ValueError:
            return {"op": "unreadable"}
        return op if isinstance(op, dict) else {"op": "unreadable"}
    return {"op": text}


def _spans(raw: dict[str, Any]) -> dict[str, tuple[float, float]]:
    """A sync's forecast ({skill: {"start", "end"}}, ISO times) as seconds."""
    out: dict[str, tuple[float, float]] = {}
    for sid, p in raw.items():
        start = _seconds(p.get("start")) if isinstance(p, dict) else None
        end = _seconds(p.get("end")) if isinstance(p, dict) else None
        if start is not None and end is not None:
            out[str(sid)] = (start, end)
    return out


def _seconds(text: Any) -> float | None:
    if not isinstance(text, str):
        return None
    try:
        return datetime.fromisoformat(text).timestamp()
    except ValueError:
        return None


class JournalReader:
    """A journal opened read-only. Batch index i is revision `base + 1 + i`."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._conn = open_read_only(self.path, "journal")
        try:
            self._read_header()
        except sqlite3.Error as e:
            self.close()
            raise RecordError(f"{self.path}: cannot read the journal: {e}") from None
        except RecordError:
            self.close()
            raise
        self._orders: dict[str, Order] = {}
        self._syncs: list[tuple[int, dict[str, tuple[float, float]]]] | None = None

    def _read_header(self) -> None:
        conn = self._conn
        if not {"meta", "batches", "snapshots"} <= tables(conn):
            raise RecordError(f"{self.path}: not a missionctl journal (no batches or snapshots)")
        self.meta: dict[str, str] = dict(conn.execute("SELECT key, value FROM meta").fetchall())
        fmt = self.meta.get("format")
        if fmt not in READABLE_FORMATS:
            raise RecordError(
                f"{self.path}: journal format {fmt!r} is not one this version reads "
                f"({', '.join(sorted(READABLE_FORMATS))})"
            )
        rows = conn.execute("SELECT revision FROM snapshots ORDER BY revision")
        snaps = [int(r) for (r,) in rows]
        if not snaps:
            raise RecordError(f"{self.path}: the journal has no snapshot: nothing to replay from")
        self.base = snaps[0]
        self.snapshot_revisions = snaps
        first, last = conn.execute("SELECT min(revision), max(revision) FROM batches").fetchone()
        # batches before the oldest snapshot cannot be replayed: it is where replay starts
        self.gap = first is not None and first <= self.base
        self.last: int = max(self.base, int(last or self.base))
        self._given: list[IndexRow] = []
        self._index: tuple[list[float], list[float | None], list[str]] | None = None
        self._names: list[str] = []  # each batch's operation

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> JournalReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- what it holds ---------------------------------------------------------------------
    @property
    def library(self) -> str:
        """The skill library file the server recorded (as it named it)."""
        return self.meta.get("library", "")

    def __len__(self) -> int:
        return self.last - self.base

    def use_index(self, rows: list[IndexRow]) -> None:
        """The server's index of this journal by time (the telemetry
        archive's, backend/protocol/archive.py): what it covers is not read
        from the journal."""
        self._given = rows

    def _times(self) -> tuple[list[float], list[float | None], list[str]]:
        """Per batch: its journal time (never going back: a wall clock that
        stepped back), its robot time (None: the ground's), its actor."""
        if self._index is None:
            rows = self._index_rows()
            ground = list(itertools.accumulate((r[1] for r in rows), max))
            self._index = (ground, [r[3] for r in rows], [r[4] or "" for r in rows])
            self._names = [r[2] for r in rows]
        return self._index

    def _index_rows(self) -> list[IndexRow]:
        """The index's rows: the given index's while it covers the batches,
        then the journal's own; RecordError if a batch is missing."""
        rows = self._covered()
        rows += self._scan(rows[-1][0] if rows else self.base)
        self._check_complete([r[0] for r in rows])
        return rows

    def _check_complete(self, revisions: list[int]) -> None:
        """RecordError naming the first batch missing from `revisions`."""
        expected = range(self.base + 1, self.last + 1)
        if revisions == list(expected):
            return
        missing = next(
            (e for e, r in zip(expected, revisions, strict=False) if e != r),
            self.base + 1 + len(revisions),
        )
        raise RecordError(
            f"{self.path}: batch {missing} is missing; `missionctl server` on this "
            "journal says how to recover it"
        )

    def _covered(self) -> list[IndexRow]:
        """The given index's rows from the first batch on, while consecutive."""
        rows = [r for r in self._given if self.base < r[0] <= self.last]
        for k, r in enumerate(rows):
            if r[0] != self.base + 1 + k:
                return rows[:k]
        return rows

    def _scan(self, after: int) -> list[IndexRow]:
        """The index of the batches after `after`, read from the journal itself."""
        rows = self._conn.execute(
            "SELECT revision, ts, actor, json_extract(op, '$.op'), json_extract(op, '$.at') "
            "FROM batches WHERE revision > ? ORDER BY revision",
            (after,),
        )
        out: list[IndexRow] = []
        for rev, ts, actor, name, at in rows:
            robot_at = _seconds(at) if name in ROBOT_TIMED else None
            out.append((rev, ts, name or "", robot_at, actor if robot_at is not None else None))
        return out

    @property
    def ground(self) -> list[float]:
        return self._times()[0]

    def start_time(self) -> float | None:
        """When the journal starts: its first batch (None: no batch yet)."""
        ground = self.ground
        return ground[0] if ground else None

    def end_time(self) -> float | None:
        ground = self.ground
        return ground[-1] if ground else None

    def order(self, clock: str) -> Order:
        """The batches in `clock`'s order (each built when first asked)."""
        if clock not in CLOCKS:
            raise ValueError(f"no clock {clock!r}: {' or '.join(CLOCKS)}")
        found = self._orders.get(clock)
        if found is None:
            ground, robot, actors = self._times()
            keys = ground if clock == GROUND else robot_keys(ground, robot, actors)
            found = self._orders[clock] = Order(keys)
        return found

    def syncs(self) -> list[tuple[int, dict[str, tuple[float, float]]]]:
        """(batch index, the forecast it was sent with: skill -> (start, end))
        of every sync that carried one, in journal order (read once)."""
        if self._syncs is None:
            self._times()
            revisions = [self.base + 1 + i for i, n in enumerate(self._names) if n == "sync"]
            found: list[tuple[int, dict[str, tuple[float, float]]]] = []
            for rev, text in self._ops(revisions):
                forecast = op_of(text).get("forecast")
                if isinstance(forecast, dict) and forecast:
                    found.append((rev - self.base - 1, _spans(forecast)))
            found.sort()
            self._syncs = found
        return self._syncs

    def _ops(self, revisions: list[int]) -> Iterator[tuple[int, str]]:
        """(revision, operation JSON) of these batches, in no given order."""
        for k in range(0, len(revisions), 500):  # SQLite's limit on parameters
            part = revisions[k : k + 500]
            marks = ", ".join("?" * len(part))
            yield from self._conn.execute(
                f"SELECT revision, op FROM batches WHERE revision IN ({marks})", part
            )

    # -- batches ---------------------------------------------------------------------------
    def batches(self, first: int, last: int) -> Iterator[Batch]:
        """Batches with revisions first..last, in journal order."""
        rows = self._conn.execute(
            "SELECT revision, ts, actor, client, op, events FROM batches "
            "WHERE revision BETWEEN ? AND ? ORDER BY revision",
            (first, last),
        )
        for rev, ts, actor, client, op, events in rows:
            yield self._batch(rev, ts, actor, client, op, events)

    def _batch(self, rev: int, ts: float, actor: str, client: str, op: str, events: str) -> Batch:
        parsed = op_of(op)
        batch = self._events(rev, events, str(parsed.get("op", "")), actor)
        return Batch(rev, ts, actor, client, parsed, batch)

    def newest(self, since: float | None = None) -> Iterator[tuple[Any, ...]]:
        """Every journaled batch (before the oldest snapshot too), newest
        first, as raw rows for `read` (an audit reads the actor before it
        parses anything)."""
        cur = self._conn.execute(
            "SELECT revision, ts, actor, client, op, events FROM batches WHERE ts >= ? "
            "ORDER BY revision DESC",
            (since if since is not None else float("-inf"),),
        )
        while rows := cur.fetchmany(1000):
            yield from rows

    def read(self, row: tuple[Any, ...]) -> Batch:
        """A raw row of `newest` as a Batch."""
        return self._batch(*row)

    def events(self, indices: Iterable[int]) -> dict[int, ev.EventBatch]:
        """The event batches at these indices (one read of their span), named
        from the index: without the operations' JSON, which a replay does not
        read (a sync's holds its forecast: a third of a batch's reading)."""
        wanted = sorted(set(indices))
        if not wanted:
            return {}
        self._times()  # each batch's operation, named
        names = self._names
        lo, hi = self.base + 1 + wanted[0], self.base + 1 + wanted[-1]
        keep = {self.base + 1 + i for i in wanted}
        rows = self._conn.execute(
            "SELECT revision, actor, events FROM batches WHERE revision BETWEEN ? AND ?",
            (lo, hi),
        )
        out: dict[int, ev.EventBatch] = {}
        for rev, actor, events in rows:
            if rev in keep:
                i = rev - self.base - 1
                out[i] = self._events(rev, events, names[i], actor)
        return out

    def _events(self, rev: int, events: str, name: str, actor: str) -> ev.EventBatch:
        try:
            batch = ev.EventBatch.model_validate_json(events)
        except ValidationError as e:
            raise RecordError(
                f"{self.path}: batch {rev} cannot be read ({e.errors()[0]['msg']}); "
                "`missionctl server` on this journal says how to recover it"
            ) from None
        batch.op, batch.actor = name, actor
        return batch

    def pick(self, indices: Iterable[int]) -> dict[int, Batch]:
        """The batches at these indices (one read of their span)."""
        wanted = sorted(set(indices))
        if not wanted:
            return {}
        lo, hi = self.base + 1 + wanted[0], self.base + 1 + wanted[-1]
        keep = {self.base + 1 + i for i in wanted}
        return {b.revision - self.base - 1: b for b in self.batches(lo, hi) if b.revision in keep}

    def snapshot(self, revision: int) -> Mission:
        (text,) = self._conn.execute(
            "SELECT mission FROM snapshots WHERE revision = ?", (revision,)
        ).fetchone()
        try:
            return Mission.model_validate_json(text)
        except ValidationError as e:
            raise RecordError(
                f"{self.path}: the snapshot at revision {revision} cannot be read "
                f"({e.errors()[0]['msg']})"
            ) from None

    # -- the state at a position -----------------------------------------------------------
    def state(self, position: int, clock: str = GROUND, window: int = 0) -> State:
        """The mission after the first `position` batches in `clock`'s order;
        with `window`, the batches among the last `window` positions as taken
        (`State.recent`: a review's log shows them)."""
        order = self.order(clock)
        position = max(0, min(position, len(order)))
        snaps = [r - self.base - 1 for r in self.snapshot_revisions]
        plan = order.plan(position, snaps)
        with gc_paused():
            mission = self.snapshot(self.base + 1 + plan.snapshot)
            batches = self.events(plan.apply)
            listed = [batches[i] for i in plan.apply]
            unplaced: list[int] = []
            mission, taken = _apply(clock, mission, listed, unplaced)
            taken = [(b, by - self.base - 1) for b, by in taken]  # revisions -> indices
            recent = self._recent(order, position - window, position, plan.snapshot, taken)
        last = max([self.base + 1 + plan.snapshot, *(b.revision for b in batches.values())])
        return State(clock, position, mission, last, unplaced, recent)

    def _recent(
        self,
        order: Order,
        start: int,
        position: int,
        snapshot: int,
        taken: list[tuple[ev.EventBatch, int]],
    ) -> list[tuple[ev.EventBatch, int]]:
        """The batches taken at positions start..position-1: those the
        snapshot holds (at their own time), then those applied after it."""
        held = [i for i in order.order[max(0, start) : position] if i <= snapshot]
        picked = self.events(held)
        pos = order.pos
        return [(picked[i], i) for i in held] + [(b, by) for b, by in taken if pos[by] >= start]

    def state_at(self, t: float, clock: str = GROUND) -> State:
        """The mission as it was at time `t` of `clock`."""
        return self.state(self.order(clock).position_at(t), clock)

    def time_of(self, position: int, clock: str = GROUND) -> float | None:
        return self.order(clock).time_of(position)

    def revision_of(self, index: int) -> int:
        return self.base + 1 + index


# -- robot time: applying out of journal order ---------------------------------------------


def _apply(
    clock: str, mission: Mission, batches: list[ev.EventBatch], unplaced: list[int]
) -> tuple[Mission, list[tuple[ev.EventBatch, int]]]:
    """`batches` applied to `mission` in `clock`'s order, and each batch taken
    with the revision it was taken at (`apply_in_order` in robot time)."""
    taken: list[tuple[ev.EventBatch, int]] = []
    if clock == ROBOT:
        return apply_in_order(mission, batches, unplaced, taken), taken
    for b in batches:
        mission = ev.apply_events(mission, b)
    return mission, [(b, b.revision) for b in batches]


def missing(mission: Mission, batch: ev.EventBatch) -> str | None:
    """What `batch` refers to that `mission` lacks (None: it applies)."""
    brought: set[str | int] = set()  # what the batch adds: skill ids (text), command ids
    for e in batch.events:
        kind = type(e)
        if kind is ev.MissionReplaced:
            return None
        bring = _BRINGS.get(kind)
        if bring is not None:
            brought.add(bring(e))
        elif kind in _LACKS:
            lacks = _LACKS[kind](mission, e, brought)
            if lacks is not None:
                return lacks
    return None


def _skill_id(e: ev.SkillAdded) -> str | int:
    return e.skill.id


def _command_id(e: ev.CommandQueued) -> str | int:
    return e.command.id


def _lacks_skill(mission: Mission, e: Any, brought: set[str | int]) -> str | None:
    sid = e.id
    return f"skill {sid}" if sid not in brought and mission.find(sid) is None else None


def _lacks_command(mission: Mission, e: Any, brought: set[str | int]) -> str | None:
    cid = e.id
    return f"command {cid}" if cid not in brought and mission.command(cid) is None else None


# the events that add what later events refer to, and those that refer to it
_BRINGS: dict[type[Any], Callable[[Any], str | int]] = {
    ev.SkillAdded: _skill_id,
    ev.CommandQueued: _command_id,
}
_LACKS: dict[type[Any], Callable[[Mission, Any, set[str | int]], str | None]] = {
    ev.SkillRemoved: _lacks_skill,
    ev.SkillMoved: _lacks_skill,
    ev.SkillStatusChanged: _lacks_skill,
    ev.SkillEdited: _lacks_skill,
    ev.CommandChanged: _lacks_command,
}


def apply_in_order(
    mission: Mission,
    batches: list[ev.EventBatch],
    unplaced: list[int],
    taken: list[tuple[ev.EventBatch, int]] | None = None,
) -> Mission:
    """Apply `batches` in this order; one that does not apply yet waits until
    a later one made it apply, or is left out (its revision in `unplaced`).
    `taken` gets each batch applied, with the revision it was applied with."""
    waiting: list[ev.EventBatch] = []
    done = taken if taken is not None else []
    for b in batches:
        if missing(mission, b) is not None:
            waiting.append(b)
            continue
        mission = ev.apply_events(mission, b)
        done.append((b, b.revision))
        mission = _let_in(mission, waiting, b.revision, done)
    unplaced.extend(w.revision for w in waiting)
    return mission


def _let_in(
    mission: Mission,
    waiting: list[ev.EventBatch],
    by: int,
    done: list[tuple[ev.EventBatch, int]],
) -> Mission:
    """Apply what waits and applies now (batch `by` made it possible), until nothing does."""
    while ready := [w for w in waiting if missing(mission, w) is None]:
        for w in ready:
            waiting.remove(w)
            mission = ev.apply_events(mission, w)
            done.append((w, by))
    return mission
