"""Whatever the engine accepts replays from the journal to an equal mission.

A stream of every kind of operation and robot report (crash_worker's
`OpGenerator`), with hypothesis-drawn values at and around the limits of
backend/core/limits.py in labels, status information, string, list and dict
parameters and mission names: deep nesting, long strings, long lists,
any code point (lone surrogates too), huge integers, NaN. Each operation
reaches the engine as the server gets it (through `wire.parse`, when the
client could send it at all) or as the server's own code hands it over (in
process); each accepted one is journaled as the server does (a batch that
would not read back is refused, `not_replayable`). Reopening the journal must
give back the engine's mission, whatever was accepted or refused.
"""

from __future__ import annotations

import math
import sys
import tempfile
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pydantic_core
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from backend.core.limits import LIMITS
from backend.core.ops import AddSkill, EditSkill, NewMission, Report
from backend.core.rules.engine import Applied
from backend.protocol.messages import Downlink, Request, dumps
from backend.protocol.wire import parse
from backend.server.journal import Journal
from backend.server.recorder import JournalRecorder

sys.path.insert(0, str(Path(__file__).parent))
from crash_worker import OpGenerator, mission_problems, start_engine  # noqa: E402

STEPS = 40  # operations per example

# -- values at the limits --------------------------------------------------------------

# any code point, lone surrogates included (JSON cannot carry those)
chars = st.one_of(st.characters(), st.characters(min_codepoint=0xD800, max_codepoint=0xDFFF))
short_text = st.text(chars, max_size=6)
# a string of about the limit's length, built from a few drawn characters (hypothesis
# draws at most a few kilobytes per example)
long_text = st.builds(
    lambda seed, n: (seed * n)[:n],
    st.text(chars, min_size=1, max_size=3),
    st.sampled_from([LIMITS.text - 1, LIMITS.text, LIMITS.text + 1]),
)
texts = st.one_of(short_text, long_text)
numbers = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
)
scalars = st.one_of(st.none(), st.booleans(), numbers, texts)


def _nest(depth: int, leaf: Any, dicts: bool) -> Any:
    """A value exactly `depth` levels deep (lists, or mappings)."""
    for _ in range(depth):
        leaf = {"k": leaf} if dicts else [leaf]
    return leaf


# inside a dict or list parameter (one level more): at, under and over the limit
deep_values = st.builds(
    _nest,
    st.sampled_from([LIMITS.value_depth - 2, LIMITS.value_depth - 1, LIMITS.value_depth]),
    scalars,
    st.booleans(),
)
long_lists = st.sampled_from([LIMITS.items, LIMITS.items + 1]).map(lambda n: [0] * n)
small_values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(short_text, inner, max_size=3),
    max_leaves=8,
)
inner_values = st.one_of(small_values, deep_values, texts)
dict_values = st.builds(lambda v: {"v": v}, inner_values)
list_values = st.one_of(st.builds(lambda v: [v], inner_values), long_lists)


class Silent:
    """Alerts nobody reads (the journal of these tests does not fail)."""

    def alert(self, message: str, *, level: str = "warning", kind: str = "") -> None:
        pass


class HostileOps(OpGenerator):
    """The crash worker's stream, with drawn values where the operator or the
    robot chooses them, journaled the way the server journals."""

    def __init__(self, engine, seed: int, data: Any, journal: Journal, via_wire: bool):
        super().__init__(engine, seed)
        self.data, self.journal, self.via_wire = data, journal, via_wire
        self.accepted = self.refused = 0
        engine.recorder = JournalRecorder(journal, Path("property.db"), Silent())

    def value_for(self, ptype: str, pspec: Any) -> Any:
        drawn = {"dict": dict_values, "list": list_values, "str": texts, "enum": texts}
        if ptype in drawn and self.rng.random() < 0.7:
            return self.data.draw(drawn[ptype])
        return super().value_for(ptype, pspec)

    # the crash worker's mix, and as often an add of a skill with free-form parameters
    ACTIONS = (*OpGenerator.ACTIONS, ("free_form", 16))

    def act_free_form(self) -> None:
        """Add a skill whose parameters take anything (a list, a dict, a string)."""
        free = [
            (robot, name)
            for robot in sorted(self.m.robots)
            for name in self.lib.skills_of(self.m.robots[robot].type)
            if any(p.type in ("str", "list", "dict") for p in self.lib.skills[name].params.values())
        ]
        if free:
            robot, name = self.pick(free)
            params, bindings = self.params_for(self.m.robots[robot].type, name)
            self.submit(AddSkill(robot=robot, skill=name, params=params, bindings=bindings), "eve")

    def params_for(self, rtype: str, skill: str) -> tuple[dict, dict]:
        """Free-form parameters (str, list, dict) always given: they take anything."""
        params, bindings = super().params_for(rtype, skill)
        for name, p in self.lib.skill_for(rtype, skill).params.items():
            if p.type in ("str", "list", "dict") and name not in params:
                params[name] = self.value_for(p.type, p)
        return params, bindings

    def hostile(self, op: Any) -> Any:
        """The operator's or robot's free text, drawn."""
        if self.data is None:
            return op
        if isinstance(op, AddSkill | EditSkill) and self.rng.random() < 0.5:
            return op.model_copy(update={"label": self.data.draw(texts)})
        if isinstance(op, Report) and self.rng.random() < 0.5:
            return op.model_copy(update={"info": self.data.draw(texts)})
        if isinstance(op, NewMission):
            return op.model_copy(update={"name": self.data.draw(texts)})
        return op

    def through_wire(self, op: Any, client: str, rid: str) -> Any:
        """The operation as the server reads it off the wire (None: the
        client could not send it, or the server refuses to read it)."""
        try:
            if isinstance(op, Report):
                down = Downlink(robot=op.robot, session="s1", messages=[op], sent=datetime.now(UTC))
                return parse(Downlink, dumps(down)).messages[0]
            if isinstance(op, AddSkill | EditSkill | NewMission):
                payload = dumps(Request(client=client, request_id=rid, op=op))
                return parse(Request, payload).op
            return parse(type(op), op.model_dump_json())  # a robot's answer, relayed
        except (ValidationError, pydantic_core.PydanticSerializationError):
            return None

    def submit(self, op: Any, client: str) -> Applied | None:
        rid = f"r{self.n_requests + 1}"  # the one OpGenerator.submit gives it
        op = self.hostile(op)
        if self.via_wire:
            op = self.through_wire(op, client, rid)
            if op is None:
                self.refused += 1
                return None
        applied = super().submit(op, client)
        if applied is None:
            self.refused += 1
        elif applied.events:
            self.accepted += 1
            self.journal.maybe_snapshot(self.engine.mission)
        return applied


@settings(
    max_examples=12,  # each is a whole stream: modest, CI time stays in check
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    # no shrinking: a failing stream is reported as drawn (shrinking one took minutes)
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
)
@given(seed=st.integers(0, 2**32 - 1), via_wire=st.booleans(), data=st.data())
def test_whatever_the_engine_accepts_replays_to_an_equal_mission(seed, via_wire, data):
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "m.db"
        engine = start_engine()
        with Journal.open(db, snapshot_every=7, snapshot_bytes=0, keep_snapshots=1000) as journal:
            journal.snapshot(engine.mission)
            gen = HostileOps(engine, seed, data, journal, via_wire)
            for _ in range(STEPS):
                gen.step()
        with Journal.open(db) as journal:
            newest, _ = journal.load()  # from the newest snapshot
            # and every batch, from the first snapshot on
            journal.conn.execute("DELETE FROM snapshots WHERE revision > 0")
            replayed, _ = journal.load()
            assert journal.load_info.replayed == engine.mission.revision
    for mission in (newest, replayed):
        assert mission == engine.mission
        assert mission.model_dump_json() == engine.mission.model_dump_json()
    assert not mission_problems(replayed)


def test_values_json_cannot_carry_are_refused_before_the_journal(tmp_path):
    """In process (no wire in between), the engine takes what JSON cannot
    carry as it is; the journal refuses it, so nothing changes."""
    engine = start_engine()
    with Journal.open(tmp_path / "m.db") as journal:
        journal.snapshot(engine.mission)
        gen = HostileOps(engine, 1, None, journal, via_wire=False)
        before = engine.mission.model_dump_json()
        for bad in ("\ud800", math.nan, (1, 2), {1: "a"}):
            op = AddSkill(
                robot="lru1",
                skill="take_science_image",
                params={"target": {"x": 1, "y": 2}, "camera": {"v": bad}},
            )
            assert gen.submit(op, "alice") is None, bad
        assert engine.mission.model_dump_json() == before
        assert journal.last_revision() == 0
