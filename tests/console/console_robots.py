"""Robots for the console's end-to-end tests (run as a subprocess, never forked).

    python console_robots.py ENDPOINT LIBRARY lru1:lru_science lru2:lru_manipulator

Runs one backend.agent.RobotAgent per robot with trivial handlers for every
skill its type offers: a skill takes ~0.4 s with progress reports; a skill
whose label contains "[fail]" fails on its first attempt (a retry succeeds);
one whose label contains "[hold]" runs until stopped; one whose label
contains "[ask]" asks the operators "go on?" (go on / stop here, default go
on after an hour), prints the reply and fails on "stop here". Prints "ready" once
every robot is registered, then runs until stdin closes or SIGTERM.
"""

from __future__ import annotations

import asyncio
import signal
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from backend.agent import Failure, RobotAgent  # noqa: E402
from backend.files.missions import load_library  # noqa: E402


def make_handler(name: str):
    async def handler(ctx, **params):
        label = ctx.skill.label
        if "[ask]" in label:
            reply = await ctx.ask_operator("Go on?", ["go on", "stop here"], "go on", "1h")
            print(
                f"{ctx.skill.id}: {reply.choice} (answered {reply.answered} by {reply.by})",
                flush=True,
            )
            return None if reply.choice == "go on" else Failure("the operator said stop here")
        if "[hold]" in label:
            i = 0
            while True:
                i += 1
                ctx.progress(min(0.99, i / 100), info="holding", eta_s=max(1.0, 100 - i))
                await ctx.sleep(0.1)
        steps = 4
        for i in range(steps):
            ctx.progress(i / steps, info=f"{name} step {i + 1}", eta_s=(steps - i) * 0.1)
            await ctx.sleep(0.1)
        if "[fail]" in label and ctx.attempt == 1:
            return Failure(f"simulated failure of {name} (attempt {ctx.attempt})")
        return None

    return handler


async def main(endpoint: str, library_file: str, specs: list[str]) -> int:
    library = load_library(library_file)
    agents: list[RobotAgent] = []
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    loop.add_reader(
        sys.stdin.fileno(), lambda: stop.set() if not sys.stdin.buffer.read1(1) else None
    )
    try:
        for spec in specs:
            name, rtype = spec.split(":")
            agent = RobotAgent(
                name,
                rtype,
                connect=[endpoint],
                modules={"test": "1.0.0"},
                lease_ms=1000,
                telemetry_hz=5,
            )
            for skill in library.skills_of(rtype):
                agent.add_skill(skill, make_handler(skill), version=library.skills[skill].version)
            await agent.start()
            agents.append(agent)
        for agent in agents:
            await agent.wait_registered(timeout=20)
        print("ready", flush=True)
        await stop.wait()
    finally:
        for agent in agents:
            await agent.stop()
    return 0


if __name__ == "__main__":
    endpoint, library_file, *specs = sys.argv[1:]
    sys.exit(asyncio.run(main(endpoint, library_file, specs)))
