"""ctl and a command's verification stages: `pending` shows them, `wait` waits for one.

The server verifies each command under way (backend/core/verification.py) and
publishes its stages with the robot (`RobotInfo.verification`): queued, sent,
received (the robot applied it), started (the first of its skills running),
completed (all of them ended), each with the time its evidence is due.

`ctl wait COMMAND --until STAGE [--grace D]` exits 0 once the stage is reached,
1 when it never will be (refused, expired, cancelled, a skill failed, taken
back), 4 when it is overdue (past its due, the server's tolerance and
`--grace`) or, with no due to judge by, after `--max-wait`.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from datetime import UTC, datetime
from typing import Any

from backend.cli.ctl.clock import CtlClock, ask
from backend.cli.ctl.errors import UsageError
from backend.core.verification import Path, Stage, Verification, verify
from backend.exit_codes import EXIT_OK, EXIT_OVERDUE, EXIT_REFUSED


def _published(client: Any) -> list[Verification]:
    """Every command under way, as the server published them with the robots."""
    return [v for info in client.robots.values() for v in getattr(info, "verification", [])]


def verification_of(client: Any, command: int) -> Verification | None:
    """The server's latest word on a command's stages (None: not under way)."""
    return next((v for v in _published(client) if v.command == command), None)


def executing(client: Any) -> list[Any]:
    """Commands the robots applied whose skills have not all ended (the server's list)."""
    cmds = (client.mission.command(v.command) for v in _published(client))
    return [c for c in cmds if c is not None and not c.pending]


def stages_json(client: Any, c: Any) -> list[dict[str, Any]] | None:
    v = verification_of(client, c.id)
    return None if v is None else [s.model_dump(mode="json") for s in v.stages]


def stage_text(client: Any, c: Any, now: datetime, clock: Any) -> str:
    """`received due 12:00:20 (in 12 s)`, `started OVERDUE since 12:00:20` ('' if unknown);
    in mission time (`clock`: a CtlClock)."""
    v = verification_of(client, c.id)
    stage = v.current if v is not None else None
    if stage is None:
        return ""
    if stage.due is None:
        return f"{stage.name}: no due"
    if stage.state == "overdue":
        return f"{stage.name} OVERDUE, due {clock.stamp(stage.due)}"
    left = max(0.0, (stage.due - now).total_seconds())
    return f"{stage.name} due {clock.stamp(stage.due)} (in {clock.duration(left)})"


def _outcome(v: Verification, until: str, grace_s: float, now: datetime) -> int | None:
    """The exit code once the wait is over (None: wait on)."""
    stage: Stage = v.stage(until)  # type: ignore[arg-type]
    if stage.state == "ok":
        return EXIT_OK
    if v.failed:
        return EXIT_REFUSED
    return EXIT_OVERDUE if stage.late(now, grace_s) else None


async def wait_stage(client: Any, args: argparse.Namespace) -> int:
    """`ctl wait COMMAND --until STAGE [--grace D] [--max-wait S]`."""
    if client.mission.command(args.command) is None:
        raise UsageError(f"wait: no command {args.command} (settled long ago, or never given)")
    changed = asyncio.Event()

    def heard(_event: Any = None) -> None:
        changed.set()

    clock = await ask(client, args.timeout)  # its messages in mission time
    client.add_listener(heard)
    try:
        return await _wait(client, args, changed, clock)
    finally:
        client.remove_listener(heard)


async def _wait(
    client: Any, args: argparse.Namespace, changed: asyncio.Event, clock: CtlClock
) -> int:
    """Look at the command's stages at every news, and when a due passes."""
    loop = asyncio.get_running_loop()
    give_up = loop.time() + args.max_wait
    while True:
        now = datetime.now(UTC)
        v = _current(client, args.command, args.until)
        code = None if v is None else _outcome(v, args.until, args.grace, now)
        left = give_up - loop.time()
        if code is None and left <= 0:
            code = EXIT_OVERDUE
        if code is not None:
            return _report(args, v, args.until, code, now, clock)
        changed.clear()
        try:  # a stage's due passes with no news: look again then
            await asyncio.wait_for(changed.wait(), min(left, _next_due(v, args.grace, now)))
        except TimeoutError:
            pass


def _current(client: Any, cid: int, until: str) -> Verification | None:
    """The server's stages, or (settled, no longer under way) the command's own."""
    c = client.mission.command(cid)
    v = verification_of(client, cid)
    if v is None and c is not None:
        v = verify(c, client.mission, Path(), {}, datetime.now(UTC))
    if v is not None and v.stage(until).state == "none":  # type: ignore[arg-type]
        raise UsageError(
            f"wait: command {cid} ({v.op}) executes no skill: it has no {until} stage "
            "(--until received)"
        )
    return v


def _next_due(v: Verification | None, grace_s: float, now: datetime) -> float:
    """Seconds until the next stage falls overdue (1 s at least, 60 s at most)."""
    if v is None:
        return 1.0
    ahead = [_until_late(s, grace_s, now) for s in v.stages if s.state == "waiting"]
    return min(60.0, max(0.2, min(filter(None, ahead), default=60.0)))


def _until_late(s: Stage, grace_s: float, now: datetime) -> float | None:
    if s.due is None:
        return None
    return (s.due - now).total_seconds() + s.tolerance_s + grace_s


def _report(
    args: argparse.Namespace,
    v: Verification | None,
    until: str,
    code: int,
    now: datetime,
    clock: CtlClock,
) -> int:
    line = f"command {args.command}: {_result(args, v, until, code, now, clock)}"
    if not args.json:
        print(line, file=sys.stdout if code == EXIT_OK else sys.stderr, flush=True)
        return code
    import json

    out = {
        "ok": code == EXIT_OK,
        "command": args.command,
        "until": until,
        "outcome": {EXIT_OK: "reached", EXIT_REFUSED: "failed"}.get(code, "overdue"),
        "message": line,
        "stages": [s.model_dump(mode="json") for s in v.stages] if v else None,
    }
    print(json.dumps(out), flush=True)
    return code


def _result(
    args: argparse.Namespace,
    v: Verification | None,
    until: str,
    code: int,
    now: datetime,
    clock: CtlClock,
) -> str:
    """'received at 12:00:20', 'received OVERDUE: due 12:00:20, 14 s late', ..."""
    stage = v.stage(until) if v is not None else None  # type: ignore[arg-type]
    if code == EXIT_OK and stage is not None:
        return f"{until} at {clock.stamp(stage.at) or '?'}"
    if code == EXIT_REFUSED:
        return f"{until} never will be ({_failed(v)})"
    if stage is not None and stage.due is not None:
        late = clock.duration((now - stage.due).total_seconds())
        return f"{until} OVERDUE: due {clock.stamp(stage.due)}, {late} late"
    return f"not {until} within {args.max_wait:g} s (no due known)"


def _failed(v: Verification | None) -> str:
    if v is None:
        return "unknown"
    bad = next((s for s in v.stages if s.state == "failed"), None)
    return f"{bad.name} failed" if bad is not None else "failed"
