"""docs/protocol.md and docs/protocol/*.json are generated from the protocol
models: keep them current, and keep what they promise true (every refusal
code the code can raise is in the table; every operation's reply value fits
its documented schema)."""

import re
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import get_args

import pytest
from pydantic import ValidationError

from backend.core import ops
from backend.core.model import Marker, Status
from backend.core.rules.engine import Engine
from backend.files.missions import load_mission
from backend.protocol.doc import (
    ERROR_CODES,
    EVENT_RULES,
    OP_CODES,
    _event_kinds,
    render,
    stale,
)
from backend.protocol.values import VALUES, check_value

ROOT = Path(__file__).resolve().parents[2]


def test_protocol_doc_is_up_to_date():
    assert stale(ROOT / "docs") == [], (
        "docs/protocol.md or docs/protocol/*.json is stale: run `python -m backend.protocol.doc`"
    )


def test_protocol_doc_names_every_key_sequence_and_promise():
    text = render()
    for needle in (
        "mc/v2/server/op",
        "mc/v2/robot/ROBOT/uplink",
        "mc/v2/server/downlink/ROBOT",
        "mc/v2/robot/ROBOT/alive/SESSION",
        "### The uplink",
        "### The downlink",
        "### Sessions and one owner per name",
        "### Barriers",
        "**Token lifetime**",
        "## Zenoh settings of a client",
        "## Error codes",
        "## A worked trace",
        "[StateSnapshot.json](protocol/StateSnapshot.json)",
        "[value-sync.json](protocol/value-sync.json)",
    ):
        assert needle in text, needle


def test_the_map_feed_is_under_the_protocols_prefix():
    from backend.protocol import mapfeed
    from backend.protocol.keys import PREFIX

    assert mapfeed.PREFIX == f"{PREFIX}/sim"


def test_every_refusal_code_is_in_the_table():
    documented = {code for code, _, _ in ERROR_CODES}
    raised: set[str] = set()
    for f in (ROOT / "backend").rglob("*.py"):
        text = f.read_text(encoding="utf-8")
        raised |= set(re.findall(r'Refusal\(\s*"([a-z_]+)"', text))
        raised |= set(re.findall(r'ErrorReply\(\s*code="([a-z_]+)"', text))
        raised |= set(re.findall(r'_refusal\(\s*"([a-z_]+)"', text))
    raised |= {"nothing_to_undo", "nothing_to_redo", "journal_failed"}  # built from parts
    assert raised - documented == set()


def test_every_event_says_how_a_mirror_applies_it():
    """A third-party client mirrors the mission from the document alone."""
    assert [ev.strip("`") for ev, _, _ in EVENT_RULES] == _event_kinds()


def test_the_codes_of_each_operation_are_documented_codes():
    documented = {code for code, _, _ in ERROR_CODES}
    ops_named = set()
    for names, codes in OP_CODES:
        ops_named |= set(names.split(", "))
        listed = {c.split(" ")[0] for c in codes.split(", ") if not c.startswith("and ")}
        assert listed <= documented, names
    assert ops_named == set(VALUES)


def test_every_reply_value_fits_its_schema():
    mission, library = load_mission(ROOT / "missions" / "tutorial.yaml")
    e = Engine(mission, library)
    seen: dict[str, dict] = {}

    def do(op, client="c"):
        applied = e.submit(op, client=client)
        check_value(op.op, applied.value)
        seen[op.op] = applied.value
        return applied

    do(ops.NewMission())
    do(ops.LoadMission(mission=mission.copy_deep()))
    added = do(ops.AddSkill(robot="lru1", skill="recharge")).value["id"]
    do(ops.EditSkill(id=added, label="x"))
    do(ops.MoveSkill(id=added, index=0))
    do(ops.AddBarrier(ids=[added, "lru2-1"]))
    do(ops.EditBarrier(barrier="b1", timeout=600, on_timeout="continue"))
    do(ops.RemoveBarrier(barrier="b1"))
    marker = Marker.__args__[0].__args__[0](pose={"x": 1, "y": 1})  # a PoseMarker
    do(ops.MarkerAdd(name="M", marker=marker))
    do(ops.MarkerMove(name="M", value={"x": 2, "y": 2, "z": 0, "roll": 0, "pitch": 0, "yaw": 0}))
    do(ops.MarkerRename(name="M", new_name="N"))
    do(ops.MarkerDelete(name="N"))
    do(ops.DeleteSkills(ids=[added]))
    do(ops.Undo())
    do(ops.Redo())
    sync = do(ops.Sync(robot="lru1")).value
    do(ops.Cancel(command=sync["command"]))
    sync = do(ops.Sync(robot="lru1", expire_s=60)).value
    e.submit(
        ops.Answer(
            robot="lru1", seq=1, command=sync["seq"], outcome="applied", queued=["lru1-1", "lru1-2"]
        )
    )
    do(ops.Control(op="run", robot="lru1"))
    e.submit(ops.Report(robot="lru1", seq=2, id="lru1-1", status=Status.RUNNING))
    do(ops.Control(op="pause", robot="lru1"))
    do(ops.Control(op="stop", robot="lru1"))
    do(ops.Unsync(robot="lru1", from_id="lru1-2"))
    do(ops.Control(op="reset"))
    at = datetime.now(UTC)
    asked = ops.Ask(
        robot="lru1",
        seq=3,
        ref="r-1",
        skill="lru1-1",
        text="search wider?",
        choices=["wider", "give up"],
        default="wider",
        timeout_s=600,
        at=at,
        due=at + timedelta(minutes=10),
    )
    e.submit(asked)
    do(ops.AnswerQuestion(question=1, choice="wider"))
    e.submit(ops.Report(robot="lru1", seq=4, id="lru1-1", status=Status.FAILURE))
    do(ops.Retry(id="lru1-1"))
    do(ops.RetryEdit(id="lru1-1"))
    do(ops.Waive(check="barrier.deadlock:b1+b2", reason="they meet by radio"))
    do(ops.Waive(check="barrier.deadlock:b1+b2", reason="they meet by radio"))  # no change
    do(ops.Unwaive(check="barrier.deadlock:b1+b2"))
    do(ops.AddRobot(name="lru3", type="lru_science"))
    do(ops.Reassign(from_robot="lru2", to="lru3"))
    do(ops.RetireRobot(name="lru3", reason="a test"))
    assert set(VALUES) - set(seen) == set()
    every_op = {
        name
        for model in get_args(ops.OperatorOperation)
        for name in get_args(model.model_fields["op"].annotation)
    }
    assert every_op <= set(VALUES)
    with pytest.raises(ValidationError):
        check_value("sync", {"command": 1})  # a value that does not fit is caught
