"""Client library: what consoles and `missionctl ctl` use to talk to the server.

It keeps a mirror of the mission (snapshot + event stream through
`events.apply_events`), detects gaps and resynchronizes, follows a server
restart, tracks robot presence and telemetry, and submits operations. Every
call is asyncio-friendly: Zenoh callbacks only hand data to the event loop.

The robot link, for consoles and scripts (protocol 2): an operation on a
robot returns once its command is queued (`OpReply.value["command"]`); the
commands live in the mirrored mission (`mission.uplink`, per robot, with
state, created / sent / expires / settled times), so every change of a
command arrives as events like any other. `pending(robot)` lists the
commands not settled yet, `wait_command(id)` waits for one to settle, and
`link(robot)` says per robot its one-way delay, when the ground last heard
from it and whether its state is stale (see `LinkStatus`).
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import os
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import zenoh
from pydantic import ValidationError

from backend.client.events import (
    AlertRaised,
    BatchApplied,
    ClientEvent,
    ConnectionState,
    Listener,
    Malformed,
    RobotChanged,
    StateSynced,
    TelemetryReceived,
)
from backend.core import events as ev
from backend.core.bulk import gc_paused
from backend.core.library import Library
from backend.core.model import Mission, UplinkCommand
from backend.protocol.keys import PROTOCOL_VERSION, Keys
from backend.protocol.messages import (
    AccountInfo,
    Alert,
    ErrorReply,
    FleetEvent,
    OpReply,
    Request,
    RobotInfo,
    StateRequest,
    StateSnapshot,
    Telemetry,
    dumps,
    first_error,
)
from backend.protocol.wire import parse
from backend.transport import (
    NoResponder,
    QueryError,
    QueryTimeout,
    client_config,
    query,
    subscribe,
    transport_events,
    watch_liveliness,
)
from backend.transport.login import Login
from backend.transport.session import (
    LoginRefused,
    TransportUnreachable,
    close_session,
    open_session,
)

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT = 10.0


# a robot silent this long (3 missed heartbeats) is shown as stale: its state is as last known
STALE_AFTER_S = 15.0


@dataclass(frozen=True)
class LinkStatus:
    """One robot's link as this client sees it.

    - `delay_s`: the server's estimate of the one-way delay robot -> ground
      (None until the robot sent something with a time stamp);
    - `heard`: when the ground last heard from the robot (the server's
      registration/downlink time, or this client's last telemetry sample,
      whichever is later); `heard_age_s` how long ago, at `now`;
    - `stale`: offline, out of reach, or silent for more than `STALE_AFTER_S`:
      what the mission shows of it is its last known state, not live;
    - `pending`: its commands not settled yet, oldest first; each has
      `created`, `sent`, `expires` (ages: now - those).
    """

    robot: str
    online: bool
    delay_s: float | None
    heard: datetime | None
    heard_age_s: float | None
    stale: bool
    in_range: bool | None
    pending: list[UplinkCommand]


class ClientError(Exception):
    """Base of what a client reports; `str()` is a sentence for a person."""


class MaybeApplied(ClientError):
    """Base of the errors after which an operation may have been applied
    (its reply was lost): `what` says what happened, `request_id` is the id
    to retry it with (the server applies it once)."""

    def __init__(self, what: str, request_id: str):
        super().__init__(
            f"{what} — retry with request id {request_id} to be safe (it is applied once)"
        )
        self.what = what
        self.request_id = request_id


class ServerUnreachable(ClientError):
    pass


class LoginFailed(ServerUnreachable):
    """The router refused the login or the TLS handshake (the sentence says which)."""


class ProtocolMismatch(ClientError):
    pass


class OperationTimeout(MaybeApplied):
    pass


class ServerGone(MaybeApplied, ServerUnreachable):
    """No server answered an operation: none was there, or it went away
    while handling it (and may have applied it)."""


class OperationRefused(ClientError):
    def __init__(self, reply: ErrorReply):
        super().__init__(reply.message)
        self.reply = reply
        self.code = reply.code


class MissionClient:
    """One connection to a mission server.

    Listeners get one `events.ClientEvent` at a time on the event loop:
    StateSynced (after each (re)sync), BatchApplied, RobotChanged,
    TelemetryReceived, AlertRaised, ConnectionState ("connected" |
    "reconnecting"), Malformed (once per key, e.g. a third-party robot's
    telemetry that does not match the protocol).
    """

    def __init__(
        self,
        connect: str | list[str],
        *,
        client_id: str | None = None,
        user: str = "",
        zenoh_extra: dict[str, Any] | None = None,
        timeout: float = DEFAULT_TIMEOUT,
        telemetry: bool = True,
        login: Login | None = None,
        mirror: bool = True,
    ):
        """`mirror` False: keep no copy of the mission (`mission` stays None);
        a listener that keeps its own (a console's model) takes the snapshot's
        mission from StateSynced and applies every BatchApplied to it."""
        self.endpoints = [connect] if isinstance(connect, str) else list(connect)
        self.client_id = client_id or f"{os.uname().nodename}-{os.getpid()}-{uuid.uuid4().hex[:6]}"
        self.login = login or Login()
        self.user = self.login.user or user
        self.zenoh_extra = {**(zenoh_extra or {}), **self.login.zenoh_options()}
        self.account: AccountInfo | None = None  # known once logged in
        self.timeout = timeout
        self.want_telemetry = telemetry
        self.session: zenoh.Session | None = None
        self.mirror = mirror
        self.mission: Mission | None = None
        self._revision = -1  # the last revision taken (the mirror's, or counted without one)
        self.library: Library | None = None
        self.robots: dict[str, RobotInfo] = {}
        self.telemetry: dict[str, Telemetry] = {}
        self.telemetry_heard: dict[str, datetime] = {}  # when this client got each robot's last
        self.server_id: str | None = None
        self.connected = False
        self._listeners: list[Listener] = []
        self._entities: list[Any] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pending: list[ev.EventBatch] = []  # events arriving during a resync
        self._pending_fleet: list[RobotInfo] = []  # presence changes arriving during a resync
        self._syncing = False
        self._resync_task: asyncio.Task[None] | None = None
        self._ids = itertools.count(1)
        self._malformed_keys: set[tuple[str, str]] = set()  # (what, key) already reported

    # -- lifecycle ---------------------------------------------------------
    async def connect(self) -> StateSnapshot:
        self._loop = asyncio.get_running_loop()
        # opening waits for the router as long as an operation would (Zenoh: 10 s)
        extra = {
            "transport/unicast/open_timeout": max(1, round(self.timeout * 1000)),
            **self.zenoh_extra,
        }
        cfg = client_config(self.endpoints, extra=extra)
        try:
            self.session = await asyncio.to_thread(open_session, cfg)
        except LoginRefused as e:
            raise LoginFailed(str(e)) from None
        except TransportUnreachable as e:
            raise ServerUnreachable(str(e)) from None
        try:
            s = self.session
            # subscribe before the snapshot so nothing between the two is lost
            self._entities.append(subscribe(s, Keys.EVENTS, self._on_events))
            self._entities.append(subscribe(s, Keys.FLEET, self._on_fleet))
            self._entities.append(subscribe(s, Keys.ALERTS, self._on_alert))
            if self.want_telemetry:
                self._entities.append(subscribe(s, Keys.ALL_TELEMETRY, self._on_telemetry))
            snap = await self.resync()
            if self.login.logged_in:
                self.account = await self._fetch_account()
            self._entities.append(
                watch_liveliness(s, Keys.SERVER_ALIVE, self._on_server_alive, history=False)
            )
            self._entities.append(transport_events(s, self._on_transport, history=False))
            return snap
        except BaseException:
            await self.close()
            raise

    async def close(self) -> None:
        if self._resync_task is not None:
            self._resync_task.cancel()
        session, self.session = self.session, None
        self._entities.clear()
        if session is not None:
            await asyncio.to_thread(close_session, session)
        self.connected = False

    def close_now(self) -> None:
        """Blocking close, for when no event loop runs any more (e.g. after an
        app's loop ended): an open session would keep the process from exiting."""
        if self._resync_task is not None and not self._resync_task.done():
            self._resync_task.cancel()
        session, self.session = self.session, None
        self._entities.clear()
        if session is not None:
            close_session(session)
        self.connected = False

    async def __aenter__(self) -> MissionClient:
        await self.connect()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def add_listener(self, fn: Listener) -> None:
        self._listeners.append(fn)

    def remove_listener(self, fn: Listener) -> None:
        self._listeners.remove(fn)

    def _emit(self, event: ClientEvent) -> None:
        for fn in list(self._listeners):
            try:
                fn(event)
            except Exception:  # a listener's bug must not stop the stream
                log.exception("client listener failed on %s", event.kind)

    # -- state -----------------------------------------------------------------
    @property
    def revision(self) -> int:
        return self._revision

    async def resync(self) -> StateSnapshot:
        """Fetch the full state and apply what arrived meanwhile."""
        self._syncing = True
        try:
            try:
                raw = await query(
                    self._session(),
                    Keys.STATE,
                    dumps(StateRequest(client=self.client_id)),
                    self.timeout,
                )
            except NoResponder:
                if self.login.logged_in:  # the router's rules may have dropped the query
                    raise ServerUnreachable(
                        f"no mission server answers user {self.user} at "
                        f"{', '.join(self.endpoints)}: either none runs there, or this account "
                        "may not read the mission (a robot account; under mutual TLS, a "
                        "certificate not named after the account)"
                    ) from None
                raise ServerUnreachable(
                    f"no mission server answers at {', '.join(self.endpoints)} "
                    "(a Zenoh router is there, but no missionctl server)"
                ) from None
            except QueryTimeout:
                raise ServerUnreachable(
                    f"the mission server at {', '.join(self.endpoints)} did not answer "
                    f"in {self.timeout:g} s"
                ) from None
            try:
                with gc_paused():
                    snap = StateSnapshot.model_validate_json(raw)
            except ValidationError:
                raise ProtocolMismatch(
                    f"the server at {', '.join(self.endpoints)} speaks another protocol version "
                    f"(this client speaks {PROTOCOL_VERSION}); upgrade the older side"
                ) from None
            if snap.protocol != PROTOCOL_VERSION:
                raise ProtocolMismatch(
                    f"the server speaks protocol {snap.protocol}, this client "
                    f"{PROTOCOL_VERSION}; upgrade the older side"
                )
            if self.mirror:
                self.mission, self.library = snap.mission, snap.library
            self._revision = snap.mission.revision
            self.robots = dict(snap.robots)
            self.server_id = snap.server_id
        finally:
            self._syncing = False
        self.connected = True
        self._emit(StateSynced(snap))
        # what arrived while the snapshot was in flight is newer: after it, in order
        fleet, self._pending_fleet = self._pending_fleet, []
        for info in fleet:
            self._got_fleet(info)
        pending, self._pending = self._pending, []
        for batch in pending:
            self._apply(batch)
        self._emit(ConnectionState("connected"))
        return snap

    async def _fetch_account(self) -> AccountInfo | None:
        try:
            raw = await query(self._session(), Keys.account(self.user), b"", self.timeout)
            return AccountInfo.model_validate_json(raw)
        except (NoResponder, QueryTimeout, QueryError, ValidationError):
            return None  # an older server: no roles known, the router still enforces them

    @property
    def read_only(self) -> str | None:
        """Why this client cannot change the mission (None: it can)."""
        a = self.account
        if a is not None and a.enforced and a.role != "operator":
            return f"read-only: logged in as {a.role} {a.user}"
        return None

    def _apply(self, batch: ev.EventBatch) -> None:
        if batch.revision <= self._revision:
            return  # already in the snapshot
        if batch.revision != self._revision + 1:
            self._schedule_resync()  # a gap: some events were lost
            return
        if self.mission is not None:
            self.mission = ev.apply_events(self.mission, batch)
        self._revision = batch.revision
        self._emit(BatchApplied(batch))

    def _schedule_resync(self) -> None:
        if self._resync_task is None or self._resync_task.done():
            self._resync_task = asyncio.ensure_future(self._resync_quietly())

    async def _resync_quietly(self) -> None:
        delay = 0.1
        while self.session is not None:
            try:
                await self.resync()
                return
            except ClientError as e:
                log.info("resync failed (%s), retrying", e)
                await asyncio.sleep(delay)  # back-off while the server restarts
                delay = min(delay * 2, 2.0)

    # -- Zenoh callbacks (other threads): hand over to the loop ---------------------
    def _post(self, fn: Callable[..., None], *args: Any) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(fn, *args)

    def _on_events(self, msg: Any) -> None:
        try:
            batches = ev.read_batches(msg.payload)
        except ValidationError as e:
            self._malformed("events", msg.key, e)
            return
        self._post(self._got_batches, batches)

    def _got_batches(self, batches: list[ev.EventBatch]) -> None:
        for batch in batches:
            if self._syncing or self._revision < 0:
                self._pending.append(batch)
            else:
                self._apply(batch)

    def _on_fleet(self, msg: Any) -> None:
        try:
            info = FleetEvent.model_validate_json(msg.payload).robot
        except ValidationError as e:
            self._malformed("fleet", msg.key, e)
            return
        self._post(self._got_fleet, info)

    def _got_fleet(self, info: RobotInfo) -> None:
        if self._syncing:  # newer than the snapshot in flight: told after it
            self._pending_fleet.append(info)
            return
        self.robots[info.name] = info
        self._emit(RobotChanged(info))

    def _on_telemetry(self, msg: Any) -> None:
        try:
            t = parse(Telemetry, msg.payload)
        except ValidationError as e:
            self._malformed("telemetry", msg.key, e)
            return
        self._post(self._got_telemetry, t)

    def _got_telemetry(self, t: Telemetry) -> None:
        self.telemetry[t.robot] = t
        self.telemetry_heard[t.robot] = datetime.now(UTC)
        self._emit(TelemetryReceived(t))

    def _on_alert(self, msg: Any) -> None:
        try:
            a = Alert.model_validate_json(msg.payload)
        except ValidationError as e:
            self._malformed("alert", msg.key, e)
            return
        self._post(self._emit, AlertRaised(a))

    def _malformed(self, what: str, key: str, e: ValidationError) -> None:
        """Said once per key (a robot's telemetry comes several times a second)."""
        if (what, key) in self._malformed_keys:
            return
        self._malformed_keys.add((what, key))
        m = Malformed(what, key, first_error(e))
        log.warning("%s", m.sentence())
        self._post(self._emit, m)

    def _on_server_alive(self, key: str, alive: bool) -> None:
        self._post(self._server_presence, alive)

    def _on_transport(self, change: Any) -> None:
        self._post(self._server_presence, change.connected)

    def _server_presence(self, alive: bool) -> None:
        if alive:
            self._schedule_resync()
        elif self.connected:
            self.connected = False
            self._emit(ConnectionState("reconnecting"))

    # -- operations --------------------------------------------------------------------
    def _session(self) -> zenoh.Session:
        if self.session is None:
            raise ClientError("not connected")
        return self.session

    def new_request_id(self) -> str:
        return f"r{next(self._ids)}"

    async def submit(
        self,
        op: Any,
        *,
        expected_revision: int | None = None,
        request_id: str | None = None,
        timeout: float | None = None,
    ) -> OpReply:
        """Apply an operation on the server. Raises OperationRefused (with the
        server's code and sentence), OperationTimeout or ServerUnreachable.
        Retrying with the same `request_id` is safe: it is applied once."""
        if self.read_only:  # the router would drop it unanswered: say why at once
            raise OperationRefused(ErrorReply(code="read_only", message=self.read_only))
        req = Request(
            client=self.client_id,
            request_id=request_id or self.new_request_id(),
            user=self.user,
            expected_revision=expected_revision,
            op=op,
        )
        wait = timeout or self.timeout
        try:
            # logged in: the user's own key, the only one the router lets it use
            key = Keys.op_as(self.user) if self.account is not None else Keys.OP
            raw = await query(self._session(), key, dumps(req), wait)
        except QueryError as e:
            raise OperationRefused(_error_reply(e.payload)) from None
        except QueryTimeout:
            raise OperationTimeout(
                f"the server did not answer '{op.op}' within {wait:g} s; "
                "it may have applied it, or still apply it",
                req.request_id,
            ) from None
        except NoResponder:
            raise ServerGone(
                f"no mission server answered '{op.op}' at {', '.join(self.endpoints)}; "
                "if one was running, it may have applied it before it went away",
                req.request_id,
            ) from None
        reply = OpReply.model_validate_json(raw)
        return reply

    # -- the robot link -----------------------------------------------------------------
    def pending(self, robot: str | None = None) -> list[UplinkCommand]:
        """Commands not settled yet (queued or sent), per robot in order."""
        return self.mission.pending_commands(robot) if self.mission is not None else []

    def link(self, robot: str, now: datetime | None = None) -> LinkStatus:
        """The robot's link: delay, last heard, stale or live, pending commands."""
        now = now or datetime.now(UTC)
        info = self.robots.get(robot)
        heard = info.heard if info is not None else None
        mine = self.telemetry_heard.get(robot)
        if mine is not None and (heard is None or mine > heard):
            heard = mine
        age = (now - heard).total_seconds() if heard is not None else None
        t = self.telemetry.get(robot)
        online = bool(info and info.online)
        stale = not online or age is None or age > STALE_AFTER_S
        return LinkStatus(
            robot=robot,
            online=online,
            delay_s=info.delay_s if info is not None else None,
            heard=heard,
            heard_age_s=age,
            stale=stale,
            in_range=t.in_range if t is not None and not stale else None,
            pending=self.pending(robot),
        )

    async def wait_command(self, command_id: int, timeout: float | None = None) -> UplinkCommand:
        """Wait until command `command_id` is settled (acked, refused, expired
        or cancelled) and return it; TimeoutError while it is still pending."""

        def settled(m: Mission) -> bool:
            c = m.command(command_id)
            # not in the mirror yet (its event follows the reply), or long settled
            return not c.pending if c is not None else command_id < m.next_command

        m = await self.wait_for(settled, timeout)
        c = m.command(command_id)
        if c is None:
            raise KeyError(f"command {command_id} was settled long ago (no longer kept)")
        return c

    async def wait_for(
        self, predicate: Callable[[Mission], bool], timeout: float | None = 10.0
    ) -> Mission:
        """Wait until the mirrored mission satisfies `predicate`."""
        done = asyncio.Event()

        def check(_event: ClientEvent | None = None) -> None:
            if self.mission is not None and predicate(self.mission):
                done.set()

        self.add_listener(check)
        try:
            check()
            await asyncio.wait_for(done.wait(), timeout)
        finally:
            self.remove_listener(check)
        assert self.mission is not None
        return self.mission


def _error_reply(payload: bytes) -> ErrorReply:
    try:
        return ErrorReply.model_validate_json(payload)
    except ValidationError:
        text = payload.decode(errors="replace")
        return ErrorReply(code="server_error", message=text)
