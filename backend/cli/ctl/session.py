"""ctl's run: connect, do one operation, print the outcome; every error -> an exit code.

One invocation opens one connection (a `MissionClient`, subscribed to
telemetry only for `robots` and `watch`), does one thing and always closes it.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import socket
import sys
import uuid
from collections.abc import Awaitable, Callable, Collection
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from backend.cli.ctl.args import DEFAULT_CONNECT, ROBOT_OPS
from backend.cli.ctl.clock import WALL, CtlClock
from backend.cli.ctl.clock import ask as ask_clock
from backend.cli.ctl.errors import FileInvalid, UsageError
from backend.cli.ctl.history import view as history_view
from backend.cli.ctl.nowcast import nowcasts_json, nowcasts_text
from backend.cli.ctl.plan import check as plan_check
from backend.cli.ctl.plan import timeline as plan_timeline
from backend.cli.ctl.plan import wait_telemetry
from backend.cli.ctl.questions import questions_view
from backend.cli.ctl.render import (
    command_json,
    describe,
    pending_json,
    pending_text,
    robots_json,
    robots_text,
    state_json,
    state_text,
    unicode_ok,
    watch_line,
)
from backend.cli.ctl.suggest import suggest_view
from backend.cli.ctl.team import joining_type
from backend.cli.ctl.verify import wait_stage
from backend.core.credentials import AccountsError
from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK, EXIT_REFUSED, EXIT_UNREACHABLE
from backend.transport.login import login_from_args

_ENDPOINT_RE = re.compile(r"^[a-z][a-z0-9\-]*/\S+$")


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


def _tolerant_output() -> None:
    """Labels may hold what the terminal cannot show: replace, never fail."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="replace")  # type: ignore[union-attr]
        except (AttributeError, ValueError):
            pass


def _quiet_broken_pipe() -> int:
    try:  # the reader went away (`| head`): no complaint at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except OSError:
        pass
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    """`missionctl ctl ...`: returns the exit code; never raises for bad input."""
    _tolerant_output()
    if not getattr(args, "op", None):
        return _usage(args, "give an operation (missionctl ctl --help lists them)")
    try:
        return _run(args)
    except UsageError as e:
        return _usage(args, str(e))
    except FileInvalid as e:
        return _file_invalid(args, e)
    except KeyboardInterrupt:
        return _interrupted(args)
    except BrokenPipeError:
        return _quiet_broken_pipe()
    except Exception as e:  # never a traceback for a person
        if os.environ.get("MISSIONCTL_DEBUG"):
            raise
        return _unexpected(args, e)


def _usage(args: argparse.Namespace, message: str) -> int:
    """The command line is wrong: said as argparse says it, exit 2."""
    return _fail(
        args, "bad_input", message, EXIT_BAD_INPUT, lines=[f"missionctl ctl: error: {message}"]
    )


def _interrupted(args: argparse.Namespace) -> int:
    """Ctrl-C: the way to end `watch`; any other operation was cut short."""
    return EXIT_OK if args.op == "watch" else 130


def _unexpected(args: argparse.Namespace, e: Exception) -> int:
    return _fail(
        args,
        "internal_error",
        f"unexpected error: {type(e).__name__}: {e} (MISSIONCTL_DEBUG=1 shows the traceback)",
        EXIT_REFUSED,
    )


def _file_invalid(args: argparse.Namespace, e: FileInvalid) -> int:
    """A file given on the command line has problems: each on its own line."""
    return _fail(
        args,
        "bad_file",
        str(e),
        EXIT_BAD_INPUT,
        extra={"issues": [str(i) for i in e.issues]},
        lines=[str(i) for i in e.issues],
    )


def _endpoints(args: argparse.Namespace) -> list[str]:
    """--connect (repeated, or comma-separated), each one checked, or UsageError."""
    raw = args.connect or default_endpoints()
    out = [e.strip() for item in raw for e in item.split(",") if e.strip()]
    if not out:
        raise UsageError("--connect: no endpoint given")
    for e in out:
        _check_endpoint(e)
    _check_config(out)
    return out


def _check_endpoint(e: str) -> None:
    if not _ENDPOINT_RE.match(e):
        raise UsageError(f"--connect: {e!r} is not a Zenoh endpoint (e.g. tcp/127.0.0.1:7447)")


def _check_config(endpoints: list[str]) -> None:
    """Endpoints Zenoh's client config refuses."""
    from backend.transport import client_config

    try:
        client_config(endpoints)
    except ValueError as e:
        raise UsageError(f"--connect: {e}") from None


def _check_save_target(args: argparse.Namespace) -> None:
    """`save FILE`: a place it can be written to, checked before connecting."""
    target = Path(args.file)
    if target.is_dir():
        raise UsageError(f"save: {args.file} is a directory")
    parent = target.resolve().parent
    if not parent.is_dir():
        why = "is not a folder" if parent.exists() else "does not exist"
        raise UsageError(f"save: {target.parent} {why}: nothing was written")


def _run(args: argparse.Namespace) -> int:
    from backend.cli.ctl.build import build_op
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
        _check_save_target(args)
    try:
        return asyncio.run(_session(args, endpoints, login))
    except OperationRefused as e:
        return _refused(args, e.reply)
    except MaybeApplied as e:  # the request left: it may have been applied
        return _maybe_applied(args, e)
    except (ServerUnreachable, ProtocolMismatch, OperationTimeout, TransportError) as e:
        return _fail(args, _failure_code(e), str(e), EXIT_UNREACHABLE)


def _refused(args: argparse.Namespace, r: Any) -> int:
    """The server's refusal, with what it names (robot, skill, param) in --json."""
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


def _maybe_applied(args: argparse.Namespace, e: Any) -> int:
    from backend.client.client import OperationTimeout

    retry = f"--request-id {e.request_id}" + (
        f" --client-id {args.client_id}" if args.client_id else ""
    )
    message = (
        f"{e.what}. Once the server answers, look with `missionctl ctl state`, or run the "
        f"same command again with {retry}: it is applied once (the reply says so if it had been)"
    )
    code = "timeout" if isinstance(e, OperationTimeout) else "unreachable"
    return _fail(
        args,
        code,
        message,
        EXIT_UNREACHABLE,
        extra={"request_id": e.request_id, "maybe_applied": True},
    )


def _failure_code(e: Exception) -> str:
    """The --json code of a connection failure (exit 3), most specific first."""
    from backend.client.client import OperationTimeout, ProtocolMismatch, ServerUnreachable

    codes = (
        (ServerUnreachable, "unreachable"),
        (ProtocolMismatch, "protocol_mismatch"),
        (OperationTimeout, "timeout"),
    )
    return next((code for cls, code in codes if isinstance(e, cls)), "transport_error")


async def _session(args: argparse.Namespace, endpoints: list[str], login: Any = None) -> int:
    from backend.client.client import MissionClient

    client = MissionClient(
        endpoints,
        login=login,
        client_id=args.client_id or default_client_id(),
        timeout=args.timeout,
        # watch: to say when a robot's telemetry is unreadable
        telemetry=args.op in ("robots", "watch", "check", "timeline", "sync", "suggest")
        or getattr(args, "nowcast", False),
    )
    async with client:
        return await VIEWS.get(args.op, _operation)(client, args)


def _print_done(args: argparse.Namespace, line: Callable[[], str], **reply: Any) -> int:
    """A success: `line()` and the notes, or with --json {"ok": true, "op",
    "revision", "value", "notes", "duplicate"} (given in that order)."""
    if args.json:
        _print_json({"ok": True, **reply})
    else:
        print(line(), flush=True)
        for n in reply["notes"]:
            print(f"note: {n}", flush=True)
    return EXIT_OK


def _only(args: argparse.Namespace, verb: str, known: Collection[str], robots: Any) -> list[str]:
    """The robots `--robots` names (none: all), each one of `known`, else
    UsageError listing the mission's `robots`."""
    only = list(args.robots or [])
    unknown = [r for r in only if r not in known]
    if unknown:
        names = ", ".join(robots) or "none"
        raise UsageError(f"{verb}: no robot {', '.join(unknown)} in this mission (robots: {names})")
    return only


async def _state(client: Any, args: argparse.Namespace) -> int:
    robots = client.mission.robots
    only = _only(args, "state", {*robots, *client.robots}, robots)
    predicted, clock = await nowcasts_json(client, args, only)
    if args.json:
        _print_json(state_json(client, only or None) | predicted)
    else:
        clock = clock or await ask_clock(client, args.timeout)  # the sim asked once
        text = state_text(client, only or None, unicode=unicode_ok(), clock=clock)
        print(text + nowcasts_text(predicted, clock), flush=True)
    return EXIT_OK


async def _pending(client: Any, args: argparse.Namespace) -> int:
    only = _only(args, "pending", client.mission.robots, client.mission.robots)
    if args.json:
        _print_json(pending_json(client, only or None))
    else:
        print(pending_text(client, only or None, await ask_clock(client, args.timeout)), flush=True)
    return EXIT_OK


async def _robots(client: Any, args: argparse.Namespace) -> int:
    if getattr(args, "robots_op", None) is not None:  # add or retire: an operation
        args.joining_type = joining_type(client, args.name)
        return await _operation(client, args)
    await wait_telemetry(client)
    if args.json:
        _print_json(robots_json(client))
    else:
        print(robots_text(client, await ask_clock(client, args.timeout)), flush=True)
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
        line = await _watch_line(client, args, kind, payload)
        if kind == "events":
            batches += 1
        if line is not None:
            print(line, flush=True)
    return EXIT_OK


async def _watch_line(client: Any, args: argparse.Namespace, kind: str, payload: Any) -> str | None:
    """A robot's line says its stamps in mission time: the clock asked at each
    (a sim may start, pause or change speed while watch runs)."""
    clock = WALL
    if kind == "fleet" and not args.json:
        clock = await ask_clock(client, args.timeout)
    return watch_line(kind, payload, args.json, clock)


async def _save(client: Any, args: argparse.Namespace) -> int:
    from backend.files.missions import save_mission_file

    m = client.mission
    target = Path(args.file)
    library = _library_file(args)
    what = "plan" if args.plan else "state"
    try:
        saved = save_mission_file(m, client.library, target, what, library)
    except OSError as e:
        raise UsageError(f"save: cannot write {args.file}: {e.strerror or e}") from None
    notes = [] if saved.library_file is None else [_library_written(m, target, saved)]
    as_what = "as a plan (every skill idle)" if args.plan else "with its statuses"
    return _print_done(
        args,
        lambda: (
            f"saved mission '{m.name}' at revision {m.revision} {as_what} to {target} "
            f"(library: {saved.library})"
        ),
        op="save",
        revision=m.revision,
        value={
            "file": str(target),
            "library": saved.library,
            "library_written": str(saved.library_file) if saved.library_file else None,
            "as": what,
        },
        notes=notes,
        duplicate=False,
    )


def _library_file(args: argparse.Namespace) -> Path | None:
    """`save --library FILE`: the file, which must exist."""
    if not args.library:
        return None
    library = Path(args.library)
    if not library.is_file():
        raise UsageError(f"save --library: no such file {args.library}")
    return library


def _library_written(m: Any, target: Path, saved: Any) -> str:
    return (
        f"the server's library reference '{m.library}' does not lead to its library from "
        f"{target.parent or '.'}: the library was written beside it, {saved.library_file}"
    )


async def _operation(client: Any, args: argparse.Namespace) -> int:
    from backend.cli.ctl.build import build_op

    op = build_op(args, client.library, client.mission)
    if args.op == "sync":  # with the plan's forecast, as a console sends it (a review's plan)
        from backend.cli.ctl.plan import sync_forecast

        op = op.model_copy(update={"forecast": await sync_forecast(client, op, args.timeout)})
    notes = _library_differs(client, args) if args.op == "load" else []
    before = client.revision
    request_id = args.request_id or f"ctl-{os.getpid()}-{uuid.uuid4().hex[:12]}"
    reply = await client.submit(op, expected_revision=args.expect_revision, request_id=request_id)
    notes += list(reply.notes)
    mission = client.mission
    done = {
        "op": op.op,
        "revision": reply.revision,
        "value": reply.value,
        "notes": notes,
        "duplicate": reply.duplicate,
    }
    clock = await _expiry_clock(client, args, reply.value)
    wait = getattr(args, "wait", None) if args.op in ROBOT_OPS else None
    if wait is None:
        return _print_done(args, lambda: describe(op, reply, before, mission, clock), **done)
    if not args.json:
        _print_done(args, lambda: describe(op, reply, before, mission, clock), **done)
    return await _wait_answers(client, args, _command_ids(reply.value), wait, done)


async def _expiry_clock(client: Any, args: argparse.Namespace, value: dict[str, Any]) -> CtlClock:
    """The clock a queued command's `(expires ...)` is said on (the text only)."""
    if args.json or not value.get("expires"):
        return WALL
    return await ask_clock(client, args.timeout)


def _library_differs(client: Any, args: argparse.Namespace) -> list[str]:
    """`load`: a note when the file's library is not the server's."""
    file_lib = args.loaded[1]
    if file_lib == client.library:
        return []
    return [
        f"{args.file} names library '{file_lib.name}', which differs from the server's "
        f"'{client.library.name}'; the server checks the mission against its own library"
    ]


def _command_ids(value: dict[str, Any]) -> list[int]:
    if "commands" in value:
        return [int(c) for c in value["commands"].values()]
    return [int(value["command"])] if "command" in value else []


async def _wait_answers(
    client: Any, args: argparse.Namespace, ids: list[int], wait: float, done: dict[str, Any]
) -> int:
    """--wait: until each command is settled; exit 0 if every one was applied,
    1 if one was refused, expired or cancelled, 3 if one is still pending."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait
    settled = []
    try:
        for cid in ids:
            settled.append(await client.wait_command(cid, max(0.0, deadline - loop.time())))
    except TimeoutError:
        return _no_answer(client, args, ids, wait, done)
    clock = WALL if args.json else await ask_clock(client, args.timeout)
    return _answers(args, settled, done, clock)


def _answers(
    args: argparse.Namespace, settled: list[Any], done: dict[str, Any], clock: CtlClock
) -> int:
    """Every command settled: exit 0 if each was applied, else 1."""
    now = datetime.now(UTC)
    bad = [c for c in settled if c.state.value != "acked"]
    if args.json:
        _print_json({"ok": not bad, **done, "answers": [command_json(c, now) for c in settled]})
    else:
        _print_answers(settled, clock)
    return EXIT_REFUSED if bad else EXIT_OK


def _print_answers(settled: list[Any], clock: CtlClock) -> None:
    """A line per command: on stdout if it was applied, else on stderr."""
    for c in settled:
        stream = sys.stderr if c.state.value != "acked" else sys.stdout
        print(_answer_line(c, clock), file=stream, flush=True)


def _no_answer(
    client: Any, args: argparse.Namespace, ids: list[int], wait: float, done: dict[str, Any]
) -> int:
    """--wait ran out: the commands still pending, exit 3."""
    pending = [c for c in (client.mission.command(i) for i in ids) if c and c.pending]
    names = ", ".join(f"command {c.id} ({c.state.value})" for c in pending)
    message = (
        f"no answer from the robot within {wait:g} s: {names} stays pending "
        f"(`missionctl ctl pending`, `missionctl ctl cancel N`)"
    )
    now = datetime.now(UTC)
    return _fail(
        args,
        "pending",
        message,
        EXIT_UNREACHABLE,
        extra={"answers": [command_json(c, now) for c in pending], **done},
    )


def _answer_line(c: Any, clock: CtlClock = WALL) -> str:
    took = ""
    if c.settled is not None:
        took = f" after {clock.fine((c.settled - c.created).total_seconds())}"
    did = f": {', '.join(c.done)}" if c.done else ""
    kept = f" (kept, already started: {', '.join(c.kept)})" if c.kept else ""
    why = f": {c.reason}" if c.reason and c.state.value != "acked" else ""
    verb = {"acked": "applied by", "refused": "refused by"}.get(c.state.value, f"{c.state.value},")
    return f"command {c.id} {verb} {c.robot}{took}{did}{kept}{why}"


# operations that read (or write a file) instead of submitting an operation;
# every other one is built, submitted and described (_operation)
VIEWS: dict[str, Callable[[Any, argparse.Namespace], Awaitable[int]]] = {
    "state": _state,
    "robots": _robots,
    "pending": _pending,
    "watch": _watch,
    "save": _save,
    "check": plan_check,
    "timeline": plan_timeline,
    "history": history_view,
    "wait": wait_stage,
    "suggest": suggest_view,
    "questions": questions_view,
}
