"""The server's link to its robots: registration and ownership of a robot
name, presence, the link's state (heard, delay), the uplink (commands,
`uplink.UplinkSender`) and the downlink (reports and answers,
`downlink.DownlinkApplier`).

Nothing here waits for a robot on an operator's behalf: an operation on a
robot is applied like any other (it queues a command in the mission, see
`backend.core.rules.uplink`); the link then transmits it whenever the robot
can hear it, and applies the robot's answer when it comes, minutes later
if need be.

The server gives the link a host (`LinkServer`: the engine, journaled
submission, alerts, fleet publication) and asks it to declare its
queryables, to act on what was applied (`applied`), and for the robots'
presence (`robots`); the engine asks it what each robot offers (`offered`).
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Callable, Iterable, Mapping
from datetime import UTC, datetime, timedelta
from typing import Any, Protocol

from pydantic import ValidationError

from backend.core import events as ev
from backend.core.alerts import AlertKind, Level
from backend.core.contingency import awaited_outcomes
from backend.core.library import SkillSignature
from backend.core.model import CommandState, Mission
from backend.core.ops import LoadMission, Reconcile, UplinkSettle
from backend.core.rules.engine import Applied, Engine, Refusal
from backend.protocol.keys import PROTOCOL_VERSION, Keys
from backend.protocol.messages import (
    Downlink,
    DownlinkAck,
    Manifest,
    Register,
    RegisterCode,
    RegisterReply,
    RobotInfo,
    dumps,
)
from backend.protocol.timing import HEARTBEAT_S
from backend.protocol.wire import LIMIT_EXCEEDED, parse, unreadable
from backend.server.contact import ContactWatch
from backend.server.downlink import DownlinkApplier, Submitter, raise_alerts
from backend.server.refusals import Handler, JournalFailed
from backend.server.team import announcement, unknown_type
from backend.server.uplink import UplinkSender
from backend.server.verification import VerificationWatch
from backend.transport import ReplyError, serve_async, watch_liveliness

log = logging.getLogger(__name__)

HEARD_PUBLISH_S = 10.0  # a robot's `heard` goes out at least this often while it talks
TICK_S = 1.0  # expiry of queued commands is checked this often
DELAY_SAMPLES = 8  # the delay estimate: the least of the last few samples
# what moves a command's verification on at once; a skill's status (a report: many
# per second from a busy fleet) waits for the next tick, a second at most
_VERIFIED_BY = (ev.CommandQueued, ev.CommandChanged, ev.MissionReplaced)


def _now() -> datetime:
    return datetime.now(UTC)


class LinkServer(Submitter, Protocol):
    """What the robot link needs from the server: what its downlinks need,
    and publishing a robot's fleet entry."""

    def publish_fleet(self, info: RobotInfo) -> None: ...


class RobotLink:
    def __init__(self, host: LinkServer, contact: ContactWatch | None = None) -> None:
        self._host = host
        self.contact = contact or ContactWatch()
        self.contact.on_change = self.refresh_contact
        self.robots: dict[str, RobotInfo] = {}  # presence, manifest, link state, by name
        self.senders: dict[str, UplinkSender] = {}
        self._tokens: dict[str, set[str]] = {}  # robot -> sessions whose token is present
        self._delays: dict[str, list[float]] = {}
        self._published_heard: dict[str, datetime] = {}
        self._said: set[tuple[str, str]] = set()
        self._renew: set[str] = set()  # robots to register again: the mission was replaced
        self._downlink = DownlinkApplier(host)
        self.verification = VerificationWatch(host, self.contact)
        self._session: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tick: asyncio.Task[None] | None = None

    # -- the server's side ------------------------------------------------------------
    def declare(self, session: Any, guard: Callable[[Handler], Handler]) -> list[Any]:
        """The link's queryables and presence watch on the server's session
        (on the event loop); `guard` turns refusals into error replies."""
        self._session = session
        self._loop = asyncio.get_running_loop()
        for sender in self.senders.values():
            sender.start()
        self._tick = self._loop.create_task(self._housekeeping(), name="robot-link")
        return [
            serve_async(session, Keys.register("*"), guard(self._handle_register), with_key=True),
            serve_async(session, Keys.downlink("*"), guard(self._handle_downlink), with_key=True),
            serve_async(session, Keys.legacy(1), _legacy, with_key=True),
            watch_liveliness(session, Keys.ALL_ALIVE, self._on_presence),
            self.contact.start(session),
        ]

    def close(self) -> None:
        self.contact.close()
        for sender in self.senders.values():
            sender.stop()
        if self._tick is not None:
            self._tick.cancel()
            self._tick = None
        self._session = None

    def add_robots(self, names: Iterable[str]) -> None:
        """The robots of a (new) mission not known yet: offline until they register."""
        for name in names:
            if name not in self.robots:
                self._set_robot(RobotInfo(name=name))
            elif self.robots[name].joining:  # added: it registers as any other now
                self._set_robot(self.robots[name].model_copy(update={"joining": False}))
            if name not in self.senders:
                sender = self.senders[name] = UplinkSender(self, name)
                if self._loop is not None:
                    sender.start()
                sender.resend()  # commands pending from before a restart

    @property
    def engine(self) -> Engine:
        engine = self._host.engine
        assert engine is not None
        return engine

    @property
    def session(self) -> Any:
        return self._session

    @property
    def _mission(self) -> Mission:
        return self.engine.mission

    def submit(self, op: Any, *, actor: str) -> Applied:
        applied = self._host.submit(op, actor=actor)
        raise_alerts(self._host, applied)
        return applied

    # -- operations on robots -----------------------------------------------------------
    def check_load(self, op: Any) -> None:
        """Refuse loading a file's statuses while one of its robots is online:
        what a robot holds is its own to say."""
        if not (isinstance(op, LoadMission) and op.keep_state):
            return
        online = [r for r in op.mission.robots if self.owner(r) is not None]
        if online:
            raise Refusal(
                "robots_online",
                f"cannot keep the file's statuses while {', '.join(online)} "
                f"{'is' if len(online) == 1 else 'are'} online: what a robot holds is its "
                "own to say; load the file as a plan (unfinished skills idle, the log kept)",
            )

    def offered(self, robot: str) -> Mapping[str, str] | None:
        """What `robot`'s manifest offers (skill -> version), as last registered;
        None if it never registered. The rules check syncs and retries with it
        (`backend.core.rules.engine.Offers`)."""
        info = self.robots.get(robot)
        return info.manifest.skills if info is not None and info.manifest is not None else None

    def applied(self, events: list[Any], op: Any = None) -> None:
        """After an applied operation: transmit what it added or withdrew;
        verify the commands it moved on."""
        self.verification.applied(op)
        self._events(events)
        if any(isinstance(e, _VERIFIED_BY) for e in events):
            self.refresh_verification()

    def _events(self, events: list[Any]) -> None:
        for e in events:
            on = _ON_EVENT.get(type(e))
            if on is not None:
                on(self, e)

    # -- one method per kind of event the link acts on

    def _queued(self, e: ev.CommandQueued) -> None:
        self._kick(e.command.robot)

    def _command_changed(self, e: ev.CommandChanged) -> None:
        c = self._mission.command(e.id) if e.cancel_requested else None
        if c is not None:
            self._kick(c.robot)

    def _robot_added(self, e: ev.RobotAdded) -> None:
        self.add_robots([e.name])

    def _mission_replaced(self, e: ev.MissionReplaced) -> None:
        self.add_robots(self._mission.robots)
        # as after a registration, the mission and what each robot holds are
        # compared: each registers again (told on its next Downlink)
        self._renew = {r for r, info in self.robots.items() if info.online}

    def _kick(self, robot: str) -> None:
        sender = self.senders.get(robot)
        if sender is not None:
            sender.kick()

    # -- what the uplink senders ask ------------------------------------------------------
    def owner(self, robot: str) -> str | None:
        info = self.robots.get(robot)
        return info.session if info is not None and info.online else None

    def delay_of(self, robot: str) -> float | None:
        info = self.robots.get(robot)
        return info.delay_s if info is not None else None

    def said_once(self, robot: str, what: str, message: str, level: Level = "warning") -> None:
        if (robot, what) in self._said:
            return
        self._said.add((robot, what))
        self._host.alert(message, level=level, robot=robot, kind=AlertKind.ROBOT_ERROR)

    # -- registration ----------------------------------------------------------------------
    def _parse(self, model: Any, payload: bytes, robot: str, what: str) -> Any:
        """A robot's message; one that cannot be read is the robot's fault."""
        try:
            return parse(model, payload)  # within the limits (backend.core.limits)
        except ValidationError as e:
            code, message = unreadable(e, f"a {what} of {robot}", "bad_message")
            if code != LIMIT_EXCEEDED:
                message += f"; see docs/protocol.md (protocol {PROTOCOL_VERSION})"
            self.said_once(robot, f"bad {what}", message, "error")
            raise Refusal(code, message, robot=robot) from None

    def _handle_register(self, payload: bytes, key: str) -> bytes:
        robot = Keys.robot_of(key)
        reg: Register = self._parse(Register, payload, robot, "registration")
        m = reg.manifest
        if m.name != robot:  # the key is what the router's rules check
            raise Refusal(
                "bad_register", f"robot '{m.name}' cannot register on {key}", robot=m.name
            )
        refused = self._not_registrable(m) or self._taken(robot, reg.session)
        if refused is not None:
            code, reason = refused
            return dumps(RegisterReply(accepted=False, code=code, reason=reason))
        progress = self._downlink.apply(robot, reg.downlink)
        lost: list[str] = []
        adopted: list[str] = []
        dropped: list[str] = []
        if progress.last_seq >= reg.last_seq:
            reconcile = Reconcile(robot=robot, queue=reg.queue, asking=reg.asking)
            value = self.submit(reconcile, actor=robot).value
            lost, adopted, dropped = value["unsynchronized"], value["adopted"], value["dropped"]
        else:
            self._host.alert(
                f"{robot} registered, but its messages {progress.last_seq + 1} to {reg.last_seq} "
                "have not arrived: its queue is compared with the mission once they have",
                robot=robot,
                kind=AlertKind.RECONCILE,
            )
        self._renew.discard(robot)
        info = self.robots[robot]
        self._set_robot(
            info.model_copy(
                update={
                    "manifest": m,
                    "online": True,
                    "session": reg.session,
                    "since": info.since if info.online else _now(),
                }
            )
        )
        self._heard(robot, reg.sent)
        self.senders[robot].resend()  # what it has not answered: again
        return dumps(
            RegisterReply(
                accepted=True,
                last_seq=progress.last_seq,
                refused=progress.refused,
                missing=lost,
                adopted=adopted,
                dropped=dropped,
                heartbeat_s=HEARTBEAT_S,
                outcomes=awaited_outcomes(self._mission, robot),
                skills=self._signatures(m),
            )
        )

    def _signatures(self, m: Manifest) -> dict[str, SkillSignature]:
        """The library's signature of each skill the robot offers and its type has."""
        library = self.engine.library
        return {
            name: library.skills[name].signature()
            for name in library.skills_of(m.type)
            if name in m.skills and name in library.skills
        }

    def _not_registrable(self, m: Manifest) -> tuple[RegisterCode, str] | None:
        """Why a robot with manifest `m` cannot register (None: it can)."""
        if m.protocol != PROTOCOL_VERSION:
            return "protocol", (
                f"protocol {m.protocol} is not supported: this server speaks protocol "
                f"{PROTOCOL_VERSION} (docs/protocol.md); upgrade the robot's side"
            )
        if m.name not in self._mission.robots:
            return self._joining(m)
        expected = self._mission.robots[m.name].type
        if m.type != expected:
            return "wrong_type", f"robot '{m.name}' is a {expected} in this mission, not a {m.type}"
        return None

    def _joining(self, m: Manifest) -> tuple[RegisterCode, str]:
        """A robot under a new name: refused if its type is unknown, else
        announced (alert and fleet entry) for an operator to add; it registers
        again until one does (`backend.server.team`)."""
        why = unknown_type(self.engine.library, m.name, m.type)
        if why is not None:
            return "unknown_type", why
        info = self.robots.get(m.name)
        if info is None or not info.joining or info.manifest != m:
            self._set_robot(RobotInfo(name=m.name, manifest=m, joining=True, since=_now()))
            self._host.alert(
                announcement(self.engine.library, m), robot=m.name, kind=AlertKind.TEAM
            )
        return "joining", (
            f"robot '{m.name}' ({m.type}) is not part of this mission yet: the operators "
            "were told; it is accepted once one adds it"
        )

    def reachable(self, robot: str) -> bool:
        """It can be told something now: registered and online (the rules ask
        it when a robot is retired: `backend.core.rules.team.Reach`)."""
        return self.owner(robot) is not None

    def _taken(self, robot: str, session: str) -> tuple[RegisterCode, str] | None:
        """One owner per robot name: another live session holds it."""
        info = self.robots.get(robot)
        if info is None or not info.online or info.session in (None, session):
            return None
        since = f" since {self.contact.time_text(info.since)}" if info.since else ""
        return "taken", (
            f"robot {robot} is connected already as another session ({info.session}, online"
            f"{since}): a second process under this name would execute every skill twice; stop "
            "one of them (a hung one loses the name once its lease expires)"
        )

    # -- the downlink --------------------------------------------------------------------------
    def _handle_downlink(self, payload: bytes, key: str) -> bytes:
        robot = Keys.robot_of(key)
        dl: Downlink = self._parse(Downlink, payload, robot, "downlink")
        if dl.robot != robot:  # the key is what the router's rules check
            message = f"{robot} cannot send the downlink of {dl.robot}; nothing was applied"
            self.said_once(robot, "other robot", message, "error")
            raise Refusal("bad_message", message, robot=robot)
        info = self.robots.get(robot)
        if info is None or not info.online or info.session != dl.session:
            raise Refusal(
                "not_registered",
                f"robot {robot} (session {dl.session}) is not registered with this server: "
                "register first (nothing was applied)",
                robot=robot,
            )
        if robot in self._renew:
            raise Refusal(
                "not_registered",
                f"the mission was replaced (loaded): robot {robot} registers again, so what it "
                "holds is compared with the new mission (nothing was applied)",
                robot=robot,
            )
        self._heard(robot, dl.sent)
        progress = self._downlink.apply(robot, dl.messages)
        self.senders[robot].reachable()  # what did not reach it: now
        return dumps(
            DownlinkAck(
                last_seq=progress.last_seq, missing=progress.missing, refused=progress.refused
            )
        )

    def _heard(self, robot: str, sent: datetime | None) -> None:
        """The robot spoke: when, and (from its `sent`) the one-way delay."""
        info = self.robots.get(robot)
        if info is None:
            return
        now = _now()
        delay = info.delay_s if sent is None else self._delay_sample(robot, now - sent)
        last = self._published_heard.get(robot)
        update = {"heard": now, "delay_s": delay}
        moved = _moved(info.delay_s, delay)
        if moved or last is None or (now - last).total_seconds() >= HEARD_PUBLISH_S:
            self._set_robot(info.model_copy(update=update))
        else:  # kept for snapshots; published with the next notable change
            self.robots[robot] = info.model_copy(update=update)

    def _delay_sample(self, robot: str, took: timedelta) -> float:
        """The one-way delay estimate with this message's (`took`): the least
        of the last DELAY_SAMPLES."""
        samples = self._delays.setdefault(robot, [])
        samples.append(max(0.0, took.total_seconds()))
        del samples[:-DELAY_SAMPLES]
        return round(min(samples), 3)

    # -- presence ---------------------------------------------------------------------
    def _set_robot(self, info: RobotInfo) -> None:
        info = info.model_copy(
            update={
                "contact": self.contact.of(info.name, info.online),
                "verification": self.verification.of(info.name),
            }
        )
        self.robots[info.name] = info
        if info.heard is not None:
            self._published_heard[info.name] = info.heard
        self._host.publish_fleet(info)

    def _on_presence(self, key: str, alive: bool) -> None:
        if self._loop is not None and not self._loop.is_closed():
            robot, session = Keys.robot_of(key), Keys.session_of(key)
            self._loop.call_soon_threadsafe(self._presence, robot, session, alive)

    def _presence(self, robot: str, session: str, alive: bool) -> None:
        tokens = self._tokens.setdefault(robot, set())
        (tokens.add if alive else tokens.discard)(session)
        info = self.robots.get(robot)
        # online once it registers (with its manifest and queue); offline when
        # its registered session's token goes (another session's does not count)
        if info is None or alive or not info.online or info.session != session:
            return
        self._set_robot(info.model_copy(update={"online": False, "since": _now()}))
        self._host.alert(f"robot {robot} went offline", robot=robot, kind=AlertKind.OFFLINE)

    # -- housekeeping ------------------------------------------------------------------
    async def _housekeeping(self) -> None:
        while True:
            await asyncio.sleep(TICK_S)
            try:
                self.refresh_contact()
                self._expire()
                self.refresh_verification()
            except JournalFailed:
                pass  # alerted by the server; tried again at the next tick
            except Exception:  # a bug must not end the housekeeping
                log.exception("robot link housekeeping failed")

    def refresh_contact(self) -> None:
        """Publish the robots whose contact state changed (a window opened or
        closed, the simulator's windows came)."""
        now = _now()
        for name, info in list(self.robots.items()):
            if self.contact.of(name, info.online, now) != info.contact:
                self._set_robot(info)

    def refresh_verification(self) -> None:
        """Publish the robots whose commands' stages moved on (or fell overdue)."""
        if self._host.engine is None:
            return
        for name in self.verification.refresh(self._mission, self.robots, _now()):
            info = self.robots.get(name)
            if info is not None:
                self._set_robot(info)

    def _expire(self) -> None:
        """Queued commands (never on their way) whose expiry passed."""
        now = _now()
        for robot, ids in self._expired(now).items():
            why = _why_unsent(robot, self.robots.get(robot), self.contact.time_text)
            self.submit(
                UplinkSettle(
                    robot=robot,
                    ids=ids,
                    state=CommandState.EXPIRED,
                    reason=f"expired before it could be sent ({why})",
                    at=now,
                ),
                actor="server",
            )

    def _expired(self, now: datetime) -> dict[str, list[int]]:
        """By robot, the queued commands not being transmitted whose expiry passed at `now`."""
        transmitting = self.engine.transmitting
        due: dict[str, list[int]] = {}
        for c in self._mission.pending_commands():
            if c.state == CommandState.QUEUED and c.expires is not None and c.expires <= now:
                if c.id not in transmitting:
                    due.setdefault(c.robot, []).append(c.id)
        return due


_ON_EVENT: dict[type[Any], Callable[[RobotLink, Any], None]] = {
    ev.CommandQueued: RobotLink._queued,
    ev.CommandChanged: RobotLink._command_changed,
    ev.RobotAdded: RobotLink._robot_added,
    ev.MissionReplaced: RobotLink._mission_replaced,
}


def _moved(before: float | None, delay: float | None) -> bool:
    """A delay estimate moved enough to be published at once."""
    return before is None or (delay is not None and abs(delay - before) > max(0.2, 0.1 * before))


def _why_unsent(robot: str, info: RobotInfo | None, said: Callable[[datetime], str]) -> str:
    """Why a queued command expired unsent: its robot online but out of reach, or
    offline (since when, said on the mission clock by `said`)."""
    if info is not None and info.online:
        return "it was out of reach"
    since = f" since {said(info.since)}" if info and info.since else ""
    return f"{robot} was offline{since}"


def _legacy(payload: bytes, key: str) -> bytes:
    """A query of protocol 1: a registration is told so in its own format,
    anything else gets an ErrorReply (protocol_mismatch)."""
    message = (
        f"this mission server speaks missionctl protocol {PROTOCOL_VERSION}, not 1 "
        "(docs/protocol.md): upgrade the robot or client"
    )
    if "/server/register/" in key:
        return json_bytes({"accepted": False, "reason": message, "last_seq": 0, "missing": []})
    raise ReplyError(json_bytes({"ok": False, "code": "protocol_mismatch", "message": message}))


def json_bytes(obj: Any) -> bytes:
    return json.dumps(obj).encode()
