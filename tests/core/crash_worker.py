"""A deterministic stream of valid operations, and a worker process journaling it.

`OpGenerator(engine, seed)` drives an `Engine` the way a server would: operator
edits (add, edit, move, delete, barriers, markers, undo/redo, new mission) and
robot answers (sync + SyncAck, reports running/paused/success/failure/stopped,
retry + RetryAck, unsync + UnsyncDone with the started-meanwhile race, reset).
The same seed on the same starting mission gives the same operations and the
same missions, revision by revision; refusals are skipped.

Run as a script (by tests/core/test_crash_safety.py, in a subprocess):

    python crash_worker.py DB SEED N_STEPS [SNAPSHOT_EVERY]

it opens a fresh journal at DB, snapshots the starting mission, applies the
stream, appends each applied batch (one transaction each), snapshots every
SNAPSHOT_EVERY revisions and prints one line per committed revision,
flushed, after the commit. It prints "done" at the end.
"""

from __future__ import annotations

import random
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from backend.core.library import Library  # noqa: E402
from backend.core.model import Mission, Pose, Position, Status, section_problems  # noqa: E402
from backend.core.ops import (  # noqa: E402
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
    NewMission,
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
from backend.core.rules.engine import Applied, Engine, Refusal  # noqa: E402
from backend.files.missions import load_mission  # noqa: E402

MISSION_FILE = ROOT / "tests" / "data" / "mars_sample_return_v1.yaml"
OPERATORS = ("alice", "bob")
T0 = datetime(2030, 7, 1, 8, 0, tzinfo=UTC)


@dataclass
class Step:
    """One applied operation that changed the mission (a journal batch)."""

    op: Any
    applied: Applied
    client: str
    request_id: str


def mission_problems(m: Mission) -> list[str]:
    """Broken invariants of a mission (empty when consistent): section order
    per robot, unique skill ids, barriers (existing skills, one per robot, at
    least two robots, a skill in one barrier at most), tasks of known robots,
    revision bookkeeping."""
    out: list[str] = []
    seen: dict[str, str] = {}
    for robot, task in m.tasks.items():
        if robot not in m.robots:
            out.append(f"tasks of unknown robot {robot}")
        for i, why in section_problems(task):
            out.append(f"{robot}[{i}]: {why}")
        for s in task:
            if s.id in seen:
                out.append(f"skill id {s.id} used twice ({seen[s.id]} and {robot})")
            seen[s.id] = robot
            if s.rev > m.revision:
                out.append(f"{s.id} changed at revision {s.rev}, after the mission's {m.revision}")
    owner: dict[str, str] = {}
    for bid, b in m.barriers.items():
        robots: list[str] = []
        for sid in b.skills:
            if sid not in seen:
                out.append(f"barrier {bid}: unknown skill {sid}")
                continue
            robots.append(seen[sid])
            if sid in owner:
                out.append(f"skill {sid} is in barriers {owner[sid]} and {bid}")
            owner[sid] = bid
        if len(set(robots)) != len(robots):
            out.append(f"barrier {bid}: two skills of one robot ({robots})")
        if len(set(robots)) < 2:
            out.append(f"barrier {bid}: fewer than two robots ({robots})")
    for name, rev in {**m.task_revs, **m.marker_revs}.items():
        if rev > m.revision:
            out.append(f"{name} changed at revision {rev}, after the mission's {m.revision}")
    return out


def start_engine() -> Engine:
    mission, library = load_mission(MISSION_FILE)
    return Engine(mission, library)


class OpGenerator:
    def __init__(self, engine: Engine, seed: int, on_step: Callable[[Step], None] | None = None):
        """`on_step` is called right after each applied operation, before the
        next one (a server journals each operation as it applies it)."""
        self.engine = engine
        self.on_step = on_step
        self.rng = random.Random(seed)
        self.n_requests = 0
        self.clock = 0
        self.out: list[Step] = []

    # -- helpers -----------------------------------------------------------
    @property
    def m(self) -> Mission:
        return self.engine.mission

    @property
    def lib(self) -> Library:
        return self.engine.library

    def now(self) -> datetime:
        self.clock += 1
        return T0 + timedelta(seconds=7 * self.clock)

    def submit(self, op: Any, client: str) -> Applied | None:
        self.n_requests += 1
        rid = f"r{self.n_requests}"
        try:
            applied = self.engine.submit(op, client=client, request_id=rid)
        except Refusal:
            return None
        if applied.events and not applied.duplicate:
            st = Step(op, applied, client, rid)
            self.out.append(st)
            if self.on_step is not None:
                self.on_step(st)
        return applied

    def idle(self, robot: str | None = None) -> list[tuple[str, Any]]:
        out = []
        for r, task in self.m.tasks.items():
            if robot is None or r == robot:
                out += [(r, s) for s in task if s.status == Status.IDLE]
        return out

    def pick(self, seq):
        seq = list(seq)
        return self.rng.choice(seq) if seq else None

    def operator(self) -> str:
        return self.rng.choice(OPERATORS)

    def coord(self) -> float:
        return round(self.rng.uniform(-80, 80), 2)

    def value_for(self, ptype: str, pspec: Any) -> Any:
        rng = self.rng
        if ptype == "pose":
            return {"x": self.coord(), "y": self.coord(), "yaw": round(rng.uniform(-3, 3), 2)}
        if ptype == "position":
            return {"x": self.coord(), "y": self.coord()}
        if ptype == "area":
            x, y = self.coord(), self.coord()
            return [{"x": x, "y": y}, {"x": x + 10, "y": y}, {"x": x + 10, "y": y + 10}]
        if ptype == "enum":
            return rng.choice(pspec.choices)
        if ptype in ("int", "float"):
            lo = pspec.min if pspec.min is not None else 0
            hi = pspec.max if pspec.max is not None else 100
            if ptype == "int":
                return rng.randint(int(lo), int(hi))
            return round(rng.uniform(lo, hi), 3)
        if ptype == "bool":
            return rng.random() < 0.5
        if ptype == "str":
            return f"s{rng.randint(0, 99)}"
        if ptype == "list":
            return [f"sensor{rng.randint(0, 3)}"]
        if ptype == "dict":
            return {"exposure_ms": rng.randint(5, 50), "gain": 1.0}
        if ptype == "robot":
            return rng.choice(sorted(self.m.robots))
        if ptype == "marker":
            kinds = pspec.marker_kinds or ["pose", "position", "area"]
            names = [n for n, mk in self.m.markers.items() if mk.kind in kinds]
            return self.pick(names)
        return None

    def marker_for(self, ptype: str) -> str | None:
        kinds = {
            "pose": ("pose", "position"),
            "position": ("pose", "position"),
            "area": ("area",),
        }.get(ptype)
        if not kinds:
            return None
        return self.pick(n for n, mk in self.m.markers.items() if mk.kind in kinds)

    def params_for(self, rtype: str, skill: str) -> tuple[dict, dict]:
        spec = self.lib.skill_for(rtype, skill)
        params: dict[str, Any] = {}
        bindings: dict[str, str] = {}
        for name, p in spec.params.items():
            if p.type in ("pose", "position", "area") and self.rng.random() < 0.4:
                mk = self.marker_for(p.type)
                if mk is not None:
                    bindings[name] = mk
                    continue
            if p.is_required or self.rng.random() < 0.3:
                v = self.value_for(p.type, p)
                if v is not None:
                    params[name] = v
        return params, bindings

    # -- operator actions --------------------------------------------------------
    def act_add(self) -> None:
        robot = self.pick(sorted(self.m.robots))
        rtype = self.m.robots[robot].type
        skill = self.pick(self.lib.skills_of(rtype))
        params, bindings = self.params_for(rtype, skill)
        n_idle = len(self.idle(robot))
        at = None if self.rng.random() < 0.5 else self.rng.randint(0, n_idle)
        label = f"{skill} #{self.rng.randint(1, 999)}" if self.rng.random() < 0.7 else ""
        self.submit(
            AddSkill(
                robot=robot, skill=skill, label=label, params=params, bindings=bindings, at=at
            ),
            self.operator(),
        )

    def act_edit(self) -> None:
        found = self.pick(self.idle())
        if found is None:
            return
        robot, s = found
        spec = self.lib.skill_for(self.m.robots[robot].type, s.skill)
        label = None
        params: dict[str, Any] = {}
        bindings: dict[str, str | None] = {}
        roll = self.rng.random()
        if roll < 0.3 or not spec.params:
            label = f"edited {self.rng.randint(1, 999)}"
        else:
            name = self.pick(sorted(spec.params))
            p = spec.params[name]
            if roll < 0.45 and p.type in ("pose", "position", "area"):
                mk = self.marker_for(p.type)
                bindings[name] = mk if mk and name not in s.bindings else None
            else:
                v = self.value_for(p.type, p)
                if v is not None:
                    params[name] = v
        self.submit(
            EditSkill(id=s.id, label=label, params=params, bindings=bindings), self.operator()
        )

    def act_move(self) -> None:
        found = self.pick(self.idle())
        if found is None:
            return
        robot, s = found
        n_idle = len(self.idle(robot))
        self.submit(
            MoveSkill(id=s.id, index=self.rng.randint(0, max(0, n_idle - 1))), self.operator()
        )

    def act_delete(self) -> None:
        idle = self.idle()
        if not idle:
            return
        ids = [s.id for _, s in self.rng.sample(idle, min(len(idle), self.rng.choice((1, 1, 2))))]
        self.submit(DeleteSkills(ids=ids), self.operator())

    def act_barrier(self) -> None:
        by_robot: dict[str, list[str]] = {}
        for r, s in self.idle():
            if self.m.barrier_of(s.id) is None:
                by_robot.setdefault(r, []).append(s.id)
        robots = sorted(by_robot)
        if len(robots) < 2:
            return
        chosen = self.rng.sample(robots, self.rng.choice((2, 2, 3)) if len(robots) > 2 else 2)
        self.submit(AddBarrier(ids=[self.rng.choice(by_robot[r]) for r in chosen]), self.operator())

    def act_unbarrier(self) -> None:
        bid = self.pick(sorted(self.m.barriers))
        if bid is not None:
            self.submit(RemoveBarrier(barrier=bid), self.operator())

    def act_marker(self) -> None:
        roll = self.rng.random()
        names = sorted(self.m.markers)
        if roll < 0.3 or not names:
            name = f"M{self.rng.randint(1, 60)}"
            kind = self.rng.choice(("pose", "position", "area"))
            marker = {"kind": kind, kind: self.value_for(kind, None), "description": "added"}
            self.submit(MarkerAdd.model_validate({"name": name, "marker": marker}), self.operator())
        elif roll < 0.7:
            name = self.rng.choice(names)
            kind = self.m.markers[name].kind
            raw = self.value_for(kind, None)
            value = (
                [Position(**p) for p in raw]
                if kind == "area"
                else (Pose(**raw) if kind == "pose" else Position(**raw))
            )
            self.submit(MarkerMove(name=name, value=value), self.operator())
        elif roll < 0.9:
            self.submit(
                MarkerRename(name=self.rng.choice(names), new_name=f"M{self.rng.randint(1, 60)}"),
                self.operator(),
            )
        else:
            self.submit(MarkerDelete(name=self.rng.choice(names)), self.operator())

    def act_undo(self) -> None:
        op = Undo() if self.rng.random() < 0.7 else Redo()
        self.submit(op, self.operator())

    def act_new(self) -> None:
        self.submit(NewMission(name=f"mission {self.rng.randint(1, 9)}"), self.operator())

    # -- robot round trips -----------------------------------------------------
    def robot_with(self, pred) -> str | None:
        return self.pick(r for r in sorted(self.m.robots) if pred(self.m.tasks.get(r, [])))

    def act_sync(self) -> None:
        robot = self.robot_with(lambda t: any(s.status == Status.IDLE for s in t))
        if robot is None:
            return
        idle = self.idle(robot)
        through = None if self.rng.random() < 0.3 else self.rng.choice(idle)[1].id
        try:
            sent = self.engine.plan_sync(Sync(robot=robot, through=through))
        except Refusal:
            return
        ids = [s.id for s in sent]
        if self.rng.random() < 0.1:  # robot out of reach: nothing changes
            self.engine.release(robot, ids)
            return
        self.submit(SyncAck(robot=robot, ids=ids), f"robot:{robot}")
        self.engine.release(robot, ids)

    def report(
        self, robot: str, sid: str, status: Status, info: str = "", attempt: int | None = None
    ) -> Applied | None:
        seq = self.m.report_seqs.get(robot, 0) + 1
        if self.rng.random() < 0.05 and seq > 1:
            seq -= 1  # a report sent twice: applied once
        op = Report(
            robot=robot, seq=seq, id=sid, status=status, info=info, attempt=attempt, at=self.now()
        )
        return self.submit(op, f"robot:{robot}")

    def act_report(self) -> None:
        robot = self.robot_with(
            lambda t: any(
                s.status == Status.IDLE_SYNCHRONIZED
                or s.status in (Status.RUNNING, Status.PAUSED, Status.SYNCHWAITING)
                for s in t
            )
        )
        if robot is None:
            return
        task = self.m.tasks[robot]
        act = self.engine.active(task)
        r = self.rng.random()
        if act is None:
            i = self.engine.first_queued(task)
            if i > 0 and task[i - 1].status == Status.FAILURE and r < 0.6:
                return  # halted after a failure: the operator decides (retry, run or unsync)
            s = task[i]
            in_barrier = self.m.barrier_of(s.id) is not None
            status = Status.SYNCHWAITING if in_barrier and r < 0.7 else Status.RUNNING
            if r > 0.97:
                status = Status.FAILURE
            self.report(robot, s.id, status, "started" if status == Status.RUNNING else "")
        elif act.status == Status.RUNNING:
            if r < 0.55:
                self.report(robot, act.id, Status.SUCCESS, "done")
            elif r < 0.8:
                self.report(robot, act.id, Status.FAILURE, f"failed: code {self.rng.randint(1, 9)}")
            elif r < 0.9:
                self.report(robot, act.id, Status.PAUSED, "paused by operator")
            elif r < 0.95:
                self.report(robot, act.id, Status.IDLE_SYNCHRONIZED, "stopped")
            else:  # an autonomous retry: running again as the next attempt
                self.report(
                    robot, act.id, Status.RUNNING, "autonomous retry", attempt=act.attempt + 1
                )
        elif act.status == Status.PAUSED:
            self.report(
                robot,
                act.id,
                Status.RUNNING if r < 0.7 else Status.IDLE_SYNCHRONIZED,
                "resumed" if r < 0.7 else "stopped",
            )
        else:  # synchwaiting
            self.report(
                robot,
                act.id,
                Status.RUNNING if r < 0.8 else Status.FAILURE,
                "partners ready" if r < 0.8 else "partner lost",
            )

    def act_retry(self) -> None:
        failed = [(r, s) for r, t in self.m.tasks.items() for s in t if s.status == Status.FAILURE]
        found = self.pick(failed)
        if found is None:
            return
        robot, s = found
        try:
            new = self.engine.plan_retry(Retry(id=s.id))
        except Refusal:
            return
        self.submit(RetryAck(robot=robot, failed_id=s.id, skill=new), f"robot:{robot}")
        self.engine.release(robot)

    def act_unsync(self) -> None:
        robot = self.robot_with(lambda t: any(s.status == Status.IDLE_SYNCHRONIZED for s in t))
        if robot is None:
            return
        queued = [s.id for s in self.m.tasks[robot] if s.status == Status.IDLE_SYNCHRONIZED]
        from_id = None if self.rng.random() < 0.4 else self.rng.choice(queued)
        try:
            ids = self.engine.plan_unsync(Unsync(robot=robot, from_id=from_id))
        except Refusal:
            return
        task = self.m.tasks[robot]
        if (
            self.rng.random() < 0.25
            and self.engine.active(task) is None
            and task[self.engine.first_queued(task)].id == ids[0]
        ):
            # the race: the robot started the first one before the request arrived
            if self.report(robot, ids[0], Status.RUNNING, "started"):
                ids = ids[1:]
        self.submit(UnsyncDone(robot=robot, ids=ids), f"robot:{robot}")
        self.engine.release(robot)

    def act_reset(self) -> None:
        robot = self.robot_with(
            lambda t: any(s.status not in (Status.IDLE, Status.SUCCESS, Status.FAILURE) for s in t)
        )
        if robot is None:
            return
        try:
            self.engine.plan_control(Control(op="reset", robot=robot))
        except Refusal:
            return
        act = self.engine.active(self.m.tasks[robot])
        if act is not None:
            self.report(robot, act.id, Status.IDLE_SYNCHRONIZED, "reset")
        queued = [s.id for s in self.m.tasks[robot] if s.status == Status.IDLE_SYNCHRONIZED]
        self.submit(UnsyncDone(robot=robot, ids=queued), f"robot:{robot}")
        self.engine.release(robot)

    ACTIONS = (
        ("add", 16),
        ("edit", 8),
        ("move", 6),
        ("delete", 6),
        ("barrier", 5),
        ("unbarrier", 2),
        ("marker", 6),
        ("undo", 5),
        ("new", 0.2),
        ("sync", 10),
        ("report", 24),
        ("retry", 5),
        ("unsync", 4),
        ("reset", 1),
    )

    def step(self) -> list[Step]:
        """One random action; the applied operations it produced."""
        self.out = []
        names = [a for a, _ in self.ACTIONS]
        weights = [w for _, w in self.ACTIONS]
        action = self.rng.choices(names, weights)[0]
        getattr(self, f"act_{action}")()
        return self.out

    def steps(self, n: int) -> Iterator[Step]:
        """The applied operations of `n` actions (yielded after each action;
        use `on_step` to see each operation's mission)."""
        for _ in range(n):
            yield from self.step()


def main(argv: list[str]) -> int:
    import threading

    from backend.server.journal import Journal

    db, seed, n = argv[0], int(argv[1]), int(argv[2])
    every = int(argv[3]) if len(argv) > 3 else 50
    # "background": checkpoints on a thread, as the server runs them (often,
    # so that kills land during them too); else SQLite's, inside commits
    background = len(argv) > 4 and argv[4] == "background"
    engine = start_engine()
    out = sys.stdout
    # snapshots every `every` batches whatever their size (snapshot_bytes=0):
    # kills land in many of them, and a restart replays at most `every`
    with Journal.open(
        db, library=engine.mission.library, snapshot_every=every, snapshot_bytes=0
    ) as journal:
        checkpointing: list[threading.Thread] = []
        if background:
            journal.checkpoint_in_background(every=16)

        def commit(st: Step) -> None:
            journal.append(
                st.applied.batch(st.client),
                op_json=st.op.model_dump_json(),
                client=st.client,
                request_id=st.request_id,
            )
            journal.maybe_snapshot(engine.mission)
            if journal.checkpoint_due and not any(t.is_alive() for t in checkpointing):
                checkpointing[:] = [threading.Thread(target=journal.checkpoint, daemon=True)]
                checkpointing[0].start()
            out.write(f"{st.applied.revision}\n")
            out.flush()

        journal.snapshot(engine.mission)
        gen = OpGenerator(engine, seed, on_step=commit)
        for _ in range(n):
            gen.step()
        for t in checkpointing:
            t.join()
    out.write("done\n")
    out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
