"""Offline mission states for console tests: built with the real rules engine
(plan_sync + SyncAck + Report), injected into the app as messages."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from backend.client import OperationRefused
from backend.files import load_mission
from backend.library import Library
from backend.model import Mission, Pose
from backend.ops import Control, Report, Retry, RetryAck, Sync, SyncAck, Unsync, UnsyncDone
from backend.protocol import ErrorReply, OpReply, RobotInfo, Telemetry
from backend.rules import Engine, Refusal

ROOT = Path(__file__).resolve().parents[2]
MARS = ROOT / "missions" / "mars_sample_return.yaml"
TUTORIAL = ROOT / "missions" / "tutorial.yaml"
DATA = Path(__file__).resolve().parent / "data"
T0 = datetime(2026, 3, 14, 10, 42, 7, tzinfo=UTC)


class Builder:
    """Drives a mission through the rules engine like a server and robots would."""

    def __init__(self, path: Path = MARS):
        mission, library = load_mission(path)
        self.engine = Engine(mission, library)
        self.seqs: dict[str, int] = {}

    @property
    def mission(self) -> Mission:
        return self.engine.mission

    @property
    def library(self) -> Library:
        return self.engine.library

    def sync(self, robot: str, through: str | None = None) -> list[str]:
        skills = self.engine.plan_sync(Sync(robot=robot, through=through))
        ids = [s.id for s in skills]
        try:
            self.engine.submit(SyncAck(robot=robot, ids=ids))
        finally:
            self.engine.release(robot, ids)
        return ids

    def report(self, robot: str, sid: str, status: str, info: str = "") -> None:
        self.seqs[robot] = self.seqs.get(robot, 0) + 1
        self.engine.submit(Report(robot=robot, seq=self.seqs[robot], id=sid, status=status, info=info, at=T0))

    def snapshot(self) -> Mission:
        return self.mission.model_copy(deep=True)


def mars_mid_execution() -> Builder:
    """Every status on screen, and barrier b1 (lru1-3 / lru2-3) mid-way."""
    b = Builder(MARS)
    b.sync("lru1", "lru1-3")
    b.report("lru1", "lru1-1", "running")
    b.report("lru1", "lru1-1", "success")
    b.report("lru1", "lru1-2", "running")
    b.sync("lru2", "lru2-4")
    b.report("lru2", "lru2-1", "running")
    b.report("lru2", "lru2-1", "success")
    b.report("lru2", "lru2-2", "running")
    b.report("lru2", "lru2-2", "success")
    b.report("lru2", "lru2-3", "synchwaiting", "waiting for lru1 at b1")
    b.sync("ardea", "ardea-4")
    b.report("ardea", "ardea-1", "running")
    b.report("ardea", "ardea-1", "success")
    b.report("ardea", "ardea-2", "running")
    b.report("ardea", "ardea-2", "failure", "battery below 15%: survey aborted")
    b.report("ardea", "ardea-3", "running")
    b.report("ardea", "ardea-3", "paused", "out of comms range")
    return b


def fleet(online: dict[str, bool]) -> dict[str, RobotInfo]:
    return {r: RobotInfo(name=r, online=on, since=T0) for r, on in online.items()}


MARS_FLEET = {"lru1": True, "lru2": True, "ardea": False, "lander": True}


def mars_telemetry() -> list[Telemetry]:
    return [
        Telemetry(robot="lru1", pose=Pose(x=20.0, y=8.0), battery=0.82, link=0.9, mode="executing", skill="lru1-2", progress=0.45, eta_s=132, at=T0),
        Telemetry(robot="lru2", pose=Pose(x=40.0, y=17.0), battery=0.64, link=0.75, mode="waiting at barrier", skill="lru2-3", at=T0),
        Telemetry(robot="lander", battery=1.0, link=1.0, mode="idle", at=T0),
    ]


class EngineBackend:
    """The console's backend, offline: operations go to a rules engine and its
    events come back to the app as EventsApplied (robots acknowledge at once)."""

    def __init__(self, builder: Builder, app: Any = None):
        self.b = builder
        self.app = app
        self.ops: list[Any] = []

    def _post(self, applied) -> None:
        if applied.events and self.app is not None:
            from console.messages import EventsApplied

            self.app.post_message(EventsApplied(applied.batch()))

    async def submit(self, op: Any, *, expected_revision: int | None = None) -> OpReply:
        self.ops.append(op)
        e = self.b.engine
        try:
            if isinstance(op, Sync):
                skills = e.plan_sync(op)
                ids = [s.id for s in skills]
                try:
                    applied = e.submit(SyncAck(robot=op.robot, ids=ids))
                finally:
                    e.release(op.robot, ids)
            elif isinstance(op, Unsync):
                ids = e.plan_unsync(op)
                try:
                    applied = e.submit(UnsyncDone(robot=op.robot, ids=ids))
                finally:
                    e.release(op.robot)
            elif isinstance(op, Retry):
                new = e.plan_retry(op)
                robot = e.mission.find(op.id)[0]
                try:
                    applied = e.submit(RetryAck(robot=robot, failed_id=op.id, skill=new))
                finally:
                    e.release(robot)
            elif isinstance(op, Control):
                robots = e.plan_control(op)
                for r in robots:
                    e.release(r)
                return OpReply(revision=e.mission.revision, value={"robots": dict.fromkeys(robots, "ok")})
            else:
                applied = e.submit(op, client="console", expected_revision=expected_revision)
        except Refusal as r:
            raise OperationRefused(ErrorReply(**r.to_dict())) from None
        self._post(applied)
        return OpReply(revision=applied.revision, value=applied.value, notes=applied.notes)


# -- driving the app -------------------------------------------------------------------


def make_app(**kw: Any):
    """A MissionApp for tests: no animations, no cursor blink."""
    from console.app import MissionApp

    app = MissionApp(**kw)
    app.animation_level = "none"
    app.cursor_blink = False
    return app


def engine_app(builder: Builder) -> tuple[Any, EngineBackend]:
    """A test app whose operations go to `builder`'s rules engine (and back)."""
    backend = EngineBackend(builder)
    app = make_app(backend=backend)
    backend.app = app
    return app, backend


async def inject(app: Any, pilot: Any, builder: Builder | None, *, online: dict[str, bool] | None = None,
                 telemetry: list[Telemetry] | None = None, connection: str = "connected") -> None:
    """Post the messages the live connection would post; wait until shown."""
    from console.messages import ConnectionChanged, StateLoaded, TelemetryChanged

    app.post_message(ConnectionChanged(connection, endpoint="tcp/127.0.0.1:7447"))
    if builder is not None:
        app.post_message(StateLoaded(builder.snapshot(), builder.library, fleet(online if online is not None else MARS_FLEET)))
    for t in telemetry or []:
        app.post_message(TelemetryChanged(t))
    await pilot.pause()
    await pilot.pause()


def screen_text(app: Any) -> str:
    """What the terminal shows now, as plain text lines."""
    strips = app.screen._compositor.render_strips()
    return "\n".join("".join(seg.text for seg in strip) for strip in strips)


async def wait_until(pilot: Any, predicate: Any, timeout: float = 10.0, what: str = "condition") -> None:
    """Let the app run until `predicate()` holds (bounded): no sleeps as sync."""
    import time as _time

    deadline = _time.monotonic() + timeout
    while not predicate():
        if _time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what} (focused: {pilot.app.focused!r})\n--- screen ---\n{screen_text(pilot.app)}")
        await pilot.pause(0.02)


async def wait_exit(app: Any, timeout: float = 10.0) -> None:
    """Wait (bounded) until the app asked to exit; the pilot cannot pause then."""
    import asyncio
    import time as _time

    deadline = _time.monotonic() + timeout
    while app.return_code is None:
        if _time.monotonic() > deadline:
            raise AssertionError("the app did not exit")
        await asyncio.sleep(0.02)
