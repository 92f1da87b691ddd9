"""Barriers across robots: which can be passed, in what order, and which never.

Each robot reaches its barrier skills in the order of its list; a barrier is
passed when every partner robot has reached it. Walking all robots forward
together finds the barriers that are never passed: a *deadlock* is a cycle
of barriers each waiting for a robot held at the next (lru1: b1 then b2,
lru2: b2 then b1 — with any number of robots); an *orphaned* barrier waits
for a partner that has already gone through it (its skill started or
finished). Barriers stuck behind those are reported with them, not apart.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from backend.core.model import FINISHED, Mission, SkillInstance, Status

GONE = FINISHED | {Status.RUNNING, Status.PAUSED}  # a member that went through its barrier


@dataclass
class BarrierAnalysis:
    # barrier -> robot -> its skill there, for members not through it yet
    pending: dict[str, dict[str, str]] = field(default_factory=dict)
    # barrier -> (robot, skill) of members already through it, while others are not
    orphaned: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    cycles: list[list[str]] = field(default_factory=list)  # barriers, each waiting for the next
    stuck: set[str] = field(default_factory=set)  # every barrier never passed
    # robot -> the barriers it reaches, in order (pending members only)
    sequence: dict[str, list[str]] = field(default_factory=dict)
    # (waiting barrier, barrier holding) -> the robot that holds it up
    held_by: dict[tuple[str, str], str] = field(default_factory=dict)

    def skill_of(self, barrier: str, robot: str) -> str:
        return self.pending[barrier][robot]


def analyse(mission: Mission) -> BarrierAnalysis:
    out = BarrierAnalysis()
    member_of = {sid: name for name, b in mission.barriers.items() for sid in b.skills}
    for robot, task in mission.tasks.items():
        for s in task:
            if s.id in member_of:
                _note_member(out, robot, s, member_of[s.id])
    out.orphaned = {b: gone for b, gone in out.orphaned.items() if b in out.pending}
    _walk(out)
    return out


def _note_member(out: BarrierAnalysis, robot: str, s: SkillInstance, barrier: str) -> None:
    """Skill `s` of `robot` in `barrier`: still to reach it, or gone through."""
    if s.status in GONE:
        out.orphaned.setdefault(barrier, []).append((robot, s.id))
    else:
        out.pending.setdefault(barrier, {})[robot] = s.id
        out.sequence.setdefault(robot, []).append(barrier)


def _walk(out: BarrierAnalysis) -> None:
    """Move every robot through the barriers it can pass; what is left is stuck."""
    at = _passed(out)
    found = strong_components(_held(out, at))
    out.cycles = sorted(sorted(c) for c in found if not any(b in out.orphaned for b in c))


def _passed(out: BarrierAnalysis) -> dict[str, int]:
    """How many of its barriers each robot gets through, moving them all on
    until none can: a barrier is passed once all its robots are at it."""
    at = dict.fromkeys(out.sequence, 0)
    moved = True
    while moved:
        moved = False
        for robot in out.sequence:
            bid = _holding(out, at, robot)
            if bid is not None and _all_at(out, at, bid):
                for r in out.pending[bid]:
                    at[r] += 1
                moved = True
    return at


def _holding(out: BarrierAnalysis, at: dict[str, int], robot: str) -> str | None:
    """The barrier `robot` is held at (None: it is through all of its)."""
    seq = out.sequence[robot]
    return seq[at[robot]] if at[robot] < len(seq) else None


def _all_at(out: BarrierAnalysis, at: dict[str, int], bid: str) -> bool:
    """Every robot of barrier `bid` is at it (never, if a partner is gone)."""
    if bid in out.orphaned:
        return False
    seqs = out.sequence
    return all(at[r] < len(seqs[r]) and seqs[r][at[r]] == bid for r in out.pending[bid])


def _held(out: BarrierAnalysis, at: dict[str, int]) -> dict[str, set[str]]:
    """Marks the barriers robots are held at, and every later one of theirs,
    as stuck; returns which barrier waits for which (each later barrier of a
    robot for the one it is held at)."""
    graph: dict[str, set[str]] = {}
    for robot, seq in out.sequence.items():
        holding = _holding(out, at, robot)
        if holding is None:
            continue
        later = seq[at[robot] + 1 :]
        out.stuck.update(later)
        out.stuck.add(holding)
        for bid in later:
            graph.setdefault(bid, set()).add(holding)
            out.held_by.setdefault((bid, holding), robot)
    return graph


def strong_components(graph: dict[str, set[str]]) -> Iterable[list[str]]:
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    tarjan = _Tarjan(graph)
    for root in sorted(graph):
        if root not in tarjan.index:
            tarjan.visit(root)
    return tarjan.found


class _Tarjan:
    """Tarjan's walk with its own stack of work (no recursion limit): each
    node numbered as it is entered, `low` the smallest number it reaches
    back to, a component closed at the node whose `low` is its own."""

    def __init__(self, graph: dict[str, set[str]]) -> None:
        self.graph = graph
        self.index: dict[str, int] = {}
        self.low: dict[str, int] = {}
        self.on: set[str] = set()  # the nodes on `stack`
        self.stack: list[str] = []
        self.found: list[list[str]] = []

    def visit(self, root: str) -> None:
        work = [self._enter(root)]  # (node, its successors still to look at)
        while work:
            node, todo = work[-1]
            if todo:
                self._follow(work, node, todo.pop())
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                self.low[parent] = min(self.low[parent], self.low[node])
            if self.low[node] == self.index[node]:
                self._close(node)

    def _enter(self, node: str) -> tuple[str, list[str]]:
        self.index[node] = self.low[node] = len(self.index)
        self.stack.append(node)
        self.on.add(node)
        return node, sorted(self.graph.get(node, ()))

    def _follow(self, work: list[tuple[str, list[str]]], node: str, nxt: str) -> None:
        """The edge node -> nxt: a new node to walk, or one back on the stack."""
        if nxt not in self.index:
            work.append(self._enter(nxt))
        elif nxt in self.on:
            self.low[node] = min(self.low[node], self.index[nxt])

    def _close(self, node: str) -> None:
        """Pop the component whose first node is `node` (kept if not alone)."""
        comp: list[str] = []
        n = None
        while n != node:
            n = self.stack.pop()
            self.on.discard(n)
            comp.append(n)
        if len(comp) > 1:
            self.found.append(comp)
