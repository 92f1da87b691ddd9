"""The demo's console: it paints at once and fills in as the server and fleet come up.

`missionctl demo` spawns the mission server and starts this app without
waiting for it: the app shows the mission's plan from its file straight away
(a preview, every action off until connected: "starting the mission
server…"), waits for the server in a thread, starts the simulated fleet,
then connects; the server's state replaces the preview. Quitting, or a
child process failing, is said here (console/demo.py runs the children).
"""

from __future__ import annotations

from typing import Any

from backend.exit_codes import EXIT_UNREACHABLE
from backend.files.missions import load_mission
from console.app import MissionApp
from console.demo import DemoError, DemoProcesses
from console.state.changes import Connecting, Previewed

CHECK_CHILDREN_S = 2.0


class DemoApp(MissionApp):
    def __init__(self, procs: DemoProcesses, **kw: Any) -> None:
        super().__init__(connect=procs.endpoint, **kw)
        self.procs = procs
        self.demo_error = ""  # why the demo could not start (the CLI prints it)
        self._server_up = False
        self._reported: set[str] = set()

    # (Textual runs MissionApp's handlers of the same messages after these: no super() calls)
    def on_mount(self) -> None:
        self.run_worker(self._load_preview, thread=True, group="demo")
        self.set_interval(CHECK_CHILDREN_S, self._check_children)

    # -- the plan from the file, at once ---------------------------------------------------
    def _load_preview(self) -> None:
        mission, library = load_mission(self.procs.mission)
        self.call_from_thread(self._show_preview, Previewed(mission, library))

    def _show_preview(self, event: Previewed) -> None:
        if self.model.mission is None:  # the server's state did not come first
            self._post_event(event)  # the model replaces it with the server's (model.py)

    # -- the server, then the fleet, then the connection --------------------------------------
    def connect_now(self) -> None:
        if self._server_up:
            super().connect_now()
            return
        detail = "starting the mission server (the plan shown is the file's)"
        self._post_event(Connecting(self.procs.endpoint, detail))
        self.run_worker(self._start_children, thread=True, group="demo", exit_on_error=False)

    def _start_children(self) -> None:
        try:
            self.procs.wait_ready()
        except DemoError as e:
            self.call_from_thread(self._failed, str(e))
            return
        self._server_up = True
        self.call_from_thread(self.connect_now)

    def _failed(self, why: str) -> None:
        self.demo_error = why
        self.exit(EXIT_UNREACHABLE, return_code=EXIT_UNREACHABLE)

    def _server_problem(self) -> str | None:
        """If the server stopped after it came up: why, in a sentence."""
        server = self.procs.server
        if not self._server_up or server is None or server.poll() is None:
            return None
        return f"the demo's mission server stopped (exit code {server.returncode})"

    def _check_children(self) -> None:
        problems = {"sim": self.procs.sim_problem(), "server": self._server_problem()}
        for who, problem in problems.items():
            if problem and who not in self._reported:
                self._reported.add(who)
                title = "Simulated fleet" if who == "sim" else "Server"
                self.notify(problem, title=title, severity="error", timeout=15)
