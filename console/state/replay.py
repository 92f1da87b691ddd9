"""A recorded mission played into the console's model — no Textual here.

`Replay` feeds a `ConsoleModel` from a journal (and its telemetry archive)
instead of a live client: the same typed events (`StateSynced`,
`BatchApplied`, `TelemetryReceived`, `AlertRaised`, `RobotChanged`) through
the same `ConsoleModel.take`, so every screen shows the mission as it was,
and the model's clock reads the replay's time (ages, freshness, the
timeline's now). The cursor is a position in a clock's order of the
journal's batches (`backend.core.clocks`: the first `position`
batches applied) and a time `at`:

- `seek(t)`: the model is emptied and given the mission at `t` as a
  state (the journal's nearest snapshot before it and the batches after
  that), then, in time order, the `LOG_WINDOW` batches before `t` for the
  log only (the state holds them), the alerts and presence news up to `t`
  and each robot's last sample with its sparkline's levels: the log, the
  alerts and the fleet's history are as a console watching then would
  have them (the window's part of them);
- `step(+1/-1)`: the next batch (with what the archive holds up to its
  time) is taken, or back to the previous one (a seek);
- `advance(seconds)`: the time moves on (playing at a speed), everything up
  to it is taken;
- `set_clock(GROUND | ROBOT)`: the same instant in the other clock.

In robot time the batches come in another order than their revisions (the
model is told: `ConsoleModel.ordered`); one that cannot apply yet (a robot
clock far behind the ground's) waits until what it needs was taken, or is
counted in `unplaced`.
"""

from __future__ import annotations

import gc
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime

from backend.client.events import (
    AlertRaised,
    BatchApplied,
    RobotChanged,
    StateSynced,
    TelemetryReceived,
)
from backend.client.mapfollow import MapUpdate
from backend.core import events as ev
from backend.core.bulk import gc_paused
from backend.core.clocks import GROUND, ROBOT
from backend.core.durations import duration_s
from backend.core.events import EventBatch
from backend.core.library import Library
from backend.core.model import Mission
from backend.files.record.journal import JournalReader, missing
from backend.protocol.archive import ArchiveReader, Sample
from backend.protocol.messages import ALERTS_KEPT, Alert, RobotInfo, StateSnapshot
from console.state.changes import MapFed, ModelEvent, StateChange, Topic, change
from console.state.model import HISTORY, ConsoleModel, heard_in

LOG_WINDOW = 200  # batches before the cursor the log shows after a seek
SERVER_ID = "review"
CLOCK_WORDS = {GROUND: "ground time", ROBOT: "robot time"}
MAP_NOTE = (
    "review: markers and goals from the journal, robots from the telemetry archive "
    "(the simulator's terrain and coverage are not recorded)"
)
SPEEDS = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0)


@dataclass
class Cursor:
    clock: str
    position: int  # the first `position` batches of the clock's order are applied
    at: float  # the time shown, seconds since the epoch


@dataclass
class Feed:
    """What one move of the cursor takes, in time order."""

    events: list[tuple[float, ModelEvent | HeldBatch]] = field(default_factory=list)

    def add(self, at: float, event: ModelEvent | HeldBatch) -> None:
        self.events.append((at, event))

    def sorted(self) -> Iterator[tuple[float, ModelEvent | HeldBatch]]:
        # stable: a batch and the samples at its time keep their order
        return iter(sorted(self.events, key=lambda e: e[0]))


class Replay:
    def __init__(
        self,
        model: ConsoleModel,
        journal: JournalReader,
        library: Library,
        archive: ArchiveReader | None = None,
    ) -> None:
        self.model = model
        self.journal = journal
        self.library = library
        self.archive = archive
        if archive is not None:  # the server's index of the journal by time: a fast start
            journal.use_index(archive.journal_index(journal.base))
        start = journal.start_time()
        self.cursor = Cursor(GROUND, 0, start if start is not None else 0.0)
        self.unplaced: list[int] = []  # revisions left out (robot time)
        self._waiting: list[EventBatch] = []
        self._syncs: list[tuple[int, str, float, float]] | None = None  # (index, skill, span)
        self._owners: dict[str, str] = {}  # skill -> robot along a seek's window
        model.clock.wall = self.now  # the recording's time is the wall the views read
        model.map_note = MAP_NOTE

    # -- the time -------------------------------------------------------------------------
    def now(self) -> datetime:
        return datetime.fromtimestamp(self.cursor.at, UTC)

    @property
    def clock(self) -> str:
        return self.cursor.clock

    def span(self) -> tuple[float, float]:
        """The first and last instants there is something to show."""
        j = self.journal
        lo, hi = j.start_time(), j.end_time()
        if self.archive is not None:
            s = self.archive.span(self.cursor.clock)
            if s is not None:
                lo = s[0] if lo is None else min(lo, s[0])
                hi = s[1] if hi is None else max(hi, s[1])
        return (lo or 0.0, hi or lo or 0.0)

    # -- moving --------------------------------------------------------------------------
    def seek(self, t: float) -> StateChange:
        """Everything as it was at `t` (of the cursor's clock)."""
        order = self.journal.order(self.cursor.clock)
        return self._seek(order.position_at(t), t)

    def seek_position(self, position: int) -> StateChange:
        order = self.journal.order(self.cursor.clock)
        position = max(0, min(position, len(order)))
        at = order.time_of(position)
        return self._seek(position, at if at is not None else self.span()[0])

    def set_clock(self, clock: str) -> StateChange:
        """The same instant, in the other clock."""
        self.cursor.clock = clock
        return self.seek(self.cursor.at)

    def step(self, by: int) -> StateChange:
        """To the next (+1) or previous (-1) batch of the clock's order."""
        if by < 0:
            return self.seek_position(self.cursor.position + by)
        order = self.journal.order(self.cursor.clock)
        p = min(len(order), self.cursor.position + by)
        at = order.time_of(p)
        if p == self.cursor.position or at is None:
            return change()
        return self._forward(p, max(at, self.cursor.at))

    def advance(self, seconds: float) -> StateChange:
        """Time moves on by `seconds` (of the clock): everything up to then."""
        t = self.cursor.at + seconds
        order = self.journal.order(self.cursor.clock)
        return self._forward(order.position_at(t), t)

    def seek_revision(self, revision: int) -> StateChange:
        """To the instant batch `revision` happened in the cursor's clock."""
        j = self.journal
        i = revision - j.base - 1
        if not 0 <= i < len(j):
            raise ValueError(
                f"no revision {revision} to show: this journal holds {j.base + 1} to {j.last}"
            )
        return self.seek(j.order(self.cursor.clock).keys[i])

    @property
    def at_end(self) -> bool:
        return self.cursor.at >= self.span()[1]

    # -- feeding the model ---------------------------------------------------------------------
    def _forward(self, position: int, t: float) -> StateChange:
        feed = Feed()
        order = self.journal.order(self.cursor.clock)
        indices = order.order[self.cursor.position : position]
        batches = self.journal.pick(indices)
        for i in indices:
            feed.add(order.keys[i], BatchApplied(batches[i].batch))
        self._archive(feed, self.cursor.at, t)
        self.cursor.position, before = position, self.cursor.at
        self._read_planned(position)
        c = self._take(feed, before)
        self.cursor.at = t
        return c

    def _seek(self, position: int, t: float) -> StateChange:
        """Everything as it was at batch `position`, time `t`. The state is a
        whole mission (150,000 objects at 2,700 skills): the collector walked
        it in each young generation right after (25 ms) and whole every few
        seeks (40-100 ms). It is built without the collector and frozen out
        of its walks (gc.freeze) until the next seek, which drops it (freed
        by reference counting) and gives the collector back the rest."""
        gc.unfreeze()
        with gc_paused():
            c = self._rebuild(position, t)
            gc.freeze()
        return c

    def release(self) -> None:
        """Give the collector back what the last seek froze (the review ends)."""
        gc.unfreeze()

    def _rebuild(self, position: int, t: float) -> StateChange:
        clock = self.cursor.clock
        order = self.journal.order(clock)
        start = max(0, position - LOG_WINDOW)
        # the state at the instant at once (from the snapshot nearest before it),
        # and the window's batches for the log only: never the state at the
        # window's start, which may lie before that snapshot (a whole spacing more)
        state = self.journal.state(position, clock, window=position - start)
        self.unplaced = []
        held = self.journal.events(r - self.journal.base - 1 for r in state.unplaced)
        self._waiting = list(held.values())  # a later batch may still let them apply
        forget(self.model)
        self.model.ordered = clock == GROUND
        window_t = order.time_of(start) if start else self.span()[0]
        feed = Feed()
        for batch, by in state.recent:
            feed.add(order.keys[by], HeldBatch(batch))
        self._archive(feed, window_t or t, t, seek=True)
        self._load(state.mission, window_t or t)
        self._owners = window_owners(self.model, [b for b, _ in state.recent])
        self.cursor.position = position
        self._read_planned(position)
        c = self._take(feed, window_t or t)
        self.cursor.at = t
        return change(*(c.topics | {Topic.MISSION, Topic.FLEET, Topic.CONNECTION}), loaded=True)

    def _load(self, mission: Mission, t: float) -> None:
        presence = self.archive.presence(t) if self.archive is not None else {}
        robots = {name: presence.get(name, RobotInfo(name=name)) for name in mission.robots}
        snap = StateSnapshot(
            server_id=SERVER_ID,
            revision=mission.revision,
            mission=mission,
            library=self.library,
            robots=robots,
        )
        self.cursor.at = t
        self.model.take(StateSynced(snap))
        self.model.take(MapFed(None, MapUpdate("none", detail="a review")))

    def _archive(self, feed: Feed, after: float, upto: float, *, seek: bool = False) -> None:
        """The archive's samples, alerts and presence news in (after, upto];
        after a seek, each robot's last samples and the last alerts before it too."""
        a = self.archive
        if a is None:
            return
        clock = self.cursor.clock
        if seek:
            samples, alerts = self._before(a, upto, clock)
        else:
            samples, alerts = list(a.samples(after, upto, clock)), a.alerts(after, upto)
        for s in samples:
            feed.add(s.at, TelemetryReceived(s.telemetry))
        for alert in alerts:
            feed.add(alert.at.timestamp(), AlertRaised(alert))
        for at, info in a.fleet(after, upto):
            feed.add(at, RobotChanged(info))

    def _before(
        self, a: ArchiveReader, upto: float, clock: str
    ) -> tuple[list[Sample], list[Alert]]:
        """What a seek to `upto` shows of the archive before it: each robot's
        last sample (the levels before it are its sparkline, set as such) and
        the last alerts."""
        samples = [s for r in a.robots for s in a.last_samples(r, upto, clock, 1)]
        for r in a.robots:
            if levels := a.last_levels(r, upto, clock, HISTORY):
                self.model.history[r] = deque(levels[:-1], maxlen=HISTORY)
        return samples, a.alerts(-1e18, upto, ALERTS_KEPT)

    def _take(self, feed: Feed, start: float) -> StateChange:
        """Each event at its time (the model's clock reads it); one change for all."""
        topics: set[Topic] = set()
        robots: set[str] | None = set()
        for at, event in feed.sorted():
            self.cursor.at = max(start, at)
            if isinstance(event, HeldBatch):
                self._log(event.batch)
                topics.add(Topic.LOG)
                continue
            if isinstance(event, BatchApplied) and not self._placeable(event):
                continue
            c = self.model.take(event)
            topics |= c.topics
            robots = None if robots is None or c.robots is None else robots | c.robots
            if isinstance(event, BatchApplied):
                self._retry_waiting(topics)
        return change(*topics, robots=robots)

    def _log(self, batch: EventBatch) -> None:
        """A batch the state holds already: its log lines and who was heard,
        as when it applied, with the skill index as it was then."""
        for e in batch.events:
            _redo(self._owners, e)
        m, owner = self.model, self._owners.get
        heard_in(m.heard, batch, owner, m.clock())
        m.log.add_batch(batch, owner, m.clock())

    def _placeable(self, event: BatchApplied) -> bool:
        """In robot time, a batch that refers to what is not taken yet waits."""
        m = self.model.mission
        if self.model.ordered or m is None or missing(m, event.batch) is None:
            return True
        self._waiting.append(event.batch)
        return False

    def _retry_waiting(self, topics: set[Topic]) -> None:
        m = self.model.mission
        while self._waiting and m is not None:
            ready = [w for w in self._waiting if missing(m, w) is None]
            if not ready:
                return
            for w in ready:
                self._waiting.remove(w)
                topics |= self.model.take(BatchApplied(w)).topics
            m = self.model.mission

    # -- the plan as synchronized ----------------------------------------------------------------
    def _read_planned(self, position: int) -> None:
        """The forecasts sent with the syncs among the first `position` batches
        of the clock's order, the latest for each skill (the timeline draws them)."""
        if self._syncs is None:
            self._syncs = [
                (i, sid, start, end)
                for i, forecast in self.journal.syncs()
                for sid, (start, end) in forecast.items()
            ]
        pos = self.journal.order(self.cursor.clock).pos
        self.model.plan.planned = {
            sid: (start, end) for i, sid, start, end in self._syncs if pos[i] < position
        }

    # -- words ----------------------------------------------------------------------------------
    def where(self) -> str:
        """'ground time 14:32:05 · batch 1234/5000 (revision 1240)'."""
        n = len(self.journal.order(self.cursor.clock))
        when = datetime.fromtimestamp(self.cursor.at).astimezone().strftime("%H:%M:%S")
        rev = self.model.mission.revision if self.model.mission is not None else "-"
        left = len(self.unplaced) + len(self._waiting)
        unplaced = f" · {left} not placed in robot time" if left else ""
        return (
            f"{CLOCK_WORDS[self.cursor.clock]} {when} · "
            f"{self.cursor.position}/{n} changes (rev {rev}){unplaced}"
        )


@dataclass(frozen=True)
class HeldBatch:
    """A batch the shown state holds already: a seek's window, for the log."""

    batch: EventBatch


def window_owners(model: ConsoleModel, window: list[EventBatch]) -> dict[str, str]:
    """skill -> robot before the window's first batch: the shown state's index
    with the window's additions and removals undone (a mission replaced in
    the window is not undone: its skills are named from the index after it)."""
    assert model.mission is not None
    owners = owners_of(model.mission)
    for batch in reversed(window):
        for e in reversed(batch.events):
            _undo(owners, e)
    return owners


def owners_of(mission: Mission) -> dict[str, str]:
    return {s.id: r for r, task in mission.tasks.items() for s in task}


def _undo(owners: dict[str, str], e: object) -> None:
    if isinstance(e, ev.SkillAdded):
        owners.pop(e.skill.id, None)
    elif isinstance(e, ev.SkillRemoved):
        owners[e.id] = e.robot


def _redo(owners: dict[str, str], e: object) -> None:
    if isinstance(e, ev.SkillAdded):
        owners[e.skill.id] = e.robot
    elif isinstance(e, ev.SkillRemoved):
        owners.pop(e.id, None)
    elif isinstance(e, ev.MissionReplaced):
        owners.clear()
        owners.update(owners_of(e.mission))


def forget(model: ConsoleModel) -> None:
    """Empty the model (going to another instant); the log and the alert
    book in place: the screens showing them keep them. The mission stays
    until the next is loaded: a load that is not the first digests no plan
    to tell unsaved edits by (a review saves nothing; 15-25 ms a seek), and
    its load indexes it."""
    for kept in (model.robots, model.telemetry, model.history, model.heard):
        kept.clear()
    model.log.clear()
    model.alerts.clear()
    model.selection.marks.clear()


# -- where to go, as typed -------------------------------------------------------------------

GOTO_HELP = "14:32 or 14:32:05 (that day), +10m / -30s (from here), #120 (a revision)"


def parse_goto(text: str, now: float) -> tuple[str, float]:
    """("time", t) or ("revision", n) for what a person typed (GOTO_HELP);
    ValueError with a sentence when it is none of them."""
    s = text.strip()
    if s.startswith("#") or s.lower().startswith("rev"):
        digits = s.lstrip("#").lower().removeprefix("revision").removeprefix("rev").strip()
        if digits.isdigit():
            return "revision", float(digits)
    elif s[:1] in "+-":
        d = duration_s(s[1:])
        if d is not None:
            return "time", now + (d if s[0] == "+" else -d)
    else:
        try:
            return "time", _clock_time(s, now)
        except ValueError:
            pass
    raise ValueError(f"cannot go to {s!r}: give {GOTO_HELP}")


def _clock_time(s: str, now: float) -> float:
    if "T" in s or "-" in s:
        d = datetime.fromisoformat(s)
        return (d if d.tzinfo else d.astimezone()).timestamp()
    day = datetime.fromtimestamp(now).astimezone()
    parts = [int(x) for x in s.split(":")]
    if len(parts) not in (2, 3):
        raise ValueError(s)
    h, m, sec = (*parts, 0) if len(parts) == 2 else parts
    return day.replace(hour=h, minute=m, second=sec, microsecond=0).timestamp()
