"""Markers chosen on board as rules (backend.core.rules.choose): a skill bound
to one goes up with its rule and its team; the robot's report of its choice
sets the marker once (idle skills bound to it follow), says so in an alert,
and a different place reported later is a warning, never a silent change.
The journal gives the chosen marker back."""

from __future__ import annotations

from pathlib import Path

from backend.core.alerts import AlertKind
from backend.core.model import ChooseOnBoard, ChooseRule, Enqueue, Pose, PoseMarker, Status
from backend.core.ops import EditSkill, MarkerAdd, Report, Retry, Sync, SyncAck
from backend.core.rules.engine import Engine
from backend.server.journal import Journal

from .conftest import T0, tutorial_engine

S = Status
RULE = ChooseRule(pick="closest_pair", rank=1, place="approach", ask=["ardea"])
ESTIMATE = Pose(x=50.0, y=-40.0)
CHOSEN = Pose(x=57.0, y=-38.0)


class Journaled:
    """The engine, every applied operation journaled as the server does."""

    def __init__(self, db: Path):
        self.engine = tutorial_engine()
        self.engine.clock = lambda: T0
        self.journal = Journal.open(db, library=self.engine.mission.library)
        self.journal.snapshot(self.engine.mission)
        self.n = 0

    def submit(self, op, client: str = "alice"):
        self.n += 1
        applied = self.engine.submit(op, client=client, request_id=f"{client}-{self.n}")
        self.journal.record(
            applied, op, client=client, request_id=f"{client}-{self.n}", mission=self.engine.mission
        )
        return applied

    def report(self, robot: str, sid: str, status: Status, **kw):
        seq = self.engine.mission.report_seqs.get(robot, 0) + 1
        return self.submit(
            Report(robot=robot, seq=seq, id=sid, status=status, at=T0, **kw), f"robot:{robot}"
        )

    def sent(self, robot: str, through: str) -> Enqueue:
        """What a sync sends the robot (its command, left pending)."""
        applied = self.submit(Sync(robot=robot, through=through))
        c = self.engine.mission.command(applied.value["command"])
        assert c is not None and isinstance(c.command, Enqueue)
        return c.command

    def sync(self, robot: str, through: str) -> None:
        """Synchronized (the direct path: the robot has them)."""
        ids = [s.id for s in self.engine.plan_sync(Sync(robot=robot, through=through))]
        self.submit(SyncAck(robot=robot, ids=ids), f"robot:{robot}")
        self.engine.release(robot, ids)


def planned(tmp_path: Path) -> Journaled:
    """R1 chosen on board; lru1-1 and lru2-1 drive to it."""
    j = Journaled(tmp_path / "journal.db")
    j.submit(MarkerAdd(name="R1", marker=PoseMarker(pose=ESTIMATE, choose=RULE)))
    j.submit(EditSkill(id="lru1-1", bindings={"goal": "R1"}))
    j.submit(EditSkill(id="lru2-1", bindings={"goal": "R1"}))
    return j


def goal(engine: Engine, sid: str) -> tuple[float, float]:
    found = engine.mission.find(sid)
    assert found is not None
    g = found[2].params["goal"]
    return g["x"], g["y"]


def test_a_skill_bound_to_a_marker_chosen_on_board_goes_up_with_its_rule(tmp_path):
    j = planned(tmp_path)
    enqueue = j.sent("lru1", "lru1-1")
    assert enqueue.choose == {
        "lru1-1": {"goal": ChooseOnBoard(marker="R1", rule=RULE, team=["lru2"])}
    }
    assert enqueue.skills[0].params["goal"]["x"] == 50.0  # the ground's estimate meanwhile


def test_the_first_report_of_a_choice_places_the_marker_and_says_so(tmp_path):
    j = planned(tmp_path)
    j.sync("lru1", "lru1-1")
    applied = j.report("lru1", "lru1-1", S.SYNCHWAITING, info="chose", chosen={"R1": CHOSEN})
    mk = j.engine.mission.markers["R1"]
    assert isinstance(mk, PoseMarker)
    assert (mk.pose, mk.chosen.robot, mk.chosen.skill, mk.choose) == (
        CHOSEN,
        "lru1",
        "lru1-1",
        RULE,
    )
    assert not mk.to_choose
    (alert,) = applied.alerts
    assert (alert.kind, alert.level) == (AlertKind.CHOSEN, "info")
    assert "lru1 chose R1 on board at (57.0, -38.0)" in alert.message
    assert goal(j.engine, "lru2-1") == (57.0, -38.0)  # an idle skill bound to it follows
    # once chosen, it goes up like any marker's value
    enqueue = j.sent("lru2", "lru2-1")
    assert enqueue.choose == {} and goal(j.engine, "lru2-1") == (57.0, -38.0)


def test_another_place_reported_later_is_a_warning_and_the_marker_stays(tmp_path):
    j = planned(tmp_path)
    j.sync("lru1", "lru1-1")
    j.sync("lru2", "lru2-1")
    j.report("lru1", "lru1-1", S.SYNCHWAITING, chosen={"R1": CHOSEN})
    same = j.report("lru2", "lru2-1", S.SYNCHWAITING, chosen={"R1": CHOSEN})
    assert same.alerts == []  # agreeing is nothing to say
    other = j.report("lru2", "lru2-1", S.RUNNING, chosen={"R1": Pose(x=90.0, y=-60.0)})
    (alert,) = other.alerts
    assert alert.level == "warning" and "lru1 chose it at (57.0, -38.0)" in alert.message
    assert j.engine.mission.markers["R1"].pose == CHOSEN
    assert j.engine.mission.find("lru2-1")[2].status == S.RUNNING  # the report itself applies


def test_a_choice_of_a_marker_not_chosen_on_board_is_ignored_with_a_warning(tmp_path):
    j = planned(tmp_path)
    j.sync("lru1", "lru1-1")
    applied = j.report("lru1", "lru1-1", S.SYNCHWAITING, chosen={"POI-A": CHOSEN})
    assert "not a marker chosen on board" in applied.alerts[0].message
    assert j.engine.mission.markers["POI-A"].pose == Pose(x=10.0, y=5.0)


def test_the_journal_gives_the_chosen_marker_back(tmp_path):
    j = planned(tmp_path)
    j.sync("lru1", "lru1-1")
    j.report("lru1", "lru1-1", S.SYNCHWAITING, chosen={"R1": CHOSEN})
    j.journal.close()
    again = Journal.open(tmp_path / "journal.db")
    mission, _requests = again.load()
    again.close()
    assert mission is not None
    assert mission.markers["R1"] == j.engine.mission.markers["R1"]
    assert mission.model_dump() == j.engine.mission.model_dump()


def test_a_retry_sends_the_place_chosen_since_the_failed_attempt(tmp_path):
    j = planned(tmp_path)
    j.sync("lru2", "lru2-1")
    j.report("lru2", "lru2-1", S.RUNNING)
    j.report("lru2", "lru2-1", S.FAILURE, info="stuck")  # before anyone chose R1
    j.sync("lru1", "lru1-1")
    j.report("lru1", "lru1-1", S.SYNCHWAITING, chosen={"R1": CHOSEN})
    applied = j.submit(Retry(id="lru2-1"))
    c = j.engine.mission.command(applied.value["command"])
    assert c is not None and isinstance(c.command, Enqueue)
    (attempt,) = c.command.skills
    assert (attempt.params["goal"]["x"], attempt.params["goal"]["y"]) == (57.0, -38.0)
    assert c.command.choose == {}  # chosen already: it goes up as a value
