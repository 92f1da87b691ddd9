"""What logins, access control and TLS cost, against the open server.

    .venv/bin/python bench/bench_security.py                 # print a Markdown table
    .venv/bin/python bench/bench_security.py --write docs/performance.md

Three mission servers (subprocesses, loopback, tutorial mission) run at once:
open (`tcp/`, no accounts: the baseline), accounts (`tcp/` + `--accounts`:
user/password and the access-control rules), and accounts over mutual TLS
(`tls/` + `--tls-ca`). Against each, measured in interleaved blocks after a
warm-up: the connect time of a `MissionClient` (session open with login and
TLS handshake, state snapshot, account query), the operation round trip
(`submit(EditSkill(label=...))`, journal included), and a raw query to
`Keys.PING` (the router's cost per message, without our code). Each figure
is given as a ratio to the open server's in the same run.

With --write, the "## Security" section of the file is replaced.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from report import machine, write_section  # noqa: E402

from backend.client.client import MissionClient  # noqa: E402
from backend.core.ops import EditSkill  # noqa: E402
from backend.protocol.keys import Keys  # noqa: E402
from backend.server.certs import make_certs  # noqa: E402
from backend.transport import free_port  # noqa: E402
from backend.transport.login import Login  # noqa: E402

SECTION = "Security"
TUTORIAL = ROOT / "missions" / "tutorial.yaml"


class Server:
    def __init__(self, tmp: Path, name: str, scheme: str, extra: list[str]):
        self.endpoint = f"{scheme}/127.0.0.1:{free_port()}"
        self.log = tmp / f"{name}.log"
        self._out = open(self.log, "w")  # noqa: SIM115 - closed in stop()
        self.p = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "backend.cli",
                "server",
                "--mission",
                str(TUTORIAL),
                "--listen",
                self.endpoint,
                "--db",
                str(tmp / f"{name}.db"),
                *extra,
            ],
            cwd=ROOT,
            stdout=self._out,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        deadline = time.monotonic() + 30
        while "listening on" not in self.log.read_text():
            if self.p.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"server {name} did not start:\n{self.log.read_text()}")
            time.sleep(0.05)

    def stop(self) -> None:
        self.p.terminate()
        self.p.wait(15)
        self._out.close()


def setup(tmp: Path) -> tuple[dict[str, Server], dict[str, Login]]:
    pki = tmp / "pki"
    make_certs(pki, clients=["ops"])
    pw = tmp / "ops.pw"
    pw.write_text("bench-password\n")
    os.chmod(pw, 0o600)
    (tmp / "accounts.yaml").write_text(
        "format: missionctl/accounts@1\naccounts:\n  ops: {role: operator, password_file: ops.pw}\n"
    )
    accounts = ["--accounts", str(tmp / "accounts.yaml")]
    tls = [
        "--tls-cert",
        str(pki / "server.pem"),
        "--tls-key",
        str(pki / "server.key"),
        "--tls-ca",
        str(pki / "ca.pem"),
    ]
    servers = {
        "open": Server(tmp, "open", "tcp", []),
        "accounts": Server(tmp, "accounts", "tcp", accounts),
        "accounts + mutual TLS": Server(tmp, "tls", "tls", accounts + tls),
    }
    logins = {
        "open": Login(),
        "accounts": Login(user="ops", password="bench-password"),
        "accounts + mutual TLS": Login(
            user="ops",
            password="bench-password",
            ca=str(pki / "ca.pem"),
            cert=str(pki / "client-ops.pem"),
            key=str(pki / "client-ops.key"),
        ),
    }
    return servers, logins


async def measure(
    servers: dict[str, Server], logins: dict[str, Login], n: int, blocks: int
) -> dict[str, dict[str, list[float]]]:
    out: dict[str, dict[str, list[float]]] = {
        k: {"connect": [], "op": [], "ping": []} for k in servers
    }
    clients = {}
    for name, s in servers.items():
        clients[name] = MissionClient(
            s.endpoint, login=logins[name], telemetry=False, client_id=f"bench-{name}"
        )
        await clients[name].connect()
    try:
        for block in range(blocks + 1):  # block 0 is the warm-up
            for name, c in clients.items():
                t0 = time.perf_counter()
                probe = MissionClient(servers[name].endpoint, login=logins[name], telemetry=False)
                await probe.connect()
                connect = time.perf_counter() - t0
                await probe.close()
                ops, pings = [], []
                for i in range(n):
                    t0 = time.perf_counter()
                    await c.submit(EditSkill(id="lru1-1", label=f"bench {block}.{i}"))
                    ops.append(time.perf_counter() - t0)
                    t0 = time.perf_counter()
                    replies = list(c.session.get(Keys.PING, timeout=5))
                    pings.append(time.perf_counter() - t0)
                    assert replies and replies[0].ok is not None
                if block:
                    out[name]["connect"].append(connect)
                    out[name]["op"] += ops
                    out[name]["ping"] += pings
    finally:
        for c in clients.values():
            await c.close()
    return out


def table(results: dict[str, dict[str, list[float]]]) -> str:
    base = {k: statistics.median(v) for k, v in results["open"].items()}
    rows = [
        "| server | connect (median) | operation round trip (median, p99) | raw query to PING "
        "(median) |",
        "| --- | --- | --- | --- |",
    ]
    for name, r in results.items():
        med = {k: statistics.median(v) for k, v in r.items()}
        p99 = sorted(r["op"])[int(0.99 * (len(r["op"]) - 1))]
        rows.append(
            f"| {name} | {med['connect'] * 1e3:.1f} ms (×{med['connect'] / base['connect']:.2f}) "
            f"| {med['op'] * 1e3:.2f} ms (×{med['op'] / base['op']:.2f}), p99 {p99 * 1e3:.2f} ms "
            f"| {med['ping'] * 1e3:.3f} ms (×{med['ping'] / base['ping']:.2f}) |"
        )
    return "\n".join(rows)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-n", type=int, default=100, help="operations and pings per block")
    p.add_argument("--blocks", type=int, default=5)
    p.add_argument("--write", metavar="FILE")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        servers, logins = setup(Path(tmp))
        try:
            results = asyncio.run(measure(servers, logins, args.n, args.blocks))
        finally:
            for s in servers.values():
                s.stop()
    body = table(results)
    print(body)
    if args.write:
        text = (
            f"## {SECTION}\n\n"
            "What logins, access-control rules and mutual TLS cost (`.venv/bin/python "
            f"bench/bench_security.py -n {args.n} --blocks {args.blocks}`; ratios against the open "
            f"server in the same run, {args.blocks} interleaved blocks of {args.n} after a "
            f"warm-up; {machine('eclipse-zenoh 1.10.2')}; {time.strftime('%Y-%m-%d')}). Connecting "
            "with a login includes one more query (the account's role); the medians of the other "
            "columns are the per-message cost of the router's rules and of TLS.\n\n"
            f"{body}\n"
        )
        write_section(Path(args.write), f"## {SECTION}", text)
        print(f"wrote the '## {SECTION}' section of {args.write}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
