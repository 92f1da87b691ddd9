"""Contingencies as rules: a fallback or goto is checked against the robot's
library where it is set, made concrete (parameters checked, markers' values
taken) where it is sent, and the branch a robot took is kept with the skill."""

from __future__ import annotations

from backend.core.checks import check_mission
from backend.core.model import Fallback, FallbackSkill, Goto, Policies, Status, Taken
from backend.core.ops import EditSkill, Sync
from backend.files.missions import load_mission

from .conftest import T0, TUTORIAL

S = Status


def test_a_fallback_the_robot_cannot_run_is_refused_naming_it(engine, refused):
    lru1_cannot = Policies(on_failure=Fallback(fallback=[FallbackSkill(skill="pick_stone")]))
    refused(
        engine,
        lambda: engine.submit(EditSkill(id="lru1-1", policies=lru1_cannot)),
        "bad_contingency",
        "lru1-1",
        "pick_stone",
        "policies.on_failure.fallback[0]",
        robot="lru1",
        skill="lru1-1",
    )
    bad_param = Fallback(fallback=[FallbackSkill(skill="drive_to", params={"speed": 9})])
    refused(
        engine,
        lambda: engine.submit(EditSkill(id="lru1-1", policies=Policies(on_timeout=bad_param))),
        "bad_contingency",
        "speed",
    )
    refused(
        engine,
        lambda: engine.submit(
            EditSkill(id="lru1-1", policies=Policies(on_failure=Goto(goto="Nowhere")))
        ),
        "bad_contingency",
        "Nowhere",
        "POI-A",  # the markers there are
    )


def test_sync_sends_the_branches_as_skills_with_marker_values(engine):
    pol = Policies(timeout="10m", on_failure=Goto(goto="POI-A"), on_timeout="skip")
    engine.submit(EditSkill(id="lru1-1", policies=pol))
    assert engine.mission.find("lru1-1")[2].policies.timeout == 600
    engine.clock = lambda: T0
    applied = engine.submit(Sync(robot="lru1", through="lru1-1"))
    c = engine.mission.command(applied.value["command"])
    enqueue = c.command
    b = enqueue.contingencies["lru1-1"]
    assert b.on_timeout == []  # skip runs nothing
    (drive,) = b.on_failure
    assert (drive.skill, drive.params["goal"]["x"], drive.params["goal"]["y"]) == (
        "drive_to",
        10.0,
        5.0,
    )
    assert drive.params["speed"] == 0.5  # the library's default, filled in
    assert enqueue.kinds["drive_to"]["goal"] == "pose"


def test_the_branch_a_robot_took_stays_with_the_skill(engine, sync, report, skill):
    engine.submit(EditSkill(id="lru1-1", policies=Policies(on_failure="skip")))
    sync(engine, "lru1")
    report(engine, "lru1", "lru1-1", S.RUNNING)
    took = Taken(trigger="failure", branch="fallback", reason="goal impassable")
    # running again, to say which branch it takes: news, not a repeat
    report(engine, "lru1", "lru1-1", S.RUNNING, branch=took)
    assert skill(engine, "lru1-1").branch == took
    took = took.model_copy(update={"branch": "skip"})
    report(engine, "lru1", "lru1-1", S.FAILURE, info="goal impassable → skip", branch=took)
    s = skill(engine, "lru1-1")
    assert (s.status, s.branch, s.status_info) == (S.FAILURE, took, "goal impassable → skip")


def test_a_mission_file_names_where_a_contingency_is_wrong(tmp_path):
    mission, library = load_mission(TUTORIAL)
    s = mission.tasks["lru2"][0]
    s.policies = Policies(on_failure=Fallback(fallback=[FallbackSkill(skill="fly_to")]))
    problems = check_mission(mission, library)
    assert [(p, "fly_to" in why) for p, why in problems] == [
        (("tasks", "lru2", 0, "policies", "on_failure", "fallback", 0), True)
    ]


def test_a_barrier_timeout_travels_with_the_sync_and_survives_undo(engine):
    from backend.core.ops import AddBarrier, RemoveBarrier, Undo

    added = engine.submit(
        AddBarrier(ids=["lru1-1", "lru2-1"], timeout="20m", on_timeout="continue"), client="c"
    )
    bid = added.value["barrier"]
    engine.submit(RemoveBarrier(barrier=bid), client="c")
    engine.submit(Undo(), client="c")
    b = engine.mission.barriers[bid]
    assert (b.timeout, b.on_timeout) == (1200, "continue")
    engine.clock = lambda: T0
    applied = engine.submit(Sync(robot="lru1", through="lru1-1"))
    info = engine.mission.command(applied.value["command"]).command.barriers["lru1-1"]
    assert (info.timeout, info.on_timeout) == (1200, "continue")


def test_after_names_another_robots_skill_and_goes_with_the_sync(engine, refused):
    refused(
        engine,
        lambda: engine.submit(EditSkill(id="lru1-2", policies=Policies(after="lru1-1"))),
        "bad_contingency",
        "lru1's own",
    )
    refused(
        engine,
        lambda: engine.submit(EditSkill(id="lru1-2", policies=Policies(after="nope-9"))),
        "bad_contingency",
        "no such skill",
    )
    engine.submit(EditSkill(id="lru1-1", policies=Policies(after="lru2-1")))
    engine.clock = lambda: T0
    applied = engine.submit(Sync(robot="lru1", through="lru1-1"))
    assert engine.mission.command(applied.value["command"]).command.after == {"lru1-1": "lru2"}


def test_a_restarted_robot_learns_the_outcomes_others_wait_for(engine, sync, report):
    """RegisterReply.outcomes: a finished skill another robot's unfinished
    skill waits for (after); none once nobody waits, none unfinished."""
    from backend.core.contingency import awaited_outcomes

    engine.submit(EditSkill(id="lru2-1", policies=Policies(after="lru1-1")))
    engine.submit(EditSkill(id="lru2-2", policies=Policies(after="lru1-2")))
    assert awaited_outcomes(engine.mission, "lru1") == {}  # lru1's skills have not ended
    sync(engine, "lru1")
    report(engine, "lru1", "lru1-1", S.RUNNING)
    report(engine, "lru1", "lru1-1", S.SUCCESS)
    report(engine, "lru1", "lru1-2", S.RUNNING)
    report(engine, "lru1", "lru1-2", S.FAILURE, info="lens cap on")
    assert awaited_outcomes(engine.mission, "lru1") == {"lru1-1": "success", "lru1-2": "failure"}
    assert awaited_outcomes(engine.mission, "lru2") == {}
    sync(engine, "lru2")
    report(engine, "lru2", "lru2-1", S.RUNNING)
    report(engine, "lru2", "lru2-1", S.SUCCESS)  # nobody waits for lru1-1 any more
    assert awaited_outcomes(engine.mission, "lru1") == {"lru1-2": "failure"}


def test_a_barriers_timeout_is_changed_while_its_skills_are_idle(engine, refused, sync):
    from backend.core.ops import AddBarrier, EditBarrier, Undo

    bid = engine.submit(AddBarrier(ids=["lru1-1", "lru2-1"]), client="c").value["barrier"]
    engine.submit(EditBarrier(barrier=bid, timeout="10m", on_timeout="continue"), client="c")
    b = engine.mission.barriers[bid]
    assert (b.skills, b.timeout, b.on_timeout) == (["lru1-1", "lru2-1"], 600, "continue")
    engine.submit(Undo(), client="c")  # back to waiting for ever
    b = engine.mission.barriers[bid]
    assert (b.timeout, b.on_timeout) == (None, "halt")
    refused(
        engine,
        lambda: engine.submit(EditBarrier(barrier="b99", timeout=60)),
        "unknown_barrier",
        bid,  # the barriers there are
    )
    sync(engine, "lru1", "lru1-1")  # on the robot with the barrier as it was
    refused(
        engine,
        lambda: engine.submit(EditBarrier(barrier=bid, timeout=60)),
        "not_idle",
        "lru1-1",
        "holds the barrier as it was synchronized",
        robot="lru1",
        skill="lru1-1",
    )
