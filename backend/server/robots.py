"""The server's link to its robots: registration, presence, the commands of
robot operations and their replies, reports and their acknowledgements.

Everything robot-facing lives in `RobotLink`. The server gives it a host
(`LinkHost`: the engine, journaled submission, alerts, fleet publication)
and asks it for three things: declare its queryables on the session, apply
a robot operation (`ROBOT_OPS`), and the robots' presence (`robots`).

One robot's commands, registrations and report batches take turns
(`RobotTurn`): a command holds the skills it sends locked until the robot
answers, and what the robot reported meanwhile is applied after it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Iterable
from datetime import UTC, datetime
from typing import Any, NamedTuple, Protocol

from pydantic import ValidationError

from backend.core.limits import echo
from backend.core.model import Mission
from backend.core.ops import (
    Control,
    Reconcile,
    Report,
    Retry,
    RetryAck,
    Sync,
    SyncAck,
    Unsync,
    UnsyncDone,
)
from backend.core.rules.engine import Applied, Engine, Refusal
from backend.protocol.keys import PROTOCOL_VERSION, Keys
from backend.protocol.messages import (
    BarrierInfo,
    CommandReply,
    Dequeue,
    Enqueue,
    ErrorReply,
    Manifest,
    Pause,
    Register,
    RegisterReply,
    ReportAck,
    ReportBatch,
    RobotInfo,
    Run,
    Stop,
    dumps,
)
from backend.protocol.messages import Reset as ResetCmd
from backend.protocol.wire import parse
from backend.server.refusals import Handler, JournalFailed
from backend.transport import (
    NoResponder,
    QueryError,
    QueryTimeout,
    query,
    serve_async,
    watch_liveliness,
)

COMMANDS = {"run": Run, "pause": Pause, "stop": Stop, "reset": ResetCmd}
# operations the server applies only once their robot answered
ROBOT_OPS = (Sync, Unsync, Control, Retry)


def _now() -> datetime:
    return datetime.now(UTC)


def _major(version: str) -> str:
    return version.split(".", 1)[0]


class LinkHost(Protocol):
    """What the robot link needs from the server."""

    engine: Engine | None

    def submit(
        self, op: Any, *, client: str = "", request_id: str | None = None, actor: str = ""
    ) -> Applied:
        """Apply an operation: journaled, then published (JournalFailed if
        the journal cannot take it)."""
        ...

    def alert(
        self,
        message: str,
        *,
        level: str = "warning",
        robot: str | None = None,
        skill: str | None = None,
        kind: str = "",
    ) -> None: ...

    def publish_fleet(self, info: RobotInfo) -> None: ...


class Origin(NamedTuple):
    """Who asked for a robot operation: its acknowledgement is journaled with it."""

    actor: str
    client: str = ""
    request_id: str | None = None


class RobotLink:
    def __init__(self, host: LinkHost, *, command_timeout: float) -> None:
        self._host = host
        self.command_timeout = command_timeout
        self.robots: dict[str, RobotInfo] = {}  # presence and manifest, by name
        self._turns: dict[str, RobotTurn] = {}
        self._session: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ops: dict[type, Callable[[Any, Origin], Awaitable[Applied]]] = {
            Sync: self._sync,
            Unsync: self._unsync,
            Retry: self._retry,
            Control: self._control,
        }

    # -- the server's side ------------------------------------------------------------
    def declare(self, session: Any, guard: Callable[[Handler], Handler]) -> list[Any]:
        """The link's queryables and presence watch on the server's session
        (on the event loop); `guard` turns refusals into error replies."""
        self._session = session
        self._loop = asyncio.get_running_loop()
        return [
            serve_async(session, Keys.register("*"), guard(self._handle_register), with_key=True),
            serve_async(session, Keys.reports("*"), guard(self._handle_reports), with_key=True),
            watch_liveliness(session, Keys.ALL_ALIVE, self._on_presence),
        ]

    def close(self) -> None:
        self._session = None

    def add_robots(self, names: Iterable[str]) -> None:
        """The robots of a (new) mission not known yet: offline until they register."""
        for name in names:
            if name not in self.robots:
                self._set_robot(RobotInfo(name=name))

    async def apply(
        self, op: Any, *, actor: str, client: str = "", request_id: str | None = None
    ) -> Applied:
        """Send a robot operation to its robot(s); journal the acknowledgement
        with the request id, so a retry after a server restart is a duplicate."""
        try:
            return await self._ops[type(op)](op, Origin(actor, client, request_id))
        except JournalFailed as f:
            raise Refusal(
                f.code,
                f"{f.message}. The robot did get the {op.op} command: once the journal works, "
                "compare `missionctl ctl state` with the robot and unsync or stop what differs",
            ) from None

    @property
    def _engine(self) -> Engine:
        engine = self._host.engine
        assert engine is not None
        return engine

    @property
    def _mission(self) -> Mission:
        return self._engine.mission

    def _ack(self, op: Any, origin: Origin) -> Applied:
        return self._host.submit(
            op, client=origin.client, request_id=origin.request_id, actor=origin.actor
        )

    # -- robot operations -------------------------------------------------------------
    async def _sync(self, op: Sync, origin: Origin) -> Applied:
        e = self._engine
        async with self._turn(op.robot):
            skills = e.plan_sync(op)
            ids = [s.id for s in skills]
            try:
                self._check_manifest(op.robot, skills)
                await self._command(
                    op.robot, Enqueue(skills=skills, barriers=self._barriers(skills))
                )
                return self._ack(SyncAck(robot=op.robot, ids=ids), origin)
            finally:
                e.release(op.robot, ids)

    def _barriers(self, skills: list[Any]) -> dict[str, BarrierInfo]:
        """The barriers of the skills sent, with the partners the robot waits for."""
        e = self._engine
        barriers = {}
        for s in skills:
            partners = e.barrier_partners(s.id)
            if partners:
                barriers[s.id] = BarrierInfo(
                    barrier=e.mission.barrier_of(s.id), partners=dict(partners)
                )
        return barriers

    async def _unsync(self, op: Unsync, origin: Origin) -> Applied:
        e = self._engine
        async with self._turn(op.robot):
            ids = e.plan_unsync(op)
            try:
                reply = await self._command(op.robot, Dequeue(ids=ids))
                applied = self._ack(UnsyncDone(robot=op.robot, ids=reply.ids), origin)
            finally:
                e.release(op.robot)
            if reply.kept:
                applied.notes.append(
                    f"{op.robot} had already started {', '.join(reply.kept)}: it stays synchronized"
                )
            applied.value["kept"] = list(reply.kept)
            return applied

    async def _retry(self, op: Retry, origin: Origin) -> Applied:
        e = self._engine
        found = e.mission.find(op.id)
        robot = found[0] if found else ""
        async with self._turn(robot or "?"):
            new = e.plan_retry(op)
            try:
                self._check_manifest(robot, [new])
                await self._command(robot, Enqueue(skills=[new], front=True))
                return self._ack(RetryAck(robot=robot, failed_id=op.id, skill=new), origin)
            finally:
                e.release(robot)

    async def _control(self, op: Control, origin: Origin) -> Applied:
        """run / pause / stop / reset, for one robot or all."""
        e = self._engine
        robots = e.plan_control(op)
        results: dict[str, str] = {}
        last = e.mission.revision
        try:
            for robot in robots:
                try:
                    last = await self._control_one(robot, op, origin.actor, last)
                    results[robot] = "ok"
                except Refusal as r:
                    if op.robot is not None:
                        raise
                    results[robot] = r.message
        finally:
            for robot in robots:
                if op.op == "reset":
                    e.release(robot)
        failed = {r: m for r, m in results.items() if m != "ok"}
        if failed and len(failed) == len(results):
            raise Refusal(
                "robot_unreachable", f"{op.op} reached no robot: " + "; ".join(failed.values())
            )
        notes = [f"{op.op} not applied: {m}" for m in failed.values()]
        return Applied(max(last, e.mission.revision), [], notes, {"robots": results})

    async def _control_one(self, robot: str, op: Control, actor: str, last: int) -> int:
        """One robot's run/pause/stop/reset; returns the last revision (a
        reset's robot gives back its queue: its skills return to the plan)."""
        async with self._turn(robot):
            reply = await self._command(robot, COMMANDS[op.op]())
            if op.op == "reset" and reply.ids:
                return self._host.submit(
                    UnsyncDone(robot=robot, ids=reply.ids), actor=actor
                ).revision
        return last

    # -- commands ---------------------------------------------------------------------
    def _turn(self, robot: str) -> RobotTurn:
        turn = self._turns.get(robot)
        if turn is None:
            turn = self._turns[robot] = RobotTurn()
        return turn

    async def _command(self, robot: str, cmd: Any) -> CommandReply:
        """Send a command to a robot agent; refusals say which robot and why.
        Reports the robot made before answering are applied first."""
        info = self.robots.get(robot)
        if info is None or not info.online:
            since = f" since {info.since:%H:%M:%S}" if info and info.since else ""
            raise Refusal(
                "robot_offline",
                f"robot {robot} is not connected{since}: nothing was sent",
                robot=robot,
            )
        try:
            raw = await query(self._session, Keys.command(robot), dumps(cmd), self.command_timeout)
        except QueryError as e:
            raise _refused(robot, e.payload) from None
        except QueryTimeout:
            raise Refusal(
                "robot_timeout",
                f"{robot} did not answer within {self.command_timeout:g} s (out of reach?): "
                "the mission is unchanged; if the robot got the command anyway, sending it "
                "again is safe",
                robot=robot,
            ) from None
        except NoResponder:
            raise Refusal(
                "robot_offline",
                f"robot {robot} does not answer commands: nothing was sent",
                robot=robot,
            ) from None
        reply = parse(CommandReply, raw)
        self._apply_reports(robot, reply.reports)
        if not reply.ok:
            raise Refusal("robot_refused", f"{robot} refused: {reply.reason}", robot=robot)
        return reply

    def _check_manifest(self, robot: str, skills: list[Any]) -> None:
        info = self.robots[robot]
        if not info.online or info.manifest is None:
            since = (
                f" (offline since {info.since:%H:%M:%S})"
                if info.since
                else " (not seen since the server started)"
            )
            raise Refusal(
                "robot_offline",
                f"robot {robot} is not connected{since}: nothing was sent",
                robot=robot,
            )
        for s in skills:
            why = _incompatible(
                info.manifest, s.skill, self._engine.library.skills[s.skill].version
            )
            if why:
                raise Refusal(
                    "incompatible",
                    f"{robot} {why}; {s.id} stays unsynchronized",
                    robot=robot,
                    skill=s.id,
                )

    # -- registration and reports ----------------------------------------------------
    def _robot_from(self, name: str) -> None:
        if name not in self._mission.robots:
            raise Refusal(
                "unknown_robot",
                f"robot '{name}' is not part of this mission "
                f"(robots: {', '.join(self._mission.robots)})",
                robot=name,
            )

    async def _handle_register(self, payload: bytes, key: str) -> bytes:
        reg = parse(Register, payload)
        m = reg.manifest
        if m.name != Keys.robot_of(key):  # the key is what the router's rules check
            raise Refusal(
                "bad_register", f"robot '{m.name}' cannot register on {key}", robot=m.name
            )
        refused = self._not_registrable(m)
        if refused:
            return dumps(RegisterReply(accepted=False, reason=refused))
        info = self.robots[m.name]
        info = info.model_copy(
            update={"manifest": m, "online": True, "since": info.since if info.online else _now()}
        )
        self._set_robot(info)
        # after a command in flight to this robot (see _handle_reports): its
        # queue and reports may already hold what that command sent it
        async with self._turn(m.name):
            self._apply_reports(m.name, reg.reports)
            lost = self._reconcile(m.name, {q.id for q in reg.queue})
        return dumps(
            RegisterReply(
                accepted=True, last_seq=self._mission.report_seqs.get(m.name, 0), missing=lost
            )
        )

    def _not_registrable(self, m: Manifest) -> str | None:
        """Why a robot with manifest `m` cannot register (None: it can)."""
        if m.protocol != PROTOCOL_VERSION:
            return f"protocol {m.protocol} is not supported (server speaks {PROTOCOL_VERSION})"
        if m.name not in self._mission.robots:
            return f"robot '{m.name}' is not part of this mission"
        expected = self._mission.robots[m.name].type
        if m.type != expected:
            return f"robot '{m.name}' is a {expected} in this mission, not a {m.type}"
        return None

    def _reconcile(self, robot: str, robot_has: set[str]) -> list[str]:
        """After a restart on either side: skills the mission holds as on the
        robot but the robot does not have go back to the plan (returned)."""
        task = self._mission.tasks.get(robot, [])
        held = [s.id for s in task if s.status.value not in ("idle", "success", "failure")]
        lost = [sid for sid in held if sid not in robot_has]
        if lost:
            try:
                self._host.submit(Reconcile(robot=robot, lost=lost), actor=robot)
                self._host.alert(
                    f"{robot} no longer had {', '.join(lost)}: returned to the plan",
                    robot=robot,
                    kind="reconcile",
                )
            except JournalFailed:
                raise  # the registration fails: the robot registers again
            except Refusal as r:
                self._host.alert(
                    f"cannot reconcile {robot}: {r.message}",
                    level="error",
                    robot=robot,
                    kind="reconcile",
                )
                return []
        return lost

    def _apply_reports(self, robot: str, reports: list[Report]) -> list[ErrorReply]:
        refused = []
        for rep in sorted(reports, key=lambda r: r.seq):
            if rep.robot != robot:
                refused.append(
                    ErrorReply(
                        code="bad_report",
                        message=f"{robot} cannot report for {rep.robot}",
                        robot=robot,
                    )
                )
                continue
            error = self._apply_report(robot, rep)
            if error is not None:
                refused.append(error)
        return refused

    def _apply_report(self, robot: str, rep: Report) -> ErrorReply | None:
        """One report of `robot`'s; a refusal is returned (and alerted)."""
        try:
            applied = self._host.submit(rep, actor=robot)
        except JournalFailed:
            raise  # not consumed: the robot keeps it and sends it again
        except Refusal as r:
            self._host.alert(
                f"report refused: {r.message}",
                level="error",
                robot=robot,
                skill=rep.id,
                kind="report_refused",
            )
            return ErrorReply(**r.to_dict())
        if not applied.duplicate and rep.status.value == "failure":
            self._host.alert(
                f"{robot}: {rep.id} failed: {rep.info}",
                level="error",
                robot=robot,
                skill=rep.id,
                kind="failure",
            )
        return None

    def _handle_reports(self, payload: bytes, key: str) -> bytes | Awaitable[bytes]:
        batch = parse(ReportBatch, payload)
        robots = {r.robot for r in batch.reports}
        if len(robots) > 1:
            raise Refusal("bad_report", "a report batch comes from one robot")
        if robots and robots != {Keys.robot_of(key)}:  # the key is what the router's rules check
            raise Refusal(
                "bad_report", f"{Keys.robot_of(key)} cannot report for {', '.join(robots)}"
            )
        robot = robots.pop() if robots else ""
        if robot:
            self._robot_from(robot)
        # after the robot's command in flight, if any: a robot in run mode starts
        # a skill it was just sent and may report it before its reply to the
        # enqueue arrives; applied before the SyncAck, `running` would be refused.
        # Always in the robot's turn, in arrival order with its registration and
        # other batches: a later sequence number applied first would make the
        # earlier one a duplicate. With nobody in or waiting for the turn (the
        # usual case), at once: no task, ~4 % off a lone report's round trip
        turn = self._turn(robot or "?")
        if turn.free:
            return self._report_ack(robot, batch, self._apply_reports(robot, batch.reports))
        return self._reports_in_turn(turn, robot, batch)

    async def _reports_in_turn(self, turn: RobotTurn, robot: str, batch: ReportBatch) -> bytes:
        async with turn:
            refused = self._apply_reports(robot, batch.reports)
        return self._report_ack(robot, batch, refused)

    def _report_ack(self, robot: str, batch: ReportBatch, refused: list[ErrorReply]) -> bytes:
        # refused reports are consumed too: the robot must not send them again
        last = max([self._mission.report_seqs.get(robot, 0), *(r.seq for r in batch.reports)])
        return dumps(ReportAck(last_seq=last, refused=refused))

    # -- presence ---------------------------------------------------------------------
    def _set_robot(self, info: RobotInfo) -> None:
        self.robots[info.name] = info
        self._host.publish_fleet(info)

    def _on_presence(self, key: str, alive: bool) -> None:
        if self._loop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._presence, Keys.robot_of(key), alive)

    def _presence(self, robot: str, alive: bool) -> None:
        info = self.robots.get(robot)
        if info is None or info.online == alive:
            return
        # online again once it registers (with its manifest and queue)
        if not alive:
            self._set_robot(info.model_copy(update={"online": False, "since": _now()}))
            self._host.alert(f"robot {robot} went offline", robot=robot, kind="offline")


class RobotTurn:
    """One robot's turn: its commands, registrations and report batches, one
    at a time in arrival order (`async with`). Unlike `asyncio.Lock.locked()`,
    `free` is also False while a released turn's next waiter has not run yet."""

    def __init__(self) -> None:
        self._lock = asyncio.Lock()
        self._users = 0  # in the turn or waiting for it

    @property
    def free(self) -> bool:
        return self._users == 0

    async def __aenter__(self) -> None:
        self._users += 1
        try:
            await self._lock.acquire()
        except BaseException:  # cancelled while waiting
            self._users -= 1
            raise

    async def __aexit__(self, *exc: object) -> None:
        self._lock.release()
        self._users -= 1


def _refused(robot: str, payload: bytes) -> Refusal:
    """A robot's error reply to a command, as a refusal that names it once."""
    try:
        err = parse(ErrorReply, payload)
    except ValidationError:
        return Refusal(
            "robot_error", f"{robot} refused: {echo(payload.decode(errors='replace'))}", robot=robot
        )
    # its own sentence may already start with its name
    text = err.message if err.message.startswith(robot) else f"{robot}: {err.message}"
    return Refusal(err.code, text, robot=robot)


def _incompatible(manifest: Manifest, skill: str, want: str) -> str | None:
    """Why a robot with `manifest` cannot run `skill` at version `want`."""
    have = manifest.skills.get(skill)
    if have is None:
        offered = ", ".join(manifest.skills) or "none"
        return f"does not offer skill '{skill}' (its manifest lists: {offered})"
    if _major(have) != _major(want):
        return f"implements {skill} {have}, the library needs {want} (major versions differ)"
    return None
