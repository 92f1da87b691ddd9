"""The mission server: a Zenoh router hosting the rules, the journal and the
link to the robots (`robots.RobotLink`).

All mission state lives on one asyncio loop: Zenoh callbacks only hand
queries to it (transport.serve_async), so the engine is never touched from
two threads. Every operation is applied and answered in the loop callback
that received it: one on a robot queues a command in the robot's uplink,
which the robot link transmits and whose answer it applies when it comes
(nothing waits for a robot). Applied operations, presence changes and
alerts are published here, after the reply of the request being handled.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import sqlite3
import uuid
from collections import deque
from collections.abc import Awaitable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import zenoh

from backend.core.alerts import AlertKind, Level
from backend.core.contact import ContactWindows
from backend.core.events import EventBatch
from backend.core.library import Library
from backend.core.model import Mission
from backend.core.rules.engine import Applied, Engine, Refusal
from backend.files.missions import library_path, load_library, load_mission
from backend.protocol.archive import archive_path
from backend.protocol.keys import PROTOCOL_VERSION, Keys
from backend.protocol.messages import (
    ALERTS_KEPT,
    AccountInfo,
    Alert,
    FleetEvent,
    HistoryRequest,
    OpReply,
    Request,
    RobotInfo,
    StateRequest,
    StateSnapshot,
    Telemetry,
    dumps,
)
from backend.protocol.wire import parse
from backend.server import history
from backend.server.accounts import Accounts, zenoh_dictionary
from backend.server.acl import acl_config
from backend.server.archive import MAX_SAMPLES, TelemetryArchive
from backend.server.contact import ContactWatch
from backend.server.journal import (
    Journal,
    JournalError,
    Remembered,
    Unreplayable,
    remember_requests,
)
from backend.server.recorder import JournalRecorder
from backend.server.refusals import guard
from backend.server.robots import RobotLink
from backend.server.telemetry import TelemetryWatch
from backend.transport import (
    declare_publisher,
    declare_token,
    router_config,
    serve,
    serve_async,
    subscribe,
    timeouts,
)
from backend.transport.session import close_session, open_session

log = logging.getLogger(__name__)


def _now() -> datetime:
    return datetime.now(UTC)


class MissionServer:
    def __init__(
        self,
        *,
        db: str | Path,
        mission_file: str | Path | None = None,
        listen: list[str] | None = None,
        zenoh_extra: dict[str, Any] | None = None,
        command_expiry: float | None = None,
        accounts: Accounts | None = None,
        recover: bool = False,
        link_delay_hint: float = 0.0,
        archive_samples: int = MAX_SAMPLES,
        contact_windows: Mapping[str, ContactWindows] | None = None,
    ):
        self.db = Path(db)
        self.mission_file = Path(mission_file) if mission_file else None
        self.listen = listen or ["tcp/127.0.0.1:7447"]
        self.zenoh_extra = zenoh_extra
        self.command_expiry = command_expiry  # seconds; None: commands never expire
        self.accounts = accounts  # None: no logins, anyone reaching the router may do anything
        # a journal with a batch that cannot be replayed: keep what comes before it
        # (the rest goes to its quarantine table) instead of refusing to start
        self.recover = recover
        self.recovered: str | None = None  # what the recovery did, for the operator
        # the long link's expected one-way delay (s): Zenoh's timeouts follow from it
        # (backend.transport.timeouts); a floor for the robots' measured delays
        self.link_delay_hint = link_delay_hint
        self.server_id = uuid.uuid4().hex[:12]
        # telemetry, alerts and presence kept beside the journal for review (0: none)
        self.archive_samples = archive_samples
        self.archive: TelemetryArchive | None = None
        # robot -> its contact windows declared by the deployment (wall clock)
        self.robot_link = RobotLink(self, ContactWatch(contact_windows))
        self.engine: Engine | None = None
        self.journal: Journal | None = None
        self.library_file: Path | None = None
        self.resumed = False
        self._session: zenoh.Session | None = None
        self._entities: list[Any] = []
        self._events_pub: zenoh.Publisher | None = None
        self._fleet_pub: zenoh.Publisher | None = None
        self._alerts_pub: zenoh.Publisher | None = None
        self._alert_ids = itertools.count(1)
        self.telemetry_watch = TelemetryWatch(self)
        self.alerts: deque[Alert] = deque(maxlen=ALERTS_KEPT)  # the latest, for snapshots
        # publications waiting for the next loop callback
        self._outbox: list[tuple[Any, bytes]] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._checkpoint: asyncio.Future[Any] | None = None  # the journal's, on a thread
        self._checkpoint_failing = False

    # -- start / stop ---------------------------------------------------------
    def _load(self) -> None:
        """Resume from the journal, or start it from the mission file."""
        journal = Journal.open(self.db, keep_snapshots=None)
        try:
            mission, requests = self._resume(journal)
            if mission is not None:
                lib_file = self._library_file(journal, mission)
                library = load_library(lib_file)
                self.resumed = True
                self.robot_link.verification.resume(mission, journal.sync_forecasts)
            else:
                if self.mission_file is None:
                    raise SystemExit(
                        f"{self.db} is empty: give a mission file to start from (--mission FILE)"
                    )
                mission, library = load_mission(self.mission_file)
                lib_file = library_path(self.mission_file, mission.library)
                journal.close()
                journal = Journal.open(self.db, library=str(lib_file), keep_snapshots=None)
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
        self.engine = Engine(
            mission,
            library,
            recorder=JournalRecorder(journal, self.db, self),
            offers=self.robot_link,
            default_expiry_s=self.command_expiry,
        )
        remember_requests(self.engine, requests)
        self.robot_link.add_robots(mission.robots)
        self._open_archive()

    def _library_file(self, journal: Journal, mission: Mission) -> Path:
        """The skill library of a resumed mission: the one its journal names,
        else the mission file's."""
        if journal.library:
            return Path(journal.library)
        if self.mission_file is not None:
            return library_path(self.mission_file, mission.library)
        raise SystemExit(f"{self.db}: the journal does not say which skill library it uses")

    def _open_archive(self) -> None:
        """The telemetry archive beside the journal; one that cannot be
        opened is said and done without (the mission does not need it)."""
        if self.archive_samples <= 0:
            return
        archive = TelemetryArchive(archive_path(self.db), max_samples=self.archive_samples)
        try:
            archive.start()
        except (sqlite3.Error, OSError) as e:
            log.warning(
                "%s: no telemetry archive (%s); the mission goes on without", archive.path, e
            )
            return
        self.archive = archive

    def _resume(self, journal: Journal) -> tuple[Mission | None, list[Remembered]]:
        """The journal's mission; with `recover`, a journal that cannot be
        replayed to its end gives what comes before the first batch that
        cannot, and keeps that batch and the later ones in its quarantine."""
        try:
            return journal.load()
        except Unreplayable as e:
            if not self.recover:
                raise
            moved, snaps = journal.quarantine_from(e.revision, reason=e.why)
            mission, requests = journal.load()
            what = f" ({e.what})" if e.what else ""
            kept = f"it and the {moved - 1} after it are" if moved > 1 else "it is"
            snapshots = f" (with {snaps} snapshot(s) from it on)" if snaps else ""
            self.recovered = (
                f"recovered {self.db} at revision {e.revision - 1}: batch {e.revision}{what} "
                f"cannot be replayed ({e.why}); {kept} kept{snapshots} in the journal's "
                f"quarantine table: sqlite3 {self.db} 'SELECT * FROM quarantine'"
            )
            log.info("%s", self.recovered)
            return mission, requests

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._load()
        assert self.journal is not None
        try:
            s = self._session = await self._open_router()
        except BaseException:
            self.journal.close()
            if self.archive is not None:
                self.archive.close()
            raise
        self._events_pub = declare_publisher(s, Keys.EVENTS)
        self._fleet_pub = declare_publisher(s, Keys.FLEET)
        self._alerts_pub = declare_publisher(s, Keys.ALERTS)
        self._entities += [
            serve_async(s, Keys.OP, guard(self._handle_op)),
            serve_async(s, Keys.STATE, guard(self._handle_state)),
            serve_async(s, Keys.HISTORY, guard(self._handle_history)),
            serve_async(s, Keys.op_as("*"), guard(self._handle_op), with_key=True),
            serve_async(s, Keys.account("*"), guard(self._handle_account), with_key=True),
            *self.robot_link.declare(s, guard),
            subscribe(s, Keys.ALL_TELEMETRY, self._on_telemetry),
            # trivial, answered on the Zenoh thread: the raw-transport baseline of benchmarks
            serve(s, Keys.PING, lambda _payload: b"pong"),
        ]
        # declared last: robots (re)register when they see it
        self._entities.append(declare_token(s, Keys.SERVER_ALIVE))

    async def _open_router(self) -> zenoh.Session:
        """The router session; with accounts, user/password logins and the
        access-control rules of their roles (the dictionary file Zenoh reads
        exists only while the session opens)."""
        extra = {**timeouts.zenoh_options(self.link_delay_hint), **(self.zenoh_extra or {})}
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
        self.robot_link.close()
        session, self._session = self._session, None
        if session is not None:
            await asyncio.to_thread(close_session, session)
        while self._checkpoint is not None:  # the journal closes after it
            await asyncio.wait([self._checkpoint])
        if self.journal is not None:
            self.journal.close()
            self.journal = None
        archive, self.archive = self.archive, None
        if archive is not None:
            await asyncio.to_thread(archive.close)

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
    def _commit(self, applied: Applied, op: Any, *, actor: str) -> None:
        """Publish an applied (and journaled) operation; snapshot when due."""
        if applied.duplicate or not applied.events:
            return
        assert self.journal is not None
        try:
            self.journal.maybe_snapshot(self.mission)
        except (sqlite3.Error, OSError, JournalError) as e:  # in the batches: a slower restart
            log.warning(
                "%s: cannot store a snapshot (%s); will try again at the next operation", self.db, e
            )
        self._maybe_checkpoint()
        if self.archive is not None:  # the review's index of the journal by time
            self.archive.journaled(applied.revision, op)
        batch = EventBatch(revision=applied.revision, events=applied.events, actor=actor, op=op.op)
        self._publish(self._events_pub, batch.model_dump_json().encode())
        self.robot_link.applied(applied.events, op)  # commands to transmit, robots a mission names

    def _maybe_checkpoint(self) -> None:
        """The journal's checkpoint (its log copied into the file, with an
        fsync) runs on a thread: inside a commit it held up one operation
        in ~400 for 4-17 ms."""
        journal, loop = self.journal, self._loop
        assert journal is not None and loop is not None
        if self._checkpoint is None and journal.checkpoint_due:
            self._checkpoint = loop.run_in_executor(None, journal.checkpoint)
            self._checkpoint.add_done_callback(self._checkpointed)

    def _checkpointed(self, done: asyncio.Future[Any]) -> None:
        self._checkpoint = None
        error = None if done.cancelled() else done.exception()
        if error is None:
            self._checkpoint_failing = False
        elif not self._checkpoint_failing:  # once, not at every checkpoint
            self._checkpoint_failing = True
            log.warning(
                "%s: cannot checkpoint the journal (%s); nothing is lost, its -wal file grows "
                "until a checkpoint succeeds",
                self.db,
                error,
            )

    def _publish(self, publisher: Any, payload: bytes) -> None:
        """Sent once the request being handled has its reply: the reply and
        the publications share the requester's link, and a reply queued behind
        its own event batch waited for the requester to take in the batch
        first. Publications keep their order."""
        if not self._outbox:
            assert self._loop is not None
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

    def submit(
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
        assert self.engine is not None
        applied = self.engine.submit(
            op,
            client=client,
            request_id=request_id,
            expected_revision=expected_revision,
            actor=who,
        )
        self._commit(applied, op, actor=who)
        return applied

    def alert(
        self,
        message: str,
        *,
        kind: AlertKind,
        level: Level = "warning",
        robot: str | None = None,
        skill: str | None = None,
        command: int | None = None,
        question: int | None = None,
    ) -> None:
        """Raise an alert: logged, numbered, kept for state snapshots, published."""
        log.warning("%s", message)
        a = Alert(
            id=next(self._alert_ids),
            level=level,
            kind=kind,
            robot=robot,
            skill=skill,
            command=command,
            question=question,
            message=message,
            at=_now(),
        )
        self.alerts.append(a)
        if self.archive is not None:
            self.archive.alert(a)
        if self._alerts_pub is not None:
            self._publish(self._alerts_pub, dumps(a))

    def _on_telemetry(self, msg: Any) -> None:
        """A robot's sample (a Zenoh thread): its alerts are raised on the loop."""
        try:
            t = parse(Telemetry, msg.payload)
        except ValueError:
            return  # not readable: consoles say so (an unreadable-message alert of their own)
        if self.archive is not None:  # on this (Zenoh) thread: the loop never waits for it
            self.archive.took(t)
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self.telemetry_watch.took, t)

    def publish_fleet(self, info: RobotInfo) -> None:
        """A robot's presence or manifest changed (the robot link's news)."""
        if self.archive is not None:
            self.archive.fleet(info)
        if self._fleet_pub is not None:
            self._publish(self._fleet_pub, dumps(FleetEvent(robot=info)))

    # -- state ------------------------------------------------------------------
    def _handle_state(self, payload: bytes) -> bytes:
        if payload:  # an empty query asks for the state too (a third party's first try)
            parse(StateRequest, payload)  # anything else is answered `bad_request`
        snap = StateSnapshot(
            protocol=PROTOCOL_VERSION,
            server_id=self.server_id,
            revision=self.mission.revision,
            mission=self.mission,
            library=self.library,
            robots=self.robot_link.robots,
            alerts=list(self.alerts),
        )
        return snap.model_dump_json().encode()

    def _handle_history(self, payload: bytes) -> Awaitable[bytes]:
        """`ctl history`: read from the journal on a worker thread (history.py)."""
        req = parse(HistoryRequest, payload) if payload else HistoryRequest()
        owners = {s.id: robot for robot, task in self.mission.tasks.items() for s in task}

        async def reply() -> bytes:
            answer = await asyncio.to_thread(history.answer, self.db, req, owners)
            return answer.model_dump_json().encode()

        return reply()

    # -- operations from consoles and ctl -------------------------------------------
    def _handle_account(self, payload: bytes, key: str) -> bytes:
        user = key.rsplit("/", 1)[-1]
        if self.accounts is None:
            return dumps(AccountInfo(user=user, role="operator", enforced=False))
        role = self.accounts.role(user)
        if role is None:  # the router lets only `user` ask this: unreachable with accounts
            raise Refusal("unknown_account", f"no account '{user}' on this server")
        if role == "relay":  # it carries its site's accounts; it is none of them
            raise Refusal("unknown_account", f"'{user}' is a relay's account: log in as yourself")
        return dumps(AccountInfo(user=user, role=role, robots=self.accounts.robots(user)))

    def _handle_op(self, payload: bytes, key: str | None = None) -> bytes:
        """Apply an operation and answer at once (one on a robot queues its
        command: the robot's answer comes later, as events)."""
        req = parse(Request, payload)
        if key is not None:  # op/{user}: the router's rules let only `user` send it
            user = key.rsplit("/", 1)[-1]
            role = self.accounts.role(user) if self.accounts is not None else "operator"
            # the ACL refuses it first; this is the clean answer if it did not
            if role != "operator":
                raise Refusal(
                    "read_only", f"read-only: logged in as {role or 'unknown account'} {user}"
                )
            req = req.model_copy(update={"user": user})
        actor = f"{req.user}@{req.client}" if req.user else req.client
        self.robot_link.check_load(req.op)
        applied = self.submit(
            req.op,
            client=req.client,
            request_id=req.request_id,
            actor=actor,
            expected_revision=req.expected_revision,
        )
        self._keep_reply(applied)
        return _reply(applied)

    def _keep_reply(self, applied: Applied) -> None:
        """Journal the reply of a request whose batch was journaled, so a
        retry after a restart gets the same value (the new skill's id...)."""
        if applied.duplicate or not applied.events or self.journal is None:
            return
        try:
            self.journal.set_reply(applied.revision, applied.value, applied.notes)
        except (sqlite3.Error, OSError, JournalError) as e:  # applied: only the reply is lost
            log.warning(
                "%s: cannot keep the reply of revision %s: %s", self.db, applied.revision, e
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
