"""The mission server: a Zenoh router hosting the rules, the journal and the
link to the robots.

All mission state lives on one asyncio loop: Zenoh callbacks only hand
queries to it (transport.serve_async), so the engine is never touched from
two threads. An operation that needs no robot is applied and answered in the
loop callback that received it; operations involving a robot are serialized
per robot and hold the skills they send locked until the robot answers.
"""

from __future__ import annotations

import asyncio
import inspect
import itertools
import logging
import sqlite3
import uuid
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from backend.core.events import EventBatch
from backend.core.library import Library
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
from backend.files.missions import library_path, load_library, load_mission
from backend.protocol.keys import PROTOCOL_VERSION, Keys
from backend.protocol.messages import (
    AccountInfo,
    Alert,
    BarrierInfo,
    CommandReply,
    Dequeue,
    Enqueue,
    ErrorReply,
    FleetEvent,
    OpReply,
    Pause,
    Register,
    RegisterReply,
    ReportAck,
    ReportBatch,
    Request,
    RobotInfo,
    Run,
    StateSnapshot,
    Stop,
    dumps,
    first_error,
)
from backend.protocol.messages import Reset as ResetCmd
from backend.server.accounts import Accounts, zenoh_dictionary
from backend.server.acl import acl_config
from backend.server.journal import Journal, JournalError, remember_requests
from backend.transport import (
    NoResponder,
    QueryError,
    QueryTimeout,
    declare_publisher,
    declare_token,
    query,
    router_config,
    serve,
    serve_async,
    watch_liveliness,
)
from backend.transport import Refusal as ReplyErr
from backend.transport.session import close_session, open_session

log = logging.getLogger(__name__)

COMMANDS = {"run": Run, "pause": Pause, "stop": Stop, "reset": ResetCmd}
# operations the server applies only once their robot answered
ROBOT_OPS = (Sync, Unsync, Control, Retry)


def _now() -> datetime:
    return datetime.now(UTC)


def _major(version: str) -> str:
    return version.split(".", 1)[0]


class MissionServer:
    def __init__(
        self,
        *,
        db: str | Path,
        mission_file: str | Path | None = None,
        listen: list[str] | None = None,
        zenoh_extra: dict[str, Any] | None = None,
        command_timeout: float = 10.0,
        accounts: Accounts | None = None,
    ):
        self.db = Path(db)
        self.mission_file = Path(mission_file) if mission_file else None
        self.listen = listen or ["tcp/127.0.0.1:7447"]
        self.zenoh_extra = zenoh_extra
        self.command_timeout = command_timeout
        self.accounts = accounts  # None: no logins, anyone reaching the router may do anything
        self.server_id = uuid.uuid4().hex[:12]
        self.robots: dict[str, RobotInfo] = {}
        self.engine: Engine | None = None
        self.journal: Journal | None = None
        self.library_file: Path | None = None
        self.resumed = False
        self._session = None
        self._entities: list[Any] = []
        self._turns: dict[str, RobotTurn] = {}
        self._inflight: dict[tuple[str, str], asyncio.Future] = {}
        self._events_pub = None
        self._fleet_pub = None
        self._alerts_pub = None
        self._outbox: list[
            tuple[Any, bytes]
        ] = []  # publications waiting for the next loop callback
        self._loop: asyncio.AbstractEventLoop | None = None
        self._journal_failing = False
        self._checkpoint: asyncio.Future | None = None  # the journal's, running on a thread
        self._checkpoint_failing = False

    # -- start / stop ---------------------------------------------------------
    def _load(self) -> None:
        """Resume from the journal, or start it from the mission file."""
        journal = Journal.open(self.db)
        try:
            mission, requests = journal.load()
            if mission is not None:
                lib_file = Path(journal.library) if journal.library else None
                if lib_file is None and self.mission_file is not None:
                    lib_file = library_path(self.mission_file, mission.library)
                if lib_file is None:
                    raise SystemExit(
                        f"{self.db}: the journal does not say which skill library it uses"
                    )
                library = load_library(lib_file)
                self.resumed = True
            else:
                if self.mission_file is None:
                    raise SystemExit(
                        f"{self.db} is empty: give a mission file to start from (--mission FILE)"
                    )
                mission, library = load_mission(self.mission_file)
                lib_file = library_path(self.mission_file, mission.library)
                journal.close()
                journal = Journal.open(self.db, library=str(lib_file))
                try:
                    journal.snapshot(mission)
                except sqlite3.Error as e:  # e.g. a full disk
                    raise JournalError(
                        f"{self.db}: cannot write the journal's first snapshot: {e}"
                    ) from None
                requests = []
        except BaseException:
            journal.close()
            raise
        self.journal = journal
        journal.checkpoint_in_background()  # see _maybe_checkpoint
        self.library_file = lib_file
        self.engine = Engine(mission, library)
        remember_requests(self.engine, requests)
        for name in mission.robots:
            self.robots[name] = RobotInfo(name=name, online=False, since=None)

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._load()
        try:
            self._session = await self._open_router()
        except BaseException:
            self.journal.close()
            raise
        s = self._session
        self._events_pub = declare_publisher(s, Keys.EVENTS)
        self._fleet_pub = declare_publisher(s, Keys.FLEET)
        self._alerts_pub = declare_publisher(s, Keys.ALERTS)
        self._entities += [
            serve_async(s, Keys.OP, self._guard(self._handle_op)),
            serve_async(s, Keys.STATE, self._guard(self._handle_state)),
            serve_async(s, Keys.op_as("*"), self._guard(self._handle_op), with_key=True),
            serve_async(s, Keys.account("*"), self._guard(self._handle_account), with_key=True),
            serve_async(s, Keys.register("*"), self._guard(self._handle_register), with_key=True),
            serve_async(s, Keys.reports("*"), self._guard(self._handle_reports), with_key=True),
            watch_liveliness(s, Keys.ALL_ALIVE, self._on_presence),
            # trivial, answered on the Zenoh thread: the raw-transport baseline of benchmarks
            serve(s, Keys.PING, lambda _payload: b"pong"),
        ]
        # declared last: robots (re)register when they see it
        self._entities.append(declare_token(s, Keys.SERVER_ALIVE))

    async def _open_router(self):
        """The router session; with accounts, user/password logins and the
        access-control rules of their roles (the dictionary file Zenoh reads
        exists only while the session opens)."""
        extra = dict(self.zenoh_extra or {})
        if self.accounts is None:
            return await asyncio.to_thread(
                open_session, router_config(self.listen, extra=extra), what="the listen endpoint"
            )
        mtls = bool(extra.get("transport/link/tls/enable_mtls"))
        extra["access_control"] = acl_config(self.accounts, cert_names=mtls)
        with zenoh_dictionary(self.accounts) as dictionary:
            extra["transport/auth/usrpwd/dictionary_file"] = dictionary
            cfg = router_config(self.listen, extra=extra)
            return await asyncio.to_thread(open_session, cfg, what="the listen endpoint")

    async def stop(self) -> None:
        self._entities.clear()
        session, self._session = self._session, None
        if session is not None:
            await asyncio.to_thread(close_session, session)
        while self._checkpoint is not None:  # the journal closes after it
            await asyncio.wait([self._checkpoint])
        if self.journal is not None:
            self.journal.close()
            self.journal = None

    async def __aenter__(self) -> MissionServer:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    @property
    def mission(self) -> Mission:
        assert self.engine is not None
        return self.engine.mission

    @property
    def library(self) -> Library:
        assert self.engine is not None
        return self.engine.library

    # -- plumbing -------------------------------------------------------------
    def _guard(
        self, handler: Callable[..., bytes | Awaitable[bytes]]
    ) -> Callable[..., bytes | Awaitable[bytes]]:
        """Bad input and refusals become an ErrorReply; nothing else escapes.
        The handler answers at once (bytes) or later (an awaitable)."""

        def run(*args: Any) -> bytes | Awaitable[bytes]:
            try:
                result = handler(*args)
            except (Refusal, ValidationError) as e:
                raise _error(e) from None
            return self._guarded(result) if inspect.isawaitable(result) else result

        return run

    async def _guarded(self, pending: Awaitable[bytes]) -> bytes:
        try:
            return await pending
        except (Refusal, ValidationError) as e:
            raise _error(e) from None

    def _commit(self, applied: Applied, op: Any, *, actor: str) -> None:
        """Publish an applied (and journaled) operation; snapshot when due."""
        if applied.duplicate or not applied.events:
            return
        try:
            self.journal.maybe_snapshot(self.mission)
        except (
            sqlite3.Error,
            OSError,
            JournalError,
        ) as e:  # the batches have it: only a slower restart
            log.warning(
                "%s: cannot store a snapshot (%s); will try again at the next operation", self.db, e
            )
        self._maybe_checkpoint()
        batch = EventBatch(revision=applied.revision, events=applied.events, actor=actor, op=op.op)
        self._publish(self._events_pub, batch.model_dump_json().encode())
        if any(e.ev == "mission_replaced" for e in applied.events):
            for name in self.mission.robots:  # a loaded mission may name other robots
                if name not in self.robots:
                    self._set_robot(RobotInfo(name=name))

    def _maybe_checkpoint(self) -> None:
        """The journal's checkpoint (its log copied into the file, with an
        fsync) runs on a thread: inside a commit it held up one operation
        in ~400 for 4-17 ms."""
        if self._checkpoint is None and self.journal.checkpoint_due:
            self._checkpoint = self._loop.run_in_executor(None, self.journal.checkpoint)
            self._checkpoint.add_done_callback(self._checkpointed)

    def _checkpointed(self, done: asyncio.Future) -> None:
        self._checkpoint = None
        error = None if done.cancelled() else done.exception()
        if error is None:
            self._checkpoint_failing = False
        elif not self._checkpoint_failing:  # once, not at every checkpoint
            self._checkpoint_failing = True
            log.warning(
                "%s: cannot checkpoint the journal (%s); nothing is lost, its -wal file grows until "
                "a checkpoint succeeds",
                self.db,
                error,
            )

    def _publish(self, publisher: Any, payload: bytes) -> None:
        """Sent once the request being handled has its reply: the reply and
        the publications share the requester's link, and a reply queued behind
        its own event batch waited for the requester to take in the batch
        first. Publications keep their order."""
        if not self._outbox:
            self._loop.call_soon(self._flush)
        self._outbox.append((publisher, payload))

    def _flush(self) -> None:
        """Send what the last loop callbacks published; event batches of
        several operations handled in a row go out as one message (a JSON
        array): each message costs every client a wake-up of two threads."""
        out, self._outbox = self._outbox, []
        if self._session is None:  # stopped meanwhile: the journal has it, clients resync
            return
        for publisher, run in itertools.groupby(out, key=lambda entry: entry[0]):
            payloads = [payload for _, payload in run]
            if publisher is self._events_pub and len(payloads) > 1:
                payloads = [b"[" + b",".join(payloads) + b"]"]
            for payload in payloads:
                publisher.put(payload)

    def _submit(
        self,
        op: Any,
        *,
        client: str = "",
        request_id: str | None = None,
        actor: str = "",
        expected_revision: int | None = None,
    ) -> Applied:
        """Apply an operation: journaled before it changes the mission, so one
        the journal cannot take is refused (JournalFailed) and changes
        nothing, in memory or at a restart; then published."""
        who = actor or client

        def journal(batch: EventBatch) -> None:
            entry = EventBatch(revision=batch.revision, events=batch.events, actor=who)
            try:
                self.journal.append(
                    entry, op_json=op.model_dump_json(), client=client, request_id=request_id
                )
            except (sqlite3.Error, OSError, JournalError) as e:
                failed = JournalFailed(self.db, e, op.op)
                if not self._journal_failing:  # once, not at every retry of every robot
                    self._journal_failing = True
                    self.alert(failed.message, level="error", kind="journal")
                raise failed from None
            if self._journal_failing:
                self._journal_failing = False
                self.alert(
                    f"the journal {self.db} can be written again", level="info", kind="journal"
                )

        self.engine.before_apply = journal
        try:
            applied = self.engine.submit(
                op, client=client, request_id=request_id, expected_revision=expected_revision
            )
        finally:
            self.engine.before_apply = None
        self._commit(applied, op, actor=who)
        return applied

    def alert(
        self,
        message: str,
        *,
        level: str = "warning",
        robot: str | None = None,
        skill: str | None = None,
        kind: str = "",
    ) -> None:
        log.warning("%s", message)
        if self._alerts_pub is not None:
            a = Alert(level=level, kind=kind, robot=robot, skill=skill, message=message, at=_now())
            self._publish(self._alerts_pub, dumps(a))

    # -- state ------------------------------------------------------------------
    def _handle_state(self, payload: bytes) -> bytes:
        snap = StateSnapshot(
            protocol=PROTOCOL_VERSION,
            server_id=self.server_id,
            revision=self.mission.revision,
            mission=self.mission,
            library=self.library,
            robots=self.robots,
        )
        return snap.model_dump_json().encode()

    # -- operations from consoles and ctl -------------------------------------------
    def _handle_account(self, payload: bytes, key: str) -> bytes:
        user = key.rsplit("/", 1)[-1]
        if self.accounts is None:
            return dumps(AccountInfo(user=user, role="operator", enforced=False))
        role = self.accounts.role(user)
        if role is None:  # the router lets only `user` ask this: unreachable with accounts
            raise Refusal("unknown_account", f"no account '{user}' on this server")
        return dumps(AccountInfo(user=user, role=role, robots=self.accounts.robots(user)))

    def _handle_op(self, payload: bytes, key: str | None = None) -> bytes | Awaitable[bytes]:
        """An operation that needs no robot is applied and answered at once;
        one that waits for a robot's answer is answered when it has it."""
        req = Request.model_validate_json(payload)
        if key is not None:  # op/{user}: the router's rules let only `user` send it
            user = key.rsplit("/", 1)[-1]
            role = self.accounts.role(user) if self.accounts is not None else "operator"
            if (
                role != "operator"
            ):  # the ACL refuses it first; this is the clean answer if it did not
                raise Refusal(
                    "read_only", f"read-only: logged in as {role or 'unknown account'} {user}"
                )
            req = req.model_copy(update={"user": user})
        done = self.engine.requests.get((req.client, req.request_id))
        if done is not None:
            return _reply(Applied(done.revision, [], done.notes, done.value, duplicate=True))
        if not isinstance(req.op, ROBOT_OPS):
            actor = f"{req.user}@{req.client}" if req.user else req.client
            return _reply(
                self._submit(
                    req.op,
                    client=req.client,
                    request_id=req.request_id,
                    actor=actor,
                    expected_revision=req.expected_revision,
                )
            )
        rid = (req.client, req.request_id)
        inflight = self._inflight.get(rid)
        if inflight is not None:  # the same request retried while its robot has not answered
            return asyncio.shield(inflight)
        # registered now, not when the task starts: a retry handed over
        # before that must find it
        fut: asyncio.Future = self._loop.create_future()
        self._inflight[rid] = fut
        return self._robot_request(req, fut)

    async def _robot_request(self, req: Request, fut: asyncio.Future) -> bytes:
        try:
            reply = await self._apply_robot_request(req)
            fut.set_result(reply)
            return reply
        except BaseException as e:
            fut.set_exception(e)
            fut.exception()  # retrieved: no "never retrieved" warning
            raise
        finally:
            del self._inflight[(req.client, req.request_id)]

    async def _apply_robot_request(self, req: Request) -> bytes:
        op = req.op
        actor = f"{req.user}@{req.client}" if req.user else req.client
        if req.expected_revision is not None:
            self.engine.check_fresh(op, req.expected_revision)
        try:
            applied = await self._robot_op(op, actor, req.client, req.request_id)
        except JournalFailed as f:
            raise Refusal(
                f.code,
                f"{f.message}. The robot did get the {op.op} command: once the journal works, "
                "compare `missionctl ctl state` with the robot and unsync or stop what differs",
            ) from None
        self.engine.remember(req.client, req.request_id, applied)
        return _reply(applied)

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
            try:
                err = ErrorReply.model_validate_json(e.payload)
                # name the robot once: its own sentence may already start with its name
                text = err.message if err.message.startswith(robot) else f"{robot}: {err.message}"
                raise Refusal(err.code, text, robot=robot) from None
            except ValidationError:
                raise Refusal(
                    "robot_error",
                    f"{robot} refused: {e.payload.decode(errors='replace')}",
                    robot=robot,
                ) from None
        except QueryTimeout:
            raise Refusal(
                "robot_timeout",
                f"{robot} did not answer within {self.command_timeout:g} s (out of reach?): the mission is unchanged; "
                "if the robot got the command anyway, sending it again is safe",
                robot=robot,
            ) from None
        except NoResponder:
            raise Refusal(
                "robot_offline",
                f"robot {robot} does not answer commands: nothing was sent",
                robot=robot,
            ) from None
        reply = CommandReply.model_validate_json(raw)
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
        manifest = info.manifest
        for s in skills:
            have = manifest.skills.get(s.skill)
            want = self.library.skills[s.skill].version
            if have is None:
                raise Refusal(
                    "incompatible",
                    f"{robot} does not offer skill '{s.skill}' (its manifest lists: {', '.join(manifest.skills) or 'none'}); {s.id} stays unsynchronized",
                    robot=robot,
                    skill=s.id,
                )
            if _major(have) != _major(want):
                raise Refusal(
                    "incompatible",
                    f"{robot} implements {s.skill} {have}, the library needs {want} (major versions differ); {s.id} stays unsynchronized",
                    robot=robot,
                    skill=s.id,
                )

    async def _robot_op(
        self, op: Any, actor: str, client: str = "", request_id: str | None = None
    ) -> Applied:
        """Send the operation to its robot(s); journal the acknowledgement with
        the request id, so a retry after a server restart is a duplicate."""
        e = self.engine
        req = {"client": client, "request_id": request_id, "actor": actor}
        if isinstance(op, Sync):
            async with self._turn(op.robot):
                skills = e.plan_sync(op)
                ids = [s.id for s in skills]
                try:
                    self._check_manifest(op.robot, skills)
                    barriers = {}
                    for s in skills:
                        partners = e.barrier_partners(s.id)
                        if partners:
                            barriers[s.id] = BarrierInfo(
                                barrier=e.mission.barrier_of(s.id), partners=dict(partners)
                            )
                    await self._command(op.robot, Enqueue(skills=skills, barriers=barriers))
                    return self._submit(SyncAck(robot=op.robot, ids=ids), **req)
                finally:
                    e.release(op.robot, ids)
        if isinstance(op, Unsync):
            async with self._turn(op.robot):
                ids = e.plan_unsync(op)
                try:
                    reply = await self._command(op.robot, Dequeue(ids=ids))
                    applied = self._submit(UnsyncDone(robot=op.robot, ids=reply.ids), **req)
                finally:
                    e.release(op.robot)
                if reply.kept:
                    applied.notes.append(
                        f"{op.robot} had already started {', '.join(reply.kept)}: it stays synchronized"
                    )
                applied.value["kept"] = list(reply.kept)
                return applied
        if isinstance(op, Retry):
            found = e.mission.find(op.id)
            robot = found[0] if found else ""
            async with self._turn(robot or "?"):
                new = e.plan_retry(op)
                try:
                    self._check_manifest(robot, [new])
                    await self._command(robot, Enqueue(skills=[new], front=True))
                    return self._submit(RetryAck(robot=robot, failed_id=op.id, skill=new), **req)
                finally:
                    e.release(robot)
        # run / pause / stop / reset, for one robot or all
        robots = e.plan_control(op)
        results: dict[str, str] = {}
        last = e.mission.revision
        try:
            for robot in robots:
                try:
                    async with self._turn(robot):
                        reply = await self._command(robot, COMMANDS[op.op]())
                        if op.op == "reset" and reply.ids:
                            last = self._submit(
                                UnsyncDone(robot=robot, ids=reply.ids), actor=actor
                            ).revision
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

    # -- robots ------------------------------------------------------------------------
    def _robot_from(self, name: str) -> None:
        if name not in self.mission.robots:
            raise Refusal(
                "unknown_robot",
                f"robot '{name}' is not part of this mission (robots: {', '.join(self.mission.robots)})",
                robot=name,
            )

    async def _handle_register(self, payload: bytes, key: str) -> bytes:
        reg = Register.model_validate_json(payload)
        m = reg.manifest
        if m.name != Keys.robot_of(key):  # the key is what the router's rules check
            raise Refusal(
                "bad_register", f"robot '{m.name}' cannot register on {key}", robot=m.name
            )
        if m.protocol != PROTOCOL_VERSION:
            return dumps(
                RegisterReply(
                    accepted=False,
                    reason=f"protocol {m.protocol} is not supported (server speaks {PROTOCOL_VERSION})",
                )
            )
        if m.name not in self.mission.robots:
            return dumps(
                RegisterReply(
                    accepted=False, reason=f"robot '{m.name}' is not part of this mission"
                )
            )
        expected = self.mission.robots[m.name].type
        if m.type != expected:
            return dumps(
                RegisterReply(
                    accepted=False,
                    reason=f"robot '{m.name}' is a {expected} in this mission, not a {m.type}",
                )
            )
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
                accepted=True, last_seq=self.mission.report_seqs.get(m.name, 0), missing=lost
            )
        )

    def _reconcile(self, robot: str, robot_has: set[str]) -> list[str]:
        """After a restart on either side: skills the mission holds as on the
        robot but the robot does not have go back to the plan (returned)."""
        task = self.mission.tasks.get(robot, [])
        held = [s.id for s in task if s.status.value not in ("idle", "success", "failure")]
        lost = [sid for sid in held if sid not in robot_has]
        if lost:
            try:
                self._submit(Reconcile(robot=robot, lost=lost), actor=robot)
                self.alert(
                    f"{robot} no longer had {', '.join(lost)}: returned to the plan",
                    robot=robot,
                    kind="reconcile",
                )
            except JournalFailed:
                raise  # the registration fails: the robot registers again
            except Refusal as r:
                self.alert(
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
            try:
                applied = self._submit(rep, actor=robot)
            except JournalFailed:
                raise  # not consumed: the robot keeps it and sends it again
            except Refusal as r:
                refused.append(ErrorReply(**r.to_dict()))
                self.alert(
                    f"report refused: {r.message}",
                    level="error",
                    robot=robot,
                    skill=rep.id,
                    kind="report_refused",
                )
                continue
            if not applied.duplicate and rep.status.value == "failure":
                self.alert(
                    f"{robot}: {rep.id} failed: {rep.info}",
                    level="error",
                    robot=robot,
                    skill=rep.id,
                    kind="failure",
                )
        return refused

    def _handle_reports(self, payload: bytes, key: str) -> bytes | Awaitable[bytes]:
        batch = ReportBatch.model_validate_json(payload)
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
        last = max([self.mission.report_seqs.get(robot, 0), *(r.seq for r in batch.reports)])
        return dumps(ReportAck(last_seq=last, refused=refused))

    def _set_robot(self, info: RobotInfo) -> None:
        self.robots[info.name] = info
        if self._fleet_pub is not None:
            self._publish(self._fleet_pub, dumps(FleetEvent(robot=info)))

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
            self.alert(f"robot {robot} went offline", robot=robot, kind="offline")


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


class JournalFailed(Refusal):
    """The journal could not take an operation's batch: refused, nothing changed.
    Never taken as a refusal of a robot's report (the robot must send it again)."""

    def __init__(self, db: Path, error: BaseException, what: str):
        why = str(error)
        if isinstance(error, JournalError):  # the file is gone: a new journal is needed
            why = why.removeprefix(f"{db} ")
            todo = "save the mission (`missionctl ctl save FILE`) and restart the server with --mission FILE and a new --db"
        elif "locked" in why or "busy" in why:
            todo = "another program holds the file locked: close it, then send it again"
        elif "full" in why:
            todo = "free disk space, then send it again"
        elif "readonly" in why or "read-only" in why or isinstance(error, PermissionError):
            todo = "make the file writable, then send it again"
        else:
            todo = "check the disk and the file, then send it again"
        super().__init__(
            "journal_failed",
            f"the server could not write {what} to its journal {db} ({why}): the mission was not changed; {todo}",
        )


def _error(e: Refusal | ValidationError) -> ReplyErr:
    if isinstance(e, Refusal):
        return ReplyErr(dumps(ErrorReply(**e.to_dict())))
    return ReplyErr(
        dumps(ErrorReply(code="bad_request", message=f"malformed request: {first_error(e)}"))
    )


def _reply(applied: Applied) -> bytes:
    return dumps(
        OpReply(
            revision=applied.revision,
            value=applied.value,
            notes=applied.notes,
            duplicate=applied.duplicate,
        )
    )
