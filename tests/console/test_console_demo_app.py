"""The demo's console paints at once (issue 27): the plan from the mission file
while the server starts in the background, every action off until connected;
a server that does not start ends the demo with its reason."""

from __future__ import annotations

import threading

from console_state import MARS, screen_text, state_loaded, wait_exit, wait_until

from backend.exit_codes import EXIT_UNREACHABLE
from backend.protocol import mapfeed as mf
from console.demo import DemoError
from console.demo_app import DemoApp
from console.state.site import GROUND


class SlowServer:
    """DemoProcesses as the app sees it, with a server that takes its time (then fails)."""

    def __init__(self) -> None:
        self.mission = MARS
        self.endpoint = "tcp/127.0.0.1:9"
        self.notices: list[str] = []
        self.server = None
        self.go = threading.Event()

    def wait_ready(self) -> None:
        self.go.wait(30)
        raise DemoError("the mission server did not start (exit code 1):\nport taken")

    def sim_problem(self) -> None:
        return None


async def test_the_demo_shows_the_plan_from_its_file_while_the_server_starts():
    procs = SlowServer()
    app = DemoApp(procs, ask_before_quit=False)
    app.animation_level = "none"
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_until(pilot, lambda: "drive to POI-A" in screen_text(app), what="the plan")
        top = screen_text(app).splitlines()[0]
        assert "Mars sample return" in top and "connecting" in top, top
        assert app.model.why_not("sync", "lru1", "lru1-1")  # nothing applies until connected
        procs.go.set()  # the server fails: the demo ends, saying why
        await wait_exit(app)
    assert app.return_code == EXIT_UNREACHABLE
    assert "did not start" in app.demo_error


def test_the_ground_names_follow_the_map_feed():
    assert set(GROUND) == {mf.T_FREE, mf.T_SLOW, mf.T_ROCK}


def test_the_servers_first_state_replaces_the_files_plan_and_a_late_preview_is_ignored():
    from backend.files.missions import load_mission
    from console.state.changes import NOTHING, Previewed
    from console.state.model import ConsoleModel

    mission, library = load_mission(MARS)
    m = ConsoleModel()
    assert m.take(Previewed(mission, library)).loaded and m.previewing
    served = mission.model_copy(deep=True, update={"revision": 7})
    served.tasks["lru1"].pop()  # the server's plan moved on from the file's
    m.take(state_loaded(served, library, server_id="s1").event)
    assert m.mission is served and not m.previewing and not m.unsaved  # its first state
    assert m.take(Previewed(mission, library)) is NOTHING and m.mission is served
