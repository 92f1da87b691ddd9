"""`ctl history`: who did what, answered from the server's journal.

Each query opens the journal file a second time, read-only
(backend/files/record/journal.py), on a worker thread: reading through
100,000 changes never holds up an operation on the server's loop. It walks
the journal from the newest change back, keeps those matching every filter
(`HistoryRequest`: robot, user, since) up to `limit`, and answers them
oldest first, with `more` when older ones were left out (the limit, or the
reply's size: a whole mission loaded is a big change).

A change concerns the robots its operation names and those of its events
(a skill's robot; for a skill named only by its id, the robot that holds it
now, or held it when it was removed or moved: the journal is read newest first).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from backend.core import events as ev
from backend.files.record.journal import Batch, JournalReader
from backend.protocol.messages import HistoryEntry, HistoryReply, HistoryRequest

REPLY_BYTES = 8 << 20  # of batches' JSON in one reply, about


def split_actor(actor: str) -> tuple[str, str]:
    """(user, client) of an actor: 'user@client', else a client id or a robot
    (client ids never hold '@'; a user may: split at the last)."""
    user, at, client = actor.rpartition("@")
    return (user, client) if at else ("", actor)


def robots_of(b: Batch, owners: dict[str, str]) -> list[str]:
    """The robots a change concerns (see the module)."""
    found: list[str] = []

    def add(robot: object) -> None:
        if isinstance(robot, str) and robot and robot not in found:
            found.append(robot)

    add(b.op.get("robot"))
    for e in b.batch.events:
        concerns = _CONCERNS.get(type(e))
        if concerns is not None:
            for robot in concerns(e, owners):
                add(robot)
    return found


# -- the robots an event concerns, by its kind; `owners` learns who holds a skill


def _added(e: ev.SkillAdded, owners: dict[str, str]) -> tuple[str | None, ...]:
    owners[e.skill.id] = e.robot
    return (e.robot,)


def _left(e: ev.SkillRemoved | ev.SkillMoved, owners: dict[str, str]) -> tuple[str | None, ...]:
    owners.setdefault(e.id, e.robot)  # read newest first: its older changes come next
    return (e.robot,)


def _held(
    e: ev.SkillStatusChanged | ev.SkillEdited, owners: dict[str, str]
) -> tuple[str | None, ...]:
    return (owners.get(e.id),)


def _barrier(e: ev.BarrierSet, owners: dict[str, str]) -> tuple[str | None, ...]:
    return tuple(owners.get(sid) for sid in e.barrier.skills)


def _queued(e: ev.CommandQueued, owners: dict[str, str]) -> tuple[str | None, ...]:
    return (e.command.robot,)


_CONCERNS: dict[type[Any], Callable[[Any, dict[str, str]], tuple[str | None, ...]]] = {
    ev.SkillAdded: _added,
    ev.SkillRemoved: _left,
    ev.SkillMoved: _left,
    ev.SkillStatusChanged: _held,
    ev.SkillEdited: _held,
    ev.BarrierSet: _barrier,
    ev.CommandQueued: _queued,
}


def answer(db: Path, req: HistoryRequest, owners: dict[str, str]) -> HistoryReply:
    """The reply to `req` from journal `db`; `owners`: skill id -> robot now."""
    owners = dict(owners)
    since = req.since.timestamp() if req.since is not None else None
    entries: list[HistoryEntry] = []
    size = 0
    more = False
    with JournalReader(db) as journal:
        for row in journal.newest(since):
            entry = _entry(journal, row, req, owners)
            if entry is None:
                continue
            size += len(row[5])
            if _full(entries, size, req.limit):
                more = True
                break
            entries.append(entry)
    entries.reverse()
    return HistoryReply(entries=entries, more=more)


def _entry(
    journal: JournalReader, row: Any, req: HistoryRequest, owners: dict[str, str]
) -> HistoryEntry | None:
    """A journal row as the history shows it, if it passes the request's filters
    (the user's before the row is read; the robots' once its events are)."""
    user, client = split_actor(row[2])
    if req.user is not None and user != req.user:
        return None
    b = journal.read(row)
    robots = robots_of(b, owners)
    if req.robot is not None and req.robot not in robots:
        return None
    return HistoryEntry(
        revision=b.revision,
        at=b.batch_time(),
        actor=b.actor,
        user=user,
        client=client or b.client,
        op=b.name,
        robots=robots,
        batch=b.batch,
    )


def _full(entries: list[HistoryEntry], size: int, limit: int) -> bool:
    """The reply holds `limit` changes, or is too big for one more (one at least)."""
    return len(entries) >= limit or (bool(entries) and size > REPLY_BYTES)
