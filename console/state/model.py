"""What the console knows, and what it derives from it — no Textual here.

`ConsoleModel` holds the mirrored mission, the skill library, the fleet
(presence, manifests), the latest telemetry per robot and the connection
state. The app updates it from messages (`console.messages`) only, so tests
can drive it without a network. What the screens show is derived here and
beside it (console/state/text.py: glyphs, summaries; availability.py: why an
action does not apply), so it can be unit-tested without a terminal.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from backend.core import events as ev
from backend.core.library import Library
from backend.core.model import ACTIVE, FINISHED, Mission, SkillInstance, Status, how_to_change
from backend.protocol.messages import RobotInfo, Telemetry
from console.state.text import GLYPHS, STATUS_WORDS, fmt_clock

HISTORY = 120  # telemetry samples kept per robot (bounded memory)

CONNECTING, CONNECTED, RECONNECTING, UNREACHABLE, OFFLINE = (
    "connecting",
    "connected",
    "reconnecting",
    "unreachable",
    "offline",
)


# actions an observer (read-only account) may still use: they change nothing on the server
_READ_ONLY_OK = frozenset({"save", "help", "edit", "mark", "toggle_static", "clear_marks"})

# -- the model --------------------------------------------------------------------


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
    # why nothing can be changed from this console ("" when it can): an observer account
    read_only: str = ""
    # skill id -> robot, skill id -> barrier id (kept in step with the mission)
    _owner: dict[str, str] = field(default_factory=dict)
    _barrier_of: dict[str, str] = field(default_factory=dict)
    # robot -> (active skill, number queued), computed on demand
    _robot_state: dict[str, tuple[SkillInstance | None, int]] = field(default_factory=dict)
    # robot -> the last HISTORY (battery, link) samples, for the fleet screen's sparklines
    history: dict[str, deque[tuple[float, float]]] = field(default_factory=dict)

    # -- updates ------------------------------------------------------------------
    def load(
        self,
        mission: Mission,
        library: Library,
        robots: dict[str, RobotInfo] | None = None,
        server_id: str = "",
    ) -> None:
        self.mission = mission
        self.library = library
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

    def apply(self, batch: ev.EventBatch, mission: Mission | None = None) -> set[str] | None:
        """Take an event batch. `mission` given: the client applied it already
        (adopt its mirror); otherwise apply it here. Returns the robots whose
        columns changed, or None when everything may have changed."""
        if self.mission is None:
            return None
        if mission is not None:
            self.mission = mission
        else:
            if batch.revision <= self.mission.revision:
                return set()
            self.mission = ev.apply_events(self.mission, batch)
        robots: set[str] = set()
        reindex = False
        barriers = False
        for e in batch.events:
            match e:
                case ev.SkillAdded(robot=r) | ev.SkillRemoved(robot=r) | ev.SkillMoved(robot=r):
                    robots.add(r)
                    reindex = True
                case ev.SkillChanged(id=sid):
                    r = self._owner.get(sid)
                    if r is None:
                        reindex = True
                    else:
                        robots.add(r)
                    bid = self._barrier_of.get(sid)
                    if bid is not None and bid in self.mission.barriers:
                        # partners waiting at the barrier show this skill's state
                        robots.update(
                            self._owner[x]
                            for x in self.mission.barriers[bid].skills
                            if x in self._owner
                        )
                case ev.BarrierSet() | ev.BarrierRemoved():
                    barriers = True
                case ev.MissionReplaced():
                    for name in self.mission.robots:
                        self.robots.setdefault(name, RobotInfo(name=name))
                    self.reindex()
                    return None
                case _:
                    pass
        for r in robots:
            self._robot_state.pop(r, None)
        if reindex or barriers:
            self.reindex()
        if barriers:  # tags of partner rows in other columns change too
            return None
        return robots

    def set_robot(self, info: RobotInfo) -> None:
        self.robots[info.name] = info

    def set_telemetry(self, t: Telemetry) -> None:
        self.telemetry[t.robot] = t
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
        return f"offline since {fmt_clock(info.since)}"

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
        if act is not None:
            t = self.telemetry.get(robot)
            extra = ""
            if (
                t is not None
                and t.skill == act.id
                and t.progress is not None
                and act.status == Status.RUNNING
            ):
                extra = f" {int(t.progress * 100)}%"
            return f"{GLYPHS[act.status]} {act.id} {STATUS_WORDS[act.status]}{extra}"
        t = self.telemetry.get(robot)
        mode = t.mode if t is not None else ""
        if queued:
            return (
                f"halted · {queued} queued"
                if not mode or mode == "idle"
                else f"{mode} · {queued} queued"
            )
        return mode or "idle"

    # -- why an action does not apply (None: it applies) -----------------------------------
    def why_not(
        self, action: str, robot: str | None, skill_id: str | None, marks: list[str] | None = None
    ) -> str | None:
        marks = marks or []
        if self.mission is None:
            return "no mission loaded yet"
        offline_ok = action in ("save", "help", "edit")
        if not self.connected and not offline_ok:
            detail = "reconnecting" if self.connection == RECONNECTING else self.connection
            return f"not connected to the mission server ({detail}): nothing can be changed now"
        if self.read_only and action not in _READ_ONLY_OK:
            return self.read_only
        found = self.find(skill_id)
        s = found[2] if found else None
        if action in ("add",):
            if robot is None:
                return "select a robot column first"
            if not self.skills_of(robot):
                return f"{robot} has no skills in the library"
            return None
        if action == "edit":
            return None if s is not None else "select a skill first"
        if action in ("delete", "move_up", "move_down"):
            if s is None:
                return "select a skill first"
            verb = {"delete": "deleted", "move_up": "moved", "move_down": "moved"}[action]
            if s.status != Status.IDLE:
                return self._not_idle(found[0], s, f"only idle skills can be {verb}")
            task = self.task(found[0])
            idle = [x.id for x in task if x.status == Status.IDLE]
            if action == "move_up" and idle and idle[0] == s.id:
                return f"{s.id} is already first in {found[0]}'s plan"
            if action == "move_down" and idle and idle[-1] == s.id:
                return f"{s.id} is already last in {found[0]}'s plan"
            return None
        if action == "sync":
            if s is None:
                return "select the last skill to synchronize"
            r = found[0]
            if s.status != Status.IDLE:
                return f"{s.id} is {STATUS_WORDS[s.status]} on {r}: synchronize through an idle (unsynchronized) skill"
            if not self.is_online(r):
                return f"{r} is {self.presence_text(r)}: it cannot receive skills"
            return None
        if action == "unsync":
            if s is None:
                return "select the first queued skill to take back"
            r = found[0]
            if s.status != Status.IDLE_SYNCHRONIZED:
                return f"{s.id} is {STATUS_WORDS[s.status]} on {r}: only queued (idle_synchronized) skills can be unsynchronized"
            if not self.is_online(r):
                return f"{r} is {self.presence_text(r)}: it cannot be asked to give skills back"
            return None
        if action == "mark":
            if s is None:
                return "select a skill to mark"
            if s.status != Status.IDLE and s.id not in marks:
                return f"{s.id} is {STATUS_WORDS[s.status]}: barriers join idle skills only"
            return None
        if action == "barrier":
            return self._why_not_barrier(marks)
        if action == "unbarrier":
            if s is None:
                return "select a skill of the barrier to remove"
            bid = self.barrier_of(s.id)
            if bid is None:
                return f"{s.id} is in no barrier"
            for sid in self.mission.barriers[bid].skills:
                f = self.find(sid)
                if f and f[2].status != Status.IDLE and f[2].status not in FINISHED:
                    return f"barrier {bid}: {sid} is {STATUS_WORDS[f[2].status]} on {f[0]}; {how_to_change(f[2].status)}"
            return None
        if action == "retry":
            if s is None:
                return "select a failed skill"
            r, i, _ = found
            if s.status != Status.FAILURE:
                return f"{s.id} is {STATUS_WORDS[s.status]}: only a failed skill can be retried"
            task = self.task(r)
            new_id = f"{s.id.split('.')[0]}.{s.attempt + 1}"
            if self.owner(new_id) is not None:
                return f"{s.id} was already retried as {new_id}"
            if any(x.status in FINISHED for x in task[i + 1 :]):
                return f"{r} has executed other skills since {s.id} failed; add a new skill instead"
            act = self.robot_state(r)[0]
            if act is not None:
                return f"{r} is executing {act.id}: stop it first"
            if not self.is_online(r):
                return f"{r} is {self.presence_text(r)}"
            return None
        if action in ("run", "pause", "stop", "reset"):
            if robot is None:
                return "select a robot column first"
            return self._control_why(action, robot)
        if action in ("run_all", "pause_all", "stop_all", "reset_all"):
            verb = action.split("_")[0]
            reasons = [self._control_why(verb, r) for r in self.mission.robots]
            if all(reasons):
                return f"{verb} applies to no robot: " + "; ".join(x for x in reasons if x)
            return None
        return None  # undo, redo, load, save: the server decides

    def _not_idle(self, robot: str, s: SkillInstance, rule: str) -> str:
        if s.status in FINISHED:
            word = "succeeded" if s.status == Status.SUCCESS else "failed"
            return f"{s.id} {word} on {robot}: {how_to_change(s.status)}"
        return f"{s.id} is {s.status.value} on {robot}: {rule}; {how_to_change(s.status)}"

    def read_only_reason(self, skill_id: str) -> str | None:
        """Why the parameter editor is read-only for this skill (None: editable)."""
        found = self.find(skill_id)
        if found is None:
            return "the skill no longer exists"
        robot, _, s = found
        if self.read_only:  # the editor says "read-only: <reason>" itself
            return self.read_only.removeprefix("read-only: ")
        if s.status == Status.IDLE:
            if not self.connected:
                return f"not connected to the mission server ({self.connection}): edits cannot be applied now"
            return None
        return self._not_idle(robot, s, "only idle skills can be edited")

    def _why_not_barrier(self, marks: list[str]) -> str | None:
        if len(marks) < 2:
            return (
                "mark one idle skill on each of at least two robots (space), then make the barrier"
            )
        robots: dict[str, str] = {}
        for sid in marks:
            f = self.find(sid)
            if f is None:
                return f"{sid} no longer exists"
            r, _, s = f
            if s.status != Status.IDLE:
                return f"{sid} is {STATUS_WORDS[s.status]} on {r}: barriers join idle skills"
            if r in robots:
                return (
                    f"{robots[r]} and {sid} both belong to {r}: a barrier takes one skill per robot"
                )
            robots[r] = sid
            bid = self.barrier_of(sid)
            if bid is not None:
                return f"{sid} is already in barrier {bid}"
        return None

    def _control_why(self, action: str, robot: str) -> str | None:
        act, n_queued = self.robot_state(robot)
        queued = n_queued > 0
        why: str | None
        if action == "run":
            if act is not None and act.status == Status.PAUSED:
                why = None
            elif act is not None:
                why = f"{robot} is already executing {act.id} ({STATUS_WORDS[act.status]})"
            else:
                why = None if queued else f"{robot} has nothing to run: synchronize skills first"
        elif action == "pause":
            why = (
                None
                if act is not None and act.status == Status.RUNNING
                else f"{robot} has no running skill to pause"
            )
        elif action == "stop":
            why = (
                None
                if act is not None
                else f"{robot} has no running, paused or waiting skill to stop"
            )
        else:
            why = (
                None if act is not None or queued else f"{robot} has nothing synchronized to reset"
            )
        if why is None and not self.is_online(robot):
            why = f"{robot} is {self.presence_text(robot)}"
        return why
