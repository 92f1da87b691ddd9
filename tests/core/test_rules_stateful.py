"""Thousands of random operations and robot reports against the rules engine.

After every step the invariants hold (section order, immutable log, barrier
rules, unique ids), and a mirror that only replays the published events
equals the engine's state (so journal replay and clients cannot drift).
"""

from __future__ import annotations

from pathlib import Path

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from backend.core import events as ev
from backend.core.model import FINISHED, Pose, Position, Status, section_problems
from backend.core.ops import (
    AddBarrier,
    AddSkill,
    Control,
    DeleteSkills,
    EditSkill,
    MarkerAdd,
    MarkerDelete,
    MarkerMove,
    MarkerRename,
    MoveSkill,
    PositionMarker,
    Redo,
    RemoveBarrier,
    Report,
    Retry,
    RetryAck,
    Sync,
    SyncAck,
    Undo,
    Unsync,
    UnsyncDone,
)
from backend.core.rules.engine import Engine, Refusal
from backend.files.missions import load_mission

MISSION = Path(__file__).resolve().parents[2] / "tests" / "data" / "mars_sample_return_v1.yaml"
CLIENTS = ["c1", "c2"]
SIMPLE = {  # skill -> params that make it valid, per robot type
    "drive_to": {"goal": {"x": 3.0, "y": 4.0}},
    "recharge": {},
    "take_science_image": {"target": {"x": 1.0, "y": 1.0}},
    "takeoff": {},
    "land": {},
    "drop_stone": {},
    "load_box": {"box": "sample_box"},
}


class MissionMachine(RuleBasedStateMachine):
    def __init__(self):
        super().__init__()
        mission, library = load_mission(MISSION)
        self.initial = mission.model_copy(deep=True)
        self.engine = Engine(mission, library)
        self.mirror = mission.model_copy(deep=True)
        self.seq: dict[str, int] = {}
        self.frozen: dict[str, dict] = {}  # finished skills, as first seen

    # -- helpers ----------------------------------------------------------
    def submit(self, op, **kw):
        try:
            applied = self.engine.submit(op, **kw)
        except Refusal as r:
            assert r.code and r.message
            return None
        if applied.events:
            self.mirror = ev.apply_events(self.mirror, applied.batch())
        return applied

    def ids(self, *statuses: Status) -> list[str]:
        return [s.id for t in self.engine.mission.tasks.values() for s in t if s.status in statuses]

    def robot_of(self, sid: str) -> str:
        return self.engine.mission.find(sid)[0]

    def report(self, robot: str, sid: str, status: Status, **kw):
        self.seq[robot] = self.seq.get(robot, 0) + 1
        return self.submit(Report(robot=robot, seq=self.seq[robot], id=sid, status=status, **kw))

    # -- operator edits -----------------------------------------------------
    @rule(
        robot=st.sampled_from(["lru1", "lru2", "ardea", "lander"]),
        data=st.data(),
        client=st.sampled_from(CLIENTS),
    )
    def add(self, robot, data, client):
        rtype = self.engine.mission.robots[robot].type
        skills = [s for s in self.engine.library.skills_of(rtype) if s in SIMPLE]
        skill = data.draw(st.sampled_from(skills))
        at = data.draw(st.none() | st.integers(0, 6))
        self.submit(
            AddSkill(robot=robot, skill=skill, params=SIMPLE[skill], at=at, label="x"),
            client=client,
        )

    @precondition(lambda self: self.ids(Status.IDLE))
    @rule(data=st.data(), client=st.sampled_from(CLIENTS))
    def delete(self, data, client):
        sid = data.draw(st.sampled_from(self.ids(Status.IDLE)))
        self.submit(DeleteSkills(ids=[sid]), client=client)

    @precondition(lambda self: self.ids(Status.IDLE))
    @rule(data=st.data(), index=st.integers(0, 6), client=st.sampled_from(CLIENTS))
    def move(self, data, index, client):
        sid = data.draw(st.sampled_from(self.ids(Status.IDLE)))
        self.submit(MoveSkill(id=sid, index=index), client=client)

    @precondition(lambda self: self.ids(Status.IDLE, Status.IDLE_SYNCHRONIZED))
    @rule(
        data=st.data(),
        label=st.text(max_size=5),
        client=st.sampled_from(CLIENTS),
        stale=st.booleans(),
    )
    def edit(self, data, label, client, stale):
        sid = data.draw(st.sampled_from(self.ids(Status.IDLE, Status.IDLE_SYNCHRONIZED)))
        seen = self.engine.mission.revision - (3 if stale else 0)
        self.submit(EditSkill(id=sid, label=label), client=client, expected_revision=seen)

    @precondition(lambda self: len(self.ids(Status.IDLE)) >= 2)
    @rule(data=st.data(), client=st.sampled_from(CLIENTS))
    def barrier(self, data, client):
        ids = data.draw(
            st.lists(st.sampled_from(self.ids(Status.IDLE)), min_size=2, max_size=3, unique=True)
        )
        self.submit(AddBarrier(ids=ids), client=client)

    @precondition(lambda self: self.engine.mission.barriers)
    @rule(data=st.data(), client=st.sampled_from(CLIENTS))
    def unbarrier(self, data, client):
        bid = data.draw(st.sampled_from(sorted(self.engine.mission.barriers)))
        self.submit(RemoveBarrier(barrier=bid), client=client)

    @rule(
        name=st.sampled_from(["M1", "M2", "POI-A", "WIFI-1"]),
        x=st.floats(-50, 50),
        op=st.integers(0, 3),
        client=st.sampled_from(CLIENTS),
    )
    def marker(self, name, x, op, client):
        if op == 0:
            self.submit(
                MarkerAdd(name=name, marker=PositionMarker(position=Position(x=x))), client=client
            )
        elif op == 1:
            kind = self.engine.mission.markers.get(name)
            value = Pose(x=x) if kind is None or kind.kind == "pose" else Position(x=x)
            self.submit(MarkerMove(name=name, value=value), client=client)
        elif op == 2:
            self.submit(MarkerRename(name=name, new_name=name + "r"), client=client)
        else:
            self.submit(MarkerDelete(name=name), client=client)

    @rule(client=st.sampled_from(CLIENTS), redo=st.booleans())
    def undo_redo(self, client, redo):
        self.submit(Redo() if redo else Undo(), client=client)

    # -- robots -------------------------------------------------------------
    @rule(
        robot=st.sampled_from(["lru1", "lru2", "ardea", "lander"]),
        data=st.data(),
        ack=st.booleans(),
    )
    def sync(self, robot, data, ack):
        idle = [s.id for s in self.engine.mission.tasks[robot] if s.status == Status.IDLE]
        through = data.draw(st.sampled_from([None, *idle]))
        try:
            plan = self.engine.plan_sync(Sync(robot=robot, through=through))
        except Refusal:
            return
        if ack:  # else: the robot was out of reach
            self.submit(SyncAck(robot=robot, ids=[s.id for s in plan]))
        self.engine.release(robot, [s.id for s in plan])

    @rule(robot=st.sampled_from(["lru1", "lru2", "ardea", "lander"]), race=st.booleans())
    def unsync(self, robot, race):
        queued = [
            s for s in self.engine.mission.tasks[robot] if s.status == Status.IDLE_SYNCHRONIZED
        ]
        from_id = queued[-1].id if queued and race else None
        try:
            ids = self.engine.plan_unsync(Unsync(robot=robot, from_id=from_id))
        except Refusal:
            return
        task = self.engine.mission.tasks[robot]
        first = self.engine.first_queued(task)
        if (
            race
            and self.engine.active(task) is None
            and first is not None
            and task[first].id == ids[0]
        ):
            # the robot started the first skill before the request arrived
            self.report(robot, ids[0], Status.RUNNING)
            ids = ids[1:]
        self.submit(UnsyncDone(robot=robot, ids=ids))
        self.engine.release(robot)

    @rule(
        robot=st.sampled_from(["lru1", "lru2", "ardea", "lander"]),
        outcomes=st.lists(
            st.sampled_from(
                ["success", "failure", "paused", "stop", "running", "synchwaiting", "bogus"]
            ),
            min_size=1,
            max_size=4,
        ),
    )
    def execute(self, robot, outcomes):
        for outcome in outcomes:
            self.step_robot(robot, outcome)

    def step_robot(self, robot, outcome):
        task = self.engine.mission.tasks[robot]
        act = self.engine.active(task)
        if act is None:
            first = self.engine.first_queued(task)
            if first is not None:
                start = Status.SYNCHWAITING if outcome == "synchwaiting" else Status.RUNNING
                self.report(robot, task[first].id, start)
            return
        status = {"stop": Status.IDLE_SYNCHRONIZED, "bogus": Status.IDLE}.get(outcome, outcome)
        self.report(robot, act.id, Status(status))

    @rule(
        robot=st.sampled_from(["lru1", "lru2", "ardea", "lander", None]),
        action=st.sampled_from(["run", "pause", "stop", "reset"]),
    )
    def control(self, robot, action):
        try:
            robots = self.engine.plan_control(Control(op=action, robot=robot))
        except Refusal:
            return
        for r in robots:
            self.engine.release(r)

    @precondition(lambda self: self.ids(Status.FAILURE))
    @rule(data=st.data(), ack=st.booleans())
    def retry(self, data, ack):
        sid = data.draw(st.sampled_from(self.ids(Status.FAILURE)))
        try:
            new = self.engine.plan_retry(Retry(id=sid))
        except Refusal:
            return
        robot = self.robot_of(sid)
        if ack:
            self.submit(RetryAck(robot=robot, failed_id=sid, skill=new))
        self.engine.release(robot)

    @rule(robot=st.sampled_from(["lru1", "lru2"]))
    def duplicate_report(self, robot):
        last = self.engine.mission.report_seqs.get(robot)
        if last:  # resend the last applied report number: applied once
            before = self.engine.mission.revision
            task = self.engine.mission.tasks[robot]
            applied = self.submit(
                Report(robot=robot, seq=last, id=task[0].id if task else "x", status=Status.RUNNING)
            )
            assert applied is None or (applied.duplicate and self.engine.mission.revision == before)

    # -- invariants ------------------------------------------------------------
    @invariant()
    def sections_in_order(self):
        for robot, task in self.engine.mission.tasks.items():
            assert section_problems(task) == [], (robot, [(s.id, s.status) for s in task])

    @invariant()
    def ids_unique(self):
        ids = [s.id for t in self.engine.mission.tasks.values() for s in t]
        assert len(ids) == len(set(ids))

    @invariant()
    def barriers_valid(self):
        m = self.engine.mission
        seen: set[str] = set()
        for bid, b in m.barriers.items():
            robots = set()
            for sid in b.skills:
                found = m.find(sid)
                assert found is not None, (bid, sid)
                assert found[0] not in robots, (bid, "two skills of one robot")
                robots.add(found[0])
                assert sid not in seen
                seen.add(sid)
            assert len(robots) >= 2, bid

    @invariant()
    def log_immutable(self):
        for t in self.engine.mission.tasks.values():
            for s in t:
                if s.status in FINISHED:
                    dump = s.model_dump(exclude={"rev"})
                    assert self.frozen.setdefault(s.id, dump) == dump, s.id

    @invariant()
    def replay_equals_state(self):
        assert self.mirror == self.engine.mission


MissionMachine.TestCase.settings = settings(
    max_examples=60,
    stateful_step_count=100,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
TestMissionRules = MissionMachine.TestCase
