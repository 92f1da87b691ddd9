"""Benchmark of the pipelined uplink (issue 28), against a baseline measured
in the same run.

    .venv/bin/python bench/bench_uplink.py                 # print a Markdown table
    .venv/bin/python bench/bench_uplink.py --write docs/performance.md

The delay is in the network: the robot connects to the mission server
through a TCP proxy (bench/delay_proxy.py) that delays every byte by D
seconds each way, so a command's receipt comes back 2·D after it left, as
on a real link (the SDK's own `agent.link.delay_s` stays 0). A mission
server, the robot (the SDK's agent, trivial handlers) and an operator
client (connected to the server directly) run in one process per D; Zenoh's
handshake and lease timeouts are set long enough for the delay.

In rounds, the operator issues two syncs back to back, the first one right
after it saw the previous round's answers (a warm-up round is not counted).
Figure: command issued (just before the operator's call) -> its first
transmission arrived at the robot (the agent's uplink queryable), minus D:
how long the command waited on the ground. Median and p90 per kind, at
D = 0.5, 2 and 6 s; target: median <= 50 ms, p90 <= 200 ms.

Baseline: the code before issue 28 (commit BASELINE: one transmission at a
time per robot, a fixed 5 s receipt timeout), taken from git into a
temporary folder and measured by this same script in the same run.

With --write, the "## Uplink (issue 28)" section of the file is replaced.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
BASELINE = "597c1e2"  # main before issue 28
SECTION = "Uplink (issue 28)"
TARGET_MEDIAN_MS = 50.0
TARGET_P90_MS = 200.0
KINDS = ("after an answer", "back to back")
SKILLS = ["drive_to", "explore", "take_science_image", "identify_stone", "recharge"]


def pct(values: list[float], q: float) -> float:
    """Nearest-rank percentile (q in 0..1)."""
    s = sorted(values)
    return s[max(0, math.ceil(q * len(s)) - 1)]


# -- one measurement (a child process, on the tree given by --tree) ---------------------


async def measure(delay: float, rounds: int) -> dict[str, list[float]]:
    """Lateness (s) of each command, by kind, at one-way delay `delay`."""
    from backend.server.server import MissionServer
    from backend.transport import free_port, loopback_endpoint

    slow_ms = int((4 * delay + 10) * 1000)  # handshake, lease: a few round trips
    tmp = Path(tempfile.mkdtemp(prefix="bench-uplink-"))
    port = free_port()
    server = MissionServer(
        db=tmp / "m.db",
        mission_file=ROOT / "missions" / "tutorial.yaml",
        listen=[loopback_endpoint(port)],
        zenoh_extra={
            "transport/unicast/accept_timeout": slow_ms,
            "transport/link/tx/lease": slow_ms,
        },
    )
    await server.start()
    try:
        return await _rounds(server, port, delay, rounds, slow_ms)
    finally:
        await server.stop()


async def _rounds(
    server: Any, port: int, delay: float, rounds: int, slow_ms: int
) -> dict[str, list[float]]:
    from delay_proxy import DelayProxy

    from backend.agent import RobotAgent
    from backend.client.client import MissionClient
    from backend.core.ops import AddSkill, Sync
    from backend.transport import loopback_endpoint

    arrived: dict[int, float] = {}  # uplink seq -> first arrival at the robot
    late: dict[str, list[float]] = {k: [] for k in KINDS}
    with DelayProxy(port, delay) as proxy:
        agent = RobotAgent(
            "lru1",
            "lru_science",
            connect=[loopback_endpoint(proxy.port)],
            modules={"base": "1.0.0"},
            lease_ms=slow_ms,
            zenoh_extra={"transport/unicast/open_timeout": slow_ms},
            request_timeout=3 * delay + 5,
        )

        async def handler(ctx: Any, **params: Any) -> None:
            ctx.progress(1.0)

        for skill in SKILLS:
            agent.add_skill(skill, handler, version="1.0.0", raw=True)
        receive = agent._uplink.on_uplink  # the queryable: declared at start()

        async def on_uplink(payload: bytes) -> bytes:
            now = time.perf_counter()
            for e in json.loads(payload).get("commands", []):
                arrived.setdefault(e["seq"], now)
            return await receive(payload)

        agent._uplink.on_uplink = on_uplink  # type: ignore[method-assign]
        client = MissionClient(server.listen, client_id="bench")
        await agent.start()
        try:
            await agent.wait_registered(20 * delay + 60)
            await client.connect()
            ids = [
                (await client.submit(AddSkill(robot="lru1", skill="recharge"))).value["id"]
                for _ in range(2 * (rounds + 1))
            ]
            for r in range(rounds + 1):
                issued: list[tuple[float, int]] = []
                for sid in ids[2 * r : 2 * r + 2]:
                    t = time.perf_counter()
                    reply = await client.submit(Sync(robot="lru1", through=sid))
                    issued.append((t, reply.value["seq"]))
                for _, seq in issued:
                    await client.wait_for(lambda m, s=seq: _answered(m, s), 10 * delay + 60)
                if r == 0:
                    continue  # warm-up
                for kind, (t, seq) in zip(KINDS, issued, strict=True):
                    late[kind].append(arrived[seq] - t - delay)
        finally:
            await client.close()
            await agent.stop()
    return late


def _answered(m: Any, seq: int) -> bool:
    c = m.command_by_seq("lru1", seq)
    return c is not None and not c.pending


def child(args: argparse.Namespace) -> None:
    sys.path[:0] = [args.tree, str(BENCH)]
    late = asyncio.run(measure(args.delay, args.rounds))
    print(json.dumps(late))


# -- the run: both trees, each delay in its own process -------------------------------------


def baseline_tree(tmp: Path) -> Path:
    """The baseline commit's files (git archive), in `tmp`."""
    tree = tmp / "baseline"
    tree.mkdir()
    archive = subprocess.run(
        ["git", "archive", BASELINE, "backend", "missions"],
        cwd=ROOT,
        check=True,
        capture_output=True,
    ).stdout
    tar = tmp / "baseline.tar"
    tar.write_bytes(archive)
    with tarfile.open(tar) as t:
        t.extractall(tree, filter="data")
    return tree


def run_child(tree: Path, delay: float, rounds: int, log: Path) -> dict[str, list[float]]:
    """One measurement in its own process; its log goes to `log`."""
    with open(log, "w") as err:
        out = subprocess.run(
            [
                sys.executable,
                __file__,
                "--child",
                "--tree",
                str(tree),
                "--delay",
                str(delay),
                "--rounds",
                str(rounds),
            ],
            cwd=tree,
            env={**os.environ, "PYTHONPATH": ""},
            check=True,
            stdout=subprocess.PIPE,
            stderr=err,
            text=True,
            timeout=300 + rounds * (10 * delay + 30),
        )
    return json.loads(out.stdout.strip().splitlines()[-1])


def summary(late: list[float]) -> tuple[float, float]:
    return statistics.median(late) * 1e3, pct(late, 0.9) * 1e3


def table(results: dict[tuple[str, float], dict[str, list[float]]], delays: list[float]) -> str:
    rows = [
        "| D | commands | n | median (ms) | p90 (ms) | baseline median (ms) | "
        "baseline p90 (ms) | median ratio |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for d in delays:
        for kind in KINDS:
            new, old = results[("new", d)][kind], results[("baseline", d)][kind]
            (nm, np), (om, op) = summary(new), summary(old)
            ratio = f"{om / nm:.0f}x faster" if nm > 0 and om > nm else f"{nm / max(om, 1e-9):.2f}"
            rows.append(
                f"| {d:g} s | {kind} | {len(new)} | {nm:.1f} | {np:.1f} | {om:.0f} | {op:.0f} "
                f"| {ratio} |"
            )
    return "\n".join(rows) + "\n"


def verdict(results: dict[tuple[str, float], dict[str, list[float]]], delays: list[float]) -> str:
    worst_median = max(summary(results[("new", d)][k])[0] for d in delays for k in KINDS)
    worst_p90 = max(summary(results[("new", d)][k])[1] for d in delays for k in KINDS)
    ok = worst_median <= TARGET_MEDIAN_MS and worst_p90 <= TARGET_P90_MS
    return (
        f"Target median <= {TARGET_MEDIAN_MS:g} ms and p90 <= {TARGET_P90_MS:g} ms at every D: "
        f"{'met' if ok else 'NOT met'} (worst median {worst_median:.1f} ms, worst p90 "
        f"{worst_p90:.1f} ms)."
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--delays", default="0.5,2,6", help="one-way delays D in seconds")
    ap.add_argument("--rounds", type=int, default=8, help="measured rounds per D")
    ap.add_argument("--write", metavar="FILE", help="replace this script's section of FILE")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--tree", help=argparse.SUPPRESS)
    ap.add_argument("--delay", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args)
        return
    from report import machine, write_section

    delays = [float(d) for d in args.delays.split(",")]
    t0 = time.perf_counter()
    results: dict[tuple[str, float], dict[str, list[float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"baseline": baseline_tree(Path(tmp)), "new": ROOT}
        for d in delays:
            for name, tree in trees.items():
                log = Path(tmp) / f"{name}-{d:g}.log"
                try:
                    results[(name, d)] = run_child(tree, d, args.rounds, log)
                except subprocess.SubprocessError:
                    sys.exit(f"D = {d:g} s, {name} failed; its log:\n{log.read_text()}")
                print(f"D = {d:g} s, {name}: done", file=sys.stderr)
    took = time.perf_counter() - t0
    command = "bench/bench_uplink.py" + (f" --write {args.write}" if args.write else "")
    text = (
        f"## {SECTION}\n\n"
        f"Measured by `.venv/bin/python {command}` in {took:.0f} s on {machine()}. "
        "The delay D is in the network (a TCP proxy delaying every byte D s each way "
        "between the robot and the server), not in the SDK; what each figure is: the module "
        "docstring of bench/bench_uplink.py. Lateness = command issued -> its first "
        "transmission at the robot, minus D. Baseline: the code before issue 28 "
        f"(commit {BASELINE}: one transmission at a time, a fixed 5 s receipt timeout), "
        "measured the same way in the same run.\n\n"
        + table(results, delays)
        + "\n"
        + verdict(results, delays)
        + "\n"
    )
    print(text)
    if args.write:
        write_section(Path(args.write), f"## {SECTION}", text)


if __name__ == "__main__":
    main()
