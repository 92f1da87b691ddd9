"""Each robot's contact state on the server (the computing: backend.core.contact).

Windows come from the deployment's file (`missionctl server --contact-windows
FILE`, on the wall clock) or from the simulator (`--comms-window`, on the sim
clock). The server learns the simulator's from its status, which it publishes
already (`KEY_STATUS_LIVE`, applied with `StatusMirror`), and asks for the
status once on start (a simulator running already); a missed publication is
mended by the next full one (at least once a minute). A robot the file lists
has the file's windows; every other robot the simulator's (one schedule for
its whole fleet).

Mission time now: the simulator's clock moved on at its speed since its last
status when a simulator runs, else the wall's.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping
from datetime import UTC, datetime, timedelta
from typing import Any

from pydantic import ValidationError

from backend.core.contact import ContactWindows, RepeatingWindow, contact_at, sim_time_text
from backend.protocol.mapfeed import KEY_STATUS, KEY_STATUS_LIVE, SimStatus, StatusMirror
from backend.protocol.messages import MissionClock, RobotContact
from backend.transport import QueryFailed, query, subscribe_on_loop

log = logging.getLogger(__name__)

STATUS_QUERY_S = 5.0  # asking a simulator for its status on start


def _now() -> datetime:
    return datetime.now(UTC)


class ContactWatch:
    def __init__(self, declared: Mapping[str, ContactWindows] | None = None) -> None:
        self.declared = dict(declared or {})  # robot -> windows on the wall clock
        self.on_change: Callable[[], object] | None = None  # the simulator's status changed
        self.mirror = StatusMirror()
        self._status_at: datetime | None = None  # when the latest status came
        self._sim_windows: ContactWindows | None = None
        self._closed = False
        self._task: asyncio.Task[None] | None = None

    def start(self, session: Any) -> Any:
        """Follow the simulator's status; returns the subscriber (to undeclare)."""
        self._closed = False
        sub = subscribe_on_loop(session, KEY_STATUS_LIVE, self._got)
        self._task = asyncio.get_running_loop().create_task(self._ask(session), name="contact")
        return sub

    def close(self) -> None:
        self._closed = True
        if self._task is not None:
            self._task.cancel()
            self._task = None

    async def _ask(self, session: Any) -> None:
        try:
            raw = await query(session, KEY_STATUS, b"", STATUS_QUERY_S)
            self.mirror.apply_full(SimStatus.model_validate_json(raw))
        except (QueryFailed, ValidationError, ValueError) as e:
            log.debug("no simulator status: %s", e)  # no simulator, or not yet
            return
        self._changed()

    def _got(self, payload: bytes) -> None:
        if self._closed:
            return
        try:
            applied = self.mirror.apply(payload)
        except (ValidationError, ValueError) as e:
            log.debug("ignoring a malformed simulator status: %s", e)
            return
        if applied:
            self._changed()

    def _changed(self) -> None:
        self._status_at = _now()
        status = self.mirror.status
        w = status.comms_window if status is not None else None
        try:
            self._sim_windows = (
                None
                if w is None
                else ContactWindows(
                    repeating=RepeatingWindow(
                        open_s=w.open_s, period_s=w.period_s, offset_s=w.offset_s
                    )
                )
            )
        except ValidationError as e:  # a window as long as its period: always open
            log.warning("ignoring the simulator's comms window: %s", e)
            self._sim_windows = None
        if self.on_change is not None:
            self.on_change()

    # -- the state ---------------------------------------------------------------------
    def mission_now(self, clock: MissionClock, now: datetime) -> float:
        status = self.mirror.status
        if clock == "sim" and status is not None and self._status_at is not None:
            # a past stamp too (negative: before the status), at the status's speed
            ran = (now - self._status_at).total_seconds()
            return status.sim_time + ran * status.speed
        return now.timestamp()

    def _windows(self, robot: str) -> tuple[ContactWindows | None, MissionClock, str]:
        if robot in self.declared:
            return self.declared[robot], "wall", "file"
        if self.mirror.status is None:
            return None, "wall", "none"
        if self._sim_windows is None:
            return None, "sim", "none"
        return self._sim_windows, "sim", "sim"

    def of(self, robot: str, present: bool, now: datetime | None = None) -> RobotContact:
        """The robot's contact state now (`present`: its presence)."""
        windows, clock, source = self._windows(robot)
        c = contact_at(windows, self.mission_now(clock, now or _now()), present=present)
        return RobotContact.model_validate({**c.model_dump(), "clock": clock, "source": source})

    # -- when a robot can be reached (backend.core.verification's Path) -------------------
    def speed(self, clock: MissionClock) -> float:
        """Mission seconds per wall second on `clock`."""
        status = self.mirror.status
        if clock == "sim" and status is not None:
            return status.speed or 1.0
        return 1.0

    def open_from(self, robot: str, present: bool, t: datetime) -> datetime | None:
        """The first instant at or after `t` (wall) when the robot is in contact
        (None: offline, or no window ahead)."""
        windows, clock, _ = self._windows(robot)
        if not present or windows is None:
            return t if present else None
        m = self.mission_now(clock, t)
        opens = m if windows.is_open(m) else windows.next_opening(m)
        return None if opens is None else t + timedelta(seconds=(opens - m) / self.speed(clock))

    def time_text(self, t: datetime) -> str:
        """A wall stamp in mission time, with its unit: 'sim 0:32:00', '14:32:05'."""
        if self.mirror.status is not None:
            return f"sim {sim_time_text(self.mission_now('sim', t))}"
        return f"{t:%H:%M:%S}"
