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

from backend.core.model import FINISHED, Mission, Status

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
    member_of: dict[str, str] = {}
    for name, b in mission.barriers.items():
        for sid in b.skills:
            member_of[sid] = name
    for robot, task in mission.tasks.items():
        for s in task:
            found = member_of.get(s.id)
            if found is None:
                continue
            if s.status in GONE:
                out.orphaned.setdefault(found, []).append((robot, s.id))
            else:
                out.pending.setdefault(found, {})[robot] = s.id
                out.sequence.setdefault(robot, []).append(found)
    out.orphaned = {b: gone for b, gone in out.orphaned.items() if b in out.pending}
    _walk(out)
    return out


def _walk(out: BarrierAnalysis) -> None:
    """Move every robot through the barriers it can pass; what is left is stuck."""
    at = dict.fromkeys(out.sequence, 0)
    moved = True
    while moved:
        moved = False
        for robot, seq in out.sequence.items():
            if at[robot] >= len(seq):
                continue
            bid = seq[at[robot]]
            if bid in out.orphaned:
                continue
            members = out.pending[bid]
            if all(at[r] < len(out.sequence[r]) and out.sequence[r][at[r]] == bid for r in members):
                for r in members:
                    at[r] += 1
                moved = True
    graph: dict[str, set[str]] = {}
    for robot, seq in out.sequence.items():
        if at[robot] < len(seq):
            holding = seq[at[robot]]
            for bid in seq[at[robot] + 1 :]:
                out.stuck.add(bid)
            out.stuck.add(holding)
            # every later barrier of this robot waits for the one it is held at
            for bid in seq[at[robot] + 1 :]:
                graph.setdefault(bid, set()).add(holding)
                out.held_by.setdefault((bid, holding), robot)
    found = strong_components(graph)
    out.cycles = [sorted(c) for c in found if not any(b in out.orphaned for b in c)]
    out.cycles.sort()


def strong_components(graph: dict[str, set[str]]) -> Iterable[list[str]]:
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work: list[tuple[str, list[str]]] = [(root, sorted(graph.get(root, ())))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            node, todo = work[-1]
            if todo:
                nxt = todo.pop()
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on.add(nxt)
                    work.append((nxt, sorted(graph.get(nxt, ()))))
                elif nxt in on:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    n = stack.pop()
                    on.discard(n)
                    comp.append(n)
                    if n == node:
                        break
                if len(comp) > 1:
                    found.append(comp)
    return found
