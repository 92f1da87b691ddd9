"""A recorded mission made without a network, for review tests and bench/bench_review.py.

The pilot mission's four robots work through cycles: the operator adds
skills, deletes one, edits one, moves a marker and synchronizes (with the
forecast a console would send); the server notes the command sent; each
robot answers and reports its skills (running, success or failure; now and
then a failure, which the operator retries), one link delay after it did
them. Everything goes through the `Engine` and the server's `Journal`
(every snapshot kept, as the server keeps them) at the times of the play,
and the telemetry (4 samples a second per robot) through the server's
`TelemetryArchive`, which downsamples it as it does live.
"""

from __future__ import annotations

import heapq
import itertools
import math
import sqlite3
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

from backend.core.alerts import AlertKind
from backend.core.model import Pose, PoseMarker, Status
from backend.core.ops import (
    AddSkill,
    Answer,
    DeleteSkills,
    EditSkill,
    MarkerAdd,
    MarkerMove,
    NewMission,
    Predicted,
    Report,
    Retry,
    Sync,
    UplinkSent,
    Waive,
)
from backend.core.rules.engine import Engine
from backend.files.missions import library_path, load_mission
from backend.protocol.archive import archive_path
from backend.protocol.messages import Alert, RobotInfo, Telemetry
from backend.server.archive import TelemetryArchive
from backend.server.journal import Journal

ROOT = Path(__file__).resolve().parents[2]
MISSION_FILE = ROOT / "missions" / "mars_sample_return.yaml"
T0 = datetime(2030, 7, 1, 8, 0, tzinfo=UTC)
SKILLS = {"lru1": "drive_to", "lru2": "drive_to", "ardea": "fly_to", "lander": "load_box"}
OPERATOR = ("alice", "console-a")  # (user, client)


def _params(robot: str, k: int) -> dict[str, object]:
    if robot == "lander":
        return {"box": "sample_box", "slot": 1 + k % 4}
    return {"goal": {"x": float(k % 50), "y": float(k % 30), "yaw": 0.0}}


@dataclass
class Plan:
    """How big the play is."""

    cycles: int = 2  # per robot
    skills: int = 3  # added per cycle (one of them deleted)
    skill_s: float = 30.0  # how long a skill takes on the robot
    delay_s: float = 60.0  # one-way link delay
    fail_every: int = 3  # every n-th skill of a robot fails (and is retried)
    telemetry_hz: float = 4.0
    snapshot_every: int = 500


@dataclass
class Recorded:
    """What the play left: files, and what happened when (seconds since the epoch)."""

    db: Path
    archive: Path
    ops: int = 0  # operations journaled (operators' and the link's)
    reports: int = 0  # robot messages journaled (answers and reports)
    start: float = 0.0
    end: float = 0.0
    # skill id -> (robot start, robot end) as the robot did it
    done: dict[str, tuple[float, float]] = field(default_factory=dict)
    # skill id -> when the robot reported it running (robot time) and the ground got it
    running: dict[str, tuple[float, float]] = field(default_factory=dict)
    failed: list[str] = field(default_factory=list)
    retried: dict[str, str] = field(default_factory=dict)  # failed id -> its next attempt
    waived: list[str] = field(default_factory=list)


class _Play:
    def __init__(self, folder: Path, plan: Plan) -> None:
        self.plan = plan
        mission, library = load_mission(MISSION_FILE)
        self.engine = Engine(mission, library)
        self.now = T0
        self.engine.clock = lambda: self.now
        db = folder / "mission.db"
        lib = library_path(MISSION_FILE, mission.library)
        self.journal = Journal.open(
            db, library=str(lib), keep_snapshots=None, snapshot_every=plan.snapshot_every
        )
        self.journal.snapshot(mission)
        self.times: list[tuple[float, int]] = []
        self.index: list[tuple[int, object, float]] = []  # what the server gives the archive
        self.out = Recorded(db, archive_path(db), start=T0.timestamp())
        self.requests = itertools.count(1)
        self.activity: dict[str, list[tuple[float, float, str]]] = {r: [] for r in SKILLS}
        self.alerts: list[Alert] = []

    # -- journaling ---------------------------------------------------------------------
    def submit(self, op, *, actor: str, client: str):
        rid = f"r{next(self.requests)}"
        applied = self.engine.submit(op, client=client, request_id=rid)
        if self.journal.record(
            applied, op, actor=actor, client=client, request_id=rid, mission=self.engine.mission
        ):
            self.times.append((self.now.timestamp(), applied.revision))
            self.index.append((applied.revision, op, self.now.timestamp()))
        return applied

    def operator(self, op):
        self.out.ops += 1
        user, client = OPERATOR
        return self.submit(op, actor=f"{user}@{client}", client=client)

    def link(self, op):
        self.out.ops += 1
        return self.submit(op, actor="server", client="server")

    def robot(self, op):
        self.out.reports += 1
        return self.submit(op, actor=op.robot, client=op.robot)

    def seq(self, robot: str) -> int:
        return self.engine.mission.report_seqs.get(robot, 0) + 1

    # -- one robot's day ------------------------------------------------------------------
    def day(self, robot: str, offset: float) -> Iterator[tuple[float, Callable[[], None]]]:
        """(ground time, what happens then), in order."""
        p = self.plan
        t = T0.timestamp() + offset
        n = 0
        for cycle in range(p.cycles):
            ids: list[str] = []
            for k in range(p.skills):
                t += 1.0
                yield t, self._add(robot, cycle * p.skills + k, ids)
            t += 1.0
            yield t, lambda ids=ids: self.operator(DeleteSkills(ids=[ids.pop(0)]))
            t += 1.0
            yield t, lambda ids=ids: self.operator(EditSkill(id=ids[0], label="edited"))
            if robot == "lru1":
                t += 1.0
                yield t, self._marker(cycle)
            t += 1.0
            sent = t + 0.5
            arrives = sent + p.delay_s  # robot time the command is there
            yield t, self._sync(robot, ids, arrives)
            yield sent, self._sent(robot)
            yield arrives + p.delay_s, self._answer(robot, arrives)
            r = arrives + 1.0
            for sid in ids:
                n += 1
                fails = p.fail_every > 0 and n % p.fail_every == 0
                r = yield from self._execute(robot, sid, r, fails)
                if fails:
                    r = yield from self._retry(robot, sid, r)
            t = max(t, r + p.delay_s) + 1.0
        return

    def _add(self, robot: str, k: int, ids: list[str]) -> Callable[[], None]:
        def add() -> None:
            a = self.operator(AddSkill(robot=robot, skill=SKILLS[robot], params=_params(robot, k)))
            ids.append(a.value["id"])

        return add

    def _marker(self, cycle: int) -> Callable[[], None]:
        def move() -> None:
            self.operator(MarkerMove(name="POI-B", value=Pose(x=-30.0 + cycle % 7, y=62.0)))
            if cycle == 0:
                self.operator(Waive(check="energy.margin:lru1", reason="charged at noon"))
                self.out.waived.append("energy.margin:lru1")

        return move

    def _sync(self, robot: str, ids: list[str], arrives: float) -> Callable[[], None]:
        p = self.plan

        def sync() -> None:
            forecast = {
                sid: Predicted(
                    start=datetime.fromtimestamp(arrives + i * p.skill_s, UTC),
                    end=datetime.fromtimestamp(arrives + (i + 1) * p.skill_s, UTC),
                )
                for i, sid in enumerate(ids)
            }
            self.operator(Sync(robot=robot, forecast=forecast))

        return sync

    def _pending(self, robot: str) -> list[int]:
        return [c.id for c in self.engine.mission.pending_commands(robot) if c.state == "queued"]

    def _sent(self, robot: str) -> Callable[[], None]:
        return lambda: self.link(UplinkSent(robot=robot, ids=self._pending(robot), at=self.now))

    def _answer(self, robot: str, at: float) -> Callable[[], None]:
        def answer() -> None:
            c = self.engine.mission.pending_commands(robot)[0]
            assert c.command.cmd == "enqueue"
            self.robot(
                Answer(
                    robot=robot,
                    seq=self.seq(robot),
                    command=c.seq,
                    outcome="applied",
                    queued=[s.id for s in c.command.skills],
                    at=datetime.fromtimestamp(at, UTC),
                )
            )

        return answer

    def _report(self, robot: str, sid: str, status: Status, info: str, at: float):
        def report() -> None:
            self.robot(
                Report(
                    robot=robot,
                    seq=self.seq(robot),
                    id=sid,
                    status=status,
                    info=info,
                    at=datetime.fromtimestamp(at, UTC),
                )
            )
            if status == Status.RUNNING and sid not in self.out.running:
                self.out.running[sid] = (at, self.now.timestamp())
            if status == Status.FAILURE:
                self._alert(robot, sid)

        return report

    def _alert(self, robot: str, sid: str) -> None:
        self.alerts.append(
            Alert(
                id=len(self.alerts) + 1,
                level="error",
                kind=AlertKind.FAILURE,
                robot=robot,
                skill=sid,
                message=f"{robot}: {sid} failed: stuck",
                at=self.now,
            )
        )

    def _execute(self, robot: str, sid: str, r: float, fails: bool):
        """Yields the skill's reports; returns the robot time it ended."""
        p = self.plan
        d = p.delay_s
        start = r
        yield start + d, self._report(robot, sid, Status.RUNNING, "", start)
        end = start + (p.skill_s / 2 if fails else p.skill_s)
        status = Status.FAILURE if fails else Status.SUCCESS
        yield end + d, self._report(robot, sid, status, "stuck" if fails else "", end)
        self.activity[robot].append((start, end, sid))
        if fails:
            self.out.failed.append(sid)
        else:
            self.out.done[sid] = (start, end)
        return end + 1.0

    def _retry(self, robot: str, sid: str, r: float):
        p = self.plan
        d = p.delay_s
        asked = r + d + 1.0  # the operator saw the failure
        new: list[str] = []

        def retry() -> None:
            new.append(self.operator(Retry(id=sid)).value["id"])
            self.out.retried[sid] = new[0]

        yield asked, retry
        yield asked + 0.5, self._sent(robot)
        arrives = asked + 0.5 + d
        yield arrives + d, self._answer(robot, arrives)
        end = yield from self._execute(robot, new[0], arrives + 1.0, False)
        return end

    # -- the whole play --------------------------------------------------------------------
    def run(self) -> Recorded:
        self.operator(NewMission(name="long day"))
        self.operator(MarkerAdd(name="POI-B", marker=PoseMarker(pose=Pose(x=-30.0, y=62.0))))
        days = {r: self.day(r, 10.0 + i * 2.5) for i, r in enumerate(SKILLS)}
        queue: list[tuple[float, int, str, Callable[[], None]]] = []
        order = itertools.count()
        for robot, day in days.items():
            first = next(day, None)
            if first is not None:
                heapq.heappush(queue, (first[0], next(order), robot, first[1]))
        while queue:
            t, _, robot, act = heapq.heappop(queue)
            self.now = datetime.fromtimestamp(t, UTC)
            act()
            nxt = next(days[robot], None)
            if nxt is not None:
                heapq.heappush(queue, (max(nxt[0], t), next(order), robot, nxt[1]))
        self.out.end = self.now.timestamp()
        self.journal.close()
        self._stamp()
        self._telemetry()
        return self.out

    def _stamp(self) -> None:
        """The journal's times are the play's (it stamps the wall clock)."""
        with sqlite3.connect(self.out.db) as conn:
            conn.executemany("UPDATE batches SET ts = ? WHERE revision = ?", self.times)

    def _telemetry(self) -> None:
        p = self.plan
        clock = [0.0]
        archive = TelemetryArchive(self.out.archive, clock=lambda: clock[0])
        archive.start()
        try:
            for i, robot in enumerate(SKILLS):
                archive.fleet(
                    RobotInfo(name=robot, online=True, since=T0), at=T0.timestamp() + i * 0.1
                )
            for a in self.alerts:
                archive.alert(a)
            for n, (revision, op, ts) in enumerate(self.index, 1):
                archive.journaled(revision, op, ts=ts)
                if n % 5_000 == 0:  # never QUEUE_MAX waiting: a full queue drops
                    archive.flush()
            step = 1.0 / p.telemetry_hz
            ticks = int((self.out.end - self.out.start) / step)
            for k in range(ticks):
                t = self.out.start + k * step
                clock[0] = t
                for robot in SKILLS:
                    archive.took(self._sample(robot, t - p.delay_s), received=t)
                # hours in a moment: let the writer keep up (a flood faster than
                # the writer's turns at the GIL filled its queue on a loaded machine)
                if k % 500 == 499:
                    archive.flush()
        finally:
            archive.close(timeout=120)

    def _sample(self, robot: str, at: float) -> Telemetry:
        busy = next((a for a in self.activity[robot] if a[0] <= at < a[1]), None)
        phase = at / 60.0 + list(SKILLS).index(robot)
        return Telemetry(
            robot=robot,
            pose=Pose(x=20 * math.cos(phase), y=20 * math.sin(phase), yaw=phase % 6.28),
            battery=0.2 + 0.7 * abs(math.sin(at / 7200.0)),
            mode="executing" if busy else "idle",
            skill=busy[2] if busy else None,
            progress=min(1.0, (at - busy[0]) / (busy[1] - busy[0])) if busy else None,
            at=datetime.fromtimestamp(at, UTC),
        )


def record_mission(folder: Path, plan: Plan | None = None) -> Recorded:
    """Play a mission into `folder` (mission.db and its telemetry archive)."""
    return _Play(folder, plan or Plan()).run()


def time_of(t: float) -> datetime:
    return datetime.fromtimestamp(t, UTC)


__all__ = ["Plan", "Recorded", "T0", "record_mission", "time_of", "timedelta"]
