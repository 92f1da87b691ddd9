"""Each robot's contact state on the server, from the deployment's windows
file (`--contact-windows`): published with its presence, offline winning."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime, timedelta

from backend.files.contact import load_contact_windows

from .harness import RawRobot, serving

WAIT = 10.0


def _windows_file(tmp_path, now: datetime):
    """lru1: its only pass an hour ahead; lru2: a pass open now for an hour."""
    f = tmp_path / "windows.yaml"
    ahead, opened = now + timedelta(hours=1), now - timedelta(minutes=1)
    f.write_text(
        "format: missionctl/contact-windows@1\n"
        "robots:\n"
        f"  lru1:\n    passes: [{{start: {ahead.isoformat()}, "
        f"end: {(ahead + timedelta(minutes=20)).isoformat()}}}]\n"
        f"  lru2:\n    passes: [{{start: {opened.isoformat()}, "
        f"end: {(now + timedelta(hours=1)).isoformat()}}}]\n"
    )
    return f, ahead, now + timedelta(hours=1)


def test_the_windows_file_gives_each_robot_its_contact_state(tmp_path) -> None:
    now = datetime.now(UTC).replace(microsecond=0)
    f, ahead, closes = _windows_file(tmp_path, now)

    async def main() -> None:
        windows = load_contact_windows(f)
        async with serving(tmp_path / "m.db", contact_windows=windows) as (server, client):
            # nobody registered: offline, whatever the windows
            assert {r: i.contact.state for r, i in client.robots.items()} == {
                "lru1": "offline",
                "lru2": "offline",
            }
            robots = [RawRobot(server.listen[0], "lru1"), RawRobot(server.listen[0], "lru2")]
            try:
                await robots[0].register("lru_science")
                await robots[1].register("lru_manipulator")
                await client.wait_for(
                    lambda _m: all(client.robots[r].online for r in ("lru1", "lru2")), WAIT
                )
                one, two = client.robots["lru1"].contact, client.robots["lru2"].contact
                assert one is not None and two is not None
                assert (one.state, one.next_contact, one.clock, one.source) == (
                    "out_of_contact",
                    ahead.timestamp(),
                    "wall",
                    "file",
                )
                assert (two.state, two.closes, two.clock) == (
                    "in_contact",
                    closes.timestamp(),
                    "wall",
                )
            finally:
                for r in robots:
                    r.close()
            await client.wait_for(lambda _m: not client.robots["lru1"].online, WAIT)
            gone = client.robots["lru1"].contact
            assert gone is not None and gone.state == "offline"  # offline wins again

    asyncio.run(main())


def test_without_windows_a_present_robot_is_in_contact(tmp_path) -> None:
    async def main() -> None:
        async with serving(tmp_path / "m.db") as (server, client):
            robot = RawRobot(server.listen[0], "lru1")
            try:
                await robot.register("lru_science")
                await client.wait_for(lambda _m: client.robots["lru1"].online, WAIT)
                c = client.robots["lru1"].contact
                assert c is not None
                assert (c.state, c.next_contact, c.closes, c.source) == (
                    "in_contact",
                    None,
                    None,
                    "none",
                )
            finally:
                robot.close()

    asyncio.run(main())


def test_a_bad_windows_file_stops_the_server_saying_where(tmp_path) -> None:
    import subprocess
    import sys

    from .harness import ROOT, TUTORIAL

    f = tmp_path / "windows.yaml"
    f.write_text("format: missionctl/contact-windows@1\nrobots:\n  lru1: {passes: [{start: 3}]}\n")
    r = subprocess.run(
        [sys.executable, "-m", "backend.cli", "server", "--mission", str(TUTORIAL),
         "--db", str(tmp_path / "m.db"), "--contact-windows", str(f)],
        capture_output=True, text=True, cwd=ROOT, timeout=60,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert f"{f}:3:" in r.stderr and "missing required field 'end'" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "m.db").exists()
