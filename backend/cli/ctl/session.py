"""`missionctl ctl`: every mission operation, scriptable against a running server.

    missionctl ctl [--connect ENDPOINT] [--json] [--timeout S] [--client-id ID]
                   [--expect-revision N] [--request-id ID] OP ...

The common options may be given before or after OP. One invocation opens one
connection (a `MissionClient`, subscribed to telemetry only for `robots`),
does one thing and always closes the connection.

Operations
  state [ROBOT...]            the mission: per robot its skills (glyph, id,
                              label, skill, parameters that differ from the
                              library defaults), barriers, markers, revision
  robots                      presence, type, manifest (modules, skills) and,
                              when a robot publishes it within ~1 s, battery,
                              link quality and activity
  add ROBOT SKILL [--param NAME=VALUE]... [--label TEXT] [--at INDEX] [POLICY]
  delete ID...
  move ID INDEX               INDEX within the unsynchronized section (0 = first)
  edit ID [--label TEXT] [--param NAME=VALUE]... [--unbind NAME]... [POLICY]
  sync ROBOT [--through ID]
  unsync ROBOT [--from ID]
  run|pause|stop|reset (ROBOT | --all)
  retry ID
  barrier ID ID...
  unbarrier BARRIER_ID
  marker add NAME (--pose P | --position P | --area A) [--description TEXT]
  marker move NAME (--pose P | --position P | --area A)
  marker rename NAME NEW_NAME
  marker delete NAME
  load FILE                   validated here first (file:line:col issues, exit 2)
  save FILE [--library PATH]
  new [NAME]                  an empty mission with the same robots
  undo | redo                 your own (same --client-id) edits of the plan
  watch [--count N]           one line per change until Ctrl-C (or N batches)

Parameter values (--param NAME=VALUE)
  VALUE is a YAML scalar or flow YAML: `speed=0.4`, `filter=near_infrared`,
  `goal={x: 3, y: 4, yaw: 0}` (quote it for the shell), `sensors=[lidar]`.
  `NAME=@MARKER` binds a pose/position/area parameter to a marker (the value
  follows the marker while the skill is idle); for a `marker` parameter it
  names the marker. An empty VALUE (`speed=`) means the library default.
  `--unbind NAME` (edit) keeps the current value but drops the binding.
  POLICY: --retries N, --pause-out-of-comms / --no-pause-out-of-comms,
  --recharge-below F (0..1, or `off`); on edit, unnamed policies are kept.

Geometry
  --pose x,y[,z[,roll,pitch,yaw]] or a flow mapping '{x: 1, y: 2, yaw: 1.57}'
  --position x,y[,z] or '{x: 1, y: 2}'
  --area "x,y x,y x,y ..." (at least 3 points; ';' also separates points)
  A value starting with '-' must be attached: --pose=-3,4. `marker move` with
  --position on a pose marker keeps the marker's orientation.

Connection and identity
  --connect defaults to $MISSIONCTL_CONNECT, else tcp/127.0.0.1:7447 (repeat
  it, or separate endpoints with commas, to give several).
  --client-id defaults to $MISSIONCTL_CLIENT_ID, else `ctl-USER@HOST`: stable
  across invocations, so `ctl undo` undoes what the previous `ctl add` did.
  Every request gets a fresh unique request id; after a timeout, retry with
  `--request-id` (the id is in the message) and the server applies it once.
  --expect-revision N refuses the operation if what it touches changed after
  revision N (optimistic concurrency).

Output
  One line per success (`added lru1-7 (drive_to) to lru1 at revision 12`) and
  the server's notes as `note: ...`. With --json, exactly one JSON object on
  stdout: for operations {"ok": true, "op", "revision", "value", "notes",
  "duplicate"}; `state --json` is the state itself ({"revision", "name",
  "library", "robots", "tasks", "barriers", "markers"}); `watch --json` prints
  one object per line. Failures print on stderr (one line; a usage error
  also the usage) and, with --json, exactly one {"ok": false, "code",
  "message", ...} on stdout, usage errors included. "code" is bad_input or
  bad_file (exit 2; bad_file lists "issues" as file:line:col), the server's
  refusal (exit 1: stale, not_idle, unknown_skill, journal_failed, ..., with
  "robot", "skill", "param" when known), or unreachable, timeout,
  protocol_mismatch (exit 3). With "maybe_applied": true (a timeout, or a
  server gone mid-request) the operation may have been applied: run it again
  with --request-id REQUEST_ID (given in "request_id"), it is applied once.

Exit codes: 0 ok, 1 refused by the server, 2 bad usage or input (nothing is
sent), 3 server unreachable, not answering in time, or speaking another
protocol version. Never a traceback (MISSIONCTL_DEBUG=1 shows one for
unexpected errors).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import re
import socket
import sys
import uuid
from dataclasses import dataclass
from datetime import date, datetime
from pathlib import Path
from typing import Any

from backend.core.credentials import AccountsError
from backend.core.params import POSE_FIELDS, POSITION_FIELDS
from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK, EXIT_REFUSED, EXIT_UNREACHABLE
from backend.transport.login import add_login_arguments, login_from_args

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"
DEFAULT_TIMEOUT = 10.0
TELEMETRY_WAIT = 1.0  # `robots`: how long to wait for one sample per online robot

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_\-]*$")  # model.NAME_PATTERN (kept light to import)
_ENDPOINT_RE = re.compile(r"^[a-z][a-z0-9\-]*/\S+$")

CONTROL_OPS = ("run", "pause", "stop", "reset")


class UsageError(Exception):
    """Bad input on the command line: exit 2, nothing sent."""


class FileInvalid(Exception):
    """A mission file that does not validate: exit 2 with every issue."""

    def __init__(self, file: str, issues: list[Any]):
        super().__init__(f"{file} is not a valid mission ({len(issues)} problem(s))")
        self.file = file
        self.issues = issues


@dataclass(frozen=True)
class MarkerRef:
    """`NAME=@MARKER` on the command line."""

    name: str


# ---------------------------------------------------------------- parsing


def default_client_id() -> str:
    env = os.environ.get("MISSIONCTL_CLIENT_ID")
    if env:
        return env
    try:
        import getpass

        user = getpass.getuser()
    except Exception:  # no user name (containers): still stable per host
        user = f"uid{os.getuid()}"
    return f"ctl-{user}@{socket.gethostname()}"


def default_endpoints() -> list[str]:
    env = os.environ.get("MISSIONCTL_CONNECT", "")
    return [e.strip() for e in env.split(",") if e.strip()] or [DEFAULT_CONNECT]


def _check_name(value: str, what: str) -> str:
    if not _NAME_RE.match(value or ""):
        raise UsageError(
            f"{what}: {value!r} is not a valid name (letters, digits, '_' and '-', starting with a letter)"
        )
    return value


def _plain(value: Any, where: str) -> Any:
    """YAML values as JSON carries them: dates become strings, NaN/inf refused."""
    if isinstance(value, float) and not math.isfinite(value):
        raise UsageError(f"{where}: {value} is not a finite number")
    if isinstance(value, datetime | date):
        return value.isoformat()
    if isinstance(value, dict):
        return {str(k): _plain(v, where) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v, where) for v in value]
    return value


def parse_param(text: str) -> tuple[str, Any]:
    """`NAME=VALUE` -> (name, value); VALUE is YAML, `@M` a MarkerRef."""
    import yaml

    name, sep, raw = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise UsageError(
            f"--param {text!r}: expected NAME=VALUE (e.g. --param speed=0.5 or --param goal=@POI-A)"
        )
    if not _NAME_RE.match(name):
        raise UsageError(f"--param {text!r}: {name!r} is not a parameter name")
    stripped = raw.strip()
    if stripped.startswith("@"):
        return name, MarkerRef(_check_name(stripped[1:], f"--param {name}=@MARKER"))
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError as e:
        why = getattr(e, "problem", None) or str(e).splitlines()[0]
        hint = ""
        if stripped[:1] in "{[":
            hint = f"; quote the whole argument for the shell: --param '{name}={{x: 3, y: 4}}'"
        elif ":" in stripped:
            hint = f"; write a mapping in braces: --param '{name}={{x: 3, y: 4}}'"
        raise UsageError(
            f"--param {name}: {raw!r} is not a valid YAML value ({why}){hint}"
        ) from None
    if isinstance(value, dict | list) and stripped[:1] not in "{[":
        raise UsageError(
            f"--param {name}: {raw!r} reads as a YAML block {'mapping' if isinstance(value, dict) else 'list'}; "
            f"write mappings in braces ({{x: 3, y: 4}}) and lists in brackets ([a, b]), quoted for the shell"
        )
    if isinstance(value, str) and value.startswith("@") and len(value) > 1:
        return name, MarkerRef(_check_name(value[1:], f"--param {name}=@MARKER"))
    return name, _plain(value, f"--param {name}")


def parse_params(items: list[str] | None) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for text in items or []:
        name, value = parse_param(text)
        if name in out:
            raise UsageError(f"--param {name} is given twice")
        out[name] = value
    return out


def _numbers(text: str, what: str, lo: int, hi: int) -> list[float]:
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    if not lo <= len(parts) <= hi:
        n = f"{lo}" if lo == hi else f"{lo} to {hi}"
        raise UsageError(f"{what}: expected {n} comma-separated numbers, got {text!r}")
    out = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise UsageError(f"{what}: {p!r} is not a number (in {text!r})") from None
        if not math.isfinite(v):
            raise UsageError(f"{what}: {p!r} is not a finite number")
        out.append(v)
    return out


def _mapping(text: str, what: str, fields: tuple[str, ...]) -> dict[str, float]:
    import yaml

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise UsageError(
            f"{what}: {text!r} is not a valid YAML mapping ({getattr(e, 'problem', e)})"
        ) from None
    if not isinstance(data, dict):
        raise UsageError(f"{what}: expected a mapping like {{x: 1, y: 2}}, got {text!r}")
    out = {}
    for k, v in data.items():
        if k not in fields:
            raise UsageError(f"{what}: unknown field {k!r} (fields: {', '.join(fields)})")
        if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
            raise UsageError(f"{what}: {k} must be a finite number, got {v!r}")
        out[k] = float(v)
    return out


def parse_pose(text: str) -> dict[str, float]:
    if text.strip().startswith("{"):
        return _mapping(text, "--pose", POSE_FIELDS)
    return dict(zip(POSE_FIELDS, _numbers(text, "--pose", 2, 6), strict=False))


def parse_position(text: str, what: str = "--position") -> dict[str, float]:
    if text.strip().startswith("{"):
        return _mapping(text, what, POSITION_FIELDS)
    return dict(zip(POSITION_FIELDS, _numbers(text, what, 2, 3), strict=False))


def parse_area(text: str) -> list[dict[str, float]]:
    import yaml

    stripped = text.strip()
    if stripped.startswith("["):
        try:
            data = yaml.safe_load(stripped)
        except yaml.YAMLError as e:
            raise UsageError(
                f"--area: {text!r} is not a valid YAML list ({getattr(e, 'problem', e)})"
            ) from None
        if not isinstance(data, list):
            raise UsageError(f"--area: expected a list of positions, got {text!r}")
        points = []
        for i, p in enumerate(data):
            if isinstance(p, dict):
                points.append(_mapping(json.dumps(p), f"--area point {i + 1}", POSITION_FIELDS))
            elif isinstance(p, list):
                points.append(parse_position(",".join(str(v) for v in p), f"--area point {i + 1}"))
            else:
                raise UsageError(
                    f"--area point {i + 1}: expected [x, y] or {{x: .., y: ..}}, got {p!r}"
                )
    else:
        chunks = [c for c in re.split(r"[;\s]+", stripped) if c]
        points = [parse_position(c, f"--area point {i + 1}") for i, c in enumerate(chunks)]
    if len(points) < 3:
        raise UsageError(
            f'--area: a polygon needs at least 3 points, got {len(points)} (write "x,y x,y x,y")'
        )
    return points


def _recharge(text: str) -> float | None:
    if text.strip().lower() in ("off", "none", "no", "never"):
        return None
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a battery fraction 0..1 or 'off', got {text!r}"
        ) from None
    if not (0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(
            f"expected a battery fraction between 0 and 1, got {text!r}"
        )
    return v


def _nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected 0 or more, got {v}")
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return v


# ---------------------------------------------------------------- argparse


def _common(p: argparse.ArgumentParser, *, top: bool) -> None:
    """Options accepted before and after OP (after OP they override)."""
    d = (lambda v: v) if top else (lambda v: argparse.SUPPRESS)
    g = p.add_argument_group("connection and output")
    g.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        default=d(None),
        help=f"mission server endpoint (default: $MISSIONCTL_CONNECT or {DEFAULT_CONNECT}); repeatable",
    )
    g.add_argument(
        "--json",
        action="store_true",
        default=d(False),
        help="print one JSON object (watch: one per line)",
    )
    g.add_argument(
        "--timeout",
        type=_positive_float,
        metavar="S",
        default=d(DEFAULT_TIMEOUT),
        help=f"seconds to wait for the server (default {DEFAULT_TIMEOUT:g})",
    )
    g.add_argument(
        "--client-id",
        metavar="ID",
        default=d(None),
        help="client id (default: $MISSIONCTL_CLIENT_ID or ctl-USER@HOST; undo/redo are per client id)",
    )
    g.add_argument(
        "--expect-revision",
        type=_nonneg_int,
        metavar="N",
        default=d(None),
        help="refuse if what the operation touches changed after revision N",
    )
    g.add_argument(
        "--request-id",
        metavar="ID",
        default=d(None),
        help="request id (default: a fresh one); reuse it to retry safely after a timeout",
    )
    add_login_arguments(p.add_argument_group("login and TLS (docs/security.md)"), suppress=not top)


def _policies(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("policies")
    g.add_argument(
        "--retries",
        type=_nonneg_int,
        metavar="N",
        help="autonomous retries after a failure (0..20)",
    )
    g.add_argument(
        "--pause-out-of-comms",
        dest="pause_out_of_comms",
        action="store_const",
        const=True,
        help="pause while out of communication range",
    )
    g.add_argument(
        "--no-pause-out-of-comms", dest="pause_out_of_comms", action="store_const", const=False
    )
    g.add_argument(
        "--recharge-below",
        type=_recharge,
        metavar="F",
        default=argparse.SUPPRESS,
        help="return to recharge below this battery fraction (0..1, or 'off')",
    )


def _geometry(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument(
        "--pose", metavar="P", help="x,y[,z[,roll,pitch,yaw]] or '{x: 1, y: 2, yaw: 0.5}'"
    )
    g.add_argument("--position", metavar="P", help="x,y[,z] or '{x: 1, y: 2}'")
    g.add_argument("--area", metavar="A", help='polygon "x,y x,y x,y ..." (3 points or more)')


def register(subparsers: Any) -> argparse.ArgumentParser:
    """Add `ctl` to missionctl's sub-commands."""
    p = subparsers.add_parser(
        "ctl",
        help="run mission operations against a running server (scriptable, --json)",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _common(p, top=True)
    ops = p.add_subparsers(dest="op", metavar="OP")

    def op(name: str, help: str, **kw: Any) -> argparse.ArgumentParser:
        sp = ops.add_parser(name, help=help, description=help, **kw)
        _common(sp, top=False)
        return sp

    s = op("state", "print the mission: robots, skills, barriers, markers, revision")
    s.add_argument("robots", nargs="*", metavar="ROBOT", help="only these robots")

    op("robots", "robot presence, type, manifest and telemetry")

    a = op("add", "add a skill to a robot's unsynchronized section")
    a.add_argument("robot", metavar="ROBOT")
    a.add_argument("skill", metavar="SKILL")
    a.add_argument(
        "--param", action="append", metavar="NAME=VALUE", help="parameter value (YAML) or @MARKER"
    )
    a.add_argument("--label", metavar="TEXT")
    a.add_argument(
        "--at",
        type=int,
        metavar="INDEX",
        help="position in the unsynchronized section (default: end)",
    )
    _policies(a)

    d = op("delete", "delete idle skills")
    d.add_argument("ids", nargs="+", metavar="ID")

    m = op("move", "move an idle skill within its robot's unsynchronized section")
    m.add_argument("id", metavar="ID")
    m.add_argument("index", type=int, metavar="INDEX", help="0 = first unsynchronized skill")

    e = op("edit", "change the label, parameters, bindings or policies of an idle skill")
    e.add_argument("id", metavar="ID")
    e.add_argument("--label", metavar="TEXT")
    e.add_argument(
        "--param", action="append", metavar="NAME=VALUE", help="parameter value (YAML) or @MARKER"
    )
    e.add_argument(
        "--unbind",
        action="append",
        metavar="NAME",
        help="drop a parameter's marker binding (keeps its value)",
    )
    _policies(e)

    sy = op("sync", "send a robot its unsynchronized skills (all, or through ID)")
    sy.add_argument("robot", metavar="ROBOT")
    sy.add_argument("--through", metavar="ID", help="last skill to synchronize")

    u = op("unsync", "take queued skills back from a robot (all, or from ID on)")
    u.add_argument("robot", metavar="ROBOT")
    u.add_argument("--from", dest="from_id", metavar="ID", help="first queued skill to take back")

    for name, what in (
        ("run", "start or resume execution"),
        ("pause", "pause the running skill"),
        ("stop", "stop the active skill (it returns to the queue)"),
        ("reset", "stop and unsynchronize everything queued"),
    ):
        c = op(name, f"{what}, on one robot or --all")
        c.add_argument("robot", nargs="?", metavar="ROBOT")
        c.add_argument("--all", action="store_true", help="every robot")

    r = op("retry", "retry a failed skill (a new attempt right after it)")
    r.add_argument("id", metavar="ID")

    b = op("barrier", "make idle skills of different robots start together")
    b.add_argument("ids", nargs="+", metavar="ID")

    ub = op("unbarrier", "remove a barrier")
    ub.add_argument("barrier", metavar="BARRIER_ID")

    mk = op("marker", "add, move, rename or delete a marker")
    mops = mk.add_subparsers(dest="marker_op", metavar="ACTION")
    mops.required = True

    def mop(name: str, help: str) -> argparse.ArgumentParser:
        sp = mops.add_parser(name, help=help, description=help)
        _common(sp, top=False)
        sp.add_argument("name", metavar="NAME")
        return sp

    ma = mop("add", "add a pose, position or area marker")
    _geometry(ma)
    ma.add_argument("--description", default="", metavar="TEXT")
    mm = mop("move", "give a marker a new pose, position or area (idle bound skills follow)")
    _geometry(mm)
    mr = mop("rename", "rename a marker (bindings follow)")
    mr.add_argument("new_name", metavar="NEW_NAME")
    mop("delete", "delete a marker (not while a synchronized skill uses it)")

    lo = op("load", "replace the mission with a mission file (validated here first)")
    lo.add_argument("file", metavar="FILE")

    sv = op("save", "write the mission to a YAML file")
    sv.add_argument("file", metavar="FILE")
    sv.add_argument(
        "--library",
        metavar="PATH",
        help="the skill library file to reference, written relative to FILE "
        "(default: the server's reference, as is)",
    )

    n = op("new", "start an empty mission with the same robots")
    n.add_argument("name", nargs="?", default="mission", metavar="NAME")

    op("undo", "undo your last edit of the plan")
    op("redo", "redo what you undid last")

    w = op("watch", "print changes as they happen, one line each, until Ctrl-C")
    w.add_argument("--count", type=_nonneg_int, metavar="N", help="stop after N change batches")

    p.set_defaults(func=run)
    return p


def build_parser() -> argparse.ArgumentParser:
    """A stand-alone `missionctl` parser with only `ctl` (tests, `python -m backend.cli.ctl.session`)."""
    try:
        from backend.cli.main import _Parser as parser_class
    except ImportError:  # pragma: no cover
        parser_class = argparse.ArgumentParser
    top = parser_class(prog="missionctl")
    sub = top.add_subparsers(dest="command", metavar="COMMAND", parser_class=parser_class)
    register(sub)
    return top


def wants_json(argv: list[str]) -> bool:
    """`missionctl ARGV...` is `ctl ... --json ...` (before any `--`)."""
    if not argv or argv[0] != "ctl":
        return False
    args = argv[1 : argv.index("--")] if "--" in argv else argv[1:]
    return "--json" in args


def parse_args(argv: list[str]) -> argparse.Namespace:
    """`missionctl ctl ARGV...` parsed (argparse errors exit 2)."""
    parser = build_parser()
    type(parser).json_errors = wants_json(["ctl", *argv])
    return parser.parse_args(["ctl", *argv])


# ---------------------------------------------------------------- operations


def _param_spec(library: Any, mission: Any, robot: str | None, skill: str | None, name: str) -> Any:
    if library is None or mission is None or robot is None or skill is None:
        return None
    spec = mission.robots.get(robot)
    if spec is None:
        return None
    sk = library.skill_for(spec.type, skill)
    return sk.params.get(name) if sk else None


def _resolve(
    parsed: dict[str, Any], library: Any, mission: Any, robot: str | None, skill: str | None
) -> tuple[dict[str, Any], dict[str, str]]:
    """Split parsed params into values and marker bindings, by parameter type."""
    params: dict[str, Any] = {}
    bindings: dict[str, str] = {}
    for name, value in parsed.items():
        if not isinstance(value, MarkerRef):
            params[name] = value
            continue
        pspec = _param_spec(library, mission, robot, skill, name)
        if pspec is None or pspec.type in ("pose", "position", "area"):
            bindings[name] = value.name  # unknown: the server names the problem
        elif pspec.type == "marker":
            params[name] = value.name
        else:  # a plain string that happens to start with '@'
            params[name] = f"@{value.name}"
    return params, bindings


def _given_policies(args: argparse.Namespace) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if getattr(args, "retries", None) is not None:
        out["retries"] = args.retries
    if getattr(args, "pause_out_of_comms", None) is not None:
        out["pause_out_of_comms"] = args.pause_out_of_comms
    if hasattr(args, "recharge_below"):
        out["recharge_below"] = args.recharge_below
    return out


def _validated(model: type, what: str, **fields: Any) -> Any:
    """Build an operation; a field the protocol refuses is a usage error."""
    from pydantic import ValidationError

    try:
        return model(**fields)
    except ValidationError as e:
        err = e.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        value = err.get("input")
        msg = err["msg"]
        if err["type"] == "string_pattern_mismatch":
            msg = "not a valid name or id (letters, digits, '_', '-', '.')"
        raise UsageError(f"{what}: {loc + ': ' if loc else ''}{value!r}: {msg}") from None


def _geometry_value(args: argparse.Namespace) -> tuple[str, Any]:
    if args.pose is not None:
        return "pose", parse_pose(args.pose)
    if args.position is not None:
        return "position", parse_position(args.position)
    return "area", parse_area(args.area)


def build_op(args: argparse.Namespace, library: Any = None, mission: Any = None) -> Any:
    """The operation `args` asks for (None for state/robots/watch/save).

    Without `library`/`mission` (before connecting) only the command line is
    checked; with them, `@MARKER` values are resolved by parameter type and
    edits keep the policies they do not name. Raises UsageError / FileInvalid.
    """
    from backend.core import ops
    from backend.core.model import AreaMarker, Policies, Pose, PoseMarker, Position, PositionMarker

    name = args.op
    if name in ("state", "robots", "watch", "save", None):
        for r in getattr(args, "robots", None) or []:
            _check_name(r, "ROBOT")
        return None
    if name == "add":
        _check_name(args.robot, "ROBOT")
        _check_name(args.skill, "SKILL")
        params, bindings = _resolve(
            parse_params(args.param), library, mission, args.robot, args.skill
        )
        given = _given_policies(args)
        policies = _validated(Policies, "policies", **given) if given else None
        return _validated(
            ops.AddSkill,
            "add",
            robot=args.robot,
            skill=args.skill,
            label=args.label or "",
            params=params,
            bindings=bindings,
            policies=policies,
            at=args.at,
        )
    if name == "delete":
        return _validated(ops.DeleteSkills, "delete", ids=args.ids)
    if name == "move":
        if args.index < 0:
            raise UsageError(f"move: INDEX must be 0 or more, got {args.index}")
        return _validated(ops.MoveSkill, "move", id=args.id, index=args.index)
    if name == "edit":
        parsed = parse_params(args.param)
        unbind = list(dict.fromkeys(args.unbind or []))
        for u in unbind:
            _check_name(u, "--unbind")
            if u in parsed:
                raise UsageError(f"--unbind {u} and --param {u}=... contradict each other")
        given = _given_policies(args)
        if args.label is None and not parsed and not unbind and not given:
            raise UsageError(
                "edit: nothing to change (give --label, --param, --unbind or a policy option)"
            )
        found = mission.find(args.id) if mission is not None else None
        robot, skill = (found[0], found[2].skill) if found else (None, None)
        params, bindings = _resolve(parsed, library, mission, robot, skill)
        all_bindings: dict[str, str | None] = {**bindings, **dict.fromkeys(unbind)}
        policies = None
        if given:
            base = found[2].policies.model_dump() if found else {}
            policies = _validated(Policies, "policies", **{**base, **given})
        return _validated(
            ops.EditSkill,
            "edit",
            id=args.id,
            label=args.label,
            params=params,
            bindings=all_bindings,
            policies=policies,
        )
    if name == "sync":
        _check_name(args.robot, "ROBOT")
        return _validated(ops.Sync, "sync", robot=args.robot, through=args.through)
    if name == "unsync":
        _check_name(args.robot, "ROBOT")
        return _validated(ops.Unsync, "unsync", robot=args.robot, from_id=args.from_id)
    if name in CONTROL_OPS:
        if args.all == (args.robot is not None):
            raise UsageError(f"{name}: give a ROBOT or --all (not both)")
        if args.robot is not None:
            _check_name(args.robot, "ROBOT")
        return _validated(ops.Control, name, op=name, robot=args.robot)
    if name == "retry":
        return _validated(ops.Retry, "retry", id=args.id)
    if name == "barrier":
        if len(args.ids) < 2:
            raise UsageError("barrier: give the ids of at least two skills of different robots")
        return _validated(ops.AddBarrier, "barrier", ids=args.ids)
    if name == "unbarrier":
        return _validated(ops.RemoveBarrier, "unbarrier", barrier=args.barrier)
    if name == "marker":
        _check_name(args.name, "NAME")
        if args.marker_op == "add":
            kind, value = _geometry_value(args)
            if kind == "pose":
                marker = PoseMarker(pose=Pose(**value), description=args.description)
            elif kind == "position":
                marker = PositionMarker(position=Position(**value), description=args.description)
            else:
                marker = AreaMarker(
                    area=[Position(**p) for p in value], description=args.description
                )
            return _validated(ops.MarkerAdd, "marker add", name=args.name, marker=marker)
        if args.marker_op == "move":
            kind, value = _geometry_value(args)
            current = mission.markers.get(args.name) if mission is not None else None
            if kind == "pose":
                new: Any = Pose(**value)
            elif kind == "position":
                new = Position(**value)
                if current is not None and current.kind == "pose":  # keep the orientation
                    o = current.pose
                    new = Pose(**value, roll=o.roll, pitch=o.pitch, yaw=o.yaw)
            else:
                new = [Position(**p) for p in value]
            return _validated(ops.MarkerMove, "marker move", name=args.name, value=new)
        if args.marker_op == "rename":
            _check_name(args.new_name, "NEW_NAME")
            return _validated(
                ops.MarkerRename, "marker rename", name=args.name, new_name=args.new_name
            )
        return _validated(ops.MarkerDelete, "marker delete", name=args.name)
    if name == "load":
        from backend.files.diagnostics import FileProblems
        from backend.files.missions import load_mission

        loaded = getattr(args, "loaded", None)
        if loaded is None:
            try:
                loaded = load_mission(args.file)
            except FileProblems as e:
                raise FileInvalid(args.file, e.issues) from None
            args.loaded = loaded  # (mission, library): read the file once
        return ops.LoadMission(mission=loaded[0].copy_deep())
    if name == "new":
        return _validated(ops.NewMission, "new", name=args.name)
    if name == "undo":
        return ops.Undo()
    if name == "redo":
        return ops.Redo()
    raise UsageError(f"unknown operation {name!r}")


# ---------------------------------------------------------------- output helpers

_GLYPHS = {
    "idle": ("○", "."),
    "idle_synchronized": ("●", "o"),
    "synchwaiting": ("⧗", "w"),
    "running": ("▶", ">"),
    "paused": ("‖", "|"),
    "success": ("✓", "+"),
    "failure": ("✗", "x"),
}


def _unicode_ok() -> bool:
    enc = getattr(sys.stdout, "encoding", None) or "ascii"
    try:
        ("".join(g for g, _ in _GLYPHS.values()) + "—").encode(enc)
        return True
    except (UnicodeEncodeError, LookupError):
        return False


def glyph(status: str, unicode: bool = True) -> str:
    u, a = _GLYPHS.get(status, ("?", "?"))
    return u if unicode else a


def _num(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def short_value(v: Any, limit: int = 40) -> str:
    """A compact rendering of a parameter value for one line of `state`."""
    if (
        isinstance(v, dict)
        and v
        and set(v) <= set(POSE_FIELDS)
        and all(isinstance(x, int | float) for x in v.values())
    ):
        text = f"({_num(v.get('x', 0))},{_num(v.get('y', 0))}"
        extra = [f"{k}={_num(v[k])}" for k in ("z", "roll", "pitch", "yaw") if v.get(k)]
        text += (" " + " ".join(extra) if extra else "") + ")"
    elif (
        isinstance(v, list)
        and v
        and all(isinstance(p, dict) and set(p) <= set(POSITION_FIELDS) for p in v)
    ):
        text = f"[{len(v)} points]"
    elif isinstance(v, str):
        text = v if v and re.fullmatch(r"[\w.\-@/]+", v) else json.dumps(v, ensure_ascii=False)
    else:
        text = json.dumps(v, separators=(",", ":"), ensure_ascii=False)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _differs_from_default(library: Any, skill: str, name: str, value: Any) -> bool:
    if library is None:
        return True
    spec = library.skills.get(skill)
    pspec = spec.params.get(name) if spec else None
    if pspec is None or pspec.default is None:
        return True
    from backend.core.params import normalize_value

    try:
        return normalize_value(pspec, pspec.default) != value
    except Exception:
        return True


def short_params(s: Any, library: Any) -> str:
    parts = []
    for name, value in s.params.items():
        if name in s.bindings:
            parts.append(f"{name}=@{s.bindings[name]}")
        elif _differs_from_default(library, s.skill, name, value):
            parts.append(f"{name}={short_value(value)}")
    for name, marker in s.bindings.items():
        if name not in s.params:
            parts.append(f"{name}=@{marker}")
    return " ".join(parts)


def _time(t: datetime | None) -> str:
    if t is None:
        return ""
    try:
        return t.astimezone().strftime("%H:%M:%S")
    except (ValueError, OSError):
        return t.strftime("%H:%M:%S")


def _presence(info: Any) -> str:
    if info is None:
        return "not registered"
    if info.online:
        return f"online since {_time(info.since)}" if info.since else "online"
    return (
        f"offline since {_time(info.since)}"
        if info.since
        else "offline (not seen since the server started)"
    )


def _marker_text(mk: Any) -> str:
    if mk.kind == "pose":
        text = "pose " + short_value(mk.pose.model_dump())
    elif mk.kind == "position":
        text = "position " + short_value(mk.position.model_dump())
    else:
        pts = " ".join(
            f"{_num(p.x)},{_num(p.y)}" + (f",{_num(p.z)}" if p.z else "") for p in mk.area
        )
        text = f"area {pts}"
    return text + (f"  {mk.description}" if mk.description else "")


def state_json(client: Any, only: list[str] | None = None) -> dict[str, Any]:
    m, lib = client.mission, client.library
    robots: dict[str, Any] = {}
    for name in list(m.robots) + [r for r in client.robots if r not in m.robots]:
        if only and name not in only:
            continue
        spec = m.robots.get(name)
        info = client.robots.get(name)
        rtype = spec.type if spec else (info.manifest.type if info and info.manifest else None)
        rt = lib.robot_types.get(rtype) if rtype else None
        robots[name] = {
            "type": rtype,
            "kind": rt.kind if rt else None,
            "in_mission": spec is not None,
            "online": bool(info and info.online),
            "since": info.since.isoformat() if info and info.since else None,
            "manifest": info.manifest.model_dump(mode="json") if info and info.manifest else None,
        }
    tasks: dict[str, Any] = {}
    for robot, task in m.tasks.items():
        if only and robot not in only:
            continue
        tasks[robot] = [
            {
                "id": s.id,
                "skill": s.skill,
                "label": s.label,
                "status": s.status.value,
                "status_info": s.status_info,
                "attempt": s.attempt,
                "params": s.params,
                "bindings": s.bindings,
                "policies": s.policies.model_dump(mode="json"),
                "barrier": m.barrier_of(s.id),
                "started_at": s.started_at.isoformat() if s.started_at else None,
                "finished_at": s.finished_at.isoformat() if s.finished_at else None,
            }
            for s in task
        ]
    return {
        "revision": m.revision,
        "name": m.name,
        "library": m.library,
        "server_id": client.server_id,
        "robots": robots,
        "tasks": tasks,
        "barriers": {bid: list(b.skills) for bid, b in m.barriers.items()},
        "markers": {n: mk.model_dump(mode="json") for n, mk in m.markers.items()},
    }


def state_text(client: Any, only: list[str] | None = None, unicode: bool = True) -> str:
    m, lib = client.mission, client.library
    dash = "—" if unicode else "-"
    lines = [
        f"mission '{m.name}' at revision {m.revision} (library '{lib.name}', {', '.join(client.endpoints)})"
    ]
    robots = list(m.robots) + [r for r in m.tasks if r not in m.robots]
    for robot in robots:
        if only and robot not in only:
            continue
        spec = m.robots.get(robot)
        rtype = spec.type if spec else "?"
        kind = lib.robot_types[rtype].kind if rtype in lib.robot_types else ""
        lines.append(
            f"{robot} ({rtype}{', ' + kind if kind == 'static' else ''}) {dash} {_presence(client.robots.get(robot))}"
        )
        task = m.tasks.get(robot, [])
        if not task:
            lines.append("  (no skills)")
            continue
        ids = [s.id + (f" [{m.barrier_of(s.id)}]" if m.barrier_of(s.id) else "") for s in task]
        wid = max(len(i) for i in ids)
        wlabel = max(len(s.label) for s in task)
        wskill = max(len(s.skill) for s in task)
        for s, ident in zip(task, ids, strict=True):
            line = f"  {glyph(s.status.value, unicode)} {ident:<{wid}}  {s.label:<{wlabel}}  {s.skill:<{wskill}}"
            extra = short_params(s, lib)
            if extra:
                line += "  " + extra
            if s.attempt > 1:
                line += f"  (attempt {s.attempt})"
            if not s.policies.is_default():
                p = s.policies
                pol = []
                if p.retries:
                    pol.append(f"retries={p.retries}")
                if p.pause_out_of_comms:
                    pol.append("pause-out-of-comms")
                if p.recharge_below is not None:
                    pol.append(f"recharge<{p.recharge_below:g}")
                line += "  {" + " ".join(pol) + "}"
            if s.status_info:
                line += f"  {dash} {s.status_info}"
            lines.append(line.rstrip())
    if m.barriers:
        lines.append(
            "barriers: "
            + "; ".join(f"{bid} = {' + '.join(b.skills)}" for bid, b in m.barriers.items())
        )
    else:
        lines.append("barriers: none")
    if m.markers:
        lines.append("markers:")
        w = max(len(n) for n in m.markers)
        lines += [f"  {n:<{w}}  {_marker_text(mk)}" for n, mk in m.markers.items()]
    else:
        lines.append("markers: none")
    legend = ", ".join(f"{glyph(st, unicode)} {st}" for st in _GLYPHS)
    lines.append(f"({legend})")
    return "\n".join(lines)


def robots_json(client: Any) -> dict[str, Any]:
    out = state_json(client)["robots"]
    for name, entry in out.items():
        t = client.telemetry.get(name)
        entry["telemetry"] = t.model_dump(mode="json") if t else None
    return {"revision": client.revision, "robots": out}


def robots_text(client: Any) -> str:
    data = robots_json(client)["robots"]
    if not data:
        return "no robots"
    lines = []
    for name, r in data.items():
        head = f"{name} ({r['type'] or '?'}{', not in the mission' if not r['in_mission'] else ''}): {_presence(client.robots.get(name))}"
        t = client.telemetry.get(name)
        if t is not None:
            head += f"; battery {t.battery:.0%}, link {t.link:.0%}{'' if t.in_range else ' (out of range)'}, {t.mode}"
            if t.skill:
                head += f" {t.skill}" + (f" {t.progress:.0%}" if t.progress is not None else "")
        lines.append(head)
        man = r["manifest"]
        if man:
            mods = ", ".join(f"{x['name']} {x['version']}" for x in man["modules"]) or "none"
            skills = ", ".join(f"{k} {v}" for k, v in man["skills"].items()) or "none"
            lines.append(f"  modules: {mods}")
            lines.append(f"  skills:  {skills}")
            if man["properties"]:
                lines.append(
                    "  properties: "
                    + ", ".join(f"{k}={short_value(v)}" for k, v in man["properties"].items())
                )
        else:
            lines.append("  (no manifest: never registered with this server)")
    return "\n".join(lines)


def _ids(v: Any) -> str:
    return ", ".join(v) if isinstance(v, list) else str(v)


def describe(op: Any, reply: Any, before: int, mission: Any) -> str:
    """One line saying what an applied operation did."""
    rev = reply.revision
    at = f"at revision {rev}"
    v = reply.value
    changed = rev != before or reply.duplicate
    name = op.op
    if name == "add":
        text = f"added {v.get('id', '?')} ({op.skill}) to {op.robot} {at}"
    elif name == "delete":
        text = f"deleted {', '.join(op.ids)} {at}"
    elif name == "move":
        found = mission.find(op.id) if mission is not None else None
        where = f" of {found[0]}'s unsynchronized section" if found else ""
        text = (
            f"moved {op.id} to position {op.index}{where} {at}"
            if changed
            else f"{op.id} is already at position {op.index}; nothing changed (revision {rev})"
        )
    elif name == "edit":
        text = (
            f"edited {op.id} {at}"
            if changed
            else f"{op.id} already had these values; nothing changed (revision {rev})"
        )
    elif name == "sync":
        text = f"synchronized {_ids(v.get('synchronized', []))} to {op.robot} {at}"
    elif name == "unsync":
        back = v.get("unsynchronized", [])
        text = f"unsynchronized {_ids(back) or 'nothing'} from {op.robot} {at}"
    elif name in CONTROL_OPS:
        robots = v.get("robots", {})
        ok = [r for r, res in robots.items() if res == "ok"]
        target = ", ".join(ok) if ok else (op.robot or "all robots")
        text = f"{name} sent to {target} {at}"
    elif name == "retry":
        text = f"retrying {op.id} as {v.get('id', '?')} {at}"
    elif name == "barrier":
        text = f"created barrier {v.get('barrier', '?')} ({', '.join(op.ids)}) {at}"
    elif name == "unbarrier":
        text = f"removed barrier {op.barrier} {at}"
    elif name == "marker_add":
        text = f"added marker {op.name} ({op.marker.kind}) {at}"
    elif name == "marker_move":
        text = (
            f"moved marker {op.name} {at}"
            if changed
            else f"marker {op.name} is already there; nothing changed (revision {rev})"
        )
    elif name == "marker_rename":
        text = f"renamed marker {op.name} to {op.new_name} {at}"
    elif name == "marker_delete":
        text = f"deleted marker {op.name} {at}"
    elif name == "load":
        m = op.mission
        n = sum(len(t) for t in m.tasks.values())
        text = f"loaded mission '{m.name}' ({len(m.robots)} robots, {n} skills) {at}"
    elif name == "new":
        text = f"started a new mission '{op.name}' {at}"
    elif name == "undo":
        text = f"undid {v.get('undone', 'the last edit')} {at}"
    elif name == "redo":
        text = f"redid {v.get('redone', 'the last undone edit')} {at}"
    else:
        text = f"{name} done {at}"
    if reply.duplicate:
        text += " (this request had been applied already)"
    return text


def _event_text(e: Any) -> str | None:
    kind = e.ev
    if kind == "skill_added":
        s = e.skill
        return f"+{s.id} {s.skill} on {e.robot} at {e.index} ({s.status.value})"
    if kind == "skill_removed":
        return f"-{e.id} from {e.robot}"
    if kind == "skill_moved":
        return f"{e.id} moved to {e.index} on {e.robot}"
    if kind == "skill_changed":
        # A status change stamps started_at/finished_at itself: not news.
        ch = {k: v for k, v in e.changes.items() if k not in ("started_at", "finished_at", "rev")}
        parts = []
        if "status" in ch:
            parts.append(str(ch.pop("status")))
        if ch.get("status_info"):
            parts.append(f"({ch['status_info']})")
        ch.pop("status_info", None)
        if "attempt" in ch:
            parts.append(f"attempt {ch.pop('attempt')}")
        if ch:
            parts.append("changed " + ", ".join(sorted(ch)))
        return f"{e.id}: {' '.join(parts) or 'timestamps'}"
    if kind == "barrier_set":
        return f"barrier {e.id} = {' + '.join(e.barrier.skills)}"
    if kind == "barrier_removed":
        return f"barrier {e.id} removed"
    if kind == "marker_set":
        return f"marker {e.name}: {_marker_text(e.marker)}"
    if kind == "marker_removed":
        return f"marker {e.name} removed"
    if kind == "mission_replaced":
        n = sum(len(t) for t in e.mission.tasks.values())
        return f"mission replaced: '{e.mission.name}' ({n} skills)"
    return None  # report_seq: bookkeeping


def watch_line(kind: str, payload: Any, as_json: bool) -> str | None:
    if as_json:
        if kind == "events":
            return json.dumps({"kind": "events", **payload.model_dump(mode="json")})
        if kind == "fleet":
            return json.dumps({"kind": "fleet", "robot": payload.model_dump(mode="json")})
        if kind == "alert":
            return json.dumps({"kind": "alert", **payload.model_dump(mode="json")})
        if kind == "malformed":
            return json.dumps(
                {
                    "kind": "malformed",
                    "what": payload.what,
                    "key": payload.key,
                    "error": payload.error,
                }
            )
        if kind == "connection":
            return json.dumps({"kind": "connection", "state": payload})
        if kind == "state":
            return json.dumps(
                {"kind": "resync", "revision": payload.revision, "server_id": payload.server_id}
            )
        return None
    if kind == "events":
        parts = [t for t in (_event_text(e) for e in payload.events) if t]
        who = f" by {payload.actor}" if payload.actor else ""
        return f"r{payload.revision} {payload.op or 'change'}{who}: {'; '.join(parts) or 'bookkeeping'}"
    if kind == "fleet":
        return f"robot {payload.name} {_presence(payload)}"
    if kind == "alert":
        where = (
            f" [{payload.robot}{'/' + payload.skill if payload.skill else ''}]"
            if payload.robot
            else ""
        )
        return f"{payload.level}{where}: {payload.message}"
    if kind == "malformed":
        return f"unreadable {payload.what} on {payload.key} (ignored): {payload.error}"
    if kind == "connection":
        return f"connection: {payload}"
    if kind == "state":
        return f"resynchronized at revision {payload.revision} (server {payload.server_id})"
    return None


# ---------------------------------------------------------------- running


def _print_json(obj: Any) -> None:
    print(json.dumps(obj, ensure_ascii=False, default=str), flush=True)


def _fail(
    args: argparse.Namespace,
    code: str,
    message: str,
    exit_code: int,
    *,
    extra: dict | None = None,
    lines: list[str] | None = None,
) -> int:
    """A failure: one line (or the given lines) on stderr, and with --json
    {"ok": false, "code", "message", ...} on stdout."""
    for line in lines or [f"missionctl: {message}"]:
        print(line, file=sys.stderr, flush=True)
    if getattr(args, "json", False):
        _print_json({"ok": False, "code": code, "message": message, **(extra or {})})
    return exit_code


def run(args: argparse.Namespace) -> int:
    """`missionctl ctl ...`: returns the exit code; never raises for bad input."""
    for stream in (sys.stdout, sys.stderr):  # labels may hold what the terminal cannot show
        try:
            stream.reconfigure(errors="replace")  # type: ignore[attr-defined]
        except (AttributeError, ValueError):
            pass
    if not getattr(args, "op", None):
        return _fail(
            args,
            "bad_input",
            "give an operation (missionctl ctl --help lists them)",
            EXIT_BAD_INPUT,
            lines=["missionctl ctl: error: give an operation (missionctl ctl --help lists them)"],
        )
    try:
        return _run(args)
    except UsageError as e:
        return _fail(
            args, "bad_input", str(e), EXIT_BAD_INPUT, lines=[f"missionctl ctl: error: {e}"]
        )
    except FileInvalid as e:
        return _fail(
            args,
            "bad_file",
            str(e),
            EXIT_BAD_INPUT,
            extra={"issues": [str(i) for i in e.issues]},
            lines=[str(i) for i in e.issues],
        )
    except KeyboardInterrupt:
        return EXIT_OK if args.op == "watch" else 130
    except BrokenPipeError:
        try:  # the reader went away (`| head`): no complaint at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except OSError:
            pass
        return EXIT_OK
    except Exception as e:  # never a traceback for a person
        if os.environ.get("MISSIONCTL_DEBUG"):
            raise
        return _fail(
            args,
            "internal_error",
            f"unexpected error: {type(e).__name__}: {e} (MISSIONCTL_DEBUG=1 shows the traceback)",
            EXIT_REFUSED,
        )


def _endpoints(args: argparse.Namespace) -> list[str]:
    raw = args.connect or default_endpoints()
    out = [e.strip() for item in raw for e in item.split(",") if e.strip()]
    for e in out:
        if not _ENDPOINT_RE.match(e):
            raise UsageError(f"--connect: {e!r} is not a Zenoh endpoint (e.g. tcp/127.0.0.1:7447)")
    if not out:
        raise UsageError("--connect: no endpoint given")
    from backend.transport import client_config

    try:
        client_config(out)
    except ValueError as e:
        raise UsageError(f"--connect: {e}") from None
    return out


def _run(args: argparse.Namespace) -> int:
    from backend.client.client import (
        MaybeApplied,
        OperationRefused,
        OperationTimeout,
        ProtocolMismatch,
        ServerUnreachable,
    )
    from backend.transport import TransportError

    endpoints = _endpoints(args)
    build_op(args)  # the command line alone: bad usage never needs a server
    try:
        login = login_from_args(args)
    except AccountsError as e:
        raise UsageError(str(e)) from None
    if args.op == "save":
        target = Path(args.file)
        if target.is_dir():
            raise UsageError(f"save: {args.file} is a directory")
        parent = target.resolve().parent
        if not parent.is_dir():
            why = "is not a folder" if parent.exists() else "does not exist"
            raise UsageError(f"save: {target.parent} {why}: nothing was written")
    try:
        return asyncio.run(_session(args, endpoints, login))
    except OperationRefused as e:
        r = e.reply
        return _fail(
            args,
            r.code,
            r.message,
            EXIT_REFUSED,
            lines=[f"missionctl: refused: {r.message}"],
            extra={
                k: v
                for k, v in r.model_dump().items()
                if k not in ("ok", "code", "message") and v is not None
            },
        )
    except MaybeApplied as e:  # the request left: it may have been applied
        retry = f"--request-id {e.request_id}" + (
            f" --client-id {args.client_id}" if args.client_id else ""
        )
        message = (
            f"{e.what}. Once the server answers, look with `missionctl ctl state`, or run the same command "
            f"again with {retry}: it is applied once (the reply says so if it had been)"
        )
        code = "timeout" if isinstance(e, OperationTimeout) else "unreachable"
        return _fail(
            args,
            code,
            message,
            EXIT_UNREACHABLE,
            extra={"request_id": e.request_id, "maybe_applied": True},
        )
    except ServerUnreachable as e:
        return _fail(args, "unreachable", str(e), EXIT_UNREACHABLE)
    except ProtocolMismatch as e:
        return _fail(args, "protocol_mismatch", str(e), EXIT_UNREACHABLE)
    except OperationTimeout as e:
        return _fail(args, "timeout", str(e), EXIT_UNREACHABLE)
    except TransportError as e:
        return _fail(args, "transport_error", str(e), EXIT_UNREACHABLE)


async def _session(args: argparse.Namespace, endpoints: list[str], login: Any = None) -> int:
    from backend.client.client import MissionClient

    client = MissionClient(
        endpoints,
        login=login,
        client_id=args.client_id or default_client_id(),
        timeout=args.timeout,
        telemetry=args.op
        in ("robots", "watch"),  # watch: to say when a robot's telemetry is unreadable
    )
    async with client:
        if args.op == "state":
            return _state(client, args)
        if args.op == "robots":
            return await _robots(client, args)
        if args.op == "watch":
            return await _watch(client, args)
        if args.op == "save":
            return _save(client, args)
        return await _operation(client, args)


def _state(client: Any, args: argparse.Namespace) -> int:
    only = list(args.robots or [])
    unknown = [r for r in only if r not in client.mission.robots and r not in client.robots]
    if unknown:
        known = ", ".join(client.mission.robots) or "none"
        raise UsageError(f"state: no robot {', '.join(unknown)} in this mission (robots: {known})")
    if args.json:
        _print_json(state_json(client, only or None))
    else:
        print(state_text(client, only or None, unicode=_unicode_ok()), flush=True)
    return EXIT_OK


async def _robots(client: Any, args: argparse.Namespace) -> int:
    """Wait briefly for one telemetry sample of every online robot."""
    done = asyncio.Event()

    def check(_kind: str = "", _payload: Any = None) -> None:
        online = [n for n, r in client.robots.items() if r.online]
        if all(n in client.telemetry for n in online):
            done.set()

    client.add_listener(check)
    check()
    try:
        await asyncio.wait_for(done.wait(), TELEMETRY_WAIT)
    except TimeoutError:
        pass  # a robot that publishes nothing: shown without telemetry
    if args.json:
        _print_json(robots_json(client))
    else:
        print(robots_text(client), flush=True)
    return EXIT_OK


async def _watch(client: Any, args: argparse.Namespace) -> int:
    q: asyncio.Queue[tuple[str, Any]] = asyncio.Queue()
    client.add_listener(lambda event: q.put_nowait((event.kind, event.payload)))
    print(
        f"watching mission '{client.mission.name}' at {', '.join(client.endpoints)} from revision "
        f"{client.revision}; Ctrl-C to stop",
        file=sys.stderr,
        flush=True,
    )
    batches = 0
    while args.count is None or batches < args.count:
        kind, payload = await q.get()
        if kind == "telemetry":
            continue
        line = watch_line(kind, payload, args.json)
        if kind == "events":
            batches += 1
        if line is not None:
            print(line, flush=True)
    return EXIT_OK


def _session_free(m: Any) -> Any:
    """The mission without the server's concurrency bookkeeping (per-skill and
    per-list revisions, report sequence numbers): a file is a plan and a log."""
    tasks = {r: [s.model_copy(update={"rev": 0}) for s in t] for r, t in m.tasks.items()}
    return m.model_copy(
        update={"tasks": tasks, "task_revs": {}, "marker_revs": {}, "report_seqs": {}}
    )


def _save(client: Any, args: argparse.Namespace) -> int:
    from backend.files.diagnostics import FileProblems
    from backend.files.missions import library_path, load_library, save_mission

    m = _session_free(client.mission)
    target = Path(args.file)
    notes: list[str] = []
    try:
        if args.library:
            lib_file = Path(args.library)
            if not lib_file.is_file():
                raise UsageError(f"save --library: no such file {args.library}")
            save_mission(m, target, library_file=lib_file)
        else:
            resolved = library_path(target, m.library)
            try:
                same = resolved.is_file() and load_library(resolved) == client.library
            except FileProblems:
                same = False
            if not same:
                notes.append(
                    f"the library reference '{m.library}' is written as the server has it (relative to the "
                    f"mission file the server loaded); from {target.parent or '.'} it does not lead to the server's "
                    f"library '{client.library.name}'; pass --library PATH to set it"
                )
            save_mission(m, target)
    except OSError as e:
        raise UsageError(f"save: cannot write {args.file}: {e.strerror or e}") from None
    written = m.library
    if args.library:
        written = os.path.relpath(Path(args.library).resolve(), target.resolve().parent)
    if args.json:
        _print_json(
            {
                "ok": True,
                "op": "save",
                "revision": m.revision,
                "value": {"file": str(target), "library": written},
                "notes": notes,
                "duplicate": False,
            }
        )
    else:
        print(
            f"saved mission '{m.name}' at revision {m.revision} to {target} (library: {written})",
            flush=True,
        )
        for n in notes:
            print(f"note: {n}", flush=True)
    return EXIT_OK


async def _operation(client: Any, args: argparse.Namespace) -> int:
    notes: list[str] = []
    op = build_op(args, client.library, client.mission)
    if args.op == "load":
        file_lib = args.loaded[1]
        if file_lib != client.library:
            notes.append(
                f"{args.file} names library '{file_lib.name}', which differs from the server's "
                f"'{client.library.name}'; the server checks the mission against its own library"
            )
    before = client.revision
    request_id = args.request_id or f"ctl-{os.getpid()}-{uuid.uuid4().hex[:12]}"
    reply = await client.submit(op, expected_revision=args.expect_revision, request_id=request_id)
    notes += list(reply.notes)
    mission = client.mission
    if args.json:
        _print_json(
            {
                "ok": True,
                "op": op.op,
                "revision": reply.revision,
                "value": reply.value,
                "notes": notes,
                "duplicate": reply.duplicate,
            }
        )
    else:
        print(describe(op, reply, before, mission), flush=True)
        for n in notes:
            print(f"note: {n}", flush=True)
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """`python -m backend.cli.ctl.session OP ...` is `missionctl ctl OP ...`."""
    args = parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        return run(args)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
