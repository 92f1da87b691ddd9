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
from pathlib import Path
from typing import Any

from backend.cli.ctl.args import DEFAULT_CONNECT
from backend.cli.ctl.errors import FileInvalid, UsageError
from backend.cli.ctl.render import (
    describe,
    robots_json,
    robots_text,
    state_json,
    state_text,
    unicode_ok,
    watch_line,
)
from backend.core.credentials import AccountsError
from backend.exit_codes import EXIT_BAD_INPUT, EXIT_OK, EXIT_REFUSED, EXIT_UNREACHABLE
from backend.transport.login import login_from_args

TELEMETRY_WAIT = 1.0  # `robots`: how long to wait for one sample per online robot

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
        print(state_text(client, only or None, unicode=unicode_ok()), flush=True)
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
    client.add_listener(lambda kind, payload: q.put_nowait((kind, payload)))
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
    from backend.cli.ctl.build import build_op

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
