"""The mission journal: every applied operation's events, plus snapshots, in SQLite.

The server appends one `EventBatch` per applied operation (operator edits and
robot acknowledgements and reports alike: they all go through
`Engine.submit`), with the operation itself as JSON, who sent it and its
request id. Every few hundred batches, once they add up to half the size of
the last snapshot, it stores a snapshot of the whole mission. Restarting,
`load()` takes the newest readable snapshot and replays the batches after it
through `events.apply_events` — the same, only mutation path the engine uses
— so the mission comes back exactly as it was after the last committed
operation, never half of one.

Invariants:
- batch revisions are consecutive (each is the previous one plus one); an
  append that breaks this is refused with `ValueError`;
- a journal starts with a snapshot (its base mission); batches are only
  accepted once there is one;
- one transaction per `append` (or per `append_many`): after a crash the
  journal holds a prefix of what was appended, at batch boundaries;
- what is journaled replays: a batch is serialized and read back to the same
  events before it is stored, else refused (`NotReplayable`); a journal that
  holds an unreplayable batch anyway (written by an older version) says
  which (`Unreplayable`), and `quarantine_from` keeps everything before it.

Tables (created by `journal_file`, which opens the file for its one writer):
  meta(key, value)                      format, library, created
  batches(revision PK, ts, actor, client, request_id, op, events, reply)
  snapshots(revision PK, mission)       the last `keep_snapshots` only (None: all, as
                                        the server keeps them: `missionctl review` seeks
                                        from the nearest; they add at most twice the
                                        batches' bytes, SNAPSHOT_BYTES)
  quarantine(id PK, at, reason, kind, revision, ts, actor, client,
             request_id, op, content, reply)   moved aside by a recovery
  index batches_request on batches(client, request_id)

Usage (a server):

    with Journal.open("mission.db", library="libraries/mars.yaml") as journal:
        mission, requests = journal.load()
        if mission is None:
            mission, library = load_mission(path)
            journal.snapshot(mission)
        engine = Engine(mission, library)
        remember_requests(engine, requests)
        ...
        applied = engine.submit(op, client=c, request_id=r)
        journal.record(applied, op, client=c, request_id=r, mission=engine.mission)
        journal.set_reply(applied.revision, applied.value, applied.notes)
"""

from __future__ import annotations

import copy
import json
import os
import sqlite3
import threading
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple
from urllib.parse import quote

import pydantic_core
from pydantic import BaseModel, ValidationError

from backend.core.bulk import gc_paused
from backend.core.events import EventBatch, apply_events
from backend.core.model import Mission
from backend.core.ops import Predicted, Sync
from backend.core.records import size_on_disk
from backend.server.journal_file import (
    JOURNAL_FORMAT,
    JournalCorrupt,
    JournalError,
    Unreplayable,
    damaged,
    identity,
    open_database,
    quarantine,
    rollback,
    transaction,
)

__all__ = [
    "JOURNAL_FORMAT",  # the file's, from journal_file
    "Entry",
    "Journal",
    "JournalCorrupt",
    "JournalError",
    "LoadInfo",
    "NotReplayable",
    "Record",
    "Remembered",
    "Unreplayable",
    "remember_requests",
]

SNAPSHOT_EVERY = 500
# ...and not before the batches since the newest snapshot add up to this
# share of its size: a 10,000-skill mission's 4 MB snapshot (57-84 ms) every
# 500 reports cost about as much as the reports and wrote 8 KB per report;
# a restart replays at most this share of a snapshot's size in batches
SNAPSHOT_BYTES = 0.5
KEEP_SNAPSHOTS = 3
# appended batches between checkpoints, when the owner runs them (see
# Journal.checkpoint_in_background): a write-ahead log of a few MB at most
CHECKPOINT_EVERY = 512
REMEMBERED_REQUESTS = 10_000  # as many as the engine remembers
# How long a write waits for a lock another program holds on the file. The
# server's event loop waits with it: short, so the refusal reaches the client
# well within its 10 s operation timeout.
BUSY_TIMEOUT_S = 2.0


class Entry(NamedTuple):
    """One batch to append, with what caused it."""

    batch: EventBatch
    op_json: str = ""
    client: str = ""
    request_id: str | None = None
    reply: str | None = None  # the request's reply (`_reply_text`), when known already


class Remembered(NamedTuple):
    """A journaled request (`load()`): a retry of it gets its reply again."""

    client: str
    request_id: str
    revision: int
    reply: dict[str, Any] | None = None  # {"value": ..., "notes": [...]}; None: not kept


class NotReplayable(ValueError):
    """A batch that would not read back as it is (nesting the JSON reader
    refuses, a value JSON cannot carry): refused before it is journaled, so
    the operation is refused and changes nothing."""


class Record(NamedTuple):
    """One journaled batch, as read back (the event log, clients catching up)."""

    revision: int
    ts: float
    actor: str
    client: str
    request_id: str | None
    op: str
    batch: EventBatch


@dataclass
class LoadInfo:
    """How the last `load()` rebuilt the mission."""

    snapshot_revision: int | None = None
    replayed: int = 0
    # newer snapshots that could not be read: (revision, why)
    skipped_snapshots: list[tuple[int, str]] = field(default_factory=list)
    seconds: float = 0.0


def _faithful_serializer(model_cls: type[BaseModel]) -> pydantic_core.SchemaSerializer | None:
    """A JSON serializer for `model_cls` that writes non-finite floats as
    NaN/Infinity instead of null (pydantic's default), so what the journal
    stores always reads back to an equal model. The mission model accepts
    such floats in marker coordinates (and so in bound parameters): writing
    them as null would make the journal unreadable. Same speed as
    `model_dump_json`; None if this pydantic's schema layout is unexpected."""
    try:
        schema = copy.deepcopy(model_cls.__pydantic_core_schema__)

        def walk(node: Any) -> None:
            if isinstance(node, dict):
                if isinstance(node.get("config"), dict):
                    node["config"]["ser_json_inf_nan"] = "constants"
                for v in node.values():
                    walk(v)
            elif isinstance(node, list):
                for v in node:
                    walk(v)

        walk(schema)
        return pydantic_core.SchemaSerializer(schema, {"ser_json_inf_nan": "constants"})
    except Exception:  # pragma: no cover - a future pydantic: fall back to model_dump_json
        return None


def _forecast_of(op_text: str) -> dict[str, Predicted]:
    """A journaled sync's forecast ({} for one that cannot be read)."""
    try:
        return Sync.model_validate_json(op_text).forecast
    except ValidationError:
        return {}


_INSERT_BATCH = (
    "INSERT INTO batches (revision, ts, actor, client, request_id, op, events, reply) "
    "VALUES (?, ?, ?, ?, ?, ?, ?, ?)"
)

_MISSION_JSON = _faithful_serializer(Mission)
_BATCH_JSON = _faithful_serializer(EventBatch)


def _dump(
    serializer: pydantic_core.SchemaSerializer | None,
    model: BaseModel,
    exclude: set[str] | None = None,
) -> str:
    if serializer is None:
        return model.model_dump_json(exclude=exclude)
    return serializer.to_json(model, exclude=exclude).decode()


def _batch_text(b: EventBatch) -> str:
    """The batch's events as the journal stores them, once read back to the
    same events: whatever is journaled can be replayed."""
    try:
        text = _dump(_BATCH_JSON, b, exclude={"op"})
        back = EventBatch.model_validate_json(text)
    except (ValueError, TypeError, pydantic_core.PydanticSerializationError) as e:
        raise NotReplayable(f"it cannot be stored and read back ({_why(e)})") from None
    if back.events != b.events:
        raise NotReplayable(
            "it reads back differently (a value JSON cannot carry as it is: "
            "not-a-number, a tuple, a key that is not a string?)"
        )
    return text


def _reply_text(value: dict[str, Any], notes: list[str]) -> str | None:
    try:
        return pydantic_core.to_json({"value": value, "notes": notes}).decode()
    except pydantic_core.PydanticSerializationError:
        return None  # not kept: a retry is still recognized, without its value


def _op_text(op: Any) -> str:
    if op is None:
        return ""
    if isinstance(op, str):
        return op
    if isinstance(op, BaseModel):
        return op.model_dump_json()
    return json.dumps(op)


# revision, ts, actor, client, request_id, op, events, reply: a row of `batches`
_BatchRow = tuple[int, float, str, str, str | None, str, str, str | None]


def _batch_rows(entries: Iterable[Entry | EventBatch], now: float) -> list[_BatchRow]:
    """The rows to insert for `entries`, each stamped `now`; ValueError for a
    batch without events."""
    rows = []
    for e in entries:
        if isinstance(e, EventBatch):
            e = Entry(e)
        b = e.batch
        if not b.events:
            raise ValueError(f"batch {b.revision} has no events: no-ops are not journaled")
        op, text = e.op_json or b.op, _batch_text(b)
        rows.append((b.revision, now, b.actor, e.client, e.request_id, op, text, e.reply))
    return rows


def _following(last: int | None, rows: list[_BatchRow]) -> int:
    """The journal's last revision once `rows` follow `last`; ValueError unless
    they follow it one by one (and there is a base snapshot)."""
    if last is None:
        raise ValueError(
            "the journal has no base mission: store a snapshot(mission) before appending batches"
        )
    for row in rows:
        if row[0] != last + 1:
            raise ValueError(
                f"batch revision {row[0]} does not follow the journal's last revision "
                f"{last} (expected {last + 1}): revisions are consecutive"
            )
        last = row[0]
    return last


class Journal:
    """Append-only journal of a mission's event batches, with snapshots.

    Thread-safe (one lock around the connection). One writing process per file.
    """

    def __init__(
        self,
        conn: sqlite3.Connection,
        path: Path,
        *,
        snapshot_every: int = SNAPSHOT_EVERY,
        snapshot_bytes: float = SNAPSHOT_BYTES,
        keep_snapshots: int | None = KEEP_SNAPSHOTS,
        lock_fd: int | None = None,
    ):
        self._conn: sqlite3.Connection | None = conn
        self.path = path
        self._lock_fd = lock_fd
        self._identity = identity(path)
        self.snapshot_every = snapshot_every
        self.snapshot_bytes = snapshot_bytes
        # None: every snapshot is kept (the server's: a review seeks from the nearest one)
        self.keep_snapshots = None if keep_snapshots is None else max(1, keep_snapshots)
        self._lock = threading.RLock()
        self.load_info = LoadInfo()
        row = conn.execute("SELECT max(revision) FROM snapshots").fetchone()
        self._snapshot_rev: int | None = row[0]
        # characters of the base snapshot, and of the batches after it
        self._snapshot_size, self._since_snapshot = self._sizes(conn, self._snapshot_rev)
        # the last revision, kept in memory after the first look (this object is
        # the journal's only writer): saves two SELECTs per appended operation
        self._last_rev: int | None = self._last(conn)
        # checkpoints run by the owner (None: SQLite runs them inside a commit)
        self.checkpoint_every: int | None = None
        self.checkpoints = 0  # completed by checkpoint()
        self._appended = 0  # batches since the last checkpoint() started
        self._ckpt_conn: sqlite3.Connection | None = None
        self._ckpt_lock = threading.Lock()

    # -- opening and closing -----------------------------------------------------
    @staticmethod
    def _sizes(conn: sqlite3.Connection, revision: int | None) -> tuple[int, int]:
        """Characters of the snapshot at `revision` and of the batches after it."""
        if revision is None:
            return 0, 0
        row = conn.execute(
            "SELECT length(mission) FROM snapshots WHERE revision = ?", (revision,)
        ).fetchone()
        return (row[0] if row else 0), Journal._since(conn, revision)

    @staticmethod
    def _since(conn: sqlite3.Connection, revision: int) -> int:
        size: int = conn.execute(
            "SELECT coalesce(sum(length(op) + length(events)), 0) FROM batches WHERE revision > ?",
            (revision,),
        ).fetchone()[0]
        return size

    @classmethod
    def open(
        cls,
        path: str | Path,
        *,
        library: str | None = None,
        snapshot_every: int = SNAPSHOT_EVERY,
        snapshot_bytes: float = SNAPSHOT_BYTES,
        keep_snapshots: int | None = KEEP_SNAPSHOTS,
    ) -> Journal:
        """Open (or create) the journal at `path`. `library` is recorded in a
        new journal (the skill library file the mission refers to); an
        existing journal keeps the one it has."""
        p = Path(path)
        conn, lock_fd = open_database(p, library=library, timeout=BUSY_TIMEOUT_S)
        try:
            return cls(
                conn,
                p,
                snapshot_every=snapshot_every,
                snapshot_bytes=snapshot_bytes,
                keep_snapshots=keep_snapshots,
                lock_fd=lock_fd,
            )
        except sqlite3.Error as e:  # its first reads
            conn.close()
            os.close(lock_fd)
            raise damaged(p, e) from None

    def close(self) -> None:
        # after a checkpoint running on another thread; none starts after it
        with self._ckpt_lock, self._lock:
            if self._ckpt_conn is not None:
                self._ckpt_conn.close()
                self._ckpt_conn = None
            if self._conn is not None:
                self._conn.close()
                self._conn = None
            # after SQLite's own descriptors: see journal_file._lock_writer
            if self._lock_fd is not None:
                os.close(self._lock_fd)
                self._lock_fd = None

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def conn(self) -> sqlite3.Connection:
        if self._conn is None:
            raise JournalError(f"{self.path}: the journal is closed")
        return self._conn

    def _writable(self) -> sqlite3.Connection:
        """The connection, once sure the file is still the one opened: SQLite
        goes on writing into a deleted file, which a restart would not find."""
        if identity(self.path) != self._identity:
            raise JournalError(
                f"{self.path} was deleted or replaced while open; "
                "what is written now would be lost at a restart"
            )
        return self.conn

    # -- metadata ------------------------------------------------------------------
    def meta(self) -> dict[str, str]:
        with self._lock:
            return dict(self.conn.execute("SELECT key, value FROM meta").fetchall())

    @property
    def library(self) -> str:
        """The library path recorded when the journal was created."""
        return self.meta().get("library", "")

    def last_revision(self) -> int | None:
        """Revision of the newest batch or snapshot; None for an empty journal."""
        with self._lock:
            return self._last(self.conn)

    @staticmethod
    def _last(conn: sqlite3.Connection) -> int | None:
        b: int | None = conn.execute("SELECT max(revision) FROM batches").fetchone()[0]
        s: int | None = conn.execute("SELECT max(revision) FROM snapshots").fetchone()[0]
        if b is None:
            return s
        return b if s is None else max(b, s)

    def snapshot_revisions(self) -> list[int]:
        with self._lock:
            return [
                r for (r,) in self.conn.execute("SELECT revision FROM snapshots ORDER BY revision")
            ]

    # -- writing -------------------------------------------------------------------
    def append(
        self,
        batch: EventBatch,
        *,
        op_json: str = "",
        client: str = "",
        request_id: str | None = None,
    ) -> None:
        """Append one batch in its own transaction. Raises ValueError unless its
        revision is the last one plus one (and the journal has a base snapshot)."""
        self.append_many([Entry(batch, op_json, client, request_id)])

    def append_many(self, entries: Iterable[Entry | EventBatch]) -> int:
        """Append several batches in one transaction (all or none). Returns
        how many were appended."""
        rows = _batch_rows(entries, time.time())
        if not rows:
            return 0
        with self._lock:
            last = _following(self._last_rev, rows)
            conn = self._writable()
            if len(rows) == 1:  # one statement is its own transaction (autocommit)
                conn.execute(_INSERT_BATCH, rows[0])
            else:
                with transaction(conn):
                    conn.executemany(_INSERT_BATCH, rows)
            self._last_rev = last
            self._appended += len(rows)
            self._since_snapshot += sum(len(row[5]) + len(row[6]) for row in rows)
        return len(rows)

    # -- checkpoints -----------------------------------------------------------------
    def checkpoint_in_background(self, every: int = CHECKPOINT_EVERY) -> None:
        """From now on the owner calls `checkpoint()` (from another thread)
        when `checkpoint_due`. SQLite's own checkpoint runs inside the commit
        that fills its write-ahead log (1,000 pages: one operation in ~400)
        and waits for an fsync there: 4-17 ms for that operation."""
        with self._lock:
            self.conn.execute("PRAGMA wal_autocheckpoint=0")
            self.checkpoint_every = every

    @property
    def checkpoint_due(self) -> bool:
        return self.checkpoint_every is not None and self._appended >= self.checkpoint_every

    def checkpoint(self) -> tuple[int, int, int]:
        """Copy the write-ahead log into the database file without holding
        up the writer (SQLite's PASSIVE checkpoint). Safe on any thread: it
        has a connection of its own. Returns SQLite's (busy, frames in the
        log, frames copied)."""
        with self._lock:
            self._appended = 0
        with self._ckpt_lock:
            if self._conn is None:
                raise JournalError(f"{self.path}: the journal is closed")
            if identity(self.path) != self._identity:
                raise JournalError(
                    f"{self.path} was deleted or replaced while open; nothing to checkpoint"
                )
            if self._ckpt_conn is None:  # mode=rw: never create a file where the journal was
                uri = f"file:{quote(str(self.path.resolve()))}?mode=rw"
                self._ckpt_conn = sqlite3.connect(
                    uri,
                    uri=True,
                    isolation_level=None,
                    check_same_thread=False,
                    timeout=BUSY_TIMEOUT_S,
                )
            busy, log_frames, copied = self._ckpt_conn.execute(
                "PRAGMA wal_checkpoint(PASSIVE)"
            ).fetchone()
            self.checkpoints += 1
            return busy, log_frames, copied

    def record(
        self,
        applied: Any,
        op: Any = None,
        *,
        actor: str = "",
        client: str = "",
        request_id: str | None = None,
        mission: Mission | None = None,
    ) -> bool:
        """Journal what `Engine.submit` returned: nothing for a duplicate or a
        no-op, else its batch with the operation. With `mission` (the engine's
        mission after the operation), snapshot when one is due. Returns True
        when a batch was written."""
        if applied.duplicate or not applied.events:
            return False
        reply = _reply_text(applied.value, applied.notes) if request_id is not None else None
        entry = Entry(applied.batch(actor or client), _op_text(op), client, request_id, reply)
        self.append_many([entry])
        if mission is not None:
            self.maybe_snapshot(mission)
        return True

    def set_reply(self, revision: int, value: dict[str, Any], notes: list[str]) -> None:
        """Keep the reply of the request journaled at `revision`: a client
        retrying it after a restart gets it again (`load`, `remember_requests`)."""
        text = _reply_text(value, notes)
        with self._lock:
            self._writable().execute(
                "UPDATE batches SET reply = ? WHERE revision = ?", (text, revision)
            )

    def snapshot(self, mission: Mission) -> None:
        """Store the whole mission at its revision; keep the newest
        `keep_snapshots`. The mission must be the state after the journal's
        batch of the same revision (or the journal's first, base mission,
        which must read back: a restart starts from it)."""
        text = _dump(_MISSION_JSON, mission)
        if self._snapshot_rev is None:
            _reads_back(text)
        rev = mission.revision
        with self._lock:
            conn = self._writable()
            last = self._last_rev
            if last is not None and rev > last:
                raise ValueError(
                    f"cannot snapshot revision {rev}: the journal ends at revision {last}; "
                    "append the batches up to it first"
                )
            with transaction(conn):
                conn.execute(
                    "INSERT OR REPLACE INTO snapshots (revision, mission) VALUES (?, ?)",
                    (rev, text),
                )
                if self.keep_snapshots is not None:
                    conn.execute(
                        "DELETE FROM snapshots WHERE revision NOT IN "
                        "(SELECT revision FROM snapshots ORDER BY revision DESC LIMIT ?)",
                        (self.keep_snapshots,),
                    )
            if self._snapshot_rev is None or rev >= self._snapshot_rev:
                self._snapshot_rev = rev
                self._snapshot_size, self._since_snapshot = len(text), self._since(conn, rev)
            self._last_rev = rev if last is None else max(last, rev)

    def snapshot_due(self, revision: int) -> bool:
        """At `revision`: `snapshot_every` batches since the newest snapshot,
        adding up to `snapshot_bytes` of its size (or no snapshot yet)."""
        base = self._snapshot_rev
        return base is None or (
            revision - base >= self.snapshot_every
            and self._since_snapshot >= self.snapshot_bytes * self._snapshot_size
        )

    def maybe_snapshot(self, mission: Mission) -> bool:
        """Snapshot when one is due (`snapshot_due`). Returns True when it did."""
        if not self.snapshot_due(mission.revision):
            return False
        self.snapshot(mission)
        return True

    # -- reading -------------------------------------------------------------------
    def sync_forecasts(self, skills: set[str]) -> dict[str, Predicted]:
        """What the newest journaled syncs of `skills` forecast for them (a
        restart's verification times their started and completed stages
        from it, as before the restart)."""
        wanted, found = set(skills), {}
        if wanted:
            with self._lock:
                rows = self.conn.execute(
                    "SELECT op FROM batches WHERE op LIKE ? ORDER BY revision DESC",
                    ('{"op":"sync"%',),
                ).fetchall()
            for (text,) in rows:
                forecast = _forecast_of(text)
                found.update({s: forecast[s] for s in wanted & forecast.keys()})
                wanted -= forecast.keys()
        return found

    def load(self) -> tuple[Mission | None, list[Remembered]]:
        """The mission as of the last committed batch, and the last requests
        (`Remembered`: client, request_id, revision, reply), oldest first.

        (None, []) for an empty journal. The newest readable snapshot is the
        base; an unreadable one is skipped for an older one (see `load_info`).
        Raises JournalCorrupt rather than return a partial mission
        (Unreplayable when a batch is missing or cannot be applied: see
        `quarantine_from`)."""
        try:
            with gc_paused():
                return self._load()
        except sqlite3.Error as e:  # a damaged file (or pages of it)
            with self._lock:
                rollback(self.conn)
            raise damaged(self.path, e) from None

    def _load(self) -> tuple[Mission | None, list[Remembered]]:
        t0 = time.perf_counter()
        info = LoadInfo()
        with self._lock:
            conn = self.conn
            conn.execute("BEGIN")  # one consistent read of snapshots and batches
            try:
                snaps = conn.execute(
                    "SELECT revision FROM snapshots ORDER BY revision DESC"
                ).fetchall()
                n_batches = conn.execute("SELECT count(*) FROM batches").fetchone()[0]
                if not snaps and not n_batches:
                    self.load_info = info
                    return None, []
                mission = _newest_snapshot(conn, self.path, [rev for (rev,) in snaps], info)
                info.snapshot_revision = mission.revision
                mission = _replay(conn, self.path, mission, info)
                rows = conn.execute(
                    "SELECT client, request_id, revision, reply FROM batches "
                    "WHERE request_id IS NOT NULL ORDER BY revision DESC LIMIT ?",
                    (REMEMBERED_REQUESTS,),
                ).fetchall()
            finally:
                conn.execute("COMMIT")
            # snapshot policy counts from the snapshot actually usable (sized
            # at open already when it is the newest: a 4 MB one is read to count)
            if info.snapshot_revision != self._snapshot_rev:
                self._snapshot_rev = info.snapshot_revision
                self._snapshot_size, self._since_snapshot = self._sizes(conn, self._snapshot_rev)
        info.seconds = time.perf_counter() - t0
        self.load_info = info
        rows.reverse()
        return mission, [Remembered(c, r, rev, _reply(reply)) for c, r, rev, reply in rows]

    def quarantine_from(self, revision: int, reason: str) -> tuple[int, int]:
        """Keep the journal up to `revision - 1` (what `load` could replay
        when it raised Unreplayable): the batches and snapshots from
        `revision` on move to its quarantine table, where they stay. Returns
        how many batches and snapshots moved."""
        with self._lock:
            moved = quarantine(self._writable(), revision, reason)
            conn = self.conn
            self._last_rev = self._last(conn)
            self._snapshot_rev = conn.execute("SELECT max(revision) FROM snapshots").fetchone()[0]
            self._snapshot_size, self._since_snapshot = self._sizes(conn, self._snapshot_rev)
        return moved

    def request_revision(self, client: str, request_id: str) -> int | None:
        """Revision at which a request was applied, if it is journaled."""
        with self._lock:
            row = self.conn.execute(
                "SELECT revision FROM batches WHERE client = ? AND request_id = ? "
                "ORDER BY revision DESC LIMIT 1",
                (client, request_id),
            ).fetchone()
        return None if row is None else row[0]

    def records(self, after: int = 0, limit: int | None = None) -> Iterator[Record]:
        """Journaled batches with revision > `after`, oldest first."""
        with self._lock:
            rows = self.conn.execute(
                "SELECT revision, ts, actor, client, request_id, op, events FROM batches "
                "WHERE revision > ? ORDER BY revision LIMIT ?",
                (after, -1 if limit is None else limit),
            ).fetchall()
        for rev, ts, actor, client, rid, op, events in rows:
            batch = EventBatch.model_validate_json(events)
            batch.op = op
            yield Record(rev, ts, actor, client, rid, op, batch)

    def size_bytes(self) -> int:
        """Bytes on disk: the database and its write-ahead log."""
        return size_on_disk(self.path)


def remember_requests(engine: Any, requests: Iterable[tuple[Any, ...]]) -> None:
    """Teach a fresh engine the requests `load()` returned, so a client that
    retries a request applied before the restart gets the duplicate answer,
    with the reply's value and notes when they were kept."""
    from backend.core.rules.engine import Applied

    for client, request_id, revision, *kept in requests:
        reply = kept[0] if kept and kept[0] else {}
        value, notes = reply.get("value", {}), reply.get("notes", [])
        engine.remember(client, request_id, Applied(revision, [], notes, value, duplicate=False))


def _reply(text: str | None) -> dict[str, Any] | None:
    if not text:
        return None
    try:
        reply = json.loads(text)
    except ValueError:
        return None
    return reply if isinstance(reply, dict) else None


def _reads_back(text: str) -> None:
    """NotReplayable unless the mission in `text` reads back (a restart starts from it)."""
    try:
        Mission.model_validate_json(text)
    except ValueError as e:
        raise NotReplayable(f"the mission cannot be read back ({_why(e)})") from None


def _newest_snapshot(
    conn: sqlite3.Connection, path: Path, revisions: list[int], info: LoadInfo
) -> Mission:
    """The newest of the snapshots at `revisions` (newest first) that reads
    back as the mission of its revision; the others it passes are noted in
    `info`. JournalCorrupt when none does."""
    for rev in revisions:
        (text,) = conn.execute(
            "SELECT mission FROM snapshots WHERE revision = ?", (rev,)
        ).fetchone()
        try:
            m = Mission.model_validate_json(text)
        except (ValidationError, ValueError, TypeError) as e:
            info.skipped_snapshots.append((rev, _why(e)))
            continue
        if m.revision == rev:
            return m
        info.skipped_snapshots.append((rev, f"it holds revision {m.revision}"))
    if revisions:
        why = "; ".join(f"revision {r}: {w}" for r, w in info.skipped_snapshots)
        raise JournalCorrupt(f"{path}: no snapshot can be read ({why})")
    raise JournalCorrupt(f"{path}: batches without a base snapshot")


def _replay(conn: sqlite3.Connection, path: Path, mission: Mission, info: LoadInfo) -> Mission:
    """`mission` with the batches after its revision applied, in order; or
    Unreplayable naming the first that is missing or cannot be applied."""
    expected = mission.revision + 1
    cur = conn.execute(
        "SELECT revision, events, actor, op FROM batches WHERE revision > ? ORDER BY revision",
        (mission.revision,),
    )
    for rev, text, actor, op in cur:
        if rev != expected:
            raise _missing(conn, path, expected, rev)
        try:
            batch = EventBatch.model_validate_json(text)
            if batch.revision != rev:
                raise ValueError(f"it says revision {batch.revision}")
            mission = apply_events(mission, batch)
        except (ValidationError, ValueError, KeyError, TypeError, IndexError) as e:
            raise _unappliable(conn, path, expected, actor, op, _why(e)) from None
        info.replayed += 1
        expected += 1
    return mission


def _later(conn: sqlite3.Connection, revision: int) -> int:
    """How many batches the journal holds after `revision`."""
    return int(
        conn.execute("SELECT count(*) FROM batches WHERE revision > ?", (revision,)).fetchone()[0]
    )


def _missing(conn: sqlite3.Connection, path: Path, expected: int, rev: int) -> Unreplayable:
    """Batch `expected` is not in the journal: the next one there is `rev`."""
    return Unreplayable(
        f"{path}: batch {expected} is missing (the next one is {rev}); "
        f"cannot replay past revision {expected - 1}",
        revision=expected,
        why=f"it is missing (the next one is {rev})",
        later=_later(conn, expected),
        what="",
    )


def _unappliable(
    conn: sqlite3.Connection, path: Path, expected: int, actor: str, op: str, why: str
) -> Unreplayable:
    """Batch `expected` is there but cannot be read or applied, for `why`."""
    what = f"{_op_name(op)} by {actor}" if actor else ""
    return Unreplayable(
        f"{path}: batch {expected}{f' ({what})' if what else ''} cannot be replayed: {why}",
        revision=expected,
        why=why,
        later=_later(conn, expected),
        what=what,
    )


def _op_name(op: str) -> str:
    """The operation's name from its journaled JSON ('add', 'report')."""
    try:
        name = json.loads(op).get("op") if op.startswith("{") else op
    except (ValueError, AttributeError):
        name = None
    return name if isinstance(name, str) and name else "an operation"


def _why(e: BaseException) -> str:
    if isinstance(e, ValidationError):
        err = e.errors()[0]
        loc = ".".join(str(x) for x in err.get("loc", ()))
        return f"{err.get('msg', 'invalid')}" + (f" at {loc}" if loc else "")
    return str(e) or type(e).__name__
