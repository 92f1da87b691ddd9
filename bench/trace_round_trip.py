"""Where an operation's round trip goes: timestamps at each stage, both processes.

    .venv/bin/python bench/trace_round_trip.py [-n 2500]

The mission server runs as `bench/traced_server.py` (the real server with
timestamps around the functions an operation passes through); this process
wraps the client library's the same way. Clocks: `time.perf_counter` is
CLOCK_MONOTONIC, shared by the processes of one machine. `MissionClient.submit(
EditSkill(label=...))` on the tutorial mission, one at a time, after a
warm-up; for each stage the time since the previous one (median, p99) and
since the submit started (median). The raw query to the server's PING
queryable, measured in the same run, is the baseline. The wrapping adds a
few microseconds per stage; the total is printed next to the untraced
figure of `bench_transport.py`.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "bench"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from bench_transport import TUTORIAL, Server, ms, pct, raw_ping  # noqa: E402

import backend.client as client_mod  # noqa: E402
import backend.transport.aio as aio  # noqa: E402
from backend.client import MissionClient  # noqa: E402
from backend.ops import EditSkill  # noqa: E402

MARKS: list[tuple[str, float]] = []
TRACING = False

# stage -> what happened just before it (the time is since the previous stage)
STAGES = {
    "c_query": "client: submit() built and serialised the Request, session.get starts",
    "s_query": "server: the op queryable's callback runs (Zenoh, then its Python thread)",
    "s_handler": "server: the event loop runs the handler (hop from the Zenoh thread)",
    "s_journal": "server: Request parsed, rules applied (Engine.submit)",
    "s_journal_end": "server: journal append (SQLite, one transaction)",
    "s_reply": "server: EventBatch published, OpReply serialised",
    "s_replied": "server: query.reply and query finalised",
    "c_events": "client: the EventBatch reaches the subscriber callback and is parsed",
    "c_applied": "client: the batch is applied to the mirror on the event loop",
    "c_reply": "client: the reply reaches the query callback (Zenoh thread)",
    "c_done": "client: Zenoh ends the query (drop callback), posts to the event loop",
    "c_resumed": "client: the awaiting coroutine resumes on the event loop",
    "c_end": "client: OpReply parsed, submit() returns",
}


def mark(tag: str) -> None:
    if TRACING:
        MARKS.append((tag, time.perf_counter()))


def wrap_client() -> None:
    start_get = aio._start_get
    on_reply = aio._Collector.on_reply
    post = aio._post
    query = client_mod.query
    on_events = MissionClient._on_events
    got_batch = MissionClient._got_batch

    def traced_start_get(*args, **kwargs):
        mark("c_query")
        return start_get(*args, **kwargs)

    def traced_on_reply(self, reply):
        mark("c_reply")
        return on_reply(self, reply)

    def traced_post(loop, fn, *args):
        if getattr(fn, "__name__", "") == "finish":
            mark("c_done")
        return post(loop, fn, *args)

    @functools.wraps(query)
    async def traced_query(*args, **kwargs):
        try:
            return await query(*args, **kwargs)
        finally:
            mark("c_resumed")

    def traced_on_events(self, msg):
        mark("c_events")
        return on_events(self, msg)

    def traced_got_batch(self, batch):
        mark("c_applied")
        return got_batch(self, batch)

    aio._start_get = traced_start_get
    aio._Collector.on_reply = traced_on_reply
    aio._post = traced_post
    client_mod.query = traced_query
    MissionClient._on_events = traced_on_events
    MissionClient._got_batch = traced_got_batch


def stage_table(marks: list[tuple[str, float]]) -> tuple[list[tuple[str, float, float, float, float]], list[float]]:
    """Split the merged marks into one window per operation (from its c_start);
    per stage, in order: (name, step median, step p99, step median over the
    slowest 2 % of operations, since-start median)."""
    windows: list[dict[str, float]] = []
    for tag, t in sorted(marks, key=lambda m: m[1]):
        if tag == "c_start":
            windows.append({"c_start": t})
        elif windows and tag not in windows[-1]:
            windows[-1][tag] = t
    # an EventBatch that came after submit() returned lands in the next window: drop it there
    for w in windows:
        for late in ("c_events", "c_applied"):
            if late in w and w[late] < w.get("s_journal_end", float("inf")):
                del w[late]
    complete = [w for w in windows if "c_end" in w]
    order = sorted((s for s in STAGES if any(s in w for w in complete)),
                   key=lambda s: statistics.median(w[s] - w["c_start"] for w in complete if s in w))
    slow = sorted(complete, key=lambda w: w["c_end"] - w["c_start"])[-max(1, len(complete) // 50):]

    def steps_of(ws: list[dict[str, float]], i: int) -> list[float]:
        out = []
        for w in ws:
            if order[i] in w:
                prev = next((w[p] for p in reversed(order[:i]) if p in w), w["c_start"])
                out.append(w[order[i]] - prev)
        return out or [0.0]

    rows = []
    for i, stage in enumerate(order):
        steps = steps_of(complete, i)
        since = [w[stage] - w["c_start"] for w in complete if stage in w]
        rows.append((stage, statistics.median(steps), pct(steps, 0.99), statistics.median(steps_of(slow, i)), statistics.median(since)))
    totals = [w["c_end"] - w["c_start"] for w in complete]
    return rows, totals


async def run(n: int) -> None:
    global TRACING
    wrap_client()
    with tempfile.TemporaryDirectory(prefix="trace-rtt-") as d:
        tmp = Path(d)
        trace_file = tmp / "server-trace.json"
        server = Server(tmp, "traced", TUTORIAL, launcher=[sys.executable, str(ROOT / "bench" / "traced_server.py"), str(trace_file)])
        try:
            server.wait_ready(60)
            client = MissionClient(server.endpoint, client_id="trace")
            await client.connect()
            try:
                for i in range(300):  # warm-up
                    await client.submit(EditSkill(id="lru1-1", label=f"warm {i}"))
                    raw_ping(client.session)
                raw = []
                for _ in range(n):
                    t = time.perf_counter()
                    raw_ping(client.session)
                    raw.append(time.perf_counter() - t)
                TRACING = True
                for i in range(n):
                    mark("c_start")
                    await client.submit(EditSkill(id="lru1-1", label=f"trace {i}"))
                    mark("c_end")
                TRACING = False
            finally:
                await client.close()
        finally:
            server.stop()
        server_marks = [tuple(m) for m in json.loads(trace_file.read_text())]
    rows, totals = stage_table(MARKS + server_marks)
    print(f"{len(totals)} operations; raw query to PING: median {ms(statistics.median(raw)):.3f} ms\n")
    print("| Stage (time since the previous one) | median | p99 | slowest 2 % of operations, median | since submit() started, median |")
    print("|---|---|---|---|---|")
    for stage, med, p99, tail, since in rows:
        print(f"| {STAGES[stage]} | {med * 1e6:.0f} µs | {p99 * 1e6:.0f} µs | {tail * 1e6:.0f} µs | {since * 1e6:.0f} µs |")
    slow = sorted(totals)[-max(1, len(totals) // 50):]
    print(f"| **whole operation (traced)** | **{ms(statistics.median(totals)):.3f} ms** | **{ms(pct(totals, 0.99)):.3f} ms** "
          f"| **{ms(statistics.median(slow)):.3f} ms** | |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-n", type=int, default=2500, help="traced operations (default 2500)")
    args = ap.parse_args(argv)
    asyncio.run(run(args.n))
    return 0


if __name__ == "__main__":
    sys.exit(main())
