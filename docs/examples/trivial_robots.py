"""Robot agents with trivial handlers: the smallest integration of the robot
SDK, used by the live tests and the README's three-terminal walk-through:

    python docs/examples/trivial_robots.py --connect tcp/127.0.0.1:7447 \
        lru1:lru_science lru2:lru_manipulator

On a server with accounts add `--user ACCOUNT --password-file FILE` (a robot
account listing these robots) and, for tls/ endpoints, `--ca FILE`
(docs/security.md); on a long link, `--link-delay-hint D` (docs/deployment.md).

Behaviour by skill label (so a test can script a robot from the plan):
  "hold"   runs until another robot or the test tells it topic "release"
           with {"id": skill id}, or until stopped;
  "fail"   fails ("asked to fail");
  "flaky"  fails on attempt 1, succeeds on later attempts;
  anything else succeeds at once.
Prints "ready NAME" per registered robot, then runs until SIGTERM/SIGINT.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys

from backend.agent import RobotAgent, SkillFailed
from backend.core.credentials import AccountsError
from backend.transport import TransportUnreachable
from backend.transport.login import Login, add_login_arguments, login_from_args
from backend.transport.timeouts import startup_s

SKILLS = {
    "lru_science": ["drive_to", "explore", "take_science_image", "identify_stone", "recharge"],
    "lru_manipulator": [
        "drive_to",
        "explore",
        "identify_stone",
        "pick_stone",
        "drop_stone",
        "pick_payload_box",
        "place_payload_box",
        "deploy_wifi_box",
        "recharge",
    ],
}


def make_agent(
    name: str, rtype: str, connect: str, delay: float, login: Login | None = None
) -> RobotAgent:
    agent = RobotAgent(
        name,
        rtype,
        connect=[connect],
        modules={"base": "1.0.0"},
        lease_ms=1000,
        telemetry_hz=5,
        login=login,
    )
    agent.link.delay_s = delay
    released: set[str] = set()
    agent.on_tell("release", lambda data, sender: released.add(data.get("id", "")))

    async def handler(ctx, **params):
        label = ctx.skill.label
        if "fail" in label and "flaky" not in label:
            raise SkillFailed("asked to fail")
        if "flaky" in label and ctx.skill.attempt == 1:
            raise SkillFailed("flaky: first attempt fails")
        if "hold" in label:
            base = ctx.skill.id.split(".")[0]
            while ctx.skill.id not in released and base not in released:
                ctx.progress(0.5, "holding")
                await ctx.sleep(0.01)
        ctx.progress(1.0)

    for skill in SKILLS[rtype]:
        agent.add_skill(skill, handler, version="1.0.0", raw=True)
    return agent


async def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--delay", type=float, default=0.0)
    p.add_argument("robots", nargs="+", metavar="NAME:TYPE")
    p.add_argument("-v", "--verbose", action="store_true", help="log the agents' activity")
    add_login_arguments(p)
    args = p.parse_args(argv)
    try:
        login = login_from_args(args)
    except AccountsError as e:
        print(f"trivial_robots: {e}", file=sys.stderr)
        return 2
    if args.verbose:
        import logging

        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    agents = [make_agent(*r.split(":"), args.connect, args.delay, login) for r in args.robots]
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    started = []
    try:
        for a in agents:
            await a.start()
            started.append(a)
    except TransportUnreachable as e:  # router down, or login/TLS refused: one line
        print(f"trivial_robots: {e}", file=sys.stderr)
        for a in started:
            await a.stop()
        return 3
    try:
        for a in agents:
            # on a long link (--link-delay-hint) registering takes a few round trips more
            await a.wait_registered(timeout=startup_s(20, login.link_delay_hint))
            print(f"ready {a.name}", flush=True)
        await stop.wait()
    finally:
        for a in agents:
            await a.stop()
    return 0


if __name__ == "__main__":
    sys.exit(asyncio.run(main(sys.argv[1:])))
