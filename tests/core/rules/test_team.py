"""Robots joining and retiring at runtime, and skills given to another robot
(issue 30): `backend.core.rules.team` and `backend.core.rules.reassign`."""

from __future__ import annotations

from collections.abc import Mapping

from backend.core.events import EventBatch, apply_events
from backend.core.model import CommandState, Policies, Status
from backend.core.ops import (
    AddBarrier,
    AddRobot,
    AddSkill,
    Control,
    EditSkill,
    Reassign,
    RemoveBarrier,
    RetireRobot,
    Sync,
    Undo,
)
from backend.core.rules.engine import Engine
from tests.core.rules.conftest import bring, ids, refused, skill, status_of, sync


def test_a_robot_of_a_known_type_joins_with_an_empty_plan(engine: Engine) -> None:
    applied = engine.submit(AddRobot(name="lru3", type="lru_science"))
    assert engine.mission.robots["lru3"].type == "lru_science"
    assert engine.mission.tasks["lru3"] == []
    assert [a.robot for a in applied.alerts] == ["lru3"]
    assert "joined" in applied.alerts[0].message
    # it can be planned for at once
    engine.submit(AddSkill(robot="lru3", skill="drive_to", params={"goal": {"x": 1, "y": 2}}))
    assert len(ids(engine, "lru3")) == 1


def test_an_unknown_type_is_refused_naming_what_is_missing(engine: Engine) -> None:
    r = refused(
        engine,
        lambda: engine.submit(AddRobot(name="rover9", type="hovercraft")),
        "unknown_robot_type",
        "hovercraft",
        "lru_science",
        "add robot type",
        robot="rover9",
    )
    assert "rover9" in r.message


def test_a_robot_is_added_once(engine: Engine) -> None:
    refused(
        engine,
        lambda: engine.submit(AddRobot(name="lru1", type="lru_science")),
        "robot_exists",
        "lru1",
    )


def test_retired_robot_gets_no_new_syncs_and_keeps_its_log(engine: Engine) -> None:
    bring(engine, "lru1", "lru1-1", Status.SUCCESS)
    applied = engine.submit(RetireRobot(name="lru1", reason="wheel stuck"))
    assert engine.mission.robots["lru1"].retired == "wheel stuck"
    assert status_of(engine, "lru1-1") == Status.SUCCESS  # the log stays
    assert applied.value["to_reassign"] == ["lru1-2"]
    assert any("reassign --from lru1" in n for n in applied.notes)
    refused(engine, lambda: engine.submit(Sync(robot="lru1")), "retired", "wheel stuck")


class _Link:
    """The robot link as the rules see it: lru1 registered, then went out of reach."""

    def __init__(self, reachable: bool, offers: Mapping[str, Mapping[str, str]] = {}):
        self._reachable = reachable
        self._offers = offers

    def offered(self, robot: str) -> Mapping[str, str] | None:
        return self._offers.get(robot)

    def reachable(self, robot: str) -> bool:
        return self._reachable


def test_retiring_a_reachable_robot_unsyncs_its_queue_by_its_uplink(engine: Engine) -> None:
    engine.offers = _Link(reachable=True)
    bring(engine, "lru1", "lru1-2", Status.IDLE_SYNCHRONIZED)
    applied = engine.submit(RetireRobot(name="lru1", reason="low battery"))
    [c] = engine.mission.pending_commands("lru1")
    assert (c.op, c.skills) == ("unsync", ["lru1-1", "lru1-2"])
    # until the robot answers, they are its: locked, still queued
    assert status_of(engine, "lru1-1") == Status.IDLE_SYNCHRONIZED
    assert applied.value["to_reassign"] == ["lru1-1", "lru1-2"]


def test_retiring_an_unreachable_robot_takes_its_queue_back_on_the_ground(
    engine: Engine,
) -> None:
    engine.offers = _Link(reachable=False)
    bring(engine, "lru1", "lru1-1", Status.RUNNING)
    sync_queued = engine.submit(Sync(robot="lru1"))  # never transmitted
    retired = engine.submit(RetireRobot(name="lru1", reason="stopped responding"))
    assert retired.value["to_reassign"] == ["lru1-1.2", "lru1-2"]
    assert status_of(engine, "lru1-1") == Status.FAILURE
    assert "outcome is unknown" in skill(engine, "lru1-1").status_info
    assert status_of(engine, "lru1-2") == Status.IDLE
    # the interrupted skill's next attempt leads the plan to reassign
    assert ids(engine, "lru1") == ["lru1-1", "lru1-1.2", "lru1-2"]
    assert skill(engine, "lru1-1.2").attempt == 2
    command = engine.mission.command(sync_queued.value["command"])
    assert command is not None and command.state == CommandState.CANCELLED
    assert engine.mission.pending_commands("lru1") == []


def test_a_given_skill_says_where_it_came_from_not_its_old_robots_news(
    engine: Engine,
) -> None:
    engine.offers = _Link(reachable=False)
    bring(engine, "lru1", "lru1-2", Status.IDLE_SYNCHRONIZED)
    engine.submit(RetireRobot(name="lru1", reason="stopped responding"))
    assert "taken back on the ground" in skill(engine, "lru1-2").status_info
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    engine.submit(Reassign(from_robot="lru1", to="lru3"))
    assert skill(engine, "lru1-2").status_info == "given by lru1"
    engine.submit(Undo())  # back on lru1, as it was
    assert "taken back on the ground" in skill(engine, "lru1-2").status_info


def test_whole_plan_moves_keeping_params_bindings_and_order(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    before = [skill(engine, sid) for sid in ("lru1-1", "lru1-2")]
    applied = engine.submit(Reassign(from_robot="lru1", to="lru3"))
    assert ids(engine, "lru3") == ["lru1-1", "lru1-2"]
    assert ids(engine, "lru1") == []
    for old in before:
        new = skill(engine, old.id)
        assert (new.params, new.bindings, new.label) == (old.params, old.bindings, old.label)
    assert applied.value["moved"] == ["lru1-1", "lru1-2"]


def test_a_skill_the_target_cannot_do_stays_and_says_why(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    engine.submit(AddSkill(robot="lru2", skill="pick_stone", params={"target": {"x": 1, "y": 1}}))
    picked = ids(engine, "lru2")[-1]
    applied = engine.submit(Reassign(ids=["lru2-1", picked], to="lru3"))
    assert applied.value["moved"] == ["lru2-1"]
    assert "has no skill 'pick_stone'" in applied.value["refused"][picked]
    assert any(n.startswith(f"{picked} stays") for n in applied.notes)


def test_nothing_movable_is_refused_with_each_reason(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    bring(engine, "lru1", "lru1-1", Status.IDLE_SYNCHRONIZED)
    refused(
        engine,
        lambda: engine.submit(Reassign(ids=["lru1-1"], to="lru3")),
        "cannot_reassign",
        "lru1-1",
        "idle_synchronized",
    )


def test_manifest_without_the_skill_refuses_it(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    engine.offers = _Link(reachable=True, offers={"lru3": {"drive_to": "1.0.0"}})
    applied = engine.submit(Reassign(from_robot="lru1", to="lru3"))
    assert applied.value["moved"] == ["lru1-1"]
    assert "does not offer skill 'take_science_image'" in applied.value["refused"]["lru1-2"]


def test_barrier_follows_its_skill_or_is_dissolved(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    engine.submit(AddBarrier(ids=["lru1-2", "lru2-2"]))
    kept = engine.submit(Reassign(ids=["lru1-2"], to="lru3"))
    assert engine.mission.barrier_of("lru1-2") is not None
    assert any("now ties" in n for n in kept.notes)
    engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]))
    gone = engine.submit(Reassign(ids=["lru2-1"], to="lru1"))
    assert engine.mission.barrier_of("lru1-1") is None
    assert any("dissolved" in n for n in gone.notes) and gone.value["dissolved"]


def test_undo_returns_each_skill_with_its_barrier(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c")
    engine.submit(Reassign(ids=["lru1-1", "lru2-1"], to="lru3"), client="c")
    assert engine.mission.barrier_of("lru1-1") is None
    engine.submit(Undo(), client="c")
    assert ids(engine, "lru1") == ["lru1-1", "lru1-2"]
    assert ids(engine, "lru2") == ["lru2-1", "lru2-2"]
    assert engine.mission.barrier_of("lru1-1") == engine.mission.barrier_of("lru2-1") is not None


def test_reassigning_to_a_retired_robot_is_refused(engine: Engine) -> None:
    engine.submit(RetireRobot(name="lru2", reason="arm broken"))
    refused(
        engine,
        lambda: engine.submit(Reassign(ids=["lru1-1"], to="lru2")),
        "retired",
        "arm broken",
    )


def test_team_events_replay_to_the_same_mission(engine: Engine) -> None:
    start = engine.mission.copy_deep()
    batches: list[EventBatch] = []
    for op in (
        AddRobot(name="lru3", type="lru_science"),
        RetireRobot(name="lru1", reason="broken"),
        Reassign(from_robot="lru1", to="lru3"),
    ):
        applied = engine.submit(op)
        batches.append(EventBatch.model_validate_json(applied.batch().model_dump_json()))
    replayed = start
    for b in batches:
        replayed = apply_events(replayed, b)
    assert replayed.model_dump() == engine.mission.model_dump()


def test_team_operations_are_refused_stale_after_a_later_change(engine: Engine) -> None:
    """--expect-revision: retire, reassign (and the undo of a reassign) touch
    the robot's list and the skills they move."""
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    seen = engine.mission.revision
    engine.submit(EditSkill(id="lru1-2", label="look again"), client="other")
    give = Reassign(ids=["lru1-2"], to="lru3")
    refused(engine, lambda: engine.submit(give, expected_revision=seen), "stale", "skill lru1-2")
    seen = engine.mission.revision
    engine.submit(AddSkill(robot="lru1", skill="recharge"), client="other")
    for op, what in (
        (RetireRobot(name="lru1", reason="broken"), "the list of lru1"),
        (Reassign(from_robot="lru1", to="lru3"), "the list of lru1"),
        (Reassign(ids=["lru2-1"], to="lru1"), "the list of lru1"),  # the list it goes to
    ):
        r = refused(engine, lambda op=op: engine.submit(op, expected_revision=seen), "stale", what)
        assert f"after the revision {seen} you saw" in r.message
    # the robots' lists as the client saw them now: accepted
    now = engine.mission.revision
    engine.submit(Reassign(ids=["lru1-2"], to="lru3"), expected_revision=now, client="c")
    engine.submit(AddSkill(robot="lru3", skill="recharge"), client="other")
    engine.submit(EditSkill(id="lru1-2", label="mine now"), client="other")
    undo = refused(engine, lambda: engine.submit(Undo(), client="c"), "stale", "another client")
    assert "cannot undo" in undo.message
    assert ids(engine, "lru3")[0] == "lru1-2"  # the other client's edit stays
    fresh = engine.mission.revision
    engine.submit(AddRobot(name="lru4", type="lru_science"), expected_revision=fresh)
    engine.submit(RetireRobot(name="lru4", reason="not needed"), expected_revision=fresh + 1)


def _after(engine: Engine, waiter: str, awaited: str | None) -> None:
    engine.submit(EditSkill(id=waiter, policies=Policies(after=awaited)))


def _waits_for(engine: Engine, sid: str) -> str | None:
    return skill(engine, sid).policies.after


def test_an_after_link_follows_its_skill_to_another_robot(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    _after(engine, "lru1-2", "lru2-1")
    applied = engine.submit(Reassign(ids=["lru1-2"], to="lru3"))
    assert _waits_for(engine, "lru1-2") == "lru2-1"  # lru3 asks lru2 now
    assert "lru1-2 (on lru3) still starts after lru2-1, now on lru2" in applied.notes
    assert applied.value["afters_dissolved"] == {}
    # the awaited skill moves: its waiter asks the new robot (the link names the skill)
    applied = engine.submit(Reassign(ids=["lru2-1"], to="lru1"))
    assert _waits_for(engine, "lru1-2") == "lru2-1"
    assert "lru1-2 (on lru3) still starts after lru2-1, now on lru1" in applied.notes


def test_an_after_link_that_would_tie_a_robot_to_itself_is_dissolved(engine: Engine) -> None:
    _after(engine, "lru1-1", "lru2-1")
    applied = engine.submit(Reassign(ids=["lru1-1"], to="lru2"))
    assert _waits_for(engine, "lru1-1") is None
    assert applied.value["afters_dissolved"] == {"lru1-1": "lru2-1"}
    said = next(n for n in applied.notes if n.startswith("lru1-1 no longer starts after"))
    assert "both are on lru2 now, and a robot never waits for itself" in said
    assert said.endswith("its plan runs lru2-1 first, as before")
    sync(engine, "lru2")  # nothing left for the plan checks to refuse


def test_a_dissolved_after_says_when_the_plan_runs_the_waiter_first(engine: Engine) -> None:
    _after(engine, "lru1-2", "lru2-1")  # lru1-2 stays; what it waits for comes to lru1
    applied = engine.submit(Reassign(ids=["lru2-1"], to="lru1"), client="c")
    assert ids(engine, "lru1") == ["lru1-1", "lru1-2", "lru2-1"]
    assert _waits_for(engine, "lru1-2") is None
    assert any(
        n.endswith("its plan runs lru1-2 first: move lru2-1 above it to keep the order")
        for n in applied.notes
    ), applied.notes
    engine.submit(Undo(), client="c")  # back, and the link with it
    assert ids(engine, "lru2") == ["lru2-1", "lru2-2"]
    assert _waits_for(engine, "lru1-2") == "lru2-1"


def test_a_skill_awaited_by_one_on_its_robot_stays(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    _after(engine, "lru2-1", "lru1-1")
    sync(engine, "lru2", "lru2-1")  # lru2 asks lru1 for lru1-1, robot to robot
    refused(
        engine,
        lambda: engine.submit(Reassign(ids=["lru1-1"], to="lru3")),
        "cannot_reassign",
        "lru2-1",
        "waits for it, asking lru1 robot to robot; unsynchronize lru2-1 first",
    )


def test_a_skill_whose_partner_is_the_robot_it_goes_to_stays(engine: Engine) -> None:
    look = {"target": {"x": 1, "y": 1}, "partner": "lru2"}
    sid = engine.submit(AddSkill(robot="lru1", skill="identify_stone", params=look)).value["id"]
    refused(
        engine,
        lambda: engine.submit(Reassign(ids=[sid], to="lru2")),
        "cannot_reassign",
        "its partner is lru2: a robot is not its own partner",
    )


def _identify_together(engine: Engine) -> str:
    """lru1's new identify_stone with lru2 (partner) at a barrier with lru2-2, whose
    partner is lru1: the pair of the demo mission. Returns lru1's skill id."""
    look = {"target": {"x": 10, "y": 5}, "partner": "lru2"}
    sid = engine.submit(AddSkill(robot="lru1", skill="identify_stone", params=look)).value["id"]
    params = {**skill(engine, "lru2-2").params, "partner": "lru1"}
    engine.submit(EditSkill(id="lru2-2", params=params))
    engine.submit(AddBarrier(ids=[sid, "lru2-2"]))
    return sid


def test_a_barrier_partner_works_with_the_robot_its_partner_skill_went_to(
    engine: Engine,
) -> None:
    """Seen in the demo: lru2-3 kept `partner: lru1` after lru1-3 went to lru3
    with their barrier, so lru2 asked the broken lru1 and identified alone."""
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    sid = _identify_together(engine)
    applied = engine.submit(Reassign(ids=[sid], to="lru3"), client="c")
    assert skill(engine, "lru2-2").params["partner"] == "lru3"
    assert skill(engine, sid).params["partner"] == "lru2"  # the one moved keeps its own
    assert applied.value["partners_renamed"] == {"lru2-2": "lru1"}
    assert "lru2-2 works with lru3 now (its partner was lru1)" in applied.notes
    assert engine.mission.barrier_of(sid) == engine.mission.barrier_of("lru2-2") is not None
    engine.submit(Undo(), client="c")
    assert skill(engine, "lru2-2").params["partner"] == "lru1"
    assert sid in ids(engine, "lru1")


def test_undo_keeps_a_later_edit_of_the_renamed_partner(engine: Engine) -> None:
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    sid = _identify_together(engine)
    engine.submit(Reassign(ids=[sid], to="lru3"), client="c")
    params = {**skill(engine, "lru2-2").params, "search_radius": 3.0}
    engine.submit(EditSkill(id="lru2-2", params=params), client="other")
    refused(engine, lambda: engine.submit(Undo(), client="c"), "stale", "another client")
    assert skill(engine, "lru2-2").params["partner"] == "lru3"


def test_a_partner_elsewhere_is_not_renamed(engine: Engine) -> None:
    """A skill in no barrier with the one moved keeps its partner (the plan
    checks say it names a robot it will not meet)."""
    sid = _identify_together(engine)
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    engine.submit(RemoveBarrier(barrier=engine.mission.barrier_of(sid) or ""))
    applied = engine.submit(Reassign(ids=[sid], to="lru3"))
    assert skill(engine, "lru2-2").params["partner"] == "lru1"
    assert applied.value["partners_renamed"] == {}


def test_a_skill_tied_to_a_partner_under_way_says_to_stop_its_robot(engine: Engine) -> None:
    """The demo's lru2 waits at the barrier for lru1 by name: it must be stopped
    before its skill can be unsynchronized (unsync takes queued skills only)."""
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    sid = _identify_together(engine)
    bring(engine, "lru2", "lru2-1", Status.SUCCESS)
    bring(engine, "lru2", "lru2-2", Status.SYNCHWAITING)
    refused(
        engine,
        lambda: engine.submit(Reassign(ids=[sid], to="lru3")),
        "cannot_reassign",
        "barrier",
        "synchwaiting on lru2 (which waits for this skill's robot by name)",
        "stop lru2 (lru2-2 goes back to its queue), then unsynchronize lru2-2",
    )


def test_a_skill_that_stays_ahead_of_moved_ones_says_the_order_is_lost(engine: Engine) -> None:
    """Seen in the demo walk: lru1-3 (held by lru2 at their barrier) stayed while
    lru1-4 moved; given later it went last on lru3, after the science image it
    prepared, which failed. The gift says so, and how to restore the order."""
    engine.submit(AddRobot(name="lru3", type="lru_science"))
    sid = _identify_together(engine)  # last of lru1's plan: add one after it
    image = {"target": {"x": 10, "y": 5}}
    after = engine.submit(AddSkill(robot="lru1", skill="take_science_image", params=image))
    bring(engine, "lru2", "lru2-1", Status.SUCCESS)
    bring(engine, "lru2", "lru2-2", Status.SYNCHWAITING)
    applied = engine.submit(Reassign(from_robot="lru1", to="lru3"))
    later = after.value["id"]
    assert later in applied.value["moved"] and sid in applied.value["refused"]
    (said,) = [n for n in applied.notes if n.startswith(f"{sid} came before")]
    assert said == (
        f"{sid} came before {later} on lru1: given later, it goes last on lru3; "
        f"move it before {later} there, or undo and give them once {sid} can move"
    )
    # a skill that stays after the moved ones loses no order: nothing said
    engine.submit(Undo())
    quiet = engine.submit(Reassign(ids=["lru1-1", sid], to="lru3"))
    assert sid in quiet.value["refused"]
    assert not [n for n in quiet.notes if "came before" in n]


def test_retiring_says_which_skills_a_partner_under_way_holds(engine: Engine) -> None:
    """lru2 waits at the barrier for lru1, which breaks: retiring lru1 says what
    frees the skill lru2 waits for (and nothing of skills no one waits for)."""
    sid = _identify_together(engine)
    bring(engine, "lru2", "lru2-1", Status.SUCCESS)
    bring(engine, "lru2", "lru2-2", Status.SYNCHWAITING)
    applied = engine.submit(RetireRobot(name="lru1", reason="stopped responding"))
    (said,) = [n for n in applied.notes if "cannot be given away yet" in n]
    assert said.startswith(f"{sid} cannot be given away yet: barrier")
    assert said.endswith("stop lru2 (lru2-2 goes back to its queue), then unsynchronize lru2-2")


def test_run_all_says_nothing_of_a_retired_robot(engine: Engine) -> None:
    """It gets no new syncs: "lru1 has nothing to run: synchronize skills first"
    (seen in the demo after lru1 was retired) told the operator to do what is refused."""
    engine.submit(RetireRobot(name="lru1", reason="broken"))
    sync(engine, "lru2")
    applied = engine.submit(Control(op="run"))
    assert applied.value["commands"].keys() == {"lru2"}
    assert not any("lru1" in n for n in applied.notes), applied.notes
    alone = refused(
        engine, lambda: engine.submit(Control(op="run", robot="lru1")), "not_applicable"
    )
    assert "lru1" in alone.message  # named, it still says why
