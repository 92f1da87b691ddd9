"""A recorded mission's files (the journal, the telemetry archive), opened
read-only: SQLite's `mode=ro`, so reading never writes them."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from urllib.parse import quote


class RecordError(Exception):
    """A recorded mission that cannot be read: the sentence says which file,
    what is wrong and what to do."""


def open_read_only(path: Path, what: str) -> sqlite3.Connection:
    """`path` opened so that nothing is ever written to it (`mode=ro`: SQLite
    refuses every write; with write-ahead logging it reads the -wal beside
    the file, so a copy taken with its -wal reads whole)."""
    if not path.is_file():
        raise RecordError(f"{path}: no such {what}")
    uri = f"file:{quote(str(path.resolve()))}?mode=ro"
    try:
        conn = sqlite3.connect(uri, uri=True, check_same_thread=False)
        conn.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except sqlite3.Error as e:
        raise RecordError(f"{path}: cannot read the {what}: {e}") from None
    return conn


def tables(conn: sqlite3.Connection) -> set[str]:
    return {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}


def size_on_disk(path: Path) -> int:
    """Bytes an SQLite database takes: the file and its write-ahead log."""
    total = 0
    for suffix in ("", "-wal"):
        f = path.with_name(path.name + suffix)
        if f.exists():
            total += f.stat().st_size
    return total
