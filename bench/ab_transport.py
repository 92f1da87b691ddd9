"""A/B of two versions of missionctl on the operation round trip (throughput, robot reports).

    .venv/bin/python bench/ab_transport.py HEAD~3 HEAD            # two git revisions
    .venv/bin/python bench/ab_transport.py /tmp/other-checkout .  # or two source trees
    .venv/bin/python bench/ab_transport.py HEAD~1 HEAD --throughput 2
    .venv/bin/python bench/ab_transport.py HEAD~1 HEAD --reports

Speeds differ between machines and drift on a shared VM (the raw query took
0.32-0.63 ms within one hour here), so a change is judged against the other
version in the same run: each version gets its own
server and client (processes started from its own tree, with this venv's
Python and packages), and the two are measured in alternating blocks after a
warm-up. Per version: raw query to PING and `MissionClient.submit(EditSkill)`
round trips (medians, p99, p99.9, max, ratio), or with --throughput S, operations per
second with 16 in flight for S seconds per block, or with --reports, a robot's lone
status reports (one every ~12 ms, as in bench_transport's fan-out): until the robot
has its acknowledgement, and until the client's mirror has applied it.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


# -- the child: one client of one version's server, measuring a block per request --------------


def _either(new: str, old: str):
    """A module by its name in this version's tree, or by its name before the
    restructure (issue 18), so that trees from both sides of it can be compared.
    Decided by the tree itself: the venv's editable install would also resolve
    the new names for an old tree."""
    import importlib
    from pathlib import Path

    import backend

    layered = (Path(backend.__path__[0]) / "core").is_dir()
    return importlib.import_module(new if layered else old)


async def child(endpoint: str) -> None:
    # this version's backend (PYTHONPATH); not bench_transport, which would
    # put the tree this script lives in first on sys.path
    MissionClient = _either("backend.client.client", "backend.client").MissionClient
    EditSkill = _either("backend.core.ops", "backend.ops").EditSkill
    Keys = _either("backend.protocol.keys", "backend.protocol").Keys

    client = MissionClient(endpoint, client_id="ab")
    await client.connect()
    count = 0
    robot = None

    async def op(skill: str = "lru1-1") -> float:
        nonlocal count
        count += 1
        t = time.perf_counter()
        await client.submit(EditSkill(id=skill, label=f"ab {count}"))
        return time.perf_counter() - t

    def ping() -> float:  # raw: a blocking Zenoh query, nothing of ours in between
        t = time.perf_counter()
        for reply in client.session.get(Keys.PING, payload=b"ping", timeout=5.0):
            reply.ok.payload.to_bytes()
        return time.perf_counter() - t

    async def throughput(seconds: float, inflight: int = 16) -> float:
        end = time.perf_counter() + seconds
        done = 0

        async def worker(w: int) -> None:
            nonlocal done
            while time.perf_counter() < end:
                await op(("lru1-1", "lru1-2")[w % 2])
                done += 1

        t0 = time.perf_counter()
        await asyncio.gather(*(worker(w) for w in range(inflight)))
        return done / (time.perf_counter() - t0)

    try:
        for _ in range(200):  # warm-up
            await op()
            ping()
        if "--reports" in sys.argv:
            robot = await _Robot.start(endpoint, client)
        print("ready", flush=True)
        loop = asyncio.get_running_loop()
        while line := (await loop.run_in_executor(None, sys.stdin.readline)).strip():
            kind, amount = line.split()
            if kind == "throughput":
                print(json.dumps({"throughput": await throughput(float(amount))}), flush=True)
            elif kind == "reports":
                acks, applied = await robot.block(client, int(amount))
                print(json.dumps({"acks": acks, "applied": applied}), flush=True)
            else:
                n = int(amount)
                raw = [ping() for _ in range(n)]
                ops = [await op() for _ in range(n)]
                print(json.dumps({"raw": raw, "ops": ops}), flush=True)
    finally:
        if robot is not None:
            robot.close()
        await client.close()


class _Robot:
    """Robot lru2 as the server sees it (registered, accepting commands) on
    a plain Zenoh session, reporting its synchronized skill lru2-1 running
    and paused in turn with blocking queries, as bench_transport's fan-out."""

    @classmethod
    async def start(cls, endpoint: str, client) -> _Robot:
        Sync = _either("backend.core.ops", "backend.ops").Sync
        load_library = _either("backend.files.missions", "backend.files").load_library
        Keys = _either("backend.protocol.keys", "backend.protocol").Keys
        m = _either("backend.protocol.messages", "backend.protocol")
        CommandReply, Manifest, Module = m.CommandReply, m.Manifest, m.Module
        Register, RegisterReply, dumps = m.Register, m.RegisterReply, m.dumps
        from backend.transport import client_config, declare_token, query, serve
        from backend.transport.session import open_session

        self = cls()
        self.session = open_session(client_config([endpoint]))

        def on_command(payload: bytes) -> bytes:
            cmd = json.loads(payload)
            return dumps(CommandReply(ok=True, ids=[s["id"] for s in cmd.get("skills", [])]))

        self.entities = [
            declare_token(self.session, Keys.alive("lru2")),
            serve(self.session, Keys.command("lru2"), on_command),
        ]
        lib = load_library(Path.cwd() / "missions" / "libraries" / "mars.yaml")
        manifest = Manifest(
            name="lru2",
            type="lru_manipulator",
            modules=[Module(name="base", version="1.0.0")],
            skills={s: lib.skills[s].version for s in lib.skills_of("lru_manipulator")},
        )
        reply = RegisterReply.model_validate_json(
            await query(
                self.session, Keys.register("lru2"), dumps(Register(manifest=manifest)), 60.0
            )
        )
        assert reply.accepted, reply.reason
        self.seq = reply.last_seq
        await client.submit(Sync(robot="lru2", through="lru2-1"))
        self.running = False
        await self.block(client, 30)  # warm-up
        return self

    async def block(self, client, n: int) -> tuple[list[float], list[float]]:
        from datetime import UTC, datetime

        Status = _either("backend.core.model", "backend.model").Status
        Report = _either("backend.core.ops", "backend.ops").Report
        Keys = _either("backend.protocol.keys", "backend.protocol").Keys
        m = _either("backend.protocol.messages", "backend.protocol")
        ReportBatch, dumps = m.ReportBatch, m.dumps

        applied_at: dict[int, float] = {}

        def on_event(*args) -> None:
            # one typed event; a version before issue 18 calls with (kind, payload)
            kind, batch = (args[0].kind, args[0].payload) if len(args) == 1 else args
            if kind == "events":
                applied_at.setdefault(batch.revision, time.perf_counter())

        client.add_listener(on_event)

        def send(payload: bytes) -> float:
            t = time.perf_counter()
            for reply in self.session.get(Keys.reports("lru2"), payload=payload, timeout=30.0):
                assert reply.ok is not None, reply.err.payload.to_bytes()
            return t

        acks, applied = [], []
        for _ in range(n):
            self.seq += 1
            self.running = not self.running
            status = Status.RUNNING if self.running else Status.PAUSED
            payload = dumps(
                ReportBatch(
                    reports=[
                        Report(
                            robot="lru2",
                            seq=self.seq,
                            id="lru2-1",
                            status=status,
                            at=datetime.now(UTC),
                        )
                    ]
                )
            )
            revision = client.revision + 1
            t = await asyncio.to_thread(send, payload)
            acks.append(time.perf_counter() - t)
            await client.wait_for(lambda m, r=revision: m.revision >= r, 10)
            applied.append(applied_at[revision] - t)
            await asyncio.sleep(0.012)  # lone reports: the server's threads go idle in between
        client._listeners.remove(on_event)  # no remove_listener before issue 18
        return acks, applied

    def close(self) -> None:
        from backend.transport.session import close_session

        self.entities.clear()
        close_session(self.session)


# -- the parent ------------------------------------------------------------------------------------


def source_tree(spec: str, tmp: Path) -> tuple[Path, str]:
    """A directory as it is, or a git revision checked out into a worktree."""
    if Path(spec).is_dir():
        return Path(spec).resolve(), spec
    rev = subprocess.run(
        ["git", "rev-parse", "--short", spec], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.strip()
    tree = tmp / f"rev-{rev}"
    subprocess.run(
        ["git", "worktree", "add", "--detach", "-q", str(tree), rev], cwd=ROOT, check=True
    )
    return tree, f"{spec} ({rev})"


class Version:
    def __init__(
        self, tree: Path, label: str, tmp: Path, index: int, child_args: tuple[str, ...] = ()
    ):
        from backend.transport import free_port, loopback_endpoint

        self.tree, self.label = tree, label
        self.env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONUNBUFFERED": "1"}
        self.endpoint = loopback_endpoint(free_port())
        self.log = tmp / f"server-{index}.log"
        with open(self.log, "w") as out:
            self.server = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "backend.cli",
                    "server",
                    "--mission",
                    str(tree / "missions" / "tutorial.yaml"),
                    "--listen",
                    self.endpoint,
                    "--db",
                    str(tmp / f"ab-{index}.db"),
                ],
                cwd=tree,
                env=self.env,
                stdout=out,
                stderr=subprocess.STDOUT,
            )
        deadline = time.monotonic() + 60
        while "listening on" not in self.log.read_text():
            if self.server.poll() is not None or time.monotonic() > deadline:
                self.server.kill()
                raise RuntimeError(f"{label}: the server did not start:\n{self.log.read_text()}")
            time.sleep(0.05)
        self.client = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--child", self.endpoint, *child_args],
            cwd=tree,
            env=self.env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        if self.client.stdout.readline().strip() != "ready":
            # not in `versions` yet, so main's cleanup would leave both running
            self.client.kill()
            self.server.terminate()
            self.client.wait(30)
            self.server.wait(30)
            raise RuntimeError(f"{label}: the client did not start")
        self.raw: list[float] = []
        self.ops: list[float] = []
        self.rates: list[float] = []
        self.acks: list[float] = []
        self.applied: list[float] = []

    def block(self, request: str) -> None:
        self.client.stdin.write(request + "\n")
        self.client.stdin.flush()
        got = json.loads(self.client.stdout.readline())
        if "throughput" in got:
            self.rates.append(got["throughput"])
        elif "acks" in got:
            self.acks += got["acks"]
            self.applied += got["applied"]
        else:
            self.raw += got["raw"]
            self.ops += got["ops"]

    def stop(self) -> None:
        if self.client.poll() is None:
            self.client.stdin.write("\n")
            self.client.stdin.flush()
            self.client.wait(30)
        self.server.terminate()
        self.server.wait(30)

    def report(self) -> str:
        if self.rates:
            rate = statistics.median(self.rates)
            return f"{self.label}: {rate:,.0f} ops/s median of {len(self.rates)} blocks"
        if self.acks:
            p99 = sorted(self.applied)[int(0.99 * (len(self.applied) - 1))]
            return (
                f"{self.label}: {len(self.acks)} lone reports: acknowledged "
                f"{statistics.median(self.acks) * 1e3:.3f} ms, applied by the client "
                f"{statistics.median(self.applied) * 1e3:.3f} ms (p99 {p99 * 1e3:.3f} ms) (medians)"
            )
        raw, ops = statistics.median(self.raw), statistics.median(self.ops)
        ranked = sorted(self.ops)
        p99, p999 = (ranked[int(q * (len(ranked) - 1))] for q in (0.99, 0.999))
        over = sum(t > 0.003 for t in ranked)  # e.g. an fsync in the operation's path
        return (
            f"{self.label}: raw {raw * 1e3:.3f} ms, operation {ops * 1e3:.3f} ms (p99 "
            f"{p99 * 1e3:.3f} ms, p99.9 {p999 * 1e3:.2f} ms, max {ranked[-1] * 1e3:.2f} ms, {over} "
            f"of {len(ranked)} over 3 ms), ratio {ops / raw:.2f}x"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", nargs="?", help="git revision or source tree")
    ap.add_argument("b", nargs="?", help="git revision or source tree")
    ap.add_argument(
        "--blocks", type=int, default=12, help="blocks per version, alternating (default 12)"
    )
    ap.add_argument(
        "-n", type=int, default=200, help="round trips of each kind per block (default 200)"
    )
    ap.add_argument(
        "--throughput",
        type=float,
        metavar="S",
        help="measure operations/s instead, S seconds per block",
    )
    ap.add_argument(
        "--reports",
        action="store_true",
        help="measure a robot's lone status reports instead (-n per block)",
    )
    ap.add_argument("--child", metavar="ENDPOINT", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        asyncio.run(child(args.child))
        return 0
    if not (args.a and args.b):
        ap.error("give two git revisions or source trees")
    with tempfile.TemporaryDirectory(prefix="ab-transport-") as d:
        tmp = Path(d)
        trees = [source_tree(spec, tmp) for spec in (args.a, args.b)]
        versions: list[Version] = []
        try:
            for i, (tree, label) in enumerate(trees):
                versions.append(
                    Version(tree, label, tmp, i, ("--reports",) if args.reports else ())
                )
            request = (
                f"throughput {args.throughput}"
                if args.throughput
                else f"reports {args.n}"
                if args.reports
                else f"ops {args.n}"
            )
            for b in range(args.blocks):
                for v in versions if b % 2 == 0 else versions[::-1]:
                    v.block(request)
            for v in versions:
                print(v.report())
        finally:
            for v in versions:
                v.stop()
            for tree, _ in trees:
                if tree.is_relative_to(tmp):
                    subprocess.run(
                        ["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False
                    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
