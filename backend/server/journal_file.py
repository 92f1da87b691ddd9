"""The journal's SQLite file: opened for its one writer, in write-ahead
logging, with the schema and format version a journal has.

`journal.Journal` keeps the log in it; this module only opens the file and
says clearly why it cannot (another server on it, another program's lock,
not a journal, another format version, damaged pages).
"""

from __future__ import annotations

import os
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

JOURNAL_FORMAT = "missionctl/journal@1"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS batches (
    revision   INTEGER PRIMARY KEY,
    ts         REAL NOT NULL,
    actor      TEXT NOT NULL DEFAULT '',
    client     TEXT NOT NULL DEFAULT '',
    request_id TEXT,
    op         TEXT NOT NULL DEFAULT '',
    events     TEXT NOT NULL,
    reply      TEXT
);
CREATE INDEX IF NOT EXISTS batches_request ON batches (client, request_id);
CREATE TABLE IF NOT EXISTS snapshots (
    revision INTEGER PRIMARY KEY,
    mission  TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS quarantine (
    id         INTEGER PRIMARY KEY AUTOINCREMENT,
    at         TEXT NOT NULL,
    reason     TEXT NOT NULL,
    kind       TEXT NOT NULL,
    revision   INTEGER NOT NULL,
    ts         REAL,
    actor      TEXT,
    client     TEXT,
    request_id TEXT,
    op         TEXT,
    content    TEXT NOT NULL,
    reply      TEXT
);
"""
# `batches.reply` came after journals were first written: added to theirs at open
_ADDED_COLUMNS = (("batches", "reply", "TEXT"),)


class JournalError(Exception):
    """The journal file cannot be used (not a journal, another format version)."""


class JournalCorrupt(JournalError):
    """The journal cannot give back a whole mission (no readable snapshot, a
    damaged or missing batch). Nothing partial is ever returned."""


class Unreplayable(JournalCorrupt):
    """Batch `revision` is missing or cannot be replayed; everything before it
    can (`Journal.quarantine_from(revision)` keeps that and moves the rest
    aside). `later`: how many batches follow it."""

    def __init__(self, message: str, *, revision: int, why: str, later: int, what: str = ""):
        super().__init__(message)
        self.revision, self.why, self.later, self.what = revision, why, later, what


def open_database(
    p: Path, *, library: str | None, timeout: float
) -> tuple[sqlite3.Connection, int]:
    """Open (or create) the journal file `p` for its one writer; `library`
    is recorded in a new journal. Returns the connection and the descriptor
    holding the writer's lock (to close after the connection). `timeout`:
    how long a write waits for a lock another program holds."""
    if not p.parent.is_dir():
        raise JournalError(f"{p}: cannot open the journal: no such folder {p.parent}")
    lock_fd = _lock_writer(p)
    try:
        conn = sqlite3.connect(p, isolation_level=None, check_same_thread=False, timeout=timeout)
    except sqlite3.Error as e:
        os.close(lock_fd)
        raise JournalError(f"{p}: cannot open the journal: {e}") from None
    try:
        _prepare(conn, p, library)
    except JournalError:
        _abandon(conn, lock_fd)
        raise
    except sqlite3.Error as e:
        _abandon(conn, lock_fd)
        raise _unusable(p, e) from None
    return conn, lock_fd


def _unusable(p: Path, e: sqlite3.Error) -> JournalError:
    """What SQLite's refusal to prepare the journal means for a person."""
    if "locked" in str(e) or "busy" in str(e):
        return JournalError(
            f"{p}: the journal is locked by another program (an sqlite3 shell, a backup?): "
            "close it, then start again"
        )
    return JournalError(f"{p}: not a usable journal: {e}")


def _prepare(conn: sqlite3.Connection, p: Path, library: str | None) -> None:
    mode = conn.execute("PRAGMA journal_mode=WAL").fetchone()[0]
    if str(mode).lower() != "wal":
        raise JournalError(f"{p}: SQLite refused write-ahead logging (journal_mode={mode})")
    # WAL + synchronous=NORMAL: a commit is in the WAL file (the OS
    # page cache) when COMMIT returns, so a killed process (SIGKILL,
    # OOM, a crash) loses nothing it committed and never leaves half a
    # transaction. Only a power loss or kernel crash may drop the last
    # commits (never corrupt the file); synchronous=FULL would cover
    # that too at the price of an fsync per operation.
    conn.execute("PRAGMA synchronous=NORMAL")
    conn.execute("BEGIN IMMEDIATE")
    _make_tables(conn, p)
    _check_meta(conn, p, library)
    conn.execute("COMMIT")


def _make_tables(conn: sqlite3.Connection, p: Path) -> None:
    """The journal's tables, created (or brought up to date); a database of
    something else is refused."""
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if tables and "meta" not in tables:
        raise JournalError(
            f"{p}: an SQLite database, but not a missionctl journal "
            f"(tables: {', '.join(sorted(tables))})"
        )
    for stmt in _SCHEMA.split(";"):
        if stmt.strip():
            conn.execute(stmt)
    _add_columns(conn)


def _add_columns(conn: sqlite3.Connection) -> None:
    """A journal written before a column was added gets it (empty)."""
    for table, column, kind in _ADDED_COLUMNS:
        if column not in {row[1] for row in conn.execute(f"PRAGMA table_info({table})")}:
            conn.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")


def _check_meta(conn: sqlite3.Connection, p: Path, library: str | None) -> None:
    """A new journal gets its metadata; an existing one must be of this format."""
    meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
    if not meta:
        now = datetime.now(UTC).isoformat(timespec="seconds")
        conn.executemany(
            "INSERT INTO meta (key, value) VALUES (?, ?)",
            [("format", JOURNAL_FORMAT), ("library", library or ""), ("created", now)],
        )
    elif meta.get("format") != JOURNAL_FORMAT:
        raise JournalError(
            f"{p}: journal format {meta.get('format')!r} is not supported "
            f"(this version reads {JOURNAL_FORMAT!r})"
        )
    elif library and not meta.get("library"):
        conn.execute("UPDATE meta SET value = ? WHERE key = 'library'", (library,))


def quarantine(conn: sqlite3.Connection, revision: int, reason: str) -> tuple[int, int]:
    """Move the batches and snapshots from `revision` on into the quarantine
    table, in one transaction: the journal then ends at `revision - 1`, and
    nothing is deleted (an operator can read them there). Returns how many
    batches and snapshots moved."""
    now = datetime.now(UTC).isoformat(timespec="seconds")
    with transaction(conn):
        batches = conn.execute(
            "INSERT INTO quarantine (at, reason, kind, revision, ts, actor, client, request_id, "
            "op, content, reply) SELECT ?, ?, 'batch', revision, ts, actor, client, request_id, "
            "op, events, reply FROM batches WHERE revision >= ? ORDER BY revision",
            (now, reason, revision),
        ).rowcount
        snapshots = conn.execute(
            "INSERT INTO quarantine (at, reason, kind, revision, content) "
            "SELECT ?, ?, 'snapshot', revision, mission FROM snapshots WHERE revision >= ? "
            "ORDER BY revision",
            (now, reason, revision),
        ).rowcount
        conn.execute("DELETE FROM batches WHERE revision >= ?", (revision,))
        conn.execute("DELETE FROM snapshots WHERE revision >= ?", (revision,))
    return batches, snapshots


def _abandon(conn: sqlite3.Connection, lock_fd: int) -> None:
    rollback(conn)
    conn.close()
    os.close(lock_fd)


def damaged(path: Path, e: sqlite3.Error) -> JournalCorrupt:
    return JournalCorrupt(
        f"{path}: the journal cannot be read ({e}); restore a copy of the file, "
        "or start from the mission file with a new journal"
    )


def identity(path: Path) -> tuple[int, int] | None:
    """What tells the file opened from another one at its path (None: gone)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _lock_writer(p: Path) -> int:
    """Take the file's one-writer lock (a second server on the same journal
    would write the same revisions), or raise JournalError. A BSD lock
    (flock): independent of SQLite's POSIX locks on the same file. The
    descriptor must stay open while SQLite has the file: closing any
    descriptor of a file drops the process's POSIX locks on it."""
    try:
        fd = os.open(p, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise JournalError(f"{p}: cannot open the journal for writing: {e.strerror}") from None
    try:
        import fcntl
    except ImportError:  # not a POSIX system: no guard
        return fd
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise JournalError(
            f"{p} is in use by another process (another missionctl server on this journal?): "
            "stop it first, or give this one another --db"
        ) from None
    return fd


@contextmanager
def transaction(conn: sqlite3.Connection) -> Iterator[None]:
    """One write transaction: committed at the end, rolled back on any
    exception (which goes on)."""
    conn.execute("BEGIN IMMEDIATE")
    try:
        yield
        conn.execute("COMMIT")
    except BaseException:
        rollback(conn)
        raise


def rollback(conn: sqlite3.Connection) -> None:
    if conn.in_transaction:
        try:
            conn.execute("ROLLBACK")
        except sqlite3.Error:
            pass
