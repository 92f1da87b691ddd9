"""Telemetry: what the robot publishes of itself (pose, battery, link, mode,
the active skill's progress and the last status text), at a steady rate and
after every change."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime

import zenoh

from backend.agent.queue import SkillQueue
from backend.agent.runtime import Runtime, log
from backend.core.model import Pose
from backend.protocol.messages import Telemetry, dumps


class TelemetryFeed:
    """The telemetry fields the agent keeps and the publisher they go out on."""

    def __init__(self, rt: Runtime, queue: SkillQueue):
        self.rt = rt
        self.queue = queue
        # the queue's mode, as of the last status change or command
        self.mode = "idle"
        self.progress: float | None = None
        self.eta: float | None = None
        self.info = ""
        self.publisher: zenoh.Publisher | None = None

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
        if self.publisher is None or not self.rt.in_range():
            return  # out of range: the operator cannot hear us
        payload = dumps(self.rt.robot.telemetry())  # the agent's: a subclass may extend it
        delay = self.rt.delay_s()
        if delay > 0 and self.rt.loop is not None:
            # the ground sees the robot as it was one link delay ago
            self.rt.loop.call_later(delay, self._put, payload)
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
        """Publish `hz` times a second until the agent stops."""
        period = 1.0 / hz if hz > 0 else None
        if period is None:
            return
        while not self.rt.closing:
            self.publish()
            await asyncio.sleep(period)
