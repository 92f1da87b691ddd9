"""Hostile input at the server's doors: every message is held to the limits
of backend/core/limits.py where it enters (`wire.parse`), a refusal is short
and says which field broke which limit, nothing over a limit is journaled,
and the server restarts on its journal afterwards.

Each case is a reproduction from issue 20, found on main by a careless user
or an attacker."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from datetime import UTC, datetime

import pytest

from backend.client.client import OperationRefused
from backend.core.limits import LIMITS
from backend.core.ops import AddSkill, Report, Sync
from backend.protocol.keys import Keys
from backend.protocol.messages import (
    Downlink,
    ErrorReply,
    Manifest,
    Register,
    StateRequest,
    StateSnapshot,
    Telemetry,
    dumps,
)
from backend.protocol.wire import is_limit, parse
from backend.server.journal import Journal
from backend.transport import QueryError, query
from backend.transport.session import close_session, open_session

from .harness import ROOT, RawRobot, serving

MAX_REPLY = 600  # bytes of a refusal, whatever the refused message held


def deep(levels: int) -> object:
    value: object = []
    for _ in range(levels - 1):
        value = [value]
    return value


async def refusal(session, key: str, payload: bytes) -> ErrorReply:
    with pytest.raises(QueryError) as e:
        await query(session, key, payload, 10.0)
    assert len(e.value.payload) < MAX_REPLY, e.value.payload[:MAX_REPLY]
    return ErrorReply.model_validate_json(e.value.payload)


def request(op: dict) -> bytes:
    return json.dumps({"client": "attacker", "request_id": "r1", "op": op}).encode()


TARGET = {"x": 1, "y": 1}


# -- operations ------------------------------------------------------------------------


async def test_a_value_nested_past_the_limit_is_refused_and_the_journal_replays(tmp_path):
    """The issue's `ctl add ... camera={a: [[[...196 deep...]]]}` was accepted,
    and no client could read the state again, nor the server its journal."""
    db = tmp_path / "m.db"
    async with serving(db) as (server, client):
        before = server.mission.revision
        op = {"op": "add", "robot": "lru1", "skill": "take_science_image"}
        op["params"] = {"target": TARGET, "camera": {"a": deep(196)}}
        err = await refusal(client.session, Keys.OP, request(op))
        assert err.code == "limit_exceeded"
        assert err.message.startswith("op.params.camera.a[0][0]")
        assert err.message.endswith("nested deeper than the limit of 64 levels")
        # within the message limit, past the parameter's own (16 levels)
        op["params"]["camera"] = {"a": deep(LIMITS.value_depth)}
        with pytest.raises(OperationRefused) as refused:
            await client.submit(AddSkill.model_validate(op))
        assert "camera.a[0]" in refused.value.reply.message
        assert "nested deeper than the limit of 16 levels" in refused.value.reply.message
        # at the limit: accepted, journaled, replayed
        op["params"]["camera"] = {"a": deep(LIMITS.value_depth - 1)}
        added = await client.submit(AddSkill.model_validate(op))
        assert added.revision == before + 1
        await client.resync()  # every client reads the state
    with Journal.open(db) as j:
        mission, _ = j.load()
    assert mission.revision == before + 1


@pytest.mark.parametrize(
    ("field", "value", "path"),
    [
        ("label", "x" * 8_000_000, "op.label"),  # was journaled and broadcast
        ("params", {"target": TARGET, "filter": "u" * 2_000_000}, "op.params.filter"),
    ],
    ids=["8 MB label", "2 MB parameter"],
)
async def test_an_oversized_string_gets_a_short_refusal_and_nothing_is_journaled(
    tmp_path, field, value, path
):
    async with serving(tmp_path / "m.db") as (server, client):
        before = server.mission.revision
        op = {"op": "add", "robot": "lru1", "skill": "take_science_image", "params": {}}
        op[field] = value
        err = await refusal(client.session, Keys.OP, request(op))
        assert err.code == "limit_exceeded"
        assert err.message.startswith(f"{path}: ")
        assert "characters, more than the limit of 10,000" in err.message
        assert server.mission.revision == before
        assert server.journal.last_revision() == before


async def test_an_enum_value_under_the_limit_is_echoed_short(tmp_path):
    async with serving(tmp_path / "m.db") as (_, client):
        op = AddSkill(
            robot="lru1",
            skill="take_science_image",
            params={"target": TARGET, "filter": "v" * 9000},
        )
        with pytest.raises(OperationRefused) as refused:
            await client.submit(op)
        message = refused.value.reply.message
        assert "'vvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvvv'… is not one of" in message
        assert len(message) < MAX_REPLY


def test_a_message_over_the_payload_limit_is_not_read():
    """(No 32 MiB over the link in a test: the size is checked first, in parse.)"""
    from backend.protocol.messages import Request

    payload = b" " * (LIMITS.payload + 1)
    with pytest.raises(ValueError) as e:
        parse(Request, payload)
    assert is_limit(e.value)
    assert f"{LIMITS.payload + 1:,} bytes, more than the limit of {LIMITS.payload:,}" in str(
        e.value
    )


def test_a_union_is_read_within_the_limits_too():
    """`parse_as`: for a robot's commands (`RobotCommand`, a union of models)."""
    from pydantic import TypeAdapter

    from backend.core.model import Dequeue, RobotCommand
    from backend.protocol.messages import first_error
    from backend.protocol.wire import parse_as

    commands = TypeAdapter(RobotCommand)
    assert parse_as(commands, b'{"cmd": "dequeue", "ids": ["lru1-1"]}') == Dequeue(ids=["lru1-1"])
    with pytest.raises(ValueError) as e:
        parse_as(commands, json.dumps({"cmd": "dequeue", "ids": ["x" * 20_000]}))
    assert is_limit(e.value) and first_error(e.value).startswith("ids[0]: 20,000 characters")
    with pytest.raises(ValueError) as e:
        parse_as(commands, b"not json")
    assert not is_limit(e.value) and "Invalid JSON" in str(e.value)


# -- the state key ---------------------------------------------------------------------


async def test_the_state_key_answers_bad_request_to_what_is_not_a_state_request(tmp_path):
    async with serving(tmp_path / "m.db") as (server, client):
        for payload in (b"not json", b'{"protocol": "x"}', b"[1, 2]"):
            err = await refusal(client.session, Keys.STATE, payload)
            assert err.code == "bad_request", payload
        for payload in (b"", dumps(StateRequest(client="t"))):  # an empty query asks too
            snap = StateSnapshot.model_validate_json(
                await query(client.session, Keys.STATE, payload, 10.0)
            )
            assert snap.revision == server.mission.revision


# -- replies of retried requests -------------------------------------------------------


async def test_a_request_retried_after_a_restart_gets_its_original_reply(tmp_path):
    """It was recognized as applied, but answered `added ? (recharge)`, value {}."""
    db = tmp_path / "m.db"
    add = AddSkill(robot="lru1", skill="recharge", label="before the restart")
    sync = Sync(robot="lru1")
    async with serving(db) as (_, client):
        added = await client.submit(add, request_id="add-1")
        robot = RawRobot(client.endpoints[0], "lru1")
        try:
            await robot.register("lru_science")
            synced = await client.submit(sync, request_id="sync-1")  # its command's number
        finally:
            robot.close()
    assert added.value["id"].startswith("lru1-") and synced.value["command"] == 1
    async with serving(db) as (_, client):  # restarted; the robot is gone
        for op, rid, first in ((add, "add-1", added), (sync, "sync-1", synced)):
            again = await client.submit(op, request_id=rid)
            assert again.duplicate and again.revision == first.revision
            assert (again.value, again.notes) == (first.value, first.notes)


# -- robots ------------------------------------------------------------------------------


async def test_robot_registrations_and_reports_are_held_to_the_limits(tmp_path):
    async with serving(tmp_path / "m.db") as (server, client):
        session = client.session
        manifest = Manifest(name="lru1", type="lru_science", properties={"p": deep(100)})
        err = await refusal(
            session, Keys.register("lru1"), dumps(Register(manifest=manifest, session="s1"))
        )
        assert err.code == "limit_exceeded"
        assert err.message.startswith("manifest.properties.p[0][0]")
        report = Report(robot="lru1", seq=1, id="lru1-1", status="running", info="i" * 20_000)
        down = Downlink(robot="lru1", session="s1", messages=[report], sent=datetime.now(UTC))
        err = await refusal(session, Keys.downlink("lru1"), dumps(down))
        assert err.code == "limit_exceeded" and err.robot == "lru1"
        assert err.message.startswith("messages[0].info: 20,000 characters, more than the limit")
        assert server.mission.report_seqs.get("lru1", 0) == 0


async def test_telemetry_over_a_limit_is_ignored_and_said(tmp_path):
    from backend.client.client import Malformed
    from backend.transport import client_config, declare_publisher, wait_matching

    async with serving(tmp_path / "m.db") as (_, client):
        seen: list[Malformed] = []
        client.add_listener(lambda e: seen.append(e) if isinstance(e, Malformed) else None)
        robot = open_session(client_config(client.endpoints))
        try:
            pub = declare_publisher(robot, Keys.telemetry("lru1"))
            assert await asyncio.to_thread(wait_matching, pub, 10)
            at = datetime.now(UTC)
            pub.put(dumps(Telemetry(robot="lru1", info="t" * 20_000, at=at)))
            pub.put(dumps(Telemetry(robot="lru1", battery=0.5, at=at)))
            await client.wait_for(lambda _e: "lru1" in client.telemetry, 10)
        finally:
            close_session(robot)
        assert client.telemetry["lru1"].info == ""
        [m] = seen
        assert m.error.startswith("info: 20,000 characters, more than the limit of 10,000")


# -- the command line -------------------------------------------------------------------


def ctl(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "backend.cli", "ctl", "--connect", endpoint, *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )


async def test_the_ctl_reproductions_are_short_located_refusals(tmp_path):
    async with serving(tmp_path / "m.db") as (server, client):
        endpoint = client.endpoints[0]
        add = ("add", "lru1", "take_science_image", "--param", "target={x: 1, y: 1}")
        nested = "camera={a: " + "[" * 196 + "]" * 196 + "}"
        r = await asyncio.to_thread(ctl, endpoint, *add, "--param", nested)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.startswith("missionctl ctl: error: --param camera: a[0][0][0]")
        assert "nested deeper than the limit of 64 levels" in r.stderr and len(r.stderr) < 300
        within = "camera={a: " + "[" * 20 + "]" * 20 + "}"  # past the parameter's limit
        r = await asyncio.to_thread(ctl, endpoint, *add, "--param", within)
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        assert "camera.a[0]" in r.stderr and "nested deeper than the limit of 16 levels" in r.stderr
        bomb = (
            "camera={a: &a [1,1,1,1,1,1,1,1,1], "
            + ", ".join(
                f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]"
                for p, c in zip("abcdefgh", "bcdefghi", strict=True)
            )
            + "}"
        )
        r = await asyncio.to_thread(ctl, endpoint, *add, "--param", bomb)
        assert r.returncode == 2 and "YAML nodes" in r.stderr, r.stderr
        assert server.mission.revision == 0
        r = await asyncio.to_thread(ctl, endpoint, "state", "--json")
        assert r.returncode == 0, r.stderr  # every client still reads the state
