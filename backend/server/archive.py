"""The telemetry archive: what the journal does not hold, kept for review.

Beside the journal (`mission.db` -> `mission.telemetry.db`, see
backend/files/record/archive.py for the schema) the server keeps:

- every robot's telemetry, **downsampled**: a robot's sample is kept when
  its mode, its skill or its contact (in range or not) differs from its last
  kept sample, or when `every_s` (default 1 s) has passed since that one by
  the ground's clock; never more than 10 a second per robot (a value that
  flaps cannot flood it). The rest are dropped: a rover reporting 4 times a
  second leaves about one sample a second, each with the robot's own time
  and the time the ground took it.
- the server's alerts and the robots' presence changes (`notes`);
- an index of the journal by time (`journal`: each batch's revision, when
  it was journaled, its operation and, for a robot's report or answer, the
  robot and its own time): a review orders 100,000 batches in either clock from it
  without reading the journal through (a review of a journal without it
  reads the journal through instead, slower).

**Bounded**: at most `max_samples` samples (default 2,000,000: about 140
robot-hours... see docs/performance.md for the bytes per robot-hour), plus
up to `MOVE_AT` waiting to be moved (below); past that the oldest samples
go first (retention: the newest `max_samples`).
Alerts and presence are a few per robot and hour and are all kept, as is
the index (about 30 bytes per journaled batch).

**Off the event loop**: the sample is taken or dropped on the Zenoh thread
that received it (a comparison), made a row there and handed to a writer
thread (appended to a deque: no lock); the writer writes whatever waits in
one transaction when `flush_s` (default 5 s) has passed since the first of
it arrived, or at once when `WAKE_AT` (1,000) wait. (Making the rows in the
writer cost more: the samples then crossed threads, and were freed on the
other one.) A full queue drops the sample (counted in `dropped`, logged
once): nothing ever waits for the disk but that thread.

**Two tables, one write an index**: a write appends its samples to
`recent`, a table without an index (one B-tree a row); once `MOVE_AT`
(1,000, about 4 minutes of 4 robots at 4 Hz) wait there, the same write
moves them to `telemetry` (indexed by robot in both clocks) in one
statement, and drops the oldest past `max_samples` then. A write of 20 rows
into three B-trees dirtied about 14 pages (each robot's leaf of both
indexes) for its COMMIT; into `recent` 2-4; each robot's index pages are
now written once a move (the writer 34 -> 22-24 us a row, measured). The
price: up to `MOVE_AT` samples more than `max_samples` between moves, and a
review of a live copy scans those few unindexed rows (`ArchiveReader`
merges both tables); a clean stop moves them all.

**Written every few seconds, the price**: a write's own cost (BEGIN, the
COMMIT to the WAL, the wake-ups: 55-100 us) is most of the archive's when a
write carries few rows, as live (4 robots at 4 Hz keep about 4 rows a
second); every 5 s it carries about 20. So a copy of a live server's
database, read by `missionctl review`, lacks up to the last `flush_s` of
telemetry, alerts, presence and index (the review completes the index from
the journal), and a crash (power, SIGKILL) loses them. A clean stop loses
nothing: `close` (the server's `stop`) writes what waits at once.
"""

from __future__ import annotations

import functools
import logging
import sqlite3
import threading
import time
from collections import deque
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from backend.core.clocks import ROBOT_TIMED
from backend.protocol.archive import (
    ALERT,
    ARCHIVE_FORMAT,
    FLEET,
    SAMPLE_COLUMNS,
    SCHEMA,
    sample_row,
)
from backend.protocol.messages import Alert, RobotInfo, Telemetry

log = logging.getLogger(__name__)

EVERY_S = 1.0  # a robot's sample at least this often (ground seconds)
MIN_GAP_S = 0.1  # ...and never more often than this, whatever changes
MAX_SAMPLES = 2_000_000
QUEUE_MAX = 20_000  # samples waiting for the writer (about a minute of a busy site)
FLUSH_S = 5.0  # a write at most this long after the first row waiting (the docstring's price)
WAKE_AT = 1_000  # rows waiting that wake the writer before its flush_s is up

# samples one INSERT carries (17 x 50 parameters, under SQLite's oldest limit of
# 999): the sqlite3 module lets the GIL go around each statement's step, and
# took it back once a row with executemany, each time waiting for the
# receiving thread to give it up: the writer's CPU a row 8-11 -> 5-7 us
ROWS_A_STATEMENT = 50
PRAGMAS = (
    "PRAGMA journal_mode=WAL",
    "PRAGMA synchronous=NORMAL",  # a lost last write is acceptable here
)
# samples waiting in `recent` (appended, unindexed) that the writer moves to
# `telemetry` (indexed by robot in both clocks) at once: each robot's index
# pages are then written once a move, not once a write (about 4 minutes of 4
# robots at 4 Hz; a review of a live copy scans them)
MOVE_AT = 1_000
_MOVE = f"INSERT INTO telemetry ({SAMPLE_COLUMNS}) SELECT {SAMPLE_COLUMNS} FROM recent ORDER BY id"
_INSERT_BATCH = (
    "INSERT OR REPLACE INTO journal (revision, ts, op, robot_at, robot) VALUES (?, ?, ?, ?, ?)"
)


# a robot's last kept sample: when (the archive's clock), and its mode, skill, contact
_Kept = tuple[float, tuple[str, str | None, bool]]
_Item = tuple[str, Any]  # ("sample", row), ("note", row), ... for the writer


class TelemetryArchive:
    """The archive's writer: `took` and `note` from any thread, `close` once."""

    def __init__(
        self,
        path: str | Path,
        *,
        every_s: float = EVERY_S,
        max_samples: int = MAX_SAMPLES,
        flush_s: float = FLUSH_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.path = Path(path)
        self.every_s = every_s
        self.max_samples = max(1, max_samples)
        self.flush_s = flush_s
        self._clock = clock  # for the downsampling (tests and benches play time)
        self._kept: dict[str, _Kept] = {}
        # what waits for the writer: appended on any thread, taken by the writer
        # (a deque's append and popleft need no lock: 0.1 us against a Queue's 2.8)
        self._queue: deque[_Item] = deque()
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()  # something waits (set by a put that found it clear)
        self._now = threading.Event()  # write at once: a burst, a flush, closing
        self._closing = False
        self.kept = 0  # samples handed to the writer
        self.skipped = 0  # samples the downsampling left out
        self.dropped = 0  # samples lost to a full queue
        self.written = 0  # rows the writer committed
        self.failed: str | None = None  # why the writer stopped writing
        self._staged = 0  # samples in `recent` (the writer's)

    # -- start and stop -------------------------------------------------------------------
    def start(self) -> None:
        """Open (or create) the file and start the writer thread. Raises
        sqlite3.Error / OSError when the file cannot be used."""
        conn = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
        try:
            for pragma in PRAGMAS:
                conn.execute(pragma)
            conn.executescript(SCHEMA)
            conn.execute(
                "INSERT OR IGNORE INTO meta (key, value) VALUES ('created', ?)",
                (datetime.now(UTC).isoformat(timespec="seconds"),),
            )
            conn.execute(  # an @1 file has `recent` now (the SCHEMA above): it is @2
                "INSERT OR REPLACE INTO meta (key, value) VALUES ('format', ?), ('rule', ?)",
                (
                    ARCHIVE_FORMAT,
                    f"every {self.every_s:g} s or on a change of mode, skill or contact; "
                    f"the newest {self.max_samples} samples",
                ),
            )
            self._staged = conn.execute("SELECT count(*) FROM recent").fetchone()[0]
            count = self._staged + conn.execute("SELECT count(*) FROM telemetry").fetchone()[0]
        except BaseException:
            conn.close()
            raise
        self._thread = threading.Thread(
            target=self._write, args=(conn, count), name="telemetry-archive", daemon=True
        )
        self._thread.start()

    def close(self, timeout: float = 5.0) -> None:
        """Write what waits, stop the writer."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        self._closing = True
        self._now.set()
        self._ready.set()
        thread.join(timeout)

    def flush(self, timeout: float = 60.0) -> bool:
        """Wait until what was taken so far is written (True), for a caller
        that takes samples faster than any robot sends them (a recording): a
        sample taken while the queue is full is dropped, never waited for."""
        if self._thread is None:
            return True
        done = threading.Event()
        self._queue.append(("flush", done))  # this caller asked to wait: it may
        self._now.set()
        self._ready.set()
        return done.wait(timeout)

    # -- taking (any thread) --------------------------------------------------------------------
    def took(self, t: Telemetry, received: float | None = None) -> bool:
        """A sample the server received: kept (True) or left out by the rule."""
        if self._thread is None or self._left_out(t):
            return False
        kept = self._put(("sample", sample_row(t, time.time() if received is None else received)))
        self.kept += kept
        return kept

    def _left_out(self, t: Telemetry) -> bool:
        """The downsampling rule: left out (counted), or noted as the robot's last kept."""
        now, said = self._clock(), (t.mode, t.skill, t.in_range)
        last = self._kept.get(t.robot)
        if last is not None:
            gap = now - last[0]
            if gap < MIN_GAP_S or (gap < self.every_s and said == last[1]):
                self.skipped += 1
                return True
        self._kept[t.robot] = (now, said)
        return False

    def journaled(self, revision: int, op: Any, ts: float | None = None) -> None:
        """The journal took `op` at `revision`: its row in the review's index
        (when, and for a robot's report or answer, the robot and its own time)."""
        name = str(getattr(op, "op", ""))
        at = getattr(op, "at", None) if name in ROBOT_TIMED else None
        robot = getattr(op, "robot", None) if at is not None else None
        when = time.time() if ts is None else ts
        self._put(("batch", (revision, when, name, at.timestamp() if at else None, robot)))

    def alert(self, a: Alert) -> None:
        self._put(("note", (ALERT, a.at.timestamp(), a.model_dump_json())))

    def fleet(self, info: RobotInfo, at: float | None = None) -> None:
        when = time.time() if at is None else at
        self._put(("note", (FLEET, when, info.model_dump_json())))

    def _put(self, item: _Item) -> bool:
        waiting = len(self._queue)
        if waiting >= QUEUE_MAX:
            self.dropped += 1
            if self.dropped == 1:
                log.warning(
                    "%s: the telemetry archive cannot keep up; samples are dropped "
                    "(the mission is not affected)",
                    self.path,
                )
            return False
        self._queue.append(item)
        # after the append: the writer clears _ready before it takes, so either it
        # takes this item or this test sees _ready clear (a test of the length
        # before the append missed the wake-up when the writer took all between)
        if not self._ready.is_set():
            self._ready.set()
        elif waiting >= WAKE_AT:  # a burst: write now, before the queue fills
            self._now.set()
        return True

    # -- the writer thread ------------------------------------------------------------------------
    def _write(self, conn: sqlite3.Connection, count: int) -> None:
        try:
            while not self._closing or self._queue:
                self._ready.wait()
                # let flush_s of samples gather, then take them all: one wake-up
                # of this thread per flush, not one per sample (each would take
                # the GIL from the Zenoh thread that receives the telemetry)
                self._now.wait(self.flush_s)
                self._ready.clear()
                self._now.clear()
                items = self._take_all()
                if items and self.failed is None:
                    count = self._commit(conn, items, count)
            if self._staged and self.failed is None:  # closed: every sample indexed
                self._in_transaction(conn, lambda: self._move(conn, count))
        except (sqlite3.Error, OSError) as e:
            self._stopped(e)
        finally:
            conn.close()

    def _take_all(self) -> list[_Item]:
        q, items = self._queue, []
        while q:
            items.append(q.popleft())
        return items

    def _commit(self, conn: sqlite3.Connection, items: list[_Item], count: int) -> int:
        by: dict[str, list[Any]] = {"sample": [], "note": [], "batch": [], "flush": []}
        for kind, row in items:
            by[kind].append(row)
        samples = by["sample"]
        try:
            count = self._insert(conn, samples, by["note"], by["batch"], count)
        except (sqlite3.Error, OSError) as e:  # what comes later is taken and left out
            self._stopped(e)
            return count  # (a flush waiting then times out: False)
        self.written += len(items) - len(by["flush"])
        for done in by["flush"]:
            done.set()
        return count

    def _stopped(self, e: Exception) -> None:
        self.failed = str(e)
        log.warning("%s: the telemetry archive stopped writing: %s", self.path, e)

    def _insert(
        self,
        conn: sqlite3.Connection,
        samples: list[tuple[object, ...]],
        notes: list[Any],
        batches: list[Any],
        count: int,
    ) -> int:
        """One write: the samples appended to `recent`, moved to `telemetry`
        once MOVE_AT wait there; the count of samples kept after it."""

        def write() -> int:
            for k in range(0, len(samples), ROWS_A_STATEMENT):
                rows = samples[k : k + ROWS_A_STATEMENT]
                conn.execute(_insert_samples(len(rows)), [v for row in rows for v in row])
            conn.executemany("INSERT INTO notes (kind, at, body) VALUES (?, ?, ?)", notes)
            conn.executemany(_INSERT_BATCH, batches)
            self._staged += len(samples)
            n = count + len(samples)
            return self._move(conn, n) if self._staged >= MOVE_AT else n

        return self._in_transaction(conn, write)

    def _move(self, conn: sqlite3.Connection, count: int) -> int:
        """`recent` into `telemetry` in one statement (each robot's index pages
        written once for all), then the oldest past max_samples dropped."""
        conn.execute(_MOVE)
        conn.execute("DELETE FROM recent")
        self._staged = 0
        if count > self.max_samples:  # the oldest go first
            over = count - self.max_samples
            conn.execute(
                "DELETE FROM telemetry WHERE id IN (SELECT id FROM telemetry ORDER BY id LIMIT ?)",
                (over,),
            )
            count -= over
        return count

    def _in_transaction(self, conn: sqlite3.Connection, write: Callable[[], int]) -> int:
        staged = self._staged
        conn.execute("BEGIN")
        try:
            count = write()
            conn.execute("COMMIT")
        except BaseException:
            self._staged = staged  # as the file has it
            if conn.in_transaction:
                conn.execute("ROLLBACK")
            raise
        return count


@functools.cache
def _insert_samples(n: int) -> str:
    """The INSERT of `n` samples in one statement."""
    row = f"({', '.join('?' * len(SAMPLE_COLUMNS.split(',')))})"
    return f"INSERT INTO recent ({SAMPLE_COLUMNS}) VALUES {', '.join([row] * n)}"
