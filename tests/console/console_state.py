"""Offline mission states for console tests: built with the real rules engine
(plan_sync + SyncAck + Report), injected into the app as the events the
client library would deliver (`backend.client.events`: StateSynced,
BatchApplied, RobotChanged, ...), each posted as it is (`Incoming`)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from backend.client.client import OperationRefused
from backend.core.library import Library
from backend.core.model import Mission, Pose
from backend.core.ops import Control, Report, Retry, RetryAck, Sync, SyncAck, Unsync, UnsyncDone
from backend.core.rules.engine import Engine, Refusal
from backend.files.missions import load_mission
from backend.protocol.messages import ErrorReply, OpReply, RobotInfo, Telemetry

ROOT = Path(__file__).resolve().parents[2]
MARS = ROOT / "tests" / "data" / "mars_sample_return_v1.yaml"
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
        self.engine.submit(
            Report(robot=robot, seq=self.seqs[robot], id=sid, status=status, info=info, at=T0)
        )

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
        Telemetry(
            robot="lru1",
            pose=Pose(x=20.0, y=8.0),
            battery=0.82,
            link=0.9,
            mode="executing",
            skill="lru1-2",
            progress=0.45,
            eta_s=132,
            at=T0,
        ),
        Telemetry(
            robot="lru2",
            pose=Pose(x=40.0, y=17.0),
            battery=0.64,
            link=0.75,
            mode="waiting at barrier",
            skill="lru2-3",
            at=T0,
        ),
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
            self.app.post_message(applied_batch(applied.batch()))

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
                return OpReply(
                    revision=e.mission.revision, value={"robots": dict.fromkeys(robots, "ok")}
                )
            else:
                applied = e.submit(op, client="console", expected_revision=expected_revision)
        except Refusal as r:
            raise OperationRefused(ErrorReply(**r.to_dict())) from None
        self._post(applied)
        return OpReply(revision=applied.revision, value=applied.value, notes=applied.notes)


# -- the events the client library delivers, as the app gets them ----------------------

ENDPOINT = "tcp/127.0.0.1:7447"


def incoming(event: Any):
    from console.messages import Incoming

    return Incoming(event)


def state_loaded(
    mission: Mission,
    library: Library,
    robots: dict[str, RobotInfo] | None = None,
    server_id: str = "",
    alerts: list[Any] | None = None,
):
    """A whole state, as the client delivers it after (re)connecting."""
    from backend.client.events import StateSynced
    from backend.protocol.messages import StateSnapshot

    snap = StateSnapshot(
        server_id=server_id,
        revision=mission.revision,
        mission=mission,
        library=library,
        robots=robots or {},
        alerts=alerts or [],
    )
    return incoming(StateSynced(snap))


def applied_batch(batch: Any):
    from backend.client.events import BatchApplied

    return incoming(BatchApplied(batch))


def fleet_changed(info: RobotInfo):
    from backend.client.events import RobotChanged

    return incoming(RobotChanged(info))


def telemetry_changed(t: Telemetry):
    from backend.client.events import TelemetryReceived

    return incoming(TelemetryReceived(t))


def alert_received(alert: Any):
    from backend.client.events import AlertRaised

    return incoming(AlertRaised(alert))


def account_known(read_only: str = ""):
    from console.state.changes import AccountKnown

    return incoming(AccountKnown(read_only))


def connection_changed(status: str, endpoint: str | None = ENDPOINT) -> list[Any]:
    """What the app gets as its link to the server reaches `status`:
    connecting (the app says it), then the client's own word."""
    from backend.client.events import ConnectionState
    from console.state.changes import Connecting

    out = [incoming(Connecting(endpoint))] if endpoint is not None else []
    if status in ("connected", "reconnecting"):
        out.append(incoming(ConnectionState(status)))
    return out


def link_state(status: str):
    """The client's word on its link: "connected" (after a resync) or "reconnecting"."""
    from backend.client.events import ConnectionState

    return incoming(ConnectionState(status))


def map_fed(mirror: Any, update: Any, speed: float | None = None):
    """The simulator's map feed moved (the bridge's, as the map follower says)."""
    from console.state.changes import MapFed

    return incoming(MapFed(mirror, update, speed))


def post_all(app: Any, *messages: Any) -> None:
    for m in messages:
        for one in m if isinstance(m, list) else [m]:
            app.post_message(one)


# -- driving the app -------------------------------------------------------------------


def make_app(**kw: Any):
    """A MissionApp for tests: no animations, no cursor blink; offline, its
    clock at T0 (injected states are stamped T0: how old a robot's state is,
    and so what the schedule shows, must not depend on when the test runs;
    a live one keeps the real clock, as the server's stamps do)."""
    from console.app import MissionApp

    app = MissionApp(**kw)
    app.animation_level = "none"
    app.cursor_blink = False
    if not kw.get("connect"):
        app.clock = lambda: T0
    return app


def engine_app(builder: Builder) -> tuple[Any, EngineBackend]:
    """A test app whose operations go to `builder`'s rules engine (and back)."""
    backend = EngineBackend(builder)
    app = make_app(backend=backend)
    backend.app = app
    return app, backend


async def inject(
    app: Any,
    pilot: Any,
    builder: Builder | None,
    *,
    online: dict[str, bool] | None = None,
    telemetry: list[Telemetry] | None = None,
    connection: str = "connected",
) -> None:
    """Post the events the live connection would deliver; wait until shown."""
    post_all(app, connection_changed(connection))
    if builder is not None:
        app.post_message(
            state_loaded(
                builder.snapshot(),
                builder.library,
                fleet(online if online is not None else MARS_FLEET),
            )
        )
    for t in telemetry or []:
        app.post_message(telemetry_changed(t))
    await settle(pilot)


async def settle(pilot: Any) -> None:
    """Until what was posted is shown: the app takes each event, then every
    screen its change (a hop each), then what their redraws started."""
    for _ in range(3):
        await pilot.pause()


def screen_text(app: Any) -> str:
    """What the terminal shows now, as plain text lines."""
    strips = app.screen._compositor.render_strips()
    return "\n".join("".join(seg.text for seg in strip) for strip in strips)


async def wait_until(
    pilot: Any, predicate: Any, timeout: float = 10.0, what: str = "condition"
) -> None:
    """Let the app run until `predicate()` holds (bounded): no sleeps as sync."""
    import time as _time

    deadline = _time.monotonic() + timeout
    while not predicate():
        if _time.monotonic() > deadline:
            raise AssertionError(
                f"timed out after {timeout:g} s waiting for {what} "
                f"(focused: {pilot.app.focused!r})\n--- screen ---\n{screen_text(pilot.app)}"
            )
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


# -- part 2: manifests, telemetry history, a pinned clock ----------------------------------


def manifest(name: str, type_: str, skills: list[str], modules: dict[str, str], **props: Any):
    from backend.protocol.messages import Manifest, Module

    return Manifest(
        name=name,
        type=type_,
        modules=[Module(name=m, version=v) for m, v in modules.items()],
        properties=props,
        skills=dict.fromkeys(skills, "1.0.0"),
    )


def mars_fleet_with_manifests() -> dict[str, RobotInfo]:
    """lru1, lru2 and the lander registered (manifests); ardea offline, never registered."""
    b = Builder(MARS)
    lib = b.library
    out = {
        "lru1": RobotInfo(
            name="lru1",
            online=True,
            since=T0,
            manifest=manifest(
                "lru1",
                "lru_science",
                lib.skills_of("lru_science"),
                {"nav": "2.1.0", "science_cam": "1.4.2"},
                max_speed=1.0,
                simulated=True,
                capabilities=["science_camera"],
            ),
        ),
        "lru2": RobotInfo(
            name="lru2",
            online=True,
            since=T0,
            manifest=manifest(
                "lru2",
                "lru_manipulator",
                lib.skills_of("lru_manipulator"),
                {"nav": "2.1.0", "arm": "0.9.3"},
                payload_kg=5,
            ),
        ),
        "ardea": RobotInfo(name="ardea", online=False, since=T0),
        "lander": RobotInfo(
            name="lander",
            online=True,
            since=T0,
            manifest=manifest("lander", "lander", lib.skills_of("lander"), {"shelf": "1.0.0"}),
        ),
    }
    return out


def telemetry_series() -> list[Telemetry]:
    """A few samples per robot, so the sparklines have a shape."""
    out = []
    for i in range(10):
        out.append(
            Telemetry(
                robot="lru1",
                battery=0.95 - 0.03 * i,
                link=0.9 - 0.05 * (i % 4),
                mode="executing",
                skill="lru1-2",
                progress=0.45,
                at=T0,
            )
        )
        out.append(
            Telemetry(
                robot="lru2",
                battery=0.70 - 0.02 * i,
                link=0.6 + 0.04 * i,
                mode="waiting at barrier",
                skill="lru2-3",
                at=T0,
            )
        )
        out.append(Telemetry(robot="lander", battery=1.0, link=1.0, at=T0))
    return out


def pin_clock(app: Any) -> None:
    """The event log and alerts stamp entries with app.clock(): make it fixed."""
    app.clock = lambda: T0


CONSOLE_A = "host-4711-a1b2c3"  # a client id, like MissionClient makes them


async def awareness_scenario(app: Any, pilot: Any) -> Builder:
    """A small history with every kind of log entry and alert, at T0:
    an operator's edit and sync, robot reports (one failure, alerted by the
    server), the console's own refusal, a robot going offline, low battery
    and out of range (the server's alerts)."""
    from backend.core.ops import EditSkill
    from backend.protocol.messages import Alert

    pin_clock(app)
    b = Builder(MARS)
    post = app.post_message
    post_all(app, connection_changed("connected"))
    post(state_loaded(b.snapshot(), b.library, mars_fleet_with_manifests()))
    for t in telemetry_series():
        post(telemetry_changed(t))
    await pilot.pause()

    def op(applied, actor: str, name: str) -> None:
        post(applied_batch(applied.batch(actor, name)))

    e = b.engine
    op(e.submit(EditSkill(id="lru2-2", label="find a good stone")), f"ada@{CONSOLE_A}", "edit")
    for robot, through in (("lru1", "lru1-2"), ("lru2", "lru2-2")):
        ids = [s.id for s in e.plan_sync(Sync(robot=robot, through=through))]
        try:
            op(e.submit(SyncAck(robot=robot, ids=ids)), f"ada@{CONSOLE_A}", "sync_ack")
        finally:
            e.release(robot, ids)
    seq = {"lru1": 0, "lru2": 0}

    def report(robot: str, sid: str, status: str, info: str = "") -> None:
        seq[robot] += 1
        op(
            e.submit(Report(robot=robot, seq=seq[robot], id=sid, status=status, info=info, at=T0)),
            robot,
            "report",
        )

    report("lru1", "lru1-1", "running")
    report("lru2", "lru2-1", "running")
    report("lru2", "lru2-1", "success")
    report("lru2", "lru2-2", "running")
    report("lru2", "lru2-2", "failure", "no stone in reach")
    await pilot.pause()
    post(
        alert_received(
            Alert(
                id=1,
                level="error",
                kind="failure",
                robot="lru2",
                skill="lru2-2",
                message="lru2: lru2-2 failed: no stone in reach",
                at=T0,
            )
        )
    )
    app.ops.refused("Run refused: [lru1] lru1 is already executing lru1-1 (running)", "lru1", None)
    post(fleet_changed(RobotInfo(name="lander", online=False, since=T0)))
    post(
        alert_received(
            Alert(
                id=2,
                level="warning",
                kind="offline",
                robot="lander",
                message="robot lander went offline",
                at=T0,
            )
        )
    )
    post(
        telemetry_changed(
            Telemetry(
                robot="lru1",
                battery=0.66,
                link=0.2,
                in_range=False,
                mode="executing",
                skill="lru1-1",
                at=T0,
            )
        )
    )
    post(telemetry_changed(Telemetry(robot="lru2", battery=0.15, link=0.9, mode="idle", at=T0)))
    # the server's alerts from that telemetry (backend/server/telemetry.py)
    post(
        alert_received(
            Alert(
                id=3,
                kind="out_of_range",
                robot="lru1",
                message="lru1 is out of communication range",
                at=T0,
            )
        )
    )
    post(
        alert_received(
            Alert(
                id=4,
                kind="low_battery",
                robot="lru2",
                message="lru2: battery low (15 % < 20 %)",
                at=T0,
            )
        )
    )
    # every message handled (under load a pause or two is not enough)
    await wait_until(
        pilot,
        lambda: (
            len(app.event_log.entries) == 12
            and len(app.alerts.alerts) == 5
            and app.alerts.alerts[-1].kind == "low_battery"
            and app.model.robots["lander"].online is False
        ),
        what="the scenario's messages handled",
    )
    await pilot.pause()
    return b
