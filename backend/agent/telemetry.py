"""Telemetry: what the robot publishes of itself (pose, battery, link, mode,
the active skill's progress and the last status text).

A sample goes out when what an operator sees changed: beyond a deadband for
the continuous fields (position, heading, battery, link quality, progress,
and an ETA that no longer counts down as the last one said), at once for the
rest (mode, skill, status text, range); at most `telemetry_hz` times a second
(the cap); and at least every `heartbeat_s`, changed or not (the ground's
"last heard"). Samples are compact JSON of `Telemetry`: defaults left out,
numbers rounded to what is shown. `TelemetryPolicy(steady=True)` publishes at
a steady rate whatever changed, as before (a link budget's baseline)."""

from __future__ import annotations

import asyncio
import json
import math
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import zenoh

from backend.agent.queue import SkillQueue
from backend.agent.runtime import Runtime, log
from backend.core.model import Pose
from backend.protocol.messages import Telemetry, dumps

# fields compared with a deadband; every other field (and an integrator's own) at any change
_CONTINUOUS = {"pose", "battery", "link", "progress", "eta_s", "at"}
# decimals kept on the wire: millimetres, milliradians, 0.1 % of battery and link
_DECIMALS = {"x": 3, "y": 3, "z": 3, "roll": 3, "pitch": 3, "yaw": 3, "eta_s": 1}
_DEFAULT_DECIMALS = 3


@dataclass(frozen=True)
class TelemetryPolicy:
    """When a robot's telemetry goes out (see the module docstring)."""

    heartbeat_s: float = 5.0  # a sample at least this often (the downlink's heartbeat)
    position_m: float = 0.5
    heading_rad: float = math.radians(5)  # yaw, roll, pitch
    battery: float = 0.01
    link: float = 0.05
    progress: float = 0.05
    eta_s: float = 2.0  # or 10 % of the ETA, whichever is more
    compact: bool = True  # defaults left out, numbers rounded
    steady: bool = False  # every 1 / rate whatever changed, full JSON (the baseline)


STEADY = TelemetryPolicy(steady=True, compact=False)


def _angle(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def changed(policy: TelemetryPolicy, new: Telemetry, old: Telemetry | None, age_s: float) -> bool:
    """Does `new` say something the ground should see, `old` having gone
    out `age_s` seconds ago?"""
    if old is None:
        return True
    p = policy
    a, b = new.pose, old.pose
    if math.dist((a.x, a.y, a.z), (b.x, b.y, b.z)) >= p.position_m:
        return True
    if any(
        _angle(x, y) >= p.heading_rad
        for x, y in ((a.yaw, b.yaw), (a.roll, b.roll), (a.pitch, b.pitch))
    ):
        return True
    if abs(new.battery - old.battery) >= p.battery or abs(new.link - old.link) >= p.link:
        return True
    if (new.progress is None) != (old.progress is None) or (
        new.progress is not None
        and old.progress is not None
        and abs(new.progress - old.progress) >= p.progress
    ):
        return True
    if (new.eta_s is None) != (old.eta_s is None):
        return True
    if new.eta_s is not None and old.eta_s is not None:
        counted_down = max(0.0, old.eta_s - age_s)  # what the ground shows by now
        if abs(new.eta_s - counted_down) >= max(p.eta_s, 0.1 * new.eta_s):
            return True
    return _rest(new) != _rest(old)


def _rest(t: Telemetry) -> dict[str, Any]:
    return t.model_dump(exclude=_CONTINUOUS)


def _rounded(value: Any, decimals: int = _DEFAULT_DECIMALS) -> Any:
    if isinstance(value, float):
        return round(value, decimals)
    if isinstance(value, dict):
        return {k: _rounded(v, _DECIMALS.get(k, _DEFAULT_DECIMALS)) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v, decimals) for v in value]
    return value


def encode(t: Telemetry, *, compact: bool = True) -> bytes:
    """The wire form: `Telemetry` as JSON; compact leaves out what equals its
    default (the receiver's model puts it back) and rounds the numbers."""
    if not compact:
        return dumps(t)
    fields = _rounded(t.model_dump(mode="json", exclude_defaults=True))
    return json.dumps(fields, separators=(",", ":"), ensure_ascii=False).encode()


class TelemetryFeed:
    """The telemetry fields the agent keeps and the publisher they go out on."""

    def __init__(self, rt: Runtime, queue: SkillQueue, policy: TelemetryPolicy | None = None):
        self.rt = rt
        self.queue = queue
        self.policy = policy or TelemetryPolicy()
        # the queue's mode, as of the last status change or command
        self.mode = "idle"
        self.progress: float | None = None
        self.eta: float | None = None
        self.info = ""
        self.publisher: zenoh.Publisher | None = None
        self.sent = 0  # samples published (tests, benchmarks)
        self._last: Telemetry | None = None  # the last sample sent
        self._last_at = -math.inf  # loop time it was sent
        self._pending = False  # a change was announced: send at the next allowed moment
        self._wake: asyncio.Event | None = None

    def update_mode(self) -> None:
        self.mode = self.queue.mode

    def restart_progress(self) -> None:
        """A new skill or attempt starts: no progress known yet."""
        self.progress = None
        self.eta = None

    def snapshot(self) -> Telemetry:
        # An integrator's source must never break a command reply or a report
        # (both publish telemetry): a bad value is replaced, and said once.
        pose, battery, quality = self._pose(), self._battery(), self._quality()
        active = self.queue.active
        in_range = self.rt.in_range()
        return Telemetry(
            robot=self.rt.name,
            pose=pose,
            battery=battery,
            link=quality if in_range else 0.0,
            in_range=in_range,
            mode=self.mode,
            skill=active.entry.id if active is not None else None,
            progress=self.progress if active is not None else None,
            eta_s=self.eta if active is not None else None,
            info=self.info,
            at=datetime.now(UTC),
        )

    def _pose(self) -> Pose:
        try:
            pose = self.rt.robot.pose()
            if not isinstance(pose, Pose):
                pose = Pose.model_validate(pose)  # a dict of pose fields will do
        except Exception as exc:
            self._source_failed(
                "pose",
                f"agent.pose() must return a backend.core.model.Pose: {type(exc).__name__}: {exc}",
            )
            pose = Pose()
        return pose

    def _battery(self) -> float:
        try:
            return min(1.0, max(0.0, float(self.rt.robot.battery())))
        except Exception as exc:
            self._source_failed(
                "battery", f"agent.battery() must return a number 0..1: {type(exc).__name__}: {exc}"
            )
            return 0.0

    def _quality(self) -> float:
        try:
            return min(1.0, max(0.0, float(getattr(self.rt.robot.link, "quality", 1.0))))
        except Exception as exc:
            self._source_failed(
                "link", f"agent.link.quality must be a number 0..1: {type(exc).__name__}: {exc}"
            )
            return 0.0

    def _source_failed(self, what: str, problem: str) -> None:
        """A telemetry source failed: the telemetry goes on with a default."""
        self.rt.say_once(
            f"source {what}", f"{problem}; telemetry sends a default instead", exc_info=True
        )

    def show(self, text: str) -> None:
        """Show a status text that is not a status change (no report)."""
        if text != self.info:
            self.info = text
            self.publish()

    def publish(self) -> None:
        """Something changed (a status, a command, back in range): a sample
        goes out as soon as the rate cap allows."""
        if self.policy.steady:
            self._send()
            return
        self._pending = True
        if self._wake is not None:
            self._wake.set()

    def _send(self, sample: Telemetry | None = None) -> None:
        if self.publisher is None or not self.rt.in_range():
            return  # out of range: the operator cannot hear us (sent when back)
        if sample is None:
            sample = self.rt.robot.telemetry()  # the agent's: a subclass may extend it
        payload = encode(sample, compact=self.policy.compact)
        loop = self.rt.loop
        self._last = sample
        self._last_at = loop.time() if loop is not None else 0.0
        self._pending = False
        self.sent += 1
        delay = self.rt.delay_s()
        if delay > 0 and loop is not None:
            # the ground sees the robot as it was one link delay ago
            loop.call_later(delay, self._put, payload)
        else:
            self._put(payload)

    def _put(self, payload: bytes) -> None:
        publisher = self.publisher
        if publisher is None:
            return  # stopped meanwhile
        try:
            publisher.put(payload)
        except Exception:
            log.exception("%s: cannot publish telemetry", self.rt.name)

    async def run(self, hz: float) -> None:
        """Until the agent stops: look at the sources `hz` times a second (at
        most that many samples; 0: at changes and heartbeats only)."""
        if self.policy.steady:
            await self._steady(hz)
            return
        loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        self._pending = True  # the first sample at once
        gap = 1.0 / hz if hz > 0 else 0.0
        try:
            while not self.rt.closing:
                wait = self._last_at + gap - loop.time()
                if wait > 0:  # the cap
                    await asyncio.sleep(wait)
                self._maybe_send(loop.time())
                try:
                    await asyncio.wait_for(self._wake.wait(), gap or self.policy.heartbeat_s)
                except TimeoutError:
                    pass
                self._wake.clear()
        finally:
            self._wake = None

    def _maybe_send(self, now: float) -> None:
        age = now - self._last_at
        if self._pending or age >= self.policy.heartbeat_s:
            self._send()
            return
        sample = self.rt.robot.telemetry()
        if changed(self.policy, sample, self._last, age):
            self._send(sample)

    async def _steady(self, hz: float) -> None:
        if hz <= 0:
            return
        while not self.rt.closing:
            self._send()
            await asyncio.sleep(1.0 / hz)
