"""ctl's contingency options and how a row shows them."""

from __future__ import annotations

import pytest

from backend.cli.ctl.args import parse_args
from backend.cli.ctl.build import build_op
from backend.cli.ctl.errors import UsageError
from backend.core.contingency import marks
from backend.core.model import Fallback, FallbackSkill, Goto, Policies
from backend.files.missions import load_mission

from .helpers import TUTORIAL


@pytest.fixture
def tutorial():
    return load_mission(TUTORIAL)


def op_of(argv, tutorial):
    mission, library = tutorial
    return build_op(parse_args(argv), mission=mission, library=library)


def test_edit_sets_contingencies_and_keeps_the_rest(tutorial):
    mission, _ = tutorial
    mission.tasks["lru1"][0].policies = Policies(retries=2, on_timeout="skip")
    op = op_of(["edit", "lru1-1", "--skill-timeout", "10m", "--on-failure", "skip"], tutorial)
    assert op.policies == Policies(retries=2, timeout=600, on_timeout="skip", on_failure="skip")
    op = op_of(["edit", "lru1-1", "--on-failure", "goto:POI-A", "--not-after", "2h"], tutorial)
    assert op.policies.on_failure == Goto(goto="POI-A") and op.policies.not_after == 7200
    op = op_of(["edit", "lru1-1", "--on-timeout", "fallback:recharge+explore"], tutorial)
    assert op.policies.on_timeout == Fallback(
        fallback=[FallbackSkill(skill="recharge"), FallbackSkill(skill="explore")]
    )
    op = op_of(["edit", "lru1-1", "--skill-timeout", "off"], tutorial)
    assert op.policies.timeout is None


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--skill-timeout", "soon"], "mission-time duration"),
        (["--on-failure", "retry"], "goto:MARKER"),
        (["--on-timeout", "goto:"], "goto:MARKER"),
    ],
)
def test_bad_contingency_options_say_what_they_take(tutorial, argv, needle, capsys):
    with pytest.raises((UsageError, SystemExit)):
        op_of(["edit", "lru1-1", *argv], tutorial)
    assert needle in capsys.readouterr().err


def test_marks_on_a_row():
    p = Policies(
        timeout="10m",
        on_timeout="skip",
        on_failure=Fallback(fallback=[FallbackSkill(skill="recharge", bindings={"at": "Lander"})]),
    )
    assert marks(p) == ["⏱10m→skip", "✗→recharge@Lander"]
    assert marks(p, unicode=False) == ["T10m->skip", "X->recharge@Lander"]
    assert marks(Policies(not_after=7200, on_failure=Goto(goto="Lander"))) == [
        "⏱≤sim 2:00:00→halt",  # an instant of the mission clock, not a duration
        "✗→goto@Lander",
    ]
    assert marks(Policies()) == []


def test_after_is_set_and_cleared(tutorial):
    op = op_of(["edit", "lru1-1", "--after", "lru2-1"], tutorial)
    assert op.policies.after == "lru2-1"
    assert op_of(["edit", "lru1-1", "--after", "off"], tutorial).policies.after is None
    assert marks(Policies(after="lander-1")) == ["after lander-1"]


def test_ctl_after_edits_only_the_after(tutorial):
    mission, _ = tutorial
    mission.tasks["lru1"][0].policies = Policies(retries=2)
    op = op_of(["after", "lru1-1", "lru2-1"], tutorial)
    assert (op.id, op.policies) == ("lru1-1", Policies(retries=2, after="lru2-1"))
    assert op_of(["after", "lru1-1", "off"], tutorial).policies.after is None


def test_ctl_state_tags_both_ends_of_an_after(tutorial):
    from backend.cli.ctl.render import state_json, state_text
    from backend.client.client import MissionClient

    mission, library = tutorial
    mission.tasks["lru2"][0].policies = Policies(after="lru1-2")
    client = MissionClient("tcp/127.0.0.1:1")  # never connected: filled in here
    client.mission, client.library, client.robots = mission, library, {}
    text = state_text(client, unicode=True)
    line = {ln.split()[1]: ln for ln in text.splitlines() if ln.startswith("  ")}
    assert "lru1-2 [⇢lru2-1]" in line["lru1-2"]  # the awaited row
    assert "lru2-1 [⇠lru1-2]" in line["lru2-1"] and "after lru1-2" in line["lru2-1"]
    assert "[before:lru2-1]" in state_text(client, unicode=False)
    assert state_json(client)["tasks"]["lru1"][1]["awaited_by"] == ["lru2-1"]


@pytest.mark.parametrize(
    ("typed", "seconds"),
    [
        ("sim 1:30:00", 5400.0),
        ("1:30:00", 5400.0),
        ("90m", 5400.0),  # a duration: that far into the simulation
        ("2030-01-01 12:00", 1893499200.0),  # a real mission: a UTC time
        ("2030-01-01T12:00:00+00:00", 1893499200.0),
    ],
)
def test_not_after_is_a_mission_clock_time(tutorial, typed, seconds):
    op = op_of(["edit", "lru1-1", "--not-after", typed], tutorial)
    assert op.policies.not_after == seconds
    assert marks(op.policies)[0].startswith("⏱≤sim 1:30:00" if seconds < 1e9 else "⏱≤2030-01-01")


def test_a_mission_file_takes_not_after_as_a_sim_clock_time():
    assert Policies(not_after="sim 0:20:00").not_after == 1200


def test_ctl_barrier_takes_a_timeout_and_changes_an_existing_one(tutorial):
    from backend.core.model import Barrier

    op = op_of(
        ["barrier", "lru1-1", "lru2-1", "--barrier-timeout", "10m", "--on-timeout", "continue"],
        tutorial,
    )
    assert (op.op, op.ids, op.timeout, op.on_timeout) == (
        "barrier",
        ["lru1-1", "lru2-1"],
        600,
        "continue",
    )
    mission, _ = tutorial
    mission.barriers["b1"] = Barrier(
        skills=["lru1-1", "lru2-1"], timeout=600, on_timeout="continue"
    )
    op = op_of(["barrier", "b1", "--on-timeout", "halt"], tutorial)  # the timeout is kept
    assert (op.op, op.barrier, op.timeout, op.on_timeout) == ("barrier_edit", "b1", 600, "halt")
    op = op_of(["barrier", "b1", "--barrier-timeout", "off"], tutorial)
    assert (op.timeout, op.on_timeout) == (None, "continue")
    with pytest.raises(UsageError, match="lru1-1 is no barrier"):
        op_of(["barrier", "lru1-1", "--barrier-timeout", "5m"], tutorial)


def test_ctl_barrier_wait_against_a_server(tmp_path):
    """Every step a separate ctl process, as a script runs it."""
    from .helpers import Server, ok, ok_json, state

    server = Server(tmp_path)
    try:
        e = server.endpoint
        made = ok_json(
            e, "barrier", "lru1-1", "lru2-1", "--barrier-timeout", "10m", "--on-timeout", "continue"
        )
        bid = made["value"]["barrier"]
        said = ok(e, "barrier", bid, "--barrier-timeout", "5m").stdout
        assert f"barrier {bid} waits 5m, then continue" in said, said
        assert state(e)["barrier_waits"][bid] == {"timeout": 300.0, "on_timeout": "continue"}
        ok(e, "undo")
        shown = ok(e, "state").stdout
        assert f"{bid} = lru1-1 + lru2-1 (waits 10m, then continue)" in shown, shown
    finally:
        server.stop()
