"""`ctl history`: who did what, from the server's journal.

    history [--robot R] [--user U] [--since T] [--limit N]

One line per change, oldest first: when the server journaled it (local
time; `sim h:mm:ss` for a change during a running simulator's run), its
revision, the operation and who did it, and what it changed (as `ctl watch`
says it). --json: {"ok": true, "entries": [...], "more"}
with each entry's `batch` (its events) as the protocol carries it.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from backend.cli.ctl.clock import WALL, CtlClock, ask
from backend.cli.ctl.render import watch_line
from backend.exit_codes import EXIT_OK
from backend.protocol.messages import HistoryReply, HistoryRequest


def request(args: argparse.Namespace) -> HistoryRequest:
    return HistoryRequest(
        robot=args.robot, user=args.history_user, since=args.since, limit=args.limit
    )


def text(reply: HistoryReply, clock: CtlClock = WALL) -> str:
    lines = []
    for e in reply.entries:  # in sim time if it was journaled during the sim's run
        when = clock.sim_stamp(e.at) or e.at.astimezone().strftime("%Y-%m-%d %H:%M:%S")
        lines.append(f"{when} {watch_line('events', e.batch, False)}")
    if not reply.entries:
        lines.append("no change matches")
    if reply.more:
        lines.append(
            "… older changes match too: narrow with --since, --robot, --user, or raise --limit"
        )
    return "\n".join(lines)


async def view(client: Any, args: argparse.Namespace) -> int:
    reply = await client.history(request(args), timeout=args.timeout)
    if args.json:
        print(json.dumps({"ok": True, **reply.model_dump(mode="json")}), flush=True)
    else:
        print(text(reply, await ask(client, args.timeout)), flush=True)
    return EXIT_OK
