"""`missionctl server` with timestamps around the stages of an operation (bench only).

    python bench/traced_server.py TRACE_FILE server --mission ... --listen ... --db ...

Wraps, in this process only, the functions an operation passes through and
records `time.perf_counter()` (CLOCK_MONOTONIC, shared by the processes of a
machine) at each; the list is written to TRACE_FILE as JSON at exit. Used by
`trace_round_trip.py`; production code carries no tracing.
"""

from __future__ import annotations

import asyncio
import atexit
import functools
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import backend.transport.aio as aio  # noqa: E402
from backend.cli.main import main  # noqa: E402
from backend.server.journal import Journal  # noqa: E402
from backend.server.server import MissionServer  # noqa: E402

MARKS: list[tuple[str, float]] = []


def mark(tag: str) -> None:
    MARKS.append((tag, time.perf_counter()))


def around(owner: object, name: str, before: str, after: str | None = None) -> None:
    fn = getattr(owner, name)
    if asyncio.iscoroutinefunction(fn):

        @functools.wraps(fn)
        async def traced_async(*args, **kwargs):
            mark(before)
            try:
                return await fn(*args, **kwargs)
            finally:
                if after:
                    mark(after)

        setattr(owner, name, traced_async)
        return

    @functools.wraps(fn)
    def traced(*args, **kwargs):
        mark(before)
        try:
            return fn(*args, **kwargs)
        finally:
            if after:
                mark(after)

    setattr(owner, name, traced)


# the queryable's Zenoh-thread callback hands the operation to the event loop here
around(aio, "hand_over", "s_query")
around(MissionServer, "_handle_op", "s_handler", "s_handler_end")
around(Journal, "append_many", "s_journal", "s_journal_end")
around(aio, "_respond", "s_reply", "s_replied")
around(MissionServer, "_flush", "s_publish", "s_published")


def _dump(path: str) -> None:
    Path(path).write_text(json.dumps(MARKS))


if __name__ == "__main__":
    atexit.register(_dump, sys.argv[1])
    sys.exit(main(sys.argv[2:]))
