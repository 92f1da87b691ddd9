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
import bisect
import functools
import importlib.metadata
import json
import statistics
import sys
import tempfile
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "bench"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from bench_transport import TUTORIAL, Server, ms, pct, raw_ping  # noqa: E402
from report import machine, write_section  # noqa: E402

import backend.client.client as client_mod  # noqa: E402
import backend.transport.aio as aio  # noqa: E402
from backend.client.client import MissionClient  # noqa: E402
from backend.core.ops import EditSkill  # noqa: E402
from backend.protocol.messages import Request, dumps  # noqa: E402
from backend.server.server import MissionServer  # noqa: E402
from backend.transport import free_port, loopback_endpoint  # noqa: E402

SECTION = "Server and transport: where an operation's time goes"

MARKS: list[tuple[str, float]] = []
TRACING = False

# stage -> what happened just before it (the time is since the previous stage)
STAGES = {
    "c_query": "client: submit() built and serialised the Request, session.get starts",
    "s_query": "server: the op queryable's callback runs (Zenoh, then its Python thread)",
    "s_handler": "server: the event loop runs the handler (hop from the Zenoh thread)",
    "s_journal": "server: Request parsed, rules checked, events made (Engine.submit)",
    "s_journal_end": "server: journal append (SQLite, one transaction), before the mission changes",
    "s_reply": "server: events applied to the mission, EventBatch queued for after the reply, "
    "OpReply serialised",
    "s_replied": "server: query.reply and query finalised",
    "s_publish": "server: the next loop callback starts sending the queued EventBatch",
    "s_published": "server: publisher.put returned (it sends at once, then waits to take the GIL "
    "back)",
    "c_events": "client: the EventBatch reaches the subscriber callback and is parsed",
    "c_applied": "client: the batch is applied to the mirror on the event loop",
    "c_reply": "client: the reply reaches the query callback (Zenoh thread)",
    "c_posted": "client: the reply is recorded and handed to the event loop (the query's end "
    "comes later, unawaited)",
    "c_resumed": "client: the awaiting coroutine resumes on the event loop",
    "c_end": "client: OpReply parsed, submit() returns",
}


def mark(tag: str) -> None:
    if TRACING:
        MARKS.append((tag, time.perf_counter()))


def wrap_client() -> None:
    start_get = aio._start_get
    on_reply = aio._Collector.on_reply
    query = client_mod.query
    on_events = MissionClient._on_events
    got_batches = MissionClient._got_batches

    def traced_start_get(*args, **kwargs):
        mark("c_query")
        return start_get(*args, **kwargs)

    def traced_on_reply(self, reply):
        mark("c_reply")
        try:
            return on_reply(self, reply)
        finally:
            mark("c_posted")

    @functools.wraps(query)
    async def traced_query(*args, **kwargs):
        try:
            return await query(*args, **kwargs)
        finally:
            mark("c_resumed")

    def traced_on_events(self, msg):
        mark("c_events")
        return on_events(self, msg)

    def traced_got_batches(self, batches):
        mark("c_applied")
        return got_batches(self, batches)

    aio._start_get = traced_start_get
    aio._Collector.on_reply = traced_on_reply
    client_mod.query = traced_query
    MissionClient._on_events = traced_on_events
    MissionClient._got_batches = traced_got_batches


def stage_table(
    marks: list[tuple[str, float]],
) -> tuple[list[tuple[str, float, float, float, float]], list[float]]:
    """Per stage of the operations in the merged marks, in order: (name, step
    median, step p99, step median over the slowest 2 % of operations,
    since-start median); and the operations' whole times."""
    complete = [w for w in operation_windows(marks) if "c_end" in w]
    order = sorted(
        (s for s in STAGES if any(s in w for w in complete)),
        key=lambda s: statistics.median(w[s] - w["c_start"] for w in complete if s in w),
    )
    slow = sorted(complete, key=lambda w: w["c_end"] - w["c_start"])[-max(1, len(complete) // 50) :]

    def steps_of(ws: list[dict[str, float]], i: int) -> list[float]:
        out = []
        for w in ws:
            if order[i] in w:
                # client and server stages overlap (the event batch and the reply
                # travel side by side): measure from the latest earlier stage
                t = w[order[i]]
                prev = max((w[p] for p in order[:i] if p in w and w[p] <= t), default=w["c_start"])
                out.append(t - prev)
        return out or [0.0]

    rows = []
    for i, stage in enumerate(order):
        steps = steps_of(complete, i)
        since = [w[stage] - w["c_start"] for w in complete if stage in w]
        rows.append(
            (
                stage,
                statistics.median(steps),
                pct(steps, 0.99),
                statistics.median(steps_of(slow, i)),
                statistics.median(since),
            )
        )
    totals = [w["c_end"] - w["c_start"] for w in complete]
    return rows, totals


def operation_windows(marks: list[tuple[str, float]]) -> list[dict[str, float]]:
    """Split the merged marks into one window per operation (from its c_start)."""
    windows: list[dict[str, float]] = []
    batch_marks: dict[str, list[float]] = {"c_events": [], "c_applied": []}
    for tag, t in sorted(marks, key=lambda m: m[1]):
        if tag in batch_marks:
            batch_marks[tag].append(t)
        elif tag == "c_start":
            windows.append({"c_start": t})
        elif windows and tag not in windows[-1]:
            windows[-1][tag] = t
    match_batches(windows, batch_marks)
    return windows


def match_batches(windows: list[dict[str, float]], batch_marks: dict[str, list[float]]) -> None:
    """Add to each operation's window when its EventBatch reached the client."""
    # an operation's own EventBatch is the first to reach the client after its
    # journal append; it often comes after submit() returned, during the next
    # operation (the reply usually arrives first), so it is matched by time
    for w, nxt in zip(windows, [*windows[1:], {}], strict=True):
        if "s_journal_end" not in w:
            continue
        i = bisect.bisect_left(batch_marks["c_events"], w["s_journal_end"])
        if i == len(batch_marks["c_events"]) or batch_marks["c_events"][i] >= nxt.get(
            "s_journal_end", float("inf")
        ):
            continue
        w["c_events"] = batch_marks["c_events"][i]
        j = bisect.bisect_left(batch_marks["c_applied"], w["c_events"])
        if j < len(batch_marks["c_applied"]):
            w["c_applied"] = batch_marks["c_applied"][j]


async def traced_round_trips(n: int) -> tuple[list[float], list[tuple[str, float]]]:
    """Raw PING round trips and the marks of `n` traced operations."""
    global TRACING
    wrap_client()
    with tempfile.TemporaryDirectory(prefix="trace-rtt-") as d:
        tmp = Path(d)
        trace_file = tmp / "server-trace.json"
        server = Server(
            tmp,
            "traced",
            TUTORIAL,
            launcher=[sys.executable, str(ROOT / "bench" / "traced_server.py"), str(trace_file)],
        )
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
    return raw, MARKS + server_marks


async def handler_alone(n: int) -> list[float]:
    """`MissionServer._handle_op` for the same operation with the server in
    this process and nothing else running: the Python work an operation needs."""
    with tempfile.TemporaryDirectory(prefix="trace-rtt-") as d:
        srv = MissionServer(
            db=Path(d) / "alone.db", mission_file=TUTORIAL, listen=[loopback_endpoint(free_port())]
        )
        await srv.start()
        try:

            def request(i: int) -> bytes:
                return dumps(
                    Request(
                        client="alone",
                        request_id=f"r{i}",
                        op=EditSkill(id="lru1-1", label=f"alone {i}"),
                    )
                )

            for i in range(300):
                srv._handle_op(request(i))  # answered at once: it needs no robot
                await asyncio.sleep(0)
            out = []
            for i in range(300, 300 + n):
                payload = request(i)
                t = time.perf_counter()
                srv._handle_op(payload)
                await asyncio.sleep(0)  # the publication, queued for after the reply
                out.append(time.perf_counter() - t)
            return out
        finally:
            await srv.stop()


def loop_wakeups(n: int) -> list[float]:
    """Another thread hands a result to an idle asyncio loop
    (`call_soon_threadsafe`) until the awaiting coroutine runs: the least
    each side of an asyncio client or server adds to a Zenoh callback."""
    out: list[float] = []

    async def measure() -> None:
        loop = asyncio.get_running_loop()
        for _ in range(n):
            fut = loop.create_future()
            sent = [0.0]

            def fire(fut: asyncio.Future = fut, sent: list[float] = sent) -> None:
                sent[0] = time.perf_counter()
                loop.call_soon_threadsafe(fut.set_result, None)

            timer = threading.Timer(0.0002, fire)
            timer.start()
            await fut
            out.append(time.perf_counter() - sent[0])
            timer.join()

    asyncio.run(measure())
    return out


def report(
    raw: list[float], marks: list[tuple[str, float]], alone: list[float], wake: list[float]
) -> str:
    rows, totals = stage_table(marks)
    raw_med, alone_med, wake_med = (
        statistics.median(raw),
        statistics.median(alone),
        statistics.median(wake),
    )
    slow = sorted(totals)[-max(1, len(totals) // 50) :]
    lines = [
        f"{len(totals)} `EditSkill` operations, traced; raw query to PING in the same run: median "
        f"{ms(raw_med):.3f} ms.",
        "",
        "| Stage (time since the previous one) | median | p99 | slowest 2 % of operations, median "
        "| since submit() started, median |",
        "|---|---|---|---|---|",
    ]
    for stage, med, p99, tail, since in rows:
        lines.append(
            f"| {STAGES[stage]} | {med * 1e6:.0f} µs | {p99 * 1e6:.0f} µs | {tail * 1e6:.0f} µs | "
            f"{since * 1e6:.0f} µs |"
        )
    lines.append(
        f"| **whole operation (traced)** | **{ms(statistics.median(totals)):.3f} ms** | "
        f"**{ms(pct(totals, 0.99)):.3f} ms** | **{ms(statistics.median(slow)):.3f} ms** | |"
    )
    floor = raw_med + alone_med + wake_med
    lines += [
        "",
        "Rows are in the order of their median time since submit() started, each measured from "
        "the latest earlier stage of the same operation; an operation's EventBatch is the first "
        "to reach the client after its journal append. The two processes' stages overlap: `put` "
        "sends the batch at once, then waits to take the GIL back from the server's Zenoh "
        "threads. The batch leaves right behind the reply but usually reaches the client's Python "
        "after submit() has returned: its subscriber thread waits for the GIL while the client "
        "takes in the reply, so the mirror shows an operation a little after submit() returns "
        "(`wait_for` waits for it).",
        "",
        "Floor, measured in the same run: the handler alone in-process (rules, journal, "
        f"publication; no client, nothing else running) {alone_med * 1e6:.0f} µs; one hand-over "
        f"from another thread to an idle asyncio loop {wake_med * 1e6:.0f} µs. An asyncio client "
        "(the issue asks for one) needs at least one such hand-over, the journal must be written "
        f"before the reply: raw query + handler + one hand-over = {ms(floor):.3f} ms = "
        f"{floor / raw_med:.2f}x the raw query, against the 1.5x target ({ms(1.5 * raw_med):.3f} "
        "ms), before any contention between the two processes' threads for 2 cores.",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-n", type=int, default=2500, help="traced operations (default 2500)")
    ap.add_argument(
        "--write", metavar="FILE", help=f"write/update the '## {SECTION}' section of FILE"
    )
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    raw, marks = asyncio.run(traced_round_trips(args.n))
    alone = asyncio.run(handler_alone(args.n))
    wake = loop_wakeups(args.n)
    body = report(raw, marks, alone, wake)
    print(body)
    if args.write:
        date = datetime.now(UTC).strftime("%Y-%m-%d")
        text = (
            f"## {SECTION}\n\n"
            "Timestamps at each stage of `MissionClient.submit(EditSkill(label=...))`, one at a "
            "time, in both processes (`bench/traced_server.py` is the real server with wrappers "
            "that record the time; production code carries no tracing). Clocks: CLOCK_MONOTONIC, "
            "shared by the processes.\n\n"
            "Reproduce: `.venv/bin/python bench/trace_round_trip.py --write "
            "docs/performance.md`\n\n"
            f"Machine: {machine('eclipse-zenoh ' + importlib.metadata.version('eclipse-zenoh'))}. "
            f"Date: {date}. Whole run: {time.perf_counter() - t0:.0f} s.\n\n"
            f"{body}\n"
        )
        write_section(Path(args.write), f"## {SECTION}", text)
        print(f"\nwrote the '## {SECTION}' section of {args.write}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
