"""What the console knows, and what it derives from it — no Textual here.

`ConsoleModel` is the console's only mirror: the mission, the skill
library, the fleet (presence, manifests), the latest telemetry per robot,
the connection, the event log and the alerts. It takes the client library's
typed events as they are (`take`: a state, an event batch, a robot, a
telemetry sample, an alert, the connection, an unreadable message) and the
few the console says about itself (console/state/changes.py), applies each
through one path (batches through `backend.core.events.apply_events`, as the
server does) and answers one `StateChange`: which topics, which robots. Tests
feed it the same events, without a network. What the screens show is
derived here and beside it (console/state/text.py: glyphs, summaries;
availability.py: why an action does not apply).
"""

from __future__ import annotations

import hashlib
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from backend.client.events import (
    AlertRaised,
    BatchApplied,
    ConnectionState,
    Malformed,
    RobotChanged,
    StateSynced,
    TelemetryReceived,
)
from backend.core import events as ev
from backend.core.library import Library
from backend.core.model import ACTIVE, Mission, SkillInstance, Status, UplinkCommand
from backend.protocol.keys import Keys
from backend.protocol.messages import RobotInfo, StateSnapshot, Telemetry
from console.state import availability, link
from console.state.changes import (
    NOTHING,
    AccountKnown,
    Connecting,
    MapFed,
    ModelEvent,
    Previewed,
    StateChange,
    Topic,
    Unreachable,
    change,
)
from console.state.clock import MissionClock
from console.state.contact import out_of_contact
from console.state.eventlog import AlertBook, EventLog, Owner
from console.state.freshness import Freshness, freshness
from console.state.keys import KeyNames
from console.state.plan import PlanView
from console.state.site import SiteScore
from console.state.text import GLYPHS, STATUS_WORDS

HISTORY = 120  # telemetry samples kept per robot (bounded memory)

CONNECTING, CONNECTED, RECONNECTING, UNREACHABLE, OFFLINE = (
    "connecting",
    "connected",
    "reconnecting",
    "unreachable",
    "offline",
)
REVIEW = "review"  # a recording, not a server: there is no connection to show


# -- the model --------------------------------------------------------------------


# operations a robot's answer or report becomes (the robot was heard)
ROBOT_OPS = frozenset(
    {"report", "answer", "ask", "ask_ended", "sync_ack", "unsync_done", "retry_ack", "reconcile"}
)


def heard_in(heard: dict[str, datetime], batch: ev.EventBatch, owner: Owner, now: datetime) -> None:
    """Note in `heard` the robots a robot's answer or report in `batch` speaks
    for (it was alive `now`); `owner`: each skill's robot."""
    if batch.op in ROBOT_OPS:
        for e in batch.events:
            robot = owner(getattr(e, "id", "")) or getattr(e, "robot", None)
            if isinstance(robot, str):
                heard[robot] = now


PLAN_FIELDS = {"id", "skill", "label", "params", "bindings", "policies"}  # a skill, as planned
_PLAN: dict[str, Any] = {
    "tasks": {"__all__": {"__all__": PLAN_FIELDS}},
    "barriers": True,
    "markers": True,
}


def plan_digest(mission: Mission) -> str:
    """What a saved mission file holds of the plan, as a digest: skills
    (without their statuses), barriers and markers — two plans with the
    same digest save to the same file. One serializer call (pydantic's, in
    Rust): per-skill dumps took 0.2 s of a 10,000-skill mission's first frame."""
    raw = mission.model_dump_json(include=_PLAN)
    return hashlib.sha1(raw.encode()).hexdigest()


@dataclass
class Selection:
    """The schedule's selection, which other screens act on too (the map binds
    a marker to the selected skill): the skill under the schedule's cursor and
    the skills marked for a new barrier. The schedule widget keeps it."""

    skill: str | None = None
    marks: list[str] = field(default_factory=list)


def _kept_indexed(
    owner: dict[str, str], e: ev.SkillAdded | ev.SkillRemoved | ev.SkillMoved
) -> bool:
    """Keep the skill -> robot index in step with one event, if it can be
    without a rebuild (a review's seek takes 200 batches: a rebuild each was
    a third of it). An added skill is in no barrier yet; a moved one stays
    with its robot; a removal rebuilds (barriers may lose it)."""
    if isinstance(e, ev.SkillAdded):
        owner[e.skill.id] = e.robot
    return not isinstance(e, ev.SkillRemoved)


def _touches_after(m: Mission, batch: ev.EventBatch) -> bool:
    """The batch sets, clears or removes an `after` (policies.after): the rows
    at both of its ends carry a tag, in two robots' columns."""
    return any(_after_event(m, e) for e in batch.events)


def _after_event(m: Mission, e: ev.Event) -> bool:
    if isinstance(e, ev.SkillEdited) and e.policies is not None:
        return e.policies.after is not None or _after_of(m, e.id) is not None
    return isinstance(e, ev.SkillRemoved) and _after_of(m, e.id) is not None


def _doing(s: SkillInstance) -> str:
    """Its status in words; one waiting on board for its `after`, not at a barrier, says so."""
    if s.status == Status.SYNCHWAITING and s.status_info.startswith("after "):
        return f"after {s.policies.after}"
    return STATUS_WORDS[s.status]


def _progress(act: SkillInstance, t: Telemetry | None) -> str:
    """' 42%': how far the running skill is, when its robot's telemetry says."""
    if t is None or t.progress is None or t.skill != act.id or act.status != Status.RUNNING:
        return ""
    return f" {int(t.progress * 100)}%"


def _idle_text(mode: str, queued: int) -> str:
    """A robot without an active skill: its mode, and the skills it has queued."""
    if queued:
        return f"{mode if mode and mode != 'idle' else 'halted'} · {queued} queued"
    return mode or "idle"


def _after_of(m: Mission, sid: str) -> str | None:
    found = m.find(sid)
    return found[2].policies.after if found is not None else None


# what one event shows in the schedule: the robots whose columns change, and
# whether the skill -> robot index must be rebuilt for it
_Columns = tuple[Iterable[str], bool]


@dataclass
class ConsoleModel:
    mission: Mission | None = None
    library: Library | None = None
    robots: dict[str, RobotInfo] = field(default_factory=dict)
    telemetry: dict[str, Telemetry] = field(default_factory=dict)
    connection: str = OFFLINE
    connection_detail: str = ""
    endpoint: str = ""
    server_id: str = ""
    read_only: str = ""  # why nothing can be changed from here ("": it can): an observer
    observer: str = ""  # why it never changes anything, whatever its account (a browser)
    # skill id -> robot, skill id -> barrier id (kept in step with the mission)
    _owner: dict[str, str] = field(default_factory=dict)
    _barrier_of: dict[str, str] = field(default_factory=dict)
    # robot -> (active skill, number queued), computed on demand
    _robot_state: dict[str, tuple[SkillInstance | None, int]] = field(default_factory=dict)
    # robot -> the last HISTORY (battery, link) samples, for the fleet screen's sparklines
    history: dict[str, deque[tuple[float, float]]] = field(default_factory=dict)
    selection: Selection = field(default_factory=Selection)
    # the plan as this console last saved or loaded it (or first got it): plan_digest
    saved_digest: str = ""
    # robot -> when this console last heard it (telemetry, a report, presence back)
    heard: dict[str, datetime] = field(default_factory=dict)
    # now: the wall time when called (stamps), mission time for what is shown (state/clock.py)
    clock: MissionClock = field(default_factory=MissionClock)
    # skill id -> its pending command's lock, for the revision it was built at
    _uplinking: tuple[int, dict[str, UplinkCommand]] = field(default_factory=lambda: (-1, {}))
    # the plan's forecast and checks (console/state/plan.py), refreshed by the app
    plan: PlanView = field(default_factory=PlanView)
    # the simulator's score from its map feed (None: no simulator; its time is the clock's)
    site: SiteScore | None = None
    previewing: bool = False  # what is shown is a mission file's plan, not the server's yet
    keys: KeyNames = field(default_factory=KeyNames)  # the user's keys, for sentences
    map_mirror: Any = None  # the map feed's mirror (None: no feed yet): mapfollow
    map_update: Any = None  # its last update (mapfollow.MapUpdate)
    map_note: str = ""  # why there is no map feed, when that is known (a review)
    # what happened (bounded), and what needs a person
    log: EventLog = field(default_factory=EventLog)
    alerts: AlertBook = field(default_factory=AlertBook)
    ordered: bool = True  # False: batches in another order than revisions (replay.py)

    # -- taking events --------------------------------------------------------------
    def take(self, event: ModelEvent) -> StateChange:
        """Apply one event; what changed."""
        match event:
            case StateSynced(snapshot=snap):
                return self._synced(snap)
            case BatchApplied(batch=batch):
                return self._applied(batch)
            case RobotChanged(robot=info):
                self.set_robot(info)
                return change(Topic.FLEET, robots={info.name})
            case TelemetryReceived(telemetry=t):
                self.set_telemetry(t)
                return change(Topic.TELEMETRY, robots={t.robot})
            case AlertRaised(alert=a):
                entry = self.alerts.from_server(a, self.server_id)
                return self._raised(entry)
            case Malformed():
                robot = Keys.robot_of(event.key) if "/robot/" in event.key else None
                entry = self.alerts.add("malformed", event.sentence(), self.clock(), robot=robot)
                return self._raised(entry)
            case _:
                return self._connection(event)

    def _connection(self, event: ModelEvent) -> StateChange:
        match event:
            case ConnectionState(state=state):
                self.connection, self.connection_detail = state, ""
            case Connecting(endpoint=endpoint, detail=detail):
                self.connection, self.connection_detail = CONNECTING, detail
                self.endpoint = endpoint
            case Unreachable(detail=detail):
                self.connection, self.connection_detail = UNREACHABLE, detail
            case AccountKnown(read_only=read_only):
                self.read_only = self.observer or read_only
            case Previewed(mission=mission, library=library) if self.mission is None:
                self.load(mission, library)  # (the server's state came first: nothing)
                self.previewing = True
                return change(Topic.MISSION, Topic.FLEET, loaded=True)
            case MapFed():
                return self._map_fed(event)
            case _:
                return NOTHING
        return change(Topic.CONNECTION)

    def _map_fed(self, fed: MapFed) -> StateChange:
        """The map feed moved; a simulator's brings the site's score and the
        mission clock (the simulator's time is the mission's)."""
        self.map_mirror, self.map_update = fed.mirror, fed.update
        topics = {Topic.MAP}
        if (objects := getattr(fed.mirror, "objects", None)) is not None:  # a simulator
            self.site = SiteScore(objects.score)
            if not self.clock.simulated:  # the times shown so far were wall times
                topics |= {Topic.MISSION, Topic.FLEET}
            self.clock.heard(
                fed.mirror.sim_time, getattr(fed.mirror, "speed", None) or fed.speed or 1.0
            )
        return change(*topics, map_update=fed.update)

    def _synced(self, snap: StateSnapshot) -> StateChange:
        """A whole state: the first, or after a gap or a server restart. The
        server's alerts in it that this console has not taken are news (none
        on the first: they happened before it looked)."""
        if self.previewing:  # the file's plan was no state: this is the first
            self.mission, self.previewing = None, False
        first = self.mission is None
        self.load(snap.mission, snap.library, snap.robots, snap.server_id)
        if first:
            self.alerts.seen(snap.alerts, snap.server_id)
        raised = []
        for a in snap.alerts:
            entry = self.alerts.from_server(a, snap.server_id)
            if entry is not None:
                raised.append(entry)
                if entry.kind == "failure":  # its report never reached this console
                    self.log.add("failure", entry.message, entry.at, **_about(entry))
                else:
                    self.log.add("alert", entry.message, entry.at, client="server", **_about(entry))
        topics = [Topic.MISSION, Topic.FLEET, Topic.CONNECTION]
        if raised:
            topics += [Topic.ALERTS, Topic.LOG]
        return change(*topics, loaded=True, alerts=tuple(raised))

    def _applied(self, batch: ev.EventBatch) -> StateChange:
        if self.mission is None or (self.ordered and batch.revision <= self.mission.revision):
            return NOTHING  # in the state already
        robots = self.apply(batch)
        self.log.add_batch(batch, self.owner, self.clock())
        moved = tuple(
            e.skill.id if isinstance(e, ev.SkillAdded) else e.id
            for e in batch.events
            if isinstance(e, ev.SkillAdded | ev.SkillMoved)
        )
        return change(Topic.MISSION, Topic.LOG, robots=robots, revision=batch.revision, moved=moved)

    def _raised(self, entry: Any) -> StateChange:
        if entry is None:  # taken already, or counted up
            return change(Topic.ALERTS)
        if entry.kind != "failure":  # a failure is a log line already (the report's)
            self.log.add("alert", entry.message, entry.at, client=entry.source, **_about(entry))
        return change(Topic.ALERTS, Topic.LOG, alerts=(entry,))

    # -- updates ------------------------------------------------------------------
    def load(
        self,
        mission: Mission,
        library: Library,
        robots: dict[str, RobotInfo] | None = None,
        server_id: str = "",
    ) -> None:
        first = self.mission is None
        self.mission = mission
        self.library = library
        if first:  # what the server had: the plan from its file (the demo's), or journal
            self.mark_saved()
        if robots is not None:
            self.robots = dict(robots)
        for name in mission.robots:
            self.robots.setdefault(name, RobotInfo(name=name))
        self.server_id = server_id
        self.reindex()

    def reindex(self) -> None:
        self._robot_state.clear()
        m = self.mission
        self._owner = {s.id: r for r, task in m.tasks.items() for s in task} if m else {}
        self._barrier_of = (
            {sid: bid for bid, b in m.barriers.items() for sid in b.skills} if m else {}
        )

    def apply(self, batch: ev.EventBatch) -> set[str] | None:
        """Apply an event batch (the one path: `apply_events`). Returns the
        robots whose columns changed, or None when everything may have changed
        (an old batch, in the state already: none)."""
        if self.mission is None:
            return None
        if self.ordered and batch.revision <= self.mission.revision:
            return set()
        tags = _touches_after(self.mission, batch)  # partner rows' tags change (before it applies)
        self.mission = ev.apply_events(self.mission, batch)
        heard_in(self.heard, batch, self._owner.get, self.clock())
        touched = _touched(self, batch.events)
        if touched is None:
            self._reshaped()
            return None
        robots, unindexed, tagging = touched
        tags = tags or tagging
        self._recache(robots, unindexed or tags)
        return None if tags else robots  # tags of partner rows in other columns change too

    def _recache(self, robots: set[str], rebuild: bool) -> None:
        """Forget the cached state of the robots whose columns changed, or
        rebuild the indexes (which forgets every robot's)."""
        if rebuild:
            self.reindex()
        else:
            for r in robots:
                self._robot_state.pop(r, None)

    def _reshaped(self) -> None:
        """The mission was replaced, or a robot joined or left: every column
        may have changed (None), the fleet lists each of its robots."""
        assert self.mission is not None
        for name in self.mission.robots:
            self.robots.setdefault(name, RobotInfo(name=name))
        self.reindex()

    def _shown_by(self, sid: str) -> set[str] | None:
        """The columns that show skill `sid`'s state: its robot's and, at a
        barrier, its partners' (they say what they wait for); None when the
        skill is not indexed yet."""
        assert self.mission is not None
        r = self._owner.get(sid)
        if r is None:
            return None
        out = {r}
        bid = self._barrier_of.get(sid)
        if bid is not None and bid in self.mission.barriers:
            out.update(
                self._owner[x] for x in self.mission.barriers[bid].skills if x in self._owner
            )
        return out

    def mark_saved(self) -> None:
        """The plan was just saved to (or loaded from) a file."""
        self.saved_digest = plan_digest(self.mission) if self.mission is not None else ""

    @property
    def unsaved(self) -> bool:
        """The plan differs from what was last saved or loaded (or first shown)."""
        return self.mission is not None and plan_digest(self.mission) != self.saved_digest

    def quit_risks(self) -> list[str]:
        """What quitting now would walk away from: robots executing, commands
        not yet acknowledged, plan edits not saved to a file (sentences)."""
        risks: list[str] = []
        busy = []
        for robot in self.robot_order():
            act = self.robot_state(robot)[0]
            if act is not None:
                busy.append(f"{robot} is {STATUS_WORDS[act.status]} ({act.id})")
        if busy:
            risks.append("; ".join(busy))
        waiting = link.risks(self.mission, self.clock)
        if waiting:
            risks.append("commands not yet acknowledged — " + "; ".join(waiting))
        if self.unsaved:
            risks.append("the plan has changes not saved to a file")
        return risks

    def set_robot(self, info: RobotInfo) -> None:
        self.robots[info.name] = info
        if info.online and not out_of_contact(info):  # (its window closing is no word from it)
            self.heard[info.name] = self.clock()

    def set_telemetry(self, t: Telemetry) -> None:
        self.telemetry[t.robot] = t
        self.heard[t.robot] = self.clock()
        h = self.history.get(t.robot)
        if h is None:
            h = self.history[t.robot] = deque(maxlen=HISTORY)
        h.append((t.battery, t.link))

    # -- lookups --------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self.connection == CONNECTED

    def owner(self, skill_id: str) -> str | None:
        return self._owner.get(skill_id)

    def barrier_of(self, skill_id: str) -> str | None:
        return self._barrier_of.get(skill_id)

    def find(self, skill_id: str | None) -> tuple[str, int, SkillInstance] | None:
        # the owner index answers "no such skill" at once (a scan of the mission
        # otherwise); Mission.find remembers where it saw the others
        if skill_id is None or self.mission is None or skill_id not in self._owner:
            return None
        return self.mission.find(skill_id)

    def task(self, robot: str) -> list[SkillInstance]:
        if self.mission is None:
            return []
        return self.mission.tasks.get(robot, [])

    def insertion_point(self, robot: str, skill_id: str | None) -> tuple[int, str]:
        """Where a new skill goes in the robot's plan (index among its idle
        skills, and in words): after the selected idle skill, else first."""
        found = self.find(skill_id)
        if found and found[2].status == Status.IDLE:
            idle = [s.id for s in self.task(robot) if s.status == Status.IDLE]
            return idle.index(found[2].id) + 1, f"after {found[2].id}"
        return 0, "at the head of the plan"

    def robot_kind(self, robot: str) -> str:
        if self.mission is None or self.library is None:
            return "dynamic"
        spec = self.mission.robots.get(robot)
        rt = self.library.robot_types.get(spec.type) if spec else None
        return rt.kind if rt else "dynamic"

    def robot_order(self) -> list[str]:
        """Dynamic robots first (mission order), static robots at the end."""
        if self.mission is None:
            return []
        names = list(self.mission.robots)
        return [r for r in names if self.robot_kind(r) == "dynamic"] + [
            r for r in names if self.robot_kind(r) == "static"
        ]

    def skills_of(self, robot: str) -> list[str]:
        if self.mission is None or self.library is None:
            return []
        spec = self.mission.robots.get(robot)
        return self.library.skills_of(spec.type) if spec else []

    def is_online(self, robot: str) -> bool:
        info = self.robots.get(robot)
        return bool(info and info.online)

    def presence_text(self, robot: str) -> str:
        info = self.robots.get(robot)
        if info is None:
            return "unknown"
        if info.online:
            return "online"
        if info.since is None:
            return "offline (not seen)"
        return f"offline since {self.clock.stamp_text(info.since)}"

    @staticmethod
    def active(task: list[SkillInstance]) -> SkillInstance | None:
        for s in task:
            if s.status in ACTIVE:
                return s
        return None

    def robot_state(self, robot: str) -> tuple[SkillInstance | None, int]:
        """(active skill, number of queued skills) of a robot, cached per change."""
        st = self._robot_state.get(robot)
        if st is None:
            task = self.task(robot)
            st = (self.active(task), sum(1 for s in task if s.status == Status.IDLE_SYNCHRONIZED))
            self._robot_state[robot] = st
        return st

    def activity_text(self, robot: str) -> str:
        """What the robot is doing: from telemetry when fresh, else the plan."""
        act, queued = self.robot_state(robot)
        t = self.telemetry.get(robot)
        if act is not None:
            return f"{GLYPHS[act.status]} {act.id} {_doing(act)}{_progress(act, t)}"
        return _idle_text(t.mode if t is not None else "", queued)

    def uplinking(self, sid: str) -> UplinkCommand | None:
        """The pending command to a robot that locks skill `sid`, if any."""
        rev = self.mission.revision if self.mission is not None else -1
        if self._uplinking[0] != rev:
            self._uplinking = (rev, link.uplinking(self.mission))
        return self._uplinking[1].get(sid)

    def pending(self, robot: str) -> list[UplinkCommand]:
        """The robot's commands not settled yet, oldest first."""
        return self.mission.pending_commands(robot) if self.mission is not None else []

    def freshness(self, robot: str) -> Freshness:
        """Whether what is shown of `robot` is live or its last known state."""
        return freshness(self, robot, self.clock)

    # -- why an action does not apply (None: it applies): console/state/availability.py ----
    def why_not(
        self, action: str, robot: str | None, skill_id: str | None, marks: list[str] | None = None
    ) -> str | None:
        return availability.why_not(self, action, robot, skill_id, marks)

    def plan_blocking(self, robot: str, skill_id: str) -> list[str]:
        """Ids of the unwaived plan errors that refuse syncing `robot` through `skill_id`."""
        return [f.id for f in self.plan.blocking(self.task(robot), skill_id)]

    def read_only_reason(self, skill_id: str) -> str | None:
        """Why the parameter editor is read-only for this skill (None: editable)."""
        return availability.read_only_reason(self, skill_id)


# events after which every column may have changed: the mission's robots or all of it
_RESHAPING = frozenset({ev.MissionReplaced, ev.RobotAdded, ev.RobotRetired})
# events that change the tags of rows in other robots' columns (a barrier's partners)
_TAGGING = frozenset({ev.BarrierSet, ev.BarrierRemoved})


def _placed(m: ConsoleModel, e: ev.SkillAdded | ev.SkillRemoved | ev.SkillMoved) -> _Columns:
    return (e.robot,), not _kept_indexed(m._owner, e)


def _skill_shown(m: ConsoleModel, e: ev.SkillStatusChanged | ev.SkillEdited) -> _Columns:
    shown = m._shown_by(e.id)
    return shown or (), shown is None


def _command_queued(_m: ConsoleModel, e: ev.CommandQueued) -> _Columns:
    return (e.command.robot,), False  # its skills show ⇡, its header the count


def _command_changed(m: ConsoleModel, e: ev.CommandChanged) -> _Columns:
    assert m.mission is not None
    changed = m.mission.command(e.id)
    return ((changed.robot,) if changed is not None else ()), False


# the columns an applied event shows, by its type (how `_touched` reads each)
_COLUMNS: dict[type, Callable[[ConsoleModel, Any], _Columns]] = {
    ev.SkillAdded: _placed,
    ev.SkillRemoved: _placed,
    ev.SkillMoved: _placed,
    ev.SkillStatusChanged: _skill_shown,
    ev.SkillEdited: _skill_shown,
    ev.CommandQueued: _command_queued,
    ev.CommandChanged: _command_changed,
}


def _touched(m: ConsoleModel, events: list[ev.Event]) -> tuple[set[str], bool, bool] | None:
    """What the applied `events` changed in the schedule: the robots whose
    columns show it, whether the skill indexes need a rebuild, whether rows'
    tags in other columns change; None when every column may have."""
    robots: set[str] = set()
    unindexed = tags = False
    for e in events:
        kind = type(e)
        if kind in _RESHAPING:
            return None
        tags = tags or kind in _TAGGING
        columns = _COLUMNS.get(kind)
        if columns is not None:
            shown, rebuild = columns(m, e)
            robots.update(shown)
            unindexed = unindexed or rebuild
    return robots, unindexed, tags


def _about(entry: Any) -> dict[str, Any]:
    """An alert's robot and skill, as a log entry names them."""
    return {"robots": [entry.robot] if entry.robot else [], "skill": entry.skill}
