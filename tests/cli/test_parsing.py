"""`missionctl ctl` without a server: argument parsing, parameter values and
the operation each sub-command builds."""

from __future__ import annotations

import json
import math
import subprocess

import pytest

from backend.cli.ctl.args import DEFAULT_CONNECT, parse_args
from backend.cli.ctl.build import build_op
from backend.cli.ctl.errors import FileInvalid, UsageError
from backend.cli.ctl.render import short_value
from backend.cli.ctl.session import default_client_id, default_endpoints, run
from backend.cli.ctl.values import (
    AtMarker,
    parse_area,
    parse_param,
    parse_params,
    parse_pose,
    parse_position,
)
from backend.core import ops
from backend.core.model import Policies
from backend.files.missions import load_mission
from backend.transport import free_port, loopback_endpoint

from .helpers import LIBRARY, ROOT, TUTORIAL


@pytest.fixture(scope="module")
def tutorial():
    mission, library = load_mission(TUTORIAL)
    return mission, library


def op_of(argv: list[str], tutorial=None):
    args = parse_args(argv)
    if tutorial is None:
        return build_op(args)
    mission, library = tutorial
    return build_op(args, library, mission)


# ---------------------------------------------------------------- --param


@pytest.mark.parametrize(
    ("text", "name", "value"),
    [
        ("speed=0.5", "speed", 0.5),
        ("slot=3", "slot", 3),
        ("return_to_start=true", "return_to_start", True),
        ("filter=near_infrared", "filter", "near_infrared"),
        ("label=hello world", "label", "hello world"),
        ("box='3'", "box", "3"),
        ("speed=", "speed", None),
        ("speed=null", "speed", None),
        ("expr=a=b", "expr", "a=b"),
        ("day=2024-05-01", "day", "2024-05-01"),
        ("goal={x: 3, y: 4, yaw: 0}", "goal", {"x": 3, "y": 4, "yaw": 0}),
        ("camera={exposure_ms: 20, gain: 1.5}", "camera", {"exposure_ms": 20, "gain": 1.5}),
        ("sensors=[stereo_camera, lidar]", "sensors", ["stereo_camera", "lidar"]),
        (
            "area=[{x: 0, y: 0}, {x: 1, y: 0}, {x: 1, y: 1}]",
            "area",
            [{"x": 0, "y": 0}, {"x": 1, "y": 0}, {"x": 1, "y": 1}],
        ),
        ("goal=@POI-A", "goal", AtMarker("POI-A")),
        ('goal="@POI-A"', "goal", AtMarker("POI-A")),
        (" goal =@POI-A", "goal", AtMarker("POI-A")),
    ],
)
def test_param_values(text, name, value):
    assert parse_param(text) == (name, value)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("goal", "expected NAME=VALUE"),
        ("=3", "expected NAME=VALUE"),
        ("bad name=3", "not a parameter name"),
        ("goal={x: 3", "not a valid YAML value"),
        ("goal={x: 3", "quote the whole argument"),
        ("goal=x: 3, y: 4", "braces"),
        ("goal=x: 3", "braces"),
        ("sensors=- a", "brackets"),
        ("speed=.inf", "not a finite number"),
        ("speed=.nan", "not a finite number"),
        ("goal={x: .nan}", "not a finite number"),
        ("goal=@", "not a valid name"),
        ("goal=@bad name", "not a valid name"),
        ("goal=[1, 2", "not a valid YAML value"),
    ],
)
def test_bad_params(text, needle):
    with pytest.raises(UsageError) as e:
        parse_param(text)
    assert needle in str(e.value)
    assert "--param" in str(e.value)


def test_param_given_twice():
    with pytest.raises(UsageError, match="given twice"):
        parse_params(["speed=0.1", "speed=0.2"])


# ---------------------------------------------------------------- geometry


def test_geometry():
    assert parse_pose("1,2") == {"x": 1, "y": 2}
    # angles in degrees, as ctl prints them; `rad` says radians
    assert parse_pose("1,2,3,0.1rad,0.2rad,90") == {
        "x": 1,
        "y": 2,
        "z": 3,
        "roll": 0.1,
        "pitch": 0.2,
        "yaw": math.pi / 2,
    }
    assert parse_pose("{x: 1, y: 2, yaw: 1.5rad}") == {"x": 1, "y": 2, "yaw": 1.5}
    assert parse_pose("{x: 1, y: 2, yaw: 30deg}")["yaw"] == pytest.approx(math.pi / 6)
    assert parse_pose("-1, 2.5") == {"x": -1, "y": 2.5}
    assert parse_position("1,2,3") == {"x": 1, "y": 2, "z": 3}
    assert parse_area("0,0 5,0 5,5") == [{"x": 0, "y": 0}, {"x": 5, "y": 0}, {"x": 5, "y": 5}]
    assert parse_area("0,0;5,0;5,5,1") == [
        {"x": 0, "y": 0},
        {"x": 5, "y": 0},
        {"x": 5, "y": 5, "z": 1},
    ]
    assert parse_area("[[0, 0], {x: 5, y: 0}, [5, 5]]") == [
        {"x": 0, "y": 0},
        {"x": 5, "y": 0},
        {"x": 5, "y": 5},
    ]
    for bad, needle in [
        (lambda: parse_pose("1"), "2 to 6"),
        (lambda: parse_pose("1,2,3,4,5,6,7"), "2 to 6"),
        (lambda: parse_pose("1,north"), "not a number"),
        (lambda: parse_pose("1,inf"), "finite"),
        (lambda: parse_pose("{x: 1, heading: 2}"), "unknown field 'heading'"),
        (lambda: parse_pose("1,2,0,0,0,north"), "--pose: yaw: expected an angle in degrees"),
        (lambda: parse_position("1,2,3,4"), "2 to 3"),
        (lambda: parse_area("0,0 1,1"), "at least 3 points"),
        (lambda: parse_area("0,0 1,1 2"), "--area point 3"),
    ]:
        with pytest.raises(UsageError) as e:
            bad()
        assert needle in str(e.value)


def test_short_value():
    assert (
        short_value({"x": 9.0, "y": 4.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0})
        == "(9,4)"
    )
    assert (
        short_value({"x": 1.0, "y": 2.0, "z": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": math.pi / 2})
        == "(1,2 yaw=90°)"  # angles as a person reads them: degrees, the unit shown
    )
    assert short_value([{"x": 0, "y": 0}] * 4) == "[4 points]"
    assert short_value("near_infrared") == "near_infrared"
    assert short_value("two words") == '"two words"'
    assert len(short_value(list(range(100)))) <= 40


# ---------------------------------------------------------------- options


def test_common_options_before_or_after_op(monkeypatch):
    monkeypatch.delenv("MISSIONCTL_CONNECT", raising=False)
    a = parse_args(["state"])
    assert a.json is False and a.connect is None and a.timeout == 10.0 and a.client_id is None
    assert parse_args(["--json", "state"]).json is True
    assert parse_args(["state", "--json"]).json is True
    a = parse_args(
        [
            "--connect",
            "tcp/127.0.0.1:1",
            "--timeout",
            "2",
            "add",
            "lru1",
            "recharge",
            "--client-id",
            "me",
        ]
    )
    assert a.connect == ["tcp/127.0.0.1:1"] and a.timeout == 2.0 and a.client_id == "me"
    assert parse_args(["add", "lru1", "recharge", "--connect", "tcp/127.0.0.1:2"]).connect == [
        "tcp/127.0.0.1:2"
    ]
    assert parse_args(["edit", "x", "--label", "y", "--expect-revision", "4"]).expect_revision == 4
    assert parse_args(["marker", "delete", "M", "--json"]).json is True
    assert default_endpoints() == [DEFAULT_CONNECT]
    monkeypatch.setenv("MISSIONCTL_CONNECT", "tcp/127.0.0.1:9,tcp/127.0.0.1:10")
    assert default_endpoints() == ["tcp/127.0.0.1:9", "tcp/127.0.0.1:10"]


def test_client_id_is_stable_across_invocations(monkeypatch):
    monkeypatch.delenv("MISSIONCTL_CLIENT_ID", raising=False)
    assert default_client_id() == default_client_id()
    assert default_client_id().startswith("ctl-")
    monkeypatch.setenv("MISSIONCTL_CLIENT_ID", "console-7")
    assert default_client_id() == "console-7"


@pytest.mark.parametrize(
    "argv",
    [
        ["frobnicate"],
        ["add", "lru1"],
        ["move", "lru1-1", "first"],
        ["marker", "add", "M"],  # no geometry
        ["marker", "add", "M", "--pose", "1,2", "--position", "1,2"],
        ["marker", "spin", "M"],
        ["add", "lru1", "recharge", "--retries", "-1"],
        ["add", "lru1", "recharge", "--recharge-below", "1.5"],
        ["state", "--timeout", "0"],
        ["watch", "--count", "many"],
    ],
)
def test_argparse_errors_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as e:
        parse_args(argv)
    assert e.value.code == 2
    out, err = capsys.readouterr()
    assert "error:" in err and out == ""
    # with --json, a usage error is one JSON object on stdout like every other failure
    with pytest.raises(SystemExit) as e:
        parse_args([*argv, "--json"])
    assert e.value.code == 2
    out, err = capsys.readouterr()
    obj = json.loads(out)
    assert obj["ok"] is False and obj["code"] == "bad_input" and obj["message"] in err


def test_json_usage_errors_from_the_command_line():
    from .helpers import CTL_CMD, env

    for argv in (
        ["--json", "add", "lru1"],
        ["add", "lru1", "drive_to", "--at", "x", "--json"],
        ["--json"],
    ):
        r = subprocess.run(
            [*CTL_CMD, *argv], cwd=ROOT, env=env(), capture_output=True, text=True, timeout=30
        )
        assert r.returncode == 2, (argv, r)
        obj = json.loads(r.stdout)
        assert obj["ok"] is False and obj["code"] == "bad_input", (argv, obj)
        assert obj["message"] in r.stderr and "Traceback" not in r.stderr


# ---------------------------------------------------------------- operations


def test_add(tutorial):
    op = op_of(
        [
            "add",
            "lru1",
            "drive_to",
            "--param",
            "goal={x: 3, y: 4, yaw: 0}",
            "--param",
            "speed=0.4",
            "--label",
            "drive out",
            "--at",
            "1",
        ],
        tutorial,
    )
    assert op == ops.AddSkill(
        robot="lru1",
        skill="drive_to",
        label="drive out",
        params={"goal": {"x": 3, "y": 4, "yaw": 0}, "speed": 0.4},
        at=1,
    )
    # @MARKER: a pose parameter is bound; a marker parameter names the marker
    op = op_of(
        ["add", "lru2", "pick_stone", "--param", "target=@POI-A", "--param", "region=@ROI-1"],
        tutorial,
    )
    assert op.params == {"region": "ROI-1"} and op.bindings == {"target": "POI-A"}
    # other parameter types keep the text (as in mission files); without a
    # library the reference is a binding (the server names what is wrong)
    op = op_of(["add", "lru1", "explore", "--param", "sensors=@lidar"], tutorial)
    assert op.params == {"sensors": "@lidar"} and op.bindings == {}
    op = op_of(["add", "lru2", "pick_stone", "--param", "region=@ROI-1"])
    assert op.bindings == {"region": "ROI-1"}
    op = op_of(
        [
            "add",
            "lru1",
            "recharge",
            "--retries",
            "3",
            "--pause-out-of-comms",
            "--recharge-below",
            "0.2",
        ],
        tutorial,
    )
    assert op.policies == Policies(retries=3, pause_out_of_comms=True, recharge_below=0.2)
    assert op_of(["add", "lru1", "recharge"], tutorial).policies is None


def test_add_bad_input(tutorial):
    for argv, needle in [
        (["add", "lru 1", "recharge"], "ROBOT"),
        (["add", "lru1", "re charge"], "SKILL"),
        (["add", "lru1", "recharge", "--retries", "50"], "policies"),
        (["add", "lru1", "drive_to", "--param", "goal"], "--param"),
    ]:
        with pytest.raises(UsageError) as e:
            op_of(argv, tutorial)
        assert needle in str(e.value)


def test_edit(tutorial):
    mission, _ = tutorial
    op = op_of(
        ["edit", "lru1-1", "--label", "new", "--param", "speed=0.7", "--param", "goal=@POI-A"],
        tutorial,
    )
    assert op == ops.EditSkill(
        id="lru1-1", label="new", params={"speed": 0.7}, bindings={"goal": "POI-A"}
    )
    op = op_of(["edit", "lru1-1", "--unbind", "goal"], tutorial)
    assert op.bindings == {"goal": None} and op.params == {} and op.label is None
    # unnamed policies are kept from the skill as it is
    mission.tasks["lru1"][0].policies = Policies(retries=2, recharge_below=0.3)
    try:
        op = op_of(["edit", "lru1-1", "--pause-out-of-comms"], tutorial)
        assert op.policies == Policies(retries=2, pause_out_of_comms=True, recharge_below=0.3)
        op = op_of(["edit", "lru1-1", "--recharge-below", "off"], tutorial)
        assert op.policies == Policies(retries=2, recharge_below=None)
    finally:
        mission.tasks["lru1"][0].policies = Policies()
    with pytest.raises(UsageError, match="nothing to change"):
        op_of(["edit", "lru1-1"], tutorial)
    with pytest.raises(UsageError, match="contradict"):
        op_of(["edit", "lru1-1", "--param", "goal={x: 1}", "--unbind", "goal"], tutorial)
    with pytest.raises(UsageError, match="not a valid name or id"):
        op_of(["edit", "lru1 1", "--label", "x"], tutorial)


def test_simple_operations(tutorial):
    cases = [
        (["delete", "lru1-1", "lru2-2"], ops.DeleteSkills(ids=["lru1-1", "lru2-2"])),
        (["move", "lru1-2", "0"], ops.MoveSkill(id="lru1-2", index=0)),
        (["sync", "lru1"], ops.Sync(robot="lru1")),
        (["sync", "lru1", "--through", "lru1-1"], ops.Sync(robot="lru1", through="lru1-1")),
        (["unsync", "lru2"], ops.Unsync(robot="lru2")),
        (["unsync", "lru2", "--from", "lru2-2"], ops.Unsync(robot="lru2", from_id="lru2-2")),
        (["retry", "lru1-1"], ops.Retry(id="lru1-1")),
        (["barrier", "lru1-2", "lru2-2"], ops.AddBarrier(ids=["lru1-2", "lru2-2"])),
        (["unbarrier", "b1"], ops.RemoveBarrier(barrier="b1")),
        (["new"], ops.NewMission(name="mission")),
        (["new", "Day 2"], ops.NewMission(name="Day 2")),
        (["undo"], ops.Undo()),
        (["redo"], ops.Redo()),
    ]
    for action in ("run", "pause", "stop", "reset"):
        cases.append(([action, "lru1"], ops.Control(op=action, robot="lru1")))
        cases.append(([action, "--all"], ops.Control(op=action, robot=None)))
    for argv, expected in cases:
        assert op_of(argv, tutorial) == expected, argv
        assert op_of(argv) == expected, argv  # the same without server data
    for argv in (["state"], ["state", "lru1"], ["robots"], ["watch"], ["save", "x.yaml"]):
        assert op_of(argv, tutorial) is None


def test_operation_usage_errors(tutorial):
    for argv, needle in [
        (["move", "lru1-1", "-1"], "INDEX must be 0 or more"),
        (["barrier", "lru1-1"], "at least two"),
        (["run"], "ROBOT or --all"),
        (["stop", "lru1", "--all"], "ROBOT or --all"),
        (["delete", "no such id"], "not a valid name or id"),
        (["state", "bad robot"], "ROBOT"),
        (["marker", "rename", "POI-A", "bad name"], "NEW_NAME"),
    ]:
        with pytest.raises(UsageError) as e:
            op_of(argv, tutorial)
        assert needle in str(e.value), argv


def test_param_angles_are_typed_in_degrees(tutorial):
    """A pose's roll/pitch/yaw reads as degrees, as ctl prints them; `rad`
    and `deg` say their unit; the operation carries radians."""
    op = op_of(["add", "lru1", "drive_to", "--param", "goal={x: 3, y: 4, yaw: 90}"], tutorial)
    assert op.params["goal"]["yaw"] == pytest.approx(math.pi / 2)
    op = op_of(["add", "lru1", "drive_to", "--param", "goal={x: 3, y: 4, yaw: 30deg}"], tutorial)
    assert op.params["goal"]["yaw"] == pytest.approx(math.pi / 6)
    op = op_of(["add", "lru1", "drive_to", "--param", "goal={x: 3, y: 4, yaw: 0.52rad}"], tutorial)
    assert op.params["goal"]["yaw"] == 0.52
    with pytest.raises(UsageError, match="--param goal: yaw: expected an angle in degrees"):
        op_of(["add", "lru1", "drive_to", "--param", "goal={x: 3, y: 4, yaw: east}"], tutorial)


def test_markers(tutorial):
    op = op_of(
        ["marker", "add", "P1", "--pose", "1,2,0,0,0,1.5rad", "--description", "a rock"], tutorial
    )
    assert op.op == "marker_add" and op.marker.kind == "pose" and op.marker.pose.yaw == 1.5
    assert op.marker.description == "a rock"
    op = op_of(["marker", "add", "P2", "--pose=-3,4"], tutorial)
    assert (op.marker.pose.x, op.marker.pose.y) == (-3, 4)
    op = op_of(["marker", "add", "Q", "--position", "1,2"], tutorial)
    assert op.marker.kind == "position" and op.marker.position.y == 2
    op = op_of(["marker", "add", "R", "--area", "0,0 4,0 4,4 0,4"], tutorial)
    assert op.marker.kind == "area" and len(op.marker.area) == 4
    op = op_of(["marker", "move", "R", "--area", "0,0 5,0 5,5"], tutorial)
    assert op.op == "marker_move" and len(op.value) == 3
    op = op_of(["marker", "move", "POI-A", "--pose", "1,2,0,0,0,90"], tutorial)
    assert op.value.yaw == pytest.approx(math.pi / 2)  # degrees, as ctl prints them
    # --position on a pose marker keeps its orientation
    mission, _ = tutorial
    mission.markers["POI-A"].pose.yaw = 0.7
    try:
        op = op_of(["marker", "move", "POI-A", "--position", "3,4"], tutorial)
        assert (op.value.x, op.value.y, op.value.yaw) == (3, 4, 0.7)
    finally:
        mission.markers["POI-A"].pose.yaw = 0.0
    assert op_of(["marker", "rename", "POI-A", "POI-B"], tutorial) == ops.MarkerRename(
        name="POI-A", new_name="POI-B"
    )
    assert op_of(["marker", "delete", "POI-A"], tutorial) == ops.MarkerDelete(name="POI-A")


def test_load(tmp_path):
    op = op_of(["load", str(TUTORIAL)])
    assert op.op == "load" and op.mission.name == "Tutorial"
    assert op.mission.tasks["lru1"][0].bindings == {"goal": "POI-A"}  # "@POI-A" in the file
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        f"format: missionctl/mission@1\nlibrary: {LIBRARY}\nrobots:\n  lru1: {{type: hovercraft}}\n"
    )
    with pytest.raises(FileInvalid) as e:
        op_of(["load", str(bad)])
    assert any("hovercraft" in str(i) and f"{bad}:4:" in str(i) for i in e.value.issues)
    with pytest.raises(FileInvalid):
        op_of(["load", str(tmp_path / "missing.yaml")])


# ------------------------------------------------------- run(): exit codes without a server


def _nobody() -> str:
    return loopback_endpoint(free_port())  # nothing listens there


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["add", "lru1", "drive_to", "--param", "goal"], "--param 'goal'"),
        (["add", "lru1", "drive_to", "--param", "goal={x: 3"], "--param goal"),
        (["edit", "lru1-1"], "nothing to change"),
        (["barrier", "lru1-1"], "at least two"),
        (["run"], "ROBOT or --all"),
        (["marker", "add", "M", "--area", "1,1"], "--area"),
        (["move", "lru1-1", "-2"], "INDEX"),
    ],
)
def test_bad_usage_exits_2_before_connecting(argv, needle, capsys):
    """Bad input is refused here (exit 2) even though no server runs (that would be 3)."""
    code = run(parse_args(["--connect", _nobody(), *argv]))
    out, err = capsys.readouterr()
    assert code == 2
    assert needle in err and "Traceback" not in err
    assert out == ""


def test_bad_usage_json(capsys):
    code = run(
        parse_args(
            ["--connect", _nobody(), "--json", "add", "lru1", "drive_to", "--param", "speed"]
        )
    )
    out, err = capsys.readouterr()
    assert code == 2
    obj = json.loads(out)
    assert obj["ok"] is False and obj["code"] == "bad_input" and "--param" in obj["message"]
    assert "--param" in err


def test_invalid_file_exits_2_before_connecting(tmp_path, capsys):
    bad = tmp_path / "broken.yaml"
    bad.write_text("format: missionctl/mission@1\nlibrary: nowhere.yaml\n")
    code = run(parse_args(["--connect", _nobody(), "load", str(bad)]))
    err = capsys.readouterr().err
    assert code == 2
    assert f"{bad}:2:" in err and "nowhere.yaml" in err


def test_bad_endpoint_exits_2(capsys):
    code = run(parse_args(["--connect", "not-an-endpoint", "state"]))
    assert code == 2
    assert "--connect" in capsys.readouterr().err


def test_save_into_missing_folder_exits_2(tmp_path, capsys):
    code = run(
        parse_args(["--connect", _nobody(), "save", str(tmp_path / "no" / "such" / "m.yaml")])
    )
    assert code == 2
    assert "does not exist" in capsys.readouterr().err
    a_file = tmp_path / "plain.txt"
    a_file.write_text("x")
    code = run(parse_args(["--connect", _nobody(), "save", str(a_file / "m.yaml")]))
    assert code == 2
    assert f"save: {a_file} is not a folder" in capsys.readouterr().err


def test_help_documents_everything():
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), pytest.raises(SystemExit):
        parse_args(["--help"])
    text = buf.getvalue()
    for needle in (
        "--param NAME=VALUE",
        "@MARKER",
        "Exit codes",
        "--expect-revision",
        "MISSIONCTL_CONNECT",
        "marker add",
        "watch",
        "--json",
    ):
        assert needle in text, needle
    assert ROOT.exists()


# ---------------------------------------------------------------- rendering (no server)


def _fake_client(tutorial):
    from datetime import UTC, datetime, timedelta

    from backend.client.client import MissionClient
    from backend.core.model import Status
    from backend.core.rules.engine import Engine
    from backend.protocol.messages import RobotInfo

    mission, library = tutorial
    m = mission.model_copy(deep=True)
    m.tasks["lru1"][0].status = Status.SUCCESS
    m.tasks["lru1"][1].status = Status.RUNNING
    m.tasks["lru1"][1].status_info = "imaging"
    m.tasks["lru2"][0].attempt = 2
    now = datetime.now(UTC)
    robots = {
        "lru1": RobotInfo(name="lru1", online=True, heard=now - timedelta(seconds=3), delay_s=2.0),
        "lru2": RobotInfo(name="lru2"),
    }
    # a sync of lru2's idle skills, sent 12 s ago, not answered yet
    e = Engine(m, library)
    e.clock = lambda: now - timedelta(seconds=14)
    cid = e.submit(ops.Sync(robot="lru2", expire_s=3600)).value["command"]
    e.submit(ops.UplinkSent(robot="lru2", ids=[cid], at=now - timedelta(seconds=12)))
    client = MissionClient("tcp/127.0.0.1:1")  # never connected: filled in here
    client.mission, client.library, client.robots = e.mission, library, robots
    client.server_id = "s1"
    return client


def test_state_text_and_json_without_server(tutorial):
    from backend.cli.ctl.render import state_json, state_text

    client = _fake_client(tutorial)
    text = state_text(client, unicode=True)
    assert "✓ lru1-1" in text and "▶ lru1-2" in text and "○ lru2-1" in text
    assert "goal=@POI-A" in text and "speed" not in text  # defaults are left out
    assert "— imaging" in text and "(attempt 2)" in text and "lru1 (lru_science) — online" in text
    ascii_text = state_text(client, unicode=False)
    assert ascii_text.isascii() and "+ lru1-1" in ascii_text and "> lru1-2" in ascii_text
    only = state_text(client, ["lru2"], unicode=True)
    assert "lru1-1" not in only and "lru2-1" in only
    data = state_json(client)
    json.dumps(data)  # plain JSON
    assert (
        data["tasks"]["lru1"][1]["status"] == "running"
        and data["tasks"]["lru1"][1]["status_info"] == "imaging"
    )
    assert data["robots"]["lru1"]["online"] is True and data["robots"]["lru2"]["online"] is False
    # the link: delay, heard, pending commands with age and expiry, uplinking skills
    assert "lru1 (lru_science) — online; delay 2.0 s, heard 3 s ago" in text
    assert "lru2-1" in text and "(uplinking: command 1, sent 12 s ago)" in text
    assert "pending: command 1 to lru2 (seq 1): sync lru2-1, lru2-2: sent 12 s ago" in text
    assert "[expires " in text
    link = data["robots"]["lru1"]["link"]
    assert link["delay_s"] == 2.0 and 2 < link["heard_age_s"] < 10 and link["stale"] is False
    assert data["robots"]["lru2"]["link"]["pending"] == [1]
    assert data["tasks"]["lru2"][0]["uplink"] == {"command": 1, "op": "sync", "state": "sent"}
    [cmd] = data["uplink"]["lru2"]
    assert cmd["state"] == "sent" and 11 < cmd["sent_age_s"] < 20 and cmd["expires"]


def test_robots_show_delay_heard_and_pending_commands(tutorial):
    from backend.cli.ctl.render import robots_json, robots_text

    client = _fake_client(tutorial)
    text = robots_text(client)
    assert "lru1 (lru_science): online" in text and "delay 2.0 s, heard 3 s ago" in text
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("lru2 "))
    pending = [line for line in lines[at:] if line.startswith("  pending: ")]
    assert (
        len(pending) == 1 and "command 1 to lru2 (seq 1): sync lru2-1, lru2-2: sent" in (pending[0])
    )
    assert "[expires " in pending[0]
    data = robots_json(client)["robots"]
    [cmd] = data["lru2"]["pending_commands"]
    assert cmd["id"] == 1 and cmd["state"] == "sent" and 11 < cmd["sent_age_s"] < 20
    assert data["lru1"]["pending_commands"] == [] and data["lru1"]["link"]["delay_s"] == 2.0


def test_robots_and_state_say_each_robots_contact_and_next_window(tutorial):
    """Out of contact is never "online"; times are mission time with their clock."""
    from datetime import UTC, datetime

    from backend.cli.ctl.render import (
        mission_time_text,
        robots_json,
        robots_text,
        state_json,
        state_text,
    )
    from backend.protocol.messages import RobotContact

    client = _fake_client(tutorial)
    closes = datetime(2031, 1, 2, 12, 20, tzinfo=UTC)  # not today: with its date
    client.robots["lru1"] = client.robots["lru1"].model_copy(
        update={
            "contact": RobotContact(
                state="out_of_contact", next_contact=7200.0, clock="sim", source="sim"
            )
        }
    )
    client.robots["lru2"] = client.robots["lru2"].model_copy(
        update={
            "online": True,
            "contact": RobotContact(
                state="in_contact", closes=closes.timestamp(), clock="wall", source="file"
            ),
        }
    )
    from backend.protocol.messages import Telemetry

    client.telemetry = {
        r: Telemetry(robot=r, battery=0.9, at=datetime.now(UTC)) for r in ("lru1", "lru2")
    }
    local = closes.astimezone().strftime("%Y-%m-%d %H:%M:%S")
    today = datetime.now(UTC).replace(microsecond=0)
    assert mission_time_text("wall", today.timestamp()) == f"{today.astimezone():%H:%M:%S}"
    for text in (robots_text(client), state_text(client)):
        [one] = [line for line in text.splitlines() if line.startswith("lru1 ")]
        [two] = [line for line in text.splitlines() if line.startswith("lru2 ")]
        assert "out of contact: window closed, next contact sim 2:00:00" in one, one
        assert "online" not in one, one
        assert f"online, in contact until {local}" in two, two
    robots = robots_text(client).splitlines()
    assert "; last known: battery 90%" in robots[0]  # lru1, out of contact
    assert "; battery 90%" in next(line for line in robots if line.startswith("lru2 "))
    for data in (robots_json(client)["robots"], state_json(client)["robots"]):
        assert data["lru1"]["contact"] == {
            "state": "out_of_contact",
            "next_contact": 7200.0,
            "closes": None,
            "clock": "sim",
            "source": "sim",
        }
        assert data["lru2"]["contact"]["closes"] == closes.timestamp()


def test_pending_lists_commands_with_age_and_expiry(tutorial):
    from backend.cli.ctl.render import pending_json, pending_text

    client = _fake_client(tutorial)
    assert pending_text(client).startswith("command 1 to lru2 (seq 1): sync lru2-1, lru2-2")
    assert pending_text(client, ["lru1"]) == "no pending commands for lru1"
    [c] = pending_json(client)["pending"]
    assert (c["id"], c["robot"], c["state"]) == (1, "lru2", "sent")


def test_describe_lines():
    from backend.cli.ctl.render import describe
    from backend.protocol.messages import OpReply

    add = ops.AddSkill(robot="lru1", skill="drive_to")
    assert (
        describe(add, OpReply(revision=12, value={"id": "lru1-7"}), 11, None)
        == "added lru1-7 (drive_to) to lru1 at revision 12"
    )
    edit = ops.EditSkill(id="lru1-7", label="x")
    assert "nothing changed" in describe(edit, OpReply(revision=12), 12, None)
    dup = describe(add, OpReply(revision=12, value={"id": "lru1-7"}, duplicate=True), 12, None)
    assert dup.endswith("(this request had been applied already)")
    run_all = ops.Control(op="run")
    value = {
        "robots": {"lru1": "queued", "lru2": "lru2 has nothing to run"},
        "commands": {"lru1": 4},
    }
    assert (
        describe(run_all, OpReply(revision=3, value=value), 2, None)
        == "run queued for lru1 (command 4) at revision 3"
    )
    sync = ops.Sync(robot="lru1")
    value = {
        "command": 5,
        "robot": "lru1",
        "seq": 2,
        "state": "queued",
        "skills": ["a", "b"],
        "expires": None,
    }
    assert (
        describe(sync, OpReply(revision=4, value=value), 3, None)
        == "queued for lru1, command 5: sync a, b at revision 4"
    )
    cancel = describe(
        ops.Cancel(command=5),
        OpReply(
            revision=5,
            value={"command": 5, "robot": "lru1", "state": "sent", "cancel_requested": True},
        ),
        4,
        None,
    )
    assert cancel.startswith("asked lru1 to cancel command 5 (it was sent")


def test_watch_lines_say_the_status_and_what_an_edit_changed():
    from backend.cli.ctl.render import watch_line
    from backend.core import events as ev

    def line(*events):
        return watch_line(
            "events",
            ev.EventBatch(revision=9, events=list(events), actor="lru1", op="report"),
            False,
        )

    done = ev.SkillStatusChanged(id="lru1-1", status="success", at="2026-11-22T07:00:00+00:00")
    assert line(ev.ReportSeq(robot="lru1", seq=4), done) == "r9 report by lru1: lru1-1: success"
    failed = ev.SkillStatusChanged(id="lru1-2", status="failure", info="battery low", attempt=2)
    assert line(failed) == "r9 report by lru1: lru1-2: failure (battery low) attempt 2"
    edited = ev.SkillEdited(id="lru1-3", params={"speed": 0.4}, label="slow")
    assert line(edited) == "r9 report by lru1: lru1-3: changed label, params"


def test_watch_says_which_message_was_unreadable():
    from backend.cli.ctl.render import watch_line
    from backend.client.client import Malformed

    m = Malformed(
        "telemetry",
        "mc/v1/robot/lru1/telemetry",
        "battery: Input should be less than or equal to 1",
    )
    assert watch_line("malformed", m, False) == (
        "unreadable telemetry on mc/v1/robot/lru1/telemetry (ignored): "
        "battery: Input should be less than or equal to 1"
    )
    assert json.loads(watch_line("malformed", m, True)) == {
        "kind": "malformed",
        "what": "telemetry",
        "key": "mc/v1/robot/lru1/telemetry",
        "error": "battery: Input should be less than or equal to 1",
    }
