"""Barriers: skills of several robots that start together. Each robot shows it
is ready with a liveliness token `Keys.barrier_ready(barrier, robot)` and
waits (synchwaiting) until every partner's token is there; no server involved.
A partner the robot cannot reach (`Link.can_reach`, e.g. a simulated radio
link) counts as not ready: it is shown as unreachable and looked at again.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from backend import transport
from backend.agent.context import Execution
from backend.agent.runtime import Runtime
from backend.protocol.keys import Keys

# A barrier partner whose presence token has not shown up by then is offline.
PRESENCE_GRACE_S = 1.0
# How often a partner the robot cannot reach is looked at again (the link is polled).
REACH_POLL_S = 0.1


class _Meeting:
    """What one wait knows of the partners: ready, online (None: not known yet),
    reachable (asked of the link model)."""

    def __init__(self, partners: list[str], reachable: Callable[[str], bool]):
        self.partners = partners
        self.reachable = reachable
        self.ready: set[str] = set()
        self.met = False
        self.online: dict[str, bool | None] = dict.fromkeys(partners)
        self.changed = asyncio.Event()

    def on_ready(self, key: str, alive: bool) -> None:
        robot = key.rsplit("/", 1)[-1]
        (self.ready.add if alive else self.ready.discard)(robot)
        # Judge in event order: a fast partner may start, finish and withdraw
        # its token before the wait looks again; it was ready.
        if all(p in self.ready and self.reachable(p) for p in self.partners):
            self.met = True
        self.changed.set()

    def on_alive(self, robot: str, alive: bool) -> None:
        self.online[robot] = alive
        self.changed.set()

    def presence_deadline(self) -> None:
        # The subscriber's history reports a present token within
        # milliseconds but never says "absent": no token by now = offline.
        for p in self.partners:
            if self.online[p] is None:
                self.online[p] = False
        self.changed.set()

    def missing(self) -> list[str]:
        """The partners not ready (or not reachable) yet; none once all were at one time."""
        if self.met:
            return []
        return [p for p in self.partners if p not in self.ready or not self.reachable(p)]

    def offline(self, missing: list[str]) -> tuple[str, ...]:
        return tuple(p for p in missing if self.online[p] is False)

    def unreachable(self, missing: list[str]) -> tuple[str, ...]:
        return tuple(p for p in missing if self.online[p] is not False and not self.reachable(p))


def _waiting_text(
    missing: list[str], offline: tuple[str, ...], unreachable: tuple[str, ...] = ()
) -> str:
    if offline or unreachable:
        return "waiting for " + ", ".join(
            [f"{p} (offline)" for p in offline] + [f"{p} (unreachable)" for p in unreachable]
        )
    return "waiting for " + ", ".join(missing)


def _can_reach(rt: Runtime, robot: str) -> bool:
    """The link model's answer; a link model that fails counts as reachable."""
    link = rt.robot.link
    try:
        return bool(link.can_reach(robot)) if hasattr(link, "can_reach") else True
    except Exception as exc:
        rt.say_once(
            "link.can_reach",
            f"agent.link.can_reach() failed ({type(exc).__name__}: {exc}); assuming reachable",
            exc_info=True,
        )
        return True


async def wait_for_partners(
    rt: Runtime, act: Execution, report: Callable[[str], object], show: Callable[[str], None]
) -> None:
    """Wait until every partner's ready token is present. `report(text)` makes a
    synchwaiting report, `show(text)` only updates telemetry. Our token stays
    until the skill ends (Execution.release)."""
    assert rt.session is not None and act.entry.barrier is not None
    info = act.entry.barrier
    session = rt.session
    partners = sorted(p for p in info.partners if p != rt.name)
    if not partners:
        return  # a barrier of one robot: nothing to wait for
    meeting = _Meeting(partners, lambda robot: _can_reach(rt, robot))
    report("waiting for " + ", ".join(partners))
    # Order matters (race-free): subscribe to the partners' ready tokens
    # (with history) BEFORE declaring ours. A partner starts only after it
    # saw our token, and withdraws its own only after starting; so its
    # token is either already there when we subscribe (history) or appears
    # later (live): we cannot miss it. Declaring first could let a fast
    # partner see us, start and withdraw before our subscription existed.
    act.barrier_entities.append(
        transport.watch_liveliness(
            session,
            Keys.barrier_ready(info.barrier, "*"),
            lambda key, alive: rt.post(meeting.on_ready, key, alive),
        )
    )
    act.barrier_token = transport.declare_token(session, Keys.barrier_ready(info.barrier, rt.name))
    for p in partners:

        def on_alive(_key: str, alive: bool, p: str = p) -> None:
            rt.post(meeting.on_alive, p, alive)

        act.barrier_entities.append(transport.watch_liveliness(session, Keys.alive(p), on_alive))
    deadline = asyncio.get_running_loop().call_later(PRESENCE_GRACE_S, meeting.presence_deadline)
    try:
        await _until_met(meeting, report, show)
    finally:
        deadline.cancel()


async def _until_met(
    meeting: _Meeting, report: Callable[[str], object], show: Callable[[str], None]
) -> None:
    reported: tuple[tuple[str, ...], tuple[str, ...]] = ((), ())
    while missing := meeting.missing():
        offline, unreachable = meeting.offline(missing), meeting.unreachable(missing)
        text = _waiting_text(missing, offline, unreachable)
        # Report again whenever a partner goes offline, out of reach or comes
        # back; other changes only update telemetry (no report flood).
        if (offline, unreachable) != reported:
            report(text)
            reported = (offline, unreachable)
        else:
            show(text)
        # all state changes happen on the loop: clearing here loses nothing
        meeting.changed.clear()
        if unreachable:  # reachability is polled, not announced
            try:
                await asyncio.wait_for(meeting.changed.wait(), REACH_POLL_S)
            except TimeoutError:
                pass
        else:
            await meeting.changed.wait()
