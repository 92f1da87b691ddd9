"""The robot's synchronized queue as a state machine: no Zenoh, no asyncio.

It is the one owner of what the robot holds: the skills waiting in order, the
active one (and why it is paused), the finished ids, run mode and the report
numbers. Commands return what they actually did (`Effect`), so the agent
answers the server with the truth, not with what was asked. Every status
change is a numbered `Report` handed to `on_report` at once, in order.

The rules it keeps (docs/robots.md, "Behaviour an integrator can rely on"):

- halted until `run`; in run mode `next_skill` hands out the head of the
  queue, one at a time; run mode stays on when the queue drains;
- a failure, `pause`, `stop` or `reset` leaves run mode; `run` on a skill the
  operator paused resumes it;
- `stop` puts the active skill back at the head, `reset` forgets everything;
- an enqueue sent again never queues a skill twice nor runs a finished one.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from types import MappingProxyType

from backend.core.model import (
    BarrierInfo,
    Branches,
    ChooseOnBoard,
    Pose,
    SkillInstance,
    Status,
    Taken,
)
from backend.core.ops import Answer, Ask, AskEnded, Report

Msg = Report | Answer | Ask | AskEnded  # a downlink message


def _now() -> datetime:
    return datetime.now(UTC)


@dataclass
class HeldSkill:
    """A skill the robot holds (queued or active)."""

    skill: SkillInstance
    barrier: BarrierInfo | None = None
    # parameter -> its kind, as sent with the skill (Enqueue.kinds): how its handler gets it
    kinds: Mapping[str, str] = field(default_factory=dict)
    status: Status = Status.IDLE_SYNCHRONIZED
    # the skills its fallback / goto branches run (Enqueue.contingencies), their kinds
    branches: Branches | None = None
    branch_kinds: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    after_robot: str | None = None  # the robot running policies.after (Enqueue.after)
    # parameter -> the marker chosen on board it takes its value from (Enqueue.choose)
    choose: Mapping[str, ChooseOnBoard] = field(default_factory=dict)
    attempt: int = 1
    retries_used: int = 0
    reported_attempt: int = 0  # the attempt of its last report

    @property
    def id(self) -> str:
        return self.skill.id


@dataclass
class Active:
    """The entry being executed and why it is paused (both reasons may hold)."""

    entry: HeldSkill
    paused_by_operator: bool = False
    paused_by_comms: bool = False

    @property
    def paused(self) -> bool:
        return self.paused_by_operator or self.paused_by_comms


@dataclass(frozen=True)
class Effect:
    """What a command did. A command either queues or removes skills."""

    ok: bool = True
    reason: str = ""  # why it was refused, or what the operator should know
    queued: list[str] = field(default_factory=list)  # held in the queue now
    removed: list[str] = field(default_factory=list)  # gone (unsync, reset)
    started: list[str] = field(default_factory=list)  # asked to remove, but had started


class SkillQueue:
    """The synchronized queue of robot `robot`; see the module docstring."""

    def __init__(
        self,
        robot: str,
        on_report: Callable[[Report], object] = lambda report: None,
        clock: Callable[[], datetime] = _now,
    ):
        self.robot = robot
        self.on_report = on_report
        self._clock = clock
        self._waiting: list[HeldSkill] = []
        self.active: Active | None = None
        self.run_enabled = False  # halted until `run`
        # finished ids and how they ended (a re-sent enqueue never re-runs them; other
        # robots ask for the outcome of a skill they start after: policies.after)
        self.outcomes: dict[str, Status] = {}
        self.seq = 0  # number of the last report made

    # ------------------------------------------------------------ views

    @property
    def waiting(self) -> list[str]:
        """Ids of the queued (not started) skills, in order."""
        return [e.id for e in self._waiting]

    def entries(self) -> list[HeldSkill]:
        """The active entry, then the queued ones: what the robot holds."""
        head = [self.active.entry] if self.active is not None else []
        return head + self._waiting

    def outcome(self, skill_id: str) -> str:
        """How a skill stands here: 'success' / 'failure' when it ended, its
        status while held, else 'unknown' (not synchronized to this robot)."""
        ended = self.outcomes.get(skill_id)
        held = self.holds(skill_id)
        status = ended or (held.status if held is not None else None)
        return status.value if status is not None else "unknown"

    def holds(self, skill_id: str) -> HeldSkill | None:
        return next((e for e in self.entries() if e.id == skill_id), None)

    @property
    def mode(self) -> str:
        """The robot's mode as telemetry shows it."""
        if self.active is not None:
            status = self.active.entry.status
            # just taken from the queue, not reported yet: "starting"
            return "starting" if status == Status.IDLE_SYNCHRONIZED else status.value
        if self._waiting:
            return "running" if self.run_enabled else "halted"
        return "idle"

    # ------------------------------------------------------------ commands

    def enqueue(
        self,
        skills: Iterable[SkillInstance],
        barriers: Mapping[str, BarrierInfo] | None = None,
        *,
        front: bool = False,
        offered: Collection[str],
        kinds: Mapping[str, Mapping[str, str]] | None = None,
        contingencies: Mapping[str, Branches] | None = None,
        after: Mapping[str, str] = MappingProxyType({}),
        choose: Mapping[str, Mapping[str, ChooseOnBoard]] = MappingProxyType({}),
    ) -> Effect:
        """Queue `skills` (at the head when `front`: a retry the operator asked
        for), each with its parameters' kinds (`kinds`: skill name -> parameter
        -> kind). Refused when one has no handler among `offered`. Sent again,
        it changes nothing: ids queued already or finished are skipped."""
        skills = list(skills)
        contingencies = contingencies or {}
        unknown = sorted({s.skill for s in _with_branches(skills, contingencies)} - set(offered))
        if unknown:
            return Effect(
                ok=False,
                reason=f"{self.robot} has no handler for skill {', '.join(unknown)} "
                f"(it offers: {', '.join(sorted(offered)) or 'none'})",
            )
        barriers = barriers or {}
        kinds = kinds or {}
        new: list[HeldSkill] = []
        ids: list[str] = []
        for s in skills:
            if s.id in self.outcomes:
                continue  # a re-sent enqueue: it ran already
            ids.append(s.id)
            if self.holds(s.id) is not None or any(e.id == s.id for e in new):
                continue  # a re-sent enqueue: it is queued already
            skill = s.model_copy(update={"status": Status.IDLE_SYNCHRONIZED})
            new.append(
                HeldSkill(
                    skill=skill,
                    barrier=barriers.get(s.id),
                    kinds=kinds.get(s.skill, {}),
                    branches=contingencies.get(s.id),
                    branch_kinds=kinds,
                    after_robot=after.get(s.id),
                    choose=choose.get(s.id, {}),
                    attempt=s.attempt,
                )
            )
        self._waiting = new + self._waiting if front else self._waiting + new
        return Effect(queued=ids)

    def unsync(self, ids: list[str]) -> Effect:
        """Remove queued skills. Those that started meanwhile (active or
        finished) stay: the unsync race, told by the reports."""
        wanted = set(ids)
        removed = [e.id for e in self._waiting if e.id in wanted]
        self._waiting = [e for e in self._waiting if e.id not in wanted]
        active = self.active.entry.id if self.active is not None else None
        started = [i for i in ids if i in self.outcomes or i == active]
        # Ids we never had cannot run either: they count as removed.
        removed += [i for i in ids if i not in removed and i not in started]
        return Effect(removed=removed, started=started)

    def run(self) -> Effect:
        """Run mode; a skill the operator paused resumes."""
        self.run_enabled = True
        act = self.active
        if act is not None and act.paused_by_operator:
            act.paused_by_operator = False
            if not act.paused:
                self.report(act.entry, Status.RUNNING, "resumed")
            return Effect()
        if act is None and not self._waiting:
            # Stays in run mode: skills synchronized later start at once.
            return Effect(
                reason=f"{self.robot} has nothing queued; it will run what is synchronized next"
            )
        return Effect()

    def pause(self) -> Effect:
        """Leave run mode; a running skill pauses (not one waiting at a barrier:
        the status table has no synchwaiting -> paused)."""
        act = self.active
        if act is not None and act.entry.status == Status.SYNCHWAITING:
            return Effect(
                ok=False,
                reason=f"{self.robot} is waiting at a barrier with {act.entry.id}; only a running "
                f"skill can be paused (stop it instead)",
            )
        self.run_enabled = False
        if act is None:
            return Effect(reason=f"{self.robot} has no running skill; its queue is halted")
        if not act.paused_by_operator:
            was_running = act.entry.status == Status.RUNNING
            act.paused_by_operator = True
            if was_running:
                self.report(act.entry, Status.PAUSED, "paused by operator")
        return Effect()

    def stop(self, info: str = "stopped by operator") -> Effect:
        """Leave run mode; the active skill goes back to the head of the queue."""
        self.run_enabled = False
        if self.active is None:
            return Effect(reason=f"{self.robot} has no active skill; its queue is halted")
        entry = self._end_active(info)
        self._waiting.insert(0, entry)
        return Effect()

    def reset(self, info: str = "reset by operator") -> Effect:
        """Leave run mode; the active skill and the queue are forgotten."""
        self.run_enabled = False
        removed: list[str] = []
        if self.active is not None:
            removed.append(self._end_active(info).id)
        removed += [e.id for e in self._waiting]
        self._waiting = []
        return Effect(removed=removed)

    def _end_active(self, info: str) -> HeldSkill:
        """The active skill is no longer active: `idle_synchronized` again."""
        assert self.active is not None
        entry = self.active.entry
        self.active = None
        if entry.status != Status.IDLE_SYNCHRONIZED:
            self.report(entry, Status.IDLE_SYNCHRONIZED, info)
        return entry

    # ------------------------------------------------------------ execution

    def next_skill(self) -> Active | None:
        """The head of the queue becomes active, if in run mode and idle."""
        if not self.run_enabled or self.active is not None or not self._waiting:
            return None
        self.active = Active(self._waiting.pop(0))
        return self.active

    def finish(
        self, status: Status, info: str = "", branch: Taken | None = None, go_on: bool = False
    ) -> Report:
        """The active skill ended (success or failure: final). A failure halts
        the queue unless its contingency goes on (`go_on`: skip, continue, a
        fallback that succeeded)."""
        assert self.active is not None
        entry = self.active.entry
        self.active = None
        self.outcomes[entry.id] = status
        if status == Status.FAILURE and not go_on:
            self.run_enabled = False  # the operator decides: retry, run (continue) or unsync
        report = self.report(entry, status, info, branch)
        assert report is not None  # a final status is always reported
        return report

    def next_attempt(self) -> bool:
        """The active skill failed: with a retry left (policies.retries) it
        stays running with the next attempt (failure is final, so it is never
        reported in between). False when none is left."""
        assert self.active is not None
        entry = self.active.entry
        if entry.retries_used >= entry.skill.policies.retries:
            return False
        entry.retries_used += 1
        entry.attempt += 1
        # ctx.skill.attempt agrees with ctx.attempt and the reports
        entry.skill = entry.skill.model_copy(update={"attempt": entry.attempt})
        return True

    def pause_for_comms(self) -> bool:
        """Out of range (policies.pause_out_of_comms): the running skill pauses.
        True when the pause reasons changed."""
        act = self.active
        status = act.entry.status if act is not None else None
        if act is None or act.paused_by_comms or status not in (Status.RUNNING, Status.PAUSED):
            return False
        act.paused_by_comms = True
        if status == Status.RUNNING:
            self.report(act.entry, Status.PAUSED, "paused: out of communication range")
        return True

    def resume_after_comms(self) -> bool:
        """Back in range: a skill paused for it resumes (unless the operator
        paused it too). True when the pause reasons changed."""
        act = self.active
        if act is None or not act.paused_by_comms:
            return False
        act.paused_by_comms = False
        if not act.paused:
            self.report(act.entry, Status.RUNNING, "resumed: back in communication range")
        return True

    def abandon(self) -> None:
        """The agent stops: the active skill is dropped without a report (the
        server sees the robot go offline)."""
        self.active = None

    def forget(self) -> None:
        """Another run of this robot took over: hold nothing, run nothing,
        report nothing (the ground listens to the other one)."""
        self.active = None
        self._waiting = []
        self.run_enabled = False

    # ------------------------------------------------------------ reports

    def next_seq(self) -> int:
        """The next downlink number (an answer to a command shares the
        reports' sequence)."""
        self.seq += 1
        return self.seq

    def report(
        self,
        entry: HeldSkill,
        status: Status,
        info: str = "",
        branch: Taken | None = None,
        chosen: Mapping[str, Pose] | None = None,
    ) -> Report | None:
        """Record a status change of `entry` as the next numbered report.
        None when it is no change: `running` again at the same attempt (the
        ground refuses it: running -> running only with a higher attempt),
        e.g. the skill starting after recharging first, or a retry resumed; but
        running again with the contingency branch it takes is news."""
        again = status == entry.status == Status.RUNNING and entry.attempt == entry.reported_attempt
        if again and branch is None:
            return None
        self.seq += 1
        entry.status = status
        entry.reported_attempt = entry.attempt
        report = Report(
            robot=self.robot,
            seq=self.seq,
            id=entry.id,
            status=status,
            info=info,
            attempt=entry.attempt,
            at=self._clock(),
            branch=branch,
            chosen=dict(chosen or {}),
        )
        self.on_report(report)
        return report

    def continue_after(self, last_seq: int, pending: list[Msg]) -> list[Msg] | None:
        """The server applied reports up to `last_seq`. When that is higher than
        ours (a previous run of this robot), ours would be ignored as
        duplicates: the `pending` (unacknowledged) ones are renumbered after
        it, and numbering goes on from there; none of them can have been
        applied, as the server never saw a number this high from us. None
        when our numbers are higher already."""
        if last_seq <= self.seq:
            return None
        self.seq = last_seq + len(pending)
        return [r.model_copy(update={"seq": last_seq + 1 + i}) for i, r in enumerate(pending)]


def _with_branches(
    skills: list[SkillInstance], contingencies: Mapping[str, Branches]
) -> list[SkillInstance]:
    """The skills and those their fallback / goto branches run: all need a handler."""
    return skills + [x for b in contingencies.values() for x in (*b.on_failure, *b.on_timeout)]
