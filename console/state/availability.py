"""Why an action does not apply to the selection (None: it applies).

One small rule per action of the mission screen, in a table beside the
actions table (console/state/actions.py); the footer greys out, the palette
explains and a pressed key says the rule's sentence. Before any rule: a
mission must be loaded, the console connected (but for a few offline
actions) and allowed to change the mission (an observer account is not).
Textual-free, and the model is only read (`Facts`), so every sentence is
unit-tested without a terminal.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from backend.core.model import (
    FINISHED,
    Mission,
    SkillInstance,
    Status,
    UplinkCommand,
    how_to_change,
)
from backend.core.ops import Sync
from backend.core.rules.base import Refusal, uplink_locks
from backend.core.rules.uplink import pending_allows, sync_skills
from console.state.keys import KeyNames
from console.state.text import STATUS_WORDS

Found = tuple[str, int, SkillInstance]  # (robot, index in its task, skill)

# actions that change nothing on the server: they apply while disconnected
OFFLINE_OK = frozenset({"save", "help", "edit", "search"})
# actions an observer (read-only account) may still use: they change nothing on the server
READ_ONLY_OK = frozenset({"save", "help", "edit", "mark", "toggle_static", "clear_marks", "search"})


class Facts(Protocol):
    """What the rules read of the console's model (`ConsoleModel`)."""

    mission: Mission | None
    connection: str
    read_only: str
    keys: KeyNames  # the user's keys, for the sentences that name one

    @property
    def connected(self) -> bool: ...
    def find(self, skill_id: str | None) -> Found | None: ...
    def task(self, robot: str) -> list[SkillInstance]: ...
    def skills_of(self, robot: str) -> list[str]: ...
    def owner(self, skill_id: str) -> str | None: ...
    def barrier_of(self, skill_id: str) -> str | None: ...
    def is_online(self, robot: str) -> bool: ...
    def presence_text(self, robot: str) -> str: ...
    def robot_state(self, robot: str) -> tuple[SkillInstance | None, int]: ...
    def plan_blocking(self, robot: str, skill_id: str) -> list[str]: ...
    def pending(self, robot: str) -> list[UplinkCommand]: ...
    def uplinking(self, skill_id: str) -> UplinkCommand | None: ...


@dataclass(frozen=True)
class Selected:
    """The selection a rule judges: robot column, the skill found under the
    cursor (None: no skill there), the skills marked for a barrier."""

    facts: Facts
    robot: str | None
    found: Found | None
    marks: list[str]

    @property
    def skill(self) -> SkillInstance | None:
        return self.found[2] if self.found else None


Rule = Callable[[Selected], str | None]


def why_not(
    facts: Facts,
    action: str,
    robot: str | None,
    skill_id: str | None,
    marks: list[str] | None = None,
) -> str | None:
    refused = _refused_here(facts, action)
    if refused is not None:
        return refused
    rule = RULES.get(action)
    if rule is None:
        return None  # undo, redo, load, save: the server decides
    return rule(Selected(facts, robot, facts.find(skill_id), marks or []))


def _refused_here(facts: Facts, action: str) -> str | None:
    """Why `action` cannot be done from this console now, whatever it acts
    on: no mission yet, a read-only view, no connection to the server."""
    if facts.mission is None:
        return "no mission loaded yet"
    if facts.read_only and action not in READ_ONLY_OK:
        return facts.read_only  # first: a review is never connected, and need not say so
    if not facts.connected and action not in OFFLINE_OK:
        return (
            f"not connected to the mission server ({facts.connection}): nothing can be changed now"
        )
    return None


def read_only_reason(facts: Facts, skill_id: str) -> str | None:
    """Why the parameter editor is read-only for this skill (None: editable)."""
    found = facts.find(skill_id)
    if found is None:
        return "the skill no longer exists"
    robot, _, s = found
    if facts.read_only:  # the editor says "read-only: <reason>" itself
        return facts.read_only.removeprefix("read-only: ")
    if s.status == Status.IDLE:
        c = facts.uplinking(s.id)
        if c is not None:
            return uplinking_why(c, facts.keys)
        if not facts.connected:
            return (
                f"not connected to the mission server ({facts.connection}): "
                "edits cannot be applied now"
            )
        return None
    return not_idle(robot, s, "only idle skills can be edited")


def uplinking_why(c: UplinkCommand, keys: KeyNames) -> str:
    """Why a skill a pending command concerns cannot change now, and the key that cancels it."""
    return (
        f"{c.title()} to {c.robot} is waiting for the robot's answer: "
        f"wait for it, or cancel the command ({keys.say('mission.cancel')} on the schedule)"
    )


def not_idle(robot: str, s: SkillInstance, rule: str) -> str:
    """Why a skill that is not idle cannot be changed, and how to change it."""
    if s.status in FINISHED:
        word = "succeeded" if s.status == Status.SUCCESS else "failed"
        return f"{s.id} {word} on {robot}: {how_to_change(s.status)}"
    return f"{s.id} is {s.status.value} on {robot}: {rule}; {how_to_change(s.status)}"


# -- the plan ----------------------------------------------------------------------------


def _add(q: Selected) -> str | None:
    if q.robot is None:
        return "select a robot column first"
    if not q.facts.skills_of(q.robot):
        return f"{q.robot} has no skills in the library"
    return None


def _edit(q: Selected) -> str | None:
    return None if q.skill is not None else "select a skill first"


def _idle_skill(q: Selected, verb: str) -> str | None:
    """A skill is selected and idle (only those are deleted or moved)."""
    if q.found is None:
        return "select a skill first"
    robot, _, s = q.found
    if s.status != Status.IDLE:
        return not_idle(robot, s, f"only idle skills can be {verb}")
    c = q.facts.uplinking(s.id)
    return uplinking_why(c, q.facts.keys) if c is not None else None


def _delete(q: Selected) -> str | None:
    return _idle_skill(q, "deleted")


def _move(end: int, word: str) -> Rule:
    """Move up (end 0) or down (end -1): not past that end of the plan."""

    def rule(q: Selected) -> str | None:
        why = _idle_skill(q, "moved")
        if why is not None or q.found is None:
            return why
        robot, _, s = q.found
        idle = [x.id for x in q.facts.task(robot) if x.status == Status.IDLE]
        if idle and idle[end] == s.id:
            return f"{s.id} is already {word} in {robot}'s plan"
        return None

    return rule


# -- synchronization ---------------------------------------------------------------------


def _sync(q: Selected) -> str | None:
    if q.found is None:
        return "select the last skill to synchronize"
    r, _, s = q.found
    mission = q.facts.mission
    assert mission is not None  # why_not says so first
    try:  # the rule the server applies says which skills it would send
        sync_skills(mission, Sync(robot=r, through=s.id), uplink_locks(mission))
    except Refusal as refused:
        return _sync_refused(q, refused, r, s)
    blocked = q.facts.plan_blocking(r, s.id)
    if blocked:
        more = f" and {len(blocked) - 2} more" if len(blocked) > 2 else ""
        return (
            f"unwaived plan error {', '.join(blocked[:2])}{more}: fix the plan, or waive "
            f"it with a reason on the checks screen ({q.facts.keys.say('app.show_checks')})"
        )
    return None


def _sync_refused(q: Selected, refused: Refusal, robot: str, s: SkillInstance) -> str:
    """The rule's refusal in the console's words where it has its own: the
    status as the schedule shows it, the pending command and its way out."""
    if refused.code == "not_idle":
        return (
            f"{s.id} is {STATUS_WORDS[s.status]} on {robot}: "
            "synchronize through an idle (unsynchronized) skill"
        )
    c = q.facts.uplinking(s.id) if refused.code == "locked" else None
    return uplinking_why(c, q.facts.keys) if c is not None else refused.message


def _unsync(q: Selected) -> str | None:
    if q.found is None:
        return "select the first queued skill to take back"
    r, _, s = q.found
    if s.status != Status.IDLE_SYNCHRONIZED:
        return (
            f"{s.id} is {STATUS_WORDS[s.status]} on {r}: "
            "only queued (idle_synchronized) skills can be unsynchronized"
        )
    return None


def _mark(q: Selected) -> str | None:
    s = q.skill
    if s is None:
        return "select a skill to mark"
    if s.status != Status.IDLE and s.id not in q.marks:
        return f"{s.id} is {STATUS_WORDS[s.status]}: barriers join idle skills only"
    return None


def _barrier(q: Selected) -> str | None:
    bid = q.facts.barrier_of(q.skill.id) if q.skill is not None and not q.marks else None
    if bid is not None:  # nothing marked, on a skill of a barrier: its wait changes
        return _barrier_wait(q, bid)
    if len(q.marks) < 2:
        mark = q.facts.keys.say("mission.mark")
        return (
            f"mark one idle skill on each of at least two robots ({mark}), then make the "
            "barrier (or select a skill of a barrier to change how long it waits)"
        )
    return _marks_joinable(q)


def _marks_joinable(q: Selected) -> str | None:
    """Why the marked skills cannot make a barrier (None: they can)."""
    robots: dict[str, str] = {}
    for sid in q.marks:
        f = q.facts.find(sid)
        if f is None:
            return f"{sid} no longer exists"
        r, _, s = f
        if s.status != Status.IDLE:
            return f"{sid} is {STATUS_WORDS[s.status]} on {r}: barriers join idle skills"
        if r in robots:
            return f"{robots[r]} and {sid} both belong to {r}: a barrier takes one skill per robot"
        robots[r] = sid
        bid = q.facts.barrier_of(sid)
        if bid is not None:
            return f"{sid} is already in barrier {bid}"
    return None


def _barrier_wait(q: Selected, bid: str) -> str | None:
    """A barrier's wait changes while all its skills are idle (a robot holds the rest)."""
    mission = q.facts.mission
    for sid in mission.barriers[bid].skills if mission is not None else []:
        f = q.facts.find(sid)
        if f is not None and f[2].status != Status.IDLE:
            return not_idle(
                f[0], f[2], f"barrier {bid}'s wait changes only while its skills are idle"
            )
    return None


def _unbarrier(q: Selected) -> str | None:
    s = q.skill
    if s is None:
        return "select a skill of the barrier to remove"
    bid = q.facts.barrier_of(s.id)
    if bid is None:
        return f"{s.id} is in no barrier"
    mission = q.facts.mission
    for sid in mission.barriers[bid].skills if mission is not None else []:
        f = q.facts.find(sid)
        if f and f[2].status != Status.IDLE and f[2].status not in FINISHED:
            status = f[2].status
            return (
                f"barrier {bid}: {sid} is {STATUS_WORDS[status]} on {f[0]}; {how_to_change(status)}"
            )
    return None


def _failed_once(q: Selected) -> str | None:
    """A failed skill is selected and has no next attempt yet."""
    if q.found is None:
        return "select a failed skill"
    s = q.found[2]
    if s.status != Status.FAILURE:
        return f"{s.id} is {STATUS_WORDS[s.status]}: only a failed skill can be retried"
    if q.facts.owner(s.retry_id()) is not None:
        return f"{s.id} was already retried as {s.retry_id()}"
    return None


def _retry(q: Selected) -> str | None:
    why = _failed_once(q)
    if why is not None or q.found is None:
        return why
    r, i, s = q.found
    if any(x.status in FINISHED for x in q.facts.task(r)[i + 1 :]):
        return f"{r} has executed other skills since {s.id} failed; add a new skill instead"
    act = q.facts.robot_state(r)[0]
    if act is not None:
        return f"{r} is executing {act.id}: stop it first"
    return None


def _cancel(q: Selected) -> str | None:
    if q.found is None:
        return "select a skill a pending command locks (⇡)"
    s = q.found[2]
    c = q.facts.uplinking(s.id)
    if c is None:
        return f"no command waits on {s.id}: only a skill marked ⇡ has one to cancel"
    if c.cancel_requested:
        return f"cancelling {c.title()} was asked already: {c.robot}'s answer decides"
    return None


def _duplicate(q: Selected) -> str | None:
    if q.found is None:
        return "select a skill to duplicate"
    robot, _, s = q.found
    if s.skill not in q.facts.skills_of(robot):
        return f"{robot} has no skill '{s.skill}' in the library"
    return None


def _give_to(q: Selected) -> str | None:
    """Marked skills, a retired robot's plan, or the idle skill under the cursor."""
    if q.marks:
        return None
    m = q.facts.mission
    spec = m.robots.get(q.robot) if m is not None and q.robot is not None else None
    if spec is not None and spec.retired:
        return None
    return _idle_skill(q, "given to another robot")


# -- execution: what a robot can be asked, from (active skill, any queued) ---------------------


def _run_why(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    if act is not None and act.status == Status.PAUSED:
        return None
    if act is not None:
        return f"{robot} is already executing {act.id} ({STATUS_WORDS[act.status]})"
    return None if queued else f"{robot} has nothing to run: synchronize skills first"


def _pause_why(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    if act is not None and act.status == Status.RUNNING:
        return None
    return f"{robot} has no running skill to pause"


def _stop_why(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    return None if act is not None else f"{robot} has no running, paused or waiting skill to stop"


def _reset_why(robot: str, act: SkillInstance | None, queued: bool) -> str | None:
    return None if act is not None or queued else f"{robot} has nothing synchronized to reset"


CONTROLS: dict[str, Callable[[str, SkillInstance | None, bool], str | None]] = {
    "run": _run_why,
    "pause": _pause_why,
    "stop": _stop_why,
    "reset": _reset_why,
}


def control_why(facts: Facts, verb: str, robot: str) -> str | None:
    """Why `verb` (run, pause, stop, reset) does not apply to `robot`: what the
    ground knows plus the robot's pending commands, as the server judges it.
    An offline robot can be asked: the command waits for it (the uplink)."""
    act, n_queued = facts.robot_state(robot)
    pending = {c.op for c in facts.pending(robot)}
    if pending_allows(verb, act, n_queued > 0, pending):
        return None
    return CONTROLS[verb](robot, act, n_queued > 0)


def _control(verb: str) -> Rule:
    def rule(q: Selected) -> str | None:
        if q.robot is None:
            return "select a robot column first"
        return control_why(q.facts, verb, q.robot)

    return rule


def _control_all(verb: str) -> Rule:
    def rule(q: Selected) -> str | None:
        robots = q.facts.mission.robots if q.facts.mission is not None else {}
        reasons = [control_why(q.facts, verb, r) for r in robots]
        if all(reasons):
            return f"{verb} applies to no robot: " + "; ".join(x for x in reasons if x)
        return None

    return rule


# action name -> its rule; the actions without one (undo, redo, load, save, ...) always apply
RULES: dict[str, Rule] = {
    "add": _add,
    "edit": _edit,
    "delete": _delete,
    "move_up": _move(0, "first"),
    "move_down": _move(-1, "last"),
    "sync": _sync,
    "unsync": _unsync,
    "mark": _mark,
    "barrier": _barrier,
    "unbarrier": _unbarrier,
    "retry": _retry,
    "retry_edit": _failed_once,
    "cancel": _cancel,
    "duplicate": _duplicate,
    "give_to": _give_to,
    **{verb: _control(verb) for verb in CONTROLS},
    **{f"{verb}_all": _control_all(verb) for verb in CONTROLS},
}
