"""The telemetry archive beside a journal: its file, its schema, reading it.

The server writes it (backend/server/archive.py says what it keeps and for
how long): every robot's telemetry, downsampled, and the server's alerts and
the robots' presence changes, which the journal does not hold. Each sample
has two times: `at`, the robot's (when it was measured), and `received`,
the ground's (when the server took it), so a review can show it in either
clock. `ArchiveReader` reads it read-only.
"""

from __future__ import annotations

import operator
import sqlite3
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

from pydantic import ValidationError

from backend.core.clocks import GROUND, ROBOT
from backend.core.model import Pose
from backend.core.records import RecordError, open_read_only, size_on_disk, tables
from backend.protocol.messages import Alert, RobotInfo, Telemetry

# @2 added `recent` (the newest samples, not yet in `telemetry`); @1 files read as ever
ARCHIVE_FORMAT = "missionctl/telemetry-archive@2"
FORMATS = ("missionctl/telemetry-archive@1", ARCHIVE_FORMAT)

_SAMPLE_TABLE = """
CREATE TABLE IF NOT EXISTS {name} (
    id       INTEGER PRIMARY KEY,
    robot    TEXT NOT NULL,
    at       REAL NOT NULL,
    received REAL NOT NULL,
    x REAL, y REAL, z REAL, roll REAL, pitch REAL, yaw REAL,
    battery  REAL, link REAL, in_range INTEGER,
    mode     TEXT, skill TEXT, progress REAL, eta_s REAL, info TEXT
);"""

# `telemetry`: the samples, by robot in either clock (two indexes); `recent`:
# the newest ones, appended without an index (one B-tree a row, not three)
# and moved to `telemetry` in bulk by the writer (backend/server/archive.py)
SCHEMA = f"""
CREATE TABLE IF NOT EXISTS meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
{_SAMPLE_TABLE.format(name="telemetry")}
CREATE INDEX IF NOT EXISTS telemetry_ground ON telemetry (robot, received);
CREATE INDEX IF NOT EXISTS telemetry_robot ON telemetry (robot, at);
{_SAMPLE_TABLE.format(name="recent")}
CREATE TABLE IF NOT EXISTS notes (
    id   INTEGER PRIMARY KEY,
    kind TEXT NOT NULL,
    at   REAL NOT NULL,
    body TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS notes_at ON notes (at);
CREATE TABLE IF NOT EXISTS journal (
    revision INTEGER PRIMARY KEY,
    ts       REAL NOT NULL,
    op       TEXT NOT NULL,
    robot_at REAL,
    robot    TEXT
);
"""

SAMPLE_COLUMNS = (
    "robot, at, received, x, y, z, roll, pitch, yaw, battery, link, in_range, "
    "mode, skill, progress, eta_s, info"
)
_ROBOTS = "SELECT DISTINCT robot FROM {}"
ALERT, FLEET = "alert", "fleet"  # the kinds of note
M = TypeVar("M", Alert, RobotInfo)


def archive_path(db: str | Path) -> Path:
    """The archive beside journal `db`: mission.db -> mission.telemetry.db."""
    p = Path(db)
    return p.with_name(f"{p.stem}.telemetry{p.suffix or '.db'}")


# a sample's fields as the archive's columns, read from the models' __dict__ in one
# call each (17 attribute reads of the models were 1.7 us a row, most of its cost)
_POSE = operator.itemgetter("x", "y", "z", "roll", "pitch", "yaw")
_REST = operator.itemgetter(
    "battery", "link", "in_range", "mode", "skill", "progress", "eta_s", "info"
)


def sample_row(t: Telemetry, received: float) -> tuple[object, ...]:
    """A sample as the archive's columns (SAMPLE_COLUMNS); `in_range` a
    bool, which SQLite stores as the integer 1 or 0."""
    d = t.__dict__
    return (d["robot"], d["at"].timestamp(), received, *_POSE(d["pose"].__dict__), *_REST(d))


def _sample(row: tuple[Any, ...]) -> Telemetry:  # a telemetry row as SQLite gives it
    robot, at, _received, x, y, z, roll, pitch, yaw, battery, link, in_range, *rest = row
    mode, skill, progress, eta_s, info = rest
    return Telemetry.model_construct(
        robot=robot,
        pose=Pose.model_construct(x=x, y=y, z=z, roll=roll, pitch=pitch, yaw=yaw),
        battery=battery,
        link=link,
        in_range=bool(in_range),
        mode=mode,
        skill=skill,
        progress=progress,
        eta_s=eta_s,
        info=info or "",
        at=datetime.fromtimestamp(float(at), UTC),
    )


class Sample(NamedTuple):
    at: float  # when it shows, in the clock asked for
    telemetry: Telemetry


class ArchiveReader:
    """A telemetry archive opened read-only."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._conn = open_read_only(self.path, "telemetry archive")
        try:
            have = tables(self._conn)
            if not {"meta", "telemetry", "notes"} <= have:
                raise RecordError(f"{self.path}: not a missionctl telemetry archive")
            meta = dict(self._conn.execute("SELECT key, value FROM meta").fetchall())
            if meta.get("format") not in FORMATS:
                raise RecordError(
                    f"{self.path}: archive format {meta.get('format')!r} is not one of "
                    f"{', '.join(map(repr, FORMATS))}"
                )
            self.meta = meta
            # the samples' tables, oldest samples first (@1: `telemetry` alone)
            self._tables = ("telemetry", "recent") if "recent" in have else ("telemetry",)
            self.robots = sorted(  # the index's order (SQLite compares UTF-8 bytes)
                {r for t in self._tables for (r,) in self._conn.execute(_ROBOTS.format(t))}
            )
        except sqlite3.Error as e:
            self.close()
            raise RecordError(f"{self.path}: cannot read the telemetry archive: {e}") from None
        except RecordError:
            self.close()
            raise

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> ArchiveReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @staticmethod
    def _column(clock: str) -> str:
        return "received" if clock == GROUND else "at" if clock == ROBOT else ""

    def _newest(self, cols: str, robot: str, t: float, col: str, n: int) -> list[tuple[Any, ...]]:
        """Rows (`col` first, then `cols`) of the robot's last `n` samples at or
        before `t` in `col`, newest first (ties: the newer written first): from
        each table (`recent` holds the newest, a few minutes, unindexed), merged."""
        rows: list[tuple[Any, ...]] = []
        for table in reversed(self._tables):
            rows += self._conn.execute(
                f"SELECT {col}, {cols} FROM {table} WHERE robot = ? AND {col} <= ? "
                f"ORDER BY {col} DESC, id DESC LIMIT ?",
                (robot, t, n),
            ).fetchall()
        if len(self._tables) > 1:
            rows.sort(key=_first, reverse=True)  # stable: ties stay newer first
            del rows[n:]
        return rows

    def last_samples(self, robot: str, t: float, clock: str, n: int) -> list[Sample]:
        """The robot's last `n` samples at or before `t` of `clock`, oldest first."""
        rows = self._newest(SAMPLE_COLUMNS, robot, t, self._column(clock), n)
        return [Sample(row[0], _sample(row[1:])) for row in reversed(rows)]

    def last_levels(self, robot: str, t: float, clock: str, n: int) -> list[tuple[float, float]]:
        """(battery, link) of the robot's last `n` samples at or before `t` of
        `clock`, oldest first: a sparkline's, without making each sample."""
        rows = self._newest("battery, link", robot, t, self._column(clock), n)
        return [(battery, link) for _, battery, link in reversed(rows)]

    def samples(self, after: float, upto: float, clock: str) -> Iterator[Sample]:
        """Every robot's samples with `after` < time <= `upto` in `clock`, in
        time order: a range of each robot's index (over all robots at once,
        SQLite scanned the whole table for playing's every step), then the
        newest ones not yet indexed (`recent`: a few minutes' worth)."""
        col = self._column(clock)
        where = f"{col} > ? AND {col} <= ? ORDER BY {col}, id"
        select = f"SELECT {col}, {SAMPLE_COLUMNS} FROM"
        rows = [
            row
            for r in self.robots
            for row in self._conn.execute(
                f"{select} telemetry WHERE robot = ? AND {where}", (r, after, upto)
            )
        ]
        if "recent" in self._tables:
            rank = {r: k for k, r in enumerate(self.robots)}
            news = self._conn.execute(f"{select} recent WHERE {where}", (after, upto)).fetchall()
            news.sort(key=lambda row: rank.get(row[1], len(rank)))  # as the index: by robot
            rows += news
        rows.sort(key=_first)  # stable: ties in robot order, as the index
        for row in rows:
            yield Sample(row[0], _sample(row[1:]))

    def journal_index(self, after: int) -> list[tuple[int, float, str, float | None, str | None]]:
        """The journal's batches after revision `after` as the server indexed
        them: (revision, journal time, operation, robot time or None, robot or None)."""
        if "journal" not in tables(self._conn):  # an archive older than the index
            return []
        return self._conn.execute(
            "SELECT revision, ts, op, robot_at, robot FROM journal WHERE revision > ? "
            "ORDER BY revision",
            (after,),
        ).fetchall()

    def span(self, clock: str) -> tuple[float, float] | None:
        """The first and last sample's time in `clock` (None: no sample): the
        ends of each robot's index (min() and max() over the whole table
        scanned it: 10 ms at 74,000 samples, asked at every step of playing),
        and of the few newest not yet indexed."""
        if not self.robots:
            return None
        col = self._column(clock)
        one = (  # one min() or max() a subquery: SQLite reads the index's end
            f"SELECT (SELECT min({col}) FROM telemetry WHERE robot = ?) AS lo, "
            f"(SELECT max({col}) FROM telemetry WHERE robot = ?) AS hi"
        )
        parts = [one] * len(self.robots)
        if "recent" in self._tables:
            parts.append(f"SELECT min({col}), max({col}) FROM recent")
        sql = f"SELECT min(lo), max(hi) FROM ({' UNION ALL '.join(parts)})"
        lo, hi = self._conn.execute(sql, [r for r in self.robots for _ in "lh"]).fetchone()
        return None if lo is None else (lo, hi)

    # -- alerts and presence ---------------------------------------------------------------
    def alerts(self, after: float, upto: float, limit: int = -1) -> list[Alert]:
        """The server's alerts raised in (after, upto], oldest first (with
        `limit`, the last ones)."""
        rows = self._conn.execute(
            "SELECT body FROM notes WHERE kind = ? AND at > ? AND at <= ? "
            "ORDER BY at DESC, id DESC LIMIT ?",
            (ALERT, after, upto, limit),
        ).fetchall()
        return [a for a in (_read(Alert, body) for (body,) in reversed(rows)) if a is not None]

    def presence(self, upto: float) -> dict[str, RobotInfo]:
        """Each robot's last presence (fleet) news at or before `upto`."""
        rows = self._conn.execute(
            "SELECT body FROM notes WHERE kind = ? AND at <= ? ORDER BY at, id", (FLEET, upto)
        )
        out: dict[str, RobotInfo] = {}
        for (body,) in rows:
            info = _read(RobotInfo, body)
            if info is not None:
                out[info.name] = info
        return out

    def fleet(self, after: float, upto: float) -> list[tuple[float, RobotInfo]]:
        rows = self._conn.execute(
            "SELECT at, body FROM notes WHERE kind = ? AND at > ? AND at <= ? ORDER BY at, id",
            (FLEET, after, upto),
        )
        return [(at, info) for at, body in rows if (info := _read(RobotInfo, body)) is not None]

    def size_bytes(self) -> int:
        return size_on_disk(self.path)


def _first(row: tuple[Any, ...]) -> Any:
    return row[0]


def _read(model: type[M], body: str) -> M | None:
    try:
        return model.model_validate_json(body)
    except ValidationError:
        return None  # written by another version: left out, the rest still shows
